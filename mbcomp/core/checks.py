"""Checks of public-API arguments: a clear ``ModelError`` naming the argument, never a raw
numpy/Python error, a silent NaN or an allocation that cannot succeed."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError

#: The largest output a run may hold (bytes): a run whose output would be larger is refused with its
#: size before anything is allocated (set ``mbcomp.core.checks.MAX_OUTPUT_BYTES`` to raise it).
MAX_OUTPUT_BYTES = 2 * 2 ** 30

#: Steps a run keeps by default when it stores every step (``t_eval=None``): ``simulate(...,
#: max_samples=N)`` raises it for one run, ``t_eval`` keeps only the times asked for.
MAX_SAMPLES = 1_000_000


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


def output_size(rows: float, columns: int, what: str, *, where: str = "simulate",
                fix: str = "use fewer samples (t_eval) or a larger step") -> None:
    """Refuse an output of ``rows x columns`` doubles (8 bytes each) that is larger than
    ``MAX_OUTPUT_BYTES``, before anything is allocated; ``fix`` says how to ask for less."""
    size = float(rows) * columns * 8
    if size > MAX_OUTPUT_BYTES:
        raise ModelError(where, f"{what} would need {float(rows):.3g} samples x {columns} values = "
                         f"{size / 2 ** 30:.3g} GiB of output, more than the limit of "
                         f"{MAX_OUTPUT_BYTES / 2 ** 30:.3g} GiB (mbcomp.core.checks.MAX_OUTPUT_BYTES); {fix}")


class StepBudget:
    """How many rows of ``columns`` values a run that keeps every step (``t_eval=None``) may
    store: ``max_samples`` (default ``MAX_SAMPLES``), and no more than ``MAX_OUTPUT_BYTES``
    hold.  ``exceeded`` is the ``SimulationError`` for a run that needs more."""

    def __init__(self, max_samples: Any, columns: int, t_end: float):
        if max_samples is None:
            max_samples = MAX_SAMPLES
        elif (isinstance(max_samples, (bool, np.bool_)) or not isinstance(max_samples, (int, np.integer))
              or max_samples < 2):
            raise ModelError("simulate", f"max_samples must be a whole number of at least 2 (or None for "
                                         f"{MAX_SAMPLES}), got {max_samples!r}")
        self.max_samples = int(max_samples)
        self.columns = max(int(columns), 1)
        self.by_size = MAX_OUTPUT_BYTES // (8 * self.columns)
        self.rows = max(min(self.max_samples, self.by_size), 2)
        self.t_end = t_end

    def exceeded(self, t: float):
        """The error for a run that would keep more than ``rows`` steps, reached at ``t`` (s)."""
        from mbcomp.core.errors import SimulationError
        if self.rows < self.max_samples:
            limit = (f"more than {self.rows} steps of {self.columns} values, the most that fit in "
                     f"MAX_OUTPUT_BYTES = {MAX_OUTPUT_BYTES / 2 ** 30:.3g} GiB (mbcomp.core.checks.MAX_OUTPUT_BYTES)")
        else:
            limit = f"more than max_samples = {self.max_samples} steps"
        return SimulationError(f"t_eval=None keeps every step and this run would keep {limit} (at t = {t:.6g} s of "
                               f"t_end = {self.t_end:g} s); pass t_eval (the output times you need), or raise "
                               f"max_samples (simulate(..., max_samples=N))")

    def check_rows(self, rows: float, what: str) -> None:
        """Refuse up front a run known to keep ``rows`` rows (fixed steps, prescribed motion)."""
        if rows > self.rows:
            output_size(rows, self.columns, what, fix="pass t_eval (the output times you need) or a larger step")
            raise ModelError("simulate", f"{what} keeps {int(rows) if rows < 1e12 else f'{rows:.3g}'} steps with t_eval=None, more than "
                                         f"max_samples = {self.max_samples}; pass t_eval (the output times you "
                                         f"need), a larger step, or raise max_samples")


def prescribed_times(t_end: float, max_step: float, budget: StepBudget | None) -> np.ndarray:
    """The output times of a run with no degree of freedom and ``t_eval=None``: steps of
    ``max_step`` (at most t_end / 200), refused up front beyond the step budget."""
    count = int(np.ceil(t_end / min(max_step, t_end / 200.0)))
    if budget is not None:
        budget.check_rows(count + 1, f"max_step = {max_step:g} s over t_end = {t_end:g} s")
    return np.linspace(0.0, t_end, count + 1)
