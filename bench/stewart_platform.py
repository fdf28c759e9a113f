"""The Stewart platform (``library/stewart_platform.toml``: loops through five ball joints)
in lagrange against dae, both in the compiled loop.

Each run: 2 s from the file's state with the plate turning (0.5, 0, 0.8 rad/s about the
first ball's axes, made consistent by ``assemble``), the default tolerances (rtol 1e-8,
atol 1e-10), output at 201 times.  Rounds are interleaved (lagrange, dae, lagrange, ...):
the ratio of each round is measured in the same conditions; the table gives the medians
of the times and of the per-round ratios, and the largest difference of the coordinates.

Usage: python bench/stewart_platform.py [--rounds 9]
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from mbcomp.files.toml_model import library_models, load


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=9)
    args = parser.parse_args()
    model = load(library_models()["stewart_platform"])
    systems = {f: model.compile(f) for f in ("lagrange", "dae")}
    dae = systems["dae"]
    neutral = dae.topology.state_map.neutral()
    q0 = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(dae.coords)])
    qd0 = np.zeros(dae.nv)
    for name, value in (("leg0.ankle_wx", 0.5), ("leg0.ankle_wz", 0.8)):
        qd0[list(dae.speeds).index(name)] = value
    q0, qd0 = dae.assemble(q0, qd0)
    t_eval = np.linspace(0.0, 2.0, 201)
    times = {f: [] for f in systems}
    ratios, results = [], {}
    for _ in range(args.rounds):
        for f, system in systems.items():
            started = time.perf_counter()
            results[f] = system.simulate(2.0, q0, qd0, t_eval=t_eval)
            times[f].append(time.perf_counter() - started)
        ratios.append(times["lagrange"][-1] / times["dae"][-1])
    for f in systems:
        r = results[f]
        print(f"{f:9s} median {1e3 * statistics.median(times[f]):7.1f} ms  ({r.stats['integrator']}, "
              f"{r.stats['nfev']} evaluations, {r.stats['steps']} steps)")
    print(f"lagrange / dae: median ratio {statistics.median(ratios):.2f} "
          f"(rounds: {', '.join(f'{x:.2f}' for x in ratios)})")
    print(f"largest coordinate difference: {np.max(np.abs(results['lagrange'].q - results['dae'].q)):.2e}")


if __name__ == "__main__":
    main()
