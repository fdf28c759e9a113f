"""Constraint drift against Baumgarte gains: the conservative four-bar over 100 s.

The crank-rocker of docs/constraints.md (0.3, 0.8, 0.6 on a 0.7 base, gravity -y, no
damping) swings through large angles from the crank at 1 rad/s.  For each dae setting
(gains (alpha, beta) in 1/s, with or without projection) and each rtol (atol = rtol / 100),
DOP853 runs 100 s and we report: max |C| over the steps (m), |C| at the end, the largest
energy error relative to the largest kinetic energy, steps, right-hand-side evaluations and
wall time.  lagrange is listed for comparison (its residual is Newton's, ~1e-12).

Usage: python bench/constraints_drift.py [--t-end T] [--rtol R ...]
Writes bench/results/constraints_drift.csv and prints the table.
"""
from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from constraints_work_precision import fourbar  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
GAINS = [(0, 0), (1, 1), (2, 2), (5, 5), (10, 10), (20, 20), (50, 50), (100, 100),
         (5, 0), (0, 5), (10, 5), (5, 10), (2, 5)]
PROJECTED = [(0, 0), (5, 5)]


def settings():
    yield "lagrange", "lagrange", {}
    for gains in GAINS:
        yield f"dae {gains}", "dae", {"baumgarte": gains}
    for gains in PROJECTED:
        yield f"dae {gains} + projection", "dae", {"baumgarte": gains, "projection": True}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=100.0)
    parser.add_argument("--rtol", type=float, nargs="*", default=[1e-6, 1e-8])
    args = parser.parse_args(argv)
    os.environ.setdefault("MBCOMP_CACHE_DIR", tempfile.mkdtemp(prefix="mbcomp-bench-"))
    RESULTS.mkdir(exist_ok=True)
    model = fourbar()
    q0, qd0 = model.compile("lagrange").assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
    rows = []
    print(f"four-bar, {args.t_end:g} s, DOP853, atol = rtol/100")
    header = (f"{'setting':26s} {'rtol':>7s} {'max|C| m':>10s} {'end|C| m':>10s} {'energy':>9s} "
              f"{'steps':>6s} {'nfev':>7s} {'time s':>7s}")
    for rtol in args.rtol:
        print("\n" + header)
        for label, formulation, options in settings():
            system = model.compile(formulation, **options)
            row = {"setting": label, "rtol": rtol}
            start = time.perf_counter()
            try:
                res = system.simulate(args.t_end, q0, qd0, rtol=rtol, atol=rtol * 1e-2)
            except mb.SimulationError as exc:
                row.update(failure=str(exc)[:160], time=time.perf_counter() - start)
                print(f"{label:26s} {rtol:7.0e}   FAILED after {row['time']:.1f} s: {str(exc)[:80]}")
                rows.append(row)
                continue
            wall = time.perf_counter() - start
            violation = res.constraint_violation()
            energy = res.energy()
            row.update(max_violation=float(np.max(violation)), end_violation=float(violation[-1]),
                       energy_error=float(np.max(np.abs(energy.total - energy.total[0])) / np.max(energy.kinetic)),
                       steps=int(res.stats.get("steps", 0)), nfev=int(res.stats.get("nfev", 0)), time=wall,
                       failure="")
            rows.append(row)
            print(f"{label:26s} {rtol:7.0e} {row['max_violation']:10.1e} {row['end_violation']:10.1e} "
                  f"{row['energy_error']:9.1e} {row['steps']:6d} {row['nfev']:7d} {wall:7.2f}")
    path = RESULTS / "constraints_drift.csv"
    fields = ["setting", "rtol", "max_violation", "end_violation", "energy_error", "steps", "nfev", "time", "failure"]
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    print(f"\nwrote {path}")
    return rows


if __name__ == "__main__":
    main()
