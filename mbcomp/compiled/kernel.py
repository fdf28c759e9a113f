"""Kernel: the numeric core of one compiled model with one set of parameter values.

Calls into the generated functions on the packed parameter vector, decodes their outputs,
solves the tree's ``M v' = f`` and explains failures (singular mass matrix, non-finite
values).  Formulations, contacts, integrators and derived series use it; it knows nothing
about formulations.  ``System`` is the public façade on top of it.
"""
from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping

import numpy as np

from mbcomp.spec.components.forces import checked_output
from mbcomp.build.constraint_set import ConstraintValues
from mbcomp.core.errors import ModelError, SimulationError, describe, format_state
from mbcomp.build.layout import body_fields
from mbcomp.core.small_linalg import lapack_routine
from mbcomp.core.tolerances import PIVOT_TOLERANCE

#: A pivot of the mass matrix's Cholesky factor below this fraction of its largest diagonal
#: entry counts as singular (the same threshold as the compiled ``accelerations``).
SINGULAR_PIVOT = PIVOT_TOLERANCE


class Kernel:
    """Numeric calls on a compiled model (``compiled``) with parameter values ``parameters``.

    Inputs are raw: ``q`` (nq,), ``qd`` (nv,) float arrays already checked by the caller.
    Immutable: ``with_parameters`` gives a new kernel sharing the compiled code.
    """

    def __init__(self, compiled: Any, parameters: Mapping[str, Any]):
        self.compiled = compiled
        self.topology = compiled.topology
        self.parameters = MappingProxyType(dict(parameters))
        p = compiled.layout.pack(dict(parameters))
        p.flags.writeable = False
        self.p = p
        self.nq = compiled.topology.nq
        self.nv = compiled.topology.nv
        self.n_inputs = compiled.n_inputs
        self.layout = compiled.output_layout
        self._pointer = None  # the parameter vector's ctypes pointer, bound on first compiled call
        self._fast = None     # fast_calls(), built on first use

    def with_parameters(self, parameters: Mapping[str, Any]) -> "Kernel":
        return Kernel(self.compiled, parameters)

    @property
    def backend(self) -> str:
        """``"c"`` or ``"python"``: where the generated functions run."""
        return self.compiled.functions.name

    # -- inputs ------------------------------------------------------------------------------
    def inputs(self, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """Values of the callable inputs (joint torques, forces given as functions) at a state."""
        if not self.n_inputs:
            return self.compiled.no_inputs
        u = np.zeros(self.n_inputs)
        for name, (start, size) in self.compiled.inputs.items():
            u[start:start + size] = self.topology.components[name].evaluate_input(t, q, qd, size)
        return u

    def tau(self, tau: Any, t: float, q: np.ndarray, qd: np.ndarray) -> np.ndarray | None:
        """Extra generalised forces ``tau`` (None, an array of nv, or a callable ``(t, q, qd)``)
        as a checked array (None stays None)."""
        if tau is None:
            return None
        if callable(tau):
            return checked_output("tau", tau(t, q, qd), self.nv)
        try:
            arr = np.asarray(tau, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ModelError("tau", f"must be {self.nv} finite numbers (one per speed), got {tau!r}") from None
        if arr.shape != (self.nv,) or not np.isfinite(arr).all():
            raise ModelError("tau", f"must be {self.nv} finite numbers (one per speed), got {tau!r}")
        return arr

    # -- generated functions ---------------------------------------------------------------------
    def call(self, name: str, q: np.ndarray, qd: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        """The packed output of generated function ``name`` (``dynamics``, ``energy``,
        ``kinematics``, ``constraints``, ``contacts``)."""
        if u is None:
            u = np.zeros(self.n_inputs)
        return self.compiled.functions(name, q, qd, self.p, u)

    def dynamics(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None = None):
        """Tree mass matrix ``M`` (nv, nv) and generalised forces ``f`` (+ tau): ``M qdd = f``."""
        out = self.layout.unpack("dynamics", self.call("dynamics", q, qd, self.inputs(t, q, qd)))
        f = out["forces"]
        return out["mass_matrix"], (f if tau is None else f + tau)

    def checked_dynamics(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None = None):
        """``dynamics`` with a ``SimulationError`` explaining any non-finite entry."""
        M, f = self.dynamics(t, q, qd, tau)
        self.check_finite(M, "mass matrix", q)
        self.check_finite(f, "generalised forces", q)
        return M, f

    def energy(self, q: np.ndarray, qd: np.ndarray) -> tuple[float, float]:
        """``(kinetic, potential)`` energy, J (potential: gravity and springs)."""
        out = self.layout.unpack("energy", self.call("energy", q, qd))
        return float(out["kinetic"]), float(out["potential"])

    def compiled_stretch(self, lib, q: np.ndarray, qd: np.ndarray, held=()):
        """What a compiled stretch of contact watching configures beyond the model's own
        contacts (a ``CollisionKernel``'s collision features); None here."""
        return None

    def kinematics(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per body rows (``layout.BODY_FIELDS``: rotation, origin, velocity ``(w, v0)``,
        acceleration bias; split them with ``layout.body_fields``), and the world-frame motion
        columns ``S_k = (w_k, v0_k)`` of every speed (nv, 6)."""
        out = self.layout.unpack("kinematics", self.call("kinematics", q, qd))
        return out["bodies"], out["columns"]

    def point_position(self, body: Any, local: Any, q: np.ndarray) -> np.ndarray:
        """World position (m) of a body point given in the body frame, from the kinematics."""
        comp = self.topology.resolve(body)
        local = np.asarray(local, dtype=float)
        if comp is self.topology.ground:
            return local
        row = body_fields(self.kinematics(q, np.zeros(self.nv))[0][self.topology.body_index(comp)])
        return row["origin"] + row["rotation"] @ local

    def contacts(self, q: np.ndarray, qd: np.ndarray) -> ConstraintValues:
        """Gaps (m), gap Jacobian (nk, nv) and gap acceleration bias of every contact."""
        out = self.layout.unpack("contacts", self.call("contacts", q, qd))
        nk = len(out["gap"])
        return ConstraintValues(out["gap"].copy(), out["jacobian"], np.zeros(nk), out["bias"].copy())

    def constraints(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Residuals (ng,), Jacobian (ng, nv) and acceleration bias (ng,) of the geometric
        constraint equations (loops and sliders)."""
        out = self.layout.unpack("constraints", self.call("constraints", q, qd))
        return out["residual"], out["jacobian"], out["bias"]

    def evaluate_series(self, name: str, q: np.ndarray, qd: np.ndarray | None = None) -> np.ndarray:
        """The generated function ``name`` at many states (rows of ``q`` (m, nq) and ``qd``
        (m, nv); zero speeds when None) in one call: (m, size)."""
        q = np.asarray(q, dtype=float)
        qd = np.zeros((len(q), self.nv)) if qd is None else np.asarray(qd, dtype=float)
        return self.compiled.functions.many(name, q, qd, self.p, np.zeros(self.n_inputs))

    def drive_outputs(self, t: float, q: np.ndarray, qd: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(tau_drive, z_rates)``: the drive elements' generalised forces (nv) and the rates
        of their states (nz) at time ``t`` (s), with states ``z`` (raw arrays: the hot path)."""
        drives = self.compiled.drives
        out = self.layout.unpack("drives", self.call("drives", q, qd, drives.inputs(t, z, q, qd)))
        total = float(out["forces"].sum() + out["rates"].sum())
        if total - total != 0.0:
            raise SimulationError(f"drive forces or state rates are not finite at t = {t:.6g} s, q = "
                                  f"{format_state(q)}, states {format_state(z)}")
        return out["forces"], out["rates"]

    def fast_calls(self):
        """Direct calls of the compiled ``accelerations``, mass matrix and body kinematics on
        the caller's own arrays (``mbcomp.codegen.fastcall``: each returns None where the inputs or
        the result need a checked path), or None where they do not apply: the Python backend,
        or callable inputs (their values depend on t).  Built on first use, then shared."""
        fast = self._fast
        if fast is None:
            if self.backend != "c" or self.n_inputs:
                fast = False
            else:
                from mbcomp.codegen.fastcall import calls
                fast = calls(self.compiled.functions, self.layout, self.p, self.nq, self.nv)
            self._fast = fast
        return fast or None

    # -- the tree solve ----------------------------------------------------------------------------
    @staticmethod
    def cholesky(M: np.ndarray) -> np.ndarray | None:
        """Lower Cholesky factor of a small symmetric matrix, or None when it is not positive
        definite.  LAPACK's ``dpotrf`` directly: numpy's wrapper costs 6 us per call on a 3 x 3
        matrix, this 1 us, and the scipy-stepped right-hand side factors twice per evaluation."""
        if M.size == 0:
            return M.copy()
        L, info = lapack_routine("potrf")(M, lower=1, clean=1)
        return L if info == 0 else None

    def factor(self, M: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Lower Cholesky factor of ``M``, or a ``SimulationError`` naming why M is singular."""
        L = self.cholesky(M)
        scale = max(float(np.abs(M.diagonal()).max()), 1e-300) if M.size else 1.0
        if L is None or (M.size and L.diagonal().min() ** 2 < SINGULAR_PIVOT * scale):
            raise SimulationError(f"mass matrix is singular at q = {format_state(q)}: {self.diagnose(q)}")
        return L

    @staticmethod
    def inverse(L: np.ndarray) -> np.ndarray:
        """``M^-1`` from its Cholesky factor (small dense matrices: cheaper than repeated solves);
        the triangular inverse by LAPACK's ``dtrtri`` (1 us against numpy's 8 us for 3 x 3)."""
        if L.size == 0:
            return L.copy()
        Linv, _ = lapack_routine("trtri")(L, lower=1)
        return Linv.T @ Linv

    def tree_solve(self, M: np.ndarray, f: np.ndarray, q: np.ndarray) -> np.ndarray:
        """``M^-1 f`` by Cholesky, or a ``SimulationError`` naming why M is singular."""
        L = self.factor(M, q)
        return np.linalg.solve(L.T, np.linalg.solve(L, f))

    def tree_accelerations(self, t: float, q: np.ndarray, qd: np.ndarray, tau: np.ndarray | None) -> np.ndarray:
        """Unconstrained tree accelerations (in compiled code when the backend has it)."""
        functions = self.compiled.functions
        if functions.accelerations is None:
            return self.tree_solve(*self.checked_dynamics(t, q, qd, tau), q)
        u = self.inputs(t, q, qd)
        if self._pointer is None:
            self._pointer = functions.bind_parameters(self.p)
        status, out = functions.accelerations(q, qd, self._pointer, u, tau)
        total = float(out.sum())
        if status or total - total != 0.0:  # NaN or inf somewhere
            return self.tree_solve(*self.checked_dynamics(t, q, qd, tau), q)  # raises with a diagnosis
        return out

    # -- explaining failures -------------------------------------------------------------------------
    def diagnose(self, q: np.ndarray) -> str:
        """Name the components that can make the tree mass matrix singular at ``q``."""
        hints = []
        for joint in self.topology.tree_joints:
            hint = joint.singularity(q[self.topology.q_slice[joint.name]])
            if hint:
                hints.append(hint)
        return "; ".join(hints) if hints else "check for massless bodies or bodies without inertia on rotating joints"

    def check_finite(self, values: np.ndarray, what: str, q: np.ndarray) -> np.ndarray:
        """``values`` unchanged, or a ``SimulationError`` naming what made them non-finite."""
        if not np.isfinite(values).all():
            springs = []
            for comp in self.topology.forces:
                ends = comp.line_ends()  # elements acting along a line between two points
                if ends is not None:
                    (body_a, key_a), (body_b, key_b) = ends
                    pa = self.point_position(body_a, self.parameters[key_a], q)
                    pb = self.point_position(body_b, self.parameters[key_b], q)
                    if np.linalg.norm(pb - pa) < 1e-12:
                        springs.append(f"{describe(comp)} has zero length (its direction is undefined)")
            reason = "; ".join(springs) if springs else "the generated equations produced NaN/inf"
            raise SimulationError(f"{what} is not finite at q = {format_state(q)}: {reason}")
        return values
