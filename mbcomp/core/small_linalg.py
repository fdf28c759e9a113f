"""Linear algebra on the small matrices of a Python-stepped evaluation, by direct LAPACK calls.

The formulations factor a constraint Jacobian of a few rows and solve a few small systems at
every evaluation of a Python-stepped constrained model (which rows are independent, which
speeds are dependent, the dependent coordinates' Newton steps).  For matrices this small the
library wrappers spend most of their time outside LAPACK (argument checks, routine lookup,
a workspace query per call): ``scipy.linalg.qr`` 69 us against 4 us for a 5 x 3 matrix,
``numpy.linalg.solve`` 8-13 us against 2 us for a 2 x 2 system.  These functions call the
same LAPACK routines (``geqp3``, ``geqrf``, ``orgqr``, ``gesv``) with the same optimal
workspace, looked up once per shape, and return the same numbers to the bit
(tests/test_small_linalg.py compares them).
"""
from __future__ import annotations

import functools

import numpy as np


@functools.lru_cache(maxsize=None)
def lapack_routine(name: str):
    """The double-precision LAPACK routine ``name`` (``"potrf"`` for ``dpotrf``) of scipy,
    looked up once: scipy is imported on first use (``import mbcomp`` does not import it),
    and an import statement in a per-evaluation solve cost about 1 us a call."""
    from scipy.linalg import lapack
    return getattr(lapack, "d" + name)


@functools.lru_cache(maxsize=256)
def _workspace(name: str, shape: tuple[int, int]) -> int:
    """The optimal workspace length LAPACK gives for ``name`` on a matrix of ``shape``
    (what ``scipy.linalg.qr`` asks for before every call)."""
    routine = lapack_routine(name)
    probe = np.zeros(shape, order="F")
    if name == "orgqr":
        result = routine(probe, np.zeros(min(shape)), lwork=-1)
    else:
        result = routine(probe, lwork=-1)
    return int(result[-2][0].real)


def _finite(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    if a.ndim != 2:
        raise ValueError("expected a 2-D array")
    if not np.isfinite(a).all():
        raise ValueError("array must not contain infs or NaNs")
    return a


def pivoted_qr(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(|diag R|, piv)`` of the column-pivoted QR ``a[:, piv] = Q R`` (LAPACK ``geqp3``):
    the magnitudes of R's diagonal, non-increasing, and the column order (0-based); as
    ``scipy.linalg.qr(a, mode="economic", pivoting=True)`` gives them."""
    a = _finite(a)
    if a.size == 0:
        return np.zeros(0), np.arange(a.shape[1], dtype=np.int32)
    qr, jpvt, _, _, info = lapack_routine("geqp3")(a, lwork=_workspace("geqp3", a.shape))
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal geqp3")
    return np.abs(np.diag(qr)), jpvt - 1


def orthonormal_basis(a: np.ndarray) -> np.ndarray:
    """Q of the economic QR of ``a`` (its columns span ``a``'s columns; LAPACK ``geqrf`` and
    ``orgqr``), as ``scipy.linalg.qr(a, mode="economic")[0]`` gives it."""
    a = _finite(a)
    m, n = a.shape
    if a.size == 0:
        return np.empty((m, min(m, n)))
    qr, tau, _, info = lapack_routine("geqrf")(a, lwork=_workspace("geqrf", a.shape))
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal geqrf")
    head = qr[:, :m] if m < n else qr
    q, _, info = lapack_routine("orgqr")(head, tau, lwork=_workspace("orgqr", head.shape), overwrite_a=1)
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal orgqr")
    return q


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x`` with ``a x = b`` (a square; b a vector or columns) by LAPACK ``gesv``, as
    ``numpy.linalg.solve`` computes it; ``numpy.linalg.LinAlgError`` when ``a`` is singular."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or b.shape[:1] != a.shape[:1]:
        raise ValueError(f"expected a square matrix and a right-hand side of its rows, got {a.shape} and {b.shape}")
    if a.shape[0] == 0:
        return np.empty(b.shape)
    _, _, x, info = lapack_routine("gesv")(a, b)
    if info > 0:
        raise np.linalg.LinAlgError("Singular matrix")
    if info < 0:
        raise ValueError(f"illegal value in {-info}th argument of internal gesv")
    return x


def least_norm(a: np.ndarray, b: np.ndarray, rcond: float | None, what: str) -> np.ndarray:
    """The least-norm least-squares ``x`` of ``a x ~ b`` (``numpy.linalg.lstsq``: singular
    values below ``rcond`` times the largest dropped), or a ``SimulationError`` saying
    ``what`` was being solved when the system is not finite or the SVD does not converge
    (numpy's ``LinAlgError`` names neither the model nor the cause)."""
    from mbcomp.core.errors import SimulationError
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise SimulationError(f"{what}: the system to solve is not finite (a state or force grew without bound)")
    try:
        return np.linalg.lstsq(a, b, rcond=rcond)[0]
    except np.linalg.LinAlgError as exc:
        raise SimulationError(f"{what}: the least-squares solve failed ({exc}); the contact or constraint rows "
                              f"are degenerate there") from None
