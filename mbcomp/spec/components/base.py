"""The component contracts: what a body, joint, force element, constraint and contact provide."""
from __future__ import annotations

from typing import Any, ClassVar

from mbcomp.core.errors import ModelError, describe
from mbcomp.core.params import ParameterSpec, validate

KINDS: dict[str, type] = {}
"""The component kind registry: ``kind`` (the file's ``type``, e.g. ``"revolute"``) -> class.
A class that sets ``kind`` registers itself; io, cli and plotting look kinds up here."""


def component_class(kind: str) -> type | None:
    """The component class registered under ``kind`` (None when unknown)."""
    return KINDS.get(kind) if isinstance(kind, str) else None


def kinds_in(section: str) -> dict[str, type]:
    """``{kind: class}`` of the classes with a file form (``file_keys``) in model file
    section ``section`` ("joints", ...), in registration order."""
    return {k: c for k, c in KINDS.items() if c.section == section and c.file_keys}


def one_dof_joint_problems(component: Any, joint: Any) -> list[str]:
    """Problems of an element that acts on one joint coordinate (torsion springs, drives,
    friction): ``joint`` must have exactly one."""
    if joint.n_coords != 1:
        return [f"{describe(component)}: needs a 1-DOF joint, {type(joint).__name__} {joint.name!r} "
                f"has {joint.n_coords}"]
    return []


class FrozenComponentError(ModelError, AttributeError):
    """An attempt to change a component that belongs to a compiled ``System``."""


class Component:
    """Base of everything a user adds to a ``Model``.

    A component is a pure description: its constructor stores and validates its
    arguments and touches nothing else.  ``params`` declares its numeric attributes as
    ``ParameterSpec``s; every assignment to one of them, in the constructor or later
    (``body.mass = 2.0``), goes through the one validator ``mbcomp.core.params.validate``,
    so a value that a constructor rejects is rejected everywhere.  ``parameters`` names
    the attributes that bind at run time (``"component.attribute"`` in
    ``System.parameters``); the others (``structural=True``: axes, normals) decide the
    generated code.  Compiling copies the components, so changing one after
    ``compile()`` changes later compilations, never a compiled ``System``.

    Class attributes: ``kind`` (registry key, the file's ``type``), ``section`` (the
    model file table holding this kind: ``"bodies"``, ``"joints"``, ``"forces"``,
    ``"constraints"``, ``"contacts"``), ``params``, and the file form that the generic
    reader and writer (``mbcomp.files.component_tables``) follow:

    - ``file_keys``: the keys of the component's file table (besides ``type``), in the
      order they are written; each is a reference role (``refs``), a declared parameter
      (read as the spec says: number, 3-vector, axis, inertia, time input) or an option
      (``file_options``);
    - ``file_required``: the keys a file must give;
    - ``refs``: ``{role: "body" | "joint" | "attachment"}``; an attachment is a body
      name or ``{body = "...", point = [...]}`` and its point is the parameter
      ``point_<role>``;
    - ``file_options``: ``{key: "names" | "string" | "time" | "rotation"}`` for values
      that are not parameters (coordinate names, an Euler sequence, an expression of t,
      a frame rotation);
    - ``from_file(name, values)``: builds the component from the values read (by
      default ``cls(name, **values)``).
    """

    kind: ClassVar[str] = ""
    section: ClassVar[str] = ""
    params: ClassVar[tuple[ParameterSpec, ...]] = ()
    refs: ClassVar[dict[str, str]] = {}
    file_keys: ClassVar[tuple[str, ...]] = ()
    file_required: ClassVar[tuple[str, ...]] = ()
    file_options: ClassVar[dict[str, str]] = {}
    parameters: ClassVar[tuple[str, ...]] = ()
    _specs: ClassVar[dict[str, ParameterSpec]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls._specs = {spec.name: spec for spec in cls.params}
        if "params" in cls.__dict__ and "parameters" not in cls.__dict__:
            cls.parameters = tuple(spec.name for spec in cls.params if not spec.structural)
        if cls.__dict__.get("kind"):
            KINDS[cls.kind] = cls

    def __new__(cls, *args: Any, **kwargs: Any):
        # Arguments holding sub-model parameter expressions are kept, so that a run-time
        # parameter change can rebuild this component's values (mbcomp.spec.compose).
        obj = super().__new__(cls)
        if args or kwargs:
            from mbcomp.spec.components.expr import contains_expr
            if contains_expr(args) or contains_expr(kwargs):
                object.__setattr__(obj, "expression_args", (args, kwargs))
        return obj

    #: ``(args, kwargs)`` of the constructor call when they hold sub-model parameter
    #: expressions (``None`` otherwise).
    expression_args: Any = None

    def __init__(self, name: str):
        if not isinstance(name, str) or not name.strip():
            raise ModelError(type(self).__name__, f"name must be a non-empty string, got {name!r}")
        if any(ch in name for ch in ".[]") or name != name.strip():
            raise ModelError(type(self).__name__, f"name {name!r} may not contain '.', '[', ']' or edge spaces")
        self.name = name

    def __setattr__(self, attr: str, value: Any) -> None:
        """Declared parameters are validated on every assignment; the name is set once."""
        if self.__dict__.get("_frozen"):
            raise FrozenComponentError(self, f"is a compiled copy and cannot change ({attr}); change the "
                                       "model's component and compile again, or use System.with_parameters")
        spec = self._specs.get(attr)
        if spec is not None:
            value = validate(spec, value, self)
        elif attr == "name" and "name" in self.__dict__ and value != self.__dict__["name"]:
            raise ModelError(self, "the name of a component cannot change (models find components by name); "
                             "make a new component instead")
        object.__setattr__(self, attr, value)

    @classmethod
    def from_file(cls, name: str, values: dict[str, Any]) -> "Component":
        """The component a model file describes (``values``: file key -> value read)."""
        return cls(name, **values)

    def file_value(self, key: str) -> Any:
        """The value the writer stores under file key ``key`` (an attachment: ``(body, point)``)."""
        if self.refs.get(key) == "attachment":
            return getattr(self, f"body_{key}"), getattr(self, f"point_{key}")
        return getattr(self, key, None)

    def freeze(self) -> None:
        """Make this component read-only (the compiler's copies; see ``mbcomp.build.flatten``)."""
        object.__setattr__(self, "_frozen", True)

    @classmethod
    def spec(cls, attr: str) -> ParameterSpec | None:
        """The ``ParameterSpec`` of attribute ``attr`` (None when it is not a declared value)."""
        return cls._specs.get(attr)

    def references(self) -> dict[str, Any]:
        """The other components this one refers to, by role (``{"parent": ..., "child": ...}``)."""
        return {}

    def parameter_values(self) -> dict[str, Any]:
        """Current numeric values of ``parameters`` (floats or tuples), by attribute; a value
        that is ``None`` or a callable (a run-time input) is not a parameter."""
        values = {}
        for attr in self.parameters:
            value = getattr(self, attr, None)
            if value is not None and not callable(value):
                values[attr] = value
        return values

    def structure(self) -> tuple:
        """What, besides names and references, decides the generated code (axes, shapes)."""
        return ()

    def is_conservative(self) -> bool:
        """False when the component adds or removes energy (dampers, driven inputs, motors,
        impacts): the energy of a model made only of conservative components is constant."""
        return True

    def summary(self) -> str:
        """A short description for listings (``"revolute about x"``): the kind and what
        distinguishes it."""
        return self.kind or type(self).__name__.lower()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


class ForceElement(Component):
    """A force element contributes loads (world-frame point forces, body torques or
    generalised forces) and, if conservative, a potential energy.

    Hooks (``kin`` is the symbolic kinematics accessor the compiler hands over):
    - ``_loads(kin) -> list`` of ``("point", body, point_world_expr, force_world_expr)``,
      ``("torque", body, torque_world_expr)`` or ``("generalized", joint, values)``;
    - ``_potential(kin) -> expr`` (0 when not conservative).
    """

    def _loads(self, kin) -> list:
        raise NotImplementedError

    def is_conservative(self) -> bool:
        return False

    def _potential(self, kin):
        return 0


class Constraint(Component):
    """A bilateral constraint ``C(q, t) = 0`` with ``n_equations`` equations.

    Its reaction (``System.reactions``) is reported under the component's name.
    """

    n_equations: ClassVar[int] = 0

    def reaction_unit(self, resolve) -> str:
        """Unit of this constraint's reaction (``resolve(ref)`` gives referenced components)."""
        return "N, N m"
