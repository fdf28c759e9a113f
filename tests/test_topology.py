"""The graph compiler: depth-first body order, coordinate slices, cut joints."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.build.topology import build_topology


def body(name):
    return mb.Body(name, mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.05))


def branched_model():
    """ground - A (ball xyz) - B (revolute) - D (prismatic)
                             \\ C (ball xy)   - E (fixed)
    Joints are added in an order unrelated to the tree (children before parents)."""
    m = mb.Model("tree")
    m.add(*(body(n) for n in "ABCDE"))
    m.add(mb.Prismatic("jD", "B", "D", axis="z"))
    m.add(mb.Fixed("jE", "C", "E", parent_point=(0.1, 0, 0)))
    m.add(mb.Spherical("jA", "ground", "A", sequence="xyz"))
    m.add(mb.Revolute("jB", "A", "B", axis="y", parent_point=(0, 0, -1)))
    m.add(mb.Spherical("jC", "A", "C", sequence="xy", coords=("c1", "c2"), parent_point=(0, 0.3, 0)))
    return m


def subtree(topology, name):
    """Names of ``name`` and all bodies below it."""
    below = {name}
    changed = True
    while changed:
        changed = False
        for b, parent in topology.parent_of.items():
            if parent.name in below and b not in below:
                below.add(b)
                changed = True
    return below


class TestTreeOrder:
    def test_parents_come_before_children(self):
        top = build_topology(branched_model())
        order = [b.name for b in top.bodies]
        assert sorted(order) == list("ABCDE")
        for name, parent in top.parent_of.items():
            if parent is not top.ground:
                assert order.index(parent.name) < order.index(name)

    def test_order_is_depth_first(self):
        top = build_topology(branched_model())
        order = [b.name for b in top.bodies]
        assert order[0] == "A"
        # Depth-first: every subtree occupies one contiguous run of the order.
        for name in order:
            members = subtree(top, name)
            positions = sorted(order.index(b) for b in members)
            assert positions == list(range(positions[0], positions[0] + len(members))), f"subtree of {name}"
        assert order in (list("ABDCE"), list("ACEBD"))

    def test_parent_of_and_tree_joints(self):
        top = build_topology(branched_model())
        parents = {name: parent.name for name, parent in top.parent_of.items()}
        assert parents == {"A": "ground", "B": "A", "C": "A", "D": "B", "E": "C"}
        for b, joint in zip(top.bodies, top.tree_joints):
            assert joint.name == f"j{b.name}"
            assert top.ancestors(b)[0] is b

    def test_coordinates_follow_the_body_order(self):
        top = build_topology(branched_model())
        expected = []
        for joint in top.tree_joints:
            expected.extend(joint.coords)
        assert top.coords == tuple(expected)
        assert top.nq == 3 + 1 + 2 + 1 + 0
        assert set(top.coords) == {"jA_x", "jA_y", "jA_z", "jB", "c1", "c2", "jD"}

    def test_q_slice_picks_each_joints_coordinates(self):
        top = build_topology(branched_model())
        assert set(top.q_slice) == {"jA", "jB", "jC", "jD", "jE"}
        covered = []
        for joint in top.tree_joints:
            sl = top.q_slice[joint.name]
            assert top.coords[sl] == joint.coords
            covered.extend(range(sl.start, sl.stop))
        assert sorted(covered) == list(range(top.nq))
        assert top.q_slice["jA"] == slice(0, 3)
        assert top.q_slice["jE"].stop - top.q_slice["jE"].start == 0

    def test_coordinates_moving_a_body_are_its_chains(self):
        top = build_topology(branched_model())
        idx = lambda *joints: sorted(i for j in joints for i in range(top.q_slice[j].start, top.q_slice[j].stop))
        assert top.coord_indices_of_body("D") == idx("jA", "jB", "jD")
        assert top.coord_indices_of_body("E") == idx("jA", "jC")
        assert top.body_index("ground") == -1
        assert top.bodies[top.body_index("C")].name == "C"

    def test_compiled_system_uses_the_topology_order(self):
        m = branched_model()
        sys = m.compile(backend="python")
        assert sys.coords == build_topology(m).coords
        # Coordinates of one branch do not couple with the other branch's joint below A.
        M = sys.mass_matrix(np.linspace(0.1, 0.7, sys.nq))
        i_b, i_c = sys.coords.index("jD"), sys.coords.index("c1")
        assert M[i_b, i_c] == 0.0

    def test_tree_without_loops(self):
        top = build_topology(branched_model())
        assert top.cut_joints == ()
        assert not top.has_loops

    def test_topology_is_frozen(self):
        top = build_topology(branched_model())
        with pytest.raises(AttributeError):
            top.coords = ()


def four_bar(closing):
    """Crank, coupler, rocker in the x-z plane; ``closing`` builds the joint that closes the loop."""
    m = mb.Model("fourbar")
    crank = m.add(body("crank"))
    coupler = m.add(body("coupler"))
    rocker = m.add(body("rocker"))
    m.add(mb.Revolute("j1", m.ground, crank, axis="y"))
    m.add(mb.Revolute("j2", crank, coupler, axis="y", parent_point=(0, 0, -1)))
    m.add(mb.Revolute("j3", m.ground, rocker, axis="y", parent_point=(2, 0, 0)))
    m.add(closing(coupler, rocker))
    return m


class TestCutJoints:
    def test_fixed_joint_closing_a_loop_is_a_cut_joint(self):
        m = four_bar(lambda c, r: mb.Fixed("weld", c, r, parent_point=(0, 0, -1), child_point=(0, 0, -1)))
        top = build_topology(m)
        assert [j.name for j in top.cut_joints] == ["weld"]
        assert top.has_loops
        assert [j.name for j in top.tree_joints] == ["j1", "j2", "j3"]
        assert top.coords == ("j1", "j2", "j3")
        assert "weld" not in top.q_slice

    def test_joint_into_the_ground_is_a_cut_joint(self):
        m = mb.Model("m")
        a = m.add(body("a"))
        m.add(mb.Revolute("j", m.ground, a, axis="x"), mb.Fixed("back", a, m.ground))
        top = build_topology(m)
        assert [j.name for j in top.cut_joints] == ["back"]

    def test_second_joint_into_a_body_is_a_cut_joint(self):
        m = mb.Model("m")
        a = m.add(body("a"))
        m.add(mb.Revolute("first", m.ground, a, axis="x"), mb.Fixed("second", m.ground, a))
        top = build_topology(m)
        assert [j.name for j in top.tree_joints] == ["first"]
        assert [j.name for j in top.cut_joints] == ["second"]

    def test_revolute_closing_a_loop_is_a_cut_joint_without_tree_coordinates(self):
        m = four_bar(lambda c, r: mb.Revolute("j4", c, r, axis="y", parent_point=(0, 0, -1), child_point=(0, 0, -1)))
        top = build_topology(m)
        assert [j.name for j in top.cut_joints] == ["j4"]
        assert top.coords == ("j1", "j2", "j3")

    def test_joint_whose_child_is_an_ancestor_closes_a_loop(self):
        m = mb.Model("m")
        a, b = m.add(body("a")), m.add(body("b"))
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("jb", a, b, axis="x"), mb.Fixed("back", b, a))
        top = build_topology(m)
        assert [j.name for j in top.cut_joints] == ["back"]
        assert top.coords == ("ja", "jb")

    def test_torque_on_a_cut_joint_is_reported(self):
        m = mb.Model("m")
        a, b = m.add(body("a")), m.add(body("b"))
        m.add(mb.Revolute("ja", m.ground, a, axis="x"), mb.Revolute("jb", a, b, axis="x"), mb.Fixed("back", b, a))
        m.add(mb.JointTorque("push", "back", []))
        with pytest.raises(mb.ModelError, match="JointTorque 'push': joint 'back' closes a loop"):
            build_topology(m)


def _networkx_spanning_tree(model):
    """The body order and cut joints by networkx (the graph algorithms topology.py used to
    call): an independent computation of the same spanning tree."""
    import networkx as nx
    from mbcomp.build.flatten import flatten
    flat = flatten(model)
    tree, cut, parent_of = nx.DiGraph(), [], {}
    tree.add_node(flat.ground.name)
    for joint in (c for c in flat.components.values() if isinstance(c, mb.components.Joint)):
        parent, child = mb.components.values.name_of(joint.parent), mb.components.values.name_of(joint.child)
        joined = parent in tree and child in tree and nx.has_path(tree.to_undirected(as_view=True), parent, child)
        if child == flat.ground.name or child in parent_of or joined:
            cut.append(joint.name)
        else:
            tree.add_edge(parent, child)
            parent_of[child] = parent
    order = [n for n in nx.dfs_preorder_nodes(tree, flat.ground.name) if n != flat.ground.name]
    return order, cut


def _loop_model():
    """Two loops and a branch; joints in an order unrelated to the tree."""
    m = mb.Model("loops")
    m.add(*(body(n) for n in "ABCDEF"))
    m.add(mb.Revolute("jC", "B", "C", axis="x"))
    m.add(mb.Revolute("jA", "ground", "A", axis="x"))
    m.add(mb.Revolute("jB", "A", "B", axis="x"))
    m.add(mb.Revolute("close1", "C", "A", axis="x"))       # closes A-B-C
    m.add(mb.Revolute("jD", "ground", "D", axis="y"))
    m.add(mb.Revolute("jE", "D", "E", axis="y"))
    m.add(mb.Revolute("close2", "E", "B", axis="y"))       # closes ground-D-E-B-A
    m.add(mb.Revolute("jF", "A", "F", axis="z"))
    return m


@pytest.mark.parametrize("name", ["branched", "loops", "library"])
def test_body_order_and_cut_joints_are_networkxs(name):
    from pathlib import Path
    from mbcomp.build.flatten import flatten
    if name == "library":
        models = [mb.load(p) for p in sorted((Path(__file__).resolve().parent.parent / "library").glob("*.toml"))]
    else:
        models = [branched_model() if name == "branched" else _loop_model()]
    for model in models:
        topology = build_topology(flatten(model))
        order, cut = _networkx_spanning_tree(model)
        assert [b.name for b in topology.bodies] == order, model.name
        assert [j.name for j in topology.cut_joints] == cut, model.name
    if name == "loops":
        assert cut == ["close1", "close2"]
        graph = topology.graph  # still offered, built on first use
        assert graph.number_of_edges() == 8 and set(graph.nodes) == set("ABCDEF") | {topology.ground.name}
