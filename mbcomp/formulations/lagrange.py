"""Minimal coordinates: constraints reduced away by coordinate partitioning."""
from .base import Formulation


class LagrangeFormulation(Formulation):
    """Independent coordinates only; dependent ones follow from the constraints."""

    name = "lagrange"
