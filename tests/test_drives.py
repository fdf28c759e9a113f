"""Drive trains, signals and control against independent hand-derived ODEs (scipy)."""
import numpy as np
import pytest
from scipy.integrate import simpson, solve_ivp

import mbcomp as mb
from conftest import fourbar

G = 9.81
T = np.linspace(0.0, 2.0, 41)


def pendulum(name="p", *, mass=1.0, length=0.5, inertia=0.0, gravity=(0, 0, -G)):
    """A rod on a hinge about x: its COM at ``length`` below the hinge at q = 0."""
    m = mb.Model(name, gravity=gravity)
    rod = m.add(mb.Body("rod", mass=mass, com=(0, 0, -length), inertia=(inertia, inertia, 0.0)))
    joint = m.add(mb.Revolute("hinge", m.ground, rod, axis="x", coords="th"))
    return m, joint


def reference(f, y0, t=T, t_end=None):
    sol = solve_ivp(f, (0.0, t[-1] if t_end is None else t_end), y0, t_eval=t, rtol=1e-11, atol=1e-12,
                    method="LSODA")
    assert sol.success
    return sol.y


def test_geared_pendulum_with_rotor_inertia_and_sine_torque():
    m, j = pendulum(inertia=0.1)
    m.add(mb.Drive("drive", j, ratio=10.0, rotor_inertia=1e-3, torque=mb.Sine(0.2, 0.5)))
    sys = m.compile()
    inertia = 1.0 * 0.25 + 0.1 + 10.0 ** 2 * 1e-3
    assert sys.mass_matrix([0.4])[0, 0] == pytest.approx(inertia, rel=1e-12)
    assert sys.energy([0.0], [2.0]).kinetic == pytest.approx(0.5 * inertia * 4.0, rel=1e-12)
    res = sys.simulate(T[-1], [0.3], t_eval=T)

    def f(t, y):
        return [y[1], (10.0 * 0.2 * np.sin(np.pi * t) - G * 0.5 * np.sin(y[0])) / inertia]

    assert np.max(np.abs(res["th"] - reference(f, [0.3, 0.0])[0])) < 1e-7


def test_drive_torque_is_a_parameter_and_a_callable_works_through_python():
    m, j = pendulum()
    m.add(mb.Drive("drive", j, ratio=-3.0, torque=0.5))
    sys = m.compile()
    assert sys.parameters["drive.torque"] == 0.5
    # holding: -3 * 0.5 = -1.5 N m balances gravity where G 0.5 sin(th) = -1.5
    assert sys.accelerations([np.arcsin(-1.5 / (G * 0.5))], [0.0])[0] == pytest.approx(0.0, abs=1e-12)
    assert sys.with_parameters({"drive.torque": 0.0}).accelerations([0.0], [0.0])[0] == 0.0
    m2, j2 = pendulum()
    m2.add(mb.Drive("drive", j2, ratio=2.0, torque=lambda t, q, qd: 0.25 * t))
    sys2 = m2.compile()
    assert sys2.integration_path() == "compiled"  # (the callable is called back from the compiled loop)
    res = sys2.simulate(1.0, [0.0], t_eval=T[:21])
    assert res.stats["integrator"] == "compiled"

    def f(t, y):
        return [y[1], (0.5 * t - G * 0.5 * np.sin(y[0])) / 0.25]

    assert np.max(np.abs(res["th"] - reference(f, [0.0, 0.0], T[:21])[0])) < 1e-7


def dc_pendulum(voltage, name="dc"):
    m, j = pendulum(name)
    m.add(mb.DCMotor("motor", j, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=voltage,
                     rotor_inertia=2e-4))
    return m, j


def test_dc_motor_pendulum_and_its_current():
    m, _ = dc_pendulum(6.0)
    sys = m.compile()
    assert sys.extra_states == ("motor.current",)
    assert sys.states[-1] == "motor.current"
    res = sys.simulate(T[-1], [0.1], t_eval=T, x0={"motor.current": 0.5}, rtol=1e-10, atol=1e-12)
    inertia = 0.25 + 400 * 2e-4

    def f(t, y):
        th, w, i = y
        return [w, (20 * 0.03 * i - G * 0.5 * np.sin(th)) / inertia, (6.0 - 2.0 * i - 0.03 * 20 * w) / 0.05]

    ref = reference(f, [0.1, 0.0, 0.5])
    assert res["motor.current"][0] == 0.5
    assert np.max(np.abs(res["th"] - ref[0])) < 1e-7
    assert np.max(np.abs(res["motor.current"] - ref[2])) < 1e-6


def test_pid_holds_a_pendulum_with_zero_steady_state_error():
    m, j = pendulum("pid")
    pid = m.add(mb.PID("pid", mb.Angle(j), mb.Step(0.2, 0.8), kp=60.0, ki=80.0, kd=6.0))
    m.add(mb.DCMotor("motor", j, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=pid))
    sys = m.compile()
    t = np.linspace(0, 6.0, 61)
    res = sys.simulate(t[-1], [0.0], t_eval=t, rtol=1e-10, atol=1e-12)

    def f(t, y):
        th, w, i, z = y
        e = (0.8 if t >= 0.2 else 0.0) - th
        v = 60 * e + 80 * z + 6 * (0.0 - w)
        return [w, (0.6 * i - G * 0.5 * np.sin(th)) / 0.25, (v - 2 * i - 0.6 * w) / 0.05, e]

    ref = reference(f, [0, 0, 0, 0], t)
    assert np.max(np.abs(res["th"] - ref[0])) < 1e-6
    assert res["th"][-1] == pytest.approx(0.8, abs=1e-3)  # no steady-state error against gravity
    # the integral state carries the holding voltage: R i = R (m g l sin th) / (k r)
    holding_current = G * 0.5 * np.sin(0.8) / 0.6
    assert res["motor.current"][-1] == pytest.approx(holding_current, rel=1e-3)
    assert 80 * res["pid.integral"][-1] == pytest.approx(2.0 * holding_current, rel=1e-2)


def test_pid_limit_clips_and_stops_windup():
    def build(limit):
        m, j = pendulum("lim")
        pid = m.add(mb.PID("pid", mb.Angle(j), 1.0, kp=40.0, ki=40.0, limit=limit))
        m.add(mb.JointTorque("torque", j, pid))
        return m.compile()

    free, limited = build(None), build(3.0)
    assert "pid.limit" in limited.parameters and "pid.limit" not in free.parameters
    res = limited.simulate(3.0, [0.0], t_eval=np.linspace(0, 3, 31))
    # 3 N m cannot lift the rod to 1 rad (needs G 0.5 sin 1 = 4.13 N m): the output saturates
    # and the clamped integral stays where the output first reached the limit
    reactions = [limited.accelerations([th], [w], states=[z])[0] * 0.25 + G * 0.5 * np.sin(th)
                 for th, w, z in zip(res["th"], res["dth"], res["pid.integral"])]
    assert np.max(np.abs(reactions)) <= 3.0 + 1e-9
    assert np.max(res["pid.integral"]) < 0.1
    unclamped = free.with_parameters({"pid.kp": 40.0})
    assert unclamped.accelerations([0.0], [0.0])[0] * 0.25 == pytest.approx(40.0)


def test_viscous_friction_decay_is_exponential():
    m = mb.Model("wheel", gravity=(0, 0, 0))
    wheel = m.add(mb.Body("wheel", mass=1.0, inertia=(0.2, 0.2, 0.2)))
    j = m.add(mb.Revolute("axle", m.ground, wheel, axis="z", coords="phi"))
    m.add(mb.JointFriction("friction", j, viscous=0.05))
    res = m.compile().simulate(T[-1], [0.0], [3.0], t_eval=T)
    assert np.allclose(res["dphi"], 3.0 * np.exp(-0.05 / 0.2 * T), rtol=1e-8)
    assert np.allclose(res["phi"], 3.0 * 0.2 / 0.05 * (1 - np.exp(-0.05 / 0.2 * T)), rtol=1e-8)


def test_coulomb_friction_holds_a_block_on_a_slope():
    slope = np.radians(20.0)
    gravity = (0, -G * np.sin(slope), -G * np.cos(slope))  # the slope is the x-y plane, down along -y
    m = mb.Model("slope", gravity=gravity)
    block = m.add(mb.Body("block", mass=2.0))
    j = m.add(mb.Prismatic("slide", m.ground, block, axis="y", coords="s"))
    # friction coefficient 0.5: limit 0.5 m g cos(20 deg) = 9.22 N > pull m g sin(20 deg) = 6.71 N
    limit = 0.5 * 2.0 * G * np.cos(slope)
    m.add(mb.JointFriction("friction", j, coulomb=limit, speed_scale=1e-4))
    sys = m.compile()
    res = sys.simulate(1.0, [0.0], method="Radau")
    creep = 1e-4 * np.arctanh(2.0 * G * np.sin(slope) / limit)  # documented creep speed
    assert abs(res["s"][-1]) <= 1.01 * creep * 1.0
    assert abs(res["s"][-1]) < 2e-4
    # without enough friction it slides with a = g (sin - mu cos)
    weak = sys.with_parameters({"friction.coulomb": 0.1 * 2.0 * G * np.cos(slope)})
    res = weak.simulate(1.0, [0.0], [-0.1], t_eval=[0.0, 1.0])
    a = -G * (np.sin(slope) - 0.1 * np.cos(slope))
    assert res["s"][-1] == pytest.approx(-0.1 + a / 2, rel=1e-4)


def test_joint_limit_bounces_with_restitution_and_rests_against_the_stop():
    m, j = pendulum("stop", gravity=(0, 0, 0))
    m.add(mb.JointLimit("stop", j, lower=-0.2, upper=0.5, restitution=0.5))
    sys = m.compile()
    assert sys.gaps([0.0]) == {"stop.lower": 0.2, "stop.upper": 0.5}
    res = sys.simulate(1.0, [0.0], [2.0])
    first, second = res.events[:2]
    assert first.contact == "stop.upper" and first.time == pytest.approx(0.25, rel=1e-9)
    assert first.impulse == pytest.approx(0.25 * 2.0 * 1.5, rel=1e-9)  # I (1 + e) w
    assert second.contact == "stop.lower" and second.time == pytest.approx(0.25 + 0.7 / 1.0, rel=1e-9)
    assert res["th"].max() <= 0.5 + 1e-9 and res["th"].min() >= -0.2 - 1e-9
    # gravity pushing the rod against the upper stop: it comes to rest there and the
    # stop's reaction is the gravity torque
    m, j = pendulum("rest", gravity=(0, G, 0))
    m.add(mb.JointLimit("stop", j, upper=0.3))
    res = m.compile().simulate(2.0, [0.0])
    assert res["th"][-1] == pytest.approx(0.3, abs=1e-9)
    assert res.reactions["stop.upper"][-1, 0] == pytest.approx(G * 0.5 * np.cos(0.3), rel=1e-6)


def test_signals_compose_into_a_joint_torque():
    m, j = pendulum("sig")
    signal = 2.0 * mb.Sine(1.0, 1.0) - 0.5 * mb.Speed(j) + mb.Step(0.5, 1.0) + mb.Constant(0.25)
    m.add(mb.JointTorque("torque", j, signal))
    res = m.compile().simulate(1.0, [0.0], t_eval=T[:21])

    def f(t, y):
        tau = 2 * np.sin(2 * np.pi * t) - 0.5 * y[1] + (1.0 if t >= 0.5 else 0.0) + 0.25
        return [y[1], (tau - G * 0.5 * np.sin(y[0])) / 0.25]

    assert np.max(np.abs(res["th"] - reference(f, [0.0, 0.0], T[:21])[0])) < 1e-6


def test_dc_motor_drives_a_fourbar_in_both_formulations():
    """Energy balance (independent of the equations): the electrical work V i dt goes into
    resistive heat R i^2, magnetic energy L i^2 / 2 and the mechanism's energy."""
    t = np.linspace(0.0, 0.4, 401)
    results = {}
    for formulation in ("lagrange", "dae"):
        m = fourbar(name=f"fourbar_dc_{formulation}")
        m.add(mb.DCMotor("motor", "A", ratio=5.0, resistance=1.5, inductance=0.02, k=0.05, voltage=4.0))
        sys = m.compile(formulation)
        q0, _ = sys.assemble([1.0, -0.5, 1.5])
        res = sys.simulate(t[-1], q0, t_eval=t, rtol=1e-10, atol=1e-12)
        i, w = res["motor.current"], res["dA"]
        energy = res.energy().total
        mechanical_in = simpson(5.0 * 0.05 * i * w, x=t)
        assert energy[-1] - energy[0] == pytest.approx(mechanical_in, rel=1e-4, abs=1e-6)
        electrical = simpson(4.0 * i - 1.5 * i ** 2, x=t) - 0.02 * i[-1] ** 2 / 2
        assert electrical == pytest.approx(mechanical_in, rel=1e-4, abs=1e-6)
        assert np.max(res.constraint_violation()) < 1e-6
        results[formulation] = res
    assert np.max(np.abs(results["lagrange"]["A"] - results["dae"]["A"])) < 1e-5
    assert np.max(np.abs(results["lagrange"]["motor.current"] - results["dae"]["motor.current"])) < 1e-4


def test_states_in_csv_and_errors(tmp_path):
    m, _ = dc_pendulum(1.0, "csv")
    sys = m.compile()
    res = sys.simulate(0.1, [0.0], t_eval=[0.0, 0.05, 0.1])
    res.to_csv(tmp_path / "r.csv")
    header = (tmp_path / "r.csv").read_text().splitlines()[0].split(",")
    assert "motor.current" in header
    column = np.loadtxt(tmp_path / "r.csv", delimiter=",", skiprows=1)[:, header.index("motor.current")]
    assert np.allclose(column, res["motor.current"])
    with pytest.raises(mb.ModelError, match="unknown state"):
        sys.simulate(0.1, [0.0], x0={"motor.voltage": 1.0})
    with pytest.raises(mb.ModelError, match="kd"):
        mb.PID("pid", mb.Speed("hinge"), 0.0, kp=1.0, kd=1.0)
    with pytest.raises(mb.ModelError, match="lower or an upper"):
        mb.JointLimit("stop", "hinge")
    with pytest.raises(mb.ModelError, match="inductance"):
        mb.DCMotor("m", "hinge", ratio=1, resistance=1, inductance=0, k=1, voltage=1)
    m, j = pendulum("missing")
    pid = mb.PID("pid", mb.Angle(j), 1.0, kp=1.0)
    m.add(mb.Drive("drive", j, torque=pid))
    with pytest.raises(mb.ModelError, match="pid"):
        m.compile()
    m = mb.Model("ball")
    body = m.add(mb.Body("b", mass=1.0, inertia=(1, 1, 1)))
    sph = m.add(mb.Spherical("s", m.ground, body, sequence="xy"))
    m.add(mb.Drive("drive", sph, torque=1.0))
    with pytest.raises(mb.ModelError, match="1-DOF"):
        m.compile()


def servo_pendulum(name, controller=None):
    """A pendulum on a DC motor whose voltage a PID (or a Python callable) sets."""
    m, j = pendulum(name)
    if controller is None:
        controller = m.add(mb.PID("pid", mb.Angle(j), mb.Step(0.105, 0.6), kp=60.0, ki=80.0, kd=6.0, limit=12.0))
    m.add(mb.DCMotor("motor", j, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=controller))
    return m


def test_drive_states_run_in_the_compiled_integrators():
    sys = servo_pendulum("servo_c").compile()
    assert sys.integration_path() == "compiled"
    t = np.linspace(0, 2.0, 21)
    compiled = sys.simulate(2.0, [0.0], t_eval=t, x0={"pid.integral": 0.01})
    assert compiled.stats["integrator"] == "compiled"
    stepped = sys.simulate(2.0, [0.0], t_eval=t, x0={"pid.integral": 0.01}, integrator="scipy")
    assert stepped.stats["integrator"] == "scipy"
    for name in ("th", "motor.current", "pid.integral"):
        assert np.max(np.abs(compiled[name] - stepped[name])) < 1e-6, name  # rtol 1e-8: steps differ at the kinks
    radau = sys.simulate(2.0, [0.0], t_eval=t, x0={"pid.integral": 0.01}, method="Radau")  # compiled Jacobian
    assert radau.stats["njev"] > 0 and np.max(np.abs(radau["th"] - compiled["th"])) < 1e-5
    rk4 = sys.simulate(2.0, [0.0], method="RK4", dt=1e-3, t_eval=t, x0={"pid.integral": 0.01})
    # fixed steps across the setpoint step and the anti-windup switch: first-order errors
    assert np.max(np.abs(rk4["th"] - compiled["th"])) < 1e-3
    assert np.max(np.abs(rk4["motor.current"] - compiled["motor.current"])) < 1e-2
    # a Python callable voltage: called back from the compiled loop
    gains = sys.parameters

    def callable_model():
        m, j = pendulum("servo_py")
        m.add(mb.DCMotor("motor", j, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=lambda t, q, qd: 0.0))
        return m

    python = callable_model().compile()
    assert python.integration_path() == "compiled"
    assert gains["pid.kp"] == 60.0


def test_sweeping_pid_gains_does_not_recompile():
    sys = servo_pendulum("servo_sweep").compile()
    t = np.linspace(0, 1.5, 16)
    tuned = sys.with_parameters({"pid.kp": 20.0, "pid.limit": 6.0})
    assert tuned.integration_path() == "compiled" and tuned.compile_time == sys.compile_time
    m = mb.Model("fresh")
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0, -0.5)))
    j = m.add(mb.Revolute("hinge", m.ground, rod, axis="x", coords="th"))
    pid = m.add(mb.PID("pid", mb.Angle(j), mb.Step(0.105, 0.6), kp=20.0, ki=80.0, kd=6.0, limit=6.0))
    m.add(mb.DCMotor("motor", j, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=pid))
    fresh = m.compile().simulate(1.5, [0.0], t_eval=t)
    res = tuned.simulate(1.5, [0.0], t_eval=t)
    assert np.max(np.abs(res["th"] - fresh["th"])) < 1e-12
    assert np.max(np.abs(res["th"] - sys.simulate(1.5, [0.0], t_eval=t)["th"])) > 1e-3


def test_servo_part_and_drives_inside_submodels():
    m, j = pendulum("servo_part")
    servo = m.add(mb.Servo("servo", joint=j, setpoint=0.5, kp=60.0, ki=80.0, kd=6.0, ratio=20.0, resistance=2.0,
                           inductance=0.05, k=0.03, rotor_inertia=0.0))
    sys = m.compile()
    assert sys.extra_states == ("servo.pid.integral", "servo.motor.current")
    assert sys.integration_path() == "compiled"
    assert m["servo.pid"].kp == 60.0 and servo.path == "servo"
    t = np.linspace(0, 2.0, 21)
    res = sys.simulate(2.0, [0.0], t_eval=t, rtol=1e-10, atol=1e-12)

    def f(t, y):
        th, w, i, z = y
        e = 0.5 - th
        v = 60 * e + 80 * z - 6 * w
        return [w, (0.6 * i - G * 0.5 * np.sin(th)) / 0.25, (v - 2 * i - 0.6 * w) / 0.05, e]

    ref = reference(f, [0, 0, 0, 0], t)
    assert np.max(np.abs(res["th"] - ref[0])) < 1e-6
    assert np.max(np.abs(res["servo.motor.current"] - ref[2])) < 1e-5
    # a sub-model parameter reaches the PID without recompiling
    slower = sys.with_parameters({"servo.kp": 30.0}).simulate(2.0, [0.0], t_eval=t)
    assert abs(slower["th"][5] - res["th"][5]) > 1e-3


SERVO_FILE = """
name = "servo_file"
[bodies.rod]
mass = 1.0
com = [0.0, 0.0, -0.5]
[joints.hinge]
type = "revolute"
parent = "ground"
child = "rod"
axis = "x"
coords = "th"
[forces.pid]
type = "pid"
measured = { type = "angle", joint = "hinge" }
setpoint = { type = "step", time = 0.105, after = 0.6 }
kp = 60.0
ki = 80.0
kd = 6.0
limit = 12.0
[forces.motor]
type = "dc_motor"
joint = "hinge"
ratio = 20.0
resistance = 2.0
inductance = 0.05
k = 0.03
voltage = { type = "pid", name = "pid" }
[forces.friction]
type = "joint_friction"
joint = "hinge"
viscous = 0.01
[constraints.stop]
type = "joint_limit"
joint = "hinge"
upper = 1.5
"""


def test_drives_in_model_files(tmp_path):
    path = tmp_path / "servo.toml"
    path.write_text(SERVO_FILE)
    sys = mb.load(path).compile()
    m, j = pendulum("servo_py")
    pid = m.add(mb.PID("pid", mb.Angle(j), mb.Step(0.105, 0.6), kp=60.0, ki=80.0, kd=6.0, limit=12.0))
    m.add(mb.DCMotor("motor", j, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=pid))
    m.add(mb.JointFriction("friction", j, viscous=0.01), mb.JointLimit("stop", j, upper=1.5))
    python = m.compile()
    assert sys.extra_states == python.extra_states and sys.parameters == {**python.parameters}
    a = sys.simulate(1.0, [0.0], t_eval=[0.5, 1.0])
    b = python.simulate(1.0, [0.0], t_eval=[0.5, 1.0])
    assert np.allclose(a["th"], b["th"], atol=1e-12) and np.allclose(a["motor.current"], b["motor.current"], atol=1e-10)
    mb.load(path).save(tmp_path / "again.toml")  # written back: the same model
    again = mb.load(tmp_path / "again.toml").compile().simulate(1.0, [0.0], t_eval=[0.5, 1.0])
    assert np.allclose(again["th"], a["th"], atol=1e-12)
    path.write_text(SERVO_FILE.replace('joint = "hinge" }', 'joint = "hing" }'))
    with pytest.raises(mb.ModelError, match=r"forces.pid\] measured.joint: unknown joint 'hing'"):
        mb.load(path)
    path.write_text(SERVO_FILE.replace('type = "step"', 'type = "ramp"'))
    with pytest.raises(mb.ModelError, match=r"forces.pid\] setpoint: signal type must be one of"):
        mb.load(path)


def test_cli_info_lists_the_extra_states(capsys):
    from mbcomp.face.cli import main
    from pathlib import Path
    library = Path(__file__).resolve().parents[1] / "library" / "servo_arm.toml"
    assert main(["info", str(library)]) == 0
    out = capsys.readouterr().out
    assert "extra states  shoulder.pid.integral, shoulder.motor.current, elbow.pid.integral, elbow.motor.current" in out
