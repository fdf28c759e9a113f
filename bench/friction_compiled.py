"""Coulomb friction in the compiled loops against Python stepping of the same law.

The library's friction models, in both formulations: ``sliding_ball`` (launched sliding,
it rolls from t = 2 v0 / (7 mu g) on: one stick event) over 1 s, and ``box_on_slope``
sliding (theta = 0.5 rad > atan(mu)) and sticking (theta = 0.3 rad) over 1 s, at
rtol = 1e-10, atol = 1e-12.  Each setting runs the compiled loop (``integrator="auto"``,
``res.stats["path"] == "compiled"``) and scipy's stepping (``integrator="scipy"``: scipy's
DOP853; before friction ran compiled this was the only path, with the friction solve in
Python; scipy's methods now step the compiled right-hand side, friction solve included,
where the model could run compiled), in turn, ``--rounds`` times; the figure is the median
wall time of ``simulate`` (systems compiled and warmed up first).  Both paths must agree on
the events and the end state (checked).

Usage: python bench/friction_compiled.py [--rounds 7]
Writes bench/results/friction_compiled.csv.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from mbcomp.files.toml_model import library_models, load

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import write_csv  # noqa: E402

CASES = {  # name: (model, parameters, q0, qd0)
    "sliding_ball": ("sliding_ball", {}, [0.1, 0.0, 0.0], [0.0, 2.0, 0.0]),
    "box sliding": ("box_on_slope", {"theta": 0.5, "mu": 0.4}, [0.05, 0.0, 0.0], [0.0, 0.0, 0.0]),
    "box sticking": ("box_on_slope", {"theta": 0.3, "mu": 0.4}, [0.05, 0.0, 0.0], [0.0, 0.0, 0.0]),
}
T_END, RTOL, ATOL = 1.0, 1e-10, 1e-12


def run(system, case, integrator):
    _, parameters, q0, qd0 = CASES[case]
    start = time.perf_counter()
    res = system.simulate(T_END, q0, qd0, parameters=parameters, rtol=RTOL, atol=ATOL, integrator=integrator)
    return time.perf_counter() - start, res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args()
    models = library_models()
    rows = []
    for formulation in ("dae", "lagrange"):
        systems = {name: load(models[name]).compile(formulation) for name in ("sliding_ball", "box_on_slope")}
        for case, (model, *_) in CASES.items():
            system = systems[model]
            times = {"auto": [], "scipy": []}
            results = {}
            for integrator in times:  # warm-up (late libraries load on first use)
                results[integrator] = run(system, case, integrator)[1]
            compiled, python = results["auto"], results["scipy"]
            assert compiled.stats["path"] == "compiled", compiled.stats["path"]
            assert [e.kind for e in compiled.events] == [e.kind for e in python.events]
            events = max((abs(a.time - b.time) for a, b in zip(compiled.events, python.events)), default=0.0)
            state = float(np.abs(compiled.q[-1] - python.q[-1]).max())
            for _ in range(args.rounds):
                for integrator in times:
                    times[integrator].append(run(system, case, integrator)[0])
            t_c, t_p = statistics.median(times["auto"]), statistics.median(times["scipy"])
            rows.append({"formulation": formulation, "case": case, "compiled_s": t_c, "scipy_s": t_p,
                         "speedup": t_p / t_c, "steps_compiled": compiled.stats["steps"],
                         "events": len(compiled.events), "event_time_diff_s": events, "end_q_diff": state})
            print(f"{formulation:9s} {case:13s} compiled {t_c * 1e3:8.2f} ms  scipy {t_p * 1e3:8.2f} ms  "
                  f"x{t_p / t_c:6.1f}  (events {len(compiled.events)}, |dt_event| {events:.1e} s, "
                  f"|dq_end| {state:.1e})")
    print("wrote", write_csv(rows, "friction_compiled.csv"))


if __name__ == "__main__":
    main()
