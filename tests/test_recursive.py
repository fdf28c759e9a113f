"""The recursive (articulated-body, O(N)) tree dynamics against the dense mass-matrix path:
the same accelerations to rounding on every library model and on every joint kind, the same
trajectories, an analytic pendulum, the automatic choice and its place in the cache key."""
from __future__ import annotations

import math

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.build import recursive
from mbcomp.files.toml_model import library_models

from conftest import pendulum_chain


def tree_accelerations(system, t, q, qd, tau):
    """The unconstrained tree accelerations of a System (its compiled or generated solve)."""
    return system.kernel.tree_accelerations(t, q, qd, tau)


def dense_solution(system, t, q, qd, tau):
    """``M^-1 (f + tau)`` from the dense mass matrix and forces, solved by numpy."""
    M, f = system.tree_dynamics(q, qd, t)
    return np.linalg.solve(M, f + tau), M


def random_state(system, rng):
    q = rng.uniform(-1.5, 1.5, system.nq)
    return q, rng.uniform(-2.0, 2.0, system.nv), rng.uniform(-1.0, 1.0, system.nv)


def assert_same_accelerations(recursive_qdd, dense_qdd, M):
    """Equal to rounding: within a few eps times the condition number of M, relative to the
    largest acceleration (two exact algorithms, different rounding)."""
    scale = max(float(np.max(np.abs(dense_qdd))), 1.0)
    bound = 1e-14 * max(np.linalg.cond(M), 1.0) + 1e-13
    assert np.max(np.abs(recursive_qdd - dense_qdd)) <= bound * scale, (recursive_qdd, dense_qdd, bound)


@pytest.mark.parametrize("name", sorted(library_models()))
def test_every_library_model_has_the_dense_tree_accelerations(name):
    """The generated recursive program (Python backend: no C compile) reproduces
    ``M^-1 (f + tau)`` of the dense program at random states and torques."""
    model = mb.load(library_models()[name])
    system = model.compile(backend="python", dynamics="recursive")
    assert system.kernel.compiled.dynamics == "recursive"
    rng = np.random.default_rng(sum(map(ord, name)))
    for _ in range(3):
        q, qd, tau = random_state(system, rng)
        expected, M = dense_solution(system, 0.3, q, qd, tau)
        assert_same_accelerations(tree_accelerations(system, 0.3, q, qd, tau), expected, M)


def every_joint_model() -> mb.Model:
    """A tree with every joint kind, springs, a callable torque, a force and a geared drive."""
    m = mb.Model("zoo", gravity=(0.3, -0.2, -9.81))
    inertia = (0.02, 0.03, 0.04)
    bodies = [m.add(mb.Body(f"b{i}", mass=1.0 + 0.1 * i, com=(0.05, -0.02, -0.1), inertia=inertia)) for i in range(9)]
    m.add(mb.Free("free", m.ground, bodies[0], parent_point=(0, 0, 1)))
    m.add(mb.Ball("ball", bodies[0], bodies[1], parent_point=(0, 0, -0.2)))
    m.add(mb.Spherical("euler", bodies[1], bodies[2], sequence="zyx", parent_point=(0.1, 0, -0.2)))
    m.add(mb.Universal("universal", bodies[2], bodies[3], axes=("x", "y"), parent_point=(0, 0.1, -0.2)))
    m.add(mb.Cylindrical("cylinder", bodies[3], bodies[4], axis=(0.0, 0.6, 0.8), parent_point=(0, 0, -0.2)))
    m.add(mb.Planar("planar", bodies[4], bodies[5], normal="y", parent_point=(0, 0, -0.2)))
    m.add(mb.Prismatic("slide", bodies[5], bodies[6], axis="z", parent_point=(0, 0, -0.2)))
    m.add(mb.Fixed("weld", bodies[6], bodies[7], parent_point=(0.1, 0, 0)))
    m.add(mb.Revolute("hinge", bodies[2], bodies[8], axis="y", parent_point=(0, -0.1, -0.1)))  # a branch
    m.add(mb.Spring("spring", a=(m.ground, (0, 0, 1.2)), b=(bodies[1], (0, 0, -0.1)), stiffness=20.0, damping=0.5))
    m.add(mb.TorsionSpring("twist", "hinge", stiffness=3.0, rest=0.2, damping=0.1))
    m.add(mb.JointTorque("push", "slide", lambda t, q, qd: [0.5 * math.sin(3 * t)]))
    m.add(mb.Force("wind", bodies[7], (0, 0.1, 0), (0.4, 0.0, 0.1)))
    m.add(mb.Drive("motor", "hinge", ratio=8.0, rotor_inertia=2e-3, torque=0.05))
    return m


@pytest.fixture(scope="module")
def zoo_pair():
    """The every-joint tree with both programs, Python backend (no C compile: fast)."""
    model = every_joint_model()
    return model.compile(dynamics="dense", backend="python"), model.compile(dynamics="recursive", backend="python")


def unit_quaternions(q, *slices):
    for sl in slices:
        q[sl] /= np.linalg.norm(q[sl])
    return q


@pytest.mark.xdist_group("joint-zoo")  # (the module fixture is built once)
def test_every_joint_kind_accelerations_agree(zoo_pair):
    """Free, Ball, Euler spherical, Universal, Cylindrical, Planar, Prismatic, Fixed and a
    branch, with springs, a callable torque, a point force and a drive's reflected inertia on
    the diagonal: the public accelerations (with tau) agree to rounding."""
    dense, rec = zoo_pair
    assert (dense.kernel.compiled.dynamics, rec.kernel.compiled.dynamics) == ("dense", "recursive")
    assert dense.nq == rec.nq == dense.nv + 2  # two quaternions
    rng = np.random.default_rng(7)
    for t in (0.0, 0.4):
        q, qd, tau = random_state(dense, rng)
        q = unit_quaternions(q, slice(3, 7), slice(7, 11))
        assert_same_accelerations(rec.accelerations(q, qd, t, tau=tau), dense.accelerations(q, qd, t, tau=tau),
                                  dense.mass_matrix(q, t))


@pytest.mark.xdist_group("joint-zoo")  # (the module fixture is built once)
def test_every_joint_kind_trajectories_agree(zoo_pair):
    """Stepped in Python (scipy's DOP853), both programs give the same trajectory."""
    dense, rec = zoo_pair
    q0 = np.zeros(dense.nq)
    q0[3] = q0[7] = 1.0  # identity quaternions (free, ball)
    qd0 = np.linspace(-0.5, 0.5, dense.nv)
    a = dense.simulate(0.1, q0, qd0, rtol=1e-8, atol=1e-8)
    b = rec.simulate(0.1, q0, qd0, rtol=1e-8, atol=1e-8)
    assert a.t[-1] == b.t[-1] == 0.1
    np.testing.assert_allclose(b.q[-1], a.q[-1], rtol=0, atol=1e-11)
    np.testing.assert_allclose(b.qd[-1], a.qd[-1], rtol=0, atol=1e-10)


def ball_chain(n: int) -> mb.Model:
    """A floating body with a chain of ``n`` bodies on ball joints hanging from it, one of
    them driven through a gear (the drive's reflected inertia is on the diagonal)."""
    m = mb.Model(f"balls{n}", gravity=(0, 0, -9.81))
    parent = m.add(mb.Body("base", mass=2.0, com=(0, 0, 0), inertia=(0.1, 0.2, 0.15)))
    m.add(mb.Free("float", m.ground, parent))
    for i in range(n):
        body = m.add(mb.Body(f"link{i}", mass=1.0, com=(0.02, 0, -0.2), inertia=(0.02, 0.018, 0.004)))
        m.add(mb.Ball(f"ball{i}", parent, body, parent_point=(0, 0, -0.4 if i else -0.1)))
        parent = body
    tip = m.add(mb.Body("tip", mass=0.5, com=(0, 0, -0.1), inertia=(0.002, 0.002, 0.001)))
    m.add(mb.Revolute("wrist", parent, tip, axis="y", parent_point=(0, 0, -0.4)))
    m.add(mb.Drive("servo", "wrist", ratio=20.0, rotor_inertia=1e-4, torque=0.01))
    return m


@pytest.fixture(scope="module")
def ball_pair():
    model = ball_chain(2)
    return model.compile(), model.compile(dynamics="dense")


@pytest.mark.xdist_group("ball-chain")  # (the module fixture is built once)
def test_ball_chain_compiled_accelerations_agree(ball_pair):
    """Compiled C, a Free and two Ball joints (13 speeds: auto chooses the recursive program);
    the dynamics choice is part of the cache key."""
    auto, dense = ball_pair
    assert auto.kernel.compiled.dynamics == "recursive" and dense.kernel.compiled.dynamics == "dense"
    assert auto.backend == dense.backend == "c"
    assert auto.kernel.compiled.key != dense.kernel.compiled.key
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, qd, tau = random_state(dense, rng)
        q = unit_quaternions(q, slice(3, 7), slice(7, 11), slice(11, 15))
        assert_same_accelerations(auto.accelerations(q, qd, tau=tau), dense.accelerations(q, qd, tau=tau),
                                  dense.mass_matrix(q))


@pytest.mark.xdist_group("ball-chain")  # (the module fixture is built once)
def test_ball_chain_compiled_trajectories_agree(ball_pair):
    """The compiled integrators give the same trajectories with either program: fixed-step
    RK4 at every step; adaptive DOP853 at the end (its step sizes follow error estimates that
    are differences of nearly equal numbers, so the sample times differ in the 6th digit while
    the solution agrees to rounding)."""
    auto, dense = ball_pair
    q0 = np.zeros(dense.nq)
    q0[[3, 7, 11]] = 1.0
    qd0 = np.linspace(-1.0, 1.0, dense.nv)
    a = dense.simulate(0.5, q0, qd0, method="RK4", dt=1e-3)
    b = auto.simulate(0.5, q0, qd0, method="RK4", dt=1e-3)
    assert a.q.shape == b.q.shape == (501, dense.nq)
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.qd, a.qd, rtol=0, atol=1e-11)
    a = dense.simulate(0.5, q0, qd0, rtol=1e-10, atol=1e-10)
    b = auto.simulate(0.5, q0, qd0, rtol=1e-10, atol=1e-10)
    assert a.t[-1] == b.t[-1] == 0.5
    np.testing.assert_allclose(b.q[-1], a.q[-1], rtol=0, atol=1e-11)
    np.testing.assert_allclose(b.qd[-1], a.qd[-1], rtol=0, atol=1e-10)


def test_pendulum_matches_the_closed_form():
    """A rod pendulum: qdd = (tau - m g c sin q) / (I_c + m c^2) by the recursive program."""
    mass, c, inertia, g = 2.0, 0.3, 0.05, 9.81
    m = mb.Model("pendulum", gravity=(0, 0, -g))
    rod = m.add(mb.Body("rod", mass=mass, com=(0, 0, -c), inertia=(inertia, inertia, 1e-3)))
    m.add(mb.Revolute("pivot", m.ground, rod, axis="x"))
    system = m.compile(dynamics="recursive", backend="python")
    for q, tau in ((0.4, 0.0), (-1.2, 0.7), (2.5, -0.3)):
        expected = (tau - mass * g * c * math.sin(q)) / (inertia + mass * c * c)
        assert system.accelerations([q], [0.3], tau=[tau])[0] == pytest.approx(expected, rel=1e-13)


def structure(model):
    """The compiled structure (topology) of a model, without generating code."""
    from mbcomp.build.flatten import flatten
    from mbcomp.build.topology import build_topology
    return build_topology(flatten(model.flat()))


def test_auto_choice_by_size_and_structure():
    small, large = structure(pendulum_chain(2)), structure(pendulum_chain(recursive.CROSSOVER_NV))
    assert recursive.choose("auto", small) == "dense"
    assert recursive.choose("auto", large) == "recursive"
    assert recursive.choose("dense", large) == "dense"
    assert recursive.choose("recursive", small) == "recursive"
    assert recursive.choose("auto", structure(mb.load(library_models()["four_bar"]))) == "dense"  # constraints


def test_bad_dynamics_option_names_it():
    with pytest.raises(mb.ModelError, match="dynamics must be one of 'auto', 'dense', 'recursive'"):
        pendulum_chain(2).compile(dynamics="fast", backend="python")


def test_singular_mass_matrix_is_diagnosed_as_in_the_dense_path():
    """A point mass on the axis of its revolute joint: the pivot is zero, and the call falls
    back to the dense path, which raises a SimulationError naming the singular mass matrix."""
    m = mb.Model("axis", gravity=(0, 0, -9.81))
    bead = m.add(mb.Body("bead", mass=1.0))
    m.add(mb.Revolute("spin", m.ground, bead, axis="z"))
    system = m.compile(dynamics="recursive", backend="python")
    with pytest.raises(mb.SimulationError, match="mass matrix is singular"):
        system.accelerations([0.1], [0.0])


def test_speed_tree_of_a_branched_model():
    """Every speed's predecessor node: within a joint the previous speed, across joints the
    parent body's last speed; a welded body hangs on its parent's node."""
    system = every_joint_model().compile(backend="python", dynamics="dense")
    pred, attach = recursive.speed_tree(system.topology)
    v = system.topology.v_slice
    assert pred[0] is None and pred[1:6] == [0, 1, 2, 3, 4]          # free: 3 + 3 speeds
    assert pred[v["ball"].start] == 5                                # ball after free
    assert pred[v["hinge"].start] == v["universal"].start - 1        # branch off the euler body
    assert attach["b7"] == attach["b6"] == v["slide"].start          # welded to b6


def test_pickled_system_keeps_its_dynamics():
    """A System rebuilt elsewhere (process pools, clusters) compiles the same program."""
    import pickle
    system = pendulum_chain(3).compile(dynamics="recursive", backend="python")
    again = pickle.loads(pickle.dumps(system))
    assert again.kernel.compiled.dynamics == "recursive"
    q, qd = np.array([0.1, -0.4, 0.9]), np.array([0.3, 0.0, -0.2])
    np.testing.assert_array_equal(again.accelerations(q, qd), system.accelerations(q, qd))


def chain_on_rail(n: int) -> mb.Model:
    """The pendulum chain with its tip held on the vertical line through the pivot (a slider:
    two constraint rows)."""
    m = pendulum_chain(n)
    m.add(mb.Slider("rail", f"link{n - 1}", (0, 0, -0.5), origin=(0, 0, 0), axis=(0, 0, 1)))
    return m


def test_dae_compiled_kkt_solve_by_the_recursion():
    """The dae formulation's compiled KKT solve with M^-1 J^T from the articulated-body
    factors gives the dense solve's trajectory (fixed-step RK4, compiled loop, projection on)."""
    model = chain_on_rail(4)
    dense, rec = model.compile("dae", dynamics="dense"), model.compile("dae", dynamics="recursive")
    assert rec.kernel.compiled.dynamics == "recursive"
    q, qd = dense.assemble(np.zeros(4), np.array([0.5, 0.7, 0.9, 1.0]))
    a = dense.simulate(0.5, q, qd, method="RK4", dt=1e-3)
    b = rec.simulate(0.5, q, qd, method="RK4", dt=1e-3)
    assert a.stats["integrator"] == b.stats["integrator"] == "compiled"
    np.testing.assert_allclose(b.q, a.q, rtol=0, atol=1e-12)
    assert b.constraint_violation().max() < 1e-9


def test_motor_only_constraints_with_the_recursive_program():
    """A motor adds a constraint equation but no geometric row: the recursive program then
    carries no KKT factors (the compiled and generated outputs must agree in size)."""
    model = pendulum_chain(2)
    model.add(mb.Motor("drive", "joint0", speed=1.0))
    dense, rec = model.compile(dynamics="dense"), model.compile(dynamics="recursive")
    q, qd = np.array([0.2, -0.3]), np.array([1.0, 0.4])
    np.testing.assert_allclose(rec.accelerations(q, qd), dense.accelerations(q, qd), rtol=1e-12, atol=1e-12)
    rng = np.random.default_rng(5)
    tau = rng.uniform(-1, 1, 2)
    expected, M = dense_solution(dense, 0.0, q, qd, tau)
    assert_same_accelerations(tree_accelerations(rec, 0.0, q, qd, tau), expected, M)


def test_auto_choice_for_constrained_models():
    """With constraints: dense under lagrange; recursive under dae from DAE_CROSSOVER_NV speeds."""
    topology = structure(chain_on_rail(recursive.DAE_CROSSOVER_NV))
    assert recursive.choose("auto", topology, formulation="lagrange") == "dense"
    assert recursive.choose("auto", topology, formulation="dae") == "recursive"
    small = structure(chain_on_rail(3))
    assert recursive.choose("auto", small, formulation="dae") == "dense"
    # with contacts the dense KKT solve, which takes their friction rows in the compiled loop
    touching = chain_on_rail(recursive.DAE_CROSSOVER_NV)
    touching.add(mb.Contact("floor", "link0", (0, 0, -0.5), normal=(0, 0, 1), friction=0.3, radius=0.05))
    assert recursive.choose("auto", structure(touching), formulation="dae") == "dense"
