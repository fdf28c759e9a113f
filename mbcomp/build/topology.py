"""Graph compiler: bodies as nodes, joints as edges; spanning tree, cut joints, coordinates."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from mbcomp.spec.components import Body, Component, Constraint, ForceElement, Joint
from mbcomp.spec.components.contacts import Contact
from mbcomp.spec.components.values import name_of
from mbcomp.core.errors import CompileError, describe

# What each reference role must resolve to.
_ROLE_TYPES = {"parent": Body, "child": Body, "body": Body, "a": Body, "b": Body, "joint": Joint}


@dataclass(frozen=True)
class Topology:
    """The compiled structure of a model (never modified after construction).

    ``bodies`` are the moving bodies in depth-first order from the ground (parents
    before children); ``tree_joints[i]`` is the joint into ``bodies[i]``; ``coords``
    are the tree coordinates in that order and ``q_slice[joint name]`` their slice;
    ``speeds`` the tree speeds (``nv <= nq``) and ``v_slice[joint name]`` theirs.
    ``input_sizes[component name]`` is the number of run-time input values of each
    component with a callable (a force's 3, a joint torque's joint coordinates).

    The components are the compiler's frozen copies (``flatten``), never the user's.
    """

    ground: Body
    bodies: tuple
    tree_joints: tuple
    cut_joints: tuple
    parent_of: dict
    coords: tuple
    q_slice: dict
    forces: tuple
    constraints: tuple
    contacts: tuple
    components: dict
    speeds: tuple = ()
    v_slice: dict = field(default_factory=dict)
    input_sizes: dict = field(default_factory=dict)

    @property
    def nq(self) -> int:
        return len(self.coords)

    @property
    def nv(self) -> int:
        return len(self.speeds)

    @property
    def state_map(self):
        """The numeric ``q' = G(q) v``, ``integrate``, ``normalize`` of the whole tree."""
        from mbcomp.core.statemap import StateMap
        found = self.__dict__.get("_state_map")
        if found is None:
            found = StateMap.of(self)
            object.__setattr__(self, "_state_map", found)
        return found

    @property
    def graph(self):
        """The model as a networkx ``MultiDiGraph``: bodies as nodes, every joint as an edge
        parent -> child keyed by its name (with the joint as ``joint``); built on first use."""
        found = self.__dict__.get("_graph")
        if found is None:
            import networkx as nx  # not needed to compile: imported only here
            found = nx.MultiDiGraph()
            found.add_nodes_from(c.name for c in self.components.values() if isinstance(c, Body))
            for joint in (*self.tree_joints, *self.cut_joints):
                found.add_edge(name_of(joint.parent), name_of(joint.child), key=joint.name, joint=joint)
            object.__setattr__(self, "_graph", found)
        return found

    @property
    def has_loops(self) -> bool:
        return bool(self.cut_joints)

    def resolve(self, ref: Any) -> Component:
        """The component a reference (object or name) stands for."""
        return self.components[name_of(ref)]

    def body_index(self, ref: Any) -> int:
        """Index into ``bodies`` (-1 for the ground)."""
        body = self.resolve(ref)
        return -1 if body is self.ground else self.bodies.index(body)

    def ancestors(self, ref: Any) -> list:
        """Bodies from ``ref`` up to (excluding) the ground."""
        chain, body = [], self.resolve(ref)
        while body is not self.ground:
            chain.append(body)
            body = self.parent_of[body.name]
        return chain

    def coord_indices_of_body(self, ref: Any) -> list[int]:
        """Indices of every coordinate that moves ``ref`` (its joint and its ancestors')."""
        indices = []
        for body in self.ancestors(ref):
            joint = self.tree_joints[self.bodies.index(body)]
            indices.extend(range(*self.q_slice[joint.name].indices(self.nq)))
        return sorted(indices)

    def speed_indices_of_body(self, ref: Any) -> list[int]:
        """Indices of every speed that moves ``ref`` (its joint and its ancestors')."""
        indices = []
        for body in self.ancestors(ref):
            joint = self.tree_joints[self.bodies.index(body)]
            indices.extend(range(*self.v_slice[joint.name].indices(self.nv)))
        return sorted(indices)


def build_topology(model) -> Topology:
    """Resolve references, find the spanning tree and the cut joints, name coordinates.

    Collects every structural problem and raises one ``CompileError`` listing them.
    """
    problems: list[str] = []
    components = dict(model.components)
    ground = model.ground

    broken: set[str] = set()
    for comp in components.values():
        for role, ref in comp.references().items():
            target = components.get(name_of(ref))
            wanted = _ROLE_TYPES.get(role, Component)
            if target is None:
                problems.append(f"{describe(comp)}: {role} {name_of(ref)!r} is not in the model")
            elif not isinstance(ref, str) and ref is not target:
                problems.append(f"{describe(comp)}: {role} refers to {describe(ref)}, which was not added to the model "
                                f"(the model's {name_of(ref)!r} is another object)")
            elif not isinstance(target, wanted):
                problems.append(f"{describe(comp)}: {role} {name_of(ref)!r} is a {type(target).__name__}, "
                                f"expected a {wanted.__name__}")
            else:
                continue
            broken.add(comp.name)

    # Components with broken references stay out of the graph; the checks go on so that
    # every problem is reported at once.
    joints = [c for c in components.values() if isinstance(c, Joint) and c.name not in broken]
    # The spanning tree, grown joint by joint in the model's order: a joint whose child has
    # a parent already, or whose bodies the tree joins already, is cut (closes a loop).
    degree = {c.name: 0 for c in components.values() if isinstance(c, Body)}  # joints at each body
    children: dict[str, list[str]] = {}
    joined = _Joined(ground.name)
    tree_joint_of: dict[str, Joint] = {}
    cut_joints = []
    for joint in joints:
        parent, child = name_of(joint.parent), name_of(joint.child)
        degree[parent] = degree.get(parent, 0) + 1
        degree[child] = degree.get(child, 0) + 1
        if parent == child:
            problems.append(f"{describe(joint)}: connects body {parent!r} to itself")
            continue
        if child == ground.name or child in tree_joint_of or joined.together(parent, child):
            cut_joints.append(joint)
        else:
            children.setdefault(parent, []).append(child)
            joined.join(parent, child)
            tree_joint_of[child] = joint

    order = _depth_first(children, ground.name)  # parents before children, children in joint order
    reachable = set(order)
    for node, joints_at in degree.items():
        if node != ground.name and node not in reachable and not (broken and joints_at == 0 and
                                                                    _mentioned_by_broken(node, broken, components)):
            why = "has no joint" if joints_at == 0 else "is not connected to the ground by a chain of parent->child joints"
            problems.append(f"{describe(components[node])}: {why}")

    bodies = tuple(components[n] for n in order)
    tree_joints = tuple(tree_joint_of[n] for n in order)
    parent_of = {n: components[name_of(tree_joint_of[n].parent)] for n in order}

    coords, q_slice, speeds, v_slice = [], {}, [], {}
    for joint in tree_joints:
        q_slice[joint.name] = slice(len(coords), len(coords) + joint.nq)
        coords.extend(joint.coords)
        v_slice[joint.name] = slice(len(speeds), len(speeds) + joint.nv)
        speeds.extend(joint.speeds)
    seen: dict[str, int] = {}
    for name in coords + [v for j in tree_joints for v in j.speeds if v not in j.coords]:
        seen[name] = seen.get(name, 0) + 1
    for name, count in seen.items():
        if count > 1:
            problems.append(f"coordinate name {name!r} is used {count} times")
        if name in components and not isinstance(components[name], Joint):
            problems.append(f"coordinate name {name!r} is also the name of {describe(components[name])}")

    forces = tuple(c for c in components.values() if isinstance(c, ForceElement) and c.name not in broken)
    input_sizes: dict[str, int] = {}
    for comp in forces:
        resolved = {role: components[name_of(ref)] for role, ref in comp.references().items()}
        if hasattr(comp, "check"):
            problems.extend(comp.check(resolved))
        joint = resolved.get("joint")
        if joint is not None and joint in cut_joints:
            problems.append(f"{describe(comp)}: joint {joint.name!r} closes a loop and has no coordinates")
        size = comp.input_size(joint) if hasattr(comp, "input_size") else 0
        if size:
            input_sizes[comp.name] = size
    constraints = tuple(c for c in components.values() if isinstance(c, Constraint) and c.name not in broken)
    for comp in constraints:
        joint = components.get(name_of(comp.joint)) if hasattr(comp, "joint") else None
        if joint is None:
            continue
        if joint.n_coords != 1:
            problems.append(f"{describe(comp)}: needs a 1-DOF joint, {describe(joint)} has {joint.n_coords} coordinates")
        elif joint in cut_joints:
            problems.append(f"{describe(comp)}: joint {joint.name!r} closes a loop and has no coordinate to drive; "
                            f"declare the loop so that the driven joint is part of the tree")
    contacts = tuple(c for c in components.values() if isinstance(c, Contact) and c.name not in broken)
    for comp in contacts:
        if name_of(comp.body) == ground.name:
            problems.append(f"{describe(comp)}: is on the ground, which never moves; put it on a moving body")
    for comp in components.values():  # joint stops (drivetrain.JointLimit): a contact per bound
        if hasattr(comp, "sides") and comp.name not in broken:
            joint = components[name_of(comp.joint)]
            if joint.n_coords != 1 or joint in cut_joints:
                problems.append(f"{describe(comp)}: needs a 1-DOF joint of the tree, {describe(joint)} is not one")
            contacts += comp.sides()
    if problems:
        raise CompileError(problems=problems)
    return Topology(ground=ground, bodies=bodies, tree_joints=tree_joints, cut_joints=tuple(cut_joints),
                    parent_of=parent_of, coords=tuple(coords), q_slice=q_slice, forces=forces,
                    constraints=constraints, contacts=contacts, components=components,
                    speeds=tuple(speeds), v_slice=v_slice, input_sizes=input_sizes)


class _Joined:
    """Which bodies the tree joins so far (disjoint sets, path halving): a joint between two
    joined bodies would close a loop.  (networkx's graph algorithms give the same answers
    but cost a tenth of a second of imports at every compile, cached or not.)"""

    def __init__(self, ground: str):
        self.root = {ground: ground}

    def _find(self, node: str) -> str:
        root = self.root
        while root[node] != node:
            root[node] = root[root[node]]
            node = root[node]
        return node

    def together(self, a: str, b: str) -> bool:
        """True when ``a`` and ``b`` are both in the tree and joined by it."""
        return a in self.root and b in self.root and self._find(a) == self._find(b)

    def join(self, a: str, b: str) -> None:
        for node in (a, b):
            self.root.setdefault(node, node)
        self.root[self._find(b)] = self._find(a)


def _depth_first(children: dict, start: str) -> list:
    """Nodes reachable from ``start`` (excluded) in depth-first preorder, each node's
    children in the order given (networkx's ``dfs_preorder_nodes`` on the same edges)."""
    order, stack = [], [iter(children.get(start, ()))]
    while stack:
        node = next(stack[-1], None)
        if node is None:
            stack.pop()
            continue
        order.append(node)
        stack.append(iter(children.get(node, ())))
    return order


def _mentioned_by_broken(body: str, broken: set, components: dict) -> bool:
    """True when a component left out for a broken reference would have connected ``body``
    (its 'not connected' report would only repeat that problem)."""
    return any(name_of(ref) == body for name in broken for ref in components[name].references().values())
