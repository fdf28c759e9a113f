"""Small value helpers for arguments that are not declared parameters (all through
``mbcomp.core.params.validate``, the one validator)."""
from __future__ import annotations

from typing import Any

from mbcomp.core.params import ParameterSpec, finite, in_range, nonnegative, positive, validate


def vector3(value: Any, owner: Any, what: str) -> tuple[float, float, float]:
    """A finite 3-vector, or a ``ModelError`` naming ``owner`` and ``what``."""
    return validate(ParameterSpec(what, (3,)), value, owner)


def scalar(value: Any, owner: Any, what: str, *, positive: bool = False,
           nonnegative: bool = False, low: float | None = None, high: float | None = None) -> float:
    """A finite float with optional sign or range checks, else a ``ModelError``."""
    check = _positive if positive else _nonnegative if nonnegative else finite
    if low is not None or high is not None:
        check = in_range(-float("inf") if low is None else low, float("inf") if high is None else high)
    return validate(ParameterSpec(what, (), check=check), value, owner)


_positive, _nonnegative = positive, nonnegative


def name_of(ref: Any) -> str:
    """The name a component reference stands for (an object with ``.name`` or a string)."""
    return ref if isinstance(ref, str) else getattr(ref, "name", repr(ref))
