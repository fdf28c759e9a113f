"""The direct LAPACK calls on small matrices give scipy.linalg.qr's and numpy.linalg.solve's numbers to the bit."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from mbcomp.core.small_linalg import least_norm, orthonormal_basis, pivoted_qr, solve
from mbcomp.core.errors import SimulationError


def matrices():
    rng = np.random.default_rng(7)
    for trial in range(300):
        m, n = (int(k) for k in rng.integers(1, 9, 2))
        a = rng.standard_normal((m, n))
        if trial % 3 == 0 and m > 1:
            a[-1] = 2.0 * a[0]                       # a dependent row: rank-deficient
        if trial % 5 == 0:
            a = np.asfortranarray(a)
        yield a


def test_pivoted_qr_gives_scipys_pivots_and_diagonal():
    for a in matrices():
        _, r, piv = scipy.linalg.qr(a, mode="economic", pivoting=True)
        diag, order = pivoted_qr(a)
        np.testing.assert_array_equal(diag, np.abs(np.diag(r)))
        np.testing.assert_array_equal(order, piv)
        assert np.all(np.diff(diag) <= 0)                  # non-increasing: rank revealing


def test_orthonormal_basis_is_scipys_q():
    for a in matrices():
        q = orthonormal_basis(a)
        np.testing.assert_array_equal(q, scipy.linalg.qr(a, mode="economic")[0])
        np.testing.assert_allclose(q.T @ q, np.eye(q.shape[1]), atol=1e-14)


def test_a_rank_one_matrix_has_one_pivot_above_rounding():
    a = np.outer([1.0, 2.0, -1.0], [0.5, 0.0, 3.0, 1.0])
    diag, _ = pivoted_qr(a)
    assert diag[0] > 1.0 and np.all(diag[1:] < 1e-14 * diag[0])


def test_empty_and_non_finite_input():
    diag, order = pivoted_qr(np.zeros((0, 3)))
    assert diag.size == 0 and order.tolist() == [0, 1, 2]
    assert orthonormal_basis(np.zeros((3, 0))).shape == (3, 0)
    with pytest.raises(ValueError, match="infs or NaNs"):
        pivoted_qr(np.array([[1.0, np.nan]]))
    with pytest.raises(ValueError, match="2-D"):
        orthonormal_basis(np.ones(3))


def test_solve_gives_numpys_solution_to_the_bit():
    rng = np.random.default_rng(11)
    for _ in range(2000):
        n = int(rng.integers(1, 6))
        a = rng.standard_normal((n, n))
        b = rng.standard_normal(n) if rng.random() < 0.5 else rng.standard_normal((n, int(rng.integers(1, 4))))
        np.testing.assert_array_equal(solve(a, b), np.linalg.solve(a, b))
    x = solve(np.array([[2.0, 0.0], [0.0, 4.0]]), np.array([1.0, 1.0]))
    np.testing.assert_array_equal(x, [0.5, 0.25])


def test_solve_refuses_a_singular_matrix_and_mismatched_shapes():
    with pytest.raises(np.linalg.LinAlgError):
        solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.array([1.0, 0.0]))
    with pytest.raises(ValueError, match="square"):
        solve(np.ones((2, 3)), np.ones(2))
    with pytest.raises(ValueError, match="rows"):
        solve(np.eye(2), np.ones(3))
    assert solve(np.zeros((0, 0)), np.zeros(0)).shape == (0,)


def test_least_norm_is_lstsq_and_names_what_failed():
    """The least-norm solution of a rank-deficient system equals numpy's; a non-finite system
    is a SimulationError naming what was solved (never numpy's LinAlgError)."""
    a = np.array([[1.0, 2.0], [2.0, 4.0], [0.0, 0.0]])
    b = np.array([1.0, 2.0, 0.0])
    x = least_norm(a, b, 1e-10, "test rows")
    np.testing.assert_array_equal(x, np.linalg.lstsq(a, b, rcond=1e-10)[0])
    np.testing.assert_allclose(x, [0.2, 0.4], rtol=1e-14)  # the shortest x with x0 + 2 x1 = 1
    a[0, 0] = np.nan
    with pytest.raises(SimulationError, match="test rows: the system to solve is not finite"):
        least_norm(a, b, 1e-10, "test rows")
