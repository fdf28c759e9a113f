"""Contacts on quaternion joints (Free, Ball) in the dae formulation's compiled loop
(formulations/dae_compiled.py ``DaeRun`` on the state ``[q (nq), v (nv)]``, c/dae.c's watch
and locators): closed forms, conserved energy, and the motion of lagrange's compiled run and
of scipy's stepping."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb

G = 9.81
R = 0.1


def assert_compiled(system, res) -> None:
    assert system.integration_path() == "compiled"
    assert res.stats["path"] == "compiled"


def free_ball(formulation: str, e: float = 0.8):
    """A sphere of radius R on a Free joint over the floor z = 0 (a point contact with radius)."""
    m = mb.Model("free_ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.0, inertia=(0.4 * R * R,) * 3))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), restitution=e, radius=R))
    return m.compile(formulation=formulation)


@pytest.fixture(scope="module")
def dae_ball():
    return free_ball("dae")


Q0 = [0.3, -0.2, 1.0, 1.0, 0.0, 0.0, 0.0]
QD0 = [0.5, 0.1, 0.0, 1.0, 2.0, -0.5]   # drifting and spinning: the quaternion moves
OPTIONS = dict(rtol=1e-10, atol=1e-12)


def test_free_ball_bounces_to_e_squared_apexes_in_compiled_code(dae_ball):
    e, drop = 0.8, 1.0 - R
    res = dae_ball.simulate(2.0, Q0, QD0, **OPTIONS)
    assert_compiled(dae_ball, res)
    assert [ev.kind for ev in res.events] == ["impact"] * 3
    assert res.events[0].time == pytest.approx(np.sqrt(2 * drop / G), rel=1e-9)
    for n, event in enumerate(res.events, start=1):
        k = np.flatnonzero(res.t == event.time)[-1]           # the state just after the impact
        apex = res["free_z"][k] + res.qd[k][2] ** 2 / (2 * G) - R
        assert apex == pytest.approx(e ** (2 * n) * drop, rel=1e-8)
    np.testing.assert_allclose(np.linalg.norm(res.q[:, 3:7], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(res.qd[-1][3:], QD0[3:], atol=1e-9)   # frictionless: the spin is untouched


def test_free_ball_moves_as_lagrange_and_scipy_stepping(dae_ball):
    compiled = dae_ball.simulate(2.0, Q0, QD0, **OPTIONS)
    scipy = dae_ball.simulate(2.0, Q0, QD0, integrator="scipy", **OPTIONS)
    assert scipy.stats["path"].startswith("scipy")
    lagrange_system = free_ball("lagrange")
    lagrange = lagrange_system.simulate(2.0, Q0, QD0, **OPTIONS)
    assert_compiled(lagrange_system, lagrange)
    for other in (scipy, lagrange):
        assert [ev.time for ev in compiled.events] == pytest.approx([ev.time for ev in other.events], abs=1e-9)
        np.testing.assert_allclose(compiled.q[-1], other.q[-1], atol=1e-8)
        np.testing.assert_allclose(compiled.qd[-1], other.qd[-1], atol=1e-8)


def test_free_ball_launched_sliding_with_spin_rolls_at_the_closed_form_time():
    """Friction on a Free joint in dae's compiled loop: a ball sliding with spin rolls at
    t = 2 |u0| / (7 mu g) (tests/test_friction.py), as scipy's stepping finds."""
    mu, mass = 0.3, 1.5
    m = mb.Model("rough_ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=mass, inertia=(0.4 * mass * R * R,) * 3))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), friction=mu, radius=R))
    system = m.compile(formulation="dae")
    v0, w0 = np.array([2.0, 0.5, 0.0]), np.array([3.0, -4.0, 7.0])
    q0, qd0 = [0, 0, R, 1, 0, 0, 0], np.concatenate((v0, w0))
    res = system.simulate(0.3, q0, qd0, **OPTIONS)
    assert_compiled(system, res)
    u0 = (v0 + np.cross(w0, [0.0, 0.0, -R]))[:2]
    assert [ev.kind for ev in res.events] == ["stick"]
    assert res.events[0].time == pytest.approx(2 * np.linalg.norm(u0) / (7 * mu * G), rel=1e-7)
    scipy = system.simulate(0.3, q0, qd0, integrator="scipy", **OPTIONS)
    np.testing.assert_allclose(res.q[-1], scipy.q[-1], atol=1e-8)
    np.testing.assert_allclose(res.qd[-1], scipy.qd[-1], atol=1e-8)


def _spheres():
    """Three spheres on Free joints in zero gravity, elastic collisions between them."""
    m = mb.Model("spheres", gravity=(0, 0, 0))
    balls = []
    for i in range(3):
        ball = m.add(mb.Body(f"s{i}", mass=1.0 + 0.5 * i, inertia=(0.4 * (1.0 + 0.5 * i) * R * R,) * 3,
                             shape=mb.Sphere(R)))
        m.add(mb.Free(f"j{i}", m.ground, ball))
        balls.append(ball)
    m.add(mb.Collision("hits", balls, balls, restitution=1.0))
    return m.compile(formulation="dae")


def test_free_spheres_collide_elastically_in_compiled_code():
    """Momentum and kinetic energy after the collisions (e = 1, no friction) are the start's;
    every sphere keeps its spin, and scipy's stepping meets the same events."""
    system = _spheres()
    masses = np.array([1.0, 1.5, 2.0])
    unit = [1.0, 0.0, 0.0, 0.0]
    q0 = np.concatenate([[-0.5, 0.03, 0.0], unit, [0.0, 0.0, 0.0], unit, [0.45, -0.04, 0.02], unit])
    v = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [-0.8, 0.0, 0.0]])
    w = np.array([[0.0, 3.0, 1.0], [2.0, 0.0, 0.0], [0.0, 0.0, -4.0]])
    qd0 = np.concatenate([np.concatenate((v[i], w[i])) for i in range(3)])
    res = system.simulate(1.0, q0, qd0, **OPTIONS)
    assert_compiled(system, res)
    assert len(res.events) >= 2
    qd = res.qd[-1].reshape(3, 6)
    np.testing.assert_allclose(masses @ qd[:, :3], masses @ v, atol=1e-10)
    energy = lambda vs: 0.5 * masses @ (vs ** 2).sum(axis=1)   # noqa: E731  (the spins do not change)
    assert energy(qd[:, :3]) == pytest.approx(energy(v), rel=1e-9)
    np.testing.assert_allclose(qd[:, 3:], w, atol=1e-9)
    scipy = system.simulate(1.0, q0, qd0, integrator="scipy", **OPTIONS)
    assert [ev.time for ev in res.events] == pytest.approx([ev.time for ev in scipy.events], abs=1e-9)
    np.testing.assert_allclose(res.q[-1], scipy.q[-1], atol=1e-8)


def test_ball_joint_pendulum_hits_a_wall_in_compiled_code():
    """A rod on a Ball joint swinging (and twisting) into the wall x = 0.3 with e = 1: every
    impact keeps the energy; the motion is scipy stepping's and lagrange's."""
    length = 1.0

    def pendulum(formulation):
        m = mb.Model("ball_pendulum", gravity=(0, 0, -G))
        rod = m.add(mb.Body("rod", mass=2.0, com=(0, 0, -length), inertia=(0.05, 0.05, 0.01)))
        m.add(mb.Ball("pivot", m.ground, rod))
        m.add(mb.Contact("wall", rod, (0, 0, -length), origin=(0.3, 0, 0), normal=(-1, 0, 0), restitution=1.0))
        return m.compile(formulation=formulation)

    system = pendulum("dae")
    angle = 0.4                                    # tilted about y: the tip at x = -0.39, swinging to the wall
    q0 = [np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0]
    qd0 = [0.3, 0.0, 3.0]
    res = system.simulate(3.5, q0, qd0, **OPTIONS)
    assert_compiled(system, res)
    assert len(res.events) >= 2 and {ev.kind for ev in res.events} == {"impact"}
    energy = res.energy().total
    assert np.ptp(energy) < 1e-7 * abs(energy[0])
    qw, qx, qy, qz = res.q.T
    tip_x = -2 * length * (qx * qz + qw * qy)       # R(q) (0, 0, -length), its x
    assert tip_x.max() < 0.3 + 1e-9 and tip_x.max() > 0.3 - 1e-6
    scipy = system.simulate(3.5, q0, qd0, integrator="scipy", **OPTIONS)
    lagrange = pendulum("lagrange").simulate(3.5, q0, qd0, **OPTIONS)
    for other in (scipy, lagrange):
        assert [ev.time for ev in res.events] == pytest.approx([ev.time for ev in other.events], abs=1e-9)
        np.testing.assert_allclose(res.q[-1], other.q[-1], atol=1e-8)
        np.testing.assert_allclose(res.qd[-1], other.qd[-1], atol=1e-8)


# -- drive elements with contacts: their states ride in the compiled stretches -----------------
RATIO, K_T, RES, IND, VOLT = 20.0, 0.03, 2.0, 0.05, 6.0


def motor_pendulum(formulation: str, backend: str = "auto", e: float = 1.0):
    """A rod (COM 0.5 m below a hinge about x) turned by a DC motor into the wall y = 0.3
    (its tip, 1 m below the hinge, hits it at th = asin 0.3)."""
    m = mb.Model("motor_wall", gravity=(0, 0, -G))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0, -0.5), inertia=(0.01, 0.01, 0.0)))
    hinge = m.add(mb.Revolute("hinge", m.ground, rod, axis="x", coords="th"))
    m.add(mb.DCMotor("motor", hinge, ratio=RATIO, resistance=RES, inductance=IND, k=K_T, voltage=VOLT))
    m.add(mb.Contact("wall", rod, (0, 0, -1.0), origin=(0, 0.3, 0), normal=(0, -1, 0), restitution=e))
    return m.compile(formulation=formulation, backend=backend)


@pytest.mark.parametrize("formulation", ["dae", "lagrange"])
def test_motor_driven_pendulum_hits_a_wall_in_compiled_code(formulation):
    """The motor's current is a state of the compiled stretches and carries over the impacts:
    the run equals Python stepping (the model without C), the impacts happen where the tip
    meets the wall, and the motor's work is the mechanical energy gained (e = 1)."""
    system = motor_pendulum(formulation)
    t_eval = np.linspace(0.0, 1.5, 30001)
    res = system.simulate(1.5, [0.0], [0.0], t_eval=t_eval, **OPTIONS)
    assert_compiled(system, res)
    assert len(res.events) >= 2 and {ev.kind for ev in res.events} == {"impact"}
    python = motor_pendulum(formulation, backend="python").simulate(1.5, [0.0], [0.0], t_eval=t_eval, **OPTIONS)
    assert python.stats["path"].startswith("scipy")
    assert [ev.time for ev in res.events] == pytest.approx([ev.time for ev in python.events], abs=1e-9)
    np.testing.assert_allclose(res.q, python.q, atol=1e-8)
    np.testing.assert_allclose(res.qd, python.qd, atol=1e-8)
    np.testing.assert_allclose(res["motor.current"], python["motor.current"], atol=1e-8)
    scipy = system.simulate(1.5, [0.0], [0.0], t_eval=t_eval, integrator="scipy", **OPTIONS)   # (the compiled rhs)
    assert scipy.stats["rhs"] == "compiled"
    np.testing.assert_allclose(scipy.q, python.q, atol=1e-8)
    np.testing.assert_allclose(scipy["motor.current"], python["motor.current"], atol=1e-8)
    for event in res.events:   # the tip at the wall: -sin(th) = -0.3 ... th = asin 0.3
        k = np.argmin(np.abs(res.t - event.time))
        assert np.sin(res["th"][k]) == pytest.approx(0.3, abs=1e-3)
    # the motor's work from its electrical side (the current is continuous at impacts, the
    # speed is not): V i - R i^2 - d(L i^2 / 2)/dt = k ratio i th_d
    energy, i = res.energy().total, res["motor.current"]
    work = np.trapezoid(VOLT * i - RES * i ** 2, res.t) - IND * (i[-1] ** 2 - i[0] ** 2) / 2
    assert energy[-1] - energy[0] == pytest.approx(work, rel=1e-6)
