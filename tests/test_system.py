"""System: invariants on random trees (RigidBodyDynamics.jl style), parameters, states,
immutability, singularities, backends and the code cache."""
from __future__ import annotations


import numpy as np
import pytest

import mbcomp as mb
from conftest import arm_model, assert_close, pendulum_chain


# ----------------------------------------------------------------------------------
# Random mechanisms
# ----------------------------------------------------------------------------------
def random_rotation(rng) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q @ np.diag(np.sign(np.diag(R)))
    return Q if np.linalg.det(Q) > 0 else -Q


def random_inertia(rng, mass) -> np.ndarray:
    """A box's inertia about its COM, in a random orientation (physically valid by construction)."""
    a, b, c = rng.uniform(0.1, 0.6, 3)
    principal = mass / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    R = random_rotation(rng)
    I = R @ np.diag(principal) @ R.T
    return (I + I.T) / 2


def random_model(seed: int, n: int = 5, *, chain: bool = False, springs: bool = True) -> mb.Model:
    """A seeded random chain or tree of ``n`` rigid bodies on revolute, prismatic and
    Tait-Bryan ball joints with random axes, points, masses, inertias and gravity;
    with ``springs``, a spring from the ground and a torsion spring (both undamped)."""
    rng = np.random.default_rng(seed)
    m = mb.Model(f"random{seed}", gravity=tuple(rng.normal(size=3) * 5))
    bodies = [m.ground]
    one_dof = []
    for i in range(n):
        mass = float(rng.uniform(0.5, 3.0))
        body = m.add(mb.Body(f"b{i}", mass=mass, com=tuple(rng.normal(size=3) * 0.2),
                             inertia=random_inertia(rng, mass)))
        parent = bodies[-1] if chain else bodies[int(rng.integers(len(bodies)))]
        points = dict(parent_point=tuple(rng.normal(size=3) * 0.3), child_point=tuple(rng.normal(size=3) * 0.3))
        kind = ("R", "P", "S")[i % 3] if i < 3 else str(rng.choice(["R", "P", "S"]))
        axis = tuple(rng.normal(size=3))
        if kind == "R":
            joint = mb.Revolute(f"j{i}", parent, body, axis=axis, **points)
            one_dof.append(joint)
        elif kind == "P":
            joint = mb.Prismatic(f"j{i}", parent, body, axis=axis, **points)
            one_dof.append(joint)
        else:
            sequence = "".join(rng.permutation(list("xyz"))[: int(rng.integers(1, 4))])
            joint = mb.Spherical(f"j{i}", parent, body, sequence=sequence, **points)
        m.add(joint)
        bodies.append(body)
    if springs:
        m.add(mb.Spring("spring", a=(m.ground, (0.5, 0.5, 0.5)), b=(bodies[-1], (0.1, 0.0, 0.0)),
                        stiffness=float(rng.uniform(5, 20)), rest_length=0.2))
        m.add(mb.TorsionSpring("twist", one_dof[0], stiffness=float(rng.uniform(1, 5)), rest=0.1))
    return m


SEEDS = [pytest.param((seed, chain), id=f"{'chain' if chain else 'tree'}-{seed}")
         for seed, chain in ((0, True), (1, False), (2, False), (3, True))]


@pytest.fixture(params=SEEDS)
def random_system(request):
    seed, chain = request.param
    sys = random_model(seed, chain=chain).compile(backend="python")
    rng = np.random.default_rng(100 + seed)
    return sys, rng


def random_state(sys, rng):
    return rng.uniform(-1.0, 1.0, sys.nq), rng.normal(size=sys.nq)


def _skew_vector(W):
    W = (W - W.T) / 2
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


# ----------------------------------------------------------------------------------
# Invariants
# ----------------------------------------------------------------------------------
class TestInvariants:
    def test_mass_matrix_is_symmetric_positive_definite(self, random_system):
        sys, rng = random_system
        for _ in range(3):
            M = sys.mass_matrix(random_state(sys, rng)[0])
            assert M.shape == (sys.nq, sys.nq)
            assert_close(M, M.T, rtol=0, atol=0, name="M - M^T")
            assert np.linalg.eigvalsh(M).min() > 0

    def test_kinetic_energy_is_half_qd_m_qd(self, random_system):
        sys, rng = random_system
        for _ in range(3):
            q, qd = random_state(sys, rng)
            kinetic = sys.energy(q, qd).kinetic
            assert kinetic == pytest.approx(0.5 * qd @ sys.mass_matrix(q) @ qd, rel=1e-12)

    def test_kinetic_energy_is_the_sum_over_bodies(self, random_system):
        """1/2 m |v_com|^2 + 1/2 w . I_world w, from the body states: an independent sum."""
        sys, rng = random_system
        q, qd = random_state(sys, rng)
        total = 0.0
        for body in sys.topology.bodies:
            state = sys.body_state(body, q, qd)
            I_world = state.rotation @ body.inertia_matrix() @ state.rotation.T
            w = state.angular_velocity
            total += 0.5 * body.mass * state.velocity @ state.velocity + 0.5 * w @ I_world @ w
        assert sys.energy(q, qd).kinetic == pytest.approx(total, rel=1e-12)

    def test_power_balance(self, random_system):
        """dE/dt = tau . qd for a conservative model driven by a constant tau (central
        difference in time along the motion, second order)."""
        sys, rng = random_system
        for _ in range(2):
            q, qd = random_state(sys, rng)
            tau = rng.normal(size=sys.nq)
            qdd = sys.accelerations(q, qd, tau=tau)

            def rate(h):
                energies = [sys.energy(q + s * h * qd + 0.5 * h * h * qdd, qd + s * h * qdd).total for s in (1, -1)]
                return (energies[0] - energies[1]) / (2 * h)

            dE_dt = (4 * rate(5e-4) - rate(1e-3)) / 3      # Richardson: the h^2 error cancels
            scale = abs(tau) @ abs(qd) + abs(qd @ sys.mass_matrix(q) @ qdd)
            assert dE_dt == pytest.approx(tau @ qd, abs=1e-8 * scale)

    def test_holding_forces_are_the_potential_gradient(self, random_system):
        """Holding forces balance gravity and springs: they equal dV/dq (central differences)."""
        sys, rng = random_system
        q = random_state(sys, rng)[0]
        h = 1e-6
        gradient = np.empty(sys.nq)
        for k in range(sys.nq):
            dq = np.zeros(sys.nq)
            dq[k] = h
            gradient[k] = (sys.energy(q + dq, None).potential - sys.energy(q - dq, None).potential) / (2 * h)
        assert_close(sys.holding_forces(q), gradient, rtol=1e-6, atol=1e-7, name="holding forces")

    def test_holding_forces_keep_the_system_at_rest(self, random_system):
        sys, rng = random_system
        q = random_state(sys, rng)[0]
        qdd = sys.accelerations(q, np.zeros(sys.nq), tau=sys.holding_forces(q))
        assert_close(qdd, np.zeros(sys.nq), atol=1e-10, name="accelerations under holding forces")

    def test_gravity_potential_is_minus_m_g_dot_com(self):
        m = random_model(4, springs=False)
        sys = m.compile(backend="python")
        q = np.random.default_rng(4).uniform(-1, 1, sys.nq)
        g = np.array(m.gravity)
        expected = -sum(b.mass * g @ sys.body_state(b, q).position for b in m.bodies)
        assert sys.energy(q, None).potential == pytest.approx(expected, rel=1e-12)

    def test_body_velocity_is_the_derivative_of_position(self, random_system):
        sys, rng = random_system
        q, qd = random_state(sys, rng)
        h = 1e-6
        point = (0.1, -0.2, 0.3)
        for body in sys.topology.bodies:
            for where in (None, point):
                state = sys.body_state(body, q, qd, point=where)
                plus = sys.body_state(body, q + h * qd, point=where).position
                minus = sys.body_state(body, q - h * qd, point=where).position
                assert_close(state.velocity, (plus - minus) / (2 * h), rtol=1e-6, atol=1e-8,
                             name=f"velocity of {body.name} at {where}")

    def test_body_angular_velocity_is_the_derivative_of_rotation(self, random_system):
        sys, rng = random_system
        q, qd = random_state(sys, rng)
        h = 1e-6
        for body in sys.topology.bodies:
            state = sys.body_state(body, q, qd)
            dR = (sys.body_state(body, q + h * qd).rotation - sys.body_state(body, q - h * qd).rotation) / (2 * h)
            assert_close(state.angular_velocity, _skew_vector(dR @ state.rotation.T), rtol=1e-6, atol=1e-8,
                         name=f"angular velocity of {body.name}")

    def test_body_accelerations_are_the_derivatives_of_velocities(self, random_system):
        """Along the motion (q, qd advanced with the model's own accelerations)."""
        sys, rng = random_system
        q, qd = random_state(sys, rng)
        qdd = sys.accelerations(q, qd)
        h = 1e-4
        ahead = (q + h * qd + 0.5 * h * h * qdd, qd + h * qdd)
        behind = (q - h * qd + 0.5 * h * h * qdd, qd - h * qdd)
        point = (0.2, 0.1, -0.1)
        for body in sys.topology.bodies:
            state = sys.body_state(body, q, qd, point=point)
            plus, minus = sys.body_state(body, *ahead, point=point), sys.body_state(body, *behind, point=point)
            scale = np.abs(state.acceleration).max() + 1.0
            assert_close(state.acceleration, (plus.velocity - minus.velocity) / (2 * h), rtol=0,
                         atol=1e-6 * scale, name=f"acceleration of {body.name}")
            scale = np.abs(state.angular_acceleration).max() + 1.0
            assert_close(state.angular_acceleration, (plus.angular_velocity - minus.angular_velocity) / (2 * h),
                         rtol=0, atol=1e-6 * scale, name=f"angular acceleration of {body.name}")

    def test_ground_state_is_the_world_frame(self, random_system):
        sys, rng = random_system
        q, qd = random_state(sys, rng)
        state = sys.body_state("ground", q, qd, point=(1, 2, 3))
        assert_close(state.position, [1, 2, 3], name="position")
        assert_close(state.rotation, np.eye(3), name="rotation")
        for v in (state.velocity, state.acceleration, state.angular_velocity, state.angular_acceleration):
            assert_close(v, np.zeros(3), name="motion")

    def test_rotations_are_proper(self, random_system):
        sys, rng = random_system
        q = random_state(sys, rng)[0]
        for body in sys.topology.bodies:
            R = sys.body_state(body, q).rotation
            assert_close(R.T @ R, np.eye(3), atol=1e-13, name="R^T R")
            assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-13)

    def test_calls_do_not_modify_their_inputs(self, random_system):
        sys, rng = random_system
        q, qd = random_state(sys, rng)
        q0, qd0 = q.copy(), qd.copy()
        sys.accelerations(q, qd)
        sys.body_state(sys.topology.bodies[-1], q, qd)
        sys.energy(q, qd)
        assert np.array_equal(q, q0) and np.array_equal(qd, qd0)

    def test_unknown_body_is_rejected(self, random_system):
        sys, _ = random_system
        with pytest.raises(mb.ModelError, match="'nobody'"):
            sys.body_state("nobody", np.zeros(sys.nq))


# ----------------------------------------------------------------------------------
# Parameters
# ----------------------------------------------------------------------------------
def simple_pendulum(length=0.8, mass=1.5):
    m = mb.Model("pendulum", gravity=(0, 0, -9.81))
    bob = m.add(mb.Body("bob", mass=mass, com=(0, 0, -length)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    return m


class TestParameters:
    def test_parameters_list_every_numeric_value(self):
        sys = arm_model().compile(backend="python")
        params = sys.parameters
        assert params["upper.mass"] == 3.0
        assert params["lower.com"] == (0.0, 0.2, 0.0)
        assert params["elbow.parent_point"] == (0.0, 0.0, -0.3)
        assert params["gravity"] == (0.0, 0.0, -9.81)

    def test_parameters_is_a_copy(self):
        sys = arm_model().compile(backend="python")
        sys.parameters["upper.mass"] = 100.0
        assert sys.parameters["upper.mass"] == 3.0

    def test_with_parameters_shares_the_compiled_code_and_leaves_the_original(self):
        sys = simple_pendulum().compile(backend="python")
        heavier = sys.with_parameters({"bob.mass": 3.0})
        assert heavier is not sys
        assert heavier._compiled is sys._compiled
        assert sys.parameters["bob.mass"] == 1.5 and heavier.parameters["bob.mass"] == 3.0

    def test_holding_torque_scales_with_mass(self):
        sys = simple_pendulum(length=0.8, mass=1.5).compile(backend="python")
        heavier = sys.with_parameters({"bob.mass": 4.5})
        theta = 0.4
        # Holding torque of a point mass: m g L sin(theta).
        assert sys.holding_forces([theta])[0] == pytest.approx(1.5 * 9.81 * 0.8 * np.sin(theta), rel=1e-12)
        assert heavier.holding_forces([theta])[0] == pytest.approx(3 * sys.holding_forces([theta])[0], rel=1e-12)

    def test_pendulum_motion_is_independent_of_mass(self):
        sys = simple_pendulum().compile(backend="python")
        t = np.linspace(0, 2, 21)
        light = sys.simulate(2.0, [0.5], t_eval=t)
        heavy = sys.simulate(2.0, [0.5], t_eval=t, parameters={"bob.mass": 20.0})
        assert_close(heavy["theta"], light["theta"], rtol=0, atol=1e-9, name="theta(t)")
        assert heavy.energy().total[0] == pytest.approx(20.0 / 1.5 * light.energy().total[0], rel=1e-12)

    def test_longer_pendulum_swings_slower_as_sqrt_length(self):
        sys = simple_pendulum(length=0.8).compile(backend="python")
        q0 = [0.01]
        for length in (0.8, 3.2):
            res = sys.simulate(4.0, q0, t_eval=np.linspace(0, 4, 4001), parameters={"bob.com": (0, 0, -length)})
            y = res["theta"]
            i = np.flatnonzero(np.sign(y[:-1]) != np.sign(y[1:]))
            crossings = res.t[i] - y[i] * (res.t[i + 1] - res.t[i]) / (y[i + 1] - y[i])
            assert 2 * np.mean(np.diff(crossings)) == pytest.approx(2 * np.pi * np.sqrt(length / 9.81), rel=1e-4)

    def test_gravity_rebinds(self):
        sys = simple_pendulum().compile(backend="python")
        moon = sys.with_parameters({"gravity": (0, 0, -1.62)})
        assert moon.holding_forces([0.3])[0] == pytest.approx(sys.holding_forces([0.3])[0] * 1.62 / 9.81, rel=1e-12)

    @pytest.mark.parametrize("values, match", [
        ({"bob.weight": 1.0}, "unknown parameter 'bob.weight'"),
        ({"bob.mass": -1.0}, "mass must be positive"),
        ({"bob.mass": float("nan")}, "must be finite"),
        ({"bob.com": (0, 1)}, "Body 'bob': com must have 3 components, got 2"),
        ({"bob.mass": "heavy"}, "Body 'bob': mass must be a number"),
    ], ids=["unknown", "negative-mass", "nan", "shape", "text"])
    def test_bad_parameter_values_are_rejected(self, values, match):
        sys = simple_pendulum().compile(backend="python")
        with pytest.raises(mb.ModelError, match=match):
            sys.with_parameters(values)
        with pytest.raises(mb.ModelError, match=match):
            sys.simulate(1.0, [0.1], parameters=values)


# ----------------------------------------------------------------------------------
# States, immutability, singularities
# ----------------------------------------------------------------------------------
class TestStates:
    @pytest.fixture
    def arm(self):
        return arm_model().compile(backend="python")

    @pytest.mark.parametrize("q", [[0.1, 0.2], [0.1, 0.2, 0.3, 0.4], [[0.1, 0.2, 0.3]] * 2], ids=["short", "long", "2-d"])
    def test_state_of_wrong_length_is_rejected(self, arm, q):
        with pytest.raises(mb.ModelError, match="q"):
            arm.accelerations(q, [0, 0, 0])

    @pytest.mark.parametrize("bad", [float("nan"), float("inf")], ids=["nan", "inf"])
    def test_non_finite_state_is_rejected_naming_the_coordinate(self, arm, bad):
        with pytest.raises(mb.ModelError, match="beta"):
            arm.accelerations([0.1, bad, 0.3], [0, 0, 0])
        with pytest.raises(mb.ModelError, match="gamma"):
            arm.accelerations([0.1, 0.2, 0.3], [0, 0, bad])
        with pytest.raises(mb.ModelError):
            arm.mass_matrix([bad, 0, 0])
        with pytest.raises(mb.ModelError):
            arm.simulate(1.0, [0, 0, 0], [bad, 0, 0])

    def test_non_numeric_state_is_rejected(self, arm):
        with pytest.raises(mb.ModelError):
            arm.energy(["a", "b", "c"], None)

    def test_dict_state_by_coordinate_name(self, arm):
        q, qd = [0.3, -0.2, 0.9], [0.1, 0.4, -0.3]
        by_name = dict(zip(("gamma", "alpha", "beta"), (q[2], q[0], q[1])))
        speeds = dict(zip(arm.coords, qd))
        assert_close(arm.accelerations(by_name, speeds), arm.accelerations(q, qd), rtol=0, atol=0, name="qdd")
        assert_close(arm.mass_matrix(by_name), arm.mass_matrix(q), rtol=0, atol=0, name="M")
        res = arm.simulate(0.1, by_name, speeds)
        assert_close(res.q[0], q, rtol=0, atol=0, name="initial q")

    def test_dict_state_with_missing_or_unknown_names_is_rejected(self, arm):
        with pytest.raises(mb.ModelError, match="missing coordinate.*gamma"):
            arm.accelerations({"alpha": 0.1, "beta": 0.2}, None)
        with pytest.raises(mb.ModelError, match="unknown coordinate.*delta"):
            arm.accelerations({"alpha": 0.1, "beta": 0.2, "gamma": 0.0, "delta": 1.0}, None)

    def test_tau_of_wrong_length_is_rejected(self, arm):
        with pytest.raises(mb.ModelError, match="tau"):
            arm.accelerations([0, 0, 0], [0, 0, 0], tau=[1.0, 2.0])

    def test_tau_adds_generalised_forces(self, arm):
        q, qd, tau = [0.3, -0.2, 0.9], [0.1, 0.4, -0.3], np.array([0.5, -1.0, 0.25])
        expected = arm.accelerations(q, qd) + np.linalg.solve(arm.mass_matrix(q), tau)
        assert_close(arm.accelerations(q, qd, tau=tau), expected, name="qdd with tau")
        assert_close(arm.accelerations(q, qd, tau=lambda t, q_, qd_: tau), expected, name="qdd with callable tau")

    def test_system_is_immutable(self, arm):
        with pytest.raises(AttributeError):
            arm.coords = ("a", "b", "c")
        with pytest.raises(AttributeError):
            arm.anything = 1
        with pytest.raises(AttributeError):
            arm._p = np.zeros(3)
        assert arm.coords == ("alpha", "beta", "gamma")

    def test_description(self, arm):
        assert arm.coords == ("alpha", "beta", "gamma")
        assert arm.ndof == 3 and arm.nq == 3
        assert arm.formulation == "lagrange"
        assert "arm3d" in repr(arm)


def _gimbal_model(sequence):
    m = mb.Model("gimbal")
    b = m.add(mb.Body("b", mass=1.0, com=(0.1, 0.2, -0.5), inertia=(0.1, 0.2, 0.25)))
    m.add(mb.Spherical("wrist", m.ground, b, sequence=sequence))
    return m.compile(backend="python")


class TestSingularities:
    @pytest.mark.parametrize("sequence, middle", [("zxz", 0.0), ("xyz", np.pi / 2), ("zyx", -np.pi / 2), ("xzx", np.pi)])
    def test_euler_angle_singularity_raises_naming_the_joint(self, sequence, middle):
        sys = _gimbal_model(sequence)
        q = [0.3, middle, -0.4]
        with pytest.raises(mb.SimulationError, match="Spherical 'wrist'.*singularity"):
            sys.accelerations(q, [0.1, 0.2, 0.3])
        with pytest.raises(mb.SimulationError, match="Spherical 'wrist'"):
            sys.simulate(1.0, q)

    def test_mass_matrix_is_available_at_the_singularity(self):
        sys = _gimbal_model("zxz")
        M = sys.mass_matrix([0.3, 0.0, -0.4])
        # First and last columns coincide: rank 2.
        assert_close(M[0], M[2], rtol=0, atol=1e-15, name="rows of the aligned axes")
        assert np.linalg.matrix_rank(M) == 2

    def test_near_the_singularity_accelerations_are_finite(self):
        sys = _gimbal_model("zxz")
        assert np.all(np.isfinite(sys.accelerations([0.3, 1e-3, -0.4], [0.0, 0.0, 0.0])))

    def test_pose_is_available_at_the_singularity(self):
        sys = _gimbal_model("zxz")
        state = sys.body_state("b", [0.3, 0.0, -0.4])
        assert_close(state.rotation, mb.Spherical("w", "a", "b", sequence="zxz").relative_pose([0.3, 0.0, -0.4])[0],
                     atol=1e-15, name="rotation")

    def test_massless_rotation_raises(self):
        # A point mass on the axis of its own revolute joint has no inertia about it.
        m = mb.Model("axle")
        bead = m.add(mb.Body("bead", mass=1.0, com=(0, 0, 0.5)))
        m.add(mb.Revolute("spin", m.ground, bead, axis="z"))
        with pytest.raises(mb.SimulationError, match="singular"):
            m.compile(backend="python").accelerations([0.0], [0.0])


# ----------------------------------------------------------------------------------
# Backends and the cache
# ----------------------------------------------------------------------------------
def _evaluate(sys, rng):
    """Every numeric output at a few random states, for comparisons."""
    out = []
    for _ in range(3):
        q, qd = random_state(sys, rng)
        tau = rng.normal(size=sys.nq)
        out.append(sys.mass_matrix(q).ravel())
        out.append(sys.accelerations(q, qd, tau=tau))
        out.append(sys.holding_forces(q))
        energy = sys.energy(q, qd)
        out.append([energy.kinetic, energy.potential])
        for body in sys.topology.bodies:
            s = sys.body_state(body, q, qd, point=(0.1, 0.2, 0.3))
            out.extend([s.position, s.velocity, s.acceleration, s.rotation.ravel(), s.angular_velocity,
                        s.angular_acceleration])
        out.append(sys.motion_columns(q).ravel())
    return np.concatenate([np.ravel(x) for x in out])


BACKEND_MODELS = {
    "arm": lambda: arm_model(),
    "random-tree": lambda: random_model(1),
    "chain6": lambda: pendulum_chain(6),
}


class TestBackends:
    @pytest.mark.parametrize("make", BACKEND_MODELS.values(), ids=BACKEND_MODELS.keys())
    def test_python_and_c_agree(self, make):
        python, c = make().compile(backend="python"), make().compile(backend="c")
        assert python.backend == "python" and c.backend == "c"
        a, b = _evaluate(python, np.random.default_rng(0)), _evaluate(c, np.random.default_rng(0))
        assert_close(b, a, rtol=1e-12, atol=1e-12, name="C versus Python outputs")

    def test_python_and_c_simulations_agree(self):
        python, c = arm_model().compile(backend="python"), arm_model().compile(backend="c")
        t = np.linspace(0, 1, 11)
        a = python.simulate(1.0, [0.3, -0.2, 0.9], t_eval=t)
        b = c.simulate(1.0, [0.3, -0.2, 0.9], t_eval=t)
        assert_close(b.q, a.q, rtol=1e-12, atol=1e-12, name="q(t)")
        assert_close(b.qd, a.qd, rtol=1e-12, atol=1e-12, name="qd(t)")


class TestCache:
    @pytest.fixture
    def cache(self, tmp_path, monkeypatch):
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(tmp_path))
        return tmp_path

    @pytest.mark.parametrize("backend", ["python", "c"])
    def test_second_compile_is_a_cache_hit_with_identical_results(self, primed_cache_dir, backend):
        first = arm_model().compile(backend=backend)
        assert not first._compiled.cache_hit
        second = arm_model().compile(backend=backend)
        assert second._compiled.cache_hit
        assert second.backend == backend
        a, b = _evaluate(first, np.random.default_rng(1)), _evaluate(second, np.random.default_rng(1))
        assert np.array_equal(a, b)

    @pytest.mark.parametrize("backend", ["python", "c"])
    def test_other_parameter_values_share_the_cached_code(self, primed_cache_dir, backend):
        arm_model().compile(backend=backend)
        m = arm_model()
        m["upper"].mass = 7.0
        m["elbow"].parent_point = (0.0, 0.0, -0.5)
        sys = m.compile(backend=backend)
        assert sys._compiled.cache_hit
        assert sys.parameters["upper.mass"] == 7.0
        reference = arm_model().compile(backend="python", cache=False).with_parameters(
            {"upper.mass": 7.0, "elbow.parent_point": (0.0, 0.0, -0.5)})
        q, qd = [0.3, -0.2, 0.9], [0.1, 0.4, -0.3]
        assert_close(sys.accelerations(q, qd), reference.accelerations(q, qd), rtol=1e-13, name="qdd")

    def test_changed_structure_is_a_cache_miss(self, cache):
        arm_model().compile(backend="python")
        m = arm_model()
        m.add(mb.TorsionSpring("spring", "elbow", stiffness=1.0))
        assert not m.compile(backend="python")._compiled.cache_hit
        other_axis = mb.Model("arm3d")
        other_axis.add(mb.Body("upper", mass=3.0, com=(0, 0, -0.1), inertia=(0.025, 0.025, 0.004)))
        other_axis.add(mb.Body("lower", mass=3.0, com=(0, 0.2, 0), inertia=(0.04, 0.002, 0.04)))
        other_axis.add(mb.Spherical("shoulder", "ground", "upper", sequence="xy", coords=("alpha", "beta")))
        other_axis.add(mb.Revolute("elbow", "upper", "lower", axis="y", parent_point=(0, 0, -0.3), coords="gamma"))
        assert not other_axis.compile(backend="python")._compiled.cache_hit

    @pytest.mark.parametrize("backend", ["python", "c"])
    def test_cache_false_does_not_hit(self, primed_cache_dir, backend):
        arm_model().compile(backend=backend)
        sys = arm_model().compile(backend=backend, cache=False)
        assert not sys._compiled.cache_hit
        assert sys.backend == backend

    def test_cache_false_with_python_backend_writes_nothing(self, cache):
        arm_model().compile(backend="python", cache=False)
        assert list(cache.iterdir()) == []

    def test_cache_false_with_c_backend_writes_nothing(self, cache):
        arm_model().compile(backend="c", cache=False)
        assert list(cache.iterdir()) == []

    def test_cache_directory_follows_the_environment(self, cache):
        arm_model().compile(backend="python")
        assert any(path.suffix == ".py" for path in cache.iterdir())


class TestSymbolicDisplay:
    """``equations()`` gives M and f that evaluate to the numeric ones; LaTeX for small models."""

    def test_equations_evaluate_to_the_numeric_mass_matrix_and_forces(self, double_pendulum):
        import sympy as sp
        sys = double_pendulum.compile()
        M, f = sys.equations()
        q, qd = np.array([0.4, -0.7]), np.array([1.2, -0.3])
        values = {}
        for key, value in sys.parameters.items():
            if np.ndim(value):
                values.update({sp.Symbol(f"{key}[{i}]"): v for i, v in enumerate(value)})
            else:
                values[sp.Symbol(key)] = value
        values.update({sp.Symbol(c): v for c, v in zip(sys.coords, q)})
        values.update({sp.Symbol(f"\\dot{{{c}}}"): v for c, v in zip(sys.coords, qd)})
        M_num = np.array(M.xreplace(values).evalf(), dtype=float)
        f_num = np.array(f.xreplace(values).evalf(), dtype=float).reshape(-1)
        assert_close(M_num, sys.mass_matrix(q), rtol=1e-12, name="symbolic M")
        assert_close(np.linalg.solve(M_num, f_num), sys.accelerations(q, qd), rtol=1e-10, name="symbolic f")

    def test_latex_for_small_models_only(self, double_pendulum):
        sys = double_pendulum.compile()
        latex = sys._repr_latex_()
        assert latex.startswith("$") and "\\ddot{j1}" in latex
        assert pendulum_chain(5).compile()._repr_latex_() is None
