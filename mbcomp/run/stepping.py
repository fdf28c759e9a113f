"""The pluggable stepping of the simulate driver (``run/simulate.py``).

A stepping advances a run and hands the driver the accepted steps it must finish in Python:

- ``ScipyStepping``: scipy's ``OdeSolver`` (any ``solve_ivp`` method) on the formulation's
  workspace, whose right-hand side calls the compiled functions; every accepted step comes
  back to the driver (samples inside it, events, projections, new partitions).
- ``CompiledStepping``: the DOP853 or RK4 loop compiled with the model; it records its own
  output rows and comes back only at the end of the run or at a step in which a contact
  event happens (the formulation's ``contact_run`` watches the contacts in C).

Both implement ``begin``, ``advance``, ``go_on``, ``restart_at`` and ``finish_counts``; the
driver does not know which one it holds.  A formulation plugs into the compiled stepping
through its hooks (``Formulation.compiled_setup``, ``compiled_session``, ``contact_run``,
``explain_compiled_failure``), never through a class test.
"""
from __future__ import annotations

import contextlib
from typing import Any, Callable, Protocol

import numpy as np

from mbcomp.codegen.callbacks import input_hook
from mbcomp.codegen.integrators import (EVENT, FINISHED, CollapseWatch, compiled_jacobian, dop853_segment, hooked,
                                        poll_step_hooks, run_loops, step_hook)
from mbcomp.core.errors import ModelError, SimulationError, TrialStateError
from mbcomp.core.run_options import RunOptions
from mbcomp.formulations.impact import GAP_TOLERANCE
from mbcomp.run.drive_runtime import DriveTorque, DriveWorkspace
from mbcomp.run.paths import why_not_compiled
from mbcomp.run.stats import Counts

#: scipy methods that use a Jacobian: given one computed in compiled code when possible.
IMPLICIT_METHODS = ("Radau", "BDF", "LSODA")


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


class Step:
    """An accepted step the driver finishes in Python: from ``t_old`` to ``t`` (s), its end
    state ``y`` (the workspace's coordinates) and dense output; ``workspace`` the one it was
    taken in; ``finished``: it reached t_end.  A compiled loop's event step also carries the
    gaps at its start (``gaps``) and the C gap and force functions on it (``locator``)."""

    def __init__(self, t_old: float, t: float, y: np.ndarray, dense: Callable[[], Any], workspace, *,
                 finished: bool = False, gaps: np.ndarray | None = None, locator: Any = None):
        self.t_old, self.t, self.y, self._dense = t_old, t, y, dense
        self.workspace, self.finished, self.gaps, self.locator = workspace, finished, gaps, locator

    def dense_output(self):
        return self._dense()


class Stepping(Protocol):
    """What the driver (``simulate.run_steps``) asks of a stepping.

    ``integrator`` (the name ``Result.stats`` gives it), ``method``, ``counts`` (``Counts``),
    ``applied`` (the applied forces contact events see), ``records_start`` (its rows include
    the start sample), ``state_columns`` (drive states in a sample, ``states()`` their values),
    ``error_prefix``, ``result_tau``, ``nothing_to_integrate`` (after ``begin``), ``rhs``
    (``"compiled"`` or ``"python"``: ``Result.stats["rhs"]``)."""

    integrator: str
    rhs: str
    records_start: bool
    error_prefix: str
    finite_checked: bool

    def running(self, bar, interval: float):
        """A context manager around the run (the compiled loops' step hook)."""

    def begin(self, t0: float, q0: np.ndarray, qd0: np.ndarray, offsets: dict, contacts: tuple,
              watched: bool) -> None:
        """Start from the consistent ``(q0, qd0)`` at ``t0``."""

    def advance(self, recorder, gaps: np.ndarray | None) -> "Step | None":
        """The next accepted step that needs Python, or None at t_end (rows it wrote: into
        ``recorder``)."""

    def accepted(self, t: float, step: "Step") -> None:
        """After the driver finished ``step`` at ``t``."""

    def go_on(self, t: float, corrected: np.ndarray | None, step: "Step") -> None:
        """Continue after a step without an event (from ``corrected`` when not None)."""

    def stop(self) -> None:
        """Stop for an event."""

    def restart_at(self, t: float, q: np.ndarray, qd: np.ndarray, contacts: tuple) -> None:
        """Start afresh after an event, with the closed ``contacts``."""

    def finish_counts(self) -> None:
        """Complete ``counts`` at the end of the run."""


class ScipyStepping:
    """scipy's stepping: one accepted step per ``advance``."""

    integrator = "scipy"
    #: The driver records the start sample (this stepping does not).
    records_start = False
    #: Put before the message of a ``SimulationError`` raised during the run.
    error_prefix = "simulation stopped: "
    #: The samples are known finite (else the driver checks them).
    finite_checked = False

    def __init__(self, kernel, formulation, options: RunOptions, tau: Any, z0: np.ndarray, counts: Counts,
                 compiled_rhs: bool = True):
        self.kernel, self.formulation, self.options, self.counts = kernel, formulation, options, counts
        self.cls = solver_class(options.method)
        self.method = getattr(self.cls, "__name__", str(options.method))
        drives = bool(kernel.compiled.drives.elements)
        #: The solver steps the compiled right-hand side (``formulations/compiled_rhs.py``): the
        #: model could run in the compiled loops (only the method is scipy's) and has
        #: constraints, contacts or drive elements (whose states the C code integrates, as in
        #: the compiled loops).  With contacts, each stretch between events configures its
        #: rows through ``Formulation.contact_run``.
        self.compiled_rhs = bool(compiled_rhs
                                 and (formulation.constraints is not None or kernel.topology.contacts or drives)
                                 and why_not_compiled(kernel, formulation, "DOP853", tau) is None)
        self.setup = contextlib.ExitStack()
        self.stretch = None  #: the compiled rows of the stretch between contact events (compiled_rhs)
        self.drive = None
        if drives:  # drive elements: their forces join tau, their states y
            self.drive = DriveTorque(kernel, tau if tau is None or callable(tau) else np.asarray(tau, dtype=float), z0)
            if not self.compiled_rhs:  # (the compiled rhs evaluates them itself)
                tau = self.drive
        self.tau = tau
        self.applied = tau if self.drive is None else self.drive  #: what contact events see as applied forces
        if self.drive is not None and self.compiled_rhs:  # (the compiled workspace keeps the drive states)
            self.applied = self._applied
        self.state_columns = 0 if self.drive is None else len(self.drive.z)  #: drive states in a sample
        self.max_step = options.max_step
        self.solver_options: dict = {}
        self.workspace = self.solver = None
        self.offsets: dict = {}
        self.retries = 0
        self.collapse = CollapseWatch(0.0, options.t_end)

    # -- the driver's interface -------------------------------------------------------------------
    @contextlib.contextmanager
    def running(self, bar, interval: float):
        """The block of the run (the bar is updated step by step); the compiled
        right-hand side's configuration (``begin``) is undone at its end."""
        self.bar = bar
        with self.setup:
            try:
                yield
            except SimulationError:
                if self.compiled_rhs:  # the cause its C code recorded (a motor's law that was not finite)
                    self.formulation.explain_compiled_failure(self.kernel.compiled.functions.lib)
                raise

    @property
    def rhs(self) -> str:
        """What evaluates the right-hand side (``Result.stats["rhs"]``)."""
        return "compiled" if self.compiled_rhs else "python"

    def states(self) -> np.ndarray:
        """The drive elements' states at the sample just evaluated."""
        if self.drive is None:
            return np.zeros(0)
        if self.compiled_rhs and self.workspace is not None:
            return self.workspace.z  # (the compiled workspace's, set by its full_state)
        return self.drive.z

    def begin(self, t0: float, q0: np.ndarray, qd0: np.ndarray, offsets: dict, contacts: tuple, watched: bool) -> None:
        """Start from the consistent state ``(q0, qd0)`` at ``t0``."""
        self.offsets = offsets
        if self.compiled_rhs:  # the C configuration of the last stretch is undone at the end of the run
            self.setup.callback(self._close_stretch)
        try:
            # the model's Python callables, called back from the compiled right-hand side and Jacobian
            self.setup.enter_context(input_hook(self.kernel, self.drive.tau if self.drive is not None else self.tau))
            self._begin(t0, q0, qd0, contacts, watched)
        except BaseException:
            self.setup.close()
            raise

    def _begin(self, t0, q0, qd0, contacts, watched) -> None:
        self.workspace = self._workspace(t0, q0, qd0, contacts)
        if self.workspace.y0.size == 0:
            if not watched:
                return  # nothing to integrate: the driver evaluates the prescribed motion
            self.max_step = min(self.max_step, self.options.t_end / 500)  # nothing to integrate: step time to watch
        if self.method in IMPLICIT_METHODS and self.compiled_rhs and self.stretch.jacobian is not None:
            self.solver_options["jac"] = self.stretch.jacobian  # (in compiled code: one call, not 2 n)
        elif (self.method in IMPLICIT_METHODS and self.formulation.constraints is None
                and why_not_compiled(self.kernel, self.formulation, "DOP853", self.tau) is None):
            tau = self.tau
            self.solver_options["jac"] = compiled_jacobian(
                self.kernel, tau if tau is None or callable(tau) else self.kernel.tau(tau, 0.0, q0, qd0))
        try:
            self.solver = self._solver(t0, self.workspace.y0)  # (scipy evaluates the right-hand side here)
        except SimulationError as exc:
            raise SimulationError(f"{self.error_prefix}{exc}") from None

    @property
    def nothing_to_integrate(self) -> bool:
        return self.workspace.y0.size == 0

    def advance(self, recorder, gaps: np.ndarray | None) -> Step:
        """One accepted step (a trial state the workspace cannot evaluate is retried from the
        last accepted state with a quarter of the step, at most ten times in a row)."""
        while True:
            try:
                message = self.solver.step()
            except TrialStateError:
                self.retries += 1
                if self.retries > 10:
                    raise
                self._add_counts()
                self.counts.restarts += 1
                h = getattr(self.solver, "h_abs", None) or (self.options.t_end / 100)
                t_back, y_back = self.workspace.retreat()
                self.solver = self._solver(t_back, y_back, first_step=max(h / 4, 1e-12))
                continue
            break
        self.retries = 0
        solver = self.solver
        if solver.status == "failed":
            raise SimulationError(f"solver {self.method} gave up at t = {solver.t:.6g} s: {message}")
        self.workspace.normalize(solver.y)  # quaternions to unit length, in place
        self.counts.steps += 1
        return Step(solver.t_old, solver.t, solver.y, solver.dense_output, self.workspace,
                    finished=solver.status == "finished")

    def accepted(self, t: float, step: Step) -> None:
        """After the driver finished a step at ``t``: progress, step hooks, step-size collapse."""
        self.bar.update_to(t)
        poll_step_hooks(t)
        if self.collapse.collapsed(t):
            q_now, qd_now = self.workspace.full_state(t, step.y)
            raise SimulationError(self.collapse.message(f"solver {self.method}", t, qd_now,
                                                        self.kernel.topology.speeds))

    def go_on(self, t: float, corrected: np.ndarray | None, step: Step) -> None:
        """Continue after a step without an event: a corrected state (projection, new
        partition) restarts the solver there."""
        if corrected is not None:
            self._add_counts()
            self.counts.restarts += 1
            self.solver = self._solver(t, corrected)
        elif getattr(self.kernel, "step_limit", None) is not None and self.solver is not None:
            self.solver.max_step = self._capped(t, self.solver.y)   # collisions: the next step's limit

    def stop(self) -> None:
        """The stepping stops for an event (counted as a restart, whether or not one follows)."""
        self._add_counts()
        self.counts.restarts += 1
        self.solver = None

    def restart_at(self, t: float, q: np.ndarray, qd: np.ndarray, contacts: tuple) -> None:
        """A fresh start after an event at ``t`` with the closed ``contacts``."""
        self.workspace = self._workspace(t, q, qd, contacts)
        self.workspace.offsets = self.offsets
        self.solver = self._solver(t, self.workspace.y0)

    def finish_counts(self) -> None:
        if self.solver is not None:
            self._add_counts()

    @property
    def result_tau(self):
        return self.tau if self.drive is None else self.drive.tau

    # -- helpers -------------------------------------------------------------------------------------
    def _applied(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """What contact events see as applied forces with the compiled right-hand side: tau and
        the drive elements' forces at the drive states of the state last evaluated."""
        self.drive.z = np.array(self.states())
        return self.drive(t, q, qd)

    def _workspace(self, t0, q0, qd0, contacts):
        if not self.compiled_rhs:
            workspace = self.formulation.start(self.kernel, t0, q0, qd0, self.tau, contacts)
            return workspace if self.drive is None else DriveWorkspace(workspace, self.drive)
        tau = self.tau if self.tau is None or callable(self.tau) else \
            np.ascontiguousarray(self.kernel.tau(self.tau, t0, q0, qd0), dtype=float)  # (a callable: the input callback's)
        self._close_stretch()
        z0 = None if self.drive is None else np.array(self.states())
        self.stretch = self.formulation.scipy_stretch(self.kernel, self.kernel.compiled.functions.lib, t0, q0, qd0, tau,
                                                      contacts, self.offsets, self.method, z0)
        return self.stretch.workspace

    def _close_stretch(self) -> None:
        if self.stretch is not None:
            stretch, self.stretch = self.stretch, None
            stretch.close()

    def _fun(self, t, y):
        total = float(y.sum())
        if total - total != 0.0:  # a NaN or inf entry
            raise SimulationError(f"state became non-finite at t = {t:.6g} s")
        return self.workspace.rhs(t, y)

    def _capped(self, t, y) -> float:
        """The step limit: ``max_step``, and with collisions the longest step that cannot carry
        a shape through another unseen (``CollisionKernel.step_limit``)."""
        limit = getattr(self.kernel, "step_limit", None)
        return self.max_step if limit is None else min(self.max_step, limit(*self.workspace.full_state(t, y)))

    def _solver(self, t0, y0, first_step=None):
        o = self.options
        cap = self._capped(t0, y0)
        first_step = first_step if first_step is None else min(first_step, cap)
        return self.cls(self._fun, t0, y0, o.t_end, rtol=o.rtol, atol=o.atol, max_step=cap,
                        first_step=first_step, **self.solver_options)

    def _add_counts(self) -> None:
        for key in ("nfev", "njev", "nlu"):
            setattr(self.counts, key, getattr(self.counts, key) + getattr(self.solver, key, 0))


class CompiledStepping:
    """The loop compiled with the model.  Without contacts the whole run is one compiled
    stretch (``compiled_setup`` and ``compiled_session`` of the formulation around it);
    with contacts each stretch between events is a ``Formulation.contact_run``, and the step
    with an event comes back to the driver."""

    integrator = "compiled"
    rhs = "compiled"
    error_prefix = ""  # (the compiled loops' messages name the method and the time)
    finite_checked = True  # (the compiled loops stop at a non-finite state: NOT_FINITE)

    def __init__(self, kernel, formulation, options: RunOptions, tau: Any, z0: np.ndarray, counts: Counts,
                 budget=None):
        self.kernel, self.formulation, self.options, self.counts = kernel, formulation, options, counts
        self.lib = kernel.compiled.functions.lib
        self.tau, self.z0, self.budget = tau, z0, budget
        self.method = options.method
        self.watched = bool(kernel.topology.contacts)
        #: Without contacts the compiled rows hold the start sample.
        self.records_start = not self.watched
        self.state_columns = kernel.compiled.drives.nz
        self.applied = tau  # (what the events see: the drive elements' forces join tau, as in Python stepping)
        #: With contacts, the drive elements' states: the stretches carry them after their
        #: state (``[q, v, z]``, lagrange ``[x_i, qd_i, z]``); between stretches they are
        #: ``drive.z`` (set by the event step's ``full_state``), which the events' forces read.
        self.drive = None
        if self.watched and kernel.compiled.drives.elements:
            self.drive = DriveTorque(kernel, tau if tau is None or callable(tau) else np.asarray(tau, dtype=float), z0)
            self.applied = self.drive
        self.max_step = options.max_step
        self.nothing_to_integrate = False
        self.segment = None
        self.result_tau = tau
        self.loop_counts = np.zeros(3, dtype=np.int64)  #: [nfev, accepted, rejected] of the compiled stretches

    @contextlib.contextmanager
    def running(self, bar, interval: float):
        """The compiled loops call the step hook (Ctrl-C, ``step_hook`` callbacks) and, with a
        bar, report the time reached to it about every ``interval`` s (the callback never
        asks to stop, so the run and its result are unchanged)."""
        progress = step_hook(lambda t: bar.update_to(t) and False, interval=interval) if bar.enabled \
            else contextlib.nullcontext()
        with progress, hooked(self.lib) as hook, input_hook(self.kernel, self.tau):
            self.hook = hook
            try:
                yield
            finally:
                self._close_segment()

    def states(self) -> np.ndarray:
        """The drive elements' states at the sample the driver just evaluated (with contacts)."""
        return np.zeros(0) if self.drive is None else self.drive.z.copy()

    def begin(self, t0: float, q0: np.ndarray, qd0: np.ndarray, offsets: dict, contacts: tuple, watched: bool) -> None:
        self.offsets = offsets
        self.t, self.q, self.qd = t0, q0, qd0
        self.contacts = contacts
        tau = self.tau
        if callable(tau):  # (evaluated at every evaluation by the input callback: running)
            self.tau_arr, self.tau_ptr = tau, None
        else:
            self.tau_arr = None if tau is None else np.ascontiguousarray(self.kernel.tau(tau, 0.0, q0, qd0), dtype=float)
            self.tau_ptr = None if self.tau_arr is None else self.tau_arr.ctypes.data
        self.finished = False

    def advance(self, recorder, gaps: np.ndarray | None) -> Step | None:
        """Run compiled code until t_end (None) or a step with a contact event (that step);
        ``gaps``: every contact's gap at the start (m)."""
        if not self.watched:
            self._whole_run(recorder)
            return None
        return self._stretch(recorder, gaps)

    def accepted(self, t: float, step: Step) -> None:
        """(The compiled loops report progress and watch the step size themselves.)"""

    def go_on(self, t: float, corrected: np.ndarray | None, step: Step) -> None:
        """The loop's watch saw an event Python does not confirm: carry on from the step's end."""
        self.counts.restarts += 1
        self.t = t
        self.q, self.qd = step.workspace.full_state(t, step.y if corrected is None else corrected)

    def stop(self) -> None:
        """The stepping stops for an event (counted as a restart)."""
        self.counts.restarts += 1

    def restart_at(self, t: float, q: np.ndarray, qd: np.ndarray, contacts: tuple) -> None:
        self.t, self.q, self.qd, self.contacts = t, q, qd, contacts

    def finish_counts(self) -> None:
        """(Counted as the loops ran.)"""

    # -- the stretches ---------------------------------------------------------------------------------
    def _whole_run(self, recorder) -> None:
        """No contacts: one compiled run from the start to t_end (the rows include the start)."""
        kernel, formulation, lib = self.kernel, self.formulation, self.lib
        with formulation.compiled_setup(lib, kernel=kernel, q0=self.q):  # e.g. the dae rows and gains
            session = formulation.compiled_session(kernel, lib, self.q, self.qd, self.tau_arr)  # e.g. lagrange's
            try:
                with session if session is not None else contextlib.nullcontext():
                    times, values, counts = run_loops(kernel, lib, self.hook, self.options, self.q, self.qd,
                                                      self.z0, self.tau_ptr, session, self.budget)
            except SimulationError:
                formulation.explain_compiled_failure(lib)  # raises the cause when it knows one (a motor's law)
                raise
        self.method = counts.pop("method", self.method)
        for key, value in counts.items():
            setattr(self.counts, key, value)
        recorder.extend(np.asarray(times, dtype=float), values)

    def _close_segment(self) -> None:
        if self.segment is not None:
            segment, self.segment = self.segment, None
            segment.__exit__(None, None, None)

    def _stretch(self, recorder, gaps) -> Step | None:
        """Contacts: one stretch from ``(t, q, qd)`` in compiled code, watching the contacts
        after every step; the rows go to ``recorder``; the step with an event comes back."""
        kernel, formulation, lib, o = self.kernel, self.formulation, self.lib, self.options
        n = kernel.nv
        self._close_segment()  # (the last event step's stretch: open until the driver finished that step)
        if self.t >= o.t_end:
            return None
        counts = self.loop_counts  # (the whole run's, as the collapse message reads them)
        segment = formulation.contact_run(kernel, lib, self.q, self.qd, self.tau_arr, t0=self.t,
                                          contacts=self.contacts, offsets=self.offsets)
        self.segment = segment.__enter__()
        try:
            if self.t == 0.0 and segment.ni == 0:
                self.max_step = min(self.max_step, o.t_end / 500)  # nothing to integrate: step time to watch
            segment.watch_contacts(gaps, GAP_TOLERANCE)
            state, y = np.array([self.t, 0.0]), segment.y0
            if self.drive is not None:  # the drive states follow the stretch's state
                segment.drive_states(self.drive.z)
                y = np.ascontiguousarray(np.concatenate((y, self.drive.z)), dtype=float)
            t_out = None if o.t_eval is None else np.ascontiguousarray(o.t_eval, dtype=float)
            y_out = None if o.t_eval is None else np.empty((len(t_out), kernel.nq + n + self.state_columns))
            i_out = np.array([recorder.next], dtype=np.int64)
            try:
                status, steps_t, steps_y, y, f = dop853_segment(
                    kernel, segment.loop(lib), self.hook, segment, o.replace(method="DOP853", max_step=min(self.max_step, segment.step_cap)),
                    state, y, np.empty_like(y), self.tau_ptr, counts, t_out, i_out, y_out, budget=self.budget,
                    stored=len(recorder.t))
            except SimulationError:
                failure = getattr(segment, "friction_failure", lambda: None)()  # (a failed friction solve: Painleve)
                if failure is not None:
                    raise failure from None
                raise
            self.counts.nfev, self.counts.steps, self.counts.rejected = (int(c) for c in counts)
            if t_out is not None:
                recorder.extend(t_out[recorder.next:int(i_out[0])], y_out[recorder.next:int(i_out[0])])
                recorder.next = int(i_out[0])
            recorder.extend(steps_t, steps_y)
            self.counts.restarts += segment.restarts
            if status == FINISHED:
                self._close_segment()
                return None
            segment.sync()  # the Python workspace at the step's start, where the loop stopped
            t_new, y_new, dense = segment.event_step(float(state[0]), y)
            # (the stretch stays open for the driver's work on the event step: closed before the next)
            workspace = segment.workspace
            if self.drive is not None:  # full_state splits the drive states off (into drive.z)
                workspace = DriveWorkspace(workspace, self.drive, len(y_new) - self.state_columns)
            return Step(float(state[0]), t_new, y_new, lambda: dense, workspace, gaps=segment.gaps.copy(),
                        locator=segment.locator(float(state[0]), y))
        except BaseException:
            self._close_segment()
            raise
