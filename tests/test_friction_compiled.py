"""Coulomb friction in the compiled loops (formulations/friction_c.py, c/friction.h): the
library's friction models run compiled in both formulations, with the closed forms of
tests/test_friction.py and the numbers of the Python-stepped path (integrator="scipy"),
which solves the same law in Python."""
import math

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.files.toml_model import library_models, load
from mbcomp.formulations.friction import Closed, plane_contact_rows
from mbcomp.formulations.friction_c import FrictionRows

G = 9.81
FORMULATIONS = ("lagrange", "dae")
MODELS = library_models()


def library_system(name: str, formulation: str):
    return load(MODELS[name]).compile(formulation)


def assert_compiled(system, res) -> None:
    assert system.integration_path() == "compiled"
    assert res.stats["integrator"] == "compiled" and res.stats["path"] == "compiled"


@pytest.fixture(scope="module", params=FORMULATIONS)
def sliding_ball(request):
    return library_system("sliding_ball", request.param)


@pytest.fixture(scope="module", params=FORMULATIONS)
def box_on_slope(request):
    return library_system("box_on_slope", request.param)


class TestSlidingBall:
    """Launched sliding at v0 without spin (library/sliding_ball.toml): rolling starts at
    t = 2 v0 / (7 mu g) with speed 5 v0 / 7, having lost m v0^2 / 7."""

    V0, MU, R, M = 2.0, 0.3, 0.1, 1.5

    def run(self, system, **options):
        return system.simulate(0.3, [self.R, 0.0, 0.0], [0.0, self.V0, 0.0], rtol=1e-10, atol=1e-12, **options)

    def test_rolls_at_the_closed_form_time_in_compiled_code(self, sliding_ball):
        res = self.run(sliding_ball)
        assert_compiled(sliding_ball, res)
        assert [e.kind for e in res.events] == ["stick"]
        assert res.events[0].time == pytest.approx(2 * self.V0 / (7 * self.MU * G), rel=1e-7)
        assert res["x_d"][-1] == pytest.approx(5 * self.V0 / 7, rel=1e-9)
        assert res["phi_d"][-1] == pytest.approx(5 * self.V0 / 7 / self.R, rel=1e-9)
        energy = res.energy().total
        assert energy[0] - energy[-1] == pytest.approx(self.M * self.V0 ** 2 / 7, rel=1e-8)

    def test_compiled_and_python_stepping_agree(self, sliding_ball):
        compiled, python = self.run(sliding_ball), self.run(sliding_ball, integrator="scipy")
        assert python.stats["integrator"] != "compiled"
        assert [e.kind for e in compiled.events] == [e.kind for e in python.events]
        assert compiled.events[0].time == pytest.approx(python.events[0].time, abs=1e-8)
        np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-8)
        np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-8)

    def test_friction_force_while_sliding_then_none(self, sliding_ball):
        t = np.array([0.0, 0.1, 0.25])
        res = self.run(sliding_ball, t_eval=t)
        weight = self.M * G
        np.testing.assert_allclose(res.contact_forces["floor"][:2], [[-self.MU * weight, 0.0, weight]] * 2,
                                   rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(res.contact_forces["floor"][2], [0.0, 0.0, weight], atol=1e-8)


class TestBoxOnSlope:
    """library/box_on_slope.toml: at rest on its two lower edges, it stays put iff
    tan(theta) <= mu, else slides with a = g (sin theta - mu cos theta)."""

    def run(self, system, theta, mu, **options):
        return system.simulate(1.0, [0.05, 0.0, 0.0], [0.0, 0.0, 0.0], parameters={"theta": theta, "mu": mu},
                               rtol=1e-10, atol=1e-12, **options)

    def test_sticks_below_the_friction_angle_without_creep(self, box_on_slope):
        res = self.run(box_on_slope, 0.3, 0.4)
        assert_compiled(box_on_slope, res)
        assert res.events == []
        assert abs(res["x"][-1]) < 1e-12 and abs(res["x_d"][-1]) < 1e-12

    def test_slides_above_it_with_the_kinetic_acceleration(self, box_on_slope):
        theta, mu = 0.5, 0.4
        res = self.run(box_on_slope, theta, mu)
        assert_compiled(box_on_slope, res)
        a = G * (math.sin(theta) - mu * math.cos(theta))
        assert res["x"][-1] == pytest.approx(a / 2, rel=1e-8)
        assert res["x_d"][-1] == pytest.approx(a, rel=1e-8)
        assert {e.kind for e in res.events} == {"slip"}

    @pytest.mark.parametrize("theta", [0.3, 0.5])
    def test_compiled_and_python_stepping_agree(self, box_on_slope, theta):
        compiled, python = self.run(box_on_slope, theta, 0.4), self.run(box_on_slope, theta, 0.4, integrator="scipy")
        assert [(e.kind, e.contact, e.time) for e in compiled.events] == \
            [(e.kind, e.contact, pytest.approx(e.time, abs=1e-8)) for e in python.events]
        np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-8)
        np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-8)


def free_ball(formulation: str, mu: float = 0.3, r: float = 0.1, mass: float = 1.5):
    m = mb.Model("ball3d", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=mass, inertia=(0.4 * mass * r * r,) * 3))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), friction=mu, radius=r))
    return m.compile(formulation=formulation)


def test_3d_ball_launched_sliding_with_spin():
    """A ball on a Free joint sliding with spin: its slip keeps its direction until it rolls
    at t = 2 |u0| / (7 mu g) (tests/test_friction.py); the compiled run gives the Python
    path's numbers (dae's in tests/test_contacts_free_compiled.py)."""
    mu, r = 0.3, 0.1
    system = free_ball("lagrange", mu, r)
    v0, w0 = np.array([2.0, 0.5, 0.0]), np.array([3.0, -4.0, 7.0])
    q0, qd0 = [0, 0, r, 1, 0, 0, 0], np.concatenate((v0, w0))
    compiled = system.simulate(0.3, q0, qd0, rtol=1e-10, atol=1e-12)
    python = system.simulate(0.3, q0, qd0, rtol=1e-10, atol=1e-12, integrator="scipy")
    assert_compiled(system, compiled)
    u0 = (v0 + np.cross(w0, [0.0, 0.0, -r]))[:2]
    assert [e.kind for e in compiled.events] == ["stick"]
    assert compiled.events[0].time == pytest.approx(2 * np.linalg.norm(u0) / (7 * mu * G), rel=1e-7)
    assert compiled.events[0].time == pytest.approx(python.events[0].time, abs=1e-8)
    np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-8)
    np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-8)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_tangential_rows_in_c_are_the_python_rows(formulation):
    """The C rows (friction.h, from the compiled body kinematics) of a spinning 3D ball's
    contact: its slip velocity's Jacobian and bias as ``plane_contact_rows``."""
    system = free_ball(formulation)
    kernel = system.kernel
    rng = np.random.default_rng(3)
    quat = rng.normal(size=4)
    q = np.concatenate(([0.1, -0.2, 0.1], quat / np.linalg.norm(quat)))
    qd = rng.normal(size=6)
    lib = kernel.compiled.functions.lib
    rows = FrictionRows(kernel, lib, Closed((0,), stick=(0,)), {0: 0}, 1, q, qd)
    try:
        Jt, bias, slip = np.zeros(2 * kernel.nv), np.zeros(2), np.zeros(2)
        fn = lib.mb_friction_rows_at
        fn.argtypes = [np.ctypeslib.ndpointer(dtype=float)] * 3 + [np.ctypeslib.ctypes.c_int] + \
            [np.ctypeslib.ndpointer(dtype=float)] * 4
        fn(q, qd, kernel.p, 0, Jt, bias, slip, np.zeros(6))
    finally:
        rows.close()
    expected = plane_contact_rows(kernel, q, qd, [0])
    np.testing.assert_allclose(Jt.reshape(2, -1), expected.tangent[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(bias, expected.tangent_bias[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(slip, expected.tangent[0] @ qd, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_painleve_in_the_compiled_loop_is_the_python_error(formulation):
    """A rod sliding on one end with mu = 5 turns into Painleve's paradox (its end's
    effective inverse mass with friction, 1 + 3 cos^2 phi - 15 s sin phi cos phi per unit
    mass, falls through zero as phi turns from -0.25 rad): the compiled loop stops with the
    Python path's error, at the same time."""
    m = mb.Model("rod", gravity=(0, 0, -G))
    length = 0.5
    rod = m.add(mb.Body("rod", mass=1.0, inertia=(length * length / 3,) * 3))
    m.add(mb.Planar("plane", m.ground, rod, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("end", rod, (-length, 0, 0), normal=(0, 0, 1), friction=5.0))
    system = m.compile(formulation=formulation)
    phi, w = -0.25, -3.0
    q0, qd0 = [length * math.sin(-phi), 0.0, phi], [-length * math.cos(phi) * w, -3.0, w]
    assert system.integration_path() == "compiled"
    messages = []
    for integrator in ("compiled", "scipy"):
        with pytest.raises(mb.SimulationError, match="Painleve's paradox at t = .*'end'") as error:
            system.simulate(0.1, q0, qd0, integrator=integrator)
        messages.append(str(error.value).split("Painleve")[1])
    assert messages[0] == messages[1]


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_friction_with_the_recursive_dynamics_runs_compiled(formulation):
    """The loops' friction solve factors the dense mass matrix, which a model with contacts
    has with the recursive dynamics too: the sliding ball's closed form, compiled."""
    m = mb.Model("ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.5, inertia=(0.006,) * 3))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), friction=0.3, radius=0.1))
    system = m.compile(formulation, dynamics="recursive")
    res = system.simulate(0.3, [0.1, 0.0, 0.0], [0.0, 2.0, 0.0], rtol=1e-10, atol=1e-12)
    assert_compiled(system, res)
    assert res.events[0].time == pytest.approx(2 * 2.0 / (7 * 0.3 * G), rel=1e-7)
    assert res["x_d"][-1] == pytest.approx(5 * 2.0 / 7, rel=1e-9)


def cart_with_pendulum(formulation: str, mu: float = 0.12):
    """A 2 kg cart on two edge contacts (planar) carrying a 1 kg pendulum of 0.5 m: the swing's
    pull on the cart grows until the cart's friction cannot hold it."""
    m = mb.Model("cart", gravity=(0, 0, -G))
    a, c = 0.2, 0.05
    box = m.add(mb.Body("cart", mass=2.0, inertia=(0.02, 0.03, 0.02)))
    bob = m.add(mb.Body("bob", mass=1.0, inertia=(0.001,) * 3, com=(0, 0, -0.5)))
    m.add(mb.Planar("plane", m.ground, box, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Revolute("hinge", box, bob, axis="y"))
    for s, name in ((1, "front"), (-1, "back")):
        m.add(mb.Contact(name, box, (s * a, 0, -c), normal=(0, 0, 1), friction=mu))
    return m.compile(formulation=formulation)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_stick_slip_events_of_a_cart_with_a_pendulum(formulation, monkeypatch):
    """The cart sticks, slips when its force reaches the cone (located by the C cone margin),
    sticks again when it stops and slips again: every event, and the end state, as scipy's
    stepping finds them."""
    from mbcomp.formulations import compiled_watch, dae_compiled
    system = cart_with_pendulum(formulation)
    located = []
    for cls in (compiled_watch.EventStepFunctions, dae_compiled._Locator):
        for name in ("cone_root", "slip_root"):
            if name in vars(cls):
                def spy(*args, _original=vars(cls)[name], _name=name):
                    located.append(_name)
                    return _original(*args)
                monkeypatch.setattr(cls, name, spy)
    q0, qd0 = [0.05, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 3.0]
    compiled = system.simulate(1.0, q0, qd0, rtol=1e-10, atol=1e-12)
    python = system.simulate(1.0, q0, qd0, rtol=1e-10, atol=1e-12, integrator="scipy")
    assert_compiled(system, compiled)
    kinds = [e.kind for e in compiled.events]
    assert kinds == ["slip", "slip", "stick", "stick", "slip", "slip"]
    assert "cone_root" in located   # (on the compiled loop's event steps, in C; a stop by its slip speed in Python)
    assert [(e.kind, e.contact) for e in compiled.events] == [(e.kind, e.contact) for e in python.events]
    np.testing.assert_allclose([e.time for e in compiled.events], [e.time for e in python.events], atol=1e-8)
    np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-8)
    np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-8)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_the_compiled_friction_rhs_equals_the_python_friction_solve(formulation):
    """The right-hand side with friction in C (``friction.h`` through the formulation's
    ``scipy_stretch``) against the Python workspace's (``friction.friction_solve``), on the
    cart with one edge sticking and one sliding, at perturbed speeds."""
    system = cart_with_pendulum(formulation)
    formulation_, kernel = system._formulation, system.kernel
    q0, qd0 = formulation_.assemble(kernel, np.array([0.05, 0.0, 0.0, 0.4]), np.array([0.0, 0.3, 0.0, 2.0]))
    closed = Closed((0, 1), stick=(0,), slip={1: np.array([1.0, 0.0, 0.0])})
    assert_compiled_rhs_is_the_python_one(system, q0, qd0, closed)


def assert_compiled_rhs_is_the_python_one(system, q0, qd0, closed) -> None:
    """The compiled right-hand side of the stretch with the contacts ``closed`` (friction in C,
    through the formulation's ``scipy_stretch``) equals the Python workspace's (the oracle) to
    1e-9 at three states with randomly perturbed speeds."""
    formulation_, kernel = system._formulation, system.kernel
    lib = kernel.compiled.functions.lib
    stretch = formulation_.scipy_stretch(kernel, lib, 0.0, q0, qd0, None, contacts=closed, offsets={}, method="test")
    try:
        compiled = stretch.workspace
        python = compiled.run.workspace if formulation_.name == "lagrange" else compiled.inner
        rng = np.random.default_rng(7)
        for _ in range(3):
            y = python.y0.copy()
            y[len(y) // 2:] += rng.normal(scale=0.2, size=len(y) - len(y) // 2)
            expected, got = python.rhs(0.01, y), compiled.rhs(0.01, y)
            np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    finally:
        stretch.close()


def test_recursive_dae_with_a_loop_says_why_its_friction_steps_in_python():
    """The dae formulation's hook (``compiled_friction_problem``): with the recursive dynamics
    and a closed loop its KKT solve is the recursive program's, which has no friction rows,
    so the run steps in Python and says why; the dense dynamics runs the same model
    compiled, and both give the same motion."""
    from conftest import fourbar
    m = fourbar()
    m.add(mb.Contact("floor", "coupler", (0.0, 0.0, 0.0), normal=(0, 1, 0), friction=0.4, radius=0.01,
                     restitution=0.0))
    recursive = m.compile("dae", dynamics="recursive")
    dense = m.compile("dae", dynamics="dense")
    path = recursive.integration_path()
    assert path.startswith("scipy") and "recursive" in path and "no friction rows" in path
    assert dense.integration_path() == "compiled"
    q, qd = dense.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
    a = recursive.simulate(0.3, q, qd, rtol=1e-10, atol=1e-12)
    b = dense.simulate(0.3, q, qd, rtol=1e-10, atol=1e-12)
    assert a.stats["integrator"] == "scipy" and b.stats["integrator"] == "compiled"
    np.testing.assert_allclose(a.q[-1], b.q[-1], atol=1e-7)
