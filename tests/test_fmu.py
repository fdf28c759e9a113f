"""FMU export (FMI 2.0, face/fmu): FMPy's validator, and FMPy's simulation of the exported
co-simulation and model-exchange FMUs against mbcomp's own simulate (a tree, a closed loop,
a contact), parameters, inputs, running without mbcomp, and the command line."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest

import mbcomp as mb

fmpy = pytest.importorskip("fmpy", exc_type=ImportError)
from fmpy import read_model_description, simulate_fmu  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

pytestmark = pytest.mark.xdist_group("fmu")

#: (library model, end time (s)): a tree, a closed loop, a contact (three bounces).
MODELS = {"double_pendulum": 1.0, "four_bar": 0.6, "bouncing_ball": 1.6}
DT = 0.05
RTOL, ATOL = 1e-11, 1e-12


def start_state(model, system):
    q0 = [model.initial["q"].get(c, 0.0) for c in system.coords]
    qd0 = [model.initial["qd"].get(c, 0.0) for c in system.speeds]
    return q0, qd0


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """Per model: (model, system, {kind: fmu path}), each FMU written once."""
    folder = tmp_path_factory.mktemp("fmu")
    out = {}
    for name in MODELS:
        model = mb.load(name)
        system = model.compile()
        paths = {kind: system.export_fmu(folder / f"{name}_{kind}.fmu", kind=kind) for kind in ("cs", "me")}
        out[name] = (model, system, paths)
    return out


def times(t_end: float) -> np.ndarray:
    return np.round(np.linspace(0.0, t_end, int(round(t_end / DT)) + 1), 12)


def run_fmu(path, kind: str, t_end: float, **options):
    """FMPy's simulation on the output grid (model exchange: CVode, tight tolerances; the
    rows FMPy adds at events are left out)."""
    if kind == "cs":
        start = {"mbcomp.rtol": RTOL, "mbcomp.atol": ATOL, **options.pop("start_values", {})}
        result = simulate_fmu(str(path), stop_time=t_end, output_interval=DT, start_values=start, **options)
    else:
        result = simulate_fmu(str(path), stop_time=t_end, output_interval=DT, relative_tolerance=RTOL, **options)
    keep = np.isin(np.round(result["time"], 9), times(t_end))
    return result[keep]


@pytest.mark.parametrize("name", list(MODELS))
def test_fmpy_validator_finds_no_problem(exported, name):
    for path in exported[name][2].values():
        assert validate_fmu(str(path)) == []


def test_contents_and_variables(exported):
    model, system, paths = exported["double_pendulum"]
    with zipfile.ZipFile(paths["cs"]) as zf:
        names = zf.namelist()
    assert "modelDescription.xml" in names
    assert any(n.startswith("binaries/") and n.endswith("/double_pendulum.so") for n in names)
    assert {"sources/templates.c", "sources/model.c", "sources/fmu_tables.c"} <= set(names)
    md = read_model_description(str(paths["me"]))
    assert md.modelExchange is not None and md.coSimulation is None
    variables = {v.name: v for v in md.modelVariables}
    # every coordinate and speed by its mbcomp name, start values from the file's [initial]
    assert float(variables["phi1"].start) == pytest.approx(np.pi / 2) and variables["phi1"].unit == "rad"
    assert variables["theta2_d"].causality == "output" and variables["theta2_d"].unit == "rad/s"
    # every numeric parameter, vectors element by element (1-based)
    for key, value in system.parameters.items():
        if np.ndim(value) == 0:
            assert float(variables[key].start) == pytest.approx(value)
        else:
            for i, v in enumerate(value):
                assert float(variables[f"{key}[{i + 1}]"].start) == pytest.approx(v)
    assert variables["bar1.mass"].causality == "parameter" and variables["bar1.mass"].unit == "kg"
    for name in ("g", "L", "width", "thickness", "rho", "m", "I"):  # the file's [parameters]
        assert float(variables[name].start) == pytest.approx(system.parameters[name])
    assert len(md.derivatives) == 4 and md.numberOfEventIndicators == 0
    ball = read_model_description(str(exported["bouncing_ball"][2]["me"]))
    assert ball.numberOfEventIndicators == 1


@pytest.mark.parametrize("kind", ["cs", "me"])
@pytest.mark.parametrize("name", list(MODELS))
def test_fmpy_matches_mbcomp(exported, name, kind):
    model, system, paths = exported[name]
    t_end = MODELS[name]
    q0, qd0 = start_state(model, system)
    ref = system.simulate(t_end, q0, qd0, t_eval=times(t_end), rtol=RTOL, atol=ATOL)
    got = run_fmu(paths[kind], kind, t_end)
    assert len(got) == len(ref.t)
    for i, c in enumerate(system.coords):
        assert np.abs(got[c] - ref.q[:, i]).max() < 1e-6, c
    speeds = [f"{c}_d" for c in system.speeds]
    for i, c in enumerate(speeds):
        assert np.abs(got[c] - ref.qd[:, i]).max() < 1e-5, c
    if name == "bouncing_ball":  # two bounces inside the run (at 0.44 s and 1.14 s), matched through both
        assert len(ref.events) == 2


#: (System parameters, the same as FMU start values): component values (a vector by its
#: elements); model parameters of the file's [parameters], whose component values follow
#: (L: lengths, masses and inertias; rho through the derived m), a component value set with
#: them winning (as in with_parameters), a derived parameter set on its own.
CHANGES = [({"bar2.mass": 0.3, "gravity": (9.0, 1.0, 0.0)}, {"bar2.mass": 0.3, "gravity[1]": 9.0, "gravity[2]": 1.0}),
           ({"L": 0.7}, {"L": 0.7}),
           ({"rho": 1000.0, "bar2.mass": 0.3}, {"rho": 1000.0, "bar2.mass": 0.3}),
           ({"m": 0.2, "g": 5.0}, {"m": 0.2, "g": 5.0})]


@pytest.mark.parametrize("kind", ["cs", "me"])
@pytest.mark.parametrize("change", range(len(CHANGES)))
def test_parameter_start_values_take_effect(exported, kind, change):
    model, system, paths = exported["double_pendulum"]
    parameters, start = CHANGES[change]
    q0, qd0 = start_state(model, system)
    ref = system.simulate(1.0, q0, qd0, t_eval=times(1.0), rtol=RTOL, atol=ATOL, parameters=parameters)
    base = system.simulate(1.0, q0, qd0, t_eval=times(1.0), rtol=RTOL, atol=ATOL)
    assert np.abs(ref.q - base.q).max() > 1e-2  # the change matters
    got = run_fmu(paths[kind], kind, 1.0, start_values=start)
    assert np.abs(got["phi1"] - ref.q[:, 0]).max() < 1e-6
    assert np.abs(got["theta2"] - ref.q[:, 1]).max() < 1e-6


def test_start_values_of_coordinates_take_effect(exported):
    model, system, paths = exported["four_bar"]
    q0, qd0 = start_state(model, system)
    qd0 = [2.0 * v for v in qd0]
    ref = system.simulate(0.5, q0, qd0, t_eval=times(0.5), rtol=RTOL, atol=ATOL)
    got = run_fmu(paths["cs"], "cs", 0.5, start_values={"theta1_d": 6.0})
    assert np.abs(got["theta1"] - ref.q[:, 0]).max() < 1e-6


@pytest.mark.parametrize("kind", ["cs", "me"])
def test_an_input_torque_acts_as_tau(tmp_path, kind):
    model = mb.load("double_pendulum")
    system = model.compile()
    path = system.export_fmu(tmp_path / f"driven_{kind}.fmu", kind=kind, inputs=["A"])
    md = read_model_description(str(path))
    (torque,) = [v for v in md.modelVariables if v.causality == "input"]
    assert torque.name == "A.tau" and torque.unit == "N m"
    q0, qd0 = start_state(model, system)
    ref = system.simulate(1.0, q0, qd0, t_eval=times(1.0), rtol=RTOL, atol=ATOL, tau=[0.4, 0.0])
    free = system.simulate(1.0, q0, qd0, t_eval=times(1.0), rtol=RTOL, atol=ATOL)
    assert np.abs(ref.q - free.q).max() > 1e-2
    signal = np.array([(0.0, 0.4), (1.0, 0.4)], dtype=[("time", float), ("A.tau", float)])
    got = run_fmu(path, kind, 1.0, input=signal)
    assert np.abs(got["phi1"] - ref.q[:, 0]).max() < 1e-6
    assert np.abs(got["theta2"] - ref.q[:, 1]).max() < 1e-6


RUN_WITHOUT_MBCOMP = r"""
import json, sys
sys.modules["mbcomp"] = None          # any import of mbcomp fails
sys.path = [p for p in sys.path if p and not p.startswith(sys.argv[2])]
try:
    import mbcomp  # noqa: F401
    raise SystemExit("mbcomp could be imported")
except ImportError:
    pass
from fmpy import simulate_fmu
r = simulate_fmu(sys.argv[1], stop_time=1.0, output_interval=0.5,
                 start_values={"mbcomp.rtol": 1e-11, "mbcomp.atol": 1e-12})
print(json.dumps([list(r["phi1"]), list(r["theta2"])]))
"""


def test_the_fmu_runs_where_mbcomp_cannot_be_imported(exported, tmp_path):
    model, system, paths = exported["double_pendulum"]
    project = os.path.dirname(os.path.dirname(os.path.abspath(mb.__file__)))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MBCOMP_CACHE_DIR")}
    done = subprocess.run([sys.executable, "-c", RUN_WITHOUT_MBCOMP, str(paths["cs"]), project],
                          capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    phi1, theta2 = json.loads(done.stdout.strip().splitlines()[-1])
    q0, qd0 = start_state(model, system)
    ref = system.simulate(1.0, q0, qd0, t_eval=[0.0, 0.5, 1.0], rtol=RTOL, atol=ATOL)
    assert np.abs(np.array(phi1) - ref.q[:, 0]).max() < 1e-6
    assert np.abs(np.array(theta2) - ref.q[:, 1]).max() < 1e-6


def test_the_command_line_writes_an_fmu(tmp_path, capsys):
    from mbcomp.face.cli import main
    out = tmp_path / "pendulum.fmu"
    assert main(["export", "double_pendulum", "--fmu", str(out), "--kind", "me", "--input", "B"]) == 0
    assert "wrote" in capsys.readouterr().out
    assert validate_fmu(str(out)) == []
    md = read_model_description(str(out))
    assert md.modelExchange is not None and [v.name for v in md.modelVariables if v.causality == "input"] == ["B.tau"]
    assert main(["export", "double_pendulum", "--fmu", str(out), "--input", "nowhere"]) == 2
    assert "nowhere" in capsys.readouterr().err


def test_bad_requests_name_the_problem(exported, tmp_path):
    _, system, _ = exported["double_pendulum"]
    with pytest.raises(mb.ModelError, match="kind"):
        system.export_fmu(tmp_path / "x.fmu", kind="both")
    with pytest.raises(mb.ModelError, match="phi9"):
        system.export_fmu(tmp_path / "x.fmu", outputs=["phi9"])
    m = mb.Model("pushed")
    bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -1), inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    m.add(mb.JointTorque("push", "pivot", value=lambda t, q, qd: 0.1))
    with pytest.raises(mb.ModelError, match="callable"):
        m.compile().export_fmu(tmp_path / "x.fmu")


def test_outputs_choose_which_states_are_outputs(exported, tmp_path):
    _, system, _ = exported["double_pendulum"]
    path = system.export_fmu(tmp_path / "few.fmu", kind="cs", outputs=["phi1"])
    md = read_model_description(str(path))
    causality = {v.name: v.causality for v in md.modelVariables}
    assert causality["phi1"] == "output" and causality["theta2"] == "local"
    assert validate_fmu(str(path)) == []


@pytest.mark.parametrize("name", ["double_pendulum", "bouncing_ball"])
def test_the_wrapper_compiles_without_warnings(exported, tmp_path, name):
    """The FMU's sources as shipped (sources/ of the zip) compile with -Wall -Wextra -Werror:
    a tree (no KKT rows) and a contact model (the dae rows, the impact)."""
    from mbcomp.codegen.backend import c_compiler
    with zipfile.ZipFile(exported[name][2]["cs"]) as zf:
        for unit in ("templates", "fmu_tables"):
            source = tmp_path / f"{unit}.c"
            source.write_bytes(zf.read(f"sources/{unit}.c"))
            done = subprocess.run([c_compiler(), "-std=gnu99", "-Wall", "-Wextra", "-Werror", "-fsyntax-only",
                                   str(source)], capture_output=True, text=True, timeout=120)
            assert done.returncode == 0, done.stderr[-2000:]


def test_drive_states_are_states_of_the_fmu(tmp_path):
    """A PID-controlled DC-motor arm: the controllers' integrals and the motors' currents are
    outputs (and model-exchange states) and follow mbcomp's run."""
    system = mb.load("pid_arm").compile()
    path = system.export_fmu(tmp_path / "pid_arm.fmu", kind="cs")
    md = read_model_description(str(path))
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert set(system.extra_states) <= set(outputs)
    ref = system.simulate(0.5, [0.0, 0.0], t_eval=times(0.5), rtol=RTOL, atol=ATOL)
    got = run_fmu(path, "cs", 0.5)
    for i, name in enumerate(system.extra_states):
        assert np.abs(got[name] - ref.z[:, i]).max() < 1e-6 * max(1.0, np.abs(ref.z[:, i]).max()), name
    assert np.abs(got["elbow.angle"] - ref.q[:, 1]).max() < 1e-6


def test_parameter_programs_evaluate_as_expressions():
    """The programs the FMU evaluates for derived parameters (face/fmu/derived.py) give what
    the expressions give in Python, every operation included."""
    from mbcomp.face.fmu.derived import program, run
    from mbcomp.spec.components import expr
    a, b = expr.Expr.parameter("a", 0.7), expr.Expr.parameter("b", 2.5)
    e = (-(a * b) + abs(a - b) / b) ** 2 + expr.sqrt(b) * expr.sin(a) - expr.cos(b) + a.tan() \
        + a.exp() / b.log()
    index = {"a": 0, "b": 1}
    for env in ({"a": 0.7, "b": 2.5}, {"a": -1.3, "b": 0.4}):
        assert run(program(e, index), [env["a"], env["b"]]) == pytest.approx(e.evaluate(env), rel=1e-15)


def test_a_position_motor_drives_the_fmu(tmp_path):
    """A motor prescribing phi1(t) = amplitude sin(2 pi frequency t) (a KKT row whose position
    runs as a program in C) through both kinds; its parameters are compiled into the motion,
    so they are not variables of the FMU (mbcomp refuses to change them at run time too)."""
    model = mb.load("double_pendulum_motor")
    system = model.compile()
    for kind in ("cs", "me"):
        path = system.export_fmu(tmp_path / f"motor_{kind}.fmu", kind=kind)
        assert validate_fmu(str(path)) == []
        names = {v.name for v in read_model_description(str(path)).modelVariables}
        assert "L" in names and "amplitude" not in names and "frequency" not in names
        q0, qd0 = start_state(model, system)
        ref = system.simulate(1.0, q0, qd0, t_eval=times(1.0), rtol=RTOL, atol=ATOL)
        got = run_fmu(path, kind, 1.0)
        assert np.abs(got["phi1"] - 0.5 * np.sin(2 * np.pi * times(1.0))).max() < 1e-6
        assert np.abs(got["theta2"] - ref.q[:, 1]).max() < 1e-6


def test_the_start_of_a_quaternion_loop_is_projected_onto_its_constraints(tmp_path):
    """The FMU's start-up projection (dae_project) moves quaternion coordinates by the exp
    map: a spatial four-bar through two Ball joints, started 0.02 rad off its loop, starts on
    it to 1e-10 in both kinds, near where ``assemble``'s Newton puts the same start (the two
    minimum-norm iterations end within a few 1e-6), with unit quaternions, and from there moves
    as mbcomp's run from the FMU's start state."""
    from components.test_ball_free import rssr
    system = rssr("dae")
    v0 = np.zeros(system.nv)
    v0[0] = 2.0
    q_ok, v_ok = system.assemble(system.state_vector({"crank_pivot": 0.0, "rocker_pivot": 0.0}), v0)
    names = system.coords
    speeds = [name + "_d" if name in names else name for name in system.speeds]  # (the FMU's speed names)
    off = np.array(q_ok)
    off[names.index("rocker_pivot")] += 0.02
    assert system.constraint_violation(off) > 1e-3
    q_in, _ = system.assemble(off, v_ok)
    for kind in ("cs", "me"):
        path = system.export_fmu(tmp_path / f"rssr_{kind}.fmu", kind=kind)
        start = {name: float(v) for name, v in zip(names, off)}
        start.update({name: float(v) for name, v in zip(speeds, v_ok)})
        got = run_fmu(path, kind, 0.3, start_values=start)
        q0 = np.array([got[name][0] for name in names])
        qd0 = np.array([got[name][0] for name in speeds])
        assert system.constraint_violation(q0) < 1e-10
        assert np.abs(q0 - q_in).max() < 1e-5
        assert abs(np.linalg.norm(q0[1:5]) - 1.0) < 1e-14
        ref = system.simulate(0.3, q0, qd0, t_eval=times(0.3), rtol=RTOL, atol=ATOL)
        assert np.abs(np.array([got[name] for name in names]).T - ref.q).max() < 1e-6
