"""The friction and sphere-box benchmarks against MuJoCo (bench/friction_vs_mujoco.py,
bench/spheres_vs_mujoco.py): their closed forms, the equal-error pairing and the MuJoCo
scenes (skipped without mujoco).  No timing is asserted here, and nothing is compiled.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"
sys.path.insert(0, str(BENCH))

import friction_vs_mujoco as fric  # noqa: E402
import spheres_vs_mujoco as spheres  # noqa: E402


def test_ball_closed_form_rolls_at_five_sevenths_from_the_onset():
    v0, mu, g = fric.BALL["v0"], fric.BALL["mu"], fric.G
    t_roll = 2 * v0 / (7 * mu * g)
    x_on, v_on = fric.ball_exact(t_roll)
    assert math.isclose(v_on, 5 * v0 / 7, rel_tol=1e-12)               # continuous at the onset
    x_later, v_later = fric.ball_exact(t_roll + 0.1)
    assert v_later == 5 * v0 / 7 and math.isclose(x_later - x_on, 0.1 * 5 * v0 / 7, rel_tol=1e-12)
    assert math.isclose(x_on, v0 * t_roll - mu * g * t_roll ** 2 / 2, rel_tol=1e-12)


def test_box_closed_form_slides_past_the_friction_angle_and_sticks_below():
    mu = fric.BOX["mu"]
    x, v = fric.box_exact(0.5, 2.0)
    a = 9.81 * (math.sin(0.5) - mu * math.cos(0.5))
    assert a > 0 and math.isclose(x, 2 * a) and math.isclose(v, 2 * a)
    assert fric.box_exact(math.atan(mu) - 1e-3, 1.0) == (0.0, 0.0)
    assert fric.error("box sticks", 1e-3, -2e-3) == 2e-3


def test_pairs_take_the_cheapest_mbcomp_run_at_least_as_accurate_as_each_mujoco_point():
    row = lambda tool, setting, wall, err: {"case": "c", "tool": tool, "setting": setting, "wall_s": wall,  # noqa: E731
                                           "cpu_s": wall, "error": err}
    rows = [row("MuJoCo", "a", 1.0, 1e-3), row("MuJoCo", "b", 10.0, 1e-5), row("MuJoCo", "dominated", 20.0, 1e-4),
            row("mbcomp", "loose", 5.0, 1e-4), row("mbcomp", "tight", 8.0, 1e-9), row("mbcomp", "slow", 50.0, 1e-4)]
    out = fric.pairs(rows, "c")
    assert [p["mujoco_setting"] for p in out] == ["a", "b"]            # MuJoCo's Pareto front only
    assert [p["mbcomp_setting"] for p in out] == ["loose", "tight"]
    assert [p["ratio"] for p in out] == [5.0, 0.8]
    none = fric.pairs([row("MuJoCo", "a", 1.0, 1e-12), row("mbcomp", "x", 1.0, 1e-9)], "c")
    assert none[0]["mbcomp_setting"] == "" and math.isnan(none[0]["ratio"])


def test_bouncing_closed_form_of_a_lone_sphere():
    z0, r, e, g = 0.2, spheres.RADIUS, spheres.E, spheres.G
    t_fall = math.sqrt(2 * (z0 - r) / g)
    assert math.isclose(spheres.z_exact(z0, t_fall), r, abs_tol=1e-15)
    apex_time = t_fall + e * g * t_fall / g                              # the first rebound's top
    assert math.isclose(spheres.z_exact(z0, apex_time) - r, e ** 2 * (z0 - r), rel_tol=1e-12)
    rest = t_fall * (1 + e) / (1 - e)
    assert spheres.z_exact(z0, rest + 1e-9) == r and spheres.z_exact(z0, rest - 1e-3) > r


def test_observe_finds_overlaps_touches_and_the_energy_left():
    p0, v0 = spheres.initial_state()
    assert p0.shape == (spheres.N, 3) and np.all(p0[:, 2] - spheres.RADIUS >= 0.05)
    assert np.all(np.abs(p0[:, :2]) + spheres.RADIUS < spheres.HALF)          # inside the walls
    end = p0.copy()
    end[:, 2] = spheres.RADIUS                                               # all resting on the floor
    end[5, 2] -= 1e-4                                                        # one sinks 0.1 mm
    end[1, :2] = end[0, :2] - [2 * spheres.RADIUS - 3e-4, 0]                 # two overlap by 0.3 mm (a corner)
    out = spheres.observe(np.array([p0, end]), np.zeros((spheres.N, 3)), np.zeros((spheres.N, 3)))
    assert math.isclose(out["max_penetration_m"], 3e-4, rel_tol=1e-9)
    assert out["touched"][0] and out["touched"][1] and out["touched"].sum() == 2
    assert abs(out["energy_left"]) < 1e-3                                    # at rest: only the sunk sphere's -m g 1e-4


def test_mujoco_scenes_match_mbcomp_initial_states():
    mujoco = pytest.importorskip("mujoco", exc_type=ImportError)
    model, data, reset = spheres.mujoco_setup(1e-3, 0.25)
    reset()
    q0, qd0 = spheres.mbcomp_state()
    assert model.ngeom == spheres.N + 5 and model.nbody == spheres.N + 1
    assert np.allclose(data.qpos, q0) and np.allclose(data.qvel, qd0)
    assert np.allclose(model.body_mass[1:], spheres.MASS)
    for case in fric.CASES:                                                  # the friction scenes build and start at rest
        m = mujoco.MjModel.from_xml_string(fric.mujoco_xml(case, 100, fric.MUJOCO_SETTINGS["RK4 stiff"]))
        assert m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC and math.isclose(m.opt.timestep, fric.horizon(case) / 100)
        assert math.isclose(m.geom_solref[1][0], 2 * m.opt.timestep)
