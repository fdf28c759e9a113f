"""Ball, Free, Universal, Cylindrical and Planar: poses against closed forms, motion against
analytic solutions, files, the command line, results and errors."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.face.cli import main as cli_main
from mbcomp.files.toml_model import dumps, load
from mbcomp.core.rotations import axis_angle, rot_x, rot_y, rot_z

POINTS = dict(parent_point=(0.1, 0.2, 0.3), child_point=(-0.05, 0.0, 0.1))


def _origin(joint, R, translation):
    return np.asarray(joint.parent_point) + translation - R @ np.asarray(joint.child_point)


# -- poses against closed forms ---------------------------------------------------------------
def test_ball_pose_is_the_quaternion_rotation():
    joint = mb.Ball("j", "a", "b", **POINTS)
    axis, angle = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5]), 0.8
    q = np.concatenate(([np.cos(angle / 2)], np.sin(angle / 2) * axis))
    R, p = joint.relative_pose(3.0 * q)  # any non-zero multiple rotates the same way
    np.testing.assert_allclose(R, axis_angle(axis, angle), atol=1e-15)
    np.testing.assert_allclose(p, _origin(joint, R, np.zeros(3)), atol=1e-15)
    assert joint.neutral == (1.0, 0.0, 0.0, 0.0)
    np.testing.assert_allclose(joint.qdot(q, [0.0, 0.0, 0.0]), 0.0)


def test_free_pose_is_translation_then_rotation():
    joint = mb.Free("j", "a", "b", **POINTS)
    q = np.array([0.4, -0.3, 1.2, np.cos(0.3), 0.0, 0.0, np.sin(0.3)])
    R, p = joint.relative_pose(q)
    np.testing.assert_allclose(R, rot_z(0.6), atol=1e-15)
    np.testing.assert_allclose(p, _origin(joint, R, q[:3]), atol=1e-15)
    np.testing.assert_allclose(joint.qdot(q, [1.0, 2.0, 3.0, 0.0, 0.0, 0.0])[:3], [1.0, 2.0, 3.0])


def test_universal_pose_is_two_body_fixed_rotations():
    joint = mb.Universal("j", "a", "b", axes=("x", "y"), **POINTS)
    assert joint.coords == ("j_x", "j_y")
    R, p = joint.relative_pose([0.3, -0.7])
    np.testing.assert_allclose(R, rot_x(0.3) @ rot_y(-0.7), atol=1e-15)
    np.testing.assert_allclose(p, _origin(joint, R, np.zeros(3)), atol=1e-15)
    assert mb.Universal("k", "a", "b", axes=((1, 1, 0), "z")).coords == ("k_1", "k_2")


def test_cylindrical_pose_turns_and_slides_on_one_axis():
    joint = mb.Cylindrical("j", "a", "b", axis="y", **POINTS)
    assert joint.coords == ("j_angle", "j_slide")
    R, p = joint.relative_pose([0.9, 0.25])
    np.testing.assert_allclose(R, rot_y(0.9), atol=1e-15)
    np.testing.assert_allclose(p, _origin(joint, R, np.array([0.0, 0.25, 0.0])), atol=1e-15)


@pytest.mark.parametrize("normal, first, second", [("z", "x", "y"), ("x", "y", "z"), ("y", "z", "x")])
def test_planar_pose_moves_in_the_plane_and_turns_about_the_normal(normal, first, second):
    joint = mb.Planar("j", "a", "b", normal=normal, **POINTS)
    assert joint.coords == (f"j_{first}", f"j_{second}", "j_angle")
    R, p = joint.relative_pose([0.2, -0.4, 1.1])
    unit = {"x": np.eye(3)[0], "y": np.eye(3)[1], "z": np.eye(3)[2]}
    np.testing.assert_allclose(R, axis_angle(unit[normal], 1.1), atol=1e-15)
    np.testing.assert_allclose(p, _origin(joint, R, 0.2 * unit[first] - 0.4 * unit[second]), atol=1e-15)
    t1, t2 = joint.plane_axes
    np.testing.assert_allclose(np.cross(t1, t2), unit[normal], atol=1e-15)


def test_bad_arguments_name_the_joint():
    with pytest.raises(mb.ModelError, match="Universal 'u'.*parallel"):
        mb.Universal("u", "a", "b", axes=("x", "-x"))
    with pytest.raises(mb.ModelError, match="Universal 'u'.*two axes"):
        mb.Universal("u", "a", "b", axes="xy")
    with pytest.raises(mb.ModelError, match="Ball 'b'.*speeds must be 3"):
        mb.Ball("b", "p", "c", speeds=("a", "b"))
    with pytest.raises(mb.ModelError, match="Free 'f'.*named like its coordinate"):
        mb.Free("f", "p", "c", speeds=("vx", "vy", "vz", "wx", "wy", "wz"))
    with pytest.raises(mb.ModelError, match="Ball 'b'.*non-zero"):
        mb.Ball("b", "p", "c").normalize([0.0, 0.0, 0.0, 0.0])
    m = mb.Model("loop")
    a = m.add(mb.Body("a", mass=1.0))
    m.add(mb.Revolute("r", m.ground, a))
    m.add(mb.Free("f", m.ground, a))
    with pytest.raises(mb.ModelError, match="Free 'f'.*cannot close a loop"):
        m.compile()


# -- motion against analytic solutions ------------------------------------------------------------
def test_planar_body_falls_in_its_plane_and_keeps_turning():
    """A body on a planar joint with normal y (the x-z plane) under gravity (0, 0, -g):
    z = -g t^2 / 2, x = v t, the angle grows at its constant rate."""
    m = mb.Model("planar", gravity=(0, 0, -9.81))
    body = m.add(mb.Body("b", mass=2.0, com=(0.1, 0.0, 0.0), inertia=(0.01, 0.02, 0.03)))
    m.add(mb.Planar("p", m.ground, body, normal="y"))
    system = m.compile()
    assert system.coords == ("p_z", "p_x", "p_angle")
    result = system.simulate(1.0, [0.0, 0.0, 0.0], [0.0, 0.5, 3.0], t_eval=np.linspace(0, 1, 11))
    com = np.array([system.body_state("b", q).position for q in result.q])
    # the centre of mass starts at (0.1, 0, 0) with velocity (0.5, 0, 0) + (0, 3, 0) x (0.1, 0, 0)
    np.testing.assert_allclose(com[:, 2], -0.3 * result.t - 9.81 / 2 * result.t ** 2, atol=1e-9)
    np.testing.assert_allclose(com[:, 0], 0.1 + 0.5 * result.t, atol=1e-9)
    np.testing.assert_allclose(result["p_angle"], 3.0 * result.t, atol=1e-9)


def test_cylindrical_joint_slides_under_gravity_along_its_axis():
    m = mb.Model("cyl", gravity=(0, 0, -9.81))
    body = m.add(mb.Body("b", mass=1.0, com=(0.2, 0.0, 0.0), inertia=(0.01, 0.01, 0.02)))
    m.add(mb.Cylindrical("c", m.ground, body, axis="z"))
    result = m.compile().simulate(0.5, [0.0, 0.0], [4.0, 0.0], t_eval=np.linspace(0, 0.5, 6))
    np.testing.assert_allclose(result["c_slide"], -9.81 / 2 * result.t ** 2, atol=1e-9)
    np.testing.assert_allclose(result["c_angle"], 4.0 * result.t, atol=1e-9)


def test_universal_pendulum_conserves_energy_and_matches_euler_xy():
    def build(joint):
        m = mb.Model("cardan", gravity=(0, 0, -9.81))
        body = m.add(mb.Body("b", mass=1.0, com=(0.0, 0.0, -0.5), inertia=(0.02, 0.03, 0.01)))
        m.add(joint(m.ground, body))
        return m.compile()
    universal = build(lambda p, c: mb.Universal("u", p, c, axes=("x", "y")))
    euler = build(lambda p, c: mb.Spherical("u", p, c, sequence="xy"))
    q, v = [0.4, -0.3], [0.5, 1.0]
    np.testing.assert_array_equal(universal.mass_matrix(q), euler.mass_matrix(q))
    a = universal.simulate(1.0, q, v, rtol=1e-10, atol=1e-12)
    assert np.ptp(a.energy().total) < 1e-8


# -- torques, results, files and the command line ----------------------------------------------------
def _ball_model() -> mb.Model:
    m = mb.Model("ballmodel", gravity=(0, 0, -9.81))
    body = m.add(mb.Body("top", mass=0.1, com=(0, 0, 0.04), inertia=(1.3e-4, 1.3e-4, 2e-4)))
    m.add(mb.Ball("pivot", m.ground, body))
    return m


def test_torque_on_a_ball_is_in_the_child_frame():
    """A torque about the child's z axis on a body resting on a ball, without gravity,
    spins it up about that axis at torque / I3."""
    m = mb.Model("spin", gravity=(0, 0, 0))
    body = m.add(mb.Body("b", mass=1.0, inertia=(0.2, 0.3, 0.4)))
    m.add(mb.Ball("ball", m.ground, body))
    m.add(mb.JointTorque("motor", "ball", value=(0.0, 0.0, 0.8)))
    system = m.compile()
    q = [np.cos(0.4), np.sin(0.4), 0.0, 0.0]  # tilted: the child frame is not the world's
    np.testing.assert_allclose(system.accelerations(q, [0.0, 0.0, 0.0]), [0.0, 0.0, 2.0], atol=1e-12)
    with pytest.raises(mb.ModelError, match="3 speed"):
        m2 = _ball_model()
        m2.add(mb.JointTorque("bad", "pivot", value=(1.0, 2.0, 3.0, 4.0)))
        m2.compile()


def test_result_speeds_and_csv(tmp_path):
    system = _ball_model().compile()
    result = system.simulate(0.2, [1.0, 0.1, 0.0, 0.0], [0.0, 0.0, 50.0], t_eval=np.linspace(0, 0.2, 5))
    assert result.q.shape == (5, 4) and result.qd.shape == (5, 3)
    assert result.speeds == ("pivot_wx", "pivot_wy", "pivot_wz")
    np.testing.assert_array_equal(result["pivot_wy"], result.qd[:, 1])
    np.testing.assert_array_equal(result["pivot_qx"], result.q[:, 1])
    path = tmp_path / "ball.csv"
    result.to_csv(path)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:8] == ["t", "pivot_qw", "pivot_qx", "pivot_qy", "pivot_qz", "pivot_wx", "pivot_wy", "pivot_wz"]
    figure = result.plot(("q", "qd"))
    labels = [ax.get_ylabel() for ax in figure.axes]
    assert "quaternion (1)" in labels and "angular speed (rad/s)" in labels


def test_files_round_trip_every_new_joint(tmp_path):
    m = mb.Model("all_joints", gravity=(0, 0, -9.81))
    names = ["b1", "b2", "b3", "b4", "b5"]
    bodies = [m.add(mb.Body(n, mass=1.0 + i, com=(0.1, 0.0, -0.1 * i), inertia=(0.01, 0.02, 0.03)))
              for i, n in enumerate(names)]
    m.add(mb.Free("fly", m.ground, bodies[0]))
    m.add(mb.Ball("ball", bodies[0], bodies[1], parent_point=(0.1, 0, 0), speeds=("p", "r", "y")))
    m.add(mb.Universal("cardan", bodies[1], bodies[2], axes=("z", (1.0, 1.0, 0.0))))
    m.add(mb.Cylindrical("cyl", bodies[2], bodies[3], axis=(0.0, 0.6, 0.8)))
    m.add(mb.Planar("plane", bodies[3], bodies[4], normal="x"))
    text = dumps(m)
    for kind in ('type = "free"', 'type = "ball"', 'type = "universal"', 'type = "cylindrical"', 'type = "planar"'):
        assert kind in text
    path = tmp_path / "all.toml"
    path.write_text(text)
    again = load(path)
    a, b = m.compile(backend="python"), again.compile(backend="python")  # (the file is the subject here)
    assert a.coords == b.coords and a.speeds == b.speeds
    assert "p" in a.speeds and a.nq == 7 + 4 + 2 + 2 + 3 and a.nv == 6 + 3 + 2 + 2 + 3
    rng = np.random.default_rng(1)
    q, v = a.state_vector(rng.uniform(-1, 1, a.nq)), rng.uniform(-1, 1, a.nv)
    # (an oblique axis is written to 16 digits and normalised again when read)
    np.testing.assert_allclose(a.mass_matrix(q), b.mass_matrix(q), rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(a.accelerations(q, v), b.accelerations(q, v), rtol=1e-9, atol=1e-12)


def test_file_initial_values_name_ball_speeds(tmp_path):
    path = tmp_path / "top.toml"
    path.write_text('description = "A top on a ball joint, for the file reader test."\nname = "top"\n'
                    '[bodies.top]\nmass = 0.1\ncom = [0, 0, 0.04]\ninertia = [1.3e-4, 1.3e-4, 2e-4]\n'
                    '[joints.pivot]\ntype = "ball"\nparent = "ground"\nchild = "top"\n'
                    '[initial.qd]\npivot_wz = 100.0\n')
    model = load(path)
    assert model.initial["qd"] == {"pivot_wz": 100.0}
    path.write_text(path.read_text().replace("pivot_wz", "pivot_wq"))
    with pytest.raises(mb.ModelError, match="pivot_wq"):
        load(path)


def test_cli_info_and_run_on_the_ball_top(capsys, tmp_path):
    assert cli_main(["info", "spinning_top"]) == 0
    out = capsys.readouterr().out
    assert "pivot: ball, ground -> top" in out
    assert "speeds       pivot_wx, pivot_wy, pivot_wz (3;" in out
    assert "M[2,2]" in out and "f[2]" in out and "M[3," not in out
    # Unit quaternions make M the constant inertia about the pivot: I1 + m h^2, I3.
    assert "M[0,0] = 0.00029\n" in out and "M[2,2] = 0.0002\n" in out and "M[0,1]" not in out
    csv = tmp_path / "top.csv"
    assert cli_main(["run", "spinning_top", "--t-end", "0.05", "--out", str(csv)]) == 0
    out = capsys.readouterr().out
    assert "pivot_wz" in out and "pivot_qw" in out
    assert "pivot_wz" in csv.read_text().splitlines()[0]


def test_state_map_of_a_tree_matches_its_joints():
    """The whole-tree ``q' = G(q) v``, ``integrate`` and ``difference`` agree with each
    joint's own, and ``difference`` undoes ``integrate``."""
    m = mb.Model("mixed")
    a = m.add(mb.Body("a", mass=1.0, inertia=(0.1, 0.2, 0.25)))
    b = m.add(mb.Body("b", mass=1.0, inertia=(0.1, 0.2, 0.25)))
    c = m.add(mb.Body("c", mass=1.0, inertia=(0.1, 0.2, 0.25)))
    m.add(mb.Free("f", m.ground, a))
    m.add(mb.Revolute("r", a, b, axis="y"))
    m.add(mb.Ball("k", b, c))
    system = m.compile(backend="python")
    state_map = system.topology.state_map
    rng = np.random.default_rng(2)
    q = system.state_vector(rng.uniform(-1, 1, system.nq))
    v, dv = rng.normal(size=system.nv), rng.uniform(-0.5, 0.5, system.nv)
    q1 = state_map.integrate(q, dv)
    np.testing.assert_allclose(state_map.difference(q, q1), dv, atol=1e-12)
    for joint in system.topology.tree_joints:
        sq, sv = system.topology.q_slice[joint.name], system.topology.v_slice[joint.name]
        np.testing.assert_allclose(state_map.qdot(q, v)[sq], joint.qdot(q[sq], v[sv]), atol=1e-15)
        np.testing.assert_allclose(q1[sq], joint.integrate(q[sq], dv[sv]), atol=1e-15)
    np.testing.assert_allclose(state_map.neutral(), [0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0])


def test_system_integrate_difference_and_rates():
    system = _ball_model().compile()
    q = system.state_vector([1.0, 0.2, -0.1, 0.3])
    dv = np.array([0.1, -0.2, 0.05])
    q1 = system.integrate(q, dv)
    np.testing.assert_allclose(system.difference(q, q1), dv, atol=1e-12)
    R0, R1 = system.body_state("top", q).rotation, system.body_state("top", q1).rotation
    np.testing.assert_allclose(R1, R0 @ axis_angle(dv / np.linalg.norm(dv), np.linalg.norm(dv)), atol=1e-12)
    w = np.array([0.0, 0.0, 2.0])
    rate = system.coordinate_rates(q, w)
    np.testing.assert_allclose(rate @ q, 0.0, atol=1e-15)  # keeps |q| = 1
    np.testing.assert_allclose(rate, [-q[3], q[2], -q[1], q[0]], atol=1e-15)  # q (0, 0, 0, 2) / 2
