"""Model -> FlatModel: the frozen copy the compiler works on.

Compiling never changes the user's components and keeps no reference to them: the
compiler reads a ``FlatModel`` whose components are copies (references between them
stay consistent), frozen so that nothing downstream can change them either.  Editing a
component after ``compile()`` therefore changes later compilations only, never a
compiled ``System``.  A FlatModel is also the recipe to rebuild (unpickle) a System.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping

from .components import Component


@dataclass(frozen=True)
class FlatModel:
    """A model's name, gravity (m/s^2, world frame), ground and components (by name, in
    the order they were added, ground first), all frozen copies."""

    name: str
    gravity: tuple
    ground: Any
    components: Mapping[str, Component]

    def __getitem__(self, name: str) -> Component:
        return self.components[name]

    def __reduce__(self):
        return (FlatModel, (self.name, self.gravity, self.ground, dict(self.components)))

    def __post_init__(self) -> None:
        if not isinstance(self.components, MappingProxyType):
            object.__setattr__(self, "components", MappingProxyType(dict(self.components)))


def flatten(model: Any) -> FlatModel:
    """A frozen copy of ``model`` (a ``Model`` or a ``FlatModel``) for the compiler.

    Components are deep-copied together (a joint's ``parent`` in the copy is the copy of
    its parent body; a reference to an object that was never added stays a foreign
    object, which the topology reports) and frozen; callables are shared, not copied.
    """
    components = dict(model.components)
    memo: dict[int, Any] = {}
    copies = copy.deepcopy(components, memo)
    ground = copies.get(model.ground.name, copy.deepcopy(model.ground, memo))
    for comp in list(copies.values()) + [ground]:
        comp._freeze()
    return FlatModel(model.name, tuple(float(g) for g in model.gravity), ground, copies)
