"""solo12 (example-robot-data) standing on four frictional foot contacts under compiled PD
control plus a feed-forward (examples/solo12_standing.py).

The standing height and the foot forces are computed from the kinematics alone (the lowest
foot centre below the base plus the foot radius; the least-norm vertical foot forces whose
wrench balances the weight); the simulation must hold them, with the feet stuck and no drift.
Skipped without example-robot-data.
"""
import functools
import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("yourdfpy", exc_type=ImportError)
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "solo12_standing.py"
_spec = importlib.util.spec_from_file_location("solo12_standing", EXAMPLE)
solo = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(solo)
if solo.urdf_path() is None:
    pytest.skip("example-robot-data is not installed", allow_module_level=True)

# Compiling the 18-speed robot takes ~20 s per formulation; its tests stay on one worker,
# which builds each formulation's robot and runs each drop once (a worker of its own would
# build and run them again).
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("solo12")]
G = 9.81
FORMULATIONS = ("lagrange", "dae")


@functools.cache
def built(formulation: str):
    """The robot of ``formulation`` (built once for the module's tests)."""
    return solo.solo12(formulation)


@functools.cache
def dropped(formulation: str):
    """Pure PD (no feed-forward), dropped with the feet 2 mm above the floor, run 0.4 s:
    ``(system, q0, result)``, run once for the module's tests."""
    pd_only = built(formulation).with_parameters({f"{name}_pd.value.constant4.value": 0.0 for name in solo.POSTURE})
    q0 = solo.standing_state(pd_only, clearance=0.002)
    t = np.linspace(0.0, 0.4, 81)
    return pd_only, q0, pd_only.simulate(0.4, q0, np.zeros(pd_only.nv), t_eval=t)


@pytest.fixture(scope="module", autouse=True)
def _forget_the_robots():
    """The module's robots and runs are released when its tests are done."""
    yield
    built.cache_clear()
    dropped.cache_clear()


@pytest.fixture(scope="module", params=FORMULATIONS)
def formulation(request):
    return request.param


@pytest.fixture(scope="module")
def robot(formulation):
    return built(formulation)


@pytest.fixture(scope="module")
def standing_runs(robot):
    """The robot put down touching the floor at rest in the posture, run 0.3 s."""
    q0 = solo.standing_state(robot)
    res = robot.simulate(0.3, q0, np.zeros(robot.nv), t_eval=[0.0, 0.1, 0.2, 0.3])
    return robot, q0, res


def test_the_standing_height_is_the_kinematic_one(robot):
    """The base height puts the lowest foot sphere on the floor: every gap is zero (the
    posture is symmetric) and the feet hang 0.16 m (shank) below the knees."""
    q0 = solo.standing_state(robot)
    assert max(abs(g) for g in robot.gaps(q0).values()) < 1e-12
    # By hand: the hip joint sits at the base's height (URDF origins z = 0), the thigh (0.16 m)
    # leans by HFE = 0.8 rad and the shank (0.16 m) by HFE + KFE = -0.8 rad: both drop 0.16 cos 0.8.
    assert q0[robot.coords.index("base_link_free_z")] == pytest.approx(2 * 0.16 * np.cos(0.8) + solo.FOOT_RADIUS,
                                                                       rel=1e-12)


def test_it_stands_still_with_its_feet_stuck(standing_runs):
    robot, q0, res = standing_runs
    assert res.events == []
    assert sorted(res.persistent_contacts) == sorted(f"{leg}_foot" for leg in solo.LEGS)
    np.testing.assert_allclose(res.q[-1], q0, atol=1e-9)          # no drift, no creep
    np.testing.assert_allclose(res.qd[-1], 0.0, atol=1e-8)
    for q in res.q:
        assert min(robot.gaps(q).values()) >= -1e-9


def test_the_feet_carry_the_weight_as_the_statics_say(standing_runs):
    """Each foot carries the least-norm vertical force of the statics (a quarter of the weight
    by the robot's symmetry) and no friction force; together exactly m g."""
    robot, q0, res = standing_runs
    _, f = solo.feed_forward(robot, q0)
    mass = sum(float(node.get("value")) for node in ET.parse(solo.urdf_path()).iter("mass"))   # the URDF's links
    total = sum(res.contact_forces[f"{leg}_foot"][-1] for leg in solo.LEGS)
    weight = mass * G
    assert f.sum() == pytest.approx(weight, rel=1e-12)
    np.testing.assert_allclose(total, [0.0, 0.0, weight], rtol=1e-9, atol=1e-8)
    for leg, fz in zip(solo.LEGS, f):
        np.testing.assert_allclose(res.contact_forces[f"{leg}_foot"][-1], [0.0, 0.0, fz], rtol=1e-8, atol=1e-8)


@pytest.fixture(scope="module")
def drop_runs(formulation):
    """Pure PD (no feed-forward), dropped with the feet 2 mm above the floor, run 0.4 s."""
    return dropped(formulation)


def test_dropped_it_lands_on_four_feet_and_settles(drop_runs):
    """The four feet land together after the free fall of 2 mm (t = sqrt(2 h / g): in free
    fall the PD keeps the posture), stick, and the robot settles with no drift."""
    robot, q0, res = drop_runs
    assert [e.kind for e in res.events] == ["impact"] * 4
    assert [e.time for e in res.events] == [pytest.approx(np.sqrt(2 * 0.002 / G), rel=1e-6)] * 4
    for q in res.q:
        assert min(robot.gaps(q).values()) >= -1e-6
    late = res.t >= 0.3
    assert np.abs(res.q[late] - res.q[-1]).max() < 1e-6                     # at rest: no drift
    assert np.abs(res.qd[-1]).max() < 1e-6
    total = sum(res.contact_forces[f"{leg}_foot"][-1] for leg in solo.LEGS)
    mass = sum(float(node.get("value")) for node in ET.parse(solo.urdf_path()).iter("mass"))
    np.testing.assert_allclose(total, [0.0, 0.0, mass * G], rtol=1e-6, atol=1e-6 * mass * G)


def test_dropped_its_feet_stick(drop_runs):
    """After landing the material point of each foot sphere touching the floor does not
    move (stick; the sphere may roll as the knees give)."""
    robot, _, res = drop_runs
    for k in np.flatnonzero(res.t > 0.03):
        for leg in solo.LEGS:
            state = robot.body_state(f"{leg}_LOWER_LEG", res.q[k])
            below = state.rotation.T @ np.array([0.0, 0.0, -solo.FOOT_RADIUS])
            touching = np.asarray(solo.foot_point(leg)) + below
            v = robot.body_state(f"{leg}_LOWER_LEG", res.q[k], res.qd[k], point=touching).velocity
            assert np.hypot(v[0], v[1]) < 1e-6, (leg, res.t[k], v)


def foot_forces_generalised(robot, res, q) -> np.ndarray:
    """``J^T F`` at ``q``: the generalised forces of the feet's last contact forces (world,
    acting at each foot's touching point), by virtual power over unit speeds."""
    nv = robot.nv
    generalised = np.zeros(nv)
    for leg in solo.LEGS:
        force = res.contact_forces[f"{leg}_foot"][-1]          # acts at the touching point
        below = robot.body_state(f"{leg}_LOWER_LEG", q).rotation.T @ np.array([0.0, 0.0, -solo.FOOT_RADIUS])
        touching = np.asarray(solo.foot_point(leg)) + below
        for k in range(nv):
            e = np.zeros(nv)
            e[k] = 1.0
            generalised[k] += force @ robot.body_state(f"{leg}_LOWER_LEG", q, e, point=touching).velocity
    return generalised


def test_dropped_the_knees_give_as_the_statics_say(drop_runs):
    """At rest the PD torques kp (target - q) balance what holds the robot with the
    contact forces found: h(q) = J^T F on the joints (the sag below the kinematic height
    is the joints' compliance, ~2.8 mm at kp = 20 N m/rad)."""
    robot, q0, res = drop_runs
    q = res.q[-1]
    nv = robot.nv
    generalised = foot_forces_generalised(robot, res, q)
    kp = robot.parameters["FL_HAA_pd.value.constant1.value"]
    pd = np.array([kp * (solo.POSTURE[name] - q[robot.coords.index(name)]) for name in robot.coords[7:]])
    hold = robot.holding_forces(q)
    np.testing.assert_allclose(hold[6:], pd + generalised[6:], atol=1e-6)
    np.testing.assert_allclose(hold[:6], generalised[:6], atol=1e-6)
    assert 0.001 < q0[2] - 0.002 - q[2] < 0.02


def test_formulations_agree_on_the_drop():
    """Lagrange and DAE: the same landing time and the same rest state (to 1e-7)."""
    ends = []
    for formulation in FORMULATIONS:
        res = dropped(formulation)[2]        # the drop the other tests check, run once
        assert res.t[-1] == 0.4
        ends.append((res.events[0].time, res.q[-1]))
    assert ends[0][0] == pytest.approx(ends[1][0], rel=1e-7)   # (lagrange runs compiled, dae in Python: each its steps)
    np.testing.assert_allclose(ends[0][1], ends[1][1], atol=1e-7)


@pytest.fixture(scope="module")
def feed_forward_drop(robot):
    """PD and feed-forward on (kp = 20 N m/rad, kd = 0.5 N m s/rad), dropped with the feet
    2 mm above the floor, run 0.3 s.  In the fall the feed-forward, unbalanced, stretches
    the legs; the front feet land first, slide, and stop on a slip that turns as it decays
    (this collapsed the step size before stops were found by the slip speed)."""
    q0 = solo.standing_state(robot, clearance=0.002)
    return robot, q0, robot.simulate(0.3, q0, np.zeros(robot.nv))      # (every step and event state)


def test_dropped_with_feed_forward_it_lands_on_four_feet_and_stands(feed_forward_drop):
    """Four impacts (front pair, then hind pair), the front feet stop sliding and stick, no
    foot lets go; no penetration; at the end the feet carry m g and the statics hold:
    ``h(q) = J^T F + kp (target - q) + tau_ff`` on the joints and ``h = J^T F`` on the base."""
    robot, q0, res = feed_forward_drop
    feet = [f"{leg}_foot" for leg in solo.LEGS]
    assert sorted(e.contact for e in res.events if e.kind == "impact") == sorted(feet)
    assert [e.kind for e in res.events].count("release") == 0
    assert sorted(res.persistent_contacts) == sorted(feet)
    for q in res.q:
        assert min(robot.gaps(q).values()) >= -1e-9
    mass = sum(float(node.get("value")) for node in ET.parse(solo.urdf_path()).iter("mass"))
    total = sum(res.contact_forces[name][-1] for name in feet)
    np.testing.assert_allclose(total, [0.0, 0.0, mass * G], rtol=0, atol=1e-5 * mass * G)
    q, nv = res.q[-1], robot.nv
    generalised = foot_forces_generalised(robot, res, q)
    p = robot.parameters
    pd = np.array([p[f"{name}_pd.value.constant1.value"] * (solo.POSTURE[name] - q[robot.coords.index(name)])
                   + p[f"{name}_pd.value.constant4.value"] for name in robot.coords[7:]])
    hold = robot.holding_forces(q)
    np.testing.assert_allclose(hold[6:], pd + generalised[6:], atol=1e-4)
    np.testing.assert_allclose(hold[:6], generalised[:6], atol=1e-4)
    for leg in solo.LEGS:                     # stuck: the touching material points stand still
        below = robot.body_state(f"{leg}_LOWER_LEG", q).rotation.T @ np.array([0.0, 0.0, -solo.FOOT_RADIUS])
        touching = np.asarray(solo.foot_point(leg)) + below
        v = robot.body_state(f"{leg}_LOWER_LEG", q, res.qd[-1], point=touching).velocity
        assert np.hypot(v[0], v[1]) < 1e-6, leg


def test_dropped_with_feed_forward_it_settles_near_the_standing_height(feed_forward_drop):
    """The feet stick where the stretched legs put them down, not on the standing footprint,
    so the robot settles in a posture near, not at, the standing one: the base ends above the
    kinematic height by less than the legs had stretched at touchdown (base height minus
    foot-centre height, over the standing one), and no lower than it (the feed-forward
    carries the weight: no sag)."""
    robot, q0, res = feed_forward_drop
    standing = solo.standing_state(robot)[2]
    touchdown = res.events[0].time
    k = int(np.flatnonzero(res.t == touchdown)[0])
    lowest = min(robot.body_state(f"{leg}_LOWER_LEG", res.q[k], point=solo.foot_point(leg)).position[2]
                 for leg in solo.LEGS)
    stretch = (res.q[k, 2] - lowest) - (standing - solo.FOOT_RADIUS)
    assert 0.5e-3 < stretch < 3e-3                               # ~1.5 mm at kp = 20
    z = res["base_link_free_z"]
    assert standing < z[-1] < standing + stretch
    late = res.t >= 0.25
    assert np.abs(z[late] - z[-1]).max() < 1e-6                  # settled
    assert np.abs(res.qd[-1]).max() < 1e-4
