"""Elementary rotations, axis parsing and Euler sequences (sympy and numpy alike)."""
from __future__ import annotations

from typing import Any, Sequence

import sys

import numpy as np

from mbcomp.core.errors import ModelError

AXIS_NAMES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def _math(a):
    """sympy functions for symbolic angles, numpy for numbers (a symbolic angle means
    sympy is imported already: numbers never import it)."""
    sp = sys.modules.get("sympy")
    return sp if sp is not None and isinstance(a, sp.Basic) else np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of 3-vectors (or along the last axis of arrays of them), with the
    operations of ``np.cross`` (the same numbers) without its axis handling: ``np.cross``
    costs ~20 us a call, which the per-step quaternion updates paid several times."""
    a1, a2, a3 = a[..., 0], a[..., 1], a[..., 2]
    b1, b2, b3 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack((a2 * b3 - a3 * b2, a3 * b1 - a1 * b3, a1 * b2 - a2 * b1), axis=-1)


def unit_axis(spec: Any, owner: Any = None) -> tuple[float, float, float]:
    """Unit 3-vector from ``"x" | "y" | "z"`` (optionally signed, ``"-z"``) or a 3-vector.

    Raises ``ModelError`` naming ``owner`` for an unknown name, a wrong length,
    a non-finite entry or a zero vector.
    """
    if isinstance(spec, str):
        key = spec.strip().lower()
        sign = -1.0 if key.startswith("-") else 1.0
        key = key.lstrip("+-")
        if key not in AXIS_NAMES:
            raise ModelError(owner, f"axis {spec!r} is not 'x', 'y', 'z' or a 3-vector")
        return tuple(sign * c for c in AXIS_NAMES[key])
    try:
        vec = np.asarray(spec, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError(owner, f"axis {spec!r} is not 'x', 'y', 'z' or a 3-vector") from None
    if vec.shape != (3,):
        raise ModelError(owner, f"axis must have 3 components, got {vec.size}")
    if not np.all(np.isfinite(vec)):
        raise ModelError(owner, f"axis {tuple(vec)} has a non-finite component")
    norm = float(np.linalg.norm(vec))
    if norm < 1e-12:
        raise ModelError(owner, "axis has zero length")
    vec = vec / norm
    # Snap exact axis directions so that symbolic code prunes their zeros.
    vec[np.abs(vec) < 1e-15] = 0.0
    return tuple(float(c) for c in vec)


def skew(v: Sequence) -> Any:
    """The cross-product matrix ``[v]x`` with ``[v]x @ u = v x u``."""
    x, y, z = v
    return [[0, -z, y], [z, 0, -x], [-y, x, 0]]


def axis_angle(axis: Sequence[float], angle: Any) -> Any:
    """Rotation by ``angle`` (rad, right-handed) about the unit ``axis`` (Rodrigues).

    Returns a sympy Matrix for a symbolic angle, a numpy (3, 3) array otherwise.
    Axis-aligned axes give the plain ``rot_x``-style matrices with no zero terms.
    """
    m = _math(angle)
    c, s = m.cos(angle), m.sin(angle)
    x, y, z = axis
    rows = [
        [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
        [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
        [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
    ]
    if m is not np:
        sp = m
        return sp.Matrix(rows).applyfunc(lambda e: sp.expand(e) if e.has(sp.cos(angle)) else e)
    return np.array(rows, dtype=float)


def rot_x(angle: Any) -> Any:
    """Right-handed rotation about x."""
    return axis_angle(AXIS_NAMES["x"], angle)


def rot_y(angle: Any) -> Any:
    """Right-handed rotation about y."""
    return axis_angle(AXIS_NAMES["y"], angle)


def rot_z(angle: Any) -> Any:
    """Right-handed rotation about z."""
    return axis_angle(AXIS_NAMES["z"], angle)


def parse_sequence(sequence: Any, owner: Any = None) -> str:
    """Validate an intrinsic Euler sequence of 1 to 3 axes from ``x, y, z``.

    Consecutive repeated axes (``"xx"``) are rejected: they describe one rotation twice.
    """
    if not isinstance(sequence, str):
        raise ModelError(owner, f"sequence must be a string such as 'xyz', got {sequence!r}")
    seq = sequence.strip().lower()
    if not 1 <= len(seq) <= 3:
        raise ModelError(owner, f"sequence {sequence!r} must have 1 to 3 axes")
    bad = [ch for ch in seq if ch not in AXIS_NAMES]
    if bad:
        raise ModelError(owner, f"sequence {sequence!r} has invalid axis {bad[0]!r} (use x, y, z)")
    for a, b in zip(seq, seq[1:]):
        if a == b:
            raise ModelError(owner, f"sequence {sequence!r} repeats axis {a!r} consecutively")
    return seq


def euler_rotation(sequence: str, angles: Sequence[Any]) -> Any:
    """Intrinsic (body-fixed) rotation ``R_a1(q1) R_a2(q2) ... `` for the given sequence."""
    result = None
    for axis_name, angle in zip(sequence, angles):
        r = axis_angle(AXIS_NAMES[axis_name], angle)
        result = r if result is None else result @ r
    return result


# -- unit quaternions (w, x, y, z); plain arithmetic, so sympy symbols work as well ---------
def quat_matrix(q: Sequence[Any]) -> list:
    """Rotation matrix (nested lists) of the quaternion ``q = (w, x, y, z)``.

    Scaled by ``2 / |q|^2``, so any non-zero quaternion gives an orthogonal matrix:
    an integrator's stage values that drift off unit length still rotate rigidly.
    """
    w, x, y, z = q
    s = 2 / (w * w + x * x + y * y + z * z)
    return [[1 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)],
            [s * (x * y + w * z), 1 - s * (x * x + z * z), s * (y * z - w * x)],
            [s * (x * z - w * y), s * (y * z + w * x), 1 - s * (x * x + y * y)]]


def quat_multiply(a: Sequence[Any], b: Sequence[Any]) -> list:
    """Hamilton product ``a b``: its rotation matrix is ``R(a) R(b)``."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return [aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw]


def quat_rate(q: Sequence[Any], w: Sequence[Any]) -> list:
    """``q' = q (0, w) / 2``: the quaternion rate for angular velocity ``w`` (rad/s) given
    in the rotated (child) frame."""
    return [c / 2 for c in quat_multiply(q, [0, *w])]


def quat_exp(phi: Sequence[float]) -> np.ndarray:
    """Unit quaternion of the rotation vector ``phi`` (rad; axis times angle)."""
    phi = np.asarray(phi, dtype=float)
    angle = float(np.linalg.norm(phi))
    half = angle / 2
    # sin(half) / angle without cancellation for small angles
    k = 0.5 - angle * angle / 48 if angle < 1e-4 else np.sin(half) / angle
    return np.concatenate(([np.cos(half)], k * phi))


def quat_log(q: Sequence[float]) -> np.ndarray:
    """Rotation vector (rad) of the unit quaternion ``q`` (the shorter of ``q``, ``-q``)."""
    q = np.asarray(q, dtype=float)
    if q[0] < 0:
        q = -q
    n = float(np.linalg.norm(q[1:]))
    if n < 1e-12:
        return 2 * q[1:] / max(q[0], 1e-300)
    return 2 * np.arctan2(n, q[0]) * q[1:] / n


def quat_normalize(q: Sequence[float], owner: Any = None) -> np.ndarray:
    """``q / |q|``; ``ModelError`` naming ``owner`` for a zero (or non-finite) quaternion."""
    q = np.asarray(q, dtype=float)
    n = float(np.linalg.norm(q))
    if not (n > 1e-300 and np.isfinite(n)):
        raise ModelError(owner, f"quaternion {tuple(q.tolist())} must be non-zero and finite")
    return q / n


def normals(axis) -> tuple[tuple, tuple]:
    """Two unit vectors perpendicular to ``axis`` and to each other (exact for x, y, z)."""
    a = np.asarray(axis, dtype=float)
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    n1 = np.cross(a, helper)
    n1 /= np.linalg.norm(n1)
    n2 = np.cross(a, n1)
    clean = lambda v: tuple(float(round(x, 15)) + 0.0 for x in v)
    return clean(n1), clean(n2)
