"""What ``import mbcomp`` and a run from the code cache import: no sympy, no scipy.integrate
(a cached model runs in compiled code without them), and what the lazy paths give instead."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen.backend import c_compiler

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("sympy", "scipy.integrate", "scipy.optimize", "scipy.linalg", "scipy.interpolate", "networkx", "matplotlib")


def _run(code: str, cache: Path) -> dict:
    """Run ``code`` in a new interpreter (this checkout first on the path); its last stdout line as JSON."""
    env = {**os.environ, "MBCOMP_CACHE_DIR": str(cache), "PYTHONPATH": os.pathsep.join(
        [str(ROOT), str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, env=env,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


LOADED = f"{{m: m in sys.modules for m in {HEAVY!r}}}"  # evaluated in the child


def test_import_mbcomp_imports_no_sympy_scipy_integrate_or_networkx(tmp_path):
    loaded = _run(f"import json, sys\nimport mbcomp\nprint(json.dumps({LOADED}))", tmp_path)
    assert loaded == {m: False for m in HEAVY}


@pytest.mark.skipif(c_compiler() is None, reason="no C compiler")
def test_a_cached_model_loads_and_runs_without_the_symbolic_and_scipy_layers(tmp_path):
    """A second process builds the model, loads its code from the cache and integrates 1 s in
    compiled code without importing sympy or scipy.integrate, and gets the first process's numbers."""
    script = f"""
        import json, sys
        import mbcomp
        from conftest import pendulum_chain
        system = pendulum_chain(3).compile(backend="c")
        result = system.simulate(1.0, [0.3, 0.2, 0.1], [0.0, 0.0, 0.0])
        print(json.dumps({{"hit": system._compiled.cache_hit, "q": result.q[-1].tolist(),
                          "loaded": {LOADED}}}))
    """
    first = _run(script, tmp_path)
    second = _run(script, tmp_path)
    assert not first["hit"] and second["hit"]
    assert first["loaded"]["sympy"]  # the first one generated the code
    assert second["loaded"] == {m: False for m in HEAVY}
    assert second["q"] == first["q"]
    # and the same numbers as this process's scipy-stepped run of the same model
    from conftest import pendulum_chain
    reference = pendulum_chain(3).compile().simulate(1.0, [0.3, 0.2, 0.1], [0.0, 0.0, 0.0], integrator="scipy")
    np.testing.assert_allclose(first["q"], reference.q[-1], rtol=0, atol=1e-6)


def test_lazy_names_are_the_real_objects():
    from mbcomp.run.batch import sweep
    import mbcomp.files.toml_model
    assert mb.sweep is sweep and mb.io is mbcomp.files.toml_model
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        mb.no_such_name  # noqa: B018


def test_dop853_coefficients_read_from_scipys_file_are_scipys():
    from scipy.integrate._ivp import dop853_coefficients as dop
    from mbcomp.codegen.integrators import _dop853_from_file
    read = _dop853_from_file()
    assert read is not None and read is not dop
    for name in ("A", "B", "C", "E3", "E5", "D"):
        assert np.array_equal(getattr(read, name), getattr(dop, name)), name
