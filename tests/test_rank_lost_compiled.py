"""The dae formulation's compiled KKT solve at singular positions (c/least_norm.h): the
least-norm multipliers of a rank-revealing Jacobi eigen-decomposition of the Schur complement
``J M^-1 J^T``, so that the compiled loop carries on where the constraint rows lose rank.

Oracles: the least-norm solve in Python (``core.small_linalg.least_norm``, numpy's lstsq) on
the same rows at the same states, and for a parallelogram four-bar, the closed-form reduction
of its parallelogram branch to one degree of freedom."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import mbcomp as mb
from components.test_constraints import DEAD, G, parallelogram, two_fourbars
from mbcomp.core.small_linalg import least_norm
from mbcomp.core.tolerances import RANK_TOLERANCE, REST_SPEED, SINGULAR_TOLERANCE
from mbcomp.formulations.compiled_rhs import CompiledRhsWorkspace

L, D = 0.3, 0.7  # the parallelogram's crank and coupler lengths (m)


@pytest.fixture(scope="module")
def para():
    return parallelogram(L, D).compile("dae")


def python_least_norm(system, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The accelerations ``M^-1 (f + J^T lam)`` with ``lam`` the least-norm solution (numpy's
    lstsq) of ``(J M^-1 J^T) lam = rhs - J M^-1 f`` on the configured rows, cut off where the
    C solve is documented to cut: ``sqrt(w) <= tol max(sqrt(w_max), schur_scale)`` with the
    rank tolerance at rest and the singular tolerance in motion, and rounding (16 n eps)."""
    formulation, kernel = system._formulation, system.kernel
    M, f = kernel.checked_dynamics(0.0, q, qd)
    cv = formulation.constraint_values(kernel, 0.0, q, qd)
    rows = formulation.nominal_rows
    J, rhs = cv.J[rows], formulation.acceleration_targets(cv, qd)[rows]
    Minv_f, Minv_JT = np.linalg.solve(M, f), np.linalg.solve(M, J.T)
    A = J @ Minv_JT
    tol = RANK_TOLERANCE if np.all(np.abs(qd) < REST_SPEED) else SINGULAR_TOLERANCE
    wmax = np.linalg.eigvalsh(A).max()
    top = max(np.sqrt(wmax), formulation.schur_scale)
    rcond = max(tol ** 2 * top ** 2 / wmax, 16 * len(rows) * np.finfo(float).eps)
    lam = least_norm(A, rhs - J @ Minv_f, rcond, "the oracle")
    return Minv_f + Minv_JT @ lam


def c_accelerations(system, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """The accelerations of the compiled right-hand side (``rhs_value``: the dae KKT solve in C)."""
    formulation, kernel = system._formulation, system.kernel
    with formulation.compiled_setup(kernel.compiled.functions.lib, kernel=kernel, q0=q):
        y = np.concatenate((q, qd))
        rates = CompiledRhsWorkspace(SimpleNamespace(y0=y), kernel, None, "test").rhs(0.0, y)
    return rates[len(q):]


def rank_gap(system, q: np.ndarray) -> float:
    """sqrt of the smallest over the largest eigenvalue of the Schur complement at q."""
    formulation, kernel = system._formulation, system.kernel
    M, _ = kernel.checked_dynamics(0.0, q, np.zeros(len(q)))
    J = formulation.constraint_values(kernel, 0.0, q, np.zeros(len(q))).J[formulation.nominal_rows]
    w = np.linalg.eigvalsh(J @ np.linalg.solve(M, J.T))
    return float(np.sqrt(max(w.min(), 0.0) / w.max()))


def off_dead(eps: float) -> np.ndarray:
    """The parallelogram branch ``eps`` rad from the dead point (cranks parallel, coupler level)."""
    return np.array([DEAD[0] + eps, DEAD[1] - eps, DEAD[2] + eps])


@pytest.mark.parametrize("eps, qd, dropped", [
    (0.0, [1.0, -1.0, 1.0], True),      # at the dead point, in motion: the lost direction dropped
    (1e-5, [0.5, -0.5, 0.5], True),     # inside the singular tolerance in motion: dropped
    (1e-2, [0.5, -0.3, 0.2], False),    # regular: the full solve (and speeds off the constraints)
    (1e-5, [0.0, 0.0, 0.0], False),     # at rest near the dead point: only the rank tolerance applies
    (1e-6, [0.0, 0.0, 0.0], False),
])
def test_c_solve_is_the_python_least_norm_solve_near_the_dead_point(para, eps, qd, dropped):
    q, qd = off_dead(eps), np.array(qd, dtype=float)
    gap = rank_gap(para, q)
    assert (gap <= SINGULAR_TOLERANCE and np.any(qd)) == dropped
    expected = python_least_norm(para, q, qd)
    got = c_accelerations(para, q, qd)
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    if eps == 0.0:  # the parallelogram branch at the dead point: theta'' = 6 g / (5 L) sin(theta) (below)
        assert got[0] == pytest.approx(-6 * G / (5 * L), rel=1e-9)


def test_c_solve_at_the_two_fourbars_singular_position(para):
    """IFToMM A02 with every crank horizontal (each four-bar at its singular position) and the
    first crank turning: the compiled solve is the least-norm one."""
    s = two_fourbars().compile("dae")
    q, qd = s.assemble(np.array([-np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2, -np.pi / 2]), [1.0, 0, 0, 0, 0])
    assert rank_gap(s, q) < SINGULAR_TOLERANCE
    expected = python_least_norm(s, q, qd)
    np.testing.assert_allclose(c_accelerations(s, q, qd), expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def branch_angle(eps: float, times: np.ndarray) -> np.ndarray:
    """Crank angle on the parallelogram branch released at rest ``eps`` from the dead point:
    cranks parallel, coupler translating, so ``T = (5/6) L^2 theta'^2`` (two cranks of m L^2/3
    and the coupler's m L^2, 1 kg each) and ``V = 2 m g L cos(theta)``: ``theta'' = 6 g / (5 L)
    sin(theta)``."""
    sol = solve_ivp(lambda t, y: [y[1], 6 * G / (5 * L) * np.sin(y[0])], (0.0, times[-1]), [DEAD[0] + eps, 0.0],
                    t_eval=times, rtol=1e-12, atol=1e-14)
    return sol.y[0]


@pytest.mark.parametrize("eps", [1e-5, 1e-6])
def test_released_at_rest_near_the_dead_point_runs_compiled_on_its_branch(para, eps):
    """Within the singular tolerance of the dead point at rest the compiled solve used to give
    up (``RankLost``) and the run was repeated in Python, which left the branch at eps = 1e-5
    (crank at -3.03 rad at 1 s instead of -2.22) and drifted 3e-3 rad at 1e-6.  Now it runs
    compiled, on the branch, with the closed form's motion to the run tolerance."""
    q0, qd0 = para.assemble(off_dead(eps), [0.0, 0.0, 0.0])
    times = np.linspace(0.0, 1.0, 21)
    res = para.simulate(1.0, q0, qd0, t_eval=times)
    assert res.stats["path"] == "compiled" and para.integration_path() == "compiled"
    np.testing.assert_allclose(res["A"], branch_angle(eps, times), atol=1e-6)
    np.testing.assert_allclose(res["D"], res["A"], atol=1e-6)                       # rocker parallel
    np.testing.assert_allclose(np.angle(np.exp(1j * (res["A"] + res["B"]))), 0.0, atol=1e-6)  # coupler level
    energy = res.energy().total
    assert np.ptp(energy) < 1e-6 * np.max(res.energy().kinetic)


@pytest.mark.parametrize("integrator", ["auto", "compiled", "scipy"])
def test_at_rest_on_the_dead_point_the_motion_is_not_determined(para, integrator):
    """Exactly at the dead point at rest the least-norm solve would pick one motion of several:
    the compiled solve reports the lost rank (the one case left for ``RankLost``) and the run
    raises the Python path's error naming the constraint."""
    with pytest.raises(mb.SimulationError, match=r"'C'|\bC\b|singular position"):
        para.simulate(0.1, DEAD, [0.0, 0.0, 0.0], integrator=integrator)
