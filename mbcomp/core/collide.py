"""Collision geometry on plain arrays: the narrow phase (the touching features of two placed
shapes) and the broad phase (which pairs of bounding spheres may touch).

Shapes are placed in the world as tuples of arrays (m):

- ``("sphere", centre, radius)``
- ``("capsule", end0, end1, radius)``: the points within ``radius`` of the segment end0-end1
- ``("box", centre, R, half)``: ``R`` world from box axes (3x3), ``half`` the half edges
- ``("plane", point, normal)``: the half-space ``normal . (p - point) < 0`` is solid

A pair ``(A, B)`` has a fixed number of features (``feature_count``), each a candidate
contact; ``features(A, B)`` measures them all.  Feature ``i`` is the gap ``g`` (m, negative
when the shapes overlap), the unit normal ``n`` pointing from A to B (B moves along +n to
separate), a point of A ``pa`` and a point of B ``pb`` (world; the material points whose
relative velocity along n is the gap's rate) and how the normal turns (``owner``):

- ``OWNER_A`` / ``OWNER_B``: n is a face normal fixed in A (B): it turns with that body;
- ``OWNER_LINE``: n is the direction from pa to pb (two rounded features: sphere, capsule,
  an edge or corner of a box), and ``dist = |pb - pa|``;
- ``OWNER_EDGE``: an edge of box A against an edge of box B: n is the unit cross product of
  the edges' directions (oriented from A's centre to B's), the gap the separation of the two
  edges along it.

A point that slides along a line of its body as the shapes move (the nearest point of a
capsule's axis, of a box edge, of an edge against another edge) carries that line's unit
direction (``slide_a``, ``slide_b``; None for a material point): the acceleration bias
then includes the sliding terms (``mbcomp.compiled.collision_kernel``).

The gap's acceleration at zero generalised acceleration follows from these (the caller has
the bodies' velocities): see ``mbcomp.compiled.collision_kernel``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

OWNER_A, OWNER_B, OWNER_LINE, OWNER_EDGE = 0, 1, 2, 3

#: Features per ordered pair of kinds (the kinds sorted as in ``ORDER``).
ORDER = ("plane", "box", "capsule", "sphere")
_COUNTS = {("plane", "sphere"): 1, ("plane", "capsule"): 2, ("plane", "box"): 8, ("box", "sphere"): 1,
           ("box", "capsule"): 2, ("box", "box"): 25, ("capsule", "sphere"): 1, ("capsule", "capsule"): 1,
           ("sphere", "sphere"): 1, ("plane", "plane"): 0}
_CORNERS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)


@dataclass
class Feature:
    """One candidate contact (see the module docstring; lengths in m, world frame)."""

    gap: float
    normal: np.ndarray
    pa: np.ndarray
    pb: np.ndarray
    owner: int
    dist: float = 0.0
    ra: float = 0.0     #: the rounding radius of A at pa (the surface is at pa + ra n)
    rb: float = 0.0     #: and of B at pb (its surface at pb - rb n)
    slide_a: np.ndarray | None = None   #: unit direction pa slides along (fixed in A), or None
    slide_b: np.ndarray | None = None   #: and pb (fixed in B)

    def touching_points(self) -> tuple[np.ndarray, np.ndarray]:
        """The surface points of A and B that touch (or face each other), world (m)."""
        return self.pa + self.ra * self.normal, self.pb - self.rb * self.normal


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of 3-vectors along the last axis (numpy's ``cross`` costs ten times
    more on small arrays)."""
    if a.ndim == 1 and b.ndim == 1:
        return np.array((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    b1, b2, b3 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1), axis=-1)


def canonical(kind_a: str, kind_b: str) -> bool:
    """True when the pair ``(kind_a, kind_b)`` is in the order ``features`` expects (else swap)."""
    return ORDER.index(kind_a) <= ORDER.index(kind_b)


def feature_count(kind_a: str, kind_b: str) -> int:
    """Number of candidate contacts between two shapes of these kinds (0: they never touch)."""
    key = (kind_a, kind_b) if canonical(kind_a, kind_b) else (kind_b, kind_a)
    return _COUNTS[key]


def bounding_sphere(shape: tuple) -> tuple[np.ndarray, float]:
    """Centre and radius (m) of a sphere holding the shape; a plane's radius is infinite."""
    kind = shape[0]
    if kind == "sphere":
        return shape[1], float(shape[2])
    if kind == "capsule":
        return 0.5 * (shape[1] + shape[2]), 0.5 * float(np.linalg.norm(shape[2] - shape[1])) + float(shape[3])
    if kind == "box":
        return shape[1], float(np.linalg.norm(shape[3]))
    return shape[1], np.inf


# -- narrow phase ---------------------------------------------------------------------------------
def _line(pa: np.ndarray, pb: np.ndarray, ra: float, rb: float, fallback: np.ndarray, slide_a=None,
          slide_b=None) -> Feature:
    """Two rounded features: points pa, pb with radii ra, rb (sliding along slide_a, slide_b)."""
    d = pb - pa
    dist = float(np.linalg.norm(d))
    n = d / dist if dist > 1e-12 else fallback
    return Feature(dist - ra - rb, n, pa, pb, OWNER_LINE, max(dist, 1e-12), ra, rb, slide_a, slide_b)


def _point_plane(point: np.ndarray, radius: float, plane: tuple) -> Feature:
    o, n = plane[1], plane[2]
    height = float(n @ (point - o))
    return Feature(height - radius, n, point - height * n, point, OWNER_A, rb=radius)


def _point_box(point: np.ndarray, radius: float, box: tuple) -> Feature:
    """A sphere (or a corner: radius 0) against a box A: the box's nearest point; inside, the
    face of least penetration."""
    c, R, half = box[1], box[2], box[3]
    local = R.T @ (point - c)
    clamped = np.clip(local, -half, half)
    outside = np.abs(local) > half
    if outside.any():
        if int(outside.sum()) == 1:  # a face: its normal is fixed in the box
            k = int(np.flatnonzero(outside)[0])
            n = R[:, k] * np.sign(local[k])
            height = abs(local[k]) - half[k]
            return Feature(float(height - radius), n, c + R @ clamped, point, OWNER_A, rb=radius)
        free = np.flatnonzero(~outside)  # an edge (one free axis: the nearest point slides along it) or a corner
        return _line(c + R @ clamped, point, 0.0, radius, R @ (np.sign(local) / np.sqrt(3)),
                     slide_a=R[:, int(free[0])].copy() if len(free) == 1 else None)
    depth = half - np.abs(local)  # inside: out through the nearest face
    k = int(np.argmin(depth))
    sign = 1.0 if local[k] >= 0 else -1.0
    n = R[:, k] * sign
    surface = local.copy()
    surface[k] = sign * half[k]
    return Feature(float(-depth[k] - radius), n, c + R @ surface, point, OWNER_A, rb=radius)


def closest_on_segment(p0: np.ndarray, p1: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The point of segment p0-p1 nearest to ``x``."""
    d = p1 - p0
    s = float(np.clip((x - p0) @ d / max(d @ d, 1e-300), 0.0, 1.0))
    return p0 + s * d


def segment_parameter(p0: np.ndarray, p1: np.ndarray, x: np.ndarray) -> float:
    """The parameter in [0, 1] of the point of segment p0-p1 nearest to ``x``."""
    d = p1 - p0
    return float(np.clip((x - p0) @ d / max(d @ d, 1e-300), 0.0, 1.0))


def closest_between_segments(p0, p1, q0, q1) -> tuple[np.ndarray, np.ndarray]:
    """Nearest points of segments p0-p1 and q0-q1 (parallel segments: the middle of the
    overlap, so that a capsule lying on another is held at its middle)."""
    pa, pb, _, _ = closest_parameters(p0, p1, q0, q1)
    return pa, pb


def closest_parameters(p0, p1, q0, q1) -> tuple[np.ndarray, np.ndarray, float, float]:
    """``closest_between_segments`` with the parameters s, t in [0, 1] of the two points
    (NaN for parallel segments, whose points are chosen, not nearest)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = d1 @ d1, d2 @ d2, d2 @ r
    c, b = d1 @ r, d1 @ d2
    denom = a * e - b * b
    if denom <= 1e-12 * a * e:  # parallel: overlap of the projections of q's ends on p
        s0 = np.clip([(q0 - p0) @ d1 / a, (q1 - p0) @ d1 / a], 0.0, 1.0)
        s = 0.5 * (s0.min() + s0.max())
        pa = p0 + s * d1
        return pa, closest_on_segment(q0, q1, pa), np.nan, np.nan
    s = float(np.clip((b * f - c * e) / denom, 0.0, 1.0))
    t = (b * s + f) / e
    if t < 0.0:
        t, s = 0.0, float(np.clip(-c / a, 0.0, 1.0))
    elif t > 1.0:
        t, s = 1.0, float(np.clip((b - c) / a, 0.0, 1.0))
    return p0 + s * d1, q0 + t * d2, s, t


def _axis(p0, p1, s):
    """The unit direction of segment p0-p1 when parameter s is inside it (a sliding point), else None."""
    if not 0.0 < s < 1.0:
        return None
    d = p1 - p0
    return d / np.linalg.norm(d)


def edge_edge(a: tuple, b: tuple, i: int, j: int) -> Feature:
    """Box A's edge along its axis i against box B's edge along its axis j: the edges of
    each box that lie farthest towards the other along ``L = +-(a_i x b_j)/|a_i x b_j|``
    (oriented from A's centre to B's).  When the nearest points of the two edge lines lie
    on both edges the gap is the separation along L (negative: the edges cross into each
    other); else the edges pass each other and the gap is ``max(separation, 0)`` plus how
    far the nearest points lie beyond the edges' ends (positive).  Parallel edges: the sum
    of the boxes' half diagonals (they meet through a face or a corner instead)."""
    ca, Ra, ha = a[1], a[2], a[3]
    cb, Rb, hb = b[1], b[2], b[3]
    da, db = Ra[:, i], Rb[:, j]
    u = cross(da, db)
    size = float(np.linalg.norm(u))
    if size < EDGE_PARALLEL:
        far = float(np.linalg.norm(ha) + np.linalg.norm(hb))
        return Feature(far, _UP.copy(), ca.copy(), cb.copy(), OWNER_EDGE, 0.0)
    L = u / size
    if L @ (cb - ca) < 0.0:
        L = -L
    pa0, pb0 = ca.copy(), cb.copy()
    for k in range(3):
        if k != i:
            pa0 = pa0 + (1.0 if L @ Ra[:, k] >= 0.0 else -1.0) * ha[k] * Ra[:, k]
        if k != j:
            pb0 = pb0 - (1.0 if L @ Rb[:, k] >= 0.0 else -1.0) * hb[k] * Rb[:, k]
    r = pa0 - pb0
    c = float(da @ db)
    d1, e1 = float(da @ r), float(db @ r)
    s = (c * e1 - d1) / (1.0 - c * c)
    t = e1 + c * s
    over = max(abs(s) - ha[i], 0.0) + max(abs(t) - hb[j], 0.0)
    s, t = float(np.clip(s, -ha[i], ha[i])), float(np.clip(t, -hb[j], hb[j]))
    pa, pb = pa0 + s * da, pb0 + t * db
    separation = float(L @ (pb - pa))
    if over > 0.0:
        return Feature(max(separation, 0.0) + float(over), L, pa, pb, OWNER_EDGE, 0.0)
    return Feature(separation, L, pa, pb, OWNER_EDGE, 0.0, slide_a=da.copy(), slide_b=db.copy())


#: |a_i x b_j| below this: the edges are parallel (no edge-edge contact of their own).
EDGE_PARALLEL = 1e-6


_UP = np.array([0.0, 0.0, 1.0])


def _swap(f: Feature) -> Feature:
    """The feature seen from the other side."""
    owner = {OWNER_A: OWNER_B, OWNER_B: OWNER_A}.get(f.owner, f.owner)
    return Feature(f.gap, -f.normal, f.pb, f.pa, owner, f.dist, f.rb, f.ra, f.slide_b, f.slide_a)


def features(a: tuple, b: tuple) -> list[Feature]:
    """Every candidate contact of the placed shapes ``a`` and ``b`` (``feature_count`` of them,
    in a fixed order)."""
    if not canonical(a[0], b[0]):
        return [_swap(f) for f in features(b, a)]
    kinds = (a[0], b[0])
    if kinds == ("plane", "plane"):
        return []
    if kinds == ("plane", "sphere"):
        return [_point_plane(b[1], b[2], a)]
    if kinds == ("plane", "capsule"):
        return [_point_plane(b[1], b[3], a), _point_plane(b[2], b[3], a)]
    if kinds == ("plane", "box"):
        corners = b[1] + (_CORNERS * b[3]) @ b[2].T
        o, n = a[1], a[2]
        heights = (corners - o) @ n
        feet = corners - heights[:, None] * n
        return [Feature(float(h), n, foot, p, OWNER_A) for h, foot, p in zip(heights, feet, corners)]
    if kinds == ("box", "sphere"):
        return [_point_box(b[1], b[2], a)]
    if kinds == ("box", "capsule"):
        return [_point_box(b[1], b[3], a), _point_box(b[2], b[3], a)]
    if kinds == ("box", "box"):  # corners of each against the other, then the 9 pairs of edge directions
        of_b = [_point_box(p, 0.0, a) for p in b[1] + (_CORNERS * b[3]) @ b[2].T]
        of_a = [_swap(_point_box(p, 0.0, b)) for p in a[1] + (_CORNERS * a[3]) @ a[2].T]
        return of_b + of_a + [edge_edge(a, b, i, j) for i in range(3) for j in range(3)]
    if kinds == ("capsule", "sphere"):
        s = segment_parameter(a[1], a[2], b[1])
        return [_line(a[1] + s * (a[2] - a[1]), b[1], a[3], b[2], _UP, slide_a=_axis(a[1], a[2], s))]
    if kinds == ("capsule", "capsule"):
        pa, pb, s, t = closest_parameters(a[1], a[2], b[1], b[2])
        return [_line(pa, pb, a[3], b[3], _UP, _axis(a[1], a[2], s), _axis(b[1], b[2], t))]
    if kinds == ("sphere", "sphere"):
        return [_line(a[1], b[1], a[2], b[2], _UP)]
    raise ValueError(f"no narrow phase for {kinds}")


def sliding_rates(f: Feature, dv: np.ndarray, wa: np.ndarray, wb: np.ndarray) -> tuple[float, float]:
    """Rates (m/s) at which ``f.pa`` slides along ``f.slide_a`` and ``f.pb`` along
    ``f.slide_b`` (0 for a material point), from keeping ``pb - pa`` normal to each sliding
    direction: ``dv`` the velocity of B's material point at pb relative to A's at pa, ``wa``,
    ``wb`` the bodies' angular velocities (rad/s)."""
    a, b, w = f.slide_a, f.slide_b, f.pb - f.pa
    r1 = float(dv @ a + w @ cross(wa, a)) if a is not None else 0.0
    r2 = float(dv @ b + w @ cross(wb, b)) if b is not None else 0.0
    if a is not None and b is not None:
        c = float(a @ b)
        if 1.0 - c * c < 1e-12:
            return 0.0, 0.0
        t = (c * r1 - r2) / (1.0 - c * c)
        return r1 + c * t, t
    return r1, -r2


def turning_term(f: Feature, dv: np.ndarray, wa: np.ndarray, wb: np.ndarray) -> float:
    """The part of the gap's acceleration (m/s^2, at zero generalised acceleration) beyond
    ``n . (a_b - a_a)`` (the material points' accelerations): how the normal turns and the
    contact points slide.  ``dv``, ``wa``, ``wb`` as in ``sliding_rates``.

    - a face normal fixed in A (B): ``2 (w_A x n) . dv`` (``w_B``);
    - two rounded features at distance d: with ``w' = dv + t' b - s' a`` (the points' sliding
      rates s', t' along their directions a, b): ``(|w'|^2 - (n . w')^2) / d + 2 t' n . (w_B x b)
      - 2 s' n . (w_A x a)``;
    - two edges, ``L = +-(a x b)/|a x b|``: ``L' . dv + t' L . (w_B x b) - s' L . (w_A x a)``
      (exact while the nearest points lie on both edges; outside them the points are
      taken as material)."""
    n = f.normal
    if f.owner in (OWNER_A, OWNER_B):
        return float(2.0 * cross(wa if f.owner == OWNER_A else wb, n) @ dv)
    sd, td = sliding_rates(f, dv, wa, wb)
    ta = cross(wa, f.slide_a) if f.slide_a is not None else np.zeros(3)
    tb = cross(wb, f.slide_b) if f.slide_b is not None else np.zeros(3)
    if f.owner == OWNER_LINE:
        wd = dv.copy()
        if f.slide_a is not None:
            wd = wd - sd * f.slide_a
        if f.slide_b is not None:
            wd = wd + td * f.slide_b
        along = float(n @ wd)
        return float((wd @ wd - along * along) / max(f.dist, 1e-12) + 2.0 * td * (n @ tb) - 2.0 * sd * (n @ ta))
    if f.slide_a is None or f.slide_b is None:
        return 0.0
    a, b = f.slide_a, f.slide_b
    u = cross(a, b)
    size = float(np.linalg.norm(u))
    uh = u / size
    udot = cross(ta, b) + cross(a, tb)
    ldot = (1.0 if n @ u >= 0.0 else -1.0) * (udot - uh * (uh @ udot)) / size
    return float(ldot @ dv + td * (n @ tb) - sd * (n @ ta))


# -- broad phase ----------------------------------------------------------------------------------
def near_pairs(centres: np.ndarray, radii: np.ndarray, margin: float) -> set[tuple[int, int]]:
    """Pairs ``(i, j)``, i < j, of spheres whose surfaces are within ``margin`` (m):
    ``|c_i - c_j| <= r_i + r_j + margin``.  A k-d tree (scipy's cKDTree) finds the candidates
    within ``2 max(r) + margin`` in O(n log n), and the exact test keeps the true ones: no pair
    test over all n^2 pairs."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    radii = np.asarray(radii, dtype=float).reshape(-1)
    if len(centres) < 2:
        return set()
    if len(centres) <= 16:
        return brute_force_pairs(centres, radii, margin)
    from scipy.spatial import cKDTree
    candidates = cKDTree(centres).query_pairs(2.0 * float(radii.max()) + margin, output_type="ndarray")
    if not len(candidates):
        return set()
    i, j = candidates[:, 0], candidates[:, 1]
    keep = np.linalg.norm(centres[i] - centres[j], axis=1) <= radii[i] + radii[j] + margin
    return {(int(x), int(y)) if x < y else (int(y), int(x)) for x, y in candidates[keep]}


def brute_force_pairs(centres: np.ndarray, radii: np.ndarray, margin: float) -> set[tuple[int, int]]:
    """``near_pairs`` by testing every pair (the reference the tests compare with)."""
    centres = np.asarray(centres, dtype=float).reshape(-1, 3)
    radii = np.asarray(radii, dtype=float).reshape(-1)
    d = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
    i, j = np.nonzero(np.triu(d <= radii[:, None] + radii[None, :] + margin, 1))
    return {(int(x), int(y)) for x, y in zip(i, j)}
