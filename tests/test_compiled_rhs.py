"""scipy's methods step the compiled right-hand side (``run/compiled_rhs.py``): the C function
the compiled loops step, checked here against the Python solve it replaced (now the oracle)."""
from __future__ import annotations

import numpy as np
import pytest

from mbcomp.formulations.compiled_rhs import CompiledRhsWorkspace
from test_cross_paths import initial_state, system_of


@pytest.mark.parametrize("name", ["four_bar", "stewart_platform", "arm3d", "slider_crank"])
def test_the_compiled_rhs_equals_the_python_solve(name):
    """At random states near the start, the compiled KKT solve (dae) and the Python one give
    the same rates to rounding; the tree models' compiled rhs the same as the tree solve."""
    system = system_of(name, "dae")
    q0, qd0 = initial_state(name, system)
    formulation, kernel = system._formulation, system.kernel
    rng = np.random.default_rng(3)
    lib = kernel.compiled.functions.lib
    with formulation.compiled_setup(lib, kernel=kernel, q0=q0):
        inner = formulation.start(kernel, 0.0, q0, qd0, None)
        compiled = CompiledRhsWorkspace(inner, kernel, None, "test")
        for _ in range(3):
            y = inner.y0 + np.concatenate((np.zeros(len(q0)), rng.normal(scale=0.5, size=len(qd0))))
            expected = inner.rhs(0.1, y)
            got = compiled.rhs(0.1, y)
            assert np.allclose(got, expected, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(expected).max()))


@pytest.mark.parametrize("method", ["RK45", "Radau"])
def test_a_scipy_method_steps_the_compiled_rhs_of_a_loop(method):
    """The four-bar in dae with a scipy method: the same motion as the compiled DOP853 loop
    to the tolerances asked for, and the run says it stepped the compiled rhs."""
    system = system_of("four_bar", "dae")
    q0, qd0 = initial_state("four_bar", system)
    t_eval = np.linspace(0.0, 1.0, 11)
    reference = system.simulate(1.0, q0, qd0, t_eval=t_eval, rtol=1e-11, atol=1e-12)
    res = system.simulate(1.0, q0, qd0, t_eval=t_eval, method=method, rtol=1e-9, atol=1e-11)
    assert res.stats["integrator"] == "scipy"
    assert np.abs(res.q - reference.q).max() < 1e-5
    assert res.constraint_violation().max() < 1e-6
