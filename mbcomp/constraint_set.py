"""The constraint equations of a compiled model: residual, Jacobian, acceleration bias.

Everything is evaluated numerically from the generated kinematics (per body
rotation, origin, spatial velocity and bias acceleration; per coordinate the
motion column ``S_k = (w_k, v0_k)``), so constraints need no code generation.

For every equation ``g(q, t)``: ``gdot = J qd + g_t`` and ``gddot = J qdd + bias``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .components._values import name_of
from .components.constraints import LoopClosure
from .components.primitives import CoordinateEquation, DotEquation, PointEquation
from .errors import SimulationError


@dataclass
class Frames:
    """Numeric kinematics of every body at one state (world frame)."""

    R: np.ndarray        # (nb, 3, 3)
    origin: np.ndarray   # (nb, 3)
    V: np.ndarray        # (nb, 6)  (w, v0)
    A: np.ndarray        # (nb, 6)  bias (alpha, a0) at qdd = 0
    S: np.ndarray        # (nq, 6)


@dataclass
class ConstraintValues:
    """``g`` (position residual, NaN for speed-only rows), ``J``, ``g_t`` and ``bias``."""

    g: np.ndarray
    J: np.ndarray
    g_t: np.ndarray
    bias: np.ndarray


def _derivatives(f, t: float, h: float = 1e-3):
    """Value, first and second derivative of a function of time (5-point stencils, O(h^4))."""
    values = [float(f(t + k * h)) for k in (-2, -1, 0, 1, 2)]
    fm2, fm1, f0, fp1, fp2 = values
    if not np.all(np.isfinite(values)):
        raise ValueError("non-finite value")
    d1 = (fm2 - 8 * fm1 + 8 * fp1 - fp2) / (12 * h)
    d2 = (-fm2 + 16 * fm1 - 30 * f0 + 16 * fp1 - fp2) / (12 * h * h)
    return f0, d1, d2


class ConstraintSet:
    """All constraint equations of a model in a fixed order, with names for reactions."""

    def __init__(self, topology):
        self.topology = topology
        ground = topology.ground
        self.groups: list[tuple[str, Any, list]] = []   # (reaction name, component, equations)
        for joint in topology.cut_joints:
            closure = LoopClosure(joint)
            self.groups.append((joint.name, closure, closure._equations(ground)))
        for comp in topology.constraints:
            self.groups.append((comp.name, comp, comp._equations(ground)))
        self.equations = [eq for _, _, eqs in self.groups for eq in eqs]
        self.owner = [name for name, _, eqs in self.groups for _ in eqs]
        self.labels = [f"{name}.{eq.label}" if eq.label else name for name, _, eqs in self.groups for eq in eqs]
        self.nc = len(self.equations)
        self.slices = {}
        start = 0
        for name, _, eqs in self.groups:
            self.slices[name] = slice(start, start + len(eqs))
            start += len(eqs)
        self.position_rows = np.array([not (isinstance(eq, CoordinateEquation) and eq.speed is not None)
                                       for eq in self.equations], dtype=bool)
        self._chain = {b.name: topology.coord_indices_of_body(b) for b in topology.bodies}
        self._index = {b.name: i for i, b in enumerate(topology.bodies)}

    # -- body point kinematics -------------------------------------------------------------
    def _point(self, frames: Frames, body, local):
        """World position, velocity, bias acceleration and Jacobian (3, nq) of a body point."""
        nq = self.topology.nq
        name = name_of(body)
        if name == self.topology.ground.name:
            zero = np.zeros(3)
            return np.asarray(local, float), zero, zero, np.zeros((3, nq))
        i = self._index[name]
        R, V, A = frames.R[i], frames.V[i], frames.A[i]
        p = frames.origin[i] + R @ np.asarray(local, float)
        w, v0, alpha, a0 = V[:3], V[3:], A[:3], A[3:]
        v = v0 + np.cross(w, p)
        a = a0 + np.cross(alpha, p) + np.cross(w, v)
        J = np.zeros((3, nq))
        idx = self._chain[name]
        if idx:
            S = frames.S[idx]
            J[:, idx] = (np.cross(S[:, :3], p) + S[:, 3:]).T
        return p, v, a, J

    def _rotation(self, frames: Frames, body):
        """Rotation, angular velocity, bias angular acceleration and Jacobian (3, nq)."""
        nq = self.topology.nq
        name = name_of(body)
        if name == self.topology.ground.name:
            return np.eye(3), np.zeros(3), np.zeros(3), np.zeros((3, nq))
        i = self._index[name]
        J = np.zeros((3, nq))
        idx = self._chain[name]
        if idx:
            J[:, idx] = frames.S[idx][:, :3].T
        return frames.R[i], frames.V[i][:3], frames.A[i][:3], J

    # -- evaluation -------------------------------------------------------------------------------
    def evaluate(self, frames: Frames, q: np.ndarray, qd: np.ndarray, t: float,
                 motor_offsets: dict | None = None) -> ConstraintValues:
        """Residuals, Jacobian (nc, nq), explicit time rates and acceleration bias."""
        nq, nc = self.topology.nq, self.nc
        g, J, g_t, bias = np.zeros(nc), np.zeros((nc, nq)), np.zeros(nc), np.zeros(nc)
        for r, eq in enumerate(self.equations):
            if isinstance(eq, PointEquation):
                pa, va, aa, Ja = self._point(frames, eq.body_a, eq.point_a)
                pb, vb, ab, Jb = self._point(frames, eq.body_b, eq.point_b)
                Rf, wf, alf, Jwf = self._rotation(frames, eq.frame)
                n = Rf @ np.asarray(eq.normal, float)
                d = pb - pa
                wn = np.cross(wf, n)
                g[r] = n @ d
                J[r] = n @ (Jb - Ja) + np.cross(n, d) @ Jwf
                bias[r] = n @ (ab - aa) + 2 * wn @ (vb - va) + (np.cross(alf, n) + np.cross(wf, wn)) @ d
            elif isinstance(eq, DotEquation):
                Ra, wa, ala, Jwa = self._rotation(frames, eq.body_a)
                Rb, wb, alb, Jwb = self._rotation(frames, eq.body_b)
                ua, ub = Ra @ np.asarray(eq.u_a, float), Rb @ np.asarray(eq.u_b, float)
                axis = np.cross(ub, ua)
                g[r] = ua @ ub
                J[r] = axis @ (Jwb - Jwa)
                rate = np.cross(np.cross(wb, ub), ua) + np.cross(ub, np.cross(wa, ua))
                bias[r] = (alb - ala) @ axis + (wb - wa) @ rate
            else:
                k = self.topology.q_slice[name_of(eq.joint)].start
                J[r, k] = 1.0
                if eq.speed is not None and motor_offsets is not None and r in motor_offsets:
                    g[r] = q[k] - motor_offsets[r] - eq.speed * t
                    g_t[r] = -eq.speed
                elif eq.speed is not None:
                    g[r] = np.nan  # a speed motor without a start value constrains qd only
                    g_t[r] = -eq.speed
                else:
                    try:
                        s, s1, s2 = _derivatives(eq.position, t)
                    except Exception as exc:  # the user's callable failed
                        raise SimulationError(f"position({t:g}) failed: {exc}", self.groups_by_row(r)) from None
                    g[r] = q[k] - s
                    g_t[r] = -s1
                    bias[r] = -s2
        return ConstraintValues(g, J, g_t, bias)

    def groups_by_row(self, r: int):
        for name, comp, _ in self.groups:
            if r < self.slices[name].stop:
                return comp
        return None

    def split_reactions(self, lam: np.ndarray) -> dict[str, np.ndarray]:
        """Multipliers by constraint name (a float for a motor, an array otherwise)."""
        out = {}
        for name, comp, eqs in self.groups:
            value = lam[self.slices[name]]
            out[name] = float(value[0]) if len(eqs) == 1 else value.copy()
        return out

    def names_of_rows(self, rows) -> list[str]:
        return sorted({self.owner[r] for r in rows})
