"""Minimal coordinates: constraints reduced away by coordinate partitioning."""
from __future__ import annotations

import numpy as np

from mbcomp.core.errors import SimulationError, TrialStateError, format_state
from mbcomp.core.small_linalg import least_norm, pivoted_qr, solve
from mbcomp.core.statemap import Chart
from mbcomp.formulations.base import ASSEMBLY_TOLERANCE, Formulation, Workspace
from mbcomp.formulations.friction import has_friction
from mbcomp.formulations.lagrange_c import c_lagrange

#: Re-centre a ball's chart (a restart) once its rotation vector exceeds this (rad).
CHART_LIMIT = 1.0

#: Re-choose the independent coordinates when the dependent block's condition number
#: exceeds this (and a fresh choice is clearly better).
REPARTITION_CONDITION = 30.0


def partition(J: np.ndarray):
    """``(dependent, independent)`` speed indices: the dependent ones are the pivot
    columns of a column-pivoted QR of the (independent-row) Jacobian."""
    nq = J.shape[1]
    if J.shape[0] == 0:
        return np.arange(0), np.arange(nq)
    _, piv = pivoted_qr(J)
    dep = np.sort(piv[: J.shape[0]])
    ind = np.setdiff1d(np.arange(nq), dep)
    return dep, ind


class LagrangeWorkspace(Workspace):
    """State ``[x_ind, qd_ind]``: the independent chart coordinates (``statemap.Chart``: the
    coordinates themselves for screw joints, a rotation vector from a base orientation for
    a ball) and their speeds; the dependent ones by warm-started Newton."""

    def __init__(self, formulation, kernel, t0, q0, qd0, tau, contacts=()):
        super().__init__(formulation, kernel, t0, q0, qd0, tau, contacts)
        # Newton starts from the last accepted state, advanced by its speeds: stage values of
        # rejected steps must not carry the iteration onto another assembly branch.
        self.t_accepted, self.q_accepted, self.qd_accepted = t0, q0.copy(), qd0.copy()
        self._span = None  # (t, q, qd) at the end of the step whose samples are being taken
        self.chart = Chart(self.state_map, q0)
        self.choose(t0, q0)
        self.y0 = np.concatenate((self.chart.to_x(q0)[self.qind], qd0[self.ind]))

    def choose(self, t, q):
        """Partition the speeds at ``q`` (and centre the chart there)."""
        self.chart = Chart(self.state_map, q)
        cv = self.formulation.constraint_values(self.kernel, t, q, np.zeros(self.kernel.nv), self.offsets,
                                                self.contacts)
        self.rows = self.formulation.rows_of(cv.J)
        self.formulation.check_dead_point(cv.J, self.qd_accepted, t, q, self.contacts, self.rows)
        self.set_partition(cv.J, self.rows)

    def set_partition(self, J, rows):
        """Speeds partitioned on every independent row ``rows`` of ``J``, coordinates on the
        position rows among them: velocity (rolling, no-slip) rows remove speeds, not
        coordinates.  Without velocity rows the two partitions are the same."""
        self.rows = rows
        self.dep, self.ind = partition(J[rows])
        mask = self.formulation.position_mask(J.shape[0])
        self.prows = rows[mask[rows]]
        if self.prows.size == rows.size:
            self.qdep, self.qind = self.dep, self.ind
        else:
            self.qdep, self.qind = partition(J[self.prows])

    def span(self, t_end: float, y_end: np.ndarray) -> None:
        """Before the dense output and samples of the step to ``(t_end, y_end)``: Newton starts
        from the interpolant of the step's two full states (Hermite; for quaternions the nearer
        end advanced by its speeds) instead of the start state advanced by its speeds, which
        near a singular position can be closer to another assembly branch."""
        self._span = None
        q, qd, _ = self._full_state(t_end, np.asarray(y_end)[:len(self.qind) + len(self.ind)])  # (without drive states)
        self._span = (float(t_end), q, qd)

    def end_span(self) -> None:
        """After the step's samples: Newton starts from the accepted state again."""
        self._span = None

    def _predictor(self, t: float) -> np.ndarray:
        """Where Newton starts for time ``t`` (coordinates)."""
        ta, qa, va = self.t_accepted, self.q_accepted, self.qd_accepted
        if self._span is None or not self._span[0] > ta:
            return self.state_map.integrate(qa, va * (t - ta))
        te, qe, ve = self._span
        h = te - ta
        u = (t - ta) / h
        if not self.state_map.identity:
            return (self.state_map.integrate(qe, ve * (t - te)) if u > 0.5
                    else self.state_map.integrate(qa, va * (t - ta)))
        return ((2 * u**3 - 3 * u**2 + 1) * qa + (u**3 - 2 * u**2 + u) * h * va
                + (-2 * u**3 + 3 * u**2) * qe + (u**3 - u**2) * h * ve)

    def dependent(self, t, xi):
        """Full q (and its chart coordinates) from the independent chart coordinates (Newton
        from the last accepted state, advanced along its velocity, or ``span``'s predictor)."""
        chart = self.chart
        x = chart.to_x(self._predictor(t))
        x[self.qind] = xi
        q = chart.to_q(x)
        zero = np.zeros(self.kernel.nv)
        for _ in range(25):
            cv = self.formulation.constraint_values(self.kernel, t, q, zero, self.offsets, self.contacts)
            g = cv.g[self.prows]
            if float(np.abs(g).max(initial=0.0)) < ASSEMBLY_TOLERANCE:
                break
            D = chart.tangent(x)
            Jx = cv.J[self.prows] if D is None else cv.J[self.prows] @ D
            try:
                x[self.qdep] -= solve(Jx[:, self.qdep], g)
            except np.linalg.LinAlgError:
                raise TrialStateError(f"dependent coordinates are singular at t = {t:g}: constraints "
                                      f"{self.formulation.row_names(self.rows, self.contacts)}") from None
            q = chart.to_q(x)
        else:
            raise TrialStateError(f"dependent coordinates did not converge at t = {t:g} (residual "
                                  f"{np.max(np.abs(g)):.3g}): constraints "
                                  f"{self.formulation.row_names(self.rows, self.contacts)}")
        return q, cv, x

    def retreat(self):
        """``(t, y)`` of the last accepted state, with the coordinates chosen afresh there."""
        self.choose(self.t_accepted, self.q_accepted)
        return self.t_accepted, np.concatenate((self.chart.to_x(self.q_accepted)[self.qind],
                                                self.qd_accepted[self.ind]))

    def _full_state(self, t, y):
        k = len(self.qind)
        xi, qdi = y[:k], y[k:k + len(self.ind)]
        q, cv, x = self.dependent(t, xi)
        qd = np.zeros(self.kernel.nv)
        qd[self.ind] = qdi
        if len(self.dep):
            J = cv.J[self.rows]
            qd[self.dep] = solve(J[:, self.dep], -(J[:, self.ind] @ qdi + cv.g_t[self.rows]))
        return q, qd, x

    def full_state(self, t, y):
        return self._full_state(t, y)[:2]

    def normalize(self, y) -> None:
        return None  # the chart keeps quaternions at unit length

    def rhs(self, t, y):
        q, qd, x = self._full_state(t, y)
        tau = self.kernel.tau(self.tau, t, q, qd)
        qdd, _ = self.formulation.solve(self.kernel, t, q, qd, tau, self.offsets, self.contacts,
                                        (self.rows, self.dep, self.ind), multipliers=False)
        return np.concatenate((self.chart.rate(x, qd)[self.qind], qdd[self.ind]))

    def after_step(self, t, y):
        q, qd, x = self._full_state(t, y)
        self.t_accepted, self.q_accepted, self.qd_accepted = t, q, qd
        if self.chart.largest_rotation(x) > CHART_LIMIT:
            self.chart = Chart(self.state_map, q)  # re-centre the rotations' chart here
            return np.concatenate((self.chart.to_x(q)[self.qind], qd[self.ind]))
        if not len(self.dep):
            return None
        return self.repartition(t, q, qd)

    def repartition(self, t, q, qd):
        """At the accepted state ``(t, q, qd)``: when the dependent block is ill-conditioned and
        a clearly better choice exists, take it (and centre the chart at q) and return the
        state in the new coordinates; else None.  ``SimulationError`` when the constraint
        Jacobian lost rank (no independent coordinates exist there)."""
        cv = self.formulation.constraint_values(self.kernel, t, q, np.zeros(self.kernel.nv), self.offsets,
                                                self.contacts)
        condition = max(self.condition(cv.J, self.rows, self.dep), self.condition(cv.J, self.prows, self.qdep))
        if condition < REPARTITION_CONDITION:
            return None
        rows = self.formulation.rows_of(cv.J)
        nominal = self.formulation.nominal_rank
        if nominal is not None and not self.contacts and rows.size < nominal:
            lost = sorted(set(range(cv.J.shape[0])) - set(rows.tolist()))
            raise SimulationError(
                f"the mechanism reaches a singular position at t = {t:g} (q = {format_state(q)}): the constraint "
                f"Jacobian loses rank, so no set of independent coordinates exists there; constraints involved: "
                f"{self.formulation.row_names(lost)}. The dae formulation can pass such positions in motion.")
        old = (self.rows, self.dep, self.ind, self.prows, self.qdep, self.qind)
        self.set_partition(cv.J, rows)
        if all(np.array_equal(a, b) for a, b in zip(old, (self.rows, self.dep, self.ind, self.prows, self.qdep,
                                                          self.qind))):
            return None
        if max(self.condition(cv.J, self.rows, self.dep), self.condition(cv.J, self.prows, self.qdep)) > 0.5 * condition:
            self.rows, self.dep, self.ind, self.prows, self.qdep, self.qind = old
            return None  # no clearly better choice
        self.chart = Chart(self.state_map, q)
        return np.concatenate((self.chart.to_x(q)[self.qind], qd[self.ind]))

    def condition(self, J, rows, dep) -> float:
        """How close the dependent block is to singular, against the Jacobian's regular size:
        largest singular value of J (or its size where the mechanism is regular) over the
        smallest of J_d.  Scale-aware, so a 1 x 1 block that shrinks counts too."""
        block = J[np.ix_(rows, dep)]
        smallest = np.linalg.svd(block, compute_uv=False).min() if block.size else np.inf
        largest = max(np.linalg.norm(J, 2) if J.size else 0.0, self.formulation.jacobian_scale)
        return largest / smallest if smallest > 0 else np.inf


class LagrangeFormulation(Formulation):
    """Independent coordinates only (coordinate partitioning)::

        qd = B qd_i + b,   qdd = B qdd_i + c,   B = [I; -J_d^-1 J_i]
        (B^T M B) qdd_i = B^T (f + tau - M c)

    Dependent coordinates follow from ``g(q, t) = 0`` by Newton; motors make their
    coordinate dependent.  Reactions come from the residual ``J^T lam = M qdd - f - tau``.
    """

    name = "lagrange"
    workspace_class = LagrangeWorkspace
    #: condition number of the dependent block above which the independent coordinates are chosen anew
    repartition_condition = REPARTITION_CONDITION
    #: largest rotation vector (rad) of a ball's chart before it is re-centred
    chart_limit = CHART_LIMIT

    @classmethod
    def c_source(cls, nv: int, ng: int) -> str:
        return c_lagrange(nv, ng)

    @property
    def compiled_methods(self) -> tuple[str, ...]:
        """The compiled loops this formulation can step in: DOP853 only with constraints or
        contacts (the reduced loop has no fixed-step variant)."""
        return ("DOP853", "RK4") if self.constraints is None and not self.compiled.contact_rows else ("DOP853",)

    @property
    def compiled_contacts(self) -> bool:
        """Whether the compiled loop can watch this model's contacts (the reduced loop is
        compiled in and the constraints, if any, run in it)."""
        return bool(self.compiled.reduced_loop) and self.compiled_loop() is None

    def compiled_loop(self) -> str | None:
        if self.constraints is None:
            return None
        if not self.compiled.reduced_loop:
            return "the compiled library has no reduced loop for this model"
        if self.nominal_rows is None:
            return "no consistent configuration was found at compile time"
        return None

    def contact_run(self, kernel, lib, q0, qd0, tau, t0=0.0, contacts=(), offsets=None):
        """The compiled stretch between contact events: the reduced loop (``Formulation.contact_run``)."""
        from mbcomp.formulations.lagrange_compiled import ReducedRun
        return ReducedRun(self, kernel, lib, q0, qd0, tau, t0=t0, contacts=contacts, offsets=offsets)

    def scipy_stretch(self, kernel, lib, t0, q0, qd0, tau, contacts=(), offsets=None, method="", z0=None):
        """The compiled reduced right-hand side (``Formulation.scipy_stretch``): with
        constraints or contacts, a ``ReducedRun``'s configuration stepped by scipy
        (``compiled_rhs.CompiledReducedWorkspace``; the drive states ``z0`` after ``[x_i, qd_i]``)."""
        if self.constraints is None and not self.compiled.contact_rows:   # (contacts or collision features)
            return super().scipy_stretch(kernel, lib, t0, q0, qd0, tau, contacts, offsets, method, z0)
        from mbcomp.formulations.compiled_rhs import CompiledReducedWorkspace, Stretch
        from mbcomp.formulations.lagrange_compiled import ReducedRun
        run = ReducedRun(self, kernel, lib, q0, qd0, tau, t0=t0, contacts=contacts, offsets=offsets)
        if self.compiled.contact_rows:  # (armed, the C code evaluates the held contacts' gaps)
            from mbcomp.formulations.impact import GAP_TOLERANCE
            run.watch_contacts(kernel.contacts(q0, qd0).g, GAP_TOLERANCE)
        return Stretch(CompiledReducedWorkspace(run, method, z0), run.close)

    def compiled_session(self, kernel, lib, q0, qd0, tau):
        """The Python side of the compiled reduced loop (None without constraints)."""
        if self.constraints is None:
            return None
        from mbcomp.formulations.lagrange_compiled import ReducedRun
        return ReducedRun(self, kernel, lib, q0, qd0, tau)

    def solve(self, kernel, t, q, qd, tau, offsets=None, contacts=(), partition_hint=None, multipliers=True):
        """``(qdd, lam)``; without ``multipliers`` (the stepping's right-hand side, which
        needs only qdd) lam is left zero instead of solved for."""
        if self.constraints is None and not contacts:
            return kernel.tree_accelerations(t, q, qd, tau), np.zeros(0)
        if has_friction(contacts):
            solution = self.solve_friction(kernel, t, q, qd, tau, offsets, contacts)
            return solution.qdd, solution.lam
        M, f = kernel.checked_dynamics(t, q, qd, tau)
        cv = self.constraint_values(kernel, t, q, qd, offsets, contacts)
        if partition_hint is None:
            rows = self.rows_of(cv.J)
            self.check_dead_point(cv.J, qd, t, q, contacts, rows)
            dep, ind = partition(cv.J[rows])
        else:
            rows, dep, ind = partition_hint
        lam = np.zeros(cv.J.shape[0])
        if rows.size == 0:
            return kernel.tree_solve(M, f, q), lam
        J = cv.J[rows]
        Jd = J[:, dep]
        try:
            X = solve(Jd, np.column_stack((J[:, ind], cv.bias[rows])))
        except np.linalg.LinAlgError:
            raise SimulationError(f"constraint Jacobian is singular at t = {t:g}: constraints "
                                  f"{self.row_names(rows, contacts)}") from None
        B = np.zeros((len(qd), len(ind)))
        B[ind, np.arange(len(ind))] = 1.0
        B[dep] = -X[:, :-1]
        c = np.zeros(len(qd))
        c[dep] = -X[:, -1]
        if len(ind):
            Mr = B.T @ M @ B
            qdd_i = kernel.inverse(kernel.factor(Mr, q)) @ (B.T @ (f - M @ c))
            qdd = B @ qdd_i + c
        else:
            qdd = c
        if multipliers:
            lam[rows] = least_norm(J.T, M @ qdd - f, None, f"the constraint forces at t = {t:g}")
        return qdd, lam
