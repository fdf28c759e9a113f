"""Colliding shapes: contacts between the collision shapes of bodies (``mb.Collision``)."""
from __future__ import annotations

from typing import Any

from mbcomp.core.errors import ModelError
from mbcomp.core.params import ParameterSpec, in_range, nonnegative
from mbcomp.spec.components.base import Component
from mbcomp.spec.components.values import name_of


def _side(value: Any, owner: Any, key: str) -> tuple:
    """A side of a collision as a tuple of ``(body, shape or None)`` entries: a body, a
    ``(body, shape)`` pair, or a list of them (None: the body's own ``shape`` collides)."""
    from mbcomp.spec.shapes import COLLIDING, Shape
    if isinstance(value, tuple) and len(value) == 2 and isinstance(value[1], Shape):
        items = [value]
    elif isinstance(value, (list, tuple)):
        items = list(value)
    else:
        items = [value]
    if not items:
        raise ModelError(owner, f"{key} must name at least one body")
    entries = []
    for item in items:
        shape = None
        if isinstance(item, tuple) and len(item) == 2 and isinstance(item[1], Shape):
            item, shape = item
            if not isinstance(shape, COLLIDING):
                raise ModelError(owner, f"{key}: a {type(shape).__name__} does not collide; use mb.Sphere, mb.Box, "
                                        "mb.Capsule or mb.Plane")
        if isinstance(item, Shape) or not (isinstance(item, str) or hasattr(item, "name")):
            raise ModelError(owner, f"{key} must be a body, (body, shape) or a list of them, got {item!r}")
        entries.append((item, shape))
    return tuple(entries)


class Collision(Component):
    """Contacts between the collision shapes of bodies (``mb.Sphere``, ``mb.Box``,
    ``mb.Capsule``, ``mb.Plane``).

    ``a`` and ``b`` are each a body (its ``shape`` collides: every Sphere, Box, Capsule and
    Plane among its shapes), a ``(body, shape)`` pair (the shape in the body's frame; the
    ground may carry one, e.g. ``(m.ground, mb.Plane())``), or a list of these; every entry
    of ``a`` collides with every entry of ``b`` on another body (the same list on both sides:
    each unordered pair once).  Every touching feature (a sphere's nearest point, a box's
    corner, a capsule's end or nearest point) is a contact with Newton's impact law of
    coefficient ``restitution`` in [0, 1], and ``friction`` (Coulomb's coefficient).  Each
    is named ``NAME`` when the collision has one feature, else ``NAME[i]``.
    """

    kind = "collision"
    section = "collisions"
    params = (ParameterSpec("restitution", (), "", in_range(0.0, 1.0), default=0.0,
                            doc="Newton's coefficient of restitution"),
              ParameterSpec("friction", (), "", nonnegative, default=0.0, doc="Coulomb's friction coefficient"))
    file_keys = ("a", "b", "restitution", "friction")
    file_required = ("a", "b")
    file_options = {"a": "collision_side", "b": "collision_side"}

    def __init__(self, name: str, a: Any, b: Any, restitution: float = 0.0, friction: float = 0.0):
        super().__init__(name)
        self.a = _side(a, self, "a")
        self.b = _side(b, self, "b")
        self.restitution = restitution
        self.friction = friction

    def references(self) -> dict[str, Any]:
        refs = {}
        for key in ("a", "b"):
            entries = getattr(self, key)
            if len(entries) == 1:
                refs[key] = entries[0][0]
            else:
                refs.update({f"{key}{i}": body for i, (body, _) in enumerate(entries)})
        return refs

    def file_value(self, key: str) -> Any:
        return getattr(self, key)

    def is_conservative(self) -> bool:
        return False

    def structure(self) -> tuple:
        return ()

    def same_sides(self) -> bool:
        """True when both sides list the same entries (each unordered pair once)."""
        names = lambda side: [(name_of(body), shape) for body, shape in side]  # noqa: E731
        return names(self.a) == names(self.b)
