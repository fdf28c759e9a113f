"""A batch of runs against ``mujoco.rollout``: 1,000 simulations of the 5-link chain over
10 s from different initial states, both tools on every core.

Initial states: angles uniform in [-0.5, 0.5] rad, speeds uniform in [-0.5, 0.5] rad/s
(seeded).  Two comparisons, each timed as medians of interleaved rounds (timing.py, wall
time: CPU time adds the threads up):

1. **At the same accuracy** (error <= 1e-6 rad at 10 s on every one of 20 sampled initial
   states, against mbcomp's DOP853 at 1e-13): mbcomp ``mb.sweep`` with the loosest DOP853
   tolerance that reaches it, against ``mujoco.rollout`` (RK4) with the fewest steps that
   reach it (both found on the sample before timing).
2. **At the same fixed RK4 step** (MuJoCo's step from 1.): mbcomp ``mb.sweep`` with
   ``method="RK4"`` against the same ``rollout``; the final states agree (same ODE, same
   method: checked).

mbcomp runs ``mb.sweep(system, cases)`` (a thread pool over the compiled loop, which releases
the GIL; only the final sample kept, ``t_eval=[t_end]``); MuJoCo runs one ``rollout`` call per
chunk of steps with one ``MjData`` per core.

Usage: python bench/batch_rollout.py [--count 1000] [--rounds 3] [--quick]
Writes bench/results/batch_rollout.csv.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain, write_csv  # noqa: E402
from timing import Run, fmt, measure  # noqa: E402

N, T_END, LEVEL, SAMPLE = 5, 10.0, 1e-6, 20
TOLERANCES = [10.0 ** (-k / 2) for k in range(6, 27)]
STEPS = [500, 700, 1000, 1500, 2000, 2500, 3000, 4000, 5000, 6000, 7000, 8000, 10000, 12000, 15000, 20000]


def initial_states(count: int, seed: int = 7):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.5, 0.5, (count, N)), rng.uniform(-0.5, 0.5, (count, N))


def run(count: int = 1000, rounds: int = 3, quick: bool = False, log=print) -> dict:
    log(f"batch: {count} runs of the {N}-link chain over {T_END} s, all cores ({os.cpu_count()})")
    system = pendulum_chain(N).compile()
    q0s, qd0s = initial_states(count)
    sample = range(min(SAMPLE, count))
    refs = np.array([system.simulate(T_END, q0s[i], qd0s[i], rtol=1e-13, atol=1e-13, integrator="compiled").q[-1]
                     for i in sample])

    def sample_error(final):
        return float(np.max(np.abs(np.asarray(final) - refs)))

    tol = next((t for t in TOLERANCES if sample_error(
        [system.simulate(T_END, q0s[i], qd0s[i], rtol=t, atol=t, integrator="compiled").q[-1] for i in sample])
        <= LEVEL), None)
    log(f"  mbcomp: DOP853 rtol = atol = {tol:.3g} reaches {LEVEL:g} on the sample")
    rows = []
    try:
        import mujoco
        from peers import MujocoChain, mujoco_rollout
    except ImportError:
        log("  mujoco: not installed; nothing to compare with")
        return {"rows": rows}
    mj = MujocoChain(N)
    model = mj.model
    datas = [mujoco.MjData(model) for _ in range(os.cpu_count() or 1)]
    steps = next((s for s in STEPS if sample_error(
        mujoco_rollout(model, datas, T_END, q0s[:len(sample)], qd0s[:len(sample)], dt=T_END / s)) <= LEVEL), None)
    if steps is None:
        raise RuntimeError(f"MuJoCo RK4 does not reach {LEVEL} with up to {STEPS[-1]} steps")
    dt = T_END / steps
    log(f"  MuJoCo: RK4 with {steps} steps (dt = {dt:.3g} s) reaches {LEVEL:g} on the sample")

    def cases(**options):
        return [{"q0": q0s[i], "qd0": qd0s[i], "t_end": T_END, "t_eval": [T_END], **options} for i in range(count)]
    dop_cases = cases(rtol=tol, atol=tol, integrator="compiled")
    rk4_cases = cases(method="RK4", dt=dt, integrator="compiled")

    def finals(results):
        return np.array([r.q[-1] for r in results])
    runs = [Run("mbcomp mb.sweep DOP853", "rtol", tol, lambda: finals(mb.sweep(system, dop_cases))),
            Run("MuJoCo rollout RK4", "steps", steps, lambda: mujoco_rollout(model, datas, T_END, q0s, qd0s, dt=dt)),
            Run("mbcomp mb.sweep RK4", "steps", steps, lambda: finals(mb.sweep(system, rk4_cases)))]
    measure(runs, rounds, burst=0.0, log=log)
    by = {r.label: r for r in runs}
    for r in runs:
        if r.failed:
            raise RuntimeError(f"{r.label} failed: {r.failed}")
    same_step = float(np.max(np.abs(by["mbcomp mb.sweep RK4"].result - by["MuJoCo rollout RK4"].result)))
    log(f"  same RK4 step: mbcomp and MuJoCo final states agree to {same_step:.1e} rad over {count} runs")
    assert same_step < 1e-9, "mbcomp RK4 and MuJoCo RK4 disagree at the same step"
    errors = {r.label: sample_error(r.result[:len(sample)]) for r in runs}
    mj_run = by["MuJoCo rollout RK4"]
    for r in runs:
        rows.append({"label": r.label, "setting": r.setting, "value": r.value, "count": count, "threads": len(datas),
                     "sample_error": errors[r.label], "time": r.wall, "cpu_time": r.cpu,
                     "ratio_to_rollout": r.wall / mj_run.wall, "rounds": len(r.walls)})
    write_csv(rows, "batch_rollout.csv")
    for row in rows:
        log(f"  {row['label']:24s} {fmt(row['time'])} s (cpu {fmt(row['cpu_time'])} s), error {row['sample_error']:.1e}, "
            f"/ rollout {fmt(row['ratio_to_rollout'], 2)}")
    return {"rows": rows}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    return run(100 if args.quick else args.count, 1 if args.quick else args.rounds, args.quick)


if __name__ == "__main__":
    main()
