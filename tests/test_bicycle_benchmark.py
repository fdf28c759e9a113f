"""The bicycle oracle (tests/bicycle_benchmark.py) against numbers published by others.

Two independent sources: the paper itself (its section 3 prints M, C1, K0 and K2 for the
benchmark parameters, its table 2 the eigenvalues at several speeds and the weave and capsize
speeds), and sympy's own test of the benchmark (sympy/physics/mechanics/tests/test_kane3.py),
which derives the bicycle with Kane's method in other coordinates and tabulates the lean/steer
state matrix as a polynomial in the speed v.
"""

from __future__ import annotations

import numpy as np
import pytest

try:                                    # tests/ on sys.path (pytest's default rootdir-less import)
    import bicycle_benchmark as bb
except ImportError:                     # tests imported as a package
    from tests import bicycle_benchmark as bb


def test_matrices_are_the_published_ones():
    M, C1, K0, K2 = bb.matrices()
    np.testing.assert_allclose(M, bb.PUBLISHED_M, rtol=0, atol=1e-12)
    np.testing.assert_allclose(C1, bb.PUBLISHED_C1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(K0, bb.PUBLISHED_K0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(K2, bb.PUBLISHED_K2, rtol=0, atol=1e-12)
    assert M[0, 1] == M[1, 0] and K0[0, 1] == K0[1, 0]   # symmetric by construction


# The paper's table 2 (14 significant digits).
TABLE_2 = {
    0.0: [-5.53094371765393, -3.13164324790656, 3.13164324790656, 5.53094371765393],
    4.0: [-12.15861426576447, -1.42944427361326,
          0.41325331521125 - 3.07910818603206j, 0.41325331521125 + 3.07910818603206j],
    5.0: [-14.07838969279822, -0.32286642900409,
          -0.77534188219585 - 4.46486771378823j, -0.77534188219585 + 4.46486771378823j],
    10.0: [-24.62459635017404, 0.16105338653172,
           -3.72016840437287 - 10.90681139476287j, -3.72016840437287 + 10.90681139476287j],
}


@pytest.mark.parametrize("v", sorted(TABLE_2))
def test_eigenvalues_are_the_papers_table_2(v):
    np.testing.assert_allclose(np.sort_complex(bb.eigenvalues(v)), np.sort_complex(TABLE_2[v]), rtol=0, atol=1e-12)


def test_weave_and_capsize_speeds():
    assert bb.weave_speed() == pytest.approx(bb.PUBLISHED_WEAVE_SPEED, abs=1e-12)
    assert bb.capsize_speed() == pytest.approx(bb.PUBLISHED_CAPSIZE_SPEED, abs=1e-12)


def sympy_kane3_state_matrix(v: float) -> np.ndarray:
    """sympy's tabulated lean/steer state matrix (test_kane3.py's ``Res``), states (lean, steer, rates)."""
    return np.array([
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
        [9.48977444677355, -0.891197738059089 * v**2 - 0.571523173729245,
         -0.105522449805691 * v, -0.330515398992311 * v],
        [11.7194768719633, -1.97171508499972 * v**2 + 30.9087533932407,
         3.67680523332152 * v, -3.08486552743311 * v],
    ])


@pytest.mark.parametrize("v", range(6))
def test_state_matrix_is_sympys_kane_derivation(v):
    np.testing.assert_allclose(bb.state_matrix(v), sympy_kane3_state_matrix(v), rtol=0, atol=1e-12)


def test_self_stable_range():
    """Between the weave and capsize speeds every eigenvalue has a negative real part, outside it one does not."""
    for v in (4.4, 5.0, 6.0):
        assert bb.eigenvalues(v).real.max() < 0
    for v in (0.0, 3.0, 4.2, 6.1, 8.0):
        assert bb.eigenvalues(v).real.max() > 0


def test_gravity_scales_with_g():
    """Doubling g is the same as scaling time: eigenvalues at (2 g, sqrt(2) v) are sqrt(2) times those at (g, v)."""
    p = dict(bb.BENCHMARK, g=2 * bb.BENCHMARK["g"])
    np.testing.assert_allclose(np.sort_complex(bb.eigenvalues(np.sqrt(2) * 5.0, p)),
                               np.sqrt(2) * np.sort_complex(bb.eigenvalues(5.0)), rtol=1e-12)
