"""rotations.cross and the quaternion updates built on it (statemap)."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mbcomp.core.rotations import cross
from mbcomp.core.statemap import StateMap


def test_cross_gives_the_numbers_of_numpy_cross():
    rng = np.random.default_rng(7)
    for shape in [(3,), (6, 3), (2, 5, 3)]:
        a, b = rng.normal(size=shape), rng.normal(size=shape)
        assert np.array_equal(cross(a, b), np.cross(a, b)), shape   # the same operations: to the bit
    assert np.array_equal(cross(np.array([1.0, 0, 0]), np.array([0.0, 1, 0])), [0.0, 0.0, 1.0])


def test_quaternion_steps_compose_rotations_in_the_rotated_frame():
    """``integrate(q, dv)``: ``R(q) exp([dv]x)`` for a ball's quaternion (scalar first), and
    ``qdot`` the rate ``q (0, w) / 2``; against scipy's rotations."""
    state_map = StateMap(nq=5, nv=4, screw_q=np.array([4]), screw_v=np.array([3]), quat_q=np.array([0]),
                         quat_v=np.array([0]), owners=("ball",))
    rng = np.random.default_rng(3)
    for _ in range(5):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        q = np.concatenate((quat, [0.25]))
        dv = np.concatenate((rng.normal(scale=0.7, size=3), [0.5]))
        moved = state_map.integrate(q, dv)
        start = Rotation.from_quat(np.roll(quat, -1))                   # scipy: scalar last
        expected = (start * Rotation.from_rotvec(dv[:3])).as_matrix()
        np.testing.assert_allclose(Rotation.from_quat(np.roll(moved[:4], -1)).as_matrix(), expected, atol=1e-14)
        assert moved[4] == 0.75                                           # the screw coordinate adds
        w = dv[:3]
        rate = state_map.qdot(q, dv)[:4]
        a, b = quat[0], quat[1:]
        np.testing.assert_allclose(rate, 0.5 * np.concatenate(([-b @ w], a * w + np.cross(b, w))), rtol=1e-15)
