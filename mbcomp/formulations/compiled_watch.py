"""Contact watching shared by the compiled loops of both formulations.

A compiled run with contacts arms the loop's watch (``<prefix>_watch``): after each accepted
step the C loop checks the gaps of open contacts and the normal forces of held ones, and on a
sign change stops with EVENT, writing the step into ``event``: ``[t_new, y_new (ny values),
(ny values the loop uses), the 7 x ny DOP853 dense-output coefficients]``.  Python then
locates the event on that step with ``<prefix>_gap_root`` / ``<prefix>_force_root`` /
``<prefix>_cone_root`` / ``<prefix>_slip_root`` (Brent's method in C, ``codegen/c/brentq.h``,
on the C functions ``<prefix>_<what>_at`` of the step's dense output: the root scipy's
``brentq`` finds on them, to rounding) and applies the impact law.
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.codegen.integrators import LoopSession
from mbcomp.core.errors import SimulationError

_VOID, _INT, _DBL, _LONG = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_long


def pointer(array: np.ndarray) -> int:
    """The address of a contiguous numpy array's data (for the C loops' arguments)."""
    return array.__array_interface__["data"][0]


class ContactWatching(LoopSession):
    """Mixin of a compiled run (``lib``, ``n`` reduced/full coordinates, ``contacts`` held):
    arming the loop's watch and reading back the step it stopped at.  ``WATCH`` names the C
    function of the formulation (``dae_watch``, ``lagrange_watch``)."""

    WATCH = ""
    #: The longest step (s) of the stretch (collision features: ``CollisionStretch.step_cap``).
    step_cap = float("inf")

    def watch_contacts(self, gaps: np.ndarray, gap_tolerance: float) -> None:
        """Check every accepted step for contact events: ``gaps`` of every contact at the
        start (updated by the loop, m); the held ones are this stretch's ``contacts``."""
        nk = len(gaps)
        self.gap_tolerance = float(gap_tolerance)
        self.gaps = np.ascontiguousarray(gaps, dtype=float).copy()
        self.held = np.zeros(nk, dtype=np.int64)
        self.held[list(self.contacts)] = 1
        self.event = np.zeros(1 + 9 * self.loop_ny)
        watch = getattr(self.lib, self.WATCH)
        watch.argtypes = [_INT, _VOID, _VOID, _DBL, _VOID]
        watch.restype = ctypes.c_int
        watch(nk, pointer(self.held), pointer(self.gaps), self.gap_tolerance, pointer(self.event))

    @property
    def loop_ny(self) -> int:
        """The most values the loop's state can have (the event buffer holds 9 of them): the
        reduced ``[x_i, qd_i]`` of at most 2 ``n`` values, then the drive states."""
        return 2 * self.n + self.kernel.compiled.drives.nz

    def event_step(self, t_old: float, y_old: np.ndarray):
        """``(t_new, y_new, dense)`` of the step the loop stopped at with EVENT: its end and its
        dense output (scipy's DOP853 interpolant, from the loop's coefficients)."""
        from scipy.integrate._ivp.rk import Dop853DenseOutput
        ny = len(y_old)
        t_new = float(self.event[0])
        y_new = self.event[1:1 + ny].copy()
        F = self.event[1 + 2 * ny:1 + 9 * ny].reshape(7, ny).copy()
        return t_new, y_new, Dop853DenseOutput(t_old, t_new, y_old.copy(), F)


class EventStepFunctions:
    """The C gap and held-force functions (``<prefix>_gap_at``, ``<prefix>_force_at``) bound
    to the event step of ``run`` that starts at ``(t_old, y_old)``: ``self._gap(s, *self.args,
    i, self.p)`` and ``self._force(s, *self.args, row, self.p, self.tau)``."""

    def __init__(self, run, t_old: float, y_old: np.ndarray, prefix: str):
        self.run, self.t_old, self.prefix = run, float(t_old), prefix
        self.y_old = np.ascontiguousarray(y_old, dtype=float).copy()
        ny = len(self.y_old)
        self.h = float(run.event[0]) - self.t_old
        self.F = np.ascontiguousarray(run.event[1 + 2 * ny:1 + 9 * ny])
        self._gap, self._force = getattr(run.lib, f"{prefix}_gap_at"), getattr(run.lib, f"{prefix}_force_at")
        self._gap.argtypes = [_DBL, _DBL, _DBL, _VOID, _VOID, _INT, _LONG, _VOID]
        self._force.argtypes = [_DBL, _DBL, _DBL, _VOID, _VOID, _INT, _LONG, _VOID, _VOID]
        self._gap.restype = self._force.restype = _DBL
        self.args = (self.t_old, self.h, pointer(self.y_old), pointer(self.F), ny)
        self.p = pointer(run.kernel.p)
        self.tau = None if run.tau is None else pointer(run.tau)

    # -- friction (friction_c.FrictionRows of the run): friction.h's functions on the step --
    @property
    def has_friction(self) -> bool:
        """Whether the run's held contacts have friction modes (``cone`` and ``slip`` apply)."""
        return getattr(self.run, "friction", None) is not None

    def _friction_index(self, i: int) -> int:
        return self.run.friction.indices.index(int(i))

    def _tangent(self, i: int, direction) -> tuple[float, float]:
        """A world direction (3,) in contact ``i``'s tangent coordinates (``FrictionRows.tangent_coordinates``)."""
        return self.run.friction.tangent_coordinates(self._friction_index(i), direction)

    def _friction_fn(self, what: str):
        fn = getattr(self.run.lib, f"{self.prefix}_{what}_at")
        extra = [_VOID] if what == "cone" else [_DBL, _DBL]
        fn.argtypes = [_DBL, _DBL, _DBL, _VOID, _VOID, _INT, _LONG, _VOID] + extra
        fn.restype = _DBL
        return fn

    def _friction_value(self, value: float, s: float, what: str) -> float:
        if value != value:
            raise SimulationError(f"the {what} cannot be evaluated at t = {s:.6g} s")
        return value

    def cone(self, s: float, i: int) -> float:
        """Sticking contact ``i``'s distance outside its friction cone (N, positive outside:
        ``ContactWatch.cone_excess``) at time ``s`` on the step, from the friction solve in C."""
        value = self._friction_fn("cone")(float(s), *self.args, self._friction_index(i), self.p, self.tau)
        return self._friction_value(value, s, "friction force")

    def slip(self, s: float, i: int, direction) -> float:
        """Contact ``i``'s slip velocity (m/s) along the world ``direction`` at time ``s`` on the
        step (``ContactWatch.slip_speed``), in C."""
        value = self._friction_fn("slip")(float(s), *self.args, self._friction_index(i), self.p,
                                          *self._tangent(i, direction))
        return self._friction_value(value, s, "slip velocity")

    # -- locating an event on the step: Brent's method in C (``<prefix>_<what>_root``) --
    def root_failure(self, what: str, a: float, b: float) -> SimulationError:
        """The error when ``what`` cannot be evaluated at a trial time in [a, b] (a formulation
        with more to say about it overrides this)."""
        return SimulationError(f"the {what} cannot be evaluated on [{a:.9g}, {b:.9g}] s")

    def _root(self, kind: str, index: int, a: float, b: float, xtol: float, rtol: float, what: str,
              extra_types: list, *extra) -> float:
        """The C function ``<prefix>_<kind>_root(a, b, t_old, h, y_old, F, ny, index, p, *extra,
        xtol, rtol, &status)``: ``mb_brentq`` (codegen/c/brentq.h, scipy's brentq to rounding)
        on ``<prefix>_<kind>_at`` over the step's dense output."""
        fn = getattr(self.run.lib, f"{self.prefix}_{kind}_root")
        fn.argtypes = [_DBL, _DBL, _DBL, _DBL, _VOID, _VOID, _INT, _LONG, _VOID, *extra_types, _DBL, _DBL, _VOID]
        fn.restype = _DBL
        status = ctypes.c_int(0)
        value = fn(float(a), float(b), *self.args, int(index), self.p, *extra, float(xtol), float(rtol),
                   ctypes.byref(status))
        if status.value == 1:
            raise SimulationError(f"the {what} does not change sign on [{a:.9g}, {b:.9g}] s")
        if status.value == 3:
            raise self.root_failure(what, a, b)
        if status.value:
            raise SimulationError(f"the {what} could not be located on [{a:.9g}, {b:.9g}] s (status {status.value})")
        return value

    def cone_root(self, i: int, a: float, b: float, xtol: float, rtol: float) -> float:
        """Where sticking contact ``i``'s force reaches the cone in [a, b] (s): Brent's method in C."""
        return self._root("cone", self._friction_index(i), a, b, xtol, rtol, "friction force", [_VOID], self.tau)

    def slip_root(self, i: int, direction, a: float, b: float, xtol: float, rtol: float) -> float:
        """Where contact ``i``'s slip along the world ``direction`` reaches zero in [a, b] (s):
        Brent's method in C."""
        return self._root("slip", self._friction_index(i), a, b, xtol, rtol, "slip velocity", [_DBL, _DBL],
                          *self._tangent(i, direction))

    def gap_root(self, i: int, a: float, b: float, xtol: float, rtol: float) -> float:
        """Where contact ``i``'s gap crosses 0 in [a, b] (s): Brent's method in C."""
        return self._root("gap", i, a, b, xtol, rtol, "gap", [])

    def force_row(self, k: int) -> int | None:
        """The index ``<prefix>_force_at`` reads held contact ``k``'s normal force at (None: the
        contact has no force of its own, e.g. dropped as dependent)."""
        raise NotImplementedError

    def force_root(self, k: int, a: float, b: float, xtol: float, rtol: float) -> float:
        """Where held contact ``k``'s force crosses 0 in [a, b] (s): Brent's method in C (``a``
        for a contact without a force of its own)."""
        row = self.force_row(k)
        if row is None:
            return a
        return self._root("force", row, a, b, xtol, rtol, "contact force", [_VOID], self.tau)

    def gap(self, s: float, i: int) -> float:
        """Contact ``i``'s gap (m) at time ``s`` on the step (a formulation's locator defines it)."""
        raise NotImplementedError

    def force(self, s: float, k: int) -> float:
        """Held contact ``k``'s normal force (N) at time ``s`` on the step."""
        raise NotImplementedError
