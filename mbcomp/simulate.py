"""Solver backend: integrate a System with scipy's solve_ivp."""
from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from .errors import ModelError, SimulationError
from .result import Result


class _Progress:
    """A one-line text progress bar on stderr (``progress=True``)."""

    def __init__(self, t_end: float, enabled: bool, width: int = 30):
        self.t_end, self.enabled, self.width = t_end, enabled, width
        self.shown = -1

    def update(self, t: float) -> None:
        if not self.enabled:
            return
        fraction = min(max(t / self.t_end, 0.0), 1.0) if self.t_end > 0 else 1.0
        percent = int(100 * fraction)
        if percent != self.shown:
            self.shown = percent
            filled = int(self.width * fraction)
            sys.stderr.write(f"\rsimulating [{'#' * filled}{'.' * (self.width - filled)}] {percent:3d}% t={t:.4g} s")
            sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def simulate(system, t_end: float, q0: Any, qd0: Any = None, *, method: Any = "DOP853", rtol: float = 1e-8,
             atol: float = 1e-10, t_eval: Any = None, tau: Any = None, progress: bool = False,
             max_step: float = np.inf) -> Result:
    """Integrate ``system`` from ``(q0, qd0)`` at t = 0 to ``t_end``; see ``System.simulate``."""
    try:
        t_end = float(t_end)
    except (TypeError, ValueError):
        raise ModelError("simulate", f"t_end must be a number, got {t_end!r}") from None
    if not np.isfinite(t_end) or t_end <= 0:
        raise ModelError("simulate", f"t_end must be positive and finite, got {t_end}")
    for name, value in (("rtol", rtol), ("atol", atol)):
        if not (np.isfinite(value) and value > 0):
            raise ModelError("simulate", f"{name} must be positive, got {value}")
    if t_eval is not None:
        t_eval = np.asarray(t_eval, dtype=float)
        if t_eval.ndim != 1 or np.any(t_eval < 0) or np.any(t_eval > t_end) or np.any(np.diff(t_eval) <= 0):
            raise ModelError("simulate", "t_eval must be increasing times within [0, t_end]")
    q0 = system.state_vector(q0, "q0")
    qd0 = system._velocity(qd0) if qd0 is not None else np.zeros(system.nq)
    if qd0 is not None and not isinstance(qd0, np.ndarray):
        qd0 = system.state_vector(qd0, "qd0")
    if tau is not None and not callable(tau):
        system._tau(tau, 0.0, q0, qd0)
    q0, qd0 = system.assemble(q0, qd0)
    n = system.nq
    bar = _Progress(t_end, progress)
    counter = {"rhs": 0}

    def rhs(t, y):
        counter["rhs"] += 1
        q, qd = y[:n], y[n:]
        if not np.all(np.isfinite(y)):
            raise SimulationError(f"state became non-finite at t = {t:.6g} s")
        qdd = system._formulation.accelerations(system, t, q, qd, system._tau(tau, t, q, qd))
        bar.update(t)
        return np.concatenate((qd, qdd))

    started = time.perf_counter()
    try:
        sol = solve_ivp(rhs, (0.0, t_end), np.concatenate((q0, qd0)), method=method, rtol=rtol, atol=atol,
                        t_eval=t_eval, max_step=max_step)
    except SimulationError as exc:
        raise SimulationError(f"simulation stopped: {exc}") from None
    except ValueError as exc:
        raise ModelError("simulate", f"solver rejected the settings: {exc}") from None
    finally:
        bar.close()
    wall = time.perf_counter() - started
    if sol.status < 0:
        reached = sol.t[-1] if sol.t.size else 0.0
        raise SimulationError(f"solver {method!r} gave up at t = {reached:.6g} s: {sol.message}")
    if not np.all(np.isfinite(sol.y)):
        raise SimulationError("solver returned non-finite states")
    stats = {"method": method if isinstance(method, str) else getattr(method, "__name__", str(method)),
             "nfev": int(sol.nfev), "njev": int(sol.njev), "nlu": int(sol.nlu), "steps": max(len(sol.t) - 1, 0)
             if t_eval is None else None, "status": int(sol.status), "message": sol.message,
             "success": bool(sol.success), "wall_time": wall, "rtol": rtol, "atol": atol}
    return Result(system=system, t=sol.t, q=sol.y[:n].T.copy(), qd=sol.y[n:].T.copy(), stats=stats, tau=tau)
