"""A model whose right-hand side is the recursive program builds its dense dynamics (mass
matrix, forces) only when they are first asked for: compiling and simulating never build
them, the first ``mass_matrix`` does (once, cached), with the numbers of an eager build."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mbcomp.codegen.backend import c_compiler
from conftest import pendulum_chain, primed_cache, run_in_new_process, templates_cache

pytestmark = [pytest.mark.skipif(c_compiler() is None, reason="no C compiler"),
              pytest.mark.xdist_group("lazy-dense")]

#: A short chain with the recursive program asked for: lazy building depends on the program,
#: not the size (``auto`` choosing it from ``recursive.CROSSOVER_NV`` speeds is tested in
#: test_recursive.py), and a 4-link chain compiles in half the time of a 12-link one.
N = 4


def chain():
    return pendulum_chain(N)


@pytest.fixture(scope="module")
def templates(tmp_path_factory):
    """The chain's compiled templates object, shared by the tests' own caches."""
    return templates_cache(tmp_path_factory.mktemp("templates") / "cache", chain(), dynamics="recursive")


@pytest.fixture
def cache_dir(tmp_path, monkeypatch, templates):
    path = primed_cache(templates, tmp_path / "cache")
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(path))
    return path


def state():
    return np.linspace(0.1, 0.6, N), np.linspace(-0.3, 0.4, N)


def libraries(path: Path) -> set[str]:
    return {p.name for p in path.glob("*.so")}


def test_compile_and_simulate_never_build_the_dense_dynamics_and_mass_matrix_does(cache_dir):
    system = chain().compile(backend="c", dynamics="recursive")
    compiled = system._compiled
    assert compiled.dynamics == "recursive" and compiled.lazy_dense
    q, qd = state()
    system.simulate(0.2, q, qd)
    system.accelerations(q, qd)
    compiled.wait_for_background()                             # (the output functions' library)
    before = libraries(cache_dir)
    assert "dynamics" not in system._compiled.functions.loaded
    dense = chain().compile(backend="c", dynamics="dense", cache=False)
    M = system.mass_matrix(q)
    assert len(libraries(cache_dir) - before) == 1          # the dense dynamics' own entry
    np.testing.assert_array_equal(M, dense.mass_matrix(q))
    np.testing.assert_array_equal(system.holding_forces(q), dense.holding_forces(q))
    # the recursive accelerations solve the dense equations
    a = system.accelerations(q, qd)
    np.testing.assert_allclose(M @ a, M @ dense.accelerations(q, qd), rtol=1e-10, atol=1e-10)


def test_a_new_process_loads_the_dense_dynamics_from_the_cache(cache_dir):
    q, _ = state()
    expected = chain().compile(backend="c", dynamics="recursive").mass_matrix(q)  # builds and caches both
    out = run_in_new_process(f"s = pendulum_chain({N}).compile(backend='c', dynamics='recursive')\n"
                             f"M = s.mass_matrix(np.linspace(0.1, 0.6, {N}))\n"
                             "print(json.dumps({'hit': s._compiled.cache_hit, 'sympy': 'sympy' in sys.modules,"
                             " 'M': M.tolist()}))\n")
    assert out["hit"] and not out["sympy"]
    np.testing.assert_array_equal(np.array(out["M"]), expected)


def test_a_damaged_dense_entry_is_rebuilt(cache_dir):
    q, _ = state()
    first = chain().compile(backend="c", dynamics="recursive")
    first._compiled.wait_for_background()                      # (the output functions' library)
    before = libraries(cache_dir)
    expected = first.mass_matrix(q)
    (dense_entry,) = libraries(cache_dir) - before
    system = chain().compile(backend="c", dynamics="recursive")     # a cache hit: the model's library
    damaged = cache_dir / dense_entry
    damaged.unlink()                      # (a new file: the loaded library keeps its own pages)
    damaged.write_bytes(b"not a library")
    damaged.chmod(0o600)
    np.testing.assert_array_equal(system.mass_matrix(q), expected)
