"""Sliding contacts whose slip turns as it stops, alone and in a cluster of four.

A body launched sideways on an incline (``tan(theta) < mu``) slides on a curve: gravity's
down-slope pull ``a = g sin(theta)`` turns its velocity while friction
``f = mu g cos(theta)`` slows it, and it stops with its velocity turned towards the
down-slope direction.  Its slip therefore never crosses zero along the direction it had at
the start of a step; the stop must be found where the slip speed vanishes (the failure this
guards against: solo12 dropped with its feed-forward on, whose front feet slid to a stop on
a turning slip, chattered at a slip of ~1e-9 m/s and collapsed the step size).

Closed form (``phi`` the angle between the velocity and the down-slope direction,
``k = f / a = mu / tan(theta) > 1``): ``dv/dt = a cos(phi) - f`` and ``v dphi/dt = -a
sin(phi)`` give ``v = v0 tan(phi/2)^k / sin(phi)`` from ``phi0 = pi/2``, and with
``u = tan(phi/2)``:

- stop time ``t = (v0 / a) int_0^1 u^(k-2) (1 + u^2) / 2 du = v0 k / (a (k^2 - 1))``;
- sideways travel ``int v sin(phi) dt = v0^2 2 k / (a (4 k^2 - 1))``;
- down-slope travel ``int v cos(phi) dt = v0^2 / (4 a (k^2 - 1))``.
"""
import math

import numpy as np
import pytest

import mbcomp as mb

G = 9.81
THETA, MU, V0 = 0.3, 0.6, 1.0
K = MU / math.tan(THETA)
A = G * math.sin(THETA)
T_STOP = V0 * K / (A * (K * K - 1))
SIDEWAYS = V0 ** 2 * 2 * K / (A * (4 * K * K - 1))
DOWN = V0 ** 2 / (4 * A * (K * K - 1))
NORMAL = np.array([-math.sin(THETA), 0.0, math.cos(THETA)])
DOWNHILL = np.array([-math.cos(THETA), 0.0, -math.sin(THETA)])


def on_incline(formulation: str, corners: bool) -> mb.System:
    """A 2 kg body on a ``Free`` joint on the incline through the origin: one contact at its
    centre of mass (``corners=False``, so friction has no moment) or four at the corners of
    its 0.2 x 0.2 m base, 2 cm below the centre of mass (a redundant cluster)."""
    m = mb.Model("incline", gravity=(0, 0, -G))
    body = m.add(mb.Body("block", mass=2.0, inertia=(0.01, 0.01, 0.01)))
    m.add(mb.Free("free", m.ground, body))
    if corners:
        tilt = np.array([[math.cos(THETA), 0.0, -math.sin(THETA)], [0.0, 1.0, 0.0],
                         [math.sin(THETA), 0.0, math.cos(THETA)]])      # body axes along the incline
        for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
            point = tilt @ np.array([0.1 * sx, 0.1 * sy, -0.02])
            m.add(mb.Contact(f"corner{i}", body, tuple(point), normal=tuple(NORMAL), friction=MU))
    else:
        m.add(mb.Contact("incline", body, (0, 0, 0), normal=tuple(NORMAL), friction=MU))
    return m.compile(formulation=formulation)


def launch(system: mb.System, corners: bool, t_end: float):
    """Launched sideways (along +y) at ``V0``, touching the incline at rest otherwise."""
    q0 = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    if corners:
        q0[:3] = 0.02 * NORMAL            # the corners on the incline
    return system.simulate(t_end, q0, [0.0, V0, 0.0, 0.0, 0.0, 0.0], rtol=1e-10, atol=1e-12,
                           t_eval=[0.0, T_STOP / 2, t_end]), q0


@pytest.mark.parametrize("formulation", ("lagrange", "dae"))
def test_a_turning_slip_stops_at_the_closed_form_time(formulation):
    system = on_incline(formulation, corners=False)
    res, q0 = launch(system, False, 1.5 * T_STOP)
    assert [e.kind for e in res.events] == ["stick"]
    assert res.events[0].time == pytest.approx(T_STOP, rel=1e-7)
    travel = res.q[-1, :3] - q0[:3]
    np.testing.assert_allclose(travel, SIDEWAYS * np.array([0, 1, 0]) + DOWN * DOWNHILL, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.qd[-1], 0.0, atol=1e-9)          # stuck: tan(theta) < mu holds it
    # Half-way it still slides, its friction mu N opposite its velocity.
    force = res.contact_forces["incline"][1]
    v = res.qd[1, :3]
    normal = force @ NORMAL
    assert normal == pytest.approx(2.0 * G * math.cos(THETA), rel=1e-9)
    np.testing.assert_allclose(force - normal * NORMAL, -MU * normal * v / np.linalg.norm(v), atol=1e-9)


def test_a_cluster_of_four_corners_stops_together():
    """The box slides without turning (the least-norm normal forces shift the pressure centre
    along the slip, so friction has no moment about the normal), so it moves as the point
    above: all four corners stop at the closed-form time, stick, and carry its weight."""
    system = on_incline("lagrange", corners=True)
    res, q0 = launch(system, True, 1.5 * T_STOP)
    assert sorted(e.kind for e in res.events) == ["stick"] * 4
    assert [e.time for e in res.events] == [pytest.approx(T_STOP, rel=1e-7)] * 4
    travel = res.q[-1, :3] - q0[:3]
    np.testing.assert_allclose(travel, SIDEWAYS * np.array([0, 1, 0]) + DOWN * DOWNHILL, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.q[-1, 3:], [1.0, 0.0, 0.0, 0.0], atol=1e-9)     # it did not turn
    np.testing.assert_allclose(res.qd[-1], 0.0, atol=1e-9)
    total = sum(res.contact_forces[f"corner{i}"][-1] for i in range(4))
    np.testing.assert_allclose(total, [0.0, 0.0, 2.0 * G], atol=1e-8)
