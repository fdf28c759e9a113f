"""Joints: Revolute, Prismatic, Spherical (Euler angles) and Fixed.

A joint is a sequence of elementary motions ("screws"), each a rotation about
or a translation along a unit axis resolved in the frame left by the previous
ones; the compiler derives poses, velocities and Jacobians from that sequence.
"""
from __future__ import annotations

from typing import Any, ClassVar, Sequence

import numpy as np

from ..errors import ModelError
from ..params import ParameterSpec, axis_name, unit_vector
from ..rotations import AXIS_NAMES, axis_angle, parse_sequence
from .base import Component
from .frame import Frame, split_frame

AXIS = ParameterSpec("axis", (3,), "", unit_vector, structural=True,
                     doc="'x', 'y', 'z' (optionally signed) or a 3-vector in the parent frame; stored as a unit vector")


class Joint(Component):
    """Connects ``parent`` to ``child``; at zero coordinates the child frame is parallel
    to the parent frame.

    Parameters
    ----------
    parent, child : Body, str or Frame.  A ``Frame`` carries the joint location and
        may be rotated: the axis is then in the parent frame's rotated axes, and at
        zero coordinates the child frame coincides with the parent frame
        (``R_child = R_parent R_pf R_joint(q) R_cf^T``).
    parent_point : (3,) m, joint location in the parent body frame (with a body)
    child_point : (3,) m, joint location in the child body frame (with a body)
    coords : str or sequence of str, names of the joint coordinates (default from the
        joint name)

    Subclasses provide ``n_coords``, ``coord_suffixes`` and ``_screws()``.
    """

    n_coords: ClassVar[int] = 0
    section = "joints"
    coord_unit: ClassVar[str] = "rad"
    params = (ParameterSpec("parent_point", (3,), "m", default=(0.0, 0.0, 0.0), doc="joint location in the parent body frame"),
              ParameterSpec("child_point", (3,), "m", default=(0.0, 0.0, 0.0), doc="joint location in the child body frame"))

    refs = {"parent": "body", "child": "body"}
    file_keys = ("parent", "child", "parent_point", "child_point", "parent_rotation", "child_rotation", "coords")
    file_required = ("parent", "child")
    file_options = {"coords": "names", "parent_rotation": "rotation", "child_rotation": "rotation"}

    def __init__(self, name: str, parent: Any, child: Any, *, parent_point: Any = None,
                 child_point: Any = None, coords: Any = None):
        super().__init__(name)
        self.parent, parent_point, self.parent_rotation = split_frame(parent, parent_point, self, "parent")
        self.child, child_point, self.child_rotation = split_frame(child, child_point, self, "child")
        self.parent_point = parent_point
        self.child_point = child_point
        self.coords = self._coord_names(coords)

    @classmethod
    def from_file(cls, name: str, values: dict[str, Any]) -> "Joint":
        """A joint from its file table.  An end that is a port (a ``Frame`` bound by the
        user of a part file) takes the point as an offset in the port frame's axes; a
        rotation turns the end's frame further (in the port's axes for a port)."""
        values = dict(values)
        for role in ("parent", "child"):
            end = values[role]
            point = values.pop(f"{role}_point", None)
            rotation = values.pop(f"{role}_rotation", None)
            if isinstance(end, Frame):
                if point is not None:
                    end = end.offset(point)
                if rotation is not None:
                    end = Frame(end.body, end.point, end.rotation_matrix @ np.asarray(rotation, dtype=float))
                values[role] = end
            elif rotation is not None:
                values[role] = Frame(end, (0.0, 0.0, 0.0) if point is None else point, rotation)
            elif point is not None:
                values[f"{role}_point"] = point
        return cls(name, **values)

    def file_value(self, key: str) -> Any:
        if key == "coords":
            if not self.n_coords:
                return None
            return self.coords[0] if self.n_coords == 1 else list(self.coords)
        return super().file_value(key)

    # -- contract -----------------------------------------------------------
    @property
    def coord_suffixes(self) -> tuple[str, ...]:
        """Suffixes for the default coordinate names ``f"{name}_{suffix}"`` (``""`` = the name)."""
        return ("",) * self.n_coords

    def _screws(self) -> list[tuple[str, tuple[float, float, float]]]:
        """Elementary motions ``("R" | "P", unit axis)``, each axis in the frame after the
        previous ones; coordinate i drives screw i."""
        raise NotImplementedError

    def reaction_unit(self, resolve) -> str:
        """Unit of the reactions of this joint when it closes a loop (forces, then torques)."""
        return "N, N m"

    def summary(self) -> str:
        detail = getattr(self, "axis", None)
        if detail is not None:
            word = "along" if self.coord_unit == "m" else "about"
            name = axis_name(detail)
            return f"{self.kind} {word} {name if isinstance(name, str) else tuple(name)}"
        if hasattr(self, "sequence"):
            return f"{self.kind} {self.sequence!r}"
        return self.kind

    @property
    def coord_units(self) -> tuple[str, ...]:
        """Unit of each coordinate (``"rad"`` or ``"m"``), for plots and tables."""
        return (self.coord_unit,) * self.n_coords

    # -- derived ------------------------------------------------------------
    def references(self) -> dict[str, Any]:
        return {"parent": self.parent, "child": self.child}

    def structure(self) -> tuple:
        screws = tuple(self._screws())
        if self.parent_rotation is None and self.child_rotation is None:
            return screws
        return screws + (("frames", self.parent_rotation, self.child_rotation),)

    @property
    def parent_frame_rotation(self) -> np.ndarray:
        """(3, 3) rotation of the joint's parent frame in the parent body frame."""
        return np.eye(3) if self.parent_rotation is None else np.array(self.parent_rotation)

    @property
    def child_frame_rotation(self) -> np.ndarray:
        """(3, 3) rotation of the joint's child frame in the child body frame."""
        return np.eye(3) if self.child_rotation is None else np.array(self.child_rotation)

    def relative_pose(self, q: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """``(R_PC, p_PC)``: child body frame rotation and origin in the parent body frame.

        ``R_PC = R_pf R_joint(q) R_cf^T`` and ``p_PC = parent_point + R_pf translation(q)
        - R_PC child_point`` (m, parent body frame).
        """
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape != (self.n_coords,):
            raise ModelError(self, f"needs {self.n_coords} coordinate(s), got {q.size}")
        rotation = self.parent_frame_rotation
        translation = np.zeros(3)
        for (kind, axis), value in zip(self._screws(), q):
            if kind == "R":
                rotation = rotation @ axis_angle(axis, value)
            else:
                translation = translation + rotation @ (np.asarray(axis) * value)
        rotation = rotation @ self.child_frame_rotation.T
        origin = np.asarray(self.parent_point) + translation - rotation @ np.asarray(self.child_point)
        return rotation, origin

    def _coord_names(self, coords: Any) -> tuple[str, ...]:
        if coords is None:
            return tuple(self.name if not s else f"{self.name}_{s}" for s in self.coord_suffixes)
        try:
            names = (coords,) if isinstance(coords, str) else tuple(coords)
        except TypeError:
            raise ModelError(self, f"coords must be a name or a sequence of names, got {coords!r}") from None
        if len(names) != self.n_coords:
            raise ModelError(self, f"coords must name {self.n_coords} coordinate(s), got {len(names)}")
        if not all(isinstance(n, str) and n.strip() and n == n.strip() for n in names):
            raise ModelError(self, f"coords must be non-empty names without edge spaces, got {coords!r}")
        if len(set(names)) != len(names):
            raise ModelError(self, f"coords {names} repeat a name")
        return names


class Revolute(Joint):
    """Rotation of the child about ``axis`` (parent frame) through ``parent_point``.

    Coordinate: the angle in rad, positive right-handed about ``axis``.
    """

    kind = "revolute"
    n_coords = 1
    params = Joint.params + (AXIS,)
    file_keys = Joint.file_keys + ("axis",)
    file_required = ("parent", "child", "axis")

    def __init__(self, name: str, parent: Any, child: Any, axis: Any = "z", **options: Any):
        super().__init__(name, parent, child, **options)
        self.axis = axis

    def _screws(self):
        return [("R", self.axis)]


class Prismatic(Joint):
    """Translation of the child by ``q`` (m) along ``axis`` (parent frame)."""

    kind = "prismatic"
    n_coords = 1
    coord_unit = "m"
    params = Joint.params + (AXIS,)
    file_keys = Joint.file_keys + ("axis",)
    file_required = ("parent", "child", "axis")

    def __init__(self, name: str, parent: Any, child: Any, axis: Any = "x", **options: Any):
        super().__init__(name, parent, child, **options)
        self.axis = axis

    def _screws(self):
        return [("P", self.axis)]


class Spherical(Joint):
    """Euler-angle joint: intrinsic rotations ``R = R_a1(q1) R_a2(q2) R_a3(q3)``.

    ``sequence`` holds 1 to 3 axes from x, y, z (``"xy"``, ``"xyz"``, ``"zxz"``); the
    coordinates are the angles in rad.  The mass matrix is singular where the first
    and last axes of a 3-axis sequence align (gimbal lock).
    """

    kind = "spherical"
    file_keys = Joint.file_keys + ("sequence",)
    file_options = {**Joint.file_options, "sequence": "string"}

    def __init__(self, name: str, parent: Any, child: Any, sequence: str = "xyz", **options: Any):
        self.sequence = parse_sequence(sequence, owner=f"Spherical {name!r}")
        super().__init__(name, parent, child, **options)

    @property
    def n_coords(self) -> int:  # type: ignore[override]
        return len(self.sequence)

    @property
    def coord_suffixes(self) -> tuple[str, ...]:
        letters = tuple(self.sequence)
        if len(set(letters)) == len(letters):
            return letters
        return tuple(f"{ch}{i + 1}" for i, ch in enumerate(letters))

    def _screws(self):
        return [("R", AXIS_NAMES[ch]) for ch in self.sequence]


class Fixed(Joint):
    """Rigid connection: the child frame keeps the parent frame's orientation."""

    kind = "fixed"
    n_coords = 0
    file_keys = tuple(k for k in Joint.file_keys if k != "coords")

    def _screws(self):
        return []
