"""Model: composition, name resolution and the structural validation done by compile()."""
from __future__ import annotations

import pytest

import mbcomp as mb
from conftest import arm_model, assert_close


def two_bodies():
    m = mb.Model("m")
    a = m.add(mb.Body("a", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.02)))
    b = m.add(mb.Body("b", mass=2.0, com=(0, 0, -0.5), inertia=(0.2, 0.2, 0.03)))
    return m, a, b


class TestComposition:
    def test_add_returns_the_first_component(self):
        m = mb.Model("m")
        a, b = mb.Body("a", mass=1.0), mb.Body("b", mass=1.0)
        assert m.add(a, b) is a
        assert m["b"] is b

    def test_add_keeps_order_and_ground_first(self):
        m, a, b = two_bodies()
        assert list(m.components) == ["ground", "a", "b"]
        assert m.bodies == [a, b]
        assert "a" in m and "nope" not in m

    def test_ground_is_a_body_at_the_world_frame(self):
        m = mb.Model("m")
        assert m["ground"] is m.ground
        assert m.bodies == []

    def test_duplicate_name_is_rejected(self):
        m, a, _ = two_bodies()
        with pytest.raises(mb.ModelError, match="Revolute 'a': name 'a' is already used by Body 'a'"):
            m.add(mb.Revolute("a", m.ground, a, axis="x"))

    def test_adding_the_same_component_twice_is_rejected(self):
        m, a, _ = two_bodies()
        with pytest.raises(mb.ModelError, match="Body 'a': was already added"):
            m.add(a)

    def test_a_component_named_ground_is_rejected(self):
        m = mb.Model("m")
        with pytest.raises(mb.ModelError, match="ground"):
            m.add(mb.Body("ground", mass=1.0))

    def test_non_component_is_rejected(self):
        m = mb.Model("m")
        with pytest.raises(mb.ModelError, match="Model 'm': cannot add"):
            m.add("a body")

    def test_add_needs_a_component(self):
        with pytest.raises(mb.ModelError, match="Model 'm'"):
            mb.Model("m").add()

    def test_failed_add_leaves_the_earlier_components(self):
        m, a, _ = two_bodies()
        with pytest.raises(mb.ModelError):
            m.add(mb.Body("c", mass=1.0), mb.Body("a", mass=1.0))
        assert "c" in m and m["a"] is a

    def test_unknown_name_lookup_raises_key_error(self):
        with pytest.raises(KeyError, match="no component 'x'"):
            mb.Model("m")["x"]

    @pytest.mark.parametrize("gravity", [(0, 0), (0, 0, float("nan"))], ids=["short", "nan"])
    def test_bad_gravity_is_rejected(self, gravity):
        with pytest.raises(mb.ModelError, match="Model 'm': gravity"):
            mb.Model("m", gravity=gravity)

    def test_components_by_name_or_object_compile_to_the_same_system(self):
        by_object = arm_model()
        by_name = mb.Model("arm3d", gravity=(0, 0, -9.81))
        by_name.add(mb.Body("upper", mass=3.0, com=(0, 0, -0.1), inertia=(0.025, 0.025, 0.004)))
        by_name.add(mb.Body("lower", mass=3.0, com=(0, 0.2, 0), inertia=(0.04, 0.002, 0.04)))
        by_name.add(mb.Spherical("shoulder", "ground", "upper", sequence="xy", coords=("alpha", "beta")))
        by_name.add(mb.Revolute("elbow", "upper", "lower", axis="x", parent_point=(0, 0, -0.3), coords="gamma"))
        s1, s2 = by_object.compile(backend="python"), by_name.compile(backend="python")
        q, qd = [0.3, -0.2, 0.9], [0.1, 0.4, -0.3]
        assert s1.coords == s2.coords
        assert_close(s2.mass_matrix(q), s1.mass_matrix(q), name="mass matrix")
        assert_close(s2.accelerations(q, qd), s1.accelerations(q, qd), name="accelerations")

    def test_components_may_be_added_before_the_bodies_they_name(self):
        m = mb.Model("m")
        m.add(mb.Revolute("hinge", "ground", "bob", axis="x"))
        m.add(mb.Body("bob", mass=1.0, com=(0, 0, -1)))
        assert m.compile(backend="python").coords == ("hinge",)

    def test_model_edits_after_compile_do_not_change_the_system(self):
        m, a, _ = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("jb", a, "b", axis="y", parent_point=(0, 0, -1)))
        sys = m.compile(backend="python")
        before = sys.mass_matrix([0.2, 0.3])
        a.mass = 10.0
        m.add(mb.Body("c", mass=1.0))
        assert_close(sys.mass_matrix([0.2, 0.3]), before, rtol=0, atol=0, name="mass matrix")


class TestCompileValidation:
    def test_unknown_body_reference_names_the_joint(self):
        m, a, _ = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("elbow", a, "ghost", axis="x"))
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': child 'ghost' is not in the model"):
            m.compile(backend="python")

    def test_reference_to_a_body_that_was_not_added_is_reported(self):
        m, a, _ = two_bodies()
        stranger = mb.Body("b", mass=5.0)         # same name as the model's "b", another object
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("elbow", a, stranger, axis="x"))
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': child refers to Body 'b', which was not added"):
            m.compile(backend="python")

    def test_reference_of_the_wrong_kind_is_reported(self):
        m, a, _ = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("jb", a, "b", axis="x"))
        m.add(mb.TorsionSpring("spring", "a", stiffness=1.0))
        with pytest.raises(mb.ModelError, match="TorsionSpring 'spring': joint 'a' is a Body, expected a Joint"):
            m.compile(backend="python")

    def test_joint_connecting_a_body_to_itself_is_reported(self):
        m, a, b = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("jb", a, b, axis="x"))
        m.add(mb.Revolute("elbow", b, b, axis="x"))
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': connects body 'b' to itself"):
            m.compile(backend="python")

    def test_body_without_joint_is_reported(self):
        m, a, _ = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x"))
        with pytest.raises(mb.ModelError, match="Body 'b': has no joint"):
            m.compile(backend="python")

    def test_body_not_connected_to_ground_is_reported(self):
        m, a, b = two_bodies()
        m.add(mb.Revolute("jab", a, b, axis="x"))
        with pytest.raises(mb.ModelError, match="Body 'a': is not connected to the ground") as info:
            m.compile(backend="python")
        assert "Body 'b': is not connected to the ground" in str(info.value)

    def test_structural_problems_found_together_are_reported_at_once(self):
        m, a, b = two_bodies()
        c = m.add(mb.Body("c", mass=1.0, inertia=(0.1, 0.1, 0.1)))
        m.add(mb.Revolute("ja", m.ground, a, axis="x"))
        m.add(mb.Revolute("elbow", a, a, axis="x"))              # a body to itself
        m.add(mb.Revolute("jbc", b, c, axis="x"))                # b and c float free
        with pytest.raises(mb.ModelError) as info:
            m.compile(backend="python")
        text = str(info.value)
        for expected in ("Revolute 'elbow': connects body 'a' to itself", "Body 'b': is not connected",
                         "Body 'c': is not connected"):
            assert expected in text
        assert len(info.value.problems) == 3
        assert isinstance(info.value, mb.CompileError)

    def test_every_structural_problem_is_reported_at_once(self):
        m, a, b = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x"))
        m.add(mb.Revolute("elbow", a, a, axis="x"))              # a body to itself
        m.add(mb.Revolute("wrist", a, "ghost", axis="x"))        # unknown body
        # b: no joint at all
        with pytest.raises(mb.ModelError) as info:
            m.compile(backend="python")
        text = str(info.value)
        for expected in ("Revolute 'wrist': child 'ghost' is not in the model",
                         "Revolute 'elbow': connects body 'a' to itself", "Body 'b': has no joint"):
            assert expected in text, f"missing {expected!r} in:\n{text}"

    def test_duplicate_coordinate_names_are_reported(self):
        m, a, b = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x", coords="theta"))
        m.add(mb.Revolute("jb", a, b, axis="x", coords="theta"))
        with pytest.raises(mb.ModelError, match="coordinate name 'theta' is used 2 times"):
            m.compile(backend="python")

    def test_coordinate_named_like_another_component_is_reported(self):
        m, a, b = two_bodies()
        m.add(mb.Revolute("ja", m.ground, a, axis="x", coords="b"))
        m.add(mb.Revolute("jb", a, b, axis="x"))
        with pytest.raises(mb.ModelError, match="coordinate name 'b' is also the name of Body 'b'"):
            m.compile(backend="python")

    def test_error_names_the_component_and_is_a_value_error(self):
        m = arm_model()
        m.add(mb.Revolute("wrist", "lower", "lower", axis="x"))
        with pytest.raises(ValueError, match="Revolute 'wrist'"):
            m.compile(backend="python")

    def test_invalid_joint_is_rejected_when_constructed(self):
        with pytest.raises(mb.ModelError, match="Revolute 'elbow'"):
            mb.Revolute("elbow", "upper", "lower", axis=(0, 0, 0))

    def test_unknown_formulation_is_rejected(self):
        with pytest.raises(mb.ModelError, match="formulation"):
            arm_model().compile(formulation="hamilton", backend="python")

    def test_unknown_backend_is_rejected(self):
        with pytest.raises(mb.ModelError, match="backend"):
            arm_model().compile(backend="fortran")

    def test_unknown_formulation_option_is_rejected(self):
        with pytest.raises(mb.ModelError, match="option"):
            arm_model().compile(backend="python", stabilise=True)
