"""The one validator: ParameterSpec checks, and the same verdict from constructors,
attribute assignment, System.with_parameters and model files."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.params import ParameterSpec, in_range, nonnegative, positive, spd_inertia, unit_vector, validate


class TestValidate:
    @pytest.mark.parametrize("spec", [ParameterSpec("k", ()), ParameterSpec("m", (), check=positive),
                                      ParameterSpec("c", (), check=nonnegative), ParameterSpec("e", (), check=in_range(0, 1)),
                                      ParameterSpec("r", (3,)), ParameterSpec("a", (3,), check=unit_vector),
                                      ParameterSpec("i", (3,), check=spd_inertia)])
    def test_plain_numbers_get_the_verdict_of_the_general_path(self, spec):
        """Python numbers and tuples of them take a quick path: the same stored value, or the
        same message, as the same numbers given as a numpy array (the general path)."""
        values = [3, 2.5, -0.0, -2.0, 0.5, 1e100, -1e100, 1.5e100, float("inf"), float("nan"), (1, 2, 3), [0.0, 0.0, 0.0],
                  (1e200, 0, 0), (1.0, -2.0, 0.5), (3.0, 1.0, 1.0), [1, 2], (1.0, float("nan"), 0.0)]

        def verdict(value):
            try:
                return validate(spec, value, "x")
            except mb.ModelError as exc:
                return str(exc)
        for value in values:
            assert verdict(value) == verdict(np.array(value, dtype=float)), value
        for value in values:
            assert type(verdict(value)) is type(verdict(np.array(value, dtype=float))), value

    def test_number_is_stored_as_float(self):
        assert validate(ParameterSpec("k", ()), np.float32(2.5), "x") == 2.5
        assert type(validate(ParameterSpec("k", ()), 3, "x")) is float

    @pytest.mark.parametrize("value, match", [(True, "must be a number, got a boolean"),
                                              ("2", "must be a number, got the string '2'"),
                                              (float("nan"), "must be finite, got nan"),
                                              ([1.0, 2.0], "must be a number, got an array of shape"),
                                              (None, "must be a number"), ({}, "must be a number")])
    def test_not_a_finite_number(self, value, match):
        with pytest.raises(mb.ModelError, match=f"Spring 's': k {match}"):
            validate(ParameterSpec("k", ()), value, "Spring 's'")

    def test_checks(self):
        assert validate(ParameterSpec("c", (), check=nonnegative), 0.0, "o") == 0.0
        with pytest.raises(mb.ModelError, match="c must not be negative, got -1e-300"):
            validate(ParameterSpec("c", (), check=nonnegative), -1e-300, "o")
        with pytest.raises(mb.ModelError, match="m must be positive, got 0"):
            validate(ParameterSpec("m", (), check=positive), 0, "o")
        with pytest.raises(mb.ModelError, match=r"e must lie in \[0, 1\], got 1.5"):
            validate(ParameterSpec("e", (), check=in_range(0, 1)), 1.5, "o")
        assert validate(ParameterSpec("e", (), check=in_range(0, 1)), 1, "o") == 1.0

    def test_vector(self):
        spec = ParameterSpec("p", (3,))
        assert validate(spec, np.array([1, 2, 3]), "o") == (1.0, 2.0, 3.0)
        with pytest.raises(mb.ModelError, match="p must have 3 components, got 2"):
            validate(spec, (1, 2), "o")
        with pytest.raises(mb.ModelError, match=r"p has a non-finite entry: \(0, inf, 0\)"):
            validate(spec, (0, float("inf"), 0), "o")
        with pytest.raises(mb.ModelError, match="p must be a 3-vector of numbers"):
            validate(spec, ("a", 1, 2), "o")

    def test_unit_vector_from_name_or_numbers(self):
        spec = ParameterSpec("axis", (3,), check=unit_vector)
        assert validate(spec, "-y", "o") == (0.0, -1.0, 0.0)
        assert validate(spec, (0, 3, 4), "o") == pytest.approx((0, 0.6, 0.8), abs=1e-16)
        assert validate(spec, (1e-300, 0, 0), "o") == (1.0, 0.0, 0.0)
        assert validate(spec, (1e300, 1e300, 0), "o") == pytest.approx((2 ** -0.5, 2 ** -0.5, 0), abs=3e-16)
        with pytest.raises(mb.ModelError, match="axis has zero length"):
            validate(spec, (0, 0, 0), "o")
        with pytest.raises(mb.ModelError, match="axis must be 'x', 'y', 'z' or a 3-vector, got 'w'"):
            validate(spec, "w", "o")

    @pytest.mark.parametrize("inertia, stored", [
        ((1, 2, 2.5), (1.0, 2.0, 2.5)),
        (np.diag([1.0, 2.0, 2.5]), (1.0, 2.0, 2.5)),
        ([[2, 0.5, 0], [0.5, 2, 0], [0, 0, 3]], (2.0, 2.0, 3.0, 0.5, 0.0, 0.0)),
        ((2.0, 2.0, 3.0, 0.5, 0.0, 0.0), (2.0, 2.0, 3.0, 0.5, 0.0, 0.0)),
        ((0, 0, 0), None), (np.zeros((3, 3)), None),
    ])
    def test_inertia_forms(self, inertia, stored):
        assert validate(ParameterSpec("inertia", (3,), check=spd_inertia), inertia, "o") == stored

    @pytest.mark.parametrize("inertia, match", [
        ((1, 1, 5), "violates the triangle inequality: principal moment 5 > 1 \\+ 1"),
        ((-1, 1, 1), "is not positive semi-definite"),
        ([[1, 2, 0], [0, 1, 0], [0, 0, 1]], "matrix is not symmetric"),
        ([[1, 2, 0], [2, 1, 0], [0, 0, 1]], "is not positive semi-definite"),
        ((1e308, 1e308, 1e308, 1e308, 1e308, 1e308), "is too large|not positive|triangle"),
        ((1, 1), "must be 3 principal values or a 3x3 matrix, got shape \\(2,\\)"),
    ])
    def test_bad_inertia(self, inertia, match):
        with pytest.raises(mb.ModelError, match=match):
            validate(ParameterSpec("inertia", (3,), check=spd_inertia), inertia, "o")

    def test_time_input_and_optional(self):
        f = lambda t, q, qd: (0, 0, t)  # noqa: E731
        assert validate(ParameterSpec("force", (3,), time_input=True), f, "o") is f
        assert validate(ParameterSpec("speed", (), optional=True), None, "o") is None
        with pytest.raises(mb.ModelError, match="speed must be a number, got a callable"):
            validate(ParameterSpec("speed", ()), f, "o")


class TestAttributes:
    def test_assignment_is_validated_like_the_constructor(self):
        body = mb.Body("b", mass=1.0, com=(0, 0, -1), inertia=(1, 1, 1))
        with pytest.raises(mb.ModelError, match="Body 'b': mass must be positive, got -2"):
            body.mass = -2.0
        with pytest.raises(mb.ModelError, match="Body 'b': com must have 3 components, got 2"):
            body.com = (1, 2)
        with pytest.raises(mb.ModelError, match="Body 'b': inertia violates the triangle inequality"):
            body.inertia = (1, 1, 3)
        assert (body.mass, body.com, body.inertia) == (1.0, (0.0, 0.0, -1.0), (1.0, 1.0, 1.0))
        body.mass = 2
        body.inertia = np.diag([1.0, 2.0, 2.5])
        assert (body.mass, body.inertia) == (2.0, (1.0, 2.0, 2.5))

    def test_axis_assignment_is_normalised(self):
        a, b = mb.Body("a"), mb.Body("b")
        joint = mb.Revolute("j", a, b, axis="x")
        joint.axis = (0, 0, 2)
        assert joint.axis == (0.0, 0.0, 1.0)
        with pytest.raises(mb.ModelError, match="Revolute 'j': axis has zero length"):
            joint.axis = (0, 0, 0)

    def test_name_cannot_change(self):
        body = mb.Body("b")
        with pytest.raises(mb.ModelError, match="name of a component cannot change"):
            body.name = "c"

    def test_callable_inputs_are_not_parameters(self):
        force = mb.Force("f", "b", force=lambda t, q, qd: (0, 0, 1))
        assert force.is_callable and force.parameter_values() == {"point": (0.0, 0.0, 0.0)}
        force.force = (1, 2, 3)
        assert not force.is_callable and force.parameter_values()["force"] == (1.0, 2.0, 3.0)
