"""What each 'skip what a scene doesn't need' buys: generated statements and cost per
evaluation of the accelerations, for variants of the N-link chain.

Usage: python bench/skips.py [N]   (default 10).  Writes bench/results/skips.csv.
"""
from __future__ import annotations

import ctypes
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import sympy as sp

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import write_csv  # noqa: E402


def chain(n: int, *, point_masses=False, planar=False, springs=False, length=0.5) -> mb.Model:
    m = mb.Model("chain", gravity=(0, -9.81, 0) if planar else (0, 0, -9.81))
    parent = m.ground
    for i in range(n):
        inertia = None if point_masses else (length ** 2 / 12, length ** 2 / 12, 1e-4)
        body = m.add(mb.Body(f"link{i}", mass=1.0, com=(0, 0, -length / 2), inertia=inertia))
        axis = "z" if planar else ("x" if i % 2 == 0 else "y")
        m.add(mb.Revolute(f"joint{i}", parent, body, axis=axis, parent_point=(0, 0, -length) if i else (0, 0, 0)))
        if springs:
            m.add(mb.TorsionSpring(f"torsion{i}", f"joint{i}", stiffness=2.0, damping=0.01))
            m.add(mb.Spring(f"spring{i}", a=(m.ground, (0.3, 0, 0)), b=(body, (0, 0, -length)), stiffness=5.0,
                            rest_length=0.2))
        parent = body
    return m


def per_eval_us(system, steps: int = 2000, repeat: int = 5) -> float:
    """Cost of one right-hand side inside the compiled RK4 loop (no Python in between)."""
    lib = system._compiled.functions.lib
    rk4 = lib.rk4_run
    rk4.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_double, ctypes.c_void_p, ctypes.c_double, ctypes.c_long,
                    ctypes.c_void_p, ctypes.c_void_p]
    n = system.nq
    y = np.concatenate((np.full(n, 0.3), np.zeros(n)))
    out = np.empty((steps + 1, 2 * n))
    counts = np.zeros(3, dtype=np.int64)
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        rk4(system._p.ctypes.data, None, 0.0, y.ctypes.data, 1e-4, steps, out.ctypes.data, counts.ctypes.data)
        best = min(best, time.perf_counter() - start)
    return 1e6 * best / (4 * steps)


def run(n: int):
    variants = {
        "3D rigid bodies (reference)": dict(),
        "point masses (no rotational terms)": dict(point_masses=True),
        "planar axes (z only)": dict(planar=True),
        "with 2 springs per link": dict(springs=True),
    }
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        os.environ["MBCOMP_CACHE_DIR"] = cache
        for label, options in variants.items():
            system = chain(n, **options).compile()
            program = system._compiled.program
            needed = program.needed(["mass_matrix", "forces"])
            operations = sum(sp.count_ops(expr) for _, expr in needed)
            rows.append({"variant": label, "statements": len(needed), "operations": operations,
                         "per_eval_us": per_eval_us(system)})
    reference = rows[0]
    print(f"N = {n}: cost of one accelerations evaluation in the compiled loop")
    print(f"{'variant':40s} {'statements':>10s} {'operations':>10s} {'ops ratio':>9s} {'us/eval':>9s} {'ratio':>7s}")
    for row in rows:
        row["ops_ratio"] = row["operations"] / reference["operations"]
        row["ratio"] = row["per_eval_us"] / reference["per_eval_us"]
        print(f"{row['variant']:40s} {row['statements']:10d} {row['operations']:10d} {row['ops_ratio']:9.2f} "
              f"{row['per_eval_us']:9.2f} {row['ratio']:7.2f}")
    write_csv(rows, f"skips_N{n}.csv")
    return rows


if __name__ == "__main__":
    run(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
