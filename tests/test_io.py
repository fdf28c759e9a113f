"""TOML model files: round trips, validation messages (file, table, key), expressions."""
from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.files.toml_model import (Expression, TimeVector, dumps, library_models, load, parse_expression, save)
from mbcomp.files.toml_model import ExpressionError, evaluate

MODELS = library_models()

PENDULUM = """\
description = "A test pendulum."
name = "pendulum"
gravity = [0.0, 0.0, -9.81]

[parameters]
m = 2.0
L = 0.5

[bodies.rod]
mass = "m"
com = [0.0, 0.0, "-L/2"]
inertia = ["m*L**2/12", "m*L**2/12", 1e-4]

[joints.hinge]
type = "revolute"
parent = "ground"
child = "rod"
axis = "y"
coords = "q"

[initial.q]
q = 0.3

[simulation]
t_end = 1.0
n_samples = 11
"""


def write(tmp_path, text: str, name: str = "model.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def load_error(path) -> str:
    with pytest.raises(mb.ModelError) as info:
        load(path)
    return str(info.value)


def rounded(value):
    """Floats to 13 significant digits (a unit axis is renormalised when read back)."""
    if isinstance(value, float):
        return float(f"{value:.13g}")
    if isinstance(value, (tuple, list)):
        return type(value)(rounded(v) for v in value)
    return value


def signature(model) -> list:
    """What defines a model, component by component (types, references, values, structure)."""
    rows = [("model", model.name, tuple(model.gravity))]
    for comp in model.components.values():
        refs = tuple(sorted((role, getattr(ref, "name", ref)) for role, ref in comp.references().items()))
        values = {}
        for key, value in comp.parameter_values().items():
            if isinstance(value, (TimeVector, Expression)):
                value = ("input", repr(value))
            values[key] = value
        extras = []
        for attr in ("coords", "position", "is_callable"):
            value = getattr(comp, attr, None)
            extras.append(repr(value) if isinstance(value, (Expression, TimeVector)) else value)
        rows.append((type(comp).__name__, comp.name, refs, rounded(tuple(sorted(values.items()))),
                     rounded(comp.structure()), tuple(extras)))
    return rows


def random_state(system, seed=1):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, system.nq), rng.uniform(-1, 1, system.nq)


# ----------------------------------------------------------------------------------------------
# Loading and round trips
# ----------------------------------------------------------------------------------------------
class TestLoad:
    def test_pendulum_file_gives_the_model_and_its_extras(self, tmp_path):
        model = load(write(tmp_path, PENDULUM))
        assert model.name == "pendulum"
        assert model.description == "A test pendulum."
        assert model.named_parameters == {"m": 2.0, "L": 0.5}
        assert model["rod"].mass == 2.0 and model["rod"].com == (0.0, 0.0, -0.25)
        assert model["rod"].inertia == pytest.approx((2.0 * 0.25 / 12, 2.0 * 0.25 / 12, 1e-4))
        assert model["hinge"].coords == ("q",)
        assert model.initial == {"q": {"q": 0.3}, "qd": {}}
        assert model.simulation == {"t_end": 1.0, "n_samples": 11}

    def test_declaration_order_is_kept(self, tmp_path):
        text = PENDULUM + textwrap.dedent("""
            [bodies.b2]
            mass = 1.0
            [bodies.a1]
            mass = 1.0
            [joints.z_joint]
            type = "revolute"
            parent = "rod"
            child = "b2"
            axis = "x"
            [joints.a_joint]
            type = "revolute"
            parent = "b2"
            child = "a1"
            axis = "x"
            """)
        model = load(write(tmp_path, text))
        assert [c.name for c in model.components.values()] == ["ground", "rod", "b2", "a1", "hinge", "z_joint", "a_joint"]

    def test_name_defaults_to_the_file_stem(self, tmp_path):
        model = load(write(tmp_path, "[bodies.b]\nmass = 1.0\n", name="my_model.toml"))
        assert model.name == "my_model"
        assert model.initial == {"q": {}, "qd": {}} and model.simulation == {}

    def test_time_inputs_reach_the_system(self, tmp_path):
        # a 2 kg block pushed along x by F = 3 t + sin(t) and a joint force 0.5 t^2: x'' = F / m
        path = write(tmp_path, """
            gravity = [0.0, 0.0, 0.0]
            [parameters]
            k = 3.0
            [bodies.block]
            mass = 2.0
            [joints.slide]
            type = "prismatic"
            parent = "ground"
            child = "block"
            axis = "x"
            [forces.push]
            type = "force"
            body = "block"
            force = ["k*t + sin(t)", 0.0, 0.0]
            [forces.drive]
            type = "joint_torque"
            joint = "slide"
            value = "0.5*t**2"
            """)
        model = load(path)
        assert isinstance(model["push"].force, TimeVector)
        system = model.compile()
        for t in (0.0, 0.7, 2.0):
            expected = (3 * t + math.sin(t) + 0.5 * t ** 2) / 2
            assert system.accelerations([0.0], [0.0], t=t)[0] == pytest.approx(expected, rel=1e-12)

    def test_motor_position_is_a_callable_of_t_with_exact_derivatives(self, tmp_path):
        model = load(MODELS["double_pendulum_motor"])
        position = model["motor"].position
        assert isinstance(position, Expression) and callable(position)
        t = np.linspace(0.0, 1.0, 7)
        amplitude, frequency = 0.5, 1.0
        np.testing.assert_allclose([position(x) for x in t], amplitude * np.sin(2 * np.pi * frequency * t), atol=1e-15)
        speed, acceleration = position.diff(), position.diff().diff()
        w = 2 * np.pi * frequency
        np.testing.assert_allclose([speed(x) for x in t], amplitude * w * np.cos(w * t), atol=1e-12)
        np.testing.assert_allclose([acceleration(x) for x in t], -amplitude * w ** 2 * np.sin(w * t), atol=1e-10)

    def test_the_documented_example_loads_and_compiles(self, tmp_path):
        import pathlib
        import re
        docs = pathlib.Path(__file__).resolve().parents[1] / "docs" / "files.md"
        if not docs.is_file():
            pytest.skip("docs/files.md not present")
        block = re.search(r"```toml\n(.*?)```", docs.read_text(encoding="utf-8"), re.S).group(1)
        model = load(write(tmp_path, block))
        assert model.simulation["method"] == "DOP853" and list(model.simulation)[0] == "t_end"
        assert model.compile().coords == ("alpha", "beta", "gamma")

    def test_library_models_load(self):
        assert len(MODELS) >= 12
        for name, path in MODELS.items():
            assert load(path).name == name


class TestRoundTrip:
    @pytest.mark.parametrize("name", sorted(MODELS))
    def test_library_model_survives_save_and_load(self, tmp_path, name):
        model = load(MODELS[name])
        path = tmp_path / f"{name}.toml"
        save(model, path)
        again = load(path)
        assert signature(again) == signature(model)
        assert again.initial == model.initial and again.simulation == model.simulation
        assert again.description == model.description
        assert dumps(again) == path.read_text(encoding="utf-8"), "saving is not idempotent"

    def test_a_normalised_axis_keeps_its_parameter_expression(self, tmp_path):
        """A joint axis written with parameters (the bicycle's head axis, from ``lambda``) is
        normalised by the joint: saving writes the expressions given, not the derived
        numbers, so the reloaded model still refuses a change of ``lambda`` (structure)."""
        model = load(MODELS["whipple_bicycle"])
        save(model, tmp_path / "bike.toml")
        text = (tmp_path / "bike.toml").read_text(encoding="utf-8")
        assert 'axis = ["sin(lambda)", 0.0, "(-cos(lambda))"]' in text and "derived from" not in text
        with pytest.raises(mb.ModelError, match="lambda"):
            load(tmp_path / "bike.toml").compile().with_parameters({"lambda": 0.35})

    @pytest.mark.parametrize("name", ["arm3d", "double_pendulum_spring"])
    def test_same_coordinates_and_accelerations(self, tmp_path, name):
        model = load(MODELS[name])
        save(model, tmp_path / "saved.toml")
        first, second = model.compile(), load(tmp_path / "saved.toml").compile()
        assert first.coords == second.coords
        q, qd = random_state(first)
        np.testing.assert_allclose(second.accelerations(q, qd), first.accelerations(q, qd), rtol=1e-13, atol=1e-13)

    def test_python_built_model_with_every_force_type(self, tmp_path):
        m = mb.Model("everything", gravity=(0.1, -0.2, -9.81))
        a = m.add(mb.Body("a", mass=1.5, com=(0.1, 0.0, -0.2),
                          inertia=[[0.02, 0.001, 0.0], [0.001, 0.03, 0.0], [0.0, 0.0, 0.025]]))
        b = m.add(mb.Body("b", mass=0.7, com=(0.0, 0.1, 0.0)))
        c = m.add(mb.Body("c", mass=0.3, inertia=(1e-3, 1e-3, 1e-3)))
        m.add(mb.Spherical("ball", m.ground, a, sequence="zxz", parent_point=(0, 0, 0.1), coords=("p", "n", "s")))
        m.add(mb.Prismatic("slide", a, b, axis=(1.0, 1.0, 0.0), child_point=(0.0, 0.05, 0.0)))
        m.add(mb.Fixed("weld", b, c, parent_point=(0.0, 0.0, 0.1)))
        m.add(mb.Spring("spring", a=(m.ground, (0.3, 0, 0)), b=(b, (0, 0.1, 0)), stiffness=20.0, rest_length=0.1,
                        damping=0.3))
        m.add(mb.Damper("damper", a=m.ground, b=(c, (0.0, 0.0, 0.05)), damping=0.2))
        m.add(mb.Force("push", c, point=(0.01, 0, 0), force=(1.0, 0.0, -0.5)))
        m.add(mb.JointTorque("drive", "ball", value=(0.1, 0.0, -0.2)))
        m.add(mb.TorsionSpring("twist", "slide", stiffness=3.0, rest=0.02, damping=0.1))
        path = tmp_path / "everything.toml"
        save(m, path)
        again = load(path)
        assert signature(again) == signature(m)
        first, second = m.compile(), again.compile()
        assert first.coords == second.coords == ("p", "n", "s", "slide")
        q, qd = random_state(first, seed=7)
        q[1] = 0.8  # away from the z-x-z gimbal lock
        np.testing.assert_allclose(second.accelerations(q, qd, t=0.3), first.accelerations(q, qd, t=0.3),
                                   rtol=1e-12, atol=1e-12)

    def test_time_expressions_are_written_as_text(self, tmp_path):
        model = load(MODELS["double_pendulum_motor"])
        text = dumps(model)
        assert 'position = "amplitude*sin(2*pi*frequency*t)"' in text
        assert "[parameters]" in text and "amplitude = 0.5" in text

    def test_python_callables_cannot_be_saved(self, tmp_path):
        m = mb.Model("callable")
        body = m.add(mb.Body("b", mass=1.0))
        m.add(mb.Prismatic("slide", m.ground, body, axis="z"))
        m.add(mb.JointTorque("drive", "slide", value=lambda t, q, qd: [math.sin(t)]))
        with pytest.raises(mb.ModelError, match="JointTorque 'drive': value is a Python callable"):
            save(m, tmp_path / "x.toml")
        assert not (tmp_path / "x.toml").exists()

    def test_names_that_need_quoting(self, tmp_path):
        m = mb.Model("quoted name")
        body = m.add(mb.Body("upper arm", mass=1.0, com=(0, 0, -0.1)))
        m.add(mb.Revolute("shoulder joint", m.ground, body, axis="-x", coords="angle one"))
        save(m, tmp_path / "q.toml")
        again = load(tmp_path / "q.toml")
        assert signature(again) == signature(m)


# ----------------------------------------------------------------------------------------------
# Validation: every problem, with file, table and key
# ----------------------------------------------------------------------------------------------
JOINT = """
[joints.j]
type = "revolute"
parent = "ground"
child = "b"
axis = "x"
"""

BROKEN = {
    "missing_mass": ("[bodies.b]\ncom = [0.0, 0.0, 0.0]\n", ["[bodies.b] mass: missing (required)"]),
    "wrong_type": ("[bodies.b]\nmass = true\n", ["[bodies.b] mass: must be a number or a parameter expression, got a boolean"]),
    "string_list_type": ("[bodies.b]\nmass = 1.0\ncom = \"origin\"\n", ["[bodies.b] com: must be a 3-vector"]),
    "nan": ("[bodies.b]\nmass = nan\n", ["[bodies.b] mass: must be finite, got nan"]),
    "inf_in_vector": ("[bodies.b]\nmass = 1.0\ncom = [0.0, inf, 0.0]\n", ["[bodies.b] com[1]: must be finite, got inf"]),
    "vector_of_two": ("[bodies.b]\nmass = 1.0\ncom = [0.0, 1.0]\n", ["[bodies.b] com: must have 3 components, got 2"]),
    "negative_mass": ("[bodies.b]\nmass = -1.0\n", ["[bodies.b] mass: must be positive, got -1"]),
    "unknown_body": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('child = "b"', 'child = "bb"'),
                     ["[joints.j] child: unknown body 'bb' (did you mean 'b'?); bodies: ground, b"]),
    "unknown_key": ("[bodies.b]\nmass = 1.0\ncolour = \"red\"\n", ["[bodies.b] colour: unknown key; allowed: mass, com, inertia"]),
    "misspelt_key": ("[bodies.b]\nmass = 1.0\nintertia = [1.0, 1.0, 1.0]\n", ["[bodies.b] intertia: unknown key (did you mean 'inertia'?)"]),
    "unknown_top_key": ("gravty = [0.0, 0.0, -9.81]\n", ["model.toml gravty: unknown key (did you mean 'gravity'?)"]),
    "python_import": ("[bodies.b]\nmass = \"__import__('os').system('echo hacked')\"\n",
                      ["[bodies.b] mass: ", "is not allowed"]),
    "python_call": ("[bodies.b]\nmass = \"__import__('os')\"\n", ["[bodies.b] mass: ", "calling __import__ is not allowed (only sin, cos, exp, sqrt)"]),
    "attribute": ("[bodies.b]\nmass = \"(1).__class__\"\n", ["[bodies.b] mass: ", "Attribute is not allowed"]),
    "lambda": ("[bodies.b]\nmass = \"(lambda: 1)()\"\n", ["[bodies.b] mass: ", "not allowed"]),
    "unknown_name": ("[bodies.b]\nmass = \"mass_of_b\"\n", ["[bodies.b] mass: 'mass_of_b': unknown name 'mass_of_b'"]),
    "time_in_a_constant": ("[bodies.b]\nmass = \"1 + t\"\n", ["[bodies.b] mass: '1 + t': the time t is only allowed in time-varying inputs"]),
    "not_an_expression": ("[bodies.b]\nmass = \"1 +\"\n", ["[bodies.b] mass: '1 +' is not a number or an arithmetic expression"]),
    "math_error": ("[bodies.b]\nmass = \"1/0\"\n", ["[bodies.b] mass: '1/0' cannot be evaluated"]),
    "overflow": ("[bodies.b]\nmass = \"10**10**10\"\n", ["[bodies.b] mass: '10**10**10' cannot be evaluated"]),
    "bad_axis": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('axis = "x"', 'axis = "w"'),
                 ["[joints.j] axis: must be 'x', 'y', 'z' or a 3-vector, got 'w'"]),
    "zero_axis": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('axis = "x"', "axis = [0, 0, 0]"), ["[joints.j] axis: has zero length"]),
    "axis_of_two": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('axis = "x"', "axis = [1, 0]"),
                    ["[joints.j] axis: must be 'x', 'y', 'z' or a 3-vector, got 2 components"]),
    "missing_axis": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('axis = "x"\n', ""), ["[joints.j] axis: missing (required)"]),
    "joint_type": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('"revolute"', '"hinge"'),
                   ["[joints.j] type: must be one of 'revolute', 'prismatic', 'spherical', 'fixed', 'ball', 'free', 'universal', 'cylindrical', 'planar', got 'hinge'"]),
    "key_of_other_joint_type": ("[bodies.b]\nmass = 1.0\n" + JOINT + 'sequence = "xy"\n', ["[joints.j] sequence: unknown key"]),
    "bad_sequence": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('"revolute"', '"spherical"').replace('axis = "x"', 'sequence = "xxa"'),
                     ["[joints.j] sequence: 'xxa' has invalid axis 'a'"]),
    "coords_count": ("[bodies.b]\nmass = 1.0\n" + JOINT + 'coords = ["a", "b"]\n', ["[joints.j] coords: must name 1 coordinate(s), got 2"]),
    "inertia_matrix_shape": ("[bodies.b]\nmass = 1.0\ninertia = [[1.0, 0.0], [0.0, 1.0]]\n", ["[bodies.b] inertia: a matrix must be 3x3"]),
    "inertia_triangle": ("[bodies.b]\nmass = 1.0\ninertia = [1.0, 1.0, 5.0]\n", ["[bodies.b] inertia: violates the triangle inequality: principal moment 5 > 1 + 1"]),
    "unknown_joint": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[forces.tw]\ntype = \"torsion_spring\"\njoint = \"k\"\nstiffness = 1.0\n",
                      ["[forces.tw] joint: unknown joint 'k'"]),
    "spring_attachment": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[forces.s]\ntype = \"spring\"\na = { body = \"ground\", pt = [0, 0, 0] }\nb = \"b\"\nstiffness = 1.0\n",
                          ["[forces.s.a] pt: unknown key; allowed: body, point"]),
    "motor_both": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[constraints.m]\ntype = \"motor\"\njoint = \"j\"\nspeed = 1.0\nposition = \"t\"\n",
                   ["[constraints.m]: Motor 'm': give exactly one of position (a callable of t) or speed"]),
    "motor_expression": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[constraints.m]\ntype = \"motor\"\njoint = \"j\"\nposition = \"open('x')\"\n",
                         ["[constraints.m] position: ", "calling open is not allowed"]),
    "motor_on_spherical": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace('"revolute"', '"spherical"').replace('axis = "x"', 'sequence = "xy"')
                           + "[constraints.m]\ntype = \"motor\"\njoint = \"j\"\nspeed = 1.0\n",
                           ["[constraints.m]: Motor 'm': needs a 1-DOF joint, Spherical 'j' has 2 coordinates"]),
    "torque_size": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[forces.tq]\ntype = \"joint_torque\"\njoint = \"j\"\nvalue = [1.0, \"sin(t)\"]\n",
                    ["[forces.tq] value: has 2 entries, joint 'j' has 1 coordinate(s)"]),
    "restitution_range": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[contacts.c]\nbody = \"b\"\nnormal = \"z\"\nrestitution = 1.5\n",
                          ["[contacts.c] restitution: must lie in [0, 1], got 1.5"]),
    "duplicate_name": ("[bodies.b]\nmass = 1.0\n" + JOINT.replace("[joints.j]", "[joints.b]"),
                       ["[joints.b]: name 'b' is already used by [bodies.b]"]),
    "ground_body": ("[bodies.ground]\nmass = 1.0\n", ["[bodies.ground]: name 'ground' is already used by the ground"]),
    "reserved_parameter": ("[parameters]\npi = 3.0\n", ["[parameters] pi: 'pi' is reserved"]),
    "unknown_coordinate": ("[bodies.b]\nmass = 1.0\n" + JOINT + "[initial.q]\njj = 0.1\n",
                           ["[initial.q] jj: unknown coordinate (did you mean 'j'?); coordinates: j"]),
    "simulation_method": ("[simulation]\nmethod = \"Euler\"\nn_samples = 1\n",
                          ["[simulation] method: must be one of 'RK45'", "[simulation] n_samples: must be an integer from 2 to 1e+07, got 1"]),
    "section_not_a_table": ("bodies = 3\n", ["model.toml bodies: must be a table"]),
}


class TestValidation:
    @pytest.mark.parametrize("case", sorted(BROKEN))
    def test_broken_file_names_file_table_and_key(self, tmp_path, case):
        text, expected = BROKEN[case]
        path = write(tmp_path, text)
        message = load_error(path)
        for fragment in expected:
            assert fragment in message, f"{fragment!r} not in:\n{message}"
        assert str(path) in message

    def test_every_problem_is_reported_at_once(self, tmp_path):
        path = write(tmp_path, """
            [bodies.b]
            mass = -1.0
            com = [0.0, 1.0]
            size = 3
            [joints.j]
            type = "revolute"
            parent = "ground"
            child = "c"
            axis = "q"
            """)
        with pytest.raises(mb.ModelError) as info:
            load(path)
        problems = info.value.problems
        assert len(problems) == 5, problems
        assert all(p.startswith(str(path) + " [") for p in problems)
        assert "model has 5 problems" in str(info.value)

    def test_toml_syntax_error_gives_file_and_line(self, tmp_path):
        path = write(tmp_path, "[bodies.b]\nmass = = 1.0\ncom = [0.0, 0.0, 0.0]\n")
        message = load_error(path)
        assert f"{path}:2:" in message and "TOML syntax error" in message

    def test_duplicate_table_is_a_syntax_error(self, tmp_path):
        path = write(tmp_path, "[bodies.b]\nmass = 1.0\n[bodies.b]\nmass = 2.0\n")
        assert f"{path}:3:" in load_error(path)

    def test_missing_file(self, tmp_path):
        message = load_error(tmp_path / "nothing.toml")
        assert "nothing.toml" in message and "cannot read" in message

    def test_not_utf8(self, tmp_path):
        path = tmp_path / "latin.toml"
        path.write_bytes(b'name = "caf\xe9"\n')
        assert "not UTF-8" in load_error(path)

    def test_broken_joint_does_not_cascade_into_initial(self, tmp_path):
        path = write(tmp_path, "[bodies.b]\nmass = 1.0\n" + JOINT.replace('axis = "x"', 'axis = "w"') + "[initial.q]\nj = 0.1\n")
        assert "unknown coordinate" not in load_error(path)


# ----------------------------------------------------------------------------------------------
# The expression language
# ----------------------------------------------------------------------------------------------
class TestExpressions:
    @pytest.mark.parametrize("text, value", [
        ("1", 1.0), ("-2.5e-3", -2.5e-3), ("2*pi", 2 * math.pi), ("m*L**2/12", 3 * 4 / 12),
        ("sqrt(m) + exp(0) - cos(0) + sin(0)", math.sqrt(3)), ("-(m - 1)**2", -4.0), ("+m", 3.0),
    ])
    def test_values(self, text, value):
        assert evaluate(parse_expression(text, {"m": 3.0, "L": 2.0}, allow_t=False)) == pytest.approx(value, rel=1e-15)

    @pytest.mark.parametrize("text", [
        "__import__('os')", "open('x').read()", "m.real", "[1, 2]", "(1, 2)", "{'a': 1}", "m if t else 1",
        "lambda: 1", "t(1)", "sin(1, 2)", "sin(x=1)", "sin(*[1])", "abs(-1)", "1 < 2", "not 1", "m and 1",
        "1 // 2", "1 % 2", "~1", "'text'", "True", "None", "1j", "m[0]", "f'{m}'", "sin", "x := 1", "eval('1')",
    ])
    def test_everything_else_is_rejected(self, text):
        with pytest.raises(ExpressionError):
            parse_expression(text, {"m": 3.0}, allow_t=True)

    def test_a_parameter_may_be_named_like_a_python_keyword(self):
        """The bicycle papers call the head angle ``lambda``: a declared parameter of that name
        is usable in expressions; the keyword itself (a lambda expression) stays rejected."""
        names = {"lambda": 0.3, "lambda_": 2.0, "m": 3.0}
        node = parse_expression("sin(lambda)*lambda_ + m*lambda", names, allow_t=False)
        assert evaluate(node) == pytest.approx(math.sin(0.3) * 2.0 + 3.0 * 0.3, rel=1e-15)
        for text in ("lambda: 1", "lambda x: x", "m if lambda else 1"):
            with pytest.raises(ExpressionError):
                parse_expression(text, names, allow_t=False)
        with pytest.raises(ExpressionError, match="invalid syntax"):
            parse_expression("sin(lambda)", {"m": 1.0}, allow_t=False)   # not declared: still a keyword

    def test_deep_nesting_is_rejected_not_crashing(self):
        with pytest.raises(ExpressionError):
            parse_expression("(" * 400 + "1" + ")" * 400, {}, allow_t=False)
        with pytest.raises(ExpressionError):
            parse_expression("1" + "+1" * 600, {}, allow_t=False)

    def test_derivatives_match_finite_differences(self):
        text = "0.3*sin(2*t)**2 + exp(-t)*cos(3*t) + sqrt(1 + t**2) + t**t/(2 + t)"
        f = Expression(text, parse_expression(text, {}, allow_t=True))
        df, d2f = f.diff(), f.diff().diff()
        h = 1e-5
        for t in (0.3, 1.1, 2.0):
            assert df(t) == pytest.approx((f(t + h) - f(t - h)) / (2 * h), rel=1e-8)
            assert d2f(t) == pytest.approx((df(t + h) - df(t - h)) / (2 * h), rel=1e-7)

    def test_to_sympy_agrees(self):
        import sympy as sp
        text = "2*sin(pi*t) - t**2/3"
        f = Expression(text, parse_expression(text, {}, allow_t=True))
        t = sp.Symbol("t")
        expr = f.to_sympy(t)
        assert float(expr.subs(t, 0.7)) == pytest.approx(f(0.7), rel=1e-14)

    def test_run_time_error_names_the_input(self):
        f = Expression("sqrt(1 - t)", parse_expression("sqrt(1 - t)", {}, allow_t=True), "motor 'm'")
        with pytest.raises(mb.SimulationError, match="motor 'm'.*sqrt\\(1 - t\\).*t = 2"):
            f(2.0)

    def test_parameters_may_use_earlier_parameters(self, tmp_path):
        model = load(write(tmp_path, '[parameters]\na = 2.0\nb = "a**2 + 1"\n[bodies.x]\nmass = "b"\n'))
        assert model["x"].mass == 5.0

    def test_parameters_may_not_use_later_ones(self, tmp_path):
        message = load_error(write(tmp_path, '[parameters]\nb = "a + 1"\na = 2.0\n'))
        assert "[parameters] b: 'a + 1': unknown name 'a'" in message


@pytest.mark.parametrize("bad", [5, None, 2.5, ["a.toml"]])
def test_load_of_a_non_path_is_a_model_error(bad):
    with pytest.raises(mb.ModelError, match="path must be a file path"):
        mb.load(bad)
