"""Formulations: ``lagrange`` (minimal coordinates) and ``dae`` (multipliers)."""
from __future__ import annotations

from typing import Any

from mbcomp.core.errors import ModelError
from mbcomp.formulations.base import Formulation
from mbcomp.formulations.dae import DaeFormulation
from mbcomp.formulations.lagrange import LagrangeFormulation

FORMULATIONS = {"lagrange": LagrangeFormulation, "dae": DaeFormulation}


def get_formulation(spec: Any) -> type[Formulation]:
    """The formulation class for ``"lagrange"``, ``"dae"`` or a ``Formulation`` subclass."""
    if isinstance(spec, type) and issubclass(spec, Formulation):
        return spec
    if isinstance(spec, str) and spec in FORMULATIONS:
        return FORMULATIONS[spec]
    raise ModelError("compile", f"formulation must be one of {sorted(FORMULATIONS)} or a Formulation subclass, got {spec!r}")


__all__ = ["FORMULATIONS", "Formulation", "LagrangeFormulation", "DaeFormulation", "get_formulation"]
