"""Work-precision of the constraint formulations: lagrange against dae (Baumgarte gains,
with and without projection) on closed-loop mechanisms.

Models (planar, gravity -y, no damping):
  fourbar      the crank-rocker of docs/constraints.md (0.3, 0.8, 0.6 on a 0.7 base),
               large swings from the crank at 1 rad/s; t_end = 10 s
  chain10      a closed chain of 10 links (0.25 m, 1 kg) hung between (0, 0) and (1.5, 0),
               closed by the revolute 'close': 10 coordinates, 8 DOF; released from rest
               in an asymmetric shape; t_end = 5 s

For every setting and rtol (atol = rtol / 100): wall time of simulate() (best of
``--repeat`` runs, compilation excluded), the error max_i |q_i(t_end) - q_ref,i(t_end)| (rad)
against a reference (lagrange at rtol 1e-12, cross-checked with dae at 1e-12), the largest
constraint violation max |C| (m) over the steps, and the largest energy error relative to
the run's largest kinetic energy.  A run that raises is recorded with its message.

Usage: python bench/constraints_work_precision.py [--quick] [--repeat N]
Writes bench/results/constraints_work_precision.csv and constraints_work_precision_<model>.png,
and prints the table.
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

RESULTS = Path(__file__).resolve().parent / "results"
G = 9.81

SETTINGS = {   # label -> (formulation, options)
    "lagrange": ("lagrange", {}),
    "dae (1, 1)": ("dae", {"baumgarte": (1.0, 1.0)}),
    "dae (5, 5)": ("dae", {"baumgarte": (5.0, 5.0)}),
    "dae (20, 20)": ("dae", {"baumgarte": (20.0, 20.0)}),
    "dae (0, 0) + projection": ("dae", {"baumgarte": (0.0, 0.0), "projection": True}),
    "dae (5, 5) + projection": ("dae", {"baumgarte": (5.0, 5.0), "projection": True}),
}
TOLERANCES = [1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10]


def bar(name, length, mass=1.0):
    return mb.Body(name, mass=mass, com=(length / 2, 0, 0), inertia=(1e-4, length ** 2 / 12, length ** 2 / 12))


def fourbar():
    m = mb.Model("fourbar", gravity=(0, -G, 0))
    crank, coupler, rocker = m.add(bar("crank", 0.3)), m.add(bar("coupler", 0.8)), m.add(bar("rocker", 0.6))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(0.3, 0, 0)))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(0.7, 0, 0)))
    m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(0.8, 0, 0), child_point=(0.6, 0, 0)))
    return m


def closed_chain(n=10, length=0.25, span=1.5):
    m = mb.Model(f"chain{n}_closed", gravity=(0, -G, 0))
    parent = m.ground
    for i in range(n):
        link = m.add(bar(f"link{i}", length))
        m.add(mb.Revolute(f"J{i}", parent, link, axis="z", parent_point=(length, 0, 0) if i else (0, 0, 0)))
        parent = link
    m.add(mb.Revolute("close", m.ground, parent, axis="z", parent_point=(span, 0, 0), child_point=(length, 0, 0)))
    return m


def chain_guess(n=10):
    """Absolute link angles of a lopsided U (converted to relative joint angles)."""
    phi = -1.3 + 2.5 * np.linspace(0, 1, n) ** 1.3
    return np.concatenate(([phi[0]], np.diff(phi)))


MODELS = {
    "fourbar": (fourbar, lambda: ([1.0, -0.5, 1.5], [1.0, 0.0, 0.0]), 10.0),
    "chain10": (closed_chain, lambda: (chain_guess(), np.zeros(10)), 5.0),
}


def run(system, t_end, q0, qd0, rtol, repeat):
    """(best wall time, result) of simulate; raises what simulate raises."""
    best, res = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        res = system.simulate(t_end, q0, qd0, rtol=rtol, atol=rtol * 1e-2)
        best = min(best, time.perf_counter() - start)
    return best, res


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="three tolerances, one run each")
    parser.add_argument("--repeat", type=int, default=2)
    args = parser.parse_args(argv)
    os.environ.setdefault("MBCOMP_CACHE_DIR", tempfile.mkdtemp(prefix="mbcomp-bench-"))
    tolerances = [1e-4, 1e-7, 1e-10] if args.quick else TOLERANCES
    repeat = 1 if args.quick else args.repeat
    RESULTS.mkdir(exist_ok=True)
    rows = []
    for model_name, (builder, initial, t_end) in MODELS.items():
        model = builder()
        reference_system = model.compile("lagrange")
        q0, qd0 = reference_system.assemble(*initial())
        ref = reference_system.simulate(t_end, q0, qd0, rtol=1e-12, atol=1e-14)
        check = model.compile("dae").simulate(t_end, q0, qd0, rtol=1e-12, atol=1e-14)
        uncertainty = float(np.max(np.abs(ref.q[-1] - check.q[-1])))
        print(f"\n{model_name}: {reference_system.nq} coordinates, ndof {reference_system.ndof}, t_end {t_end} s; "
              f"reference lagrange vs dae at rtol 1e-12 differ by {uncertainty:.1e} rad")
        print(f"  {'setting':26s} {'rtol':>7s} {'time s':>8s} {'error rad':>10s} {'max|C| m':>10s} "
              f"{'energy':>9s} {'steps':>6s}")
        for label, (formulation, options) in SETTINGS.items():
            system = model.compile(formulation, **options)
            for rtol in tolerances:
                row = {"model": model_name, "label": label, "rtol": rtol, "atol": rtol * 1e-2}
                try:
                    wall, res = run(system, t_end, q0, qd0, rtol, repeat)
                except mb.SimulationError as exc:
                    row.update(time=float("nan"), error=float("nan"), max_violation=float("nan"),
                               energy_error=float("nan"), steps=0, failure=str(exc)[:160])
                    print(f"  {label:26s} {rtol:7.0e}   FAILED: {str(exc)[:90]}")
                    rows.append(row)
                    continue
                energy = res.energy()
                row.update(time=wall, error=float(np.max(np.abs(res.q[-1] - ref.q[-1]))),
                           max_violation=float(np.max(res.constraint_violation())),
                           energy_error=float(np.max(np.abs(energy.total - energy.total[0])) / np.max(energy.kinetic)),
                           steps=int(res.stats.get("steps", 0)), failure="")
                rows.append(row)
                print(f"  {label:26s} {rtol:7.0e} {wall:8.3f} {row['error']:10.1e} {row['max_violation']:10.1e} "
                      f"{row['energy_error']:9.1e} {row['steps']:6d}")
    path = RESULTS / "constraints_work_precision.csv"
    fields = ["model", "label", "rtol", "atol", "time", "error", "max_violation", "energy_error", "steps", "failure"]
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    print(f"\nwrote {path}")
    try:
        from mbcomp.face.plotting import work_precision_plot
    except ImportError:
        work_precision_plot = None
    for model_name in MODELS:
        points = [r for r in rows if r["model"] == model_name]
        png = RESULTS / f"constraints_work_precision_{model_name}.png"
        title = f"{model_name}: error at t_end vs wall time"
        if work_precision_plot is not None:
            work_precision_plot(points, png, title=title)
        else:   # pragma: no cover - older mbcomp
            import matplotlib
            matplotlib.use("Agg")
            import matplotlib.pyplot as plt
            fig, ax = plt.subplots(figsize=(7, 5))
            for label in SETTINGS:
                pts = [(r["error"], r["time"]) for r in points if r["label"] == label and r["error"] > 0]
                if pts:
                    ax.loglog(*zip(*pts), "o-", label=label)
            ax.set_xlabel("error max |q - q_ref| at t_end (rad)")
            ax.set_ylabel("wall time (s)")
            ax.set_title(title)
            ax.legend()
            fig.savefig(png, dpi=120)
        print(f"wrote {png}")
    return rows


if __name__ == "__main__":
    sys.exit(0 if main() else 1)
