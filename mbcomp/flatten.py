"""From the model users build to the frozen flat model the compiler reads.

Three steps, all leaving the user's objects untouched:

- sub-model instances become components with dotted names (``"left_leg.thigh.rod"``),
  their references and coordinate names follow;
- ``orient_joints``: a joint given "backwards" relative to the spanning tree (its
  child already reaches the ground, its parent does not) is replaced by the same joint
  pointing the other way, so that joints may be given in either direction;
- ``flatten``: the frozen copy the compiler works on.  Compiling never changes the
  user's components and keeps no reference to them: the compiler reads a ``FlatModel``
  whose components are copies (references between them stay consistent), frozen so
  that nothing downstream can change them either.  Editing a component after
  ``compile()`` therefore changes later compilations only, never a compiled ``System``.
  A FlatModel is also the recipe to rebuild (unpickle) a System.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Mapping

from .components import Component, Fixed, Joint, Prismatic, Revolute
from .components.frame import Frame
from .components._values import name_of


def reversed_joint(joint: Joint) -> Joint | None:
    """The same joint with parent and child swapped (same name, coordinate and its sign),
    or ``None`` when the joint type has no such form.

    A revolute or prismatic joint about ``a`` seen from its child is one about ``-a``
    (``a`` has the same components in both joint frames, which differ by a motion along
    or about ``a``); a fixed joint just swaps its frames.
    """
    parent = Frame(joint.child, joint.child_point, joint.child_rotation)
    child = Frame(joint.parent, joint.parent_point, joint.parent_rotation)
    if isinstance(joint, (Revolute, Prismatic)):
        axis = tuple(-float(a) + 0.0 for a in joint.axis)
        flipped = type(joint)(joint.name, parent, child, axis=axis, coords=joint.coords)
    elif isinstance(joint, Fixed):
        flipped = Fixed(joint.name, parent, child)
    else:
        return None
    return flipped


def orient_joints(components: dict, ground_name: str) -> dict:
    """``components`` with backwards joints reversed (a new dict only when one is)."""
    joints = [c for c in components.values() if isinstance(c, Joint)]
    if not joints:
        return components
    out = None
    while True:
        current = out or components
        reach = _reachable(current, ground_name)
        for joint in (c for c in current.values() if isinstance(c, Joint)):
            parent, child = name_of(joint.parent), name_of(joint.child)
            if (child in reach and parent not in reach and parent in current and parent != child):
                flipped = reversed_joint(joint)
                if flipped is not None:
                    out = dict(current)
                    out[joint.name] = flipped
                    break
        else:
            return current


def _reachable(components: dict, ground_name: str) -> set:
    """Bodies reachable from the ground along parent -> child joints."""
    children: dict[str, list[str]] = {}
    for comp in components.values():
        if isinstance(comp, Joint):
            child = name_of(comp.child)
            if child != ground_name:
                children.setdefault(name_of(comp.parent), []).append(child)
    reach, stack = {ground_name}, [ground_name]
    while stack:
        for child in children.get(stack.pop(), ()):
            if child not in reach:
                reach.add(child)
                stack.append(child)
    return reach


def copy_component(comp: Any, name: str, references: dict) -> Any:
    """A shallow copy of ``comp`` named ``name`` whose reference attributes are replaced
    by ``references`` (role -> new reference)."""
    new = copy.copy(comp)
    roles = comp.references()
    state = vars(comp)
    for role, ref in roles.items():
        if role not in references:
            continue
        for attr, value in state.items():
            if attr != "name" and value is ref:
                object.__setattr__(new, attr, references[role])
    object.__setattr__(new, "name", name)
    return new


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

    def flat(self) -> "FlatModel":
        """Already flat (``Model.flat`` is the step before): itself."""
        return self

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
        comp.freeze()
    return FlatModel(model.name, tuple(float(g) for g in model.gravity), ground, copies)
