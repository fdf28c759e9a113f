"""Progress bars for long simulations and sweeps (``progress=True``).

A bar only watches: it never changes how a run integrates.  A compiled loop reports the time it
has reached through its step hook (``integrators.step_hook``), a scipy-stepped run after each
step; the bar draws that.  It is tqdm's when the optional ``tqdm`` is installed
(``pip install "mbcomp[progress]"``), else a one-line text bar on stderr.
"""
from __future__ import annotations

import sys
import time


class ProgressBar:
    """A bar from 0 to ``total`` (``unit``), drawn on stderr once ``delay`` seconds have passed
    (so short runs stay quiet); ``enabled=False`` makes every call a no-op."""

    def __init__(self, total: float, enabled: bool = True, *, desc: str = "simulating", unit: str = "s",
                 delay: float = 0.0, width: int = 30):
        self.total, self.enabled, self.desc, self.unit = float(total), bool(enabled), desc, unit
        self.delay, self.width = float(delay), width
        self.value, self.shown = 0.0, -1
        self.started = time.monotonic()
        self._tqdm = None
        if self.enabled:
            try:
                from tqdm import tqdm
            except ImportError:
                tqdm = None
            if tqdm is not None:
                self._tqdm = tqdm(total=self.total, desc=desc, unit=unit, delay=self.delay, leave=True,
                                  file=sys.stderr, bar_format="{l_bar}{bar}| {n:.4g}/{total:.4g} " + unit
                                  + " [{elapsed}<{remaining}]")

    def update_to(self, value: float) -> None:
        """Show progress up to ``value`` (clipped to [0, total]; never moves backwards)."""
        if not self.enabled or value is None:
            return
        value = min(max(float(value), self.value), self.total)
        if self._tqdm is not None:
            if value > self.value:
                self._tqdm.update(value - self.value)
            self.value = value
            return
        self.value = value
        if time.monotonic() - self.started < self.delay:
            return
        fraction = value / self.total if self.total > 0 else 1.0
        percent = int(100 * fraction)
        if percent != self.shown:
            self.shown = percent
            filled = int(self.width * fraction)
            sys.stderr.write(f"\r{self.desc} [{'#' * filled}{'.' * (self.width - filled)}] {percent:3d}% "
                             f"{value:.4g}/{self.total:.4g} {self.unit}")
            sys.stderr.flush()

    def close(self) -> None:
        """Finish the line (or tqdm's bar)."""
        if not self.enabled:
            return
        if self._tqdm is not None:
            self._tqdm.close()
        elif self.shown >= 0:
            sys.stderr.write("\n")
            sys.stderr.flush()
        self.enabled = False
