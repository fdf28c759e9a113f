"""Dense contact: n spheres dropped into a box, time stepping against event-driven contacts.

n spheres (radius 0.05 m, 1 kg, free joints) start on a grid, at rest, in a box made of five
ground ``Plane``s (floor and four walls; side grows with n so the layers stay alike), under
gravity; every collision with restitution 0.2 and friction 0.3.  They fall, bounce and settle
into a heap: many contacts close and slide at once.

For each n: processor seconds per simulated second in ``contact_mode="timestepping"`` (step
``dt``), the fitted exponent of that cost against n (``cost ~ n^p``), and the event-driven
mode (default) for the small n, where it finishes in reasonable time.  Writes
bench/results/dense_contact.csv.

Usage: python bench/dense_contact.py [--sizes 10 25 50 100] [--t-end 0.5] [--dt 1e-3] [--events 10]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import write_csv  # noqa: E402

RADIUS = 0.05


def heap(n: int):
    """The model and its initial state: n spheres on a grid 0.2 m above the floor."""
    side = int(np.ceil(np.sqrt(n / 2)))           # two layers or so
    half = 0.5 * side * 2.5 * RADIUS + RADIUS
    m = mb.Model(f"heap{n}", gravity=(0, 0, -9.81))
    balls = []
    for i in range(n):
        ball = m.add(mb.Body(f"s{i}", mass=1.0, inertia=(0.4 * RADIUS ** 2,) * 3, shape=mb.Sphere(RADIUS)))
        m.add(mb.Free(f"j{i}", m.ground, ball))
        balls.append(ball)
    walls = [(m.ground, mb.Plane(normal=(0, 0, 1)))]
    walls += [(m.ground, mb.Plane(normal=s * np.eye(3)[k], origin=-s * half * np.eye(3)[k]))
              for k in range(2) for s in (1.0, -1.0)]
    m.add(mb.Collision("heap", balls, balls, restitution=0.2, friction=0.3))
    m.add(mb.Collision("box", balls, walls, restitution=0.2, friction=0.3))
    ticks = (np.arange(side) - (side - 1) / 2) * 2.5 * RADIUS
    rng = np.random.default_rng(0)
    grid = [(x, y, 0.2 + RADIUS + 2.5 * RADIUS * layer) for layer in range(n) for x in ticks for y in ticks][:n]
    q0 = np.concatenate([np.concatenate((np.array(p) + 0.01 * RADIUS * rng.normal(size=3), [1, 0, 0, 0]))
                         for p in grid])
    return m.compile(), q0, np.zeros(6 * n)


def run(system, q0, qd0, t_end, **options) -> dict:
    started, cpu = time.perf_counter(), time.process_time()
    res = system.simulate(t_end, q0, qd0, **options)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    z = res.q[-1].reshape(-1, 7)[:, 2]
    return {"cpu_s": round(cpu, 3), "wall_s": round(wall, 3), "cpu_per_sim_s": round(cpu / t_end, 3),
            "steps": res.stats.get("steps"), "lowest_centre_m": round(float(z.min()), 6),
            "max_active": res.stats.get("max_active", ""), "unconverged": res.stats.get("unconverged", "")}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 25, 50, 100])
    parser.add_argument("--t-end", type=float, default=0.5)
    parser.add_argument("--dt", type=float, default=1e-3)
    parser.add_argument("--events", type=int, nargs="*", default=[10], help="sizes also run event-driven")
    parser.add_argument("--events-t-end", type=float, default=0.5)
    args = parser.parse_args(argv)
    rows = []
    for n in args.sizes:
        system, q0, qd0 = heap(n)
        system.simulate(2 * args.dt, q0, qd0, contact_mode="timestepping", dt=args.dt)   # (first calls)
        row = {"n": n, "mode": "timestepping", "dt": args.dt, "t_end": args.t_end,
               **run(system, q0, qd0, args.t_end, contact_mode="timestepping", dt=args.dt)}
        rows.append(row)
        print(row, flush=True)
        if n in args.events:
            row = {"n": n, "mode": "events", "dt": "", "t_end": args.events_t_end,
                   **run(system, q0, qd0, args.events_t_end)}
            rows.append(row)
            print(row, flush=True)
    stepped = [r for r in rows if r["mode"] == "timestepping"]
    if len(stepped) > 1:
        ns = np.array([r["n"] for r in stepped], dtype=float)
        cost = np.array([r["cpu_per_sim_s"] for r in stepped])
        print(f"time stepping: cost ~ n^{np.polyfit(np.log(ns), np.log(cost), 1)[0]:.2f}", flush=True)
    write_csv(rows, "dense_contact.csv")


if __name__ == "__main__":
    main()
