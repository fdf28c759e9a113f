"""The settings of one ``simulate`` run, checked once, as one typed object.

``RunOptions`` is what ``System.simulate`` turns its keyword arguments into; the driver
(``run/simulate.py``), the compiled loops (``codegen/integrators.py``) and the formulations'
compiled stretches read their settings from it instead of long positional argument lists.
It holds settings only: the inputs of a run (initial state, ``tau``, drive states) stay
arguments of the driver.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbcomp.core import checks
from mbcomp.core.errors import ModelError

#: What ``integrator=`` accepts: choose (compiled when the model allows it), or insist.
INTEGRATORS = ("auto", "compiled", "scipy")
#: The loops compiled with every model (``codegen/integrators.py``).
COMPILED_METHODS = ("DOP853", "RK4")


@dataclass(frozen=True, eq=False)
class RunOptions:
    """The checked settings of a run (see ``System.simulate``).

    ``t_end`` (s, > 0); ``method`` a scipy ``solve_ivp`` name, an ``OdeSolver`` subclass or
    ``"RK4"`` (fixed step ``dt``, s); ``rtol``/``atol`` the integrator's tolerances;
    ``t_eval`` the output times (s, increasing within [0, t_end]) or None for every step (at
    most ``max_samples`` of them); ``max_step`` (s); ``rest_speed`` (m/s) below which a
    closing contact stays closed; ``integrator`` ``"auto"``, ``"compiled"`` or ``"scipy"``;
    ``progress`` False, True or a delay (s) before a progress bar shows."""

    t_end: float
    method: Any = "DOP853"
    rtol: float = 1e-8
    atol: float = 1e-10
    t_eval: np.ndarray | None = None
    max_step: float = np.inf
    rest_speed: float = 1e-4
    integrator: str = "auto"
    dt: float | None = None
    progress: bool | float = False
    max_samples: int | None = None

    @classmethod
    def checked(cls, t_end: float, **settings: Any) -> "RunOptions":
        """The options with every number checked (``ModelError`` naming the argument);
        ``t_eval`` becomes a float array."""
        t_end = checks.number(t_end, "t_end", positive=True)
        rtol = checks.number(settings.pop("rtol", cls.rtol), "rtol", positive=True)
        atol = checks.number(settings.pop("atol", cls.atol), "atol", positive=True)
        checks.number(settings.get("max_step", cls.max_step), "max_step", positive=True, finite=False)
        checks.number(settings.get("rest_speed", cls.rest_speed), "rest_speed", nonnegative=True)
        dt = settings.pop("dt", None)
        dt = None if dt is None else checks.number(dt, "dt", positive=True)
        t_eval = settings.pop("t_eval", None)
        t_eval = None if t_eval is None else checks.time_grid(t_eval, t_end)
        integrator = settings.get("integrator", cls.integrator)
        if integrator not in INTEGRATORS:
            raise ModelError("simulate", f"integrator must be 'auto', 'compiled' or 'scipy', got {integrator!r}")
        return cls(t_end, rtol=rtol, atol=atol, dt=dt, t_eval=t_eval, **settings)

    def replace(self, **changes: Any) -> "RunOptions":
        """A copy with ``changes`` (not checked again)."""
        return dataclasses.replace(self, **changes)

    @property
    def method_name(self) -> str:
        """The method's name (an ``OdeSolver`` subclass's class name)."""
        return self.method if isinstance(self.method, str) else getattr(self.method, "__name__", str(self.method))

    @property
    def progress_delay(self) -> float:
        """``progress=True`` shows the bar at once; a number (s) shows it once the run has
        taken that long (the command line's choice, so short runs stay quiet)."""
        if isinstance(self.progress, bool) or not isinstance(self.progress, (int, float)):
            return 0.0
        return max(float(self.progress), 0.0)
