"""Cost of one forward-dynamics evaluation (q, qd -> qdd) of the N-link 3D pendulum chain.

From Python, one call (microseconds, best of several timeit repeats):
  mbcomp System.accelerations(q, qd)                 the public API (argument checks included)
  mbcomp raw compiled call                           system._compiled.functions.accelerations(
                                                     q, qd, p, u, None): thread-local bound buffers
  mbcomp ctypes direct                               the C function through ctypes with raw addresses
                                                     (the floor of any call from Python)
  Pinocchio pin.aba(model, data, q, v, tau)
  MuJoCo mj_forward                                  state already in MjData
  MuJoCo set + mj_forward + qacc                     qpos/qvel written, qacc copied out
Inside an integration loop (per right-hand-side evaluation):
  mbcomp compiled RK4                                simulate(method="RK4", dt=1e-4, 2 s) / nfev (4 per step)
  MuJoCo RK4 mj_step(m, d, nstep)                    wall / (4 * steps), MuJoCo's own C loop
  mbcomp scipy-stepped DOP853, Pinocchio + scipy     time / nfev of a solve_ivp run (rtol = atol = 1e-8,
                                                     2 s): right-hand side plus scipy's stepping

Every number is the best over interleaved rounds (each call and loop once per round), both
as this thread's CPU time (the primary figure: the shared machine is oversubscribed and
wall time there includes waiting for a core) and as wall time (``*_wall_*`` columns).

Usage: python bench/eval_cost.py [N ...] [--rounds 5]   (default 5 10 20 50)
Writes bench/results/eval_cost.csv and prints tables with mbcomp / Pinocchio ratios.
"""
from __future__ import annotations

import csv
import gc
import sys
import time
import timeit
from pathlib import Path

import ctypes

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import chain_initial_state  # noqa: E402
from peers import MbcompChain, available, validate  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"


def per_call_us(fn, target: float = 0.01, repeat: int = 15) -> tuple[float, float]:
    """(CPU, wall) microseconds per call: best of ``repeat`` timeit repeats of ~``target`` s.
    CPU is this thread's time (``time.thread_time``): on a shared, oversubscribed machine it
    leaves out the time the process waits for a core, which wall time cannot."""
    number, _ = timeit.Timer(fn).autorange()
    number = max(1, int(number * target / 0.2))
    cpu = min(timeit.Timer(fn, timer=time.thread_time).repeat(repeat=repeat, number=number)) / number
    wall = min(timeit.Timer(fn).repeat(repeat=repeat, number=number)) / number
    return 1e6 * cpu, 1e6 * wall


def best_run(fn, repeat: int = 5):
    """(best CPU s, best wall s, first result) of ``fn()`` over ``repeat`` runs."""
    best_cpu, best_wall, first = np.inf, np.inf, None
    for _ in range(repeat):
        gc.collect()
        gc.disable()
        try:
            cpu, wall = time.process_time(), time.perf_counter()
            out = fn()
            best_wall = min(best_wall, time.perf_counter() - wall)
            best_cpu = min(best_cpu, time.process_time() - cpu)
        finally:
            gc.enable()
        first = out if first is None else first
    return best_cpu, best_wall, first


def setup(n: int, loop_time: float = 2.0, dt: float = 1e-4):
    """The calls to time for N links: ``(calls, loops)``.  ``calls``: ``{key: fn}`` of one
    evaluation each; ``loops``: ``{key: fn}`` returning the number of right-hand-side
    evaluations of one integration run."""
    rng = np.random.default_rng(1)
    q = rng.uniform(-1, 1, n)
    qd = rng.uniform(-1, 1, n)
    mb = MbcompChain(n)
    system = mb.system
    calls, loops = {}, {}
    calls["mbcomp_accelerations"] = lambda: system.accelerations(q, qd)
    fns = system._compiled.functions
    raw = fns.accelerations
    p, u = fns.bind_parameters(system._p), system._compiled.no_inputs
    out = np.empty(n)
    work = np.empty(n * (n + 1) // 2 + n)
    assert np.allclose(raw(q, qd, p, u, None)[1], system.accelerations(q, qd), rtol=1e-12, atol=1e-12)
    calls["mbcomp_raw"] = lambda: raw(q, qd, p, u, None)
    c_fn = fns._accelerations
    args = tuple(ctypes.c_void_p(a.ctypes.data) for a in (q, qd, system._p, fns._empty)) + (None,) + tuple(
        ctypes.c_void_p(a.ctypes.data) for a in (out, work))
    # The arrays behind the raw pointers must outlive the call: keep them in the closure.
    calls["mbcomp_ctypes"] = lambda keep=(q, qd, out, work): c_fn(*args)

    q0, qd0 = chain_initial_state(n)
    steps = int(round(loop_time / dt))

    def mbcomp_rk4():
        res = system.simulate(loop_time, q0, qd0, method="RK4", dt=dt, integrator="compiled")
        return res.stats["nfev"], res.q[-1]
    loops["mbcomp_rk4_loop"] = mbcomp_rk4
    loops["mbcomp_scipy"] = lambda: system.simulate(loop_time, q0, qd0, rtol=1e-8, atol=1e-8,
                                                    integrator="scipy").stats["nfev"]

    peers = available()
    if peers["pinocchio"]:
        from peers import PinocchioChain
        import pinocchio as pin
        pn = PinocchioChain(n)
        validate(mb, pn, relative=True)
        model, data, tau = pn.model, pn.data, np.zeros(n)
        calls["pinocchio_aba"] = lambda: pin.aba(model, data, q, qd, tau)

        def pin_run():
            data = model.createData()
            zero = np.zeros(n)
            return solve_ivp(lambda t, y: np.concatenate((y[n:], pin.aba(model, data, y[:n], y[n:], zero))),
                             (0, loop_time), np.concatenate((q0, qd0)), method="DOP853", rtol=1e-8, atol=1e-8).nfev
        loops["pinocchio_scipy"] = pin_run
    if peers["mujoco"]:
        from peers import MujocoChain
        import mujoco
        mj = MujocoChain(n)
        validate(mb, mj, relative=True)
        m, d = mj.model, mj.data
        d.qpos[:] = q
        d.qvel[:] = qd
        calls["mujoco_forward"] = lambda: mujoco.mj_forward(m, d)

        def set_forward_read():
            d.qpos[:] = q
            d.qvel[:] = qd
            mujoco.mj_forward(m, d)
            return d.qacc.copy()
        calls["mujoco_set_forward_read"] = set_forward_read
        m.opt.timestep = dt

        def mujoco_run():
            data = mujoco.MjData(m)
            data.qpos[:] = q0
            data.qvel[:] = qd0
            mujoco.mj_step(m, data, nstep=steps)
            return 4 * steps, data.qpos.copy()
        (_, q_mb), (_, q_mj) = mbcomp_rk4(), mujoco_run()
        assert np.max(np.abs(q_mj - q_mb)) < 1e-6, "MuJoCo RK4 and mbcomp RK4 disagree"
        loops["mujoco_rk4_loop"] = mujoco_run
    return calls, loops


def measure(n: int, rounds: int = 5):
    """Best over ``rounds`` interleaved rounds (every call and loop once per round)."""
    calls, loops = setup(n)
    row = {"N": n}
    for _ in range(rounds):
        for key, fn in calls.items():
            cpu, wall = per_call_us(fn, repeat=5)
            row[f"{key}_us"] = min(row.get(f"{key}_us", np.inf), cpu)
            row[f"{key}_wall_us"] = min(row.get(f"{key}_wall_us", np.inf), wall)
        for key, fn in loops.items():
            cpu, wall, out = best_run(fn, repeat=1)
            evals = out[0] if isinstance(out, tuple) else out
            row[f"{key}_us_per_eval"] = min(row.get(f"{key}_us_per_eval", np.inf), 1e6 * cpu / evals)
            row[f"{key}_wall_us_per_eval"] = min(row.get(f"{key}_wall_us_per_eval", np.inf), 1e6 * wall / evals)
    for suffix in ("_us", "_wall_us"):
        if f"pinocchio_aba{suffix}" in row:
            for key in ("accelerations", "raw", "ctypes"):
                row[f"ratio_{key}_over_aba{suffix[:-3]}"] = row[f"mbcomp_{key}{suffix}"] / row[f"pinocchio_aba{suffix}"]
        if f"mujoco_rk4_loop{suffix}_per_eval" in row:
            row[f"ratio_loop_mbcomp_over_mujoco{suffix[:-3]}"] = (row[f"mbcomp_rk4_loop{suffix}_per_eval"]
                                                                  / row[f"mujoco_rk4_loop{suffix}_per_eval"])
    return row


def columns(wall: bool):
    w = "_wall" if wall else ""
    calls = [(f"mbcomp_accelerations{w}_us", "mb accel()"), (f"mbcomp_raw{w}_us", "mb raw"),
             (f"mbcomp_ctypes{w}_us", "mb ctypes"), (f"pinocchio_aba{w}_us", "pin.aba"),
             (f"mujoco_forward{w}_us", "mj_forward"), (f"mujoco_set_forward_read{w}_us", "mj set+fwd+read"),
             (f"ratio_accelerations_over_aba{w}", "accel/aba"), (f"ratio_raw_over_aba{w}", "raw/aba"),
             (f"ratio_ctypes_over_aba{w}", "ctypes/aba")]
    loops = [(f"mbcomp_rk4_loop{w}_us_per_eval", "mb RK4 C loop"), (f"mujoco_rk4_loop{w}_us_per_eval", "MuJoCo nstep"),
             (f"ratio_loop_mbcomp_over_mujoco{w}", "mb/MuJoCo"), (f"mbcomp_scipy{w}_us_per_eval", "mb scipy-stepped"),
             (f"pinocchio_scipy{w}_us_per_eval", "pin+scipy")]
    return calls, loops


def print_table(rows, columns, title):
    print(title)
    head = f"{'N':>4} | " + " | ".join(f"{name:>16}" for _, name in columns)
    print(head)
    print("-" * len(head))
    for row in rows:
        cells = []
        for key, _ in columns:
            value = row.get(key)
            cells.append(f"{'-':>16}" if value is None else f"{value:16.3f}")
        print(f"{row['N']:>4} | " + " | ".join(cells))


def main(argv=None):
    import argparse
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sizes", nargs="*", type=int, default=[5, 10, 20, 50])
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (best of)")
    args = parser.parse_args(argv)
    sizes, rounds = args.sizes, args.rounds
    print(time.strftime("%Y-%m-%d %H:%M"), "| cost of one forward-dynamics evaluation")
    rows = []
    for n in sizes:
        rows.append(measure(n, rounds))
        print(f"  N = {n} done", flush=True)
    for wall in (False, True):
        what = "wall time" if wall else "CPU time"
        calls, loops = columns(wall)
        print_table(rows, calls, f"\nOne call from Python, {what} (us; ratios mbcomp / Pinocchio aba, same run)")
        print_table(rows, loops, f"\nPer right-hand-side evaluation inside an integration loop, {what} (us)")
    RESULTS.mkdir(exist_ok=True)
    keys = list(dict.fromkeys(k for row in rows for k in row))
    with open(RESULTS / "eval_cost.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=keys)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in row.items()})
    return rows


if __name__ == "__main__":
    main()
