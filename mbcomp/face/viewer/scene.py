"""What the 3D viewer shows, computed in Python: the bodies' shapes in their own frames, the
joint, spring and contact marks, and every body's pose at evenly spaced times.

The page only places these body-frame shapes with the poses computed here from the System's
own kinematics (``System.body_state``), so what it shows is what mbcomp computed.
"""
from __future__ import annotations

import base64
import warnings
from typing import Any

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.spatial.transform import Rotation

from mbcomp.core.errors import ModelError
from mbcomp.spec.shapes import Box, Cylinder, Mesh, Sphere

#: Colors given to bodies without their own, in turn (Tableau 10, readable on a light background).
PALETTE = ("#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#76b7b2", "#edc948", "#b07aa1", "#ff9da7",
           "#9c755f", "#bab0ac")


def frame_times(t: np.ndarray, fps: float, max_frames: int) -> np.ndarray:
    """Evenly spaced display times over the simulated span (s): ``fps`` per simulated second,
    at least 2 and at most ``max_frames`` of them."""
    t0, t1 = float(t[0]), float(t[-1])
    if not t1 > t0:
        return np.array([t0])
    count = int(min(max(round((t1 - t0) * fps) + 1, 2), max_frames))
    return np.linspace(t0, t1, count)


def _pieces(t: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges between repeated sample times (an impact repeats its time: q continuous,
    speeds jump)."""
    cuts = [0] + [i + 1 for i in range(len(t) - 1) if t[i + 1] <= t[i]] + [len(t)]
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]


def resample(t: np.ndarray, q: np.ndarray, times: np.ndarray, qd: np.ndarray | None) -> np.ndarray:
    """q at ``times``: cubic Hermite through the samples and their speeds when ``qd`` has q's
    shape (each piece between impacts separately), linear interpolation otherwise."""
    q = np.asarray(q, dtype=float).reshape(len(t), -1)
    out = np.repeat(q[:1], len(times), axis=0)
    hermite = qd is not None and np.shape(qd) == q.shape
    for start, stop in _pieces(t):
        piece = t[start:stop]
        inside = (times >= piece[0]) & (times <= piece[-1])
        if not np.any(inside) or q.shape[1] == 0:
            continue
        if stop - start == 1:
            out[inside] = q[start]
        elif hermite:
            out[inside] = CubicHermiteSpline(piece, q[start:stop], qd[start:stop], axis=0)(times[inside])
        else:
            out[inside] = np.column_stack([np.interp(times[inside], piece, q[start:stop, i])
                                           for i in range(q.shape[1])])
    return out


def _value(system: Any, comp: Any, attr: str) -> np.ndarray:
    """A component's body-frame vector at the system's current parameter value."""
    value = system.parameters.get(f"{comp.name}.{attr}", getattr(comp, attr))
    return np.asarray(value, dtype=float).reshape(3)


def _placement(shape: Any) -> list[float]:
    """[x, y, z, qx, qy, qz, qw]: the shape frame in the body frame."""
    quat = Rotation.from_matrix(np.reshape(shape.rotation, (3, 3))).as_quat()
    return [*map(float, shape.origin), *map(float, quat)]


def _b64(array: np.ndarray, dtype: str) -> str:
    return base64.b64encode(np.ascontiguousarray(array, dtype=dtype).tobytes()).decode("ascii")


def shape_record(shape: Any, color: str) -> dict:
    """One shape as the page draws it (sizes in m, placement in the body frame)."""
    record: dict[str, Any] = {"place": _placement(shape), "color": shape.color or color}
    if isinstance(shape, Box):
        record.update(type="box", size=list(shape.size))
    elif isinstance(shape, Cylinder):
        # The page's cylinders run along their local y axis: turn y onto the shape's axis.
        turn = Rotation.align_vectors([shape.axis], [[0.0, 1.0, 0.0]])[0]
        R = np.reshape(shape.rotation, (3, 3)) @ turn.as_matrix()
        record.update(type="cylinder", radius=shape.radius, length=shape.length,
                      place=[*map(float, shape.origin), *map(float, Rotation.from_matrix(R).as_quat())])
    elif isinstance(shape, Sphere):
        record.update(type="sphere", radius=shape.radius)
    elif isinstance(shape, Mesh):
        vertices, faces = shape.triangles()
        record.update(type="mesh", vertices=_b64(vertices, "<f4"), faces=_b64(faces, "<u4"))
    else:  # pragma: no cover - as_shapes admits only the classes above
        raise ModelError("viewer", f"cannot draw {shape!r}")
    return record


def _records(shapes: Any, color: str, owner: str) -> list[dict]:
    """Shape records; a mesh that cannot be read is left out with a warning (the body is then
    drawn from its other shapes, or as a stick figure), so one bad file does not stop the page."""
    records = []
    for shape in shapes:
        try:
            records.append(shape_record(shape, color))
        except ModelError as exc:
            warnings.warn(f"viewer: body {owner!r}: {exc}; drawn without it", UserWarning, stacklevel=3)
    return records


class SceneBuilder:
    """The static scene of a compiled system and its body poses at given configurations."""

    def __init__(self, system: Any):
        self.system = system
        topology = system.topology
        self.topology = topology
        self.bodies = list(topology.bodies)
        self.index = {b.name: k for k, b in enumerate(self.bodies)}
        self.index[topology.ground.name] = -1

    def body_of(self, ref: Any) -> int:
        """Index of a body in ``bodies`` (-1 for the ground)."""
        return self.index[self.topology.resolve(ref).name]

    # -- poses ----------------------------------------------------------------------------------
    def poses(self, qs: np.ndarray) -> np.ndarray:
        """(frames, bodies, 7) body frame poses in the world: position (m) then the rotation as
        a quaternion (x, y, z, w), from ``System.body_state`` at each configuration."""
        out = np.zeros((len(qs), len(self.bodies), 7))
        origin = (0.0, 0.0, 0.0)
        for f, q in enumerate(qs):
            rotations = np.empty((len(self.bodies), 3, 3))
            for k, body in enumerate(self.bodies):
                state = self.system.body_state(body, q, point=origin)
                out[f, k, :3] = state.position
                rotations[k] = state.rotation
            if len(self.bodies):
                out[f, :, 3:] = Rotation.from_matrix(rotations).as_quat()
        if not np.all(np.isfinite(out)):
            raise ModelError("viewer", "the motion has non-finite body poses; nothing sensible to draw")
        return out

    # -- the static scene ------------------------------------------------------------------------
    def points_of_interest(self) -> dict[int, list[np.ndarray]]:
        """Body-frame points on each body: joints, spring ends, slider and contact points."""
        system, points = self.system, {k: [] for k in range(-1, len(self.bodies))}
        for joint in tuple(self.topology.tree_joints) + tuple(self.topology.cut_joints):
            points[self.body_of(joint.parent)].append(_value(system, joint, "parent_point"))
            points[self.body_of(joint.child)].append(_value(system, joint, "child_point"))
        for comp in self.topology.forces:
            if hasattr(comp, "body_a") and hasattr(comp, "body_b"):
                points[self.body_of(comp.body_a)].append(_value(system, comp, "point_a"))
                points[self.body_of(comp.body_b)].append(_value(system, comp, "point_b"))
            elif hasattr(comp, "body") and hasattr(comp, "point"):
                points[self.body_of(comp.body)].append(_value(system, comp, "point"))
        for comp in tuple(self.topology.constraints) + tuple(self.topology.contacts):
            if hasattr(comp, "body") and hasattr(comp, "point"):
                points[self.body_of(comp.body)].append(_value(system, comp, "point"))
        return points

    def default_shapes(self, k: int, size: float, points: list[np.ndarray], mass_ratio: float) -> list[dict]:
        """A body without shapes: a rod from each of its points to the COM, a ball at the COM
        (its volume growing with the mass)."""
        body = self.bodies[k]
        com = _value(self.system, body, "com")
        color = PALETTE[k % len(PALETTE)]
        radius = size * 0.045 * max(mass_ratio, 0.05) ** (1.0 / 3.0)
        records = [{"type": "sphere", "radius": radius, "place": [*com, 0.0, 0.0, 0.0, 1.0], "color": color}]
        seen: list[np.ndarray] = []
        for p in points:
            if np.linalg.norm(p - com) < 1e-9 * max(size, 1e-300) or any(np.allclose(p, s) for s in seen):
                continue
            seen.append(p)
            records.append({"type": "rod", "a": [*map(float, p)], "b": [*map(float, com)],
                            "radius": size * 0.012, "color": color})
        return records

    def marks(self, size: float) -> dict:
        """Joints, springs, sliders and contacts as the page marks them."""
        system = self.system
        joints = []
        for joint in tuple(self.topology.tree_joints) + tuple(self.topology.cut_joints):
            kind = type(joint).__name__.lower()
            axis = getattr(joint, "axis", None)
            if axis is not None and hasattr(joint, "child_frame_rotation"):
                # The axis is in the joint frame, which sits rotated in the child body.
                axis = np.asarray(joint.child_frame_rotation, dtype=float) @ np.asarray(axis, dtype=float)
            joints.append({"name": joint.name, "kind": kind, "body": self.body_of(joint.child),
                           "point": [*map(float, _value(system, joint, "child_point"))],
                           "parent": self.body_of(joint.parent),
                           "parent_point": [*map(float, _value(system, joint, "parent_point"))],
                           "axis": None if axis is None else [*map(float, axis)]})
        springs = []
        for comp in self.topology.forces:
            if hasattr(comp, "body_a") and hasattr(comp, "body_b"):
                springs.append({"name": comp.name, "a": self.body_of(comp.body_a),
                                "pa": [*map(float, _value(system, comp, "point_a"))],
                                "b": self.body_of(comp.body_b),
                                "pb": [*map(float, _value(system, comp, "point_b"))]})
        contacts, sliders = [], []
        for comp in self.topology.contacts:
            if not all(hasattr(comp, a) for a in ("body", "point", "origin", "normal")):
                continue   # e.g. a joint stop: a coordinate gap, nothing to mark in space
            contacts.append({"name": comp.name, "body": self.body_of(comp.body),
                             "point": [*map(float, _value(system, comp, "point"))],
                             "origin": [*map(float, _value(system, comp, "origin"))],
                             "normal": [*map(float, comp.normal)]})
        for comp in self.topology.constraints:
            if type(comp).__name__ == "Slider":
                sliders.append({"name": comp.name, "body": self.body_of(comp.body),
                                "point": [*map(float, _value(system, comp, "point"))],
                                "origin": [*map(float, _value(system, comp, "origin"))],
                                "axis": [*map(float, comp.axis)]})
        return {"joints": joints, "springs": springs, "contacts": contacts, "sliders": sliders,
                "mark_size": size * 0.03}


def world_points(poses: np.ndarray, bodies: list[int], locals_: np.ndarray) -> np.ndarray:
    """(frames, n, 3) world positions of body-frame points ``locals_`` on ``bodies`` (-1 = ground)."""
    frames = poses.shape[0]
    out = np.repeat(locals_[None], frames, axis=0).astype(float)
    for i, k in enumerate(bodies):
        if k >= 0 and poses.shape[1]:
            R = Rotation.from_quat(poses[:, k, 3:]).as_matrix()
            out[:, i] = poses[:, k, :3] + R @ locals_[i]
    return out


def build_scene(result: Any, *, fps: float = 60.0, max_frames: int = 2000, title: str | None = None) -> dict:
    """The whole page data of ``result`` as a JSON-ready dict (poses packed as base64 float32)."""
    system = result.system
    if system is None:
        raise ModelError("viewer", "this result has no System (e.g. after unpickling): "
                                   "use res.with_system(system).view(...)")
    t = np.asarray(result.t, dtype=float)
    if t.size == 0:
        raise ModelError("viewer", "the result has no samples to show")
    times = frame_times(t, fps, max_frames)
    qs = resample(t, np.asarray(result.q, dtype=float), times, np.asarray(result.qd, dtype=float))
    builder = SceneBuilder(system)
    poses = builder.poses(qs)
    points = builder.points_of_interest()

    # The size of the whole motion sets the default rod and mark sizes and the camera.
    locals_, owners = [], []
    for k, pts in points.items():
        for p in pts:
            locals_.append(p)
            owners.append(k)
    for k, body in enumerate(builder.bodies):
        locals_.append(_value(system, body, "com"))
        owners.append(k)
    cloud = world_points(poses, owners, np.array(locals_).reshape(-1, 3)).reshape(-1, 3)
    cloud = np.vstack([cloud, np.zeros((1, 3))])
    low, high = cloud.min(axis=0), cloud.max(axis=0)
    size = float(max(np.max(high - low), 1e-3))

    masses = np.array([float(system.parameters.get(f"{b.name}.mass", b.mass)) for b in builder.bodies])
    bodies = []
    for k, body in enumerate(builder.bodies):
        shapes = getattr(body, "shape", ()) or ()
        color = PALETTE[k % len(PALETTE)]
        records = _records(shapes, color, body.name)
        if not records:
            records = builder.default_shapes(k, size, points[k], masses[k] / masses.max())
        bodies.append({"name": body.name, "shapes": records})

    ground_shapes = getattr(system.topology.ground, "shape", ()) or ()
    ground = _records(ground_shapes, "#8c8c8c", system.topology.ground.name)

    gravity = np.asarray(system.parameters.get("gravity", (0.0, 0.0, -9.81)), dtype=float)
    up = -gravity / np.linalg.norm(gravity) if np.linalg.norm(gravity) > 0 else np.array([0.0, 0.0, 1.0])
    name = getattr(system, "name", None)
    scene = {
        "title": title or name or "mbcomp",
        "t0": float(times[0]), "t1": float(times[-1]), "frames": int(len(times)),
        "nbodies": len(bodies), "bodies": bodies, "ground": ground,
        "poses": _b64(poses, "<f4"),
        "center": [*map(float, (low + high) / 2)], "low": [*map(float, low)], "high": [*map(float, high)],
        "size": size, "up": [*map(float, up)],
        "events": [float(getattr(e, "time", np.nan)) for e in getattr(result, "events", [])],
    }
    scene.update(builder.marks(size))
    return scene
