"""Shared fixtures: a private code cache for the test session, and small models."""
from __future__ import annotations

import contextlib
import gc
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

try:
    import fcntl
except ImportError:  # (not POSIX: each worker compiles its own)
    fcntl = None

import numpy as np
import pytest

import mbcomp as mb


@pytest.fixture(autouse=True, scope="session")
def _private_cache(tmp_path_factory):
    """Generated code goes to a temporary cache, never the user's: one directory for the
    whole run, shared by the parallel workers (pytest-xdist) and the subprocesses the tests
    start, so each model is compiled once per run.  The cache's writes are atomic and its
    entries signed, so concurrent workers are safe.  The cache's own tests use their own
    directories (tests/test_cache.py) and so still see cold builds."""
    base = tmp_path_factory.getbasetemp()
    worker = os.environ.get("PYTEST_XDIST_WORKER")   # gw0, gw1, ... under xdist (base is per worker)
    path = (base.parent if worker else base) / "mbcomp-cache"
    path.mkdir(mode=0o700, exist_ok=True)
    old = os.environ.get("MBCOMP_CACHE_DIR")
    os.environ["MBCOMP_CACHE_DIR"] = str(path)
    yield path
    if old is None:
        os.environ.pop("MBCOMP_CACHE_DIR", None)
    else:
        os.environ["MBCOMP_CACHE_DIR"] = old


@pytest.fixture(autouse=True, scope="session")
def _no_speculative_output_builds():
    """A compile starts its output functions' library (energies, body kinematics) in the
    background when the machine has a core to spare (``compiler._build_outputs``); in the
    test run two of three such libraries were never asked for, and a whole run compiled 193
    of them (55 s of a core).  Here they are built on first use only, which the tests of
    those calls exercise; tests/test_output_library.py turns the background build back on
    for itself."""
    from mbcomp.compiled import compiler
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(compiler, "spare_core", lambda: False)
        yield


def templates_cache(directory: Path, model, **options) -> Path:
    """A private cache ``directory`` holding only the compiled C templates object(s) of
    ``model``'s kind (compiled into it here, with the ``compile`` ``options``) and the
    cache's secret: the tests of one file that each need a cache of their own (what a
    compile writes, what a damaged entry does) copy it with :func:`primed_cache` instead of
    compiling the hand-written templates again."""
    old = os.environ.get("MBCOMP_CACHE_DIR")
    os.environ["MBCOMP_CACHE_DIR"] = str(directory)
    try:
        model.compile(backend="c", **options)._compiled.wait_for_background()
    finally:
        if old is None:
            del os.environ["MBCOMP_CACHE_DIR"]
        else:
            os.environ["MBCOMP_CACHE_DIR"] = old
    for path in directory.iterdir():      # keep the shared objects and the secret
        if path.name != "secret" and not path.name.endswith((".o", ".o.json")):
            path.unlink()
    return directory


def primed_cache(source: Path, target: Path) -> Path:
    """A copy of the :func:`templates_cache` ``source`` at ``target`` (modes kept: the cache
    directory 0700, the secret 0600)."""
    shutil.copytree(source, target)
    return target


@pytest.fixture(scope="session")
def tree_templates(tmp_path_factory) -> Path:
    """A :func:`templates_cache` of the plain tree's kind (dense dynamics, no constraints,
    contacts or drives: ``pendulum_chain``, ``arm_model`` and the other small trees of the
    tests share its templates object), compiled once per test run by whichever worker asks
    first (the others wait on a file lock) for the tests that need a cache of their own but
    do not test the templates' compile: each template compile costs about 1.4 s of a core."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base
    directory, done = root / "tree-templates", root / "tree-templates.done"
    with open(root / "tree-templates.lock", "a") as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)   # (released when the file closes)
        if not done.exists():
            shutil.rmtree(directory, ignore_errors=True)
            templates_cache(directory, pendulum_chain(2))
            done.touch()
    return directory


@pytest.fixture
def primed_cache_dir(tmp_path, monkeypatch, tree_templates) -> Path:
    """A cache of this test's own (``MBCOMP_CACHE_DIR``) holding the plain tree's compiled
    templates object (:func:`tree_templates`) and the cache's secret."""
    path = primed_cache(tree_templates, tmp_path / "primed-cache")
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(path))
    return path


#: The cyclic garbage collector's first threshold during the tests (Python's default: 700
#: allocations).  The suite builds millions of short-lived symbolic and array objects; with
#: collections every 50,000 allocations, and the objects that exist once the tests are
#: collected (modules, classes, test items: never garbage) frozen out of later collections,
#: the whole run took about 3 % less processor time (one pair of runs: 198 -> 192 s of user
#: time, 2 workers).
GC_THRESHOLD = (50_000, 20, 20)


def pytest_configure(config):
    gc.set_threshold(*GC_THRESHOLD)


def pytest_collection_finish(session):
    gc.freeze()


def pytest_sessionfinish(session):
    """Collect once (finalizers that raise are still reported), then freeze what is left:
    pytest's clean-up then collects five times more over the frozen heap at no cost, where
    each full collection of a worker's heap took 0.16-0.36 s (about 1 s at the end of the
    run).  What this collection's finalizers leave as garbage is not collected again."""
    gc.collect()
    gc.freeze()


#: Modules whose tests take long to start (a browser) run first: at the end of a parallel
#: run they kept one worker busy for 3-4 s while the other had nothing left to do.
RUN_FIRST = ("test_viewer_browser.py",)


def pytest_collection_modifyitems(config, items):
    """Move the ``RUN_FIRST`` modules' tests to the front (in their own order); the same on
    every worker, as pytest-xdist requires."""
    items.sort(key=lambda item: item.path.name not in RUN_FIRST)


@contextlib.contextmanager
def time_limit(seconds: float):
    """Raise TimeoutError when the block runs longer than ``seconds`` (a hang is a failure;
    SIGALRM, whose handler a compiled loop's step hook runs like Ctrl-C's)."""
    def handler(signum, frame):
        raise TimeoutError(f"took longer than {seconds} s (hangs)")
    old = signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def assert_close(actual, expected, rtol=1e-10, atol=1e-12, name="value"):
    """``np.testing.assert_allclose`` with the quantity's name in the message."""
    np.testing.assert_allclose(np.asarray(actual, dtype=float), np.asarray(expected, dtype=float),
                               rtol=rtol, atol=atol, err_msg=f"{name} differs")


def arm_model(inertia: bool = True) -> mb.Model:
    """The 3D arm of the reference cases (API.md's example)."""
    m = mb.Model("arm3d", gravity=(0, 0, -9.81))
    upper = m.add(mb.Body("upper", mass=3.0, com=(0, 0, -0.1), inertia=(0.025, 0.025, 0.004) if inertia else None))
    lower = m.add(mb.Body("lower", mass=3.0, com=(0, 0.2, 0), inertia=(0.04, 0.002, 0.04) if inertia else None))
    m.add(mb.Spherical("shoulder", m.ground, upper, sequence="xy", coords=("alpha", "beta")))
    m.add(mb.Revolute("elbow", upper, lower, axis="x", parent_point=(0, 0, -0.3), coords="gamma"))
    return m


def pendulum_chain(n: int, *, gravity=(0, 0, -9.81), length: float = 0.5) -> mb.Model:
    """The benchmark chain: uniform 1 kg rods hanging along -z, axes alternating x, y."""
    m = mb.Model(f"chain{n}", gravity=gravity)
    parent = m.ground
    for i in range(n):
        body = m.add(mb.Body(f"link{i}", mass=1.0, com=(0, 0, -length / 2),
                             inertia=(length ** 2 / 12, length ** 2 / 12, 1e-4)))
        m.add(mb.Revolute(f"joint{i}", parent, body, axis="x" if i % 2 == 0 else "y",
                          parent_point=(0, 0, -length) if i else (0, 0, 0)))
        parent = body
    return m


def run_in_new_process(code: str) -> dict:
    """Run ``code`` in a new Python process (the project's tree first on the path, numpy as
    ``np`` and conftest's ``pendulum_chain`` imported) and return the JSON object its last
    printed line holds."""
    root = Path(__file__).resolve().parents[1]
    header = ("import json, sys; sys.path.insert(0, 'tests'); import numpy as np\n"
              "from conftest import pendulum_chain\n")
    env = {**os.environ, "PYTHONPATH": str(root)}
    done = subprocess.run([sys.executable, "-c", header + code], cwd=root, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def xy_pairs() -> mb.Model:
    """Two rods on xy Euler-angle joints: 4 coordinates like a 4-link chain, with 2 bodies
    (the same state length, another output layout)."""
    m = mb.Model("xy_pairs", gravity=(0, 0, -9.81))
    upper = m.add(mb.Body("upper", mass=1.0, com=(0, 0, -0.25), inertia=(0.02, 0.02, 1e-4)))
    lower = m.add(mb.Body("lower", mass=1.0, com=(0, 0, -0.25), inertia=(0.02, 0.02, 1e-4)))
    m.add(mb.Spherical("shoulder", m.ground, upper, sequence="xy"))
    m.add(mb.Spherical("elbow", upper, lower, sequence="xy", parent_point=(0, 0, -0.5)))
    return m


@pytest.fixture
def arm():
    return arm_model().compile()


@pytest.fixture
def double_pendulum():
    """Planar double pendulum in x-y, gravity along -y, two uniform 1 m bars."""
    m = mb.Model("dpend", gravity=(0, -9.81, 0))
    b1 = m.add(mb.Body("bar1", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    b2 = m.add(mb.Body("bar2", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    return m


G = 9.81


def bar(name: str, length: float, mass: float = 1.0, along: str = "x") -> mb.Body:
    """A uniform slender bar from the body origin along its x (or y) axis."""
    if along == "x":
        return mb.Body(name, mass=mass, com=(length / 2, 0, 0), inertia=(1e-4, length ** 2 / 12, length ** 2 / 12))
    return mb.Body(name, mass=mass, com=(0, length / 2, 0), inertia=(length ** 2 / 12, 1e-4, length ** 2 / 12))


def fourbar(L1=0.3, L2=0.8, L3=0.6, d=0.7, *, closed=True, name="fourbar", motor=None) -> mb.Model:
    """Planar crank-rocker four-bar in x-y (gravity -y, no damping): crank A at the origin,
    rocker D at (d, 0, 0), closed by the revolute C between the coupler end and the rocker
    end; ``motor`` (a Motor component) is added when given."""
    m = mb.Model(name, gravity=(0, -G, 0))
    crank, coupler, rocker = (m.add(bar(n, L)) for n, L in (("crank", L1), ("coupler", L2), ("rocker", L3)))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(L1, 0, 0)))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(d, 0, 0)))
    if closed:
        m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(L2, 0, 0), child_point=(L3, 0, 0)))
    if motor is not None:
        m.add(motor)
    return m
