"""Which stepping a run takes: the loop compiled with the model, or scipy's stepping of the
compiled right-hand side, and why.

The compiled loop is the product path: every model whose forces, drives and motors are
expressions runs there in either formulation, and so does a model with Python callables
(callable forces or torques, drive signals, a callable ``tau``, a motor's callable
position), which the loop calls back (``codegen/callbacks.py``).  A run leaves it only for a reason this module names
(``IntegrationPath.reason``): a scipy method asked for, a formulation option that steps in
Python (``Formulation.compiled_loop``), a model compiled without a C compiler.  ``System.integration_path`` reports the choice.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from mbcomp.core.run_options import COMPILED_METHODS, RunOptions


@dataclass(frozen=True)
class IntegrationPath:
    """``stepping``: ``"compiled"`` or ``"scipy"``; ``reason``: why not compiled (None when
    compiled).  ``str()`` gives ``"compiled"`` or ``"scipy: <reason>"``."""

    stepping: str
    reason: str | None = None

    @property
    def compiled(self) -> bool:
        return self.stepping == "compiled"

    def __str__(self) -> str:
        return self.stepping if self.reason is None else f"{self.stepping}: {self.reason}"


def why_not_compiled(kernel, formulation, method: Any, tau: Any) -> str | None:
    """Why the compiled loop cannot run ``method`` on this model with these inputs (None when
    it can).  The formulation answers for its constraints and contacts through its hooks
    (``compiled_loop()``, ``compiled_method_problem()``, ``compiled_contacts``)."""
    if method not in COMPILED_METHODS:
        return f"scipy method {method!r} requested (compiled loops: {', '.join(COMPILED_METHODS)})"
    if kernel.backend != "c":
        return "the model was compiled without a C compiler (backend 'python')"
    reason = formulation.compiled_loop()
    if reason is not None:
        return reason
    reason = formulation.compiled_method_problem(method)
    if reason is not None:
        return reason
    if kernel.topology.contacts and not formulation.compiled_contacts:
        return "the model has contacts"
    from mbcomp.formulations.friction_c import compiled_friction_problem
    friction = compiled_friction_problem(kernel, formulation)
    if friction is not None:
        return friction
    return None  # (Python callables in the model or in tau are called back from the loop: codegen/callbacks.py)


def choose_path(kernel, formulation, options: RunOptions, tau: Any = None) -> IntegrationPath:
    """The stepping ``simulate`` takes with ``options`` (``integrator="scipy"`` asks for scipy's)."""
    if options.integrator == "scipy":
        return IntegrationPath("scipy", "integrator='scipy' requested")
    reason = why_not_compiled(kernel, formulation, options.method, tau)
    return IntegrationPath("compiled" if reason is None else "scipy", reason)
