"""Analysis of models with drive states (motor currents, PID integrals): equilibrium solves for
them, linearize/modes find them, ``mbcomp analyse`` runs on every library model.

Numbers are checked against the analytic rest (a PID integral puts its joint on the setpoint
and carries the load; a motor's current is torque / (ratio k)) and against a finite-difference
Jacobian of the full right-hand side written out here from the public API."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.optimize

import mbcomp as mb

from conftest import G, assert_close

ROOT = Path(__file__).resolve().parents[1]
LENGTH, MASS = 0.6, 1.3


def pid_pendulum(ki=40.0, setpoint=0.7, name="pid_pendulum", kp=30.0, kd=4.0, ratio=2.0):
    """A point mass on a rod (about x, gravity -z) driven by a geared Drive whose rotor torque is
    a PID on the joint angle: at rest ``ratio * ki * z = m g L sin(setpoint)``."""
    m = mb.Model(name, gravity=(0, 0, -G))
    bob = m.add(mb.Body("bob", mass=MASS, com=(0, 0, -LENGTH)))
    joint = m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    pid = m.add(mb.PID("pid", mb.Angle(joint), setpoint, kp=kp, ki=ki, kd=kd))
    m.add(mb.Drive("drive", joint, ratio=ratio, torque=pid))
    return m


MOTOR = dict(ratio=25.0, resistance=1.5, inductance=0.02, k=0.04)


def servo_pendulum(setpoint=0.5, name="servo_pendulum"):
    """The same pendulum driven by a DC motor whose voltage is a PID on the angle."""
    m = mb.Model(name, gravity=(0, 0, -G))
    bob = m.add(mb.Body("bob", mass=MASS, com=(0, 0, -LENGTH)))
    joint = m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    pid = m.add(mb.PID("pid", mb.Angle(joint), setpoint, kp=80.0, ki=120.0, kd=5.0))
    m.add(mb.DCMotor("motor", joint, voltage=pid, rotor_inertia=1e-5, **MOTOR))
    return m


@pytest.fixture(scope="module")
def servo():
    return servo_pendulum().compile()


def complex_parts(values):
    """Eigenvalues sorted, as their real then imaginary parts (for ``assert_close``)."""
    values = np.sort_complex(np.asarray(values, dtype=complex))
    return np.concatenate((values.real, values.imag))


def gravity_torque(theta):
    """The torque that holds the bob at ``theta`` (N m)."""
    return MASS * G * LENGTH * np.sin(theta)


def test_pid_integral_puts_the_joint_on_its_setpoint_and_carries_the_load():
    system = pid_pendulum().compile()
    q, states = system.equilibrium([0.0], return_states=True)   # the guess is 0.7 rad away
    assert_close(q, [0.7], rtol=1e-10, name="angle at rest = setpoint")
    assert_close(states["pid.integral"], gravity_torque(0.7) / (2.0 * 40.0), rtol=1e-9, name="integral")
    plain = system.equilibrium([0.0])                           # the default still returns q alone
    assert isinstance(plain, np.ndarray) and plain.shape == (1,)
    # the rest found is the end of a simulation from elsewhere
    res = system.simulate(30.0, [0.1], x0={"pid.integral": 0.0})
    assert_close(res.q[-1], q, atol=1e-6, name="simulated rest")


def test_a_p_controller_rests_with_the_steady_state_error_and_leaves_its_integral_alone():
    """ki = 0: the integral acts on nothing; the rest is ratio kp (sp - theta) = m g L sin(theta)."""
    system = pid_pendulum(ki=0.0, name="p_pendulum").compile()
    q, states = system.equilibrium([0.0], return_states=True)
    exact = scipy.optimize.brentq(lambda th: 2.0 * 30.0 * (0.7 - th) - gravity_torque(th), 0.0, 0.7)
    assert_close(q, [exact], rtol=1e-10, name="P rest")
    assert states == {"pid.integral": 0.0}
    assert system.modes(q).stable


def test_dc_motor_rest_current_is_the_load_over_ratio_times_k(servo):
    q, states = servo.equilibrium([0.0], return_states=True)
    assert_close(q, [0.5], rtol=1e-10, name="angle")
    current = gravity_torque(0.5) / (MOTOR["ratio"] * MOTOR["k"])
    assert_close(states["motor.current"], current, rtol=1e-9, name="rest current")
    # V = R i at rest, and V = ki z (no error, no motion)
    assert_close(states["pid.integral"], MOTOR["resistance"] * current / 120.0, rtol=1e-9, name="integral")
    assert_close(mb.analysis.rest_states(servo, q), [states["pid.integral"], states["motor.current"]],
                 rtol=1e-9, name="rest_states at the equilibrium")


def full_rhs(system, x, t=0.0):
    """``[qd, qdd, dz/dt]`` of the whole state from the public API (no analysis code)."""
    nq = len(system.coords)
    q, qd, z = x[:nq], x[nq:2 * nq], x[2 * nq:]
    qdd = system.accelerations(q, qd, t, states=z)
    rates = system.drive_outputs(t, q, qd, z)[1]
    return np.concatenate((qd, qdd, rates))


def test_linearize_finds_the_rest_states_and_matches_a_jacobian_of_the_full_rhs(servo):
    q, states = servo.equilibrium([0.2], return_states=True)
    lin = servo.linearize(q)                          # no states given: found
    assert lin.states == ("theta", "theta_dot", "pid.integral", "motor.current")
    z = np.array([states[name] for name in servo.extra_states])
    assert_close(lin.operating_states, z, rtol=1e-9, name="operating states")
    x0 = np.concatenate((q, [0.0], z))
    assert np.max(np.abs(full_rhs(servo, x0))) < 1e-8  # a rest of the full state
    jac = np.column_stack([(full_rhs(servo, x0 + h * e) - full_rhs(servo, x0 - h * e)) / (2 * h)
                           for e in np.eye(len(x0)) for h in [1e-6 * max(1.0, abs(x0 @ e))]])
    assert_close(lin.A, jac, rtol=1e-6, atol=1e-5 * np.max(np.abs(jac)), name="A vs finite differences")
    assert_close(complex_parts(np.linalg.eigvals(lin.A)), complex_parts(np.linalg.eigvals(jac)),
                 rtol=1e-6, atol=1e-6, name="eigenvalues")
    modes = servo.modes(q)                            # no states given: found
    assert modes.stable
    assert_close(complex_parts(modes.all_eigenvalues), complex_parts(np.linalg.eigvals(jac)), rtol=1e-6,
                 atol=1e-6, name="modes' eigenvalues")
    with pytest.raises(mb.SimulationError, match="not an equilibrium"):
        servo.modes(q, states={"pid.integral": 0.0, "motor.current": 0.0})   # currents off: it falls


def test_constrained_model_with_a_pid_motor_in_both_formulations():
    """A four-bar whose crank is held by a PID-driven DC motor: the crank rests on the setpoint
    and the current balances the crank's share of gravity (from the holding forces)."""
    from conftest import fourbar
    results = {}
    for form in ("lagrange", "dae"):
        model = fourbar(name=f"held_{form}")
        pid = model.add(mb.PID("pid", mb.Angle("A"), -1.2, kp=60.0, ki=90.0, kd=3.0))
        model.add(mb.DCMotor("motor", "A", voltage=pid, **MOTOR))
        system = model.compile(formulation=form)
        q, states = system.equilibrium([-1.5, 1.2, -1.5], return_states=True)
        assert_close(q[0], -1.2, rtol=1e-9, name=f"{form} crank on its setpoint")
        assert system.constraint_violation(q) < 1e-10
        # the torque the motor gives is the one that holds the crank alone (tau on A only)
        plain = fourbar(name=f"plain_{form}").compile(formulation=form)
        tau = plain.inverse_dynamics(q, np.zeros(3), np.zeros(3), actuated="A")
        assert_close(MOTOR["ratio"] * MOTOR["k"] * states["motor.current"], tau[0], rtol=1e-7,
                     name=f"{form} motor torque")
        results[form] = complex_parts(system.modes(q).all_eigenvalues)
    assert_close(results["lagrange"], results["dae"], rtol=1e-6, atol=1e-6,
                 name="same eigenvalues in both formulations")


def test_time_varying_inputs_are_held_at_t_and_a_prescribed_motion_has_no_rest():
    system = servo_pendulum(setpoint=mb.Step(0.5, 0.8, 0.2), name="stepped").compile()
    assert_close(system.equilibrium([0.0], t=0.0), [0.2], rtol=1e-10, name="before the step")
    assert_close(system.equilibrium([0.0], t=1.0), [0.8], rtol=1e-10, name="after the step")
    q = system.equilibrium([0.0])                                     # by default: where the inputs settle
    assert_close(q, [0.8], rtol=1e-10, name="settled")
    assert system.modes(q).stable                                     # at the same time: an equilibrium
    current = gravity_torque(0.8) / (MOTOR["ratio"] * MOTOR["k"])
    assert_close(mb.analysis.rest_states(system, q)[1], current, rtol=1e-9, name="settled current")
    assert mb.analysis.changing_inputs(system, [0.2], t=0.0)          # the step is ahead
    assert not mb.analysis.changing_inputs(system, [0.8], t=1.0)      # nothing changes after it
    # a sine never settles: held at t = 0, where the setpoint is its offset
    waving = servo_pendulum(setpoint=mb.Sine(0.3, 0.5, offset=0.4), name="waving").compile()
    assert mb.analysis.operating_time(waving, [0.0]) == 0.0
    assert_close(waving.equilibrium([0.0]), [0.4], rtol=1e-10, name="sine held at t = 0")
    driven = mb.load(str(ROOT / "library" / "double_pendulum_motor.toml")).compile()
    with pytest.raises(mb.SimulationError, match="'motor' prescribes motion in time"):
        driven.equilibrium([0.0, 0.3])


# -- the command line on every library model ------------------------------------------------------
#: Library models without an equilibrium, and why (the message must say so).
NO_EQUILIBRIUM = {
    "bouncing_ball": "contacts",                         # free fall: a contact is not a static load
    "sliding_ball": "contacts",                          # resting on its contact: not a static load
    "box_on_slope": "contacts",                          # the same, on two contacts
    "ball_on_box": "contacts",                           # free fall onto a box: collisions are contacts
    "double_pendulum_motor": "prescribes motion",        # a motor drives phi1(t)
    "slider_crank": "prescribes motion",                 # a motor turns the crank
    "slider_crank_parts": "prescribes motion",           # the same, from parts
    "double_pendulum_slider": "singular position",       # its rests are dead points of the slider
}


def test_cli_analyse_runs_on_every_library_model(capsys, monkeypatch):
    from mbcomp.face.cli import main
    monkeypatch.chdir(ROOT)
    names = sorted(p.stem for p in (ROOT / "library").glob("*.toml"))
    assert set(NO_EQUILIBRIUM) <= set(names) and len(names) > 10
    for name in names:
        code = main(["analyse", name])
        captured = capsys.readouterr()
        if name in NO_EQUILIBRIUM:
            assert code == 1, name
            lines = captured.err.strip().splitlines()
            assert len(lines) == 1 and NO_EQUILIBRIUM[name] in lines[0] and "Traceback" not in captured.err, \
                (name, captured.err)
            continue
        assert code == 0, (name, captured.err)
        assert "stability:" in captured.out
        assert max(len(line) for line in captured.out.splitlines()) <= 160, (name, captured.out)
    # the servo arm: both joints on their targets, the currents and integrals at rest
    main(["analyse", "servo_arm"])
    out = capsys.readouterr().out
    system = mb.load("library/servo_arm.toml").compile()
    q, states = system.equilibrium([0.0, 0.0], return_states=True)
    assert_close(q, [0.6, -0.4], rtol=1e-9, name="servo arm targets")
    assert f"{states['shoulder.motor.current']:.6g}" in out and "drive states at rest" in out
    assert "stability: stable" in out


def test_cli_shape_column_shows_the_dominant_components():
    from mbcomp.face.cli_analyse import shape_text
    speeds = tuple(f"q{i}" for i in range(40))
    shape = np.zeros(40)
    shape[[3, 17, 25, 30, 31]] = [0.5, -1.0, 0.2, 0.01, 0.3]
    assert shape_text(speeds, shape) == "q17=-1, q3=0.5, q31=0.3 (+2 smaller)"
