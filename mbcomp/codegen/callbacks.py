"""Python callables called back from compiled loops: callable forces and torques, a callable
``tau`` and drive signals given as Python functions.

The compiled right-hand side (``c/inputs.h``) copies the state ``[q, qd, z]`` of each
evaluation into a buffer this module owns and calls one C callback (a ctypes ``CFUNCTYPE``
trampoline, which takes the GIL) with the time; the callback evaluates the model's callables
there and writes their values where the generated code reads them: the input vector ``u`` of
the callable forces, the values of a callable ``tau`` (added to the constant one), and the
values of callable drive signals (after the states in the drive input vector).  So every
stage, dense-output stage and event-location evaluation of a compiled loop sees the values
the Python path would compute at the same state.

Motors whose position is a Python callable (``expressions_c.position_programs``: their
programs read slots) have a second callback: whatever C code evaluates the motor rows at a
new time (a right-hand side, a Newton solve, an event locator) calls it once with that
time, and it writes ``s, s', s''`` of each such motor (``ConstraintSet.position_derivatives``,
the values Python stepping uses: exact derivatives where the position has them, else the
same finite differences) where the slots are read (``c/inputs.h``, ``mb_motor_slot``).

An exception cannot cross the C loop: the callback keeps it, returns a failure status that
stops the loop (``INPUT_FAILED``), and ``raise_pending`` re-raises it in Python with a note
naming the callable and the time.  A callable returning a wrong number of values or a
non-finite one raises the same ``SimulationError`` as on the Python path
(``forces.checked_output``); a callable motor's failure raises the ``SimulationError`` of
``ConstraintSet.position_derivatives``, Python stepping's, naming the motor and the time.
"""
from __future__ import annotations

import contextlib
import ctypes
import threading
from typing import Any, Iterator

import numpy as np

from mbcomp.core.errors import describe
from mbcomp.codegen.expressions_c import python_positions
from mbcomp.spec.components.forces import checked_output

#: The compiled loops' status when a callable failed (``MB_INPUT_FAILED`` of ``c/inputs.h``).
INPUT_FAILED = -9

_HOOK_TYPE = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_double)
_local = threading.local()  # this thread's active InputHook


def has_callables(kernel, tau: Any = None) -> bool:
    """Whether a run of ``kernel`` with ``tau`` needs a callback: callable forces or
    torques, callable drive signals, a callable ``tau``, or a motor whose position is a
    Python callable."""
    return bool(kernel.n_inputs or kernel.compiled.drives.callables or callable(tau)
                or python_positions(kernel.compiled.constraint_set))


class InputHook:
    """The callables of one run of ``kernel`` (``tau``: the user's, None, an array or a
    callable) and the buffers the compiled code shares with them.

    ``error``: the exception a callable raised (then every later call fails at once, so
    the loop stops at its next evaluation whichever caller ignored the first failure)."""

    def __init__(self, kernel, tau: Any = None):
        topology, drives = kernel.topology, kernel.compiled.drives
        self.nq, self.nv, self.nz = kernel.nq, kernel.nv, drives.nz
        self.state = np.zeros(self.nq + self.nv + self.nz + 1)
        self.inputs = [(topology.components[name], start, size) for name, (start, size)
                       in kernel.compiled.inputs.items()]
        self.u = np.zeros(kernel.n_inputs) if kernel.n_inputs else None
        self.tau = tau if callable(tau) else None
        self.tau_values = np.zeros(max(self.nv, 1)) if self.tau is not None else None
        self.signals = tuple(drives.callables)
        self.du = np.zeros(drives.n_u) if self.signals else None
        #: the callable motors (in slot order) and their values s, s', s'' (3 a motor)
        self.constraints = kernel.compiled.constraint_set
        self.motor_rows = python_positions(self.constraints)
        self.motor_values = np.zeros(3 * len(self.motor_rows) + 1)
        #: whether the model's other callables need the per-evaluation callback
        self.inputs_on = bool(self.inputs or self.tau is not None or self.signals)
        self.error: BaseException | None = None
        self.where = ""  # which callable raised, at what time
        self.outer: "InputHook | None" = None
        self.lib = kernel.compiled.functions.lib

    def __call__(self, t: float) -> int:
        if self.error is not None:
            return 1
        owner: Any = None
        try:
            nq, nv = self.nq, self.nv
            q, qd = self.state[:nq].copy(), self.state[nq:nq + nv].copy()
            for comp, start, size in self.inputs:
                owner = comp
                self.u[start:start + size] = comp.evaluate_input(t, q, qd, size)
            if self.tau is not None:
                owner = "tau"
                self.tau_values[:nv] = checked_output("tau", self.tau(t, q, qd), nv)
            base = 1 + self.nz
            for k, signal in enumerate(self.signals):
                owner = signal
                self.du[base + k] = signal.evaluate(t, q, qd)
            return 0
        except BaseException as exc:  # noqa: BLE001 - kept, re-raised by raise_pending
            self.error = exc
            name = owner if isinstance(owner, str) else (
                f"signal {owner.describe()}" if owner in self.signals else describe(owner))
            self.where = f"raised by the callable of {name} at t = {t:.6g} s, called from compiled code"
            return 1

    def motors(self, t: float) -> int:
        """The motor callback: ``s, s', s''`` of every callable motor at ``t`` (s) into
        ``motor_values``; 0, or 1 when a position failed (its ``SimulationError`` kept)."""
        if self.error is not None:
            return 1
        try:
            values = self.motor_values
            for j, r in enumerate(self.motor_rows):
                values[3 * j:3 * j + 3] = self.constraints.position_derivatives(r, t)
            return 0
        except BaseException as exc:  # noqa: BLE001 - kept, re-raised by raise_pending
            self.error = exc  # (names the motor and the time, as Python stepping's)
            self.where = ""
            return 1

    def pointers(self):
        """The arguments of ``set_input_hook`` after the callback: the buffers' addresses."""
        def address(a):
            return None if a is None else a.ctypes.data
        return self.state.ctypes.data, address(self.u), address(self.tau_values), address(self.du)

    def raise_pending(self) -> None:
        """Raise the exception a callable raised (with a note saying which and when), once."""
        error, self.error = self.error, None
        if error is not None:
            note = self.where
            if note and note not in getattr(error, "__notes__", ()):
                error.add_note(note)
            raise error


def _dispatch(t: float) -> int:
    """The one C callback: this thread's active ``InputHook``."""
    hook = getattr(_local, "active", None)
    return 1 if hook is None else hook(t)


def _dispatch_motors(t: float) -> int:
    """The motor callback: this thread's active ``InputHook``'s callable motors."""
    hook = getattr(_local, "active", None)
    return 1 if hook is None else hook.motors(t)


_TRAMPOLINE = _HOOK_TYPE(_dispatch)
_MOTOR_TRAMPOLINE = _HOOK_TYPE(_dispatch_motors)
_NO_HOOK = _HOOK_TYPE()


def _setter(lib):
    setter = lib.set_input_hook
    if setter.restype is not None:
        setter.argtypes = [_HOOK_TYPE, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        setter.restype = None
    return setter


def _motor_setter(lib):
    setter = getattr(lib, "set_motor_hook", None)
    if setter is not None and setter.restype is not None:
        setter.argtypes = [_HOOK_TYPE, ctypes.c_void_p]
        setter.restype = None
    return setter


def _install(lib, hook: "InputHook | None") -> None:
    motors = _motor_setter(lib)
    if hook is None:
        _setter(lib)(_NO_HOOK, None, None, None, None)
        if motors is not None:
            motors(_NO_HOOK, None)
        return
    if hook.inputs_on:
        _setter(lib)(_TRAMPOLINE, *hook.pointers())
    else:
        _setter(lib)(_NO_HOOK, None, None, None, None)
    if motors is not None:
        if hook.motor_rows:
            motors(_MOTOR_TRAMPOLINE, hook.motor_values.ctypes.data)
        else:
            motors(_NO_HOOK, None)


@contextlib.contextmanager
def input_hook(kernel, tau: Any = None) -> Iterator["InputHook | None"]:
    """Within the block, the compiled code of ``kernel`` run by this thread evaluates the
    model's Python callables (and a callable ``tau``) through the callback; yields the hook,
    or None when there is nothing to call back (the block then changes nothing).  A
    callable's exception that the block's code did not raise is raised at its end."""
    if not has_callables(kernel, tau) or kernel.backend != "c":
        yield None
        return
    lib = kernel.compiled.functions.lib
    hook = InputHook(kernel, tau)
    hook.outer = getattr(_local, "active", None)
    _local.active = hook
    _install(lib, hook)
    _step_watch(lib, True)
    try:
        yield hook
    finally:
        _local.active = hook.outer
        outer = hook.outer if hook.outer is not None and hook.outer.lib is lib else None
        _install(lib, outer)  # (a nested run of the same model: the outer run's buffers again)
        _step_watch(lib, outer is not None)
        hook.outer = None
    hook.raise_pending()


#: The compiled loops' collapse check with callbacks: each step calls Python, so a runaway
#: gives up as early as a Python-stepped run (``integrators.CollapseWatch``: a hundredth of
#: ``limits.max_steps()``, windows of 1000 steps, and the rule on a pace that fell a hundredfold).
PYTHON_BUDGET, PYTHON_WINDOW = 0.01, 1000


def _step_watch(lib, python: bool) -> None:
    """This thread's collapse check of the compiled loops: the Python-stepped one
    (``python``) or the compiled loops' own (``integrators._set_step_budget``)."""
    from mbcomp.core.limits import max_steps
    budget, watch = getattr(lib, "set_step_budget", None), getattr(lib, "set_step_watch", None)
    if budget is None or watch is None:
        return
    if budget.restype is not None:
        budget.argtypes, budget.restype = [ctypes.c_double], None
    if watch.restype is not None:
        watch.argtypes, watch.restype = [ctypes.c_long, ctypes.c_int], None
    budget(float(max_steps()) * (PYTHON_BUDGET if python else 1.0))
    watch(PYTHON_WINDOW if python else 0, int(python))


def constant_tau(tau: Any) -> np.ndarray | None:
    """The constant generalised forces the compiled code takes as an argument (nv values):
    ``tau`` as a contiguous array, or None when it is None or a callable (whose values the
    callback adds at every evaluation)."""
    return None if tau is None or callable(tau) else np.ascontiguousarray(tau, dtype=float)


def raise_pending() -> None:
    """Raise the exception a callable of this thread's active hook raised, if any (the first
    thing to look at when a compiled loop or right-hand side returned a failure)."""
    hook = getattr(_local, "active", None)
    if hook is not None:
        hook.raise_pending()


def python_watch() -> tuple[int, float] | None:
    """``(window, budget)`` of the collapse check the compiled loops of this thread run with
    while a hook is active (the Python-stepped one), or None without a hook."""
    if getattr(_local, "active", None) is None:
        return None
    from mbcomp.core.limits import max_steps
    return PYTHON_WINDOW, max_steps() * PYTHON_BUDGET
