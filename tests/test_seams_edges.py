"""Edges where features meet: values too large for the equations are refused by name (Python,
run-time parameters, files, sub-model expressions), and body shapes survive save and load."""
import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.params import MAX_MAGNITUDE

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


# -- body shapes through save and load ---------------------------------------------------------
def shaped_model():
    m = mb.Model("shapes", gravity=(0, 0, -9.81))
    turned = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    link = m.add(mb.Body("link", mass=1.0, com=(0.2, 0, 0), inertia=(1e-3, 1e-2, 1e-2),
                         shape=[mb.Box((0.4, 0.1, 0.05), origin=(0.2, 0, 0), rotation=turned, color="red"),
                                mb.Cylinder(0.03, 0.4, axis=(1.0, 1.0, 0.0), origin=(0.2, 0, 0))]))
    ball = m.add(mb.Body("ball", mass=0.5, inertia=(5e-4,) * 3, shape=mb.Sphere(0.05, origin=(0, 0, 0.01),
                                                                             color=(0, 0, 1))))
    part = m.add(mb.Body("part", mass=0.5, inertia=(5e-4,) * 3,
                         shape=mb.Mesh("meshes/part.stl", scale=(0.001, 0.002, 0.001), color="#00ff00")))
    plain = m.add(mb.Body("plain", mass=0.1, inertia=(1e-4,) * 3))
    m.ground.shape = (mb.Box((2.0, 2.0, 0.01), origin=(0, 0, -0.5)),)
    m.add(mb.Revolute("hinge", m.ground, link, axis="y"))
    m.add(mb.Revolute("tip", link, ball, axis="y", parent_point=(0.4, 0, 0)))
    m.add(mb.Ball("socket", ball, part))
    m.add(mb.Prismatic("slide", part, plain, axis="x"))
    return m


def test_shapes_survive_save_and_load(tmp_path):
    m = shaped_model()
    path = tmp_path / "shapes.toml"
    m.save(path)
    again = mb.load(path)
    for name in ("link", "ball", "part", "plain"):
        assert again[name].shape == m[name].shape, name      # every field: sizes, placement, colour
    assert again.ground.shape == m.ground.shape
    assert [type(s).__name__ for s in again["link"].shape] == ["Box", "Cylinder"]
    assert again["link"].shape[1].axis == pytest.approx((2 ** -0.5, 2 ** -0.5, 0.0))
    assert again["part"].shape[0].scale == (0.001, 0.002, 0.001)
    assert again["plain"].shape == ()
    # Saving the loaded model writes the same text: nothing is lost or added on the way.
    assert mb.io.dumps(again) == path.read_text()


def test_shapes_in_a_submodel_survive_save_and_load(tmp_path):
    class Arm(mb.Submodel):
        length = mb.Parameter(0.5, unit="m", min=0.0)

        def build(self, parent: mb.Frame):
            rod = self.add(mb.Body("rod", mass=1.0, com=(0, 0, -self.length / 2), inertia=(0.02, 0.02, 0.0),
                                   shape=mb.Cylinder(0.02, 0.5, axis="z", origin=(0, 0, -0.25), color="gray")))
            self.add(mb.Revolute("joint", parent, rod, axis="x"))

    m = mb.Model("arms")
    m.add(Arm("upper", parent=m.ground.frame()))
    m.save(tmp_path / "arms.toml")
    again = mb.load(tmp_path / "arms.toml")
    assert again["upper.rod"].shape == m["upper.rod"].shape and len(m["upper.rod"].shape) == 1


@pytest.mark.parametrize("shape, where, expected", [
    ('{ type = "cone", radius = 1 }', "shape", "type must be one of box, cylinder, sphere, capsule, plane, mesh"),
    ('[{ type = "box", size = [1, 1, -1] }]', "shape[0]", "size must be positive"),
    ('{ type = "sphere", radius = 0.1, size = [1, 1, 1] }', "shape", "unknown key 'size' for a sphere"),
    ('{ type = "cylinder", radius = 0.1 }', "shape", "a cylinder needs length"),
    ('{ type = "box", size = ["a*b", 1, 1] }', "shape", "size must be numbers"),
    ('[{ type = "sphere", radius = 0.1, color = "no-such-colour" }]', "shape[0]", "color must be"),
])
def test_bad_shape_tables_are_located(tmp_path, shape, where, expected):
    path = tmp_path / "bad.toml"
    path.write_text(f'name = "m"\n[bodies.b]\nmass = 1.0\nshape = {shape}\n')
    with pytest.raises(mb.ModelError) as info:
        mb.load(path)
    assert f"[bodies.b] {where}: {expected}" in str(info.value), info.value


def test_the_page_of_a_loaded_model_draws_the_same_shapes(tmp_path):
    from mbcomp.face.viewer import build_scene
    m = shaped_model()
    for body in ("part",):              # no mesh file here: leave the mesh out of the drawing
        m[body].shape = (mb.Sphere(0.02),)
    m.save(tmp_path / "shapes.toml")
    q0 = [0.1, 0.2, 1.0, 0.0, 0.0, 0.0, 0.05]
    pages = [build_scene(model.compile().simulate(0.05, q0)) for model in (m, mb.load(tmp_path / "shapes.toml"))]
    assert pages[0]["bodies"] == pages[1]["bodies"] and pages[0]["ground"] == pages[1]["ground"]
    assert [s["type"] for s in pages[1]["bodies"][0]["shapes"]] == ["box", "cylinder"]
