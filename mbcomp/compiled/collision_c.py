"""Collision features in the compiled loops: the per-thread configuration of the C narrow
phase (``codegen/c/collide.c``) for one compiled stretch between contact events.

The broad phase stays out of the per-step work.  At the start of a stretch Python picks the
candidate pairs (``collide.near_pairs``, a k-d tree over the shapes' bounding spheres, and
the bounding spheres' heights over planes) within a margin ``STRETCH_MARGIN`` times the
largest bounding radius; C then measures only the candidates' features after every step
(their gaps for the contact watch, their rows for the held ones).  The stretch ends, and
the next one picks its candidates afresh, when a moving shape's bounding-sphere centre has
drifted by half the margin from where it started (two shapes then cannot have come within
reach of each other unseen) or when the two fastest shapes together move faster than the
speed the stretch's step limit was set for (``ceiling``): the loop's watch reports an
event that Python does not confirm, and the driver carries on (``go_on``).

The step limit of a stretch (``step_cap``, s) keeps a step from carrying a shape through
another (gaps are only checked at the ends of steps): ``STEP_FRACTION`` of the thinnest
shape's half thickness over the ceiling speed, the ceiling twice the start's speed and at
least ``sqrt(|gravity| thickness)`` (a shape falling from rest moves an eighth of its
thickness in a step).
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.core import collide

#: Candidate pairs: bounding spheres within this many times the largest bounding radius.
STRETCH_MARGIN = 4.0
#: A step moves no shape relative to another by more than this fraction of the thinnest
#: shape's half thickness (as ``collision_kernel.STEP_FRACTION``).
STEP_FRACTION = 0.5
#: Doubles of an entry's geometry in C (``MBC_GEO``) and of a candidate's output head.
GEO, OUT_HEAD = 17, 2

_VOID, _INT, _DBL = ctypes.c_void_p, ctypes.c_int, ctypes.c_double


def _ptr(array: np.ndarray) -> int:
    return array.__array_interface__["data"][0]


def shape_tables(kernel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The C tables of a ``CollisionKernel``'s shapes and features: ``feat`` (features x 3:
    entry a, entry b, slot), ``ekind`` (entries x 2: kind as ``collide.ORDER``, body row or
    -1), ``egeo`` (entries x ``GEO``: origin, rotation, half edges / axis / normal, radius,
    length; body frame, m) and ``mask`` (bodies x nv: 1 where a speed moves the body)."""
    from mbcomp.spec.shapes import Box, Capsule, Plane, Sphere
    feat = np.array([(kernel.pairs[f.pair].a, kernel.pairs[f.pair].b, f.slot) for f in kernel.features],
                    dtype=np.int64).reshape(-1, 3)
    ekind = np.zeros((len(kernel.entries), 2), dtype=np.int64)
    egeo = np.zeros((len(kernel.entries), GEO))
    for k, e in enumerate(kernel.entries):
        s = e.shape
        kind = {Sphere: "sphere", Box: "box", Capsule: "capsule", Plane: "plane"}[type(s)]
        ekind[k] = (collide.ORDER.index(kind), e.index)
        egeo[k, :3] = s.origin
        egeo[k, 3:12] = np.eye(3).ravel()
        if kind == "box":
            egeo[k, 3:12] = np.reshape(s.rotation, 9)
            egeo[k, 12:15] = 0.5 * np.asarray(s.size, dtype=float)
        elif kind == "capsule":
            egeo[k, 12:15] = s.axis
            egeo[k, 15], egeo[k, 16] = s.radius, s.length
        elif kind == "plane":
            egeo[k, 12:15] = s.normal
        else:
            egeo[k, 15] = s.radius
    mask = np.ascontiguousarray(kernel.body_masks(), dtype=float)
    return np.ascontiguousarray(feat), ekind, np.ascontiguousarray(egeo), mask


def _bind(lib):
    configure = lib.mb_collide_configure
    configure.argtypes = [_INT, _VOID, _VOID, _VOID, _VOID, _INT, _VOID, _VOID, _VOID, _VOID, _INT, _VOID, _VOID,
                          _VOID, _DBL, _DBL]
    configure.restype = ctypes.c_int
    return configure


class CollisionStretch:
    """The C narrow phase configured for one compiled stretch from ``(q, qd)`` with the held
    contacts ``held`` (contact indices); the arrays the C reads live as long as this
    object.  ``step_cap`` (s): the longest step of the stretch; ``candidates``: the feature
    indices measured in C; ``close()`` switches the C off."""

    def __init__(self, kernel, lib, q: np.ndarray, qd: np.ndarray, held=()):
        self.lib = lib
        tables = kernel.__dict__.get("_c_tables")
        if tables is None:
            tables = kernel.__dict__["_c_tables"] = shape_tables(kernel)
        self.feat, self.ekind, self.egeo, self.mask = tables
        centres, speeds, moving = kernel.bounding_state(q, qd)
        radius = kernel.entry_radius
        finite = np.flatnonzero(kernel.finite)
        rmax = float(radius[finite].max(initial=0.0))
        margin = STRETCH_MARGIN * rmax + collide_margin_floor()
        chosen = set(kernel.near_pair_indices(centres, margin))
        n_own = kernel.n_own
        for i in held:
            if int(i) >= n_own:
                chosen.add(kernel.features[int(i) - n_own].pair)
        cand = [f for k in sorted(chosen) for f in range(kernel.pairs[k].first - n_own,
                                                           kernel.pairs[k].first - n_own + kernel.pairs[k].count)]
        self.candidates = np.ascontiguousarray(cand, dtype=np.int64).reshape(-1)
        self.slot = np.full(len(kernel.features), -1, dtype=np.int64)
        self.slot[self.candidates] = np.arange(len(self.candidates))
        nv = kernel.base.nv
        self.out = np.zeros((max(len(self.candidates), 1), OUT_HEAD + nv))
        self.kin = np.zeros(kernel.base.compiled.output_layout.size("kinematics") + 1)
        self.went = np.ascontiguousarray(np.flatnonzero(moving), dtype=np.int64)
        self.wcentre = np.ascontiguousarray(centres[self.went]).reshape(-1)
        self.wradius = np.ascontiguousarray(radius[self.went], dtype=float)
        top = np.sort(speeds[self.went])[-2:].sum() if len(self.went) else 0.0
        thin = float(kernel.entry_thickness[finite].min(initial=np.inf))
        gravity = float(np.linalg.norm(np.asarray(kernel.base.parameters.get("gravity", (0.0, 0.0, -9.81)),
                                                  dtype=float)))
        floor = np.sqrt(max(gravity, 1e-3) * thin) if np.isfinite(thin) else 0.0
        self.ceiling = max(2.0 * float(top), floor)
        self.step_cap = STEP_FRACTION * thin / self.ceiling if self.ceiling > 0.0 and np.isfinite(thin) else np.inf
        self.drift = 0.5 * margin
        status = _bind(lib)(len(self.feat), _ptr(self.feat), _ptr(self.ekind), _ptr(self.egeo), _ptr(self.mask),
                            len(self.candidates), _ptr(self.candidates), _ptr(self.slot), _ptr(self.out),
                            _ptr(self.kin), len(self.went), _ptr(self.went), _ptr(self.wcentre) if len(self.went) else None,
                            _ptr(self.wradius) if len(self.went) else None, self.drift, self.ceiling)
        if status:
            raise RuntimeError(f"mb_collide_configure failed ({status})")

    def evaluate(self, q: np.ndarray, qd: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The candidates' rows at ``(q, qd)`` computed in C: (candidates, 2 + nv) with the
        gap (m), the acceleration bias (m/s^2) and the Jacobian row (for tests)."""
        fn = self.lib.mb_collide_eval
        fn.argtypes = [_VOID, _VOID, _VOID]
        fn.restype = None
        q, qd, p = (np.ascontiguousarray(x, dtype=float) for x in (q, qd, p))
        fn(_ptr(q), _ptr(qd), _ptr(p))
        return self.out[:len(self.candidates)].copy()

    def close(self) -> None:
        _bind(self.lib)(-1, None, None, None, None, 0, None, None, None, None, 0, None, None, None, 0.0, 0.0)

    def __enter__(self) -> "CollisionStretch":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def collide_margin_floor() -> float:
    """The smallest candidate margin (m), for shapes of zero size."""
    return 1e-6
