"""Frames: a point fixed on a body, optionally rotated relative to the body frame.

A ``Frame`` stands wherever a component takes a body plus a point (joint ends, spring
ends, ``Force``, ``Contact``, ``Slider``).  Its rotation matters to joints only: a joint
between frames has its axis in the parent frame's rotated axes, and at zero coordinates
the child frame coincides with the parent frame.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError
from mbcomp.spec.components.expr import parameters_in
from mbcomp.spec.components.values import name_of, vector3


def rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rotation matrix from roll, pitch, yaw (rad), as URDF defines them:
    ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (fixed-axis x, then y, then z)."""
    try:
        r, p, y = (float(v) for v in (roll, pitch, yaw))
    except (TypeError, ValueError):
        raise ModelError("rpy", f"roll, pitch, yaw must be numbers, got {(roll, pitch, yaw)!r}") from None
    if not np.all(np.isfinite((r, p, y))):
        raise ModelError("rpy", f"roll, pitch, yaw must be finite, got {(r, p, y)}")
    cr, sr, cp, sp_, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp_], [0, 1, 0], [-sp_, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def rotation_matrix(value: Any, owner: Any, what: str = "rotation") -> tuple | None:
    """A proper rotation (orthonormal, det +1) as a tuple of 3 row tuples, or ``None`` for
    ``None`` or the identity (so identity frames generate the same code as plain points).

    Entries within 1e-15 of 0 or +-1 are snapped, so axis-aligned rotations prune terms.
    """
    if value is None:
        return None
    try:
        R = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(owner, f"{what} must be a 3x3 rotation matrix, got {value!r}") from None
    if R.shape != (3, 3):
        raise ModelError(owner, f"{what} must be a 3x3 rotation matrix, got shape {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ModelError(owner, f"{what} has a non-finite entry")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-9) or np.linalg.det(R) < 0:
        raise ModelError(owner, f"{what} is not a proper rotation matrix (orthonormal with determinant +1)")
    R = R.copy()
    for target in (0.0, 1.0, -1.0):
        R[np.abs(R - target) < 1e-15] = target
    if np.array_equal(R, np.eye(3)):
        return None
    return tuple(tuple(float(v) for v in row) for row in R)


class Frame:
    """A point fixed on ``body`` (m, body frame) with an optional ``rotation`` (3x3, the
    frame's axes in the body frame; ``None`` = parallel to the body frame).

    Made by ``body.frame(point, rotation)`` or ``model.ground.frame(...)``.  The point may
    hold sub-model parameter expressions; they are resolved by the component that uses it.
    """

    __slots__ = ("body", "point", "rotation", "rotation_parameters")

    def __init__(self, body: Any, point: Any = (0.0, 0.0, 0.0), rotation: Any = None):
        if isinstance(body, Frame):
            raise ModelError("Frame", "body must be a body (or its name), not another Frame")
        if not isinstance(body, str) and not hasattr(body, "name"):
            raise ModelError("Frame", f"body must be a Body or a body name, got {body!r}")
        owner = f"Frame on {name_of(body)!r}"
        vector3(point, owner, "point")  # checks shape and finiteness; expressions keep their form
        self.body = body
        self.point = tuple(point)
        self.rotation = rotation_matrix(rotation, owner)
        #: parameters the rotation was built from: the code holds it as numbers, so a
        #: run-time change of one is refused (build.flatten.Derivation)
        self.rotation_parameters = frozenset(parameters_in(rotation))

    @property
    def rotation_matrix(self) -> np.ndarray:
        """(3, 3) rotation of the frame relative to its body (identity when none)."""
        return np.eye(3) if self.rotation is None else np.array(self.rotation)

    def offset(self, offset: Any) -> "Frame":
        """This frame moved by ``offset`` (m, in the frame's own axes); sub-model parameter
        expressions in the point stay linked."""
        R = self.rotation_matrix
        point = tuple(self.point[i] + sum(float(R[i][j]) * offset[j] for j in range(3)) for i in range(3))
        return Frame(self.body, point, self.rotation)

    def __eq__(self, other: Any) -> bool:
        return (isinstance(other, Frame) and other.body is self.body
                and tuple(float(v) for v in other.point) == tuple(float(v) for v in self.point)
                and other.rotation == self.rotation)

    def __hash__(self) -> int:
        return hash((id(self.body), self.rotation))

    def __repr__(self) -> str:
        point = tuple(round(float(v), 12) for v in self.point)
        rot = "" if self.rotation is None else ", rotated"
        return f"Frame({name_of(self.body)!r}, {point}{rot})"


def split_frame(value: Any, point: Any, owner: Any, role: str) -> tuple[Any, Any, tuple | None]:
    """``(body, point, rotation)`` from a ``Frame`` or a body with a separate point.

    ``point`` is ``None`` when the caller did not give one; giving both a Frame and a
    point is a ``ModelError`` (the Frame already carries its point).
    """
    if isinstance(value, Frame):
        if point is not None:
            raise ModelError(owner, f"{role} is a Frame, which carries its own point: do not also give a point")
        return value.body, value.point, value.rotation
    return value, (0.0, 0.0, 0.0) if point is None else point, None
