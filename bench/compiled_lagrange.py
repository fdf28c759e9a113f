"""The lagrange formulation in the compiled loop against Python (scipy) stepping and dae.

Models: the crank-rocker four-bar of ``constraints_work_precision.py`` (released at crank
angle 1 rad turning at 1 rad/s) and the library four-bar (``library/four_bar.toml``, its
initial state); the library slider-crank (a speed motor, no degree of freedom: prescribed
motion); the library bouncing ball (a contact, restitution 0.8: six impacts in 3 s, each
located and applied in Python between compiled stretches).  Each run: 10 s (slider-crank
2 s, ball 3 s), rtol as given (default 1e-6), atol = rtol / 100, output at every step.  Settings:

  lagrange compiled   the default: coordinate partitioning and Newton in C
  lagrange scipy      the same formulation stepped by scipy (``integrator="scipy"``), the
                      only path for constrained lagrange models before
  dae compiled        the KKT solve in C, Baumgarte (5, 5)

Wall time of ``simulate`` (median of interleaved rounds; the scipy path once per round, it is
slow), evaluations, steps, and the error at t_end against a lagrange run at rtol 1e-12.

Usage: python bench/compiled_lagrange.py [--rtol 1e-6] [--rounds 5]
Writes bench/results/compiled_lagrange.csv and prints the table.
"""
from __future__ import annotations

import argparse
import csv
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import mbcomp as mb  # noqa: E402
from constraints_work_precision import fourbar  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).resolve().parent / "results"


def library(name):
    model = mb.load(ROOT / "library" / f"{name}.toml")
    return model


def initial(model, system):
    q = np.array([model.initial["q"].get(c, 0.0) for c in system.coords])
    qd = np.array([model.initial["qd"].get(c, 0.0) for c in system.speeds])
    return system.assemble(q, qd)


def cases():
    """(name, t_end, lagrange system, dae system or None, q0, qd0)."""
    bench = fourbar()
    lag = bench.compile("lagrange")
    q0, qd0 = lag.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
    yield "four-bar (bench)", 10.0, lag, bench.compile("dae"), q0, qd0
    model = library("four_bar")
    lag = model.compile("lagrange")
    yield "four-bar (library)", 10.0, lag, model.compile("dae"), *initial(model, lag)
    model = library("slider_crank")
    lag = model.compile("lagrange")
    yield "slider-crank, motor (library)", 2.0, lag, None, *initial(model, lag)
    model = library("bouncing_ball")
    lag = model.compile("lagrange")
    yield "bouncing ball, contact (library)", 3.0, lag, None, *initial(model, lag)


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rtol", type=float, default=1e-6)
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    rows = []
    for name, t_end, lag, dae, q0, qd0 in cases():
        settings = {"lagrange compiled": (lag, "auto"), "lagrange scipy": (lag, "scipy")}
        if dae is not None:
            settings["dae compiled"] = (dae, "auto")
        ref = lag.simulate(t_end, q0, qd0, rtol=1e-12, atol=1e-14).q[-1]
        walls = {label: [] for label in settings}
        last = {}
        for round_ in range(args.rounds):
            for label, (system, integrator) in settings.items():
                if integrator == "scipy" and round_ >= 2:
                    continue  # ~1 s per run: two rounds are enough
                started = time.perf_counter()
                res = system.simulate(t_end, q0, qd0, rtol=args.rtol, atol=args.rtol / 100, integrator=integrator)
                walls[label].append(time.perf_counter() - started)
                last[label] = res
        base = statistics.median(walls["lagrange scipy"])
        for label, res in last.items():
            wall = statistics.median(walls[label])
            rows.append({"model": name, "setting": label, "rtol": args.rtol, "integrator": res.stats["integrator"],
                         "wall_ms": wall * 1e3, "nfev": res.stats["nfev"], "steps": res.stats["steps"],
                         "error": float(np.max(np.abs(res.q[-1] - ref))), "speedup_vs_scipy": base / wall})
    RESULTS.mkdir(exist_ok=True)
    with open(RESULTS / "compiled_lagrange.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print(f"{'model':30s} {'setting':18s} {'path':9s} {'ms':>9s} {'nfev':>7s} {'steps':>6s} {'error':>9s} "
          f"{'x scipy':>8s}")
    for r in rows:
        print(f"{r['model']:30s} {r['setting']:18s} {r['integrator']:9s} {r['wall_ms']:9.2f} {r['nfev']:7d} "
              f"{r['steps']:6d} {r['error']:9.1e} {r['speedup_vs_scipy']:8.1f}")
    return rows


if __name__ == "__main__":
    main()
