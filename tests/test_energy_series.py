"""Result.energy() evaluates every sample in one call of the generated code: the same numbers
as the per-state System.energy, for both backends."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen.backend import c_compiler
from conftest import arm_model

BACKENDS = ["python"] + (["c"] if c_compiler() else [])


@pytest.mark.parametrize("backend", BACKENDS)
def test_energy_series_equals_the_per_state_energy(backend):
    system = arm_model().compile(backend=backend)
    rng = np.random.default_rng(7)
    q, qd = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    series = system.energy_series(q, qd)
    for i in range(len(q)):
        one = system.energy(q[i], qd[i])
        assert series.kinetic[i] == pytest.approx(one.kinetic, rel=1e-14, abs=1e-14)
        assert series.potential[i] == pytest.approx(one.potential, rel=1e-14, abs=1e-14)
    # kinetic energy is a quadratic form in qd: scaling the speeds by 2 scales it by 4
    np.testing.assert_allclose(system.energy_series(q, 2 * qd).kinetic, 4 * series.kinetic, rtol=1e-13)


@pytest.mark.parametrize("backend", BACKENDS)
def test_result_energy_is_conserved_and_matches(backend):
    system = arm_model().compile(backend=backend)
    res = system.simulate(1.0, [0.3, -0.2, 0.9], [0.1, 0.4, -0.3], rtol=1e-10, atol=1e-12)
    energy = res.energy()
    assert energy.total.shape == res.t.shape
    assert np.ptp(energy.total) < 1e-7 * abs(energy.total[0])          # conservative model
    i = len(res.t) // 2
    assert energy.kinetic[i] == pytest.approx(system.energy(res.q[i], res.qd[i]).kinetic, rel=1e-14)


def test_energy_series_checks_its_arguments():
    system = arm_model().compile(backend="python")
    with pytest.raises(mb.ModelError, match=r"\(m, 3\)"):
        system.energy_series(np.zeros((4, 2)), np.zeros((4, 2)))
    with pytest.raises(mb.ModelError, match="finite"):
        system.energy_series(np.full((2, 3), np.nan), np.zeros((2, 3)))
    empty = system.energy_series(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.kinetic.shape == (0,)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_constraint_violation_series_equals_the_per_state_one(backend, formulation):
    from conftest import fourbar
    for motor in (None, mb.Motor("motor", "A", speed=2.0), mb.Motor("motor", "A", position=lambda t: 0.5 + t)):
        system = fourbar(motor=motor).compile(formulation, backend=backend)
        res = system.simulate(0.3, [0.5, 0.0, 0.0], rtol=1e-6, atol=1e-8)
        rng = np.random.default_rng(3)
        q = res.q + 1e-3 * rng.normal(size=res.q.shape)          # off the constraints
        series = system.constraint_violation_series(res.t, q, res.offsets)
        one = [system.constraint_violation(q[i], res.t[i], offsets=res.offsets) for i in range(len(q))]
        np.testing.assert_allclose(series, one, rtol=1e-13, atol=1e-15)
        assert np.all(series > 1e-5)                                   # the noise shows
        np.testing.assert_allclose(res.constraint_violation(),
                                   [system.constraint_violation(qi, ti, offsets=res.offsets)
                                    for ti, qi in zip(res.t, res.q)], rtol=1e-13, atol=1e-15)
