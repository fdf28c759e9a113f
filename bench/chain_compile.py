"""Compile time (cold and cached) and cost of one accelerations call for N-link chains.

Usage: python bench/chain_compile.py [N ...]   (default 2 5 10 20 50)
Writes bench/results/chain_compile.csv and prints a table.
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import chain_initial_state, pendulum_chain, write_csv  # noqa: E402


def time_call(fn, repeat: int = 5, number: int = 200) -> float:
    """Best-of-``repeat`` mean seconds per call (robust to a noisy shared machine)."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        for _ in range(number):
            fn()
        best = min(best, (time.perf_counter() - start) / number)
    return best


def run(sizes):
    rows = []
    with tempfile.TemporaryDirectory() as cache:
        os.environ["MBCOMP_CACHE_DIR"] = cache
        for n in sizes:
            row = {"N": n}
            for backend in ("c", "python"):
                start = time.perf_counter()
                pendulum_chain(n).compile(backend=backend)
                row[f"cold_{backend}_s"] = time.perf_counter() - start
                start = time.perf_counter()
                cached = pendulum_chain(n).compile(backend=backend)
                row[f"cached_{backend}_s"] = time.perf_counter() - start
                assert cached._compiled.cache_hit
                q, qd = chain_initial_state(n)
                row[f"accelerations_{backend}_us"] = 1e6 * time_call(lambda: cached.accelerations(q, qd))
            rows.append(row)
            print(", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
    write_csv(rows, "chain_compile.csv")
    return rows


if __name__ == "__main__":
    run([int(a) for a in sys.argv[1:]] or [2, 5, 10, 20, 50])
