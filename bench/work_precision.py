"""Work-precision benchmark of the speed issue: the N-link 3D pendulum chain, 10 s.

For every tool and setting: wall time of the whole 10 s simulation from Python (best of
>= 3 runs, taken in interleaved rounds over all tools, see ``measure``; each run includes
the per-run setup a user pays, e.g. MjData, solve_ivp's set-up, mbcomp's argument checks
and output arrays; one-time model compilation / derivation is excluded) and the error max_i |q_i(10 s) - q_ref,i(10 s)| (rad).

Reference: mbcomp's compiled DOP853 at rtol = atol = 1e-13, cross-checked against DOP853
at 1e-14 and 1e-12 and against scipy's DOP853 on the Pinocchio model at 1e-13 and 1e-12;
their largest difference is printed as the reference uncertainty.

Tools (all optional peers skipped when not installed, see peers.py):
  mbcomp DOP853 compiled  rtol = atol in 1e-4 .. 1e-12 (half decades)
  mbcomp RK4 compiled     dt = 10 s / steps
  mbcomp DOP853 scipy     integrator="scipy" (scipy's stepping, mbcomp right-hand side)
  MuJoCo RK4              dt = 10 s / steps, mj_step in a Python loop (and, for reference,
                          one mj_step(m, d, nstep) call: MuJoCo's own C loop)
  Pinocchio + scipy       pin.aba as right-hand side of solve_ivp DOP853
  sympy + scipy           Kane's equations, lambdify(cse=True), solve_ivp DOP853 (N = 5;
                          N = 10 with --sympy-n10, ~100 s derivation)

Usage: python bench/work_precision.py [--sizes 5 10] [--sympy-n10] [--quick] [--rounds 5] [--report]
Writes bench/results/work_precision_N{n}.csv (every point: wall and process CPU time),
work_precision_levels_N{n}.csv (the tables below) and work_precision_N{n}.png (wall time),
and prints, for error levels 1e-4 .. 1e-10, the fastest time of each tool reaching that
level (log-log interpolation along the tool's Pareto front, see ``time_at``) and
mbcomp_fastest / fastest_peer, by wall time and again by CPU time (on the oversubscribed
shared machine, wall time includes waiting for a core; CPU time does not).
"""
from __future__ import annotations

import argparse
import csv
import gc
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import chain_initial_state  # noqa: E402
from peers import MbcompChain, PinocchioChain, build_peers, validate  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
T_END = 10.0
LEVELS = (1e-4, 1e-6, 1e-8, 1e-10)
TOLERANCES = [10.0 ** (-k / 2) for k in range(8, 25)]          # 1e-4 .. 1e-12, half decades
STEPS = [1000, 1500, 2000, 3000, 4000, 6000, 8000, 10000, 15000, 20000, 30000, 40000, 60000, 100000]

MB_DOP = "mbcomp DOP853 (compiled)"
MB_RK4 = "mbcomp RK4 (compiled)"
MB_SCIPY = "mbcomp DOP853 (scipy-stepped)"
MJ_LOOP = "MuJoCo RK4 (mj_step loop)"
MJ_NSTEP = "MuJoCo RK4 (mj_step nstep)"
PIN = "Pinocchio aba + scipy DOP853"
SYMPY = "sympy Kane + scipy DOP853"
MBCOMP_TOOLS = (MB_DOP, MB_RK4, MB_SCIPY)
#: The peers of the issue's comparison (what a user runs from Python).  MuJoCo's own C
#: loop (nstep) is reported next to it but not counted as "the fastest peer".
PEER_TOOLS = (MJ_LOOP, PIN, SYMPY)


def timed(fn):
    """(wall s, process CPU s, result) of one call, garbage collection off (as timeit)."""
    gc.collect()
    gc.disable()
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        out = fn()
        return time.perf_counter() - wall, time.process_time() - cpu, out
    finally:
        gc.enable()


def measure(runs, rounds: int = 3, burst: float = 0.05, log=print):
    """Best wall (and CPU) time of each run over ``rounds`` interleaved rounds (every setting
    of every tool once per round, so that a noisy spell of the shared machine hits all tools
    alike); within a round a run shorter than ``burst`` seconds is repeated (at most 5
    times).  Returns ``[(wall, cpu, first result or exception, count)]``."""
    best = [[math.inf, math.inf, None, 0] for _ in runs]
    for r in range(rounds):
        for i, (_, _, _, fn) in enumerate(runs):
            if isinstance(best[i][2], Exception):
                continue
            spent = 0.0
            for _ in range(5):
                try:
                    wall, cpu, out = timed(fn)
                except Exception as exc:  # a diverging fixed step: record it, keep going
                    best[i][2] = exc
                    break
                if best[i][2] is None:
                    best[i][2] = out
                best[i][0], best[i][1] = min(best[i][0], wall), min(best[i][1], cpu)
                best[i][3] += 1
                spent += wall
                if spent > burst:
                    break
        log(f"  round {r + 1}/{rounds} done")
    return best


def reference(n: int, mb: MbcompChain, log=print):
    """The reference q(10 s) and its uncertainty (largest difference to the cross-checks)."""
    q0, qd0 = chain_initial_state(n)
    ref = mb.simulate(T_END, q0, qd0, tol=1e-13, integrator="compiled")
    checks = {"mbcomp DOP853 1e-14": mb.simulate(T_END, q0, qd0, tol=1e-14, integrator="compiled"),
              "mbcomp DOP853 1e-12": mb.simulate(T_END, q0, qd0, tol=1e-12, integrator="compiled")}
    try:
        pin = PinocchioChain(n)
        checks["Pinocchio+scipy DOP853 1e-13"] = pin.simulate(T_END, q0, qd0, tol=1e-13)
        checks["Pinocchio+scipy DOP853 1e-12"] = pin.simulate(T_END, q0, qd0, tol=1e-12)
    except ImportError:
        checks["mbcomp scipy-stepped DOP853 1e-13"] = mb.simulate(T_END, q0, qd0, tol=1e-13, integrator="scipy")
    spread = 0.0
    for name, value in checks.items():
        diff = float(np.max(np.abs(value - ref)))
        spread = max(spread, diff)
        log(f"  reference check: |{name} - mbcomp DOP853 1e-13| = {diff:.2e}")
    assert spread < min(LEVELS), f"references disagree by {spread:.3g}: the error levels cannot be resolved"
    return ref, spread


def sweep(n: int, mb: MbcompChain, peers: dict, ref: np.ndarray, quick: bool = False, rounds: int = 3,
          log=print):
    q0, qd0 = chain_initial_state(n)
    tolerances = TOLERANCES[::4] if quick else TOLERANCES
    steps_list = STEPS[::3] if quick else STEPS
    runs = []  # (label, setting name, setting value, function)
    for tol in tolerances:
        runs.append((MB_DOP, "tol", tol, lambda tol=tol: mb.simulate(T_END, q0, qd0, tol=tol, integrator="compiled")))
    for steps in steps_list:
        dt = T_END / steps
        runs.append((MB_RK4, "dt", dt, lambda dt=dt: mb.simulate(T_END, q0, qd0, method="RK4", dt=dt,
                                                                   integrator="compiled")))
    for tol in tolerances:
        runs.append((MB_SCIPY, "tol", tol, lambda tol=tol: mb.simulate(T_END, q0, qd0, tol=tol, integrator="scipy")))
    if "mujoco" in peers:
        mj = peers["mujoco"]
        for steps in steps_list:
            dt = T_END / steps
            runs.append((MJ_LOOP, "dt", dt, lambda dt=dt: mj.simulate(T_END, q0, qd0, dt=dt, loop="python")))
        for steps in steps_list:
            dt = T_END / steps
            runs.append((MJ_NSTEP, "dt", dt, lambda dt=dt: mj.simulate(T_END, q0, qd0, dt=dt, loop="nstep")))
    for name, label in (("pinocchio", PIN), ("sympy", SYMPY)):
        if name in peers:
            model = peers[name]
            for tol in tolerances:
                runs.append((label, "tol", tol, lambda tol=tol, model=model: model.simulate(T_END, q0, qd0, tol=tol)))
    rows = []
    for (label, setting, value, _), (wall, cpu, q_end, count) in zip(runs, measure(runs, rounds, log=log)):
        if isinstance(q_end, Exception):
            wall = cpu = math.nan
            error = math.inf
            log(f"  {label} {setting}={value:.3g}: failed ({type(q_end).__name__}: {str(q_end)[:80]})")
        else:
            error = float(np.max(np.abs(q_end - ref)))
            error = error if np.isfinite(error) else math.inf
        rows.append({"N": n, "label": label, "setting": setting, "value": value, "error": error, "time": wall,
                     "cpu_time": cpu, "runs": count})
        log(f"  {label:32s} {setting}={value:<10.3g} error={error:<10.3g} time={wall * 1e3:9.3f} ms "
            f"(cpu {cpu * 1e3:9.3f} ms, {count} runs)")
    return rows


def time_at(points, level: float) -> float:
    """Time a tool needs for error <= ``level``: log-log interpolation along its Pareto
    front (fastest time for each error); ``nan`` when no setting reached the level; no
    extrapolation (when every point is below the level, its cheapest one)."""
    pts = sorted((t, e) for e, t in points if np.isfinite(e) and np.isfinite(t) and e > 0)
    front, best_error = [], math.inf
    for t, e in pts:                      # by increasing time: keep points improving the error
        if e < best_error:
            front.append((t, e))
            best_error = e
    if not front or best_error > level:
        return math.nan
    if front[0][1] <= level:
        return front[0][0]
    for (t0, e0), (t1, e1) in zip(front, front[1:]):
        if e0 > level >= e1:
            s = (math.log(level) - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(t0) + s * (math.log(t1) - math.log(t0)))
    return math.nan


def level_table(rows, labels, key: str = "time"):
    """``[{level, label: time, ..., mbcomp_fastest, fastest_peer, ratio, ...}]`` from the
    rows' ``key`` ("time": wall, "cpu_time": process CPU time)."""
    table = []
    for level in LEVELS:
        entry = {"level": level}
        for label in labels:
            entry[label] = time_at([(r["error"], r[key]) for r in rows if r["label"] == label], level)
        mb_best = [(entry[l], l) for l in MBCOMP_TOOLS if l in entry and np.isfinite(entry[l])]
        peer_best = [(entry[l], l) for l in PEER_TOOLS if l in entry and np.isfinite(entry[l])]
        entry["mbcomp_fastest"] = min(mb_best)[1] if mb_best else ""
        entry["fastest_peer"] = min(peer_best)[1] if peer_best else ""
        entry["ratio"] = min(mb_best)[0] / min(peer_best)[0] if mb_best and peer_best else math.nan
        nstep = entry.get(MJ_NSTEP, math.nan)
        entry["ratio_vs_mujoco_nstep"] = min(mb_best)[0] / nstep if mb_best and np.isfinite(nstep) else math.nan
        table.append(entry)
    return table


SHORT = {MB_DOP: "mb DOP853 C", MB_RK4: "mb RK4 C", MB_SCIPY: "mb DOP853 scipy", MJ_LOOP: "MuJoCo loop",
         MJ_NSTEP: "MuJoCo nstep", PIN: "Pinocchio", SYMPY: "sympy"}


def print_table(n, table, labels, spread, what="wall time"):
    print(f"\nN = {n}: fastest {what} (ms) for 10 s with max |q - q_ref| <= level "
          f"(reference uncertainty {spread:.1e} rad)")
    head = f"{'level':>7} | " + " | ".join(f"{SHORT.get(l, l):>15}" for l in labels)
    head += f" | {'mbcomp/peer':>11} | {'mb/MJ nstep':>11} | fastest peer"
    print(head)
    print("-" * len(head))
    for entry in table:
        cells = " | ".join(f"{entry[l] * 1e3:15.3f}" if np.isfinite(entry[l]) else f"{'-':>15}" for l in labels)
        ratio = f"{entry['ratio']:11.3f}" if np.isfinite(entry["ratio"]) else f"{'-':>11}"
        ratio2 = (f"{entry['ratio_vs_mujoco_nstep']:11.3f}" if np.isfinite(entry["ratio_vs_mujoco_nstep"])
                  else f"{'-':>11}")
        print(f"{entry['level']:7.0e} | {cells} | {ratio} | {ratio2} | {SHORT.get(entry['fastest_peer'], '-')}")


def plot(rows, path, title):
    try:
        from mbcomp.plotting import work_precision_plot
    except ImportError:
        work_precision_plot = None
    if work_precision_plot is not None:
        work_precision_plot(rows, path, title)
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 5))
    for label in dict.fromkeys(r["label"] for r in rows):
        pts = sorted((r["error"], r["time"]) for r in rows if r["label"] == label
                     and np.isfinite(r["error"]) and np.isfinite(r["time"]) and r["error"] > 0)
        if pts:
            ax.loglog(*zip(*pts), "o-", label=label)
    ax.set_xlabel("error at 10 s (rad)")
    ax.set_ylabel("wall time (s)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def write_csv(path, rows):
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})


def run(n: int, sympy_n10: bool = False, quick: bool = False, rounds: int = 3):
    print(f"N = {n}")
    mb = MbcompChain(n)
    peers = build_peers(n, sympy_n10=sympy_n10)
    for name, peer in peers.items():
        worst = validate(mb, peer)
        print(f"  {name}: accelerations agree with mbcomp to {worst:.1e} rad/s^2")
    q0, qd0 = chain_initial_state(n)
    mb.simulate(T_END, q0, qd0, tol=1e-6, integrator="scipy")   # first-call imports, not timed
    ref, spread = reference(n, mb)
    rows = sweep(n, mb, peers, ref, quick=quick, rounds=rounds)
    labels = list(dict.fromkeys(r["label"] for r in rows))
    table = level_table(rows, labels)
    print_table(n, table, labels, spread)
    cpu_table = level_table(rows, labels, "cpu_time")
    print_table(n, cpu_table, labels, spread, "process CPU time")
    RESULTS.mkdir(exist_ok=True)
    write_csv(RESULTS / f"work_precision_N{n}.csv", rows)
    write_csv(RESULTS / f"work_precision_levels_N{n}.csv",
              [{"N": n, "clock": clock, "level": e["level"], **{SHORT.get(l, l): e[l] for l in labels},
                "mbcomp_fastest": SHORT.get(e["mbcomp_fastest"], ""), "fastest_peer": SHORT.get(e["fastest_peer"], ""),
                "ratio_mbcomp_over_peer": e["ratio"], "ratio_mbcomp_over_mujoco_nstep": e["ratio_vs_mujoco_nstep"],
                "reference_uncertainty": spread}
               for clock, tab in (("wall", table), ("cpu", cpu_table)) for e in tab])
    plot(rows, RESULTS / f"work_precision_N{n}.png",
         f"{n}-link 3D pendulum chain, 10 s (best of >= 3 runs; lower left is better)")
    return rows, table


def report(n: int):
    """Print the tables again from bench/results/work_precision_N{n}.csv (no new timing)."""
    with open(RESULTS / f"work_precision_N{n}.csv", newline="") as fh:
        rows = [{**r, "error": float(r["error"]), "time": float(r["time"]), "cpu_time": float(r["cpu_time"])}
                for r in csv.DictReader(fh)]
    with open(RESULTS / f"work_precision_levels_N{n}.csv", newline="") as fh:
        spread = float(next(csv.DictReader(fh))["reference_uncertainty"])
    labels = list(dict.fromkeys(r["label"] for r in rows))
    print_table(n, level_table(rows, labels), labels, spread)
    print_table(n, level_table(rows, labels, "cpu_time"), labels, spread, "process CPU time")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", nargs="*", type=int, default=[5, 10])
    parser.add_argument("--sympy-n10", action="store_true", help="also derive and run sympy for N = 10 (~100 s)")
    parser.add_argument("--quick", action="store_true", help="a few settings only (a smoke test)")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved timing rounds (best of; >= 3)")
    parser.add_argument("--report", action="store_true", help="print the tables from the saved CSVs, run nothing")
    args = parser.parse_args(argv)
    if args.report:
        for n in args.sizes:
            report(n)
        return
    print(time.strftime("%Y-%m-%d %H:%M"), "| mbcomp work-precision benchmark")
    for n in args.sizes:
        run(n, sympy_n10=args.sympy_n10, quick=args.quick, rounds=args.rounds)


if __name__ == "__main__":
    main()
