"""Coordinates and speeds of a whole tree: ``q' = G(q) v``, steps in speed space, normalisation.

Every screw coordinate's speed is its rate (``G = I`` on it); each quaternion
``(w, x, y, z)`` of a ball segment has 3 speeds, the angular velocity in the
rotated frame (``q' = q (0, w) / 2``).  Vectorised over leading dimensions, so one
call handles a single state or every sample of a result.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from mbcomp.core.errors import ModelError
from mbcomp.core.rotations import cross, quat_log
from mbcomp.core.small_linalg import solve


@dataclass(frozen=True)
class StateMap:
    """Index maps from the tree's joints: ``screw_q[i]`` has speed ``screw_v[i]``; the
    quaternion at ``q[quat_q[k]:quat_q[k] + 4]`` has speeds ``v[quat_v[k]:quat_v[k] + 3]``."""

    nq: int
    nv: int
    screw_q: np.ndarray
    screw_v: np.ndarray
    quat_q: np.ndarray
    quat_v: np.ndarray
    owners: tuple = ()  #: joint name of each quaternion (for messages)

    @classmethod
    def of(cls, topology) -> "StateMap":
        screw_q, screw_v, quat_q, quat_v, owners = [], [], [], [], []
        for joint in topology.tree_joints:
            q0, v0 = topology.q_slice[joint.name].start, topology.v_slice[joint.name].start
            for kind, _, sq, sv in joint.walk():
                if kind == "B":
                    quat_q.append(q0 + sq.start)
                    quat_v.append(v0 + sv.start)
                    owners.append(joint.name)
                else:
                    screw_q.append(q0 + sq.start)
                    screw_v.append(v0 + sv.start)
        as_int = lambda x: np.asarray(x, dtype=np.intp)
        return cls(topology.nq, topology.nv, as_int(screw_q), as_int(screw_v), as_int(quat_q), as_int(quat_v),
                   tuple(owners))

    @property
    def identity(self) -> bool:
        """True when every speed is its coordinate's rate (no quaternions)."""
        return self.quat_q.size == 0

    @functools.cached_property
    def _quat_rows(self) -> np.ndarray:
        """``(k, 4)`` indices of each quaternion's coordinates (built once: the per-step
        updates index with them)."""
        return self.quat_q[:, None] + np.arange(4)

    @functools.cached_property
    def _omega_rows(self) -> np.ndarray:
        """``(k, 3)`` indices of each quaternion's angular speeds."""
        return self.quat_v[:, None] + np.arange(3)

    def qdot(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Coordinate rates from speeds (shape ``(..., nq)``)."""
        if self.identity:
            return v
        q, v = np.asarray(q, dtype=float), np.asarray(v, dtype=float)
        out = np.empty(q.shape[:-1] + (self.nq,))
        out[..., self.screw_q] = v[..., self.screw_v]
        quat, w = q[..., self._quat_rows], v[..., self._omega_rows]
        a, b = quat[..., 0], quat[..., 1:]
        rate = np.empty_like(quat)
        rate[..., 0] = -0.5 * np.sum(b * w, axis=-1)
        rate[..., 1:] = 0.5 * (a[..., None] * w + cross(b, w))
        out[..., self._quat_rows] = rate
        return out

    def normalize(self, q: np.ndarray) -> np.ndarray:
        """``q`` with every quaternion at unit length (a new array; ``q`` itself when none)."""
        if self.identity:
            return q
        q = np.array(q, dtype=float)
        idx = self._quat_rows
        quat = q[..., idx]
        norm = np.linalg.norm(quat, axis=-1, keepdims=True)
        bad = ~((norm[..., 0] > 1e-300) & np.isfinite(norm[..., 0]))
        if bad.any():
            k = int(np.flatnonzero(bad.reshape(-1, len(self.owners)).any(axis=0))[0])
            raise ModelError(f"joint {self.owners[k]!r}", "its quaternion must be non-zero and finite "
                             "(any non-zero quaternion is accepted and normalised)")
        q[..., idx] = quat / norm
        return q

    def integrate(self, q: np.ndarray, dv: np.ndarray) -> np.ndarray:
        """Coordinates reached from ``q`` by the step ``dv`` (speed space): ``q + dv`` on
        screw coordinates, ``q exp(dv / 2)`` (rotation vector in the rotated frame) on
        quaternions."""
        if self.identity:
            return q + dv
        q, dv = np.asarray(q, dtype=float), np.asarray(dv, dtype=float)
        out = np.array(q, dtype=float)
        out[..., self.screw_q] = q[..., self.screw_q] + dv[..., self.screw_v]
        phi = dv[..., self._omega_rows]
        angle = np.linalg.norm(phi, axis=-1, keepdims=True)
        small = angle < 1e-4
        k = np.where(small, 0.5 - angle ** 2 / 48, np.sin(angle / 2) / np.where(small, 1.0, angle))
        step = np.concatenate((np.cos(angle / 2), k * phi), axis=-1)
        quat = q[..., self._quat_rows]
        product = _multiply(quat, step)
        out[..., self._quat_rows] = product / np.linalg.norm(product, axis=-1, keepdims=True)
        return out

    def difference(self, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
        """The step ``dv`` (speed space) with ``integrate(q0, dv) = q1``: ``q1 - q0`` on screw
        coordinates, the rotation vector of ``q0^-1 q1`` (the shorter way) on quaternions."""
        q0, q1 = np.asarray(q0, dtype=float), np.asarray(q1, dtype=float)
        if self.identity:
            return q1 - q0
        out = np.zeros(q0.shape[:-1] + (self.nv,))
        out[..., self.screw_v] = q1[..., self.screw_q] - q0[..., self.screw_q]
        a, b = self.normalize(q0)[..., self._quat_rows], self.normalize(q1)[..., self._quat_rows]
        relative = _multiply(a * np.array([1.0, -1.0, -1.0, -1.0]), b)
        relative = np.where(relative[..., :1] < 0, -relative, relative)
        n = np.linalg.norm(relative[..., 1:], axis=-1, keepdims=True)
        angle = 2 * np.arctan2(n, relative[..., :1])
        scale = np.where(n < 1e-12, 2.0 / np.maximum(relative[..., :1], 1e-300), angle / np.where(n < 1e-12, 1.0, n))
        out[..., self._omega_rows] = scale * relative[..., 1:]
        return out

    def neutral(self) -> np.ndarray:
        """Zero coordinates with identity quaternions."""
        q = np.zeros(self.nq)
        q[self.quat_q] = 1.0
        return q


def _multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternion arrays (last axis 4)."""
    aw, av = a[..., :1], a[..., 1:]
    bw, bv = b[..., :1], b[..., 1:]
    w = aw * bw - np.sum(av * bv, axis=-1, keepdims=True)
    v = aw * bv + bw * av + cross(av, bv)
    return np.concatenate((w, v), axis=-1)


class Chart:
    """Local coordinates ``x`` (nv) of the configuration around a base ``q``: a screw
    coordinate itself, and for each quaternion the rotation vector ``phi`` (rad, rotated
    frame) with ``quat = base exp(phi / 2)``.  Lets coordinate partitioning treat a
    ball's rotation like three coordinates; valid for ``|phi| < pi`` (re-base well before).
    The rates are ``x' = v`` on screws and ``phi' = J_r(phi)^-1 w`` on rotations.
    """

    def __init__(self, state_map: StateMap, base: np.ndarray):
        self.map = state_map
        self.base = np.array(base, dtype=float)

    def to_q(self, x: np.ndarray) -> np.ndarray:
        m = self.map
        if m.identity:
            return np.array(x, dtype=float)
        dv = np.zeros(m.nv)
        dv[m._omega_rows] = x[m._omega_rows]
        q = m.integrate(self.base, dv)
        q[m.screw_q] = x[m.screw_v]
        return q

    def to_x(self, q: np.ndarray) -> np.ndarray:
        m = self.map
        if m.identity:
            return np.array(q, dtype=float)
        x = np.zeros(m.nv)
        x[m.screw_v] = q[m.screw_q]
        for qi, vi in zip(m.quat_q, m.quat_v):
            a = self.base[qi:qi + 4] / np.linalg.norm(self.base[qi:qi + 4])
            b = q[qi:qi + 4] / np.linalg.norm(q[qi:qi + 4])
            x[vi:vi + 3] = quat_log(_multiply(a * np.array([1.0, -1.0, -1.0, -1.0]), b))
        return x

    def largest_rotation(self, x: np.ndarray) -> float:
        """The largest |phi| (rad) of the chart's rotations (0 without quaternions)."""
        if self.map.identity:
            return 0.0
        return float(np.max(np.linalg.norm(x[self.map._omega_rows], axis=-1)))

    def tangent(self, x: np.ndarray) -> np.ndarray | None:
        """``D = dv/dx`` (nv x nv): identity on screws, ``J_r(phi)`` on rotations (None when
        all of it is the identity)."""
        m = self.map
        if m.identity:
            return None
        D = np.eye(m.nv)
        for vi in m.quat_v:
            D[vi:vi + 3, vi:vi + 3] = _right_jacobian(x[vi:vi + 3])
        return D

    def rate(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``x'`` for speeds ``v``."""
        m = self.map
        if m.identity:
            return v
        out = np.array(v, dtype=float)
        for vi in m.quat_v:
            out[vi:vi + 3] = solve(_right_jacobian(x[vi:vi + 3]), v[vi:vi + 3])
        return out


def _right_jacobian(phi: np.ndarray) -> np.ndarray:
    """``J_r(phi)`` with ``w = J_r(phi) phi'`` for ``R = R0 exp([phi]x)``, w in the rotated frame."""
    theta = float(np.linalg.norm(phi))
    K = np.array([[0.0, -phi[2], phi[1]], [phi[2], 0.0, -phi[0]], [-phi[1], phi[0], 0.0]])
    if theta < 1e-5:
        a, b = 0.5 - theta ** 2 / 24, 1.0 / 6 - theta ** 2 / 120
    else:
        a, b = (1 - np.cos(theta)) / theta ** 2, (theta - np.sin(theta)) / theta ** 3
    return np.eye(3) - a * K + b * K @ K
