"""The Formulation interface shared by ``lagrange`` and ``dae``, and the machinery both use."""
from __future__ import annotations

import copy
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbcomp.build.constraint_set import ConstraintValues
from mbcomp.core.errors import format_state, ModelError, SimulationError
from mbcomp.core.small_linalg import orthonormal_basis, pivoted_qr
from mbcomp.core.tolerances import RANK_TOLERANCE, REST_SPEED, SINGULAR_TOLERANCE


#: Newton tolerance on position residuals (m for point equations, rad-like for angles).
ASSEMBLY_TOLERANCE = 1e-12


def independent_rows(J: np.ndarray, tol: float = RANK_TOLERANCE, scale: float = 0.0,
                     prefer: np.ndarray | None = None) -> np.ndarray:
    """Indices of a maximal set of independent rows of ``J`` (pivoted QR of ``J^T``).

    A pivot counts when it exceeds ``tol`` times the largest pivot or ``scale`` (the
    Jacobian's size where the mechanism is regular), so that a Jacobian which vanishes
    as a whole (a folded mechanism) is not mistaken for a full-rank one.  With ``prefer``
    (a mask), those rows are taken first and the others only where they add rank: a loop
    closure is never the row dropped in favour of a driver.
    """
    if J.shape[0] == 0 or J.shape[1] == 0:
        return np.arange(0)
    if prefer is not None and 0 < np.count_nonzero(prefer) < J.shape[0]:
        first, second = np.flatnonzero(prefer), np.flatnonzero(~np.asarray(prefer, dtype=bool))
        reference = max(float(np.max(np.linalg.norm(J, axis=1))), scale)
        chosen = first[independent_rows(J[first], tol, reference)]
        rest = J[second]
        if chosen.size:
            basis = orthonormal_basis(J[chosen].T)
            rest = rest - (rest @ basis) @ basis.T
        extra = second[independent_rows(rest, tol, reference)] if rest.size and np.any(rest) else np.arange(0)
        return np.sort(np.concatenate((chosen, extra)).astype(int))
    diag, piv = pivoted_qr(J.T)
    if diag.size == 0 or diag[0] == 0.0:
        return np.arange(0)
    rank = int(np.sum(diag > tol * max(diag[0], scale)))
    return np.sort(piv[:rank])


@dataclass(frozen=True)
class FormulationInfo:
    """What ``analyse`` finds about a model's constraints at a consistent configuration:
    degrees of freedom, the rank and independent rows of the constraint Jacobian, its size
    and the Schur complement's where the mechanism is regular, the redundant equations."""

    ndof: int
    nominal_rank: int | None = None
    nominal_rows: np.ndarray | None = None  #: read-only
    jacobian_scale: float = 0.0
    schur_scale: float = 0.0
    redundant: tuple[str, ...] = ()


class Workspace:
    """Per-simulation state of a formulation (buffers, partitions, warm starts).

    ``y0``: the integrator's initial state; ``rhs(t, y)``; ``full_state(t, y) -> (q, qd)``;
    ``after_step(t, y) -> y or None`` (a corrected state, e.g. a projection, or None);
    ``normalize(y)``: quaternions back to unit length in place after an accepted step
    (no restart: the change is of the order of the step's error).
    The plain workspace's state is ``[q, qd]`` (nq + nv), its rate ``[q'(q, qd), qdd]``.
    """

    def __init__(self, formulation, kernel, t0: float, q0: np.ndarray, qd0: np.ndarray, tau, contacts=()):
        self.formulation, self.kernel, self.tau = formulation, kernel, tau
        self.contacts = contacts if isinstance(contacts, tuple) else tuple(contacts)  # (a friction.Closed keeps its modes)
        self.n = kernel.nq
        self.state_map = kernel.topology.state_map
        self.offsets = formulation.motor_offsets(q0, t0)
        self.y0 = np.concatenate((q0, qd0))

    def rhs(self, t, y):
        q, qd = y[: self.n], y[self.n:]
        qdd = self.formulation.accelerations(self.kernel, t, q, qd, self.kernel.tau(self.tau, t, q, qd),
                                             offsets=self.offsets, contacts=self.contacts)
        return np.concatenate((self.state_map.qdot(q, qd), qdd))

    def full_state(self, t, y):
        q = y[: self.n]
        return (q if self.state_map.identity else self.state_map.normalize(q)), y[self.n:]

    def after_step(self, t, y):
        return None

    def span(self, t_end: float, y_end: np.ndarray) -> None:
        """Before samples are taken inside the accepted step ending at ``(t_end, y_end)``:
        a workspace that predicts from the step's ends (lagrange's Newton predictor) notes
        them; ``end_span`` afterwards.  Nothing here."""

    def end_span(self) -> None:
        """After the samples inside a step (see ``span``)."""

    def retreat(self):
        """``(t, y)`` of the last accepted state, to retry a step from after a
        ``TrialStateError``; a workspace that raises one overrides this."""
        raise SimulationError(f"{type(self).__name__} cannot go back to its last accepted state")

    def normalize(self, y) -> None:
        if not self.state_map.identity:
            y[: self.n] = self.state_map.normalize(y[: self.n])


class Formulation:
    """How a compiled tree plus constraints becomes ODEs.

    The tree gives ``M(q) qdd = f(q, qd, t) + tau`` over all tree coordinates ``q``
    (``nq``).  Constraints ``g(q, t) = 0`` (``nc`` equations, Jacobian ``J``, with
    ``gddot = J qdd + bias``) add reactions ``J^T lam``::

        [ M   -J^T ] [ qdd ]   [ f + tau ]
        [ J    0   ] [ lam ] = [ -bias   ]

    ``lagrange`` projects this onto independent speeds; ``dae`` solves it as it
    stands, with Baumgarte terms ``-2 alpha gdot - beta^2 g`` added to the second
    row.  Without constraints both are the tree ODE.  Methods take the ``System``
    whose parameters they use; per-simulation state lives in a ``Workspace``.
    """

    name = "base"
    option_names: tuple[str, ...] = ()
    workspace_class = Workspace
    #: Baumgarte gains ``(alpha, beta)`` in 1/s of a KKT solve of this formulation's
    #: constraints; (0, 0): the exact constraint accelerations (constraints reduced away).
    baumgarte: tuple[float, float] = (0.0, 0.0)
    #: Where a KKT solve of this formulation drops a constraint direction
    #: (``core.tolerances.SINGULAR_TOLERANCE``).
    singular_tolerance: float = SINGULAR_TOLERANCE

    def __init__(self, compiled, **options: Any):
        unknown = sorted(set(options) - set(self.option_names))
        if unknown:
            raise ModelError(f"formulation {self.name!r}", f"unknown option(s) {unknown}; "
                             f"it takes {list(self.option_names) or 'none'}")
        self.compiled = compiled
        self.options = options
        self.constraints = compiled.constraint_set
        self.info = FormulationInfo(ndof=compiled.topology.nv)  # until analyse() has run

    # -- numeric pieces -----------------------------------------------------------------------
    def constraint_values(self, kernel, t, q, qd, offsets=None, contacts=()):
        """Constraint equations at a state, with the gap rows of closed (persistent)
        ``contacts`` appended after the model's own."""
        nv = len(qd)
        if self.constraints is not None:
            cv = self.constraints.evaluate(kernel, q, qd, t, offsets)
        else:
            cv = ConstraintValues(np.zeros(0), np.zeros((0, nv)), np.zeros(0), np.zeros(0))
        if contacts:
            ck = kernel.contacts(q, qd)
            idx = list(contacts)
            cv = ConstraintValues(np.concatenate((cv.g, ck.g[idx])), np.vstack((cv.J, ck.J[idx])),
                                  np.concatenate((cv.g_t, ck.g_t[idx])), np.concatenate((cv.bias, ck.bias[idx])))
        return cv

    def row_names(self, rows, contacts=()) -> list[str]:
        """Names of the constraints (or contacts) owning the given equation rows."""
        names = [] if self.constraints is None else list(self.constraints.owner)
        own = self.compiled.topology.contacts   # (collision features follow the model's own contacts)
        names += [own[i].name if i < len(own) else f"collision feature {i - len(own)}" for i in contacts]
        return sorted({names[r] for r in rows if r < len(names)})

    def motor_offsets(self, q0: np.ndarray, t0: float) -> dict:
        """Start values of speed motors, so that their coordinate is ``q0 + speed (t - t0)``."""
        if self.constraints is None:
            return {}
        offsets = {}
        for r, eq in enumerate(self.constraints.equations):
            if getattr(eq, "speed", None) is not None:
                k = self.compiled.topology.q_slice[eq.joint if isinstance(eq.joint, str) else eq.joint.name].start
                offsets[r] = q0[k] - eq.speed * t0
        return offsets

    def solve_constrained(self, kernel, M, f, J, rhs, q, t, contacts=(), qd=None):
        """``(qdd, lam)`` of the KKT system on independent rows of ``J`` (lam 0 elsewhere).

        Fast path: the rows found independent when the model was analysed, accepted when
        the Schur complement ``J M^-1 J^T`` factors with pivots above ``RANK_TOLERANCE``;
        otherwise (contacts, redundancy changing, a singular position) the rows come
        from a pivoted QR and a dead point at rest is reported.
        """
        Minv = kernel.inverse(kernel.factor(M, q))
        Minv_f = Minv @ f
        lam = np.zeros(J.shape[0])
        rows = self.nominal_rows if not contacts and self.nominal_rows is not None else None
        for attempt in range(2):
            if rows is None:
                rows = self.rows_of(J)
                if qd is not None:
                    self.check_dead_point(J, qd, t, q, contacts, rows)
            if rows.size == 0:
                return Minv_f, lam
            every = rows.size == J.shape[0]  # (rows are sorted and distinct: then all of them, in order)
            Js = J if every else J[rows]
            Minv_JT = Minv @ Js.T
            A = Js @ Minv_JT
            LA = kernel.cholesky(A)
            if LA is not None:
                diag = LA.diagonal()
                if diag.min() > RANK_TOLERANCE * max(diag.max(), self.schur_scale):
                    break
            if attempt:
                raise SimulationError(f"constraint Jacobian is singular at t = {t:g}: constraints "
                                      f"{self.row_names(rows, contacts)}")
            rows = None
        LAinv = kernel.inverse(LA)
        lam_s = LAinv @ ((rhs if every else rhs[rows]) - Js @ Minv_f)
        if every:
            lam = lam_s
        else:
            lam[rows] = lam_s
        return Minv_f + Minv_JT @ lam_s, lam

    def check_dead_point(self, J, qd, t, q, contacts=(), rows=None):
        """At rest on a configuration where the Jacobian lost rank the motion is not
        determined (a bifurcation): raise naming the constraints involved.  ``rows``: the
        independent rows of ``J`` when the caller has them (``rows_of``)."""
        rows = self.rows_of(J) if rows is None else rows
        nominal = self.nominal_rank
        if nominal is not None and not contacts and rows.size < nominal and float(np.abs(qd).max(initial=0.0)) < REST_SPEED:
            lost = sorted(set(range(J.shape[0])) - set(rows.tolist()))
            raise SimulationError(
                f"the constraint Jacobian loses rank at q = {format_state(q)} (t = {t:g}) with the "
                f"mechanism at rest: a dead point/bifurcation where the motion is not determined; constraints "
                f"involved: {self.row_names(lost, contacts)}")

    # -- what analyse() found (FormulationInfo) --------------------------------------------------------
    @property
    def ndof(self) -> int:
        return self.info.ndof

    @property
    def redundant(self) -> tuple[str, ...]:
        return self.info.redundant

    @property
    def nominal_rank(self) -> int | None:
        return self.info.nominal_rank

    @property
    def nominal_rows(self) -> np.ndarray | None:
        return self.info.nominal_rows

    @property
    def jacobian_scale(self) -> float:
        return self.info.jacobian_scale

    @property
    def schur_scale(self) -> float:
        return self.info.schur_scale

    def with_info(self, info: "FormulationInfo") -> "Formulation":
        """A copy of this formulation using what ``analyse`` found (this one is unchanged)."""
        new = copy.copy(self)
        new.info = info
        return new

    def rows_of(self, J: np.ndarray) -> np.ndarray:
        """Independent rows of a constraint Jacobian of this model (see ``independent_rows``)."""
        return independent_rows(J, scale=self.jacobian_scale, prefer=self.preferred_rows(J.shape[0]))

    def position_mask(self, n: int) -> np.ndarray:
        """Which of ``n`` constraint rows (the model's, then closed contacts') constrain
        positions: all but the velocity rows (rolling, no-slip)."""
        mask = np.ones(n, dtype=bool)
        if self.constraints is not None:
            mask[:self.constraints.nc] = ~self.constraints.velocity_rows
        return mask

    @property
    def has_velocity_rows(self) -> bool:
        """Whether the model has velocity (non-holonomic) constraint rows."""
        return self.constraints is not None and bool(self.constraints.velocity_rows.any())

    def preferred_rows(self, n: int) -> np.ndarray | None:
        """Rows kept first when some must go: all but the drivers (motor rows); None without drivers."""
        drivers = [] if self.constraints is None else self.constraints.coordinate_rows
        if not drivers:
            return None
        mask = np.ones(n, dtype=bool)
        mask[[r for r in drivers if r < n]] = False
        return mask

    # -- the public operations ---------------------------------------------------------------------
    def accelerations(self, kernel, t, q, qd, tau, offsets=None, contacts=()) -> np.ndarray:
        return self.solve(kernel, t, q, qd, tau, offsets, contacts=contacts)[0]

    def reactions(self, kernel, t, q, qd, tau, offsets=None, contacts=()) -> dict[str, np.ndarray]:
        """Multipliers by constraint name, then each closed contact's normal force (N)."""
        if self.constraints is None and not contacts:
            return {}
        return self.reactions_of(kernel, q, self.solve(kernel, t, q, qd, tau, offsets, contacts=contacts)[1], contacts)

    def reactions_of(self, kernel, q, lam: np.ndarray, contacts=()) -> dict[str, np.ndarray]:
        """``reactions`` from the multipliers ``lam`` of a solve at ``q`` (the model's
        equations, then the closed ``contacts``' normal rows): by constraint name (a motor's
        torque or force, a loop joint's force and torques, ``ConstraintSet.split_reactions``),
        then each closed contact's normal force (N)."""
        nc = 0 if self.constraints is None else self.constraints.nc
        out = {} if self.constraints is None else self.constraints.split_reactions(lam[:nc], kernel, q)
        names = [c.name for c in kernel.topology.contacts]
        out.update({names[i]: float(value) for i, value in zip(contacts, lam[nc:])})
        return out

    def evaluation_gains(self) -> tuple[float, float]:
        """The Baumgarte gains ``(alpha, beta)`` (1/s) of this formulation's solve at a state
        (``solve``, ``compiled_solve``): none here, the exact constraint accelerations."""
        return (0.0, 0.0)

    def compiled_solve(self, kernel, contacts=(), q=None, qd=None):
        """The compiled KKT solve the evaluation calls use on ``kernel`` (``System.accelerations``,
        ``reactions``, ``contact_forces``: ``compiled_eval.CompiledSolve``, the same numbers as
        ``solve`` from the C the compiled loops run), or None where there is none (no
        constraints, no C).  ``contacts``: held contacts (indices, or a ``friction.Closed``
        with friction modes; ``q, qd`` a state of the call, for its friction rows)."""
        from mbcomp.formulations.compiled_eval import CompiledSolve
        return CompiledSolve.of(self, kernel, self.evaluation_gains(), contacts, q, qd)

    def solve(self, kernel, t, q, qd, tau, offsets=None, contacts=()):
        """``(qdd, lam)`` at a state; subclasses define how constraints enter."""
        return kernel.tree_accelerations(t, q, qd, tau), np.zeros(0)

    def contact_forces(self, kernel, t, q, qd, tau, offsets=None, contacts=()) -> dict[str, np.ndarray]:
        """``{contact name: (3,) N, world}``: the force each closed contact in ``contacts``
        applies to its body, normal plus friction (a joint limit's is zero: it has no point)."""
        from mbcomp.formulations.friction import has_friction
        if not contacts:
            return {}
        if has_friction(contacts):
            solution = self.solve_friction(kernel, t, q, qd, tau, offsets, contacts)
            lam, tangential = solution.lam, solution.tangential
        else:
            lam, tangential = self.solve(kernel, t, q, qd, tau, offsets, contacts=contacts)[1], {}
        return self.contact_forces_of(kernel, q, qd, lam, tangential, contacts)

    def contact_forces_of(self, kernel, q, qd, lam: np.ndarray, tangential: dict, contacts,
                          basis: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """``contact_forces`` from a solve's multipliers ``lam`` (the model's equations, then
        the held ``contacts``' normal rows) and its friction forces ``tangential`` (per
        contact with a mode, N in its tangent coordinates): each held contact's force on its
        body (N, world), ``lam_n n + T^T lam_t``.  ``basis``: the contacts' world bases
        (k, 3, 3: rows n, t1, t2, as ``friction.plane_contact_rows`` gives them) when the
        caller has them (a plane's is fixed)."""
        from mbcomp.formulations.friction import ContactRows, plane_contact_rows, world_forces
        normal = lam[len(lam) - len(contacts):]
        rows = plane_contact_rows(kernel, q, qd, contacts) if basis is None else \
            ContactRows(None, None, None, basis, None, None)
        forces = world_forces(rows, normal, tangential, list(contacts))
        names = [c.name for c in kernel.topology.contacts]
        return {names[i]: forces[r] for r, i in enumerate(contacts)}

    # -- friction on closed contacts (formulations/friction.py) ----------------------------------------
    def acceleration_targets(self, cv: ConstraintValues, qd: np.ndarray) -> np.ndarray:
        """``J qdd = targets`` of the constraint rows ``cv`` at speeds ``qd``: ``-bias`` (the
        dae formulation adds its Baumgarte terms)."""
        return -cv.bias

    def solve_friction(self, kernel, t, q, qd, tau, offsets=None, contacts=()):
        """The friction hook of ``solve``: ``FrictionSolution`` (qdd, multipliers of the
        constraint and closed-contact normal rows, tangential forces) when ``contacts`` is a
        ``friction.Closed`` with sticking or sliding contacts.  Both formulations solve the
        full KKT system here (at the consistent states the lagrange workspace hands it, its
        accelerations are the partitioned ones)."""
        from mbcomp.formulations.friction import friction_solve
        M, f = kernel.checked_dynamics(t, q, qd, tau)
        cv = self.constraint_values(kernel, t, q, qd, offsets, contacts)
        Minv = kernel.inverse(kernel.factor(M, q))
        return friction_solve(kernel, Minv, f, cv.J, self.acceleration_targets(cv, qd), contacts, q, qd, t)

    def assemble(self, kernel, q: np.ndarray, qd: np.ndarray, t: float = 0.0, offsets=None):
        """Positions onto ``g = 0`` (Newton, minimum-norm steps), speeds onto ``gdot = 0``
        (mass-orthogonal projection).  ``SimulationError`` naming the constraints that fail."""
        if self.constraints is None:
            return q.copy(), qd.copy()
        zero = np.zeros_like(qd)
        state_map = kernel.topology.state_map
        base = q.copy()

        def position(x):  # x: a step in speed space from the guess (the coordinates themselves for screws)
            return x if state_map.identity else state_map.integrate(base, x)

        last = [None, None]  # the solver asks for the Jacobian where it just had the residual

        def values(x):
            key = x.tobytes()
            if last[0] != key:
                last[:] = key, self.constraint_values(kernel, t, position(x), zero, offsets)
            return last[1]

        def residual(x):
            g = values(x).g
            return np.where(np.isfinite(g), g, 0.0)

        def jacobian(x):
            cv = values(x)
            return np.where(np.isfinite(cv.g)[:, None], cv.J, 0.0)

        q = q.copy()
        if float(np.max(np.abs(residual(q if state_map.identity else zero)), initial=0.0)) > 1e-6:
            # Far from the constraints: a trust-region least-squares solve, robust where
            # plain Newton steps explode (near-singular Jacobians off the solution set).
            # (With quaternions the Jacobian in speed space is exact at the guess only,
            # enough for trf; the Newton polish below is exact.)
            import scipy.optimize  # on first use: scipy is not imported with mbcomp
            solution = scipy.optimize.least_squares(residual, q if state_map.identity else zero, jac=jacobian,
                                                    method="trf", xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=400)
            q = position(solution.x)
        for _ in range(20):  # Newton polish with minimum-norm steps
            cv = self.constraint_values(kernel, t, q, zero, offsets)
            rows = np.isfinite(cv.g)
            if float(np.max(np.abs(cv.g[rows]), initial=0.0)) < ASSEMBLY_TOLERANCE:
                break
            step, *_ = np.linalg.lstsq(cv.J[rows], -cv.g[rows], rcond=1e-10)
            q = state_map.integrate(q, step)
        cv = self.constraint_values(kernel, t, q, zero, offsets)
        g = np.where(np.isfinite(cv.g), cv.g, 0.0)
        if float(np.max(np.abs(g), initial=0.0)) > 1e-9:
            worst = np.argsort(-np.abs(g))
            bad = [self.constraints.labels[r] for r in worst if abs(g[r]) > 1e-9][:6]
            error = SimulationError(f"cannot assemble: constraints {bad} cannot be met near q = "
                                    f"{format_state(q)} (largest residual {np.max(np.abs(g)):.3g})")
            error.residual = float(np.max(np.abs(g)))
            raise error
        return q, self.project_velocity(kernel, q, qd, t, offsets)

    def project_velocity(self, kernel, q, qd, t=0.0, offsets=None):
        """The speeds closest to ``qd`` in the kinetic-energy norm with ``J qd + g_t = 0``."""
        cv = self.constraint_values(kernel, t, q, np.zeros_like(qd), offsets)
        rows = self.rows_of(cv.J)
        if rows.size == 0:
            return qd.copy()
        J = cv.J[rows]
        violation = J @ qd + cv.g_t[rows]
        M, _ = kernel.dynamics(t, q, np.zeros_like(qd))
        Minv_JT = kernel.inverse(kernel.factor(M, q)) @ J.T
        correction = Minv_JT @ np.linalg.solve(J @ Minv_JT, violation)
        return qd - correction

    def constraint_violation(self, kernel, t: float, q: np.ndarray, offsets=None) -> float:
        """max |g(q, t)| over the position-level constraint equations."""
        if self.constraints is None:
            return 0.0
        g = self.constraint_values(kernel, t, q, np.zeros(kernel.nv), offsets).g
        return float(np.max(np.abs(g[np.isfinite(g)]), initial=0.0))

    def constraint_violation_series(self, kernel, t: np.ndarray, q: np.ndarray, offsets=None) -> np.ndarray:
        """``constraint_violation`` at every sample (rows of ``q``), vectorised."""
        if self.constraints is None:
            return np.zeros(len(q))
        G = self.constraints.residual_series(kernel, t, q, offsets)
        return np.max(np.where(np.isfinite(G), np.abs(G), 0.0), axis=1, initial=0.0)

    # -- hooks for the compiled code ------------------------------------------------------------------
    @classmethod
    def c_source(cls, nv: int, ng: int) -> str:
        """C code this formulation adds to every compiled model (``nv`` speeds, ``ng``
        geometric constraint rows); the compiled integrators call what it defines."""
        return ""

    def compiled_loop(self) -> str | None:
        """Why this formulation cannot step in the compiled integrators (None when it can)."""
        if self.constraints is None:
            return None
        return f"the {self.name} formulation of a constrained model steps in Python (use formulation='dae')"

    @contextmanager
    def compiled_setup(self, lib, kernel=None, q0=None):
        """Configure the compiled library for one compiled run on this thread (and undo it);
        ``kernel`` and the start coordinates ``q0`` when the configuration depends on them."""
        yield

    def scipy_stretch(self, kernel, lib, t0: float, q0: np.ndarray, qd0: np.ndarray, tau, contacts: tuple = (),
                      offsets: dict | None = None, method: str = "", z0: np.ndarray | None = None):
        """scipy's stepping of the compiled right-hand side from the consistent ``(q0, qd0)`` at
        ``t0`` with the held ``contacts`` (``tau``: constant generalised forces or None; ``z0``:
        the drive elements' states, which follow the mechanical state in ``y``): a
        ``compiled_rhs.Stretch`` whose ``workspace`` calls the C functions the compiled loops
        step; ``close()`` undoes the configuration.  Only asked for where the compiled loop
        could run the model (``run/paths.why_not_compiled``).  Here: the tree state without
        constraints and contacts, configured by ``compiled_setup``."""
        from mbcomp.formulations.compiled_rhs import tree_stretch
        workspace = self.start(kernel, t0, q0, qd0, tau, contacts)
        if offsets is not None:
            workspace.offsets = offsets
        return tree_stretch(self, kernel, workspace, tau, method, self.compiled_setup(lib, kernel=kernel, q0=q0), z0)

    #: The compiled loops (``integrators.COMPILED_METHODS``) this formulation can step in.
    compiled_methods: tuple[str, ...] = ("DOP853", "RK4")

    def compiled_friction_problem(self) -> str | None:
        """Why this formulation's compiled solve cannot take the rows of contacts with
        friction (None: it can; ``friction_c.compiled_friction_problem`` checks the contacts)."""
        return None

    def compiled_method_problem(self, method: str) -> str | None:
        """Why this formulation of the model has no compiled ``method`` loop (None: it has one)."""
        if method in self.compiled_methods:
            return None
        return f"the {self.name} formulation of this model has no compiled {method} loop"

    #: Whether the compiled loop can watch this model's contacts (``contact_run`` gives the
    #: stretches between events); False: a model with contacts steps in scipy.
    compiled_contacts: bool = False

    def contact_run(self, kernel, lib, q0: np.ndarray, qd0: np.ndarray, tau, t0: float = 0.0, contacts: tuple = (),
                    offsets: dict | None = None):
        """One compiled stretch of a run with contacts, from the consistent ``(q0, qd0)`` at
        ``t0`` with the closed (held) ``contacts`` and the run's speed-motor ``offsets``: a
        context manager and ``integrators.LoopSession`` that also arms the loop's contact
        watch (``compiled_watch.ContactWatching``: ``watch_contacts``, ``event_step``,
        ``locator``, ``sync``, ``workspace``, ``gaps``).  Only called when
        ``compiled_contacts`` is true."""
        raise NotImplementedError(f"the {self.name} formulation has no compiled contact loop")

    def compiled_session(self, kernel, lib, q0: np.ndarray, qd0: np.ndarray, tau):
        """For a formulation whose integration state is not ``[q, v, z]``: the object that drives
        its compiled loop for one run from ``(q0, qd0)`` (``y0``, ``resume``, ``close``; see
        ``formulations/lagrange_compiled.py``); None for the plain loop."""
        return None

    def explain_compiled_failure(self, lib) -> None:
        """After the compiled loop failed (inside ``compiled_setup``): raise a
        ``SimulationError`` naming the cause when this formulation's C code recorded one (a
        motor's law that was not finite); return otherwise, and the loop's own error stands."""

    def start(self, kernel, t0, q0, qd0, tau, contacts=()) -> Workspace:
        """The per-simulation workspace (the plain tree one when there are no constraints)."""
        cls = Workspace if self.constraints is None and not contacts else self.workspace_class
        return cls(self, kernel, t0, q0, qd0, tau, contacts)


def _check_drivers(formulation, J: np.ndarray, g_t: np.ndarray, rows: np.ndarray) -> None:
    """A driver (motor row) that the other constraints already determine must prescribe
    what they imply (two motors of equal speed on one joint); otherwise the constraints
    conflict: ``ModelError`` naming them."""
    constraints = formulation.constraints
    kept = set(rows.tolist())
    for r in constraints.coordinate_rows:
        if r in kept or not rows.size:
            continue
        c = np.linalg.lstsq(J[rows].T, J[r], rcond=None)[0]
        implied = float(c @ g_t[rows])
        scale = max(1.0, float(np.max(np.abs(g_t), initial=0.0)))
        if abs(g_t[r] - implied) <= 1e-8 * scale:
            continue
        involved = [rows[i] for i in np.flatnonzero(np.abs(c) > 1e-9 * np.max(np.abs(c)))]
        names = []
        for i in involved:
            comp = constraints.groups_by_row(i)
            kind = comp.noun or type(comp).__name__
            label = f"{kind} {constraints.owner[i]!r}"
            if label not in names:
                names.append(label)
        own = type(constraints.groups_by_row(r)).__name__
        raise ModelError(None, f"the constraints conflict: {own} {constraints.owner[r]!r} prescribes a rate of "
                               f"{-g_t[r]:.6g} for its coordinate, but it is "
                               f"already fixed by {' and '.join(names)} (at {-implied:.6g}); remove one of them")


def _newton_onto(formulation, kernel, q: np.ndarray, steps: int = 20) -> np.ndarray | None:
    """A configuration on ``g = 0`` reached from ``q`` by plain Newton steps of minimum norm,
    or None when they do not get there (a non-finite value, a residual that stalls or grows
    a hundredfold, or ``steps`` used up).  For the analysis, which needs some consistent
    configuration, not the one nearest the guess: about 1 ms where the trust-region search
    of ``assemble`` takes 10-30 ms (four-bar: 5-11 steps against 47-67 evaluations)."""
    zero = np.zeros(kernel.nv)
    state_map = kernel.topology.state_map
    first = None
    for _ in range(steps):
        cv = formulation.constraint_values(kernel, 0.0, q, zero)
        rows = formulation.position_mask(len(cv.g))  # (velocity rows have no residual)
        g, J = cv.g[rows], cv.J[rows]
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(J))):
            return None
        residual = float(np.max(np.abs(g), initial=0.0))
        if residual < ASSEMBLY_TOLERANCE:
            return q
        first = residual if first is None else first
        if residual > 100.0 * first:
            return None
        step, *_ = np.linalg.lstsq(J, -g, rcond=1e-10)
        if not np.any(step):  # the residual is outside the Jacobian's range (a singular guess)
            return None
        q = state_map.integrate(q, step)
    return None


def analyse(formulation, kernel, tries: int = 6, seed: int = 0) -> FormulationInfo:
    """Find a consistent configuration and from it the rank of the constraints: the
    degrees of freedom, the independent rows and the redundant equations (by label).
    Changes nothing (``formulation.with_info`` makes the formulation that uses the result).

    Raises ``ModelError`` when no configuration satisfies the constraints (they
    conflict, or leave fewer than zero degrees of freedom).
    """
    nq, nv = kernel.nq, kernel.nv
    if formulation.constraints is None:
        return FormulationInfo(ndof=nv)
    rng = np.random.default_rng(seed)
    state_map = kernel.topology.state_map
    guesses = [state_map.neutral()] + [rng.uniform(-1.0, 1.0, nq) for _ in range(tries - 1)]
    guesses = [state_map.normalize(g) for g in guesses]
    last_error, best = None, None
    closest = np.inf
    consistent = 0
    for guess in guesses:
        try:
            q = _newton_onto(formulation, kernel, guess)
            if q is None:  # Newton did not settle: the robust (and slower) trust-region assembly
                q, _ = formulation.assemble(kernel, guess, np.zeros(nv))
        except SimulationError as exc:
            residual = getattr(exc, "residual", np.inf)
            if residual < closest:
                closest, last_error = residual, exc
            continue
        consistent += 1
        values = formulation.constraint_values(kernel, 0.0, q, np.zeros(nv))
        J = values.J
        rows = independent_rows(J, prefer=formulation.preferred_rows(J.shape[0]))
        _check_drivers(formulation, J, values.g_t, rows)
        # The generic rank is the largest found: a configuration may be singular (a
        # parallelogram built collinear), never more regular than the mechanism.
        if best is None or rows.size > best[0].size:
            pivots = pivoted_qr(J.T)[0]
            best = (rows, J.shape[0], float(pivots[0]) if pivots.size else 0.0, q)
        if consistent >= 3:
            break
    if best is None:
        raise ModelError(None, f"the constraints cannot all be met: no configuration satisfies them (they "
                               f"conflict, or remove more freedom than the {nv} speeds have); from "
                               f"{len(guesses)} starting guesses, the closest: {last_error}")
    rows, nc, scale, q_best = best
    schur_scale = 0.0
    if rows.size:
        # Size of the Schur complement's Cholesky pivots where the mechanism is regular: the
        # fast path in solve_constrained must not accept rows whose pivots all collapsed.
        J = formulation.constraint_values(kernel, 0.0, q_best, np.zeros(nv)).J[rows]
        M, _ = kernel.dynamics(0.0, q_best, np.zeros(nv))
        A = J @ np.linalg.solve(M, J.T)
        schur_scale = float(np.sqrt(np.max(np.abs(np.diag(A)))))
    rows = np.array(rows, dtype=int)
    rows.flags.writeable = False
    return FormulationInfo(ndof=nv - int(rows.size), nominal_rank=int(rows.size), nominal_rows=rows,
                           jacobian_scale=scale, schur_scale=schur_scale,
                           redundant=tuple(formulation.constraints.labels[r] for r in range(nc)
                                           if r not in set(rows.tolist())))
