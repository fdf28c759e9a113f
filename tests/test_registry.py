"""The component kind registry: a new component type is one class; the file reader and
writer, ``mbcomp info`` and plots find it through its declarations."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.face.cli import describe_components
from mbcomp.spec.components.base import KINDS, ForceElement, component_class, kinds_in
from mbcomp.files.toml_model import dumps, load
from mbcomp.core.params import ParameterSpec, nonnegative


@pytest.fixture
def thruster_class():
    """A body-fixed thrust along the body's z axis: declared once, nothing else changes."""

    class Thruster(ForceElement):
        """A force ``thrust`` (N, >= 0) along the body z axis at ``point`` (m, body frame)."""

        kind = "thruster"
        section = "forces"
        params = (ParameterSpec("point", (3,), "m", default=(0.0, 0.0, 0.0)),
                  ParameterSpec("thrust", (), "N", nonnegative))
        refs = {"body": "body"}
        file_keys = ("body", "point", "thrust")
        file_required = ("body", "thrust")

        def __init__(self, name, body, thrust, point=(0.0, 0.0, 0.0)):
            super().__init__(name)
            self.body = body
            self.point = point
            self.thrust = thrust

        def references(self):
            return {"body": self.body}

        def loads(self, kin):
            R = kin.rotation(self.body)
            f = kin.param(self, "thrust")
            return [("point", self.body, kin.position(self.body, kin.param(self, "point")),
                     [R[i][2] * f for i in range(3)])]

    yield Thruster
    KINDS.pop("thruster", None)


FILE = """
name = "rocket"
gravity = [0.0, 0.0, 0.0]
[bodies.b]
mass = 2.0
com = [0.0, 0.0, -1.0]
inertia = [0.1, 0.1, 0.05]
[joints.j]
type = "revolute"
parent = "ground"
child = "b"
axis = "x"
[forces.push]
type = "thruster"
body = "b"
point = [0.0, 0.0, -1.0]
thrust = 3.0
"""


def test_registry_lists_the_built_in_kinds():
    assert component_class("revolute") is mb.Revolute and component_class("contact") is mb.Contact
    assert list(kinds_in("constraints")) == ["slider", "motor", "rolling_disc", "rolling_ball", "no_slip", "joint_limit"]
    assert component_class(["revolute"]) is None  # unhashable keys are just unknown


def test_a_new_kind_is_read_written_and_listed(thruster_class, tmp_path):
    path = tmp_path / "rocket.toml"
    path.write_text(FILE, encoding="utf-8")
    model = load(path)
    push = model["push"]
    assert isinstance(push, thruster_class) and push.thrust == 3.0 and push.point == (0.0, 0.0, -1.0)
    # Thrust along body z through the hinge: no moment about the hinge axis x.
    sys = model.compile(backend="python")
    q = 0.4
    assert sys.accelerations([q], [0.0])[0] == pytest.approx(0.0, abs=1e-12)
    # Moved 0.2 m along body y: r x F = (0, 0.2, -1) x (0, 0, 3) = (0.6, 0, 0) in the body frame.
    moved = sys.with_parameters({"push.point": (0.0, 0.2, -1.0)})
    inertia = 2.0 * 1.0 + 0.1
    assert moved.accelerations([q], [0.0])[0] == pytest.approx(3.0 * 0.2 / inertia, rel=1e-12)
    # Saved back and read again: the same model.
    again_path = tmp_path / "again.toml"
    again_path.write_text(dumps(model), encoding="utf-8")
    again = load(again_path)
    assert vars(again["push"]) == vars(push)
    assert "push (thruster)" in "\n".join(describe_components(model))


def test_a_new_kind_is_validated_in_files(thruster_class, tmp_path):
    path = tmp_path / "rocket.toml"
    path.write_text(FILE.replace("thrust = 3.0", "thrust = -3.0\ncolour = 1"), encoding="utf-8")
    with pytest.raises(mb.ModelError) as info:
        load(path)
    problems = "\n".join(info.value.problems)
    assert "[forces.push] thrust: must not be negative, got -3" in problems
    assert "[forces.push] colour: unknown key; allowed: type, body, point, thrust" in problems


def test_unknown_type_lists_the_registered_ones(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(FILE.replace('"thruster"', '["thruster"]'), encoding="utf-8")
    with pytest.raises(mb.ModelError, match=r"\[forces.push\] type: must be a string"):
        load(path)


def test_component_without_a_file_form_cannot_be_saved():
    class Anonymous(ForceElement):
        def loads(self, kin):
            return []

    m = mb.Model("m")
    m.add(mb.Body("b"), mb.Revolute("j", "ground", "b"), Anonymous("x"))
    with pytest.raises(mb.ModelError, match="Anonymous 'x': Anonymous has no file representation"):
        dumps(m)
    assert np.isfinite(m.compile(backend="python").mass_matrix([0.0])).all()
