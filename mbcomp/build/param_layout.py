"""Where the parameters and the run-time inputs live in the flat vectors ``p`` and ``u`` of
the generated functions.

Apart from the equations (``equations.py``) because loading a model's code from the cache
needs the layouts but no symbolic work: this module does not import sympy.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class ParameterLayout:
    """Where each parameter lives in the flat parameter vector ``p``.

    ``entries[key] = (start, shape)`` with key ``"component.attribute"`` (``"gravity"``
    for the model's gravity); ``shape`` is ``()`` for a scalar or ``(k,)``.
    """

    entries: dict
    size: int

    def pack(self, values: dict) -> np.ndarray:
        """Flat ``p`` from ``{key: value}`` (every key of the layout)."""
        p = np.empty(self.size)
        for key, (start, shape) in self.entries.items():
            width = shape[0] if shape else 1
            p[start:start + width] = np.asarray(values[key], dtype=float).reshape(-1)
        return p

    def symbols(self, key: str):
        """The sympy symbol(s) of parameter ``key`` in generated programs."""
        import sympy as sp  # only when a program is built
        start, shape = self.entries[key]
        if not shape:
            return sp.Symbol(_symbol_name(key))
        return [sp.Symbol(_symbol_name(f"{key}[{i}]")) for i in range(shape[0])]


def _symbol_name(key: str) -> str:
    return key


def parameter_values(model) -> dict[str, Any]:
    """``{"component.attribute": value}`` for every numeric parameter of the model."""
    values: dict[str, Any] = {"gravity": tuple(model.gravity)}
    for comp in model.components.values():
        for attr, value in comp.parameter_values().items():
            values[f"{comp.name}.{attr}"] = value if np.ndim(value) == 0 else tuple(value)
    return values


def parameter_layout(values: dict[str, Any]) -> ParameterLayout:
    """The layout of ``parameter_values``: keys in order, scalars and vectors packed flat."""
    entries, size = {}, 0
    for key, value in values.items():
        shape = () if np.ndim(value) == 0 else (len(value),)
        entries[key] = (size, shape)
        size += shape[0] if shape else 1
    return ParameterLayout(entries=entries, size=size)


def input_layout(topology) -> dict[str, tuple[int, int]]:
    """Run-time inputs (callable forces and torques): ``{component name: (start, size)}``."""
    layout, size = {}, 0
    for comp in topology.forces:
        width = topology.input_sizes.get(comp.name, 0)
        if width:
            layout[comp.name] = (size, width)
            size += width
    return layout
