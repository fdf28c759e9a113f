"""Motors that prescribe their position by an expression of t, in the lagrange formulation's
compiled loop (``expressions_c.py`` programs run from ``formulations/lagrange_c.py``):
closed-form kinematics without degrees of freedom, the motor's work equal to the change of
energy, its torque equal to inverse dynamics, the same motion as scipy stepping."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import simpson

import mbcomp as mb
from conftest import fourbar
from mbcomp.codegen.expressions_c import STACK, NotCompilable, programs as stack_programs, run_program
from mbcomp.core.expressions import Expression, differentiate, parse_expression

G, L, MASS = 9.81, 0.8, 2.0
LAW = "0.4*sin(3*t) + 0.2*t**2 - 0.1"


def law(t):
    """The prescribed angle (rad) and its first and second derivatives."""
    return (0.4 * np.sin(3 * t) + 0.2 * t ** 2 - 0.1, 1.2 * np.cos(3 * t) + 0.4 * t, -3.6 * np.sin(3 * t) + 0.4)


def compiled(system):
    if system.backend != "c":
        pytest.skip("no C compiler")
    return system


def bar(m: mb.Model, name: str, parent, point=(0.0, 0.0, 0.0)):
    body = m.add(mb.Body(name, mass=MASS, com=(L / 2, 0, 0), inertia=(1e-4, MASS * L ** 2 / 12, MASS * L ** 2 / 12)))
    m.add(mb.Revolute(name.upper(), parent, body, axis="z", parent_point=point))
    return body


def pendulum(links: int = 1, position=LAW) -> mb.Model:
    """``links`` bars in a vertical plane (gravity -y), the first joint ``BAR1`` driven
    (no motor when ``position`` is None)."""
    m = mb.Model(f"driven{links}", gravity=(0, -G, 0))
    parent, point = m.ground, (0.0, 0.0, 0.0)
    for i in range(links):
        parent = bar(m, f"bar{i + 1}", parent, point)
        point = (L, 0.0, 0.0)
    if position is not None:
        m.add(mb.Motor("motor", "BAR1", position=position))
    return m


class TestStackPrograms:
    TEXTS = ["0.4*sin(3*t) + 0.2*t**2 - 0.1", "-exp(-t/2)*cos(2*pi*t)", "sqrt(1 + t**2)/(2 + t)",
             "(1 + t)**(0.5*t)", "3", "-(t - 1)**3"]

    @pytest.mark.parametrize("text", TEXTS)
    def test_programs_equal_the_tree_walk(self, text):
        """The flattened programs (and those of the exact derivatives) give the tree's values."""
        node = parse_expression(text, {}, allow_t=True)
        trees = [node, differentiate(node), differentiate(differentiate(node))]
        programs = stack_programs(trees)
        for i, tree in enumerate(trees):
            f = Expression(text, tree)
            for t in (0.0, 0.37, 1.9):
                assert run_program(programs, t, i) == pytest.approx(f(t), rel=1e-15, abs=1e-15)

    def test_what_the_evaluator_cannot_run(self):
        with pytest.raises(NotCompilable, match="linked parameter"):
            stack_programs([("+", ("t",), ("obj", object()))])
        deep = ("t",)
        for _ in range(STACK + 1):  # right-nested: every level keeps one value on the stack
            deep = ("+", ("num", 1.0), deep)
        with pytest.raises(NotCompilable, match="stack"):
            stack_programs([deep])


class TestMotorComponent:
    def test_position_as_text_is_an_expression_with_exact_derivatives(self):
        motor = mb.Motor("m", "A", position="0.5*sin(2*pi*t)")
        assert motor.position(0.125) == pytest.approx(0.5 * math.sin(math.pi / 4), rel=1e-15)
        assert motor.position.diff()(0.0) == pytest.approx(math.pi, rel=1e-15)

    def test_bad_position_text_names_the_motor(self):
        with pytest.raises(mb.ModelError, match=r"Motor 'm'.*position.*unknown name 'x'"):
            mb.Motor("m", "A", position="sin(x)")
        with pytest.raises(mb.ModelError, match="Motor 'm'.*callable of t or an expression"):
            mb.Motor("m", "A", position=3.0)


class TestKinematicRun:
    """No degree of freedom: the motion follows from the motor in C at the output times."""

    def test_bar_follows_the_law_and_the_torque_is_inverse_dynamics(self):
        system = compiled(pendulum(1).compile("lagrange"))
        assert system.ndof == 0 and system.integration_path() == "compiled"
        t = np.linspace(0.0, 2.0, 81)
        s, s1, s2 = law(t)
        res = system.simulate(2.0, [-0.1], [1.2], t_eval=t)
        assert res.stats["integrator"] == "compiled" and res.stats["method"] == "prescribed"
        np.testing.assert_allclose(res.q[:, 0], s, rtol=0, atol=1e-13)
        np.testing.assert_allclose(res.qd[:, 0], s1, rtol=0, atol=1e-13)
        # the torque about the pivot: I_O s'' + m g (L/2) cos(s)
        torque = np.asarray(res.reactions["motor"]).reshape(-1)
        expected = (MASS * L ** 2 / 3) * s2 + MASS * G * (L / 2) * np.cos(s)
        np.testing.assert_allclose(torque, expected, rtol=1e-10, atol=1e-10)
        python = system.simulate(2.0, [-0.1], [1.2], t_eval=t, integrator="scipy")
        np.testing.assert_allclose(res.q, python.q, rtol=0, atol=1e-14)
        np.testing.assert_allclose(res.qd, python.qd, rtol=0, atol=1e-14)

    def test_driven_four_bar_closes_the_loop_at_every_output(self):
        """A position motor on the crank of a four-bar: the loop's Newton solve and the
        motor's programs in C; the crank angle is the law, the loop stays closed, and the
        rocker's motion equals Python's prescribed motion."""
        motor = mb.Motor("drive", "A", position="1.0 + 0.5*sin(t)")
        system = compiled(fourbar(motor=motor).compile("lagrange"))
        assert system.ndof == 0 and system.integration_path() == "compiled"
        q, qd = system.assemble([1.0, -0.5, 1.5], [0.5, 0.0, 0.0])
        t = np.linspace(0.0, 3.0, 61)
        res = system.simulate(3.0, q, qd, t_eval=t)
        assert res.stats["method"] == "prescribed"
        np.testing.assert_allclose(res["A"], 1.0 + 0.5 * np.sin(t), atol=1e-12)
        assert np.max(res.constraint_violation()) < 1e-10
        python = system.simulate(3.0, q, qd, t_eval=t, integrator="scipy")
        np.testing.assert_allclose(res.q, python.q, atol=1e-11)
        np.testing.assert_allclose(res.qd, python.qd, atol=1e-10)


class TestDrivenPendulum:
    """One degree of freedom left: the reduced loop steps bar 2 while the motor drives bar 1."""

    @pytest.fixture(scope="class")
    def runs(self):
        system = compiled(pendulum(2).compile("lagrange"))
        assert system.ndof == 1 and system.integration_path() == "compiled"
        t = np.linspace(0.0, 2.0, 2001)
        q0, qd0 = [-0.1, 0.4], [1.2, 0.0]
        kw = dict(t_eval=t, rtol=1e-11, atol=1e-12)
        return system, system.simulate(2.0, q0, qd0, **kw), system.simulate(2.0, q0, qd0, integrator="scipy", **kw)

    def test_same_motion_as_scipy_stepping(self, runs):
        system, res, ref = runs
        assert res.stats["integrator"] == "compiled" and ref.stats["integrator"] == "scipy"
        s, s1, _ = law(res.t)
        np.testing.assert_allclose(res["BAR1"], s, atol=1e-12)
        np.testing.assert_allclose(res.qd[:, 0], s1, atol=1e-11)
        np.testing.assert_allclose(res.q, ref.q, rtol=1e-8, atol=1e-9)
        np.testing.assert_allclose(res.qd, ref.qd, rtol=1e-8, atol=1e-9)
        assert abs(res.stats["nfev"] - ref.stats["nfev"]) <= 0.1 * ref.stats["nfev"]

    def test_motor_work_equals_the_energy_change(self, runs):
        system, res, _ = runs
        torque = np.asarray(res.reactions["motor"]).reshape(-1)
        power = torque * law(res.t)[1]
        E = res.energy().total
        work = simpson(power, x=res.t)
        assert abs(E[-1] - E[0]) > 1.0  # the motor does real work
        assert work == pytest.approx(E[-1] - E[0], rel=1e-7)

    def test_motor_torque_equals_inverse_dynamics_of_the_free_pendulum(self, runs):
        """The same two bars without the motor: the generalised forces producing the run's
        accelerations are the motor torque on the first joint and nothing on the second."""
        system, res, _ = runs
        free = compiled(pendulum(2, position=None).compile("lagrange"))
        for k in (0, 700, 1500, 2000):
            t, q, qd = res.t[k], res.q[k], res.qd[k]
            qdd = system.accelerations(q, qd, t)
            assert qdd[0] == pytest.approx(law(t)[2], abs=1e-9)
            tau = np.asarray(free.inverse_dynamics(q, qd, qdd, t=t))
            torque = float(np.atleast_1d(system.reactions(q, qd, t)["motor"])[0])
            np.testing.assert_allclose(tau, [torque, 0.0], rtol=1e-9, atol=1e-9)


def test_position_that_fails_in_c_raises_the_python_message():
    """(1 - t)**2.5 has no value after 1 s (a power of a negative number): the compiled loop
    stops there with the message Python stepping gives."""
    system = compiled(pendulum(2, position="(1 - t)**2.5").compile("lagrange"))
    q0, qd0 = [1.0, 0.0], [-2.5, 0.0]
    for way in ("compiled", "scipy"):
        with pytest.raises(mb.SimulationError, match=r"motor.*position\(1\.[0-9e-]*\) failed.*cannot be evaluated"):
            system.simulate(2.0, q0, qd0, integrator=way)


def test_python_callable_runs_compiled_through_the_motor_callback():
    system = compiled(pendulum(2, position=lambda t: 0.4 * math.sin(3 * t)).compile("lagrange"))
    assert system.integration_path() == "compiled"
    res = system.simulate(0.2, [0.0, 0.4], [1.2, 0.0], t_eval=[0.0, 0.2])
    assert res.stats["integrator"] == "compiled"
    assert res["BAR1"][-1] == pytest.approx(0.4 * math.sin(0.6), abs=1e-7)
