"""Long stress runs (too long for the test suite): energy drift of the conservative N-link
chain over 1000 s, for the compiled DOP853 at several tolerances and the compiled RK4.

Usage: python bench/stress.py [N ...]   (default 5 10).  Writes bench/results/stress.csv.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import chain_initial_state, pendulum_chain, write_csv  # noqa: E402

T_END = 1000.0


def drift(system, result) -> tuple[float, float]:
    """Largest |E(t) - E(0)| relative to the largest kinetic energy, and the final one."""
    energy = result.energy()
    scale = float(np.max(energy.kinetic))
    change = np.abs(energy.total - energy.total[0]) / scale
    return float(change.max()), float(change[-1])


def run(sizes):
    rows = []
    for n in sizes:
        system = pendulum_chain(n).compile()
        q0, qd0 = chain_initial_state(n)
        t_eval = np.linspace(0.0, T_END, 10001)
        settings = [("DOP853", dict(rtol=tol, atol=tol), f"rtol=atol={tol:g}") for tol in (1e-6, 1e-8, 1e-10, 1e-12)]
        settings += [("RK4", dict(dt=dt), f"dt={dt:g}") for dt in (1e-3, 2.5e-4)]
        for method, options, label in settings:
            start = time.perf_counter()
            result = system.simulate(T_END, q0, qd0, method=method, t_eval=t_eval, **options)
            wall = time.perf_counter() - start
            worst, final = drift(system, result)
            rows.append({"N": n, "method": method, "setting": label, "wall_s": wall, "max_drift": worst,
                         "final_drift": final, "nfev": result.stats["nfev"]})
            print(f"N={n:3d} {method:7s} {label:22s} wall {wall:8.3f} s  max |dE|/KEmax {worst:9.2e}  "
                  f"final {final:9.2e}  evaluations {result.stats['nfev']}", flush=True)
    write_csv(rows, "stress.csv")
    return rows


if __name__ == "__main__":
    run([int(a) for a in sys.argv[1:]] or [5, 10])
