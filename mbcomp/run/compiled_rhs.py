"""scipy's stepping of the compiled right-hand side.

A scipy method (``RK45``, ``Radau``, ``BDF``, ``LSODA``, ...) asked for on a model that the
compiled loops could step evaluates the same C function those loops step (``rhs_value`` in
``codegen/c/integrators.c``: the tree accelerations, or the dae formulation's KKT solve on
the rows ``Formulation.compiled_setup`` configures): one call per evaluation, no Python
solve.  The formulation's own workspace still gives the start state, the coordinates of a
sample and the quaternion normalisation.
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.codegen.integrators import rhs_failure

_VOID, _DBL = ctypes.c_void_p, ctypes.c_double


def bind_rhs_value(lib):
    """``rhs_value(p, tau, t, y, f, work)`` of a compiled library, with its argument types,
    and the work size it needs (doubles)."""
    fn = lib.rhs_value
    fn.argtypes = [_VOID, _VOID, _DBL, _VOID, _VOID, _VOID]
    fn.restype = ctypes.c_int
    size = lib.rhs_work_size
    size.argtypes, size.restype = [], ctypes.c_long
    return fn, int(size())


class CompiledRhsWorkspace:
    """A formulation workspace (``inner``) whose right-hand side is the compiled one; ``tau``
    constant generalised forces (nv values or None); ``method`` names the stepping in errors.
    Everything else is the inner one's."""

    def __init__(self, inner, kernel, tau, method: str):
        object.__setattr__(self, "inner", inner)
        d = self.__dict__
        d["kernel"], d["method"] = kernel, method
        d["fn"], size = bind_rhs_value(kernel.compiled.functions.lib)
        d["work"] = np.zeros(max(size, 1))
        d["p"] = kernel.p
        d["tau_arr"] = None if tau is None else np.ascontiguousarray(tau, dtype=float)
        d["tau_ptr"] = None if d["tau_arr"] is None else d["tau_arr"].ctypes.data

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value):
        setattr(self.inner, name, value)

    def rhs(self, t, y):
        y = np.ascontiguousarray(y, dtype=float)
        f = np.empty_like(y)
        status = self.fn(self.p.ctypes.data, self.tau_ptr, float(t), y.ctypes.data, f.ctypes.data,
                         self.work.ctypes.data)
        if status:
            rhs_failure(self.kernel, status, float(t), y, f"{self.method} on the compiled right-hand side")
        return f
