"""Constraints: Slider (body point on a world line) and Motor (prescribed joint motion)."""
from __future__ import annotations

from typing import Any, Callable

from ..errors import ModelError
from ..rotations import unit_axis
from .base import Constraint
from ._values import scalar, vector3


class Slider(Constraint):
    """The body ``point`` (m, body frame) stays on the world line through ``origin`` (m)
    along ``axis``.  Two equations: the point's offset from the line along two normals.
    Reaction: the force (N) the line exerts on the body, along those two normals.
    """

    n_equations = 2
    parameters = ("point", "origin")

    def __init__(self, name: str, body: Any, point: Any = (0.0, 0.0, 0.0), origin: Any = (0.0, 0.0, 0.0), axis: Any = "x"):
        super().__init__(name)
        self.body = body
        self.point = vector3(point, self, "point")
        self.origin = vector3(origin, self, "origin")
        self.axis = unit_axis(axis, owner=self)

    def references(self):
        return {"body": self.body}

    def structure(self):
        return (self.axis,)


class Motor(Constraint):
    """Prescribes a 1-DOF joint's coordinate: ``position(t)`` (a callable of t) or a
    constant ``speed`` from the initial value.  Its reaction is the torque (N m) or
    force (N) the motor applies along the joint coordinate.
    """

    n_equations = 1
    parameters = ()

    def __init__(self, name: str, joint: Any, position: Callable[[float], float] | None = None,
                 speed: float | None = None):
        super().__init__(name)
        self.joint = joint
        if (position is None) == (speed is None):
            raise ModelError(self, "give exactly one of position (a callable of t) or speed")
        if position is not None and not callable(position):
            raise ModelError(self, f"position must be a callable of t, got {position!r}")
        self.position = position
        self.speed = None if speed is None else scalar(speed, self, "speed")
        if speed is not None:
            self.parameters = ("speed",)

    def references(self):
        return {"joint": self.joint}

    def structure(self):
        return ("position" if self.position is not None else "speed",)
