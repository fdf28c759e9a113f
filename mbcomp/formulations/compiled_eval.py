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
from mbcomp.formulations.friction import has_friction, plane_contact_rows
from mbcomp.formulations.friction_c import FrictionRows, compiled_friction_problem

_VOID, _INT, _DBL = ctypes.c_void_p, ctypes.c_int, ctypes.c_double


class CompiledSolve:
    """The compiled KKT solve of ``formulation`` (constraints, analysed) on ``kernel`` (its
    parameter values); ``gains``: the Baumgarte ``(alpha, beta)`` in 1/s ((0, 0): the exact
    constraint accelerations)."""

    def __init__(self, formulation, kernel, gains: tuple[float, float], contacts: tuple = (), q=None, qd=None):
        constraints = formulation.constraints
        self.kernel = kernel
        self.nc = 0 if constraints is None else constraints.nc
        self.contacts = tuple(int(i) for i in contacts)
        self.friction = has_friction(contacts)
        own = np.asarray(formulation.nominal_rows if constraints is not None else [], dtype=np.int64)
        held = self.nc + np.arange(len(self.contacts), dtype=np.int64)
        # (with friction every row, as the Python path's least-norm friction solve)
        self.rows = np.arange(self.nc + len(self.contacts), dtype=np.int64) if self.friction \
            else np.concatenate((own, held))
        #: (row k of the table, equation r, coordinate index, speed) of the speed motors
        self.speed_motors = []
        offsets = {}
        for k, r in enumerate(self.rows):
            speed = constraints.motor_speed(kernel, int(r)) if r < self.nc and r in constraints.coordinate_rows \
                else None
            if speed is not None:
                joint = constraints.equations[r].joint
                joint = joint if isinstance(joint, str) else joint.name
                self.speed_motors.append((k, int(r), kernel.topology.q_slice[joint].start, float(speed)))
                offsets[int(r)] = 0.0
        self.spec, self.data, self.programs = row_tables(formulation, kernel, self.rows, offsets, self.contacts)
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
        #: the held contacts' world bases (rows n, t1, t2): fixed for points on world planes
        #: (None where another source gives contact rows, mb.Collision's: per call)
        self.basis = None
        if self.contacts and q is not None and getattr(kernel, "tangent_rows", None) is None:
            self.basis = plane_contact_rows(kernel, np.asarray(q, dtype=float), np.asarray(qd, dtype=float),
                                            self.contacts, normal_rows=False).basis
        self.friction_rows = None
        if self.friction:  # the held contacts' friction modes (friction.h), passed with each call
            self.friction_rows = FrictionRows(kernel, lib, contacts, {i: self.nc + r for r, i in enumerate(self.contacts)},
                                              len(self.rows), np.asarray(q, dtype=float), np.asarray(qd, dtype=float),
                                              configure=False)
            self.fn = lib.dae_evaluate_friction
            self.fn.argtypes = [_INT, _INT] + [_VOID] * 4 + [_INT] + [_VOID] * 3 + [_DBL] * 4 + [_VOID, _VOID, _DBL] \
                + [_VOID] * 5
            self.fn.restype = ctypes.c_int

    @classmethod
    def of(cls, formulation, kernel, gains: tuple[float, float], contacts: tuple = (), q=None,
           qd=None) -> "CompiledSolve | None":
        """The compiled solve, or None where there is none: no constraints and no held
        contacts, a model compiled without a C compiler, not analysed (a motor whose position
        is a Python callable is evaluated in Python at each call's time, its values passed as
        numbers).  ``contacts``: the held contacts (indices, or a ``friction.Closed`` with
        friction modes; ``q, qd``: a state of the call, for its friction rows).  With held
        contacts there is none where the Python solve chooses rows the C solve does not hold:
        a model whose own rows are redundant (without friction), a collision feature,
        friction the compiled loops do not take (``friction_c.compiled_friction_problem``)."""
        constraints = formulation.constraints
        if (constraints is None and not contacts) or kernel.backend != "c":
            return None
        if constraints is not None and formulation.nominal_rows is None:
            return None
        lib = kernel.compiled.functions.lib
        if not hasattr(lib, "dae_evaluate"):
            return None
        if contacts:
            own = getattr(kernel, "n_own", len(kernel.topology.contacts))
            if any(int(i) >= own or getattr(kernel.topology.contacts[int(i)], "kind", "") == "collision"
                   for i in contacts):
                return None
            if has_friction(contacts):
                if q is None or not hasattr(lib, "dae_evaluate_friction") or \
                        compiled_friction_problem(kernel, formulation) is not None:
                    return None
            elif constraints is not None and len(formulation.nominal_rows) < constraints.nc:
                return None
        try:
            return cls(formulation, kernel, gains, contacts, q, qd)
        except (ModelError, SimulationError):
            return None

    def solve(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None,
              offsets: dict | None = None) -> tuple[np.ndarray, np.ndarray] | None:
        """``(qdd, lam)`` at ``(t, q, qd)`` with the applied generalised forces ``tau`` (nv, or
        None), lam over every equation of the constraints, then each held contact's normal
        row (0 on the rows not solved for, as the Python solve leaves them); None where the
        Python solve must answer."""
        solved = self.solution(t, q, qd, tau, offsets)
        return None if solved is None else solved[:2]

    def solution(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None, offsets: dict | None = None,
                 contacts: tuple = ()) -> tuple[np.ndarray, np.ndarray, dict] | None:
        """``(qdd, lam, tangential)`` as ``solve``, with ``tangential`` the friction force (N,
        on the body, in the tangent coordinates of ``friction.plane_contact_rows``' basis) of
        each held contact with a friction mode, as ``friction.friction_solve`` returns it.
        ``contacts``: the call's closed set (its sliding contacts' slip directions; the
        solve's own when not given)."""
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
        args = (len(self.rows), pointer(self.spec), pointer(data), pointer(programs), self.alpha,
                self.beta, self.scale, self.tol, pointer(self.kernel.p), None if tau is None else pointer(tau),
                float(t), pointer(q), pointer(qd), pointer(qdd), pointer(lam_rows), pointer(work))
        rows = self.friction_rows
        if rows is None:
            status = self.fn(*args)
        else:  # (this call's arrays: calls from threads do not share them)
            fdata, out = rows.data.copy(), np.zeros_like(rows.out)
            slip = getattr(contacts, "slip", None) or {}
            for j, i in enumerate(rows.indices):
                if i in slip:
                    fdata[j, 17:20] = slip[i]
            scratch, fail = np.zeros_like(rows.scratch), np.zeros(4)
            status = self.fn(len(rows.indices), rows.cap, pointer(fdata), pointer(out), pointer(scratch),
                             pointer(fail), *args)
        moving = float(np.max(np.abs(qd), initial=0.0)) > REST_SPEED
        if status not in (0, 2) or (status == 2 and (not moving or self.contacts)) or not (
                np.all(np.isfinite(qdd)) and np.all(np.isfinite(lam_rows))):
            # (2: a row direction dropped: in motion the least-norm answer, lstsq's; at rest a
            # dead point whose motion is not determined, which the Python solve explains; with
            # held contacts the Python solve's rows are its pivoted QR's.  A failed friction
            # solve, Painleve's paradox or inconsistent rows: the Python solve names the contact)
            return None
        lam = np.zeros(self.nc + len(self.contacts))
        lam[self.rows] = lam_rows[:len(self.rows)]
        tangential = {} if rows is None else {i: out[j, 0:2].copy() for j, i in enumerate(rows.indices)}
        return qdd, lam, tangential
