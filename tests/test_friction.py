"""Coulomb friction on contacts: closed forms for sliding, sticking, rolling and impacts.

Models are planar (a ``Planar`` joint with normal y: coordinates z, x and the rotation
``phi`` about +y), so a ball's contact point velocity is ``x' - r phi'`` along x.
"""
import math

import numpy as np
import pytest

import mbcomp as mb

G = 9.81
FORMULATIONS = ("lagrange", "dae")


def planar_ball(formulation, mu, radius=0.1, mass=1.5, restitution=0.0):
    """A solid ball (I = 2/5 m r^2) whose centre carries a contact sphere of its radius."""
    m = mb.Model("ball", gravity=(0, 0, -G))
    inertia = 0.4 * mass * radius ** 2
    ball = m.add(mb.Body("ball", mass=mass, inertia=(inertia,) * 3))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), friction=mu, radius=radius,
                     restitution=restitution))
    return m.compile(formulation=formulation)


def slope(formulation, theta, mu):
    """A block (a contact at its centre of mass) on a plane inclined by ``theta`` about y,
    normal ``(-sin theta, 0, cos theta)``: up the slope is ``(cos theta, 0, sin theta)``."""
    m = mb.Model("slope", gravity=(0, 0, -G))
    block = m.add(mb.Body("block", mass=2.0, inertia=(0.01, 0.01, 0.01)))
    m.add(mb.Planar("plane", m.ground, block, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("incline", block, (0, 0, 0), normal=(-math.sin(theta), 0, math.cos(theta)), friction=mu))
    return m.compile(formulation=formulation)


@pytest.fixture(scope="module", params=FORMULATIONS)
def ball_system(request):
    return planar_ball(request.param, mu=0.3)


class TestSlidingBall:
    """Launched sliding at v0 without spin: friction -mu m g slows the centre (x'' = -mu g)
    and spins the ball up (phi'' = mu m g r / I = 5 mu g / (2 r)); the slip x' - r phi'
    falls at 7 mu g / 2, so rolling starts at t = 2 v0 / (7 mu g) with speed
    v0 - mu g t = 5 v0 / 7.  Kinetic energy then: m v^2 / 2 + I (v/r)^2 / 2 = 7 m v^2 / 10
    = 5 m v0^2 / 14, so m v0^2 / 2 - 5 m v0^2 / 14 = m v0^2 / 7 was lost."""

    V0, MU, R, M = 2.0, 0.3, 0.1, 1.5

    def test_starts_to_roll_at_the_closed_form_time(self, ball_system):
        res = ball_system.simulate(0.3, [self.R, 0.0, 0.0], [0.0, self.V0, 0.0], rtol=1e-10, atol=1e-12)
        assert [e.kind for e in res.events] == ["stick"]
        assert res.events[0].time == pytest.approx(2 * self.V0 / (7 * self.MU * G), rel=1e-7)
        assert res["x_d"][-1] == pytest.approx(5 * self.V0 / 7, rel=1e-9)
        assert res["phi_d"][-1] == pytest.approx(5 * self.V0 / 7 / self.R, rel=1e-9)   # rolling: x' = r phi'
        energy = res.energy().total
        assert energy[0] - energy[-1] == pytest.approx(self.M * self.V0 ** 2 / 7, rel=1e-8)
        np.testing.assert_allclose(res["z"], self.R, atol=1e-9)

    def test_contact_force_is_weight_plus_kinetic_friction_then_weight(self, ball_system):
        t = np.array([0.0, 0.05, 0.1, 0.25, 0.3])
        res = ball_system.simulate(0.3, [self.R, 0.0, 0.0], [0.0, self.V0, 0.0], rtol=1e-10, atol=1e-12, t_eval=t)
        force = res.contact_forces["floor"]
        weight = self.M * G
        np.testing.assert_allclose(force[:3], [[-self.MU * weight, 0.0, weight]] * 3, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(force[3:], [[0.0, 0.0, weight]] * 2, atol=1e-8)   # rolling: no friction


def test_formulations_agree_on_the_sliding_ball():
    runs = [planar_ball(f, mu=0.3).simulate(0.5, [0.1, 0.0, 0.0], [0.0, 2.0, 1.0], rtol=1e-10, atol=1e-12,
                                            t_eval=np.linspace(0, 0.5, 11)) for f in FORMULATIONS]
    np.testing.assert_allclose(runs[0].q, runs[1].q, atol=1e-8)
    np.testing.assert_allclose(runs[0].qd, runs[1].qd, atol=1e-8)
    assert [e.kind for e in runs[0].events] == [e.kind for e in runs[1].events] == ["stick"]
    assert runs[0].events[0].time == pytest.approx(runs[1].events[0].time, abs=1e-8)


class TestBlockOnSlope:
    """Static friction holds iff the tangential force needed, m g sin(theta), is at most
    mu m g cos(theta): tan(theta) <= mu.  Otherwise the block slides down with
    a = g (sin(theta) - mu cos(theta)) and covers a t^2 / 2."""

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    @pytest.mark.parametrize("theta, mu", [(0.3, 0.4), (math.atan(0.4) - 1e-3, 0.4), (0.5, 0.4),
                                           (math.atan(0.4) + 1e-2, 0.4)],
                             ids=["holds", "holds-near-limit", "slides", "slides-near-limit"])
    def test_sticks_iff_tan_theta_within_mu(self, formulation, theta, mu):
        res = slope(formulation, theta, mu).simulate(1.0, [0.0, 0.0, 0.0], rtol=1e-10, atol=1e-12)
        travelled = math.hypot(res["x"][-1], res["z"][-1])
        if math.tan(theta) <= mu:
            assert res.events == [] and travelled < 1e-12                  # no creep at rest
            force = res.contact_forces["incline"][-1]
            np.testing.assert_allclose(force, [0.0, 0.0, 2.0 * G], atol=1e-9)  # holds the weight
        else:
            assert [e.kind for e in res.events] == ["slip"] and res.events[0].time == 0.0
            a = G * (math.sin(theta) - mu * math.cos(theta))
            assert travelled == pytest.approx(a / 2, rel=1e-9)
            assert res["x"][-1] < 0                                        # down the slope

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_pushed_up_a_holding_slope_it_stops_and_sticks(self, formulation):
        """Sliding up at v0, friction and gravity both slow it: a = g (sin + mu cos); it stops
        at t = v0 / a, after v0^2 / (2 a), and stays (tan(theta) <= mu)."""
        theta, mu, v0 = 0.3, 0.4, 1.0
        up = (math.cos(theta), math.sin(theta))  # (x, z) of the up-slope direction
        res = slope(formulation, theta, mu).simulate(0.5, [0.0, 0.0, 0.0], [v0 * up[1], v0 * up[0], 0.0],
                                                       rtol=1e-10, atol=1e-12)
        a = G * (math.sin(theta) + mu * math.cos(theta))
        assert [e.kind for e in res.events] == ["stick"]
        assert res.events[0].time == pytest.approx(v0 / a, rel=1e-7)
        assert math.hypot(res["x"][-1], res["z"][-1]) == pytest.approx(v0 ** 2 / (2 * a), rel=1e-8)

    def test_pushed_up_a_steep_slope_it_turns_and_slides_back(self):
        """tan(theta) > mu: it stops at v0 / (g (sin + mu cos)) and slides back down at
        g (sin - mu cos) (a ``"slip"`` event reverses the direction)."""
        theta, mu, v0 = 0.6, 0.3, 1.0
        up = (math.cos(theta), math.sin(theta))
        res = slope("lagrange", theta, mu).simulate(0.5, [0.0, 0.0, 0.0], [v0 * up[1], v0 * up[0], 0.0],
                                                     rtol=1e-10, atol=1e-12)
        t_stop = v0 / (G * (math.sin(theta) + mu * math.cos(theta)))
        assert [e.kind for e in res.events] == ["slip"]
        assert res.events[0].time == pytest.approx(t_stop, rel=1e-7)
        back = G * (math.sin(theta) - mu * math.cos(theta)) * (0.5 - t_stop)
        speed = math.hypot(res["x_d"][-1], res["z_d"][-1])
        assert speed == pytest.approx(back, rel=1e-7) and res["x_d"][-1] < 0


def box_on_corners(formulation, mu=0.5):
    """A 0.4 x 0.2 x 0.1 m box of 3 kg on a Free joint with a contact at each bottom corner."""
    m = mb.Model("box", gravity=(0, 0, -G))
    a, b, c, mass = 0.2, 0.1, 0.05, 3.0
    box = m.add(mb.Body("box", mass=mass, inertia=(mass * (4 * b * b + 4 * c * c) / 12,
                                                   mass * (4 * a * a + 4 * c * c) / 12,
                                                   mass * (4 * a * a + 4 * b * b) / 12)))
    m.add(mb.Free("free", m.ground, box))
    for i, (sx, sy) in enumerate(((1, 1), (1, -1), (-1, 1), (-1, -1))):
        m.add(mb.Contact(f"corner{i}", box, (sx * a, sy * b, -c), normal=(0, 0, 1), friction=mu))
    return m.compile(formulation=formulation)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_box_rests_on_four_corners_without_drift(formulation):
    """Four contacts, twelve rows, six speeds: redundant.  At rest for 10 s nothing moves,
    no event happens and the least-norm forces share the weight equally (by symmetry)."""
    system = box_on_corners(formulation)
    q0 = np.array([0, 0, 0.05, 1, 0, 0, 0], dtype=float)
    res = system.simulate(10.0, q0, np.zeros(6), t_eval=[0.0, 5.0, 10.0])
    assert res.events == []
    np.testing.assert_allclose(res.q[-1], q0, atol=1e-9)
    np.testing.assert_allclose(res.qd[-1], 0.0, atol=1e-8)
    for name in ("corner0", "corner1", "corner2", "corner3"):
        np.testing.assert_allclose(res.contact_forces[name][-1], [0.0, 0.0, 3.0 * G / 4], atol=1e-7)


def test_box_landing_flat_while_sliding():
    """Dropped flat from 5 cm above the floor moving at 1 m/s: the four corners land at
    once (normal impulse m sqrt(2 g h)); the cone impact law takes mu times it off the
    momentum, v+ = 1 - mu sqrt(2 g h); then it slides to a stop after v+ / (mu g), where
    all four corners stick together."""
    mu, h, v = 0.5, 0.05, 1.0
    system = box_on_corners("lagrange", mu)
    res = system.simulate(0.5, [0, 0, 0.05 + h, 1, 0, 0, 0], [v, 0, 0, 0, 0, 0], rtol=1e-10, atol=1e-12)
    impacts = [e for e in res.events if e.kind == "impact"]
    sticks = [e for e in res.events if e.kind == "stick"]
    t_land = math.sqrt(2 * h / G)
    assert len(impacts) == 4 and len(sticks) == 4 and len(res.events) == 8
    assert sum(e.impulse for e in impacts) == pytest.approx(3.0 * math.sqrt(2 * G * h), rel=1e-8)
    v_plus = v - mu * math.sqrt(2 * G * h)
    assert sticks[0].time == pytest.approx(t_land + v_plus / (mu * G), rel=1e-7)
    assert res["free_x"][-1] == pytest.approx(v * t_land + v_plus ** 2 / (2 * mu * G), rel=1e-7)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_ball_bounces_to_e_squared_of_its_drop_height_with_friction_on(formulation):
    """Dropped straight down from h: no slip, so friction takes nothing; the rebound speed
    is e sqrt(2 g h), the next apex e^2 h above the floor."""
    e, h, r = 0.7, 0.5, 0.1
    system = planar_ball(formulation, mu=0.8, radius=r, restitution=e)
    t_fall = math.sqrt(2 * h / G)
    t = np.linspace(t_fall + 1e-6, t_fall + 2 * e * t_fall, 2001)
    res = system.simulate(t[-1], [r + h, 0.0, 0.0], rtol=1e-10, atol=1e-12, t_eval=t)
    assert res.events[0].kind == "impact" and res.events[0].time == pytest.approx(t_fall, rel=1e-9)
    assert res["z"].max() - r == pytest.approx(e ** 2 * h, rel=1e-6)
    np.testing.assert_allclose(res["x"], 0.0, atol=1e-12)


class TestObliqueImpact:
    """A ball (no spin) landing with tangential speed u and normal speed w, restitution e:
    P_n = m (1 + e) w.  Sticking the contact point needs P_t = 2 m u / 7 (the slip
    u - P_t (1/m + r^2/I) = u - 7 P_t / (2 m) reaches 0); when mu P_n covers it the ball
    leaves rolling at 5 u / 7, otherwise at u - mu (1 + e) w."""

    @pytest.mark.parametrize("mu", [0.05, 0.5], ids=["slides-through", "grips"])
    def test_tangential_speed_after_impact(self, mu):
        e, r, h, u = 0.5, 0.1, 0.2, 1.0
        system = planar_ball("lagrange", mu=mu, radius=r, restitution=e)
        w = math.sqrt(2 * G * h)
        t_fall = math.sqrt(2 * h / G)
        res = system.simulate(t_fall + 0.01, [r + h, 0.0, 0.0], [0.0, u, 0.0], rtol=1e-11, atol=1e-12)
        ev = res.events[0]
        assert ev.kind == "impact" and ev.impulse == pytest.approx(1.5 * (1 + e) * w, rel=1e-9)
        grips = mu * (1 + e) * w >= 2 * u / 7
        expected = 5 * u / 7 if grips else u - mu * (1 + e) * w
        assert grips == (mu == 0.5)
        assert res["x_d"][-1] == pytest.approx(expected, rel=1e-9)


def test_painleve_sliding_rod_is_a_clear_error():
    """A rod (length 2l, I = m l^2 / 3) sliding on one end: its end's normal acceleration
    per unit normal force is (1 + 3 cos^2 phi - 3 mu s sin phi cos phi) / m (s = +-1 the
    slip direction); with mu = 5 at phi = -0.6 and s = -1 it is -3.95 / m < 0: no normal
    force is consistent (Painleve's paradox)."""
    m = mb.Model("rod", gravity=(0, 0, -G))
    l = 0.5
    rod = m.add(mb.Body("rod", mass=1.0, inertia=(l * l / 3,) * 3))
    m.add(mb.Planar("plane", m.ground, rod, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("end", rod, (-l, 0, 0), normal=(0, 0, 1), friction=5.0))
    system = m.compile()
    phi = -0.6
    z = l * math.sin(-phi)  # the end (-l, 0, 0) rotated by phi about y touches z = 0
    with pytest.raises(mb.SimulationError, match="Painleve.*'end'"):
        system.simulate(0.1, [z, 0.0, phi], [0.0, -1.0, 0.0])
    assert system.simulate(0.05, [z, 0.0, phi], [0.0, 1.0, 0.0]).stats["success"]  # the other way: fine


def test_friction_runs_in_compiled_code():
    system = planar_ball("lagrange", mu=0.3)
    assert system.integration_path() == "compiled"
    res = system.simulate(0.05, [0.1, 0.0, 0.0], [0.0, 1.0, 0.0], integrator="compiled")
    assert res.stats["path"] == "compiled"
    assert res["x_d"][-1] == pytest.approx(1.0 - 0.3 * G * 0.05, rel=1e-9)  # still sliding: x" = -mu g
    frictionless = system.simulate(0.1, [0.1, 0.0, 0.0], [0.0, 1.0, 0.0], parameters={"floor.friction": 0.0})
    assert frictionless.stats["integrator"] == "compiled"
    assert frictionless["x_d"][-1] == pytest.approx(1.0, rel=1e-12)  # no friction: keeps sliding


def test_contact_forces_are_zero_while_open():
    system = planar_ball("lagrange", mu=0.3, restitution=0.5)
    res = system.simulate(0.4, [0.3, 0.0, 0.0], t_eval=np.linspace(0, 0.4, 9))
    np.testing.assert_array_equal(res.contact_forces["floor"], 0.0)   # in flight, bouncing: impulses only
    assert [e.kind for e in res.events] == ["impact"]


def test_friction_and_radius_are_checked_parameters():
    m = mb.Model("m")
    body = m.add(mb.Body("b", mass=1.0))
    with pytest.raises(mb.ModelError, match="friction"):
        mb.Contact("c", body, (0, 0, 0), friction=-0.1)
    with pytest.raises(mb.ModelError, match="radius"):
        mb.Contact("c", body, (0, 0, 0), radius=-1.0)


def test_friction_and_radius_survive_save_and_load(tmp_path):
    m = mb.Model("ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.0, inertia=(0.004,) * 3))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=("z", "x", "phi")))
    m.add(mb.Contact("floor", ball, (0, 0, 0), friction=0.35, radius=0.1, restitution=0.2))
    path = tmp_path / "ball.toml"
    m.save(path)
    text = path.read_text()
    assert "friction = 0.35" in text and "radius = 0.1" in text
    again = mb.load(path)
    assert again["floor"].friction == 0.35 and again["floor"].radius == 0.1
    a = m.compile().simulate(0.3, [0.1, 0.0, 0.0], [0.0, 1.0, 0.0])
    b = again.compile().simulate(0.3, [0.1, 0.0, 0.0], [0.0, 1.0, 0.0])
    np.testing.assert_array_equal(a.q, b.q)


def test_friction_modes_travel_with_a_pickled_result():
    """The closed contacts recorded per sample keep their friction modes, so a result read
    back and bound again gives the same contact forces (kinetic friction while sliding)."""
    import pickle
    system = planar_ball("lagrange", mu=0.3)
    res = system.simulate(0.3, [0.1, 0.0, 0.0], [0.0, 2.0, 0.0], t_eval=np.linspace(0, 0.3, 7))
    again = pickle.loads(pickle.dumps(res)).with_system(system)
    np.testing.assert_array_equal(again.contact_forces["floor"], res.contact_forces["floor"])
    assert again.contact_forces["floor"][0] == pytest.approx([-0.3 * 1.5 * G, 0.0, 1.5 * G], rel=1e-12)


def test_impact_by_hand_with_friction():
    """``sys.impact``: a ball (m = 1.5 kg) closing at 1 m/s while sliding at 1 m/s, e = 0,
    mu = 0.3: P_n = 1.5 N s; sticking needs 2 m u / 7 = 0.43 <= mu P_n = 0.45, so it leaves
    rolling at 5/7 m/s (spin 5/7 / r)."""
    system = planar_ball("lagrange", mu=0.3)
    impact = system.impact([0.1, 0.0, 0.0], [-1.0, 1.0, 0.0])
    assert impact.impulses == {"floor": pytest.approx(1.5, rel=1e-12)}
    np.testing.assert_allclose(impact.qd, [0.0, 5 / 7, 50 / 7], rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_ball_on_a_free_joint_slides_straight_then_rolls(formulation):
    """In 3D (Free joint) with any spin: the slip u = v + w x (-r n) keeps its direction
    (friction -mu m g u/|u| changes v by -mu g and the slip by -7/2 mu g along u), so the
    ball rolls from t = 2 |u0| / (7 mu g) on, with v = v0 - mu g t u0/|u0|; the spin about
    the normal does not matter."""
    mu, r, mass = 0.3, 0.1, 1.5
    m = mb.Model("ball3d", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=mass, inertia=(0.4 * mass * r * r,) * 3))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), friction=mu, radius=r))
    v0, w0 = np.array([2.0, 0.5, 0.0]), np.array([3.0, -4.0, 7.0])   # (body = world frame at the start)
    res = m.compile(formulation=formulation).simulate(0.3, [0, 0, r, 1, 0, 0, 0], np.concatenate((v0, w0)),
                                                      rtol=1e-10, atol=1e-12)
    u0 = (v0 + np.cross(w0, [0.0, 0.0, -r]))[:2]
    t_roll = 2 * np.linalg.norm(u0) / (7 * mu * G)
    assert [e.kind for e in res.events] == ["stick"]
    assert res.events[0].time == pytest.approx(t_roll, rel=1e-7)
    np.testing.assert_allclose(res.qd[-1, :2], v0[:2] - mu * G * t_roll * u0 / np.linalg.norm(u0), rtol=1e-7)
