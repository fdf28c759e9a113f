"""The one simulate driver: check the options, choose the stepping, one loop over accepted
steps (events and output), one stats builder.

``simulate`` turns its arguments into a ``RunOptions`` (``core/run_options.py``), asks
``run/paths.py`` which stepping to take (the loop compiled with the model, or scipy's stepping
of the compiled right-hand side: ``System.integration_path`` reports the same choice), and
runs ``run_steps``: one loop in which a stepping (``run/stepping.py``) hands over accepted steps
that need Python (an event in them, samples inside them, a projection after them) until t_end.
``Result.stats`` comes from ``run/stats.py`` on every path.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from mbcomp.codegen.integrators import RankLost
from mbcomp.core import checks
from mbcomp.core.errors import ModelError, SimulationError
from mbcomp.core.progress import ProgressBar
from mbcomp.core.result import Result
from mbcomp.core.run_options import RunOptions
from mbcomp.formulations.impact import GAP_TOLERANCE
from mbcomp.run.events import ContactWatch
from mbcomp.run.paths import IntegrationPath, choose_path
from mbcomp.run.stats import PRESCRIBED, Counts, run_stats
from mbcomp.run.stepping import CompiledStepping, ScipyStepping, Stepping


#: Processor seconds between progress updates from a compiled loop.
PROGRESS_INTERVAL = 0.1


class _Rows:
    """Rows of ``width`` values appended one by one or in blocks into one growing float array
    (8 bytes a value, not a Python array object per row); ``np.array(rows)`` gives the rows."""

    def __init__(self, width: int | None = None):
        self.data: np.ndarray | None = None if width is None else np.empty((64, width))
        self.n = 0

    def _room(self, width: int, more: int) -> None:
        if self.data is None:
            self.data = np.empty((max(64, more), width))
        elif self.n + more > len(self.data):
            grown = np.empty((max(2 * len(self.data), self.n + more), self.data.shape[1]))
            grown[:self.n] = self.data[:self.n]
            self.data = grown

    def append(self, row: Any) -> None:
        row = np.asarray(row, dtype=float).reshape(-1)
        self._room(row.size, 1)
        self.data[self.n] = row
        self.n += 1

    def extend(self, block: np.ndarray) -> None:
        block = np.asarray(block, dtype=float)
        self._room(block.shape[1], len(block))
        self.data[self.n:self.n + len(block)] = block
        self.n += len(block)

    def __len__(self) -> int:
        return self.n

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        rows = np.zeros((0, 0)) if self.data is None else self.data[:self.n]
        return rows.astype(dtype) if dtype is not None else rows.copy()


class _Recorder:
    """Collects output samples: every step, or the requested ``t_eval`` times.  ``nq``, ``nv``,
    ``nz``: the columns of q, qd and the drive states; ``closed`` gives the contacts held at a
    sample (None: no contacts watched), ``states`` the drive states at a sample."""

    def __init__(self, t_eval, nq: int, nv: int, nz: int, closed=None, states=lambda: (), budget=None):
        self.t_eval = t_eval
        self.budget = budget if t_eval is None else None  # (StepBudget: every step kept)
        self.closed_now = closed
        self.states_now = states  # drive-element states at the sample (set by full_state)
        self.nq, self.nv = nq, nv
        self.closed: list[tuple] = []  # persistent contacts at each sample
        self.next = 0
        self.t = _Rows(1)
        self.q, self.qd, self.z = _Rows(nq), _Rows(nv), _Rows(nz)

    def add(self, t, q, qd):
        if self.budget is not None and len(self.t) >= self.budget.rows:
            raise self.budget.exceeded(float(t))
        if self.closed_now is not None:
            closed = self.closed_now()
            self.closed.append(closed if isinstance(closed, tuple) else tuple(closed))  # (a Closed keeps its friction modes)
        self.z.append(self.states_now())
        self.t.append(float(t))
        self.q.append(q)
        self.qd.append(qd)

    def extend(self, times: np.ndarray, rows: np.ndarray) -> None:
        """Samples a compiled loop wrote: rows of ``[q, qd, z]`` (z may be absent)."""
        if not len(times):
            return
        if self.budget is not None and len(self.t) + len(times) > self.budget.rows:
            raise self.budget.exceeded(float(times[self.budget.rows - len(self.t)]))
        if self.closed_now is not None:
            closed = self.closed_now()
            self.closed.extend([closed if isinstance(closed, tuple) else tuple(closed)] * len(times))  # (modes kept)
        nq, nv = self.nq, self.nv
        self.t.extend(np.asarray(times, dtype=float)[:, None])
        self.q.extend(rows[:, :nq])
        self.qd.extend(rows[:, nq:nq + nv])
        self.z.extend(rows[:, nq + nv:] if rows.shape[1] > nq + nv else np.zeros((len(times), self.z.data.shape[1])))

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(t, q, qd, z)`` of the samples."""
        return np.array(self.t).reshape(-1), np.array(self.q), np.array(self.qd), np.array(self.z)

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
        try:
            while self.next < len(self.t_eval) and self.t_eval[self.next] < t_new:
                ts = self.t_eval[self.next]
                if dense is None:
                    workspace.span(t_new, solver.y)  # (lagrange: Newton's predictor spans the step)
                    dense = solver.dense_output()
                self.add(ts, *workspace.full_state(ts, dense(ts)))
                self.next += 1
        finally:
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
             dt: float | None = None, z0: np.ndarray | None = None, max_samples: int | None = None,
             contact_mode: str = "events") -> Result:
    """Integrate from ``(q0, qd0)`` (checked arrays of nq coordinates and nv speeds; ``z0`` the
    drive elements' states) at t = 0 to ``t_end`` with ``formulation`` on ``kernel``; see
    ``System.simulate``.  The Result carries no System (the caller binds one).  With
    ``t_eval=None`` at most ``max_samples`` steps are kept (``checks.StepBudget``)."""
    options = RunOptions.checked(t_end, method=method, rtol=rtol, atol=atol, t_eval=t_eval, max_step=max_step,
                                 rest_speed=rest_speed, integrator=integrator, dt=dt, progress=progress,
                                 max_samples=max_samples, contact_mode=contact_mode)
    return run(kernel, formulation, options, q0, qd0, tau=tau, z0=z0)


def run(kernel, formulation, options: RunOptions, q0: np.ndarray, qd0: np.ndarray, *, tau: Any = None,
        z0: np.ndarray | None = None) -> Result:
    """The driver: checks what the options and inputs ask for, chooses the stepping
    (``paths.choose_path``) and runs ``run_steps`` with it.  The compiled dae solve passes
    singular positions itself (least-norm multipliers); one that meets a dead point at rest,
    where the motion is not determined (``RankLost``), is run again in Python stepping, whose
    solve raises the error naming the constraints, unless the options insist on compiled code.  ``contact_mode="timestepping"``
    runs ``timestepping.simulate_timestepping`` instead."""
    if options.contact_mode == "timestepping":
        from mbcomp.run.timestepping import simulate_timestepping
        return simulate_timestepping(kernel, formulation, options, q0, qd0, tau=tau, z0=z0)
    z0 = np.zeros(kernel.compiled.drives.nz) if z0 is None else z0
    columns = len(q0) + len(qd0) + len(z0)
    budget = checks.StepBudget(options.max_samples, columns + 1, options.t_end)  # (a row: t and the state)
    if options.t_eval is not None:
        checks.output_size(len(options.t_eval), columns + 1, f"t_eval of {len(options.t_eval)} times",
                           fix="use fewer output times")
    if tau is not None and not callable(tau):
        kernel.tau(tau, 0.0, q0, qd0)
    dt, t_end = options.dt, options.t_end
    if dt is not None:  # fixed steps: every step is stored
        checks.output_size(t_end / dt + 1, len(q0) + len(qd0), f"dt = {dt:g} s over t_end = {t_end:g} s")
        if options.t_eval is None:
            budget.check_rows(t_end / dt + 1, f"dt = {dt:g} s over t_end = {t_end:g} s")
    path = choose_path(kernel, formulation, options, tau)
    if options.method == "RK4" and not path.compiled:
        raise ModelError("simulate", f"method 'RK4' runs only in compiled code, which cannot be used here: "
                                     f"{path.reason}")
    if path.compiled:
        try:
            return run_steps(CompiledStepping(kernel, formulation, options, tau, z0, Counts(), budget), kernel,
                         formulation, options, q0, qd0, path, budget)
        except RankLost:
            if options.method == "RK4" or options.integrator == "compiled":
                raise SimulationError(f"compiled {options.method} met a singular position of the constraints at "
                                      f"rest (a dead point: the motion is not determined); integrator='scipy' "
                                      f"names the constraints involved") from None
            path = IntegrationPath("scipy", "the compiled loop met a singular position of the constraints")
    elif options.integrator == "compiled":
        raise ModelError("simulate", f"integrator='compiled' is not possible: {path.reason}")
    try:
        return run_steps(ScipyStepping(kernel, formulation, options, tau, z0, Counts()), kernel, formulation,
                         options, q0, qd0, path, budget)
    except RankLost:  # (the compiled right-hand side met a singular position: the Python solve handles it)
        return run_steps(ScipyStepping(kernel, formulation, options, tau, z0, Counts(), compiled_rhs=False), kernel,
                         formulation, options, q0, qd0, path, budget)


def run_steps(stepping: Stepping, kernel, formulation, options: RunOptions, q0: np.ndarray, qd0: np.ndarray,
          path: IntegrationPath, budget=None) -> Result:
    """The one loop over accepted steps.  ``stepping`` (``run/stepping.py``) advances the run
    and returns each step that needs Python, or None at t_end; the driver samples it,
    locates and applies contact events in it (``ContactWatch``), applies the workspace's
    correction after it, and restarts the stepping where an event or a correction asks."""
    t_end = options.t_end
    offsets = formulation.motor_offsets(q0, 0.0)
    q0, qd0 = formulation.assemble(kernel, q0, qd0, 0.0, offsets)
    watch = ContactWatch(kernel, formulation, options.rest_speed, offsets, stepping.applied) \
        if kernel.topology.contacts else None
    if watch is not None:
        qd0 = watch.start(q0, qd0)
    else:
        # (without contacts, the speed motors' start values are read off the assembled state)
        offsets = formulation.motor_offsets(q0, 0.0) if stepping.records_start else offsets
    recorder = _Recorder(options.t_eval, kernel.nq, kernel.nv, stepping.state_columns,
                         (lambda: watch.persistent) if watch else None, stepping.states, budget)
    if not stepping.records_start and (options.t_eval is None or (len(options.t_eval) and options.t_eval[0] == 0.0)):
        recorder.add(0.0, q0, qd0)  # (before the stepping starts: a solver's first evaluations move drive states)
        recorder.next = 1 if options.t_eval is not None else 0
    started = time.perf_counter()
    stepping.begin(0.0, q0, qd0, offsets, watch.persistent if watch else (), watch is not None)
    if stepping.nothing_to_integrate and watch is None:
        return _prescribed_motion(kernel, formulation, options, stepping, q0, qd0, offsets, started, path, budget)
    gaps = watch.gaps(q0, qd0).g if watch else None
    bar = ProgressBar(t_end, bool(options.progress), desc="simulating", unit="s", delay=options.progress_delay)
    try:
        with stepping.running(bar, PROGRESS_INTERVAL):
            while True:
                step = stepping.advance(recorder, gaps)
                if step is None:
                    break
                t, restart, corrected = step.t, None, None
                if watch is not None:
                    watch.locator = step.locator  # (a compiled loop's gaps and forces on its event step, in C)
                    try:
                        t, restart, corrected, gaps = _contact_step(watch, step.workspace, step, recorder,
                                                                    gaps if step.gaps is None else step.gaps)
                    finally:
                        watch.locator = None
                else:
                    # Samples inside the step come from its dense output, in the coordinates it was
                    # taken in; the end sample comes after the correction (projection, new partition).
                    recorder.record_interior(step.workspace, step, t)
                    corrected = step.workspace.after_step(t, step.y)
                    recorder.record_end(step.workspace, t, step.y if corrected is None else corrected)
                stepping.accepted(t, step)
                if restart is None and step.finished:
                    break
                if restart is None:
                    stepping.go_on(t, corrected, step)
                    continue
                stepping.stop()
                t_restart, q_r, qd_r = restart
                if t_restart >= t_end:
                    break
                stepping.restart_at(t_restart, q_r, qd_r, watch.persistent)
        bar.update_to(t_end)
    except SimulationError as exc:
        if not stepping.error_prefix:
            raise
        raise SimulationError(f"{stepping.error_prefix}{exc}") from None
    finally:
        bar.close()
    stepping.finish_counts()
    wall = time.perf_counter() - started
    t, q, qd, z = recorder.arrays()
    if not stepping.finite_checked and not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        raise SimulationError("solver returned non-finite states")
    stats = run_stats(options, formulation.name, stepping.counts, wall, integrator=stepping.integrator,
                      method=stepping.method, path=str(path), rhs=stepping.rhs)
    return _result(kernel, formulation, t=t, q=q, qd=qd, z=z, stats=stats, tau=stepping.result_tau, offsets=offsets,
                   events=watch.events if watch else [],
                   persistent_contacts=[watch.names[i] for i in watch.persistent] if watch else [],
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
        qd = watch.open(release[1], te, q, qd)  # (a stick removes the slip left: new speeds)
        watch.release(te, q, qd)
    recorder.add_event_state(te, q, qd)
    return te, (te, q, qd), None, watch.gaps(q, qd).g


def _prescribed_motion(kernel, formulation, options: RunOptions, stepping, q0, qd0, offsets, started,
                       path: IntegrationPath, budget=None) -> Result:
    """No degree of freedom left (every coordinate driven or dependent): nothing to
    integrate; the motion follows from the constraints at each output time (Newton,
    continued from the previous time)."""
    t_eval = options.t_eval
    if t_eval is None:
        t_eval = checks.prescribed_times(options.t_end, options.max_step, budget)
    workspace = stepping.workspace
    qs, qds = [], []
    for t in t_eval:
        q, qd = workspace.full_state(t, np.zeros(0))
        workspace.after_step(t, np.zeros(0))
        qs.append(q)
        qds.append(qd)
    stats = run_stats(options, formulation.name, Counts(steps=len(t_eval) - 1), time.perf_counter() - started,
                      integrator="none", method="prescribed", path=str(path), message=PRESCRIBED)
    return _result(kernel, formulation, t=np.asarray(t_eval, dtype=float), q=np.array(qs), qd=np.array(qds), stats=stats,
                   tau=stepping.result_tau, offsets=offsets)


def _result(kernel, formulation, **data) -> Result:
    """A Result recording what the run used (names, parameter values, formulation)."""
    topology = kernel.topology
    return Result(system=None, coords=tuple(topology.coords), speeds=tuple(topology.speeds),
                  parameters=dict(kernel.parameters), formulation=formulation.name,
                  extra_states=tuple(kernel.compiled.drives.states), **data)
