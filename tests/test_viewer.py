"""The 3D viewer's page data: poses, shapes, marks, the self-contained page (no browser here;
tests/test_viewer_browser.py opens the page in Chromium)."""
import base64
import json
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mbcomp as mb
from mbcomp.face.viewer import Viewer, build_scene, render_page
from mbcomp.face.viewer.page import CSP, three_script
from mbcomp.face.viewer.scene import frame_times, resample


def decode(scene, key="poses"):
    return np.frombuffer(base64.b64decode(scene[key]), dtype="<f4")


@pytest.fixture(scope="module")
def pendulum():
    model = mb.load("double_pendulum")
    system = model.compile()
    return system


def test_poses_are_the_analytic_double_pendulum(pendulum):
    """bar1 turns about the origin by phi1; bar2 hangs at R(phi1) (L, 0, 0) turned by phi1 + theta2."""
    times = frame_times(np.array([0.0, 1.0]), fps=30, max_frames=1000)
    res = pendulum.simulate(1.0, [1.2, -0.4], t_eval=times)
    scene = build_scene(res, fps=30)
    assert scene["frames"] == len(times) == 31 and scene["nbodies"] == 2
    poses = decode(scene).reshape(scene["frames"], 2, 7)
    L = 0.55
    phi1, theta2 = res["phi1"], res["theta2"]
    np.testing.assert_allclose(poses[:, 0, :3], 0.0, atol=1e-6)
    expected_b = np.column_stack([L * np.cos(phi1), L * np.sin(phi1), 0 * phi1])
    np.testing.assert_allclose(poses[:, 1, :3], expected_b, atol=2e-6)
    for k, angle in ((0, phi1), (1, phi1 + theta2)):
        R = Rotation.from_quat(poses[:, k, 3:].astype(float)).as_matrix()
        np.testing.assert_allclose(R, Rotation.from_euler("z", angle[:, None]).as_matrix(), atol=2e-6)
    # Gravity along +x: up is -x; the motion fits in the reported box.
    assert scene["up"] == [-1.0, 0.0, 0.0]
    c1, s1, c12, s12 = np.cos(phi1), np.sin(phi1), np.cos(phi1 + theta2), np.sin(phi1 + theta2)
    cloud = np.concatenate([[[0.0, 0.0]], np.column_stack([L / 2 * c1, L / 2 * s1]),
                            np.column_stack([L * c1, L * s1]),
                            np.column_stack([L * c1 + L / 2 * c12, L * s1 + L / 2 * s12])])
    assert scene["size"] == pytest.approx(np.max(cloud.max(axis=0) - cloud.min(axis=0)), rel=1e-6)


def test_resample_is_exact_at_samples_and_cubic_between():
    t = np.linspace(0, 1, 6)
    q = np.column_stack([t ** 3, np.sin(t)])
    qd = np.column_stack([3 * t ** 2, np.cos(t)])
    times = np.linspace(0, 1, 41)
    out = resample(t, q, times, qd)
    np.testing.assert_allclose(out[:, 0], times ** 3, atol=1e-12)      # Hermite is exact for cubics
    np.testing.assert_allclose(out[::8], q, atol=1e-14)
    # Speeds of another length (nq != nv): linear interpolation.
    lin = resample(t, q, times, qd[:, :1])
    np.testing.assert_allclose(lin[:, 1], np.interp(times, t, q[:, 1]))


def test_impact_splits_the_interpolation():
    """At a repeated time (an impact) the pieces are interpolated separately."""
    t = np.array([0.0, 0.5, 0.5, 1.0])
    q = np.array([[0.0], [1.0], [1.0], [0.0]])
    qd = np.array([[2.0], [2.0], [-2.0], [-2.0]])
    out = resample(t, q, np.array([0.25, 0.75]), qd)
    np.testing.assert_allclose(out[:, 0], [0.5, 0.5])


def test_default_shapes_rods_and_balls(pendulum):
    res = pendulum.simulate(0.2, [0.3, 0.2])
    scene = build_scene(res)
    bar1, bar2 = scene["bodies"]
    kinds = [s["type"] for s in bar1["shapes"]]
    assert kinds.count("sphere") == 1 and kinds.count("rod") == 2   # to joint A and to joint B
    sphere = next(s for s in bar1["shapes"] if s["type"] == "sphere")
    assert sphere["place"][:3] == pytest.approx([0.275, 0.0, 0.0])
    rods = {tuple(np.round(s["a"], 6)) for s in bar1["shapes"] if s["type"] == "rod"}
    assert rods == {(0.0, 0.0, 0.0), (0.55, 0.0, 0.0)}
    assert [j["name"] for j in scene["joints"]] == ["A", "B"]
    assert scene["joints"][0]["parent"] == -1 and scene["joints"][1]["body"] == 1
    assert scene["joints"][0]["axis"] == [0.0, 0.0, 1.0]


def test_contacts_and_springs_are_marked():
    ball = mb.load("bouncing_ball").compile()
    res = ball.simulate(0.6, [1.0])
    scene = build_scene(res)
    (contact,) = scene["contacts"]
    assert contact["normal"] == [0.0, 0.0, 1.0] and contact["point"] == pytest.approx([0, 0, -0.05])
    assert scene["events"] and scene["events"][0] == pytest.approx(np.sqrt(2 * 0.95 / 9.81), rel=1e-6)
    spring = mb.load("double_pendulum_spring").compile()
    scene = build_scene(spring.simulate(0.1, np.zeros(spring.nq) + 0.1))
    assert len(scene["springs"]) >= 1


def test_body_shapes_in_the_page():
    m = mb.Model("shapes", gravity=(0, 0, -9.81))
    box = mb.Box((0.4, 0.1, 0.05), origin=(0.2, 0, 0), color="red")
    cyl = mb.Cylinder(0.03, 0.4, axis="x", origin=(0.2, 0, 0))
    link = m.add(mb.Body("link", mass=1.0, com=(0.2, 0, 0), inertia=(1e-3, 1e-2, 1e-2), shape=[box, cyl]))
    ball = m.add(mb.Body("ball", mass=0.5, inertia=(5e-4,) * 3, shape=mb.Sphere(0.05, color=(0, 0, 1))))
    m.add(mb.Revolute("hinge", m.ground, link, axis="y"))
    m.add(mb.Revolute("tip", link, ball, axis="y", parent_point=(0.4, 0, 0)))
    scene = build_scene(m.compile().simulate(0.1, [0.1, 0.0]))
    s_box, s_cyl = scene["bodies"][0]["shapes"]
    assert s_box["type"] == "box" and s_box["size"] == [0.4, 0.1, 0.05] and s_box["color"] == "#ff0000"
    # The page's cylinders run along y: the placement turns y onto the shape's x axis.
    turn = Rotation.from_quat(s_cyl["place"][3:])
    np.testing.assert_allclose(turn.apply([0, 1, 0]), [1, 0, 0], atol=1e-12)
    assert s_cyl["radius"] == 0.03 and s_cyl["length"] == 0.4
    (s_ball,) = scene["bodies"][1]["shapes"]
    assert s_ball == {"type": "sphere", "radius": 0.05, "place": [0, 0, 0, 0, 0, 0, 1], "color": "#0000ff"}


def test_shapes_are_display_data_not_parameters_or_structure():
    def build(shape):
        m = mb.Model("one")
        b = m.add(mb.Body("b", mass=1.0, com=(0, 0, -0.5), shape=shape))
        m.add(mb.Revolute("j", m.ground, b, axis="x"))
        return m.compile()

    plain, shaped = build(None), build(mb.Box((0.1, 0.1, 1.0)))
    assert plain.parameters.keys() == shaped.parameters.keys()
    assert not any("shape" in key for key in shaped.parameters)
    assert shaped._compiled.key == plain._compiled.key                 # same generated code
    assert shaped.topology.bodies[0].shape == (mb.Box((0.1, 0.1, 1.0)),)


@pytest.mark.parametrize("make, message", [
    (lambda: mb.Box((1, -1, 1)), "size must be positive"),
    (lambda: mb.Box((1, 1)), "size must be 3 finite numbers"),
    (lambda: mb.Cylinder(0.0, 1.0), "radius must be a positive number"),
    (lambda: mb.Cylinder(0.1, 1.0, axis="w"), "axis must be 'x', 'y', 'z'"),
    (lambda: mb.Sphere(float("nan")), "radius must be a positive number"),
    (lambda: mb.Box((1, 1, 1), rotation=np.diag([1, 1, -1])), "proper rotation"),
    (lambda: mb.Box((1, 1, 1), color="no-such-colour"), "color must be"),
    (lambda: mb.Mesh(""), "path must be a file path"),
    (lambda: mb.Body("b", shape="box"), "shape must be mb.Box"),
])
def test_bad_shapes_raise_model_errors(make, message):
    with pytest.raises(mb.ModelError, match=re.escape(message)):
        make()


def test_mesh_without_file_is_a_clear_error(tmp_path):
    mesh = mb.Mesh(tmp_path / "missing.stl", scale=0.001)
    assert mesh.scale == (0.001, 0.001, 0.001)
    with pytest.raises(mb.ModelError, match="missing.stl"):
        mesh.triangles()


def test_page_is_self_contained(pendulum, tmp_path):
    res = pendulum.simulate(0.5, [0.3, 0.2])
    path = res.view(tmp_path / "dp.html")
    page = path.read_text()
    assert f'content="{CSP}"' in page and "default-src 'none'" in CSP
    # Nothing is fetched: no src/href attributes, no stylesheet links, no imports left.
    assert not re.search(r"<(script|link|img|iframe)[^>]*\s(src|href)=", page)
    assert "import " not in three_script()[:200] and "export{" not in three_script()
    names = re.search(r"const __mbcompThree=\{([^}]*)\}", three_script()).group(1)
    assert {"WebGLRenderer", "Scene", "Quaternion", "CylinderGeometry"} <= {p.split(":")[0] for p in names.split(",")}
    assert "MIT License" in page and "three.js authors" in page
    data = json.loads(re.search(r'<script type="application/json" id="mbcomp-scene">(.*?)</script>',
                                page, re.S).group(1).replace("<\\/", "</"))
    assert data["title"] == "double_pendulum" and data["t1"] == pytest.approx(0.5)


def test_viewer_in_a_notebook(pendulum):
    res = pendulum.simulate(0.1, [0.3, 0.2])
    viewer = res.view()
    assert isinstance(viewer, Viewer)
    shown = viewer._repr_html_()
    assert shown.startswith("<iframe srcdoc=") and "&lt;canvas" not in shown and "&quot;" in shown
    assert render_page(build_scene(res)) == viewer.html


def test_bad_view_arguments(pendulum):
    res = pendulum.simulate(0.1, [0.3, 0.2])
    with pytest.raises(mb.ModelError, match="fps"):
        res.view(fps=0)
    with pytest.raises(mb.ModelError, match="max_frames"):
        res.view(max_frames=1)


def test_cli_writes_the_page(tmp_path):
    from mbcomp.face.cli import main
    out = tmp_path / "bb.html"
    assert main(["run", "bouncing_ball", "--t-end", "0.5", "--html", str(out)]) == 0
    assert out.stat().st_size > 500_000 and "bouncing_ball" in out.read_text()[:2000]


def test_unreadable_mesh_falls_back_to_the_stick_figure(tmp_path):
    m = mb.Model("meshy")
    b = m.add(mb.Body("b", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.01),
                      shape=mb.Mesh(tmp_path / "gone.stl")))
    m.add(mb.Revolute("j", m.ground, b, axis="x"))
    with pytest.warns(UserWarning, match="gone.stl"):
        scene = build_scene(m.compile().simulate(0.1, [0.2]))
    assert [s["type"] for s in scene["bodies"][0]["shapes"]] == ["sphere", "rod"]


def test_mesh_shape_from_a_file(tmp_path):
    trimesh = pytest.importorskip("trimesh", exc_type=ImportError)
    path = tmp_path / "tetra.stl"
    trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]],
                    faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]).export(path)
    m = mb.Model("tetra")
    b = m.add(mb.Body("b", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.01),
                      shape=mb.Mesh(path, scale=0.5, origin=(0, 0, -0.5))))
    m.add(mb.Revolute("j", m.ground, b, axis="x"))
    (record,) = build_scene(m.compile().simulate(0.1, [0.2]))["bodies"][0]["shapes"]
    vertices = np.frombuffer(base64.b64decode(record["vertices"]), dtype="<f4").reshape(-1, 3)
    faces = np.frombuffer(base64.b64decode(record["faces"]), dtype="<u4").reshape(-1, 3)
    assert record["type"] == "mesh" and faces.shape == (4, 3)
    np.testing.assert_allclose(np.sort(vertices.sum(axis=1)), [0, 0.5, 0.5, 0.5])


def test_joint_marks_follow_rotated_joint_frames():
    """A hinge between rotated frames: its axis (given in the joint frame) is drawn in the child
    body's frame, turned by the child frame's rotation."""
    m = mb.Model("tilted")
    b = m.add(mb.Body("b", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.01)))
    turn = mb.rpy(0.0, 0.0, np.pi / 2)                  # the joint's x axis is the body's y axis
    m.add(mb.Revolute("j", m.ground.frame((0, 0, 0), turn), b.frame((0, 0, 0), turn), axis="x"))
    (joint,) = build_scene(m.compile().simulate(0.1, [0.2]))["joints"]
    np.testing.assert_allclose(joint["axis"], [0.0, 1.0, 0.0], atol=1e-15)
