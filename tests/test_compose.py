"""Sub-models: parameters, options, ports, nested names, modifiers, run-time changes."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.spec.components.expr import Expr
from tests.conftest import G, assert_close


class Link(mb.Submodel):
    """A uniform rod on a revolute joint: hangs from `parent`, exposes its tip."""
    length = mb.Parameter(0.5, unit="m", min=0.0)
    mass = mb.Parameter(1.0, unit="kg", min=0.0)
    axis = mb.Option("x", choices=("x", "y", "z"))

    def build(self, parent: mb.Frame):
        rod = self.add(mb.Body("rod", mass=self.mass, com=(0, 0, -self.length / 2),
                               inertia=(self.mass * self.length**2 / 12,) * 2 + (1e-4,)))
        self.add(mb.Revolute("joint", parent, rod, axis=self.axis, coords="angle"))
        self.tip = rod.frame((0, 0, -self.length))


class Leg(mb.Submodel):
    """Two links; the shank is half as heavy as the thigh."""
    thigh_length = mb.Parameter(0.4, unit="m", min=0.05, max=2.0)
    mass = mb.Parameter(2.0, unit="kg", min=0.0)
    knee = mb.Option(mb.Revolute)

    def build(self, hip: mb.Frame):
        thigh = self.add(Link("thigh", parent=hip, length=self.thigh_length, mass=self.mass))
        shank = self.add(Link("shank", parent=thigh.tip, length=0.9 * self.thigh_length, mass=self.mass / 2,
                              axis="y"))
        self.foot = shank.tip


def double_pendulum(l1=0.3, l2=0.2, m2=0.5):
    m = mb.Model("double_pendulum")
    upper = m.add(Link("upper", parent=m.ground.frame(), length=l1))
    m.add(Link("lower", parent=upper.tip, length=l2, mass=m2))
    return m


def flat_double_pendulum(l1=0.3, l2=0.2, m2=0.5):
    m = mb.Model("flat", gravity=(0, 0, -G))
    a = m.add(mb.Body("a", mass=1.0, com=(0, 0, -l1 / 2), inertia=(l1**2 / 12, l1**2 / 12, 1e-4)))
    b = m.add(mb.Body("b", mass=m2, com=(0, 0, -l2 / 2), inertia=(m2 * l2**2 / 12, m2 * l2**2 / 12, 1e-4)))
    m.add(mb.Revolute("ja", m.ground, a, axis="x"))
    m.add(mb.Revolute("jb", a, b, axis="x", parent_point=(0, 0, -l1)))
    return m


def test_nested_names_coordinates_and_parameters():
    m = double_pendulum()
    s = m.compile()
    assert s.coords == ("upper.angle", "lower.angle")
    assert isinstance(m["lower.rod"], mb.Body) and m["lower.rod"].name == "rod"
    assert isinstance(m["lower"], Link) and m["lower"].path == "lower"
    assert s.parameters["upper.length"] == 0.3 and s.parameters["lower.mass"] == 0.5
    assert s.parameters["lower.joint.parent_point"] == (0.0, 0.0, -0.3)
    assert_close(s.parameters["lower.rod.inertia"], [0.5 * 0.04 / 12] * 2 + [1e-4], name="derived inertia")


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_submodel_built_equals_flat_built(formulation):
    s, flat = double_pendulum().compile(formulation), flat_double_pendulum().compile(formulation)
    rng = np.random.default_rng(1)
    for _ in range(3):
        q, qd = rng.normal(size=2), rng.normal(size=2)
        assert_close(s.mass_matrix(q), flat.mass_matrix(q), name="mass matrix")
        assert_close(s.accelerations(q, qd), flat.accelerations(q, qd), name="accelerations")
        assert_close(s.energy(q, qd).total, flat.energy(q, qd).total, name="energy")
    r1, r2 = s.simulate(1.0, [0.3, -0.2]), flat.simulate(1.0, [0.3, -0.2])
    assert_close(r1.q[-1], r2.q[-1], rtol=1e-9, atol=1e-11, name="q(1)")


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_run_time_change_equals_a_fresh_build(formulation):
    s = double_pendulum().compile(formulation)
    fresh = double_pendulum(l1=0.45, m2=0.8).compile(formulation)
    changed = s.with_parameters({"upper.length": 0.45, "lower.mass": 0.8})
    assert changed.parameters == fresh.parameters
    assert changed._compiled is s._compiled   # the same generated code
    q, qd = [0.4, 0.1], [0.2, -0.3]
    assert_close(changed.accelerations(q, qd), fresh.accelerations(q, qd), name="accelerations")
    r1 = s.simulate(0.5, [0.2, 0.1], parameters={"upper.length": 0.45, "lower.mass": 0.8})
    r2 = fresh.simulate(0.5, [0.2, 0.1])
    np.testing.assert_array_equal(r1.q, r2.q)
    # and against the flat model with the same numbers
    flat = flat_double_pendulum(l1=0.45, m2=0.8).compile(formulation)
    assert_close(changed.accelerations(q, qd), flat.accelerations(q, qd), name="flat accelerations")


def test_nested_instances_modifiers_and_bindings():
    m = mb.Model("legs")
    hip = m.ground.frame((0, 0.1, 0))
    left = m.add(Leg("left", hip=hip, thigh={"length": 0.5, "mass": 3.0}))
    right = m.add(Leg("right", hip=m.ground.frame((0, -0.1, 0)), thigh_length=0.3))
    s = m.compile()
    assert s.coords == ("left.thigh.angle", "left.shank.angle", "right.thigh.angle", "right.shank.angle")
    # outer modifiers win over the value build passes
    assert s.parameters["left.thigh.length"] == 0.5 and s.parameters["left.thigh.mass"] == 3.0
    assert s.parameters["left.shank.length"] == pytest.approx(0.36)   # still bound to left.thigh_length
    assert s.parameters["right.thigh.length"] == 0.3
    assert s.parameters["right.shank.joint.parent_point"] == pytest.approx((0, 0, -0.3))
    assert isinstance(m["left.thigh.rod"], mb.Body)
    assert left.foot.body is m["left.shank.rod"] and right["shank"].path == "right.shank"
    # a change of the outer parameter reaches the bound inner ones (and their components)
    changed = s.with_parameters({"right.thigh_length": 0.5})
    m2 = mb.Model("legs")
    m2.add(Leg("left", hip=m2.ground.frame((0, 0.1, 0)), thigh={"length": 0.5, "mass": 3.0}))
    m2.add(Leg("right", hip=m2.ground.frame((0, -0.1, 0)), thigh_length=0.5))
    assert changed.parameters == m2.compile().parameters
    assert changed.parameters["right.shank.length"] == pytest.approx(0.45)


def test_option_holding_a_component_class():
    m = mb.Model("m")
    m.add(Leg("leg", hip=m.ground.frame(), knee=mb.Prismatic))
    assert m["leg"].knee is mb.Prismatic
    with pytest.raises(mb.ModelError, match="option axis.*one of"):
        Link("l", parent=m.ground.frame(), axis="w")


def test_tree_lists_instances_with_parameters():
    m = mb.Model("legs")
    m.add(mb.Body("torso", mass=5.0))
    m.add(Leg("left", hip=m.ground.frame(), thigh_length=0.45))
    tree = m.tree()
    assert tree.components == ["torso"]
    left = tree.children[0]
    assert (left.name, left.kind, left.parameters["thigh_length"]) == ("left", "Leg", 0.45)
    assert [c.name for c in left.children] == ["thigh", "shank"]
    assert left.children[1].parameters["length"] == pytest.approx(0.9 * 0.45)
    text = str(tree)
    assert "left (Leg)  mass=2, thigh_length=0.45" in text and "components: rod, joint" in text


def test_unknown_keyword_lists_the_valid_ones():
    with pytest.raises(mb.ModelError, match=r"unknown keyword 'lenght'.*\['length', 'mass'\]"):
        Link("l", lenght=0.3)


def test_out_of_bounds_names_the_full_path():
    m = mb.Model("m")
    with pytest.raises(mb.ModelError, match=r"left.thigh_length.*\[0.05, 2.0\]"):
        m.add(Leg("left", hip=m.ground.frame(), thigh_length=3.0))
    m = mb.Model("m")
    with pytest.raises(mb.ModelError, match=r"left.thigh.length.*\[0.0, None\]"):
        m.add(Leg("left", hip=m.ground.frame(), thigh={"length": -1.0}))
    s = double_pendulum().compile(backend="python")
    with pytest.raises(mb.ModelError, match="'upper.length'"):
        s.with_parameters({"upper.length": -0.1})


def test_unknown_inner_instance_and_missing_port():
    m = mb.Model("m")
    with pytest.raises(mb.ModelError, match="'calf' is not a parameter, option, port or inner instance"):
        m.add(Leg("left", hip=m.ground.frame(), calf={"length": 0.3}))
    with pytest.raises(mb.ModelError, match="port 'parent' is not bound"):
        m.add(Link("free"))


def test_name_clashes_and_dotted_component_names_are_refused():
    m = double_pendulum()
    with pytest.raises(mb.ModelError, match="already used"):
        m.add(mb.Body("upper"))
    with pytest.raises(mb.ModelError, match="may not contain"):
        mb.Body("upper.rod")


class Conditional(mb.Submodel):
    length = mb.Parameter(0.5)

    def build(self, parent):
        if self.length > 0.3:
            pass


class PointOrRod(mb.Submodel):
    spin = mb.Parameter(1.0, min=0.0)

    def build(self, parent):
        rod = self.add(mb.Body("rod", mass=1.0, com=(0, 0, -0.2), inertia=(0.01 * self.spin,) * 3))
        self.add(mb.Revolute("j", parent, rod, axis="x"))


def test_parameters_cannot_decide_structure():
    m = mb.Model("m")
    with pytest.raises(mb.ModelError, match="cannot be compared.*Option"):
        m.add(Conditional("c", parent=m.ground.frame()))
    m = mb.Model("m")
    m.add(PointOrRod("p", parent=m.ground.frame()))
    s = m.compile(backend="python")
    with pytest.raises(mb.ModelError, match="changes the structure"):
        s.with_parameters({"p.spin": 0.0})   # zero inertia makes a point mass: new code


def test_expressions_keep_their_link_through_arithmetic_and_numpy():
    L = Expr.parameter("a.length", 0.5)
    e = np.sqrt(2 * L**2 + 1) / (1 - L)
    assert float(e) == pytest.approx(np.sqrt(1.5) / 0.5)
    assert e.evaluate({"a.length": 0.2}) == pytest.approx(np.sqrt(1.08) / 0.8)
    assert e.parameters() == {"a.length"}
    assert pickle.loads(pickle.dumps(e)).evaluate({"a.length": 0.2}) == e.evaluate({"a.length": 0.2})


def test_pickled_system_keeps_sub_model_parameters():
    s = double_pendulum().compile().with_parameters({"upper.length": 0.4})
    back = pickle.loads(pickle.dumps(s))
    assert back.parameters == s.parameters
    assert back.with_parameters({"lower.length": 0.3}).parameters == \
        double_pendulum(l1=0.4, l2=0.3).compile().parameters


def test_sweep_over_a_sub_model_parameter():
    s = double_pendulum().compile()
    results = mb.sweep(s, [{"parameters": {"upper.length": L}} for L in (0.2, 0.3, 0.5)], q0=[0.2, 0.0],
                       t_end=0.3, threads=1)
    for L, res in zip((0.2, 0.3, 0.5), results):
        fresh = double_pendulum(l1=L).compile().simulate(0.3, [0.2, 0.0])
        assert_close(res.q[-1], fresh.q[-1], rtol=1e-12, atol=1e-14, name=f"sweep at length {L}")


class Telescope(mb.Submodel):
    """A rod on a prismatic joint along z (a replacement for Link)."""
    length = mb.Parameter(0.5, min=0.0)
    mass = mb.Parameter(1.0, min=0.0)
    axis = mb.Option("z")

    def build(self, parent):
        rod = self.add(mb.Body("rod", mass=self.mass, com=(0, 0, -self.length / 2)))
        self.add(mb.Prismatic("joint", parent, rod, axis=self.axis, coords="extension"))
        self.tip = rod.frame((0, 0, -self.length))


class Arm(mb.Submodel):
    """Two segments of a replaceable kind (Modelica's `replaceable`)."""
    segment = mb.Option(Link)

    def build(self, base):
        first = self.add(self.segment("first", parent=base))
        self.add(self.segment("second", parent=first.tip))


def test_option_holding_a_submodel_class_replaces_the_part():
    m = mb.Model("m")
    m.add(Arm("arm", base=m.ground.frame()))
    assert m.compile(backend="python").coords == ("arm.first.angle", "arm.second.angle")
    m = mb.Model("m")
    m.add(Arm("arm", base=m.ground.frame(), segment=Telescope))
    s = m.compile(backend="python")
    assert s.coords == ("arm.first.extension", "arm.second.extension")
    # two point masses sliding along z under gravity: both fall freely
    assert_close(s.accelerations([0.0, 0.0], [0.0, 0.0]), [-G, 0.0], atol=1e-12, name="free fall")


def test_results_and_plots_use_nested_names(tmp_path):
    res = double_pendulum().compile().simulate(0.2, [0.3, 0.1])
    assert res.coords == ("upper.angle", "lower.angle")
    assert_close(res["lower.angle"], res.q[:, 1], name="series by nested name")
    res.to_csv(tmp_path / "r.csv")
    assert (tmp_path / "r.csv").read_text().splitlines()[0].startswith("t,upper.angle,lower.angle,")
    labels = [line.get_label() for ax in res.plot().axes for line in ax.lines]
    assert "upper.angle" in labels and "lower.angle" in labels


def test_a_bound_parameter_set_on_its_own_stays_set():
    def build(**modifiers):
        m = mb.Model("m")
        m.add(Leg("left", hip=m.ground.frame(), **modifiers))
        return m.compile(backend="python")
    s = build()
    pinned = s.with_parameters({"left.shank.length": 0.3})
    assert pinned.parameters == build(shank={"length": 0.3}).parameters
    later = pinned.with_parameters({"left.thigh_length": 0.5})
    assert later.parameters == build(shank={"length": 0.3}, thigh_length=0.5).parameters
    assert later.parameters["left.shank.length"] == 0.3 and later.parameters["left.thigh.length"] == 0.5
