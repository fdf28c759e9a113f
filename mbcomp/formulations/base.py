"""The Formulation interface shared by ``lagrange`` and ``dae``, and their registry."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ModelError


class Formulation:
    """How a compiled tree plus constraints becomes ODEs.

    The tree gives ``M(q) qdd = f(q, qd, t) + tau`` over all tree coordinates ``q``
    (``nq`` of them).  Constraints ``C(q, t) = 0`` (``nc`` equations, Jacobian
    ``C_q``) add reactions ``C_q^T lam``::

        [ M    C_q^T ] [ qdd ]   [ f + tau                  ]
        [ C_q  0     ] [ lam ] = [ -(dC_q/dt) qd - C_tt ... ]

    ``lagrange`` reduces this onto independent speeds; ``dae`` solves it as it
    stands with Baumgarte stabilisation.  Without constraints both are the tree ODE.
    Methods take the ``System`` whose parameters they evaluate with; a formulation
    holds no per-simulation state.
    """

    name = "base"

    def __init__(self, compiled, **options: Any):
        self.compiled = compiled
        self.options = options
        topology = compiled.topology
        if options:
            raise ModelError(f"formulation {self.name!r}", f"unknown option(s) {sorted(options)}")
        self.ndof = topology.nq

    def accelerations(self, system, t: float, q: np.ndarray, qd: np.ndarray, tau) -> np.ndarray:
        M, f = system._dynamics(t, q, qd, tau)
        system._check_finite(M, "mass matrix", q)
        system._check_finite(f, "generalised forces", q)
        return system._solve_tree(M, f, q)

    def reactions(self, system, t, q, qd, tau) -> dict[str, np.ndarray]:
        return {}

    def assemble(self, system, q: np.ndarray, qd: np.ndarray):
        return q.copy(), qd.copy()

    def constraint_violation(self, system, t: float, q: np.ndarray) -> float:
        return 0.0
