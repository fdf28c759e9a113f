"""Drivers that contradict each other or a loop are a ModelError naming them; consistent
redundant drivers keep working; a loop closure is never dropped in favour of a driver; and a
speed motor's listed parameter takes effect at run time."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import fourbar

FORMULATIONS = ["lagrange", "dae"]
Q0 = [0.5, 0.0, 0.0]


def _loop_gap(system, res) -> float:
    """Largest distance (m) between the two halves of the cut joint C over the run."""
    gaps = [np.linalg.norm(system.body_state("coupler", q, point=[0.8, 0, 0]).position
                           - system.body_state("rocker", q, point=[0.6, 0, 0]).position) for q in res.q]
    return float(max(gaps))


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_listed_motor_speed_takes_effect_at_run_time(formulation):
    system = fourbar(motor=mb.Motor("motor", "A", speed=1.0)).compile(formulation)
    assert "motor.speed" in system.parameters
    faster = system.with_parameters({"motor.speed": 3.0})
    res = faster.simulate(0.5, Q0)
    assert res["A"][-1] - res["A"][0] == pytest.approx(1.5, rel=1e-6)        # 3 rad/s for 0.5 s
    assert system.simulate(0.5, Q0)["A"][-1] - Q0[0] == pytest.approx(0.5, rel=1e-6)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_two_speed_motors_with_different_speeds_on_one_joint_conflict(formulation):
    m = fourbar(motor=mb.Motor("slow", "A", speed=1.0))
    m.add(mb.Motor("fast", "A", speed=2.0))
    with pytest.raises(mb.ModelError, match=r"conflict.*'fast'.*'slow'|conflict.*'slow'.*'fast'"):
        m.compile(formulation)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_motors_on_crank_and_rocker_conflict_through_the_loop(formulation):
    m = fourbar(motor=mb.Motor("crank_motor", "A", speed=1.0))
    m.add(mb.Motor("rocker_motor", "D", speed=1.0))
    with pytest.raises(mb.ModelError, match=r"conflict") as info:
        m.compile(formulation)
    text = str(info.value)
    assert "rocker_motor" in text and "crank_motor" in text


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_two_equal_speed_motors_on_one_joint_are_redundant_not_conflicting(formulation):
    m = fourbar(motor=mb.Motor("one", "A", speed=1.0))
    m.add(mb.Motor("two", "A", speed=1.0))
    system = m.compile(formulation)
    res = system.simulate(0.5, Q0)
    assert res["A"][-1] - Q0[0] == pytest.approx(0.5, rel=1e-6)
    assert _loop_gap(system, res) < 1e-6


def test_the_loop_closure_is_never_the_row_dropped_for_a_driver():
    from mbcomp.formulations.base import independent_rows
    # rows 0, 1: a loop (dependent on each other only through row 2's help); row 2: a driver
    # with a large norm that pivoting alone would take first.
    J = np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0], [100.0, 200.0, 100.0]])
    assert list(independent_rows(J)) == [1, 2] or list(independent_rows(J)) == [0, 2]
    assert list(independent_rows(J, prefer=np.array([True, True, False]))) == [0, 1]
