"""Model: the mutable description users assemble from components."""
from __future__ import annotations

from typing import Any

from mbcomp.spec.components import Body, Component, Ground
from mbcomp.spec.components.values import vector3
from mbcomp.core.errors import ModelError, describe
from mbcomp.core.services import service


def _plain(body: Any) -> str:
    """A body's name made fit for a component name."""
    from mbcomp.spec.components.values import name_of
    return name_of(body).replace(".", "_")


class Model:
    """A mechanism description: a ground body, components and a uniform gravity field.

    Parameters
    ----------
    name : str
    gravity : (3,) m/s^2, world frame (any direction; ``(0, 0, -9.81)`` by default)
    """

    def __init__(self, name: str = "model", gravity: Any = (0.0, 0.0, -9.81)):
        if not isinstance(name, str) or not name:
            raise ModelError("Model", f"name must be a non-empty string, got {name!r}")
        self.name = name
        self.gravity_binding = None               # gravity as expressions of model parameters
        self.set_gravity(gravity)
        self.ground = Ground("ground")
        self._components: dict[str, Component] = {"ground": self.ground}
        self._instances: dict[str, Any] = {}      # top-level sub-model instances by name
        self._entries: list = []                  # components and instances in the order added
        self._registry = None                     # what the instances produced (mbcomp.spec.compose)
        #: On a flattened model: how component values follow sub-model parameters.
        self.derivation = None

    # -- parameters -----------------------------------------------------------
    def parameter(self, name: str, value: Any, unit: str | None = None, min: float | None = None,
                  max: float | None = None, doc: str = "") -> Any:
        """Declare a model-level run-time parameter and return the expression standing for it.

        Components, sub-model modifiers, gravity and later parameters built from the returned
        value follow it: ``sys.parameters[name]`` is changeable at run time
        (``simulate(parameters=)``, ``with_parameters``, ``sweep``) with the numbers a fresh
        build gives, without compiling again.  ``value`` is a number or an expression of
        earlier parameters (a derived parameter: it follows them unless set on its own).
        The top-level ``[parameters]`` of a model file are declared this way.
        """
        from mbcomp.spec.compose import Parameter, ParameterEntry, Registry
        from mbcomp.spec.components.expr import Expr
        where = f"Model {self.name!r}"
        if not isinstance(name, str) or not name.isidentifier():
            raise ModelError(where, f"parameter name must be an identifier (letters, digits, _), got {name!r}")
        if self._registry is None:
            self._registry = Registry(names={id(self.ground): "ground"})
        if name in self._registry.parameters:
            raise ModelError(where, f"parameter {name!r} is declared twice")
        try:
            spec = Parameter(float(value) if isinstance(value, Expr) else value, unit=unit, min=min, max=max, doc=doc)
        except ModelError as exc:
            raise ModelError(where, f"parameter {name!r}: {getattr(exc, 'detail', exc)}") from None
        spec.__set_name__(Model, name)
        number = spec.check(value, f"parameter {name!r}")
        self._registry.parameters[name] = ParameterEntry(name, spec, value if isinstance(value, Expr) else number,
                                                         number)
        return Expr.parameter(name, number)

    def set_gravity(self, gravity: Any) -> None:
        """Set the uniform gravity field (m/s^2, world frame); its components may be
        expressions of model parameters (``(0, 0, -g)``), which it then follows."""
        from mbcomp.spec.components.expr import Expr
        items = tuple(gravity) if isinstance(gravity, (tuple, list)) else None
        linked = items is not None and any(isinstance(g, Expr) for g in items)
        self.gravity = vector3(tuple(float(g) if isinstance(g, Expr) else g for g in items) if linked else gravity,
                               f"Model {self.name!r}", "gravity")
        self.gravity_binding = items if linked else None

    # -- composition ----------------------------------------------------------
    def add(self, *components: Component) -> Component:
        """Add components (in order) and return the first one.

        Raises ``ModelError`` for a non-component, a duplicate name or a second ground.
        """
        if not components:
            raise ModelError(f"Model {self.name!r}", "add() needs at least one component")
        from mbcomp.spec.compose import Registry, Submodel
        for comp in components:
            if isinstance(comp, Submodel):
                if comp.name in self._components or comp.name in self._instances:
                    raise ModelError(f"{type(comp).__name__} {comp.name!r}", f"name {comp.name!r} is already used "
                                     f"in model {self.name!r}")
                if self._registry is None:
                    self._registry = Registry(names={id(self.ground): "ground"})
                comp.instantiate("", self._registry)
                self._instances[comp.name] = comp
                self._entries.append(comp)
                continue
            if not isinstance(comp, Component):
                raise ModelError(f"Model {self.name!r}", f"cannot add {comp!r}: not an mbcomp component "
                                 "or Submodel")
            if isinstance(comp, Ground):
                raise ModelError(comp, "a model has exactly one ground (model.ground)")
            existing = self._components.get(comp.name)
            if existing is comp:
                raise ModelError(comp, "was already added to this model")
            if existing is not None:
                raise ModelError(comp, f"name {comp.name!r} is already used by {describe(existing)}")
            if comp.name in self._instances:
                raise ModelError(comp, f"name {comp.name!r} is already used by a sub-model instance")
            self._components[comp.name] = comp
            self._entries.append(comp)
        return components[0]

    def connect(self, a: Any, b: Any, name: str | None = None) -> Component:
        """Weld two frames together: adds (and returns) a ``Fixed`` joint from ``a`` to ``b``,
        named ``"weld_<body a>_<body b>"`` unless ``name`` is given.  Either frame may be
        the one already connected to the ground: the compiler orients the joint."""
        from mbcomp.spec.components import Fixed
        from mbcomp.spec.components.frame import Frame
        for role, frame in (("a", a), ("b", b)):
            if not isinstance(frame, Frame):
                raise ModelError(f"Model {self.name!r}", f"connect() takes two Frames (body.frame(...)); {role} is {frame!r}")
        if name is None:
            name = f"weld_{_plain(a.body)}_{_plain(b.body)}"
        return self.add(Fixed(name, a, b))

    def flat(self) -> "Model":
        """The model the compiler reads: sub-model instances expanded into components with
        dotted names, joints oriented along the spanning tree (the model itself when
        nothing changes).  The user's components are never modified."""
        components, derivation = self._components, self.derivation
        if self._registry is not None:  # the build layer implements both steps (mbcomp.build.flatten)
            components, derivation = service("flatten_instances")(self)
        components = service("orient_joints")(components, self.ground.name)
        if components is self._components:
            return self
        flat = Model.__new__(Model)
        flat.name, flat.gravity, flat.ground = self.name, self.gravity, self.ground
        flat.gravity_binding = self.gravity_binding
        flat._components, flat._instances, flat._entries, flat._registry = components, {}, list(components.values())[1:], None
        flat.derivation = derivation
        return flat

    @property
    def entries(self) -> list:
        """Top-level components and sub-model instances in the order they were added."""
        return list(self._entries)

    @property
    def registry(self):
        """What the sub-model instances of this model produced (``None`` without any)."""
        return self._registry

    def tree(self):
        """The instance tree: every sub-model instance with its parameters and options, and
        the components of each level (``str()`` of it prints an indented outline)."""
        from mbcomp.spec.compose import TreeNode, tree_of
        return TreeNode(self.name, "Model", {}, {}, [n for n in self._components if n != "ground"],
                        [tree_of(inst) for inst in self._instances.values()])

    def __getitem__(self, name: str) -> Any:
        """A component by name, or inside sub-model instances by its dotted path
        (``m["lower.rod"]``); ``m["lower"]`` is the instance itself."""
        if name in self._components:
            return self._components[name]
        head, _, rest = name.partition(".")
        if head in self._instances:
            instance = self._instances[head]
            return instance[rest] if rest else instance
        raise KeyError(f"model {self.name!r} has no component {name!r}") from None

    def __contains__(self, name: str) -> bool:
        try:
            self[name]
            return True
        except KeyError:
            return False

    @property
    def components(self) -> dict[str, Component]:
        """All components by name, in the order they were added (ground first)."""
        if self._instances:
            return dict(self.flat()._components)  # sub-model components under their dotted names
        return dict(self._components)

    @property
    def bodies(self) -> list[Body]:
        """The moving bodies, in the order they were added."""
        return [c for c in self.components.values() if isinstance(c, Body) and c is not self.ground]

    # -- compilation ------------------------------------------------------------
    def compile(self, formulation: Any = "lagrange", *, cache: bool = True, backend: str = "auto",
                dynamics: str = "auto", **options: Any):
        """Compile to an immutable ``System``.

        Parameters
        ----------
        formulation : ``"lagrange"`` (minimal coordinates) or ``"dae"`` (multipliers), or a
            ``Formulation`` subclass.
        cache : reuse generated code stored on disk for the same model structure.
        backend : ``"auto"`` (compiled C when a C compiler works, else Python), ``"c"`` or
            ``"python"``.
        dynamics : how the compiled code computes the tree's accelerations: ``"dense"``
            (mass matrix and Cholesky factorisation, O(N^3)), ``"recursive"`` (the
            articulated-body algorithm, O(N)) or ``"auto"`` (recursive for trees without
            constraints from a measured size on, ``mbcomp.build.recursive.CROSSOVER_NV`` speeds, and
            for ``"dae"`` with constraints from ``DAE_CROSSOVER_NV``).
            Both give the same accelerations to rounding; part of the cache key.
        options : formulation options (``baumgarte=(alpha, beta)`` for ``"dae"``).
        """
        return service("compile")(self, formulation=formulation, cache=cache, backend=backend, dynamics=dynamics,
                                  **options)

    def save(self, path) -> None:
        """Write the model as a declarative TOML file that ``mb.load`` reads back."""
        service("save")(self, path)

    def __repr__(self) -> str:
        return f"Model({self.name!r}, {len(self._components) - 1} components)"
