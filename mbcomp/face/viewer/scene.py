"""What the 3D viewer shows, computed in Python: the bodies' shapes in their own frames, the
joint, spring and contact marks, and every body's pose at evenly spaced times.

The points, default rods, poses and the resampling of the motion are ``mbcomp.face.scene``'s, the
same that plots and animations draw; the page only places these body-frame shapes with those
poses, so what it shows is what mbcomp computed.
"""
from __future__ import annotations

import base64
import warnings
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from mbcomp.core.errors import ModelError
from mbcomp.face.scene import Scene, local_value, resample_result
from mbcomp.spec.shapes import Box, Capsule, Cylinder, Mesh, Plane, Sphere

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
    elif isinstance(shape, Capsule):
        turn = Rotation.align_vectors([shape.axis], [[0.0, 1.0, 0.0]])[0]   # the page's capsules run along y
        record.update(type="capsule", radius=shape.radius, length=shape.length,
                      place=[*map(float, shape.origin), *map(float, turn.as_quat())])
    elif isinstance(shape, Plane):
        # A square slab of the plane's extent just behind its surface (the solid side).
        turn = Rotation.align_vectors([shape.normal], [[0.0, 0.0, 1.0]])[0]
        thick = 0.01 * shape.extent
        centre = np.asarray(shape.origin) - 0.5 * thick * np.asarray(shape.normal)
        record.update(type="box", size=[shape.extent, shape.extent, thick],
                      place=[*map(float, centre), *map(float, turn.as_quat())])
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


def default_shapes(scene: Scene, k: int, size: float) -> list[dict]:
    """Body ``k`` (index in ``scene.bodies``) without shapes of its own: the scene's rods from
    its COM to each of its points, and a ball at the COM (its volume growing with the mass)."""
    com = scene.locals_array[scene.com_points[k]]
    color = PALETTE[k % len(PALETTE)]
    mass_ratio = scene.masses[k] / scene.masses.max()
    radius = size * 0.045 * max(mass_ratio, 0.05) ** (1.0 / 3.0)
    records = [{"type": "sphere", "radius": radius, "place": [*map(float, com), 0.0, 0.0, 0.0, 1.0], "color": color}]
    for a, b, owner in scene.rods:
        if owner == k:
            records.append({"type": "rod", "a": [*map(float, scene.locals_array[b])],
                            "b": [*map(float, scene.locals_array[a])], "radius": size * 0.012, "color": color})
    return records


def marks(scene: Scene, size: float) -> dict:
    """Joints, springs, sliders and contacts as the page marks them (body numbers: -1 the
    ground, k for ``scene.bodies[k]``)."""
    system, topology = scene.system, scene.topology
    number = lambda ref: scene.body_index(ref) - 1     # noqa: E731 - the page numbers the ground -1
    joints = []
    for joint in tuple(topology.tree_joints) + tuple(topology.cut_joints):
        axis = getattr(joint, "axis", None)
        if axis is not None and hasattr(joint, "child_frame_rotation"):
            # The axis is in the joint frame, which sits rotated in the child body.
            axis = np.asarray(joint.child_frame_rotation, dtype=float) @ np.asarray(axis, dtype=float)
        joints.append({"name": joint.name, "kind": type(joint).__name__.lower(), "body": number(joint.child),
                       "point": [*map(float, local_value(system, joint, "child_point"))],
                       "parent": number(joint.parent),
                       "parent_point": [*map(float, local_value(system, joint, "parent_point"))],
                       "axis": None if axis is None else [*map(float, axis)]})
    springs = []
    for comp in topology.forces:
        ends = [role for role, how in getattr(comp, "refs", {}).items() if how == "attachment"]
        if len(ends) == 2:
            a, b = ends
            springs.append({"name": comp.name, "a": number(getattr(comp, f"body_{a}")),
                            "pa": [*map(float, local_value(system, comp, f"point_{a}"))],
                            "b": number(getattr(comp, f"body_{b}")),
                            "pb": [*map(float, local_value(system, comp, f"point_{b}"))]})
    contacts, sliders = [], []
    for comp in topology.contacts:
        if getattr(comp, "kind", "") != "contact":
            continue   # e.g. a joint stop: a coordinate gap, nothing to mark in space
        contacts.append({"name": comp.name, "body": number(comp.body),
                         "point": [*map(float, local_value(system, comp, "point"))],
                         "origin": [*map(float, local_value(system, comp, "origin"))],
                         "normal": [*map(float, comp.normal)]})
    for comp in topology.constraints:
        if getattr(comp, "kind", "") == "slider":
            sliders.append({"name": comp.name, "body": number(comp.body),
                            "point": [*map(float, local_value(system, comp, "point"))],
                            "origin": [*map(float, local_value(system, comp, "origin"))],
                            "axis": [*map(float, comp.axis)]})
    return {"joints": joints, "springs": springs, "contacts": contacts, "sliders": sliders,
            "mark_size": size * 0.03}


def collision_shapes(topology: Any) -> dict[str, tuple]:
    """``{body name: shapes}`` given to collisions as ``(body, shape)`` pairs (not among the
    body's own shapes), so that the page draws them (a floor Plane on the ground, ...)."""
    from mbcomp.spec.components.collision import Collision
    from mbcomp.spec.components.values import name_of
    out: dict[str, tuple] = {}
    for comp in topology.components.values():
        if isinstance(comp, Collision):
            for body, shape in tuple(comp.a) + tuple(comp.b):
                if shape is not None and shape not in out.get(name_of(body), ()):
                    out[name_of(body)] = out.get(name_of(body), ()) + (shape,)
    return out


def collision_hits(system: Any, result: Any) -> list[dict]:
    """Where collisions touched: ``{"t": event time (s), "p": world point (m), "name": ...}``
    for each impact of a collision contact (the middle of the touching points)."""
    kernel = system.kernel
    points_at = getattr(kernel, "contact_points", None)
    if points_at is None:
        return []
    names = {f.name for f in getattr(kernel, "features", ())}
    hits = []
    events = [e for e in getattr(result, "events", []) if e.contact in names and getattr(e, "kind", "impact") == "impact"]
    if not events:
        return []
    qs = resample_result(result, np.array([e.time for e in events]))
    for e, q in zip(events, qs):
        point = points_at(np.asarray(q, dtype=float)).get(e.contact)
        if point is not None:
            hits.append({"t": float(e.time), "p": [*map(float, point)], "name": e.contact})
    return hits


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
    qs = resample_result(result, times)
    scene = Scene(system)
    poses = scene.body_poses(qs)

    # The size of the whole motion (and the origin) sets the default rod and mark sizes and the camera.
    cloud = np.vstack([scene.all_points(qs).reshape(-1, 3), np.zeros((1, 3))])
    low, high = cloud.min(axis=0), cloud.max(axis=0)
    size = float(max(np.max(high - low), 1e-3))

    own = collision_shapes(scene.topology)   # shapes given to a Collision as (body, shape)
    bodies = []
    for k, body in enumerate(scene.bodies):
        extra = tuple(x for x in own.get(body.name, ()) if x not in tuple(scene.shapes[k]))
        records = _records(tuple(scene.shapes[k]) + extra, PALETTE[k % len(PALETTE)], body.name)
        bodies.append({"name": body.name, "shapes": records or default_shapes(scene, k, size)})
    extra = tuple(x for x in own.get(scene.ground.name, ()) if x not in tuple(scene.ground_shapes))
    ground = _records(tuple(scene.ground_shapes) + extra, "#8c8c8c", scene.ground.name)

    gravity = np.asarray(system.parameters.get("gravity", (0.0, 0.0, -9.81)), dtype=float)
    up = -gravity / np.linalg.norm(gravity) if np.linalg.norm(gravity) > 0 else np.array([0.0, 0.0, 1.0])
    name = getattr(system, "name", None)
    page = {
        "title": title or name or "mbcomp",
        "t0": float(times[0]), "t1": float(times[-1]), "frames": int(len(times)),
        "nbodies": len(bodies), "bodies": bodies, "ground": ground,
        "poses": _b64(poses, "<f4"),
        "center": [*map(float, (low + high) / 2)], "low": [*map(float, low)], "high": [*map(float, high)],
        "size": size, "up": [*map(float, up)],
        "events": [float(getattr(e, "time", np.nan)) for e in getattr(result, "events", [])],
        "hits": collision_hits(system, result),
    }
    page.update(marks(scene, size))
    return page
