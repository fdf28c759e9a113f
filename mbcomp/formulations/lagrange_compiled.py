"""The Python side of the lagrange formulation's compiled loop (``lagrange_c.py``).

The compiled DOP853 loop steps the reduced state ``[q_i, qd_i]`` in C and returns to Python
only where the scipy-stepped path would do something other than step:

- ``PAUSED``: after an accepted step whose dependent block is ill-conditioned, the
  ``LagrangeWorkspace`` decides (as in Python stepping) whether to choose the independent
  coordinates afresh; a new choice restarts the integrator there (as a new scipy solver
  would), no new choice resumes it unchanged;
- ``TRIAL_FAILED``: a trial state had no dependent coordinates: back to the last accepted
  state with a quarter of the step (``Workspace.retreat``), at most ``MAX_RETRIES`` times in
  a row.

Held contacts with friction modes (``friction_c.py``): the loop keeps its partition on the
held rows (the state and its dependent coordinates and speeds) and takes the independent
accelerations from the full KKT system with friction, as the Python path's
``Formulation.solve_friction`` does: a sticking contact's tangential rows hold at the
acceleration level (with the ``STICK_RATE`` feedback), a sliding contact's normal force
carries its friction; the held contacts' forces are that solve's multipliers.

A model without degrees of freedom (every coordinate driven or dependent) has nothing to
integrate: ``prescribed`` evaluates the motion at the output times in C.

Motors that prescribe their position by an expression of t (``expressions.Expression``, as
model files give it) run in C as postfix programs (``expressions_c.py``: the expression and its
exact first and second derivatives, ``motor_programs``); a position given as a Python
callable runs too, its values ``s, s', s''`` called back from C once per evaluated time
(``codegen/callbacks.py``, the values Python stepping uses).
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.core.errors import SimulationError
from mbcomp.core.statemap import Chart
from mbcomp.codegen.expressions_c import position_programs
from mbcomp.codegen.callbacks import constant_tau, raise_pending
from mbcomp.codegen.integrators import PAUSED, TRIAL_FAILED, bind_reduced
from mbcomp.formulations.compiled_watch import ContactWatching, EventStepFunctions, pointer
from mbcomp.formulations.friction import has_friction
from mbcomp.formulations.friction_c import FrictionRows

#: Trial failures in a row (without an accepted step between) before the run gives up.
MAX_RETRIES = 10

_VOID, _INT, _DBL, _LONG = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_long


_ptr = pointer


def motor_programs(constraints) -> tuple[np.ndarray, np.ndarray] | None:
    """The programs (``expressions_c``) of the motors that prescribe their position (None when
    there are none): ``(prog, programs)``, motor row r's programs start at ``programs[prog[r]]``
    (nc entries, -1 for other rows): the position s (m or rad), s' (per s) and s'' (per s^2)
    one after the other, the exact derivatives Python stepping uses (``ConstraintSet``); a
    position given as a Python callable runs ``SLOT`` programs, whose values the motor
    callback (``codegen/callbacks.py``) fills with what Python stepping uses
    (``expressions_c.position_programs``)."""
    prog = np.full(constraints.nc, -1, dtype=np.int64)
    parts: list[np.ndarray] = []
    size = 0
    for r, part in sorted(position_programs(constraints)[0].items()):
        prog[r] = size
        parts.append(part)
        size += part.size
    return None if not parts else (prog, np.concatenate(parts))


class ReducedRun(ContactWatching):
    """One compiled lagrange run of ``formulation`` on ``kernel`` from the consistent state
    ``(q0, qd0)`` at t = 0 with constant generalised forces ``tau`` (None or nv values).

    Owns the arrays the C code reads (partition, motor rows) and writes (``acc``: time,
    coordinates and speeds of the last accepted state).  ``close()`` switches the loop off.
    """

    WATCH = "lagrange_watch"

    def __init__(self, formulation, kernel, lib, q0: np.ndarray, qd0: np.ndarray, tau, t0: float = 0.0,
                 contacts: tuple = (), offsets: dict | None = None):
        self.formulation, self.kernel, self.lib = formulation, kernel, lib
        self.n = kernel.nv
        self.nq = kernel.topology.nq  #: coordinates (more than speeds with quaternions)
        constraints = formulation.constraints
        topology = kernel.topology
        self.contacts = contacts if isinstance(contacts, tuple) else tuple(contacts)  # (a friction.Closed keeps its modes)
        self.workspace = formulation.workspace_class(formulation, kernel, t0, q0, qd0, tau, self.contacts)
        if offsets is not None:  # after an event: the speed motors keep the run's start values
            self.workspace.offsets = offsets
        nm = 0 if constraints is None else constraints.nc
        nc = nm + len(self.contacts)
        self.geo = np.full(nc, -1, dtype=np.int64)
        self.mq = np.zeros(nc, dtype=np.int64)
        self.mv = np.zeros(nc, dtype=np.int64)
        self.speed = np.zeros(nc)
        self.offset = np.zeros(nc)
        if constraints is not None:
            self.geo[constraints.geometric_rows] = np.arange(len(constraints.geometric_rows))
            for r in constraints.coordinate_rows:
                joint = constraints.equations[r].joint
                joint = joint if isinstance(joint, str) else joint.name
                self.mq[r] = topology.q_slice[joint].start
                self.mv[r] = topology.v_slice[joint].start
                speed = constraints.motor_speed(kernel, r)
                if speed is not None:  # (a position motor's row runs its stack programs)
                    self.speed[r] = speed
                    self.offset[r] = self.workspace.offsets[r]
        for j, k in enumerate(self.contacts):
            self.geo[nm + j] = -2 - k
        self.nz = kernel.compiled.drives.nz  #: drive states, after [q_i, qd_i] in the reduced state
        self.acc = np.concatenate(([t0], q0, qd0, np.zeros(self.nz)))
        self.info = np.array([0.0, np.nan])  # [condition, time of a non-finite motor position]
        self.programs = None if constraints is None else motor_programs(constraints)
        self.tau = constant_tau(tau)  # (a callable tau: the input callback's)
        self.retries, self.t_retry = 0, -np.inf
        self.restarts = 0  #: new partitions and retreats (as Python stepping counts them)
        configure = lib.lagrange_configure
        configure.argtypes = ([_INT] + [_VOID] * 5 + [_INT, _VOID, _VOID, _INT, _VOID] * 2
                              + [_DBL, _DBL, _VOID, _VOID])
        configure.restype = ctypes.c_int
        self.run = lib.dop853_reduced_run
        self.gaps = self.event = self.held = None
        self._configure()
        self.friction = None
        if has_friction(self.contacts):  # the full KKT solve with friction on every equation (friction_c.py)
            self.friction = FrictionRows(kernel, lib, self.contacts, {i: nm + r for r, i in enumerate(self.contacts)},
                                         nc, q0, qd0)
        if self.programs is not None:  # (after configuring: the C side reports into self.info)
            positions = lib.lagrange_positions
            positions.argtypes, positions.restype = [_VOID] * 2, ctypes.c_int
            prog, programs = self.programs
            positions(_ptr(prog), _ptr(programs))
        drives = lib.lagrange_drives
        drives.argtypes, drives.restype = [_INT], ctypes.c_int
        drives(int(bool(kernel.compiled.drives.elements)))  # (their states follow [q_i, qd_i] in y)
        # collision features: the C narrow phase on this stretch's candidates (compiled/collision_c.py)
        self.collisions = kernel.compiled_stretch(lib, q0, qd0, self.contacts)
        if self.collisions is not None:
            self.step_cap = self.collisions.step_cap

    def loop(self, lib):
        """The reduced loop (``dop853_reduced_run``): it steps ``[q_i, qd_i, z]``."""
        return bind_reduced(lib)

    def locator(self, t_old: float, y_old: np.ndarray) -> "_Locator":
        """The gaps and held contacts' forces on the event step the loop stopped at, in C
        (for ``ContactWatch.locator``)."""
        return _Locator(self, t_old, y_old)

    # -- configuration ---------------------------------------------------------------------------
    def reconfigure(self) -> None:
        """Hand the run's Python workspace's partition (and chart) to the C code again (after
        it chose them anew)."""
        self._configure()

    def _configure(self) -> None:
        ws = self.workspace
        self.rows = np.ascontiguousarray(ws.rows, dtype=np.int64)
        self.dep = np.ascontiguousarray(ws.dep, dtype=np.int64)
        self.ind = np.ascontiguousarray(ws.ind, dtype=np.int64)
        # the coordinates' partition (on the position rows: the speeds' one without velocity rows)
        self.prows = np.ascontiguousarray(ws.prows, dtype=np.int64)
        self.qdep = np.ascontiguousarray(ws.qdep, dtype=np.int64)
        self.qind = np.ascontiguousarray(ws.qind, dtype=np.int64)
        status = self.lib.lagrange_configure(
            len(self.geo), _ptr(self.geo), _ptr(self.mq), _ptr(self.mv), _ptr(self.speed), _ptr(self.offset),
            len(self.rows), _ptr(self.rows), _ptr(self.dep), len(self.ind), _ptr(self.ind),
            len(self.prows), _ptr(self.prows), _ptr(self.qdep), len(self.qind), _ptr(self.qind),
            float(self.formulation.jacobian_scale), float(self.formulation.repartition_condition), _ptr(self.acc), _ptr(self.info))
        if status:
            raise SimulationError("the compiled lagrange loop could not allocate its work space")
        self.base = np.ascontiguousarray(ws.chart.base, dtype=float)  # (the C side reads it: kept alive here)
        chart = self.lib.lagrange_chart
        chart.argtypes, chart.restype = [_VOID, _DBL], ctypes.c_int
        chart(_ptr(self.base), float(self.formulation.chart_limit))
        if self.gaps is not None:  # (configuring clears the contact watch)
            self.lib.lagrange_watch(len(self.gaps), _ptr(self.held), _ptr(self.gaps), self.gap_tolerance,
                                    _ptr(self.event))

    def check_motors(self) -> None:
        """After a failed C evaluation: when a motor's prescribed position (or a derivative)
        was not finite, raise the ``SimulationError`` Python stepping raises there."""
        t = float(self.info[1])
        if t != t or self.programs is None:
            return
        raise_pending()  # (a callable motor's own error, kept by the motor callback)
        self.formulation.constraints.explain_position_failure(np.flatnonzero(self.programs[0] >= 0), t)

    def failure_hint(self, status: int) -> str | None:
        """What to add to a step-size failure: near a singular position of the constraints (the
        dependent block ill-conditioned at the last accepted state) the dependent solve
        amplifies rounding, and dae passes such positions."""
        from mbcomp.codegen.integrators import STEP_TOO_SMALL, COLLAPSED
        if status not in (STEP_TOO_SMALL, COLLAPSED) or not len(self.workspace.dep):
            return None
        ws = self.workspace
        t, q, _ = self.accepted()
        cv = self.formulation.constraint_values(self.kernel, t, q, np.zeros(self.n), ws.offsets, self.contacts)
        condition = ws.condition(cv.J, ws.rows, ws.dep)
        if condition < 10 * self.formulation.repartition_condition:
            return None
        return (f"the dependent coordinates are nearly singular there (condition {condition:.3g}: a singular "
                f"position of the constraints {self.formulation.row_names(ws.rows)}); a looser tolerance steps "
                f"over it, and the dae formulation passes such positions in motion")

    def friction_failure(self) -> SimulationError | None:
        """The error of a friction solve that stopped the loop (Painleve), or None."""
        return None if self.friction is None else self.friction.failure()

    def close(self) -> None:
        if getattr(self, "friction", None) is not None:
            self.friction.close()
        if getattr(self, "collisions", None) is not None:
            self.collisions.close()
        self.lib.lagrange_configure(-1, None, None, None, None, None, 0, None, None, 0, None, 0, None, None, 0, None,
                                    0.0, 0.0, None, None)
        self.lib.lagrange_drives(0)

    def __enter__(self) -> "ReducedRun":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- the state ---------------------------------------------------------------------------------
    @property
    def ni(self) -> int:
        """Degrees of freedom in the current partition: the independent speeds (the reduced
        state has as many independent coordinates besides, more where velocity rows remove
        speeds only).  Where the speeds are all dependent but coordinates are not (velocity
        rows), the count of those coordinates: 0 means nothing to integrate."""
        ws = self.workspace
        return len(ws.ind) or len(ws.qind)

    @property
    def y0(self) -> np.ndarray:
        return np.ascontiguousarray(self.workspace.y0, dtype=float)

    def accepted(self) -> tuple[float, np.ndarray, np.ndarray]:
        """``(t, q, qd)`` of the last accepted state (as the C loop left it)."""
        n, nq = self.n, self.nq
        return float(self.acc[0]), self.acc[1:1 + nq].copy(), self.acc[1 + nq:1 + nq + n].copy()

    def drive_states(self, z: np.ndarray) -> None:
        """The drive states of the accepted state (at the start: the run's ``z0``); the loop
        writes them after every accepted step."""
        self.acc[1 + self.nq + self.n:] = z

    def accepted_states(self) -> np.ndarray:
        """The drive states of the last accepted state (empty without drive elements)."""
        return self.acc[1 + self.nq + self.n:].copy()

    def sync(self) -> None:
        """The Python workspace's accepted state becomes the loop's."""
        ws = self.workspace
        ws.t_accepted, ws.q_accepted, ws.qd_accepted = self.accepted()

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """The reduced right-hand side at ``(t, y)`` from the C code."""
        fn = self.lib.lagrange_rhs
        fn.argtypes = [_DBL, _VOID, _VOID, _VOID, _VOID]
        fn.restype = ctypes.c_int
        f = np.empty_like(y)
        status = fn(float(t), _ptr(y), _ptr(f), _ptr(self.kernel.p), None if self.tau is None else _ptr(self.tau))
        if status:
            self.check_motors()
            raise SimulationError(f"no dependent coordinates at t = {t:.6g} s (the constraints "
                                  f"{self.formulation.row_names(self.rows)} cannot be solved there)")
        return f

    # -- between compiled stretches --------------------------------------------------------------------
    def resume(self, status: int, state: np.ndarray, y: np.ndarray, f: np.ndarray, counts: np.ndarray):
        """Act on a ``PAUSED`` or ``TRIAL_FAILED`` return; the ``(y, f)`` to continue with
        (``state`` is updated in place: a restart sets a new first step)."""
        ws = self.workspace
        self.sync()
        z = self.accepted_states()
        if status == PAUSED:
            t, q, qd = self.accepted()
            chart = ws.chart
            if chart.largest_rotation(chart.to_x(q)) > self.formulation.chart_limit:  # re-centre the rotations' chart (as after_step)
                ws.chart = Chart(ws.state_map, q)
                y_new = np.concatenate((ws.chart.to_x(q)[ws.qind], qd[ws.ind]))
            else:
                y_new = ws.repartition(t, q, qd)
            if y_new is None:
                return y, f  # no clearly better choice: carry on with the same step size
            self._configure()
            self.restarts += 1
            y = np.ascontiguousarray(np.concatenate((y_new, z)), dtype=float)
            state[:] = (t, 0.0)  # a new start, as a new scipy solver would make
            return y, np.empty_like(y)
        if status != TRIAL_FAILED:
            raise SimulationError(f"compiled lagrange loop: unexpected status {status}")
        self.check_motors()
        if state[0] > self.t_retry:
            self.retries = 0
        self.retries += 1
        if self.retries > MAX_RETRIES:
            raise SimulationError(f"dependent coordinates cannot be found near t = {state[0]:.6g} s: constraints "
                                  f"{self.formulation.row_names(self.rows)}")
        h = state[1] if state[1] > 0 else 1e-3
        t_back, y_back = ws.retreat()
        self.t_retry = t_back
        self._configure()
        self.restarts += 1
        y = np.ascontiguousarray(np.concatenate((y_back, z)), dtype=float)
        f = self.rhs(t_back, y)
        counts[0] += 1
        state[:] = (t_back, max(h / 4, 1e-12))
        return y, f

    def prescribed(self, t_end: float, t_eval, max_step: float):
        """No degree of freedom: ``(times, rows of [q, qd], counts)`` at the output times
        (``t_eval``, or as Python stepping chooses them), computed in C."""
        if t_eval is None:
            count = int(np.ceil(t_end / min(max_step, t_end / 200.0)))
            t_eval = np.linspace(0.0, t_end, count + 1)
        times = np.ascontiguousarray(t_eval, dtype=float)
        out = np.empty((len(times), self.nq + self.n))
        done = np.zeros(1, dtype=np.int64)
        fn = self.lib.lagrange_prescribed
        fn.argtypes = [_VOID, _LONG, _VOID, _VOID, _VOID]
        fn.restype = ctypes.c_int
        if fn(_ptr(self.kernel.p), len(times), _ptr(times), _ptr(out), _ptr(done)):
            self.check_motors()
            t = times[int(done[0])]
            raise SimulationError(f"the prescribed motion cannot be followed at t = {t:.6g} s: constraints "
                                  f"{self.formulation.row_names(self.rows)} have no solution near the last one")
        return times, out, {"nfev": 0, "steps": max(len(times) - 1, 0), "rejected": 0, "method": "prescribed"}


class _Locator(EventStepFunctions):
    """``gap(s, i)`` and ``force(s, k)`` on the event step of a ``ReducedRun`` (its dense
    output, the dependent coordinates by Newton from the step's start), computed in C."""

    def __init__(self, run: ReducedRun, t_old: float, y_old: np.ndarray):
        super().__init__(run, t_old, y_old, "lagrange")
        self.nm = 0 if run.formulation.constraints is None else run.formulation.constraints.nc

    def _checked(self, value: float, s: float, what: str) -> float:
        if value != value:
            self.run.check_motors()
            raise SimulationError(f"the {what} cannot be evaluated at t = {s:.6g} s (no dependent coordinates "
                                  f"near the step's start)")
        return value

    def gap(self, s: float, i: int) -> float:
        return self._checked(self._gap(float(s), *self.args, int(i), self.p), s, "gap")

    def force_row(self, k: int) -> int:
        """The row of the k-th held contact (after the model's own constraint rows)."""
        return self.nm + int(k)

    def root_failure(self, what: str, a: float, b: float) -> SimulationError:
        self.run.check_motors()
        return SimulationError(f"the {what} cannot be evaluated on [{a:.9g}, {b:.9g}] s (no dependent coordinates "
                               f"near the step's start)")

    def force(self, s: float, k: int) -> float:
        value = self._force(float(s), *self.args, self.force_row(k), self.p, self.tau)
        return self._checked(value, s, "contact force")
