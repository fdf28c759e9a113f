"""Solver backend: step scipy's integrators, with restarts for projections and partitions."""
from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from scipy.integrate import OdeSolver
from scipy.integrate._ivp.ivp import METHODS

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


def solver_class(method: Any) -> type[OdeSolver]:
    """scipy's ``OdeSolver`` for a name (``"RK45"``, ``"DOP853"``, ``"Radau"``, ``"BDF"``,
    ``"LSODA"``, ``"RK23"``) or a subclass passed directly."""
    if isinstance(method, type) and issubclass(method, OdeSolver):
        return method
    if isinstance(method, str) and method in METHODS:
        return METHODS[method]
    raise ModelError("simulate", f"method must be one of {sorted(METHODS)} or an OdeSolver subclass, got {method!r}")


def check_settings(t_end, rtol, atol, t_eval):
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
        t_eval = np.asarray(t_eval, dtype=float).reshape(-1)
        if np.any(t_eval < 0) or np.any(t_eval > t_end) or np.any(np.diff(t_eval) <= 0):
            raise ModelError("simulate", "t_eval must be increasing times within [0, t_end]")
    return t_end, t_eval


class _Recorder:
    """Collects output samples: every step, or the requested ``t_eval`` times."""

    def __init__(self, t_eval):
        self.t_eval = t_eval
        self.next = 0
        self.t: list[float] = []
        self.q: list[np.ndarray] = []
        self.qd: list[np.ndarray] = []

    def add(self, t, q, qd):
        self.t.append(float(t))
        self.q.append(np.array(q, dtype=float))
        self.qd.append(np.array(qd, dtype=float))

    def record_step(self, workspace, solver, t_old, t_new):
        if self.t_eval is None:
            q, qd = workspace.full_state(t_new, solver.y)
            self.add(t_new, q, qd)
            return
        dense = None
        while self.next < len(self.t_eval) and self.t_eval[self.next] <= t_new:
            ts = self.t_eval[self.next]
            if dense is None:
                dense = solver.dense_output()
            y = dense(ts) if ts != t_new else solver.y
            q, qd = workspace.full_state(ts, y)
            self.add(ts, q, qd)
            self.next += 1


def simulate(system, t_end: float, q0: Any, qd0: Any = None, *, method: Any = "DOP853", rtol: float = 1e-8,
             atol: float = 1e-10, t_eval: Any = None, tau: Any = None, progress: bool = False,
             max_step: float = np.inf) -> Result:
    """Integrate ``system`` from ``(q0, qd0)`` at t = 0 to ``t_end``; see ``System.simulate``."""
    t_end, t_eval = check_settings(t_end, rtol, atol, t_eval)
    cls = solver_class(method)
    q0 = system.state_vector(q0, "q0")
    qd0 = system._velocity(qd0)
    if tau is not None and not callable(tau):
        system._tau(tau, 0.0, q0, qd0)
    formulation = system._formulation
    offsets = formulation.motor_offsets(q0, 0.0)
    q0, qd0 = formulation.assemble(system, q0, qd0, 0.0, offsets)
    workspace = formulation.start(system, 0.0, q0, qd0, tau)
    bar = _Progress(t_end, progress)
    recorder = _Recorder(t_eval)
    counts = {"nfev": 0, "njev": 0, "nlu": 0, "steps": 0, "restarts": 0}

    def fun(t, y):
        if not np.all(np.isfinite(y)):
            raise SimulationError(f"state became non-finite at t = {t:.6g} s")
        return workspace.rhs(t, y)

    def make_solver(t0, y0):
        return cls(fun, t0, y0, t_end, rtol=rtol, atol=atol, max_step=max_step)

    started = time.perf_counter()
    t = 0.0
    if t_eval is None or (len(t_eval) and t_eval[0] == 0.0):
        recorder.add(0.0, q0, qd0)
        recorder.next = 1 if t_eval is not None else 0
    try:
        solver = make_solver(0.0, workspace.y0)
        while True:
            message = solver.step()
            if solver.status == "failed":
                raise SimulationError(f"solver {getattr(cls, '__name__', method)} gave up at t = {solver.t:.6g} s: {message}")
            counts["steps"] += 1
            t_old, t = solver.t_old, solver.t
            recorder.record_step(workspace, solver, t_old, t)
            bar.update(t)
            if solver.status == "finished":
                break
            corrected = workspace.after_step(t, solver.y)
            if corrected is not None:
                for key in ("nfev", "njev", "nlu"):
                    counts[key] += getattr(solver, key, 0)
                counts["restarts"] += 1
                solver = make_solver(t, corrected)
    except SimulationError as exc:
        raise SimulationError(f"simulation stopped: {exc}") from None
    finally:
        bar.close()
    for key in ("nfev", "njev", "nlu"):
        counts[key] += getattr(solver, key, 0)
    wall = time.perf_counter() - started
    q = np.array(recorder.q).reshape(-1, system.nq)
    qd = np.array(recorder.qd).reshape(-1, system.nq)
    if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
        raise SimulationError("solver returned non-finite states")
    stats = {"method": getattr(cls, "__name__", str(method)), **counts, "status": 0,
             "message": "The solver successfully reached the end of the integration interval.",
             "success": True, "wall_time": wall, "rtol": rtol, "atol": atol, "formulation": system.formulation}
    return Result(system=system, t=np.array(recorder.t), q=q, qd=qd, stats=stats, tau=tau, offsets=offsets)
