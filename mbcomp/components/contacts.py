"""Unilateral contacts with Newton's impact law."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ModelError
from ..rotations import unit_axis
from .base import Component
from .frame import split_frame
from ._values import scalar, vector3


class Contact(Component):
    """A body ``point`` (m, body frame) that may not cross the plane through ``origin`` with
    unit ``normal`` (world frame): gap ``normal . (p - origin) >= 0``.  When the gap
    closes, the normal velocity reverses with the coefficient ``restitution`` in [0, 1].
    """

    parameters = ("point", "origin", "restitution")

    def __init__(self, name: str, body: Any, point: Any = None, normal: Any = (0.0, 0.0, 1.0),
                 origin: Any = (0.0, 0.0, 0.0), restitution: float = 0.0):
        super().__init__(name)
        self.body, point, _ = split_frame(body, point, self, "body")
        self.point = vector3(point, self, "point")
        if isinstance(normal, str):
            self.normal = unit_axis(normal, owner=self)
        else:
            n = np.asarray(vector3(normal, self, "normal"))
            length = float(np.linalg.norm(n))
            if length < 1e-12:
                raise ModelError(self, "normal has zero length")
            self.normal = tuple(float(v) for v in n / length)
        self.origin = vector3(origin, self, "origin")
        self.restitution = scalar(restitution, self, "restitution", low=0.0, high=1.0)

    def references(self):
        return {"body": self.body}

    def structure(self):
        return (self.normal,)

    def _gap_equation(self, ground):
        """The gap as a point equation: ``normal . (p - origin)`` (m), world-fixed normal."""
        from .primitives import PointEquation
        return PointEquation(ground, self.normal, ground, f"{self.name}.origin", self.body, f"{self.name}.point", "gap")
