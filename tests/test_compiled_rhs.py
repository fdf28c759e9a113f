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


@pytest.mark.parametrize("name", ["four_bar", "stewart_platform", "double_pendulum_slider"])
def test_the_reduced_compiled_rhs_equals_the_python_partitioning(name):
    """lagrange: the compiled reduced right-hand side and dependent coordinates (``lagrange_rhs``,
    ``lagrange_full``) equal the Python workspace's on the same partition, at perturbed speeds."""
    system = system_of(name, "lagrange")
    q0, qd0 = initial_state(name, system)
    formulation, kernel = system._formulation, system.kernel
    q0, qd0 = formulation.assemble(kernel, q0, qd0)
    lib = kernel.compiled.functions.lib
    stretch = formulation.scipy_stretch(kernel, lib, 0.0, q0, qd0, None, method="test")
    try:
        compiled, python = stretch.workspace, stretch.workspace.run.workspace
        rng = np.random.default_rng(5)
        for _ in range(3):
            y = python.y0.copy()
            k = len(python.qind)
            y[k:] += rng.normal(scale=0.3, size=len(y) - k)
            expected, got = python.rhs(0.05, y), compiled.rhs(0.05, y)
            assert np.allclose(got, expected, rtol=1e-8, atol=1e-8 * max(1.0, np.abs(expected).max(initial=0.0)))
            for a, b in zip(compiled.full_state(0.05, y), python.full_state(0.05, y)):
                assert np.allclose(a, b, rtol=1e-10, atol=1e-10)
    finally:
        stretch.close()


def test_scipy_stepping_of_the_reduced_rhs_repartitions_like_the_loop():
    """The four-bar in lagrange over 2 s (its crank turns: the partition changes): RK45 on the
    compiled reduced rhs follows the compiled DOP853 loop, and the constraints hold."""
    system = system_of("four_bar", "lagrange")
    q0, qd0 = initial_state("four_bar", system)
    t_eval = np.linspace(0.0, 2.0, 21)
    reference = system.simulate(2.0, q0, qd0, t_eval=t_eval, rtol=1e-11, atol=1e-12)
    res = system.simulate(2.0, q0, qd0, t_eval=t_eval, method="RK45", rtol=1e-10, atol=1e-12)
    assert res.stats["integrator"] == "scipy"
    assert np.abs(res.q - reference.q).max() < 1e-6
    assert res.constraint_violation().max() < 1e-9
