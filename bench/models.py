"""Model builders shared by the benchmarks (the N-link 3D pendulum chain of the speed issue)."""
from __future__ import annotations

import math
import time
from typing import Any, Callable

import numpy as np

import mbcomp as mb


def pendulum_chain(n: int, length: float = 0.5, mass: float = 1.0) -> mb.Model:
    """N uniform rods (1 kg, 0.5 m, inertia diag(mL^2/12, mL^2/12, 1e-4)) hanging along -z
    from a fixed point; revolute axes alternate x, y; gravity -9.81 along z."""
    m = mb.Model(f"chain{n}", gravity=(0, 0, -9.81))
    parent = m.ground
    for i in range(n):
        body = m.add(mb.Body(f"link{i}", mass=mass, com=(0, 0, -length / 2),
                             inertia=(mass * length ** 2 / 12, mass * length ** 2 / 12, 1e-4)))
        m.add(mb.Revolute(f"joint{i}", parent, body, axis="x" if i % 2 == 0 else "y",
                          parent_point=(0, 0, -length) if i else (0, 0, 0)))
        parent = body
    return m


def chain_initial_state(n: int):
    """All angles 0.3 rad, at rest."""
    return np.full(n, 0.3), np.zeros(n)


def write_csv(rows: list[dict], name: str):
    """Write benchmark rows to bench/results/<name> (columns: every key, in first-seen
    order; floats with 6 significant digits)."""
    import csv
    from pathlib import Path
    out = Path(__file__).resolve().parent / "results" / name
    out.parent.mkdir(exist_ok=True)
    with open(out, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(dict.fromkeys(k for row in rows for k in row)))
        writer.writeheader()
        writer.writerows({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()} for row in rows)
    return out


def bounce_height(t: float, z0: float, radius: float, e: float, g: float) -> float:
    """Centre height (m) at time t (s) of a ball of ``radius`` dropped from rest at centre
    height ``z0`` onto a floor: free flight between impacts, each reversing the speed times
    ``e`` (Newton); at rest on the floor (z = radius) once the rebound speeds have summed up."""
    t_fall = math.sqrt(2 * (z0 - radius) / g)
    if t <= t_fall:
        return z0 - 0.5 * g * t * t
    start, speed = t_fall, g * t_fall
    while speed > 1e-12:
        speed *= e
        duration = 2 * speed / g
        if t <= start + duration:
            s = t - start
            return radius + speed * s - 0.5 * g * s * s
        start += duration
    return radius


def interleaved_medians(runs: dict[str, Callable[[], Any]], repeat: int) -> tuple[dict[str, float], dict[str, Any]]:
    """Median wall seconds and last result of each zero-argument run of ``runs`` ({name: run}),
    each run ``repeat`` times, interleaved (the machine's load, which changes from second to
    second on a shared machine, hits every run alike): the paired timing of the benchmarks."""
    seconds: dict[str, list[float]] = {name: [] for name in runs}
    results: dict[str, Any] = {}
    for _ in range(repeat):
        for name, run in runs.items():
            started = time.perf_counter()
            results[name] = run()
            seconds[name].append(time.perf_counter() - started)
    return {name: float(np.median(s)) for name, s in seconds.items()}, results
