"""The generic joint contract, run on every Joint subclass (Pinocchio's joint-generic suite).

A new joint type is tested here the moment it exists: add a factory to ``FACTORIES``
(``test_every_joint_type_has_a_factory`` fails until you do).
"""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.spec.components import Joint
from conftest import assert_close


def all_subclasses(cls) -> list[type]:
    found = []
    for sub in cls.__subclasses__():
        found.append(sub)
        found.extend(all_subclasses(sub))
    return found


# Joint class -> {variant id: factory(name, parent, child)}; points and axes deliberately generic.
_POINTS = dict(parent_point=(0.3, -0.2, 0.5), child_point=(-0.1, 0.4, 0.2))
FACTORIES = {
    mb.Revolute: {
        "revolute-x": lambda n, p, c: mb.Revolute(n, p, c, axis="x", **_POINTS),
        "revolute-oblique": lambda n, p, c: mb.Revolute(n, p, c, axis=(0.3, -0.5, 0.8), **_POINTS),
    },
    mb.Prismatic: {
        "prismatic-z": lambda n, p, c: mb.Prismatic(n, p, c, axis="z", **_POINTS),
        "prismatic-oblique": lambda n, p, c: mb.Prismatic(n, p, c, axis=(-0.6, 0.2, 0.7), **_POINTS),
    },
    mb.Spherical: {
        "spherical-xyz": lambda n, p, c: mb.Spherical(n, p, c, sequence="xyz", **_POINTS),
        "spherical-zxz": lambda n, p, c: mb.Spherical(n, p, c, sequence="zxz", **_POINTS),
        "spherical-xy": lambda n, p, c: mb.Spherical(n, p, c, sequence="xy", **_POINTS),
        "spherical-y": lambda n, p, c: mb.Spherical(n, p, c, sequence="y", **_POINTS),
    },
    mb.Fixed: {
        "fixed": lambda n, p, c: mb.Fixed(n, p, c, **_POINTS),
    },
    mb.Ball: {
        "ball": lambda n, p, c: mb.Ball(n, p, c, **_POINTS),
    },
    mb.Free: {
        "free": lambda n, p, c: mb.Free(n, p, c, **_POINTS),
    },
    mb.Universal: {
        "universal-xy": lambda n, p, c: mb.Universal(n, p, c, axes=("x", "y"), **_POINTS),
        "universal-oblique": lambda n, p, c: mb.Universal(n, p, c, axes=((0.3, -0.5, 0.8), "z"), **_POINTS),
    },
    mb.Cylindrical: {
        "cylindrical-y": lambda n, p, c: mb.Cylindrical(n, p, c, axis="y", **_POINTS),
        "cylindrical-oblique": lambda n, p, c: mb.Cylindrical(n, p, c, axis=(0.6, 0.0, -0.8), **_POINTS),
    },
    mb.Planar: {
        "planar-z": lambda n, p, c: mb.Planar(n, p, c, normal="z", **_POINTS),
        "planar-oblique": lambda n, p, c: mb.Planar(n, p, c, normal=(0.2, 0.9, -0.4), **_POINTS),
    },
}

JOINT_TYPES = [cls for cls in all_subclasses(Joint) if not cls.__name__.startswith("_")]
CASES = [pytest.param(cls, factory, id=variant)
         for cls in JOINT_TYPES for variant, factory in FACTORIES.get(cls, {}).items()]


def _skew_vector(W: np.ndarray) -> np.ndarray:
    """The vector w of a (nearly) skew-symmetric matrix ``W = [w]x``."""
    W = (W - W.T) / 2
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


def _model(factory):
    """A body on an "xyz" ball joint (the joint's parent, at a random fixed pose) and,
    below it, the child on the joint under test."""
    m = mb.Model("contract", gravity=(0, 0, -9.81))
    carrier = m.add(mb.Body("carrier", mass=1.3, com=(0.1, 0.0, -0.2), inertia=(0.05, 0.06, 0.07)))
    child = m.add(mb.Body("child", mass=0.7, com=(0.0, 0.2, 0.1), inertia=(0.02, 0.03, 0.04)))
    m.add(mb.Spherical("mount", m.ground, carrier, sequence="xyz", parent_point=(0.2, 0.1, -0.3)))
    joint = m.add(factory("tested", carrier, child))
    return m, joint


@pytest.mark.parametrize("cls", JOINT_TYPES, ids=lambda c: c.__name__)
def test_every_joint_type_has_a_factory(cls):
    assert FACTORIES.get(cls), f"add a factory for {cls.__name__} to FACTORIES in {__file__}"


@pytest.mark.parametrize("cls, factory", CASES)
class TestJointContract:
    def test_factory_builds_the_class(self, cls, factory):
        assert type(factory("j", "a", "b")) is cls

    def test_coord_suffixes_match_number_of_coordinates(self, cls, factory):
        joint = factory("j", "a", "b")
        assert len(joint.coord_suffixes) == joint.n_coords
        assert len(joint.coords) == joint.n_coords
        assert len(set(joint.coords)) == joint.n_coords
        assert len(joint.speeds) == joint.nv <= joint.nq
        assert len(set(joint.speeds)) == joint.nv

    def test_pose_at_neutral_is_identity_rotation_with_joint_points_coincident(self, cls, factory):
        joint = factory("j", "a", "b")
        R, p = joint.relative_pose(np.array(joint.neutral))
        assert_close(R, np.eye(3), atol=1e-15, name="rotation at q = 0")
        expected = np.asarray(joint.parent_point) - np.asarray(joint.child_point)
        assert_close(p, expected, atol=1e-15, name="child origin at q = 0")

    def test_rotation_is_proper_orthonormal(self, cls, factory):
        joint = factory("j", "a", "b")
        rng = np.random.default_rng(11)
        for _ in range(5):
            R, p = joint.relative_pose(rng.uniform(-3, 3, joint.n_coords))
            assert_close(R.T @ R, np.eye(3), atol=1e-14, name="R^T R")
            assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-14)
            assert p.shape == (3,) and np.all(np.isfinite(p))

    def test_relative_pose_rejects_wrong_number_of_coordinates(self, cls, factory):
        joint = factory("j", "a", "b")
        with pytest.raises(mb.ModelError, match=f"{cls.__name__} 'j'"):
            joint.relative_pose(np.zeros(joint.n_coords + 1))

    def test_compiled_pose_matches_relative_pose(self, cls, factory):
        rng = np.random.default_rng(5)
        m, joint = _model(factory)
        sys = m.compile(backend="python")
        mount = m["mount"]
        for _ in range(3):
            q = rng.uniform(-1.2, 1.2, sys.nq)
            R1, p1 = mount.relative_pose(q[sys.topology.q_slice["mount"]])
            R2, p2 = joint.relative_pose(q[sys.topology.q_slice["tested"]])
            state = sys.body_state("child", q, point=(0, 0, 0))
            assert_close(state.rotation, R1 @ R2, atol=1e-13, name="child rotation")
            assert_close(state.position, p1 + R1 @ p2, atol=1e-13, name="child origin")

    def test_finite_difference_of_pose_matches_motion_columns(self, cls, factory):
        """Column k of the compiled motion subspace is ``(w_k, v0_k)`` (world frame, velocity
        of the body point at the world origin); the pose moved by a step along speed k
        (``joint.integrate``) must give ``dR/dv_k R^T = [w_k]x`` and ``dp/dv_k = v0_k + w_k x p``."""
        rng = np.random.default_rng(3)
        m, joint = _model(factory)
        sys = m.compile(backend="python")
        mount = m["mount"]
        sl, vs = sys.topology.q_slice["tested"], sys.topology.v_slice["tested"]
        h = 1e-6

        def world_pose(q):
            R1, p1 = mount.relative_pose(q[sys.topology.q_slice["mount"]])
            R2, p2 = joint.relative_pose(q[sl])
            return R1 @ R2, p1 + R1 @ p2

        def moved(q, k, step):
            dv = np.zeros(joint.nv)
            dv[k - vs.start] = step
            out = q.copy()
            out[sl] = joint.integrate(q[sl], dv)
            return out

        for _ in range(3):
            q = sys.state_vector(rng.uniform(-1.2, 1.2, sys.nq))
            columns = sys.motion_columns(q)
            R, p = world_pose(q)
            for k in range(vs.start, vs.stop):
                (Rp, pp), (Rm, pm) = world_pose(moved(q, k, h)), world_pose(moved(q, k, -h))
                w = _skew_vector((Rp - Rm) / (2 * h) @ R.T)
                v = (pp - pm) / (2 * h)
                w_k, v0_k = columns[k, :3], columns[k, 3:]
                assert_close(w_k, w, rtol=1e-7, atol=1e-8, name=f"angular part of column {k}")
                assert_close(v0_k + np.cross(w_k, p), v, rtol=1e-7, atol=1e-8, name=f"linear part of column {k}")

    def test_columns_match_velocity_of_the_child(self, cls, factory):
        """``body_state`` speeds agree with the joint columns times the joint speeds."""
        rng = np.random.default_rng(9)
        m, joint = _model(factory)
        sys = m.compile(backend="python")
        q = rng.uniform(-1.2, 1.2, sys.nq)
        qd = np.zeros(sys.nv)
        sl = sys.topology.v_slice["tested"]
        qd[sl] = rng.normal(size=sl.stop - sl.start)
        state = sys.body_state("child", q, qd, point=(0, 0, 0))
        V = sys.motion_columns(q).T @ qd
        assert_close(state.angular_velocity, V[:3], atol=1e-13, name="angular velocity")
        assert_close(state.velocity, V[3:] + np.cross(V[:3], state.position), atol=1e-13, name="velocity")

    def test_relative_velocity_is_the_rate_of_the_pose(self, cls, factory):
        """``relative_velocity(q, v)`` equals the finite-difference rate of ``relative_pose``
        along ``q' = qdot(q, v)``."""
        joint = factory("j", "a", "b")
        rng = np.random.default_rng(21)
        h = 1e-6
        for _ in range(3):
            q = joint.normalize(rng.uniform(-1.2, 1.2, joint.nq))
            v = rng.normal(size=joint.nv)
            rate = joint.qdot(q, v)
            (Rp, pp), (Rm, pm) = joint.relative_pose(q + h * rate), joint.relative_pose(q - h * rate)
            R, _ = joint.relative_pose(q)
            w, u = joint.relative_velocity(q, v)
            assert_close(w, _skew_vector((Rp - Rm) / (2 * h) @ R.T), atol=1e-8, name="angular velocity")
            assert_close(u, (pp - pm) / (2 * h), atol=1e-8, name="origin velocity")

    def test_integrate_and_difference_are_inverse(self, cls, factory):
        joint = factory("j", "a", "b")
        rng = np.random.default_rng(4)
        q = joint.normalize(rng.uniform(-1.0, 1.0, joint.nq))
        dv = rng.uniform(-0.5, 0.5, joint.nv)
        q1 = joint.integrate(q, dv)
        assert_close(joint.difference(q, q1), dv, atol=1e-12, name="difference(q, integrate(q, dv))")
        assert_close(joint.normalize(q1), q1, atol=1e-15, name="integrate keeps unit quaternions")
