"""Integration loops compiled with the model: DOP853 (adaptive, dense output) and RK4.

The C source (``c/integrators.c``, ``c/dop853_loop.c``) is compiled next to the model's
code so that the right-hand side is a direct C call: no Python between steps.  DOP853 follows scipy's implementation step
for step (same tableau, error norm, step-size control and dense output; Hairer,
Norsett & Wanner, Solving ODEs I, II.5), so results match ``solve_ivp`` to rounding.
"""
from __future__ import annotations

import functools
import importlib.util
import sys
from pathlib import Path

import numpy as np

from mbcomp.codegen.callbacks import constant_tau, python_watch, raise_pending
from mbcomp.core import c_text

#: Status codes returned by the compiled loops.
FINISHED, BUFFER_FULL, STEP_TOO_SMALL, SINGULAR, NOT_FINITE, RANK_LOST, STOPPED, COLLAPSED = 0, 1, -1, -2, -3, -5, -6, -7
#: The reduced (lagrange) loop's: paused after an accepted step for Python to look at the
#: partition; a trial state without dependent coordinates (formulations/lagrange_c.py).
PAUSED, TRIAL_FAILED = 2, -8
#: ... and with contacts watched: a step in which a contact closes or a held one would pull.
EVENT = 3
#: Step-size collapse: every WINDOW accepted steps, a run gives up (COLLAPSED) when, at the
#: pace of that window, the rest of the interval would need more than its step budget
#: (``limits.max_steps()``, default COLLAPSE_STEPS; Python-stepped loops get a hundredth).
COLLAPSE_WINDOW, COLLAPSE_STEPS = 4096, 1e9


def _array(name: str, values) -> str:
    """A C table of ``values`` (1-D or 2-D; ``repr`` of each float, so each entry is the same double)."""
    values = np.asarray(values, dtype=float)
    shape = "".join(f"[{s}]" for s in values.shape)

    def row(v) -> str:
        return ", ".join(repr(float(x)) for x in v)
    body = row(values) if values.ndim == 1 else ", ".join(f"{{{row(r)}}}" for r in values)
    return f"static const double {name}{shape} = {{{body}}};"


@functools.lru_cache(maxsize=1)
def _dop853_tables() -> tuple[str, ...]:
    """The C tables of scipy's DOP853 tableau (``scipy.integrate._ivp.dop853_coefficients``).

    Read from that module's file without importing ``scipy.integrate``: the package costs
    about half a second of imports, and a process that loads a cached model and runs it
    in compiled code needs this text only for the cache key, never the package.  Falls
    back to the package import when the file is not where scipy keeps it."""
    dop = sys.modules.get("scipy.integrate._ivp.dop853_coefficients") or _dop853_from_file()
    if dop is None:
        from scipy.integrate._ivp import dop853_coefficients as dop
    return (_array("DOP_A", dop.A[:16, :16]), _array("DOP_B", dop.B), _array("DOP_C", dop.C[:16]),
            _array("DOP_E3", dop.E3), _array("DOP_E5", dop.E5), _array("DOP_D", dop.D))


def _dop853_from_file():
    """scipy's ``dop853_coefficients`` module executed from its file (it imports only numpy),
    or None when it is not found there."""
    try:
        spec = importlib.util.find_spec("scipy")  # finds the package, does not import it
        path = Path(spec.submodule_search_locations[0]) / "integrate" / "_ivp" / "dop853_coefficients.py"
        file_spec = importlib.util.spec_from_file_location("_mbcomp_dop853_coefficients", path)
        module = importlib.util.module_from_spec(file_spec)
        file_spec.loader.exec_module(module)
        return module
    except (ImportError, OSError, AttributeError, TypeError, IndexError):
        return None


def c_integrators() -> str:
    """C source of ``dop853_run`` and ``rk4_run`` for a tree whose coordinates, speeds and
    quaternion and screw indices the model's sizes unit gives (``c_sizes.CSizes``: ``NCOORD``,
    ``NV``, ``QUAT_Q``, ...): the state is ``y = [q, v, z]``, its rate ``[q'(q, v), v', z']``;
    quaternions are normalised after every accepted step.  With ``HAS_DRIVES``, the ``NZ``
    states of drive elements follow the mechanical ones (``drive_equations``: their forces
    join ``tau``, their rates come from ``drives``).
    Where ``REDUCED_LOOP`` is defined (a constrained model the lagrange formulation steps
    in compiled code), also ``dop853_reduced_run``: the same loop on the reduced state of
    ``formulations/lagrange_c.py``.  The C is ``c/integrators.c`` with ``c/dop853_loop.c``
    instantiated once per loop (``@RUN@``, ``@INIT@``), after the tables and sizes above."""
    lines = [
        "#include <float.h>",
        "#include <time.h>",
        f"#define COLLAPSE_WINDOW {COLLAPSE_WINDOW}",
        f"#define COLLAPSE_STEPS {COLLAPSE_STEPS!r}",
        f"#define LOOP_EVENT {EVENT}",
        "#define NY (NMECH + NZ)",
        "#define NWORK (DYNAMICS_SIZE > NDAEWORK ? DYNAMICS_SIZE : NDAEWORK)",
        *_dop853_tables(),
    ]
    loops = [_instance("dop853_run", "initial_step", reduced=False),
             "#ifdef REDUCED_LOOP", _instance("dop853_reduced_run", "reduced_initial_step", reduced=True), "#endif"]
    return "\n".join(lines + [c_text.fill(c_text.read("mbcomp.codegen", "integrators.c"), LOOPS="\n".join(loops))])


def _instance(run: str, init: str, reduced: bool) -> str:
    """One DOP853 loop: on the tree state (``rhs``) or on the lagrange formulation's reduced
    state (``lagrange_rhs``; full output rows)."""
    macros = ("#define LOOP_REDUCED 1\n#define LOOP_NY (lag_nqi + lag_ni + NZ)\n"
              "#define LOOP_RHS(tt, yy, ff) lagrange_rhs(tt, yy, ff, p, tau)\n" if reduced else
              "#define LOOP_REDUCED 0\n#define LOOP_NY NY\n#define LOOP_RHS(tt, yy, ff) rhs(tt, yy, ff, p, tau, work)\n")
    return (macros + c_text.fill(c_text.read("mbcomp.codegen", "dop853_loop.c"), RUN=run, INIT=init)
            + "#undef LOOP_REDUCED\n#undef LOOP_NY\n#undef LOOP_RHS\n")


# -- Python drivers ------------------------------------------------------------------------------
import contextlib  # noqa: E402
import ctypes  # noqa: E402
import signal  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402
from typing import Callable, Iterator  # noqa: E402

from mbcomp.core.errors import ModelError, SimulationError  # noqa: E402

from mbcomp.core.run_options import COMPILED_METHODS, RunOptions  # noqa: E402,F401  (COMPILED_METHODS: re-exported)


class LoopSession:
    """The Python side of a formulation's compiled loop for one stretch of a run: the hook
    point between ``dop853_segment`` and a formulation whose stepping needs more than the
    plain DOP853 loop on ``[q, v, z]`` (``Formulation.compiled_session`` and
    ``Formulation.contact_run`` return one; ``formulations/lagrange_compiled.ReducedRun``,
    ``formulations/dae_compiled.DaeRun``).  The defaults here are the plain loop's.

    ``y0``: the loop's initial state; ``ni``: independent speeds (0: nothing to integrate);
    ``restarts``: restarts the stretch made (new partitions, retreats), counted as Python
    stepping counts them."""

    #: The loop's state is the full ``[q, qd]`` (a failure is diagnosed from it); otherwise
    #: from ``accepted()``.
    full_state_loop = False
    restarts = 0

    def loop(self, lib):
        """The compiled loop this session steps (bound): ``dop853_run`` on the tree state."""
        return bind_dop853(lib)

    def resume(self, status: int, state: np.ndarray, y: np.ndarray, f: np.ndarray, counts: np.ndarray):
        """After the loop returned PAUSED or TRIAL_FAILED: ``(y, f)`` to go on from."""
        raise SimulationError(f"the compiled loop returned status {status}, which this run cannot resume")

    def accepted(self) -> tuple[float, np.ndarray, np.ndarray]:
        """``(t, q, qd)`` of the last accepted state (read where a loop on a reduced state failed)."""
        raise NotImplementedError

    def drive_states(self, z: np.ndarray) -> None:
        """The drive elements' states at the start (a session that keeps them copies them)."""

    def prescribed(self, t_end: float, t_eval, max_step: float):
        """No degree of freedom (``ni == 0``): ``(times, rows, counts)`` at the output times."""
        raise NotImplementedError

    def failure_hint(self, status: int) -> str | None:
        """What to add to the message of a failed loop (None: nothing)."""
        return None


# -- the step hook: Ctrl-C, stop requests and progress inside compiled loops -------------------
#: Processor time (s) between two calls of the hook from a compiled loop.
HOOK_INTERVAL = 0.05
_HOOK_TYPE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double)
_hooks = threading.local()  # this thread's callbacks (step_hook)
try:  # the C functions behind ``signal.signal``/``getsignal``: the wrappers convert handlers to
    # and from enums, which cost ~40 us per run, a tenth of a 50-link chain's loose-tolerance run
    from _signal import SIGINT as _SIGINT, getsignal as _getsignal, signal as _setsignal
except ImportError:  # not CPython
    _SIGINT, _getsignal, _setsignal = signal.SIGINT, signal.getsignal, signal.signal
try:
    _check_signals = ctypes.pythonapi.PyErr_CheckSignals  # runs Python's handlers: Ctrl-C raises here
    _check_signals.argtypes, _check_signals.restype = [], ctypes.c_int
except AttributeError:  # not CPython: handlers still run when the hook's own code executes
    _check_signals = None


@contextlib.contextmanager
def step_hook(callback: Callable[[float], bool], interval: float = HOOK_INTERVAL) -> Iterator[None]:
    """Within the block, compiled loops run by this thread call ``callback(t)`` (t: the
    simulated time reached, s) about every ``interval`` seconds of processor time; a true
    return stops the run with a ``SimulationError``.  For progress displays and for stopping
    runs from another thread (``sweep`` uses it to stop its workers)."""
    stack = _hooks.__dict__.setdefault("stack", [])
    stack.append((callback, float(interval)))
    try:
        yield
    finally:
        stack.remove((callback, float(interval)))


def poll_step_hooks(t: float) -> None:
    """For Python-stepped loops: call this thread's ``step_hook`` callbacks once; raise
    ``SimulationError`` when one asks to stop."""
    for callback, _ in getattr(_hooks, "stack", ()):
        if callback(t):
            raise SimulationError(f"stopped at t = {t:.6g} s by a step hook")


class _Hook:
    """What a compiled loop calls back: notes Ctrl-C (main thread), then asks this thread's
    ``step_hook`` callbacks.  Python runs signal handlers when the hook's code starts, where
    an exception could not cross the C loop: so during a run SIGINT only sets a flag, and
    the previous handler (``KeyboardInterrupt`` by default) gets the signal once the loop has
    returned."""

    def __init__(self):
        self.callbacks = list(getattr(_hooks, "stack", ()))
        self.interval = min([HOOK_INTERVAL] + [interval for _, interval in self.callbacks])
        self.main = threading.current_thread() is threading.main_thread()
        self.previous = None      # the SIGINT handler to restore (when one was replaced)
        self.signal = None        # (signum, frame) of a SIGINT received during the run
        self.error: BaseException | None = None
        self.outer: "_Hook | None" = None  # the hook of a run this one is nested in (a callback's)

    def __call__(self, t: float) -> int:
        try:
            if self.main and _check_signals is not None:
                _check_signals()
            if self.signal is not None:
                return 1
            return int(any(callback(t) for callback, _ in self.callbacks))
        except BaseException as exc:  # noqa: BLE001 - re-raised by stopped()
            self.error = exc
            return 1

    def _on_sigint(self, signum, frame) -> None:
        self.signal = (signum, frame)

    def install(self, lib) -> None:
        if self.main:
            try:
                previous = _getsignal(_SIGINT)
                if callable(previous):
                    _setsignal(_SIGINT, self._on_sigint)
                    self.previous = previous
            except ValueError:  # not the main interpreter
                pass
        self.outer = getattr(_hooks, "active", None)
        _hooks.active = self
        _hook_setter(lib)(_TRAMPOLINE, self.interval)
        _set_step_budget(lib)

    def remove(self, lib) -> None:
        """Unset the hook (the outer run's again, for a nested run), restore the SIGINT
        handler and deliver a pending Ctrl-C to it."""
        _hooks.active = self.outer
        if self.outer is None:
            _hook_setter(lib)(_NO_HOOK, 0.0)
        else:
            _hook_setter(lib)(_TRAMPOLINE, self.outer.interval)
        self.outer = None
        self._deliver()

    def _deliver(self, where: str = "") -> None:
        if self.previous is not None:
            _setsignal(_SIGINT, self.previous)
        previous, self.previous = self.previous, None
        pending, self.signal = self.signal, None
        if pending is not None and previous is not None:
            try:
                previous(*pending)  # the default handler raises KeyboardInterrupt
            except BaseException as exc:
                if where and hasattr(exc, "add_note"):
                    exc.add_note(where)
                raise

    def stopped(self, t: float, method: str):
        """Raise for a run the hook stopped at simulated time ``t``."""
        where = f"compiled {method} interrupted at t = {t:.6g} s"
        self._deliver(where)
        if self.error is not None:
            if hasattr(self.error, "add_note"):
                self.error.add_note(where)
            raise self.error
        raise SimulationError(f"compiled {method} stopped at t = {t:.6g} s by a step hook")


def _dispatch(t: float) -> int:
    """The one C callback of every compiled loop: this thread's active ``_Hook`` (creating a
    ctypes callback per run cost more than the rest of a short run's set-up)."""
    hook = getattr(_hooks, "active", None)
    return 0 if hook is None else hook(t)


_TRAMPOLINE = _HOOK_TYPE(_dispatch)
_NO_HOOK = _HOOK_TYPE()


def _set_step_budget(lib) -> None:
    """The compiled loops' step budget for this thread: ``limits.max_steps()``."""
    from mbcomp.core.limits import max_steps
    setter = getattr(lib, "set_step_budget", None)
    if setter is None:   # (a library without the integrators)
        return
    if setter.restype is not None:
        setter.argtypes, setter.restype = [ctypes.c_double], None
    setter(float(max_steps()))


def _hook_setter(lib):
    """``lib.set_step_hook`` with its argument types (set once per library)."""
    setter = lib.set_step_hook
    if setter.restype is not None:
        setter.argtypes, setter.restype = [_HOOK_TYPE, ctypes.c_double], None
    return setter


@contextlib.contextmanager
def hooked(lib) -> Iterator["_Hook"]:
    """Within the block, compiled loops run by this thread on ``lib`` call the step hook
    (Ctrl-C, ``step_hook`` callbacks); for drivers that run several compiled stretches."""
    hook = _Hook()
    hook.install(lib)
    try:
        yield hook
    finally:
        hook.remove(lib)


def bind_reduced(lib):
    """``dop853_reduced_run`` (the lagrange formulation's reduced loop), same arguments as ``dop853_run``."""
    void, lng, dbl = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
    run = lib.dop853_reduced_run
    run.argtypes = [void, void, void, void, void, dbl, dbl, dbl, dbl, void, lng, void, void, void, void, lng,
                    void, void]
    run.restype = ctypes.c_int
    return run


def bind_dop853(lib):
    """``dop853_run`` (the loop on the tree state ``[q, v, z]``) with its argument types."""
    return _bind(lib)[0]


def _bind(lib):
    void, lng, dbl = ctypes.c_void_p, ctypes.c_long, ctypes.c_double
    run = lib.dop853_run
    run.argtypes = [void, void, void, void, void, dbl, dbl, dbl, dbl, void, lng, void, void, void, void, lng,
                    void, void]
    run.restype = ctypes.c_int
    rk4 = lib.rk4_run
    rk4.argtypes = [void, void, dbl, void, dbl, lng, void, lng, void, void]
    rk4.restype = ctypes.c_int
    return run, rk4


def compiled_jacobian(kernel, tau):
    """``jac(t, y)`` for scipy's implicit methods, computed in compiled code (forward
    differences of the compiled right-hand side: one call instead of 2 nq Python calls)."""
    lib = kernel.compiled.functions.lib
    fn = lib.rhs_jacobian
    fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p]
    fn.restype = ctypes.c_int
    n2 = kernel.nq + kernel.nv + kernel.compiled.drives.nz
    tau_arr = constant_tau(tau)  # (a callable tau: the input callback's)
    tau_ptr = None if tau_arr is None else tau_arr.ctypes.data
    p = kernel.p

    def jac(t, y):
        y = np.ascontiguousarray(y, dtype=float)
        out = np.empty((n2, n2))
        status = fn(p.ctypes.data, tau_ptr, float(t), y.ctypes.data, out.ctypes.data)
        if status:
            _fail(kernel, status, t, y, "Jacobian")
        return out

    jac.tau = tau_arr  # keep the buffer alive with the closure
    return jac


def _diagnose(kernel, t: float, y: np.ndarray, method: str) -> None:
    """Evaluate the tree accelerations at the state the compiled loop stopped at through the
    checked Python path, which names the cause (a zero-length spring, a singular joint)."""
    n = kernel.nq
    if not np.all(np.isfinite(y)):
        return
    when = f"at t = {t:.6g} s" if np.isfinite(t) else "during the run"
    q, qd = y[:n], y[n:]
    try:
        kernel.tree_solve(*kernel.checked_dynamics(t if np.isfinite(t) else 0.0, q, qd), q)
    except SimulationError as exc:
        raise SimulationError(f"compiled {method} stopped {when}: {exc}") from None
    except ModelError:
        pass


def rhs_failure(kernel, status: int, t: float, y: np.ndarray, method: str) -> None:
    """Raise for a nonzero status of the compiled right-hand side at ``(t, y)`` (``RankLost``
    when the dae rows lost rank, else the singular mass matrix, with its cause when known)."""
    _fail(kernel, RANK_LOST if status == RANK_LOST else SINGULAR, t, y, method)


def _fail(kernel, status: int, t: float, y: np.ndarray, method: str, steps: int | None = None,
          t_end: float | None = None):
    raise_pending()  # (a Python callable's exception stopped the loop: INPUT_FAILED)
    n = kernel.nq
    if status == RANK_LOST:
        raise RankLost(f"the constraint rows lost rank at t = {t:.6g} s")
    if status == STEP_TOO_SMALL:
        raise SimulationError(f"compiled {method} gave up at t = {t:.6g} s: required step size is less than "
                              f"spacing between numbers")
    if status in (SINGULAR, NOT_FINITE):
        _diagnose(kernel, t, y, method)
    if status == SINGULAR:
        raise SimulationError(f"mass matrix is singular at t = {t:.6g} s")
    if status == COLLAPSED:
        from mbcomp.core.limits import max_steps
        window, budget = python_watch() or (COLLAPSE_WINDOW, max_steps())  # (with callbacks: the Python-stepped check)
        raise SimulationError(collapse_message(f"compiled {method}", t, y[n:], kernel.topology.speeds, window,
                                               budget if window == COLLAPSE_WINDOW else budget / 30,
                                               steps=steps, t_end=t_end, budget=budget))
    if status == NOT_FINITE:
        raise SimulationError(f"compiled {method}: state became non-finite at t = {t:.6g} s")
    raise SimulationError(f"compiled {method} failed with status {status} at t = {t:.6g} s")


class CollapseWatch:
    """Step-size collapse of a Python-stepped run: every ``window`` accepted steps, whether at
    that window's pace the rest of the interval would need more than ``limit`` steps, or more
    than ``limit / 30`` while the pace has fallen a hundredfold below the run's best (a state
    running away, not a model that needs small steps throughout).  ``limit``: a hundredth of
    ``limits.max_steps()`` (Python steps cost about a hundred compiled ones)."""

    def __init__(self, t0: float, t_end: float, window: int = 1000, limit: float | None = None):
        if limit is None:
            from mbcomp.core.limits import max_steps
            limit = max_steps() / 100
        self.t_end, self.window, self.limit = t_end, window, limit
        self.t0, self.n, self.best = t0, 0, 0.0
        self.start, self.steps = t0, 0   # the whole run's, for its average pace
        self.projected = 0.0  # steps the rest of the run would need at the last window's pace

    def collapsed(self, t: float) -> bool:
        self.n += 1
        self.steps += 1
        if self.n < self.window:
            return False
        pace, self.t0, self.n = (t - self.t0) / self.window, t, 0
        self.best = max(self.best, pace)
        rest = self.t_end - t
        self.projected = rest / pace if pace > 0 else float("inf")
        return rest > 0 and (rest > self.limit * pace or (rest > self.limit / 30 * pace and pace < 1e-2 * self.best))

    def message(self, who: str, t: float, speeds, names=()) -> str:
        """Why the run gave up at ``t`` (see ``collapse_message``)."""
        return collapse_message(who, t, speeds, names, self.window, self.projected, steps=self.steps,
                                t_end=self.t_end, budget=self.limit, start=self.start)


def collapse_message(who: str, t: float, speeds, names=(), window: int = COLLAPSE_WINDOW,
                     projected: float = COLLAPSE_STEPS, *, steps: int | None = None, t_end: float | None = None,
                     budget: float | None = None, start: float = 0.0) -> str:
    """Why a run whose step size collapsed gave up, and the largest speed it reached.

    With the run's ``steps`` so far, ``t_end`` and the step ``budget``: when even the run's
    average pace could not reach ``t_end`` within the budget, the run is merely longer than
    the budget allows (a bounded motion over a long time), and the message says so and how
    to raise it; otherwise the pace collapsed (a state growing without bound)."""
    speeds = np.abs(np.asarray(speeds, dtype=float))
    largest = ""
    if speeds.size:
        i = int(speeds.argmax())
        largest = f"; largest speed {speeds[i]:.3g} ({names[i] if len(names) == speeds.size else f'speed {i}'})"
    if steps and t_end is not None and budget and t > start:
        average = (t - start) / steps
        needed = steps + (t_end - t) / average
        if needed > budget:
            return (f"{who}: the step budget ran out at t = {t:.6g} s: {steps} steps reached it ({average:.2g} s a "
                    f"step), so t_end = {t_end:.6g} s would take about {needed:.2g} steps, more than the budget of "
                    f"{budget:.2g} steps (set MBCOMP_MAX_STEPS to raise it, simulate in shorter stretches, or loosen "
                    f"rtol/atol for longer steps){largest} (if the motion should be slower, check the initial state "
                    f"and the forces)")
    return (f"{who}: step size collapsed at t = {t:.6g} s: at the pace of the last {window} steps the rest of "
            f"the run would need more than {projected:.2g} steps; the state is growing without bound{largest} "
            f"(check the initial state and the forces), or a stiff force law (strong damping on light links) or "
            f"contacts switching back and forth demand ever shorter explicit steps (then try an implicit method, "
            f"method='Radau', or with contacts contact_mode='timestepping')")


class RankLost(Exception):
    """The compiled dae solve met a dead point at rest (its rows lost rank with every speed
    below ``REST_SPEED``: the motion is not determined) or rows that are not finite: the
    caller falls back to Python stepping, whose solve names the cause."""


def run_loops(kernel, lib, hook: "_Hook", options: RunOptions, q0: np.ndarray, qd0: np.ndarray, z0: np.ndarray,
              tau_ptr, session: LoopSession | None = None, budget=None):
    """The compiled loops over the whole run from the consistent state ``(q0, qd0, z0)`` at
    t = 0 (``options``: method, t_end, rtol, atol, max_step, dt, t_eval; ``tau_ptr``: the
    address of constant generalised forces, or None).  With a ``session`` (a formulation
    stepping its own reduced state, ``Formulation.compiled_session``) the DOP853 loop is the
    session's: it starts from ``session.y0``, writes full ``[q, qd, z]`` rows, and hands PAUSED
    and TRIAL_FAILED returns to ``session.resume``.  Returns ``(times, rows, counts)``:
    ``counts`` holds ``nfev``, ``steps``, ``rejected`` and, with a session, ``restarts`` and
    possibly ``method`` (``"prescribed"``)."""
    method, t_end, t_eval, dt = options.method, options.t_end, options.t_eval, options.dt
    p = kernel.p
    y = np.ascontiguousarray(np.concatenate((q0, qd0, z0)), dtype=float)
    ny = y.size  # the output rows
    run = bind_dop853(lib)
    if session is not None:
        if method != "DOP853":
            raise ModelError("simulate", f"method {method!r} has no compiled loop for this formulation")
        if session.ni == 0 and not kernel.compiled.drives.nz:  # nothing to integrate: the motion follows from the constraints
            if t_eval is None:
                from mbcomp.core.checks import prescribed_times
                t_eval = prescribed_times(t_end, options.max_step, budget)
            return session.prescribed(t_end, t_eval, options.max_step)
        run = session.loop(lib)
        full0, y = y, np.ascontiguousarray(np.concatenate((session.y0, z0)), dtype=float)  # [q_i, qd_i, z]
        if z0.size:
            session.drive_states(z0)  # (the accepted state's, where a retreat goes back to)
    else:
        full0 = y.copy()  # (the loop advances y in place)
    if method == "RK4":
        return _rk4(kernel, lib, hook, options, y, tau_ptr, budget)
    state = np.array([0.0, 0.0])
    counts = np.zeros(3, dtype=np.int64)
    if t_eval is not None:
        t_out = np.ascontiguousarray(t_eval, dtype=float)
        y_out = np.empty((len(t_out), ny))
        i_out = np.zeros(1, dtype=np.int64)
        if len(t_out) and t_out[0] == 0.0:
            y_out[0] = full0
            i_out[0] = 1
        dop853_segment(kernel, run, hook, session, options, state, y, np.empty(y.size), tau_ptr, counts, t_out, i_out,
                       y_out)
        times, values = t_out, y_out
    else:
        _, steps_t, steps_y, _, _ = dop853_segment(kernel, run, hook, session, options, state, y, np.empty(y.size),
                                                   tau_ptr, counts, budget=budget, stored=1)
        times, values = np.concatenate(([0.0], steps_t)), np.concatenate((full0[None, :], steps_y))
    stats = {"nfev": int(counts[0]), "steps": int(counts[1]), "rejected": int(counts[2])}
    if session is not None:
        stats["restarts"] = session.restarts
    return times, values, stats


def _rk4(kernel, lib, hook: "_Hook", options: RunOptions, y: np.ndarray, tau_ptr, budget=None):
    """The fixed-step RK4 loop (step ``options.dt``) from ``y`` at t = 0: every step, or the
    rows at ``options.t_eval`` (Hermite between the steps around each)."""
    _, rk4 = _bind(lib)
    method, t_end, dt, t_eval = options.method, options.t_end, options.dt, options.t_eval
    p = kernel.p
    if dt is None:
        raise ModelError("simulate", "method 'RK4' is fixed-step: give dt (s)")
    steps = int(round(t_end / dt))
    if steps < 1 or abs(steps * dt - t_end) > 1e-9 * max(t_end, 1.0):
        raise ModelError("simulate", f"t_end = {t_end} must be a whole number of steps dt = {dt}")
    counts = np.zeros(3, dtype=np.int64)
    ny = y.size
    if t_eval is None:  # every step
        if budget is not None:
            budget.check_rows(steps + 1, f"dt = {dt:g} s over t_end = {t_end:g} s")
        out = np.empty((steps + 1, ny))
        status = rk4(p.ctypes.data, tau_ptr, 0.0, y.ctypes.data, float(dt), steps, None, 0, out.ctypes.data,
                     counts.ctypes.data)
        t = np.arange(steps + 1) * dt
    else:  # only at the requested times
        t = np.ascontiguousarray(t_eval, dtype=float)
        out = np.empty((len(t), ny))
        status = rk4(p.ctypes.data, tau_ptr, 0.0, y.ctypes.data, float(dt), steps, t.ctypes.data, len(t),
                     out.ctypes.data, counts.ctypes.data)
    if status == STOPPED:
        hook.stopped(counts[1] * dt, method)
    if status:
        _fail(kernel, status, counts[1] * dt, y, method)
    return t, out, {"nfev": int(counts[0]), "steps": int(counts[1]), "rejected": 0}


def dop853_segment(kernel, run, hook: "_Hook", session: LoopSession | None, options: RunOptions, state: np.ndarray,
                   y: np.ndarray, f: np.ndarray, tau_ptr, counts: np.ndarray, t_out=None, i_out=None, y_out=None,
                   budget=None, stored: int = 0):
    """Run a compiled DOP853 loop (``run``: ``dop853_run`` or a session's loop) from
    ``state = [t, h]`` (h <= 0: a first step is chosen and ``f`` computed) and ``y`` to
    ``options.t_end`` or to a step the loop stops at (EVENT), with ``options``' rtol, atol
    and max_step.  Output rows at ``t_out`` from index ``i_out[0]`` into ``y_out``, or
    (``t_out`` None) every accepted step.  PAUSED and TRIAL_FAILED returns go to
    ``session.resume``; failures raise ``SimulationError``, and so does keeping every step
    beyond ``budget.rows`` rows in all (``stored`` of them kept before): the step buffers
    never hold more than one row past the budget.
    Returns ``(status, step times, step rows, y, f)`` (status FINISHED or EVENT; ``y``,
    ``f``: the state the loop stopped at, which a restart may have replaced)."""
    p = kernel.p
    t_end, rtol, atol, max_step, method = float(options.t_end), options.rtol, options.atol, options.max_step, options.method
    n_steps = np.zeros(1, dtype=np.int64)
    if i_out is None:
        i_out = np.zeros(1, dtype=np.int64)
    chunks_t, chunks_y = [np.zeros(0)], [np.zeros((0, kernel.nq + kernel.nv + kernel.compiled.drives.nz))]
    cap, kept = 256, stored
    while True:
        if t_out is None:
            if budget is not None:
                if kept > budget.rows:
                    raise budget.exceeded(float(state[0]))
                cap = max(min(cap, budget.rows - kept + 1), 1)
            t_steps, y_steps = np.empty(cap), np.empty((cap, chunks_y[0].shape[1]))
            n_steps[0] = 0
            status = run(p.ctypes.data, tau_ptr, state.ctypes.data, y.ctypes.data, f.ctypes.data, t_end,
                         rtol, atol, max_step, None, 0, i_out.ctypes.data, None, t_steps.ctypes.data,
                         y_steps.ctypes.data, cap, n_steps.ctypes.data, counts.ctypes.data)
            chunks_t.append(t_steps[: n_steps[0]])
            chunks_y.append(y_steps[: n_steps[0]])
            kept += int(n_steps[0])
            if budget is not None and kept > budget.rows:
                raise budget.exceeded(float(state[0]))
        else:
            status = run(p.ctypes.data, tau_ptr, state.ctypes.data, y.ctypes.data, f.ctypes.data, t_end,
                         rtol, atol, max_step, t_out.ctypes.data, len(t_out), i_out.ctypes.data, y_out.ctypes.data,
                         None, None, 0, n_steps.ctypes.data, counts.ctypes.data)
        if status == BUFFER_FULL:
            cap = min(cap * 4, 1 << 20)
            continue
        if session is not None and status in (PAUSED, TRIAL_FAILED):
            y, f = session.resume(status, state, y, f, counts)
            continue
        if status in (FINISHED, EVENT):
            return status, np.concatenate(chunks_t), np.concatenate(chunks_y), y, f
        if status == STOPPED:
            hook.stopped(state[0], method)
        full = session is None or session.full_state_loop  # (the loop's y is [q, qd])
        try:
            _fail(kernel, status, state[0], y if full else np.concatenate(session.accepted()[1:]), method,
                  steps=int(counts[1]), t_end=t_end)
        except SimulationError as exc:
            extra = None if session is None else session.failure_hint(status)
            if extra:
                raise SimulationError(f"{exc}; {extra}") from None
            raise
