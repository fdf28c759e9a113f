"""Geometric primitives that constraints are written in (evaluated by ``constraint_set``).

- ``PointEquation``: ``n . (p_b - p_a) = 0`` with the unit ``n`` fixed in ``frame``
  (a body or the ground), ``p_a``/``p_b`` body points (m, body frames) given as the
  key of the parameter that holds them (``"slider.point"``) or as constants.  Its multiplier
  is the force (N) along ``n`` on body ``b`` (and its opposite on ``a``).
- ``DotEquation``: ``u_a . u_b = 0`` for unit vectors fixed in two bodies; its
  multiplier is a torque (N m) about ``u_b x u_a`` on body ``b``.
- ``CoordinateEquation``: ``q_k - s(t) = 0`` (or, with ``speed``, ``qd_k - speed = 0``);
  its multiplier is the generalised force along coordinate ``k``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable


@dataclass(frozen=True)
class PointEquation:
    frame: Any
    normal: tuple
    body_a: Any
    point_a: tuple
    body_b: Any
    point_b: tuple
    label: str = ""
    offset: Any = None  #: a parameter key (m) subtracted from the residual (a contact sphere's radius)


@dataclass(frozen=True)
class DotEquation:
    body_a: Any
    u_a: tuple
    body_b: Any
    u_b: tuple
    label: str = ""


@dataclass(frozen=True)
class CoordinateEquation:
    joint: Any
    position: Callable[[float], float] | None = None
    speed: float | None = None
    label: str = ""


@dataclass(frozen=True)
class CoordinateGap:
    """A unilateral gap on a tree coordinate: ``sign * (q_k - bound)`` with the bound a
    parameter key (a ``JointLimit`` side); its multiplier is the generalised force along
    ``sign`` times the coordinate."""

    joint: Any
    bound: str
    sign: int
    label: str = ""


@dataclass(frozen=True)
class RollingEquation:
    """One row of a rolling (or no-slip) contact between ``body`` and ``plane`` (a body or
    the ground) at the contact point ``c(q)``: the relative velocity of the two bodies'
    material points at ``c`` along the unit ``direction`` (constants, fixed in ``frame``:
    the plane or the body) is zero::

        direction . (v_body(c) - v_plane(c)) = 0

    ``contact`` says where ``c`` is: ``("point", key)`` a body point (parameter key, body
    frame); ``("ball", center_key, radius_key)`` the ball's point nearest the plane,
    ``center - radius n``; ``("disc", center_key, radius_key, axis)`` the lowest point of
    a thin disc of body-frame ``axis`` (``n`` the plane's unit ``normal``, constants in the
    plane's frame).  With ``origin`` (a parameter key: a point of the plane, plane frame)
    the row is holonomic, ``g = direction . (c - origin)``, whose rate is the row; without
    it the row constrains speeds only (``g`` is NaN in ``ConstraintValues``, 0 in the
    generated code so that Baumgarte's velocity term acts on it alone).  Its multiplier is
    the force (N) along ``direction`` on ``body`` at ``c`` (its opposite on ``plane``).
    """

    body: Any
    plane: Any
    frame: Any
    direction: tuple
    contact: tuple
    normal: tuple = (0.0, 0.0, 1.0)
    origin: str | None = None
    label: str = ""

    @property
    def speed_only(self) -> bool:
        return self.origin is None
