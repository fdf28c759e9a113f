"""One scene for plots, animations and the viewer (mbcomp.face.scene): a spinning body on a
quaternion joint (Ball, Free) resampled between sparse samples lands where a dense
simulation puts it at that time."""
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mbcomp as mb
from mbcomp.face.scene import Scene, resample_result
from mbcomp.face.viewer import build_scene
from mbcomp.face.viewer.scene import frame_times

SPIN = [0.3, 4.0, 0.2]          # rad/s, body frame: near the unstable middle axis, so it tumbles


def tumbling(joint: str):
    m = mb.Model("tumbling", gravity=(0, 0, -9.81))
    body = m.add(mb.Body("top", mass=1.0, inertia=(1.0, 2.0, 3.0)))
    m.add((mb.Ball if joint == "ball" else mb.Free)("j", m.ground, body))
    return m.compile()


def start(joint: str):
    if joint == "ball":
        return [1.0, 0.0, 0.0, 0.0], SPIN
    return [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0], [0.5, -0.2, 3.0, *SPIN]


@pytest.fixture(scope="module", params=["ball", "free"])
def case(request):
    system = tumbling(request.param)
    q0, v0 = start(request.param)
    sparse = system.simulate(2.0, q0, v0, t_eval=np.linspace(0.0, 2.0, 11))   # a sample every 0.2 s
    return system, q0, v0, sparse


def rotation_error(system, q, q_ref) -> float:
    scene = Scene(system)
    (R, p), (R_ref, p_ref) = (scene.poses(x) for x in (q, q_ref))
    return Rotation.from_matrix(R[1].T @ R_ref[1]).magnitude(), float(np.linalg.norm(p[1] - p_ref[1]))


def test_resampled_pose_between_samples_matches_a_dense_run(case):
    """Between samples 0.2 s apart (0.8 rad of turn each), the resampled attitude is within 1e-4
    rad of the dense run's; taking the speeds as quaternion rates, or interpolating the
    quaternion linearly, is off by 2e-3 to 5e-3 rad there."""
    system, q0, v0, sparse = case
    times = np.array([0.7, 1.1, 1.5])
    dense = system.simulate(2.0, q0, v0, t_eval=np.concatenate([[0.0], times, [2.0]]))
    resampled = resample_result(sparse, times)
    np.testing.assert_allclose(np.linalg.norm(resampled[:, -4:], axis=1), 1.0, atol=1e-14)   # unit quaternions
    for k, time in enumerate(times):
        angle, offset = rotation_error(system, resampled[k], dense.q[k + 1])
        assert angle < 1e-4, (time, angle)
        assert offset < 1e-9, (time, offset)                     # a parabola: Hermite is exact
        linear = np.array([np.interp(time, sparse.t, sparse.q[:, i]) for i in range(system.nq)])
        assert rotation_error(system, system.topology.state_map.normalize(linear), dense.q[k + 1])[0] > 1e-3


def test_viewer_frames_are_the_shared_resampling(case):
    """The page's poses at its frame times are the scene's poses of the resampled motion, and
    at frames between samples they match the dense run: positions to float32, attitudes to
    5e-4 rad (the interpolation error grows to 2.7e-4 rad as the body tumbles faster)."""
    system, q0, v0, sparse = case
    page = build_scene(sparse, fps=10)
    times = frame_times(sparse.t, 10, 2000)
    assert page["frames"] == len(times) == 21
    import base64
    poses = np.frombuffer(base64.b64decode(page["poses"]), dtype="<f4").reshape(21, 1, 7).astype(float)
    dense = system.simulate(2.0, q0, v0, t_eval=times)
    expected = Scene(system).body_poses(dense.q)
    np.testing.assert_allclose(poses[:, 0, :3], expected[:, 0, :3], atol=1e-5)
    turn = Rotation.from_quat(poses[:, 0, 3:]).inv() * Rotation.from_quat(expected[:, 0, 3:])
    assert np.max(turn.magnitude()) < 5e-4


def test_one_resampler():
    """Plots, animations and the viewer draw through mbcomp.face.scene: no interpolation of their own."""
    package = Path(mb.__file__).parent / "face"
    for path in (package / "plotting.py", *sorted((package / "viewer").glob("*.py"))):
        text = path.read_text(encoding="utf-8")
        assert "CubicHermiteSpline" not in text and "np.interp(" not in text, path.name
    assert "resample" in (package / "plotting.py").read_text() and "resample" in (package / "viewer/scene.py").read_text()
