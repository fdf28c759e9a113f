"""Solver backend: step scipy's integrators, with restarts for projections and partitions."""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from mbcomp.core import checks
from mbcomp.core.errors import ModelError, SimulationError, TrialStateError
from mbcomp.run.events import ContactWatch
from mbcomp.compiled.collision_kernel import with_collisions
from mbcomp.formulations.impact import GAP_TOLERANCE
from mbcomp.run.drive_runtime import DriveTorque, DriveWorkspace
from mbcomp.codegen.integrators import (EVENT, FINISHED, CollapseWatch, RankLost, bind_dop853, bind_reduced, collapse_message, compiled_jacobian,
                          dop853_segment, hooked, poll_step_hooks, run_compiled, step_hook, why_not_compiled)
from mbcomp.core.progress import ProgressBar

#: scipy methods that use a Jacobian: given one computed in compiled code when possible.
IMPLICIT_METHODS = ("Radau", "BDF", "LSODA")
from mbcomp.core.result import Result


#: Processor seconds between progress updates from a compiled loop.
PROGRESS_INTERVAL = 0.1


def _delay(progress: Any) -> float:
    """``progress=True`` shows the bar at once; a number (s) shows it once the run has taken
    that long (the command line's choice, so short runs stay quiet)."""
    if isinstance(progress, bool) or not isinstance(progress, (int, float)):
        return 0.0
    return max(float(progress), 0.0)


def solver_class(method: Any) -> type:
    """scipy's ``OdeSolver`` for a name (``"RK45"``, ``"DOP853"``, ``"Radau"``, ``"BDF"``,
    ``"LSODA"``, ``"RK23"``) or a subclass passed directly.  (scipy.integrate is imported
    here, for scipy's stepping only: runs in compiled code never need it.)"""
    from scipy.integrate import OdeSolver
    from scipy.integrate._ivp.ivp import METHODS
    if isinstance(method, type) and issubclass(method, OdeSolver):
        return method
    if isinstance(method, str) and method in METHODS:
        return METHODS[method]
    raise ModelError("simulate", f"method must be one of {sorted(METHODS)} or an OdeSolver subclass, got {method!r}")


def check_settings(t_end, rtol, atol, t_eval, max_step=np.inf, dt=None, rest_speed=1e-4):
    """The numeric settings of a run, checked (``ModelError`` naming the argument)."""
    t_end = checks.number(t_end, "t_end", positive=True)
    rtol = checks.number(rtol, "rtol", positive=True)
    atol = checks.number(atol, "atol", positive=True)
    checks.number(max_step, "max_step", positive=True, finite=False)
    checks.number(rest_speed, "rest_speed", nonnegative=True)
    if dt is not None:
        dt = checks.number(dt, "dt", positive=True)
    if t_eval is not None:
        t_eval = checks.time_grid(t_eval, t_end)
    return t_end, t_eval


class _Rows:
    """Rows of equal length appended one by one into one growing float array (8 bytes a
    value, not a Python array object per row); ``np.array(rows)`` gives the rows."""

    def __init__(self):
        self.data: np.ndarray | None = None
        self.n = 0

    def append(self, row: Any) -> None:
        row = np.asarray(row, dtype=float).reshape(-1)
        if self.data is None:
            self.data = np.empty((64, row.size))
        elif self.n == len(self.data):
            grown = np.empty((2 * len(self.data), self.data.shape[1]))
            grown[:self.n] = self.data
            self.data = grown
        self.data[self.n] = row
        self.n += 1

    def __len__(self) -> int:
        return self.n

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        rows = np.zeros((0, 0)) if self.data is None else self.data[:self.n]
        return rows.astype(dtype) if dtype is not None else rows.copy()


class _Recorder:
    """Collects output samples: every step, or the requested ``t_eval`` times."""

    def __init__(self, t_eval, closed=lambda: (), states=lambda: (), budget=None):
        self.t_eval = t_eval
        self.budget = budget if t_eval is None else None  # (StepBudget: every step kept)
        self.closed_now = closed
        self.states_now = states  # drive-element states at the sample (set by full_state)
        self.z = _Rows()
        self.closed: list[tuple] = []  # persistent contacts at each sample
        self.next = 0
        self.t: list[float] = []
        self.q = _Rows()
        self.qd = _Rows()

    def add(self, t, q, qd):
        if self.budget is not None and len(self.t) >= self.budget.rows:
            raise self.budget.exceeded(float(t))
        closed = self.closed_now()
        self.closed.append(closed if isinstance(closed, tuple) else tuple(closed))  # (a Closed keeps its friction modes)
        self.z.append(self.states_now())
        self.t.append(float(t))
        self.q.append(q)
        self.qd.append(qd)

    def record_until(self, workspace, solver, dense, t_old, t_stop, q_stop, qd_stop):
        """Samples up to an event at ``t_stop`` (the state there is given)."""
        if self.t_eval is None:
            self.add(t_stop, q_stop, qd_stop)
            return
        while self.next < len(self.t_eval) and self.t_eval[self.next] < t_stop:
            ts = self.t_eval[self.next]
            self.add(ts, *workspace.full_state(ts, dense(ts)))
            self.next += 1

    def add_event_state(self, t, q, qd):
        """The state just after an impact (every-step output only)."""
        if self.t_eval is None:
            self.add(t, q, qd)
        elif self.next < len(self.t_eval) and self.t_eval[self.next] == t:
            self.add(t, q, qd)
            self.next += 1

    def record_interior(self, workspace, solver, t_new):
        """Requested samples strictly inside the step just taken (its dense output)."""
        if self.t_eval is None:
            return
        dense = None
        span = getattr(workspace, "span", None)  # (lagrange: Newton's predictor spans the step)
        try:
            while self.next < len(self.t_eval) and self.t_eval[self.next] < t_new:
                ts = self.t_eval[self.next]
                if dense is None:
                    if span is not None:
                        span(t_new, solver.y)
                    dense = solver.dense_output()
                self.add(ts, *workspace.full_state(ts, dense(ts)))
                self.next += 1
        finally:
            if span is not None:
                workspace.end_span()

    def record_end(self, workspace, t_new, y_end):
        """The state at the end of a step (after any projection), when it is a sample."""
        if self.t_eval is None or (self.next < len(self.t_eval) and self.t_eval[self.next] == t_new):
            self.add(t_new, *workspace.full_state(t_new, y_end))
            if self.t_eval is not None:
                self.next += 1


def simulate(kernel, formulation, t_end: float, q0: np.ndarray, qd0: np.ndarray, *, method: Any = "DOP853", rtol: float = 1e-8,
             atol: float = 1e-10, t_eval: Any = None, tau: Any = None, progress: bool = False,
             max_step: float = np.inf, rest_speed: float = 1e-4, integrator: str = "auto",
             dt: float | None = None, z0: np.ndarray | None = None, max_samples: int | None = None) -> Result:
    """Integrate from ``(q0, qd0)`` (checked arrays of nq coordinates and nv speeds; ``z0`` the
    drive elements' states) at t = 0 to ``t_end`` with ``formulation`` on ``kernel``; see
    ``System.simulate``.  The Result carries no System (the caller binds one).  With
    ``t_eval=None`` at most ``max_samples`` steps are kept (``checks.StepBudget``)."""
    t_end, t_eval = check_settings(t_end, rtol, atol, t_eval, max_step, dt, rest_speed)
    kernel = with_collisions(kernel)  # collision features join the contacts (stepped in Python)
    z0 = np.zeros(kernel.compiled.drives.nz) if z0 is None else z0
    columns = len(q0) + len(qd0) + len(z0)
    budget = checks.StepBudget(max_samples, columns + 1, t_end)  # (a row: t and the state)
    if t_eval is not None:
        checks.output_size(len(t_eval), columns + 1, f"t_eval of {len(t_eval)} times", fix="use fewer output times")
    if tau is not None and not callable(tau):
        kernel.tau(tau, 0.0, q0, qd0)
    if integrator not in ("auto", "compiled", "scipy"):
        raise ModelError("simulate", f"integrator must be 'auto', 'compiled' or 'scipy', got {integrator!r}")
    if dt is not None:  # fixed steps: every step is stored
        checks.output_size(t_end / dt + 1, len(q0) + len(qd0), f"dt = {dt:g} s over t_end = {t_end:g} s")
        if t_eval is None:
            budget.check_rows(t_end / dt + 1, f"dt = {dt:g} s over t_end = {t_end:g} s")
    reason = why_not_compiled(kernel, formulation, method, tau) if integrator != "scipy" else "integrator='scipy'"
    if method == "RK4" and reason is not None:
        raise ModelError("simulate", f"method 'RK4' runs only in compiled code, which cannot be used here: {reason}")
    compiled = None
    if reason is None:
        # (speed motors hold their coordinate at its start value, as in Python stepping)
        start_offsets = formulation.motor_offsets(q0, 0.0)
        q_start, qd_start = formulation.assemble(kernel, q0, qd0, 0.0, start_offsets)

        def run():
            if kernel.topology.contacts:  # compiled stretches between contact events
                return _compiled_contacts(kernel, formulation, t_end, q0, qd0, rtol=rtol, atol=atol, t_eval=t_eval,
                                          tau=tau, max_step=max_step, rest_speed=rest_speed, budget=budget)
            return run_compiled(kernel, formulation, t_end, q_start, qd_start, method=method, rtol=rtol,
                                atol=atol, t_eval=t_eval, tau=tau, max_step=max_step, dt=dt, z0=z0, budget=budget)
        try:
            if progress:
                # The compiled loop's step hook reports the time reached; the bar only reads it
                # (the callback never asks to stop), so the run and its result are unchanged.
                bar = ProgressBar(t_end, desc="simulating", unit="s", delay=_delay(progress))
                try:
                    with step_hook(lambda t: bar.update_to(t) and False, interval=PROGRESS_INTERVAL):
                        compiled = run()
                    bar.update_to(t_end)
                finally:
                    bar.close()
            else:
                compiled = run()
        except RankLost:
            if method == "RK4" or integrator == "compiled":
                raise SimulationError(f"compiled {method} met a singular position of the constraints; "
                                      f"use integrator='scipy', which handles it") from None
    if isinstance(compiled, Result):
        return compiled
    if compiled is not None:
        times, values, counts, wall = compiled
        n = kernel.nq
        stats = {"method": method, "integrator": "compiled", "restarts": 0, **counts, "njev": 0, "nlu": 0,
                 "status": 0, "message": "The solver successfully reached the end of the integration interval.",
                 "success": True, "wall_time": wall, "rtol": rtol, "atol": atol, "formulation": formulation.name}
        nv = kernel.nv
        return _result(kernel, formulation, t=np.asarray(times, dtype=float), q=values[:, :n].copy(),
                       qd=values[:, n:n + nv].copy(), z=values[:, n + nv:].copy(), stats=stats, tau=tau,
                       offsets=formulation.motor_offsets(q_start, 0.0))
    if integrator == "compiled" and reason is not None:
        raise ModelError("simulate", f"integrator='compiled' is not possible: {reason}")
    cls = solver_class(method)
    drive = None
    if kernel.compiled.drives.elements:  # drive elements: their forces join tau, their states y
        drive = tau = DriveTorque(kernel, tau if tau is None or callable(tau) else np.asarray(tau, dtype=float), z0)
    offsets = formulation.motor_offsets(q0, 0.0)
    q0, qd0 = formulation.assemble(kernel, q0, qd0, 0.0, offsets)
    watch = ContactWatch(kernel, formulation, rest_speed, offsets, tau) if kernel.topology.contacts else None
    if watch is not None:
        qd0 = watch.start(q0, qd0)
    workspace = formulation.start(kernel, 0.0, q0, qd0, tau, watch.persistent if watch else ())
    if drive is not None:
        workspace = DriveWorkspace(workspace, drive)
    if watch is not None and workspace.y0.size == 0:
        max_step = min(max_step, t_end / 500)  # nothing to integrate: step time to watch the contacts
    bar = ProgressBar(t_end, bool(progress), desc="simulating", unit="s", delay=_delay(progress))
    recorder = _Recorder(t_eval, (lambda: watch.persistent) if watch else (lambda: ()),
                         (lambda: drive.z) if drive is not None else (lambda: ()), budget)
    counts = {"nfev": 0, "njev": 0, "nlu": 0, "steps": 0, "restarts": 0}

    def fun(t, y):
        total = float(y.sum())
        if total - total != 0.0:  # a NaN or inf entry
            raise SimulationError(f"state became non-finite at t = {t:.6g} s")
        return workspace.rhs(t, y)

    options = {}
    if (getattr(cls, "__name__", "") in IMPLICIT_METHODS and formulation.constraints is None
            and why_not_compiled(kernel, formulation, "DOP853", tau) is None):
        options["jac"] = compiled_jacobian(kernel, None if tau is None else kernel.tau(tau, 0.0, q0, qd0))

    limit = getattr(kernel, "step_limit", None)  # collisions: a step may not carry a shape through another

    def capped(t, y):
        return max_step if limit is None else min(max_step, limit(*workspace.full_state(t, y)))

    def make_solver(t0, y0, first_step=None):
        cap = capped(t0, y0)
        first_step = first_step if first_step is None else min(first_step, cap)
        return cls(fun, t0, y0, t_end, rtol=rtol, atol=atol, max_step=cap, first_step=first_step, **options)

    def add_counts(solver):
        for key in ("nfev", "njev", "nlu"):
            counts[key] += getattr(solver, key, 0)

    started = time.perf_counter()
    if workspace.y0.size == 0 and watch is None:
        return _prescribed_motion(kernel, formulation, workspace, t_end, t_eval, max_step, q0, qd0, tau, offsets, started,
                                  budget)
    if t_eval is None or (len(t_eval) and t_eval[0] == 0.0):
        recorder.add(0.0, q0, qd0)
        recorder.next = 1 if t_eval is not None else 0
    gaps_old = watch.gaps(q0, qd0).g if watch else None
    collapse = CollapseWatch(0.0, t_end)
    try:
        solver = make_solver(0.0, workspace.y0)
        retries = 0
        while True:
            try:
                message = solver.step()
            except TrialStateError:
                # Like a rejected step: back to the last accepted state, a quarter of the step.
                retries += 1
                if retries > 10:
                    raise
                add_counts(solver)
                counts["restarts"] += 1
                h = getattr(solver, "h_abs", None) or (t_end / 100)
                t_back, y_back = workspace.retreat()
                solver = make_solver(t_back, y_back, first_step=max(h / 4, 1e-12))
                continue
            retries = 0
            if solver.status == "failed":
                raise SimulationError(f"solver {getattr(cls, '__name__', method)} gave up at t = {solver.t:.6g} s: {message}")
            workspace.normalize(solver.y)  # quaternions to unit length, in place
            counts["steps"] += 1
            t, restart = solver.t, None
            if watch is not None:
                t, restart, corrected, gaps_old = _contact_step(watch, workspace, solver, recorder, gaps_old)
                if limit is not None and restart is None:
                    solver.max_step = capped(t, solver.y if corrected is None else corrected)
            else:
                # Samples inside the step come from its dense output, in the coordinates it was
                # taken in; the end sample comes after the correction (projection, new partition).
                recorder.record_interior(workspace, solver, t)
                corrected = workspace.after_step(t, solver.y)
                recorder.record_end(workspace, t, solver.y if corrected is None else corrected)
            bar.update_to(t)
            poll_step_hooks(t)
            if collapse.collapsed(t):
                q_now, qd_now = workspace.full_state(t, solver.y)
                raise SimulationError(collapse.message(f"solver {getattr(cls, '__name__', method)}", t, qd_now,
                                                       kernel.topology.speeds))
            if restart is None and solver.status == "finished":
                break
            if restart is None:
                if corrected is not None:
                    add_counts(solver)
                    counts["restarts"] += 1
                    solver = make_solver(t, corrected)
                continue
            add_counts(solver)
            counts["restarts"] += 1
            t_restart, q_r, qd_r = restart
            if t_restart >= t_end:
                break
            workspace = formulation.start(kernel, t_restart, q_r, qd_r, tau, watch.persistent)
            if drive is not None:
                workspace = DriveWorkspace(workspace, drive)
            workspace.offsets = offsets
            solver = make_solver(t_restart, workspace.y0)
    except SimulationError as exc:
        raise SimulationError(f"simulation stopped: {exc}") from None
    finally:
        bar.close()
    add_counts(solver)
    wall = time.perf_counter() - started
    q = np.array(recorder.q).reshape(-1, kernel.nq)
    qd = np.array(recorder.qd).reshape(-1, kernel.nv)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        raise SimulationError("solver returned non-finite states")
    stats = {"method": getattr(cls, "__name__", str(method)), "integrator": "scipy", **counts, "status": 0,
             "message": "The solver successfully reached the end of the integration interval.",
             "success": True, "wall_time": wall, "rtol": rtol, "atol": atol, "formulation": formulation.name}
    events = watch.events if watch else []
    z = np.array(recorder.z).reshape(len(recorder.t), -1)
    return _result(kernel, formulation, t=np.array(recorder.t), q=q, qd=qd, z=z, stats=stats,
                   tau=tau if drive is None else drive.tau, offsets=offsets,
                  events=events, persistent_contacts=[watch.names[i] for i in watch.persistent] if watch else [],
                  closed_contacts=recorder.closed)


def _contact_step(watch, workspace, solver, recorder, gaps_old):
    """Finish an accepted step with contacts watched: locate the first closing or lift-off
    in it, record up to there and apply the event.  Returns ``(t, restart, corrected,
    gaps)``: the time reached, ``(t, q, qd)`` to restart from after an event (else None),
    a corrected end state (else None) and the gaps there."""
    t_old, t = solver.t_old, solver.t
    q, qd = workspace.full_state(t, solver.y)
    dense = solver.dense_output()
    t_close = watch.locate_closing(workspace, dense, t_old, t, gaps_old, watch.gaps(q, qd).g)
    release = watch.locate_release(workspace, dense, t_old, t, q, qd)
    t_release = None if release is None else release[0]
    te = min((x for x in (t_close, t_release) if x is not None), default=None)
    if te is None:
        recorder.record_interior(workspace, solver, t)
        corrected = workspace.after_step(t, solver.y)
        recorder.record_end(workspace, t, solver.y if corrected is None else corrected)
        return t, None, corrected, watch.gaps(q, qd).g
    y_event = dense(te) if te != t else solver.y
    q, qd = workspace.full_state(te, y_event)
    recorder.record_until(workspace, solver, dense, t_old, te, q, qd)
    workspace.full_state(te, y_event)  # samples moved the drive states: back to the event's
    if te == t_close:
        qd, changed = watch.impact(te, q, qd)
        if not changed:  # closed but not closing: it rests on its surface
            gaps = watch.gaps(q, qd).g
            closing = [i for i in range(len(watch.names)) if i not in watch.persistent and gaps[i] < GAP_TOLERANCE]
            watch.persistent = tuple(sorted(set(watch.persistent) | set(closing)))
        watch.settle(te, q, qd)  # friction modes of the contacts closed now
    else:
        watch.open(release[1], te, q, qd)
        watch.release(te, q, qd)
    recorder.add_event_state(te, q, qd)
    return te, (te, q, qd), None, watch.gaps(q, qd).g


class _EventStep:
    """The step a compiled loop stopped at because of a contact event: what ``_contact_step``
    reads of a solver (its span, end state and dense output)."""

    def __init__(self, t_old, t, y, dense):
        self.t_old, self.t, self.y, self._dense = t_old, t, y, dense

    def dense_output(self):
        return self._dense


def _compiled_contacts(kernel, formulation, t_end, q0, qd0, *, rtol, atol, t_eval, tau, max_step, rest_speed,
                       budget=None) -> Result:
    """Contacts with the compiled loop: the stretches between events run in C (the lagrange
    formulation's reduced loop, watching the contacts after every step); a step with an event
    comes back here, where ``ContactWatch`` locates and applies it exactly as in Python
    stepping (``_contact_step``), and the loop restarts after it."""
    from mbcomp.formulations.lagrange_compiled import ReducedRun
    lib = kernel.compiled.functions.lib
    Run = getattr(formulation, "contact_run", None) or ReducedRun  # the dae formulation steps [q, qd] itself
    run_loop = bind_reduced(lib) if Run is ReducedRun else bind_dop853(lib)
    n = kernel.nv
    offsets = formulation.motor_offsets(q0, 0.0)
    q0, qd0 = formulation.assemble(kernel, q0, qd0, 0.0, offsets)
    applied = tau  # (what the events see: the drive elements' forces join tau, as in Python stepping)
    if kernel.compiled.drives.elements:
        applied = DriveTorque(kernel, None if tau is None else np.asarray(tau, dtype=float), np.zeros(0))
    watch = ContactWatch(kernel, formulation, rest_speed, offsets, applied)
    qd0 = watch.start(q0, qd0)
    recorder = _Recorder(t_eval, lambda: watch.persistent, budget=budget)
    if t_eval is None or (len(t_eval) and t_eval[0] == 0.0):
        recorder.add(0.0, q0, qd0)
        recorder.next = 1 if t_eval is not None else 0
    tau_arr = None if tau is None else np.ascontiguousarray(kernel.tau(tau, 0.0, q0, qd0), dtype=float)
    tau_ptr = None if tau_arr is None else tau_arr.ctypes.data
    t_out = None if t_eval is None else np.ascontiguousarray(t_eval, dtype=float)
    y_out = None if t_eval is None else np.empty((len(t_out), 2 * n))
    counts, restarts = np.zeros(3, dtype=np.int64), 0
    t, q, qd, gaps = 0.0, q0, qd0, watch.gaps(q0, qd0).g
    started = time.perf_counter()
    with hooked(lib) as hook:
        while t < t_end:
            with Run(formulation, kernel, lib, q, qd, tau_arr, t0=t, contacts=watch.persistent,
                     offsets=offsets) as segment:
                if t == 0.0 and segment.ni == 0:
                    max_step = min(max_step, t_end / 500)  # nothing to integrate: step time to watch the contacts
                segment.watch_contacts(gaps, GAP_TOLERANCE)
                state, y = np.array([t, 0.0]), segment.y0
                i_out = np.array([recorder.next], dtype=np.int64)
                status, steps_t, steps_y, y, f = dop853_segment(kernel, run_loop, hook, segment, "DOP853", state, y,
                                                                np.empty_like(y), t_end, rtol, atol, max_step,
                                                                tau_ptr, counts, t_out, i_out, y_out,
                                                                budget=budget, stored=len(recorder.t))
                if t_out is not None:
                    for j in range(recorder.next, int(i_out[0])):
                        recorder.add(t_out[j], y_out[j, :n], y_out[j, n:])
                    recorder.next = int(i_out[0])
                for tj, row in zip(steps_t, steps_y):
                    recorder.add(tj, row[:n], row[n:])
                restarts += segment.restarts
                if status == FINISHED:
                    break
                segment.sync()  # the Python workspace at the step's start, where the loop stopped
                t_new, y_new, dense = segment.event_step(float(state[0]), y)
                watch.locator = segment.locator(float(state[0]), y)  # the root finder's gaps and forces in C
                try:
                    t, restart, corrected, gaps = _contact_step(watch, segment.workspace, _EventStep(
                        float(state[0]), t_new, y_new, dense), recorder, segment.gaps.copy())
                finally:
                    watch.locator = None
                restarts += 1
                if restart is None:  # (the loop's watch and Python's disagree: carry on from the step's end)
                    q, qd = segment.workspace.full_state(t, y_new if corrected is None else corrected)
                    continue
                t, q, qd = restart
    wall = time.perf_counter() - started
    q = np.array(recorder.q).reshape(-1, kernel.nq)
    qd = np.array(recorder.qd).reshape(-1, kernel.nv)
    stats = {"method": "DOP853", "integrator": "compiled", "nfev": int(counts[0]), "njev": 0, "nlu": 0,
             "steps": int(counts[1]), "rejected": int(counts[2]), "restarts": restarts, "status": 0,
             "message": "The solver successfully reached the end of the integration interval.", "success": True,
             "wall_time": wall, "rtol": rtol, "atol": atol, "formulation": formulation.name}
    return _result(kernel, formulation, t=np.array(recorder.t), q=q, qd=qd, z=np.zeros((len(recorder.t), 0)),
                   stats=stats, tau=tau, offsets=offsets, events=watch.events,
                   persistent_contacts=[watch.names[i] for i in watch.persistent], closed_contacts=recorder.closed)


def _prescribed_motion(kernel, formulation, workspace, t_end, t_eval, max_step, q0, qd0, tau, offsets, started,
                       budget=None) -> Result:
    """No degree of freedom left (every coordinate driven or dependent): nothing to
    integrate; the motion follows from the constraints at each output time (Newton,
    continued from the previous time)."""
    if t_eval is None:
        t_eval = checks.prescribed_times(t_end, max_step, budget)
    qs, qds = [], []
    for t in t_eval:
        q, qd = workspace.full_state(t, np.zeros(0))
        workspace.after_step(t, np.zeros(0))
        qs.append(q)
        qds.append(qd)
    stats = {"method": "prescribed", "integrator": "none", "nfev": 0, "njev": 0, "nlu": 0, "steps": len(t_eval) - 1,
             "restarts": 0, "status": 0, "message": "No degree of freedom: the motion follows from the constraints.",
             "success": True, "wall_time": time.perf_counter() - started, "formulation": formulation.name}
    return _result(kernel, formulation, t=np.asarray(t_eval, dtype=float), q=np.array(qs), qd=np.array(qds), stats=stats,
                  tau=tau, offsets=offsets)


def _result(kernel, formulation, **data) -> Result:
    """A Result recording what the run used (names, parameter values, formulation)."""
    topology = kernel.topology
    return Result(system=None, coords=tuple(topology.coords), speeds=tuple(topology.speeds),
                  parameters=dict(kernel.parameters), formulation=formulation.name,
                  extra_states=tuple(kernel.compiled.drives.states), **data)
