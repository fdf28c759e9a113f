"""projection=True on quaternion coordinates in the dae formulation's compiled DOP853 loop:
``dae_project`` (formulations/c/dae.c) steps each quaternion by the exp-map of its
speed-space Newton step, as ``StateMap.integrate`` does in Python."""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from components.test_ball_free import rssr

_DBL_P = ctypes.POINTER(ctypes.c_double)


@pytest.fixture(scope="module")
def systems():
    projected, plain = rssr("dae", projection=True), rssr("dae")
    q0 = projected.state_vector({"crank_pivot": 0.0, "rocker_pivot": 0.0})
    v0 = np.zeros(projected.nv)
    v0[0] = 2.0
    q0, v0 = projected.assemble(q0, v0)
    return projected, plain, q0, v0


def _pointer(a: np.ndarray):
    return a.ctypes.data_as(_DBL_P)


def test_projection_on_quaternions_runs_compiled_and_rk4_still_refuses(systems):
    projected, plain, _, _ = systems
    assert projected.integration_path() == "compiled"
    assert plain.integration_path() == "compiled"
    problem = projected._formulation.compiled_method_problem("RK4")
    assert problem is not None and "projection=True" in problem


def test_c_quaternion_step_is_the_state_maps(systems):
    """``dae_quaternion_step`` against ``StateMap.integrate`` on random states and steps
    (small ones through the series branch, large ones through sin/cos)."""
    projected = systems[0]
    kernel = projected.kernel
    lib, state_map = kernel.compiled.functions.lib, kernel.topology.state_map
    step = lib.dae_quaternion_step
    step.argtypes, step.restype = [_DBL_P, _DBL_P], None
    rng = np.random.default_rng(3)
    for scale in (1e-9, 1e-5, 1e-3, 0.3, 2.5):
        q = state_map.normalize(rng.normal(size=state_map.nq))
        dv = scale * rng.normal(size=state_map.nv)
        expected = state_map.integrate(q, dv)
        got = np.ascontiguousarray(q.copy())
        step(_pointer(got), _pointer(np.ascontiguousarray(dv)))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15)


def test_c_projection_is_the_python_assembly(systems):
    """One ``dae_project`` from perturbed states lands where the Python projection
    (``Formulation.assemble``: minimum-norm Newton steps through the state map, speeds
    mass-orthogonally) does, with unit quaternions.  (From further off the Python assembly
    starts with a trust-region solve, whose point on the constraints is a different one.)"""
    projected, _, q0, v0 = systems
    formulation, kernel = projected._formulation, projected.kernel
    lib, state_map = kernel.compiled.functions.lib, kernel.topology.state_map
    project = lib.dae_project
    project.argtypes, project.restype = [_DBL_P, _DBL_P, _DBL_P, _DBL_P], ctypes.c_int
    size = lib.rhs_work_size
    size.argtypes, size.restype = [], ctypes.c_long
    work, u = np.zeros(max(int(size()), 1)), np.zeros(1)
    p = np.ascontiguousarray(kernel.p, dtype=float)
    rng = np.random.default_rng(7)
    with formulation.compiled_setup(lib, kernel=kernel, q0=q0):
        for _ in range(5):
            # (a drift of a few steps: below 1e-6 the Python assembly takes Newton steps alone)
            q = state_map.integrate(q0, 1e-7 * rng.normal(size=state_map.nv))
            v = v0 + 1e-3 * rng.normal(size=state_map.nv)
            assert 1e-9 < formulation.constraint_violation(kernel, 0.0, q) < 1e-6
            y = np.ascontiguousarray(np.concatenate((q, v)))
            assert project(_pointer(y), _pointer(p), _pointer(u), _pointer(work)) == 1
            q_py, v_py = formulation.assemble(kernel, q, v, 0.0)
            q_c, v_c = y[:state_map.nq], y[state_map.nq:]
            np.testing.assert_allclose(q_c, q_py, rtol=0, atol=1e-12)
            np.testing.assert_allclose(v_c, v_py, rtol=0, atol=1e-12)
            assert formulation.constraint_violation(kernel, 0.0, q_c) < 1e-13
            np.testing.assert_allclose(np.linalg.norm(q_c[state_map.quat_q[0]:][:4]), 1.0, rtol=0, atol=1e-15)


def _quaternion_norms(system, result) -> np.ndarray:
    quat = system.kernel.topology.state_map.quat_q
    return np.stack([np.linalg.norm(result.q[:, k:k + 4], axis=1) for k in quat])


def test_projected_loop_holds_the_constraints_and_matches_python_stepping(systems):
    projected, plain, q0, v0 = systems
    options = dict(rtol=1e-10, atol=1e-12)
    compiled = projected.simulate(3.0, q0, v0, **options)       # accepted steps
    python = projected.simulate(3.0, q0, v0, integrator="scipy", **options)
    baumgarte = plain.simulate(3.0, q0, v0, **options)
    held, drifted = np.max(compiled.constraint_violation()), np.max(baumgarte.constraint_violation())
    assert held < 1e-12
    assert drifted > 10 * held   # Baumgarte alone lets it drift
    np.testing.assert_allclose(_quaternion_norms(projected, compiled), 1.0, rtol=0, atol=1e-14)
    energy = compiled.energy()
    assert np.ptp(energy.total) < 1e-8 * np.abs(energy.kinetic).max()
    # the same motion as the Python-stepped projected run, to integration tolerance
    t = np.linspace(0.0, 3.0, 31)
    a = projected.simulate(3.0, q0, v0, t_eval=t, **options)
    b = projected.simulate(3.0, q0, v0, t_eval=t, integrator="scipy", **options)
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-7)
    np.testing.assert_allclose(a.qd, b.qd, rtol=0, atol=1e-6)
    assert python.t[-1] == compiled.t[-1] == 3.0


def test_loose_tolerance_projection_holds_what_baumgarte_loses(systems):
    """At rtol 1e-6 Baumgarte alone drifts to ~1e-8; the compiled projection keeps every
    accepted step on the constraints."""
    projected, plain, q0, v0 = systems
    compiled = projected.simulate(3.0, q0, v0, rtol=1e-6, atol=1e-8)
    baumgarte = plain.simulate(3.0, q0, v0, rtol=1e-6, atol=1e-8)
    assert np.max(compiled.constraint_violation()) < 1e-12
    assert np.max(baumgarte.constraint_violation()) > 1e-9
    np.testing.assert_allclose(_quaternion_norms(projected, compiled), 1.0, rtol=0, atol=1e-14)
