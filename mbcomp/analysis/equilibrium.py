"""Static equilibrium on the constraint manifold."""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.optimize

from mbcomp.core.errors import SimulationError, format_state
from mbcomp.formulations.base import independent_rows
from mbcomp.analysis.space import Chart, difference, force_vector, integrate, model_forces, speed_names

#: Accept an equilibrium when the reduced generalised force is below this fraction of the
#: loads (the largest generalised force at the guess, or 1), and the constraints hold to
#: ``POSITION_TOLERANCE``.
FORCE_TOLERANCE = 1e-9
POSITION_TOLERANCE = 1e-10


def equilibrium(system, q_guess: Any, tau: Any = None, t: float = 0.0, max_evaluations: int = 2000) -> np.ndarray:
    """Configuration ``q`` near ``q_guess`` where the system rests: every constraint met and
    the generalised forces (gravity, springs, ``tau``) balanced by constraint reactions::

        f(q) + tau + J(q)^T lam = 0,   g(q) = 0      (unknowns: tangent offset x, lam)

    Solved as a nonlinear least-squares problem by scipy's trust-region reflective method
    (a globalised Newton: from a poor guess it cannot step away), then checked on the
    *reduced* residual ``N^T (f + tau)`` (N spans the motions the constraints allow).
    ``tau``: constant generalised forces (array, one per speed) or a callable ``(t, q, qd)``.
    Which equilibrium is found (a pendulum has two) depends on the guess; stable or not
    (see ``modes``).  ``SimulationError`` when none is found near the guess.
    """
    q0 = system.state_vector(q_guess, "q_guess")
    n = len(speed_names(system))
    zero = np.zeros(n)
    if system.constraint_names:
        q0, _ = system.assemble(q0)  # onto the constraints first (raises when impossible)

    def forces(q):
        _, f = model_forces(system, q, zero, t)
        extra = force_vector(system, tau, t, q, zero)
        return f if extra is None else f + extra

    f0 = forces(q0)
    scale = max(float(np.max(np.abs(f0), initial=0.0)), 1.0)
    rows = np.arange(0)
    if system.constraint_names:
        rows = independent_rows(system.constraint_values(q0, None, t).J)
    r = len(rows)

    def residual(x):
        q = integrate(system, q0, x)
        f = forces(q)
        if not r:
            return f / scale
        cv = system.constraint_values(q, None, t)
        J = cv.J[rows]
        projected = f - J.T @ np.linalg.solve(J @ J.T, J @ f)
        return np.concatenate((projected / scale, cv.g[rows]))

    def solved(q):
        worst = float(np.max(np.abs(reduced_forces(system, q, t, tau)), initial=0.0))
        violation = system.constraint_violation(q, t) if r else 0.0
        return worst <= FORCE_TOLERANCE * scale and violation <= POSITION_TOLERANCE, worst

    try:
        # 1. Newton on the projected force and the constraints, globalised by a trust region.
        q = integrate(system, q0, _least_squares(residual, zero, max_evaluations))
        if r:
            q, _ = system.assemble(q)
        ok, worst = solved(q)
        if not ok:
            # 2. It stopped where the force is smallest but not zero (a fold of the force field):
            # pseudo-transient continuation follows the overdamped motion towards a stable rest.
            q = _continuation(system, q0, t, tau, solved)
            # close to it now: Newton finishes from there
            polished = integrate(system, q0, _least_squares(residual, difference(system, q0, q), max_evaluations))
            if r:
                polished, _ = system.assemble(polished)
            if solved(polished)[0] or not solved(q)[0]:
                q = polished
            ok, worst = solved(q)
    except (SimulationError, np.linalg.LinAlgError) as exc:
        raise SimulationError(f"no equilibrium found near q = {format_state(q0)}: the search left the region "
                              f"where the model can be evaluated ({exc})") from None
    if not ok or not np.all(np.isfinite(q)):
        hint = "try another guess, or the loads have no balance"
        if r and np.all(np.isfinite(q)):
            lost = r - len(independent_rows(system.constraint_values(q, None, t).J))
            if lost > 0 or np.max(np.abs(q - q0), initial=0.0) > 1e3:
                hint = ("the search runs into a singular position of the mechanism (the constraint Jacobian loses "
                        "rank: a dead point, where an equilibrium cannot be found this way)")
        raise SimulationError(f"no equilibrium found near q = {format_state(q0)}: the closest point reached, "
                              f"q = {format_state(q)}, leaves an unbalanced generalised force of {worst:.3g} "
                              f"(loads up to {scale:.3g}); {hint}")
    return q


#: "Near the guess": each tangent coordinate stays within this distance of the guess (rad or m).
SEARCH_RADIUS = 2 * np.pi

#: Largest pseudo-transient step per iteration (rad or m).
MAX_STEP = 0.5


def _least_squares(residual, x0: np.ndarray, max_evaluations: int) -> np.ndarray:
    solution = scipy.optimize.least_squares(residual, x0, method="trf", jac="3-point",
                                            bounds=(x0 - SEARCH_RADIUS, x0 + SEARCH_RADIUS),
                                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_evaluations)
    x = solution.x
    for _ in range(4):  # Newton polish (the trust region stops on its own tolerances)
        res = residual(x)
        if np.max(np.abs(res), initial=0.0) < 1e-15:
            break
        x = x - np.linalg.lstsq(_jacobian(residual, x), res, rcond=None)[0]
    return x


def _continuation(system, q0: np.ndarray, t: float, tau: Any, solved, max_steps: int = 300) -> np.ndarray:
    """Pseudo-transient continuation (Kelley and Keyes) on the independent coordinates:
    ``(I / h - da/dx) dx = a`` with ``a`` the accelerations at rest; the pseudo time step ``h``
    grows as the accelerations shrink (switched evolution relaxation), so the iteration
    follows the overdamped motion far away and becomes Newton near the equilibrium."""
    q = q0.copy()
    zero = np.zeros(len(speed_names(system)))

    def accel(chart, xi):
        qx, _ = chart.position(xi)
        extra = force_vector(system, tau, t, qx, zero)
        return system.accelerations(qx, zero, t, tau=extra)[chart.ind]

    chart = Chart(system, q, t)
    a = accel(chart, np.zeros(chart.k))
    D = _jacobian(lambda xi: accel(chart, xi), np.zeros(chart.k), 1e-6)
    h = 0.1 / max(float(np.linalg.norm(D, 2)), 1e-12)
    for _ in range(max_steps):
        if solved(q)[0] or (h > 1e6 and np.linalg.norm(a) < 1e-6 * max(1.0, np.linalg.norm(D))):
            return q  # solved, or Newton-like steps close to the solution: the caller polishes
        try:
            dx = np.linalg.solve(np.eye(chart.k) / h - D, a)
            size = float(np.max(np.abs(dx), initial=0.0))
            if size > MAX_STEP:
                h *= 0.5
                continue
            q_new, _ = chart.position(dx)
            new_chart = Chart(system, q_new, t)
            a_new = accel(new_chart, np.zeros(new_chart.k))
        except (SimulationError, np.linalg.LinAlgError):
            h *= 0.25
            continue
        if np.linalg.norm(a_new) > 2.0 * np.linalg.norm(a) and h > 1e-12:
            h *= 0.25  # too bold: the step made things worse
            continue
        h = min(h * max(np.linalg.norm(a) / max(np.linalg.norm(a_new), 1e-300), 0.5), 1e12)
        q, chart, a = q_new, new_chart, a_new
        D = _jacobian(lambda xi: accel(chart, xi), np.zeros(chart.k), 1e-6)
    return q

def reduced_forces(system, q: np.ndarray, t: float = 0.0, tau: Any = None) -> np.ndarray:
    """``N^T (f + tau)`` at rest: the generalised forces along the independent speeds, zero at
    an equilibrium (N from ``Chart.basis``; without constraints simply ``f + tau``)."""
    n = len(speed_names(system))
    _, f = model_forces(system, q, np.zeros(n), t)
    extra = force_vector(system, tau, t, q, np.zeros(n))
    if extra is not None:
        f = f + extra
    if not system.constraint_names:
        return f
    chart = Chart(system, q, t)
    return chart.basis(q).T @ f


def _jacobian(fun, z: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian (for the final Newton steps only)."""
    cols = []
    for j in range(len(z)):
        step = h * max(1.0, abs(z[j]))
        e = np.zeros_like(z)
        e[j] = step
        cols.append((fun(z + e) - fun(z - e)) / (2 * step))
    return np.column_stack(cols)
