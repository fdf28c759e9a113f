"""Impacts and events: Newton's impact law on unilateral contacts, checked against analytic
solutions (bouncing ball, pendulum against a wall) and against the impact equations
themselves, evaluated independently here (contact Jacobians by finite differences of
``body_state`` positions, momenta summed body by body)::

    M (qd+ - qd-) = J^T P,   J_i qd+ = -e J_i qd-  (P_i > 0),   P >= 0

together with every other constraint (closed loops, sliders, motors) and the simulation's
event location, persistent contacts and energy bookkeeping.
"""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest
from scipy.special import ellipk

import mbcomp as mb
from conftest import time_limit

G = 9.81
FORMULATIONS = ("lagrange", "dae")


# ----------------------------------------------------------------------------------------------
# Independent helpers
# ----------------------------------------------------------------------------------------------
def contact_jacobian(system, body, point, normal, q, h=1e-6) -> np.ndarray:
    """d(normal . p)/dq of a body point, by central differences of ``body_state`` positions."""
    q = np.asarray(q, dtype=float)
    row = np.zeros(q.size)
    for k in range(q.size):
        dq = np.zeros(q.size)
        dq[k] = h
        plus = system.body_state(body, q + dq, point=point).position
        minus = system.body_state(body, q - dq, point=point).position
        row[k] = np.dot(normal, (plus - minus) / (2 * h))
    return row


def normal_speed(system, body, point, normal, q, qd) -> float:
    return float(np.dot(normal, system.body_state(body, q, qd, point=point).velocity))


def kinetic(system, q, qd) -> float:
    return system.energy(q, qd).kinetic


def angular_momentum_z(system, bodies, q, qd, about=(0.0, 0.0, 0.0)) -> float:
    """z angular momentum about a point of planar bodies turning about z:
    sum of m (c - o) x v_c + I_zz w_z; ``bodies`` is ``{name: (mass, I_zz)}``."""
    total = 0.0
    for name, (mass, izz) in bodies.items():
        s = system.body_state(name, q, qd)
        r = s.position - np.asarray(about)
        total += mass * (r[0] * s.velocity[1] - r[1] * s.velocity[0]) + izz * s.angular_velocity[2]
    return total


def event_states(result, event):
    """(q, qd before, qd after) at an event: the Result holds both samples at its time."""
    i = np.flatnonzero(result.t == event.time)
    assert len(i) >= 1, f"no sample at the event time {event.time}"
    return result.q[i[0]], result.qd[i[0]], result.qd[i[-1]]


# ----------------------------------------------------------------------------------------------
# Models (compiled once per structure; the compiled code is shared through the cache)
# ----------------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=None)
def ball(formulation="lagrange", e=0.5, mass=1.0):
    """A point mass on a vertical slide above the floor z = 0."""
    m = mb.Model("ball", gravity=(0, 0, -G))
    b = m.add(mb.Body("ball", mass=mass))
    m.add(mb.Prismatic("z", m.ground, b, axis="z", coords="z"))
    m.add(mb.Contact("floor", b, normal=(0, 0, 1), restitution=e))
    return m.compile(formulation=formulation)


ROD_L, ROD_M = 0.8, 2.0
ROD_I = ROD_M * ROD_L ** 2 / 3  # about the hinge


@functools.lru_cache(maxsize=None)
def rod_against_wall(formulation="lagrange", e=0.6):
    """A uniform rod hanging from a hinge about y; its tip (0, 0, -L) hits the wall x = 0
    from the side x < 0 (gap = L sin q for the angle q)."""
    m = mb.Model("rod_wall", gravity=(0, 0, -G))
    rod = m.add(mb.Body("rod", mass=ROD_M, com=(0, 0, -ROD_L / 2),
                        inertia=(ROD_M * ROD_L ** 2 / 12, ROD_M * ROD_L ** 2 / 12, 0)))
    m.add(mb.Revolute("hinge", m.ground, rod, axis="y", coords="q"))
    m.add(mb.Contact("wall", rod, point=(0, 0, -ROD_L), normal=(-1, 0, 0), restitution=e))
    return m.compile(formulation=formulation)


DP_Q = np.array([-0.3, 0.5])
DP_BODIES = {"bar1": (1.0, 1 / 12), "bar2": (1.0, 1 / 12)}


def dp_points(q):
    """Elbow and tip of the double pendulum below, in the world frame."""
    p1 = np.array([np.cos(q[0]), np.sin(q[0]), 0.0])
    return p1, p1 + [np.cos(q[0] + q[1]), np.sin(q[0] + q[1]), 0.0]


@functools.lru_cache(maxsize=None)
def double_pendulum(n_elbow, n_tip, e, formulation="lagrange"):
    """Planar double pendulum in x-y (two uniform 1 m bars, as in conftest) with contacts at
    the elbow and at the tip, both touching (gap 0) at ``DP_Q``."""
    m = mb.Model("dpend_contacts", gravity=(0, -G, 0))
    b1 = m.add(mb.Body("bar1", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    b2 = m.add(mb.Body("bar2", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    elbow, tip = dp_points(DP_Q)
    m.add(mb.Contact("elbow", b1, point=(1, 0, 0), normal=n_elbow, origin=tuple(elbow), restitution=e))
    m.add(mb.Contact("tip", b2, point=(1, 0, 0), normal=n_tip, origin=tuple(tip), restitution=e))
    return m.compile(formulation=formulation)


def dp_contacts(n_elbow, n_tip):
    return {"elbow": ("bar1", (1, 0, 0), np.asarray(n_elbow, float)),
            "tip": ("bar2", (1, 0, 0), np.asarray(n_tip, float))}


def check_impact_equations(system, contacts, q, qd, impact, e, *, atol=1e-7):
    """The impact equations, evaluated independently: returns (J, P, v-, v+)."""
    names = list(contacts)
    J = np.array([contact_jacobian(system, *contacts[n], q) for n in names])
    P = np.array([impact.impulses.get(n, 0.0) for n in names])
    M = system.mass_matrix(q)
    np.testing.assert_allclose(M @ (impact.qd - qd), J.T @ P, atol=atol, err_msg="M (qd+ - qd-) != J^T P")
    v_before, v_after = J @ qd, J @ impact.qd
    assert np.all(P >= -1e-12), f"an impulse pulls: {dict(zip(names, P))}"
    for n, p, vb, va in zip(names, P, v_before, v_after):
        if p > 1e-12:
            # Newton's law on approaching contacts; a closed contact that was separating and is
            # driven in by the impact joins plastically (it may not bounce into the surface).
            expected = -e * min(vb, 0.0)
            assert va == pytest.approx(expected, abs=atol), f"{n}: normal speed after {va} != {expected}"
        assert va >= -atol, f"{n} penetrates after the impact (normal speed {va})"
    return J, P, v_before, v_after


# ----------------------------------------------------------------------------------------------
# Bouncing ball: analytic bounce series, rest, persistence
# ----------------------------------------------------------------------------------------------
H0, E_BALL = 1.0, 0.5
T0 = math.sqrt(2 * H0 / G)
V0 = G * T0


def bounce_times(n, e=E_BALL):
    """t_1 = t0, t_(k+1) = t_k + 2 e^k t0."""
    return T0 + 2 * T0 * np.array([sum(e ** j for j in range(1, k + 1)) for k in range(n)])


@functools.lru_cache(maxsize=None)
def ball_run(formulation, rest_speed=1e-4):
    return ball(formulation).simulate(2.0, [H0], [0.0], rtol=1e-10, atol=1e-12, rest_speed=rest_speed)


@pytest.mark.parametrize("formulation", FORMULATIONS)
class TestBouncingBall:
    def test_event_times_follow_the_geometric_series(self, formulation):
        events = ball_run(formulation).events
        assert all(ev.contact == "floor" for ev in events)
        times = np.array([ev.time for ev in events])
        assert np.all(np.diff(times) > 0)
        np.testing.assert_allclose(times[:12], bounce_times(12), atol=1e-9)

    def test_apex_heights_from_the_post_impact_speed(self, formulation):
        res = ball_run(formulation)
        for k, ev in enumerate(res.events[:10], start=1):
            q, qd_before, qd_after = event_states(res, ev)
            assert q[0] == pytest.approx(0.0, abs=1e-10)
            assert qd_before[0] == pytest.approx(-E_BALL ** (k - 1) * V0, rel=1e-8)
            apex = qd_after[0] ** 2 / (2 * G)
            assert apex == pytest.approx(E_BALL ** (2 * k) * H0, rel=1e-8)
            # The impulse gives the same speed: v+ = P / m - v-.
            assert ev.impulse / 1.0 - (-qd_before[0]) == pytest.approx(qd_after[0], rel=1e-10)
            assert ev.impulse == pytest.approx((1 + E_BALL) * E_BALL ** (k - 1) * V0, rel=1e-8)

    def test_apex_heights_from_dense_samples(self, formulation):
        t = np.linspace(0.0, 1.3, 13001)
        res = ball(formulation).simulate(1.3, [H0], [0.0], rtol=1e-10, atol=1e-12, t_eval=t)
        np.testing.assert_array_equal(res.t, t)
        hits = bounce_times(4)
        for k in range(1, 4):
            window = (res.t > hits[k - 1]) & (res.t < hits[k])
            assert np.max(res["z"][window]) == pytest.approx(E_BALL ** (2 * k) * H0, abs=1e-7)
        assert np.min(res["z"]) >= -1e-10

    @pytest.mark.parametrize("rest_speed", [1e-4, 1e-2])
    def test_comes_to_rest_at_the_sum_of_the_series(self, formulation, rest_speed):
        res = ball_run(formulation, rest_speed)
        t_rest = T0 * (1 + E_BALL) / (1 - E_BALL)
        # It stops bouncing at the first impact whose rebound is slower than rest_speed ...
        n = math.ceil(math.log(rest_speed / V0) / math.log(E_BALL))
        assert len(res.events) == n
        # ... missing at most the flights of the rebounds left out of the series.
        last = res.events[-1].time
        assert last <= t_rest
        assert t_rest - last <= 2 * rest_speed / (G * (1 - E_BALL)) + 1e-9

    def test_stays_on_the_floor_as_a_persistent_contact(self, formulation):
        res = ball_run(formulation)
        assert res.persistent_contacts == ["floor"]
        resting = res.t > res.events[-1].time
        assert np.count_nonzero(resting) >= 1 and res.t[-1] == 2.0
        np.testing.assert_allclose(res["z"][resting], 0.0, atol=1e-12)
        np.testing.assert_allclose(res["dz"][resting], 0.0, atol=1e-12)
        assert ball(formulation).gaps(res.q[-1])["floor"] == pytest.approx(0.0, abs=1e-12)

    def test_persistent_contact_carries_the_weight(self, formulation):
        res = ball_run(formulation)
        resting = res.t > res.events[-1].time
        reaction = np.asarray(res.reactions["floor"]).reshape(len(res.t), -1)[resting, 0]
        np.testing.assert_allclose(reaction, 1.0 * G, rtol=1e-9)

    def test_the_resting_event_books_the_momentum_and_energy_applied(self, formulation):
        res = ball_run(formulation)
        q, qd_before, qd_after = event_states(res, res.events[-1])
        assert qd_after[0] == 0.0
        assert res.events[-1].impulse == pytest.approx(1.0 * (qd_after[0] - qd_before[0]), rel=1e-9)
        assert res.events[-1].energy_loss == pytest.approx(
            kinetic(ball(formulation), q, qd_before) - kinetic(ball(formulation), q, qd_after), rel=1e-9)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_closing_contact_at_the_start_is_an_impact_at_t0(formulation):
    res = ball(formulation).simulate(0.3, [0.0], [-2.0], rtol=1e-10, atol=1e-12)
    first = res.events[0]
    assert first.time == 0.0 and first.contact == "floor"
    assert first.impulse == pytest.approx((1 + E_BALL) * 2.0, rel=1e-12)
    assert res.qd[0, 0] == pytest.approx(E_BALL * 2.0, rel=1e-12)
    # Back on the floor after the flight 2 v+ / g.
    assert res.events[1].time == pytest.approx(2 * E_BALL * 2.0 / G, abs=1e-9)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_starting_at_rest_on_the_floor(formulation):
    with time_limit(2.0):
        res = ball(formulation, 0.0).simulate(0.5, [0.0], [0.0])
    np.testing.assert_allclose(res["z"], 0.0, atol=1e-12)
    assert res.persistent_contacts == ["floor"]


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_plastic_landing_becomes_persistent(formulation):
    res = ball(formulation, 0.0).simulate(0.5, [0.05], [0.0], rtol=1e-10, atol=1e-12)
    assert len(res.events) == 1
    t_land = math.sqrt(2 * 0.05 / G)
    assert res.events[0].time == pytest.approx(t_land, abs=1e-10)
    assert res.events[0].impulse == pytest.approx(G * t_land, rel=1e-9)
    assert res.persistent_contacts == ["floor"]
    after = res.t > t_land
    np.testing.assert_allclose(res["z"][after], 0.0, atol=1e-12)


LIFT_T = 0.25


def lift_force(t, q, qd):
    """Upward force growing as m g t / LIFT_T: the floor's reaction m g (1 - t / LIFT_T)
    would pull after t = LIFT_T."""
    return np.array([G * t / LIFT_T])


def lifted_height(t):
    """z(t) for the ramp force above: at rest until LIFT_T, then z'' = g (t - LIFT_T) / LIFT_T."""
    return np.where(t > LIFT_T, G / LIFT_T * (t - LIFT_T) ** 3 / 6, 0.0)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_persistent_contact_is_released_when_its_reaction_would_pull(formulation):
    t = np.linspace(0.0, 0.5, 21)
    res = ball(formulation, 0.0).simulate(0.5, [0.05], [0.0], rtol=1e-10, atol=1e-12, tau=lift_force, t_eval=t)
    assert [e.kind for e in res.events] == ["impact", "release"] and res.persistent_contacts == []
    assert res.events[1].time == pytest.approx(LIFT_T, abs=1e-9)  # the floor's reaction m g (1 - t / LIFT_T) ends
    after = t >= 0.15  # landed at 0.101 s
    np.testing.assert_allclose(res["z"][after], lifted_height(t[after]), atol=1e-6)


def test_persistent_contact_release_with_short_steps():
    """With steps of at most 2 ms the release (checked between steps) comes at most 2 ms late."""
    t = np.linspace(0.0, 0.5, 21)
    res = ball("dae", 0.0).simulate(0.5, [0.05], [0.0], rtol=1e-10, atol=1e-12, tau=lift_force, t_eval=t,
                                    max_step=2e-3)
    assert [e.kind for e in res.events] == ["impact", "release"] and res.persistent_contacts == []
    # z error of a release delayed by d: about (g / LIFT_T) d (t - LIFT_T)^2 / 2 <= 2.5e-3 m.
    after = t >= 0.15
    np.testing.assert_allclose(res["z"][after], lifted_height(t[after]), atol=3e-3)
    assert res["z"][-1] > 0.09


# ----------------------------------------------------------------------------------------------
# Pendulum against a wall
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("e", [0.0, 0.6, 1.0])
def test_rod_reverses_with_tip_speed_ratio_e(formulation, e):
    system = rod_against_wall(formulation, e)
    q, qd = np.zeros(1), np.array([-2.0])
    assert system.gaps(q)["wall"] == pytest.approx(0.0, abs=1e-15)
    impact = system.impact(q, qd)
    assert list(impact.impulses) == ["wall"]
    v_before = normal_speed(system, "rod", (0, 0, -ROD_L), (-1, 0, 0), q, qd)
    v_after = normal_speed(system, "rod", (0, 0, -ROD_L), (-1, 0, 0), q, impact.qd)
    assert v_before == pytest.approx(-2.0 * ROD_L, rel=1e-12)
    assert v_after == pytest.approx(-e * v_before, abs=1e-12)
    # Angular impulse about the hinge: I (w+ - w-) = L P.
    assert ROD_I * (impact.qd[0] - qd[0]) == pytest.approx(ROD_L * impact.impulses["wall"], rel=1e-12)
    ke = 0.5 * ROD_I * qd[0] ** 2
    assert impact.energy_loss == pytest.approx((1 - e ** 2) * ke, rel=1e-12, abs=1e-14)
    assert impact.energy_loss == pytest.approx(kinetic(system, q, qd) - kinetic(system, q, impact.qd),
                                               rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_rod_released_against_the_wall(formulation):
    """Released from q0, it hits after a quarter of the compound pendulum's large-amplitude
    period, loses (1 - e^2) of its kinetic energy, and rebounds to cos q1 = 1 - e^2 (1 - cos q0)."""
    e, q0 = 0.6, 0.5
    system = rod_against_wall(formulation, e)
    omega = math.sqrt(ROD_M * G * ROD_L / 2 / ROD_I)
    t_hit = ellipk(math.sin(q0 / 2) ** 2) / omega
    t = np.linspace(0.0, 1.5 * t_hit, 1501)
    res = system.simulate(t[-1], [q0], [0.0], rtol=1e-10, atol=1e-12)
    assert len(res.events) == 1
    ev = res.events[0]
    assert ev.contact == "wall"
    assert ev.time == pytest.approx(t_hit, abs=1e-8)
    q, qd_before, qd_after = event_states(res, ev)
    assert q[0] == pytest.approx(0.0, abs=1e-10)
    ke_before = ROD_M * G * ROD_L / 2 * (1 - math.cos(q0))
    assert kinetic(system, q, qd_before) == pytest.approx(ke_before, rel=1e-8)
    assert qd_after[0] / qd_before[0] == pytest.approx(-e, rel=1e-10)
    assert ev.energy_loss == pytest.approx((1 - e ** 2) * ke_before, rel=1e-8)
    assert ev.energy_loss == pytest.approx(kinetic(system, q, qd_before) - kinetic(system, q, qd_after), rel=1e-12)
    # Rebound amplitude.
    dense = system.simulate(2.2 * t_hit, [q0], [0.0], rtol=1e-10, atol=1e-12,
                            t_eval=np.linspace(0, 2.2 * t_hit, 4001))
    q1 = math.acos(1 - e ** 2 * (1 - math.cos(q0)))
    assert np.max(dense["q"][dense.t > t_hit]) == pytest.approx(q1, abs=1e-6)
    assert np.min(dense["q"]) >= -1e-10


# ----------------------------------------------------------------------------------------------
# Energy bookkeeping over a run
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_event_energy_loss_is_the_kinetic_energy_drop(formulation):
    system = ball(formulation)
    res = ball_run(formulation)
    for ev in res.events[:-1]:  # the last one brings it to rest (its own test below)
        q, qd_before, qd_after = event_states(res, ev)
        drop = kinetic(system, q, qd_before) - kinetic(system, q, qd_after)
        assert ev.energy_loss == pytest.approx(drop, rel=1e-9, abs=1e-15)
        assert ev.energy_loss == pytest.approx((1 - E_BALL ** 2) * 0.5 * qd_before[0] ** 2, rel=1e-9, abs=1e-15)
    # Between events the total energy is conserved; each event removes exactly its loss.
    total = res.energy().total
    losses = sum(ev.energy_loss for ev in res.events[:-1])
    before_last = res.t < res.events[-1].time
    assert total[before_last][-1] == pytest.approx(total[0] - losses, abs=1e-8)


# ----------------------------------------------------------------------------------------------
# Simultaneous impacts at two points of a double pendulum
# ----------------------------------------------------------------------------------------------
BOTH_UP = ((0, 1, 0), (0, 1, 0))        # elbow and tip above floors through their points
UP_AND_WALL = ((0, 1, 0), (1, 0, 0))    # elbow above a floor, tip to the right of a wall


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_simultaneous_impacts_satisfy_the_impact_equations(formulation, e):
    system = double_pendulum(*BOTH_UP, e, formulation)
    contacts = dp_contacts(*BOTH_UP)
    q, qd = DP_Q, np.array([-0.6, -0.4])
    assert all(abs(g) < 1e-12 for g in system.gaps(q).values())
    impact = system.impact(q, qd, contacts=["elbow", "tip"])
    J, P, v_before, v_after = check_impact_equations(system, contacts, q, qd, impact, e)
    assert np.all(v_before < 0), "both contacts close"
    assert sorted(impact.impulses) == ["elbow", "tip"] and np.all(P > 0)
    np.testing.assert_allclose(v_after, -e * v_before, atol=1e-7)
    # The default (every closed and closing contact) is the same impact.
    default = system.impact(q, qd)
    np.testing.assert_allclose(default.qd, impact.qd, atol=1e-14)
    # Kinetic energy: conserved for e = 1, and the reported loss is the drop.
    drop = kinetic(system, q, qd) - kinetic(system, q, impact.qd)
    assert impact.energy_loss == pytest.approx(drop, rel=1e-10, abs=1e-14)
    if e == 1.0:
        assert abs(drop) < 1e-12
    else:
        assert drop > 0
    # Angular momentum about the pivot changes by the moments of the contact impulses
    # (the pivot's impulse has no moment about it).
    elbow, tip = dp_points(q)
    moment = sum(p * np.cross(point, n)[2] for p, point, n in
                 zip(P, (elbow, tip), (contacts["elbow"][2], contacts["tip"][2])))
    dH = angular_momentum_z(system, DP_BODIES, q, impact.qd) - angular_momentum_z(system, DP_BODIES, q, qd)
    assert dH == pytest.approx(moment, abs=1e-10)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_restitution_argument_overrides_the_contacts(formulation):
    system = double_pendulum(*BOTH_UP, 0.5, formulation)
    q, qd = DP_Q, np.array([-0.6, -0.4])
    for e in (0.0, 1.0):
        override = system.impact(q, qd, restitution=e)
        own = double_pendulum(*BOTH_UP, e, formulation).impact(q, qd)
        np.testing.assert_allclose(override.qd, own.qd, atol=1e-12)
    with pytest.raises(mb.ModelError, match="restitution"):
        system.impact(q, qd, restitution=1.5)
    with pytest.raises(mb.ModelError, match="restitution"):
        system.impact(q, qd, restitution=-0.1)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_contact_whose_impulse_would_pull_is_released(formulation):
    e = 0.5
    system = double_pendulum(*UP_AND_WALL, e, formulation)
    contacts = dp_contacts(*UP_AND_WALL)
    q, qd = DP_Q, np.array([-1.25, -0.3])
    # Both closing; holding both closed needs a pulling impulse on the tip.
    J = np.array([contact_jacobian(system, *contacts[n], q) for n in contacts])
    v_before = J @ qd
    assert np.all(v_before < 0)
    M = system.mass_matrix(q)
    both = np.linalg.solve(J @ np.linalg.solve(M, J.T), -(1 + e) * v_before)
    assert both[0] > 0 > both[1]
    impact = system.impact(q, qd, contacts=["elbow", "tip"])
    _, P, _, v_after = check_impact_equations(system, contacts, q, qd, impact, e)
    assert P[1] == 0.0 and impact.impulses.get("tip", 0.0) == 0.0
    assert P[0] > 0
    assert v_after[1] >= 0.0, "the released contact separates"
    # Which is the impact on the elbow alone.
    alone = system.impact(q, qd, contacts=["elbow"])
    np.testing.assert_allclose(alone.qd, impact.qd, atol=1e-12)
    assert alone.impulses["elbow"] == pytest.approx(impact.impulses["elbow"], rel=1e-12)


@pytest.mark.parametrize("qd", [
    pytest.param((-0.03, 0.06), id="joins-slightly"),
    pytest.param((-0.64, 1.54), id="joins-strongly"),
])
def test_closed_contact_driven_in_by_the_impact_does_not_penetrate(qd):
    e = 0.5
    system = double_pendulum(*BOTH_UP, e)
    contacts = dp_contacts(*BOTH_UP)
    q, qd = DP_Q, np.asarray(qd)
    J = np.array([contact_jacobian(system, *contacts[n], q) for n in contacts])
    assert J[0] @ qd < 0 < J[1] @ qd  # elbow closing, tip (closed) separating
    impact = system.impact(q, qd)
    check_impact_equations(system, contacts, q, qd, impact, e)


# ----------------------------------------------------------------------------------------------
# A free planar body hitting with two points at once
# ----------------------------------------------------------------------------------------------
PLATE_Q = np.array([0.1, 0.2, 0.4])
PLATE_POINTS = {"A": (0.3, -0.1, 0.0), "B": (-0.2, -0.15, 0.0)}
PLATE_NORMALS = {"A": (-1.0, 0.0, 0.0), "B": (0.0, 1.0, 0.0)}
PLATE_MASSES = {"cx": 0.3, "cy": 0.3, "plate": 2.0}


@functools.lru_cache(maxsize=None)
def plate(e, formulation="lagrange"):
    """A plate moving freely in the x-y plane (slides x, y on two carriages, then a turn about z);
    corner A touches a wall on its right, corner B a floor below it, at ``PLATE_Q``."""
    m = mb.Model("plate", gravity=(0, -G, 0))
    cx = m.add(mb.Body("cx", mass=PLATE_MASSES["cx"]))
    cy = m.add(mb.Body("cy", mass=PLATE_MASSES["cy"]))
    pl = m.add(mb.Body("plate", mass=PLATE_MASSES["plate"], inertia=(0.01, 0.02, 0.03)))
    m.add(mb.Prismatic("x", m.ground, cx, axis="x"), mb.Prismatic("y", cx, cy, axis="y"),
          mb.Revolute("th", cy, pl, axis="z"))
    c, s = math.cos(PLATE_Q[2]), math.sin(PLATE_Q[2])
    for name, (px, py, _) in PLATE_POINTS.items():
        origin = (PLATE_Q[0] + c * px - s * py, PLATE_Q[1] + s * px + c * py, 0.0)
        m.add(mb.Contact(name, pl, point=PLATE_POINTS[name], normal=PLATE_NORMALS[name], origin=origin,
                         restitution=e))
    return m.compile(formulation=formulation)


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("e", [0.0, 0.5, 1.0])
def test_free_body_two_point_impact_momentum(formulation, e):
    system = plate(e, formulation)
    contacts = {n: ("plate", PLATE_POINTS[n], np.array(PLATE_NORMALS[n])) for n in PLATE_POINTS}
    q, qd = PLATE_Q, np.array([0.7, -1.2, -0.7])
    assert all(abs(g) < 1e-12 for g in system.gaps(q).values())
    impact = system.impact(q, qd)
    _, P, v_before, v_after = check_impact_equations(system, contacts, q, qd, impact, e)
    assert np.all(v_before < 0) and np.all(P > 0)
    # Linear momentum (all bodies) changes by the sum of the contact impulses.
    def momentum(qdot):
        return sum(mass * system.body_state(name, q, qdot).velocity for name, mass in PLATE_MASSES.items())
    impulse = sum(p * np.array(PLATE_NORMALS[n]) for n, p in zip(PLATE_POINTS, P))
    np.testing.assert_allclose((momentum(impact.qd) - momentum(qd))[:2], impulse[:2], atol=1e-10)
    # The plate's spin about its COM changes by the impulses' moments about the COM.
    com = system.body_state("plate", q).position
    moment = sum(p * np.cross(system.body_state("plate", q, point=PLATE_POINTS[n]).position - com,
                              PLATE_NORMALS[n])[2] for n, p in zip(PLATE_POINTS, P))
    spin = system.body_state("plate", q, impact.qd).angular_velocity[2] - system.body_state("plate", q, qd).angular_velocity[2]
    assert 0.03 * spin == pytest.approx(moment, abs=1e-10)
    if e == 1.0:
        assert impact.energy_loss == pytest.approx(0.0, abs=1e-12)


# ----------------------------------------------------------------------------------------------
# Impacts with other constraints: a closed loop, a motor, a slider
# ----------------------------------------------------------------------------------------------
FB = dict(a=0.1, b=0.35, c=0.3, d=0.4, rho=2.0)
FB_Q0 = np.array([np.pi / 2, -1.0226484275561756, 1.9151556505110299])  # library/four_bar.toml


def four_bar(formulation, e=0.5, stop_x=None):
    """The library crank-rocker four-bar (revolute C closes the loop) with a stop: the
    coupler's midpoint may not go left of the line x = stop_x."""
    a, b, c, d, rho = FB["a"], FB["b"], FB["c"], FB["d"], FB["rho"]
    m = mb.Model("four_bar_stop", gravity=(0, -G, 0))
    crank = m.add(mb.Body("crank", mass=rho * a, com=(a / 2, 0, 0), inertia=(1e-6, rho * a ** 3 / 12, rho * a ** 3 / 12)))
    coupler = m.add(mb.Body("coupler", mass=rho * b, com=(b / 2, 0, 0), inertia=(1e-6, rho * b ** 3 / 12, rho * b ** 3 / 12)))
    rocker = m.add(mb.Body("rocker", mass=rho * c, com=(c / 2, 0, 0), inertia=(1e-6, rho * c ** 3 / 12, rho * c ** 3 / 12)))
    m.add(mb.Revolute("A", m.ground, crank, axis="z", coords="theta1"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(a, 0, 0), coords="theta2"))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(d, 0, 0), coords="theta4"))
    m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(b, 0, 0), child_point=(c, 0, 0)))
    m.add(mb.Contact("stop", coupler, point=(b / 2, 0, 0), normal=(1, 0, 0), origin=(stop_x, 0, 0), restitution=e))
    return m.compile(formulation=formulation)


def loop_velocity(system, q, qd):
    """Relative velocity of the two points the loop-closing joint C joins."""
    return (system.body_state("coupler", q, qd, point=(FB["b"], 0, 0)).velocity
            - system.body_state("rocker", q, qd, point=(FB["c"], 0, 0)).velocity)


@functools.lru_cache(maxsize=None)
def four_bar_run(formulation):
    system = four_bar(formulation, 0.5, stop_x=0.14)
    q, qd = system.assemble(FB_Q0, [3.0, 0.0, 0.0])
    return system, q, qd, system.simulate(0.25, q, qd, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_impact_inside_a_closed_loop_respects_the_loop(formulation):
    e = 0.5
    probe = four_bar(formulation, e, stop_x=0.0)
    q, qd = probe.assemble(FB_Q0, [3.0, 0.0, 0.0])
    mid = probe.body_state("coupler", q, qd, point=(FB["b"] / 2, 0, 0))
    assert mid.velocity[0] < 0, "the coupler's midpoint moves left, into the stop"
    system = four_bar(formulation, e, stop_x=mid.position[0])  # touching at q
    assert system.gaps(q)["stop"] == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(loop_velocity(system, q, qd), 0.0, atol=1e-12)
    impact = system.impact(q, qd)
    assert impact.impulses["stop"] > 0
    np.testing.assert_allclose(loop_velocity(system, q, impact.qd), 0.0, atol=1e-12)
    v_after = normal_speed(system, "coupler", (FB["b"] / 2, 0, 0), (1, 0, 0), q, impact.qd)
    assert v_after == pytest.approx(-e * mid.velocity[0], rel=1e-10)
    assert impact.energy_loss == pytest.approx(kinetic(system, q, qd) - kinetic(system, q, impact.qd), rel=1e-10)
    # One degree of freedom: the speeds all scale by -e.
    np.testing.assert_allclose(impact.qd, -e * qd, rtol=1e-10)


def test_four_bar_with_a_stop_agrees_between_formulations():
    runs = {f: four_bar_run(f) for f in FORMULATIONS}
    for formulation, (system, q0, qd0, res) in runs.items():
        assert res.events, f"{formulation}: the coupler never reached the stop"
        assert np.max(res.constraint_violation()) < 1e-8
        for ev in res.events:
            q, qd_before, qd_after = event_states(res, ev)
            assert system.gaps(q)["stop"] == pytest.approx(0.0, abs=1e-9)
            np.testing.assert_allclose(loop_velocity(system, q, qd_after), 0.0, atol=1e-9)
            v_before = normal_speed(system, "coupler", (FB["b"] / 2, 0, 0), (1, 0, 0), q, qd_before)
            v_after = normal_speed(system, "coupler", (FB["b"] / 2, 0, 0), (1, 0, 0), q, qd_after)
            assert v_before < 0 and v_after == pytest.approx(-0.5 * v_before, rel=1e-8)
    (_, _, _, lag), (_, _, _, dae) = runs["lagrange"], runs["dae"]
    assert len(lag.events) == len(dae.events)
    for a, b in zip(lag.events, dae.events):
        assert a.time == pytest.approx(b.time, abs=1e-8)
        assert a.impulse == pytest.approx(b.impulse, rel=1e-6)
        np.testing.assert_allclose(event_states(lag, a)[2], event_states(dae, b)[2], rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_impact_keeps_a_speed_motor_turning(formulation):
    """A motor holds its joint's speed through the impact (its impulse does work, so the
    'loss' may be negative); the tip rebounds with -e times its normal speed."""
    e, q = 0.5, np.array([-np.pi / 2 + 0.2, -0.5])
    _, tip = dp_points(q)
    m = mb.Model("dpend_motor_contact", gravity=(0, -G, 0))
    b1 = m.add(mb.Body("bar1", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    b2 = m.add(mb.Body("bar2", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    m.add(mb.Motor("motor", "j1", speed=0.7))
    m.add(mb.Contact("tip", b2, point=(1, 0, 0), normal=(1, 0, 0), origin=tuple(tip), restitution=e))
    system = m.compile(formulation=formulation)
    qd = np.array([0.7, -2.0])
    impact = system.impact(q, qd)
    assert impact.qd[0] == pytest.approx(0.7, abs=1e-12)
    v_before = normal_speed(system, "bar2", (1, 0, 0), (1, 0, 0), q, qd)
    v_after = normal_speed(system, "bar2", (1, 0, 0), (1, 0, 0), q, impact.qd)
    assert v_before < 0 and v_after == pytest.approx(-e * v_before, rel=1e-10)
    # Only j2 is free: its momentum balance is M[1] (qd+ - qd-) = J[1] P.
    J = contact_jacobian(system, "bar2", (1, 0, 0), (1, 0, 0), q)
    M = system.mass_matrix(q)
    assert M[1] @ (impact.qd - qd) == pytest.approx(J[1] * impact.impulses["tip"], abs=1e-8)
    assert impact.energy_loss == pytest.approx(kinetic(system, q, qd) - kinetic(system, q, impact.qd), rel=1e-10)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_impact_keeps_a_slider_on_its_line(formulation):
    """Double pendulum whose tip slides on the x axis; the elbow hits a floor below it."""
    e, q = 0.5, np.array([-0.6, 1.2])  # tip on y = 0: sin(q1) + sin(q1 + q2) = 0
    elbow, _ = dp_points(q)
    m = mb.Model("dpend_slider_contact", gravity=(0, -G, 0))
    b1 = m.add(mb.Body("bar1", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    b2 = m.add(mb.Body("bar2", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    m.add(mb.Slider("slider", b2, point=(1, 0, 0), axis=(1, 0, 0)))
    m.add(mb.Contact("floor", b1, point=(1, 0, 0), normal=(0, 1, 0), origin=tuple(elbow), restitution=e))
    system = m.compile(formulation=formulation)
    assert system.constraint_violation(q) < 1e-12
    _, qd = system.assemble(q, [-1.0, 2.0])
    assert system.body_state("bar2", q, qd, point=(1, 0, 0)).velocity[1] == pytest.approx(0.0, abs=1e-12)
    v_before = normal_speed(system, "bar1", (1, 0, 0), (0, 1, 0), q, qd)
    assert v_before < 0
    impact = system.impact(q, qd)
    after = system.body_state("bar2", q, impact.qd, point=(1, 0, 0)).velocity
    assert after[1] == pytest.approx(0.0, abs=1e-12) and after[2] == pytest.approx(0.0, abs=1e-12)
    v_after = normal_speed(system, "bar1", (1, 0, 0), (0, 1, 0), q, impact.qd)
    assert v_after == pytest.approx(-e * v_before, rel=1e-10)
    assert impact.energy_loss == pytest.approx(kinetic(system, q, qd) - kinetic(system, q, impact.qd), rel=1e-10)


# ----------------------------------------------------------------------------------------------
# Persistent contacts during another impact
# ----------------------------------------------------------------------------------------------
CART_L = 0.5


@functools.lru_cache(maxsize=None)
def cart_with_pendulum(formulation):
    """A cart on a vertical slide resting on a floor, with a rod swinging below it whose tip
    hits a slope (normal (-0.6, 0, 0.8)) at the angle -0.2 rad: the slope's impulse lifts the
    cart off the floor."""
    m = mb.Model("cart_pendulum", gravity=(0, 0, -G))
    cart = m.add(mb.Body("cart", mass=1.0))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0, -CART_L / 2), inertia=(CART_L ** 2 / 12, CART_L ** 2 / 12, 1e-4)))
    m.add(mb.Prismatic("lift", m.ground, cart, axis="z", coords="z"))
    m.add(mb.Revolute("hinge", cart, rod, axis="y", coords="th"))
    m.add(mb.Contact("floor", cart, normal=(0, 0, 1), restitution=0.0))
    tip = (CART_L * math.sin(0.2), 0.0, -CART_L * math.cos(0.2))
    m.add(mb.Contact("slope", rod, point=(0, 0, -CART_L), normal=(-0.6, 0, 0.8), origin=tip, restitution=0.5))
    return m.compile(formulation=formulation)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_persistent_contact_lets_go_when_another_impact_lifts_it(formulation):
    system = cart_with_pendulum(formulation)
    # Lands plastically at t = 0 (persistent), then the rod swings into the slope.
    res = system.simulate(0.5, [0.0, 0.6], [-1e-3, 0.0], rtol=1e-10, atol=1e-12)
    slope = [ev for ev in res.events if ev.contact == "slope"]
    assert slope, "the rod never reached the slope"
    q, qd_before, qd_after = event_states(res, slope[0])
    # The same impact with both contacts free to act: the floor's impulse would pull, so it lets go.
    free = system.impact(q, qd_before, contacts=["slope", "floor"])
    assert "floor" not in free.impulses or free.impulses["floor"] == 0.0
    assert free.qd[0] > 0.1
    np.testing.assert_allclose(qd_after, free.qd, rtol=1e-9)


# (The examples of docs/contacts.md run, each block on its own, in tests/test_examples.py.)
