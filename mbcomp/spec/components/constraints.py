"""Constraints: Slider (body point on a world line) and Motor (prescribed joint motion)."""
from __future__ import annotations

from typing import Any, Callable

from mbcomp.core.errors import ModelError, describe
from mbcomp.core.params import ParameterSpec, unit_vector
from mbcomp.core.rotations import normals
from mbcomp.spec.components.base import Constraint
from mbcomp.spec.components.primitives import CoordinateEquation, PointEquation
from mbcomp.spec.components.frame import split_frame


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

    def equations(self, ground):
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

    def equations(self, ground):
        return [CoordinateEquation(self.joint, self.position, self.speed, "torque")]


class LoopClosure(Constraint):
    """The constraint equations of a loop-closing (cut) joint, made by the compiler.

    The joint says what holds (``Joint.closure_equations``, derived from its segments, so
    a joint class written from segments closes loops too): point coincidence of its two
    points along the directions it does not slide in (multipliers: the force on the child,
    N) plus the orientation conditions its rotations leave (multipliers: torques, N m).
    Reactions carry the joint's name.
    """

    noun = "loop closure"

    def __init__(self, joint):
        super().__init__("closure")
        object.__setattr__(self, "name", joint.name)  # may be a nested (dotted) name
        self.joint = joint

    def references(self):
        return {"joint": self.joint}

    def equations(self, ground):
        """The cut joint's own closure conditions (``Joint.closure_equations``, from its segments)."""
        return self.joint.closure_equations(ground)
