"""solo12 (example-robot-data) standing on four frictional foot contacts under compiled PD
control plus a feed-forward (examples/solo12_standing.py).

The standing height and the foot forces are computed from the kinematics alone (the lowest
foot centre below the base plus the foot radius; the least-norm vertical foot forces whose
wrench balances the weight); the simulation must hold them, with the feet stuck and no drift.
Skipped without example-robot-data.
"""
import importlib.util
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("yourdfpy")
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "solo12_standing.py"
_spec = importlib.util.spec_from_file_location("solo12_standing", EXAMPLE)
solo = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(solo)
if solo.urdf_path() is None:
    pytest.skip("example-robot-data is not installed", allow_module_level=True)

pytestmark = pytest.mark.slow   # compiling the 18-speed robot takes ~20 s per formulation
G = 9.81
FORMULATIONS = ("lagrange", "dae")


@pytest.fixture(scope="module", params=FORMULATIONS)
def robot(request):
    return solo.solo12(request.param)


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
