"""The benchmark bicycle's linearised equations in closed form: a test oracle.

Meijaard, Papadopoulos, Ruina and Schwab (2007), "Linearized dynamics equations for the
balance and steer of a bicycle: a benchmark and review", Proc. R. Soc. A 463, 1955-1982,
give the lean and steer equations of the Whipple bicycle (two knife-edge wheels rolling
without slip on level ground, a rear frame with a rigid rider, a front frame of fork and
handlebar) linearised about riding straight ahead, upright, at forward speed ``v``:

    M q'' + v C1 q' + (g K0 + v**2 K2) q = f,     q = (lean phi, steer delta)

with the 2x2 matrices given in closed form by the paper's appendix A from 25 parameters
(``BENCHMARK``, the paper's table 1). This module implements those formulas and nothing else:
it shares no code with ``mbcomp`` and derives nothing symbolically, so the tests can compare
``mbcomp``'s linearisation of its 3D multibody model with an independent computation.

Conventions (the paper's): the rear-frame axes are x forward, y to the right, z down (the
rear contact point the origin); lean ``phi`` positive to the right (about x), steer ``delta``
positive to the right (about the head axis, pointing down). ``xB, zB`` etc. are centre-of-mass
coordinates in that frame, so ``zB < 0`` is above the ground; products of inertia ``IBxz``
are ``-sum m x z`` style entries of the inertia matrix in those axes (the matrix entry, not
its negative). ``lam`` is the head angle measured from the vertical (the steer axis tilt).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

BENCHMARK: dict[str, float] = {
    "w": 1.02, "c": 0.08, "lam": math.pi / 10, "g": 9.81,
    "rR": 0.3, "mR": 2.0, "IRxx": 0.0603, "IRyy": 0.12,
    "xB": 0.3, "zB": -0.9, "mB": 85.0, "IBxx": 9.2, "IByy": 11.0, "IBzz": 2.8, "IBxz": 2.4,
    "xH": 0.9, "zH": -0.7, "mH": 4.0, "IHxx": 0.05892, "IHyy": 0.06, "IHzz": 0.00708, "IHxz": -0.00756,
    "rF": 0.35, "mF": 3.0, "IFxx": 0.1405, "IFyy": 0.28,
}
"""The paper's table 1 (SI units; ``lam`` in rad)."""

# The paper's equations (A 1)-(A 25) evaluated for BENCHMARK, as printed in its section 3.
PUBLISHED_M = np.array([[80.81722, 2.31941332208709], [2.31941332208709, 0.29784188199686]])
PUBLISHED_C1 = np.array([[0.0, 33.86641391492494], [-0.85035641456978, 1.68540397397560]])
PUBLISHED_K0 = np.array([[-80.95, -2.59951685249872], [-2.59951685249872, -0.80329488458618]])
PUBLISHED_K2 = np.array([[0.0, 76.59734589573222], [0.0, 2.65431523794604]])
PUBLISHED_WEAVE_SPEED = 4.29238253634111  # m/s, the weave eigenvalues' real part crosses zero
PUBLISHED_CAPSIZE_SPEED = 6.02426201538837  # m/s, the capsize eigenvalue crosses zero


def matrices(p: dict[str, float] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(M, C1, K0, K2)`` of the benchmark equations for the parameters ``p`` (default BENCHMARK).

    Rows and columns are (lean, steer). Units: M in kg m^2, C1 in kg m, K0 in kg m, K2 in kg
    (so that ``v C1`` and ``g K0 + v**2 K2`` are in N m s/rad and N m/rad).
    """
    p = dict(BENCHMARK if p is None else p)
    w, c, lam, g = p["w"], p["c"], p["lam"], p["g"]
    rR, mR, IRxx, IRyy = p["rR"], p["mR"], p["IRxx"], p["IRyy"]
    xB, zB, mB = p["xB"], p["zB"], p["mB"]
    IBxx, IBzz, IBxz = p["IBxx"], p["IBzz"], p["IBxz"]
    xH, zH, mH = p["xH"], p["zH"], p["mH"]
    IHxx, IHzz, IHxz = p["IHxx"], p["IHzz"], p["IHxz"]
    rF, mF, IFxx, IFyy = p["rF"], p["mF"], p["IFxx"], p["IFyy"]
    del g  # gravity multiplies K0 outside these matrices
    sl, cl = math.sin(lam), math.cos(lam)

    # the whole bicycle (rear and front assemblies together), about the rear contact point
    mT = mR + mB + mH + mF
    xT = (xB * mB + xH * mH + w * mF) / mT
    zT = (-rR * mR + zB * mB + zH * mH - rF * mF) / mT
    ITxx = IRxx + IBxx + IHxx + IFxx + mR * rR**2 + mB * zB**2 + mH * zH**2 + mF * rF**2
    ITxz = IBxz + IHxz - mB * xB * zB - mH * xH * zH + mF * w * rF
    IRzz, IFzz = IRxx, IFxx  # thin symmetric wheels
    ITzz = IRzz + IBzz + IHzz + IFzz + mB * xB**2 + mH * xH**2 + mF * w**2

    # the front assembly (handlebar and front wheel) about its own centre of mass
    mA = mH + mF
    xA = (xH * mH + w * mF) / mA
    zA = (zH * mH - rF * mF) / mA
    IAxx = IHxx + IFxx + mH * (zH - zA) ** 2 + mF * (rF + zA) ** 2
    IAxz = IHxz - mH * (xH - xA) * (zH - zA) + mF * (w - xA) * (rF + zA)
    IAzz = IHzz + IFzz + mH * (xH - xA) ** 2 + mF * (w - xA) ** 2
    # its centre of mass ahead of the steer axis, and its inertias about that axis
    uA = (xA - w - c) * cl - zA * sl
    IAll = mA * uA**2 + IAxx * sl**2 + 2 * IAxz * sl * cl + IAzz * cl**2
    IAlx = -mA * uA * zA + IAxx * sl + IAxz * cl
    IAlz = mA * uA * xA + IAxz * sl + IAzz * cl

    mu = c / w * cl  # the trail ratio
    SR, SF = IRyy / rR, IFyy / rF  # gyrostatic coefficients of the wheels
    ST = SR + SF
    SA = mA * uA + mu * mT * xT  # the static moment of the steering

    M = np.array([[ITxx, IAlx + mu * ITxz], [IAlx + mu * ITxz, IAll + 2 * mu * IAlz + mu**2 * ITzz]])
    K0 = np.array([[mT * zT, -SA], [-SA, -SA * sl]])
    K2 = np.array([[0.0, (ST - mT * zT) / w * cl], [0.0, (SA + SF * sl) / w * cl]])
    C1 = np.array([
        [0.0, mu * ST + SF * cl + ITxz / w * cl - mu * mT * zT],
        [-(mu * ST + SF * cl), IAlz / w * cl + mu * (SA + ITzz / w * cl)],
    ])
    return M, C1, K0, K2


def state_matrix(v: float, p: dict[str, float] | None = None) -> np.ndarray:
    """The 4x4 ``A`` of ``x' = A x`` with ``x = (phi, delta, phi', delta')`` at forward speed ``v`` (m/s)."""
    g = (BENCHMARK if p is None else p)["g"]
    M, C1, K0, K2 = matrices(p)
    Minv = np.linalg.inv(M)
    return np.block([
        [np.zeros((2, 2)), np.eye(2)],
        [-Minv @ (g * K0 + v**2 * K2), -Minv @ (v * C1)],
    ])


def eigenvalues(v: float, p: dict[str, float] | None = None) -> np.ndarray:
    """The four eigenvalues (1/s) of the lean-steer motion at forward speed ``v``, sorted by
    real then imaginary part."""
    lam = np.linalg.eigvals(state_matrix(v, p))
    return lam[np.lexsort((lam.imag, lam.real))]


def weave_speed(p: dict[str, float] | None = None, bracket: tuple[float, float] = (3.0, 5.0)) -> float:
    """The speed (m/s) above which the oscillatory weave mode is stable: its complex pair's real part is zero."""
    def weave_real(v: float) -> float:
        lam = eigenvalues(v, p)
        return max(x.real for x in lam if abs(x.imag) > 1e-9)

    return brentq(weave_real, *bracket, xtol=1e-14)


def capsize_speed(p: dict[str, float] | None = None, bracket: tuple[float, float] = (5.0, 8.0)) -> float:
    """The speed (m/s) above which the real capsize eigenvalue is positive (the slow fall sets in)."""
    def capsize_real(v: float) -> float:
        lam = eigenvalues(v, p)
        # of the real eigenvalues, the one nearest zero (castering is large and negative)
        return min((x.real for x in lam if abs(x.imag) <= 1e-9), key=abs)

    return brentq(capsize_real, *bracket, xtol=1e-14)
