"""Constraints kept with Lagrange multipliers, Baumgarte stabilised (optionally projected)."""
from __future__ import annotations

import ctypes
from contextlib import contextmanager

import numpy as np

from mbcomp.core.errors import ModelError, SimulationError
from mbcomp.codegen.callbacks import raise_pending
from mbcomp.formulations.base import Formulation, Workspace
from mbcomp.formulations.dae_c import c_dae_accelerations
from mbcomp.formulations.dae_compiled import DaeRows, DaeRun, set_quaternion_projection
from mbcomp.formulations.friction import has_friction

#: Default Baumgarte gains (alpha, beta) in 1/s: critically damped constraint error with a
#: 0.2 s time constant (see bench/constraints_drift.py for the drift/cost study).
DEFAULT_BAUMGARTE = (5.0, 5.0)


class DaeWorkspace(Workspace):
    """State ``[q, qd]`` over all tree coordinates; optional projection after each step."""

    def after_step(self, t, y):
        if not self.formulation.projection:
            return None
        q, qd = y[: self.n], y[self.n:]
        drift = self.formulation.constraint_violation(self.kernel, t, q, self.offsets)
        if drift < 1e-10:
            return None
        q2, qd2 = self.formulation.assemble(self.kernel, q, qd, t, self.offsets)
        return np.concatenate((q2, qd2))


class DaeFormulation(Formulation):
    """Augmented system with multipliers::

        [ M   -J^T ] [ qdd ]   [ f + tau                                  ]
        [ J    0   ] [ lam ] = [ -bias - 2 alpha gdot - beta^2 g          ]

    Options: ``baumgarte=(alpha, beta)`` (1/s, default ``DEFAULT_BAUMGARTE``);
    ``projection=True`` moves the state back onto the constraints after every
    accepted step (positions by Newton, speeds by mass-orthogonal projection).
    """

    name = "dae"
    option_names = ("baumgarte", "projection")
    workspace_class = DaeWorkspace

    def __init__(self, compiled, **options):
        super().__init__(compiled, **options)
        gains = options.get("baumgarte", DEFAULT_BAUMGARTE)
        try:
            alpha, beta = (float(v) for v in gains)
        except (TypeError, ValueError):
            raise ModelError("formulation 'dae'", f"baumgarte must be (alpha, beta), got {gains!r}") from None
        if not (np.isfinite(alpha) and np.isfinite(beta) and alpha >= 0 and beta >= 0):
            raise ModelError("formulation 'dae'", f"baumgarte gains must be finite and >= 0, got {gains!r}")
        self.baumgarte = (alpha, beta)
        self.projection = bool(options.get("projection", False))

    @classmethod
    def c_source(cls, nv: int, ng: int) -> str:
        return c_dae_accelerations(nv, ng)

    def compiled_loop(self) -> str | None:
        if self.constraints is None and not self.compiled.contact_rows:
            return None
        if self.constraints is not None and self.nominal_rows is None:
            return "no consistent configuration was found at compile time"
        return None

    def scipy_stretch(self, kernel, lib, t0, q0, qd0, tau, contacts=(), offsets=None, method="", z0=None):
        """The compiled KKT solve on the tree state (``Formulation.scipy_stretch``): the rows of
        the constraints (``compiled_setup``) or, with contacts, of the stretch between events
        (``DaeRun``: the held contacts' rows too)."""
        if not self.compiled.contact_rows:   # (contacts or collision features)
            return super().scipy_stretch(kernel, lib, t0, q0, qd0, tau, contacts, offsets, method, z0)
        from mbcomp.codegen.integrators import compiled_jacobian
        from mbcomp.formulations.compiled_rhs import Stretch, CompiledRhsWorkspace
        run = DaeRun(self, kernel, lib, q0, qd0, tau, t0=t0, contacts=contacts, offsets=offsets)
        return Stretch(CompiledRhsWorkspace(run.workspace, kernel, tau, method, run.friction_failure, z0), run.close,
                       compiled_jacobian(kernel, tau))

    @property
    def compiled_methods(self) -> tuple[str, ...]:
        """The compiled loops: with ``projection=True`` only DOP853, whose loop moves the state
        back onto the constraints after every accepted step (``dae_project``, c/dae.c: positions
        by Newton to ``PROJECTION_RESIDUAL``, speeds mass-orthogonally; it does so whatever this
        option for models without quaternion coordinates, and on quaternion coordinates (each
        rotated by the exp-map of its step, as ``StateMap.integrate``) only with it); the
        fixed-step RK4 loop does not."""
        return ("DOP853",) if self.projection else ("DOP853", "RK4")

    def compiled_friction_problem(self) -> str | None:
        """With the recursive dynamics and geometric constraints the KKT solve is the recursive
        program's (``build/c``), which has no friction rows."""
        if self.compiled.dynamics == "recursive" and len(self.compiled.geometric_rows):
            return ("contacts with friction step in Python in the dae formulation with the recursive dynamics and "
                    "constraints (its compiled KKT solve has no friction rows); dynamics='dense' runs them compiled")
        return None

    def compiled_method_problem(self, method: str) -> str | None:
        if self.projection and method not in self.compiled_methods:
            return (f"projection=True: only the compiled DOP853 loop projects after each accepted step "
                    f"(no compiled {method} loop with projection)")
        return super().compiled_method_problem(method)

    @property
    def compiled_contacts(self) -> bool:
        """Contacts run in the compiled loop (events handled between compiled stretches)."""
        return self.compiled_loop() is None

    def contact_run(self, kernel, lib, q0, qd0, tau, t0=0.0, contacts=(), offsets=None) -> DaeRun:
        """The compiled stretch between contact events (``Formulation.contact_run``)."""
        return DaeRun(self, kernel, lib, q0, qd0, tau, t0=t0, contacts=contacts, offsets=offsets)

    def explain_compiled_failure(self, lib) -> None:
        """A position motor whose law was not finite in C (``dae_motor_failure``): the
        ``SimulationError`` Python stepping raises there, not the singular solve it caused."""
        if self.constraints is None or not hasattr(lib, "dae_motor_failure"):
            return
        failure = lib.dae_motor_failure
        failure.argtypes, failure.restype = [], ctypes.c_double
        t = float(failure())
        if t == t:
            raise_pending()  # (a callable motor's own error, kept by the motor callback)
            rows = [r for r in self.constraints.coordinate_rows if self.constraints.equations[r].speed is None]
            self.constraints.explain_position_failure(rows, t)

    @contextmanager
    def compiled_setup(self, lib, kernel=None, q0=None):
        """The compiled right-hand side solves the KKT system on the rows found independent
        at compile time (motor rows with the run's start values, from ``kernel`` and the
        start coordinates ``q0``), with this formulation's Baumgarte gains (set per thread)."""
        if self.constraints is None:
            yield
            return
        if self.constraints.coordinate_rows:
            if kernel is None or q0 is None:
                raise SimulationError("the compiled dae solve of a model with motors needs the kernel and q0")
            rows = DaeRows(self, kernel, lib, self.nominal_rows, self.motor_offsets(np.asarray(q0, dtype=float), 0.0))
            try:
                yield
            finally:
                rows.close()
            return
        configure = lib.dae_configure
        configure.argtypes = [ctypes.c_int, ctypes.c_void_p] + [ctypes.c_double] * 4
        rows = np.ascontiguousarray(self.nominal_rows, dtype=np.int64)
        alpha, beta = self.baumgarte
        configure(len(rows), rows.ctypes.data, alpha, beta, self.schur_scale,
                  self.singular_tolerance)
        set_quaternion_projection(lib, self)
        try:
            yield
        finally:
            configure(-1, None, 0.0, 0.0, 0.0, 0.0)

    def solve(self, kernel, t, q, qd, tau, offsets=None, contacts=()):
        if self.constraints is None and not contacts:
            return kernel.tree_accelerations(t, q, qd, tau), np.zeros(0)
        if has_friction(contacts):
            solution = self.solve_friction(kernel, t, q, qd, tau, offsets, contacts)
            return solution.qdd, solution.lam
        M, f = kernel.checked_dynamics(t, q, qd, tau)
        cv = self.constraint_values(kernel, t, q, qd, offsets, contacts)
        return self.solve_constrained(kernel, M, f, cv.J, self.acceleration_targets(cv, qd), q, t, contacts, qd)

    def evaluation_gains(self) -> tuple[float, float]:
        """This formulation's Baumgarte gains (1/s): its solve at a state includes them."""
        return self.baumgarte

    def acceleration_targets(self, cv, qd):
        """``-bias - 2 alpha gdot - beta^2 g`` (Baumgarte)."""
        alpha, beta = self.baumgarte
        gdot = cv.J @ qd + cv.g_t
        g = np.where(np.isfinite(cv.g), cv.g, 0.0)
        return -cv.bias - 2 * alpha * gdot - beta ** 2 * g
