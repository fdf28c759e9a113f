"""Rolling and sliding without slip: velocity (non-holonomic) constraints.

- ``RollingDisc``: a thin disc rolls on a plane (the ground's or a body's): its lowest point
  touches the plane (one holonomic row) and moves with the plane there (two velocity rows).
- ``RollingBall``: a ball rolls (free to spin about the normal) on a plane: the same three rows.
- ``NoSlip``: a body point does not move along a body-fixed direction (a blade, a skate, the
  Chaplygin sleigh's knife edge): one velocity row.

Each row is a ``primitives.RollingEquation``: the relative velocity of the two bodies'
material points at the contact point along a direction; the velocity rows' ``g`` is NaN
(``ConstraintValues``), so that assembly, drift and Baumgarte's position term leave them alone.

Reactions (``System.reactions``, ``Result.reactions``): for ``RollingDisc`` and
``RollingBall`` the contact force (N) the plane exerts on the disc/ball, a world-frame
3-vector; for ``NoSlip`` the force (N) along its ``direction`` on the body at ``point``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.core.params import ParameterSpec, positive, unit_vector
from mbcomp.core.rotations import normals
from mbcomp.spec.components.base import Constraint
from mbcomp.spec.components.frame import split_frame
from mbcomp.spec.components.primitives import RollingEquation


class _RollingOnPlane(Constraint):
    """What a disc and a ball share: the plane (the ground when ``plane`` is None; a body
    otherwise, its ``normal`` and ``origin`` then in that body's frame), the three rows
    (normal: holonomic; two tangents: velocity) and the reaction as a world-frame force."""

    section = "constraints"
    n_equations = 3
    #: the attribute (and reference role) naming the rolling body: "disc" or "ball"
    rolling_role = ""

    @property
    def body(self) -> Any:
        """The rolling body (the disc or the ball)."""
        return getattr(self, self.rolling_role)

    def references(self):
        refs = {self.rolling_role: self.body}
        if self.plane is not None:
            refs["plane"] = self.plane
        return refs

    def reaction_unit(self, resolve) -> str:
        return "N"

    def is_conservative(self) -> bool:
        return True  # rolling without slip does no work (the contact point's velocity is zero)

    def contact(self) -> tuple:
        raise NotImplementedError

    def plane_directions(self) -> np.ndarray:
        """The rows' directions (columns: normal, first and second tangent) in the plane's frame."""
        t1, t2 = normals(self.normal)
        return np.column_stack((self.normal, t1, t2))

    def equations(self, ground):
        """The normal row ``n . (c - origin) = 0`` and the tangent rows ``t_i . v_rel(c) = 0``."""
        plane = ground if self.plane is None else self.plane
        directions = self.plane_directions().T
        contact = self.contact()
        labels = ("n", "t1", "t2")
        return [RollingEquation(self.body, plane, plane, tuple(float(x) for x in d), contact, tuple(self.normal),
                                f"{self.name}.origin" if i == 0 else None, labels[i])
                for i, d in enumerate(directions)]


class RollingDisc(_RollingOnPlane):
    """A thin disc (the body ``disc``; its symmetry ``axis`` in the body frame, through the
    body point ``center``, m) of ``radius`` (m) rolls without slipping on a plane: the
    ground's (``plane=None``: ``normal`` and ``origin`` in the world frame) or a body's
    (``plane=body``: in that body's frame).  Its lowest point (towards the plane along the
    disc's own plane) touches the plane and moves with the plane there; the disc may pivot
    about the normal.  Rows: ``n`` (holonomic: the lowest point's height above the plane),
    ``t1``, ``t2`` (velocity: the slip along two tangents).  Undefined when the disc lies
    flat (its axis along the normal).  Reaction: the contact force on the disc (N, world frame).
    """

    kind = "rolling_disc"
    rolling_role = "disc"
    params = (ParameterSpec("radius", (), "m", positive, default=None, doc="disc radius"),
              ParameterSpec("center", (3,), "m", default=(0.0, 0.0, 0.0), doc="disc centre, body frame"),
              ParameterSpec("axis", (3,), "", unit_vector, default="y", structural=True,
                            doc="symmetry axis, body frame"),
              ParameterSpec("normal", (3,), "", unit_vector, default=(0.0, 0.0, 1.0), structural=True,
                            doc="plane normal, plane frame (world for the ground)"),
              ParameterSpec("origin", (3,), "m", default=(0.0, 0.0, 0.0), doc="a point of the plane, plane frame"))
    refs = {"disc": "body", "plane": "body"}
    file_keys = ("disc", "radius", "axis", "center", "plane", "normal", "origin")
    file_required = ("disc", "radius")

    def __init__(self, name: str, disc: Any, radius: float, axis: Any = "y", center: Any = (0.0, 0.0, 0.0),
                 plane: Any = None, normal: Any = (0.0, 0.0, 1.0), origin: Any = (0.0, 0.0, 0.0)):
        super().__init__(name)
        self.disc = disc
        self.radius = radius
        self.axis = axis
        self.center = center
        self.plane = plane
        self.normal = normal
        self.origin = origin

    def structure(self):
        return (self.axis, self.normal)

    def contact(self) -> tuple:
        return ("disc", f"{self.name}.center", f"{self.name}.radius", tuple(self.axis))


class RollingBall(_RollingOnPlane):
    """A ball (the body ``ball``, centre ``center`` in the body frame, m) of ``radius`` (m)
    rolls without slipping on a plane (the ground's, or a body's as for ``RollingDisc``) and
    is free to spin about the normal.  Rows: ``n`` (holonomic: the centre's height above the
    plane minus the radius), ``t1``, ``t2`` (velocity: the contact point's slip).
    Reaction: the contact force on the ball (N, world frame).
    """

    kind = "rolling_ball"
    rolling_role = "ball"
    params = (ParameterSpec("radius", (), "m", positive, default=None, doc="ball radius"),
              ParameterSpec("center", (3,), "m", default=(0.0, 0.0, 0.0), doc="ball centre, body frame"),
              ParameterSpec("normal", (3,), "", unit_vector, default=(0.0, 0.0, 1.0), structural=True,
                            doc="plane normal, plane frame (world for the ground)"),
              ParameterSpec("origin", (3,), "m", default=(0.0, 0.0, 0.0), doc="a point of the plane, plane frame"))
    refs = {"ball": "body", "plane": "body"}
    file_keys = ("ball", "radius", "center", "plane", "normal", "origin")
    file_required = ("ball", "radius")

    def __init__(self, name: str, ball: Any, radius: float, center: Any = (0.0, 0.0, 0.0), plane: Any = None,
                 normal: Any = (0.0, 0.0, 1.0), origin: Any = (0.0, 0.0, 0.0)):
        super().__init__(name)
        self.ball = ball
        self.radius = radius
        self.center = center
        self.plane = plane
        self.normal = normal
        self.origin = origin

    def structure(self):
        return (self.normal,)

    def contact(self) -> tuple:
        return ("ball", f"{self.name}.center", f"{self.name}.radius")


class NoSlip(Constraint):
    """The velocity of the body ``point`` (m, body frame) along the body-fixed unit
    ``direction`` is zero (a knife edge, skate or wheel that cannot slide sideways: the
    Chaplygin sleigh).  One velocity row; its reaction is the force (N) along ``direction``
    on the body at ``point`` (the blade's side force).
    """

    kind = "no_slip"
    section = "constraints"
    n_equations = 1
    params = (ParameterSpec("point", (3,), "m", default=(0.0, 0.0, 0.0), doc="body point, body frame"),
              ParameterSpec("direction", (3,), "", unit_vector, default="y", structural=True,
                            doc="the direction without slip, body frame"))
    refs = {"body": "body"}
    file_keys = ("body", "point", "direction")
    file_required = ("body", "direction")

    def __init__(self, name: str, body: Any, point: Any = None, direction: Any = "y"):
        super().__init__(name)
        self.body, point, _ = split_frame(body, point, self, "body")
        self.point = point
        self.direction = direction

    def references(self):
        return {"body": self.body}

    def reaction_unit(self, resolve) -> str:
        return "N"

    def structure(self):
        return (self.direction,)

    def equations(self, ground):
        """``direction . v(point) = 0`` with the direction fixed in the body."""
        return [RollingEquation(self.body, ground, self.body, tuple(float(x) for x in self.direction),
                                ("point", f"{self.name}.point"), label="")]
