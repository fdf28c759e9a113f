"""The benchmark harness (bench/): its numerics and the peer models it times mbcomp against.

The peers (MuJoCo, Pinocchio, Exudyn) are optional benchmark dependencies: each check that
needs one is skipped when it is not installed.  No timing is asserted here.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
sys.path.insert(0, str(BENCH))

import peers  # noqa: E402
import timing  # noqa: E402
from contact import E, G, HEIGHT, RADIUS, exact_height  # noqa: E402


def test_time_at_interpolates_log_log_along_the_pareto_front():
    # error 1e-4 at 1 ms, 1e-8 at 100 ms: 1e-6 lies halfway in log-log, at 10 ms.
    points = [(1e-4, 1e-3), (1e-8, 1e-1), (1e-5, 5e-1)]          # the last is dominated
    assert math.isclose(timing.time_at(points, 1e-6), 1e-2, rel_tol=1e-12)
    assert math.isclose(timing.time_at(points, 1e-3), 1e-3)         # reached by the cheapest point
    assert math.isnan(timing.time_at(points, 1e-9))                 # never extrapolated
    assert math.isnan(timing.time_at([(math.inf, 1.0), (1e-3, math.nan)], 1e-2))


def test_measure_takes_medians_and_stops_a_sweep_once_accurate():
    values = iter([5.0, 1.0, 3.0])
    runs = [timing.Run("a", "k", 1, lambda: 0.1, group="a"), timing.Run("a", "k", 2, lambda: 0.001, group="a"),
            timing.Run("a", "k", 3, lambda: 1e-9, group="a"), timing.Run("b", "k", 1, lambda: 1 / 0, group="b")]
    timing.measure(runs, 3, check=lambda r: r.result, stop_error=0.01, burst=0.0, log=lambda *_: None)
    assert [len(r.walls) for r in runs] == [3, 3, 0, 0]             # run 3 skipped: run 2 was accurate
    assert runs[2].skipped and runs[3].failed.startswith("ZeroDivisionError")
    run = timing.Run("c", "k", 1, lambda: None)
    run.walls = [next(values) for _ in range(3)]
    assert run.wall == 3.0


def test_a_short_run_is_timed_after_a_warm_up_call(monkeypatch):
    """Below ``burst``: one untimed warm-up call, then up to 5 timed ones (their mean); one
    garbage collection per round, none between the calls; a long run is timed once."""
    script = iter([(0.004, 0.003), (0.001, 0.001), (0.002, 0.002), (0.001, 0.001), (0.002, 0.002), (0.004, 0.004),
                   (0.5, 0.4)])
    collects = []
    monkeypatch.setattr(timing, "timed", lambda fn, collect=True: (*next(script), fn()))
    monkeypatch.setattr(timing.gc, "collect", lambda: collects.append(1))
    short, long = timing.Run("s", "k", 1, lambda: "out"), timing.Run("l", "k", 1, lambda: "out")
    timing.measure([short, long], 1, burst=0.05, log=lambda *_: None)
    assert short.walls == [pytest.approx(0.002)] and short.cpus == [pytest.approx(0.002)]   # the warm-up left out
    assert long.walls == [0.5] and long.cpus == [0.4] and short.result == "out"
    assert len(collects) == 2                                                                 # one per run and round


def test_exact_bouncing_ball():
    t1 = math.sqrt(2 * (HEIGHT - RADIUS) / G)
    assert math.isclose(exact_height(0.0), HEIGHT)
    assert math.isclose(exact_height(t1), RADIUS)
    v = E * G * t1                                                    # rebound speed, apex after v / g
    assert math.isclose(exact_height(t1 + v / G), RADIUS + v * v / (2 * G), rel_tol=1e-12)
    assert math.isclose(exact_height(t1 + 2 * v / G), RADIUS, rel_tol=1e-12, abs_tol=1e-12)


@pytest.fixture(scope="module")
def chain2():
    return peers.MbcompChain(2)


@pytest.mark.parametrize("peer", ["mujoco", "pinocchio", "exudyn"])
def test_peer_chain_accelerations_agree_with_mbcomp(peer, chain2):
    if not peers.available()[peer]:
        pytest.skip(f"{peer} not installed")
    model = peers.BUILDERS[peer](2)
    assert peers.validate(chain2, model, states=3, tol=1e-10) <= 1e-10


def test_peer_integrators_reach_the_same_state(chain2):
    """Every peer runner integrates the same ODE: q(1 s) agrees with mbcomp's to the tolerance."""
    q0, qd0 = np.array([0.3, -0.2]), np.array([0.1, 0.0])
    ref = chain2.simulate(1.0, q0, qd0, tol=1e-12, integrator="compiled")
    found = peers.available()
    if found["pinocchio"]:
        pn = peers.PinocchioChain(2)
        for solver in ("solve_ivp", "dop853", "lsoda"):
            assert np.max(np.abs(pn.simulate(1.0, q0, qd0, tol=1e-10, solver=solver) - ref)) < 1e-7, solver
    if found["mujoco"]:
        mj = peers.MujocoChain(2)
        rk4 = chain2.simulate(1.0, q0, qd0, method="RK4", dt=1e-3, integrator="compiled")
        for loop in ("nstep", "rollout"):                      # the same RK4: the same numbers
            assert np.max(np.abs(mj.simulate(1.0, q0, qd0, dt=1e-3, loop=loop) - rk4)) < 1e-12, loop
    if found["exudyn"]:
        ex = peers.ExudynChain(2)
        assert np.max(np.abs(ex.simulate(1.0, q0, qd0, solver="DOPRI5", tol=1e-10) - ref)) < 1e-7
        assert np.max(np.abs(ex.simulate(1.0, q0, qd0, solver="RK67", steps=200) - ref)) < 1e-7


def test_mujoco_rollout_runs_many_states_in_chunks(chain2):
    if not peers.available()["mujoco"]:
        pytest.skip("mujoco not installed")
    import mujoco
    mj = peers.MujocoChain(2)
    q0s, qd0s = np.array([[0.3, -0.2], [0.1, 0.4], [-0.5, 0.0]]), np.zeros((3, 2))
    datas = [mujoco.MjData(mj.model) for _ in range(2)]
    finals = peers.mujoco_rollout(mj.model, datas, 0.5, q0s, qd0s, dt=1e-3, chunk=64)   # 500 = 7 x 64 + 52
    for i in range(3):
        expected = chain2.simulate(0.5, q0s[i], qd0s[i], method="RK4", dt=1e-3, integrator="compiled")
        assert np.max(np.abs(finals[i] - expected)) < 1e-12
