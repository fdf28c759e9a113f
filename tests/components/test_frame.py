"""Frames: points fixed on bodies, optionally rotated; joints between rotated frames."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.rotations import axis_angle
from tests.conftest import G, assert_close, bar


def test_rpy_is_the_urdf_convention():
    r, p, y = 0.3, -0.7, 1.1
    expected = axis_angle((0, 0, 1), y) @ axis_angle((0, 1, 0), p) @ axis_angle((1, 0, 0), r)
    assert_close(mb.rpy(r, p, y), expected, name="rpy")
    # a pure yaw of 90 degrees takes x to y
    assert_close(mb.rpy(0, 0, np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15, name="yaw")


def test_frame_carries_body_point_rotation():
    body = mb.Body("b", mass=1.0)
    f = body.frame((0.1, 0.2, 0.3), mb.rpy(0.1, 0.2, 0.3))
    assert f.body is body and f.point == (0.1, 0.2, 0.3)
    assert_close(f.rotation_matrix, mb.rpy(0.1, 0.2, 0.3), name="rotation")
    assert body.frame().rotation is None and body.frame().point == (0.0, 0.0, 0.0)
    assert body.frame(rotation=np.eye(3)).rotation is None  # identity = no rotation


@pytest.mark.parametrize("bad", [np.diag([1.0, 1.0, -1.0]), np.ones((3, 3)), np.eye(2), [[np.nan] * 3] * 3])
def test_frame_rejects_non_rotations(bad):
    with pytest.raises(mb.ModelError, match="rotation"):
        mb.Body("b").frame(rotation=bad)


def test_frame_and_point_together_is_an_error():
    b = mb.Body("b")
    with pytest.raises(mb.ModelError, match="parent is a Frame"):
        mb.Revolute("j", b.frame((1, 0, 0)), mb.Body("c"), parent_point=(1, 0, 0))


def test_components_accept_frames_like_body_and_point():
    m = mb.Model("m")
    b = m.add(mb.Body("b", mass=1.0))
    f = b.frame((0.1, 0.0, -0.2))
    assert mb.Spring("s", a=f, b=m.ground.frame((0, 0, 1)), stiffness=1.0).point_a == (0.1, 0.0, -0.2)
    force = mb.Force("f", f, force=(0, 0, 1))
    assert force.body is b and force.point == (0.1, 0.0, -0.2)
    contact = mb.Contact("c", f)
    assert contact.body is b and contact.point == (0.1, 0.0, -0.2)
    slider = mb.Slider("sl", f, axis="z")
    assert slider.body is b and slider.point == (0.1, 0.0, -0.2)
    joint = mb.Revolute("j", m.ground.frame((0, 0, 1)), f, axis="x")
    assert joint.parent is m.ground and joint.parent_point == (0, 0, 1) and joint.child_point == (0.1, 0.0, -0.2)
    assert joint.structure() == mb.Revolute("j2", m.ground, b, axis="x").structure()  # unrotated: same code


def _rotated_pendulum(rp, rc):
    m = mb.Model("rot", gravity=(0, 0, -G))
    rod = m.add(mb.Body("rod", mass=1.2, com=(0.1, -0.05, -0.3), inertia=(0.02, 0.03, 0.01)))
    mid = m.add(mb.Body("mid", mass=0.7, com=(0.0, 0.2, 0.0), inertia=(0.01, 0.004, 0.012)))
    m.add(mb.Revolute("j1", m.ground.frame((0.1, 0, 0), rp), mid.frame((0, 0, 0.05), rc), axis="z"))
    m.add(mb.Prismatic("j2", mid.frame((0, 0.3, 0), rc), rod.frame((0, 0, 0.1), rp), axis="x"))
    return m


def test_joint_between_rotated_frames_matches_the_pose_formula():
    rp, rc = mb.rpy(0.4, -0.3, 1.2), mb.rpy(-0.2, 0.9, 0.1)
    system = _rotated_pendulum(rp, rc).compile(backend="python")
    q = np.array([0.7, 0.15])
    j1, j2 = system.topology.components["j1"], system.topology.components["j2"]
    R1, p1 = j1.relative_pose(q[:1])
    R2, p2 = j2.relative_pose(q[1:])
    # independent: R_child = R_parent R_pf R_joint(q) R_cf^T
    assert_close(R1, rp @ axis_angle((0, 0, 1), 0.7) @ rc.T, name="R1 formula")
    mid, rod = system.body_state("mid", q), system.body_state("rod", q)
    assert_close(mid.rotation, R1, name="mid rotation")
    assert_close(system.body_state("mid", q, point=(0, 0, 0.05)).position, [0.1, 0, 0], atol=1e-14,
                 name="child frame origin on the parent frame origin")
    assert_close(rod.rotation, R1 @ R2, name="rod rotation")
    assert_close(system.body_state("rod", q, point=(0, 0, 0)).position, p1 + R1 @ p2, name="rod origin")


def test_at_zero_coordinates_the_frames_coincide():
    rp, rc = mb.rpy(0.4, -0.3, 1.2), mb.rpy(-0.2, 0.9, 0.1)
    system = _rotated_pendulum(rp, rc).compile(backend="python")
    mid = system.body_state("mid", [0.0, 0.0])
    assert_close(mid.rotation @ rc, rp, name="child frame axes = parent frame axes")


def test_rotated_frames_give_the_dynamics_of_the_rotated_axis():
    """Same rotation R on both ends of a revolute about z = a plain revolute about R z."""
    R = mb.rpy(0.5, 0.8, -0.4)
    m1 = mb.Model("framed", gravity=(0, 0, -G))
    a = m1.add(mb.Body("a", mass=1.0, com=(0.2, 0.1, -0.3), inertia=(0.03, 0.02, 0.01)))
    b = m1.add(mb.Body("b", mass=0.5, com=(0.0, 0.1, -0.2), inertia=(0.01, 0.02, 0.015)))
    m1.add(mb.Revolute("j1", m1.ground.frame(rotation=R), a.frame(rotation=R), axis="z"))
    m1.add(mb.Revolute("j2", a.frame((0, 0, -0.4), R), b.frame((0, 0.1, 0), R), axis="y"))
    m2 = mb.Model("plain", gravity=(0, 0, -G))
    a2 = m2.add(mb.Body("a", mass=1.0, com=(0.2, 0.1, -0.3), inertia=(0.03, 0.02, 0.01)))
    b2 = m2.add(mb.Body("b", mass=0.5, com=(0.0, 0.1, -0.2), inertia=(0.01, 0.02, 0.015)))
    m2.add(mb.Revolute("j1", m2.ground, a2, axis=R @ [0, 0, 1]))
    m2.add(mb.Revolute("j2", a2, b2, axis=R @ [0, 1, 0], parent_point=(0, 0, -0.4), child_point=(0, 0.1, 0)))
    s1, s2 = m1.compile(), m2.compile()
    rng = np.random.default_rng(3)
    for _ in range(3):
        q, qd = rng.normal(size=2), rng.normal(size=2)
        assert_close(s1.mass_matrix(q), s2.mass_matrix(q), name="mass matrix")
        assert_close(s1.accelerations(q, qd), s2.accelerations(q, qd), name="accelerations")
        assert_close(s1.energy(q, qd).total, s2.energy(q, qd).total, name="energy")


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_loop_closed_by_a_joint_between_rotated_frames(formulation):
    """Four-bar closed by a revolute about z written as a revolute about x between frames
    whose x axes are the bodies' z axes: same motion as the plain four-bar."""
    L1, L2, L3, d = 0.3, 0.8, 0.6, 0.7
    R = mb.rpy(0, -np.pi / 2, 0)   # frame x axis = body z axis
    assert_close(R @ [1, 0, 0], [0, 0, 1], atol=1e-15, name="frame x")
    models = []
    for framed in (False, True):
        m = mb.Model("fb", gravity=(0, -G, 0))
        crank, coupler, rocker = (m.add(bar(n, L)) for n, L in (("crank", L1), ("coupler", L2), ("rocker", L3)))
        m.add(mb.Revolute("A", m.ground, crank, axis="z"))
        m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(L1, 0, 0)))
        m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(d, 0, 0)))
        if framed:
            m.add(mb.Revolute("C", coupler.frame((L2, 0, 0), R), rocker.frame((L3, 0, 0), R), axis="x"))
        else:
            m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(L2, 0, 0), child_point=(L3, 0, 0)))
        models.append(m.compile(formulation))
    plain, framed = models
    q0, _ = plain.assemble([0.5, 0.4, 1.5])
    assert framed.constraint_violation(q0) < 1e-10
    r1, r2 = (s.simulate(0.5, q0, t_eval=[0.5]) for s in (plain, framed))
    assert_close(r2.q[-1], r1.q[-1], rtol=1e-7, atol=1e-9, name="q(0.5)")


def test_rotated_fixed_joint_locks_the_relative_rotation():
    R = mb.rpy(0.3, 0.2, -0.5)
    m = mb.Model("weld", gravity=(0, 0, -G))
    a = m.add(mb.Body("a", mass=1.0, com=(0, 0, -0.2), inertia=(0.01, 0.01, 0.01)))
    b = m.add(mb.Body("b", mass=1.0, com=(0.1, 0, 0), inertia=(0.01, 0.02, 0.01)))
    m.add(mb.Revolute("hinge", m.ground, a, axis="x"))
    m.add(mb.Fixed("weld", a.frame((0, 0, -0.4), R), b.frame()))
    s = m.compile(backend="python")
    for q in (0.0, 0.9):
        assert_close(s.body_state("b", [q]).rotation, axis_angle((1, 0, 0), q) @ R, name="welded rotation")


def test_rotated_frames_round_trip_through_a_file(tmp_path):
    m = _rotated_pendulum(mb.rpy(0.4, -0.3, 1.2), mb.rpy(-0.2, 0.9, 0.1))
    path = tmp_path / "rot.toml"
    m.save(path)
    back = mb.load(path)
    assert back["j1"].parent_rotation == m["j1"].parent_rotation
    assert back["j2"].child_rotation == m["j2"].child_rotation
    q, qd = [0.3, 0.1], [0.5, -0.2]
    s1, s2 = m.compile(), back.compile()
    assert_close(s2.accelerations(q, qd), s1.accelerations(q, qd), name="accelerations after the round trip")


def test_file_rotation_that_is_not_a_rotation_is_located(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\n[bodies.a]\nmass = 1.0\n[joints.j]\ntype = "revolute"\nparent = "ground"\n'
                    'child = "a"\naxis = "z"\nparent_rotation = [[1, 0, 0], [0, 1, 0], [0, 0, 2]]\n')
    with pytest.raises(mb.ModelError, match=r"\[joints.j\] parent_rotation.*rotation"):
        mb.load(path)


def _hanging(reverse: bool, connect: bool = False, swap_weld: bool = False):
    """ground -> a (revolute x) -> b (revolute y) -> c (weld), with every joint optionally
    given from child to parent."""
    m = mb.Model("rev", gravity=(0, 0, -G))
    a = m.add(mb.Body("a", mass=1.0, com=(0, 0, -0.2), inertia=(0.01, 0.02, 0.01)))
    b = m.add(mb.Body("b", mass=0.5, com=(0.1, 0, -0.1), inertia=(0.01, 0.01, 0.02)))
    c = m.add(mb.Body("c", mass=0.3, com=(0, 0.1, 0), inertia=(0.003, 0.002, 0.004)))
    R = mb.rpy(0.2, 0.1, 0.4)
    ends = [(m.ground.frame((0, 0, 0.1)), a.frame((0, 0, 0.05))),
            (a.frame((0, 0, -0.4), R), b.frame((0.02, 0, 0))),
            (b.frame((0.1, 0, -0.3)), c.frame((0, 0, 0.1), R.T))]
    if reverse:
        ends = [(y, x) for x, y in ends]
    if swap_weld:
        ends[2] = ends[2][::-1]
    m.add(mb.Revolute("j1", *ends[0], axis="x"))
    m.add(mb.Prismatic("j2", *ends[1], axis="y"))
    if connect:
        m.connect(*ends[2])
    else:
        m.add(mb.Fixed("j3", *ends[2]))
    return m


def test_joints_given_from_child_to_parent_are_turned_around():
    forward, backward = _hanging(False).compile(), _hanging(True).compile()
    assert backward.coords == forward.coords == ("j1", "j2")
    rng = np.random.default_rng(5)
    # A joint's coordinate moves its child relative to its parent: given backwards, the
    # coordinates count the other way (q -> -q for these revolute and prismatic joints).
    for _ in range(3):
        q, qd = rng.normal(size=2), rng.normal(size=2)
        assert_close(backward.mass_matrix(-q), forward.mass_matrix(q), name="mass matrix")
        assert_close(backward.accelerations(-q, -qd), -forward.accelerations(q, qd), name="accelerations")
        assert_close(backward.body_state("c", -q).position, forward.body_state("c", q).position, name="c position")


def test_connect_welds_two_frames_either_way():
    reference = _hanging(False).compile()
    for reverse in (False, True):
        m = _hanging(False, connect=True, swap_weld=reverse)
        name = "weld_c_b" if reverse else "weld_b_c"
        assert isinstance(m[name], mb.Fixed)
        s = m.compile()
        q, qd = [0.3, -0.1], [0.4, 0.2]
        assert_close(s.accelerations(q, qd), reference.accelerations(q, qd), name="accelerations")
        assert_close(s.body_state("c", q).rotation, reference.body_state("c", q).rotation, name="c rotation")


def test_connect_needs_frames():
    m = mb.Model("m")
    b = m.add(mb.Body("b"))
    with pytest.raises(mb.ModelError, match="two Frames"):
        m.connect(m.ground, b.frame())
