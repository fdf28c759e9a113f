"""Constraints: loop-closing joints, Slider, Motor; reactions, redundancy, assembly, dead points.

Every number is checked against something computed here independently: statics by hand,
inverse dynamics on the same model without the constraint, finite differences of
``body_state`` positions, the work-energy balance.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.optimize

import mbcomp as mb
from conftest import assert_close, bar, fourbar
from mbcomp.spec.components.constraints import normals

FORMULATIONS = ("lagrange", "dae")
G = 9.81


# -- models --------------------------------------------------------------------------------------


def parallelogram(L=0.3, d=0.7, name="parallelogram"):
    """Crank and rocker (length L) along their body y axes, coupler (length d) along x:
    q = 0 is a rectangle; q = (-pi/2, pi/2, -pi/2) lays every link on the x axis."""
    m = mb.Model(name, gravity=(0, -G, 0))
    crank, coupler, rocker = m.add(bar("crank", L, along="y")), m.add(bar("coupler", d)), m.add(bar("rocker", L, along="y"))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(0, L, 0)))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(d, 0, 0)))
    m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(d, 0, 0), child_point=(0, L, 0)))
    return m


def slider_crank(r=0.2, l=0.6, *, closed=True, gravity=(0, -G, 0), name="slider_crank"):
    """Crank (r) and rod (l) in x-y; the rod end slides on the x axis (Slider 'piston')."""
    m = mb.Model(name, gravity=gravity)
    crank, rod = m.add(bar("crank", r)), m.add(bar("rod", l, mass=0.5))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(r, 0, 0)))
    if closed:
        m.add(mb.Slider("piston", rod, point=(l, 0, 0), origin=(0, 0, 0), axis="x"))
    return m


def double_pendulum(motor=None, name="dpend"):
    """Two uniform 1 m, 1 kg bars in x-y, gravity -y (the conftest double pendulum)."""
    m = mb.Model(name, gravity=(0, -G, 0))
    b1, b2 = m.add(bar("bar1", 1.0)), m.add(bar("bar2", 1.0))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    if motor is not None:
        m.add(motor)
    return m


def point_jacobian(system, body, point, q, h=1e-6):
    """(3, nq) d p_world / d q of a body point, by central differences of body_state."""
    q = np.asarray(q, dtype=float)
    cols = []
    for k in range(len(q)):
        e = np.zeros_like(q)
        e[k] = h
        plus = system.body_state(body, q + e, point=point).position
        minus = system.body_state(body, q - e, point=point).position
        cols.append((plus - minus) / (2 * h))
    return np.array(cols).T


def generalised_reaction(closed, free, q, qd, tau=None):
    """``J^T lam`` from the equations of motion: M (qdd - qdd_free), with qdd_free the
    accelerations of the same tree without the constraint (so ``M qdd_free = f + tau``)."""
    M = closed.mass_matrix(q)
    return M @ (closed.accelerations(q, qd, tau=tau) - free.accelerations(q, qd, tau=tau))


# -- input validation ------------------------------------------------------------------------------
class TestBadInput:
    def test_motor_with_both_position_and_speed_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Motor 'mot'"):
            mb.Motor("mot", "j1", position=lambda t: t, speed=1.0)

    def test_motor_with_neither_position_nor_speed_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Motor 'mot'"):
            mb.Motor("mot", "j1")

    def test_motor_position_must_be_callable(self):
        with pytest.raises(mb.ModelError, match="Motor 'mot'.*callable"):
            mb.Motor("mot", "j1", position=0.5)

    def test_motor_speed_must_be_finite(self):
        with pytest.raises(mb.ModelError, match="Motor 'mot'"):
            mb.Motor("mot", "j1", speed=float("nan"))

    def test_slider_with_zero_axis_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Slider 'guide'.*axis"):
            mb.Slider("guide", "bar1", point=(1, 0, 0), axis=(0, 0, 0))

    def test_motor_on_a_three_dof_joint_is_rejected(self):
        m = mb.Model("ball", gravity=(0, -G, 0))
        b = m.add(bar("bar", 1.0))
        m.add(mb.Spherical("shoulder", m.ground, b, sequence="xyz"))
        m.add(mb.Motor("mot", "shoulder", speed=1.0))
        with pytest.raises(mb.ModelError, match="Motor 'mot'"):
            m.compile()

    def test_motor_on_a_body_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Motor 'mot'"):
            double_pendulum(mb.Motor("mot", "bar1", speed=1.0)).compile()

    def test_motor_on_an_unknown_joint_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Motor 'mot'.*nojoint"):
            double_pendulum(mb.Motor("mot", "nojoint", speed=1.0)).compile()

    def test_motor_on_a_loop_closing_joint_is_rejected(self):
        m = fourbar()
        m.add(mb.Motor("mot", "C", speed=1.0))
        with pytest.raises(mb.ModelError, match="Motor 'mot'"):
            m.compile()

    def test_lagrange_takes_no_baumgarte_gains(self):
        with pytest.raises(mb.ModelError, match="baumgarte"):
            fourbar().compile("lagrange", baumgarte=(5, 5))


# -- loop closure ----------------------------------------------------------------------------------
class TestLoopClosure:
    def test_cut_joint_is_a_constraint_named_after_the_joint(self):
        s = fourbar().compile("lagrange")
        assert s.coords == ("A", "B", "D")
        assert s.constraint_names == ["C"]
        assert s.ndof == 1

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_loop_reaction_is_the_force_on_the_child(self, formulation):
        """J^T F (J by finite differences of the two joint points) equals the generalised
        force the constraint adds to the open tree's equations of motion."""
        closed = fourbar().compile(formulation)
        free = fourbar(closed=False, name="fourbar_open").compile(formulation)
        q, qd = closed.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        reaction = closed.reactions(q, qd)["C"]
        assert reaction.shape == (5,)   # force on the rocker (x, y, z), two torques
        F = reaction[:3]
        J = (point_jacobian(closed, "rocker", (0.6, 0, 0), q) - point_jacobian(closed, "coupler", (0.8, 0, 0), q))
        assert_close(J.T @ F, generalised_reaction(closed, free, q, qd), rtol=1e-6, atol=1e-6, name="J^T F")
        assert np.linalg.norm(F[:2]) > 0.5   # a real load, not a vacuous zero
        assert_close(reaction[2:], 0.0, atol=1e-9, name="out-of-plane force and torques of a planar loop")

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_loop_reaction_with_applied_torque(self, formulation):
        closed = fourbar().compile(formulation)
        free = fourbar(closed=False, name="fourbar_open").compile(formulation)
        q, qd = closed.assemble([0.3, 0.5, 2.0], [-2.0, 0, 0])
        tau = [1.5, -0.4, 0.7]
        F = closed.reactions(q, qd, tau=tau)["C"][:3]
        J = (point_jacobian(closed, "rocker", (0.6, 0, 0), q) - point_jacobian(closed, "coupler", (0.8, 0, 0), q))
        assert_close(J.T @ F, generalised_reaction(closed, free, q, qd, tau), rtol=1e-6, atol=1e-6, name="J^T F")


# -- slider ----------------------------------------------------------------------------------------
class TestSlider:
    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_pendulum_held_by_an_inclined_slider_at_rest_statics(self, formulation):
        """A bar (m, L) pinned at the origin with its tip on a line at angle phi: 0 DOF.
        Moments about the pin: N L cos(theta - phi) = m g (L/2) cos(theta), with the line's
        force N along its in-plane normal (-sin phi, cos phi)."""
        mass, L, theta, phi = 2.0, 1.0, 0.6, -0.4
        tip = np.array([L * np.cos(theta), L * np.sin(theta), 0.0])
        u = np.array([np.cos(phi), np.sin(phi), 0.0])
        m = mb.Model("propped", gravity=(0, -G, 0))
        b = m.add(bar("bar", L, mass=mass))
        m.add(mb.Revolute("pin", m.ground, b, axis="z"))
        m.add(mb.Slider("prop", b, point=(L, 0, 0), origin=tuple(tip - 0.5 * u), axis=tuple(u)))
        s = m.compile(formulation)
        assert s.ndof == 0
        assert len(s.redundant_constraints) == 1   # the out-of-plane normal
        q, qd = s.assemble([0.55], [0.0])
        assert_close(q, [theta], atol=1e-10, name="assembled angle")
        assert_close(s.accelerations(q, qd), [0.0], atol=1e-9, name="qdd at rest")
        lam = s.reactions(q, qd)["prop"]
        n1, n2 = normals(tuple(u))
        force = lam[0] * np.array(n1) + lam[1] * np.array(n2)
        N = mass * G * np.cos(theta) / (2 * np.cos(theta - phi))
        assert_close(force, N * np.array([-np.sin(phi), np.cos(phi), 0.0]), atol=1e-9, name="slider force")

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_slider_reaction_in_motion(self, formulation):
        closed = slider_crank().compile(formulation)
        free = slider_crank(closed=False, name="crank_rod").compile(formulation)
        q, qd = closed.assemble([0.5, -0.6], [2.0, 0.0])
        lam = closed.reactions(q, qd)["piston"]
        n1, n2 = normals((1.0, 0.0, 0.0))
        F = lam[0] * np.array(n1) + lam[1] * np.array(n2)
        J = point_jacobian(closed, "rod", (0.6, 0, 0), q)
        assert_close(J.T @ F, generalised_reaction(closed, free, q, qd), rtol=1e-6, atol=1e-6, name="J^T F")
        assert abs(F[1]) > 0.5 and abs(F[0]) < 1e-12   # normal to the line, and not zero

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_point_stays_on_the_line(self, formulation):
        s = slider_crank().compile(formulation)
        q, qd = s.assemble([0.5, -0.6], [2.0, 0.0])
        res = s.simulate(1.0, q, qd, t_eval=np.linspace(0, 1, 21))
        y = [s.body_state("rod", qq, point=(0.6, 0, 0)).position[1] for qq in res.q]
        assert np.max(np.abs(y)) < 1e-6
        assert np.ptp([s.body_state("rod", qq, point=(0.6, 0, 0)).position[0] for qq in res.q]) > 0.2


# -- motor -----------------------------------------------------------------------------------------
class TestMotor:
    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_position_motor_prescribes_the_coordinate(self, formulation):
        s = double_pendulum(mb.Motor("mot", "j1", position=lambda t: 0.3 * np.sin(2 * t))).compile(formulation)
        assert s.ndof == 1
        q, qd = s.assemble([0.3, 0.2], [0.0, 0.0])
        assert_close(q[0], 0.0, atol=1e-12, name="assembled j1 = position(0)")
        assert_close(qd[0], 0.6, atol=1e-9, name="assembled j1 speed = position'(0)")
        res = s.simulate(2.0, q, qd, t_eval=np.linspace(0, 2, 41))
        assert_close(res["j1"], 0.3 * np.sin(2 * res.t), atol=1e-8, name="q_j1(t)")
        assert_close(res["j1_d"], 0.6 * np.cos(2 * res.t), atol=1e-7, name="qd_j1(t)")
        assert np.ptp(res["j2"]) > 0.1   # the free bar really moves

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_speed_motor_turns_at_constant_speed(self, formulation):
        s = double_pendulum(mb.Motor("mot", "j1", speed=2.0)).compile(formulation)
        q, qd = s.assemble([0.3, 0.2], [0.0, 0.0])
        assert_close(qd[0], 2.0, atol=1e-12, name="assembled speed")
        res = s.simulate(1.0, q, qd, t_eval=np.linspace(0, 1, 21))
        assert_close(res["j1"], 0.3 + 2.0 * res.t, atol=1e-8, name="q_j1(t)")
        assert_close(res["j1_d"], 2.0, atol=1e-8, name="qd_j1(t)")

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_motor_torque_is_the_inverse_dynamics_torque(self, formulation):
        """Applied as tau to the model without the motor, the motor torque reproduces the
        motion: zero acceleration of the driven joint and the same acceleration of the other."""
        s = double_pendulum(mb.Motor("mot", "j1", speed=2.0)).compile(formulation)
        free = double_pendulum(name="dpend_free").compile(formulation)
        for guess in ([0.3, 0.2], [2.0, -1.0], [-1.0, 2.5]):
            q, qd = s.assemble(guess, [0.0, 1.0])
            torque = s.reactions(q, qd)["mot"]
            qdd = s.accelerations(q, qd)
            qdd_free = free.accelerations(q, qd, tau=[torque, 0.0])
            assert_close(qdd[0], 0.0, atol=1e-9, name="driven joint acceleration")
            assert_close(qdd_free, qdd, rtol=1e-9, atol=1e-9, name="inverse dynamics")
            assert abs(torque) > 0.1

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_motor_work_equals_the_change_of_energy(self, formulation):
        """P = torque * speed; the integral of P over the run (Simpson's rule on 401 samples)
        equals E(t) - E(0)."""
        from scipy.integrate import cumulative_simpson
        speed = 2.0
        s = double_pendulum(mb.Motor("mot", "j1", speed=speed)).compile(formulation)
        q, qd = s.assemble([0.3, 0.2], [0.0, 0.0])
        res = s.simulate(2.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=np.linspace(0, 2, 401))
        torque = res.reactions["mot"][:, 0]
        for i in (0, 100, 400):   # the series is the state-by-state reaction
            assert_close(torque[i], s.reactions(res.q[i], res.qd[i], t=res.t[i])["mot"], rtol=1e-9, name="series")
        power = torque * res["j1_d"]
        assert_close(res["j1_d"], speed, atol=1e-8, name="speed")
        work = cumulative_simpson(power, x=res.t, initial=0.0)
        E = res.energy().total
        scale = np.max(np.abs(work))
        assert scale > 1.0
        assert np.max(np.abs(work - (E - E[0]))) < 1e-6 * scale


# -- redundancy ------------------------------------------------------------------------------------
def bricard_model():
    """Bricard's orthogonal 6R linkage (all links 1 m, twists alternately 90 and 270 deg, no
    offsets): Grübler count 6 coordinates - 6 = 0, yet it moves with one DOF.  Built in the
    symmetric configuration theta = (a, b, a, b, a, b) found here by least squares on the
    Denavit-Hartenberg loop; there every body frame is the world frame (q = 0)."""
    twists = [np.pi / 2, 3 * np.pi / 2] * 3

    def dh(theta, alpha):
        ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
        return np.array([[ct, -st * ca, st * sa, ct], [st, ct * ca, -ct * sa, st], [0, sa, ca, 0], [0, 0, 0, 1]])

    def frames(ab):
        T = [np.eye(4)]
        for i in range(6):
            T.append(T[-1] @ dh(ab[i % 2], twists[i]))
        return T

    def closure(ab):
        T = frames(ab)[-1]
        return np.concatenate((T[:3, 3], (T[:3, :3] - np.eye(3)).ravel()))

    sol = scipy.optimize.least_squares(closure, [-0.97, 1.94], xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.max(np.abs(closure(sol.x))) < 1e-12
    T = frames(sol.x)
    axes = [tuple(T[i][:3, 2]) for i in range(6)]
    points = [T[i][:3, 3] for i in range(6)]
    m = mb.Model("bricard", gravity=(0, 0, -G))
    links = [m.ground] + [m.add(mb.Body(f"L{i + 1}", mass=1.0, com=tuple((points[i] + points[i + 1]) / 2),
                                        inertia=(0.1, 0.1, 0.1))) for i in range(5)]
    for i in range(5):
        p = tuple(points[i])
        m.add(mb.Revolute(f"J{i + 1}", links[i], links[i + 1], axis=axes[i], parent_point=p, child_point=p))
    p = tuple(points[5])
    m.add(mb.Revolute("J6", m.ground, links[5], axis=axes[5], parent_point=p, child_point=p))
    return m


class TestRedundantConstraints:
    def test_planar_fourbar_has_three_redundant_equations(self):
        s = fourbar().compile("dae")
        assert s.ndof == 1
        assert sorted(s.redundant_constraints) == ["C.t1", "C.t2", "C.z"]

    def test_planar_slider_has_one_redundant_equation(self):
        s = slider_crank().compile("dae")
        assert s.ndof == 1
        assert len(s.redundant_constraints) == 1 and s.redundant_constraints[0].startswith("piston.")

    def test_prismatic_loop_in_a_plane(self):
        """Slider-crank closed by a revolute onto a piston on a prismatic joint: 3 coords,
        5 loop equations of which 3 are redundant in the plane."""
        s = prismatic_slider_crank().compile("dae")
        assert s.ndof == 1
        assert len(s.redundant_constraints) == 3

    def test_ndof_is_the_generic_rank_even_when_q0_is_singular(self):
        s = fourbar(0.3, 0.7, 0.3, 0.7, name="parallelogram_x").compile("dae")
        assert s.ndof == 1
        assert sorted(s.redundant_constraints) == ["C.t1", "C.t2", "C.z"]

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_bricard_linkage_moves_with_one_dof(self, formulation):
        s = bricard_model().compile(formulation)
        assert s.ndof == 1
        assert len(s.redundant_constraints) == 1
        assert s.constraint_violation(np.zeros(5)) < 1e-12
        q, qd = s.assemble(np.zeros(5), [1.0, 0, 0, 0, 0])
        assert np.max(np.abs(qd)) > 0.1
        res = s.simulate(1.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=np.linspace(0, 1, 11))
        assert np.max(res.constraint_violation()) < 1e-8
        E = res.energy()
        assert np.max(np.abs(E.total - E.total[0])) < 1e-7 * np.max(E.kinetic)
        # The threefold-symmetric motion: J1 = J3 = J5 and J2 = J4 relative to the start.
        assert_close(res.q[:, [2, 4, 3]], res.q[:, [0, 0, 1]], atol=1e-7, name="symmetric motion")
        assert np.ptp(res.q[:, 0]) > 0.05

    def test_bricard_assembles_from_a_nearby_guess(self):
        s = bricard_model().compile("dae")
        q, _ = s.assemble([0.1, 0.02, 0.1, 0.02, 0.1])
        assert s.constraint_violation(q) < 1e-10
        assert_close(q[[2, 4, 3]], q[[0, 0, 1]], atol=1e-8, name="on the symmetric branch")

    def test_bricard_assembles_from_random_guesses_within_5_centiradians(self):
        s = bricard_model().compile("dae")
        rng = np.random.default_rng(1)
        for _ in range(30):
            q, _ = s.assemble(rng.normal(0.0, 0.05, 5))
            assert s.constraint_violation(q) < 1e-10


def prismatic_slider_crank(r=0.2, l=0.6):
    """Crank + rod, and a 0.3 kg piston on a prismatic joint along x; the rod end is pinned
    to the piston by the loop-closing revolute 'wrist'."""
    m = mb.Model("prismatic_slider_crank", gravity=(0, -G, 0))
    crank, rod = m.add(bar("crank", r)), m.add(bar("rod", l, mass=0.5))
    piston = m.add(mb.Body("piston", mass=0.3, com=(0, 0, 0), inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(r, 0, 0)))
    m.add(mb.Prismatic("P", m.ground, piston, axis="x"))
    m.add(mb.Revolute("wrist", rod, piston, axis="z", parent_point=(l, 0, 0)))
    return m


# -- assembly --------------------------------------------------------------------------------------
class TestAssembly:
    @pytest.mark.parametrize("formulation", FORMULATIONS)
    @pytest.mark.parametrize("guess", [[1.0, 0.0, 1.0], [-1.0, 2.0, 3.0], [0.0, 0.0, 0.5]], ids=str)
    def test_fourbar_from_a_poor_guess(self, formulation, guess):
        s = fourbar().compile(formulation)
        qd_guess = np.array([1.0, -0.3, 0.4])
        q, qd = s.assemble(guess, qd_guess)
        assert s.constraint_violation(q) < 1e-10
        # Loop points coincide (world positions, independent of the constraint code).
        pc = s.body_state("coupler", q, point=(0.8, 0, 0)).position
        pr = s.body_state("rocker", q, point=(0.6, 0, 0)).position
        assert_close(pc, pr, atol=1e-10, name="loop points")
        # J qd = 0: moving along qd keeps them together to second order.
        h = 1e-5
        gap = lambda qq: (s.body_state("coupler", qq, point=(0.8, 0, 0)).position
                          - s.body_state("rocker", qq, point=(0.6, 0, 0)).position)
        rate = (gap(q + h * qd) - gap(q - h * qd)) / (2 * h)
        assert np.max(np.abs(rate)) < 1e-8 * max(1.0, np.max(np.abs(qd)))
        # Mass-orthogonal projection: the correction is M-orthogonal to the motion.
        M = s.mass_matrix(q)
        assert abs(qd @ M @ (qd - qd_guess)) < 1e-10 * (1 + abs(qd_guess @ M @ qd_guess))
        assert np.linalg.norm(qd) > 0.1

    def test_fourbar_from_guesses_within_half_a_radian(self):
        s = fourbar().compile("dae")
        q0, _ = s.assemble([1.0, -0.5, 1.5])
        rng = np.random.default_rng(0)
        for _ in range(50):
            q, _ = s.assemble(q0 + rng.normal(0.0, 0.5, 3))
            assert s.constraint_violation(q) < 1e-10

    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_links_too_short_to_close_the_loop(self, formulation):
        """L1 + L2 + L3 = 0.4 < d = 0.7: no configuration closes the loop."""
        m = fourbar(0.1, 0.2, 0.1, 0.7, name="open_fourbar")
        try:
            s = m.compile(formulation)
        except mb.ModelError as exc:
            message = str(exc)
        else:
            with pytest.raises(mb.SimulationError) as info:
                s.assemble([0.0, 0.0, 0.0])
            message = str(info.value)
        assert "'C" in message or "C." in message, message

    def test_assembly_does_not_touch_a_consistent_state(self):
        s = fourbar().compile("lagrange")
        q, qd = s.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        q2, qd2 = s.assemble(q, qd)
        assert_close(q2, q, atol=1e-13, name="q")
        assert_close(qd2, qd, atol=1e-12, name="qd")


# -- dead points -----------------------------------------------------------------------------------
DEAD = [-np.pi / 2, np.pi / 2, -np.pi / 2]   # the parallelogram with every link on the x axis


class TestDeadPoints:
    @pytest.mark.parametrize("formulation", FORMULATIONS)
    def test_parallelogram_at_its_dead_point_at_rest_raises(self, formulation):
        s = parallelogram().compile(formulation)
        assert s.ndof == 1
        assert s.constraint_violation(DEAD) < 1e-15
        for call in (lambda: s.accelerations(DEAD, [0, 0, 0]), lambda: s.reactions(DEAD, [0, 0, 0])):
            with pytest.raises(mb.SimulationError, match=r"'C'|\bC\b"):
                call()

    @pytest.mark.parametrize("formulation", ["lagrange", "dae"])
    def test_simulating_from_the_dead_point_at_rest_raises(self, formulation):
        s = parallelogram().compile(formulation)
        with pytest.raises(mb.SimulationError, match=r"'C'|\bC\b"):
            s.simulate(0.1, DEAD, [0, 0, 0])

    @pytest.mark.parametrize("formulation", ["lagrange", "dae"])
    def test_folded_slider_crank_at_rest_raises(self, formulation):
        """Crank = rod: at A = 90 deg, B = 180 deg the rod lies folded on the crank with its
        end at the origin; the slider equation's gradient vanishes."""
        s = slider_crank(0.4, 0.4, gravity=(-G, 0, 0), name="folded").compile(formulation)
        assert s.ndof == 1
        with pytest.raises(mb.SimulationError, match="piston"):
            s.accelerations([np.pi / 2, np.pi], [0.0, 0.0])

    @pytest.mark.parametrize("formulation, rtol", [
        ("dae", 1e-8),
        ("dae", 1e-10),  # left the branch at the 5th crossing before the compiled projection
        ("lagrange", 1e-8),
    ])
    def test_passing_the_singular_position_in_motion(self, formulation, rtol):
        """Started as a rectangle with the crank turning, the parallelogram passes its
        collinear position five times in 1.6 s.  Either the run continues on the
        parallelogram branch (coupler stays horizontal, energy conserved) or it raises
        SimulationError; nothing else (no wrong branch, no LinAlgError, no NaN)."""
        s = parallelogram().compile(formulation)
        q, qd = s.assemble([0, 0, 0], [-3.0, 3.0, -3.0])
        try:
            res = s.simulate(1.6, q, qd, rtol=rtol, atol=rtol * 1e-2, t_eval=np.linspace(0, 1.6, 161))
        except mb.SimulationError:
            return
        crossings = np.sum(np.diff(np.floor((res["A"] + np.pi / 2) / np.pi)) != 0)
        assert crossings >= 4
        coupler_angle = np.angle(np.exp(1j * (res["A"] + res["B"])))
        assert np.max(np.abs(coupler_angle)) < 1e-4, "left the parallelogram branch"
        E = res.energy()
        assert np.max(np.abs(E.total - E.total[0])) < 1e-6 * np.max(E.kinetic)


def two_fourbars():
    """IFToMM benchmark A02 with N = 2: three 1 m, 1 kg cranks pinned at x = 0, 1, 2 (along
    their y axes, vertical at q = 0) and two 1 m couplers along x; every crank horizontal is
    a singular position where a coupler and the next crank can turn together."""
    m = mb.Model("two_fourbars", gravity=(0, -G, 0))
    cranks = [m.add(bar(f"crank{i}", 1.0, along="y")) for i in range(3)]
    couplers = [m.add(bar(f"coupler{i}", 1.0)) for i in range(2)]
    for i in range(3):
        m.add(mb.Revolute(f"A{i}", m.ground, cranks[i], axis="z", parent_point=(float(i), 0, 0)))
    for i in range(2):
        m.add(mb.Revolute(f"B{i}", cranks[i], couplers[i], axis="z", parent_point=(0, 1, 0)))
        m.add(mb.Revolute(f"C{i}", couplers[i], cranks[i + 1], axis="z", parent_point=(1, 0, 0),
                          child_point=(0, 1, 0)))
    return m


class TestDaeThroughSingularPositions:
    """The compiled dae loop drops near-singular directions from its solves and projects the
    state back onto the constraints after each accepted step."""

    @pytest.mark.parametrize("rtol", [1e-8, 1e-10, 1e-12])
    def test_two_fourbars_pass_eight_singular_positions_on_their_branch(self, rtol):
        s = two_fourbars().compile("dae")
        assert sorted(s.redundant_constraints) == ["C0.t1", "C0.t2", "C0.z", "C1.t1", "C1.t2", "C1.z"]
        q, qd = s.assemble(np.zeros(5), [-1.0, 0, 0, 0, 0])
        res = s.simulate(10.0, q, qd, rtol=rtol, atol=rtol * 1e-2, t_eval=np.linspace(0, 10, 1001))
        assert res.stats["integrator"] == "compiled"
        crossings = np.sum(np.diff(np.floor((res["A0"] + np.pi / 2) / np.pi)) != 0)
        assert crossings == 8
        # Parallelogram branch: cranks parallel, couplers horizontal.
        assert_close(res.q[:, [2, 4]], res.q[:, [0, 0]], atol=1e-5, name="cranks parallel")
        assert np.max(np.abs(np.angle(np.exp(1j * (res["A0"] + res["B0"]))))) < 1e-5
        assert np.max(res.constraint_violation()) < 1e-5
        E = res.energy()
        assert np.max(np.abs(E.total - E.total[0])) < 1e-5 * np.max(E.kinetic)

    def test_two_fourbars_agree_with_lagrange(self):
        s = two_fourbars().compile("dae")
        q, qd = s.assemble(np.zeros(5), [-1.0, 0, 0, 0, 0])
        t = np.linspace(0, 3, 31)
        dae = s.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        lag = two_fourbars().compile("lagrange").simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        assert np.ptp(dae["A0"]) > 5  # through several singular positions
        assert_close(dae["A0"], lag["A0"], atol=1e-5, name="crank angle")

    def test_bricard_with_gravity_over_ten_seconds(self):
        s = bricard_model().compile("dae")
        q, qd = s.assemble(np.zeros(5), [1.0, 0, 0, 0, 0])
        res = s.simulate(10.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=np.linspace(0, 10, 101))
        assert res.stats["integrator"] == "compiled"
        assert np.max(res.constraint_violation()) < 1e-8
        E = res.energy()
        assert np.max(np.abs(E.total - E.total[0])) < 1e-8 * np.max(E.kinetic)
        assert_close(res.q[:, [2, 4, 3]], res.q[:, [0, 0, 1]], atol=1e-8, name="symmetric motion")
        lag = bricard_model().compile("lagrange").simulate(2.0, q, qd, rtol=1e-10, atol=1e-12,
                                                           t_eval=res.t[:21])
        assert_close(res.q[:21], lag.q, atol=1e-6, name="dae vs lagrange")

    def test_at_rest_on_a_singular_position_still_raises(self):
        s = parallelogram().compile("dae")
        with pytest.raises(mb.SimulationError, match="rank"):
            s.simulate(0.5, [-np.pi / 2, np.pi / 2, -np.pi / 2], [0, 0, 0])
