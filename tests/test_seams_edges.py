"""Edges where features meet: values too large for the equations are refused by name (Python,
run-time parameters, files, sub-model expressions), and body shapes survive save and load."""
import numpy as np
import pytest

import mbcomp as mb
from mbcomp.params import MAX_MAGNITUDE

TOO_LARGE = "is too large to handle"


def pendulum(**body):
    m = mb.Model("m", gravity=(0, 0, -9.81))
    b = m.add(mb.Body("b", **{"mass": 1.0, "inertia": (1.0, 1.0, 1.0), **body}))
    m.add(mb.Free("j", m.ground, b))
    return m


@pytest.mark.parametrize("field, value", [("inertia", (1e308,) * 3), ("com", (1e300, 0.0, 0.0)),
                                          ("com", (0.0, 1e160, 0.0)), ("mass", 1e200),
                                          ("inertia", (2e100, 2e100, 2e100))])
def test_python_refuses_overflowing_body_values_by_name(field, value):
    with pytest.raises(mb.ModelError) as info:
        pendulum(**{field: value})
    assert str(info.value).startswith(f"Body 'b': {field} {TOO_LARGE}"), info.value


def test_the_limit_is_where_products_still_fit():
    """At the limit itself the model compiles and its mass matrix is finite (m c^2 = 1e200):
    the refusal is of values that would overflow, not of large ones."""
    system = pendulum(com=(MAX_MAGNITUDE, 0.0, 0.0)).compile(backend="python")
    M = system.mass_matrix(system.topology.state_map.neutral())
    assert np.all(np.isfinite(M)) and M[4, 4] == pytest.approx(1.0 + MAX_MAGNITUDE ** 2)


def test_non_finite_values_are_refused_by_name():
    with pytest.raises(mb.ModelError, match="Body 'b': com has a non-finite entry"):
        pendulum(com=(np.inf, 0.0, 0.0))
    with pytest.raises(mb.ModelError, match="Body 'b': mass must be finite"):
        pendulum(mass=np.nan)


def test_run_time_parameters_are_refused_the_same_way():
    system = pendulum().compile(backend="python")
    with pytest.raises(mb.ModelError, match=f"Body 'b': com {TOO_LARGE}"):
        system.with_parameters({"b.com": (1e300, 0.0, 0.0)})
    with pytest.raises(mb.ModelError, match=f"Body 'b': inertia {TOO_LARGE}"):
        system.simulate(0.1, system.topology.state_map.neutral(), parameters={"b.inertia": (1e308,) * 3})


FILE = """name = "m"
gravity = {gravity}
[parameters]
big = 1e300
[bodies.b]
mass = 1.0
com = {com}
inertia = {inertia}
[joints.j]
type = "free"
parent = "ground"
child = "b"
"""


@pytest.mark.parametrize("com, inertia, gravity, where", [
    ("[1e300, 0, 0]", "[1, 1, 1]", "[0, 0, -9.81]", "[bodies.b] com"),
    ('["big", 0, 0]', "[1, 1, 1]", "[0, 0, -9.81]", "[bodies.b] com"),
    ("[0, 0, 0]", "[1e308, 1e308, 1e308]", "[0, 0, -9.81]", "[bodies.b] inertia"),
    ("[0, 0, 0]", "[1, 1, 1]", "[0, 0, -1e300]", "gravity"),
])
def test_files_name_the_body_and_the_key(tmp_path, com, inertia, gravity, where):
    path = tmp_path / "m.toml"
    path.write_text(FILE.format(com=com, inertia=inertia, gravity=gravity))
    with pytest.raises(mb.ModelError) as info:
        mb.load(path)
    message = str(info.value)
    assert f"{path} {where}: {TOO_LARGE}" in message, message
    assert "constraints cannot all be met" not in message


def test_a_submodel_expression_that_overflows_names_the_expression():
    class Rod(mb.Submodel):
        length = mb.Parameter(0.5, unit="m", min=0.0)

        def build(self, parent: mb.Frame):
            rod = self.add(mb.Body("rod", mass=1.0, com=(0, 0, -self.length / 2),
                                   inertia=(self.length ** 2 / 12,) * 2 + (0.0,)))
            self.add(mb.Revolute("joint", parent, rod, axis="x"))

    m = mb.Model("m")
    with pytest.raises(mb.ModelError, match=r"expression upper.length \*\* 2: overflows the float range"):
        m.add(Rod("upper", parent=m.ground.frame(), length=1e300))
    m = mb.Model("m")
    with pytest.raises(mb.ModelError, match=f"Body 'rod': inertia {TOO_LARGE}"):
        m.add(Rod("upper", parent=m.ground.frame(), length=1e60))
