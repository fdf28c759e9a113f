"""save -> load keeps a model's sub-model parameters: the instances' ``[parameters]`` are
written, and the component values built from them are written as expressions of them, so
the reloaded model has the same ``System.parameters`` and follows a run-time change of an
instance parameter exactly as the original does (files.toml_model.save, docs/files.md)."""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.files.toml_model import dumps, library_models, load

T_END = 0.4   # pid_arm rests until its first setpoint step (0.2 s, 0.21 s after the change)
T_EVAL = np.linspace(0.0, T_END, 5)
RTOL, ATOL = 1e-10, 1e-12
SAME = 1e-12
LIBRARY = ["double_pendulum_parts", "four_bar_parts", "servo_arm", "walker_legs", "pid_arm", "stewart_platform"]


class Link(mb.Submodel):
    """The double pendulum's link of docs/composition.md."""
    length = mb.Parameter(0.5, unit="m", min=0.0)
    mass = mb.Parameter(1.0, unit="kg", min=0.0)
    axis = mb.Option("x", choices=("x", "y", "z"))

    def build(self, parent: mb.Frame):
        rod = self.add(mb.Body("rod", mass=self.mass, com=(0, 0, -self.length / 2),
                               inertia=(self.mass * self.length**2 / 12,) * 2 + (0.0,)))
        self.add(mb.Revolute("joint", parent, rod, axis=self.axis, coords="angle"))
        self.tip = rod.frame((0, 0, -self.length))


def python_pendulum() -> mb.Model:
    m = mb.Model("double_pendulum")
    upper = m.add(Link("upper", parent=m.ground.frame(), length=0.3))
    m.add(Link("lower", parent=upper.tip, length=0.2, mass=0.5))
    m.initial = {"q": {"upper.angle": 0.5, "lower.angle": -0.3}, "qd": {}}
    return m


class Arm(mb.Submodel):
    """A part whose inner links' parameters are expressions of its own (passed down)."""
    reach = mb.Parameter(0.6, unit="m", min=0.0)

    def build(self, parent: mb.Frame):
        first = self.add(Link("first", parent=parent, length=self.reach * 0.6))
        self.add(Link("second", parent=first.tip, length=self.reach - first.length, mass=0.4))


def nested_arm() -> mb.Model:
    m = mb.Model("arm")
    m.add(Arm("arm", parent=m.ground.frame()))
    m.initial = {"q": {"arm.first.angle": 0.4, "arm.second.angle": 0.2}, "qd": {}}
    return m


MODELS = {**{name: lambda name=name: load(library_models()[name]) for name in LIBRARY},
          "python_pendulum": python_pendulum, "nested_arm": nested_arm}


@lru_cache(maxsize=None)
def pair(name: str, tmp: str) -> tuple:
    """(original system, reloaded system, original model) of ``name``."""
    model = MODELS[name]()
    path = f"{tmp}/{name}.toml"
    model.save(path)
    return model.compile(), load(path).compile(), model


@pytest.fixture(scope="module")
def tmp(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("save_params"))


def state(model, system) -> tuple[np.ndarray, np.ndarray]:
    initial = getattr(model, "initial", None) or {"q": {}, "qd": {}}
    neutral = system.topology.state_map.neutral()
    q = np.array([initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
    qd = np.array([initial["qd"].get(c, 0.0) for c in system.speeds])
    return q, qd


def instance_parameters(model) -> list[str]:
    return list(model.registry.parameters)


@pytest.mark.parametrize("name", list(MODELS))
def test_a_saved_model_has_the_same_parameters(name, tmp):
    original, again, model = pair(name, tmp)
    assert instance_parameters(model), name   # the test is about sub-model parameters
    assert list(again.parameters) == list(original.parameters)
    for key, value in original.parameters.items():
        np.testing.assert_array_equal(np.asarray(again.parameters[key], float), np.asarray(value, float),
                                      err_msg=f"{name}: {key}")
    assert again.coords == original.coords and again.speeds == original.speeds


@pytest.mark.parametrize("name", list(MODELS))
def test_a_run_time_change_of_an_instance_parameter_moves_both_alike(name, tmp):
    original, again, model = pair(name, tmp)
    q0, qd0 = state(model, original)
    changes = {key: original.parameters[key] * 1.05 for key in instance_parameters(model)
               if original.parameters[key] != 0.0}
    common = dict(t_eval=T_EVAL, rtol=RTOL, atol=ATOL)
    before = original.simulate(T_END, q0, qd0, **common)
    first = original.simulate(T_END, q0, qd0, parameters=changes, **common)
    second = again.simulate(T_END, q0, qd0, parameters=changes, **common)
    # the change matters (else the comparison below could not fail) ...
    moved = max(np.abs(first.q - before.q).max(), np.abs(first.qd - before.qd).max())
    assert moved > 1e-6, f"{name}: the change moved nothing ({moved})"
    # ... and the reloaded model follows it exactly as the original does
    np.testing.assert_allclose(second.q, first.q, rtol=SAME, atol=SAME, err_msg=name)
    np.testing.assert_allclose(second.qd, first.qd, rtol=SAME, atol=SAME, err_msg=name)
    changed_original = original.with_parameters(changes).parameters
    changed_again = again.with_parameters(changes).parameters
    for key, value in changed_original.items():
        np.testing.assert_allclose(np.asarray(changed_again[key], float), np.asarray(value, float), rtol=1e-15,
                                   atol=0, err_msg=f"{name}: {key}")


def test_derived_values_follow_the_parameters_they_came_from(tmp):
    """The analytic values of the pendulum's links after ``upper.length`` = 0.4 on the reloaded
    model: the lower joint hangs from the new tip, the upper rod's inertia is m L**2 / 12."""
    _, again, _ = pair("python_pendulum", tmp)
    values = again.with_parameters({"upper.length": 0.4, "lower.mass": 0.8}).parameters
    assert values["lower.joint.parent_point"] == (0.0, 0.0, -0.4)
    assert values["upper.rod.com"] == (0.0, 0.0, -0.2)
    assert math.isclose(values["upper.rod.inertia"][0], 1.0 * 0.4**2 / 12, rel_tol=1e-15)
    assert math.isclose(values["lower.rod.inertia"][0], 0.8 * 0.2**2 / 12, rel_tol=1e-15)


def test_an_inner_parameter_bound_to_an_outer_one_stays_bound(tmp):
    """``Arm`` passes ``reach * 0.6`` down: the file writes it as an expression of ``reach``,
    and a change of ``arm.reach`` moves the inner lengths (0.7 * 0.6 and 0.7 - 0.42)."""
    original, again, model = pair("nested_arm", tmp)
    text = dumps(model)
    assert 'length = { value = "(reach * 0.6)"' in text
    for system in (original, again):
        values = system.with_parameters({"arm.reach": 0.7}).parameters
        assert math.isclose(values["arm.first.length"], 0.7 * 0.6, rel_tol=1e-15)
        assert math.isclose(values["arm.second.length"], 0.7 - 0.7 * 0.6, rel_tol=1e-15)


def test_a_value_the_language_cannot_write_is_a_number_with_a_note(tmp_path):
    """``tan`` is not in the file's expression language: the value is written as its number,
    with a comment saying it will not follow a change; the parameter itself is kept."""

    class Tilted(mb.Submodel):
        angle = mb.Parameter(0.3)

        def build(self, parent: mb.Frame):
            rod = self.add(mb.Body("rod", mass=1.0, com=(0, 0, -self.angle.tan()), inertia=(0.01, 0.01, 0.0)))
            self.add(mb.Revolute("joint", parent, rod, axis="x"))

    m = mb.Model("tilted")
    m.add(Tilted("t", parent=m.ground.frame()))
    path = tmp_path / "tilted.toml"
    m.save(path)
    text = path.read_text()
    assert "will not follow a parameter change" in text and "tan" in text
    again = mb.load(path).compile()
    assert again.parameters["t.angle"] == 0.3
    assert again.parameters["t.rod.com"] == (0.0, 0.0, -math.tan(0.3))


def test_a_file_may_name_an_instance_parameter_by_its_path(tmp_path):
    """A top-level joint of a model file uses ``"-upper.length"``: it follows the instance's
    parameter at run time; a misspelt path is an error naming the known parameters."""
    (tmp_path / "link.toml").write_text(
        'name = "link"\n[parameters]\nlength = 0.5\n[ports]\nparent = "external"\n'
        '[bodies.rod]\nmass = 1.0\ncom = [0.0, 0.0, "-length/2"]\ninertia = [0.01, 0.01, 0.0]\n'
        '[joints.joint]\ntype = "revolute"\nparent = "parent"\nchild = "rod"\naxis = "x"\n')
    model = ('[submodels.upper]\nuse = "link.toml"\nparent = "ground"\nlength = 0.3\n'
             '[bodies.weight]\nmass = 0.5\ninertia = [0.001, 0.001, 0.001]\n'
             '[joints.hang]\ntype = "revolute"\nparent = "upper.rod"\nchild = "weight"\naxis = "x"\n'
             'parent_point = [0.0, 0.0, "-upper.{}"]\n')
    (tmp_path / "m.toml").write_text(model.format("length"))
    system = mb.load(tmp_path / "m.toml").compile()
    assert system.parameters["hang.parent_point"] == (0.0, 0.0, -0.3)
    assert system.with_parameters({"upper.length": 0.45}).parameters["hang.parent_point"] == (0.0, 0.0, -0.45)
    (tmp_path / "m.toml").write_text(model.format("lenght"))
    with pytest.raises(mb.ModelError, match=r"parent_point.*unknown name 'upper\.lenght' \(parameters: upper\.length\)"):
        mb.load(tmp_path / "m.toml")
