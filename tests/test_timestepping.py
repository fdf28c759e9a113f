"""Moreau-Jean time stepping (``contact_mode="timestepping"``): Newton's law per bounce,
Coulomb friction's rolling speed, resting contact without drift, first-order convergence
to the event-driven run, the vectorised cone sweeps against ``friction.cone_impact``, and
checked settings.

The ball is planar (a ``Planar`` joint with normal y: coordinates z, x and the rotation phi
about +y), its contact point's slip ``x' - r phi'``.
"""
import math

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.formulations.cone_sweeps import colours, cone_sweeps
from mbcomp.formulations.friction import cone_impact

G = 9.81
R = 0.1


def planar_ball(formulation="lagrange", mu=0.0, restitution=0.0, mass=1.5):
    m = mb.Model("ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=mass, inertia=(0.4 * mass * R ** 2,) * 3))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), friction=mu, radius=R, restitution=restitution))
    return m.compile(formulation=formulation)


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_bounce_keeps_e_squared_of_the_energy(formulation):
    """Dropped from 0.5 m above contact with e = 0.5: the first rebound's apex is e^2 of the
    drop height (to O(dt))."""
    system = planar_ball(formulation, restitution=0.5)
    dt = 1e-3
    res = system.simulate(0.62, [0.6, 0, 0], [0, 0, 0], contact_mode="timestepping", dt=dt)
    z, vz = res.q[:, 0], res.qd[:, 0]
    first = int(np.argmax(vz > 0))                 # the first step after the impact
    assert 0.30 < res.t[first] < 0.33              # falls 0.5 m in sqrt(2 h / g) = 0.319 s
    apex = float(z[first:].max()) - R
    assert apex / 0.5 == pytest.approx(0.25, abs=0.02)
    assert res.stats["path"] == "timestepping" and res.stats["unconverged"] == 0
    assert z.min() > R - 3.2 * dt * 3.2            # penetration at most a step's travel


def test_sliding_ball_rolls_at_five_sevenths():
    """Launched sliding at v0 with no spin (mu = 0.3): it rolls at 5 v0 / 7 after
    t = 2 v0 / (7 mu g) = 0.19 s."""
    system = planar_ball(mu=0.3)
    v0 = 2.0
    res = system.simulate(0.4, [R, 0, 0], [0, v0, 0], contact_mode="timestepping", dt=1e-3)
    x_d, phi_d = res.qd[-1, 1], res.qd[-1, 2]
    assert x_d == pytest.approx(5 * v0 / 7, abs=5e-3)
    assert abs(x_d - R * phi_d) < 1e-6             # rolling: no slip
    t_roll = res.t[np.argmax(np.abs(res.qd[:, 1] - R * res.qd[:, 2]) < 1e-6)]
    assert t_roll == pytest.approx(2 * v0 / (7 * 0.3 * G), abs=3e-3)
    assert np.all(np.abs(res.q[:, 0] - R) < 1e-9)  # never leaves the floor, never sinks


def box_on_corners(mu=0.5):
    m = mb.Model("box", gravity=(0, 0, -G))
    box = m.add(mb.Body("box", mass=2.0, inertia=(0.02, 0.03, 0.04)))
    m.add(mb.Free("free", m.ground, box))
    for i, (sx, sy) in enumerate([(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        m.add(mb.Contact(f"corner{i}", box, (0.2 * sx, 0.1 * sy, -0.05), normal=(0, 0, 1), friction=mu))
    return m.compile()


def test_box_on_four_corners_stays_at_rest():
    """Four redundant corner contacts carry the weight: no drift, no sinking, no spin."""
    system = box_on_corners()
    q0 = np.array([0, 0, 0.05, 1, 0, 0, 0], dtype=float)
    res = system.simulate(0.5, q0, np.zeros(6), contact_mode="timestepping", dt=2e-3)
    assert np.max(np.abs(res.q - q0)) < 1e-9
    assert np.max(np.abs(res.qd)) < 1e-9
    assert min(system.gaps(res.q[-1]).values()) > -1e-9


def test_sphere_shape_rests_on_a_plane_collision():
    """A ``Collision`` (Sphere shape on a ground Plane) enters as a contact does: at rest,
    no drift; a push slides it to rolling at 5 v0 / 7."""
    m = mb.Model("shape", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.0, inertia=(0.4 * R ** 2,) * 3, shape=mb.Sphere(R)))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Collision("floor", [ball], [(m.ground, mb.Plane(normal=(0, 0, 1)))], friction=0.3))
    system = m.compile()
    q0 = np.array([0, 0, R, 1, 0, 0, 0], dtype=float)
    rest = system.simulate(0.3, q0, np.zeros(6), contact_mode="timestepping", dt=2e-3)
    assert np.max(np.abs(rest.q - q0)) < 1e-9
    push = system.simulate(0.4, q0, [1.0, 0, 0, 0, 0, 0], contact_mode="timestepping", dt=1e-3)
    assert push.qd[-1, 0] == pytest.approx(5 / 7, abs=5e-3)
    assert abs(push.q[-1, 2] - R) < 1e-9


def test_first_order_convergence_to_the_event_driven_run():
    """The bouncing ball's height over its first bounce against the event-driven run (at
    the same times): the largest error is within the impact speed times dt (an impact falls
    inside a step) and falls at least linearly with dt (fitted order)."""
    system = planar_ball(restitution=0.5)
    t_end, v_impact = 0.45, math.sqrt(2 * G * 0.5)
    steps = np.array([4e-3, 2e-3, 1e-3, 5e-4])
    errors = []
    for dt in steps:
        res = system.simulate(t_end, [0.6, 0, 0], [0, 0, 0], contact_mode="timestepping", dt=dt)
        assert res.t[-1] == pytest.approx(t_end)
        exact = system.simulate(t_end, [0.6, 0, 0], [0, 0, 0], t_eval=res.t)
        errors.append(float(np.abs(res.q[:, 0] - exact.q[:, 0]).max()))
    errors = np.array(errors)
    assert np.all(errors < v_impact * steps), errors
    order = np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert order > 0.9, (errors, order)


def test_sweeps_agree_with_cone_impact():
    """The coloured vectorised sweeps solve the same law as ``friction.cone_impact``."""
    rng = np.random.default_rng(3)
    nv, k = 12, 3
    A = rng.normal(size=(nv, nv))
    M = A @ A.T + nv * np.eye(nv)
    Minv = np.linalg.inv(M)
    J = rng.normal(size=(3 * k, nv))
    v = rng.normal(size=nv)
    e = np.array([0.5, 0.0, 0.2])
    approach = J[0::3] @ v
    bias = np.zeros(3 * k)
    bias[0::3] = e * np.minimum(approach, 0.0)
    mu = np.array([0.3, 0.6, 0.1])
    G_ = J @ Minv @ J.T
    P_ref = cone_impact(G_, J @ v + bias, 0, mu, "test", 0.0)
    sol = cone_sweeps(J, Minv @ J.T, v, bias, mu, sweeps=20000, tolerance=1e-13)
    assert sol.converged
    assert np.allclose(sol.v, v + Minv @ J.T @ P_ref, atol=1e-8)
    assert np.all(sol.P[0::3] >= 0) and np.all(J[0::3] @ sol.v + bias[0::3] >= -1e-9)


def test_colours_separate_contacts_sharing_a_speed():
    J = np.zeros((9, 4))
    J[0, 0] = J[3, 0] = 1.0   # contacts 0 and 1 share speed 0
    J[6, 3] = 1.0             # contact 2 alone
    groups = colours(J)
    assert sorted(np.concatenate(groups).tolist()) == [0, 1, 2]
    assert all(not ({0, 1} <= set(g.tolist())) for g in groups)


@pytest.mark.parametrize("dt", [0.0, -1e-3, float("nan"), float("inf"), None, 2.0, "x"])
def test_bad_dt_is_a_model_error_naming_dt(dt):
    system = planar_ball()
    with pytest.raises(mb.ModelError, match="dt"):
        system.simulate(1.0, [R, 0, 0], contact_mode="timestepping", dt=dt)


def test_unknown_contact_mode_is_a_model_error():
    with pytest.raises(mb.ModelError, match="contact_mode"):
        planar_ball().simulate(1.0, [R, 0, 0], contact_mode="implicit")


def test_loops_are_refused_in_time_stepping():
    m = mb.Model("slider", gravity=(0, 0, -G))
    a = m.add(mb.Body("a", mass=1.0, inertia=(0.1,) * 3))
    m.add(mb.Prismatic("p", m.ground, a, axis="z", coords="z"))
    m.add(mb.Contact("floor", a, (0, 0, 0)))
    m.add(mb.Prismatic("p2", m.ground, a, axis="z", coords="z2"))
    system = m.compile(formulation="dae")
    with pytest.raises(mb.ModelError, match="trees only"):
        system.simulate(0.1, np.zeros(system.nq), contact_mode="timestepping", dt=1e-3)


def test_free_flight_is_exact_and_samples_follow_t_eval():
    """Away from contact the midpoint step is exact under constant gravity; ``t_eval``
    picks the steps at those times, and a last partial step ends at t_end."""
    system = planar_ball()
    res = system.simulate(0.1, [0.6, 0, 0], [0, 0, 0], contact_mode="timestepping", dt=1e-3, t_eval=[0, 0.05, 0.1])
    assert np.allclose(res.t, [0, 0.05, 0.1])
    assert np.allclose(res.q[:, 0], 0.6 - 0.5 * G * res.t ** 2, atol=1e-12)
    every = system.simulate(0.1005, [0.6, 0, 0], [0, 0, 0], contact_mode="timestepping", dt=1e-3)
    assert len(every.t) == 102 and every.t[-1] == pytest.approx(0.1005)
    assert every.qd[-1, 0] == pytest.approx(-G * 0.1005, rel=1e-12)
