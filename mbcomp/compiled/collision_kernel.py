"""Collision contacts as contact rows: a kernel whose ``contacts`` adds, after the model's own
contacts, one row per candidate feature of every ``mb.Collision``.

The features are fixed when the kernel is made (each pair of collision shapes has
``collide.feature_count`` of them), so contact indices, names and persistent sets keep their
meaning through a run and every piece of the contact machinery (event location, Newton's
impact law, resting contacts held as constraints, both formulations) works on them as on a
``Contact``.  Their gaps, Jacobians and biases are computed numerically from the compiled
body kinematics at each call:

- a broad phase (``collide.near_pairs``, a k-d tree over bounding spheres, re-run at every
  call) picks the pairs whose bounding spheres come within a margin; the features of every
  other pair get a positive lower bound of their gap (the bounding spheres' clearance) and a
  zero Jacobian row, which keeps the sign of every gap right for event location;
- the narrow phase (``collide.features``) measures the rest: gap ``g``, normal ``n`` (A to
  B), points ``pa`` of body A and ``pb`` of body B; the Jacobian row is
  ``n . (J_b(pb) - J_a(pa))`` with ``J(p)`` a point's velocity columns ``v0_k + w_k x p``;
- the acceleration bias (``gddot = J qdd + bias``) is ``n . (a_b - a_a)`` at zero
  generalised acceleration, plus ``2 (w x n) . (v_b - v_a)`` for a face normal turning with
  its body, or ``(|dv|^2 - (n . dv)^2) / |pb - pa|`` for a normal along the line between two
  rounded features, with the terms of points sliding along a capsule's axis or a box's edge
  and of two edges' normal turning (``collide.turning_term``: exact).

The compiled loops compute the same numbers in C (``c/collide.c``, configured per compiled
stretch by ``CollisionKernel.compiled_stretch``: ``mbcomp.compiled.collision_c``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mbcomp.build.constraint_set import ConstraintValues
from mbcomp.build.layout import body_fields
from mbcomp.core import collide
from mbcomp.core.errors import ModelError
from mbcomp.spec.components.collision import Collision
from mbcomp.spec.components.values import name_of
from mbcomp.spec.shapes import Box, Capsule, Plane, Sphere

#: Pairs whose bounding spheres are farther apart than this fraction of their radii (plus
#: ``MARGIN_FLOOR``, m) are not measured (their gap is bounded below instead).
MARGIN_FRACTION = 0.25
MARGIN_FLOOR = 1e-6
#: A step moves no shape relative to another by more than this fraction of the thinnest
#: shape's half thickness (``CollisionKernel.step_limit``).
STEP_FRACTION = 0.5


@dataclass(frozen=True)
class CollisionFeature:
    """One candidate contact of a collision: what the contact machinery reads of a contact
    (``name``, ``restitution_key``, ``friction_key``) and where it comes from."""

    name: str
    collision: str
    pair: int      #: index of its shape pair in ``CollisionKernel.pairs``
    slot: int      #: which of the pair's features
    kind: str = "collision"

    @property
    def restitution_key(self) -> str:
        return f"{self.collision}.restitution"

    @property
    def friction_key(self) -> str:
        return f"{self.collision}.friction"


@dataclass(frozen=True)
class ShapeEntry:
    """A collision shape on a body: its kind, sizes and placement in the body frame."""

    body: str
    index: int     #: the body's index in the kinematics rows (-1: the ground)
    shape: object


@dataclass(frozen=True)
class ShapePair:
    """Two collision shapes that may touch: their entries, and where their features sit
    among the contact rows."""

    a: int           #: entries' indices
    b: int
    first: int       #: index of its first feature among all contact rows
    count: int
    restitution_key: str


def _entries_of(topology, collision, side_key):
    """The collision shapes of one side of a collision, as ``(body name, shape)``."""
    out = []
    for body, shape in getattr(collision, side_key):
        name = name_of(body)
        comp = topology.components.get(name)
        if comp is None:
            raise ModelError(collision, f"{side_key}: body {name!r} is not in the model")
        shapes = (shape,) if shape is not None else tuple(s for s in comp.shape
                                                           if isinstance(s, (Sphere, Box, Capsule, Plane)))
        if not shapes:
            raise ModelError(collision, f"{side_key}: body {name!r} has no collision shape (mb.Sphere, mb.Box, "
                                        "mb.Capsule or mb.Plane); give one as (body, shape)")
        out.extend((name, s) for s in shapes)
    return out


def _kind(shape) -> str:
    return {Sphere: "sphere", Box: "box", Capsule: "capsule", Plane: "plane"}[type(shape)]


def _bounding_radius(shape) -> float:
    """Radius (m) of a sphere about the shape's origin holding it (0 for a plane)."""
    if isinstance(shape, Sphere):
        return float(shape.radius)
    if isinstance(shape, Capsule):
        return 0.5 * float(shape.length) + float(shape.radius)
    if isinstance(shape, Box):
        return 0.5 * float(np.linalg.norm(shape.size))
    return 0.0


def _thickness(shape) -> float:
    """Half the thinnest dimension of a shape (m; a plane's is infinite)."""
    if isinstance(shape, (Sphere, Capsule)):
        return float(shape.radius)
    if isinstance(shape, Box):
        return 0.5 * float(min(shape.size))
    return np.inf


def collisions_of(topology) -> list:
    """The model's ``Collision`` components (compiled copies)."""
    return [c for c in topology.components.values() if isinstance(c, Collision)]


class RowMatrix:
    """A contact Jacobian (rows, nv) of mostly zero rows: the nonzero rows ``block`` at
    ``rows``.  ``J @ x`` and ``J[indices]`` (dense rows) are what the contact machinery uses."""

    def __init__(self, n_rows: int, head: np.ndarray, rows: np.ndarray, block: np.ndarray):
        self.head = head                  # the model's own contacts' rows (dense)
        self.rows = rows                  # indices (>= len(head)) of the nonzero collision rows
        self.block = block
        self.shape = (n_rows, head.shape[1])

    def __matmul__(self, x):
        x = np.asarray(x, dtype=float)
        out = np.zeros(self.shape[0] if x.ndim == 1 else (self.shape[0], x.shape[1]))
        out[:len(self.head)] = self.head @ x
        if len(self.rows):
            out[self.rows] = self.block @ x
        return out

    def __getitem__(self, index):
        index = np.atleast_1d(np.arange(self.shape[0])[index])
        out = np.zeros((len(index), self.shape[1]))
        where = {int(r): k for k, r in enumerate(self.rows)}
        nh = len(self.head)
        for j, i in enumerate(index):
            if i < nh:
                out[j] = self.head[i]
            elif int(i) in where:
                out[j] = self.block[where[int(i)]]
        return out

    def __array__(self, dtype=None, copy=None):
        return self[:].astype(dtype) if dtype is not None else self[:]


def shape_features(topology) -> tuple[list, list, tuple]:
    """``(entries, pairs, features)`` of a topology's collisions: its collision shapes
    (``ShapeEntry``), the pairs of them that may touch (``ShapePair``) and their features
    (``CollisionFeature``, numbered after the topology's own contacts).  ``ModelError`` for a
    collision without a pair of shapes that can touch."""
    entries: list[ShapeEntry] = []
    index = {id(b): k for k, b in enumerate(topology.bodies)}
    known: dict = {}

    def entry(body: str, shape) -> int:
        key = (body, id(shape))
        if key not in known:
            comp = topology.components[body]
            known[key] = len(entries)
            entries.append(ShapeEntry(body, index.get(id(comp), -1), shape))
        return known[key]

    shape_pairs: list[ShapePair] = []
    features = []
    first = len(topology.contacts)
    for coll in collisions_of(topology):
        side_a = [entry(*e) for e in _entries_of(topology, coll, "a")]
        side_b = [entry(*e) for e in _entries_of(topology, coll, "b")]
        seen, pairs = set(), []
        for i in side_a:
            for j in side_b:
                ea, eb = entries[i], entries[j]
                if ea.body == eb.body or (ea.index < 0 and eb.index < 0):
                    continue
                key = (min(i, j), max(i, j))
                if key in seen:
                    continue
                seen.add(key)
                count = collide.feature_count(_kind(ea.shape), _kind(eb.shape))
                if count:
                    pairs.append((i, j, count))
        total = sum(c for _, _, c in pairs)
        if total == 0:
            raise ModelError(coll, "has no pair of shapes that can touch (two bodies, not both the ground, "
                                   "and not two planes)")
        k = 0
        for i, j, count in pairs:
            shape_pairs.append(ShapePair(i, j, first, count, f"{coll.name}.restitution"))
            for slot in range(count):
                name = coll.name if total == 1 else f"{coll.name}[{k}]"
                features.append(CollisionFeature(name, coll.name, len(shape_pairs) - 1, slot))
                k += 1
            first += count
    return entries, shape_pairs, tuple(features)


class CollisionKernel:
    """A ``Kernel`` (``base``) whose contacts include the collision features; every other
    call goes to ``base``.  ``topology`` is the base topology with the features appended to
    its ``contacts``."""

    def __init__(self, base):
        import dataclasses
        self.base = base
        topology = base.topology
        self.entries, self.pairs, self.features = shape_features(topology)
        self.n_own = len(topology.contacts)
        self.topology = dataclasses.replace(topology, contacts=tuple(topology.contacts) + self.features)
        # Per-entry local geometry, for placing the shapes from the body kinematics.
        self.finite = np.array([_kind(e.shape) != "plane" for e in self.entries])
        self.pair_of = {(p.a, p.b): k for k, p in enumerate(self.pairs)}
        self.plane_pairs = np.array([k for k, p in enumerate(self.pairs) if not (self.finite[p.a] and self.finite[p.b])],
                                    dtype=int)
        # Each plane pair as (plane entry, other entry): the other's bounding sphere against the plane.
        self.plane_side = np.array([(p.a, p.b) if not self.finite[p.a] else (p.b, p.a)
                                    for p in (self.pairs[k] for k in self.plane_pairs)], dtype=int).reshape(-1, 2)
        self.pair_feature_rows = [np.arange(p.first, p.first + p.count) for p in self.pairs]
        # Per entry, constant: its body's kinematics row (-1: the ground), the shape's origin in
        # the body frame, its bounding radius about that origin (planes: 0) and a plane's normal.
        self.entry_body = np.array([e.index for e in self.entries], dtype=int)
        self.entry_local = np.array([e.shape.origin for e in self.entries], dtype=float).reshape(-1, 3)
        self.entry_radius = np.array([_bounding_radius(e.shape) for e in self.entries])
        self.entry_thickness = np.array([_thickness(e.shape) for e in self.entries])
        self.entry_normal = np.array([getattr(e.shape, "normal", (0.0, 0.0, 0.0)) for e in self.entries],
                                     dtype=float).reshape(-1, 3)

    def __getattr__(self, name):
        return getattr(self.base, name)

    def with_parameters(self, parameters) -> "CollisionKernel":
        return CollisionKernel(self.base.with_parameters(parameters))

    # -- placing the shapes -------------------------------------------------------------------
    def _bodies(self, q, qd):
        rows, columns = self.base.kinematics(q, qd)
        return body_fields(rows), columns

    def placed(self, fields, k: int) -> tuple:
        """Entry ``k``'s shape placed in the world."""
        e = self.entries[k]
        if e.index < 0:
            R, o = np.eye(3), np.zeros(3)
        else:
            R, o = fields["rotation"][e.index], fields["origin"][e.index]
        s = e.shape
        centre = o + R @ np.asarray(s.origin)
        if isinstance(s, Sphere):
            return ("sphere", centre, s.radius)
        if isinstance(s, Capsule):
            half = 0.5 * s.length * (R @ np.asarray(s.axis))
            return ("capsule", centre - half, centre + half, s.radius)
        if isinstance(s, Box):
            return ("box", centre, R @ np.reshape(s.rotation, (3, 3)), 0.5 * np.asarray(s.size))
        return ("plane", centre, R @ np.asarray(s.normal))

    def measured(self, q, qd):
        """``(pairs measured {pair index: [Feature]}, kinematics fields, columns)``: the
        narrow phase on the pairs the broad phase keeps (the last answer is kept)."""
        key = (q.tobytes(), qd.tobytes())
        last = self.__dict__.get("_last_measured")
        if last is not None and last[0] == key:
            return last[1]
        found = self._measure(q, qd)
        self.__dict__["_last_measured"] = (key, found)
        return found

    def _measure(self, q, qd):
        fields, columns = self._bodies(q, qd)
        # Every entry's bounding sphere at once: its centre is the shape's origin.
        R = np.concatenate((fields["rotation"], np.eye(3)[None]), axis=0)      # row -1: the ground
        O = np.concatenate((fields["origin"], np.zeros((1, 3))), axis=0)
        centres = O[self.entry_body] + np.einsum("eij,ej->ei", R[self.entry_body], self.entry_local)
        finite = np.flatnonzero(self.finite)
        radii = self.entry_radius[finite]
        margin = MARGIN_FRACTION * 2.0 * float(radii.max(initial=0.0)) + MARGIN_FLOOR
        near = collide.near_pairs(centres[finite], radii, margin) if len(finite) else set()
        chosen = []
        if len(self.plane_pairs):  # planes: the bounding sphere's height above the plane
            planes, others = self.plane_side[:, 0], self.plane_side[:, 1]
            n = np.einsum("eij,ej->ei", R[self.entry_body[planes]], self.entry_normal[planes])
            height = np.einsum("ij,ij->i", n, centres[others] - centres[planes]) - self.entry_radius[others]
            chosen.extend(self.plane_pairs[height <= margin].tolist())
        for i, j in near:
            a, b = int(finite[i]), int(finite[j])
            k = self.pair_of.get((a, b), self.pair_of.get((b, a)))
            if k is not None:
                chosen.append(k)
        out, placed = {}, {}
        for k in chosen:
            p = self.pairs[k]
            for e in (p.a, p.b):
                if e not in placed:
                    placed[e] = self.placed(fields, e)
            out[k] = collide.features(placed[p.a], placed[p.b])
        return out, fields, columns, (centres, self.entry_radius), margin

    # -- the contact rows ---------------------------------------------------------------------
    def contacts(self, q: np.ndarray, qd: np.ndarray) -> ConstraintValues:
        """The model's contacts, then every collision feature: gaps (m), Jacobian (a
        ``RowMatrix``), zero ``g_t``, acceleration bias.  The last answer is kept: a step's
        end is examined several times (event location, then the next step's start)."""
        key = (q.tobytes(), qd.tobytes())
        last = self.__dict__.get("_last")
        if last is not None and last[0] == key:
            return last[1]
        values = self._contacts(q, qd)
        self.__dict__["_last"] = (key, values)
        return values

    def _contacts(self, q: np.ndarray, qd: np.ndarray) -> ConstraintValues:
        own = self.base.contacts(q, qd)
        nk = self.n_own + len(self.features)
        g = np.empty(nk)
        bias = np.zeros(nk)
        g[:self.n_own], bias[:self.n_own] = own.g, own.bias
        measured, fields, columns, spheres, margin = self.measured(q, qd)
        # Unmeasured pairs: their bounding spheres are more than `margin` apart.
        g[self.n_own:] = margin
        rows, ia, ib, feats = [], [], [], []
        for k, found in measured.items():
            p = self.pairs[k]
            rows.extend(range(p.first, p.first + len(found)))
            ia.extend([self.entries[p.a].index] * len(found))
            ib.extend([self.entries[p.b].index] * len(found))
            feats.extend(found)
        nv = self.base.nv
        if feats:
            rows = np.array(rows, dtype=int)
            ia, ib = np.array(ia), np.array(ib)
            n = np.array([f.normal for f in feats])
            pa = np.array([f.pa for f in feats])
            pb = np.array([f.pb for f in feats])
            g[rows] = [f.gap for f in feats]
            masks = np.vstack((self._masks(), np.zeros((1, nv))))   # row -1: the ground
            W, V0 = columns[:, :3], columns[:, 3:]
            block = (masks[ib] * (n @ V0.T + collide.cross(pb, n) @ W.T)
                     - masks[ia] * (n @ V0.T + collide.cross(pa, n) @ W.T))
            bias[rows] = self._biases(fields, ia, ib, n, pa, pb, feats)
        else:
            rows, block = np.zeros(0, dtype=int), np.zeros((0, nv))
        J = RowMatrix(nk, np.asarray(own.J).reshape(self.n_own, nv), rows, block)
        return ConstraintValues(g, J, np.zeros(nk), bias)

    def body_masks(self) -> np.ndarray:
        """(bodies, nv): 1 where a speed moves the body (its column enters the body's velocity)."""
        return self._masks()

    def bounding_state(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per entry: its bounding sphere's centre (world, m), the speed bound of its points
        (m/s: the centre's speed plus the angular speed times the bounding radius), and
        whether it moves (a finite shape on a moving body)."""
        fields, _ = self._bodies(q, qd)
        R = np.concatenate((fields["rotation"], np.eye(3)[None]), axis=0)      # row -1: the ground
        O = np.concatenate((fields["origin"], np.zeros((1, 3))), axis=0)
        V = np.concatenate((fields["velocity"], np.zeros((1, 6))), axis=0)
        centres = O[self.entry_body] + np.einsum("eij,ej->ei", R[self.entry_body], self.entry_local)
        Ve = V[self.entry_body]
        w = Ve[:, :3]
        speeds = np.linalg.norm(Ve[:, 3:] + collide.cross(w, centres), axis=1) + np.linalg.norm(w, axis=1) * self.entry_radius
        return centres, speeds, self.finite & (self.entry_body >= 0)

    def near_pair_indices(self, centres: np.ndarray, margin: float) -> list[int]:
        """Indices of the pairs that may touch within ``margin`` (m): bounding spheres within
        it (k-d tree), a bounding sphere within it of a fixed plane, and every pair with a
        plane on a moving body."""
        finite = np.flatnonzero(self.finite)
        near = collide.near_pairs(centres[finite], self.entry_radius[finite], margin) if len(finite) else set()
        chosen = []
        if len(self.plane_pairs):
            planes, others = self.plane_side[:, 0], self.plane_side[:, 1]
            moving = self.entry_body[planes] >= 0
            n = self.entry_normal[planes]   # (fixed planes: the ground's frame is the world)
            height = np.einsum("ij,ij->i", n, centres[others] - centres[planes]) - self.entry_radius[others]
            chosen.extend(self.plane_pairs[(height <= margin) | moving].tolist())
        for i, j in near:
            a, b = int(finite[i]), int(finite[j])
            k = self.pair_of.get((a, b), self.pair_of.get((b, a)))
            if k is not None:
                chosen.append(k)
        return chosen

    def compiled_stretch(self, lib, q: np.ndarray, qd: np.ndarray, held=()):
        """The C narrow phase configured for a compiled stretch from ``(q, qd)`` with the held
        contacts ``held`` (``collision_c.CollisionStretch``: close it after the stretch)."""
        from mbcomp.compiled.collision_c import CollisionStretch
        self.base.kinematics(q, qd)   # (loads the kinematics the C calls)
        return CollisionStretch(self, lib, q, qd, held)

    def _masks(self) -> np.ndarray:
        masks = self.__dict__.get("_mask_cache")
        if masks is None:
            topology = self.base.topology
            masks = np.zeros((len(topology.bodies), self.base.nv))
            for i, body in enumerate(topology.bodies):
                masks[i, topology.speed_indices_of_body(body)] = 1.0
            self.__dict__["_mask_cache"] = masks
        return masks

    @staticmethod
    def _biases(fields, ia, ib, n, pa, pb, feats) -> np.ndarray:
        """The gaps' acceleration at zero generalised acceleration (see the module docstring)."""
        velocity = np.vstack((fields["velocity"], np.zeros((1, 6))))   # row -1: the ground
        acc = np.vstack((fields["bias"], np.zeros((1, 6))))

        def motion(index, p):
            V, A = velocity[index], acc[index]
            w = V[:, :3]
            v = V[:, 3:] + collide.cross(w, p)
            return v, A[:, 3:] + collide.cross(A[:, :3], p) + collide.cross(w, v), w

        va, aa, wa = motion(ia, pa)
        vb, ab, wb = motion(ib, pb)
        dv = vb - va
        value = np.einsum("ij,ij->i", n, ab - aa)
        owner = np.array([f.owner for f in feats])
        dist = np.array([max(f.dist, 1e-12) for f in feats])
        along = np.einsum("ij,ij->i", n, dv)
        line = (np.einsum("ij,ij->i", dv, dv) - along * along) / dist
        w = np.where((owner == collide.OWNER_A)[:, None], wa, wb)
        face = 2.0 * np.einsum("ij,ij->i", collide.cross(w, n), dv)
        out = value + np.where(owner == collide.OWNER_LINE, line, face)
        for k, f in enumerate(feats):  # sliding points and edge pairs: their own terms
            if f.owner == collide.OWNER_EDGE or f.slide_a is not None or f.slide_b is not None:
                out[k] = value[k] + collide.turning_term(f, dv[k], wa[k], wb[k])
        return out

    def gap_of(self, q: np.ndarray, qd: np.ndarray, index: int) -> float:
        """Contact ``index``'s gap (m) alone: a collision feature's exact gap from its own pair
        of shapes (no broad phase), for locating its closing."""
        if index < self.n_own:
            return float(self.base.contacts(q, qd).g[index])
        feature = self.features[index - self.n_own]
        pair = self.pairs[feature.pair]
        fields, _ = self._bodies(q, qd)
        return float(collide.features(self.placed(fields, pair.a), self.placed(fields, pair.b))[feature.slot].gap)

    def tangent_rows(self, q: np.ndarray, qd: np.ndarray, indices) -> dict:
        """Friction rows of the collision features among the contact ``indices``:
        ``{position in indices: (basis (3, 3) rows n, t1, t2 with n from B to A; tangent rows (2, nv); their
        bias (2,); touching point (3,) m; friction coefficient)}``, all world frame.  The
        tangent rows give the slip velocity of B's touching point relative to A's; their
        bias is the points' acceleration at zero generalised acceleration (the turning of
        the basis left out, as for a fixed plane)."""
        wanted = {int(i): r for r, i in enumerate(indices) if int(i) >= self.n_own}
        if not wanted:
            return {}
        measured, fields, columns, _, _ = self.measured(q, qd)
        masks = np.vstack((self._masks(), np.zeros((1, self.base.nv))))
        W, V0 = columns[:, :3], columns[:, 3:]
        velocity = np.vstack((fields["velocity"], np.zeros((1, 6))))
        acc = np.vstack((fields["bias"], np.zeros((1, 6))))
        out = {}
        for k, feats in measured.items():
            p = self.pairs[k]
            ia, ib = self.entries[p.a].index, self.entries[p.b].index
            for slot, f in enumerate(feats):
                row = wanted.get(p.first + slot)
                if row is None:
                    continue
                basis = np.vstack((f.normal, tangent_plane(f.normal)))
                ca, cb = f.touching_points()
                T = basis[1:]

                def point_rows(index, c, material):
                    Jc = masks[index][None, :] * (V0.T + (collide.cross(W, c[None, :])).T)   # (3, nv)
                    V, A = velocity[index], acc[index]
                    v_p = V[3:] + collide.cross(V[:3], material)
                    return Jc, A[3:] + collide.cross(A[:3], c) + collide.cross(V[:3], v_p)

                Jb, ab = point_rows(ib, cb, f.pb)
                Ja, aa = point_rows(ia, ca, f.pa)
                mu = float(self.base.parameters[self.features[p.first - self.n_own + slot].friction_key])
                # The basis as seen from A (n from B to A): the force these rows give is the one
                # on A's body, the collision's side ``a``; the tangential rows are unchanged.
                out[row] = (-basis, T @ (Jb - Ja), T @ (ab - aa), 0.5 * (ca + cb), mu)
        return out

    def step_limit(self, q: np.ndarray, qd: np.ndarray) -> float:
        """The longest step (s) after which no two shapes can have passed through each other
        unseen: in it no shape moves by more than ``STEP_FRACTION`` of the thinnest shape's
        half thickness relative to another (gaps are only checked at the ends of steps)."""
        fields, _ = self._bodies(q, qd)
        moving = self.finite & (self.entry_body >= 0)
        if not moving.any():
            return np.inf
        rows = self.entry_body[moving]
        R, O, V = fields["rotation"][rows], fields["origin"][rows], fields["velocity"][rows]
        centres = O + np.einsum("eij,ej->ei", R, self.entry_local[moving])
        w = V[:, :3]
        speeds = (np.linalg.norm(V[:, 3:] + collide.cross(w, centres), axis=1)
                  + np.linalg.norm(w, axis=1) * self.entry_radius[moving])
        total = float(np.sort(speeds)[-2:].sum())
        thin = float(self.entry_thickness[self.finite].min())
        return np.inf if not total > 0 else STEP_FRACTION * thin / total

    def contact_points(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """World point (m) midway between the touching surface points of every feature the
        broad phase measures at ``q`` (for drawing contacts)."""
        measured, *_ = self.measured(q, np.zeros(self.base.nv))
        out = {}
        for k, feats in measured.items():
            p = self.pairs[k]
            for slot, f in enumerate(feats):
                ca, cb = f.touching_points()
                out[self.features[p.first - self.n_own + slot].name] = 0.5 * (ca + cb)
        return out


def tangent_plane(normal: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal tangents t1, t2 of a unit normal with t1 x t2 = normal."""
    e = np.eye(3)[int(np.argmin(np.abs(normal)))]
    t1 = collide.cross(normal, e)
    t1 = t1 / np.linalg.norm(t1)
    return np.array([t1, collide.cross(normal, t1)])


def with_collisions(kernel):
    """``kernel`` itself when its model has no ``Collision``, else a ``CollisionKernel``."""
    if isinstance(kernel, CollisionKernel) or not collisions_of(kernel.topology):
        return kernel
    return CollisionKernel(kernel)
