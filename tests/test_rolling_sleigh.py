"""NoSlip and RollingBall against closed forms: the Chaplygin sleigh and a ball on a turntable.

Chaplygin sleigh (Chaplygin 1911; Neimark & Fufaev, *Dynamics of Nonholonomic Systems*
(1972) ch. III; Bloch, *Nonholonomic Mechanics and Control* (2003) §1.7): a body on the
horizontal plane whose knife edge at the body origin cannot slide sideways (body y), its
centre of mass at distance ``a`` ahead along body x, mass m, moment I about the centre of
mass, J = I + m a^2.  With u the edge's forward speed and w the yaw rate::

    m u' = m a w^2,    J w' = -m a u w

so the energy E = (m u^2 + J w^2) / 2 is constant and ``u(t) = U tanh(m a U t / J + atanh(u0 / U))``,
``U = sqrt(2 E / m)``: the sleigh ends moving straight ahead at U whichever way it started.
The blade's side force (the NoSlip reaction, along body y) is ``m u w I / J``.

Ball on a turntable (e.g. Weltner, Am. J. Phys. 47 (1979) 984; Ehrlich & Tuszynski, Am. J.
Phys. 63 (1995) 351): a ball of mass m, radius r and moment I about its centre rolls on a
table turning at constant Omega about the vertical through the origin.  No slip gives
``v' = (I / (I + m r^2)) Omega z x v``: the centre's velocity turns at ``2 Omega / 7`` for a
solid ball (I = 2 m r^2 / 5), and the centre runs on the circle
``x(t) - x(0) = -(7 / (2 Omega)) z x (v(t) - v(0))``.
"""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb

MASS, A_COM, I_COM = 2.0, 0.3, 0.05
J = I_COM + MASS * A_COM**2


def sleigh_model() -> mb.Model:
    m = mb.Model("sleigh", gravity=(0, 0, -9.81))
    sled = m.add(mb.Body("sled", mass=MASS, com=(A_COM, 0, 0), inertia=(0.02, 0.04, I_COM)))
    m.add(mb.Planar("p", m.ground, sled, normal="z"))
    m.add(mb.NoSlip("blade", sled, point=(0, 0, 0), direction="y"))
    return m


@pytest.mark.parametrize("formulation", ["dae", "lagrange"])
def test_chaplygin_sleigh_speed_law(formulation):
    """u(t) = U tanh(m a U t / J + atanh(u0/U)) and w^2 = (2E - m u^2)/J; side force m u w I/J."""
    system = sleigh_model().compile(formulation=formulation)
    assert system.ndof == 2
    u0, w0, T = 0.2, 1.5, 3.0
    heading = 0.4
    q0 = [0.1, -0.2, heading]
    qd0 = [u0 * np.cos(heading), u0 * np.sin(heading), w0]
    q, qd = system.assemble(q0, qd0)
    np.testing.assert_allclose(qd, qd0, atol=1e-12)  # already consistent: nothing moves
    t = np.linspace(0, T, 31)
    res = system.simulate(T, q, qd, t_eval=t, rtol=1e-10, atol=1e-12)
    angle = res.q[:, 2]
    u = res.qd[:, 0] * np.cos(angle) + res.qd[:, 1] * np.sin(angle)
    side = -res.qd[:, 0] * np.sin(angle) + res.qd[:, 1] * np.cos(angle)
    w = res.qd[:, 2]
    energy = 0.5 * MASS * u0**2 + 0.5 * J * w0**2
    U = np.sqrt(2 * energy / MASS)
    np.testing.assert_allclose(side, 0, atol=1e-9)
    tau = MASS * A_COM * U * t / J + np.arctanh(u0 / U)
    np.testing.assert_allclose(u, U * np.tanh(tau), atol=1e-8)
    np.testing.assert_allclose(w, U * np.sqrt(MASS / J) / np.cosh(tau), atol=1e-8)  # w^2 = (2E - m u^2) / J
    np.testing.assert_allclose(res.energy().total, energy, rtol=1e-9)
    np.testing.assert_allclose(res.reactions["blade"][:, 0], MASS * u * w * I_COM / J, atol=1e-7)
    assert system.integration_path() == "compiled" and res.stats["integrator"] == "compiled"


def turntable_model(omega: float) -> mb.Model:
    m = mb.Model("turntable", gravity=(0, 0, -9.81))
    table = m.add(mb.Body("table", mass=5.0, inertia=(1.0, 1.0, 2.0)))
    ball = m.add(mb.Body("ball", mass=0.5, inertia=(0.4 * 0.5 * 0.05**2,) * 3))
    m.add(mb.Revolute("turn", m.ground, table, axis="z", coords="phi"))
    m.add(mb.Motor("drive", "turn", speed=omega))
    m.add(mb.Free("fb", m.ground, ball))
    m.add(mb.RollingBall("rb", ball, radius=0.05, plane=table, origin=(0, 0, 0.02)))
    return m


@pytest.mark.parametrize("formulation", ["dae", "lagrange"])
def test_ball_on_turntable(formulation):
    """The ball's centre velocity turns at 2 Omega / 7 and the centre runs on its circle; the
    contact force on the ball is m (a + g z) (world frame); the ball stays on the table."""
    omega, r, mass = 3.0, 0.05, 0.5
    system = turntable_model(omega).compile(formulation=formulation)
    assert system.ndof == 3  # 7 speeds less the motor and the ball's three rows: two rolling, one spinning
    T = 2.0
    guess_q = [0, 0.2, -0.1, 0.07, 1, 0, 0, 0]
    guess_qd = [omega, 0.3, 0.1, 0, 0, 0, 0]
    q, qd = system.assemble(guess_q, guess_qd)
    t = np.linspace(0, T, 11)
    res = system.simulate(T, q, qd, t_eval=t, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res["phi"], omega * t, atol=1e-8)
    k = 2 * omega / 7
    v0 = res.qd[0, 1:3]
    rot = np.array([[np.cos(k * t), -np.sin(k * t)], [np.sin(k * t), np.cos(k * t)]]).transpose(2, 0, 1)
    v = np.einsum("mij,j->mi", rot, v0)
    np.testing.assert_allclose(res.qd[:, 1:3], v, atol=1e-7)
    dv = v - v0
    np.testing.assert_allclose(res.q[:, 1:3] - res.q[0, 1:3], -(1 / k) * np.column_stack((-dv[:, 1], dv[:, 0])),
                               atol=1e-7)
    np.testing.assert_allclose(res.q[:, 3], 0.02 + r, atol=1e-9)  # the centre's height: table top + r
    acc = k * np.column_stack((-v[:, 1], v[:, 0]))
    np.testing.assert_allclose(res.reactions["rb"], mass * np.column_stack((acc, np.full(len(t), 9.81))), atol=1e-6)
    assert system.integration_path() == "compiled" and res.stats["integrator"] == "compiled"


def test_sleigh_hitting_a_wall_keeps_its_blade():
    """A contact (the sled's nose against a wall, restitution 0.8) with the NoSlip row: the
    impact respects the blade (no side slip before or after), both formulations give the same
    motion in the compiled loop, and a driving torque on the heading (a drive input) is applied."""
    runs = {}
    for formulation in ("dae", "lagrange"):
        m = mb.Model("sleigh_wall")
        sled = m.add(mb.Body("sled", mass=MASS, com=(A_COM, 0, 0), inertia=(I_COM,) * 3))
        m.add(mb.Planar("p", m.ground, sled, normal="z", coords=("x", "y", "heading")))
        m.add(mb.NoSlip("blade", sled, point=(0, 0, 0), direction="y"))
        m.add(mb.Contact("nose", sled, point=(0.5, 0, 0), normal=(-1, 0, 0), origin=(1.0, 0, 0), restitution=0.8))
        m.add(mb.JointTorque("steer", "p", value=[0.0, 0.0, 0.1]))
        system = m.compile(formulation=formulation)
        assert system.integration_path() == "compiled"
        res = system.simulate(3.0, [0, 0, 0], [0.5, 0, 0], t_eval=np.linspace(0, 3, 31), rtol=1e-10, atol=1e-12)
        assert len(res.events) == 1 and 0.5 < res.events[0].time < 1.5
        heading = res["heading"]
        np.testing.assert_allclose(-res.qd[:, 0] * np.sin(heading) + res.qd[:, 1] * np.cos(heading), 0, atol=1e-9)
        runs[formulation] = res
    np.testing.assert_allclose(runs["dae"].q, runs["lagrange"].q, atol=1e-7)
