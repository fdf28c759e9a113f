"""The output functions (energy, body kinematics) are compiled into a library of their own,
in the background at a low priority: a compile returns once the right-hand side is
ready, the first ``energy``/``body_state`` waits for what is left of that build (once,
cached), and a later process without it compiles the C the compile cached, without sympy;
the numbers are those of the generated Python."""
from __future__ import annotations

import json
import os
import select
import signal
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

from mbcomp.codegen import backend
from mbcomp.compiled import compiler
from mbcomp.codegen.backend import OUTPUT_FUNCTIONS, c_compiler
from conftest import pendulum_chain, primed_cache, run_in_new_process

pytestmark = [pytest.mark.skipif(c_compiler() is None, reason="no C compiler"),
              pytest.mark.xdist_group("output-library")]

N = 4


@pytest.fixture(autouse=True)
def spare_core(monkeypatch):
    """These tests look at the background build: it starts whatever the machine's load
    (``test_on_a_busy_machine_...`` turns it off)."""
    monkeypatch.setattr(compiler, "spare_core", lambda: True)


@pytest.fixture(scope="module")
def templates(tree_templates):
    """The chain's compiled templates object (a tree's: ``conftest.tree_templates``), shared by
    the tests' own caches."""
    return tree_templates


@pytest.fixture
def cache_dir(tmp_path, monkeypatch, templates):
    path = primed_cache(templates, tmp_path / "cache")
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(path))
    return path


def libraries(path: Path) -> set[str]:
    return {p.name for p in path.glob("*.so")}


def state():
    return np.linspace(0.2, 0.8, N), np.linspace(-0.5, 0.7, N)


def test_the_outputs_are_built_once_in_the_background_and_cached(cache_dir):
    system = pendulum_chain(N).compile(backend="c")
    compiled, functions = system._compiled, system._compiled.functions
    q, qd = state()
    result = system.simulate(0.5, q, qd)
    assert not any(name in functions.loaded for name in OUTPUT_FUNCTIONS)   # not asked for yet
    compiled.wait_for_background()
    assert len(libraries(cache_dir)) == 2                       # the model's, and one for both outputs
    reference = pendulum_chain(N).compile(backend="python", cache=False)
    energy = result.energy()
    expected = reference.energy(result.q[-1], result.qd[-1])
    np.testing.assert_allclose([energy.kinetic[-1], energy.potential[-1]], [expected.kinetic, expected.potential],
                               rtol=1e-13, atol=1e-13)
    body = system.topology.bodies[-1].name
    state_c, state_py = system.body_state(body, q, qd), reference.body_state(body, q, qd)
    assert functions.loaded["energy"] is functions.loaded["kinematics"]
    for field in ("position", "velocity", "rotation", "angular_velocity"):
        np.testing.assert_allclose(getattr(state_c, field), getattr(state_py, field), rtol=1e-13, atol=1e-13)
    # a second System of the same structure loads the cached library: nothing is compiled
    again = pendulum_chain(N).compile(backend="c")
    assert again._compiled.cache_hit and again._compiled._outputs_build is None
    np.testing.assert_array_equal(again.body_state(body, q, qd).position, state_c.position)


def test_before_its_library_is_loaded_the_stub_writes_nan_not_stale_numbers(cache_dir):
    """The model's library calls the output functions through a pointer that Python sets:
    unset, the stub fills its output with NaN (never an uninitialised buffer)."""
    system = pendulum_chain(N).compile(backend="c", cache=False)
    functions = system._compiled.functions
    import ctypes
    q, qd = state()
    out = np.full(2, 7.0)
    p = system._kernel.p
    fn = functions.lib.energy
    fn.argtypes, fn.restype = [ctypes.c_void_p] * 5, None
    u = np.zeros(1)
    fn(q.ctypes.data, qd.ctypes.data, p.ctypes.data, u.ctypes.data, out.ctypes.data)
    assert np.isnan(out).all()
    energy = system.energy(q, qd)                                 # loads it (no cache: in memory)
    fn(q.ctypes.data, qd.ctypes.data, p.ctypes.data, u.ctypes.data, out.ctypes.data)
    np.testing.assert_array_equal(out, [energy.kinetic, energy.potential])


def test_threads_asking_at_once_load_the_outputs_once(cache_dir):
    system = pendulum_chain(N).compile(backend="c")
    compiled = system._compiled
    calls = []
    original = compiled._side_library

    def counted(*args, **kwargs):
        calls.append(1)
        return original(*args, **kwargs)
    compiled._side_library = counted
    q, qd = state()
    results, start = [], threading.Barrier(4)

    def ask():
        start.wait()
        results.append(system.energy(q, qd))
    threads = [threading.Thread(target=ask) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert calls == []                          # all four waited for the background build
    assert len(results) == 4 and len({(e.kinetic, e.potential) for e in results}) == 1


def test_a_forked_child_builds_the_outputs_itself(cache_dir):
    """A child forked while the background build runs has no copy of its thread: it builds
    the library itself instead of waiting for ever."""
    if not hasattr(os, "fork"):
        pytest.skip("no fork")
    system = pendulum_chain(N).compile(backend="c", cache=False)
    q, qd = state()
    read, write = os.pipe()
    with warnings.catch_warnings():             # (Python >= 3.12 warns of fork in a threaded process)
        warnings.simplefilter("ignore", DeprecationWarning)
        pid = os.fork()
    if pid == 0:                                # the child: report the energy, exit at once
        try:
            e = system.energy(q, qd)
            os.write(write, json.dumps([e.kinetic, e.potential]).encode())
        finally:
            os._exit(0)
    os.close(write)
    try:
        ready, _, _ = select.select([read], [], [], 120)   # a child stuck for good fails, not hangs
        if not ready:
            os.kill(pid, signal.SIGKILL)
        with os.fdopen(read) as fh:
            child = json.loads(fh.read() or "null") if ready else "no answer in 120 s"
    finally:
        os.waitpid(pid, 0)
    e = system.energy(q, qd)
    assert child == [e.kinetic, e.potential]


def test_a_new_process_builds_them_from_the_cached_source_without_sympy(cache_dir):
    """A compile stores the outputs' C: a later process that first asks for an energy
    compiles that, without generating the program again."""
    q, qd = state()
    first = pendulum_chain(N).compile(backend="c")
    expected = first.energy(q, qd)
    system = pendulum_chain(N).compile(backend="c")
    own = Path(str(system._compiled.functions.path)).name
    for name in libraries(cache_dir) - {own}:       # every library but the model's own
        (cache_dir / name).unlink()
        (cache_dir / f"{name}.json").unlink()
    out = run_in_new_process(f"s = pendulum_chain({N}).compile(backend='c')\n"
                             f"e = s.energy(np.linspace(0.2, 0.8, {N}), np.linspace(-0.5, 0.7, {N}))\n"
                             "print(json.dumps({'hit': s._compiled.cache_hit, 'sympy': 'sympy' in sys.modules,"
                             " 'e': [e.kinetic, e.potential]}))\n")
    assert out["hit"] and not out["sympy"]
    assert out["e"] == [expected.kinetic, expected.potential]
    assert len(libraries(cache_dir) - {own}) == 1     # rebuilt and cached again


def test_without_the_cached_source_they_are_generated_again(cache_dir):
    q, qd = state()
    first = pendulum_chain(N).compile(backend="c")
    expected = first.energy(q, qd)
    for path in list(cache_dir.glob("*.c")) + list(cache_dir.glob("*.c.json")):
        path.unlink()
    system = pendulum_chain(N).compile(backend="c")
    own = Path(str(system._compiled.functions.path)).name
    for name in libraries(cache_dir) - {own}:
        (cache_dir / name).unlink()
    energy = system.energy(q, qd)
    assert (energy.kinetic, energy.potential) == (expected.kinetic, expected.potential)


def test_on_a_busy_machine_the_outputs_are_built_when_first_asked_for(cache_dir, monkeypatch):
    """With no core to spare, the compile starts no background build; the first ``energy``
    builds the library (once, cached) and gives the numbers of the generated Python."""
    monkeypatch.setattr(compiler, "spare_core", lambda: False)
    system = pendulum_chain(N).compile(backend="c")
    assert system._compiled._outputs_build is None
    assert len(libraries(cache_dir)) == 1                       # the model's own only
    q, qd = state()
    energy = system.energy(q, qd)
    expected = pendulum_chain(N).compile(backend="python", cache=False).energy(q, qd)
    np.testing.assert_allclose([energy.kinetic, energy.potential], [expected.kinetic, expected.potential],
                               rtol=1e-13, atol=1e-13)
    assert len(libraries(cache_dir)) == 2                       # and the outputs', cached
    again = pendulum_chain(N).compile(backend="c")
    assert again._compiled.cache_hit
    assert again.energy(q, qd) == energy


@pytest.mark.parametrize("load, cores, spare", [((0.3, 0.2, 0.1), 2, True), ((1.6, 1.0, 0.5), 2, False),
                                                 ((3.2, 3.0, 2.0), 4, True), ((7.9, 8.0, 8.0), 8, False)])
def test_a_core_is_spare_while_the_load_is_below_the_cores_less_a_half(monkeypatch, load, cores, spare):
    monkeypatch.setattr(backend.os, "getloadavg", lambda: load)
    monkeypatch.setattr(backend.os, "cpu_count", lambda: cores)
    assert backend.spare_core() is spare


def test_where_the_load_cannot_be_read_a_core_is_spare(monkeypatch):
    def unreadable():
        raise OSError("no load average")
    monkeypatch.setattr(backend.os, "getloadavg", unreadable)
    assert backend.spare_core() is True
