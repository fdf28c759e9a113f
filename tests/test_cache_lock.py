"""The build lock of the code cache: a model compiled by two processes at once is built once."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import cache

pytestmark = pytest.mark.skipif(os.name != "posix", reason="the build lock is an flock (POSIX)")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    path = tmp_path / "cache"
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(path))
    return path


def pendulum(length: float = 0.7) -> mb.Model:
    """A planar pendulum with a rod of ``length`` (m) along -y; small, cheap to compile."""
    m = mb.Model("lock_pendulum", gravity=(0, -9.81, 0))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, -length / 2, 0), inertia=(length ** 2 / 12, 1e-4, length ** 2 / 12)))
    m.add(mb.Revolute("pin", m.ground, rod, axis="z"))
    return m


class TestBuilding:
    def test_a_second_holder_waits_and_gets_the_lock_once_it_is_released(self, cache_dir):
        events = []
        with cache.building("x") as first:
            assert first
            # another open file of the same lock blocks, also within one process (flock)
            with cache.building("x", wait=0.05) as second:
                assert not second

            def take():
                with cache.building("x", wait=10.0) as held:
                    events.append(("taken", held, time.monotonic()))

            thread = threading.Thread(target=take)
            thread.start()
            time.sleep(0.2)
            assert events == []  # still waiting for the first holder
            released = time.monotonic()
        thread.join(10.0)
        assert len(events) == 1 and events[0][1] and events[0][2] >= released

    def test_the_lock_of_a_killed_process_is_free(self, cache_dir):
        code = ("import sys, time; from mbcomp.codegen import cache\n"
                "with cache.building('held') as ok:\n    print(ok, flush=True); time.sleep(60)\n")
        env = {**os.environ, "MBCOMP_CACHE_DIR": str(cache_dir), "PYTHONPATH": str(ROOT)}
        holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env)
        try:
            assert holder.stdout.readline().strip() == "True"
            with cache.building("held", wait=0.05) as held:
                assert not held
            holder.send_signal(signal.SIGKILL)
            holder.wait(10)
            with cache.building("held", wait=5.0) as held:
                assert held
        finally:
            holder.kill()
            holder.wait()
            holder.stdout.close()

    def test_an_unusable_cache_gives_no_lock_and_no_error(self, tmp_path, monkeypatch):
        blocker = tmp_path / "file"
        blocker.write_text("not a directory")
        monkeypatch.setenv("MBCOMP_CACHE_DIR", str(blocker / "cache"))
        with pytest.warns(cache.CacheWarning):
            with cache.building("x") as held:
                assert held in (True, False)  # the fallback directory may or may not lock


class TestOneBuildPerModel:
    def test_threads_compiling_one_model_build_it_once(self, primed_cache_dir):
        systems, errors = [], []

        def compile_one():
            try:
                systems.append(pendulum().compile())
            except Exception as exc:  # surfaced below
                errors.append(exc)

        threads = [threading.Thread(target=compile_one) for _ in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(120)
        assert not errors
        hits = sorted(s._compiled.cache_hit for s in systems)
        assert hits == [False, True, True]  # one build, two loads of it
        q, qd = np.array([0.4]), np.array([-0.3])
        expected = -9.81 * np.sin(0.4) * 1.0 * 0.35 / (0.7 ** 2 / 12 + 0.35 ** 2)  # pendulum about the pin
        for s in systems:
            np.testing.assert_allclose(s.accelerations(q, qd), [expected], rtol=1e-12)

    def test_processes_compiling_one_model_at_once_build_it_once(self, primed_cache_dir):
        code = ("import json, sys; sys.path.insert(0, 'tests'); from test_cache_lock import pendulum\n"
                "import numpy as np\n"
                "s = pendulum().compile()\n"
                "print(json.dumps({'hit': s._compiled.cache_hit,"
                " 'a': s.accelerations(np.array([1.1]), np.array([0.5])).tolist()}))\n")
        env = {**os.environ, "MBCOMP_CACHE_DIR": str(primed_cache_dir), "PYTHONPATH": str(ROOT)}
        children = [subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, env=env) for _ in range(2)]
        done = [(child, *child.communicate(timeout=120)) for child in children]
        outs = []
        for child, stdout, stderr in done:
            assert child.returncode == 0, stderr[-2000:]
            outs.append(json.loads(stdout.strip().splitlines()[-1]))
        assert sorted(o["hit"] for o in outs) == [False, True]
        assert outs[0]["a"] == outs[1]["a"]


def test_threads_compiling_models_of_one_kind_compile_the_templates_once(cache_dir, monkeypatch):
    """Three chains of 2 links, axes in other orders (three models of one kind and state
    length), compiled at once share the templates' build lock: one compiles them, the
    others link its object."""
    from mbcomp.codegen import backend
    calls, real = [], backend.subprocess.Popen

    def popen(cmd, *args, **kwargs):
        calls.append(" ".join(map(str, cmd)))
        return real(cmd, *args, **kwargs)
    monkeypatch.setattr(backend.subprocess, "Popen", popen)
    systems, errors = {}, []

    def chain(axes):
        m = mb.Model(f"chain_{axes}", gravity=(0, 0, -9.81))
        parent = m.ground
        for i, axis in enumerate(axes):
            body = m.add(mb.Body(f"link{i}", mass=1.0, com=(0, 0, -0.25), inertia=(0.02, 0.02, 1e-4)))
            m.add(mb.Revolute(f"joint{i}", parent, body, axis=axis, parent_point=(0, 0, -0.5) if i else (0, 0, 0)))
            parent = body
        return m

    def compile_one(axes):
        try:
            systems[axes] = chain(axes).compile(backend="c")
        except Exception as exc:  # surfaced below
            errors.append(exc)

    threads = [threading.Thread(target=compile_one, args=(axes,)) for axes in ("xy", "yx", "xx")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors
    assert sum("templates.c" in c for c in calls) == 1 and len(list(cache_dir.glob("*.o"))) == 1
    for axes, system in systems.items():
        q, qd = np.array([0.3, -0.2]), np.array([-0.1, 0.4])
        twin = chain(axes).compile(backend="python", cache=False)
        np.testing.assert_allclose(system.accelerations(q, qd), twin.accelerations(q, qd), rtol=1e-12)
