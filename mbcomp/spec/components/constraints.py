"""Constraints: Slider (body point on a world line) and Motor (prescribed joint motion)."""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from mbcomp.core.errors import ModelError, describe
from mbcomp.core.params import ParameterSpec, unit_vector
from mbcomp.core.rotations import AXIS_NAMES, normals
from mbcomp.spec.components.base import Constraint
from mbcomp.spec.components.primitives import CoordinateEquation, DotEquation, PointEquation
from mbcomp.spec.components.frame import split_frame

WORLD_AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


class Slider(Constraint):
    """The body ``point`` (m, body frame) stays on the world line through ``origin`` (m)
    along ``axis``.  Two equations: the point's offset from the line along two normals.
    Reaction: the force (N) the line exerts on the body, along those two normals.
    """

    kind = "slider"
    section = "constraints"
    n_equations = 2
    params = (ParameterSpec("point", (3,), "m", default=(0.0, 0.0, 0.0), doc="body point, body frame"),
              ParameterSpec("origin", (3,), "m", default=(0.0, 0.0, 0.0), doc="a point of the line, world frame"),
              ParameterSpec("axis", (3,), "", unit_vector, default="x", structural=True,
                            doc="direction of the line, world frame"))
    refs = {"body": "body"}
    file_keys = ("body", "point", "origin", "axis")
    file_required = ("body", "axis")

    def __init__(self, name: str, body: Any, point: Any = None, origin: Any = (0.0, 0.0, 0.0), axis: Any = "x"):
        super().__init__(name)
        self.body, point, _ = split_frame(body, point, self, "body")
        self.point = point
        self.origin = origin
        self.axis = axis

    def references(self):
        return {"body": self.body}

    def reaction_unit(self, resolve) -> str:
        return "N"

    def structure(self):
        return (self.axis,)

    def _equations(self, ground):
        """Offsets of the point from the line along two world normals (m)."""
        return [PointEquation(ground, n, ground, f"{self.name}.origin", self.body, f"{self.name}.point", f"n{i + 1}")
                for i, n in enumerate(normals(self.axis))]


class Motor(Constraint):
    """Prescribes a 1-DOF joint's coordinate: ``position(t)`` (a callable of t, or the text
    of an expression of t such as ``"0.5*sin(2*pi*t)"``, as model files write it) or a
    constant ``speed`` from the initial value.  Its reaction is the torque (N m) or
    force (N) the motor applies along the joint coordinate.  A position given as an
    expression runs in compiled code (with its exact derivatives); a Python callable is
    evaluated in Python, so the simulation steps in Python.
    """

    kind = "motor"
    section = "constraints"
    n_equations = 1
    params = (ParameterSpec("speed", (), "rad/s or m/s", default=None, optional=True,
                            doc="constant speed of the joint coordinate (None when position is given)"),)
    refs = {"joint": "joint"}
    file_keys = ("joint", "speed", "position")
    file_required = ("joint",)
    file_options = {"position": "time"}

    def __init__(self, name: str, joint: Any, position: Callable[[float], float] | str | None = None,
                 speed: float | None = None):
        super().__init__(name)
        self.joint = joint
        if (position is None) == (speed is None):
            raise ModelError(self, "give exactly one of position (a callable of t) or speed")
        if isinstance(position, str):
            from mbcomp.core.expressions import Expression, ExpressionError, parse_expression
            try:
                position = Expression(position, parse_expression(position, {}, allow_t=True), name)
            except ExpressionError as exc:
                raise ModelError(self, f"position: {exc}") from None
        if position is not None and not callable(position):
            raise ModelError(self, f"position must be a callable of t or an expression of t, got {position!r}")
        self.position = position
        self.speed = speed

    def references(self):
        return {"joint": self.joint}

    def check(self, resolved: dict) -> list[str]:
        """Problems against the resolved references (``{"joint": Joint}``); sets nothing."""
        joint = resolved["joint"]
        if joint.n_coords != 1:
            return [f"{describe(self)}: needs a 1-DOF joint, {describe(joint)} has {joint.n_coords} coordinates"]
        return []

    def is_conservative(self) -> bool:
        return False  # it does work on the system

    def reaction_unit(self, resolve) -> str:
        """N m for a rotation, N for a translation (the driven coordinate's generalised force)."""
        return "N" if resolve(self.joint).coord_units[0] == "m" else "N m"

    def structure(self):
        return ("position" if self.position is not None else "speed",)

    def _equations(self, ground):
        return [CoordinateEquation(self.joint, self.position, self.speed, "torque")]


class LoopClosure(Constraint):
    """The constraint equations of a loop-closing (cut) joint, made by the compiler.

    Point coincidence of the joint's two points along world axes (multipliers: the
    force on the child, N, world frame) plus the orientation conditions the joint
    type imposes (multipliers: torques, N m).  Reactions carry the joint's name.
    """

    def __init__(self, joint):
        super().__init__("closure")
        object.__setattr__(self, "name", joint.name)  # may be a nested (dotted) name
        self.joint = joint

    def references(self):
        return {"joint": self.joint}

    def _equations(self, ground):
        from mbcomp.spec.components.joints import Ball, Cylindrical, Fixed, Free, Planar, Prismatic, Revolute, Spherical, Universal
        j = self.joint
        if isinstance(j, Free):
            raise ModelError(j, "a Free joint constrains nothing, so it cannot close a loop")
        a, b, pa, pb = j.parent, j.child, f"{j.name}.parent_point", f"{j.name}.child_point"
        # Directions of the joint frames in their body frames (rotated frames: R_pf, R_cf).
        Rp, Rc = j.parent_frame_rotation, j.child_frame_rotation
        in_a = (lambda v: v) if j.parent_rotation is None else (lambda v: _rotated(Rp, v))
        in_b = (lambda v: v) if j.child_rotation is None else (lambda v: _rotated(Rc, v))
        if isinstance(j, Prismatic):
            eqs = [PointEquation(a, in_a(n), a, pa, b, pb, f"f{i + 1}") for i, n in enumerate(normals(j.axis))]
            return eqs + _orientation_lock(a, b, in_a, in_b)
        if isinstance(j, Cylindrical):  # on the axis line, the axis kept parallel
            eqs = [PointEquation(a, in_a(n), a, pa, b, pb, f"f{i + 1}") for i, n in enumerate(normals(j.axis))]
            return eqs + [DotEquation(a, in_a(j.axis), b, in_b(n), f"t{i + 1}") for i, n in enumerate(normals(j.axis))]
        if isinstance(j, Planar):  # in the plane, the normal kept parallel
            eqs = [PointEquation(a, in_a(j.normal), a, pa, b, pb, "f")]
            return eqs + [DotEquation(a, in_a(j.normal), b, in_b(n), f"t{i + 1}") for i, n in enumerate(j.plane_axes)]
        eqs = [PointEquation(ground, n, a, pa, b, pb, "fxyz"[i + 1]) for i, n in enumerate(WORLD_AXES)]
        if isinstance(j, Fixed):
            return eqs + _orientation_lock(a, b, in_a, in_b)
        if isinstance(j, Revolute) or isinstance(j, Spherical) and len(j.sequence) == 1:
            axis = j.axis if isinstance(j, Revolute) else AXIS_NAMES[j.sequence]
            return eqs + [DotEquation(a, in_a(axis), b, in_b(n), f"t{i + 1}") for i, n in enumerate(normals(axis))]
        if isinstance(j, Spherical) and len(j.sequence) == 2:
            return eqs + [DotEquation(a, in_a(AXIS_NAMES[j.sequence[0]]), b, in_b(AXIS_NAMES[j.sequence[1]]), "t")]
        if isinstance(j, (Spherical, Ball)):
            return eqs
        if isinstance(j, Universal):
            if abs(float(np.dot(j.axes[0], j.axes[1]))) > 1e-12:
                raise ModelError(j, "a universal joint closes a loop only with perpendicular axes")
            return eqs + [DotEquation(a, in_a(j.axes[0]), b, in_b(j.axes[1]), "t")]
        raise ModelError(j, "this joint type cannot close a loop")


def _rotated(R, v):
    """``R @ v`` as a tuple of floats (a joint-frame direction in its body frame)."""
    return tuple(float(x) for x in np.asarray(R) @ np.asarray(v, dtype=float))


def _orientation_lock(a, b, in_a=lambda v: v, in_b=lambda v: v):
    """Three conditions keeping frame b's axes parallel to frame a's (``in_a``/``in_b`` map
    joint-frame directions into the body frames)."""
    x, y, z = WORLD_AXES
    return [DotEquation(a, in_a(x), b, in_b(y), "tz"), DotEquation(a, in_a(y), b, in_b(z), "tx"),
            DotEquation(a, in_a(z), b, in_b(x), "ty")]
