"""Timing shared by the benchmarks: medians of interleaved repetitions, wall and CPU time.

The machine the numbers come from may be shared and noisy.  Every benchmark therefore runs
each of its settings once per *round* (all tools and settings in turn, so that a noisy
spell hits them alike) and reports the **median over the rounds**, both as wall time and
as process CPU time (CPU time leaves out the time spent waiting for a core; for the
multi-threaded batch runs it adds the threads up, so there wall time is the figure).
A run shorter than ``burst`` seconds is repeated within its round (after one untimed
warm-up call) and averaged; one garbage collection per setting and round.
"""
from __future__ import annotations

import gc
import math
import statistics
import time
from dataclasses import dataclass, field
from typing import Any, Callable


def timed(fn: Callable[[], Any], collect: bool = True) -> tuple[float, float, Any]:
    """(wall s, process CPU s, result) of one call, garbage collection off (as timeit);
    ``collect``: a full collection first."""
    if collect:
        gc.collect()
    gc.disable()
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        out = fn()
        return time.perf_counter() - wall, time.process_time() - cpu, out
    finally:
        gc.enable()


@dataclass
class Run:
    """One setting of one tool: ``fn()`` returns its result (e.g. the final q)."""

    label: str
    setting: str
    value: float
    fn: Callable[[], Any]
    group: str = ""                 # settings of one group are swept in order (see ``measure``)
    walls: list = field(default_factory=list)
    cpus: list = field(default_factory=list)
    result: Any = None
    error: float = math.nan         # filled by the caller's ``check``
    failed: str = ""
    skipped: bool = False

    @property
    def wall(self) -> float:
        return statistics.median(self.walls) if self.walls else math.nan

    @property
    def cpu(self) -> float:
        return statistics.median(self.cpus) if self.cpus else math.nan


def _once(run: Run, burst: float) -> None:
    """Time ``run`` once in this round; a run shorter than ``burst`` is repeated (up to 5
    timed calls) after one untimed warm-up call.

    One garbage collection per setting and round, not one per call: with a compiled model's
    sympy objects alive a collection takes ~70 ms and leaves the caches cold, which added
    0.2-0.5 ms to every millisecond run right after it, whichever the tool (an additive
    penalty that favours the slower tool in a ratio); the warm-up puts the short run's code
    and data back in the caches, as when a user runs it in a loop."""
    gc.collect()
    walls, cpus = [], []
    while True:
        try:
            wall, cpu, out = timed(run.fn, collect=False)
        except Exception as exc:        # a diverging fixed step: recorded, never timed again
            run.failed = f"{type(exc).__name__}: {str(exc)[:100]}"
            return
        if run.result is None:
            run.result = out
        walls.append(wall)
        cpus.append(cpu)
        if walls[0] > burst or sum(walls[1:]) > burst or len(walls) >= 6:
            break
    if len(walls) > 1:  # the first call was the warm-up
        walls, cpus = walls[1:], cpus[1:]
    run.walls.append(sum(walls) / len(walls))
    run.cpus.append(sum(cpus) / len(cpus))


def measure(runs: list[Run], rounds: int, *, check: Callable[[Run], float] | None = None,
            stop_error: float = 0.0, max_run: float = math.inf, burst: float = 0.05, log=print) -> list[Run]:
    """Time every run in ``rounds`` interleaved rounds (medians in ``Run.wall``/``Run.cpu``).

    The first round is also the pilot: within a ``group`` (one tool's sweep, from coarse to
    fine) ``check(run)`` gives the run's error, and once it is below ``stop_error`` the finer
    settings of that group are skipped (they cannot change which setting is fastest at the
    error levels asked for); a setting slower than ``max_run`` s ends its group too.  Failed
    runs are not repeated.
    """
    for r in range(rounds):
        done_groups: set[str] = set()
        for run in runs:
            if run.skipped or run.failed:
                continue
            if r == 0 and run.group in done_groups:
                run.skipped = True
                continue
            _once(run, burst)
            if r == 0:
                if check is not None and not run.failed:
                    run.error = check(run)
                if run.group and ((not run.failed and run.error < stop_error) or run.wall > max_run):
                    done_groups.add(run.group)
        log(f"    round {r + 1}/{rounds} done")
    return runs


def time_at(points: list[tuple[float, float]], level: float) -> float:
    """Time a tool needs for error <= ``level`` from its ``(error, time)`` points: log-log
    interpolation along its Pareto front (fastest time for each error); ``nan`` when no
    setting reached the level; no extrapolation (when every point is below the level, its
    cheapest one)."""
    pts = sorted((t, e) for e, t in points if math.isfinite(e) and math.isfinite(t) and e > 0 and t > 0)
    front, best_error = [], math.inf
    for t, e in pts:                      # by increasing time: keep points improving the error
        if e < best_error:
            front.append((t, e))
            best_error = e
    if not front or best_error > level:
        return math.nan
    if front[0][1] <= level:
        return front[0][0]
    for (t0, e0), (t1, e1) in zip(front, front[1:]):
        if e0 > level >= e1:
            s = (math.log(level) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + s * (math.log(t1) - math.log(t0)))
    return math.nan


def median_time(fn: Callable[[], Any], rounds: int) -> tuple[float, float]:
    """(median wall s, median CPU s) of ``rounds`` calls of ``fn``."""
    walls, cpus = [], []
    for _ in range(rounds):
        wall, cpu, _ = timed(fn)
        walls.append(wall)
        cpus.append(cpu)
    return statistics.median(walls), statistics.median(cpus)


def fmt(value: float, digits: int = 3) -> str:
    """A number for a table: ``-`` for nan/inf, else ``digits`` significant digits."""
    if value is None or not math.isfinite(value):
        return "-"
    return f"{value:.{digits}g}"


def rounds_main(run: Callable[[int, bool], Any], doc: str, argv: list[str] | None = None) -> Any:
    """The command line of a benchmark taking ``--rounds`` and ``--quick`` (one round):
    ``run(rounds, quick)``, described by the first paragraph of ``doc``."""
    import argparse
    parser = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    return run(1 if args.quick else args.rounds, args.quick)
