"""GIF animations draw the still parts once and only the moving artists per frame: the
frames must be the pixels of drawing every frame in full (matplotlib's own writer)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")
from PIL import Image  # noqa: E402

import mbcomp as mb  # noqa: E402
from mbcomp import plotting  # noqa: E402


def full_redraw_gif(fig, drawing, points, times, path, fps, dpi):
    """The reference: every frame drawn in full by matplotlib's ``PillowWriter``."""
    from matplotlib import animation
    writer = animation.PillowWriter(fps=fps)
    with writer.saving(fig, str(path), dpi):
        for k, time in enumerate(times):
            drawing.update(points[k], float(time))
            writer.grab_frame()


def frames_of(path):
    with Image.open(path) as image:
        out = []
        for k in range(image.n_frames):
            image.seek(k)
            out.append(np.asarray(image.convert("RGB")))
        return out


def spring_arm():
    """A 3D two-body arm on a ball-like spherical joint with a spring to the ground: sticks,
    balls, joints and a spring line all move."""
    m = mb.Model("spring_arm", gravity=(0, 0, -9.81))
    upper = m.add(mb.Body("upper", mass=2.0, com=(0, 0, -0.15), inertia=(0.02, 0.02, 0.004)))
    lower = m.add(mb.Body("lower", mass=1.0, com=(0, 0.15, 0), inertia=(0.01, 0.002, 0.01)))
    m.add(mb.Spherical("shoulder", m.ground, upper, sequence="xy"))
    m.add(mb.Revolute("elbow", upper, lower, axis="x", parent_point=(0, 0, -0.3)))
    m.add(mb.Spring("spring", a=(m.ground, (0.2, 0, 0)), b=(lower, (0, 0.3, 0)), stiffness=20.0, rest_length=0.2))
    return m


@pytest.mark.parametrize("view", [None, "xy"])
def test_blitted_frames_equal_full_redraws(tmp_path, monkeypatch, view):
    res = spring_arm().compile(backend="python").simulate(0.4, q0=[0.4, -0.3, 0.8], t_eval=np.linspace(0, 0.4, 9))
    fast = frames_of(plotting.animate_result(res, tmp_path / "fast.gif", frames=5, view=view))
    monkeypatch.setattr(plotting, "_write_gif", full_redraw_gif)
    full = frames_of(plotting.animate_result(res, tmp_path / "full.gif", frames=5, view=view))
    assert len(fast) == len(full) == 5
    for k, (a, b) in enumerate(zip(fast, full)):
        assert a.shape == b.shape
        assert np.array_equal(a, b), f"frame {k}: {np.mean(np.any(a != b, axis=2)):.2%} of the pixels differ"
    assert not np.array_equal(fast[0], fast[-1])  # the mechanism moved
