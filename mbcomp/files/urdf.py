"""URDF robot descriptions as mbcomp models (``mb.load("robot.urdf")``, ``mb.load_urdf``).

The file is parsed by ``yourdfpy`` (optional: ``pip install "mbcomp[urdf]"``).  The mapping:

- a **link** with its ``<inertial>`` becomes a ``Body`` whose frame is the link frame: the COM
  is the inertial origin, the inertia (given about the COM in the inertial frame) is rotated
  into the link frame, ``R I R^T``;
- a **revolute** or **continuous** joint becomes a ``Revolute``, a **prismatic** joint a
  ``Prismatic``, each from a frame on the parent body at the joint origin (position and
  roll-pitch-yaw rotation: a rotated ``Frame``) to the child link's frame, about or along the
  joint axis (in the joint frame, as URDF defines it); the coordinate is named after the joint;
- a **fixed** joint welds its child link to the parent: masses, COMs and inertias are combined
  (parallel-axis theorem) into one body, as Pinocchio's reader does;
- the root link is the ground (``floating=False``), or is joined to the ground by a ``Free``
  joint (``floating=True``, for mobile robots);
- ``<visual>`` boxes, cylinders, spheres and meshes become the bodies' shapes for the viewer
  (mesh files through ``package://`` are looked up beside the URDF file and its parents).

What this does not model is named in one ``UserWarning`` per kind, never dropped silently:
joint limits and safety controllers (not enforced), joint damping and friction, mimic joints
(simulated as independent joints), transmissions, Gazebo tags and collision geometry.
The limits are kept on the model as ``model.joint_limits`` (``{joint: (lower, upper)}``).
"""
from __future__ import annotations

import os
import re
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from mbcomp.spec.components import Body, Free, Prismatic, Revolute
from mbcomp.spec.components.frame import Frame
from mbcomp.core.errors import ModelError
from mbcomp.spec.model import Model
from mbcomp.core.limits import file_problem
from mbcomp.spec.shapes import Box, Cylinder, Mesh, Sphere

__all__ = ["load_urdf"]

GRAVITY = (0.0, 0.0, -9.81)


def _name(text: str, taken: set[str]) -> str:
    """A valid, unused component name for a URDF link or joint name."""
    base = re.sub(r"\W", "_", text) or "unnamed"
    if base[0].isdigit():
        base = "_" + base
    name, k = base, 1
    while name in taken:
        k += 1
        name = f"{base}_{k}"
    taken.add(name)
    return name


class _Mass:
    """Mass, COM and inertia about the COM of a rigid body, all in one frame."""

    def __init__(self, mass: float = 0.0, com: Any = (0.0, 0.0, 0.0), inertia: Any = None):
        self.mass = float(mass)
        self.com = np.asarray(com, dtype=float)
        self.inertia = np.zeros((3, 3)) if inertia is None else np.asarray(inertia, dtype=float)

    def moved(self, T: np.ndarray) -> "_Mass":
        """The same mass seen from a frame in which this one's frame is ``T`` (4x4)."""
        R, p = T[:3, :3], T[:3, 3]
        return _Mass(self.mass, R @ self.com + p, R @ self.inertia @ R.T)

    def plus(self, other: "_Mass") -> "_Mass":
        mass = self.mass + other.mass
        if mass <= 0:
            return _Mass()
        com = (self.mass * self.com + other.mass * other.com) / mass
        inertia = np.zeros((3, 3))
        for part in (self, other):
            d = part.com - com
            inertia += part.inertia + part.mass * (d @ d * np.eye(3) - np.outer(d, d))
        return _Mass(mass, com, inertia)


def _link_mass(link: Any) -> _Mass:
    inertial = getattr(link, "inertial", None)
    if inertial is None or inertial.mass is None:
        return _Mass()
    T = np.eye(4) if inertial.origin is None else np.asarray(inertial.origin, dtype=float)
    inertia = np.zeros((3, 3)) if inertial.inertia is None else np.asarray(inertial.inertia, dtype=float)
    mass = float(inertial.mass)
    if not np.isfinite(mass) or mass < 0:
        raise ModelError(f"URDF link {link.name!r}", f"mass must be a non-negative number, got {inertial.mass!r}")
    return _Mass(mass, (0.0, 0.0, 0.0), inertia).moved(T)


def _resolve_mesh(filename: str, urdf_dir: Path) -> Path | None:
    """A mesh file named in the URDF (``package://pkg/rest``, ``file://``, relative or absolute)."""
    if filename.startswith("file://"):
        path = Path(filename[len("file://"):])
        return path if path.is_file() else None
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        package, _, inner = rest.partition("/")
        for folder in (urdf_dir, *urdf_dir.parents):
            for candidate in (folder / rest, folder / inner if folder.name == package else None):
                if candidate is not None and candidate.is_file():
                    return candidate
        return None
    path = Path(filename)
    if not path.is_absolute():
        path = urdf_dir / path
    return path if path.is_file() else None


def _color(visual: Any, materials: dict) -> Any:
    material = getattr(visual, "material", None)
    if material is None:
        return None
    color = getattr(material, "color", None)
    if color is None and getattr(material, "name", None) in materials:
        color = getattr(materials[material.name], "color", None)
    rgba = getattr(color, "rgba", None)
    if rgba is None:
        return None
    return tuple(float(min(max(c, 0.0), 1.0)) for c in list(rgba)[:3])


def _shapes(link: Any, T_body_link: np.ndarray, urdf_dir: Path, materials: dict, skipped: list) -> list:
    """The link's visuals as shapes in its body's frame."""
    out = []
    for visual in getattr(link, "visuals", None) or ():
        T = T_body_link @ (np.eye(4) if visual.origin is None else np.asarray(visual.origin, dtype=float))
        where = {"origin": T[:3, 3], "rotation": T[:3, :3], "color": _color(visual, materials)}
        geometry = visual.geometry
        if geometry.box is not None:
            out.append(Box(geometry.box.size, **where))
        elif geometry.cylinder is not None:
            out.append(Cylinder(geometry.cylinder.radius, geometry.cylinder.length, axis="z", **where))
        elif geometry.sphere is not None:
            out.append(Sphere(geometry.sphere.radius, origin=where["origin"], color=where["color"]))
        elif geometry.mesh is not None:
            path = _resolve_mesh(geometry.mesh.filename, urdf_dir)
            if path is None:
                skipped.append(f"{link.name}: {geometry.mesh.filename}")
                continue
            scale = 1.0 if geometry.mesh.scale is None else geometry.mesh.scale
            out.append(Mesh(path, scale=scale, **where))
    return out


def _check_tree(joints: list, links: dict, path: Path) -> None:
    """``ModelError`` naming the joints when the links do not form a tree: a joint to an
    unknown link or from a link to itself, a link with two parent joints, joints in a cycle."""
    import networkx as nx
    problems, parents = [], {}
    for joint in joints:
        if joint.parent not in links or joint.child not in links:
            problems.append(f"URDF joint {joint.name!r}: connects unknown links {joint.parent!r} -> {joint.child!r}")
        elif joint.parent == joint.child:
            problems.append(f"URDF joint {joint.name!r}: connects link {joint.parent!r} to itself")
        else:
            parents.setdefault(joint.child, []).append(joint)
    for link, found in parents.items():
        if len(found) > 1:
            names = ", ".join(repr(j.name) for j in found)
            problems.append(f"URDF link {link!r}: has {len(found)} parent joints ({names}); a link hangs from one "
                            "joint (the links must form a tree: close a loop with a constraint after loading)")
    graph = nx.DiGraph()
    graph.add_edges_from((j.parent, j.child, {"joint": j.name}) for found in parents.values() for j in found)
    try:
        cycle = nx.find_cycle(graph)
    except nx.NetworkXNoCycle:
        cycle = []
    if cycle:
        names = ", ".join(repr(graph.edges[u, v]["joint"]) for u, v in cycle)
        loop = " -> ".join([cycle[0][0]] + [v for _, v in cycle])
        problems.append(f"URDF joints {names}: form a cycle ({loop}); the links must form a tree")
    if problems:
        raise ModelError(problems=[f"{path}: {problem}" for problem in problems])


def load_urdf(path: str | os.PathLike, floating: bool = False, *, gravity: Any = GRAVITY,
              limits: bool = False) -> Model:
    """Read a URDF file into a ``Model`` (see the module docstring for the mapping).

    ``floating=True`` joins the root link to the ground with a ``Free`` joint (a mobile or
    flying robot); otherwise the root link is the ground.  ``gravity`` (m/s^2, world frame)
    defaults to ``(0, 0, -9.81)``.  ``limits=True`` enforces the joints' position limits as
    ``JointLimit`` stops (named ``JOINT_limit``; inelastic); by default they are only kept in
    ``model.joint_limits``.  Coordinates are named after the URDF joints.  Raises
    ``ModelError`` for an unreadable file, a moving link without mass, or an unsupported
    joint type; warns (``UserWarning``) naming every URDF feature that is not modelled.
    """
    try:
        import yourdfpy
    except ImportError:
        raise ModelError("load_urdf", "reading URDF needs the optional package yourdfpy: "
                                      "pip install 'mbcomp[urdf]'") from None
    path = Path(path)
    problem = file_problem(path)   # a FIFO, a device or an oversized file is never opened
    if problem is not None:
        raise ModelError("load_urdf", f"{path}: {'no such file' if not path.exists() else problem}")
    try:
        robot = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False,
                                   build_collision_scene_graph=False, load_collision_meshes=False).robot
    except Exception as exc:  # noqa: BLE001 - the parser raises many kinds; name the file
        raise ModelError("load_urdf", f"{path}: not a readable URDF file ({exc})") from None

    links = {link.name: link for link in robot.links}
    _check_tree(robot.joints, links, path)
    children: dict[str, list] = {}
    parent_joint: dict[str, Any] = {}
    for joint in robot.joints:
        children.setdefault(joint.parent, []).append(joint)
        parent_joint[joint.child] = joint
    roots = [name for name in links if name not in parent_joint]
    if len(roots) != 1:
        raise ModelError("load_urdf", f"{path}: the links must form one tree, found roots {roots}")
    root = roots[0]

    model = Model(re.sub(r"\s", "_", robot.name or path.stem), gravity=gravity)
    materials = {m.name: m for m in (robot.materials or ())}
    taken = {model.ground.name}
    unmodelled: dict[str, list[str]] = {}
    skipped_meshes: list[str] = []
    joint_limits: dict[str, tuple[float, float]] = {}

    def note(kind: str, what: str) -> None:
        unmodelled.setdefault(kind, []).append(what)

    # Weld fixed-joint children into their parents: body of each link and the link's frame in it.
    body_of: dict[str, str] = {}
    T_in_body: dict[str, np.ndarray] = {}
    mass_of: dict[str, _Mass] = {}
    shapes_of: dict[str, list] = {}
    order: list[str] = []            # bodies (their founding link), parents first
    ground_body = "__ground__"

    def visit(link_name: str, body: str, T: np.ndarray) -> None:
        """Depth first from ``link_name`` (a stack, not recursion: a chain may be long)."""
        stack = [(link_name, body, T)]
        while stack:
            link_name, body, T = stack.pop()
            body_of[link_name], T_in_body[link_name] = body, T
            if body == link_name:   # a link that founds a body (one that moves)
                order.append(link_name)
            link = links[link_name]
            mass_of[body] = mass_of.get(body, _Mass()).plus(_link_mass(link).moved(T))
            shapes_of.setdefault(body, []).extend(_shapes(link, T, path.parent, materials, skipped_meshes))
            for joint in reversed(children.get(link_name, ())):   # (popped in the file's order)
                origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)
                if joint.type == "fixed":
                    stack.append((joint.child, body, T @ origin))
                else:
                    stack.append((joint.child, joint.child, np.eye(4)))

    base = root if floating else ground_body
    visit(root, base, np.eye(4))

    names: dict[str, str] = {}
    bodies: dict[str, Any] = {ground_body: model.ground}
    for founder in order:
        mass = mass_of[founder]
        if mass.mass <= 0:
            raise ModelError(f"URDF link {founder!r}", "moves but has no mass (nor any link welded to it): "
                                                      "give it an <inertial>")
        names[founder] = _name(founder, taken)
        inertia = 0.5 * (mass.inertia + mass.inertia.T)
        bodies[founder] = model.add(Body(names[founder], mass=mass.mass, com=tuple(mass.com),
                                         inertia=None if not np.any(inertia) else inertia,
                                         shape=shapes_of.get(founder) or None))

    if shapes_of.get(ground_body):
        model.ground.shape = tuple(shapes_of[ground_body])   # drawn by the viewer, fixed
    if floating:
        model.add(Free(_name(f"{root}_free", taken), model.ground, bodies[root]))

    for joint in robot.joints:
        if joint.type == "fixed":
            continue
        if joint.type not in ("revolute", "continuous", "prismatic"):
            raise ModelError(f"URDF joint {joint.name!r}", f"type {joint.type!r} is not supported "
                                                          f"(revolute, continuous, prismatic, fixed)")
        parent_body = body_of[joint.parent]
        origin = np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)
        T = T_in_body[joint.parent] @ origin
        axis = np.array([1.0, 0.0, 0.0]) if joint.axis is None else np.asarray(joint.axis, dtype=float)
        if axis.shape != (3,) or not np.all(np.isfinite(axis)):
            raise ModelError(f"URDF joint {joint.name!r}", f"axis {' '.join(f'{v:g}' for v in axis.ravel())} is not "
                                                          "three finite numbers")
        if not np.linalg.norm(axis) > 0:
            raise ModelError(f"URDF joint {joint.name!r}", "axis is the zero vector")
        axis = axis / np.linalg.norm(axis)
        parent = Frame(bodies[parent_body], tuple(T[:3, 3]), T[:3, :3])
        kind = Revolute if joint.type in ("revolute", "continuous") else Prismatic
        name = _name(joint.name, taken)
        model.add(kind(name, parent, bodies[joint.child], axis=tuple(axis), coords=name))
        limit = getattr(joint, "limit", None)
        if limit is not None and joint.type != "continuous" and limit.lower is not None and limit.upper is not None:
            joint_limits[name] = (float(limit.lower), float(limit.upper))
        dynamics = getattr(joint, "dynamics", None)
        if dynamics is not None and any(float(getattr(dynamics, k) or 0) != 0 for k in ("damping", "friction")):
            note("joint damping and friction", joint.name)
        if getattr(joint, "mimic", None) is not None:
            note("mimic joints (simulated as independent joints)", joint.name)
        if getattr(joint, "safety_controller", None) is not None:
            note("safety controllers", joint.name)
        if getattr(joint, "calibration", None) is not None:
            note("calibration", joint.name)
    if joint_limits and limits:
        from mbcomp.spec.components import JointLimit
        for name, (lower, upper) in joint_limits.items():
            model.add(JointLimit(_name(f"{name}_limit", taken), name, lower=lower, upper=upper))
    elif joint_limits:
        note("joint position limits (not enforced: load_urdf(..., limits=True) does; kept in "
             "model.joint_limits)", ", ".join(joint_limits))
    if any(getattr(link, "collisions", None) for link in robot.links):
        note("collision geometry", ", ".join(link.name for link in robot.links if getattr(link, "collisions", None)))
    if getattr(robot, "transmission", None):
        note("transmissions", str(len(robot.transmission)))
    if getattr(robot, "gazebo", None):
        note("Gazebo tags", str(len(robot.gazebo)))
    if skipped_meshes:
        note("visual meshes whose file was not found", "; ".join(skipped_meshes))
    if unmodelled:
        listed = "; ".join(f"{kind}: {', '.join(dict.fromkeys(what))}" for kind, what in unmodelled.items())
        warnings.warn(f"{path.name}: URDF features not modelled: {listed}", UserWarning, stacklevel=2)

    model.description = f"{robot.name} (from {path.name})"
    model.named_parameters = {}
    model.initial = {"q": {}, "qd": {}}
    model.simulation = {}
    model.path = path
    model.joint_limits = joint_limits
    return model
