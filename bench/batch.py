"""Throughput of parameter studies: simulations per second for a Python loop over
System.simulate, for mb.sweep on threads, and for mb.sweep on a local Dask cluster.

Usage: python bench/batch.py [cases]   (default 200 cases of the 5-link chain, 10 s each).
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain  # noqa: E402


def main(count: int = 200) -> None:
    os.environ.setdefault("MBCOMP_CACHE_DIR", tempfile.mkdtemp(prefix="mbcomp-bench-"))
    system = pendulum_chain(5).compile()
    rng = np.random.default_rng(1)
    cases = [{"q0": rng.uniform(-0.5, 0.5, 5), "parameters": {"link0.mass": float(rng.uniform(0.5, 2.0))}}
             for _ in range(count)]
    timings = {}
    start = time.perf_counter()
    serial = [system.simulate(10.0, c["q0"], parameters=c["parameters"]) for c in cases]
    timings["python loop"] = time.perf_counter() - start
    start = time.perf_counter()
    threaded = mb.sweep(system, cases, t_end=10.0)
    timings["mb.sweep (threads)"] = time.perf_counter() - start
    assert all(np.array_equal(a.q, b.q) for a, b in zip(serial, threaded))
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        Client = None
    if Client is not None:
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None) as cluster, Client(cluster) as client:
            mb.sweep(system, cases[:2], client=client, t_end=10.0)  # workers compile (cache hit) once
            start = time.perf_counter()
            remote = mb.sweep(system, cases, client=client, t_end=10.0)
            timings["mb.sweep (Dask, 2 local workers)"] = time.perf_counter() - start
        assert all(np.array_equal(a.q, b.q) for a, b in zip(serial, remote))
    print(f"{count} simulations of the 5-link chain over 10 s (compiled DOP853, rtol 1e-8)")
    base = timings["python loop"]
    for label, seconds in timings.items():
        print(f"  {label:34s} {seconds:7.3f} s  {count / seconds:9.0f} sims/s  speed-up {base / seconds:5.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
