"""Work-precision of the N-link 3D pendulum chain: every tool at every setting, side by side.

The chain (models.py): N = 5, 10, 20 over 10 s, N = 50 over 1 s; the chain is chaotic, so
when the reference does not resolve 1e-10 over 10 s (N = 20) the horizon is shortened to
5, 2 or 1 s, the longest that does.  The error of a run is
max_i |q_i(t_end) - q_ref,i(t_end)| (rad).  Reference: mbcomp's compiled DOP853 at
rtol = atol = 1e-13, cross-checked against the same at 1e-14 and against Pinocchio under
Hairer's Fortran DOP853 at 1e-13; error levels within 3x their largest difference (the
*reference uncertainty*) are not resolved and left out.

Tools and settings (each peer at its fastest: compiled loops where the tool has them):

  mbcomp DOP853 (compiled)            rtol = atol = 1e-3 .. 1e-13 in half decades
  mbcomp RK4 (compiled)               t_end / steps, steps from 50 (geometric)
  MuJoCo RK4 (rollout)                the same steps; mujoco.rollout (MuJoCo's C loop)
  MuJoCo RK4 (mj_step nstep)          the same steps; one mj_step(m, d, nstep) call
  Exudyn DOPRI5 (C++)                 tolerances as mbcomp (ObjectKinematicTree, fast module)
  Exudyn RK67 (C++)                   fixed steps as above
  Pinocchio aba + solve_ivp DOP853    tolerances as mbcomp
  Pinocchio aba + Fortran dop853      scipy.integrate.ode("dop853"), tolerances as mbcomp
  Pinocchio aba + Fortran LSODA       scipy.integrate.odeint, tolerances as mbcomp

Every peer's model is validated first (accelerations agree with mbcomp at random states).
Each run is the whole simulation as a user runs it from Python (per-run setup included,
one-time model building excluded) and returns q(t_end) (no dense output).  Timing: medians
of ``rounds`` interleaved rounds (timing.py), wall and process CPU time; a sweep stops at
the first setting whose error is below the smallest resolved level (or slower than 8 s).  The fastest
time of a tool at a level is interpolated log-log along its Pareto front, never
extrapolated; ratio = fastest mbcomp setting / fastest peer setting, from the same run.

Usage: python bench/work_precision.py [--sizes 5 10 20 50] [--rounds 3] [--quick]
Writes bench/results/work_precision_N{n}.csv (every point), work_precision_levels.csv (the
level tables, wall and CPU) and work_precision.png (one panel per N).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import chain_initial_state, write_csv  # noqa: E402
from peers import MbcompChain, build_peers, validate  # noqa: E402
from timing import Run, fmt, measure, time_at  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
LEVELS = (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
TOLERANCES = [10.0 ** (-k / 2) for k in range(6, 27)]          # 1e-3 .. 1e-13, half decades
STEPS = [50, 70, 100, 150, 200, 300, 500, 700, 1000, 1500, 2000, 3000, 5000, 7000, 10000, 15000, 20000,
         30000, 50000, 70000, 100000, 150000, 200000, 300000]

MB_DOP = "mbcomp DOP853 (compiled)"
MB_RK4 = "mbcomp RK4 (compiled)"
MJ_ROLLOUT = "MuJoCo RK4 (rollout)"
MJ_NSTEP = "MuJoCo RK4 (mj_step nstep)"
EXU_DOPRI5 = "Exudyn DOPRI5 (C++)"
EXU_RK67 = "Exudyn RK67 (C++)"
PIN_IVP = "Pinocchio aba + solve_ivp DOP853"
PIN_DOP853 = "Pinocchio aba + Fortran dop853"
PIN_LSODA = "Pinocchio aba + Fortran LSODA"
MBCOMP_TOOLS = (MB_DOP, MB_RK4)
PEER_TOOLS = (MJ_ROLLOUT, MJ_NSTEP, EXU_DOPRI5, EXU_RK67, PIN_IVP, PIN_DOP853, PIN_LSODA)
SHORT = {MB_DOP: "mb DOP853", MB_RK4: "mb RK4", MJ_ROLLOUT: "MJ rollout", MJ_NSTEP: "MJ nstep",
         EXU_DOPRI5: "Exu DOPRI5", EXU_RK67: "Exu RK67", PIN_IVP: "pin solve_ivp", PIN_DOP853: "pin dop853",
         PIN_LSODA: "pin LSODA"}


def horizons(n: int) -> list[float]:
    """Simulated times (s) to try, longest first: 10 s up to N = 20, 1 s beyond (chaos).
    ``run`` takes the longest whose reference resolves every error level."""
    return [10.0, 5.0, 2.0, 1.0] if n <= 20 else [1.0]


def reference(n: int, mb: MbcompChain, peers: dict, t_end: float, log=print) -> tuple[np.ndarray, float]:
    """q_ref(t_end) and the reference uncertainty (largest difference to the cross-checks)."""
    q0, qd0 = chain_initial_state(n)
    ref = mb.simulate(t_end, q0, qd0, tol=1e-13, integrator="compiled")
    checks = {"mbcomp DOP853 1e-14": mb.simulate(t_end, q0, qd0, tol=1e-14, integrator="compiled")}
    if "pinocchio" in peers:
        checks["Pinocchio + Fortran dop853 1e-13"] = peers["pinocchio"].simulate(t_end, q0, qd0, tol=1e-13,
                                                                                 solver="dop853")
    spread = max(float(np.max(np.abs(value - ref))) for value in checks.values())
    for name, value in checks.items():
        log(f"  reference check: |{name} - mbcomp DOP853 1e-13| = {float(np.max(np.abs(value - ref))):.2e}")
    return ref, spread


def runs_for(n: int, mb: MbcompChain, peers: dict, quick: bool, t_end: float) -> list[Run]:
    """Every (tool, setting) of the sweep, coarse to fine within each tool."""
    q0, qd0 = chain_initial_state(n)
    tolerances = TOLERANCES[::2] if quick else TOLERANCES
    steps_list = STEPS[::2] if quick else STEPS
    runs: list[Run] = []

    def add_tol(label, fn):
        runs.extend(Run(label, "tol", tol, (lambda tol=tol: fn(tol)), group=label) for tol in tolerances)

    def add_steps(label, fn):
        runs.extend(Run(label, "steps", steps, (lambda dt=t_end / steps: fn(dt)), group=label)
                    for steps in steps_list)

    add_tol(MB_DOP, lambda tol: mb.simulate(t_end, q0, qd0, tol=tol, integrator="compiled"))
    add_steps(MB_RK4, lambda dt: mb.simulate(t_end, q0, qd0, method="RK4", dt=dt, integrator="compiled"))
    if "mujoco" in peers:
        mj = peers["mujoco"]
        add_steps(MJ_ROLLOUT, lambda dt: mj.simulate(t_end, q0, qd0, dt=dt, loop="rollout"))
        add_steps(MJ_NSTEP, lambda dt: mj.simulate(t_end, q0, qd0, dt=dt, loop="nstep"))
    if "exudyn" in peers:
        ex = peers["exudyn"]
        ex.prepare(q0, qd0)
        add_tol(EXU_DOPRI5, lambda tol: ex.simulate(t_end, q0, qd0, solver="DOPRI5", tol=tol))
        add_steps(EXU_RK67, lambda dt: ex.simulate(t_end, q0, qd0, solver="RK67", steps=round(t_end / dt)))
    if "pinocchio" in peers:
        pn = peers["pinocchio"]
        for label, solver in ((PIN_IVP, "solve_ivp"), (PIN_DOP853, "dop853"), (PIN_LSODA, "lsoda")):
            add_tol(label, lambda tol, solver=solver: pn.simulate(t_end, q0, qd0, tol=tol, solver=solver))
    return runs


def level_table(n: int, runs: list[Run], levels, clock: str = "wall") -> list[dict]:
    """Per level: fastest time of every tool, the fastest mbcomp and peer, and their ratio."""
    labels = list(dict.fromkeys(r.label for r in runs))
    table = []
    for level in levels:
        entry = {"N": n, "clock": clock, "level": level}
        for label in labels:
            entry[label] = time_at([(r.error, getattr(r, clock)) for r in runs if r.label == label], level)
        mb_best = min(((entry[l], l) for l in MBCOMP_TOOLS if math.isfinite(entry.get(l, math.nan))), default=None)
        peer_best = min(((entry[l], l) for l in PEER_TOOLS if math.isfinite(entry.get(l, math.nan))), default=None)
        entry["mbcomp_fastest"] = mb_best[1] if mb_best else ""
        entry["fastest_peer"] = peer_best[1] if peer_best else ""
        entry["mbcomp_time"] = mb_best[0] if mb_best else math.nan
        entry["peer_time"] = peer_best[0] if peer_best else math.nan
        entry["ratio"] = mb_best[0] / peer_best[0] if mb_best and peer_best else math.nan
        table.append(entry)
    return table


def run(n: int, rounds: int = 3, quick: bool = False, log=print) -> dict:
    """The whole sweep for N links: validation, reference, timing, level tables, CSV."""
    log(f"work-precision N = {n}")
    mb = MbcompChain(n)
    peers = build_peers(n, sympy=False, log=log)
    for name, peer in peers.items():
        worst = validate(mb, peer, relative=n > 20)
        log(f"  {name}: accelerations agree with mbcomp to {worst:.1e} rad/s^2")
    for t_end in horizons(n):
        ref, spread = reference(n, mb, peers, t_end, log=log)
        if 3 * spread < min(LEVELS):
            break
        log(f"  t_end = {t_end} s: the reference does not resolve {min(LEVELS):g} (chaos); trying shorter")
    log(f"  horizon t_end = {t_end} s")
    levels = [level for level in LEVELS if level > 3 * spread]
    if len(levels) < len(LEVELS):
        log(f"  levels below {3 * spread:.1e} are not resolved by the reference: left out")
    runs = runs_for(n, mb, peers, quick, t_end) if levels else []

    def check(r: Run) -> float:
        error = float(np.max(np.abs(np.asarray(r.result) - ref)))
        return error if math.isfinite(error) else math.inf

    measure(runs, rounds, check=check, stop_error=min(levels) if levels else 0.0,
            max_run=2.0 if quick else 8.0, log=log)
    rows = [{"N": n, "t_end": t_end, "label": r.label, "setting": r.setting, "value": r.value,
             "error": r.error if not r.failed else math.inf, "time": r.wall, "cpu_time": r.cpu,
             "rounds": len(r.walls), "failed": r.failed} for r in runs if not r.skipped]
    table = level_table(n, runs, levels) + level_table(n, runs, levels, "cpu")
    for entry in table:
        entry["reference_uncertainty"] = spread
    for entry in table[:len(levels)]:
        log(f"  error <= {entry['level']:.0e}: mbcomp {fmt(entry['mbcomp_time'] * 1e3)} ms "
            f"({SHORT.get(entry['mbcomp_fastest'], '-')}), fastest peer {fmt(entry['peer_time'] * 1e3)} ms "
            f"({SHORT.get(entry['fastest_peer'], '-')}), ratio {fmt(entry['ratio'], 2)}")
    if rows:
        write_csv(rows, f"work_precision_N{n}.csv")
    return {"N": n, "t_end": t_end, "rows": rows, "table": table, "uncertainty": spread, "peers": sorted(peers)}


def plot(results: list[dict], path: Path) -> None:
    """One log-log panel per N: wall time against error, every tool."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    count = len(results)
    cols = min(2, count)
    rows_ = -(-count // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(6.5 * cols, 4.8 * rows_), squeeze=False)
    styles = {MB_DOP: ("C3", "o", "-"), MB_RK4: ("C1", "s", "-"), MJ_ROLLOUT: ("C0", "^", "--"),
              MJ_NSTEP: ("C9", "v", ":"), EXU_DOPRI5: ("C2", "D", "--"), EXU_RK67: ("C8", "d", ":"),
              PIN_IVP: ("C4", "x", "--"), PIN_DOP853: ("C5", "+", "--"), PIN_LSODA: ("C6", "*", ":")}
    for ax, res in zip(axes.flat, results):
        for label in dict.fromkeys(r["label"] for r in res["rows"]):
            pts = sorted((r["error"], r["time"]) for r in res["rows"] if r["label"] == label
                         and math.isfinite(r["error"]) and math.isfinite(r["time"]) and r["error"] > 0)
            if pts:
                color, marker, line = styles.get(label, (None, "o", "-"))
                ax.loglog(*zip(*pts), marker=marker, linestyle=line, color=color, label=label,
                          linewidth=2.2 if label in MBCOMP_TOOLS else 1.2, markersize=4)
        ax.axvspan(1e-10, 1e-4, color="0.92", zorder=0)
        ax.set_title(f"N = {res['N']}, {res['t_end']:g} s")
        ax.set_xlabel("error max |q - q_ref| (rad)")
        ax.set_ylabel("wall time per run (s, median)")
        ax.grid(True, which="both", alpha=0.3)
    for ax in list(axes.flat)[count:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7, loc="upper right")
    fig.suptitle("N-link 3D pendulum chain: work-precision\n(lower left is better; shaded: the error levels compared)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[5, 10, 20, 50])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="every other setting, one round")
    args = parser.parse_args(argv)
    rounds = 1 if args.quick else args.rounds
    results = [run(n, rounds, args.quick) for n in args.sizes]
    write_csv([e for res in results for e in res["table"]], "work_precision_levels.csv")
    plot(results, RESULTS / "work_precision.png")
    return results


if __name__ == "__main__":
    main()
