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

import numpy as np

from mbcomp.spec.components import Component, Joint
from mbcomp.spec.components.frame import Frame
from mbcomp.spec.components.values import name_of
from mbcomp.spec.compose import copy_component


def reversed_joint(joint: Joint) -> Joint | None:
    """The same joint with parent and child swapped (same name, coordinate and its sign),
    or ``None`` when the joint type has no such form (``Joint.reversed``)."""
    parent = Frame(joint.child, joint.child_point, joint.child_rotation)
    child = Frame(joint.parent, joint.parent_point, joint.parent_rotation)
    return joint.reversed(parent, child)


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


# -- sub-model instances --------------------------------------------------------------------------
def _walk(instance) -> list:
    """``(full name, component, scope path)`` of an instance's components, in build order."""
    from mbcomp.spec.compose import Submodel
    out = []
    for item in instance.members().values():
        if isinstance(item, Submodel):
            out += _walk(item)
        else:
            out.append((f"{instance.path}.{item.name}", item, instance.path))
    return out


def flatten_instances(model) -> tuple[dict, "Derivation"]:
    """Components of ``model`` with every sub-model instance expanded: copies named by
    their paths, references resolved (objects by identity, names within the instance's
    scope first), joint coordinates prefixed with the instance path."""
    from mbcomp.spec.compose import Submodel
    entries = [("ground", model.ground, "")]
    for item in model.entries:
        entries += _walk(item) if isinstance(item, Submodel) else [(item.name, item, "")]
    full_of = {id(comp): full for full, comp, _ in entries}
    names = {full for full, _, _ in entries}

    def resolve(ref: Any, scope: str) -> Any:
        if isinstance(ref, str):
            if scope and f"{scope}.{ref}" in names:
                return f"{scope}.{ref}"
            return ref
        return full_of.get(id(ref), ref)

    components: dict = {}
    expressions = []
    for full, comp, scope in entries:
        if full == "ground":
            components[full] = comp
            continue
        refs = {role: resolve(ref, scope) for role, ref in comp.references().items()}
        if scope or any(not isinstance(ref, str) and new != ref.name for ref, new in
                        zip(comp.references().values(), refs.values()) if isinstance(new, str)):
            new = copy_component(comp, full, refs)
            if scope and isinstance(comp, Joint):
                object.__setattr__(new, "coords", tuple(f"{scope}.{c}" for c in comp.coords))
        else:
            new = comp
        components[full] = new
        if comp.expression_args is not None:
            expressions.append((full, comp))
    registry = model.registry
    return components, Derivation(dict(registry.parameters), expressions, getattr(model, "gravity_binding", None),
                                  getattr(model, "frozen_parameters", None))


class Derivation:
    """How component values follow sub-model parameters: the parameters (in instantiation
    order, each a number or an expression of outer ones) and the components built from
    parameter expressions, rebuilt with new numbers on a run-time change (their
    constructors validate the values, and their structure must not change)."""

    def __init__(self, parameters: dict, components: list, gravity: tuple | None = None,
                 frozen: dict | None = None):
        self.parameters = parameters
        self.components = [(full, comp, _dependencies(comp)) for full, comp in components]
        #: per component, the parameters its frames' rotations were built from (held as numbers)
        self.rotations = {full: _rotation_parameters(comp.expression_args) for full, comp in components}
        #: gravity's components as expressions of parameters (``Model.set_gravity``), or None
        self.gravity = gravity
        #: parameters whose numbers are compiled into code (``{name: where}``): not changeable
        self.frozen = dict(frozen or {})

    def values(self) -> dict[str, float]:
        """``{parameter path: value}`` as instantiated."""
        return {path: entry.value for path, entry in self.parameters.items()}

    def apply(self, current: dict, changes: dict) -> dict:
        """New values of the sub-model parameters and of every component value derived
        from them, for ``changes`` (``{parameter path: value}``) applied to ``current``.

        A parameter bound to an expression of outer ones follows them, unless it was set
        on its own before (its current value is not its binding's): then it keeps it, as
        a modifier in a fresh build would."""
        from mbcomp.spec.components.expr import Expr, substitute
        from mbcomp.core.errors import ModelError
        env: dict[str, float] = {}
        for path, entry in self.parameters.items():
            if path in changes:
                env[path] = entry.spec.check(changes[path], f"parameter {path!r}")
            elif isinstance(entry.binding, Expr) and current[path] == entry.binding.evaluate(current):
                env[path] = entry.spec.check(entry.binding.evaluate(env), f"parameter {path!r} "
                                             f"(= {entry.binding!r})")
            else:
                env[path] = float(current[path])
        touched = {p for p, v in env.items() if v != current.get(p)}
        stuck = sorted(touched & set(self.frozen))
        if stuck:
            raise ModelError(f"parameter {stuck[0]!r}", f"is compiled with its value into {self.frozen[stuck[0]]}: "
                             "change it in the model and compile again")
        updates: dict[str, Any] = dict(env)
        for full, comp, deps in self.components:
            if not deps & touched:
                continue
            turned = sorted(self.rotations.get(full, set()) & touched)
            if turned:
                raise ModelError(full, f"changing {turned} turns a frame's rotation, which the generated code holds "
                                 "as a constant (not a run-time parameter); build and compile the model again")
            args, kwargs = comp.expression_args
            try:
                new = type(comp)(*substitute(args, env), **substitute(kwargs, env))
            except ModelError as exc:
                raise ModelError(full, f"with {sorted(touched)} = {[env[p] for p in sorted(touched)]}: {exc}") from None
            if new.structure() != comp.structure():
                raise ModelError(full, f"changing {sorted(deps & touched)} changes the structure "
                                 f"({comp.structure()} -> {new.structure()}); build and compile the model again")
            frozen = _moved_constants(comp, new)
            if frozen:
                raise ModelError(full, f"changing {sorted(deps & touched)} changes {', '.join(frozen)}, which the "
                                 "generated code holds as a constant (not a run-time parameter); build and compile "
                                 "the model again")
            for attr, value in new.parameter_values().items():
                updates[f"{full}.{attr}"] = value if np.ndim(value) == 0 else tuple(value)
        if self.gravity is not None:
            updates["gravity"] = tuple(substitute(self.gravity, env))
        return updates


def _rotation_parameters(value: Any) -> set:
    """Parameters read by the rotations of the ``Frame``s in ``value`` (component arguments)."""
    if isinstance(value, Frame):
        return set(value.rotation_parameters)
    if isinstance(value, (tuple, list)):
        return set().union(*(_rotation_parameters(v) for v in value)) if value else set()
    if isinstance(value, dict):
        return set().union(*(_rotation_parameters(v) for v in value.values())) if value else set()
    return set()


def _moved_constants(old: Any, new: Any) -> list[str]:
    """Attributes of plain numbers (a joint frame's rotation, an axis) that differ between a
    component and its rebuild but are not among its run-time parameters: the code holds
    them, so a run-time change cannot reach them."""
    params = set(old.parameter_values())
    moved = []
    for attr, value in vars(old).items():
        if attr in params or attr.startswith("_") or attr == "expression_args":
            continue
        before, after = _plain_numbers(value), _plain_numbers(getattr(new, attr, None))
        if before is not None and (after is None or before.shape != after.shape or not np.array_equal(before, after)):
            moved.append(attr)
    return moved


def _plain_numbers(value: Any) -> np.ndarray | None:
    """``value`` as a float array when it is a number or a nested sequence of numbers, else None."""
    if isinstance(value, bool) or value is None or isinstance(value, str):
        return None
    if isinstance(value, (int, float, np.ndarray, tuple, list)):
        try:
            array = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            return None
        return array
    return None


def _dependencies(comp) -> set:
    from mbcomp.spec.components.expr import Expr
    found: set = set()

    def visit(value):
        if isinstance(value, Expr):
            found.update(value.parameters())
        elif isinstance(value, (tuple, list)):
            for v in value:
                visit(v)
        elif isinstance(value, dict):
            for v in value.values():
                visit(v)
        elif isinstance(value, Frame):
            visit(value.point)
            found.update(value.rotation_parameters)
        elif getattr(value, "signal_args", None) is not None:   # a signal source (components/signals.py)
            visit(value.signal_args)
    visit(comp.expression_args)
    return found
