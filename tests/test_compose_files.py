"""Model files that compose: [parameters], [ports], [submodels] with use, bindings, overrides."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from tests.conftest import assert_close
from tests.test_compose import Leg, double_pendulum

LINK = '''name = "link"
[parameters]
length = { value = 0.5, unit = "m", min = 0.0 }
mass = 1.0
[ports]
parent = "external"
tip = { body = "rod", point = [0.0, 0.0, "-length"] }
[bodies.rod]
mass = "mass"
com = [0.0, 0.0, "-length/2"]
inertia = ["mass*length**2/12", "mass*length**2/12", 1e-4]
[joints.joint]
type = "revolute"
parent = "parent"
child = "rod"
axis = "x"
coords = "angle"
'''

DOUBLE = '''name = "double_pendulum"
[submodels.upper]
use = "link.toml"
parent = "ground"
length = 0.3
[submodels.lower]
use = "link.toml"
parent = "upper.tip"
length = 0.2
mass = 0.5
'''


@pytest.fixture
def files(tmp_path):
    (tmp_path / "link.toml").write_text(LINK)
    (tmp_path / "double_pendulum.toml").write_text(DOUBLE)
    return tmp_path


def test_file_model_equals_the_python_model(files):
    m = mb.load(files / "double_pendulum.toml")
    assert isinstance(m["lower.rod"], mb.Body)
    for formulation in ("lagrange", "dae"):
        s, p = m.compile(formulation), double_pendulum().compile(formulation)
        assert s.coords == p.coords == ("upper.angle", "lower.angle")
        assert s.parameters == p.parameters
        q, qd = [0.3, -0.5], [0.1, 0.7]
        np.testing.assert_array_equal(s.accelerations(q, qd), p.accelerations(q, qd))
        # run-time changes follow the file's expressions exactly as the Python ones
        assert s.with_parameters({"upper.length": 0.45}).parameters == \
            p.with_parameters({"upper.length": 0.45}).parameters


def test_part_file_read_alone_hangs_from_the_ground(files):
    s = mb.load(files / "link.toml").compile(backend="python")
    assert s.coords == ("angle",)
    assert s.parameters["rod.com"] == (0.0, 0.0, -0.25)


def test_nested_part_files_and_inner_modifiers(files):
    (files / "parts").mkdir()
    (files / "parts" / "link.toml").write_text(LINK)
    (files / "parts" / "link_y.toml").write_text(LINK.replace('axis = "x"', 'axis = "y"'))
    (files / "parts" / "leg.toml").write_text('''name = "leg"
[parameters]
thigh_length = { value = 0.4, min = 0.05, max = 2.0 }
mass = 2.0
[ports]
hip = "external"
foot = "shank.tip"
[submodels.thigh]
use = "link.toml"
parent = "hip"
length = "thigh_length"
mass = "mass"
[submodels.shank]
use = "link_y.toml"
parent = "thigh.tip"
length = "0.9*thigh_length"
mass = "mass/2"
''')
    (files / "robot.toml").write_text('''name = "robot"
[bodies.torso]
mass = 5.0
inertia = [0.1, 0.1, 0.1]
[joints.turn]
type = "revolute"
parent = "ground"
child = "torso"
axis = "z"
[submodels.left]
use = "parts/leg.toml"
hip = "torso"
thigh = { length = 0.5 }
[submodels.right]
use = "parts/leg.toml"
hip = "torso"
thigh_length = 0.3
[forces.tie]
type = "spring"
a = "left.shank.rod"
b = "right.shank.rod"
stiffness = 20.0
''')
    m = mb.load(files / "robot.toml")
    s = m.compile()
    assert s.coords == ("turn", "left.thigh.angle", "left.shank.angle", "right.thigh.angle", "right.shank.angle")
    assert s.parameters["left.thigh.length"] == 0.5           # the outer modifier wins
    assert s.parameters["left.shank.length"] == pytest.approx(0.36)
    assert m["left"].foot.body is m["left.shank.rod"]
    # the same robot in Python
    p = mb.Model("robot")
    torso = p.add(mb.Body("torso", mass=5.0, inertia=(0.1, 0.1, 0.1)))
    p.add(mb.Revolute("turn", p.ground, torso, axis="z"))
    p.add(Leg("left", hip=torso.frame(), thigh={"length": 0.5}))
    p.add(Leg("right", hip=torso.frame(), thigh_length=0.3))
    p.add(mb.Spring("tie", a=p["left.shank.rod"], b=p["right.shank.rod"], stiffness=20.0))
    ps = p.compile()
    shared = [k for k in ps.parameters if k in s.parameters]
    assert len(shared) > 20
    for key in shared:
        assert_close(s.parameters[key], ps.parameters[key], name=key)
    q, qd = np.linspace(-0.4, 0.5, 5), np.linspace(0.3, -0.2, 5)
    assert_close(s.accelerations(q, qd), ps.accelerations(q, qd), name="accelerations")
    changed, fresh = s.with_parameters({"right.thigh_length": 0.35}), ps.with_parameters({"right.thigh_length": 0.35})
    assert_close(changed.accelerations(q, qd), fresh.accelerations(q, qd), name="after a run-time change")


def test_use_may_not_leave_the_directory(files):
    (files / "sub").mkdir()
    (files / "sub" / "m.toml").write_text('[submodels.a]\nuse = "../link.toml"\nparent = "ground"\n')
    with pytest.raises(mb.ModelError, match=r"m.toml \[submodels.a\] use: '../link.toml' leaves the directory"):
        mb.load(files / "sub" / "m.toml")


def test_a_cycle_of_use_names_the_files(files):
    (files / "a.toml").write_text('[ports]\np = "external"\n[submodels.b]\nuse = "b.toml"\np = "p"\n')
    (files / "b.toml").write_text('[ports]\np = "external"\n[submodels.a]\nuse = "a.toml"\np = "p"\n')
    with pytest.raises(mb.ModelError, match=r"cycle: .*a.toml -> .*b.toml -> .*a.toml"):
        mb.load(files / "a.toml")


def test_errors_in_a_part_carry_its_file_and_key(files):
    (files / "bad.toml").write_text(LINK.replace('axis = "x"', 'axis = "w"'))
    (files / "m.toml").write_text('[submodels.a]\nuse = "bad.toml"\nparent = "ground"\nlenght = 0.3\n')
    with pytest.raises(mb.ModelError) as info:
        mb.load(files / "m.toml")
    text = str(info.value)
    assert "m.toml [submodels.a] lenght: unknown key" in text and "parameters ['length', 'mass']" in text
    (files / "m.toml").write_text('[submodels.a]\nuse = "bad.toml"\nparent = "ground"\n')
    with pytest.raises(mb.ModelError, match=r"bad.toml \[joints.joint\] axis"):
        mb.load(files / "m.toml")


def test_bounds_and_unbound_ports_in_files(files):
    (files / "m.toml").write_text('[submodels.a]\nuse = "link.toml"\nparent = "ground"\nlength = -1.0\n')
    with pytest.raises(mb.ModelError, match=r"'a.length'.*\[0.0, None\]"):
        mb.load(files / "m.toml")
    (files / "m.toml").write_text('[submodels.a]\nuse = "link.toml"\n')
    with pytest.raises(mb.ModelError, match=r"\[submodels.a\]: port\(s\) \['parent'\] of link.toml are not bound"):
        mb.load(files / "m.toml")


def test_files_are_data(files):
    (files / "m.toml").write_text('[submodels.a]\nuse = "link.toml"\nparent = "ground"\n'
                                  'length = "__import__(\'os\').getcwd()"\n')
    with pytest.raises(mb.ModelError, match="not allowed"):
        mb.load(files / "m.toml")


def test_save_writes_nested_models_that_load_reads_back(tmp_path):
    m = mb.Model("legs")
    torso = m.add(mb.Body("torso", mass=5.0, inertia=(0.1, 0.1, 0.1)))
    m.add(mb.Revolute("turn", m.ground, torso, axis="z"))
    m.add(Leg("left", hip=torso.frame((0, 0.1, 0), mb.rpy(0.1, 0, 0)), thigh={"length": 0.5}))
    m.add(Leg("right", hip=torso.frame((0, -0.1, 0))))
    m.add(mb.Spring("s", a=m["left.shank.rod"].frame((0, 0, -0.1)), b=m["right.shank.rod"], stiffness=10.0))
    m.save(tmp_path / "legs.toml")
    back = mb.load(tmp_path / "legs.toml")
    assert [c.name for c in back.tree().children] == ["left", "right"]
    s1, s2 = m.compile(), back.compile()
    assert s1.coords == s2.coords
    for key, value in s2.parameters.items():
        assert_close(value, s1.parameters[key], name=key)
    q = np.linspace(-0.3, 0.4, 5)
    assert_close(s2.accelerations(q, -q), s1.accelerations(q, -q), name="accelerations")


def test_info_prints_the_instance_tree(files, capsys):
    from mbcomp.face.cli import main
    assert main(["info", str(files / "double_pendulum.toml"), "--no-equations"]) == 0
    out = capsys.readouterr().out
    assert "instances\n  upper (link)  length=0.3, mass=1\n" in out
    assert "  lower (link)  length=0.2, mass=0.5\n" in out


def test_part_parameters_in_a_motor_position_are_refused(tmp_path):
    """A motor position is evaluated outside the parameter vector: a part parameter in it
    would keep its build-time value while sys.parameters lists it, so the file is refused
    (naming the parameter); a literal expression of t still works."""
    (tmp_path / "part.toml").write_text('''[parameters]
amp = 0.5
[ports]
base = "external"
[bodies.rod]
mass = 1.0
com = [0.0, 0.0, -0.2]
inertia = [0.01, 0.01, 0.001]
[joints.j]
type = "revolute"
parent = "base"
child = "rod"
axis = "x"
coords = "a"
[constraints.drive]
type = "motor"
joint = "j"
position = "amp*sin(t)"
''')
    (tmp_path / "top.toml").write_text('[submodels.p]\nuse = "part.toml"\nbase = "ground"\namp = 0.3\n')
    with pytest.raises(mb.ModelError, match=r"\[constraints.drive\] position: the part's parameter\(s\) 'amp'"):
        mb.load(tmp_path / "top.toml")
    part = (tmp_path / "part.toml").read_text().replace('"amp*sin(t)"', '"0.3*sin(t)"')
    (tmp_path / "part.toml").write_text(part)
    res = mb.load(tmp_path / "top.toml").compile().simulate(1.0, [0.0], [0.3], t_eval=[0.5, 1.0])
    assert_close(res["p.a"], 0.3 * np.sin([0.5, 1.0]), atol=1e-8, name="motor position")
