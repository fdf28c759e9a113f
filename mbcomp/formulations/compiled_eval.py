"""The evaluation calls' constrained solve in compiled code.

``System.accelerations`` and ``System.reactions`` (and the analyses built on them:
equilibrium, linearisation, modes, inverse dynamics) of a compiled model with constraints
solve the same KKT system the compiled loops solve (``c/dae.c``, ``dae_evaluate``: the
Schur-complement solve on the rows found independent when the model was analysed), one C
call per evaluation:

- the dae formulation with its Baumgarte gains (``DaeFormulation.acceleration_targets``);
- the lagrange formulation without them: its partitioned solve ``B^T M B qdd_i = B^T (f -
  M c)`` with ``J qdd = -bias`` is the KKT system's solution, and its least-norm
  multipliers are the KKT ones on independent rows.

``CompiledSolve.solve`` returns None where the C solve does not answer, and the caller then
takes the formulation's Python solve (which stays the oracle of the tests): a dead point at
rest whose motion is not determined (``RankLost`` in a run), a mass matrix that is not
positive definite, a non-finite result (the Python solve explains these).  At a singular
position in motion the C solve drops the lost row direction (``c/least_norm.h``) and answers
with the least-norm multipliers, numpy's ``lstsq`` answer.  Speed motors' rows use the
given start values (``offsets``) or, without one, a residual of zero, as the Python solve
treats a speed motor without a start value.
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.core.errors import ModelError, SimulationError
from mbcomp.core.tolerances import REST_SPEED
from mbcomp.codegen.expressions_c import fill_slots, python_positions
from mbcomp.formulations.compiled_watch import pointer
from mbcomp.formulations.dae_compiled import row_tables

_VOID, _INT, _DBL = ctypes.c_void_p, ctypes.c_int, ctypes.c_double


class CompiledSolve:
    """The compiled KKT solve of ``formulation`` (constraints, analysed) on ``kernel`` (its
    parameter values); ``gains``: the Baumgarte ``(alpha, beta)`` in 1/s ((0, 0): the exact
    constraint accelerations)."""

    def __init__(self, formulation, kernel, gains: tuple[float, float]):
        constraints = formulation.constraints
        self.kernel, self.nc = kernel, constraints.nc
        self.rows = np.asarray(formulation.nominal_rows, dtype=np.int64)
        #: (row k of the table, equation r, coordinate index, speed) of the speed motors
        self.speed_motors = []
        offsets = {}
        for k, r in enumerate(self.rows):
            speed = constraints.motor_speed(kernel, int(r)) if r in constraints.coordinate_rows else None
            if speed is not None:
                joint = constraints.equations[r].joint
                joint = joint if isinstance(joint, str) else joint.name
                self.speed_motors.append((k, int(r), kernel.topology.q_slice[joint].start, float(speed)))
                offsets[int(r)] = 0.0
        self.spec, self.data, self.programs = row_tables(formulation, kernel, self.rows, offsets)
        #: motors whose position is a Python callable: their values at each call's time
        self.constraints, self.python_rows = constraints, python_positions(constraints)
        self.alpha, self.beta = (float(g) for g in gains)
        self.scale = float(formulation.schur_scale)
        self.tol = float(formulation.singular_tolerance)
        lib = kernel.compiled.functions.lib
        self.fn = lib.dae_evaluate
        self.fn.argtypes = [_INT] + [_VOID] * 3 + [_DBL] * 4 + [_VOID, _VOID, _DBL] + [_VOID] * 5
        self.fn.restype = ctypes.c_int
        size = lib.rhs_work_size
        size.argtypes, size.restype = [], ctypes.c_long
        self.work_size = max(int(size()), 1)

    @classmethod
    def of(cls, formulation, kernel, gains: tuple[float, float]) -> "CompiledSolve | None":
        """The compiled solve, or None where there is none: no constraints, a model compiled
        without a C compiler, not analysed (a motor whose position is a Python callable is
        evaluated in Python at each call's time, its values passed as numbers)."""
        if formulation.constraints is None or kernel.backend != "c" or formulation.nominal_rows is None:
            return None
        if not hasattr(kernel.compiled.functions.lib, "dae_evaluate"):
            return None
        try:
            return cls(formulation, kernel, gains)
        except (ModelError, SimulationError):
            return None

    def solve(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None,
              offsets: dict | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """``(qdd, lam)`` at ``(t, q, qd)`` with the applied generalised forces ``tau`` (nv, or
        None), lam over every equation of the constraints (0 on the rows not solved for, as
        the Python solve leaves them); None where the Python solve must answer."""
        q = np.ascontiguousarray(q, dtype=float)
        qd = np.ascontiguousarray(qd, dtype=float)
        tau = None if tau is None else np.ascontiguousarray(tau, dtype=float)
        data = self.data
        if self.speed_motors:
            data = data.copy()  # (this call's start values: calls from threads do not share them)
            for k, r, i, speed in self.speed_motors:
                data[k, 1] = offsets[r] if offsets and r in offsets else q[i] - speed * t
        programs = self.programs
        if self.python_rows:  # (the callable motors' s, s', s'' at t, as Python stepping's: its errors)
            values = [v for r in self.python_rows for v in self.constraints.position_derivatives(r, float(t))]
            programs = fill_slots(programs, values)
        qdd = np.empty(len(qd))
        lam_rows = np.empty(max(len(self.rows), 1))
        work = np.empty(self.work_size)
        status = self.fn(len(self.rows), pointer(self.spec), pointer(data), pointer(programs), self.alpha,
                         self.beta, self.scale, self.tol, pointer(self.kernel.p), None if tau is None else pointer(tau),
                         float(t), pointer(q), pointer(qd), pointer(qdd), pointer(lam_rows), pointer(work))
        moving = float(np.max(np.abs(qd), initial=0.0)) > REST_SPEED
        if status not in (0, 2) or (status == 2 and not moving) or not (
                np.all(np.isfinite(qdd)) and np.all(np.isfinite(lam_rows))):
            # (2: a row direction dropped: in motion the least-norm answer, lstsq's; at rest a
            # dead point whose motion is not determined, which the Python solve explains)
            return None
        lam = np.zeros(self.nc)
        lam[self.rows] = lam_rows[:len(self.rows)]
        return qdd, lam
