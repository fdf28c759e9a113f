"""Body: validation of mass, com and inertia, and what the compiler makes of the inertia."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import assert_close


def _rotation(rng) -> np.ndarray:
    """A random proper rotation (QR of a Gaussian matrix, sign-fixed)."""
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q @ np.diag(np.sign(np.diag(R)))
    return Q if np.linalg.det(Q) > 0 else -Q


def _ball_mass_matrix(body: mb.Body) -> np.ndarray:
    """Mass matrix of ``body`` on an "xyz" ball joint at the world origin, at q = 0.

    At q = 0 the three motion columns are the world axes, so the mass matrix is the
    inertia about the joint point: ``I_com + m (|c|^2 1 - c c^T)`` (parallel axes).
    """
    m = mb.Model("ball")
    m.add(body)
    m.add(mb.Spherical("ball", m.ground, body, sequence="xyz"))
    return m.compile(backend="python").mass_matrix(np.zeros(3))


class TestBody:
    @pytest.mark.parametrize("mass", [0.0, -1.0, float("nan"), float("inf")], ids=["zero", "negative", "nan", "inf"])
    def test_non_positive_or_non_finite_mass_is_rejected(self, mass):
        with pytest.raises(mb.ModelError, match="Body 'link': mass"):
            mb.Body("link", mass=mass)

    def test_mass_that_is_not_a_number_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Body 'link': mass"):
            mb.Body("link", mass="heavy")

    @pytest.mark.parametrize("com", [(0, float("nan"), 0), (0, 0, float("inf")), (1, 2), (1, 2, 3, 4)],
                             ids=["nan", "inf", "two-entries", "four-entries"])
    def test_bad_com_is_rejected(self, com):
        with pytest.raises(mb.ModelError, match="Body 'link': com"):
            mb.Body("link", mass=1.0, com=com)

    def test_non_symmetric_inertia_is_rejected(self):
        inertia = [[1.0, 0.1, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        with pytest.raises(mb.ModelError, match="Body 'link': inertia matrix is not symmetric"):
            mb.Body("link", mass=1.0, inertia=inertia)

    @pytest.mark.parametrize("inertia", [(-0.1, 1.0, 1.0), [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]],
                             ids=["negative-principal", "indefinite-matrix"])
    def test_inertia_that_is_not_positive_semidefinite_is_rejected(self, inertia):
        with pytest.raises(mb.ModelError, match="Body 'link': inertia is not positive semi-definite"):
            mb.Body("link", mass=1.0, inertia=inertia)

    def test_principal_moments_violating_triangle_inequality_are_rejected(self):
        with pytest.raises(mb.ModelError, match="Body 'link': inertia violates the triangle inequality"):
            mb.Body("link", mass=1.0, inertia=(1.0, 1.0, 2.5))

    def test_rotated_matrix_violating_triangle_inequality_is_rejected(self):
        R = _rotation(np.random.default_rng(1))
        with pytest.raises(mb.ModelError, match="Body 'link': inertia violates the triangle inequality"):
            mb.Body("link", mass=1.0, inertia=R @ np.diag([0.1, 0.2, 0.5]) @ R.T)

    def test_flat_plate_on_the_triangle_boundary_is_accepted(self):
        # A thin plate: I_zz = I_xx + I_yy exactly (the limiting case).
        body = mb.Body("plate", mass=1.0, inertia=(0.1, 0.2, 0.3))
        assert body.inertia == (0.1, 0.2, 0.3)

    @pytest.mark.parametrize("inertia", [np.zeros(2), np.zeros((2, 2)), np.zeros((3, 3, 1)), "big"],
                             ids=["two-values", "2x2", "3x3x1", "text"])
    def test_inertia_of_wrong_shape_is_rejected(self, inertia):
        with pytest.raises(mb.ModelError, match="Body 'link': inertia must be"):
            mb.Body("link", mass=1.0, inertia=inertia)

    def test_non_finite_inertia_is_rejected(self):
        with pytest.raises(mb.ModelError, match="Body 'link': inertia has a non-finite entry"):
            mb.Body("link", mass=1.0, inertia=(1.0, float("nan"), 1.0))

    @pytest.mark.parametrize("inertia", [None, (0, 0, 0), np.zeros((3, 3))], ids=["none", "zero-vector", "zero-matrix"])
    def test_no_inertia_makes_a_point_mass(self, inertia):
        body = mb.Body("bob", mass=2.0, com=(0.1, 0.2, 0.3), inertia=inertia)
        assert body.is_point_mass
        assert not body.has_full_inertia
        assert_close(body.inertia_matrix(), np.zeros((3, 3)), name="point-mass inertia")

    @pytest.mark.parametrize("inertia", [None, (0, 0, 0), np.zeros((3, 3))], ids=["none", "zero-vector", "zero-matrix"])
    def test_point_mass_on_ball_joint_has_only_parallel_axis_terms(self, inertia):
        mass, com = 2.0, np.array([0.1, -0.2, 0.3])
        M = _ball_mass_matrix(mb.Body("bob", mass=mass, com=com, inertia=inertia))
        expected = mass * (com @ com * np.eye(3) - np.outer(com, com))
        assert_close(M, expected, name="point-mass ball-joint mass matrix")

    def test_point_mass_generates_no_inertia_parameter(self):
        m = mb.Model("pm")
        bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -1)))
        m.add(mb.Revolute("pivot", m.ground, bob, axis="x"))
        params = m.compile(backend="python").parameters
        assert "bob.mass" in params and "bob.com" in params
        assert "bob.inertia" not in params

    def test_diagonal_matrix_becomes_principal_values(self):
        body = mb.Body("link", mass=1.0, inertia=np.diag([0.3, 0.2, 0.4]))
        assert body.inertia == (0.3, 0.2, 0.4)
        assert not body.has_full_inertia
        assert not body.is_point_mass

    def test_principal_values_are_kept(self):
        body = mb.Body("link", mass=1.0, inertia=[0.3, 0.2, 0.4])
        assert body.inertia == (0.3, 0.2, 0.4)
        assert_close(body.inertia_matrix(), np.diag([0.3, 0.2, 0.4]), name="inertia matrix")

    def test_full_inertia_matrix_is_kept(self):
        R = _rotation(np.random.default_rng(0))
        matrix = R @ np.diag([0.3, 0.25, 0.4]) @ R.T
        matrix = (matrix + matrix.T) / 2
        body = mb.Body("link", mass=1.0, inertia=matrix)
        assert body.has_full_inertia
        assert_close(body.inertia_matrix(), matrix, rtol=0, atol=1e-15, name="full inertia matrix")

    def test_full_inertia_enters_the_mass_matrix_with_parallel_axis_terms(self):
        rng = np.random.default_rng(2)
        R = _rotation(rng)
        I_com = R @ np.diag([0.3, 0.25, 0.4]) @ R.T
        I_com = (I_com + I_com.T) / 2
        mass, com = 1.5, rng.normal(size=3)
        M = _ball_mass_matrix(mb.Body("link", mass=mass, com=com, inertia=I_com))
        expected = I_com + mass * (com @ com * np.eye(3) - np.outer(com, com))
        assert_close(M, expected, name="ball-joint mass matrix")

    def test_defaults_are_unit_mass_at_the_origin(self):
        body = mb.Body("link")
        assert body.mass == 1.0 and body.com == (0.0, 0.0, 0.0) and body.is_point_mass

    @pytest.mark.parametrize("name", ["", "  ", "a.b", "a[0]", " padded"], ids=["empty", "blank", "dot", "bracket", "space"])
    def test_bad_name_is_rejected(self, name):
        with pytest.raises(mb.ModelError, match="Body"):
            mb.Body(name, mass=1.0)
