"""Parameters flow everywhere: numbers inside signals (sources, PID setpoints, motor
voltages, drive torques) are run-time parameters, in Python and in files, and a run-time
change gives the numbers of a fresh build with that value in both formulations.

The reference of every run-time change is a fresh build (a model built again with the
new value), which shares no parameter path with the change: the two agree to the
integrators' rounding (same compiled code, same steps).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb

LIBRARY = Path(__file__).resolve().parents[1] / "library"
T_EVAL = np.linspace(0.0, 1.0, 11)
SAME = 1e-10   # rad: same code, same steps (observed: bit-identical)


class ActuatedJoint(mb.Submodel):
    """A rod on a revolute joint, a geared DC motor, a PID following a Step."""

    length = mb.Parameter(0.4, unit="m", min=0.0)
    mass = mb.Parameter(1.0, unit="kg", min=0.0)
    step_time = mb.Parameter(0.2, unit="s")
    target = mb.Parameter(0.5, unit="rad")
    kp = mb.Parameter(60.0)
    ki = mb.Parameter(80.0)
    kd = mb.Parameter(6.0)
    ratio = mb.Parameter(20.0)

    def build(self, parent: mb.Frame):
        rod = self.add(mb.Body("rod", mass=self.mass, com=(0, 0, -self.length / 2),
                               inertia=(self.mass * self.length**2 / 12,) * 2 + (0.0,)))
        joint = self.add(mb.Revolute("joint", parent, rod, axis="x", coords="angle"))
        pid = self.add(mb.PID("pid", mb.Angle(joint), mb.Step(self.step_time, self.target),
                              kp=self.kp, ki=self.ki, kd=self.kd, limit=24.0))
        self.add(mb.DCMotor("motor", joint, ratio=self.ratio, resistance=2.0, inductance=0.05, k=0.03,
                            voltage=pid, rotor_inertia=1e-5))
        self.tip = rod.frame((0, 0, -self.length))


def arm(**shoulder) -> mb.Model:
    m = mb.Model("pid_arm", gravity=(0, 0, -9.81))
    s = m.add(ActuatedJoint("shoulder", parent=m.ground.frame(), **{"target": 0.6, **shoulder}))
    m.add(ActuatedJoint("elbow", parent=s.tip, length=0.3, mass=0.5, step_time=0.5, target=-0.4))
    return m


def angles(res) -> np.ndarray:
    return np.column_stack((res["shoulder.angle"], res["elbow.angle"]))


@pytest.fixture(scope="module", params=["lagrange", "dae"])
def arm_system(request):
    return arm().compile(formulation=request.param)


CHANGE = {"shoulder.step_time": 0.1, "shoulder.target": 1.1}


def test_a_setpoint_step_from_part_parameters_follows_a_run_time_change(arm_system):
    """The issue's arm: step time and target of a sub-model's Step are run-time parameters
    (they were frozen at build before, 0.8 rad away from a fresh build)."""
    fresh = arm(step_time=0.1, target=1.1).compile(formulation=arm_system.formulation)
    expected = angles(fresh.simulate(1.0, [0.0, 0.0], t_eval=T_EVAL))
    changed = angles(arm_system.simulate(1.0, [0.0, 0.0], t_eval=T_EVAL, parameters=CHANGE))
    np.testing.assert_allclose(changed, expected, rtol=0, atol=SAME)
    default = angles(arm_system.simulate(1.0, [0.0, 0.0], t_eval=T_EVAL))
    assert np.max(np.abs(default - expected)) > 0.3, "the change must matter for the test to mean anything"
    # the component values the sub-model parameters reach, by name
    new = arm_system.with_parameters(CHANGE)
    assert new.parameters["shoulder.pid.setpoint.time"] == 0.1
    assert new.parameters["shoulder.pid.setpoint.after"] == 1.1
    assert new.parameters["elbow.pid.setpoint.time"] == 0.5
    # with_parameters and sweep give the same numbers as simulate(parameters=)
    via_with = angles(new.simulate(1.0, [0.0, 0.0], t_eval=T_EVAL))
    (via_sweep,) = mb.sweep(arm_system, [{"parameters": CHANGE}], q0=[0.0, 0.0], t_end=1.0, t_eval=T_EVAL)
    np.testing.assert_allclose(via_with, expected, rtol=0, atol=SAME)
    np.testing.assert_allclose(angles(via_sweep), expected, rtol=0, atol=SAME)


def test_the_library_arm_file_gives_the_python_numbers(arm_system):
    """library/pid_arm.toml (two library:actuated_joint parts) is the Python arm: same
    parameter names for the signal numbers, same numbers before and after a change."""
    system = mb.load(LIBRARY / "pid_arm.toml").compile(formulation=arm_system.formulation)
    signal_keys = sorted(k for k in arm_system.parameters if ".setpoint." in k)
    assert signal_keys == sorted(k for k in system.parameters if ".setpoint." in k)
    assert len(signal_keys) == 6
    for parameters in (None, CHANGE):
        a = angles(system.simulate(1.0, [0.0, 0.0], t_eval=T_EVAL, parameters=parameters))
        b = angles(arm_system.simulate(1.0, [0.0, 0.0], t_eval=T_EVAL, parameters=parameters))
        np.testing.assert_allclose(a, b, rtol=0, atol=SAME)


# -- signal numbers are parameters in flat models too ---------------------------------------------
def elbow(setpoint, voltage=None, name="elbow") -> mb.Model:
    m = mb.Model(name, gravity=(0, 0, -9.81))
    link = m.add(mb.Body("link", mass=2.0, com=(0, 0.4, 0), inertia=(0.03, 0.002, 0.03)))
    joint = m.add(mb.Revolute("elbow", m.ground, link, axis="x", coords="angle"))
    if voltage is None:
        voltage = m.add(mb.PID("pid", mb.Angle(joint), setpoint, kp=150.0, ki=600.0, kd=10.0, limit=24.0))
    m.add(mb.DCMotor("motor", joint, ratio=50.0, resistance=1.2, inductance=1e-2, k=0.05, voltage=voltage,
                     rotor_inertia=2e-5))
    return m


def test_step_numbers_are_parameters_of_the_pid():
    system = elbow(mb.Step(0.2, 0.8)).compile()
    assert {k: system.parameters[k] for k in system.parameters if ".setpoint." in k} == {
        "pid.setpoint.time": 0.2, "pid.setpoint.after": 0.8, "pid.setpoint.before": 0.0}
    changed = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"pid.setpoint.after": 0.5,
                                                                        "pid.setpoint.time": 0.1})
    fresh = elbow(mb.Step(0.1, 0.5)).compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(changed["angle"], fresh["angle"], rtol=0, atol=SAME)


def test_sine_and_combination_numbers_are_named_by_kind():
    """A voltage ``2 + Sine(...) - 3 * Sine(...)``: each source's numbers under its kind,
    numbered when a kind repeats; the -1 of the difference is no parameter."""
    voltage = 2.0 + mb.Sine(amplitude=6.0, frequency=1.5) - 3.0 * mb.Sine(amplitude=1.0, frequency=0.5)
    system = elbow(None, voltage=voltage).compile()
    keys = sorted(k[len("motor.voltage."):] for k in system.parameters if k.startswith("motor.voltage."))
    assert keys == sorted(["constant1.value", "constant2.value"]
                          + [f"sine{i}.{f}" for i in (1, 2) for f in ("amplitude", "frequency", "phase", "offset")])
    assert system.parameters["motor.voltage.sine1.frequency"] == 1.5
    changed = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"motor.voltage.sine1.amplitude": 4.0,
                                                                        "motor.voltage.constant2.value": 1.0})
    voltage = 2.0 + mb.Sine(amplitude=4.0, frequency=1.5) - 1.0 * mb.Sine(amplitude=1.0, frequency=0.5)
    fresh = elbow(None, voltage=voltage, name="elbow2").compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(changed["angle"], fresh["angle"], rtol=0, atol=SAME)
    with pytest.raises(mb.ModelError, match="sine1.frequency must not be negative"):
        system.with_parameters({"motor.voltage.sine1.frequency": -1.0})


def test_a_parameter_times_a_signal_keeps_the_link():
    """``self.gain * mb.Sine(...)`` inside a part: the gain is a run-time parameter."""
    class Shaker(mb.Submodel):
        gain = mb.Parameter(3.0)

        def build(self, joint):
            self.add(mb.Drive("drive", joint, ratio=2.0, torque=self.gain * mb.Sine(1.0, 2.0)))

    def model(gain):
        m = mb.Model("shaker", gravity=(0, 0, 0))
        b = m.add(mb.Body("b", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
        j = m.add(mb.Revolute("j", m.ground, b, axis="x", coords="a"))
        m.add(Shaker("s", joint=j, gain=gain))
        return m.compile()

    changed = model(3.0).simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"s.gain": 5.0})
    fresh = model(5.0).simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(changed["a"], fresh["a"], rtol=0, atol=SAME)
    # independent: a free rotor driven by 2 * 5 sin(4 pi t): a'' = 10 sin(4 pi t) / I
    inertia = 0.01 + 1.0 * 0.1**2
    w = 4 * np.pi
    exact = 10.0 / inertia * (T_EVAL / w - np.sin(w * T_EVAL) / w**2)
    np.testing.assert_allclose(changed["a"], exact, rtol=0, atol=1e-7)


# -- files ---------------------------------------------------------------------------------------------
PART = '''name = "shaker"
[parameters]
amp = 6.0
step_time = 0.2
target = 0.5
[ports]
parent = "external"
[bodies.rod]
mass = 1.0
com = [0.0, 0.1, 0.0]
inertia = [0.01, 0.01, 0.01]
[joints.j]
type = "revolute"
parent = "parent"
child = "rod"
axis = "x"
coords = "a"
'''


def write(tmp_path, name, text) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def part_model(tmp_path, forces: str, **overrides) -> mb.System:
    write(tmp_path, "part.toml", PART + forces)
    extra = "".join(f"{k} = {v}\n" for k, v in overrides.items())
    return mb.load(write(tmp_path, "top.toml", f'gravity = [0.0, 0.0, 0.0]\n[submodels.p]\nuse = "part.toml"\nparent = "ground"\n{extra}'))


def test_file_motor_voltage_expression_of_t_is_compiled_and_parameterised(tmp_path):
    """``voltage = "amp*sin(2*pi*t)"`` in a part: compiled (it crashed at simulate before),
    ``amp`` a run-time parameter, and the numbers of the Python Sine."""
    forces = ('[forces.motor]\ntype = "dc_motor"\njoint = "j"\nratio = 10.0\nresistance = 2.0\n'
              'inductance = 0.05\nk = 0.03\nvoltage = "amp*sin(2*pi*t)"\n')
    system = part_model(tmp_path, forces).compile()
    assert system.integration_path() == "compiled"
    assert system.parameters["p.motor.voltage.amp"] == 6.0
    changed = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"p.amp": 4.0})
    fresh = part_model(tmp_path, forces, amp=4.0).compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(changed["p.a"], fresh["p.a"], rtol=0, atol=SAME)

    m = mb.Model("py", gravity=(0, 0, 0))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
    j = m.add(mb.Revolute("j", m.ground, rod, axis="x", coords="a"))
    m.add(mb.DCMotor("motor", j, ratio=10.0, resistance=2.0, inductance=0.05, k=0.03,
                     voltage=mb.Sine(amplitude=4.0, frequency=1.0)))
    python = m.compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(changed["p.a"], python["a"], rtol=0, atol=1e-9)


def test_file_step_table_takes_part_parameters(tmp_path):
    """``setpoint = { type = "step", time = "step_time", after = "target" }`` (refused before:
    "time must be a number") follows run-time changes of the part's parameters."""
    forces = ('[forces.pid]\ntype = "pid"\nmeasured = { type = "angle", joint = "j" }\n'
              'setpoint = { type = "step", time = "step_time", after = "2*target" }\nkp = 2.0\nkd = 0.2\n'
              '[forces.drive]\ntype = "drive"\njoint = "j"\ntorque = { type = "pid", name = "pid" }\n')
    system = part_model(tmp_path, forces).compile()
    assert system.parameters["p.pid.setpoint.after"] == 1.0
    changed = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"p.step_time": 0.4, "p.target": 0.3})
    fresh = part_model(tmp_path, forces, step_time=0.4, target=0.3).compile()
    expected = fresh.simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(changed["p.a"], expected["p.a"], rtol=0, atol=SAME)
    assert np.all(changed["p.a"][T_EVAL < 0.4] == 0.0) and changed["p.a"][-1] > 0.1


def test_file_pid_setpoint_expression_of_t(tmp_path):
    """A PID setpoint written as an expression of t (refused before) is compiled with its
    exact rate (the kd term) and gives the Python numbers of the same Sine."""
    forces = ('[forces.pid]\ntype = "pid"\nmeasured = { type = "angle", joint = "j" }\n'
              'setpoint = "target*sin(2*pi*t)"\nkp = 2.0\nkd = 0.2\n'
              '[forces.drive]\ntype = "drive"\njoint = "j"\ntorque = { type = "pid", name = "pid" }\n')
    system = part_model(tmp_path, forces).compile()
    assert system.integration_path() == "compiled"
    res = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"p.target": 0.7})

    m = mb.Model("py", gravity=(0, 0, 0))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
    j = m.add(mb.Revolute("j", m.ground, rod, axis="x", coords="a"))
    pid = m.add(mb.PID("pid", mb.Angle(j), mb.Sine(amplitude=0.7, frequency=1.0), kp=2.0, kd=0.2))
    m.add(mb.Drive("drive", j, torque=pid))
    python = m.compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(res["p.a"], python["a"], rtol=0, atol=1e-9)


def test_file_drive_torque_and_joint_torque_expressions(tmp_path):
    """Drive torque and joint-torque value as expressions of t: compiled, parameterised."""
    forces = ('[forces.drive]\ntype = "drive"\njoint = "j"\nratio = 2.0\ntorque = "amp*t"\n'
              '[forces.push]\ntype = "joint_torque"\njoint = "j"\nvalue = "-0.5*amp*t"\n')
    system = part_model(tmp_path, forces).compile()
    assert system.integration_path() == "compiled"
    res = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters={"p.amp": 3.0})
    # independent: net torque 2 * 3 t - 1.5 t = 4.5 t on a free rotor: a = 4.5 t^3 / (6 I)
    inertia = 0.01 + 1.0 * 0.1**2
    np.testing.assert_allclose(res["p.a"], 4.5 * T_EVAL**3 / (6 * inertia), rtol=0, atol=1e-9)


def test_file_signals_round_trip_through_save(tmp_path):
    """A saved model writes a step table and an expression of t that load back to the same numbers."""
    forces = ('[forces.pid]\ntype = "pid"\nmeasured = { type = "angle", joint = "j" }\n'
              'setpoint = { type = "step", time = "step_time", after = "target" }\nkp = 2.0\nkd = 0.2\n'
              '[forces.drive]\ntype = "drive"\njoint = "j"\ntorque = { type = "pid", name = "pid" }\n'
              '[forces.motor]\ntype = "dc_motor"\njoint = "j"\nratio = 10.0\nresistance = 2.0\n'
              'inductance = 0.05\nk = 0.03\nvoltage = "amp*sin(2*pi*t)"\n')
    model = part_model(tmp_path, forces, amp=2.5)
    model.save(tmp_path / "saved.toml")
    a = model.compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    b = mb.load(tmp_path / "saved.toml").compile().simulate(1.0, [0.0], t_eval=T_EVAL)
    np.testing.assert_allclose(a["p.a"], b["p.a"], rtol=0, atol=1e-12)


def test_a_part_parameter_where_it_would_freeze_is_refused(tmp_path):
    forces = '[forces.push]\ntype = "force"\nbody = "rod"\nforce = [0.0, "amp*t", 0.0]\n'
    with pytest.raises(mb.ModelError, match=r"parameter\(s\) 'amp' cannot be used in an expression of t here"):
        part_model(tmp_path, forces)


def test_a_failed_part_reports_its_own_error_only(tmp_path):
    """The first error, without the cascade "unknown body 'shoulder.tip'"."""
    text = (LIBRARY / "parts" / "actuated_joint.toml").read_text().replace('kp = "kp"', 'kp = "kpp"')
    write(tmp_path, "joint.toml", text)
    top = (LIBRARY / "pid_arm.toml").read_text().replace("library:actuated_joint", "joint.toml")
    with pytest.raises(mb.ModelError) as info:
        mb.load(write(tmp_path, "arm.toml", top))
    assert len(info.value.problems) == 1, info.value.problems
    assert "unknown name 'kpp'" in info.value.problems[0] and "[forces.pid] kp" in info.value.problems[0]


# -- to_control with hierarchical names ------------------------------------------------------------
def test_to_control_maps_dotted_names(arm_system):
    control = pytest.importorskip("control", exc_type=ImportError)
    lin = arm_system.linearize([0.0, 0.0], inputs=["shoulder.joint"])
    names = lin.control_names()
    assert names["shoulder.angle"] == "shoulder_angle" and names["elbow.pid.integral"] == "elbow_pid_integral"
    plant = lin.to_control()
    assert isinstance(plant, control.StateSpace)
    assert list(plant.state_labels) == [names[s] for s in lin.states]
    assert [plant.mbcomp_names[c] for c in plant.input_labels] == list(lin.inputs)
    assert plant.control_names == names
    np.testing.assert_array_equal(plant.A, lin.A)
    np.testing.assert_allclose(np.sort_complex(control.poles(plant)), np.sort_complex(np.linalg.eigvals(lin.A)))


def test_control_names_resolve_clashes():
    from mbcomp.analysis.linear import Linearization
    lin = Linearization(A=np.zeros((2, 2)), B=np.zeros((2, 0)), states=("a.b", "a_b"), inputs=(),
                        independent=(), basis=np.zeros((0, 0)), q=np.zeros(0), qd=np.zeros(0))
    assert lin.control_names() == {"a.b": "a_b", "a_b": "a_b_2"}


# -- every drive number a part parameter can reach ---------------------------------------------------
class Drives(mb.Submodel):
    """PID gains, limit and numeric setpoint, motor numbers, a drive torque, a Sine
    amplitude and a motor speed, all from part parameters."""

    kp = mb.Parameter(20.0)
    ki = mb.Parameter(10.0)
    kd = mb.Parameter(1.0)
    limit = mb.Parameter(24.0, min=0.0)
    setpoint = mb.Parameter(0.4)
    resistance = mb.Parameter(2.0, min=0.0)
    torque = mb.Parameter(0.3)
    amplitude = mb.Parameter(0.2)
    speed = mb.Parameter(1.5)

    def build(self, base: mb.Frame):
        a = self.add(mb.Body("a", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
        ja = self.add(mb.Revolute("ja", base, a, axis="x", coords="qa"))
        pid = self.add(mb.PID("pid", mb.Angle(ja), self.setpoint, kp=self.kp, ki=self.ki, kd=self.kd,
                              limit=self.limit))
        self.add(mb.DCMotor("motor", ja, ratio=50.0, resistance=self.resistance, inductance=0.05, k=0.03,
                            voltage=pid))
        b = self.add(mb.Body("b", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
        jb = self.add(mb.Revolute("jb", base, b, axis="y", coords="qb"))
        self.add(mb.Drive("drive", jb, torque=self.torque))
        self.add(mb.JointTorque("shake", jb, value=mb.Sine(self.amplitude, 2.0)))
        c = self.add(mb.Body("c", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
        jc = self.add(mb.Revolute("jc", base, c, axis="z", coords="qc"))
        self.add(mb.Motor("spin", jc, speed=self.speed))


def drives_model(**values) -> mb.Model:
    m = mb.Model("drives", gravity=(0, 0, -9.81))
    m.add(Drives("d", base=m.ground.frame(), **values))
    return m


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_every_drive_number_follows_its_part_parameter(formulation):
    system = drives_model().compile(formulation=formulation)
    changes = {"kp": 35.0, "ki": 4.0, "kd": 2.0, "limit": 1.0, "setpoint": -0.3, "resistance": 1.0,
               "torque": -0.2, "amplitude": 0.6, "speed": 0.5}

    def run(s, parameters=None):
        res = s.simulate(0.5, [0.0, 0.0, 0.0], [0.0, 0.0, s.parameter("d.speed")], t_eval=T_EVAL / 2,
                         parameters=parameters)
        return np.column_stack([res[c] for c in ("d.qa", "d.qb", "d.qc")])

    default = run(system)
    for name, value in changes.items():
        fresh = drives_model(**{name: value}).compile(formulation=formulation)
        expected = run(fresh)
        changed = system.simulate(0.5, [0.0, 0.0, 0.0], [0.0, 0.0, value if name == "speed" else 1.5],
                                  t_eval=T_EVAL / 2, parameters={f"d.{name}": value})
        changed = np.column_stack([changed[c] for c in ("d.qa", "d.qb", "d.qc")])
        assert np.max(np.abs(expected - default)) > 1e-4, f"{name}: the change must matter"
        np.testing.assert_allclose(changed, expected, rtol=0, atol=1e-9, err_msg=name)


def test_a_part_parameter_as_a_constant_motor_position_is_refused(tmp_path):
    forces = '[constraints.hold]\ntype = "motor"\njoint = "j"\nposition = "target/2"\n'
    with pytest.raises(mb.ModelError, match=r"\[constraints.hold\] position: 'target/2' uses the part's parameters"):
        part_model(tmp_path, forces)


def test_python_backend_and_scipy_stepping_follow_signal_parameters():
    """The Python path (generated Python functions, scipy stepping) reads the same
    parameter vector: a run-time change of a Step's numbers gives a fresh build's numbers."""
    system = elbow(mb.Step(0.2, 0.8), name="elbow_py").compile(backend="python")
    changed = system.simulate(0.6, [0.0], t_eval=T_EVAL * 0.6, integrator="scipy",
                              parameters={"pid.setpoint.time": 0.1, "pid.setpoint.after": 0.5})
    fresh = elbow(mb.Step(0.1, 0.5), name="elbow_py").compile(backend="python")
    expected = fresh.simulate(0.6, [0.0], t_eval=T_EVAL * 0.6, integrator="scipy")
    np.testing.assert_allclose(changed["angle"], expected["angle"], rtol=0, atol=SAME)
    compiled = elbow(mb.Step(0.1, 0.5)).compile().simulate(0.6, [0.0], t_eval=T_EVAL * 0.6)
    np.testing.assert_allclose(changed["angle"], compiled["angle"], rtol=0, atol=1e-6)


def test_a_callable_returning_a_parameter_expression_is_an_error_not_a_frozen_value():
    class Pushed(mb.Submodel):
        a = mb.Parameter(2.0)

        def build(self, joint):
            self.add(mb.Drive("d", joint, torque=mb.Constant(1.0) + (lambda t: self.a * t)))

    m = mb.Model("pushed")
    b = m.add(mb.Body("b", mass=1.0, com=(0, 0.1, 0), inertia=(0.01, 0.01, 0.01)))
    j = m.add(mb.Revolute("j", m.ground, b, axis="x"))
    m.add(Pushed("p", joint=j))
    with pytest.raises(mb.SimulationError, match=r"returned the sub-model parameter expression \(p.a \* 0.0\)"):
        m.compile().simulate(0.1, [0.0])


def test_every_signal_table_of_the_drives_page_takes_part_parameters(tmp_path):
    """constant, sine, step tables with parameter expressions, a speed sensor, a pid
    reference: loaded in a part, compiled, each number a run-time parameter."""
    forces = ('[forces.pid]\ntype = "pid"\nmeasured = { type = "speed", joint = "j" }\n'
              'setpoint = { type = "sine", amplitude = "target", frequency = "1/step_time" }\nkp = 2.0\nki = 1.0\n'
              '[forces.drive]\ntype = "drive"\njoint = "j"\ntorque = { type = "pid", name = "pid" }\n'
              '[forces.bias]\ntype = "joint_torque"\njoint = "j"\nvalue = { type = "constant", value = "-amp/60" }\n')
    system = part_model(tmp_path, forces).compile()
    assert system.integration_path() == "compiled"
    assert system.parameters["p.pid.setpoint.frequency"] == 5.0 and system.parameters["p.bias.value.value"] == -0.1
    change = {"p.target": 0.8, "p.step_time": 0.5, "p.amp": 3.0}
    changed = system.simulate(1.0, [0.0], t_eval=T_EVAL, parameters=change)
    fresh = part_model(tmp_path, forces, target=0.8, step_time=0.5, amp=3.0).compile()
    np.testing.assert_allclose(changed["p.a"], fresh.simulate(1.0, [0.0], t_eval=T_EVAL)["p.a"], rtol=0, atol=SAME)
