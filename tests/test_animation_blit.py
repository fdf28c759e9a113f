"""GIF animations draw the still parts once and only the moving artists per frame: the
frames must be the pixels of drawing every frame in full (matplotlib's own writer)."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib", exc_type=ImportError)
from PIL import Image  # noqa: E402

import mbcomp as mb  # noqa: E402
from mbcomp.face import plotting  # noqa: E402


def full_redraw(fig, drawing, points, times, dpi):
    """The reference: every frame drawn in full (``canvas.draw``), as matplotlib's writers do."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    fig.set_dpi(dpi)
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)

    def frame(k):
        drawing.update(points[k], float(times[k]))
        canvas.draw()
        return np.array(np.asarray(canvas.buffer_rgba())[..., :3])
    return frame


def rgb_frames(res, path, monkeypatch, view, render=None):
    """The RGB frames ``animate_result`` hands to the GIF encoder (with ``render`` drawing
    them instead of the blitter, when given)."""
    seen = []

    def keep(frame, count, path, fps):
        seen.extend(frame(k) for k in range(count))
    with monkeypatch.context() as patch:
        patch.setattr(plotting, "_encode_gif", keep)
        if render is not None:
            patch.setattr(plotting, "_blitter", render)
        plotting.animate_result(res, path, frames=5, view=view)
    return seen


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


@pytest.fixture(scope="module")
def spring_arm_result():
    return spring_arm().compile(backend="python").simulate(0.4, q0=[0.4, -0.3, 0.8], t_eval=np.linspace(0, 0.4, 9))


@pytest.mark.parametrize("view", [None, "xy"])
def test_blitted_frames_equal_full_redraws(tmp_path, monkeypatch, view, spring_arm_result):
    fast = rgb_frames(spring_arm_result, tmp_path / "fast.gif", monkeypatch, view)
    full = rgb_frames(spring_arm_result, tmp_path / "full.gif", monkeypatch, view, render=full_redraw)
    assert len(fast) == len(full) == 5
    for k, (a, b) in enumerate(zip(fast, full)):
        assert a.shape == b.shape
        assert np.array_equal(a, b), f"frame {k}: {np.mean(np.any(a != b, axis=2)):.2%} of the pixels differ"
    assert not np.array_equal(fast[0], fast[-1])  # the mechanism moved


def test_the_gif_shows_the_drawn_colours(tmp_path, monkeypatch, spring_arm_result):
    """One palette for every frame (fitted to the first and last): decoded, each frame is
    its drawn pixels to within a few levels (Pillow maps colours to the palette through a
    cache of reduced precision: measured mean 2.05 of 255, 0.01-0.02 % of the pixels, on
    anti-aliased edges, off by more than 24, as with a palette fitted to every frame), and
    the file loops at fps."""
    drawn = rgb_frames(spring_arm_result, tmp_path / "drawn.gif", monkeypatch, None)
    path = plotting.animate_result(spring_arm_result, tmp_path / "arm.gif", frames=5, fps=10)
    shown = frames_of(path)
    assert len(shown) == len(drawn) == 5
    for k, (a, b) in enumerate(zip(shown, drawn)):
        error = np.abs(a.astype(int) - b.astype(int)).max(axis=2)
        assert np.mean(error) < 3.0, f"frame {k}: mean colour error {np.mean(error):.2f}"
        assert np.mean(error > 24) < 0.001, f"frame {k}: {np.mean(error > 24):.2%} of the pixels off by > 24"
    with Image.open(path) as image:
        assert image.info["loop"] == 0 and image.info["duration"] == 100
