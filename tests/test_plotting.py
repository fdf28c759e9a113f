"""Plots and animations: they render real pictures, with units, from the public API."""
from __future__ import annotations

import os

import numpy as np
import pytest

import matplotlib

matplotlib.use("Agg")

import matplotlib.image as mpimg  # noqa: E402
from PIL import Image  # noqa: E402

import mbcomp as mb  # noqa: E402
from mbcomp.face import plotting  # noqa: E402
from mbcomp.face.plotting import animate_result, plot_result, render_frame, work_precision_plot  # noqa: E402


# ----------------------------------------------------------------------------------
# Models
# ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    """Generated code goes to the test run's private cache (a fresh one when run alone)."""
    path = os.environ.get("MBCOMP_CACHE_DIR") or tmp_path_factory.mktemp("plot-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MBCOMP_CACHE_DIR", str(path))
        yield path


def double_pendulum_model() -> mb.Model:
    m = mb.Model("dp", gravity=(0, -9.81, 0))
    b1 = m.add(mb.Body("b1", mass=1.0, com=(0.5, 0, 0), inertia=(0.01, 0.1, 0.1)))
    b2 = m.add(mb.Body("b2", mass=1.0, com=(0.5, 0, 0), inertia=(0.01, 0.1, 0.1)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    return m


@pytest.fixture(scope="module")
def dp_result(cache_dir):
    system = double_pendulum_model().compile()
    return system.simulate(1.0, q0=[0.5, 0.2])


@pytest.fixture(scope="module")
def cart_result(cache_dir):
    """A cart on a prismatic joint carrying a pendulum: one length and one angle."""
    m = mb.Model("cart", gravity=(0, 0, -9.81))
    cart = m.add(mb.Body("cart", mass=2.0))
    pole = m.add(mb.Body("pole", mass=0.5, com=(0, 0, -0.5), inertia=(0.04, 0.04, 0.001)))
    m.add(mb.Prismatic("slide", m.ground, cart, axis="x", coords="x"))
    m.add(mb.Revolute("hinge", cart, pole, axis="y", coords="theta"))
    m.add(mb.Spring("k", a=(m.ground, (-1, 0, 0)), b=(cart, (0, 0, 0)), stiffness=30.0, rest_length=1.0))
    return m.compile().simulate(0.5, q0=[0.2, 0.8])


@pytest.fixture(scope="module")
def slider_crank_result(cache_dir):
    """A motor-driven slider-crank: constraints, so drift and reactions exist."""
    m = mb.Model("slidercrank", gravity=(0, -9.81, 0))
    crank = m.add(mb.Body("crank", mass=1.0, com=(0.25, 0, 0), inertia=(0.001, 0.02, 0.02)))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0.5, 0, 0), inertia=(0.001, 0.08, 0.08)))
    m.add(mb.Revolute("a", m.ground, crank, axis="z"))
    m.add(mb.Revolute("b", crank, rod, axis="z", parent_point=(0.5, 0, 0)))
    m.add(mb.Slider("guide", rod, point=(1.0, 0, 0), axis="x"))
    m.add(mb.Motor("motor", "a", speed=3.0))
    system = m.compile()
    q0, _ = system.assemble([0.8, -1.0])
    return system.simulate(0.3, q0=q0)


def assert_not_blank(path) -> None:
    """The PNG at ``path`` shows a real picture: many colours and contrast."""
    image = mpimg.imread(str(path))
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
    rgb = (image[..., :3] * 255).astype(np.uint32).reshape(-1, 3)
    colours = np.unique(rgb[:, 0] << 16 | rgb[:, 1] << 8 | rgb[:, 2])   # one integer per colour (fast)
    assert len(colours) > 20, f"only {len(colours)} distinct colours"
    assert float(image[..., :3].std()) > 0.03, "the image has almost no contrast"


def ylabels(fig) -> list[str]:
    return [ax.get_ylabel() for ax in fig.axes]


# ----------------------------------------------------------------------------------
# plot_result
# ----------------------------------------------------------------------------------
class TestPlotResult:
    def test_png_is_not_blank(self, dp_result, tmp_path):
        path = tmp_path / "plot.png"
        plot_result(dp_result, path=path)
        assert path.is_file()
        assert_not_blank(path)

    def test_default_panels_are_angles_speeds_and_energy_in_joules(self, dp_result):
        fig = plot_result(dp_result)
        assert ylabels(fig) == ["angle (rad)", "angular speed (rad/s)", "energy (J)"]
        assert fig.axes[-1].get_xlabel() == "time (s)"
        assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == ["j1", "j2"]
        assert [t.get_text() for t in fig.axes[2].get_legend().get_texts()] == ["kinetic", "potential", "total"]

    def test_panels_share_the_time_axis(self, dp_result):
        fig = plot_result(dp_result)
        first = fig.axes[0]
        assert all(first.get_shared_x_axes().joined(first, ax) for ax in fig.axes[1:])

    def test_unsmoothed_lines_are_the_result_series(self, dp_result):
        fig = plot_result(dp_result, ("q", "energy"), smooth=False)
        line = fig.axes[0].get_lines()[1]
        np.testing.assert_array_equal(line.get_xdata(), dp_result.t)
        np.testing.assert_array_equal(line.get_ydata(), dp_result["j2"])
        total = [ln for ln in fig.axes[1].get_lines() if ln.get_label() == "total"][0]
        np.testing.assert_allclose(total.get_ydata(), dp_result.energy().total)

    def test_smoothed_lines_pass_through_the_samples_and_follow_the_motion(self, dp_result):
        fig = plot_result(dp_result, ("q", "qd", "energy"))
        line = fig.axes[0].get_lines()[1]
        t, y = np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
        assert len(t) > 2 * len(dp_result.t)
        np.testing.assert_allclose(np.interp(dp_result.t, t, y), dp_result["j2"], atol=1e-9)
        # Between the samples too the curves are the motion: energy stays conserved.
        total = [ln for ln in fig.axes[2].get_lines() if ln.get_label() == "total"][0]
        energy = np.asarray(total.get_ydata())
        assert np.ptp(energy) < 1e-3 * np.ptp(dp_result.energy().kinetic)

    def test_lengths_and_angles_get_their_own_units(self, cart_result):
        fig = plot_result(cart_result)
        assert ylabels(fig) == ["angle (rad)", "position (m)", "angular speed (rad/s)", "speed (m/s)", "energy (J)"]
        assert [ln.get_label() for ln in fig.axes[0].get_lines()] == ["theta"]
        assert [ln.get_label() for ln in fig.axes[1].get_lines()] == ["x"]

    def test_drift_on_request_is_log_scale(self, dp_result):
        fig = plot_result(dp_result, ("q", "drift"))
        assert len(fig.axes) == 2
        assert fig.axes[1].get_yscale() == "log"
        assert "drift" in fig.axes[1].get_ylabel()

    def test_constraints_add_drift_and_reactions_have_units(self, slider_crank_result, tmp_path):
        path = tmp_path / "constrained.png"
        fig = plot_result(slider_crank_result, ("q", "reactions"), path=path)
        labels = ylabels(fig)
        assert labels[0] == "angle (rad)"
        assert labels[1].startswith("reaction") and "N m" in labels[1]
        assert "drift" in labels[2] and fig.axes[2].get_yscale() == "log"
        names = [ln.get_label() for ln in fig.axes[1].get_lines()]
        assert "motor (N m)" in names and "guide[0] (N)" in names
        assert_not_blank(path)

    def test_result_plot_method_delegates(self, dp_result):
        fig = dp_result.plot(("energy",), figsize=(5, 3))
        assert ylabels(fig) == ["energy (J)"]
        assert tuple(fig.get_size_inches()) == (5, 3)

    def test_unknown_quantity_is_rejected(self, dp_result):
        with pytest.raises(ValueError, match="unknown quantity"):
            plot_result(dp_result, ("q", "jerk"))


# ----------------------------------------------------------------------------------
# Frames and animations
# ----------------------------------------------------------------------------------
class TestRenderFrame:
    def test_png_is_not_blank(self, dp_result, tmp_path):
        path = tmp_path / "frame.png"
        render_frame(dp_result, len(dp_result.t) // 2, path)
        assert_not_blank(path)

    def test_planar_motion_is_shown_face_on(self, dp_result):
        ax = render_frame(dp_result, 0).axes[0]
        assert (ax.elev, ax.azim) == (90.0, -90.0)
        assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"

    def test_axis_limits_are_the_same_for_every_frame(self, dp_result):
        first = render_frame(dp_result, 0).axes[0]
        last = render_frame(dp_result, -1).axes[0]
        for get in ("get_xlim", "get_ylim", "get_zlim"):
            assert getattr(first, get)() == getattr(last, get)()
        # The whole motion fits: every sample's outer COM lies inside the limits.
        system = dp_result.system
        outer = np.array([system.body_state("b2", q).position for q in dp_result.q])
        for k, get in enumerate(("get_xlim", "get_ylim")):
            low, high = getattr(first, get)()
            assert low <= outer[:, k].min() and outer[:, k].max() <= high

    def test_named_and_angle_views(self, cart_result):
        assert render_frame(cart_result, 0, view="xy").axes[0].elev == 90.0
        ax = render_frame(cart_result, 0, view=(30, 45)).axes[0]
        assert (ax.elev, ax.azim) == (30.0, 45.0)
        with pytest.raises(ValueError, match="view"):
            render_frame(cart_result, 0, view="sideways")

    def test_index_out_of_range(self, dp_result):
        with pytest.raises(IndexError):
            render_frame(dp_result, len(dp_result.t))


class TestScene:
    def test_points_are_where_body_state_puts_them(self, dp_result):
        system = dp_result.system
        scene = plotting._Scene(system)
        q = dp_result.q[-1]
        points = scene.points(q)
        points = scene.points(q)            # the second call takes the fast kinematics path
        elbow_on_b1 = system.body_state("b1", q, point=(1, 0, 0)).position
        elbow_on_b2 = system.body_state("b2", q, point=(0, 0, 0)).position
        on_parent, hub = scene.links[1]
        np.testing.assert_allclose(points[on_parent], elbow_on_b1, atol=1e-12)
        np.testing.assert_allclose(points[hub], elbow_on_b2, atol=1e-12)
        for k, body in enumerate(("b1", "b2")):
            np.testing.assert_allclose(points[scene.com_points[k]], system.body_state(body, q).position, atol=1e-12)
        np.testing.assert_allclose(points[scene.ground_marks[0]], np.zeros(3))

    def test_rebound_parameters_move_the_points(self, dp_result):
        system = dp_result.system.with_parameters({"j2.parent_point": (0.5, 0.0, 0.0)})
        scene = plotting._Scene(system)
        q = np.array([0.0, 0.0])
        on_parent, hub = scene.links[1]
        np.testing.assert_allclose(scene.points(q)[hub], [0.5, 0.0, 0.0], atol=1e-12)

    def test_resampling_without_speeds_is_linear(self):
        t = np.array([0.0, 1.0, 3.0])
        q = np.column_stack([2 * t, t ** 2])
        out = plotting._resample(t, q, np.array([0.5, 2.0]))
        np.testing.assert_allclose(out, [[1.0, 0.5], [4.0, 5.0]])

    def test_resampling_with_speeds_is_exact_for_cubics(self):
        t = np.array([0.0, 1.0, 3.0])
        q, qd = np.column_stack([t ** 3, np.sin(t)]), np.column_stack([3 * t ** 2, np.cos(t)])
        times = np.linspace(0.0, 3.0, 13)
        out = plotting._resample(t, q, times, qd)
        np.testing.assert_allclose(out[:, 0], times ** 3, atol=1e-12)
        np.testing.assert_allclose(out[:, 1], np.sin(times), atol=0.05)   # h^4 max|q""|/384

    def test_resampling_splits_at_impacts(self):
        # q = |t - 1| bounces at t = 1: the sample is repeated with the speed before and after.
        t = np.array([0.0, 1.0, 1.0, 2.0])
        q = np.abs(t - 1.0)[:, None]
        qd = np.array([-1.0, -1.0, 1.0, 1.0])[:, None]
        out = plotting._resample(t, q, np.array([0.5, 1.0, 1.5]), qd)
        np.testing.assert_allclose(out[:, 0], [0.5, 0.0, 0.5], atol=1e-12)


class TestAnimate:
    def test_gif_has_the_requested_frames(self, dp_result, tmp_path):
        path = animate_result(dp_result, tmp_path / "anim.gif", frames=4)
        assert path == tmp_path / "anim.gif"
        with Image.open(path) as image:
            assert image.format == "GIF"
            assert image.n_frames == 4
            image.seek(3)
            assert np.asarray(image.convert("RGB")).std() > 5

    def test_frame_count_follows_fps_and_duration(self, dp_result, tmp_path):
        path = dp_result.animate(tmp_path / "slow.gif", fps=5, duration=0.6)
        with Image.open(path) as image:
            assert image.n_frames == 4          # 0.6 s at 5 fps, both ends included

    def test_mp4_without_ffmpeg_says_so(self, dp_result, tmp_path, monkeypatch):
        from matplotlib import animation
        monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
        with pytest.raises(RuntimeError, match="ffmpeg"):
            animate_result(dp_result, tmp_path / "anim.mp4", frames=2)

    def test_unknown_suffix_is_rejected(self, dp_result, tmp_path):
        with pytest.raises(ValueError, match=r"\.gif or \.mp4"):
            animate_result(dp_result, tmp_path / "anim.avi", frames=2)


# ----------------------------------------------------------------------------------
# Work-precision diagrams
# ----------------------------------------------------------------------------------
class TestWorkPrecision:
    rows = [
        {"label": "DOP853", "error": 1e-9, "time": 0.3},
        {"label": "DOP853", "error": 1e-6, "time": 0.1},
        {"label": "RK45", "error": 1e-5, "time": 0.2},
        {"label": "RK45", "error": 1e-8, "time": 1.0},
        {"label": "RK45", "error": 0.0, "time": 2.0},       # cannot be drawn on log axes
    ]

    def test_one_sorted_line_per_label_on_log_axes(self, tmp_path):
        path = tmp_path / "wp.png"
        fig = work_precision_plot(self.rows, path, title="chain")
        ax = fig.axes[0]
        assert ax.get_xscale() == "log" and ax.get_yscale() == "log"
        lines = {ln.get_label(): ln for ln in ax.get_lines()}
        assert set(lines) == {"DOP853", "RK45"}
        np.testing.assert_array_equal(lines["RK45"].get_xdata(), [1e-8, 1e-5])
        np.testing.assert_array_equal(lines["RK45"].get_ydata(), [1.0, 0.2])
        assert ax.get_ylabel() == "wall time (s)" and ax.get_title() == "chain"
        assert_not_blank(path)

    def test_missing_key_is_reported(self):
        with pytest.raises(ValueError, match="'time'"):
            work_precision_plot([{"label": "x", "error": 1.0}])
