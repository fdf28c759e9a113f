"""What a drawing of a motion shows, shared by plots, animations and the 3D viewer: the
points of interest on each body, its default rods, the marks (joints, springs, sliders,
contacts), every body's pose, and the motion resampled at display times.

Resampling is correct for quaternion joints (``Ball``, ``Free``): q is interpolated by cubic
Hermite polynomials through the samples with the coordinate rates ``q' = G(q) v`` (a
quaternion's rate from its angular velocity, not the speeds themselves), each quaternion is
then brought back to unit length.  Poses come from the System's own kinematics, so what is
drawn is what mbcomp computed.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.spatial.transform import Rotation

from mbcomp.core.errors import ModelError
from mbcomp.build.layout import body_fields

__all__ = ["pieces", "resample", "resample_result", "local_value", "Scene"]


def pieces(t: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` index ranges between repeated sample times (an impact repeats its time
    with the speeds before and after; q is continuous there, the speeds jump)."""
    t = np.asarray(t, dtype=float)
    breaks = np.flatnonzero(np.diff(t) <= 0) + 1
    return [(a, b) for a, b in zip([0, *breaks], [*breaks, len(t)]) if b > a]


def resample(t: np.ndarray, q: np.ndarray, times: np.ndarray, rates: np.ndarray | None = None,
             normalize: Any = None) -> np.ndarray:
    """Rows of ``q`` (samples at times ``t``, s) interpolated at ``times``.

    With ``rates`` (dq/dt at the samples, q's shape): cubic Hermite through values and rates,
    exact for cubics, fourth-order accurate; without: linear.  Each piece between impacts is
    interpolated on its own (a later piece wins at a shared time).  ``normalize``, when given,
    maps the interpolated rows back onto the configuration space (unit quaternions).
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float).reshape(len(t), -1)
    times = np.asarray(times, dtype=float)
    if rates is not None:
        rates = np.asarray(rates, dtype=float).reshape(len(t), -1)
        if rates.shape != q.shape:
            raise ModelError("resample", f"rates have shape {rates.shape}, the coordinates {q.shape}: "
                                         "give dq/dt (System.topology.state_map.qdot turns speeds into rates)")
    out = np.repeat(q[:1], len(times), axis=0)
    for start, stop in pieces(t):
        piece = t[start:stop]
        inside = (times >= piece[0]) & (times <= piece[-1])
        if not np.any(inside) or q.shape[1] == 0:
            continue
        if stop - start == 1:
            out[inside] = q[start]
        elif rates is not None:
            out[inside] = CubicHermiteSpline(piece, q[start:stop], rates[start:stop], axis=0)(times[inside])
        else:
            out[inside] = np.column_stack([np.interp(times[inside], piece, q[start:stop, i])
                                           for i in range(q.shape[1])])
    return out if normalize is None else normalize(out)


def resample_result(result: Any, times: np.ndarray) -> np.ndarray:
    """The configurations of a simulation result at ``times`` (s), shape ``(len(times), nq)``:
    Hermite through q and ``q' = G(q) v`` per piece between impacts, quaternions renormalised."""
    state_map = result.system.topology.state_map
    t = np.asarray(result.t, dtype=float)
    q, v = np.asarray(result.q, dtype=float), np.asarray(result.qd, dtype=float)
    rates = state_map.qdot(q, v) if len(t) and v.shape[-1] == state_map.nv else None
    return resample(t, q, times, rates, state_map.normalize)


def local_value(system: Any, comp: Any, attr: str) -> np.ndarray:
    """A component's vector at the system's current parameter value (parameters can be
    rebound without recompiling, so the component's own attribute may be stale)."""
    value = system.parameters.get(f"{comp.name}.{attr}", getattr(comp, attr))
    return np.asarray(value, dtype=float).reshape(3)


def _placed(comp: Any) -> bool:
    """True for a component fixed at one body point (``body`` reference and ``point`` value;
    a joint stop's sides are coordinate gaps, not components with references)."""
    spec = getattr(comp, "spec", None)
    return getattr(comp, "refs", {}).get("body") == "body" and spec is not None and spec("point") is not None


class Scene:
    """The drawing of a compiled system, as body-frame points resolved per configuration.

    Bodies are numbered as in ``names``: 0 is the ground, ``k + 1`` is ``bodies[k]``.  Every
    point of interest (joint locations, spring ends, slider and contact points, each body's
    COM) is one row of ``locals_array`` (body frame, m) owned by ``owner_array``.  A body
    is drawn from its ``shapes``, or without them as ``rods``: one from its COM to each of its
    points.
    """

    def __init__(self, system: Any):
        self.system = system
        topology = system.topology
        self.topology = topology
        self.ground = topology.ground
        self.bodies = list(topology.bodies)
        self.names = [topology.ground.name] + [b.name for b in self.bodies]
        self.index_of = {name: i for i, name in enumerate(self.names)}
        self.locals: list[np.ndarray] = []              # body-frame points, one row each
        self.owner: list[int] = []                      # index into names
        self.links: list[tuple[int, int]] = []          # joint gaps: prismatic travel, loop closures
        self.springs: list[tuple[int, int]] = []        # two-point force elements
        self.ground_marks: list[int] = []               # points on the ground
        self.joint_marks: list[int] = []                # joint locations on the moving side
        self.com_points: list[int] = []
        self.sliders: list[tuple[np.ndarray, np.ndarray]] = []   # (origin, axis), world frame
        on_body: dict[int, list[int]] = {k: [] for k in range(1, len(self.names))}

        def add(body: Any, local: np.ndarray) -> int:
            self.locals.append(np.asarray(local, dtype=float))
            self.owner.append(self.body_index(body))
            return len(self.locals) - 1

        def attach(body: Any, local: np.ndarray) -> int:
            index = add(body, local)
            if self.owner[index] == 0:
                self.ground_marks.append(index)
            else:
                on_body[self.owner[index]].append(index)
            return index

        for joint in topology.tree_joints:
            on_parent = attach(joint.parent, local_value(system, joint, "parent_point"))
            hub = attach(joint.child, local_value(system, joint, "child_point"))
            self.joint_marks.append(hub)
            self.links.append((on_parent, hub))
        for joint in getattr(topology, "cut_joints", ()):
            a = attach(joint.parent, local_value(system, joint, "parent_point"))
            b = attach(joint.child, local_value(system, joint, "child_point"))
            self.joint_marks.extend((a, b))
            self.links.append((a, b))
        for comp in getattr(topology, "forces", ()):
            ends = [role for role, how in getattr(comp, "refs", {}).items() if how == "attachment"]
            if len(ends) == 2:
                a, b = (attach(getattr(comp, f"body_{role}"), local_value(system, comp, f"point_{role}")) for role in ends)
                self.springs.append((a, b))
            elif _placed(comp):
                attach(comp.body, local_value(system, comp, "point"))
        for comp in tuple(getattr(topology, "constraints", ())) + tuple(getattr(topology, "contacts", ())):
            if _placed(comp):
                attach(comp.body, local_value(system, comp, "point"))
            if getattr(comp, "kind", "") == "slider":
                self.sliders.append((local_value(system, comp, "origin"), np.asarray(comp.axis, dtype=float)))
        self.rods: list[tuple[int, int, int]] = []      # (COM point, other point, index in bodies)
        for k, body in enumerate(self.bodies, start=1):
            com = add(body, local_value(system, body, "com"))
            self.com_points.append(com)
            seen: list[np.ndarray] = []
            for other in on_body[k]:
                p = self.locals[other]
                if np.allclose(p, self.locals[com], rtol=0, atol=1e-12) or any(np.array_equal(p, s) for s in seen):
                    continue
                seen.append(p)
                self.rods.append((com, other, k - 1))
        if not self.ground_marks:
            self.ground_marks.append(add(self.ground, np.zeros(3)))
        self.locals_array = np.array(self.locals, dtype=float).reshape(-1, 3)
        self.owner_array = np.array(self.owner, dtype=int)
        self.masses = np.array([float(system.parameters.get(f"{b.name}.mass", b.mass)) for b in self.bodies])
        #: Each body's own shapes (``mb.Box``, ...; empty: drawn as ``rods``), and the ground's.
        self.shapes = [tuple(getattr(b, "shape", ()) or ()) for b in self.bodies]
        self.ground_shapes = tuple(getattr(self.ground, "shape", ()) or ())
        self._fast: bool | None = None

    def body_index(self, ref: Any) -> int:
        """The number of a body or body reference in ``names`` (0 for the ground)."""
        return self.index_of[self.topology.resolve(ref).name]

    # -- kinematics -----------------------------------------------------------------------------
    def _poses_public(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R_WB, p_WB) of every body through the public ``body_state`` (ground first)."""
        rotations, origins = [np.eye(3)], [np.zeros(3)]
        for body in self.bodies:
            state = self.system.body_state(body, q, point=(0.0, 0.0, 0.0))
            rotations.append(state.rotation)
            origins.append(state.position)
        return np.array(rotations), np.array(origins)

    def _poses_fast(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The same from one evaluation of the generated kinematics (no accelerations)."""
        kernel = self.system.kernel
        per_body = body_fields(kernel.kinematics(q, np.zeros(kernel.nv))[0])
        rotations = np.concatenate([np.eye(3)[None], per_body["rotation"]])
        origins = np.concatenate([np.zeros((1, 3)), per_body["origin"]])
        return rotations, origins

    def poses(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(rotations (n+1, 3, 3), origins (n+1, 3))``: every body frame in the world at
        configuration ``q``, the ground first."""
        q = np.asarray(q, dtype=float)
        if self._fast is None:
            # The fast path is used only once it agrees with the public API at this configuration
            # (body_state also evaluates accelerations, which can fail off the constraints, e.g.
            # at a drifted sample; then the kinematics alone are all there is to go on).
            try:
                reference, failure = self._poses_public(q), None
            except Exception as exc:     # noqa: BLE001 - fall back to the kinematics below
                reference, failure = None, exc
            try:
                fast = self._poses_fast(q)
            except Exception:            # noqa: BLE001 - any failure means: use the public API
                fast = None
            if reference is None:
                if fast is None:
                    raise failure
                self._fast = True
                return fast
            self._fast = fast is not None and all(np.allclose(a, b, rtol=1e-9, atol=1e-9)
                                                  for a, b in zip(fast, reference))
            return reference
        return self._poses_fast(q) if self._fast else self._poses_public(q)

    def body_poses(self, qs: np.ndarray) -> np.ndarray:
        """(frames, bodies, 7): each body frame's origin (m, world) and rotation as a quaternion
        (x, y, z, w) at each configuration of ``qs`` (the ground left out)."""
        qs = np.asarray(qs, dtype=float).reshape(-1, self.topology.nq)
        out = np.zeros((len(qs), len(self.bodies), 7))
        for f, q in enumerate(qs):
            rotations, origins = self.poses(q)
            out[f, :, :3] = origins[1:]
            if self.bodies:
                out[f, :, 3:] = Rotation.from_matrix(rotations[1:]).as_quat()
        if not np.all(np.isfinite(out)):
            raise ModelError("scene", "the motion has non-finite body poses; nothing sensible to draw")
        return out

    def points(self, q: np.ndarray) -> np.ndarray:
        """(npoints, 3) world positions (m) of every scene point at configuration ``q``."""
        rotations, origins = self.poses(np.asarray(q, dtype=float))
        R = rotations[self.owner_array]
        return origins[self.owner_array] + np.einsum("nij,nj->ni", R, self.locals_array)

    def all_points(self, qs: np.ndarray) -> np.ndarray:
        """(nframes, npoints, 3) world positions for a sequence of configurations."""
        return np.array([self.points(q) for q in qs]).reshape(len(qs), -1, 3)

    def points_on(self, k: int) -> list[int]:
        """Rows of ``locals_array`` on body number ``k`` (0: the ground)."""
        return [i for i, owner in enumerate(self.owner) if owner == k]
