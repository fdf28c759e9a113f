"""Revolute, Prismatic, Spherical and Fixed: poses, validation and coordinate names."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mbcomp as mb
from conftest import assert_close

X, Y, Z = np.eye(3)


@pytest.fixture
def parts():
    """Two bodies to connect (the joints only hold references to them)."""
    return mb.Body("a", mass=1.0), mb.Body("b", mass=1.0)


def _rodrigues(axis, angle):
    """Independent rotation matrix: scipy's rotation vector."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return Rotation.from_rotvec(angle * axis).as_matrix()


class TestRevolute:
    def test_positive_angle_rotates_y_towards_z(self, parts):
        joint = mb.Revolute("hinge", *parts, axis="x")
        R, p = joint.relative_pose([np.pi / 2])
        assert_close(R @ Y, Z, atol=1e-15, name="rotated y")
        assert_close(R @ Z, -Y, atol=1e-15, name="rotated z")
        assert_close(R @ X, X, atol=1e-15, name="axis")
        assert_close(p, np.zeros(3), name="origin")

    def test_positive_angle_about_z_rotates_x_towards_y(self, parts):
        R, _ = mb.Revolute("hinge", *parts, axis="z").relative_pose([0.3])
        assert_close(R @ X, [np.cos(0.3), np.sin(0.3), 0], atol=1e-15, name="rotated x")

    def test_negative_named_axis_reverses_the_rotation(self, parts):
        R_minus, _ = mb.Revolute("hinge", *parts, axis="-z").relative_pose([0.4])
        R_plus, _ = mb.Revolute("hinge", *parts, axis="z").relative_pose([-0.4])
        assert_close(R_minus, R_plus, atol=1e-15, name="rotation about -z")

    def test_vector_axis_is_normalised_and_matches_rotation_vector(self, parts):
        axis = (1.0, -2.0, 2.0)
        joint = mb.Revolute("hinge", *parts, axis=axis)
        assert_close(joint.axis, np.array(axis) / 3.0, name="unit axis")
        R, _ = joint.relative_pose([1.1])
        assert_close(R, _rodrigues(axis, 1.1), atol=1e-14, name="rotation")

    def test_child_point_stays_on_parent_point(self, parts):
        joint = mb.Revolute("hinge", *parts, axis=(0.2, 0.3, 0.9), parent_point=(1, 2, 3), child_point=(-0.5, 0.1, 0.4))
        for angle in (0.0, 0.7, -2.5):
            R, p = joint.relative_pose([angle])
            # The child point, carried to the parent frame, coincides with the parent point.
            assert_close(p + R @ np.array(joint.child_point), joint.parent_point, atol=1e-14, name="joint point")

    def test_zero_axis_is_rejected(self, parts):
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': axis has zero length"):
            mb.Revolute("elbow", *parts, axis=(0, 0, 0))

    @pytest.mark.parametrize("axis, unit", [((1e-200, 0, 0), (1, 0, 0)), ((0, -1e-14, 0), (0, -1, 0)),
                                            ((1e200, 1e200, 0), (2 ** -0.5, 2 ** -0.5, 0))],
                             ids=["tiny", "small", "huge"])
    def test_any_nonzero_axis_is_a_direction(self, parts, axis, unit):
        # Only the direction matters: very small and very large vectors are not zero or overflow.
        joint = mb.Revolute("elbow", *parts, axis=axis)
        assert_close(joint.axis, unit, atol=1e-15, name="unit axis")

    @pytest.mark.parametrize("axis", ["w", (1, 0), (1, 0, float("nan")), "xy"], ids=["letter", "short", "nan", "two-letters"])
    def test_bad_axis_is_rejected(self, parts, axis):
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': axis"):
            mb.Revolute("elbow", *parts, axis=axis)

    def test_default_coordinate_is_the_joint_name(self, parts):
        assert mb.Revolute("elbow", *parts, axis="x").coords == ("elbow",)

    def test_coords_string_names_the_coordinate(self, parts):
        assert mb.Revolute("elbow", *parts, axis="x", coords="gamma").coords == ("gamma",)

    def test_wrong_number_of_coordinate_names_is_rejected(self, parts):
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': coords"):
            mb.Revolute("elbow", *parts, axis="x", coords=("a", "b"))

    def test_relative_pose_checks_the_number_of_coordinates(self, parts):
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': needs 1 coordinate"):
            mb.Revolute("elbow", *parts, axis="x").relative_pose([0.1, 0.2])

    def test_non_finite_joint_point_is_rejected(self, parts):
        with pytest.raises(mb.ModelError, match="Revolute 'elbow': parent_point"):
            mb.Revolute("elbow", *parts, axis="x", parent_point=(0, float("inf"), 0))


class TestPrismatic:
    def test_child_translates_by_q_along_the_axis(self, parts):
        joint = mb.Prismatic("slide", *parts, axis=(3, 0, 4))
        R, p = joint.relative_pose([2.0])
        assert_close(R, np.eye(3), name="rotation")
        assert_close(p, [1.2, 0.0, 1.6], atol=1e-15, name="translation")

    def test_joint_points_offset_the_child_origin(self, parts):
        joint = mb.Prismatic("slide", *parts, axis="y", parent_point=(1, 0, 0), child_point=(0, 0, 0.5))
        _, p = joint.relative_pose([0.25])
        assert_close(p, [1.0, 0.25, -0.5], atol=1e-15, name="child origin")

    def test_zero_axis_is_rejected(self, parts):
        with pytest.raises(mb.ModelError, match="Prismatic 'slide': axis has zero length"):
            mb.Prismatic("slide", *parts, axis=[0.0, 0.0, 0.0])

    def test_default_coordinate_is_the_joint_name(self, parts):
        assert mb.Prismatic("slide", *parts, axis="x").coords == ("slide",)

    def test_coords_string_names_the_coordinate(self, parts):
        assert mb.Prismatic("slide", *parts, axis="x", coords="s").coords == ("s",)


class TestSpherical:
    @pytest.mark.parametrize("sequence", ["xyz", "zxz", "zyx", "xy", "yz", "z"])
    def test_rotation_is_intrinsic_euler_sequence(self, parts, sequence):
        rng = np.random.default_rng(7)
        angles = rng.uniform(-np.pi, np.pi, len(sequence))
        R, p = mb.Spherical("ball", *parts, sequence=sequence).relative_pose(angles)
        # scipy: upper-case letters are intrinsic rotations.
        expected = Rotation.from_euler(sequence.upper(), angles).as_matrix()
        assert_close(R, expected, atol=1e-14, name=f"{sequence} rotation")
        assert_close(p, np.zeros(3), name="origin")

    def test_rotation_is_product_in_sequence_order(self, parts):
        a, b = 0.4, -0.9
        R, _ = mb.Spherical("ball", *parts, sequence="xy").relative_pose([a, b])
        assert_close(R, _rodrigues(X, a) @ _rodrigues(Y, b), atol=1e-15, name="R_x R_y")

    def test_sequence_is_case_insensitive(self, parts):
        assert mb.Spherical("ball", *parts, sequence="XyZ").sequence == "xyz"

    def test_number_of_coordinates_follows_the_sequence(self, parts):
        for sequence in ("x", "xy", "xyz"):
            assert mb.Spherical("ball", *parts, sequence=sequence).n_coords == len(sequence)

    @pytest.mark.parametrize("sequence", ["xqz", "abc", "x1"], ids=["q", "abc", "digit"])
    def test_bad_sequence_letter_is_rejected(self, parts, sequence):
        with pytest.raises(mb.ModelError, match="Spherical 'ball': sequence .* invalid axis"):
            mb.Spherical("ball", *parts, sequence=sequence)

    @pytest.mark.parametrize("sequence", ["", "xyzx"], ids=["empty", "four-axes"])
    def test_sequence_of_wrong_length_is_rejected(self, parts, sequence):
        with pytest.raises(mb.ModelError, match="Spherical 'ball': sequence .* 1 to 3 axes"):
            mb.Spherical("ball", *parts, sequence=sequence)

    @pytest.mark.parametrize("sequence", ["xx", "xyy", "zzx"])
    def test_repeated_consecutive_axes_are_rejected(self, parts, sequence):
        with pytest.raises(mb.ModelError, match="Spherical 'ball': sequence .* repeats axis"):
            mb.Spherical("ball", *parts, sequence=sequence)

    def test_sequence_must_be_a_string(self, parts):
        with pytest.raises(mb.ModelError, match="Spherical 'ball': sequence must be a string"):
            mb.Spherical("ball", *parts, sequence=["x", "y"])

    def test_default_coordinates_are_named_by_axis(self, parts):
        assert mb.Spherical("shoulder", *parts, sequence="xy").coords == ("shoulder_x", "shoulder_y")
        assert mb.Spherical("shoulder", *parts, sequence="zyx").coords == ("shoulder_z", "shoulder_y", "shoulder_x")

    def test_default_coordinates_of_repeated_axes_are_numbered(self, parts):
        assert mb.Spherical("wrist", *parts, sequence="zxz").coords == ("wrist_z1", "wrist_x2", "wrist_z3")

    def test_coords_sequence_names_the_coordinates(self, parts):
        joint = mb.Spherical("shoulder", *parts, sequence="xy", coords=("alpha", "beta"))
        assert joint.coords == ("alpha", "beta")

    def test_wrong_number_of_coordinate_names_is_rejected(self, parts):
        with pytest.raises(mb.ModelError, match="Spherical 'shoulder': coords must name 2 coordinate"):
            mb.Spherical("shoulder", *parts, sequence="xy", coords="alpha")

    def test_repeated_coordinate_names_are_rejected(self, parts):
        with pytest.raises(mb.ModelError, match="Spherical 'shoulder': coords .* repeat"):
            mb.Spherical("shoulder", *parts, sequence="xy", coords=("a", "a"))

    def test_compiled_model_uses_the_coordinate_names(self):
        m = mb.Model("named")
        b = m.add(mb.Body("b", mass=1.0, com=(0, 0, -1), inertia=(0.1, 0.1, 0.1)))
        m.add(mb.Spherical("shoulder", m.ground, b, sequence="zxz"))
        assert m.compile(backend="python").coords == ("shoulder_z1", "shoulder_x2", "shoulder_z3")


class TestFixed:
    def test_has_no_coordinates(self, parts):
        joint = mb.Fixed("weld", *parts)
        assert joint.n_coords == 0 and joint.coords == ()

    def test_pose_is_the_offset_between_joint_points(self, parts):
        joint = mb.Fixed("weld", *parts, parent_point=(1, 2, 3), child_point=(0.5, 0, -1))
        R, p = joint.relative_pose([])
        assert_close(R, np.eye(3), name="rotation")
        assert_close(p, [0.5, 2.0, 4.0], name="child origin")

    def test_pose_rejects_coordinates(self, parts):
        with pytest.raises(mb.ModelError, match="Fixed 'weld': needs 0 coordinate"):
            mb.Fixed("weld", *parts).relative_pose([0.1])

    def test_welded_body_adds_its_inertia_to_its_parent(self):
        # A rod on a hinge with a point mass welded at its tip: I = I_rod + m_tip L^2.
        m = mb.Model("welded", gravity=(0, 0, 0))
        rod = m.add(mb.Body("rod", mass=2.0, com=(0, 0, -0.5), inertia=(2 / 12, 2 / 12, 1e-3)))
        tip = m.add(mb.Body("tip", mass=0.5))
        m.add(mb.Revolute("hinge", m.ground, rod, axis="x"))
        m.add(mb.Fixed("weld", rod, tip, parent_point=(0, 0, -1)))
        sys = m.compile(backend="python")
        assert sys.coords == ("hinge",)
        expected = 2 / 12 + 2.0 * 0.25 + 0.5 * 1.0
        assert_close(sys.mass_matrix([0.3]), [[expected]], name="hinge inertia")
