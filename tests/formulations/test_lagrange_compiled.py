"""The lagrange formulation stepped in the compiled loop (``formulations/lagrange_c.py``):
the same motion as Python (scipy) stepping on closed loops, sliders and speed motors, the
same right-hand side, energy conserved, closed-form kinematics without degrees of freedom."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

import mbcomp as mb
from conftest import fourbar
from mbcomp.formulations.lagrange_compiled import ReducedRun
from mbcomp.codegen.integrators import PAUSED
from mbcomp.files.toml_model import load

LIBRARY = __import__("pathlib").Path(__file__).resolve().parents[2] / "library"


def compiled(system):
    if system.backend != "c":
        pytest.skip("no C compiler")
    return system


def library(name):
    model = load(LIBRARY / f"{name}.toml")
    system = compiled(model.compile())
    neutral = system.topology.state_map.neutral()
    q = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
    qd = np.array([model.initial["qd"].get(c, 0.0) for c in system.speeds])
    return system, q, qd


def energy_error(res):
    E = res.energy()
    return np.max(np.abs(E.total - E.total[0])) / np.max(E.kinetic)


@pytest.fixture(scope="module")
def loop():
    return compiled(fourbar().compile("lagrange"))


class TestPath:
    def test_closed_loops_and_speed_motors_run_compiled(self, loop):
        assert loop.integration_path() == "compiled"
        for name in ("four_bar", "double_pendulum_slider", "slider_crank"):
            system, q, qd = library(name)
            assert system.integration_path() == "compiled", name

    def test_a_callable_position_runs_compiled(self):
        motor = mb.Motor("drive", "A", position=lambda t: 1.0 + 0.5 * np.sin(t))
        system = compiled(fourbar(motor=motor).compile("lagrange"))
        assert system.integration_path() == "compiled"  # (its values called back from C)
        q, qd = system.assemble([1.0, -0.5, 1.5])
        res = system.simulate(0.1, q, qd, integrator="compiled", t_eval=[0.0, 0.1])
        assert res["A"][-1] == pytest.approx(1.0 + 0.5 * np.sin(0.1), abs=1e-9)

    def test_no_fixed_step_loop_for_the_reduced_state(self, loop):
        q, qd = loop.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
        assert "RK4" in loop.integration_path("RK4")
        with pytest.raises(mb.ModelError, match="RK4"):
            loop.simulate(0.1, q, qd, method="RK4", dt=0.01)


class TestRightHandSide:
    def test_reduced_rhs_equals_the_python_workspace(self, loop):
        """At states off the last accepted one (Newton has work to do), with and without tau."""
        kernel, formulation = loop.kernel, loop._formulation
        q0, qd0 = loop.assemble([1.0, -0.5, 1.5], [2.0, 0.0, 0.0])
        for tau in (None, np.array([0.3, -0.2, 0.1])):
            with ReducedRun(formulation, kernel, kernel.compiled.functions.lib, q0, qd0, tau) as run:
                workspace = formulation.start(kernel, 0.0, q0, qd0, tau)
                for t, dy in ((0.0, (0.0, 0.0)), (0.01, (0.02, 0.3)), (0.05, (-0.1, -1.0))):
                    y = run.y0 + np.array(dy)
                    np.testing.assert_allclose(run.rhs(t, y), workspace.rhs(t, y), rtol=1e-9, atol=1e-9)

    @pytest.mark.parametrize("limit", [None, 1.0])
    def test_condition_of_the_dependent_block_equals_the_python_one(self, loop, limit, monkeypatch):
        """The compiled bookkeeping after a step measures J_d's condition as Python does where
        it matters (at or above the limit: exact); below it, an upper bound may say so."""
        kernel, formulation = loop.kernel, loop._formulation
        if limit is not None:
            monkeypatch.setattr(type(formulation), "repartition_condition", limit)
        q0, qd0 = loop.assemble([1.0, -0.5, 1.5], [2.0, 0.0, 0.0])
        lib = kernel.compiled.functions.lib
        with ReducedRun(formulation, kernel, lib, q0, qd0, None) as run:
            accept = lib.lagrange_accept
            accept.argtypes = [ctypes.c_double, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
            out = np.empty(6)
            y = run.y0 + np.array([0.4, 0.0])
            status = accept(0.1, y.ctypes.data, out.ctypes.data, kernel.p.ctypes.data)
            ws = run.workspace
            cv = formulation.constraint_values(kernel, 0.1, out[:3], np.zeros(3))
            assert abs(cv.g).max() < 1e-11  # the full state is on the loop
            exact = ws.condition(cv.J, ws.rows, ws.dep)
            if limit is None:  # below the limit: no pause, the bound is above the exact value
                assert status == 0 and exact <= run.info[0] * (1 + 1e-12) < formulation.repartition_condition
            else:
                assert status == PAUSED and run.info[0] == pytest.approx(exact, rel=1e-9)
            np.testing.assert_array_equal(run.acc, np.concatenate(([0.1], out)))


class TestSameMotionAsPythonStepping:
    @pytest.mark.parametrize("speed, t_end, rtol, restarts", [(1.0, 1.0, 1e-10, 0), (4.0, 2.0, 1e-6, 1)])
    def test_fourbar(self, loop, speed, t_end, rtol, restarts):
        """At speed 4 and rtol 1e-6 a trial state at t = 1.135 s has no dependent coordinates
        near the last accepted ones: both go back there and retry with a shorter step."""
        q, qd = loop.assemble([1.0, -0.5, 1.5], [speed, 0.0, 0.0])
        t = np.linspace(0, t_end, 31)
        a = loop.simulate(t_end, q, qd, rtol=rtol, atol=rtol * 1e-2, t_eval=t)
        b = loop.simulate(t_end, q, qd, rtol=rtol, atol=rtol * 1e-2, t_eval=t, integrator="scipy")
        assert a.stats["integrator"] == "compiled" and b.stats["integrator"] == "scipy"
        assert a.stats["restarts"] == b.stats["restarts"] == restarts
        assert a.stats["steps"] == b.stats["steps"]
        np.testing.assert_allclose(a.q, b.q, atol=1e-9)
        np.testing.assert_allclose(a.qd, b.qd, atol=1e-8)
        assert a.constraint_violation().max() < 1e-10

    def test_every_step_output_takes_the_same_steps(self):
        system, q, qd = library("four_bar")
        a = system.simulate(0.5, q, qd, rtol=1e-10, atol=1e-12)
        b = system.simulate(0.5, q, qd, rtol=1e-10, atol=1e-12, integrator="scipy")
        assert a.stats["steps"] == b.stats["steps"]
        np.testing.assert_allclose(a.t, b.t, rtol=1e-6)  # (step sizes feel Newton's 1e-12 rounding)
        np.testing.assert_allclose(a.q, b.q, atol=1e-8)

    def test_slider_loop_with_constant_tau(self):
        system, q, qd = library("double_pendulum_slider")
        t = np.linspace(0, 0.6, 13)
        tau = np.array([0.05, -0.02])
        a = system.simulate(0.6, q, qd, rtol=1e-10, atol=1e-12, t_eval=t, tau=tau)
        b = system.simulate(0.6, q, qd, rtol=1e-10, atol=1e-12, t_eval=t, tau=tau, integrator="scipy")
        assert a.stats["integrator"] == "compiled"
        np.testing.assert_allclose(a.q, b.q, atol=1e-8)
        np.testing.assert_allclose(a.qd, b.qd, atol=1e-7)


class TestConservationAndClosedForms:
    def test_energy_is_conserved_on_the_loop_over_10_s(self):
        system, q, qd = library("four_bar")
        res = system.simulate(10.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=np.linspace(0, 10, 501))
        assert res.stats["integrator"] == "compiled"
        assert energy_error(res) < 1e-8
        assert res.constraint_violation().max() < 1e-10
        assert res["theta1"][-1] - res["theta1"][0] > 4 * np.pi   # the crank turns over

    def test_speed_motor_slider_crank_follows_the_closed_form(self):
        """No degree of freedom: theta = omega t and x = r cos(theta) + sqrt(l^2 - r^2 sin^2(theta)),
        computed in C; the same as Python's prescribed motion."""
        system, q, qd = library("slider_crank")
        r, l, omega = 0.1, 0.3, 2 * np.pi
        t = np.linspace(0, 1.0, 41)
        res = system.simulate(1.0, q, qd, t_eval=t)
        assert res.stats["integrator"] == "compiled" and res.stats["method"] == "prescribed"
        theta = omega * t
        np.testing.assert_allclose(res["theta"], theta, atol=1e-10)
        np.testing.assert_allclose(res["x"], r * np.cos(theta) + np.sqrt(l ** 2 - (r * np.sin(theta)) ** 2), atol=1e-10)
        np.testing.assert_allclose(res["x_d"], -r * omega * np.sin(theta) * (1 + r * np.cos(theta) / np.sqrt(
            l ** 2 - (r * np.sin(theta)) ** 2)), atol=1e-9)
        python = system.simulate(1.0, q, qd, t_eval=t, integrator="scipy")
        np.testing.assert_allclose(res.q, python.q, atol=1e-12)

    def test_speed_motor_with_a_free_coordinate(self):
        """A double pendulum whose first joint turns at a constant speed: one degree of
        freedom left, the motor row evaluated in C; the motor's work equals the change of
        energy."""
        m = mb.Model("motor_pendulum", gravity=(0, -9.81, 0))
        a = m.add(mb.Body("a", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 0.1, 0.1)))
        b = m.add(mb.Body("b", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 0.1, 0.1)))
        m.add(mb.Revolute("A", m.ground, a, axis="z"))
        m.add(mb.Revolute("B", a, b, axis="z", parent_point=(1.0, 0, 0)))
        m.add(mb.Motor("spin", "A", speed=2.0))
        system = compiled(m.compile())
        assert system.integration_path() == "compiled" and system.ndof == 1
        t = np.linspace(0, 1.0, 201)
        res = system.simulate(1.0, [0.3, 0.2], [2.0, 0.0], rtol=1e-10, atol=1e-12, t_eval=t)
        ref = system.simulate(1.0, [0.3, 0.2], [2.0, 0.0], rtol=1e-10, atol=1e-12, t_eval=t, integrator="scipy")
        assert res.stats["integrator"] == "compiled"
        np.testing.assert_allclose(res["A"], 0.3 + 2.0 * t, atol=1e-11)
        np.testing.assert_allclose(res.q, ref.q, atol=1e-8)
        assert res.offsets == pytest.approx(ref.offsets)
        torque = np.array([system.reactions(qi, qdi, ti, offsets=res.offsets)["spin"]
                           for qi, qdi, ti in zip(res.q, res.qd, res.t)])
        from scipy.integrate import trapezoid
        E = res.energy().total
        assert trapezoid(torque * 2.0, t) == pytest.approx(E[-1] - E[0], rel=1e-4)


def hopper_model() -> mb.Model:
    """A cart on a vertical slide resting on the floor (plastic contact) with a rod spinning
    below it: the rod's pull lifts the cart off (the held contact's force would pull) and it
    lands again, twice in a second."""
    m = mb.Model("hopper", gravity=(0, 0, -9.81))
    cart = m.add(mb.Body("cart", mass=0.2))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0, -0.25), inertia=(0.5 ** 2 / 12, 0.5 ** 2 / 12, 1e-4)))
    m.add(mb.Prismatic("lift", m.ground, cart, axis="z", coords="z"))
    m.add(mb.Revolute("hinge", cart, rod, axis="y", coords="th"))
    m.add(mb.Contact("floor", cart, normal=(0, 0, 1), restitution=0.0))
    return m


def hopper():
    return compiled(hopper_model().compile())


class TestContacts:
    """Contacts in the compiled loop: stretches between events run in C, which stops at a step
    with an event; Python locates and applies it as in Python stepping."""

    def test_bouncing_ball_impacts_follow_the_geometric_series(self):
        system, q, qd = library("bouncing_ball")
        assert system.integration_path() == "compiled"
        a = system.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12)
        b = system.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, integrator="scipy")
        assert a.stats["integrator"] == "compiled" and b.stats["integrator"] == "scipy"
        g, e, drop = 9.81, 0.8, 1.0 - 0.05
        first = np.sqrt(2 * drop / g)
        expected = first + np.cumsum([2 * e ** k * g * first / g for k in range(1, 6)])
        times = [ev.time for ev in a.events]
        np.testing.assert_allclose(times, np.concatenate(([first], expected)), rtol=1e-9)
        np.testing.assert_allclose(times, [ev.time for ev in b.events], rtol=1e-12)
        np.testing.assert_allclose([ev.impulse for ev in a.events], [ev.impulse for ev in b.events], rtol=1e-9)

    def test_coming_to_rest_holds_the_contact(self):
        """After the bounces' series sums up the ball is held on the floor (no degree of
        freedom left: the loop steps an empty state to the end)."""
        system, q, qd = library("bouncing_ball")
        t = np.linspace(0, 5.0, 51)
        a = system.simulate(5.0, q, qd, t_eval=t)
        b = system.simulate(5.0, q, qd, t_eval=t, integrator="scipy")
        assert a.stats["integrator"] == "compiled"
        assert a.persistent_contacts == b.persistent_contacts == ["floor"]
        assert a.closed_contacts == b.closed_contacts
        np.testing.assert_allclose(a.q[-1], [0.05], atol=1e-12)
        np.testing.assert_allclose(a.q, b.q, atol=1e-9)

    def test_held_contact_lets_go_and_lands_again(self):
        system = hopper()
        assert system.integration_path() == "compiled"
        t = np.linspace(0, 1.0, 101)
        a = system.simulate(1.0, [0.0, 0.0], [0.0, 12.0], rtol=1e-10, atol=1e-12, t_eval=t)
        b = system.simulate(1.0, [0.0, 0.0], [0.0, 12.0], rtol=1e-10, atol=1e-12, t_eval=t, integrator="scipy")
        assert a.stats["integrator"] == "compiled"
        lift_offs = [i for i in range(1, len(t)) if a.closed_contacts[i] == () and a.closed_contacts[i - 1] == (0,)]
        kinds = [ev.kind for ev in a.events]
        assert len(lift_offs) == 3 and kinds.count("impact") == 2 and kinds.count("release") == 3  # lift-offs, landings
        assert a.closed_contacts == b.closed_contacts
        assert [ev.time for ev in a.events] == pytest.approx([ev.time for ev in b.events], rel=1e-10)
        np.testing.assert_allclose(a.q, b.q, atol=1e-9)
        held = np.array([c == (0,) for c in a.closed_contacts])
        np.testing.assert_allclose(a["z"][held], 0.0, atol=1e-12)   # on the floor while held
        assert a["z"].max() > 1e-3   # hops of ~2 mm

    def test_pendulum_against_a_wall(self):
        system, q, qd = library("pendulum_wall")
        t = np.linspace(0, 4.0, 81)
        a = system.simulate(4.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        b = system.simulate(4.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t, integrator="scipy")
        assert a.stats["integrator"] == "compiled" and len(a.events) == len(b.events) > 0
        np.testing.assert_allclose(a.q, b.q, atol=1e-9)
        np.testing.assert_allclose([ev.energy_loss for ev in a.events], [ev.energy_loss for ev in b.events], rtol=1e-8)


@pytest.mark.parametrize("name", ["four_bar", "bouncing_ball", "double_pendulum"])
def test_every_step_output_starts_at_the_initial_state(name):
    """The compiled loops advance their state in place: the first output row is the start."""
    system, q, qd = library(name)
    q, qd = system.assemble(q, qd)
    res = system.simulate(0.2, q, qd)
    assert res.stats["integrator"] == "compiled" and res.t[0] == 0.0
    np.testing.assert_allclose(res.q[0], q, atol=1e-12)   # (simulate assembles again: rounding)
    np.testing.assert_allclose(res.qd[0], qd, atol=1e-12)


class TestDriveElements:
    """Drive elements without states act in the reduced loop (their forces join tau)."""

    def test_drive_torque_on_a_loop(self):
        m = fourbar()
        m.add(mb.Drive("drv", "A", torque=0.8))
        system = compiled(m.compile())
        assert system.integration_path() == "compiled"
        q, qd = system.assemble([1.0, -0.5, 1.5], [0.5, 0.0, 0.0])
        t = np.linspace(0, 1.0, 21)
        a = system.simulate(1.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        b = system.simulate(1.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t, integrator="scipy")
        plain = compiled(fourbar().compile()).simulate(1.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        assert a.stats["integrator"] == "compiled"
        np.testing.assert_allclose(a.q, b.q, atol=1e-8)
        assert np.abs(a.q - plain.q).max() > 1e-2   # the drive does act
        # the drive's work (0.8 N m times the crank angle turned) is the energy gained
        E = a.energy().total
        assert E[-1] - E[0] == pytest.approx(0.8 * (a.q[-1, 0] - a.q[0, 0]), rel=1e-6)

    def test_drive_torque_with_a_held_contact(self):
        """The hopper's rod driven by a constant torque: lift-offs where Python stepping has them."""
        m = hopper_model()
        m.add(mb.Drive("spin", "hinge", torque=2.0))
        system = compiled(m.compile())
        t = np.linspace(0, 1.0, 51)
        a = system.simulate(1.0, [0.0, 0.0], [0.0, 6.0], rtol=1e-10, atol=1e-12, t_eval=t)
        b = system.simulate(1.0, [0.0, 0.0], [0.0, 6.0], rtol=1e-10, atol=1e-12, t_eval=t, integrator="scipy")
        assert a.stats["integrator"] == "compiled"
        assert a.closed_contacts == b.closed_contacts and () in a.closed_contacts
        np.testing.assert_allclose(a.q, b.q, atol=1e-8)


class TestDriveStates:
    """Drive elements with states inside loops: the states follow ``[q_i, qd_i]`` in the
    reduced state of the compiled loop."""

    V, R, L, K = 6.0, 2.0, 0.05, 0.3

    def dc_motor(self, joint="A"):
        return mb.DCMotor("dc", joint, ratio=1.0, resistance=self.R, inductance=self.L, k=self.K, voltage=self.V)

    def test_dc_motor_on_a_loop_balances_its_energy(self):
        """The four-bar's crank driven by a DC motor (current a state): the same motion and
        current as scipy stepping, and the electrical energy put in (V i minus the resistor's
        R i^2 and the inductor's L i^2 / 2) is the mechanical energy gained."""
        m = fourbar()
        m.add(self.dc_motor())
        system = compiled(m.compile())
        assert system.extra_states == ("dc.current",) and system.integration_path() == "compiled"
        q, qd = system.assemble([1.0, -0.5, 1.5], [0.5, 0.0, 0.0])
        t = np.linspace(0, 1.0, 2001)
        kw = dict(rtol=1e-11, atol=1e-12, t_eval=t)
        a = system.simulate(1.0, q, qd, **kw)
        b = system.simulate(1.0, q, qd, integrator="scipy", **kw)
        assert a.stats["integrator"] == "compiled" and b.stats["integrator"] == "scipy"
        np.testing.assert_allclose(a.q, b.q, atol=1e-8)
        np.testing.assert_allclose(a["dc.current"], b["dc.current"], atol=1e-8)
        i = a["dc.current"]
        from scipy.integrate import simpson
        electrical = simpson(self.V * i - self.R * i ** 2, x=t) - 0.5 * self.L * (i[-1] ** 2 - i[0] ** 2)
        E = a.energy().total
        assert abs(E[-1] - E[0]) > 0.1
        assert E[-1] - E[0] == pytest.approx(electrical, rel=1e-6)

    def test_dc_motor_on_a_driven_loop_without_degrees_of_freedom(self):
        """A position motor turns the crank, a DC motor sits on the rocker: nothing mechanical
        to integrate, the current alone is stepped in the loop; with the rocker's speed known,
        L di/dt = V - R i - k w_rocker is integrated independently here."""
        from scipy.integrate import solve_ivp
        m = fourbar(motor=mb.Motor("drive", "A", position="1.0 + 0.5*sin(3*t)"))
        m.add(self.dc_motor("D"))
        system = compiled(m.compile())
        assert system.ndof == 0 and system.integration_path() == "compiled"
        q, qd = system.assemble([1.0, -0.5, 1.5], [1.5, 0.0, 0.0])
        t = np.linspace(0, 1.0, 41)
        a = system.simulate(1.0, q, qd, rtol=1e-11, atol=1e-12, t_eval=t)
        b = system.simulate(1.0, q, qd, rtol=1e-9, atol=1e-11, t_eval=t, integrator="scipy")
        assert a.stats["integrator"] == "compiled"
        np.testing.assert_allclose(a.q, b.q, atol=1e-10)
        np.testing.assert_allclose(a["dc.current"], b["dc.current"], atol=1e-8)
        # the rocker's speed from the Python assembly on a fine grid, as a spline of t
        from scipy.interpolate import CubicSpline
        rocker = system.speeds.index("D")
        grid = np.linspace(0, 1.0, 101)
        w = [system.assemble(a.q[np.argmin(abs(a.t - s))], None, t=s)[1][rocker] for s in grid]
        speed = CubicSpline(grid, w)
        ref = solve_ivp(lambda s, i: (self.V - self.R * i - self.K * speed(s)) / self.L, (0, 1.0), [0.0],
                        t_eval=t, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(a["dc.current"], ref.y[0], atol=1e-6)
