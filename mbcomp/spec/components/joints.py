"""Joints: Revolute, Prismatic, Spherical (Euler angles), Ball, Free, Universal,
Cylindrical, Planar and Fixed.

The joint contract: a joint has ``nq`` coordinates (``coords``) and ``nv`` speeds
(``speeds``), with ``q' = G(q) v``.  It is a sequence of elementary motions
(``_segments()``), each resolved in the frame left by the previous ones:

- ``("R", axis)``: a rotation about a unit axis; 1 coordinate (the angle), 1 speed (its rate);
- ``("P", axis)``: a translation along a unit axis; 1 coordinate, 1 speed (its rate);
- ``("B", None)``: a free rotation; 4 coordinates, the unit quaternion ``(w, x, y, z)``
  of the child frame relative to the frame before it, and 3 speeds, the angular
  velocity (rad/s) relative to that frame, resolved in the child frame
  (``q' = q (0, w) / 2``).

Screw joints (only R and P) have ``G = I``: each speed is its coordinate's rate and
shares its name.  The compiler derives poses, motion columns and accelerations from
the segments (``equations.build_program``); ``qdot``, ``integrate``, ``difference``,
``normalize`` and ``neutral`` are the numeric side of the same contract.
"""
from __future__ import annotations

from typing import Any, ClassVar, Sequence

import numpy as np

from mbcomp.core.errors import ModelError
from mbcomp.core.params import ParameterSpec, axis_name, unit_vector
from mbcomp.core.rotations import (normals, AXIS_NAMES, axis_angle, parse_sequence, quat_exp, quat_log, quat_matrix, quat_multiply,
                         quat_normalize, quat_rate, unit_axis)
from mbcomp.spec.components.base import Component
from mbcomp.spec.components.frame import Frame, split_frame

AXIS = ParameterSpec("axis", (3,), "", unit_vector, structural=True,
                     doc="'x', 'y', 'z' (optionally signed) or a 3-vector in the parent frame; stored as a unit vector")

#: (coordinates, speeds) of each segment kind.
SEGMENT_SIZES = {"R": (1, 1), "P": (1, 1), "B": (4, 3)}


class Joint(Component):
    """Connects ``parent`` to ``child``; at zero coordinates (the identity quaternion for
    a ball) the child frame is parallel to the parent frame.

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
    speeds : sequence of str, names of the joint speeds (only joints with a rotation
        segment have speeds that are not coordinate rates; a screw coordinate's speed
        always shares its name)

    Subclasses provide ``n_coords``, ``coord_suffixes`` and ``_screws()`` (or, for
    joints with a ball segment, ``_segments()`` and ``speed_suffixes``).
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
                 child_point: Any = None, coords: Any = None, speeds: Any = None):
        super().__init__(name)
        self.parent, parent_point, self.parent_rotation = split_frame(parent, parent_point, self, "parent")
        self.child, child_point, self.child_rotation = split_frame(child, child_point, self, "child")
        self.parent_point = parent_point
        self.child_point = child_point
        self.coords = self._coord_names(coords)
        self._speeds_given = None if speeds is None else ((speeds,) if isinstance(speeds, str) else tuple(speeds))
        try:
            self._speed_names(self._speeds_given)  # checked now where the segments are known already
        except AttributeError:
            pass  # a subclass sets its axes after this constructor: checked on first use

    @property
    def speeds(self) -> tuple[str, ...]:
        """The names of the joint's speeds (``nv`` of them)."""
        return self._speed_names(self._speeds_given)

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
        if key == "speeds":
            return None if self.speeds == self.default_speeds else list(self.speeds)
        return super().file_value(key)

    # -- contract -----------------------------------------------------------
    @property
    def coord_suffixes(self) -> tuple[str, ...]:
        """Suffixes for the default coordinate names ``f"{name}_{suffix}"`` (``""`` = the name)."""
        return ("",) * self.n_coords

    #: Suffixes of the default names of the speeds of ball segments.
    speed_suffixes: ClassVar[tuple[str, ...]] = ("wx", "wy", "wz")

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
        """Unit of each coordinate (``"rad"``, ``"m"``, or ``""`` for a quaternion), for plots and tables."""
        units: list[str] = []
        for kind, _ in self._segments():
            units.extend(("",) * 4 if kind == "B" else ("m",) if kind == "P" else ("rad",))
        return tuple(units)

    @property
    def speed_units(self) -> tuple[str, ...]:
        """Unit of each speed (``"rad/s"`` or ``"m/s"``)."""
        units: list[str] = []
        for kind, _ in self._segments():
            units.extend(("rad/s",) * 3 if kind == "B" else ("m/s",) if kind == "P" else ("rad/s",))
        return tuple(units)

    def _segments(self) -> list[tuple[str, Any]]:
        """The joint's motion as segments (see the module docstring); screws by default."""
        return self._screws()

    @property
    def nq(self) -> int:
        """Number of coordinates."""
        return self.n_coords

    @property
    def nv(self) -> int:
        """Number of speeds (degrees of freedom of the joint)."""
        return sum(SEGMENT_SIZES[kind][1] for kind, _ in self._segments())

    @property
    def is_screw(self) -> bool:
        """True when every speed is its coordinate's rate (``G = I``)."""
        return all(kind in ("R", "P") for kind, _ in self._segments())

    @property
    def neutral(self) -> tuple[float, ...]:
        """Coordinates of the zero position (zeros; the identity quaternion for a ball)."""
        out: list[float] = []
        for kind, _ in self._segments():
            out.extend((1.0, 0.0, 0.0, 0.0) if kind == "B" else (0.0,))
        return tuple(out)

    # -- derived ------------------------------------------------------------
    def references(self) -> dict[str, Any]:
        return {"parent": self.parent, "child": self.child}

    def structure(self) -> tuple:
        screws = tuple(self._segments())
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

    def walk(self):
        """``(kind, axis, q slice, v slice)`` of each segment (see the module docstring), local to the joint."""
        iq = iv = 0
        for kind, axis in self._segments():
            nq, nv = SEGMENT_SIZES[kind]
            yield kind, axis, slice(iq, iq + nq), slice(iv, iv + nv)
            iq, iv = iq + nq, iv + nv

    def _checked(self, values: Any, size: int, what: str) -> np.ndarray:
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.shape != (size,):
            raise ModelError(self, f"needs {size} {what}, got {values.size}")
        return values

    def qdot(self, q: Sequence[float], v: Sequence[float]) -> np.ndarray:
        """Coordinate rates ``q' = G(q) v`` (quaternion rates ``q (0, w) / 2``)."""
        q, v = self._checked(q, self.nq, "coordinate(s)"), self._checked(v, self.nv, "speed(s)")
        out = np.empty(self.nq)
        for kind, _, sq, sv in self.walk():
            out[sq] = quat_rate(q[sq], v[sv]) if kind == "B" else v[sv]
        return out

    def integrate(self, q: Sequence[float], dv: Sequence[float]) -> np.ndarray:
        """The coordinates reached from ``q`` by the step ``dv`` in speed space (a rotation
        vector, child frame, for a ball segment); ``q + dv`` for a screw joint."""
        q, dv = self._checked(q, self.nq, "coordinate(s)"), self._checked(dv, self.nv, "speed(s)")
        out = q.copy()
        for kind, _, sq, sv in self.walk():
            if kind == "B":
                out[sq] = quat_normalize(quat_multiply(q[sq], quat_exp(dv[sv])), self)
            else:
                out[sq] = q[sq] + dv[sv]
        return out

    def difference(self, q0: Sequence[float], q1: Sequence[float]) -> np.ndarray:
        """The step ``dv`` with ``integrate(q0, dv) = q1`` (the shorter rotation for a ball)."""
        q0, q1 = self._checked(q0, self.nq, "coordinate(s)"), self._checked(q1, self.nq, "coordinate(s)")
        out = np.empty(self.nv)
        for kind, _, sq, sv in self.walk():
            if kind == "B":
                a = quat_normalize(q0[sq], self)
                out[sv] = quat_log(quat_multiply([a[0], -a[1], -a[2], -a[3]], quat_normalize(q1[sq], self)))
            else:
                out[sv] = q1[sq] - q0[sq]
        return out

    def normalize(self, q: Sequence[float]) -> np.ndarray:
        """``q`` with each quaternion scaled to unit length (``ModelError`` for a zero one)."""
        q = self._checked(q, self.nq, "coordinate(s)").copy()
        for kind, _, sq, _ in self.walk():
            if kind == "B":
                q[sq] = quat_normalize(q[sq], self)
        return q

    def relative_pose(self, q: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """``(R_PC, p_PC)``: child body frame rotation and origin in the parent body frame.

        ``R_PC = R_pf R_joint(q) R_cf^T`` and ``p_PC = parent_point + R_pf translation(q)
        - R_PC child_point`` (m, parent body frame).
        """
        q = self._checked(q, self.nq, "coordinate(s)")
        rotation = self.parent_frame_rotation
        translation = np.zeros(3)
        for kind, axis, sq, _ in self.walk():
            if kind == "R":
                rotation = rotation @ axis_angle(axis, q[sq][0])
            elif kind == "P":
                translation = translation + rotation @ (np.asarray(axis) * q[sq][0])
            else:
                rotation = rotation @ np.array(quat_matrix(q[sq]), dtype=float)
        rotation = rotation @ self.child_frame_rotation.T
        origin = np.asarray(self.parent_point) + translation - rotation @ np.asarray(self.child_point)
        return rotation, origin

    def relative_velocity(self, q: Sequence[float], v: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
        """``(w, u)``: the child's angular velocity (rad/s) and the velocity (m/s) of its frame
        origin relative to the parent, both in the parent frame (the parent at rest)."""
        q, v = self._checked(q, self.nq, "coordinate(s)"), self._checked(v, self.nv, "speed(s)")
        rotation = self.parent_frame_rotation
        translation = np.zeros(3)
        w = np.zeros(3)
        u = np.zeros(3)  # velocity of the moving joint point
        for kind, axis, sq, sv in self.walk():
            if kind == "R":
                w = w + rotation @ np.asarray(axis) * v[sv][0]
                rotation = rotation @ axis_angle(axis, q[sq][0])
            elif kind == "P":
                step = rotation @ np.asarray(axis)
                u = u + step * v[sv][0] + np.cross(w, step * q[sq][0])
                translation = translation + step * q[sq][0]
            else:
                rotation = rotation @ np.array(quat_matrix(q[sq]), dtype=float)
                w = w + rotation @ v[sv]
        rotation = rotation @ self.child_frame_rotation.T
        point = np.asarray(self.child_point)
        return w, u + np.cross(w, -rotation @ point)

    def _coord_names(self, coords: Any) -> tuple[str, ...]:
        if coords is None:
            names = tuple(self.name if not s else f"{self.name}_{s}" for s in self.coord_suffixes)
        else:
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
        from mbcomp.core.names import reserved_problem
        for n in names:
            problem = reserved_problem(n)
            if problem is not None:
                raise ModelError(self, f"coordinate {problem}" + ("" if coords is not None else
                                                                   " (the default coordinate name is the joint's: give coords)"))
        return names

    @property
    def default_speeds(self) -> tuple[str, ...]:
        """The speed names given no ``speeds``: a screw coordinate's name, ``NAME_wx`` .. for a ball."""
        default: list[str] = []
        for kind, _, sq, _ in self.walk():
            if kind == "B":
                default.extend(f"{self.name}_{s}" for s in self.speed_suffixes)
            else:
                default.append(self.coords[sq.start])
        return tuple(default)

    def _speed_names(self, speeds: Any) -> tuple[str, ...]:
        default = self.default_speeds
        if speeds is None:
            return tuple(default)
        names = (speeds,) if isinstance(speeds, str) else tuple(speeds)
        if len(names) != len(default) or not all(isinstance(n, str) and n.strip() for n in names):
            raise ModelError(self, f"speeds must be {len(default)} non-empty name(s), got {speeds!r}")
        if len(set(names)) != len(names):
            raise ModelError(self, f"speeds {names} repeat a name")
        for kind, _, sq, sv in self.walk():
            if kind != "B" and names[sv.start] != self.coords[sq.start]:
                raise ModelError(self, f"speed {names[sv.start]!r} must be named like its coordinate "
                                       f"{self.coords[sq.start]!r} (a screw coordinate's speed is its rate)")
        clash = {names[i] for kind, _, _, sv in self.walk() if kind == "B"
                 for i in range(sv.start, sv.stop) if names[i] in self.coords}
        if clash:
            raise ModelError(self, f"speed name(s) {sorted(clash)} are also coordinate names")
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


class Ball(Joint):
    """Spherical joint without singularity: the coordinates are the unit quaternion
    ``(w, x, y, z)`` of the child frame relative to the parent (default names
    ``NAME_qw``, ``NAME_qx``, ``NAME_qy``, ``NAME_qz``), the speeds the child's angular
    velocity relative to the parent in the child frame, rad/s (``NAME_wx``, ``NAME_wy``,
    ``NAME_wz``).  The integrators keep the quaternion at unit length.
    """

    kind = "ball"
    n_coords = 4
    coord_suffixes = ("qw", "qx", "qy", "qz")
    file_keys = Joint.file_keys + ("speeds",)
    file_options = {**Joint.file_options, "speeds": "names"}

    def _segments(self):
        return [("B", None)]


class Free(Joint):
    """A floating child: three translations along the parent's axes (m, coordinates
    ``NAME_x``, ``NAME_y``, ``NAME_z``, their rates the first three speeds) then a
    ``Ball`` rotation about the translated joint point (``NAME_qw`` .. ``NAME_qz``;
    speeds ``NAME_wx`` .. ``NAME_wz``, rad/s in the child frame).  7 coordinates, 6 speeds.
    """

    kind = "free"
    n_coords = 7
    coord_suffixes = ("x", "y", "z", "qw", "qx", "qy", "qz")
    file_keys = Joint.file_keys + ("speeds",)
    file_options = {**Joint.file_options, "speeds": "names"}

    def _segments(self):
        return [("P", AXIS_NAMES["x"]), ("P", AXIS_NAMES["y"]), ("P", AXIS_NAMES["z"]), ("B", None)]


def _axis_letter(spec: Any) -> str | None:
    """``"x"`` for an axis given as ``"x"`` (or ``"+x"``), else None."""
    if isinstance(spec, str) and spec.strip().lower().lstrip("+") in AXIS_NAMES:
        return spec.strip().lower().lstrip("+")
    if not isinstance(spec, str):  # a 3-vector along a coordinate axis (as a file gives it back)
        try:
            values = np.asarray(spec, dtype=float).reshape(3)
        except (TypeError, ValueError):
            return None
        for letter in "xyz":
            if np.array_equal(values, np.asarray(AXIS_NAMES[letter], dtype=float)):
                return letter
    return None


class Universal(Joint):
    """Two rotations (rad): about ``axes[0]`` (parent frame), then about ``axes[1]`` as
    carried by the first rotation (a Cardan joint).  The axes must not be parallel.
    Coordinates ``NAME_<axis>`` for named axes (``NAME_1``, ``NAME_2`` otherwise).
    """

    kind = "universal"
    n_coords = 2
    params = Joint.params + (
        ParameterSpec("axis1", (3,), "", unit_vector, structural=True, default=(1.0, 0.0, 0.0),
                      doc="first axis, in the parent frame (the file form of axes[0])"),
        ParameterSpec("axis2", (3,), "", unit_vector, structural=True, default=(0.0, 1.0, 0.0),
                      doc="second axis, as carried by the first rotation (the file form of axes[1])"))
    file_keys = Joint.file_keys + ("axis1", "axis2")

    @classmethod
    def from_file(cls, name: str, values: dict[str, Any]) -> "Joint":
        values = dict(values)
        axes = (values.pop("axis1", "x"), values.pop("axis2", "y"))
        return super().from_file(name, {**values, "axes": axes})

    def __init__(self, name: str, parent: Any, child: Any, axes: Any = ("x", "y"), **options: Any):
        owner = f"Universal {name!r}"
        if isinstance(axes, str) or len(axes) != 2:
            raise ModelError(owner, f"axes must be two axes such as ('x', 'y'), got {axes!r}")
        self.axes = tuple(unit_axis(a, owner=owner) for a in axes)
        if abs(float(np.dot(self.axes[0], self.axes[1]))) > 1.0 - 1e-9:
            raise ModelError(owner, f"axes {axes!r} are parallel: a universal joint needs two different axes")
        letters = tuple(_axis_letter(a) for a in axes)
        self._suffixes = letters if None not in letters and letters[0] != letters[1] else ("1", "2")
        super().__init__(name, parent, child, **options)
        self.axis1, self.axis2 = self.axes

    def summary(self) -> str:
        first, second = (axis_name(a) for a in self.axes)
        show = lambda n: n if isinstance(n, str) else tuple(n)  # noqa: E731
        return f"{self.kind} about {show(first)} then {show(second)}"

    @property
    def coord_suffixes(self) -> tuple[str, ...]:
        return self._suffixes

    def _screws(self):
        return [("R", self.axes[0]), ("R", self.axes[1])]


class Cylindrical(Joint):
    """Rotation about (rad, ``NAME_angle``) and translation along (m, ``NAME_slide``) one
    ``axis`` of the parent frame through ``parent_point``."""

    kind = "cylindrical"
    n_coords = 2
    coord_suffixes = ("angle", "slide")
    params = Joint.params + (AXIS,)
    file_keys = Joint.file_keys + ("axis",)

    def __init__(self, name: str, parent: Any, child: Any, axis: Any = "z", **options: Any):
        super().__init__(name, parent, child, **options)
        self.axis = axis

    def _screws(self):
        return [("R", self.axis), ("P", self.axis)]


class Planar(Joint):
    """Motion in the plane with the given ``normal`` (parent frame): two translations (m)
    along in-plane axes ``t1``, ``t2`` with ``t1 x t2 = normal`` (for ``"z"``: x then y),
    then a rotation (rad) about the normal.  Coordinates ``NAME_<t1>``, ``NAME_<t2>``,
    ``NAME_angle`` for a named normal (``NAME_u``, ``NAME_v``, ``NAME_angle`` otherwise).
    """

    kind = "planar"
    n_coords = 3
    params = Joint.params + (ParameterSpec("normal", (3,), "", unit_vector, structural=True, default=(0.0, 0.0, 1.0),
                                           doc="the plane's normal in the parent frame"),)
    file_keys = Joint.file_keys + ("normal",)
    _IN_PLANE = {"x": ("y", "z"), "y": ("z", "x"), "z": ("x", "y")}

    def __init__(self, name: str, parent: Any, child: Any, normal: Any = "z", **options: Any):
        self.normal = unit_axis(normal, owner=f"Planar {name!r}")
        letter = _axis_letter(normal)
        if letter is not None:
            pair = self._IN_PLANE[letter]
            self.plane_axes = (AXIS_NAMES[pair[0]], AXIS_NAMES[pair[1]])
            self._suffixes = (*pair, "angle")
        else:
            self.plane_axes = normals(self.normal)
            self._suffixes = ("u", "v", "angle")
        super().__init__(name, parent, child, **options)

    @property
    def coord_suffixes(self) -> tuple[str, ...]:
        return self._suffixes

    def summary(self) -> str:
        name = axis_name(self.normal)
        return f"{self.kind} normal {name if isinstance(name, str) else tuple(name)}"

    def _screws(self):
        return [("P", self.plane_axes[0]), ("P", self.plane_axes[1]), ("R", self.normal)]
