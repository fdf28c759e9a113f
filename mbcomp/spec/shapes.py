"""Body shapes: what the 3D viewer draws for a body (display data only).

A shape never enters the equations of motion: it is neither a parameter nor structure, so
changing it needs no recompilation and two models that differ only in shapes compile to the
same code.  Every shape sits in its body's frame: ``origin`` (m) is where its centre goes and
``rotation`` (a 3x3 rotation matrix, body frame from shape frame) how it is turned.

``Box(size)`` is centred on its origin with edges ``size = (x, y, z)`` along the shape axes;
``Cylinder(radius, length, axis)`` is centred on its origin with its axis along ``axis``
(``"x"``, ``"y"``, ``"z"`` or a 3-vector); ``Sphere(radius)``; ``Mesh(path, scale)`` reads a
triangle mesh file (STL, OBJ, DAE, ... through the optional ``trimesh`` package) when the page
is written.  ``color`` is a CSS-style ``"#rrggbb"`` string, a name known to matplotlib, or an
``(r, g, b)`` triple in 0..1; ``None`` picks one per body.

``Capsule(radius, length, axis)`` (a cylinder of ``length`` between the centres of two
hemispherical caps of ``radius``) and ``Plane(normal, origin)`` (the half-space behind the
plane, drawn as a large square) complete the shapes that collide: ``Sphere``, ``Box``,
``Capsule`` and ``Plane`` take part in ``mb.Collision`` contacts (``Cylinder`` and ``Mesh``
are drawn only).  A shape is still no parameter: its sizes are read when a run starts.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError

__all__ = ["Shape", "Box", "Cylinder", "Sphere", "Capsule", "Plane", "Mesh", "COLLIDING", "as_shapes", "shape_table", "shape_from_table", "SHAPE_KEYS"]


def _vector(value: Any, owner: str, what: str, *, positive: bool = False) -> tuple[float, float, float]:
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError(owner, f"{what} must be a 3-vector of numbers, got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ModelError(owner, f"{what} must be 3 finite numbers, got {value!r}")
    if positive and np.any(arr <= 0):
        raise ModelError(owner, f"{what} must be positive, got {tuple(arr.tolist())}")
    return tuple(float(v) for v in arr)


def _positive(value: Any, owner: str, what: str) -> float:
    if isinstance(value, bool):
        raise ModelError(owner, f"{what} must be a positive number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ModelError(owner, f"{what} must be a positive number, got {value!r}") from None
    if not (np.isfinite(x) and x > 0):
        raise ModelError(owner, f"{what} must be a positive number, got {value!r}")
    return x


def _rotation(value: Any, owner: str) -> tuple[float, ...]:
    """A 3x3 rotation matrix (row-major 9-tuple); ``None`` is the identity."""
    if value is None:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    try:
        R = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(owner, f"rotation must be a 3x3 rotation matrix, got {value!r}") from None
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ModelError(owner, f"rotation must be a 3x3 rotation matrix, got shape {R.shape}")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise ModelError(owner, "rotation must be a proper rotation matrix (orthonormal, det +1)")
    return tuple(float(v) for v in R.reshape(-1))


def _color(value: Any, owner: str) -> str | None:
    """``"#rrggbb"`` or None."""
    if value is None:
        return None
    try:
        from matplotlib.colors import to_hex
        return to_hex(value)
    except (ValueError, TypeError):
        raise ModelError(owner, f"color must be '#rrggbb', a color name or (r, g, b) in 0..1, "
                                f"got {value!r}") from None


def _axis(value: Any, owner: str) -> tuple[float, float, float]:
    if isinstance(value, str):
        axes = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}
        if value.lower() not in axes:
            raise ModelError(owner, f"axis must be 'x', 'y', 'z' or a 3-vector, got {value!r}")
        return axes[value.lower()]
    v = np.asarray(_vector(value, owner, "axis"))
    norm = float(np.linalg.norm(v))
    if norm == 0:
        raise ModelError(owner, "axis must not be the zero vector")
    if abs(norm - 1.0) <= 4 * np.finfo(float).eps:
        norm = 1.0   # a unit vector to rounding stays as given (a saved axis reads back bit for bit)
    return tuple(float(c) for c in v / norm)


@dataclass(frozen=True)
class Shape:
    """Common fields: placement in the body frame and color."""

    origin: tuple = (0.0, 0.0, 0.0)
    rotation: tuple = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    color: str | None = None

    def _place(self, origin: Any, rotation: Any, color: Any) -> None:
        owner = type(self).__name__
        object.__setattr__(self, "origin", _vector(origin, owner, "origin"))
        object.__setattr__(self, "rotation", _rotation(rotation, owner))
        object.__setattr__(self, "color", _color(color, owner))

    def placement(self) -> np.ndarray:
        """4x4 homogeneous transform body frame <- shape frame."""
        T = np.eye(4)
        T[:3, :3] = np.reshape(self.rotation, (3, 3))
        T[:3, 3] = self.origin
        return T


@dataclass(frozen=True, init=False)
class Box(Shape):
    """A box with edge lengths ``size`` (m) along the shape's x, y, z axes, centred on ``origin``."""

    size: tuple = (1.0, 1.0, 1.0)

    def __init__(self, size: Any, origin: Any = (0.0, 0.0, 0.0), rotation: Any = None, color: Any = None):
        object.__setattr__(self, "size", _vector(size, "Box", "size", positive=True))
        self._place(origin, rotation, color)


@dataclass(frozen=True, init=False)
class Cylinder(Shape):
    """A cylinder of ``radius`` and ``length`` (m) along ``axis``, centred on ``origin``."""

    radius: float = 1.0
    length: float = 1.0
    axis: tuple = (0.0, 0.0, 1.0)

    def __init__(self, radius: float, length: float, axis: Any = "z", origin: Any = (0.0, 0.0, 0.0),
                 rotation: Any = None, color: Any = None):
        object.__setattr__(self, "radius", _positive(radius, "Cylinder", "radius"))
        object.__setattr__(self, "length", _positive(length, "Cylinder", "length"))
        object.__setattr__(self, "axis", _axis(axis, "Cylinder"))
        self._place(origin, rotation, color)


@dataclass(frozen=True, init=False)
class Sphere(Shape):
    """A sphere of ``radius`` (m) centred on ``origin``."""

    radius: float = 1.0

    def __init__(self, radius: float, origin: Any = (0.0, 0.0, 0.0), color: Any = None):
        object.__setattr__(self, "radius", _positive(radius, "Sphere", "radius"))
        self._place(origin, None, color)


@dataclass(frozen=True, init=False)
class Capsule(Shape):
    """A capsule: the points within ``radius`` (m) of the segment of ``length`` (m) along
    ``axis`` centred on ``origin`` (a cylinder with hemispherical caps; overall length
    ``length + 2 radius``)."""

    radius: float = 1.0
    length: float = 1.0
    axis: tuple = (0.0, 0.0, 1.0)

    def __init__(self, radius: float, length: float, axis: Any = "z", origin: Any = (0.0, 0.0, 0.0),
                 color: Any = None):
        object.__setattr__(self, "radius", _positive(radius, "Capsule", "radius"))
        object.__setattr__(self, "length", _positive(length, "Capsule", "length"))
        object.__setattr__(self, "axis", _axis(axis, "Capsule"))
        self._place(origin, None, color)


@dataclass(frozen=True, init=False)
class Plane(Shape):
    """The half-space behind the plane through ``origin`` (m) with outward unit ``normal``
    (both in the frame of the body carrying it; the ground's is the world frame): what lies
    on the side ``normal . (p - origin) < 0`` is solid.  Drawn as a square of ``extent`` (m)."""

    normal: tuple = (0.0, 0.0, 1.0)
    extent: float = 2.0

    def __init__(self, normal: Any = (0.0, 0.0, 1.0), origin: Any = (0.0, 0.0, 0.0), extent: float = 2.0,
                 color: Any = None):
        object.__setattr__(self, "normal", _axis(normal, "Plane"))
        object.__setattr__(self, "extent", _positive(extent, "Plane", "extent"))
        self._place(origin, None, color)


@dataclass(frozen=True, init=False)
class Mesh(Shape):
    """A triangle mesh read from ``path`` (any format ``trimesh`` reads), its vertices scaled by
    ``scale`` (a number or a 3-vector; e.g. 0.001 for a file in millimetres)."""

    path: str = ""
    scale: tuple = (1.0, 1.0, 1.0)

    def __init__(self, path: str | os.PathLike, scale: Any = 1.0, origin: Any = (0.0, 0.0, 0.0),
                 rotation: Any = None, color: Any = None):
        if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
            raise ModelError("Mesh", f"path must be a file path, got {path!r}")
        object.__setattr__(self, "path", os.fspath(path))
        if np.ndim(scale) == 0:
            s = _positive(scale, "Mesh", "scale")
            scale = (s, s, s)
        object.__setattr__(self, "scale", _vector(scale, "Mesh", "scale", positive=True))
        self._place(origin, rotation, color)

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """(vertices (n, 3) in the shape frame, m; faces (k, 3) vertex indices), via trimesh."""
        try:
            import trimesh
        except ImportError:
            raise ModelError("Mesh", f"drawing the mesh {self.path} needs the optional package trimesh: "
                                     "pip install 'mbcomp[mesh]'") from None
        if not Path(self.path).is_file():
            raise ModelError("Mesh", f"mesh file {self.path} does not exist")
        try:
            loaded = trimesh.load(self.path, force="mesh")
        except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds; report the file
            raise ModelError("Mesh", f"cannot read the mesh file {self.path}: {exc}") from None
        vertices = np.asarray(loaded.vertices, dtype=float) * np.asarray(self.scale)
        faces = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
        if vertices.size == 0 or faces.size == 0:
            raise ModelError("Mesh", f"the mesh file {self.path} holds no triangles")
        return vertices, faces


def as_shapes(value: Any, owner: Any = "Body") -> tuple[Shape, ...]:
    """A body's ``shape`` argument as a tuple of shapes: None, one shape, or a sequence of them."""
    if value is None:
        return ()
    items = value if isinstance(value, (list, tuple)) else (value,)
    for item in items:
        if not isinstance(item, Shape):
            raise ModelError(owner, f"shape must be mb.Box, mb.Cylinder, mb.Sphere, mb.Capsule, mb.Plane, mb.Mesh "
                                    f"or a list of "
                                    f"them, got {item!r}")
    return tuple(items)


_IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
#: The keys of a shape's table in a model file, by its ``type``.
SHAPE_KEYS = {"box": ("size",), "cylinder": ("radius", "length", "axis"), "sphere": ("radius",),
              "capsule": ("radius", "length", "axis"), "plane": ("normal", "extent"), "mesh": ("path", "scale")}
_CLASSES = {"box": Box, "cylinder": Cylinder, "sphere": Sphere, "capsule": Capsule, "plane": Plane, "mesh": Mesh}
_PLACEMENT = {"box": ("origin", "rotation", "color"), "cylinder": ("origin", "rotation", "color"),
              "sphere": ("origin", "color"), "capsule": ("origin", "color"), "plane": ("origin", "color"),
              "mesh": ("origin", "rotation", "color")}
#: The shapes that collide (``mb.Collision``): the others are drawn only.
COLLIDING = (Sphere, Box, Capsule, Plane)


def axis_name(axis: tuple) -> Any:
    """``"x"``, ``"y"`` or ``"z"`` for a unit coordinate axis, else the 3 numbers as a list."""
    return next((name for name, unit in (("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0)), ("z", (0.0, 0.0, 1.0)))
                 if tuple(axis) == unit), list(axis))


def shape_table(shape: Shape) -> dict:
    """The table a model file holds for ``shape``: ``{type = "box", size = [...], ...}`` (m;
    ``rotation`` as 3 rows, body frame from shape frame); defaults are left out."""
    kind = next(k for k, cls in _CLASSES.items() if type(shape) is cls)
    table: dict[str, Any] = {"type": kind}
    for key in SHAPE_KEYS[kind]:
        value = getattr(shape, key)
        table[key] = list(value) if isinstance(value, tuple) else value
    if kind in ("cylinder", "capsule", "plane"):
        key = "normal" if kind == "plane" else "axis"
        table[key] = axis_name(getattr(shape, key))
    if kind == "plane" and shape.extent == 2.0:
        del table["extent"]
    if kind == "mesh" and len(set(shape.scale)) == 1:
        table["scale"] = shape.scale[0]
    if any(shape.origin):
        table["origin"] = list(shape.origin)
    if shape.rotation != _IDENTITY:
        table["rotation"] = [list(shape.rotation[i:i + 3]) for i in (0, 3, 6)]
    if shape.color is not None:
        table["color"] = shape.color
    return table


def shape_from_table(table: Any, owner: str = "shape") -> Shape:
    """The shape a model file's table describes (see ``shape_table``); ``ModelError`` names
    the key of a bad value.  Values are data: numbers, number lists and strings only."""
    if not isinstance(table, dict):
        raise ModelError(owner, f"must be a table such as {{ type = \"box\", size = [0.1, 0.1, 0.1] }}, "
                                f"got {type(table).__name__}")
    kind = table.get("type")
    if kind not in _CLASSES:
        raise ModelError(owner, f"type must be one of {', '.join(_CLASSES)}, got {kind!r}")
    allowed = ("type",) + SHAPE_KEYS[kind] + _PLACEMENT[kind]
    unknown = [k for k in table if k not in allowed]
    if unknown:
        raise ModelError(owner, f"unknown key {unknown[0]!r} for a {kind}; allowed: {', '.join(allowed[1:])}")
    required = {"box": ("size",), "cylinder": ("radius", "length"), "sphere": ("radius",),
                "capsule": ("radius", "length"), "plane": (), "mesh": ("path",)}[kind]
    missing = [k for k in required if k not in table]
    if missing:
        raise ModelError(owner, f"a {kind} needs {', '.join(missing)}")
    for key, value in table.items():
        if key in ("type", "path", "color", "axis") or (key == "normal" and isinstance(value, str)):
            continue   # checked by the shape's own constructor
        flat = value if isinstance(value, list) else [value]
        flat = [x for row in flat for x in (row if isinstance(row, list) else [row])]
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in flat):
            raise ModelError(owner, f"{key} must be numbers, got {value!r}")
    if "path" in table and not isinstance(table["path"], str):
        raise ModelError(owner, f"path must be a string, got {table['path']!r}")
    values = {k: v for k, v in table.items() if k != "type"}
    try:
        return _CLASSES[kind](**values)
    except ModelError as exc:
        detail = str(exc).split(": ", 1)[-1]
        raise ModelError(owner, detail) from None
