"""The benchmark bicycle (library/whipple_bicycle.toml) against the closed-form linearised
equations of Meijaard et al. (2007) (tests/bicycle_benchmark.py, itself checked against the
paper's published numbers in tests/test_bicycle_benchmark.py).

mbcomp knows nothing of bicycles: the model is four rigid bodies on revolute joints with two
``RollingDisc`` constraints, and ``System.linearize`` about the steady straight-ahead motion
must reproduce the paper's lean and steer eigenvalues, the weave and capsize speeds, and the
motions they predict (self-stable at 5 m/s, falling at 3 m/s), with energy conserved (rolling
without slip does no work).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import brentq, linear_sum_assignment

import mbcomp as mb
from mbcomp.files.toml_model import library_models

try:                                    # tests/ on sys.path (pytest's default rootdir-less import)
    import bicycle_benchmark as bb
except ImportError:                     # tests imported as a package
    from tests import bicycle_benchmark as bb

pytestmark = pytest.mark.xdist_group("whipple_bicycle")   # one compiled model per worker
LEAN_STEER = ("lean", "steer", "lean_dot", "steer_dot")
SPEEDS = np.arange(0.0, 8.5, 1.0)


@pytest.fixture(scope="module")
def model():
    return mb.load(library_models()["whipple_bicycle"])


@pytest.fixture(scope="module", params=["lagrange", "dae"])
def system(request, model):
    return model.compile(formulation=request.param)


def steady(system, v: float) -> tuple[np.ndarray, np.ndarray]:
    """Upright, straight ahead along x at forward speed ``v`` (m/s): the wheels roll at -v/r
    (their angles turn about the paper's y axis, to the right)."""
    p = bb.BENCHMARK
    q = np.zeros(len(system.coords))
    qd = dict.fromkeys(system.speeds, 0.0)
    qd.update(x=v, rear_wheel_angle=-v / p["rR"], front_wheel_angle=-v / p["rF"])
    return q, np.array([qd[s] for s in system.speeds])


def linearised(system, v: float):
    q, qd = steady(system, v)
    return system.linearize(q, qd)


def lean_steer_block(lin) -> np.ndarray:
    """The (lean, steer, rates) rows and columns of ``A``; checks that no other state feeds them,
    so that their eigenvalues are eigenvalues of the whole ``A``."""
    states = list(lin.states)
    rows = [states.index(s) for s in LEAN_STEER]
    others = [i for i in range(len(states)) if i not in rows]
    scale = np.abs(lin.A[np.ix_(rows, rows)]).max()
    assert np.abs(lin.A[np.ix_(rows, others)]).max() < 1e-10 * scale
    return lin.A[np.ix_(rows, rows)]


def test_structure(model, system):
    assert system.ndof == 3                        # lean, steer and the forward speed
    assert {"lean", "steer", "pitch", "yaw", "x", "y"} <= set(system.coords)
    p = model.named_parameters
    assert p["lambda"] == pytest.approx(np.pi / 10) and p["IBxz"] == 2.4 and p["w"] == 1.02
    assert model.initial["qd"]["x"] == 5.0


def test_upright_geometry(system):
    """At zero coordinates: wheel centres at their radii above the contact points, wheel base
    w, centres of mass where the paper puts them (x forward, z up here, z down there)."""
    p = bb.BENCHMARK
    q = np.zeros(len(system.coords))
    np.testing.assert_allclose(system.body_state("rear_wheel", q).position, [0, 0, p["rR"]], atol=1e-15)
    np.testing.assert_allclose(system.body_state("front_wheel", q).position, [p["w"], 0, p["rF"]], atol=1e-15)
    np.testing.assert_allclose(system.body_state("rear_frame", q).position, [p["xB"], 0, -p["zB"]], atol=1e-15)
    np.testing.assert_allclose(system.body_state("front_frame", q).position, [p["xH"], 0, -p["zH"]], atol=1e-15)


@pytest.mark.parametrize("v", SPEEDS)
def test_eigenvalues_are_the_benchmarks(system, v):
    """All eigenvalues of the full A (10 states: the lean, steer and forward speed, plus the
    ignorable x, y, yaw and wheel angles) are the benchmark's four and zeros."""
    lin = linearised(system, v)
    assert lin.A.shape == (10, 10)
    mine = np.linalg.eigvals(lin.A)
    expected = bb.eigenvalues(v)
    cost = np.abs(expected[:, None] - mine[None, :])
    rows, cols = linear_sum_assignment(cost)
    assert cost[rows, cols].max() < 1e-6, (expected, mine[cols])
    rest = np.delete(mine, cols)
    assert np.abs(rest).max() < 1e-4, rest     # ignorable coordinates (a double zero splits by ~sqrt(eps))
    # sharper: the lean/steer block is the benchmark's state matrix itself
    np.testing.assert_allclose(lean_steer_block(lin), bb.state_matrix(v), rtol=0, atol=1e-8)


def test_weave_and_capsize_speeds(model):
    """Root-finding on mbcomp's eigenvalues gives the paper's stability boundaries."""
    system = model.compile()

    def weave_real(v):
        lam = np.linalg.eigvals(lean_steer_block(linearised(system, v)))
        return max(x.real for x in lam if abs(x.imag) > 1e-9)

    def capsize_real(v):
        lam = np.linalg.eigvals(lean_steer_block(linearised(system, v)))
        return min((x.real for x in lam if abs(x.imag) <= 1e-9), key=abs)

    assert brentq(weave_real, 4.0, 4.6, xtol=1e-9) == pytest.approx(bb.PUBLISHED_WEAVE_SPEED, abs=1e-6)
    assert brentq(capsize_real, 5.8, 6.2, xtol=1e-9) == pytest.approx(bb.PUBLISHED_CAPSIZE_SPEED, abs=1e-6)


def perturbed_ride(system, v: float, t_end: float, lean_rate: float = 0.1):
    q, qd = steady(system, v)
    qd[list(system.speeds).index("lean")] = lean_rate
    return system.simulate(t_end, q, qd, t_eval=np.linspace(0.0, t_end, int(20 * t_end) + 1))


def assert_energy_conserved(res, rtol=1e-8):
    energy = res.energy()
    drift = np.abs(energy.total - energy.total[0]).max()
    assert drift < rtol * np.abs(energy.kinetic).max(), drift


def test_self_stable_at_5_m_per_s(system):
    """A push on the lean at 5 m/s (between the weave and capsize speeds): the weave
    oscillation dies out and the bicycle rides on upright; no energy is lost."""
    res = perturbed_ride(system, 5.0, 8.0)
    lean = np.abs(res["lean"])
    assert lean.max() < 0.05
    assert lean[res.t > 6.0].max() < 0.2 * lean.max()
    assert np.abs(res["steer"][res.t > 6.0]).max() < 0.2 * np.abs(res["steer"]).max()
    assert_energy_conserved(res)
    assert np.max(res.constraint_violation()) < 1e-8


def test_small_motions_follow_the_linear_benchmark(model):
    """The nonlinear ride after a small push follows exp(A t) x0 of the paper's equations; the
    difference is second order in the push (10 times smaller push: 100 times smaller).
    (dae only: the lagrange formulation's motion is the same, test_self_stable_at_5_m_per_s.)"""
    system = model.compile(formulation="dae")
    A = bb.state_matrix(5.0)
    errors = []
    for lean_rate in (0.1, 0.01):
        res = perturbed_ride(system, 5.0, 8.0, lean_rate)
        predicted = np.array([expm(A * t) @ [0.0, 0.0, lean_rate, 0.0] for t in res.t])
        errors.append(max(np.abs(predicted[:, 0] - res["lean"]).max() / np.abs(predicted[:, 0]).max(),
                          np.abs(predicted[:, 1] - res["steer"]).max() / np.abs(predicted[:, 1]).max()))
    assert errors[0] < 1e-2 and errors[1] < 1e-4
    assert 50 < errors[0] / errors[1] < 200


def test_falls_at_3_m_per_s(system):
    """Below the weave speed the same push grows into a fall (the weave pair is unstable)."""
    res = perturbed_ride(system, 3.0, 2.5)
    lean = np.abs(res["lean"])
    assert lean[res.t > 2.0].max() > 10 * lean[res.t < 0.5].max()
    assert_energy_conserved(res, rtol=1e-7)


@pytest.mark.parametrize("change", [{"mB": 90.0, "xB": 0.35, "IBxz": 2.0}, {"rF": 0.4, "c": 0.1, "w": 1.1},
                                    {"g": 5.0, "IFyy": 0.26, "zH": -0.75}])
def test_another_bicycle_without_recompiling(system, change):
    """The paper's parameters are the model's run-time parameters: a changed bicycle (heavier
    rider, larger front wheel, the moon...) linearises to the benchmark formulas with the
    same changes, from the same compiled code."""
    other = system.with_parameters(change)
    p = dict(bb.BENCHMARK, **change)
    v = 5.0
    qd = dict.fromkeys(other.speeds, 0.0)
    qd.update(x=v, rear_wheel_angle=-v / p["rR"], front_wheel_angle=-v / p["rF"])
    lin = other.linearize(np.zeros(len(other.coords)), np.array([qd[s] for s in other.speeds]))
    np.testing.assert_allclose(lean_steer_block(lin), bb.state_matrix(v, p), rtol=0, atol=1e-8)
    assert np.abs(lean_steer_block(lin) - bb.state_matrix(v)).max() > 1e-3     # it is another bicycle


def test_head_angle_is_structure(system):
    """``lambda`` turns the steer axis, which is structure: changing it asks for a new compile."""
    with pytest.raises(mb.ModelError, match="lambda"):
        system.with_parameters({"lambda": 0.35})
