"""The ``mbcomp`` command: end to end as a subprocess (``python -m mbcomp.face.cli``: a run
writing CSV, the library listing, a malformed file), and the many variations in process
through ``mbcomp.face.cli.main`` (same code, no start-up cost)."""
from __future__ import annotations

import csv
import importlib.util
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

PENDULUM = """\
description = "A compound pendulum for the command-line tests."
name = "pendulum"
gravity = [0.0, 0.0, -9.81]

[bodies.rod]
mass = 1.0
com = [0.0, 0.0, -0.25]
inertia = [0.02, 0.02, 1e-4]

[joints.hinge]
type = "revolute"
parent = "ground"
child = "rod"
axis = "y"
coords = "swing"

[initial.q]
swing = 0.4

[simulation]
t_end = 0.5
n_samples = 26
"""

HAS_PLOTTING = importlib.util.find_spec("mbcomp.face.plotting") is not None


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """The environment of every call: the test run's private code cache (shared with the
    other tests: the library models are compiled once per run), no terminal tricks."""
    values = dict(os.environ)
    values["MBCOMP_CACHE_DIR"] = os.environ.get("MBCOMP_CACHE_DIR") or str(tmp_path_factory.mktemp("cli-cache"))
    values["MPLBACKEND"] = "Agg"
    values.pop("MBCOMP_LIBRARY", None)
    return values


@pytest.fixture
def pendulum(tmp_path):
    path = tmp_path / "pendulum.toml"
    path.write_text(PENDULUM, encoding="utf-8")
    return path


def mbcomp(env, *args, cwd=None, timeout=120):
    return subprocess.run([sys.executable, "-m", "mbcomp.face.cli", *map(str, args)], capture_output=True,
                          text=True, env=env, cwd=cwd, timeout=timeout)


class Completed:
    """``main()``'s exit code and output, shaped like ``subprocess.CompletedProcess``."""

    def __init__(self, returncode, stdout, stderr):
        self.returncode, self.stdout, self.stderr = returncode, stdout, stderr


@pytest.fixture
def main(env, capsys, monkeypatch):
    """Run ``mbcomp.face.cli.main`` in this process with the test environment."""
    from mbcomp.face.cli import main as cli_main
    monkeypatch.setenv("MBCOMP_CACHE_DIR", env["MBCOMP_CACHE_DIR"])
    monkeypatch.delenv("MBCOMP_LIBRARY", raising=False)

    def call(*args):
        capsys.readouterr()
        try:
            code = cli_main([str(a) for a in args])
        except SystemExit as exc:  # argparse usage errors
            code = exc.code
        out, err = capsys.readouterr()
        return Completed(code, out, err)
    return call


def assert_clean_failure(proc, code=2):
    assert proc.returncode == code, proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout
    assert proc.stderr.startswith("mbcomp: ")


# ----------------------------------------------------------------------------------------------
def test_run_writes_csv_with_a_column_per_coordinate(env, pendulum, tmp_path):
    out = tmp_path / "results.csv"
    proc = mbcomp(env, "run", pendulum, "--out", out, "--no-progress")
    assert proc.returncode == 0, proc.stderr
    assert "swing" in proc.stdout and "energy" in proc.stdout
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    header, data = rows[0], np.array(rows[1:], dtype=float)
    assert header[0] == "t" and "swing" in header and "swing_d" in header
    assert len(data) == 26  # the file's n_samples
    assert data[0, 0] == 0.0 and data[-1, 0] == pytest.approx(0.5)
    assert data[0, header.index("swing")] == pytest.approx(0.4)


def test_run_options_override_the_file(main, pendulum, tmp_path):
    out = tmp_path / "r.csv"
    proc = main("run", pendulum, "--t-end", "0.2", "--samples", "5", "--method", "RK45",
                  "--rtol", "1e-6", "--atol", "1e-9", "--out", out)
    assert proc.returncode == 0, proc.stderr
    rows = list(csv.reader(open(out, newline="")))
    assert len(rows) == 1 + 5 and float(rows[-1][0]) == pytest.approx(0.2)
    assert "RK45" in proc.stdout


def test_run_accepts_a_library_model_name(main, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    proc = main("run", "double_pendulum", "--t-end", "0.1", "--samples", "3")
    assert proc.returncode == 0, proc.stderr
    assert "phi1" in proc.stdout and "theta2" in proc.stdout


def test_info_prints_coordinates_and_equations(main, pendulum):
    proc = main("info", pendulum)
    assert proc.returncode == 0, proc.stderr
    assert "swing" in proc.stdout
    assert "degrees of freedom  1" in proc.stdout
    assert "M[0,0] = 0.0825" in proc.stdout  # 0.02 + 1.0 * 0.25**2
    assert "f[0]" in proc.stdout and "sin(swing)" in proc.stdout


def test_info_on_a_large_model_says_how_to_get_the_equations(main):
    proc = main("info", "five_link_pendulum")
    assert proc.returncode == 0, proc.stderr
    assert "q1, q2, q3, q4, q5" in proc.stdout and ".equations()" in proc.stdout


def test_library_lists_models_with_descriptions(env, main):
    proc = mbcomp(env, "library")
    assert proc.returncode == 0, proc.stderr
    for name in ("arm3d", "double_pendulum", "four_bar", "slider_crank", "spinning_top", "bouncing_ball"):
        assert name in proc.stdout
    assert "The 3D arm" in proc.stdout
    shown = main("library", "arm3d")
    assert shown.returncode == 0 and shown.stdout.startswith("description = ")


def test_library_folder_from_the_environment(main, tmp_path, monkeypatch):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "my_pendulum.toml").write_text(PENDULUM, encoding="utf-8")
    monkeypatch.setenv("MBCOMP_LIBRARY", str(tmp_path / "mine"))
    proc = main("library")
    assert "my_pendulum" in proc.stdout and "compound pendulum" in proc.stdout
    assert "arm3d" in proc.stdout  # the package's library is still listed
    assert main("info", "my_pendulum", "--no-equations").returncode == 0


@pytest.mark.parametrize("text, fragment", [
    ("[bodies.rod]\nmass = \"__import__('os')\"\n", "[bodies.rod] mass: "),
    ("[bodies.rod]\nmass = 1.0\ncom = [0.0, 1.0]\n", "[bodies.rod] com: must have 3 components, got 2"),
    ("[bodies.rod]\nmass = = 1.0\n", "bad.toml:2:"),
], ids=["expression", "vector", "syntax"])
@pytest.mark.parametrize("command", ["run", "info"])
def test_malformed_file_exits_2_with_its_location(main, tmp_path, text, fragment, command):
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    proc = main(command, path)
    assert_clean_failure(proc, 2)
    assert str(path) in proc.stderr and fragment in proc.stderr


def test_malformed_file_as_a_subprocess(env, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[bodies.rod]\nmass = nan\n", encoding="utf-8")
    proc = mbcomp(env, "run", path)
    assert_clean_failure(proc, 2)
    assert f"{path} [bodies.rod] mass: must be finite, got nan" in proc.stderr


def test_missing_file_exits_2(main, tmp_path):
    proc = main("run", tmp_path / "nothing.toml")
    assert_clean_failure(proc, 2)
    assert "nothing.toml" in proc.stderr and "no such file" in proc.stderr


def test_simulation_error_exits_1_with_the_reason(main, tmp_path):
    # a top started exactly upright sits on its z-x-z Euler-angle singularity
    path = tmp_path / "locked.toml"
    path.write_text(textwrap.dedent("""
        [bodies.top]
        mass = 0.1
        com = [0.0, 0.0, 0.04]
        inertia = [1.3e-4, 1.3e-4, 2e-4]
        [joints.pivot]
        type = "spherical"
        parent = "ground"
        child = "top"
        sequence = "zxz"
        [simulation]
        t_end = 0.1
        """), encoding="utf-8")
    proc = main("run", path)
    assert_clean_failure(proc, 1)
    assert "singular" in proc.stderr


def test_bad_option_values(main, pendulum):
    assert_clean_failure(main("run", pendulum, "--t-end", "-1"), 2)
    assert_clean_failure(main("run", pendulum, "--samples", "1"), 2)
    usage = main("run", pendulum, "--formulation", "newton")
    assert usage.returncode == 2 and "invalid choice" in usage.stderr


def test_unwritable_output_is_a_message(main, pendulum, tmp_path):
    proc = main("run", pendulum, "--out", tmp_path / "no" / "such" / "dir.csv")
    assert_clean_failure(proc, 1)
    assert "cannot write" in proc.stderr


@pytest.mark.skipif(not HAS_PLOTTING, reason="mbcomp.face.plotting is not available")
def test_plot_and_animation(main, pendulum, tmp_path):
    import matplotlib.image
    png, gif = tmp_path / "plot.png", tmp_path / "anim.gif"
    proc = main("run", pendulum, "--samples", "6", "--plot", png, "--animate", gif)
    assert proc.returncode == 0, proc.stderr
    image = matplotlib.image.imread(png)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
    assert float(np.std(image[..., :3])) > 0.01, "the plot is blank"
    assert gif.read_bytes()[:6] in (b"GIF87a", b"GIF89a")


def test_help(main):
    proc = main("--help")
    assert proc.returncode == 0
    for command in ("run", "info", "library"):
        assert command in proc.stdout


def test_info_names_the_constraints_and_the_redundant_equations(main):
    """A planar four-bar closed by a 3D revolute: 3 of the loop's 5 equations are redundant."""
    proc = main("info", "four_bar")
    assert proc.returncode == 0, proc.stderr
    assert "degrees of freedom  1" in proc.stdout
    assert "loop closures: C" in proc.stdout
    redundant = next(line for line in proc.stdout.splitlines() if line.startswith("redundant"))
    assert sorted(word.strip(",") for word in redundant.split()[1:4]) == ["C.t1", "C.t2", "C.z"]


def test_run_summary_counts_events_by_kind(main, tmp_path):
    """The library's sliding ball: no impact, one stick event when it starts to roll, at
    t = 2 v0 / (7 mu g) (v0 = 2 m/s, mu = 0.3, g = 9.81: 0.194166 s)."""
    import re
    proc = main("run", "sliding_ball", "--t-end", "0.5", "--samples", "3")
    assert proc.returncode == 0, proc.stderr
    line = next(line for line in proc.stdout.splitlines() if line.startswith("events"))
    assert "impact" not in line and "1 stick" in line, line
    onset = float(re.search(r"first at t = ([0-9.e-]+)", line).group(1))
    assert abs(onset - 2 * 2.0 / (7 * 0.3 * 9.81)) < 1e-5, line
