"""Batches of runs: 1,000 simulations of the 5-link chain over 10 s from different initial
states, mbcomp's ``mb.sweep`` (compiled loops on a thread pool; the loops release the GIL)
against ``mujoco.rollout`` (MuJoCo's C loop on a thread pool), both on every core.

Initial states: angles and speeds uniform in [-0.5, 0.5] (seeded).  Two comparisons:

1. **At the same accuracy**, error <= 1e-6 rad at 10 s on each of 20 sampled initial states
   (against DOP853 at 1e-13): mbcomp's DOP853 at the loosest tolerance reaching it, MuJoCo's
   RK4 with the fewest steps reaching it (both found on the sample before timing).
2. **At the same fixed RK4 step** (MuJoCo's, from 1.): mbcomp's RK4 against the same rollout;
   the final states agree (same ODE, same method: checked).

Both ask only for the final state (mbcomp: ``t_eval=[t_end]``; rollout returns every step's
state: long runs go in chunks of steps into one reused buffer).  Also timed: the mbcomp runs
on one thread (``threads=1``: the thread pool's speed-up) and, with ``--dask``, on a local
Dask cluster of one worker process per core.

Each setting runs once per round, in turn; the figure is the median wall time over the
rounds (CPU time adds the threads up, so wall time is the figure for a batch).

Usage: python bench/batch.py [--count 1000] [--rounds 3] [--dask]
Writes bench/results/batch.csv.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain, write_csv  # noqa: E402

N, T_END, LEVEL, SAMPLE = 5, 10.0, 1e-6, 20
TOLERANCES = [10.0 ** (-k / 2) for k in range(6, 27)]
STEPS = [500, 700, 1000, 1500, 2000, 2500, 3000, 4000, 5000, 6000, 8000, 10000, 15000, 20000]
CHUNK = 2000  # rollout steps per call


def initial_states(count: int, seed: int = 7):
    rng = np.random.default_rng(seed)
    return rng.uniform(-0.5, 0.5, (count, N)), rng.uniform(-0.5, 0.5, (count, N))


def rollout_finals(model, datas, q0s, qd0s, dt: float) -> np.ndarray:
    """Final positions of one ``mujoco.rollout`` run per row of ``q0s``, ``qd0s`` (RK4, step
    dt, ``len(datas)`` threads)."""
    import mujoco
    from mujoco import rollout
    steps = int(round(T_END / dt))
    model.opt.timestep = dt
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    data = datas[0]
    state = np.empty((len(q0s), nstate))
    for i in range(len(q0s)):
        mujoco.mj_resetData(model, data)
        data.qpos[:], data.qvel[:] = q0s[i], qd0s[i]
        mujoco.mj_getState(model, data, state[i], spec)
    buffer = np.empty((len(q0s), min(CHUNK, steps), nstate))
    done = 0
    while done < steps:
        nstep = min(CHUNK, steps - done)
        out = buffer if nstep == buffer.shape[1] else np.empty((len(q0s), nstep, nstate))
        rollout.rollout(model, datas, state, nstep=nstep, state=out)
        state = out[:, -1].copy()
        done += nstep
    if np.any(np.abs(state[:, 0] - T_END) > 1e-6 * T_END) or not np.all(np.isfinite(state)):
        raise RuntimeError("MuJoCo rollout diverged")
    return state[:, 1:1 + model.nq].copy()


def timed(fn):
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - wall, time.process_time() - cpu, out


def run(count: int = 1000, rounds: int = 3, dask: bool = False, log=print) -> list[dict]:
    """Time every setting ``rounds`` times (interleaved); print and write the table."""
    cores = os.cpu_count() or 1
    log(f"batch: {count} runs of the {N}-link chain over {T_END:g} s, every core ({cores})")
    system = pendulum_chain(N).compile()
    q0s, qd0s = initial_states(count)
    sample = range(min(SAMPLE, count))
    refs = np.array([system.simulate(T_END, q0s[i], qd0s[i], rtol=1e-13, atol=1e-13).q[-1] for i in sample])

    def error(finals):
        return float(np.max(np.abs(np.asarray(finals)[:len(refs)] - refs)))

    tol = next(t for t in TOLERANCES if error(
        [system.simulate(T_END, q0s[i], qd0s[i], rtol=t, atol=t, t_eval=[T_END]).q[-1] for i in sample]) <= LEVEL)
    log(f"  mbcomp DOP853 rtol = atol = {tol:.3g} reaches {LEVEL:g} on the sample")

    def cases(**options):
        return [{"q0": q0s[i], "qd0": qd0s[i], "t_end": T_END, "t_eval": [T_END], "integrator": "compiled", **options}
                for i in range(count)]

    def finals(results):
        return np.array([r.q[-1] for r in results])
    dop = cases(rtol=tol, atol=tol)
    settings = {"mbcomp sweep DOP853": lambda: finals(mb.sweep(system, dop)),
                "mbcomp sweep DOP853, 1 thread": lambda: finals(mb.sweep(system, dop, threads=1))}
    dt = None
    try:
        import mujoco
        from peers import MujocoChain
        model = MujocoChain(N).model
        datas = [mujoco.MjData(model) for _ in range(cores)]
        steps = next(s for s in STEPS if error(rollout_finals(model, datas, q0s[:len(refs)], qd0s[:len(refs)],
                                                              T_END / s)) <= LEVEL)
        dt = T_END / steps
        log(f"  MuJoCo RK4 with {steps} steps (dt = {dt:.3g} s) reaches {LEVEL:g} on the sample")
        rk4 = cases(method="RK4", dt=dt)
        settings["MuJoCo rollout RK4"] = lambda: rollout_finals(model, datas, q0s, qd0s, dt)
        settings["mbcomp sweep RK4"] = lambda: finals(mb.sweep(system, rk4))
        settings["mbcomp sweep RK4, 1 thread"] = lambda: finals(mb.sweep(system, rk4, threads=1))
    except ImportError:
        log("  mujoco is not installed: mbcomp only")
    client = cluster = None
    if dask:
        from distributed import Client, LocalCluster
        cluster = LocalCluster(n_workers=cores, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None)
        client = Client(cluster)
        mb.sweep(system, dop[:cores], client=client)  # each worker compiles (a cache hit) once
        settings["mbcomp sweep DOP853, Dask"] = lambda: finals(mb.sweep(system, dop, client=client))
    walls, cpus, results = {k: [] for k in settings}, {k: [] for k in settings}, {}
    try:
        for r in range(rounds):
            for key, fn in settings.items():
                wall, cpu, out = timed(fn)
                walls[key].append(wall)
                cpus[key].append(cpu)
                results.setdefault(key, out)
            log(f"    round {r + 1}/{rounds} done")
    finally:
        if client is not None:
            client.close()
            cluster.close()
    for key, out in results.items():  # every way of running gives the same numbers
        twin = key.split(",")[0]
        if twin != key and twin in results:
            assert np.array_equal(out, results[twin]), f"{key} differs from {twin}"
    if dt is not None:
        agree = float(np.max(np.abs(results["mbcomp sweep RK4"] - results["MuJoCo rollout RK4"])))
        log(f"  same RK4 step: mbcomp and MuJoCo final states agree to {agree:.1e} rad")
        assert agree < 1e-9, "mbcomp RK4 and MuJoCo RK4 disagree at the same step"
    base = statistics.median(walls["MuJoCo rollout RK4"]) if dt is not None else None
    rows = []
    for key in settings:
        wall, cpu = statistics.median(walls[key]), statistics.median(cpus[key])
        rows.append({"setting": key, "count": count, "threads": cores, "wall_s": wall, "cpu_s": cpu,
                     "runs_per_s": count / wall, "error": error(results[key]),
                     "wall_over_rollout": wall / base if base else float("nan")})
    log(f"\n{'setting':32s} {'wall s':>8s} {'cpu s':>8s} {'runs/s':>8s} {'error':>8s} {'/ rollout':>9s}")
    for row in rows:
        log(f"{row['setting']:32s} {row['wall_s']:8.3f} {row['cpu_s']:8.3f} {row['runs_per_s']:8.0f} "
            f"{row['error']:8.1e} {row['wall_over_rollout']:9.3f}")
    write_csv([{k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()} for row in rows], "batch.csv")
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--count", type=int, default=1000)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--dask", action="store_true", help="also on a local Dask cluster")
    args = parser.parse_args(argv)
    return run(args.count, args.rounds, args.dask)


if __name__ == "__main__":
    main()
