"""Constraints kept with Lagrange multipliers, Baumgarte stabilised."""
from .base import Formulation


class DaeFormulation(Formulation):
    """Augmented system with multipliers (``baumgarte=(alpha, beta)``)."""

    name = "dae"
