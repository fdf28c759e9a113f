"""``System.contact_forces`` and ``System.reactions(contacts=...)`` solve in compiled code.

With held contacts (indices, or a run's closed set with friction modes) the evaluation calls
solve the KKT system with the contacts' rows in C (``formulations/compiled_eval.py``:
``dae_evaluate_friction``, the solve of the compiled loops, friction by ``c/friction.h``).
The formulation's Python solve (``Formulation.contact_forces``, ``reactions``) is the oracle
here; it also answers where the C solve does not (Painleve's paradox, a singular set of held
contacts: its errors name the contacts)."""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.formulations.friction import Closed
from mbcomp.run import post
from conftest import fourbar
from test_cross_paths import initial_state, model_of

FORMULATIONS = ("dae", "lagrange")
G = 9.81


@lru_cache(maxsize=None)
def library_system(name: str, formulation: str, theta: float | None = None):
    system = model_of(name).compile(formulation)
    return system if theta is None else system.with_parameters({"theta": theta})


@lru_cache(maxsize=None)
def fourbar_contact(formulation: str):
    """The four-bar whose crank tip rests on a plane through it (normal +y, friction 0.5):
    a closed loop plus a contact; ``(system, q0)`` at rest."""
    probe = fourbar().compile(formulation)
    q0, _ = probe.assemble([1.0, -0.5, 1.5])
    tip = 0.3 * np.array([np.cos(q0[0]), np.sin(q0[0]), 0.0])
    m = fourbar(name="fourbar_contact")
    m.add(mb.Contact("tip", "crank", point=(0.3, 0.0, 0.0), normal=(0.0, 1.0, 0.0), origin=tuple(tip),
                     friction=0.5))
    return m.compile(formulation), q0


def assert_relative(got, expected, rtol, what):
    scale = max(1.0, float(np.max(np.abs(expected), initial=0.0)))
    assert np.max(np.abs(np.asarray(got) - np.asarray(expected)), initial=0.0) <= rtol * scale, what


def assert_same_as_python(system, q, qd, t, contacts, tau=None, compiled=True):
    """The compiled contact forces and reactions equal the formulation's Python solve's, and
    the C answered (its solver exists for the held set) when ``compiled``, else the Python
    solve answers (no compiled solver)."""
    kernel, form = system.kernel, system._formulation
    applied = None if tau is None else np.asarray(tau, dtype=float)
    solver = form.compiled_solve(kernel, contacts, q, qd)
    if compiled:
        assert solver.solution(t, q, qd, applied, None, contacts) is not None
    else:
        assert solver is None
    got = system.contact_forces(q, qd, t, tau=tau, contacts=contacts)
    expected = form.contact_forces(kernel, t, q, qd, applied, None, contacts)
    assert got.keys() == expected.keys()
    for name, value in expected.items():
        assert_relative(got[name], value, 1e-10, f"contact force {name}")
    got = system.reactions(q, qd, t, tau=tau, contacts=contacts)
    expected = form.reactions(kernel, t, q, qd, applied, None, contacts)
    assert got.keys() == expected.keys()
    for name, value in expected.items():
        assert_relative(got[name], value, 1e-10, f"reaction {name}")


def slope_state(system, rng):
    """A consistent state of the box on its slope: both edges on the plane, sliding along x."""
    c = system.parameters["c"] if "c" in system.parameters else 0.05
    q = np.array([c, rng.normal(), 0.0])
    qd = np.array([0.0, abs(rng.normal()) + 0.1, 0.0])
    return q, qd


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_held_contacts_frictionless_sticking_and_sliding_equal_the_python_solve(formulation):
    """The box on the slope at random consistent states with random applied forces: without
    friction modes, both edges sticking, both sliding down the slope."""
    system = library_system("box_on_slope", formulation)
    rng = np.random.default_rng(3)
    for trial in range(3):
        q, qd = slope_state(system, rng)
        tau = rng.normal(size=3)
        t = 0.1 * trial
        assert_same_as_python(system, q, qd, t, (0, 1), tau)
        assert_same_as_python(system, q, np.zeros(3), t, Closed((0, 1), stick=(0, 1)), tau)
        slip = {i: np.array([1.0, 0.0, 0.0]) for i in (0, 1)}
        assert_same_as_python(system, q, qd, t, Closed((0, 1), slip=slip), tau)
        assert_same_as_python(system, q, qd, t, Closed((0, 1), stick=(0,), slip={1: slip[1]}), tau)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_closed_loop_with_a_held_contact_equals_the_python_solve(formulation):
    """The four-bar's crank tip held on its plane (loop rows plus the contact's row), with
    random applied forces: sticking in C (the least-norm multipliers of every row, as the
    Python friction solve's); without friction the Python solve answers, its rows chosen by
    a pivoted QR among the loop's redundant rows (the compiled solve holds the rows found
    independent without contacts)."""
    system, q0 = fourbar_contact(formulation)
    rng = np.random.default_rng(5)
    for trial in range(3):
        tau = rng.normal(size=3)
        assert_same_as_python(system, q0, np.zeros(3), 0.2 * trial, (0,), tau, compiled=False)
        assert_same_as_python(system, q0, np.zeros(3), 0.2 * trial, Closed((0,), stick=(0,)), tau)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_box_resting_on_a_slope_below_the_friction_angle(formulation):
    """tan(0.3) < mu = 0.4: sticking, the edges' forces sum to m g cos(theta) along the
    normal and m g sin(theta) up the slope (the model's x is down the slope)."""
    theta = 0.3
    system = library_system("box_on_slope", formulation, theta)
    m = system.parameters["m"]
    q = np.array([system.parameters["c"], 0.0, 0.0])
    forces = system.contact_forces(q, np.zeros(3), contacts=Closed((0, 1), stick=(0, 1)))
    total = forces["front"] + forces["back"]
    assert total == pytest.approx([-m * G * np.sin(theta), 0.0, m * G * np.cos(theta)], rel=1e-12, abs=1e-12)
    normals = system.reactions(q, np.zeros(3), contacts=Closed((0, 1), stick=(0, 1)))
    assert normals["front"] + normals["back"] == pytest.approx(m * G * np.cos(theta), rel=1e-12)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_sliding_box_feels_mu_n_against_its_slip(formulation):
    """theta = 0.5, mu = 0.4, sliding down the slope at 1 m/s: friction mu N up the slope."""
    system = library_system("box_on_slope", formulation)
    theta, mu, m = 0.5, 0.4, system.parameters["m"]
    q, qd = np.array([system.parameters["c"], 0.3, 0.0]), np.array([0.0, 1.0, 0.0])
    slip = {i: np.array([1.0, 0.0, 0.0]) for i in (0, 1)}
    forces = system.contact_forces(q, qd, contacts=Closed((0, 1), slip=slip))
    total = forces["front"] + forces["back"]
    normal = m * G * np.cos(theta)
    assert total == pytest.approx([-mu * normal, 0.0, normal], rel=1e-12, abs=1e-12)
    for force in forces.values():  # each edge: mu times its own normal force
        assert force[0] == pytest.approx(-mu * force[2], rel=1e-12)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_ball_at_rest_on_the_floor_carries_its_weight(formulation):
    system = library_system("sliding_ball", formulation)
    m, r = system.parameters["m"], system.parameters["r"]
    q = np.array([r, 0.0, 0.0])
    for contacts in ((0,), Closed((0,), stick=(0,))):
        force = system.contact_forces(q, np.zeros(3), contacts=contacts)["floor"]
        assert force == pytest.approx([0.0, 0.0, m * G], rel=1e-12, abs=1e-12)
        assert system.reactions(q, np.zeros(3), contacts=contacts)["floor"] == pytest.approx(m * G, rel=1e-12)


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name", ["box_on_slope", "sliding_ball"])
def test_result_contact_forces_equal_the_python_solve_at_every_sample(name, formulation, monkeypatch):
    """A run that held contacts (sliding, then for the ball rolling): ``contact_forces`` and
    ``reactions`` at every sample as the Python solve gives them."""
    system = model_of(name).compile(formulation)
    q0, qd0 = initial_state(name, system)
    result = system.simulate(0.5, q0, qd0, t_eval=np.linspace(0.0, 0.5, 41))
    assert any(result.closed_contacts)
    got, got_reactions = post.contact_forces(system, result), post.reactions(system, result)
    assert any(np.any(v) for v in got.values())
    monkeypatch.setattr(type(system), "_compiled_contact_solution", lambda *args, **kwargs: None)
    expected, expected_reactions = post.contact_forces(system, result), post.reactions(system, result)
    for key, value in expected.items():
        assert_relative(got[key], value, 1e-10, key)
    for key, value in expected_reactions.items():
        assert_relative(got_reactions[key], value, 1e-10, key)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_python_backend_gives_the_same_forces(formulation):
    """The same model compiled without C (the Python solve): the same numbers."""
    system = library_system("box_on_slope", formulation)
    plain = model_of("box_on_slope").compile(formulation, backend="python")
    q, qd = np.array([0.05, 0.2, 0.0]), np.array([0.0, 0.7, 0.0])
    contacts = Closed((0, 1), slip={0: np.array([1.0, 0, 0]), 1: np.array([1.0, 0, 0])})
    got, expected = system.contact_forces(q, qd, contacts=contacts), plain.contact_forces(q, qd, contacts=contacts)
    for key, value in expected.items():
        assert_relative(got[key], value, 1e-10, key)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_painleve_raises_the_python_solves_error_and_a_dependent_set_is_the_python_solves(formulation):
    """Sliding with mu so large that the sliding row loses its effective mass (Painleve's
    paradox; the C solve refuses, the Python solve names the contact), and a held contact
    twice (a dependent set at rest: the C solve refuses it, the Python solve's pivoted QR
    keeps one row)."""
    system, q0 = fourbar_contact(formulation)
    heavy = system.with_parameters({"tip.friction": 5.0})
    qd = np.zeros(3)
    with pytest.raises(mb.SimulationError) as caught:
        heavy.contact_forces(q0, qd, contacts=Closed((0,), slip={0: np.array([-1.0, 0.0, 0.0])}))
    expected = None
    try:
        heavy._formulation.contact_forces(heavy.kernel, 0.0, q0, qd, None, None,
                                          Closed((0,), slip={0: np.array([-1.0, 0.0, 0.0])}))
    except mb.SimulationError as error:
        expected = str(error)
    assert str(caught.value) == expected
    ball = library_system("sliding_ball", formulation)
    q, qd = np.array([ball.parameters["r"], 0.0, 0.0]), np.zeros(3)
    solver = ball._formulation.compiled_solve(ball.kernel, (0, 0), q, qd)
    assert solver.solution(0.0, q, qd, None) is None  # (the C refuses the dependent pair at rest)
    expected = ball._formulation.contact_forces(ball.kernel, 0.0, q, qd, None, None, (0, 0))
    assert_relative(ball.contact_forces(q, qd, contacts=(0, 0))["floor"], expected["floor"], 1e-12, "floor")


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_joint_limit_held_against_its_stop(formulation):
    """A rod pushed by gravity against a hinge's upper stop at 0.3 rad: the stop's reaction
    is the gravity torque m g l cos(0.3) (N m) in C as in the Python solve; its contact force
    is zero (a joint limit has no point)."""
    m = mb.Model("rod_stop", gravity=(0, G, 0))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0, -0.5), inertia=(0.0, 0.0, 0.0)))
    joint = m.add(mb.Revolute("hinge", m.ground, rod, axis="x", coords="th"))
    m.add(mb.JointLimit("stop", joint, upper=0.3))
    system = m.compile(formulation)
    q, qd = np.array([0.3]), np.zeros(1)
    held = ([c.name for c in system.topology.contacts].index("stop.upper"),)
    assert_same_as_python(system, q, qd, 0.0, held)
    assert system.reactions(q, qd, contacts=held)["stop.upper"] == pytest.approx(G * 0.5 * np.cos(0.3), rel=1e-12)
    assert np.all(system.contact_forces(q, qd, contacts=held)["stop.upper"] == 0.0)
