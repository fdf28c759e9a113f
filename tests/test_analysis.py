"""Analysis: equilibrium, linearisation, modes, Jacobian, inverse dynamics.

Every number is checked against an analytic solution or an independent computation
(finite differences of the public API written out here, energy along the constraint
manifold, sympy's Linearizer on the same mechanism)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize

import mbcomp as mb
from mbcomp.analysis import Linearization, Modes

from conftest import G, arm_model, assert_close, fourbar, pendulum_chain


def point_pendulum(length=1.0, mass=1.0, spring=None, damping=0.0, name="pendulum"):
    """A point mass on a massless rod about the world x axis (gravity -z); ``spring``:
    ``(stiffness, rest)`` of a torsion spring on the joint."""
    m = mb.Model(name, gravity=(0, 0, -G))
    bob = m.add(mb.Body("bob", mass=mass, com=(0, 0, -length)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    if spring is not None or damping:
        k, rest = spring or (0.0, 0.0)
        m.add(mb.TorsionSpring("spring", "pivot", stiffness=k, rest=rest, damping=damping))
    return m


def double_point_pendulum(length=1.0, mass=1.0):
    m = mb.Model("dpp", gravity=(0, 0, -G))
    a = m.add(mb.Body("a", mass=mass, com=(0, 0, -length)))
    b = m.add(mb.Body("b", mass=mass, com=(0, 0, -length)))
    m.add(mb.Revolute("j1", m.ground, a, axis="x"))
    m.add(mb.Revolute("j2", a, b, axis="x", parent_point=(0, 0, -length)))
    return m


@pytest.fixture(scope="module")
def pendulum():
    return point_pendulum(length=0.8).compile()


@pytest.fixture(scope="module")
def fourbars():
    return {form: fourbar().compile(formulation=form) for form in ("lagrange", "dae")}


# -- modes -----------------------------------------------------------------------------------------
def test_simple_pendulum_frequency_is_sqrt_g_over_l(pendulum):
    modes = pendulum.modes([0.0])
    assert isinstance(modes, Modes)
    assert_close(modes.frequencies, [np.sqrt(G / 0.8) / (2 * np.pi)], rtol=1e-8, name="frequency")
    assert_close(modes.damping_ratios, [0.0], atol=1e-7, name="damping ratio")
    assert modes.stable and modes.unstable == 0
    assert_close(modes.shapes, [[1.0]], name="shape")


def test_inverted_pendulum_is_unstable_with_growth_rate_sqrt_g_over_l(pendulum):
    modes = pendulum.modes([np.pi])
    assert not modes.stable and modes.unstable == 1
    assert_close(modes.eigenvalues.real, [np.sqrt(G / 0.8)], rtol=1e-8, name="growth rate")
    assert_close(modes.damping_ratios, [-1.0], name="damping ratio")


def test_double_pendulum_frequencies_are_the_analytic_ones():
    # equal point masses and lengths: omega^2 = (2 -+ sqrt 2) g / l
    modes = double_point_pendulum(length=0.5).compile().modes([0.0, 0.0])
    expected = np.sqrt((2 - np.sqrt(2)) * G / 0.5), np.sqrt((2 + np.sqrt(2)) * G / 0.5)
    assert_close(modes.frequencies, np.array(expected) / (2 * np.pi), rtol=1e-8, name="frequencies")
    # absolute-angle shapes (1, sqrt 2) and (1, -sqrt 2); the coordinates are relative
    # (theta2 = phi2 - phi1): (1, sqrt 2 - 1) and (1, -sqrt 2 - 1), largest entry 1
    assert_close(modes.shapes[:, 0], [1.0, np.sqrt(2) - 1], rtol=1e-6, name="slow shape")
    assert_close(modes.shapes[:, 1], [-1 / (1 + np.sqrt(2)), 1.0], rtol=1e-6, name="fast shape")


def test_damped_pendulum_damping_ratio():
    c, L = 0.3, 1.0  # torsional damping c: zeta = c / (2 m L^2 omega)
    modes = point_pendulum(length=L, damping=c, name="damped").compile().modes([0.0])
    omega = np.sqrt(G / L)
    assert_close(modes.damping_ratios, [c / (2 * omega)], rtol=1e-7, name="damping ratio")
    assert_close(modes.frequencies, [omega / (2 * np.pi)], rtol=1e-7, name="natural frequency")


@pytest.mark.parametrize("inertia, expected", [
    (True, [-2.34625412193255, 19.8527369182644, 41.1805759758834]),
    (False, [-2.56054267393227, 21.5802062070371, 56.5276415528563])])
def test_held_seed_arm_pose_matches_the_reference_eigenvalues(inertia, expected):
    """Seed case arm3d.c.torques: held at (110, -20, -20) deg by constant torques,
    eig(Mbar^-1 dQgrav/dq) as given (positive = unstable): two divergent modes."""
    arm = arm_model(inertia).compile()
    q = np.radians([110.0, -20.0, -20.0])
    held = arm.modes(q, tau=arm.holding_forces(q))
    lin = held.linearization
    assert_close(np.sort(np.linalg.eigvals(lin.A[3:, :3]).real), expected, rtol=1e-8, name="eig")
    assert not held.stable and held.unstable == 2
    # oscillation at sqrt(2.346) rad/s, divergence rates sqrt(19.85) and sqrt(41.18) 1/s
    assert_close(held.frequencies, np.sqrt(np.abs(expected)) / (2 * np.pi), rtol=1e-8, name="frequencies")
    assert_close(held.damping_ratios, [0.0, -1.0, -1.0], atol=1e-9, name="damping ratios")


def test_modes_refuse_a_pose_that_is_not_an_equilibrium_unless_held(pendulum):
    with pytest.raises(mb.SimulationError, match="not an equilibrium"):
        pendulum.modes([0.5])
    held = pendulum.modes([0.5], tau=pendulum.holding_forces([0.5]))
    # held by a constant torque m g L sin(0.5): stiffness m g L cos(0.5)
    assert_close(held.frequencies, [np.sqrt(G / 0.8 * np.cos(0.5)) / (2 * np.pi)], rtol=1e-7, name="held")


# -- linearisation ---------------------------------------------------------------------------------
def test_linearize_matches_central_differences_of_the_accelerations():
    arm = arm_model().compile()
    q, qd = np.array([0.3, -0.4, 0.7]), np.array([0.5, -0.2, 0.9])
    lin = arm.linearize(q, qd, inputs=["shoulder", "elbow"])
    assert isinstance(lin, Linearization)
    assert lin.states == ("alpha", "beta", "gamma", "alpha_dot", "beta_dot", "gamma_dot")
    assert lin.inputs == ("alpha", "beta", "gamma")
    h = 1e-5
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        dq = (arm.accelerations(q + e, qd) - arm.accelerations(q - e, qd)) / (2 * h)
        dv = (arm.accelerations(q, qd + e) - arm.accelerations(q, qd - e)) / (2 * h)
        assert_close(lin.A[3:, j], dq, rtol=1e-6, atol=1e-7, name=f"dqdd/dq{j}")
        assert_close(lin.A[3:, 3 + j], dv, rtol=1e-6, atol=1e-7, name=f"dqdd/dqd{j}")
    assert_close(lin.A[:3], np.hstack((np.zeros((3, 3)), np.eye(3))), name="kinematic rows")
    assert_close(lin.B[3:], np.linalg.inv(arm.mass_matrix(q)), rtol=1e-9, name="B = M^-1")
    assert_close(lin.B[:3], np.zeros((3, 3)), name="B kinematic rows")


def test_four_bar_in_both_formulations_has_one_dof_and_the_same_linearisation(fourbars):
    lins = {}
    for form, system in fourbars.items():
        assert system.ndof == 1
        q = system.equilibrium([-1.5, 1.2, -1.5])
        lins[form] = system.linearize(q, independent=["A"], inputs="A")
        assert lins[form].A.shape == (2, 2) and lins[form].states == ("A", "A_dot")
    assert_close(lins["dae"].A, lins["lagrange"].A, rtol=1e-8, atol=1e-8, name="A dae vs lagrange")
    assert_close(lins["dae"].B, lins["lagrange"].B, rtol=1e-8, name="B dae vs lagrange")


def test_four_bar_frequency_from_energy_along_the_manifold(fourbars):
    """omega^2 = V''(theta) / m(theta), with V and m = 2 T(theta_dot = 1) from sys.energy on
    assembled configurations (an independent route)."""
    system = fourbars["lagrange"]
    q0 = system.equilibrium([-1.5, 1.2, -1.5])
    h = 1e-3

    def at(theta):  # assemble with the crank held at theta (Newton on the other two)
        q = q0.copy()
        for _ in range(30):
            cv = system.constraint_values(q)
            rows = [0, 1]
            q[1:] -= np.linalg.solve(cv.J[np.ix_(rows, [1, 2])], cv.g[rows])
            q[0] = theta
        return q

    V = [system.energy(at(q0[0] + s * h), np.zeros(3)).potential for s in (-1, 0, 1)]
    stiffness = (V[0] - 2 * V[1] + V[2]) / h ** 2
    _, qd = system.assemble(q0, [1.0, 0.0, 0.0])
    qd = qd / qd[0]
    mass = 2 * system.energy(q0, qd).kinetic
    f = np.sqrt(stiffness / mass) / (2 * np.pi)
    assert_close(system.modes(q0).frequencies, [f], rtol=1e-5, name="four-bar frequency")
    assert system.modes(q0).stable


def test_linearize_agrees_with_sympy_linearizer_on_a_four_bar(fourbars):
    me = pytest.importorskip("sympy.physics.mechanics", exc_type=ImportError)
    L1, L2, L3, d = 0.3, 0.8, 0.6, 0.7
    q1, q2, q3 = me.dynamicsymbols("q1:4")
    u1, u2, u3 = me.dynamicsymbols("u1:4")
    N = me.ReferenceFrame("N")
    A = N.orientnew("A", "Axis", (q1, N.z))
    B = A.orientnew("B", "Axis", (q2, A.z))
    C = N.orientnew("C", "Axis", (q3, N.z))
    A.set_ang_vel(N, u1 * N.z)
    B.set_ang_vel(A, u2 * A.z)
    C.set_ang_vel(N, u3 * N.z)
    O = me.Point("O")
    O.set_vel(N, 0)
    D = O.locatenew("D", d * N.x)
    D.set_vel(N, 0)
    P1 = O.locatenew("P1", L1 * A.x)
    P2 = P1.locatenew("P2", L2 * B.x)
    P3 = D.locatenew("P3", L3 * C.x)
    bodies, loads = [], []
    for frame, origin, L, name in ((A, O, L1, "crank"), (B, P1, L2, "coupler"), (C, D, L3, "rocker")):
        cm = origin.locatenew(name + "_cm", L / 2 * frame.x)
        cm.v2pt_theory(origin, N, frame)
        inertia = me.inertia(frame, 1e-4, L ** 2 / 12, L ** 2 / 12)
        bodies.append(me.RigidBody(name, cm, frame, 1.0, (inertia, cm)))
        loads.append((cm, -G * N.y))
    P1.v2pt_theory(O, N, A)
    P2.v2pt_theory(P1, N, B)
    P3.v2pt_theory(D, N, C)
    loop = P2.pos_from(O) - P3.pos_from(O)
    gap_speed = P2.vel(N) - P3.vel(N)
    kane = me.KanesMethod(N, q_ind=[q1], q_dependent=[q2, q3], u_ind=[u1], u_dependent=[u2, u3],
                          kd_eqs=[q1.diff() - u1, q2.diff() - u2, q3.diff() - u3],
                          configuration_constraints=[loop.dot(N.x), loop.dot(N.y)],
                          velocity_constraints=[gap_speed.dot(N.x), gap_speed.dot(N.y)])
    kane.kanes_equations(bodies, loads)
    system = fourbars["lagrange"]
    assert system.coords == ("A", "B", "D")
    q, qd = system.assemble([0.4, 1.0, 1.5], [1.3, 0.0, 0.0])  # moving, away from equilibrium
    qdd = system.accelerations(q, qd)
    op = {q1: q[0], q2: q[1], q3: q[2], u1: qd[0], u2: qd[1], u3: qd[2]}
    op.update({q1.diff(): qd[0], q2.diff(): qd[1], q3.diff(): qd[2],
               u1.diff(): qdd[0], u2.diff(): qdd[1], u3.diff(): qdd[2]})
    A_sym, _ = kane.to_linearizer().linearize(op_point=op, A_and_B=True)
    lin = system.linearize(q, qd, independent=["A"])
    assert_close(lin.A, np.array(A_sym, dtype=float), rtol=1e-8, atol=1e-9, name="A vs sympy Linearizer")


def test_linearize_includes_drive_states():
    """A DC motor on a pendulum: states theta, omega, current; the textbook model
    I_eff w' = -m g l theta + n k i, L i' = -R i - k n w, I_eff = I + n^2 J_r."""
    n, R, L, k, Jr, length = 10.0, 2.0, 0.01, 0.05, 1e-4, 0.5
    model = mb.Model("servo", gravity=(0, 0, -G))
    bob = model.add(mb.Body("bob", mass=1.0, com=(0, 0, -length)))
    model.add(mb.Revolute("pivot", model.ground, bob, axis="x", coords="theta"))
    model.add(mb.DCMotor("motor", "pivot", ratio=n, resistance=R, inductance=L, k=k, voltage=0.0,
                         rotor_inertia=Jr))
    system = model.compile()
    lin = system.linearize([0.0], inputs="pivot")
    assert lin.states == ("theta", "theta_dot", "motor.current")
    inertia = length ** 2 + n ** 2 * Jr
    expected = [[0, 1, 0], [-G * length / inertia, 0, n * k / inertia], [0, -k * n / L, -R / L]]
    assert_close(lin.A, expected, rtol=1e-8, atol=1e-8, name="A with a motor current")
    assert_close(lin.B, [[0], [1 / inertia], [0]], rtol=1e-10, name="B")
    assert system.modes([0.0]).stable  # the back EMF damps the swing


def test_linearize_rejects_bad_inputs(pendulum, fourbars):
    with pytest.raises(mb.ModelError, match="neither a joint nor a speed"):
        pendulum.linearize([0.0], inputs="nope")
    with pytest.raises(mb.ModelError, match="must name 1 speed"):
        fourbars["lagrange"].linearize([-1.6, 1.2, -1.5], independent=["A", "B"])


def test_to_control_is_optional_or_works(pendulum):
    lin = pendulum.linearize([0.0], inputs="pivot")
    try:
        import control  # noqa: F401
    except ImportError:
        with pytest.raises(ImportError, match="python-control"):
            lin.to_control()
        return
    sys_ss = lin.to_control()
    assert_close(sys_ss.A, lin.A, name="A")


# -- equilibrium -----------------------------------------------------------------------------------
def test_equilibrium_of_a_spring_loaded_pendulum_from_a_poor_guess():
    m, L, k, rest = 1.5, 0.7, 12.0, 1.2
    system = point_pendulum(length=L, mass=m, spring=(k, rest)).compile()
    # at rest: -k (theta - rest) - m g L sin(theta) = 0
    exact = scipy.optimize.brentq(lambda th: -k * (th - rest) - m * G * L * np.sin(th), 0.0, rest)
    q = system.equilibrium([-2.0])
    assert_close(q, [exact], rtol=1e-10, name="equilibrium angle")
    assert system.modes(q).stable


def test_equilibrium_with_tau_and_of_the_four_bar(fourbars):
    system = point_pendulum(length=1.0).compile()
    # a constant torque T balances the gravity torque -m g L sin(theta) at sin(theta) = T / (m g L)
    q = system.equilibrium([0.1], tau=[0.5 * G])
    assert_close(np.sin(q), [0.5], rtol=1e-10, name="sin(theta)")
    for form, fb in fourbars.items():
        q = fb.equilibrium([0.3, 0.5, 2.0])  # far from rest
        assert fb.constraint_violation(q) < 1e-10
        assert_close(mb.analysis.reduced_forces(fb, q), [0.0], atol=1e-8, name=f"{form} reduced force")
        assert np.max(np.abs(fb.accelerations(q, np.zeros(3)))) < 1e-7


def test_equilibrium_and_inverse_dynamics_count_drive_torques():
    """A geared drive with a constant torque T: it balances gravity at sin(theta) = n T / (m g L)
    and adds n^2 J_r to the inertia."""
    model = point_pendulum(length=1.0, name="driven")
    model.add(mb.Drive("drive", "pivot", ratio=5.0, rotor_inertia=0.01, torque=0.1 * G))
    system = model.compile()
    q = system.equilibrium([0.0])
    assert_close(np.sin(q), [0.5], rtol=1e-10, name="sin(theta)")
    assert system.modes(q).stable
    tau = system.inverse_dynamics([0.2], [0.3], [1.5])
    assert_close(system.accelerations([0.2], [0.3], tau=tau), [1.5], rtol=1e-10, name="round trip")
    assert_close(tau, [(1.0 + 25 * 0.01) * 1.5 + G * np.sin(0.2) - 0.5 * G], rtol=1e-10, name="tau")


def test_equilibrium_reports_when_there_is_none():
    system = point_pendulum(length=1.0).compile()
    with pytest.raises(mb.SimulationError, match="no equilibrium found near"):
        system.equilibrium([0.3], tau=[2 * G])  # torque above m g L: no balance anywhere


# -- Jacobian --------------------------------------------------------------------------------------
def test_jacobian_gives_point_velocity_and_angular_velocity():
    arm = arm_model().compile()
    q, qd = np.array([0.3, -0.4, 0.7]), np.array([0.5, -0.2, 0.9])
    point = (0.0, 0.4, 0.05)
    J = arm.jacobian("lower", q, point=point)
    state = arm.body_state("lower", q, qd, point=point)
    assert J.shape == (6, 3)
    assert_close(J[:3] @ qd, state.angular_velocity, name="angular velocity")
    assert_close(J[3:] @ qd, state.velocity, name="point velocity")
    # columns by central differences of the point's position (independent of the motion columns)
    h = 1e-6
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        col = (arm.body_state("lower", q + e, point=point).position
               - arm.body_state("lower", q - e, point=point).position) / (2 * h)
        assert_close(J[3:, j], col, rtol=1e-7, atol=1e-9, name=f"column {j}")
    # the upper arm does not move with the elbow; the default point is the COM
    assert_close(arm.jacobian("upper", q)[:, 2], np.zeros(6), name="elbow column of upper")
    assert_close(arm.jacobian("lower", q)[3:] @ qd, arm.body_state("lower", q, qd).velocity, name="COM")
    model = arm_model()
    tip = model["lower"].frame((0.0, 0.4, 0.05))
    assert_close(model.compile().jacobian(tip, q), J, name="Frame")
    with pytest.raises(mb.ModelError, match="not a body"):
        arm.jacobian("elbow", q)


# -- inverse dynamics ------------------------------------------------------------------------------
def test_inverse_dynamics_round_trip_on_a_3d_chain():
    chain = pendulum_chain(4).compile()
    rng = np.random.default_rng(3)
    Q, V, A = (rng.uniform(-1, 1, (5, 4)) for _ in range(3))
    tau = chain.inverse_dynamics(Q, V, A)
    assert tau.shape == (5, 4)
    for i in range(5):
        assert_close(chain.accelerations(Q[i], V[i], tau=tau[i]), A[i], rtol=1e-9, atol=1e-10, name="qdd")
        M, f = chain.tree_dynamics(Q[i], V[i])
        assert_close(tau[i], M @ A[i] - f, rtol=1e-12, atol=1e-12, name="tau")
    one = chain.inverse_dynamics(Q[0], V[0], A[0])
    assert one.shape == (4,)
    assert_close(one, tau[0], name="single sample")
    # at rest with zero acceleration the answer is the holding forces
    assert_close(chain.inverse_dynamics(Q[1], np.zeros(4), np.zeros(4)), chain.holding_forces(Q[1]), name="hold")


def test_inverse_dynamics_with_constraints_gives_reactions_and_round_trips(fourbars):
    for form, system in fourbars.items():
        q, qd = system.assemble([0.4, 1.0, 1.5], [1.3, 0.0, 0.0])
        drive = np.array([0.7, 0.0, 0.0])
        qdd = system.accelerations(q, qd, tau=drive)  # a motion the constraints allow
        tau = system.inverse_dynamics(q, qd, qdd, actuated="A")
        assert_close(tau, drive, rtol=1e-8, atol=1e-9, name=f"{form} crank torque")
        expected = system.reactions(q, qd, tau=drive)["C"]
        assert_close(tau.reactions["C"], expected, rtol=1e-7, atol=1e-8, name=f"{form} loop reaction")
        smallest = system.inverse_dynamics(q, qd, qdd)
        assert_close(system.accelerations(q, qd, tau=smallest), qdd, rtol=1e-8, atol=1e-9, name="min-norm")
        assert np.linalg.norm(smallest) <= np.linalg.norm(drive) + 1e-12


def test_inverse_dynamics_of_a_motor_driven_mechanism_is_its_motor_torque():
    motor = mb.Motor("motor", "A", speed=2.0)
    system = fourbar(motor=motor, name="driven").compile()
    assert system.ndof == 0
    q, qd = system.assemble([0.4, 1.0, 1.5], [2.0, 0.0, 0.0])
    qdd = system.accelerations(q, qd)
    tau = system.inverse_dynamics(q, qd, qdd)
    assert_close(tau, np.zeros(3), atol=1e-9, name="no extra torque")
    assert_close(tau.reactions["motor"], system.reactions(q, qd)["motor"], rtol=1e-8, name="motor torque")


def test_inverse_dynamics_rejects_bad_shapes():
    chain = pendulum_chain(2).compile()
    with pytest.raises(mb.ModelError, match="qdd"):
        chain.inverse_dynamics([0, 0], [0, 0], [0, 0, 0])
    with pytest.raises(mb.SimulationError, match="actuated joints cannot"):
        chain.inverse_dynamics([0.2, 0.1], [0, 0], [0, 0], actuated="joint0")


# -- command line ----------------------------------------------------------------------------------
def test_cli_analyse_prints_equilibrium_modes_and_stability(capsys, monkeypatch):
    from pathlib import Path
    from mbcomp.face.cli import main
    monkeypatch.chdir(Path(__file__).resolve().parents[1])
    assert main(["analyse", "library/double_pendulum.toml", "--at", "phi1=0.4,theta2=-0.2"]) == 0
    out = capsys.readouterr().out
    system = mb.load("library/double_pendulum.toml").compile()
    q = system.equilibrium([0.4, -0.2])
    for f in system.modes(q).frequencies:
        assert f"{f:.6g}" in out
    assert "stability: stable" in out and "equilibrium" in out
    assert main(["analyse", "library/arm3d.toml", "--held", "--at", "alpha=1.91986217719376",
                 "--at", "beta=-0.349065850398866,gamma=-0.349065850398866"]) == 0
    out = capsys.readouterr().out
    assert "UNSTABLE (2 growing modes)" in out and "holding force" in out and "0.243785" in out
    assert main(["analyse", "library/double_pendulum.toml", "--at", "nope=1"]) == 2
    assert "not a coordinate" in capsys.readouterr().err
    assert main(["analyse", "library/double_pendulum.toml", "--at", "phi1=abc"]) == 2


# -- quaternion joints (speeds distinct from coordinates) ------------------------------------------
def ball_pendulum(joint="ball"):
    """A body hanging 0.6 m below a ball joint (or the Euler-angle Spherical 'xyz' for comparison)."""
    m = mb.Model(f"{joint}_pendulum", gravity=(0, 0, -G))
    body = m.add(mb.Body("body", mass=2.0, com=(0, 0, -0.6), inertia=(0.05, 0.07, 0.02)))
    if joint == "ball":
        m.add(mb.Ball("pivot", m.ground, body))
    else:
        m.add(mb.Spherical("pivot", m.ground, body, sequence="xyz"))
    return m


needs_ball = pytest.mark.skipif(not hasattr(mb, "Ball"), reason="the quaternion Ball joint is not available")


@needs_ball
def test_ball_joint_modes_and_linearisation_in_tangent_coordinates():
    ball = ball_pendulum("ball").compile()
    assert len(ball.speeds) == 3 and len(ball.coords) == 4
    identity = [1.0, 0.0, 0.0, 0.0]
    lin = ball.linearize(identity)
    assert lin.A.shape == (6, 6) and lin.states[:3] == tuple(ball.speeds)
    # at the hanging pose a small rotation vector and small xyz Euler angles agree to first order
    euler = ball_pendulum("euler").compile().linearize([0.0, 0.0, 0.0])
    assert_close(lin.A, euler.A, rtol=1e-7, atol=1e-7, name="A ball vs Euler angles")
    modes = ball.modes(identity)
    # swinging about x and y: omega^2 = m g l / (I + m l^2); spinning about z: free (zero)
    expected = sorted([0.0] + [np.sqrt(2.0 * G * 0.6 / (inertia + 2.0 * 0.36)) / (2 * np.pi) for inertia in (0.05, 0.07)])
    assert_close(modes.frequencies, expected, rtol=1e-7, atol=1e-6, name="ball frequencies")
    assert modes.stable


@needs_ball
def test_ball_joint_equilibrium_jacobian_and_inverse_dynamics():
    ball = ball_pendulum("ball").compile()
    tilted = np.array([np.cos(0.6), np.sin(0.6) * 0.6, np.sin(0.6) * 0.8, 0.0])   # 1.2 rad about (0.6, 0.8, 0)
    q = ball.equilibrium(tilted)
    assert abs(np.linalg.norm(q) - 1.0) < 1e-12
    assert_close(ball.body_state("body", q).position, [0.0, 0.0, -0.6], atol=1e-9, name="hanging COM")
    v = np.array([0.3, -0.5, 0.8])
    J = ball.jacobian("body", tilted)
    state = ball.body_state("body", tilted, v)
    assert J.shape == (6, 3)
    assert_close(J[:3] @ v, state.angular_velocity, atol=1e-12, name="angular velocity")
    assert_close(J[3:] @ v, state.velocity, atol=1e-12, name="COM velocity")
    a = np.array([1.0, -2.0, 0.5])
    tau = ball.inverse_dynamics(tilted, v, a)
    assert_close(ball.accelerations(tilted, v, tau=tau), a, rtol=1e-9, atol=1e-10, name="round trip")


@needs_ball
def test_ball_joint_linearisation_while_moving():
    """Acceleration rows against central differences through ``integrate``; the kinematic
    rows of the rotation vector: dx/dt = v + x x v / 2 + ..., so d(dx/dt)/dx = -[v]x / 2."""
    ball = ball_pendulum("ball").compile()
    q = np.array([np.cos(0.6), np.sin(0.6) * 0.6, np.sin(0.6) * 0.8, 0.0])
    v = np.array([0.3, -0.5, 0.8])
    lin = ball.linearize(q, v)
    h = 1e-5
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        dq = (ball.accelerations(ball.integrate(q, e), v) - ball.accelerations(ball.integrate(q, -e), v)) / (2 * h)
        dv = (ball.accelerations(q, v + e) - ball.accelerations(q, v - e)) / (2 * h)
        assert_close(lin.A[3:, j], dq, rtol=1e-6, atol=1e-7, name=f"dvdot/dx{j}")
        assert_close(lin.A[3:, 3 + j], dv, rtol=1e-6, atol=1e-7, name=f"dvdot/dv{j}")
    skew = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    assert_close(lin.A[:3, :3], -skew / 2, atol=1e-8, name="kinematic rows")
    assert_close(lin.A[:3, 3:], np.eye(3), atol=1e-8, name="dx/dv")
