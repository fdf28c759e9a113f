"""Sub-models: reusable parts with declared parameters, options and ports (Modelica-style).

A ``Submodel`` subclass declares ``Parameter``s (numeric: changeable at run time without
compiling again) and ``Option``s (structural), and a ``build(self, <ports>)`` method that
adds components and other sub-models.  Instances nest: every name inside one is
prefixed with the instance's path (``"left_leg.thigh.rod"``).  Keyword arguments at
instantiation are modifiers (parameters, options, ports, or a dict of modifiers for an
inner instance, where the outer value wins over the one ``build`` passes).

Inside ``build``, ``self.<parameter>`` is an ``Expr`` (its value plus the link to the
parameter), so every value derived from it follows a run-time change.
"""
from __future__ import annotations

import copy
import inspect
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mbcomp.spec.components import Component
from mbcomp.spec.components.expr import Expr
from mbcomp.spec.components.frame import Frame
from mbcomp.core.errors import ModelError

_MISSING = object()
#: The default of a port that must be bound (``Submodel.port_names``).
PORT_REQUIRED = _MISSING


class Parameter:
    """A numeric sub-model parameter: ``Parameter(default, unit=None, min=None, max=None, doc="")``.

    Its value appears in ``System.parameters`` under the instance path and may be changed
    at run time; a value outside ``[min, max]`` is a ``ModelError`` naming the full path.
    """

    def __init__(self, default: float, unit: str | None = None, min: float | None = None,
                 max: float | None = None, doc: str = ""):
        self.name = "?"
        self.unit, self.min, self.max, self.doc = unit, min, max, doc
        for what, v in (("min", min), ("max", max)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v)):
                raise ModelError("Parameter", f"{what} must be a finite number, got {v!r}")
        self.default = self.check(default, "Parameter default")

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def check(self, value: Any, where: str) -> float:
        """``value`` as a finite float within the bounds, else a ``ModelError`` naming ``where``."""
        if isinstance(value, bool):
            raise ModelError(where, f"must be a number, got {value!r}")
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ModelError(where, f"must be a number, got {value!r}") from None
        if not np.isfinite(x):
            raise ModelError(where, f"must be finite, got {x}")
        if self.min is not None and x < self.min or self.max is not None and x > self.max:
            raise ModelError(where, f"must lie in [{self.min}, {self.max}], got {x}")
        return x

    def __get__(self, instance, owner):
        if instance is None:
            return self
        return instance._values[self.name]

    def __set__(self, instance, value):
        raise AttributeError(f"parameter {self.name!r} is set by keyword at instantiation")

    def __repr__(self) -> str:
        unit = f", unit={self.unit!r}" if self.unit else ""
        return f"Parameter({self.default!r}{unit})"


class Option:
    """A structural sub-model option: ``Option(default, choices=None, doc="")``.

    It may hold any value, including a component or ``Submodel`` class (Modelica's
    "replaceable"); changing it builds a different structure (a new compile).
    """

    def __init__(self, default: Any, choices: Any = None, doc: str = ""):
        self.name = "?"
        self.choices = None if choices is None else tuple(choices)
        self.doc = doc
        self.default = self.check(default, "Option default")

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def check(self, value: Any, where: str) -> Any:
        if self.choices is not None and value not in self.choices:
            raise ModelError(where, f"must be one of {list(self.choices)}, got {value!r}")
        return value

    def __get__(self, instance, owner):
        if instance is None:
            return self
        return instance._values[self.name]

    def __set__(self, instance, value):
        raise AttributeError(f"option {self.name!r} is set by keyword at instantiation")


@dataclass
class ParameterEntry:
    """A sub-model parameter after instantiation: its path, declaration and binding
    (a number, or an ``Expr`` of outer parameters when ``build`` passed one)."""

    path: str
    spec: Parameter
    binding: Any
    value: float


@dataclass
class Registry:
    """What instantiating sub-models into one model produced, in order."""

    components: list = field(default_factory=list)        # (full name, component, scope path)
    parameters: dict = field(default_factory=dict)        # path -> ParameterEntry
    names: dict = field(default_factory=dict)             # id(component) -> full name
    instances: int = 0                                    # sub-model instances so far (limits.max_instances)


class Submodel:
    """Base of reusable parts.  Subclasses declare ``Parameter``s and ``Option``s as class
    attributes and implement ``build(self, <ports>)``; ``Submodel(name, **modifiers)``.
    """

    def __init__(self, name: str, **modifiers: Any):
        if not isinstance(name, str) or not name.strip() or any(ch in name for ch in ".[]") or name != name.strip():
            raise ModelError(type(self).__name__, f"name must be a non-empty string without '.', '[', ']', got {name!r}")
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "_modifiers", dict(modifiers))
        object.__setattr__(self, "_path", None)
        object.__setattr__(self, "_values", {})
        object.__setattr__(self, "_scope", {})
        object.__setattr__(self, "_ports", {})
        self._classify(self._modifiers, f"{type(self).__name__} {name!r}", final=False)

    # -- declarations ---------------------------------------------------------------------------
    @classmethod
    def _declared(cls, kind: type) -> dict:
        key = ("declared", kind)
        cache = cls.__dict__.get("_declaration_cache")
        if cache is None:
            cache = {}
            type.__setattr__(cls, "_declaration_cache", cache)
        if key not in cache:
            found: dict = {}
            for klass in reversed(cls.__mro__):
                for name, value in vars(klass).items():
                    if isinstance(value, (Parameter, Option)):
                        found.pop(name, None)
                        if isinstance(value, kind):
                            found[name] = value
                    elif name in found:
                        found.pop(name)
            cache[key] = dict(sorted(found.items()))
        return cache[key]

    @classmethod
    def declared_parameters(cls) -> dict[str, Parameter]:
        """The class's ``Parameter`` declarations by name (inherited ones included)."""
        return cls._declared(Parameter)

    @classmethod
    def declared_options(cls) -> dict[str, Option]:
        """The class's ``Option`` declarations by name (inherited ones included)."""
        return cls._declared(Option)

    @classmethod
    def port_names(cls) -> dict[str, Any]:
        """``build``'s arguments (the ports bound by whoever uses the part) and their defaults."""
        sig = inspect.signature(cls.build)
        return {n: (p.default if p.default is not inspect.Parameter.empty else _MISSING)
                for n, p in list(sig.parameters.items())[1:]
                if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)}

    def build(self, **ports: Any) -> None:
        """Add this part's components and sub-models (override)."""
        raise NotImplementedError(f"{type(self).__name__} must define build()")

    def _classify(self, modifiers: dict, where: str, final: bool) -> None:
        params, options, ports = self.declared_parameters(), self.declared_options(), self.port_names()
        for key, value in modifiers.items():
            if key in params:
                if final is None and not isinstance(value, Expr):
                    params[key].check(value, f"parameter {self.path + '.' + key!r}")
            elif key in options:
                options[key].check(value, f"{where}: option {key}")
            elif key in ports:
                continue
            elif isinstance(value, dict):
                if final and key not in self._scope:
                    raise ModelError(where, f"{key!r} is not a parameter, option, port or inner instance; valid: "
                                     f"{sorted(set(params) | set(options) | set(ports) | set(self._scope))}")
            else:
                raise ModelError(where, f"unknown keyword {key!r}; valid: parameters {sorted(params)}, "
                                 f"options {sorted(options)}, ports {sorted(ports)} (or a dict of modifiers "
                                 f"for an inner instance)")

    # -- instantiation (done by Model.add or the enclosing Submodel.add) ----------------------------
    @property
    def path(self) -> str:
        """The full instance path (``"left_leg.thigh"``); set once the instance is added."""
        return self._path if self._path is not None else self.name

    def instantiate(self, prefix: str, registry: Registry, outer: dict | None = None) -> None:
        """Fix the path (``prefix + name``), apply the ``outer`` modifiers (they win), resolve
        parameters and options, and run ``build`` (called by ``Model.add``/``Submodel.add``)."""
        if self._path is not None:
            raise ModelError(f"{type(self).__name__} {self.name!r}", "was already added to a model")
        if outer:
            self._modifiers.update(outer)   # outer modifiers win
        path = f"{prefix}{self.name}"
        where = f"{type(self).__name__} {path!r}"
        _check_limits(registry, path, where)
        object.__setattr__(self, "_path", path)
        object.__setattr__(self, "_registry", registry)
        self._classify(self._modifiers, where, final=False)
        for key, spec in self.declared_parameters().items():
            given = self._modifiers.get(key, spec.default)
            full = f"{path}.{key}"
            value = spec.check(given, f"parameter {full!r}")
            registry.parameters[full] = ParameterEntry(full, spec, given if isinstance(given, Expr) else value, value)
            self._values[key] = Expr.parameter(full, value)
        for key, spec in self.declared_options().items():
            self._values[key] = self._modifiers.get(key, spec.default)
        ports = {}
        for key, default in self.port_names().items():
            value = self._modifiers.get(key, default)
            if value is _MISSING:
                raise ModelError(where, f"port {key!r} is not bound: give {key}=<a Frame> when instantiating")
            ports[key] = value
            self._ports[key] = value
        self.build(**ports)
        self._classify(self._modifiers, where, final=True)

    def add(self, *items: Any) -> Any:
        """Add components or sub-model instances to this part (inside ``build``); returns the first."""
        if self._path is None:
            raise ModelError(f"{type(self).__name__} {self.name!r}", "add() works inside build() only")
        if not items:
            raise ModelError(f"{type(self).__name__} {self.path!r}", "add() needs at least one component")
        for item in items:
            where = f"{type(self).__name__} {self.path!r}"
            if not isinstance(item, (Component, Submodel)):
                raise ModelError(where, f"cannot add {item!r}: not a component or Submodel")
            if item.name in self._scope:
                raise ModelError(where, f"name {item.name!r} is already used in this part")
            self._scope[item.name] = item
            if isinstance(item, Submodel):
                inner = self._modifiers.get(item.name)
                item.instantiate(f"{self.path}.", self._registry, inner if isinstance(inner, dict) else None)
            else:
                full = f"{self.path}.{item.name}"
                self._registry.components.append((full, item, self.path))
                self._registry.names[id(item)] = full
        return items[0]

    def connect(self, a: Frame, b: Frame, name: str | None = None):
        """Weld two frames with a ``Fixed`` joint inside this part (see ``Model.connect``)."""
        from mbcomp.spec.components import Fixed
        for role, frame in (("a", a), ("b", b)):
            if not isinstance(frame, Frame):
                raise ModelError(f"{type(self).__name__} {self.path!r}", f"connect() takes two Frames; {role} is {frame!r}")
        names = [getattr(f.body, "name", f.body) for f in (a, b)]
        return self.add(Fixed(name or f"weld_{names[0]}_{names[1]}", a, b))

    # -- access -----------------------------------------------------------------------------------
    def __getitem__(self, name: str):
        head, _, rest = name.partition(".")
        try:
            item = self._scope[head]
        except KeyError:
            raise KeyError(f"{type(self).__name__} {self.path!r} has no component or instance {head!r}") from None
        if rest:
            if not isinstance(item, Submodel):
                raise KeyError(f"{item!r} in {self.path!r} is a component, it has no {rest!r}")
            return item[rest]
        return item

    def __contains__(self, name: str) -> bool:
        try:
            self[name]
            return True
        except KeyError:
            return False

    def __setattr__(self, name: str, value: Any) -> None:
        if name in self.declared_parameters() or name in self.declared_options():
            raise AttributeError(f"{name!r} is declared by {type(self).__name__}; set it by keyword at instantiation")
        object.__setattr__(self, name, value)

    def parameter_values(self) -> dict[str, float]:
        """This instance's parameter values by name (after instantiation)."""
        return {k: float(v) for k, v in self._values.items() if isinstance(v, Expr)}

    def option_values(self) -> dict[str, Any]:
        return {k: v for k, v in self._values.items() if not isinstance(v, Expr)}

    def members(self) -> dict[str, Any]:
        """Components and inner instances added by ``build``, by local name, in order."""
        return dict(self._scope)

    def instances(self) -> list["Submodel"]:
        return [v for v in self._scope.values() if isinstance(v, Submodel)]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.path!r})"


def _check_limits(registry: Registry, path: str, where: str) -> None:
    """``ModelError`` when one more instance at ``path`` would pass the limits on sub-model
    instances per model or on their nesting (``mbcomp.core.limits``; a recursive ``build`` ends here)."""
    from mbcomp.core.limits import INSTANCES, NESTING, max_instances, max_nesting
    depth, deepest = path.count(".") + 1, max_nesting()
    if depth > deepest:
        raise ModelError(where, f"sub-models nest more than {deepest} deep (set {NESTING[0]} to raise the limit)")
    registry.instances += 1
    limit = max_instances()
    if registry.instances > limit:
        raise ModelError(where, f"the model would hold more than {limit} sub-model instances (set {INSTANCES[0]} "
                                "to raise the limit)")


class FileSubmodel(Submodel):
    """Base of the sub-model classes made from part files (``[submodels.X] use = ...``)."""

    source = None   # the file the class was read from


def copy_component(comp: Any, name: str, references: dict) -> Any:
    """A shallow copy of ``comp`` named ``name`` whose reference attributes are replaced
    by ``references`` (role -> new reference)."""
    if hasattr(comp, "copy_with_references"):  # references inside signals (drivetrain, signals)
        return comp.copy_with_references(name, references)
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


# -- the instance tree ------------------------------------------------------------------------------
@dataclass
class TreeNode:
    """One instance of ``Model.tree()``: its name, kind, parameters, options and children."""

    name: str
    kind: str
    parameters: dict
    options: dict
    components: list
    children: list

    def lines(self, indent: str = "") -> list[str]:
        params = ", ".join(f"{k}={_short(v)}" for k, v in self.parameters.items())
        opts = ", ".join(f"{k}={_short(v)}" for k, v in self.options.items())
        text = f"{indent}{self.name} ({self.kind})"
        if params:
            text += f"  {params}"
        if opts:
            text += f"  [{opts}]"
        out = [text]
        if self.components:
            out.append(f"{indent}    components: {', '.join(self.components)}")
        for child in self.children:
            out += child.lines(indent + "    ")
        return out

    def __str__(self) -> str:
        return "\n".join(self.lines())


def _short(value: Any) -> str:
    if isinstance(value, type):
        return value.__name__
    if isinstance(value, float):
        return f"{value:g}"
    return repr(value)


def tree_of(instance: Submodel) -> TreeNode:
    return TreeNode(instance.name, type(instance).__name__, instance.parameter_values(), instance.option_values(),
                    [k for k, v in instance._scope.items() if not isinstance(v, Submodel)],
                    [tree_of(child) for child in instance.instances()])
