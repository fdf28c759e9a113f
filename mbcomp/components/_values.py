"""Validation of the numbers users give components (finite, right shape, right sign)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ModelError


def vector3(value: Any, owner: Any, what: str) -> tuple[float, float, float]:
    """A finite 3-vector, or a ``ModelError`` naming ``owner`` and ``what``."""
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError(owner, f"{what} must be a 3-vector of numbers, got {value!r}") from None
    if arr.shape != (3,):
        raise ModelError(owner, f"{what} must have 3 components, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ModelError(owner, f"{what} {tuple(arr.tolist())} has a non-finite component")
    return tuple(float(v) for v in arr)


def scalar(value: Any, owner: Any, what: str, *, positive: bool = False,
           nonnegative: bool = False, low: float | None = None, high: float | None = None) -> float:
    """A finite float with optional sign or range checks, else a ``ModelError``."""
    if isinstance(value, bool):
        raise ModelError(owner, f"{what} must be a number, got {value!r}")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ModelError(owner, f"{what} must be a number, got {value!r}") from None
    if not np.isfinite(x):
        raise ModelError(owner, f"{what} must be finite, got {x}")
    if positive and x <= 0:
        raise ModelError(owner, f"{what} must be positive, got {x}")
    if nonnegative and x < 0:
        raise ModelError(owner, f"{what} must not be negative, got {x}")
    if low is not None and x < low or high is not None and x > high:
        raise ModelError(owner, f"{what} must lie in [{low}, {high}], got {x}")
    return x


def name_of(ref: Any) -> str:
    """The name a component reference stands for (an object with ``.name`` or a string)."""
    return ref if isinstance(ref, str) else getattr(ref, "name", repr(ref))
