"""Unilateral contacts with Newton's impact law and Coulomb friction."""
from __future__ import annotations

from typing import Any

from mbcomp.core.params import ParameterSpec, in_range, nonnegative, unit_vector
from mbcomp.spec.components.base import Component
from mbcomp.spec.components.frame import split_frame


class Contact(Component):
    """A body ``point`` (m, body frame) that may not cross the plane through ``origin`` with
    unit ``normal`` (world frame): gap ``normal . (p - origin) - radius >= 0``.  When the gap
    closes, the normal velocity reverses with the coefficient ``restitution`` in [0, 1].

    ``friction`` is Coulomb's coefficient (dimensionless, >= 0): a closed contact sticks
    while the tangential force it needs stays within ``friction`` times its normal force
    and slides against the slip velocity otherwise (``docs/contacts.md``).  ``radius`` (m,
    >= 0) makes the contact a sphere about the body point: the gap is measured to the
    sphere's surface and the force acts where it touches, at ``p - radius * normal``.
    """

    kind = "contact"
    section = "contacts"
    params = (ParameterSpec("point", (3,), "m", default=(0.0, 0.0, 0.0), doc="body point, body frame"),
              ParameterSpec("normal", (3,), "", unit_vector, default=(0.0, 0.0, 1.0), structural=True,
                            doc="plane normal, world frame (stored as a unit vector)"),
              ParameterSpec("origin", (3,), "m", default=(0.0, 0.0, 0.0), doc="a point of the plane, world frame"),
              ParameterSpec("restitution", (), "", in_range(0.0, 1.0), default=0.0,
                            doc="Newton's coefficient of restitution"),
              ParameterSpec("friction", (), "", nonnegative, default=0.0,
                            doc="Coulomb's coefficient of friction"),
              ParameterSpec("radius", (), "m", nonnegative, default=0.0,
                            doc="radius of the sphere about the body point that touches the plane"))
    refs = {"body": "body"}
    file_keys = ("body", "point", "normal", "origin", "restitution", "friction", "radius")
    file_required = ("body", "normal")

    def __init__(self, name: str, body: Any, point: Any = None, normal: Any = (0.0, 0.0, 1.0),
                 origin: Any = (0.0, 0.0, 0.0), restitution: float = 0.0, friction: float = 0.0,
                 radius: float = 0.0):
        super().__init__(name)
        self.body, point, _ = split_frame(body, point, self, "body")
        self.point = point
        self.normal = normal
        self.origin = origin
        self.restitution = restitution
        self.friction = friction
        self.radius = radius

    def references(self):
        return {"body": self.body}

    def is_conservative(self) -> bool:
        return False  # impacts dissipate (restitution < 1) and resting contact is not tracked in the energy

    def structure(self):
        return (self.normal,)

    def gap_equation(self, ground):
        """The gap as a point equation: ``normal . (p - origin) - radius`` (m), world-fixed
        normal (the sphere's surface moves with its centre along the normal, so the Jacobian
        and bias are the centre's)."""
        from mbcomp.spec.components.primitives import PointEquation
        return PointEquation(ground, self.normal, ground, f"{self.name}.origin", self.body, f"{self.name}.point", "gap",
                             offset=f"{self.name}.radius")
