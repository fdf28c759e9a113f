"""Checks of public-API arguments: a clear ``ModelError`` naming the argument, never a raw
numpy/Python error, a silent NaN or an allocation that cannot succeed."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError

#: The largest output a run may allocate up front (bytes): beyond it a run is refused with its size.
MAX_OUTPUT_BYTES = 8 * 2 ** 30


def number(value: Any, name: str, *, where: str = "simulate", positive: bool = False, nonnegative: bool = False,
           finite: bool = True) -> float:
    """``value`` as a float; raises ``ModelError`` naming ``name`` when it is not a real number
    (strings, arrays, booleans, None), not finite (when ``finite``), or of the wrong sign."""
    if isinstance(value, (bool, np.bool_)) or value is None or isinstance(value, (str, bytes)):
        raise ModelError(where, f"{name} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ModelError(where, f"{name} must be a number, got {value!r}") from None
    if math.isnan(x) or (finite and math.isinf(x)):
        raise ModelError(where, f"{name} must be a finite number, got {value!r}")
    if positive and not x > 0:
        raise ModelError(where, f"{name} must be positive, got {value!r}")
    if nonnegative and not x >= 0:
        raise ModelError(where, f"{name} must be zero or positive, got {value!r}")
    return x


def vector(value: Any, size: int, name: str, *, where: str) -> np.ndarray:
    """``value`` as a finite float array of shape ``(size,)``; ``ModelError`` naming ``name`` otherwise."""
    if isinstance(value, (str, bytes)):
        raise ModelError(where, f"{name} must be {size} numbers, got {value!r}")
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ModelError(where, f"{name} must be {size} numbers, got {value!r}") from None
    if arr.shape != (size,):
        raise ModelError(where, f"{name} must be {size} numbers (shape ({size},)), got shape {arr.shape}: {value!r}")
    if not np.all(np.isfinite(arr)):
        raise ModelError(where, f"{name} must be finite, got {value!r}")
    return arr


def time_grid(t_eval: Any, t_end: float) -> np.ndarray:
    """Output times: a non-empty, finite, strictly increasing 1-D sequence within [0, t_end]."""
    if isinstance(t_eval, (str, bytes)):
        raise ModelError("simulate", f"t_eval must be a sequence of times (s), got {t_eval!r}")
    try:
        arr = np.asarray(t_eval, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ModelError("simulate", f"t_eval must be a sequence of times (s), got {t_eval!r}") from None
    if arr.ndim > 1 and arr.size != max(arr.shape):
        raise ModelError("simulate", f"t_eval must be one-dimensional, got shape {arr.shape}")
    arr = arr.reshape(-1)
    if arr.size == 0:
        raise ModelError("simulate", "t_eval is empty: give at least one output time (or None for every step)")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise ModelError("simulate", f"t_eval must be finite, got {arr[bad[0]]} at index {bad[0]}")
    if arr[0] < 0 or arr[-1] > t_end or np.any(np.diff(arr) <= 0):
        raise ModelError("simulate", f"t_eval must be increasing times within [0, t_end = {t_end:g}] s")
    return arr


def output_size(rows: int, columns: int, what: str) -> None:
    """Refuse an output of ``rows x columns`` doubles that is larger than ``MAX_OUTPUT_BYTES``."""
    size = float(rows) * columns * 8
    if size > MAX_OUTPUT_BYTES:
        raise ModelError("simulate", f"{what} would need {rows:.3g} samples x {columns} values = "
                         f"{size / 2 ** 30:.3g} GiB of output; use fewer samples (t_eval) or a larger step")
