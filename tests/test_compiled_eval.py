"""The evaluation calls and scipy's methods on models with drive elements evaluate compiled code.

``System.accelerations`` and ``System.reactions`` of a constrained model solve the KKT system
in C (``formulations/compiled_eval.py``: ``dae_evaluate``, the solve of the compiled loops);
the formulation's Python solve is the oracle here, also where the C solve drops a lost row
direction.  scipy's methods on a model with drive elements step the compiled right-hand side
with the drive states in it (``formulations/compiled_rhs.py``)."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.formulations.base import Formulation
from conftest import fourbar
from test_cross_paths import initial_state, system_of

FORMULATIONS = ("dae", "lagrange")


def drive_fourbar() -> mb.Model:
    """The crank-rocker four-bar whose crank a DC motor turns, its voltage a PID on the crank
    angle (two drive states: the PID's integral, the motor's current)."""
    m = fourbar(name="fourbar_pid")
    pid = m.add(mb.PID("pid", mb.Angle("A"), 1.2, kp=20.0, ki=10.0, kd=1.0, limit=12.0))
    m.add(mb.DCMotor("motor", "A", ratio=5.0, resistance=1.5, inductance=0.02, k=0.05, voltage=pid))
    return m


@lru_cache(maxsize=None)
def drive_system(formulation: str):
    return drive_fourbar().compile(formulation)


def drive_start(system):
    q0, qd0 = system.assemble([1.0, -0.5, 1.5])
    return q0, qd0


def python_only(system_factory, monkeypatch):
    """A fresh System of the factory's model whose evaluation calls take the Python solve."""
    monkeypatch.setattr(Formulation, "compiled_solve", lambda self, kernel: None)
    return system_factory()


def case(name: str, formulation: str):
    """``(system, q0, qd0)`` of a library model or the drive four-bar."""
    if name == "fourbar_pid":
        system = drive_system(formulation)
        return (system, *drive_start(system))
    system = system_of(name, formulation)
    return (system, *initial_state(name, system))


def assert_relative(got, expected, rtol, what):
    scale = max(1.0, float(np.max(np.abs(expected), initial=0.0)))
    assert np.max(np.abs(np.asarray(got) - np.asarray(expected)), initial=0.0) <= rtol * scale, what


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name", ["four_bar", "stewart_platform", "slider_crank", "fourbar_pid"])
def test_the_compiled_solve_equals_the_python_solve(name, formulation):
    """At random states near the start (off the constraints too) with random applied forces:
    the C solve's accelerations and multipliers equal the Python solve's to rounding, and
    ``System.accelerations`` / ``reactions`` give the C numbers."""
    system, q0, qd0 = case(name, formulation)
    kernel, form = system.kernel, system._formulation
    solver = form.compiled_solve(kernel)
    assert solver is not None
    rng = np.random.default_rng(11)
    nz = len(system.extra_states)
    for trial in range(4):
        q = q0 + (rng.normal(scale=1e-3, size=len(q0)) if trial else 0.0)
        if not system.topology.state_map.identity:
            q = system.topology.state_map.normalize(q)
        qd = qd0 + rng.normal(scale=0.5, size=len(qd0))
        tau = rng.normal(size=len(qd0))
        z = rng.normal(size=nz)
        t = 0.1 + 0.2 * trial
        applied = tau + (system.drive_outputs(t, q, qd, z)[0] if nz else 0.0)
        qdd, lam = form.solve(kernel, t, q, qd, applied)   # the oracle
        c_qdd, c_lam = solver.solve(t, q, qd, applied)
        assert_relative(c_qdd, qdd, 1e-10, "accelerations")
        assert_relative(c_lam, lam, 1e-10, "multipliers")
        states = z if nz else None
        assert np.array_equal(system.accelerations(q, qd, t, tau=tau, states=states), c_qdd)
        reactions = system.reactions(q, qd, t, tau=tau, states=states)
        expected = form.reactions(kernel, t, q, qd, applied)
        assert reactions.keys() == expected.keys()
        for key, value in expected.items():
            assert_relative(reactions[key], value, 1e-10, f"reaction {key}")


def test_a_speed_motors_start_value_enters_the_compiled_solve():
    """The slider-crank's motor with a start value 0.01 rad off the state (dae: its Baumgarte
    terms pull the crank back): reactions as the Python solve gives them, and not those
    without the start value."""
    system, q0, qd0 = case("slider_crank", "dae")
    kernel, form = system.kernel, system._formulation
    q0, qd0 = system.assemble(q0, qd0)
    offsets = form.motor_offsets(q0 + 0.01, 0.0)
    got = system.reactions(q0, qd0 + 0.1, 0.2, offsets=offsets)
    expected = form.reactions(kernel, 0.2, q0, qd0 + 0.1, None, offsets)
    for key, value in expected.items():
        assert_relative(got[key], value, 1e-10, f"reaction {key}")
    plain = system.reactions(q0, qd0 + 0.1, 0.2)
    assert abs(plain["motor"] - got["motor"]) > 1e-3


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_where_a_row_direction_is_lost_the_compiled_solve_gives_the_least_norm_answer(formulation):
    """Every bar along x (off the loop: a closure row of zeros): the C solve drops the lost
    direction (``c/least_norm.h``) and answers what the Python least-squares solve (numpy's
    ``lstsq``, the oracle) answers: the same accelerations and reactions."""
    system = drive_system(formulation)
    kernel, form = system.kernel, system._formulation
    q, qd, tau = np.zeros(3), np.array([0.5, -0.2, 0.3]), np.array([0.1, 0.0, -0.2])
    applied = tau + system.drive_outputs(0.0, q, qd, np.zeros(2))[0]
    solved = form.compiled_solve(kernel).solve(0.0, q, qd, applied)
    assert solved is not None
    expected = form.accelerations(kernel, 0.0, q, qd, applied)
    assert_relative(solved[0], expected, 1e-10, "qdd")
    assert_relative(system.accelerations(q, qd, tau=tau), expected, 1e-10, "System.accelerations")
    got = system.reactions(q, qd, tau=tau)
    for key, value in form.reactions(kernel, 0.0, q, qd, applied).items():
        assert_relative(got[key], value, 1e-10, f"reaction {key}")


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("method", ["RK45", "Radau"])
def test_scipy_methods_step_the_compiled_rhs_of_a_drive_model(formulation, method):
    """The PID-and-motor four-bar with a scipy method: the compiled right-hand side steps the
    drive states too (``stats["rhs"]``), and the motion and the states follow the compiled
    DOP853 loop to the tolerances asked for."""
    system = drive_system(formulation)
    q0, qd0 = drive_start(system)
    t = np.linspace(0.0, 0.5, 11)
    reference = system.simulate(0.5, q0, qd0, t_eval=t, rtol=1e-11, atol=1e-12)
    assert reference.stats["integrator"] == "compiled"
    res = system.simulate(0.5, q0, qd0, t_eval=t, method=method, rtol=1e-9, atol=1e-11)
    assert res.stats["integrator"] == "scipy" and res.stats["rhs"] == "compiled"
    assert system.integration_path(method) == f"scipy: scipy method {method!r} requested (compiled loops: DOP853, RK4)"
    assert_relative(res.q, reference.q, 1e-6, "q")
    assert_relative(res.z, reference.z, 1e-5, "drive states")
    assert np.max(np.abs(res.z[-1] - res.z[0])) > 0.1  # (the states moved)
    assert res.constraint_violation().max() < 1e-6


def test_a_tree_with_drive_elements_steps_the_compiled_rhs():
    """No constraints: a scipy method still steps the compiled right-hand side with the drive
    states (DC motor on a pendulum), as the compiled loop does."""
    m = mb.Model("servo_tree", gravity=(0, 0, -9.81))
    bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -0.5)))
    joint = m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    m.add(mb.DCMotor("motor", joint, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=6.0))
    system = m.compile()
    t = np.linspace(0.0, 1.0, 11)
    reference = system.simulate(1.0, [0.0], t_eval=t, rtol=1e-11, atol=1e-12)
    res = system.simulate(1.0, [0.0], t_eval=t, method="RK45", rtol=1e-9, atol=1e-11)
    assert res.stats["rhs"] == "compiled"
    assert_relative(res.q, reference.q, 1e-6, "q")
    assert_relative(res.z, reference.z, 1e-5, "current")


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_analysis_is_unchanged_by_the_compiled_solve(formulation, monkeypatch):
    """Equilibrium and linearisation of the PID four-bar (a loop with drive states) and the
    linearisation of the library four-bar: the same with the compiled solve as with the
    Python one, to 1e-9."""
    system = drive_fourbar().compile(formulation)
    q_guess = drive_start(system)[0]
    q, states = system.equilibrium(q_guess, return_states=True)
    lin = system.linearize(q)
    loop = system_of("four_bar", formulation)
    q_loop = initial_state("four_bar", loop)[0]
    lin_loop = loop.linearize(q_loop)
    python = python_only(lambda: drive_fourbar().compile(formulation), monkeypatch)
    q_py, states_py = python.equilibrium(q_guess, return_states=True)
    assert np.max(np.abs(q - q_py)) < 1e-9
    assert all(abs(states[k] - states_py[k]) < 1e-9 for k in states)
    lin_py = python.linearize(q_py)
    assert_relative(lin.A, lin_py.A, 1e-9, "A")
    loop_py = python_only(lambda: load_four_bar(formulation), monkeypatch)
    assert_relative(lin_loop.A, loop_py.linearize(q_loop).A, 1e-9, "A of the four-bar")


def load_four_bar(formulation: str):
    from test_cross_paths import model_of
    return model_of("four_bar").compile(formulation)
