"""scipy's stepping of the compiled right-hand side.

A scipy method (``RK45``, ``Radau``, ``BDF``, ``LSODA``, ...) asked for on a model that the
compiled loops could step evaluates the same C functions those loops step, one call per
evaluation, with no Python solve:

- the tree state ``[q, v]`` (no constraints, or the dae formulation): ``rhs_value`` of
  ``codegen/c/integrators.c``, the tree accelerations or the dae KKT solve on the rows that
  ``Formulation.compiled_setup`` (or, with contacts, the stretch's ``contact_run``) configures;
- the lagrange formulation's reduced state ``[x_i, qd_i]``: ``lagrange_rhs``, with the
  dependent coordinates from ``lagrange_full``; after each accepted step ``lagrange_accept``
  checks the dependent block, and a new partition is chosen as in the compiled loop
  (``ReducedRun.resume``).

Drive elements (motors, PIDs, signals): their states ``z`` follow the mechanical state in
``y`` (``[q, v, z]``, or ``[x_i, qd_i, z]``) and the same C functions give their rates, as in
the compiled loops; ``z`` (the workspace's attribute) holds the states of the last
``full_state``, the sample the driver records.

A stretch (``Stretch``) is what a formulation's ``scipy_stretch`` hook returns: the workspace
the solver steps (``workspace``) and ``close()``, which undoes the C configuration.
"""
from __future__ import annotations

import contextlib
import ctypes

import numpy as np

from mbcomp.codegen.callbacks import INPUT_FAILED, constant_tau, raise_pending
from mbcomp.codegen.integrators import PAUSED, TRIAL_FAILED, compiled_jacobian, rhs_failure
from mbcomp.core.errors import SimulationError, TrialStateError
from mbcomp.formulations.compiled_watch import pointer

_VOID, _DBL = ctypes.c_void_p, ctypes.c_double


class Stretch:
    """A workspace stepping compiled code, and the configuration to undo when it is done
    (``close``: a context's exit, or a compiled run's ``close``); ``jacobian``: the
    right-hand side's Jacobian ``jac(t, y)`` in compiled code for scipy's implicit methods
    (None: scipy's finite differences)."""

    def __init__(self, workspace, closing, jacobian=None):
        self.workspace = workspace
        self._closing = closing
        self.jacobian = jacobian

    def close(self) -> None:
        closing, self._closing = self._closing, None
        if closing is not None:
            closing()


def tree_stretch(formulation, kernel, workspace, tau, method: str, setup=None, z0=None) -> Stretch:
    """The tree-state workspace ``workspace`` stepping ``rhs_value``; ``setup``: the context
    (``compiled_setup``) that configures the C solve for it, entered here; ``z0``: the drive
    elements' states at the start (None: no drive elements)."""
    stack = contextlib.ExitStack()
    if setup is not None:
        stack.enter_context(setup)
    return Stretch(CompiledRhsWorkspace(workspace, kernel, tau, method, z0=z0), stack.close,
                   compiled_jacobian(kernel, tau))


def _states(z0) -> np.ndarray:
    return np.zeros(0) if z0 is None else np.array(z0, dtype=float).reshape(-1)


class CompiledRhsWorkspace:
    """A formulation workspace (``inner``) on the tree state whose right-hand side is the
    compiled ``rhs_value``; ``tau`` constant generalised forces (nv values or None); ``method``
    names the stepping in errors; ``z0`` the drive elements' states at the start (their
    rates come from ``rhs_value`` too: ``y = [q, v, z]``).  Everything else is the inner
    one's."""

    def __init__(self, inner, kernel, tau, method: str, failure=None, z0=None):
        object.__setattr__(self, "inner", inner)
        d = self.__dict__
        d["kernel"], d["method"] = kernel, method
        d["failure"] = failure  # () -> the error of a failed friction solve (Painleve) or None
        d["z"] = _states(z0)  #: the drive states of the last full_state (the sample's)
        d["m"] = inner.y0.size  # (the mechanical part of y)
        lib = kernel.compiled.functions.lib
        fn = lib.rhs_value
        fn.argtypes = [_VOID, _VOID, _DBL, _VOID, _VOID, _VOID]
        fn.restype = ctypes.c_int
        size = lib.rhs_work_size
        size.argtypes, size.restype = [], ctypes.c_long
        d["fn"], d["work"] = fn, np.zeros(max(int(size()), 1))
        d["tau_arr"] = constant_tau(tau)  # (a callable tau: the input callback's)
        d["tau_ptr"] = None if d["tau_arr"] is None else pointer(d["tau_arr"])

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value):
        setattr(self.inner, name, value)

    @property
    def y0(self) -> np.ndarray:
        return np.concatenate((self.inner.y0, self.z)) if self.z.size else self.inner.y0

    def full_state(self, t, y):
        if not self.z.size:
            return self.inner.full_state(t, y)
        self.__dict__["z"] = np.array(y[self.m:], dtype=float)
        return self.inner.full_state(t, y[:self.m])

    def after_step(self, t, y):
        if not self.z.size:
            return self.inner.after_step(t, y)
        corrected = self.inner.after_step(t, y[:self.m])
        return None if corrected is None else np.concatenate((corrected, y[self.m:]))

    def rhs(self, t, y):
        y = np.ascontiguousarray(y, dtype=float)
        f = np.empty_like(y)
        status = self.fn(pointer(self.kernel.p), self.tau_ptr, float(t), pointer(y), pointer(f), pointer(self.work))
        if status:
            error = None if self.failure is None else self.failure()
            if error is not None:
                raise error
            rhs_failure(self.kernel, status, float(t), y, f"{self.method} on the compiled right-hand side")
        return f


class CompiledReducedWorkspace:
    """The lagrange formulation's reduced state stepped through its compiled functions, on the
    configuration of a ``ReducedRun`` (``run``: partition, motors, held contacts).  The
    partition decisions are the run's (its Python workspace's ``repartition``), as in the
    compiled loop."""

    def __init__(self, run, method: str, z0=None):
        self.run, self.method = run, method
        lib = run.lib
        self.n, self.nq = run.n, run.nq
        self.z = _states(z0)  #: the drive states of the last full_state (the sample's)
        if self.z.size:
            run.drive_states(self.z)  # (the accepted state's: a retreat goes back to them)
        self._rhs = lib.lagrange_rhs
        self._rhs.argtypes, self._rhs.restype = [_DBL, _VOID, _VOID, _VOID, _VOID], ctypes.c_int
        self._full = lib.lagrange_full
        self._full.argtypes, self._full.restype = [_DBL, _VOID, _VOID, _VOID, _VOID], ctypes.c_int
        self._accept = lib.lagrange_accept
        self._accept.argtypes, self._accept.restype = [_DBL, _VOID, _VOID, _VOID], ctypes.c_int
        self._span = lib.lagrange_span
        self._span.argtypes, self._span.restype = [_DBL, _VOID, _VOID], ctypes.c_int
        self._tau = None if run.tau is None else pointer(run.tau)
        self.q_out, self.qd_out = np.zeros(self.nq), np.zeros(self.n)

    # -- what the driver and scipy's stepping read ------------------------------------------------
    @property
    def y0(self) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate((self.run.y0, self.z)), dtype=float)

    @property
    def offsets(self):
        return self.run.workspace.offsets

    @offsets.setter
    def offsets(self, value) -> None:
        self.run.workspace.offsets = value

    @property
    def contacts(self):
        return self.run.contacts

    def _trial_failed(self, t: float, what: str):
        self.run.check_motors()  # (a motor's law that was not finite: its own error)
        return TrialStateError(f"dependent coordinates cannot be found at t = {t:.6g} s ({what}): constraints "
                               f"{self.run.formulation.row_names(self.run.rows, self.run.contacts)}")

    def rhs(self, t, y):
        y = np.ascontiguousarray(y, dtype=float)
        f = np.empty_like(y)
        status = self._rhs(float(t), pointer(y), pointer(f), pointer(self.run.kernel.p), self._tau)
        if status == INPUT_FAILED:
            raise_pending()  # (a Python callable's exception)
        if status:
            error = self.run.friction_failure()  # (a failed friction solve: Painleve)
            if error is not None:
                raise error
        if status == TRIAL_FAILED:
            raise self._trial_failed(float(t), "a trial state")
        if status:
            raise SimulationError(f"the reduced mass matrix is not positive definite at t = {t:.6g} s")
        return f

    def full_state(self, t, y):
        y = np.ascontiguousarray(y, dtype=float)
        if self.z.size:
            self.z = np.array(y[len(y) - self.z.size:])
        q, qd = np.empty(self.nq), np.empty(self.n)
        if self._full(float(t), pointer(y), pointer(q), pointer(qd), pointer(self.run.kernel.p)):
            raise self._trial_failed(float(t), "a sample")
        return q, qd

    def span(self, t_end: float, y_end: np.ndarray) -> None:
        y = np.ascontiguousarray(y_end, dtype=float)
        if self._span(float(t_end), pointer(y), pointer(self.run.kernel.p)):
            raise self._trial_failed(float(t_end), "a step's end")

    def end_span(self) -> None:
        self.run.lib.lagrange_span_end()

    def normalize(self, y) -> None:
        return None  # the chart keeps quaternions at unit length

    def after_step(self, t, y):
        """The accepted state becomes the predictor's start; a new partition (or a re-centred
        chart) when the dependent block's condition reached the limit: the state in the new
        coordinates (the solver restarts there), else None."""
        y = np.ascontiguousarray(y, dtype=float)
        status = self._accept(float(t), pointer(y), None, pointer(self.run.kernel.p))
        if status == TRIAL_FAILED:
            raise self._trial_failed(float(t), "an accepted state")
        if status != PAUSED:
            return None
        state = np.array([float(t), 0.0])
        y_new, _ = self.run.resume(PAUSED, state, y, None, np.zeros(3, dtype=np.int64))
        return None if y_new is y else y_new

    def retreat(self):
        """``(t, y)`` of the last accepted state, the partition chosen afresh there."""
        self.run.sync()
        z = self.run.accepted_states()
        t_back, y_back = self.run.workspace.retreat()
        self.run.reconfigure()
        return t_back, np.concatenate((y_back, z))
