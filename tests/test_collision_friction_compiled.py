"""Coulomb friction on collision features in the compiled loops (``c/friction.h`` with the
features of ``codegen/c/collide.c``): the C tangential rows and right-hand side equal the
Python friction solve (``CollisionKernel.tangent_rows``, ``friction.friction_solve``), and
colliding shapes with friction run compiled in both formulations with the closed forms and
the numbers of Python stepping (``integrator="scipy"``)."""
import math

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.formulations.friction import Closed, plane_contact_rows
from mbcomp.formulations.friction_c import FrictionRows
from test_friction_compiled import assert_compiled_rhs_is_the_python_one

G = 9.81
FORMULATIONS = ("lagrange", "dae")
TOL = dict(rtol=1e-10, atol=1e-12)


def ball_inertia(mass: float, r: float) -> tuple:
    return (0.4 * mass * r * r,) * 3


def ball_on_box(formulation: str, mu: float = 0.3, r: float = 0.1, mass: float = 1.5):
    """A ball (Sphere shape) in the x-z plane on a long ground Box whose top face is z = 0."""
    m = mb.Model("ball_on_box", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=mass, inertia=ball_inertia(mass, r), shape=mb.Sphere(r)))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=["z", "x", "phi"]))
    m.add(mb.Collision("floor", ball, (m.ground, mb.Box((20.0, 2.0, 0.2), origin=(0, 0, -0.1))), friction=mu))
    return m.compile(formulation=formulation)


def rotation_y(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def box_on_incline(formulation: str, theta: float, mu: float = 0.4):
    """A 0.4 x 0.3 x 0.2 m box (Box shape, planar in x-z) resting flat on a ground Box tilted
    by ``theta`` about y (its top face through the origin, falling along +x): the start
    state ``(q0, qd0)`` rests on its four lower corners."""
    m = mb.Model("box_on_incline", gravity=(0, 0, -G))
    box = m.add(mb.Body("box", mass=2.0, inertia=(0.02, 0.03, 0.04), shape=mb.Box((0.4, 0.3, 0.2))))
    m.add(mb.Planar("plane", m.ground, box, normal="y", coords=["z", "x", "phi"]))
    R = rotation_y(theta)
    normal = R[:, 2]
    m.add(mb.Collision("slope", box, (m.ground, mb.Box((8.0, 2.0, 0.4), origin=-0.2 * normal, rotation=R)),
                       friction=mu))
    centre = 0.1 * normal
    return m.compile(formulation=formulation), [centre[2], centre[0], theta], [0.0, 0.0, 0.0]


def ball_on_ball(formulation: str, mu: float = 0.5):
    """A ball (Free joint) resting slightly off the top of a ground-fixed ball: it rolls
    off, sliding once the friction cannot hold it (a normal that turns as it goes)."""
    m = mb.Model("ball_on_ball", gravity=(0, 0, -G))
    r = 0.1
    ball = m.add(mb.Body("ball", mass=1.0, inertia=ball_inertia(1.0, r), shape=mb.Sphere(r)))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Collision("touch", ball, (m.ground, mb.Sphere(r, origin=(0, 0, -r))), friction=mu))
    return m.compile(formulation=formulation)


def assert_compiled(system, res) -> None:
    assert system.integration_path() == "compiled"
    assert res.stats["integrator"] == "compiled" and res.stats["path"] == "compiled"


# -- the C rows and right-hand side against Python ---------------------------------------------------
def c_rows(kernel, rows: FrictionRows, j: int, q, qd):
    lib = rows.lib
    Jt, bias, slip, basis = np.zeros(2 * kernel.nv), np.zeros(2), np.zeros(2), np.zeros(6)
    fn = lib.mb_friction_rows_at
    fn.argtypes = [np.ctypeslib.ndpointer(dtype=float)] * 3 + [np.ctypeslib.ctypes.c_int] + \
        [np.ctypeslib.ndpointer(dtype=float)] * 4
    fn(np.ascontiguousarray(q, dtype=float), np.ascontiguousarray(qd, dtype=float), kernel.p, j, Jt, bias, slip,
       basis)
    return Jt.reshape(2, -1), bias, slip, basis.reshape(2, 3)


def features_at(kernel, q, qd, within: float = np.inf):
    """The collision features with a measured (nonzero) normal row at (q, qd) and a gap below
    ``within`` (m)."""
    values = kernel.contacts(q, qd)
    return [i for i in range(kernel.n_own, len(kernel.topology.contacts))
            if np.any(values.J[[i]]) and values.g[i] < within]


@pytest.mark.parametrize("case", ["ball_on_box", "box_on_incline", "ball_on_ball", "box_on_box_spinning",
                                  "capsule_on_box_and_plane"])
def test_c_tangential_rows_are_the_python_rows_at_random_states(case):
    """Sphere-box faces, box-box corners, sphere-sphere (a turning normal), box-box edges and
    corners of a tumbling box, capsule ends on a box and a plane: C's rows, biases, slip
    velocities and bases (as Python keeps them) are ``CollisionKernel.tangent_rows``'s at
    random states."""
    rng = np.random.default_rng(11)
    if case == "ball_on_box":
        system = ball_on_box("lagrange")
        states = [([0.1 - 0.01 * rng.random(), rng.normal(), rng.normal()], rng.normal(size=3)) for _ in range(3)]
    elif case == "box_on_incline":
        system, q0, _ = box_on_incline("lagrange", 0.3)
        states = [(np.array(q0) + 0.002 * rng.normal(size=3), rng.normal(size=3)) for _ in range(3)]
    elif case == "ball_on_ball":
        system = ball_on_ball("lagrange")
        states = []
        for _ in range(3):
            d = rng.normal(size=3)
            d[2] = abs(d[2]) + 1.0
            quat = rng.normal(size=4)
            states.append((np.concatenate((-0.1 * np.array([0, 0, 1]) + 0.199 * d / np.linalg.norm(d),
                                           quat / np.linalg.norm(quat))), rng.normal(size=6)))
    elif case == "capsule_on_box_and_plane":
        m = mb.Model("capsule", gravity=(0, 0, -G))
        rod = m.add(mb.Body("rod", mass=1.0, inertia=(0.01, 0.01, 0.002), shape=mb.Capsule(0.03, 0.3, axis="x")))
        m.add(mb.Free("free", m.ground, rod))
        m.add(mb.Collision("box", rod, (m.ground, mb.Box((0.2, 1.0, 0.2), origin=(0.15, 0, -0.1))), friction=0.4))
        m.add(mb.Collision("floor", rod, (m.ground, mb.Plane(origin=(0, 0, -0.01))), friction=0.6))
        system = m.compile(formulation="lagrange")
        states = []
        for _ in range(3):
            quat = np.array([1.0, 0.0, 0.0, 0.0]) + 0.1 * rng.normal(size=4)
            states.append((np.concatenate(([0.02 * rng.normal(), 0.02 * rng.normal(), 0.03],
                                           quat / np.linalg.norm(quat))), rng.normal(size=6)))
    else:
        m = mb.Model("tumbling", gravity=(0, 0, -G))
        box = m.add(mb.Body("box", mass=1.0, inertia=(0.01, 0.02, 0.03), shape=mb.Box((0.3, 0.2, 0.1))))
        m.add(mb.Free("free", m.ground, box))
        m.add(mb.Collision("hit", box, (m.ground, mb.Box((1.0, 1.0, 0.2), origin=(0, 0, -0.1))), friction=0.4))
        system = m.compile(formulation="lagrange")
        states = []
        for _ in range(3):
            quat = rng.normal(size=4)
            states.append((np.concatenate(([0.05 * rng.normal(), 0.05 * rng.normal(), 0.12],
                                           quat / np.linalg.norm(quat))), rng.normal(size=6)))
    kernel = system.kernel
    lib = kernel.compiled.functions.lib
    checked = 0
    for q, qd in states:
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        moded = features_at(kernel, q, qd)
        assert moded, "no feature measured at the state"
        closed = Closed(moded, stick=moded)
        with kernel.compiled_stretch(lib, q, qd, moded):
            rows = FrictionRows(kernel, lib, closed, {i: r for r, i in enumerate(moded)}, len(moded), q, qd)
            try:
                expected = plane_contact_rows(kernel, q, qd, moded, normal_rows=False)
                for j in range(len(moded)):
                    Jt, bias, slip, basis = c_rows(kernel, rows, j, q, qd)
                    scale = max(1.0, float(np.abs(expected.tangent_bias[j]).max()))
                    np.testing.assert_allclose(Jt, expected.tangent[j], rtol=1e-12, atol=1e-13)
                    np.testing.assert_allclose(bias, expected.tangent_bias[j], rtol=1e-11, atol=1e-12 * scale)
                    np.testing.assert_allclose(slip, expected.tangent[j] @ qd, rtol=1e-11, atol=1e-12)
                    np.testing.assert_allclose(basis, expected.basis[j, 1:], rtol=1e-12, atol=1e-14)
                    checked += 1
            finally:
                rows.close()
    assert checked >= 3


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_the_compiled_rhs_equals_the_python_friction_solve(formulation):
    """The right-hand side with friction on box-box corners in C (``friction.h`` through the
    formulation's ``scipy_stretch``: two corners sticking, two sliding) against the Python
    workspace's (``friction.friction_solve``), at perturbed speeds."""
    system, q, qd = box_on_incline(formulation, 0.3)
    formulation_, kernel = system._formulation, system.kernel
    q0, qd0 = formulation_.assemble(kernel, np.array(q), np.array([0.0, 0.2, 0.0]))
    corners = features_at(kernel, np.asarray(q, dtype=float), np.asarray(qd, dtype=float), 1e-9)
    assert len(corners) == 4
    closed = Closed(corners, stick=corners[:2], slip={i: np.array([-1.0, 0.0, 0.0]) for i in corners[2:]})
    assert_compiled_rhs_is_the_python_one(system, q0, qd0, closed)


# -- closed forms, compiled, and compiled against Python stepping ---------------------------------------
@pytest.fixture(scope="module", params=FORMULATIONS)
def rolling(request):
    return ball_on_box(request.param)


class TestBallSlidingOnABox:
    """Launched sliding at v0 without spin on a Box shape: rolling starts at t = 2 v0 / (7 mu g)
    with speed 5 v0 / 7."""

    V0, MU, R = 2.0, 0.3, 0.1

    def run(self, system, **options):
        return system.simulate(0.3, [self.R, 0.0, 0.0], [0.0, self.V0, 0.0], **TOL, **options)

    def test_rolls_at_the_closed_form_time_in_compiled_code(self, rolling):
        res = self.run(rolling)
        assert_compiled(rolling, res)
        assert [e.kind for e in res.events] == ["stick"]
        assert res.events[0].time == pytest.approx(2 * self.V0 / (7 * self.MU * G), rel=1e-7)
        assert res["x_d"][-1] == pytest.approx(5 * self.V0 / 7, rel=1e-9)
        assert res["phi_d"][-1] == pytest.approx(5 * self.V0 / 7 / self.R, rel=1e-9)

    def test_compiled_and_python_stepping_agree(self, rolling):
        compiled, python = self.run(rolling), self.run(rolling, integrator="scipy", method="DOP853")
        assert python.stats["integrator"] != "compiled"
        assert [(e.kind, e.contact) for e in compiled.events] == [(e.kind, e.contact) for e in python.events]
        np.testing.assert_allclose([e.time for e in compiled.events], [e.time for e in python.events], atol=1e-8)
        np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-8)
        np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-8)


@pytest.mark.parametrize("formulation", FORMULATIONS)
class TestBoxOnAnInclinedBox:
    """A box resting flat on a tilted Box shape (four corner features): it stays put iff
    tan(theta) <= mu, else slides with a = g (sin theta - mu cos theta) along the slope."""

    MU = 0.4

    def run(self, formulation, theta, **options):
        system, q0, qd0 = box_on_incline(formulation, theta, self.MU)
        return system, q0, system.simulate(0.5, q0, qd0, **TOL, **options)

    def test_sticks_below_the_friction_angle_without_creep(self, formulation):
        system, q0, res = self.run(formulation, 0.3)
        assert_compiled(system, res)
        assert res.events == []
        assert np.abs(res.q[-1] - q0).max() < 1e-12 and np.abs(res.qd[-1]).max() < 1e-12

    def test_slides_above_it_with_the_kinetic_acceleration(self, formulation):
        theta = 0.5
        system, q0, res = self.run(formulation, theta)
        assert_compiled(system, res)
        a = G * (math.sin(theta) - self.MU * math.cos(theta))
        along = (res.q[-1][1] - q0[1]) * math.cos(theta) - (res.q[-1][0] - q0[0]) * math.sin(theta)
        assert along == pytest.approx(a * 0.5 ** 2 / 2, rel=1e-8)
        assert res["x_d"][-1] == pytest.approx(a * 0.5 * math.cos(theta), rel=1e-8)
        assert abs(res.q[-1][2] - theta) < 1e-9

    @pytest.mark.parametrize("theta", [0.3, 0.5])
    def test_compiled_and_python_stepping_agree(self, formulation, theta):
        _, _, compiled = self.run(formulation, theta)
        _, _, python = self.run(formulation, theta, integrator="scipy", method="DOP853")
        assert [(e.kind, e.contact) for e in compiled.events] == [(e.kind, e.contact) for e in python.events]
        np.testing.assert_allclose([e.time for e in compiled.events], [e.time for e in python.events], atol=1e-8)
        np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-8)
        np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-8)


def test_a_ball_rolling_off_a_ball_runs_compiled_as_python_steps_it():
    """A ball on a Free joint starting just off the top of a fixed ball (a sphere-sphere
    feature whose normal turns): rolling, then sliding when the cone is left; compiled
    (lagrange) with the events and end state of Python stepping.  (Set sliding from the
    slip a sticking phase leaves, ~1e-12 m/s pointing anywhere, it is watched along its own
    direction: ``tolerances.SLIP_FLOOR``.)"""
    system = ball_on_ball("lagrange")
    q0 = np.concatenate((-0.1 * np.array([0, 0, 1]) + 0.2 * np.array([math.sin(0.05), 0, math.cos(0.05)]),
                         [1.0, 0.0, 0.0, 0.0]))
    compiled = system.simulate(0.6, q0, np.zeros(6), **TOL)
    python = system.simulate(0.6, q0, np.zeros(6), **TOL, integrator="scipy", method="DOP853")
    assert_compiled(system, compiled)
    assert [(e.kind, e.contact) for e in compiled.events] == [(e.kind, e.contact) for e in python.events]
    assert "slip" in [e.kind for e in compiled.events]
    np.testing.assert_allclose([e.time for e in compiled.events], [e.time for e in python.events], atol=1e-8)
    np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-7)


def test_collisions_with_friction_run_compiled_in_both_formulations():
    for formulation in FORMULATIONS:
        assert ball_on_box(formulation).integration_path() == "compiled"


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_ball_launched_over_a_hill_stops_sliding_rolls_slips_and_leaves(formulation):
    """A ball (planar) launched sliding at 1 m/s without spin over the top of a fixed ball of
    radius 1 m (a sphere-sphere feature whose normal turns as it goes, mu = 0.4): its slip
    stops (located on the turned normal), it rolls, slips when the cone cannot hold it, and
    leaves the surface; compiled, with the events and end state of Python stepping."""
    m = mb.Model("hill", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.0, inertia=ball_inertia(1.0, 0.1), shape=mb.Sphere(0.1)))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=["z", "x", "phi"]))
    m.add(mb.Collision("hill", ball, (m.ground, mb.Sphere(1.0, origin=(0, 0, -1.0))), friction=0.4))
    system = m.compile(formulation=formulation)
    compiled = system.simulate(0.9, [0.1, 0.0, 0.0], [0.0, 1.0, 0.0], **TOL)
    python = system.simulate(0.9, [0.1, 0.0, 0.0], [0.0, 1.0, 0.0], **TOL, integrator="scipy", method="DOP853")
    assert_compiled(system, compiled)
    assert [e.kind for e in compiled.events] == ["stick", "slip", "release"]
    assert [(e.kind, e.contact) for e in compiled.events] == [(e.kind, e.contact) for e in python.events]
    np.testing.assert_allclose([e.time for e in compiled.events], [e.time for e in python.events], atol=1e-8)
    np.testing.assert_allclose(compiled.q[-1], python.q[-1], atol=1e-7)
    np.testing.assert_allclose(compiled.qd[-1], python.qd[-1], atol=1e-7)
