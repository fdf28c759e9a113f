"""The component contracts: what a body, joint, force element, constraint and contact provide."""
from __future__ import annotations

from typing import Any, ClassVar

from ..errors import ModelError


class Component:
    """Base of everything a user adds to a ``Model``.

    A component is a pure description: its constructor stores and validates its
    arguments and touches nothing else.  ``parameters`` names the numeric
    attributes that bind at run time (``"component.attribute"`` in
    ``System.parameters``); everything else is structure.
    """

    parameters: ClassVar[tuple[str, ...]] = ()

    def __new__(cls, *args: Any, **kwargs: Any):
        # Arguments holding sub-model parameter expressions are kept, so that a run-time
        # parameter change can rebuild this component's values (mbcomp.compose).
        obj = super().__new__(cls)
        if args or kwargs:
            from .expr import contains_expr
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

    def references(self) -> dict[str, Any]:
        """The other components this one refers to, by role (``{"parent": ..., "child": ...}``)."""
        return {}

    def parameter_values(self) -> dict[str, Any]:
        """Current numeric values of ``parameters`` (floats or tuples), by attribute."""
        return {attr: getattr(self, attr) for attr in self.parameters}

    def structure(self) -> tuple:
        """What, besides names and references, decides the generated code (axes, shapes)."""
        return ()

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

    def _potential(self, kin):
        return 0


class Constraint(Component):
    """A bilateral constraint ``C(q, t) = 0`` with ``n_equations`` equations.

    Its reaction (``System.reactions``) is reported under the component's name.
    """

    n_equations: ClassVar[int] = 0
