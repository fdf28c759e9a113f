"""Python callables called back from the compiled loops (codegen/callbacks.py): callable
torques, a callable ``tau`` and callable drive signals run compiled, give the motion of the
equivalent expression models and closed forms, and their failures stop the loop with the
callable's own exception or the Python path's error."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import fourbar

K, C, INERTIA = 5.0, 0.3, 0.8  # N m/rad, N m s/rad, kg m^2
TIGHT = dict(rtol=1e-12, atol=1e-14)


def rotor(torque=None, *, spring: bool = False, name: str = "cb_rotor") -> mb.Model:
    """A rotor on a pivot without gravity: ``INERTIA phi'' = torque``; with ``spring`` the
    torque ``-K phi - C phi'`` as an expression (TorsionSpring)."""
    m = mb.Model(name, gravity=(0, 0, 0))
    body = m.add(mb.Body("wheel", mass=1.0, inertia=(INERTIA, 1.0, 1.0)))
    m.add(mb.Revolute("pivot", m.ground, body, axis="x", coords="phi"))
    if torque is not None:
        m.add(mb.JointTorque("ctl", "pivot", torque))
    if spring:
        m.add(mb.TorsionSpring("spring", "pivot", stiffness=K, damping=C))
    return m


def damped(t: np.ndarray, phi0: float) -> np.ndarray:
    """Closed form of ``INERTIA phi'' = -K phi - C phi'`` from rest at ``phi0``."""
    w0, zeta = np.sqrt(K / INERTIA), C / (2 * np.sqrt(K * INERTIA))
    wd = w0 * np.sqrt(1 - zeta ** 2)
    return phi0 * np.exp(-zeta * w0 * t) * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t))


@pytest.fixture(scope="module")
def controlled():
    system = rotor(lambda t, q, qd: [-K * q[0] - C * qd[0]]).compile()
    if system.backend != "c":
        pytest.skip("no C compiler: the callbacks come from compiled loops")
    return system


T = np.linspace(0.0, 3.0, 13)


class TestCallableTorque:
    def test_runs_compiled_and_follows_the_closed_form(self, controlled):
        assert controlled.integration_path() == "compiled"
        res = controlled.simulate(3.0, [0.3], t_eval=T, **TIGHT)
        assert res.stats["integrator"] == "compiled"
        np.testing.assert_allclose(res["phi"], damped(T, 0.3), rtol=0, atol=1e-9)

    def test_equals_the_expression_model(self, controlled):
        spring = rotor(spring=True, name="cb_rotor_spring").compile()
        ref = spring.simulate(3.0, [0.3], t_eval=T, **TIGHT)
        res = controlled.simulate(3.0, [0.3], t_eval=T, **TIGHT)
        np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-9)
        assert res.stats["steps"] == ref.stats["steps"]  # the same values at every stage: the same steps

    @pytest.mark.parametrize("method", ["RK45", "Radau"])
    def test_scipy_methods_step_the_compiled_rhs_with_the_callback(self, controlled, method):
        res = controlled.simulate(3.0, [0.3], t_eval=T, method=method, rtol=1e-10, atol=1e-12)
        assert res.stats["integrator"] == "scipy"
        np.testing.assert_allclose(res["phi"], damped(T, 0.3), rtol=0, atol=1e-7)

    def test_rk4_calls_back_at_every_stage(self, controlled):
        res = controlled.simulate(3.0, [0.3], method="RK4", dt=1e-3, t_eval=T)
        np.testing.assert_allclose(res["phi"], damped(T, 0.3), rtol=0, atol=1e-10)  # O(dt^4)

    def test_exception_stops_the_loop_and_names_the_component(self):
        def torque(t, q, qd):
            if t > 0.5:
                raise ValueError("controller saturated")
            return [0.0]
        system = rotor(torque, name="cb_rotor_raise").compile()
        for integrator in ("compiled", "scipy"):
            with pytest.raises(ValueError, match="controller saturated") as info:
                system.simulate(1.0, [0.3], integrator=integrator)
        with pytest.raises(ValueError, match="controller saturated") as info:
            system.simulate(1.0, [0.3])
        note = " ".join(getattr(info.value, "__notes__", ()))
        assert "JointTorque 'ctl'" in note and "compiled code" in note
        assert 0.5 < float(note.split("t = ")[1].split(" s")[0]) < 1.0  # the stage time the callable saw

    @pytest.mark.parametrize("value, message", [(float("nan"), "non-finite value"),
                                                ([1.0, 2.0], "2 values, expected 1")])
    def test_bad_values_give_the_python_paths_error(self, value, message):
        system = rotor(lambda t, q, qd: [0.0] if t < 0.2 else value, name="cb_rotor_bad").compile()
        for integrator in ("compiled", "scipy"):
            with pytest.raises(mb.SimulationError, match=f"JointTorque 'ctl': callable returned.*{message}"):
                system.simulate(1.0, [0.3], integrator=integrator)


class TestCallableTau:
    def test_equals_the_expression_model_and_the_python_path(self):
        free = rotor(name="cb_rotor_free").compile()
        tau = lambda t, q, qd: [-K * q[0] - C * qd[0]]  # noqa: E731
        assert free.integration_path(tau=tau) == "compiled"
        res = free.simulate(3.0, [0.3], t_eval=T, tau=tau, **TIGHT)
        assert res.stats["integrator"] == "compiled"
        np.testing.assert_allclose(res["phi"], damped(T, 0.3), rtol=0, atol=1e-9)
        python = free.simulate(3.0, [0.3], t_eval=T, tau=tau, integrator="scipy", **TIGHT)
        np.testing.assert_allclose(res.q, python.q, rtol=0, atol=1e-11)  # (scipy's DOP853: the same steps)

    def test_adds_to_the_models_own_callable(self, controlled):
        """A callable tau and a callable torque together: half the law each."""
        half = rotor(lambda t, q, qd: [-0.5 * K * q[0]], name="cb_rotor_half").compile()
        res = half.simulate(3.0, [0.3], t_eval=T, tau=lambda t, q, qd: [-0.5 * K * q[0] - C * qd[0]], **TIGHT)
        np.testing.assert_allclose(res["phi"], damped(T, 0.3), rtol=0, atol=1e-9)

    def test_exception_names_tau(self):
        free = rotor(name="cb_rotor_free").compile()

        def tau(t, q, qd):
            raise KeyError("gain table")
        with pytest.raises(KeyError, match="gain table") as info:
            free.simulate(1.0, [0.3], tau=tau)
        assert "callable of tau" in " ".join(info.value.__notes__)

    def test_sweep_on_threads_calls_each_cases_own_callable(self):
        free = rotor(name="cb_rotor_free").compile()
        cases = [{"q0": [0.3], "tau": (lambda k: lambda t, q, qd: [-k * q[0]])(k)} for k in (1.0, 4.0, 9.0)]
        threaded = mb.sweep(free, cases, t_end=1.0, t_eval=[1.0], threads=3, **TIGHT)
        for k, res in zip((1.0, 4.0, 9.0), threaded):
            assert res.stats["integrator"] == "compiled"
            assert res["phi"][-1] == pytest.approx(0.3 * np.cos(np.sqrt(k / INERTIA)), abs=1e-9)


class TestCallableDriveSignal:
    def test_drive_torque_callable_equals_the_expression_signal(self):
        def model(torque, name):
            m = rotor(name=name)
            m.add(mb.Drive("drive", "pivot", ratio=2.0, torque=torque))
            return m.compile()
        called = model(lambda t, q, qd: 0.25 * np.sin(3.0 * t), "cb_drive_py")
        signal = model(mb.Sine(amplitude=0.25, frequency=3.0 / (2 * np.pi)), "cb_drive_expr")
        assert called.integration_path() == "compiled"
        res = called.simulate(2.0, [0.0], t_eval=T[:9], **TIGHT)
        ref = signal.simulate(2.0, [0.0], t_eval=T[:9], **TIGHT)
        assert res.stats["integrator"] == "compiled"
        np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-9)
        # closed form: INERTIA phi'' = 2 * 0.25 sin(3 t) from rest
        t = T[:9]
        np.testing.assert_allclose(res["phi"], 0.5 / INERTIA * (t / 3 - np.sin(3 * t) / 9), rtol=0, atol=1e-9)
        # a scipy method on the compiled right-hand side (drive elements: their inputs called back too)
        rk45 = called.simulate(2.0, [0.0], t_eval=t, method="RK45", rtol=1e-10, atol=1e-12)
        assert rk45.stats["integrator"] == "scipy" and rk45.stats["rhs"] == "compiled"
        np.testing.assert_allclose(rk45["phi"], 0.5 / INERTIA * (t / 3 - np.sin(3 * t) / 9), rtol=0, atol=1e-8)

    def test_motor_voltage_callable_with_drive_states(self):
        def model(voltage, name):
            m = rotor(name=name)
            m.add(mb.DCMotor("motor", "pivot", ratio=5.0, resistance=2.0, inductance=0.05, k=0.03, voltage=voltage))
            return m.compile()
        called = model(lambda t, q, qd: 1.0 - 0.5 * qd[0], "cb_motor_py")
        assert called.integration_path() == "compiled"
        res = called.simulate(1.0, [0.0], t_eval=T[:5], **TIGHT)
        python = called.simulate(1.0, [0.0], t_eval=T[:5], integrator="scipy", **TIGHT)
        assert res.stats["integrator"] == "compiled" and python.stats["integrator"] == "scipy"
        np.testing.assert_allclose(res.q, python.q, rtol=0, atol=1e-10)
        np.testing.assert_allclose(res["motor.current"], python["motor.current"], rtol=0, atol=1e-10)
        assert abs(res["motor.current"][-1]) > 1e-3  # (the callable drove the motor)

    def test_exception_names_the_signal(self):
        def voltage(t, q, qd):
            raise RuntimeError("sensor offline")
        m = rotor(name="cb_motor_raise")
        m.add(mb.DCMotor("motor", "pivot", ratio=5.0, resistance=2.0, inductance=0.05, k=0.03, voltage=voltage))
        with pytest.raises(RuntimeError, match="sensor offline") as info:
            m.compile().simulate(1.0, [0.0])
        assert "signal" in " ".join(info.value.__notes__)


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_fourbar_with_a_callable_crank_torque(formulation):
    """A loop model in both formulations: the callable torque equals the TorsionSpring on the
    crank (compiled loop and scipy's stepping of the compiled right-hand side)."""
    law = lambda t, q, qd: [-2.0 * (q[0] - 1.0) - 0.1 * qd[0]]  # noqa: E731
    called_model = fourbar(name="cb_fourbar_py")
    called_model.add(mb.JointTorque("ctl", "A", law))
    called = called_model.compile(formulation)
    spring_model = fourbar(name="cb_fourbar_spring")
    spring_model.add(mb.TorsionSpring("spring", "A", stiffness=2.0, rest=1.0, damping=0.1))
    spring = spring_model.compile(formulation)
    assert called.integration_path() == "compiled"
    q, qd = called.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
    t = np.linspace(0.0, 1.0, 6)
    for options in ({}, {"method": "RK45"}):
        res = called.simulate(1.0, q, qd, t_eval=t, rtol=1e-11, atol=1e-13, **options)
        ref = spring.simulate(1.0, q, qd, t_eval=t, rtol=1e-11, atol=1e-13, **options)
        assert res.stats["integrator"] == ref.stats["integrator"] == ("scipy" if options else "compiled")
        np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-9)
    assert res.constraint_violation().max() < 1e-8


def test_contact_events_see_the_callables_values():
    """Impacts located in the compiled stretches (gap and dense output from the same stage
    values): a callable damping torque and a callable tau give the events of the expression
    model driven by the same tau."""
    from pathlib import Path
    library = Path(__file__).resolve().parents[1] / "library" / "pendulum_wall.toml"
    called_model = mb.load(library)
    called_model.add(mb.JointTorque("ctl", "hinge", lambda t, q, qd: [-0.4 * qd[0]]))
    spring_model = mb.load(library)
    spring_model.add(mb.TorsionSpring("damper", "hinge", stiffness=0.0, damping=0.4))
    tau = lambda t, q, qd: [0.2 * np.sin(5.0 * t)]  # noqa: E731
    t = np.linspace(0.0, 3.0, 7)
    res = called_model.compile().simulate(3.0, [0.6], [0.0], t_eval=t, tau=tau, rtol=1e-10, atol=1e-12)
    ref = spring_model.compile().simulate(3.0, [0.6], [0.0], t_eval=t, tau=tau, rtol=1e-10, atol=1e-12)
    assert res.stats["integrator"] == "compiled" and len(res.events) == len(ref.events) >= 2
    for a, b in zip(res.events, ref.events):
        assert a.time == pytest.approx(b.time, abs=1e-10) and a.impulse == pytest.approx(b.impulse, rel=1e-9)
    np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-9)


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_fourbar_with_a_callable_motor_voltage(formulation):
    """Drive states and a callable signal on a loop model (the lagrange reduced loop's drive
    inputs, the dae loop's): the compiled loop equals scipy's stepping of the Python solve."""
    m = fourbar(name="cb_fourbar_motor")
    m.add(mb.DCMotor("motor", "A", ratio=5.0, resistance=2.0, inductance=0.05, k=0.03,
                     voltage=lambda t, q, qd: 1.0 - 0.5 * qd[0]))
    system = m.compile(formulation)
    q, qd = system.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
    t = np.linspace(0.0, 1.0, 6)
    res = system.simulate(1.0, q, qd, t_eval=t, rtol=1e-11, atol=1e-13)
    python = system.simulate(1.0, q, qd, t_eval=t, rtol=1e-11, atol=1e-13, integrator="scipy")
    assert res.stats["integrator"] == "compiled" and python.stats["integrator"] == "scipy"
    np.testing.assert_allclose(res.q, python.q, rtol=0, atol=1e-10)
    np.testing.assert_allclose(res["motor.current"], python["motor.current"], rtol=0, atol=1e-10)
    assert abs(res["motor.current"][-1]) > 0.1  # (the callable drove the motor)
