"""Force elements: Spring, Damper, Force, JointTorque, TorsionSpring, against closed forms."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import assert_close


def zero_crossing_times(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Upward and downward zero crossings by linear interpolation between samples."""
    i = np.flatnonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


def period_from_crossings(t: np.ndarray, y: np.ndarray) -> float:
    crossings = zero_crossing_times(t, y)
    assert len(crossings) >= 3, "too few zero crossings to measure a period"
    return 2 * float(np.mean(np.diff(crossings)))


def spring_cart(stiffness=40.0, mass=2.5, rest_length=1.0, damping=0.0, *, with_damper=None):
    """A cart on a prismatic joint along x whose origin sits at x = 1 + q, tied to the
    world origin by a spring (and optionally a separate damper); gravity is along -z,
    across the slide, so it does no work."""
    m = mb.Model("spring_cart")
    cart = m.add(mb.Body("cart", mass=mass))
    m.add(mb.Prismatic("slide", m.ground, cart, axis="x", parent_point=(1, 0, 0), coords="x"))
    m.add(mb.Spring("spring", a=(m.ground, (0, 0, 0)), b=(cart, (0, 0, 0)), stiffness=stiffness,
                    rest_length=rest_length, damping=damping))
    if with_damper is not None:
        m.add(mb.Damper("damper", a=(m.ground, (0, 0, 0)), b=(cart, (0, 0, 0)), damping=with_damper))
    return m


def rotor(inertia_zz=0.2, gravity=(0, 0, -9.81)):
    """A disc on a revolute joint about the world z axis (gravity along the axis does no work)."""
    m = mb.Model("rotor", gravity=gravity)
    disc = m.add(mb.Body("disc", mass=3.0, inertia=(inertia_zz / 2, inertia_zz / 2, inertia_zz)))
    m.add(mb.Revolute("spin", m.ground, disc, axis="z", coords="phi"))
    return m, disc


class TestSpring:
    def test_period_is_two_pi_sqrt_m_over_k(self):
        k, mass = 40.0, 2.5
        sys = spring_cart(k, mass).compile(backend="python")
        period = 2 * np.pi * np.sqrt(mass / k)
        t = np.linspace(0, 3.2 * period, 4001)
        res = sys.simulate(t[-1], [0.1], t_eval=t, rtol=1e-10, atol=1e-12)
        assert period_from_crossings(res.t, res["x"]) == pytest.approx(period, rel=1e-7)

    def test_trajectory_is_a_cosine(self):
        k, mass = 40.0, 2.5
        sys = spring_cart(k, mass).compile(backend="python")
        t = np.linspace(0, 3.0, 301)
        res = sys.simulate(3.0, [0.1], t_eval=t, rtol=1e-10, atol=1e-12)
        assert_close(res["x"], 0.1 * np.cos(np.sqrt(k / mass) * t), rtol=0, atol=1e-8, name="x(t)")

    @pytest.mark.parametrize("rest_length", [0.0, 0.7, 1.3])
    def test_potential_is_half_k_stretch_squared(self, rest_length):
        k = 40.0
        sys = spring_cart(k, rest_length=rest_length).compile(backend="python")
        for x in (-0.4, 0.0, 0.25):
            length = 1.0 + x
            energy = sys.energy([x], [0.0])
            assert energy.potential == pytest.approx(0.5 * k * (length - rest_length) ** 2, rel=1e-12, abs=1e-14)
            assert energy.kinetic == 0.0

    def test_rest_length_and_stiffness_rebind_as_parameters(self):
        sys = spring_cart(40.0, rest_length=1.0).compile(backend="python")
        other = sys.with_parameters({"spring.stiffness": 10.0, "spring.rest_length": 0.5})
        assert other.energy([0.2], [0.0]).potential == pytest.approx(0.5 * 10.0 * 0.7 ** 2, rel=1e-12)
        # The spring pulls back towards its rest length: F = -k (l - l0).
        assert other.accelerations([0.2], [0.0])[0] == pytest.approx(-10.0 * 0.7 / 2.5, rel=1e-12)

    def test_damping_decays_energy_monotonically(self):
        sys = spring_cart(40.0, damping=0.8).compile(backend="python")
        res = sys.simulate(4.0, [0.1], t_eval=np.linspace(0, 4.0, 401), rtol=1e-10, atol=1e-12)
        total = res.energy().total
        assert np.all(np.diff(total) <= 1e-12 * total[0])
        assert total[-1] < 0.5 * total[0]

    def test_spring_damping_matches_damped_oscillator(self):
        k, mass, c = 40.0, 2.5, 0.8
        sys = spring_cart(k, mass, damping=c).compile(backend="python")
        t = np.linspace(0, 3.0, 151)
        res = sys.simulate(3.0, [0.1], t_eval=t, rtol=1e-10, atol=1e-12)
        assert_close(res["x"], damped_oscillation(t, 0.1, k, mass, c), rtol=0, atol=1e-8, name="x(t)")

    def test_two_bodies_feel_equal_and_opposite_forces(self):
        m = mb.Model("pair", gravity=(0, 0, 0))
        a = m.add(mb.Body("a", mass=1.5, inertia=(0.1, 0.1, 0.1)))
        b = m.add(mb.Body("b", mass=0.5, inertia=(0.1, 0.1, 0.1)))
        m.add(mb.Prismatic("sa", m.ground, a, axis="x", coords="xa"))
        m.add(mb.Prismatic("sb", m.ground, b, axis="x", parent_point=(1, 0, 0), coords="xb"))
        m.add(mb.Spring("spring", a=(a, (0, 0, 0)), b=(b, (0, 0, 0)), stiffness=30.0, rest_length=0.6))
        sys = m.compile(backend="python")
        qdd = sys.accelerations([0.1, -0.2], [0.0, 0.0])
        # Length 1 - 0.2 - 0.1 = 0.7: tension 30 * 0.1 pulls a towards +x and b towards -x.
        assert_close(qdd, [3.0 / 1.5, -3.0 / 0.5], name="accelerations")

    @pytest.mark.parametrize("backend", ["python", "c"])
    def test_coincident_attachment_points_raise_naming_the_spring(self, backend):
        sys = spring_cart(rest_length=0.5).compile(backend=backend)
        with pytest.raises(mb.SimulationError, match="Spring 'spring' has zero length"):
            sys.accelerations([-1.0], [0.0])

    @pytest.mark.parametrize("kwargs", [dict(stiffness=-1.0), dict(stiffness=1.0, rest_length=-0.1),
                                        dict(stiffness=1.0, damping=-0.5), dict(stiffness=float("nan"))],
                             ids=["stiffness", "rest_length", "damping", "nan"])
    def test_negative_values_are_rejected(self, kwargs):
        with pytest.raises(mb.ModelError, match="Spring 'spring'"):
            mb.Spring("spring", a=("ground", (0, 0, 0)), b=("cart", (0, 0, 0)), **kwargs)


def damped_oscillation(t, x0, k, mass, c):
    """Underdamped ``m x'' + c x' + k x = 0`` from rest at ``x0``."""
    omega = np.sqrt(k / mass)
    zeta = c / (2 * np.sqrt(k * mass))
    omega_d = omega * np.sqrt(1 - zeta ** 2)
    return np.exp(-zeta * omega * t) * x0 * (np.cos(omega_d * t) + zeta * omega / omega_d * np.sin(omega_d * t))


class TestDamper:
    def test_damped_oscillator_follows_the_closed_form(self):
        k, mass, c = 40.0, 2.5, 1.5
        sys = spring_cart(k, mass, with_damper=c).compile(backend="python")
        t = np.linspace(0, 4.0, 201)
        res = sys.simulate(4.0, [0.1], t_eval=t, rtol=1e-10, atol=1e-12)
        assert_close(res["x"], damped_oscillation(t, 0.1, k, mass, c), rtol=0, atol=1e-8, name="x(t)")

    def test_decay_rate_of_peaks_is_c_over_2m(self):
        k, mass, c = 40.0, 2.5, 1.5
        sys = spring_cart(k, mass, with_damper=c).compile(backend="python")
        t = np.linspace(0, 4.0, 8001)
        res = sys.simulate(4.0, [0.1], t_eval=t, rtol=1e-10, atol=1e-12)
        # Energy ~ exp(-c t / m) on average; compare the same phase one damped period apart.
        omega_d = np.sqrt(k / mass) * np.sqrt(1 - c ** 2 / (4 * k * mass))
        period = 2 * np.pi / omega_d
        i0, i1 = 0, int(round(period / (t[1] - t[0])))
        ratio = np.hypot(res["x"][i1], res.qd[i1, 0] / omega_d) / np.hypot(res["x"][i0], res.qd[i0, 0] / omega_d)
        assert ratio == pytest.approx(np.exp(-c / (2 * mass) * t[i1]), rel=2e-2)
        assert res.t[i1] == pytest.approx(period, abs=t[1])

    def test_damper_force_is_linear_in_the_stretch_rate(self):
        sys = spring_cart(0.0, 2.5, with_damper=1.5).compile(backend="python")
        for speed in (-0.3, 0.2, 1.0):
            assert sys.accelerations([0.1], [speed])[0] == pytest.approx(-1.5 * speed / 2.5, rel=1e-12)

    def test_motion_across_the_line_is_not_damped(self):
        m = mb.Model("across")
        cart = m.add(mb.Body("cart", mass=1.0))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="y", coords="y"))
        m.add(mb.Damper("damper", a=(m.ground, (-1, 0, 0)), b=(cart, (0, 0, 0)), damping=5.0))
        sys = m.compile(backend="python")
        assert sys.accelerations([0.0], [2.0])[0] == pytest.approx(0.0, abs=1e-14)
        # Away from y = 0 only the component of the speed along the line is damped.
        y, v = 0.5, 2.0
        along = y / np.hypot(1.0, y)
        assert sys.accelerations([y], [v])[0] == pytest.approx(-5.0 * v * along ** 2, rel=1e-12)

    def test_damper_stores_no_energy(self):
        sys = spring_cart(0.0, with_damper=1.5).compile(backend="python")
        assert sys.energy([0.3], [1.0]).potential == 0.0
        assert sys.holding_forces([0.3])[0] == pytest.approx(0.0, abs=1e-14)

    def test_negative_damping_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Damper 'damper': damping"):
            mb.Damper("damper", a="ground", b="cart", damping=-1.0)


class TestForce:
    def test_constant_force_gives_a_equals_f_over_m(self):
        axis = np.array([0.3, -0.4, 0.5]) / np.linalg.norm([0.3, -0.4, 0.5])
        force, mass, gravity = np.array([2.0, 1.0, -3.0]), 1.7, np.array([0.0, 0.0, -9.81])
        m = mb.Model("pushed", gravity=gravity)
        block = m.add(mb.Body("block", mass=mass, inertia=(0.1, 0.2, 0.25)))
        m.add(mb.Prismatic("slide", m.ground, block, axis=tuple(axis), coords="s"))
        m.add(mb.Force("push", block, point=(0.2, 0.1, 0), force=tuple(force)))
        sys = m.compile(backend="python")
        a = (force + mass * gravity) @ axis / mass
        assert sys.accelerations([0.3], [0.5])[0] == pytest.approx(a, rel=1e-12)
        res = sys.simulate(1.0, [0.0], [0.5], t_eval=[0.5, 1.0])
        assert_close(res["s"], 0.5 * res.t + 0.5 * a * res.t ** 2, rtol=1e-10, atol=1e-12, name="s(t)")

    def test_force_at_a_point_makes_a_torque(self):
        m = mb.Model("lever", gravity=(0, 0, 0))
        bar = m.add(mb.Body("bar", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
        m.add(mb.Revolute("pivot", m.ground, bar, axis="z", coords="theta"))
        m.add(mb.Force("push", bar, point=(1.0, 0, 0), force=(0.0, 2.0, 0.0)))
        sys = m.compile(backend="python")
        inertia = 1 / 12 + 0.25
        for theta in (0.0, 0.6, 2.0):
            # Arm (cos, sin) crossed with (0, 2): torque 2 cos(theta) about z.
            assert sys.accelerations([theta], [0.0])[0] == pytest.approx(2 * np.cos(theta) / inertia, rel=1e-12, abs=1e-14)

    def test_force_on_the_ground_is_ignored(self):
        sys = spring_cart(0.0).compile(backend="python")
        m = spring_cart(0.0)
        m.add(mb.Force("on_ground", m.ground, force=(5.0, 0, 0)))
        assert m.compile(backend="python").accelerations([0.1], [0.0])[0] == sys.accelerations([0.1], [0.0])[0]

    def test_callable_force_receives_t_q_qd(self):
        seen = []

        def force(t, q, qd):
            seen.append((t, np.array(q), np.array(qd)))
            return (t - 2 * q[0] + 3 * qd[0], 0.0, 0.0)

        m = mb.Model("driven", gravity=(0, 0, -9.81))
        cart = m.add(mb.Body("cart", mass=2.0))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="x", coords="x"))
        m.add(mb.Force("push", cart, force=force))
        sys = m.compile(backend="python")
        a = sys.accelerations([0.5], [0.25], t=1.5)[0]
        assert a == pytest.approx((1.5 - 1.0 + 0.75) / 2.0, rel=1e-12)
        t, q, qd = seen[-1]
        assert t == 1.5 and q.tolist() == [0.5] and qd.tolist() == [0.25]

    def test_callable_spring_force_oscillates_with_the_spring_period(self):
        k, mass = 9.0, 1.0
        m = mb.Model("driven", gravity=(0, 0, -9.81))
        cart = m.add(mb.Body("cart", mass=mass))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="x", coords="x"))
        m.add(mb.Force("push", cart, force=lambda t, q, qd: (-k * q[0], 0.0, 0.0)))
        res = m.compile(backend="python").simulate(3.0, [0.2], t_eval=np.linspace(0, 3, 61), rtol=1e-10, atol=1e-12)
        assert_close(res["x"], 0.2 * np.cos(3.0 * res.t), atol=1e-8, name="x(t)")

    @pytest.mark.parametrize("bad", [(np.nan, 0, 0), (0, np.inf, 0), (1.0, 2.0)], ids=["nan", "inf", "two-values"])
    def test_callable_returning_bad_value_raises_naming_the_force(self, bad):
        m = mb.Model("broken")
        cart = m.add(mb.Body("cart", mass=1.0))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="x"))
        m.add(mb.Force("push", cart, force=lambda t, q, qd: bad))
        sys = m.compile(backend="python")
        with pytest.raises(mb.SimulationError, match="Force 'push'"):
            sys.accelerations([0.0], [0.0])
        with pytest.raises(mb.SimulationError, match="Force 'push'"):
            sys.simulate(1.0, [0.0])

    def test_callable_failing_late_stops_the_simulation_naming_the_force(self):
        m = mb.Model("broken")
        cart = m.add(mb.Body("cart", mass=1.0))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="x"))
        m.add(mb.Force("push", cart, force=lambda t, q, qd: (np.nan if t > 0.5 else 1.0, 0, 0)))
        with pytest.raises(mb.SimulationError, match="Force 'push'"):
            m.compile(backend="python").simulate(1.0, [0.0])

    def test_non_vector_constant_force_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Force 'push': force"):
            mb.Force("push", "cart", force=(1.0, 2.0))


class TestJointTorque:
    def test_constant_torque_gives_angular_acceleration_t_over_i(self):
        m, _ = rotor(inertia_zz=0.2)
        m.add(mb.JointTorque("drive", "spin", 0.5))
        sys = m.compile(backend="python")
        assert sys.accelerations([1.0], [3.0])[0] == pytest.approx(0.5 / 0.2, rel=1e-12)
        res = sys.simulate(2.0, [0.0], t_eval=[1.0, 2.0])
        assert_close(res["phi"], 0.5 * (0.5 / 0.2) * res.t ** 2, rtol=1e-10, name="phi(t)")

    def test_torque_array_on_a_ball_joint_equals_tau(self):
        m = arm_like_ball()
        m.add(mb.JointTorque("drive", "ball", [0.3, -0.7]))
        with_torque = m.compile(backend="python")
        without = arm_like_ball().compile(backend="python")
        q, qd = [0.4, -0.3], [0.2, 0.5]
        assert_close(with_torque.accelerations(q, qd), without.accelerations(q, qd, tau=[0.3, -0.7]),
                     name="accelerations")
        assert_close(with_torque.holding_forces(q), without.holding_forces(q) - [0.3, -0.7], name="holding forces")

    def test_callable_torque_acts_as_a_torsion_spring(self):
        m, _ = rotor(inertia_zz=0.2)
        m.add(mb.JointTorque("drive", "spin", lambda t, q, qd: -1.8 * q[0]))
        res = m.compile(backend="python").simulate(2.0, [0.1], t_eval=np.linspace(0, 2, 41), rtol=1e-10, atol=1e-12)
        assert_close(res["phi"], 0.1 * np.cos(3.0 * res.t), atol=1e-8, name="phi(t)")

    def test_callable_torque_may_depend_on_time(self):
        m, _ = rotor(inertia_zz=0.2)
        m.add(mb.JointTorque("drive", "spin", lambda t, q, qd: 0.2 * t))
        res = m.compile(backend="python").simulate(2.0, [0.0], t_eval=[0.5, 1.0, 2.0], rtol=1e-10, atol=1e-12)
        assert_close(res["phi"], res.t ** 3 / 6, rtol=1e-8, name="phi(t)")

    def test_wrong_size_is_rejected_at_compile(self):
        m = arm_like_ball()
        m.add(mb.JointTorque("drive", "ball", 0.5))
        with pytest.raises(mb.ModelError, match="JointTorque 'drive': value has 1 entries"):
            m.compile(backend="python")

    def test_callable_of_wrong_size_raises_naming_the_torque(self):
        m = arm_like_ball()
        m.add(mb.JointTorque("drive", "ball", lambda t, q, qd: 1.0))
        sys = m.compile(backend="python")
        with pytest.raises(mb.SimulationError, match="JointTorque 'drive'"):
            sys.accelerations([0.0, 0.0], [0.0, 0.0])

    @pytest.mark.parametrize("value", [np.nan, [[1.0, 2.0]], "big"], ids=["nan", "2-d", "text"])
    def test_bad_constant_is_rejected(self, value):
        with pytest.raises(mb.ModelError, match="JointTorque 'drive'"):
            mb.JointTorque("drive", "spin", value)

    def test_torque_on_an_unknown_joint_is_reported(self):
        m, _ = rotor()
        m.add(mb.JointTorque("drive", "nowhere", 1.0))
        with pytest.raises(mb.ModelError, match="JointTorque 'drive': joint 'nowhere' is not in the model"):
            m.compile(backend="python")


def arm_like_ball():
    """A body hanging on an "xy" ball joint (2 coordinates)."""
    m = mb.Model("ball")
    b = m.add(mb.Body("b", mass=2.0, com=(0.1, 0.0, -0.5), inertia=(0.05, 0.04, 0.02)))
    m.add(mb.Spherical("ball", m.ground, b, sequence="xy"))
    return m


class TestTorsionSpring:
    def test_torsional_pendulum_period(self):
        J, k = 0.2, 1.8
        m, _ = rotor(inertia_zz=J)
        m.add(mb.TorsionSpring("twist", "spin", stiffness=k, rest=0.3))
        sys = m.compile(backend="python")
        period = 2 * np.pi * np.sqrt(J / k)
        t = np.linspace(0, 3.3 * period, 3001)
        res = sys.simulate(t[-1], [0.5], t_eval=t, rtol=1e-10, atol=1e-12)
        assert period_from_crossings(res.t, res["phi"] - 0.3) == pytest.approx(period, rel=1e-7)

    def test_potential_is_half_k_deflection_squared(self):
        m, _ = rotor()
        m.add(mb.TorsionSpring("twist", "spin", stiffness=1.8, rest=0.3))
        sys = m.compile(backend="python")
        for phi in (-1.0, 0.3, 2.0):
            assert sys.energy([phi], [0.0]).potential == pytest.approx(0.5 * 1.8 * (phi - 0.3) ** 2, abs=1e-14)
            assert sys.holding_forces([phi])[0] == pytest.approx(1.8 * (phi - 0.3), abs=1e-14)

    def test_damping_gives_exponential_decay(self):
        J, k, c = 0.2, 1.8, 0.1
        m, _ = rotor(inertia_zz=J)
        m.add(mb.TorsionSpring("twist", "spin", stiffness=k, damping=c))
        t = np.linspace(0, 3.0, 61)
        res = m.compile(backend="python").simulate(3.0, [0.5], t_eval=t, rtol=1e-10, atol=1e-12)
        assert_close(res["phi"], damped_oscillation(t, 0.5, k, J, c), atol=1e-8, name="phi(t)")
        assert np.all(np.diff(res.energy().total) <= 1e-14)

    def test_on_a_prismatic_joint_it_is_a_linear_spring(self):
        m = mb.Model("linear")
        cart = m.add(mb.Body("cart", mass=2.0))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="x", coords="x"))
        m.add(mb.TorsionSpring("spring", "slide", stiffness=8.0))
        res = m.compile(backend="python").simulate(2.0, [0.1], t_eval=np.linspace(0, 2, 41), rtol=1e-10, atol=1e-12)
        assert_close(res["x"], 0.1 * np.cos(2.0 * res.t), atol=1e-8, name="x(t)")

    @pytest.mark.parametrize("joint", ["spherical", "fixed"])
    def test_only_one_dof_joints_are_accepted(self, joint):
        m = mb.Model("bad")
        b = m.add(mb.Body("b", mass=1.0, com=(0, 0, -1), inertia=(0.1, 0.1, 0.1)))
        if joint == "spherical":
            m.add(mb.Spherical("j", m.ground, b, sequence="xyz"))
        else:
            m.add(mb.Fixed("j", m.ground, b))
        m.add(mb.TorsionSpring("twist", "j", stiffness=1.0))
        with pytest.raises(mb.ModelError, match="TorsionSpring 'twist': needs a 1-DOF joint"):
            m.compile(backend="python")

    def test_negative_stiffness_is_rejected(self):
        with pytest.raises(mb.ModelError, match="TorsionSpring 'twist': stiffness"):
            mb.TorsionSpring("twist", "spin", stiffness=-1.0)
