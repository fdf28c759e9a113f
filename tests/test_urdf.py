"""URDF import: real robots against Pinocchio's own URDF reader, and the mapping piece by piece
on a small hand-written robot."""
import importlib.util
import warnings

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.files.library import library_robots

# Checked without importing them (about 1 s): a test worker that runs none of these tests
# does not pay for Pinocchio and yourdfpy at collection.
pytestmark = [
    pytest.mark.skipif(importlib.util.find_spec("pinocchio") is None,
                       reason="Pinocchio is a test dependency (pip install pin)"),
    pytest.mark.skipif(importlib.util.find_spec("yourdfpy") is None,
                       reason="yourdfpy is the URDF parser (pip install yourdfpy)"),
]

ROBOTS = library_robots()


def pinocchio_check(path, system, states=3, seed=0):
    """Largest relative differences of the mass matrix and of the forward dynamics (ABA) at
    random states, mbcomp against Pinocchio (joints matched by name; a continuous joint is
    (cos, sin) in Pinocchio's q)."""
    import pinocchio as pin
    model = pin.buildModelFromUrdf(str(path))
    data = model.createData()
    joints = list(model.joints)[1:]
    perm = [list(system.coords).index(name) for name in list(model.names)[1:]]
    assert all(j.nv == 1 for j in joints) and len(perm) == system.nq == model.nv
    rng = np.random.default_rng(seed)
    worst_m = worst_a = 0.0
    for _ in range(states):
        angle, v, tau = rng.uniform(-1.5, 1.5, model.nv), rng.uniform(-2, 2, model.nv), rng.uniform(-10, 10, model.nv)
        q = np.zeros(model.nq)
        for k, j in enumerate(joints):
            q[j.idx_q:j.idx_q + j.nq] = (np.cos(angle[k]), np.sin(angle[k])) if j.nq == 2 else angle[k]
        qm, vm, tm = (np.zeros(system.nq) for _ in range(3))
        qm[perm], vm[perm], tm[perm] = angle, v, tau
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        worst_m = max(worst_m, np.abs(system.mass_matrix(qm)[np.ix_(perm, perm)] - M).max() / np.abs(M).max())
        a = pin.aba(model, data, q, v, tau)
        worst_a = max(worst_a, np.abs(system.accelerations(qm, vm, tau=tm)[perm] - a).max() / np.abs(a).max())
    return worst_m, worst_a


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_robot_matches_pinocchio(name):
    if name not in ROBOTS:
        pytest.skip("example-robot-data is a test dependency (pip install example-robot-data)")
    with pytest.warns(UserWarning, match="not modelled"):
        model = mb.load(name)             # a library robot's name, as the command line takes it
    system = model.compile()
    assert system.nq == {"ur5": 6, "panda": 9}[name]
    worst_m, worst_a = pinocchio_check(ROBOTS[name], system)
    assert worst_m < 1e-10 and worst_a < 1e-10, (worst_m, worst_a)
    assert model.joint_limits and all(lo < hi for lo, hi in model.joint_limits.values())
    bodies = [c for c in system.topology.bodies]
    assert all(b.shape for b in bodies)   # every link drawn from its visual meshes


SMALL = """<?xml version="1.0"?>
<robot name="small">
  <material name="steel"><color rgba="0.5 0.5 0.6 1"/></material>
  <link name="base">
    <visual><geometry><box size="0.2 0.2 0.1"/></geometry><material name="steel"/></visual>
  </link>
  <link name="arm">
    <inertial><origin xyz="0 0 0.25" rpy="0.3 0 0"/><mass value="2.0"/>
      <inertia ixx="0.05" ixy="0.001" ixz="0" iyy="0.04" iyz="0" izz="0.01"/></inertial>
    <visual><origin xyz="0 0 0.25"/><geometry><cylinder radius="0.03" length="0.5"/></geometry>
      <material name="red"><color rgba="1 0 0 1"/></material></visual>
    <visual><geometry><mesh filename="package://nowhere/meshes/arm.stl"/></geometry></visual>
  </link>
  <link name="weight">
    <inertial><origin xyz="0.05 0 0"/><mass value="1.0"/>
      <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/></inertial>
    <visual><geometry><sphere radius="0.05"/></geometry></visual>
  </link>
  <link name="slider">
    <inertial><mass value="0.5"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.002"/></inertial>
  </link>
  <link name="tip">
    <inertial><origin xyz="0.1 0 0"/><mass value="0.3"/>
      <inertia ixx="0.0005" ixy="0" ixz="0" iyy="0.0006" iyz="0" izz="0.0007"/></inertial>
  </link>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="arm"/><origin xyz="0 0 0.1" rpy="0.2 -0.4 0.7"/>
    <axis xyz="0 1 0"/><limit lower="-1.5" upper="1.5" effort="50" velocity="2"/>
    <dynamics damping="0.1"/>
  </joint>
  <joint name="weld" type="fixed">
    <parent link="arm"/><child link="weight"/><origin xyz="0 0.02 0.5" rpy="0 0.5 0"/>
  </joint>
  <joint name="rail" type="prismatic">
    <parent link="weight"/><child link="slider"/><origin xyz="0.1 0 0" rpy="0 0 1.0"/>
    <axis xyz="1 0 0"/><limit lower="-0.2" upper="0.2" effort="10" velocity="1"/>
  </joint>
  <joint name="wrist" type="continuous">
    <parent link="slider"/><child link="tip"/><origin xyz="0 0 0.05" rpy="1.0 0.2 -0.3"/>
    <axis xyz="0.6 0 0.8"/>
  </joint>
</robot>
"""


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    path = tmp_path_factory.mktemp("urdf") / "small.urdf"
    path.write_text(SMALL)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = mb.load(path)
    return path, model, model.compile(), [str(w.message) for w in caught]


def test_small_robot_matches_pinocchio(small):
    path, model, system, _ = small
    assert system.coords == ("shoulder", "rail", "wrist")
    worst_m, worst_a = pinocchio_check(path, system, states=4)
    assert worst_m < 1e-10 and worst_a < 1e-10, (worst_m, worst_a)


def test_fixed_joint_welds_masses(small):
    """The arm carries the welded weight: total mass, COM and inertia by the parallel-axis
    theorem, computed here from the URDF numbers."""
    _, model, system, _ = small
    arm = system.topology.resolve("arm")
    assert arm.mass == pytest.approx(3.0)
    R_in = mb.rpy(0.3, 0, 0)
    I_arm = R_in @ np.array([[0.05, 0.001, 0], [0.001, 0.04, 0], [0, 0, 0.01]]) @ R_in.T
    R_w, p_w = mb.rpy(0, 0.5, 0), np.array([0, 0.02, 0.5])
    c_arm, c_w = np.array([0, 0, 0.25]), p_w + R_w @ np.array([0.05, 0, 0])
    com = (2.0 * c_arm + 1.0 * c_w) / 3.0
    inertia = I_arm + R_w @ (0.001 * np.eye(3)) @ R_w.T
    for m, c in ((2.0, c_arm), (1.0, c_w)):
        d = c - com
        inertia = inertia + m * (d @ d * np.eye(3) - np.outer(d, d))
    np.testing.assert_allclose(arm.com, com, atol=1e-14)
    np.testing.assert_allclose(arm.inertia_matrix(), inertia, atol=1e-14)
    assert "weight" not in system.topology.components


def test_unmodelled_features_are_named(small):
    _, model, _, messages = small
    (message,) = messages
    for text in ("joint position limits", "shoulder, rail", "joint damping and friction: shoulder",
                 "visual meshes whose file was not found", "package://nowhere/meshes/arm.stl"):
        assert text in message
    assert model.joint_limits == {"shoulder": (-1.5, 1.5), "rail": (-0.2, 0.2)}


def test_visuals_become_shapes(small):
    _, model, system, _ = small
    base = system.topology.ground.shape
    assert len(base) == 1 and base[0].size == (0.2, 0.2, 0.1) and base[0].color == "#808099"
    arm = system.topology.resolve("arm")
    kinds = [type(s).__name__ for s in arm.shape]
    assert kinds == ["Cylinder", "Sphere"]   # the missing mesh is left out (and warned about)
    cylinder, sphere = arm.shape
    assert cylinder.color == "#ff0000" and cylinder.origin == (0, 0, 0.25)
    # The welded link's sphere sits at the weld, in the arm's frame.
    np.testing.assert_allclose(sphere.origin, [0, 0.02, 0.5], atol=1e-15)


def test_cli_runs_a_urdf_file(small, tmp_path):
    from mbcomp.face.cli import main
    path = small[0]
    out = tmp_path / "small.html"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["run", str(path), "--t-end", "0.2", "--html", str(out), "--no-progress"]) == 0
    assert out.stat().st_size > 500_000


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('type="continuous"', 'type="planar"'), "type 'planar' is not supported"),
    (lambda t: t.replace('<inertial><mass value="0.5"/><inertia ixx="0.002" ixy="0" ixz="0" iyy="0.002" '
                         'iyz="0" izz="0.002"/></inertial>', ''), "moves but has no mass"),
    (lambda t: "not xml at all", "not a readable URDF"),
])
def test_bad_urdf_is_a_model_error(tmp_path, edit, message):
    path = tmp_path / "bad.urdf"
    path.write_text(edit(SMALL))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(mb.ModelError, match=message):
            mb.load_urdf(path)


def test_missing_file():
    with pytest.raises(mb.ModelError, match="no such file"):
        mb.load_urdf("/nonexistent/robot.urdf")


def test_limits_can_be_enforced(small):
    path = small[0]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = mb.load_urdf(path, limits=True)
    assert not any("position limits" in str(w.message) for w in caught)
    system = model.compile()
    stops = {c.name: (c.lower, c.upper) for c in system.topology.components.values()
             if isinstance(c, mb.JointLimit)}
    assert stops == {"shoulder_limit": (-1.5, 1.5), "rail_limit": (-0.2, 0.2)}
    from mbcomp.face.viewer import build_scene
    assert build_scene(system.simulate(0.05, [0.0, 0.0, 0.0]))["contacts"] == []   # stops are no spatial marks
    # Thrown against its upper stop, the shoulder stays within it (inelastic stop).
    res = system.simulate(0.5, [1.4, 0.0, 0.0], [3.0, 0.0, 0.0])
    assert res["shoulder"].max() <= 1.5 + 1e-6 and res["shoulder"].max() > 1.5 - 1e-3
    assert any(str(e.contact).startswith("shoulder_limit") for e in res.events)


def test_floating_robot_conserves_energy_and_momentum(tmp_path):
    """``floating=True``: the root joins the ground by a ``Free`` joint.  Without gravity and
    torques, the total energy and the linear momentum (sum of m v_com) stay constant."""
    base_inertial = ('<link name="base">\n    <inertial><origin xyz="0.01 0 0.02"/><mass value="3.0"/>'
                     '<inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.04"/></inertial>')
    path = tmp_path / "floating.urdf"
    path.write_text(SMALL.replace('<link name="base">', base_inertial))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = mb.load_urdf(path, floating=True, gravity=(0, 0, 0))
    system = model.compile()
    assert len(system.coords) == 10 and len(system.speeds) == 9
    q0 = [0, 0, 0, 1, 0, 0, 0, 0.3, 0.05, 0.2]
    qd0 = [0.1, -0.2, 0.05, 0.3, -0.5, 0.8, 1.0, 0.2, -2.0]
    res = system.simulate(1.0, q0, qd0, rtol=1e-10, atol=1e-12, t_eval=[0.0, 0.5, 1.0])

    def momentum(q, qd):
        return sum(model[b].mass * system.body_state(b, q, qd).velocity for b in ("base", "arm", "slider", "tip"))

    energy = res.energy().total
    p0 = momentum(res.q[0], res.qd[0])
    assert energy[0] > 0.1 and np.linalg.norm(p0) > 0.5
    assert np.max(np.abs(energy - energy[0])) < 1e-8 * energy[0]
    for i in (1, 2):
        assert np.linalg.norm(momentum(res.q[i], res.qd[i]) - p0) < 1e-8 * np.linalg.norm(p0)
    assert np.allclose(np.linalg.norm(res.q[:, 3:7], axis=1), 1.0, atol=1e-12)
