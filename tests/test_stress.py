"""Short numerical stress tests (the long ones live in bench/stress.py)."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import pendulum_chain


def test_conservative_chain_energy_drift_over_100_s():
    system = pendulum_chain(5).compile()
    result = system.simulate(100.0, np.full(5, 0.3), rtol=1e-11, atol=1e-11)
    energy = result.energy().total
    scale = np.abs(result.energy().kinetic).max()
    assert np.ptp(energy) < 1e-7 * scale


def test_stiff_spring_with_an_implicit_method():
    """k = 1e6 N/m on a 1 kg slider: Radau follows x(t) = A cos(w t) with w = 1e3 rad/s
    while an explicit method would need ~1e3 steps per period."""
    m = mb.Model("stiff", gravity=(0, 0, 0))
    body = m.add(mb.Body("mass", mass=1.0))
    m.add(mb.Prismatic("x", m.ground, body, axis="x"))
    m.add(mb.Spring("spring", a=(m.ground, (0, 0, 0)), b=(body, (0, 0, 0)), stiffness=1e6, damping=20.0))
    system = m.compile()
    result = system.simulate(0.05, [1e-3], [0.0], method="Radau", rtol=1e-8, atol=1e-12)
    w0, zeta = 1e3, 20.0 / (2 * 1e3)
    wd = w0 * np.sqrt(1 - zeta ** 2)
    t = result.t
    exact = 1e-3 * np.exp(-zeta * w0 * t) * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t))
    np.testing.assert_allclose(result["x"], exact, atol=2e-8)
    assert result.stats["nlu"] > 0


@pytest.mark.parametrize("theta0", [1e-2, 1e-4])
def test_spinning_top_close_to_its_euler_singularity_stays_correct(theta0):
    """A symmetric top spinning about its vertical axis, slightly tilted: energy and the two
    cyclic momenta are conserved; nearer than the solver can resolve it raises instead."""
    m = mb.Model("top", gravity=(0, 0, -9.81))
    top = m.add(mb.Body("top", mass=0.1, com=(0, 0, 0.04), inertia=(1.3e-4, 1.3e-4, 2e-4)))
    m.add(mb.Spherical("pivot", m.ground, top, sequence="zxz", coords=("psi", "theta", "phi")))
    system = m.compile()
    result = system.simulate(0.5, [0.0, theta0, 0.0], [0.0, 0.0, 150.0], rtol=1e-10, atol=1e-12)
    energy = result.energy().total
    assert np.ptp(energy) < 1e-9 * np.abs(energy).max()
    # Spin momentum p_phi = I3 (phi_d + psi_d cos theta) is conserved.
    p_phi = 2e-4 * (result["phi_d"] + result["psi_d"] * np.cos(result["theta"]))
    assert np.ptp(p_phi) < 1e-9


def test_spinning_top_at_its_singularity_raises_naming_the_joint():
    m = mb.Model("top", gravity=(0, 0, -9.81))
    top = m.add(mb.Body("top", mass=0.1, com=(0, 0, 0.04), inertia=(1.3e-4, 1.3e-4, 2e-4)))
    m.add(mb.Spherical("pivot", m.ground, top, sequence="zxz"))
    with pytest.raises(mb.SimulationError, match="Spherical 'pivot'"):
        m.compile().simulate(0.5, [0.0, 1e-9, 0.0], [0.0, 0.0, 150.0])


def test_backends_agree():
    model = pendulum_chain(3)
    c = model.compile(backend="c")
    if c.backend != "c":
        pytest.skip("no C compiler")
    p = model.compile(backend="python")
    q, qd = np.array([0.3, -0.2, 0.5]), np.array([1.0, 0.0, -2.0])
    np.testing.assert_allclose(c.accelerations(q, qd), p.accelerations(q, qd), rtol=1e-13, atol=1e-13)
    t_eval = np.linspace(0, 2.0, 21)
    a = c.simulate(2.0, q, qd, integrator="scipy", rtol=1e-11, atol=1e-11, t_eval=t_eval)
    b = p.simulate(2.0, q, qd, integrator="scipy", rtol=1e-11, atol=1e-11, t_eval=t_eval)
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=1e-9)
