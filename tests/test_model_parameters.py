"""Model-level run-time parameters (``Model.parameter``; a file's top-level ``[parameters]``).

Each check compares a run-time change with a fresh build given the new value: the two must
agree to rounding, since both evaluate the same expressions of the same numbers."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.files.library import find_library_model


def pendulum(L: float | None = None, g: float | None = None, *, linked: bool = True) -> mb.Model:
    """A double pendulum of uniform bars; with ``linked`` its length, density and gravity are
    model parameters (the bar mass a derived one), otherwise the same numbers are plain."""
    m = mb.Model("dp")
    if linked:
        L_, g_, rho = m.parameter("L", 0.5 if L is None else L, unit="m", min=0.0), \
            m.parameter("g", 9.81 if g is None else g), m.parameter("rho", 2.0)
        mass = m.parameter("mass", rho * L_)
        m.set_gravity((0.0, 0.0, -g_))
    else:
        L_, g_ = (0.5 if L is None else L), (9.81 if g is None else g)
        mass = 2.0 * L_
        m.set_gravity((0.0, 0.0, -g_))
    for name, parent in (("a", m.ground), ("b", None)):
        body = m.add(mb.Body(name, mass=mass, com=(0, 0, -L_ / 2), inertia=(mass * L_**2 / 12,) * 2 + (0.0,)))
        if parent is None:
            m.add(mb.Revolute("jb", m["a"].frame((0, 0, -L_)), body, axis="x", coords="q2"))
        else:
            m.add(mb.Revolute("ja", parent, body, axis="x", coords="q1"))
    return m


def final_state(system: mb.System, **kwargs) -> np.ndarray:
    res = system.simulate(1.0, [0.4, -0.2], rtol=1e-10, atol=1e-12, **kwargs)
    return np.concatenate([res.q[-1], res.qd[-1]])


def test_parameters_are_listed_with_their_values():
    sys = pendulum().compile()
    assert {k: sys.parameters[k] for k in ("L", "g", "rho", "mass")} == {"L": 0.5, "g": 9.81, "rho": 2.0, "mass": 1.0}
    assert sys.parameters["gravity"] == pytest.approx((0.0, 0.0, -9.81))


def test_run_time_change_matches_a_fresh_build():
    """L reaches the centres of mass, inertias, the joint location and the derived mass."""
    sys = pendulum().compile()
    fresh = pendulum(L=0.7).compile()
    np.testing.assert_allclose(final_state(sys, parameters={"L": 0.7}), final_state(fresh), rtol=0, atol=1e-12)
    np.testing.assert_allclose(final_state(sys.with_parameters({"L": 0.7})), final_state(fresh), rtol=0, atol=1e-12)
    assert sys.with_parameters({"L": 0.7}).parameters["mass"] == pytest.approx(1.4)
    # the plain model with the same numbers gives the same motion: the links add nothing
    np.testing.assert_allclose(final_state(fresh), final_state(pendulum(L=0.7, linked=False).compile()), atol=1e-12)


def test_gravity_follows_its_parameter():
    sys = pendulum().compile()
    changed = sys.with_parameters({"g": 3.0})
    assert changed.parameters["gravity"] == pytest.approx((0.0, 0.0, -3.0))
    np.testing.assert_allclose(final_state(changed), final_state(pendulum(g=3.0).compile()), atol=1e-12)


def test_a_derived_parameter_set_on_its_own_keeps_its_value():
    sys = pendulum().compile().with_parameters({"mass": 3.0})
    assert sys.with_parameters({"L": 0.6}).parameters["mass"] == 3.0   # as a modifier would


def test_bad_declarations_are_refused_with_the_name():
    m = mb.Model("m")
    m.parameter("k", 1.0, min=0.0)
    with pytest.raises(mb.ModelError, match="'k' is declared twice"):
        m.parameter("k", 2.0)
    with pytest.raises(mb.ModelError, match="identifier"):
        m.parameter("a.b", 1.0)
    with pytest.raises(mb.ModelError, match="parameter 'c'"):
        m.parameter("c", -1.0, min=0.0)
    sys = pendulum().compile()
    with pytest.raises(mb.ModelError, match="'L'"):
        sys.with_parameters({"L": -1.0})


def test_file_parameters_change_at_run_time(tmp_path):
    """The library's double pendulum: [parameters] L, the derived m and I, and gravity g."""
    text = find_library_model("double_pendulum").read_text()
    assert "\nL = 0.55" in text
    changed = tmp_path / "longer.toml"
    changed.write_text(text.replace("\nL = 0.55", "\nL = 0.65").replace("\ng = 9.81", "\ng = 9.0"))
    sys = mb.load("double_pendulum").compile()
    fresh = mb.load(changed).compile()
    np.testing.assert_allclose(final_state(sys, parameters={"L": 0.65, "g": 9.0}), final_state(fresh), atol=1e-12)
    assert sys.with_parameters({"L": 0.65}).parameters["bar1.com"][0] == pytest.approx(0.325)


def test_saved_file_keeps_the_links(tmp_path):
    path = tmp_path / "saved.toml"
    mb.load("double_pendulum").save(path)
    again = mb.load(path).compile()
    fresh = mb.load("double_pendulum").compile()
    np.testing.assert_allclose(final_state(again, parameters={"L": 0.6, "g": 8.0}),
                               final_state(fresh, parameters={"L": 0.6, "g": 8.0}), atol=1e-12)


def test_python_and_file_models_name_the_same_parameters(tmp_path):
    path = tmp_path / "dp.toml"
    pendulum().save(path)
    assert sorted(mb.load(path).compile().parameters) == sorted(pendulum().compile().parameters)


def test_a_parameter_compiled_into_an_expression_of_t_is_refused_at_change():
    """The motor's position amplitude*sin(2 pi frequency t) is compiled with its numbers:
    a run-time change would not reach it, so it is refused, naming where it is used."""
    sys = mb.load("double_pendulum_motor").compile()
    with pytest.raises(mb.ModelError, match=r"'amplitude'.*\[constraints.motor\] position"):
        sys.with_parameters({"amplitude": 0.3})
    assert sys.with_parameters({"L": 0.6}).parameters["L"] == 0.6   # the others still change


def test_a_joint_rotation_follows_or_refuses_its_parameter(tmp_path):
    """A file's joint frame turned by a parameter ``a``: changing ``a`` at run time must either
    turn the frame as a fresh build does or be refused (the code holds the rotation as
    numbers): it is refused, naming where the parameter is used."""
    path = tmp_path / "turned.toml"
    path.write_text('''name = "turned"
[parameters]
a = 0.3
[bodies.b]
mass = 1.0
com = [0.0, 0.0, -1.0]
inertia = [0.01, 0.01, 0.01]
[joints.j]
type = "revolute"
parent = "ground"
child = "b"
axis = "x"
parent_rotation = [["cos(a)", 0.0, "sin(a)"], [0.0, 1.0, 0.0], ["-sin(a)", 0.0, "cos(a)"]]
''')
    system = mb.load(path).compile()
    with pytest.raises(mb.ModelError, match=r"parameter 'a'.*\[joints.j\] parent_rotation"):
        system.with_parameters({"a": 0.6})
    assert system.with_parameters({"a": 0.3}).body_state("b", [0.0]).rotation[0, 2] == pytest.approx(np.sin(0.3))


def test_a_sub_model_rotation_built_from_its_parameter_is_refused_at_change():
    """In Python, a part whose joint frame is turned by its own parameter: the rebuilt joint's
    rotation moves, which the compiled code cannot follow, so the change is refused."""
    class Turned(mb.Submodel):
        angle = mb.Parameter(0.3)

        def build(self):
            body = self.add(mb.Body("b", mass=1.0, com=(0, 0, -1.0), inertia=(0.01, 0.01, 0.01)))
            c, s = np.cos(self.angle), np.sin(self.angle)
            turn = ((c, 0.0, s), (0.0, 1.0, 0.0), (-s, 0.0, c))
            self.add(mb.Revolute("j", mb.Frame("ground", rotation=turn), body, axis="x"))
    m = mb.Model("m")
    m.add(Turned("part"))
    system = m.compile()
    with pytest.raises(mb.ModelError, match=r"part.j.*rotation.*as a constant"):
        system.with_parameters({"part.angle": 0.6})
