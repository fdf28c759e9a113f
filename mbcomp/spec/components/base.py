"""The component contracts: what a body, joint, force element, constraint and contact provide."""
from __future__ import annotations

import inspect
import warnings
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


#: Extension points that had private names until version 0.1: ``{old: new}``.  A subclass
#: that still defines the old name gets it as the new one, with a ``DeprecationWarning``
#: (the old names stop working in the next release).
RENAMED_HOOKS = {"_loads": "loads", "_potential": "potential", "_equations": "equations",
                 "_gap_equation": "gap_equation", "_screws": "screws", "_segments": "segments"}


def reference_role(argument: str) -> str:
    """The role a derived file form gives a constructor argument that is a reference:
    ``"body"`` for ``body``, ``parent``, ``child`` and ``body_*``, ``"joint"`` for ``joint``
    and ``joint_*``, else ``"component"`` (a body or a joint, by name)."""
    if argument in ("body", "parent", "child") or argument.startswith("body_"):
        return "body"
    if argument == "joint" or argument.startswith("joint_"):
        return "joint"
    return "component"


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
    - ``refs``: ``{role: "body" | "joint" | "attachment" | "component"}``; an attachment
      is a body name or ``{body = "...", point = [...]}`` and its point is the parameter
      ``point_<role>``; a component is the name of a body or a joint;
    - ``file_options``: ``{key: "names" | "string" | "time" | "rotation"}`` for values
      that are not parameters (coordinate names, an Euler sequence, an expression of t,
      a frame rotation);
    - ``from_file(name, values)``: builds the component from the values read (by
      default ``cls(name, **values)``).

    A class that sets ``kind`` and ``section`` but no ``file_keys`` gets its file form
    from its constructor: each argument after ``name`` is a file key, a declared
    parameter when a ``ParameterSpec`` has its name and a reference otherwise (role from
    ``refs``, else ``reference_role``); the arguments without a default are required.  So a
    user's force element is saved and loaded with no file code (docs/architecture.md).
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
        for old, new in RENAMED_HOOKS.items():
            if old in cls.__dict__ and new not in cls.__dict__:
                warnings.warn(f"{cls.__qualname__}.{old} is deprecated: name the method {new} (the public "
                              "extension point); the old name stops working in the next release",
                              DeprecationWarning, stacklevel=2)
                setattr(cls, new, cls.__dict__[old])
        if cls.__dict__.get("kind"):
            if cls.section and not cls.file_keys:
                cls._derive_file_form()
            KINDS[cls.kind] = cls

    @classmethod
    def _derive_file_form(cls) -> None:
        """``file_keys``, ``file_required`` and ``refs`` from the constructor's arguments
        (see the class docstring); nothing when it takes ``*args``."""
        try:
            arguments = list(inspect.signature(cls.__init__).parameters.values())[2:]  # self, name
        except (TypeError, ValueError):
            return
        if any(a.kind is inspect.Parameter.VAR_POSITIONAL for a in arguments):
            return
        named = [a for a in arguments if a.kind is not inspect.Parameter.VAR_KEYWORD]
        refs = dict(cls.refs)
        for a in named:
            if a.name not in cls._specs and a.name not in refs:
                refs[a.name] = reference_role(a.name)
        cls.refs = refs
        cls.file_keys = tuple(a.name for a in named)
        cls.file_required = tuple(a.name for a in named if a.default is inspect.Parameter.empty)

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
        if key in self.refs and key not in self.__dict__:
            return self.references().get(key)
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

    def check(self, resolved: dict[str, Any]) -> list[str]:
        """Problems against the resolved references (``{role: component}``), e.g. a motor on a
        joint with more than one coordinate; sets nothing.  None by default."""
        return []

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

    Extension points (``kin`` is the symbolic kinematics accessor the compiler hands over,
    docs/architecture.md):
    - ``loads(kin) -> list`` of ``("point", body, point_world_expr, force_world_expr)``,
      ``("torque", body, torque_world_expr)`` or ``("generalized", joint, values)``;
    - ``potential(kin) -> expr`` (0 when not conservative).
    """

    section = "forces"

    def loads(self, kin) -> list:
        """The element's loads (N, N m; world frame) as symbolic expressions of ``kin``."""
        raise NotImplementedError(f"{type(self).__name__} defines no loads(kin)")

    def is_conservative(self) -> bool:
        return False

    def line_ends(self) -> tuple | None:
        """``((body_a, key_a), (body_b, key_b))`` (the parameter keys of two body points, m)
        when the element acts along the line between them, which is undefined where they
        meet (``Kernel.check_finite`` names the element then); None otherwise."""
        return None

    def input_size(self, joint: Any = None) -> int:
        """Number of run-time input values (a callable force or torque) this element reads; 0 by default."""
        return 0

    def potential(self, kin):
        """The element's potential energy (J) as an expression of ``kin``; 0 when not conservative."""
        return 0


class Constraint(Component):
    """A bilateral constraint ``C(q, t) = 0`` with ``n_equations`` equations.

    Its reaction (``System.reactions``) is reported under the component's name.
    """

    n_equations: ClassVar[int] = 0
    section = "constraints"
    #: How messages name this kind of constraint ("" : by its class name).
    noun: ClassVar[str] = ""

    def equations(self, ground) -> list:
        """The constraint's equations as primitives (``mbcomp.spec.components.primitives``:
        ``PointEquation``, ``DotEquation``, ``CoordinateEquation``); ``ground`` is the model's ground body."""
        raise NotImplementedError(f"{type(self).__name__} defines no equations(ground)")

    def reaction_unit(self, resolve) -> str:
        """Unit of this constraint's reaction (``resolve(ref)`` gives referenced components)."""
        return "N, N m"
