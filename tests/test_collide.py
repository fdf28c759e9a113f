"""Collision geometry (mbcomp.core.collide): each narrow-phase answer against an independent
computation (dense sampling of the shapes' surfaces, closed forms), and the broad phase
against testing every pair."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mbcomp.core import collide


def sphere(c, r):
    return ("sphere", np.asarray(c, dtype=float), float(r))


def box(c, half, R=np.eye(3)):
    return ("box", np.asarray(c, dtype=float), np.asarray(R, dtype=float), np.asarray(half, dtype=float))


def capsule(p0, p1, r):
    return ("capsule", np.asarray(p0, dtype=float), np.asarray(p1, dtype=float), float(r))


def plane(o, n):
    n = np.asarray(n, dtype=float)
    return ("plane", np.asarray(o, dtype=float), n / np.linalg.norm(n))


def segment_distance_sampled(p0, p1, q0, q1, n=2001):
    s = np.linspace(0, 1, n)[:, None]
    a, b = p0 + s * (p1 - p0), q0 + s * (q1 - q0)
    from scipy.spatial import cKDTree
    return float(cKDTree(b).query(a)[0].min())


def box_distance_sampled(point, c, half, R, n=81):
    """Distance from a point outside a box to the box, sampling the box's surface."""
    g = np.linspace(-1, 1, n)
    pts = []
    for k in range(3):
        i, j = [m for m in range(3) if m != k]
        u, v = np.meshgrid(g, g)
        for sign in (-1, 1):
            local = np.zeros((u.size, 3))
            local[:, i], local[:, j], local[:, k] = u.ravel() * half[i], v.ravel() * half[j], sign * half[k]
            pts.append(local)
    world = c + np.vstack(pts) @ R.T
    return float(np.linalg.norm(world - point, axis=1).min())


def test_sphere_sphere_gap_normal_and_points():
    (f,) = collide.features(sphere((0, 0, 0), 0.1), sphere((0.3, 0.4, 0), 0.2))
    assert f.gap == pytest.approx(0.5 - 0.3)
    assert np.allclose(f.normal, [0.6, 0.8, 0])
    assert f.owner == collide.OWNER_LINE and f.dist == pytest.approx(0.5)


def test_sphere_plane_and_swapped_order():
    (f,) = collide.features(sphere((1, 2, 0.5), 0.2), plane((0, 0, 0.1), (0, 0, 1)))
    assert f.gap == pytest.approx(0.5 - 0.1 - 0.2)
    assert np.allclose(f.normal, [0, 0, -1])        # from the sphere (A) to the plane (B)
    assert np.allclose(f.pa, [1, 2, 0.5]) and np.allclose(f.pb, [1, 2, 0.1])
    assert f.owner == collide.OWNER_B                # the plane's normal turns with B


def test_box_plane_corners_are_the_heights_of_the_corners():
    R = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    b = box((0.1, 0.2, 0.7), (0.2, 0.15, 0.1), R)
    feats = collide.features(plane((0, 0, 0), (0, 0, 1)), b)
    assert len(feats) == collide.feature_count("plane", "box") == 8
    corners = np.array([b[1] + R @ (np.array(s) * b[3]) for s in collide._CORNERS])
    assert np.allclose(sorted(f.gap for f in feats), sorted(corners[:, 2]))


@pytest.mark.parametrize("seed", range(6))
def test_sphere_box_against_sampled_surface(seed):
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=seed).as_matrix()
    half = rng.uniform(0.1, 0.4, 3)
    c = rng.normal(size=3)
    centre = c + rng.normal(size=3) * 0.6
    local = R.T @ (centre - c)
    if np.all(np.abs(local) <= half):
        centre = c + R @ (half * 1.5 * np.sign(local))
    (f,) = collide.features(box(c, half, R), sphere(centre, 0.05))
    expected = box_distance_sampled(centre, c, half, R) - 0.05
    assert f.gap == pytest.approx(expected, abs=2e-2 * half.max())
    # the normal points from the box's nearest point to the centre
    assert np.allclose(f.pb, centre) and f.normal @ (centre - f.pa) == pytest.approx(f.gap + 0.05)


def test_sphere_inside_box_leaves_through_the_nearest_face():
    (f,) = collide.features(box((0, 0, 0), (1.0, 0.5, 0.2)), sphere((0.3, 0.1, 0.15), 0.1))
    assert np.allclose(f.normal, [0, 0, 1]) and f.gap == pytest.approx(-(0.2 - 0.15) - 0.1)


@pytest.mark.parametrize("seed", range(8))
def test_capsule_capsule_against_sampled_segments(seed):
    rng = np.random.default_rng(seed)
    p0, p1, q0, q1 = rng.normal(size=(4, 3))
    if seed == 0:  # parallel segments
        q0, q1 = p0 + [0.0, 0.3, 0.0], p1 + [0.0, 0.3, 0.0]
    (f,) = collide.features(capsule(p0, p1, 0.05), capsule(q0, q1, 0.02))
    assert f.gap == pytest.approx(segment_distance_sampled(p0, p1, q0, q1) - 0.07, abs=2e-3)
    assert np.linalg.norm(f.pb - f.pa) == pytest.approx(f.gap + 0.07)


def test_capsule_sphere_and_capsule_plane():
    cap = capsule((0, 0, 0), (1, 0, 0), 0.1)
    (f,) = collide.features(cap, sphere((0.4, 0.5, 0), 0.2))
    assert f.gap == pytest.approx(0.2) and np.allclose(f.pa, [0.4, 0, 0])
    (f,) = collide.features(cap, sphere((1.3, 0.4, 0), 0.2))    # beyond an end: the end's cap
    assert f.gap == pytest.approx(0.5 - 0.3)
    tilted = capsule((0, 0, 0.5), (1, 0, 0.8), 0.1)
    gaps = [f.gap for f in collide.features(plane((0, 0, 0), (0, 0, 1)), tilted)]
    assert np.allclose(gaps, [0.4, 0.7])


def test_box_box_corner_on_a_face():
    lower = box((0, 0, 0), (1.0, 1.0, 0.5))
    upper = box((0.1, 0.0, 0.5 + 0.2 + 0.01), (0.2, 0.2, 0.2))
    feats = collide.features(lower, upper)
    assert len(feats) == 25                          # 8 + 8 corners, 9 pairs of edge directions
    gaps = sorted(f.gap for f in feats[:16])
    assert np.allclose(gaps[:4], 0.01) and gaps[4] > 0.01 + 1e-9   # the upper box's 4 bottom corners
    assert min(f.gap for f in feats[16:]) >= 0.01 - 1e-12           # no edge pair closer than the corners
    assert all(np.allclose(f.normal, [0, 0, 1]) for f in feats[:16] if abs(f.gap - 0.01) < 1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_broad_phase_gives_the_pairs_of_testing_every_pair(seed):
    rng = np.random.default_rng(seed)
    n = [5, 40, 200, 500, 17][seed]
    centres = rng.uniform(0, 1, (n, 3))
    radii = rng.uniform(0.005, 0.05, n)
    margin = 0.01
    found = collide.near_pairs(centres, radii, margin)
    assert found == collide.brute_force_pairs(centres, radii, margin)
    assert n < 40 or found             # the larger sets are dense enough to have pairs


def test_bounding_spheres_hold_the_shapes():
    R = Rotation.from_rotvec([0.1, 0.2, 0.3]).as_matrix()
    for shape, points in ((box((1, 2, 3), (0.1, 0.2, 0.3), R),
                           [np.array([1, 2, 3]) + R @ (s * np.array([0.1, 0.2, 0.3])) for s in collide._CORNERS]),
                          (capsule((0, 0, 0), (1, 0, 0), 0.1), [np.array([-0.1, 0, 0]), np.array([1.1, 0, 0])])):
        c, r = collide.bounding_sphere(shape)
        assert max(np.linalg.norm(p - c) for p in points) <= r + 1e-12
