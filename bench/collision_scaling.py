"""Colliding spheres: how the cost of a run grows with the number of spheres.

N spheres (radius 0.05 m, 1 kg, free joints) in zero gravity inside a box of six ground
``Plane``s (0.8 m x 0.8 m x 0.8 m, or larger so that the spheres fill the same fraction of it),
every collision elastic (``Collision("gas", balls, balls, restitution=1)`` and the walls),
random initial speeds (seeded), 1 s simulated with the default tolerances.  The broad phase
(a k-d tree over the spheres, ``mbcomp.core.collide.near_pairs``) keeps the narrow phase to the
pairs that may touch, so the cost per step grows with N (the state and the contact rows) and
not with N^2 pair tests; the number of steps grows with N as well (more collisions per second,
and the step limit against tunnelling follows the fastest sphere).

Reports, per N: wall and processor time (the processor time is the fairer number on a
shared machine), steps, impacts, kinetic energy drift; writes
bench/results/collision_scaling.csv.  Usage: python bench/collision_scaling.py [--sizes 10 25 50 100] [--t-end 1]

``--paths``: the compiled loop against scipy's stepping of the same model (the collision
features measured in C, ``codegen/c/collide.c``, against the Python narrow phase): the
library's ``newtons_cradle`` and ``ball_on_box`` in both formulations, and N = 10, 30
spheres dropped under gravity into a box of planes (restitution 0.9; free joints: the
lagrange formulation), simulated time in s, medians of ``--repeats`` runs taken in turn
(the same machine state for both); writes bench/results/collision_paths.csv.  With 30
free bodies an impact factors the 180 x 180 mass matrix in Python (LAPACK): on a loaded
machine run it with ``OPENBLAS_NUM_THREADS=1``, or BLAS threads waiting for cores cost
more than everything else.
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


def spheres_in_a_box(n: int, name: str, gravity: tuple, restitution: float):
    """n spheres (radius RADIUS, 1 kg) on Free joints inside a box of six planes, colliding
    with each other and the walls; and the grid of their start positions (m)."""
    side = int(np.ceil(n ** (1 / 3)))
    half = max(0.4, 0.5 * side * 3 * RADIUS + RADIUS)
    m = mb.Model(name, gravity=gravity)
    balls = []
    for i in range(n):
        ball = m.add(mb.Body(f"s{i}", mass=1.0, inertia=(0.4 * RADIUS ** 2,) * 3, shape=mb.Sphere(RADIUS)))
        m.add(mb.Free(f"j{i}", m.ground, ball))
        balls.append(ball)
    walls = [(m.ground, mb.Plane(normal=s * np.eye(3)[k], origin=-s * half * np.eye(3)[k]))
             for k in range(3) for s in (1.0, -1.0)]
    m.add(mb.Collision("gas", balls, balls, restitution=restitution))
    m.add(mb.Collision("walls", balls, walls, restitution=restitution))
    ticks = (np.arange(side) - (side - 1) / 2) * 3 * RADIUS
    return m, np.array([(x, y, z) for x in ticks for y in ticks for z in ticks])[:n]


def gas(n: int, seed: int = 0):
    """The model and its initial state: n spheres on a grid inside a box of planes."""
    m, grid = spheres_in_a_box(n, f"gas{n}", (0, 0, 0), 1.0)
    rng = np.random.default_rng(seed)
    q0 = np.concatenate([np.concatenate((p, [1, 0, 0, 0])) for p in grid])
    qd0 = np.concatenate([np.concatenate((v, [0, 0, 0])) for v in rng.normal(size=(n, 3))])
    return m, q0, qd0


def run(n: int, t_end: float) -> dict:
    m, q0, qd0 = gas(n)
    system = m.compile()
    system.simulate(1e-3, q0, qd0)   # (imports and first calls out of the timing)
    started, cpu = time.perf_counter(), time.process_time()
    res = system.simulate(t_end, q0, qd0)
    wall, cpu = time.perf_counter() - started, time.process_time() - cpu
    v = res.qd.reshape(len(res.t), n, 6)[:, :, :3]
    kinetic = 0.5 * (v ** 2).sum(axis=(1, 2))
    return {"n": n, "wall_s": round(wall, 3), "cpu_s": round(cpu, 3), "steps": res.stats["steps"],
            "impacts": len(res.events), "cpu_ms_per_step": round(1e3 * cpu / max(res.stats["steps"], 1), 3),
            "energy_drift": float(abs(kinetic[-1] / kinetic[0] - 1))}


def dropped(n: int, seed: int = 0):
    """n spheres on a grid, at rest, dropped under gravity into a box of six planes
    (restitution 0.9 everywhere)."""
    m, grid = spheres_in_a_box(n, f"drop{n}", (0, 0, -9.81), 0.9)
    rng = np.random.default_rng(seed)
    grid = grid + rng.uniform(-0.01, 0.01, (n, 3))
    q0 = np.concatenate([np.concatenate((p, [1, 0, 0, 0])) for p in grid])
    return m, q0, np.zeros(6 * n)


def path_cases():
    """(label, system, q0, qd0, t_end) of the compiled-against-scipy comparison."""
    cases = []
    for name, q0, t_end in (("newtons_cradle", [0.5, 0, 0, 0, 0], 1.5), ("ball_on_box", [1.05], 2.0)):
        for formulation in ("lagrange", "dae"):
            model = mb.load(name)
            cases.append((f"{name} ({formulation})", model.compile(formulation=formulation), q0, None, t_end))
    for n in (10, 30):
        m, q0, qd0 = dropped(n)
        cases.append((f"{n} spheres dropped (lagrange)", m.compile(), q0, qd0, 0.5))
    return cases


def compare_paths(repeats: int, only: str = "") -> list[dict]:
    """Median wall times (s) of the compiled loop and of scipy's stepping, runs in turn (the
    cases whose label contains ``only``)."""
    rows = []
    for label, system, q0, qd0, t_end in path_cases():
        if only not in label:
            continue
        system.simulate(t_end, q0, qd0)                            # (first calls, imports)
        system.simulate(min(t_end, 0.2), q0, qd0, integrator="scipy")
        times = {"compiled": [], "scipy": []}
        for _ in range(repeats):
            for path in times:
                started = time.perf_counter()
                res = system.simulate(t_end, q0, qd0, integrator="scipy" if path == "scipy" else "auto")
                times[path].append(time.perf_counter() - started)
                events = len(res.events)
        assert res.stats["path"].startswith("scipy") and system.integration_path() == "compiled"
        compiled, scipy = float(np.median(times["compiled"])), float(np.median(times["scipy"]))
        rows.append({"case": label, "t_end_s": t_end, "events": events, "compiled_s": round(compiled, 4),
                     "scipy_s": round(scipy, 4), "speedup": round(scipy / compiled, 1)})
        print(rows[-1], flush=True)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 25, 50, 100])
    parser.add_argument("--t-end", type=float, default=1.0)
    parser.add_argument("--paths", action="store_true", help="compiled loop against scipy's stepping")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--only", default="", help="--paths: only the cases whose label contains this")
    args = parser.parse_args(argv)
    if args.paths:
        write_csv(compare_paths(args.repeats, args.only), "collision_paths.csv")
        return
    rows = []
    for n in args.sizes:
        row = run(n, args.t_end)
        rows.append(row)
        print(row, flush=True)
    write_csv(rows, "collision_scaling.csv")


if __name__ == "__main__":
    main()
