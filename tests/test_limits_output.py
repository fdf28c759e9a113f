"""Limits of what a run stores and what a compile writes: a run that keeps every step stops at
its step budget with a message naming ``t_eval`` and ``max_samples``; every output is checked
against the output-size budget before anything is allocated; the code cache works without a
home directory; a full disk is a ``CompileError`` that says so and where."""
from __future__ import annotations

import errno
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import backend, cache
from mbcomp.core import checks
from mbcomp.codegen.backend import c_compiler

ROOT = Path(__file__).resolve().parents[1]


def stiff_spring(k: float = 1e12) -> mb.Model:
    """A 1 kg slider on a spring of stiffness ``k`` (N/m): period 2 pi / sqrt(k)."""
    m = mb.Model("stiff", gravity=(0, 0, 0))
    body = m.add(mb.Body("b", mass=1.0))
    m.add(mb.Prismatic("slide", m.ground, body, axis="x", coords="x"))
    m.add(mb.TorsionSpring("k", "slide", stiffness=k))
    return m


@pytest.fixture(scope="module")
def stiff():
    return stiff_spring().compile()


@pytest.fixture(scope="module")
def soft():
    return stiff_spring(1e4).compile()


# -- stored steps (t_eval=None) ----------------------------------------------------------------------
class TestStepBudget:
    @pytest.mark.parametrize("integrator", ["auto", "scipy"])
    def test_a_run_past_max_samples_stops_naming_t_eval_and_max_samples(self, soft, integrator):
        # Period 2 pi / 100 s: DOP853 takes some ten steps per period, so 2 s takes far more
        # than 200 steps; the run stops at the 200th, long before t_end.
        with pytest.raises(mb.SimulationError, match=r"more than max_samples = 200 steps.*t_eval.*max_samples") as info:
            soft.simulate(2.0, [1e-3], [0.0], integrator=integrator, max_samples=200)
        t_stop = float(str(info.value).split("at t = ")[1].split(" s")[0])
        assert 0 < t_stop < 2.0

    def test_the_budget_is_a_ceiling_not_a_size(self, soft):
        # Under the budget the run is the same as without one: the same steps, to the end.
        free = soft.simulate(0.2, [1e-3], [0.0], max_samples=10 ** 6)
        tight = soft.simulate(0.2, [1e-3], [0.0], max_samples=len(free.t))
        np.testing.assert_array_equal(free.t, tight.t)
        np.testing.assert_array_equal(free.q, tight.q)
        with pytest.raises(mb.SimulationError, match="max_samples"):
            soft.simulate(0.2, [1e-3], [0.0], max_samples=len(free.t) - 1)
        # and it is the harmonic motion: x = x0 cos(100 t)
        np.testing.assert_allclose(free.q[:, 0], 1e-3 * np.cos(100 * free.t), atol=1e-9)

    def test_the_stiff_spring_over_60_s_stops_at_the_default_budget(self, stiff):
        # 1e8 steps would be needed; the default budget (1e6) stops it, its buffers never
        # larger than the budget: the peak memory stays far below 1e8 stored steps (2.4 GB).
        with pytest.raises(mb.SimulationError, match=r"more than max_samples = 1000000 steps.*pass t_eval"):
            stiff.simulate(60.0, [1.0], [0.0])

    def test_output_times_are_not_limited_by_the_step_budget(self, soft):
        t = np.linspace(0, 2.0, 11)
        res = soft.simulate(2.0, [1e-3], [0.0], t_eval=t, max_samples=2)
        np.testing.assert_allclose(res.q[:, 0], 1e-3 * np.cos(100 * t), atol=1e-8)

    @pytest.mark.skipif(c_compiler() is None, reason="RK4 is compiled only")
    def test_fixed_steps_beyond_the_budget_are_refused_up_front(self, soft):
        with pytest.raises(mb.ModelError, match=r"dt = 0\.001 s over t_end = 10 s keeps 10001 steps.*max_samples = 5000"):
            soft.simulate(10.0, [1e-3], [0.0], method="RK4", dt=1e-3, max_samples=5000)
        res = soft.simulate(10.0, [1e-3], [0.0], method="RK4", dt=1e-3, max_samples=10001)
        assert len(res.t) == 10001

    @pytest.mark.parametrize("bad", [0, 1, -5, 2.5, "100", True, [10]])
    def test_bad_max_samples_is_a_model_error(self, soft, bad):
        with pytest.raises(mb.ModelError, match="max_samples must be a whole number"):
            soft.simulate(0.1, [1e-3], [0.0], max_samples=bad)

    def test_the_budget_in_bytes_caps_max_samples(self, soft, monkeypatch):
        # 3 values a row (t, x, xd) x 8 bytes: 24 000 bytes hold 1000 rows, whatever max_samples says.
        monkeypatch.setattr(checks, "MAX_OUTPUT_BYTES", 24_000)
        with pytest.raises(mb.SimulationError, match=r"more than 1000 steps of 3 values.*MAX_OUTPUT_BYTES"):
            soft.simulate(20.0, [1e-3], [0.0], max_samples=10 ** 7)

    def test_a_sweep_case_takes_max_samples(self, soft):
        with pytest.raises(mb.SimulationError, match="max_samples = 50"):
            mb.sweep(soft, [{"q0": [1e-3], "t_end": 2.0, "max_samples": 50}], threads=1)

    def test_a_prescribed_motion_with_a_tiny_max_step_is_refused_up_front(self):
        m = mb.Model("driven", gravity=(0, 0, 0))
        body = m.add(mb.Body("b", mass=1.0))
        m.add(mb.Prismatic("slide", m.ground, body, axis="x", coords="x"))
        m.add(mb.Motor("motor", "slide", position="0.1*sin(t)"))
        system = m.compile()
        with pytest.raises(mb.ModelError, match=r"max_step = 1e-07 s over t_end = 1 s keeps 10000001 steps.*max_samples"):
            system.simulate(1.0, [0.0], [0.1], max_step=1e-7)


# -- output size before allocation --------------------------------------------------------------------
class TestOutputSize:
    def test_too_many_output_times_are_refused_with_the_size(self, soft, monkeypatch):
        monkeypatch.setattr(checks, "MAX_OUTPUT_BYTES", 8 * 3 * 1000)
        with pytest.raises(mb.ModelError, match=r"t_eval of 1001 times would need 1e\+03 samples x 3 values"):
            soft.simulate(1.0, [1e-3], [0.0], t_eval=np.linspace(0, 1, 1001))
        assert len(soft.simulate(1.0, [1e-3], [0.0], t_eval=np.linspace(0, 1, 1000)).t) == 1000

    def test_the_message_says_how_to_raise_the_limit(self):
        with pytest.raises(mb.ModelError, match=r"3\.73e\+03 GiB.*limit of 2 GiB \(mbcomp\.core\.checks\.MAX_OUTPUT_BYTES\)"):
            checks.output_size(1e11, 5, "--samples 100000000000")


def _cli(*args, cwd, env=None):
    return subprocess.run([sys.executable, "-m", "mbcomp.face.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


class TestCommandLine:
    def test_samples_beyond_memory_are_refused_before_allocating(self, tmp_path):
        proc = _cli("run", "double_pendulum", "--t-end", "0.1", "--samples", "100000000000", cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert "--samples 100000000000 would need 1e+11 samples x 5 values" in proc.stderr
        assert "Traceback" not in proc.stderr and "MemoryError" not in proc.stderr

    def test_n_samples_of_a_file_on_a_large_chain_is_refused_with_its_size(self, tmp_path, capsys):
        # 10 000 000 samples (a file's most) of a 14-link chain: 1e7 x 29 values (t, 14 angles,
        # 14 rates) x 8 bytes = 2.16 GiB, just over the limit; the value count is the file's
        # model's (a 40-link chain, 6 GiB, is refused the same way but takes ~10 s to compile).
        # The command's main in this process (the test above runs it as a new process).
        lines = ['name = "long_chain"\n\n[simulation]\nt_end = 0.01\nn_samples = 10000000\n']
        parent = "ground"
        for i in range(14):
            lines.append(f'[bodies.b{i}]\nmass = 1.0\ncom = [0, 0, -0.25]\ninertia = [0.02, 0.02, 0.001]\n')
            lines.append(f'[joints.j{i}]\ntype = "revolute"\nparent = "{parent}"\nchild = "b{i}"\n'
                         f'axis = "x"\n' + ("parent_point = [0, 0, -0.5]\n" if i else ""))
            parent = f"b{i}"
        path = tmp_path / "chain.toml"
        path.write_text("".join(lines))
        from mbcomp.face.cli import main
        capsys.readouterr()
        code = main(["run", str(path)])
        out, err = capsys.readouterr()
        assert code == 2, err + out
        assert "the file's n_samples = 10000000 would need 1e+07 samples x 29 values = 2.16 GiB" in err
        assert "Traceback" not in err


# -- the cache without a home directory ------------------------------------------------------------
class TestCacheWithoutHome:
    def test_no_home_and_no_passwd_entry_gives_the_per_uid_temp_directory(self, monkeypatch, tmp_path):
        import pwd
        for name in ("HOME", "MBCOMP_CACHE_DIR", "XDG_CACHE_HOME"):
            monkeypatch.delenv(name, raising=False)
        monkeypatch.setattr(pwd, "getpwuid", lambda uid: (_ for _ in ()).throw(KeyError(f"getpwuid(): uid not found: {uid}")))
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        with pytest.raises(RuntimeError):
            Path.home()  # what the cache met before
        expected = tmp_path / f"mbcomp-{os.getuid()}"
        assert cache.configured_dir() == expected
        with warnings.catch_warnings():
            warnings.simplefilter("error", cache.CacheWarning)  # the expected place: no warning
            assert cache.cache_dir() == expected
        assert expected.stat().st_mode & 0o777 == 0o700

    def test_an_unsafe_per_uid_directory_is_not_used(self, monkeypatch, tmp_path):
        import pwd
        for name in ("HOME", "MBCOMP_CACHE_DIR", "XDG_CACHE_HOME"):
            monkeypatch.delenv(name, raising=False)
        monkeypatch.setattr(pwd, "getpwuid", lambda uid: (_ for _ in ()).throw(KeyError(uid)))
        monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
        planted = tmp_path / f"mbcomp-{os.getuid()}"
        planted.mkdir(mode=0o777)
        planted.chmod(0o777)  # another user could plant code here
        with pytest.warns(cache.CacheWarning, match="writable by group or others"):
            used = cache.cache_dir()
        assert used != planted and used.parent == tmp_path and used.stat().st_mode & 0o077 == 0

    @pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="needs root to run as an unknown uid")
    def test_a_compile_as_a_uid_without_passwd_entry_and_no_home_works(self, tmp_path):
        import pwd
        uid = 54321
        while True:
            try:
                pwd.getpwuid(uid)
                uid += 1
            except KeyError:
                break
        tmp = tmp_path / "tmp"
        tmp.mkdir()
        tmp.chmod(0o1777)
        code = ("import mbcomp as mb, os, json, tempfile\n"
                "m = mb.Model('p'); b = m.add(mb.Body('b', mass=1.0, com=(0, 0, -1)))\n"
                "m.add(mb.Revolute('j', m.ground, b, axis='x'))\n"
                "s = m.compile(backend='python')\n"
                "from mbcomp.codegen import cache\n"
                "print(json.dumps({'dir': str(cache.cache_dir()), 'q': float(s.simulate(0.1, [0.1]).q[-1, 0])}))\n")
        env = {"PATH": os.environ.get("PATH", ""), "PYTHONPATH": str(ROOT), "TMPDIR": str(tmp)}
        try:
            probe = subprocess.run([sys.executable, "-c", "import mbcomp"], env=env, capture_output=True, timeout=120,
                                   user=uid, cwd=str(tmp))
        except PermissionError:
            pytest.skip("this Python cannot be run by another uid")
        if probe.returncode != 0:
            pytest.skip("mbcomp cannot be imported by another uid here")
        done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300,
                              user=uid, cwd=str(tmp))
        assert done.returncode == 0, done.stderr[-2000:]
        assert "Could not determine home directory" not in done.stderr
        import json
        out = json.loads(done.stdout.strip().splitlines()[-1])
        assert out["dir"] == str(tmp / f"mbcomp-{uid}")
        # a small pendulum of length 1 from 0.1 rad: after 0.1 s, 0.1 cos(sqrt(9.81) 0.1) nearly
        assert out["q"] == pytest.approx(0.1 * np.cos(np.sqrt(9.81) * 0.1), rel=1e-3)


# -- a full disk -----------------------------------------------------------------------------------------
class TestFullDisk:
    @staticmethod
    def _full(monkeypatch):
        real_open = open

        class FullFile:
            def __init__(self, fh):
                self.fh = fh

            def __enter__(self):
                return self

            def __exit__(self, *exc):
                self.fh.close()

            def write(self, data):
                raise OSError(errno.ENOSPC, "No space left on device")

        def fake_open(path, mode="r", *args, **kwargs):
            fh = real_open(path, mode, *args, **kwargs)
            return FullFile(fh) if "w" in mode else fh

        monkeypatch.setattr(backend, "open", fake_open, raising=False)

    @pytest.mark.skipif(c_compiler() is None, reason="the C build writes the generated units")
    def test_a_compile_on_a_full_disk_is_a_compile_error_naming_the_file(self, monkeypatch):
        self._full(monkeypatch)
        with pytest.raises(mb.CompileError, match=r"Model 'stiff': the disk is full: cannot write \S*mbcomp-build-\S+\.c "
                                                  r"\(No space left on device\).*TMPDIR.*MBCOMP_CACHE_DIR"):
            stiff_spring(3.0).compile(cache=False, backend="c")

    def test_a_compiler_that_runs_out_of_space_is_a_compile_error(self, monkeypatch, tmp_path):
        # A compiler that fails as gcc does on a full disk.
        fake = tmp_path / "cc"
        fake.write_text("#!/bin/sh\n"
                        "for a in \"$@\"; do [ \"$a\" = --version ] && echo 'fake cc 1.0' && exit 0; done\n"
                        "echo 'fatal error: error writing to /tmp/ccX.s: No space left on device' >&2\nexit 1\n")
        fake.chmod(0o755)
        monkeypatch.setattr(backend, "c_compiler", lambda: str(fake))
        monkeypatch.setattr("mbcomp.compiled.compiler.c_compiler", lambda: str(fake))
        with pytest.raises(mb.CompileError, match=r"the disk is full: cannot write \S*mbcomp-build-"):
            stiff_spring(5.0).compile(cache=False, backend="c")
