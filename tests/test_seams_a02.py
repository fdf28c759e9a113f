"""IFToMM benchmark A02 (two four-bars through singular positions) in both formulations.

The published problem: 2N + 1 = 5 bars of 1 m and 1 kg, gravity 9.81 along -y, point B0 (the
first crank's tip) starting at 1 m/s along +x, 10 s, output at 400 steps; the reference is
conservation of the mechanical energy and the motion on the parallelogram branch (every
crank parallel to the first, couplers horizontal), which crosses the singular horizontal
position eight times.  Compared here against a dae run at rtol 1e-12 as well.
"""
from __future__ import annotations

import numpy as np
import pytest

from components.test_constraints import two_fourbars

T = np.linspace(0.0, 10.0, 401)


@pytest.fixture(scope="module")
def a02():
    systems = {f: two_fourbars().compile(f) for f in ("lagrange", "dae")}
    q0, qd0 = systems["dae"].assemble(np.zeros(5), [-1.0, 0, 0, 0, 0])  # B0 at +1 m/s along x
    reference = systems["dae"].simulate(10.0, q0, qd0, t_eval=T, rtol=1e-12, atol=1e-14)
    return systems, q0, qd0, reference


@pytest.mark.parametrize("formulation, integrator", [("lagrange", "compiled"), ("dae", "compiled"),
                                                     ("lagrange", "scipy")])
def test_a02_passes_eight_singular_positions_at_the_default_tolerances(a02, formulation, integrator):
    systems, q0, qd0, reference = a02
    res = systems[formulation].simulate(10.0, q0, qd0, t_eval=T, integrator=integrator)
    assert res.stats["integrator"] == integrator
    crossings = np.sum(np.diff(np.floor((res["A0"] + np.pi / 2) / np.pi)) != 0)
    assert crossings == 8
    np.testing.assert_allclose(res.q[:, [2, 4]], res.q[:, [0, 0]], atol=1e-5)  # cranks parallel
    assert np.max(np.abs(np.angle(np.exp(1j * (res["A0"] + res["B0"]))))) < 1e-5  # couplers horizontal
    energy = res.energy()
    # every output sample (also those inside steps across a singular position) conserves energy
    assert np.ptp(energy.total) < 1e-4 * np.max(energy.kinetic)
    np.testing.assert_allclose(res.q, reference.q, atol=1e-3)
    np.testing.assert_allclose(res.qd, reference.qd, atol=2e-3)
    # B0's x coordinate: sin of the crank angle (1 m crank turning from vertical)
    np.testing.assert_allclose(-np.sin(res["A0"]), -np.sin(reference["A0"]), atol=1e-3)


def test_a02_in_lagrange_at_a_tight_tolerance_says_why_it_stops(a02):
    """At rtol 1e-10 the steps shrink onto the singular position at t = 3.381 s, where the
    dependent solve amplifies rounding: the error names the singular position and the loop
    closures, and points to the dae formulation."""
    import mbcomp as mb
    systems, q0, qd0, _ = a02
    with pytest.raises(mb.SimulationError, match=r"t = 3\.38.*nearly singular.*C0.*C1.*dae formulation"):
        systems["lagrange"].simulate(10.0, q0, qd0, rtol=1e-10, atol=1e-12)
