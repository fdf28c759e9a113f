"""Coulomb friction against MuJoCo: work-precision against the closed form, and equal-error times.

Three cases with exact answers (tests/test_friction.py derives them):

- **sliding ball**: a solid ball (1.5 kg, r = 0.1 m, mu = 0.3) launched sliding at
  v0 = 2 m/s without spin: it rolls from t = 2 v0 / (7 mu g) on at 5 v0 / 7.
  Error: max(|x(T) - x_exact(T)|, |x'(T) - 5 v0 / 7|) at T = 0.5 s;
- **box slides**: a box (2 kg, 0.4 m x 0.1 m high) on a slope of 0.5 rad with mu = 0.4
  (tan 0.5 = 0.546 > mu; gravity tilted, the floor flat): it slides with
  a = g (sin - mu cos).  Error: max(|x(T) - a T^2 / 2|, |x'(T) - a T|) at T = 1 s;
- **box sticks**: the same box on a slope of 0.3 rad (tan 0.3 = 0.309 < mu): it stays put.
  Error: max(|x(T)|, |x'(T)|) at T = 1 s (MuJoCo's soft cone lets it creep).

mbcomp: ``library/sliding_ball.toml`` and ``library/box_on_slope.toml`` (the slope angle a
run-time parameter), Coulomb's law with stick/slip events, DOP853 over rtol = 1e-2 .. 1e-12
(atol = rtol / 100); ``sys.integration_path()`` is reported (it names the path the runs took,
Python stepping or the compiled loop).  Compile time is reported apart: a cold compile
(``cache=False``) and a compile served by the cache; the runs are timed on the compiled
system (cache warm, first call out of the timing).

MuJoCo: a sphere / box (free joint) on a plane, ``friction = mu``, elliptic cone, solver
tolerance 1e-12 and 200 iterations, a sweep of fixed steps with five contact settings, the
Pareto front over all of them taken as MuJoCo's best:

- ``RK4 default``: MuJoCo's default soft contact (solref 0.02 1, solimp 0.9 0.95 0.001);
- ``RK4 impratio``: the same with impratio = 100 (friction 100x stiffer than the normal);
- ``RK4 stiff``: the stiffest contact MuJoCo's refsafe allows, solref = (2 dt, 1), with
  solimp 0.99 0.9999 0.001 and impratio 100;
- ``RK4 stiff+noslip``: that, plus 100 noslip iterations (removes slip of sticking contacts);
- ``implicitfast stiff``: the stiff setting under the implicit-in-velocity integrator.

Each run is one ``mj_step(m, d, nstep)`` call (MuJoCo's C loop), from a reset.

Timing: ``bench/timing.py``'s interleaved rounds (every setting of both tools once per round,
medians over the rounds; runs under 50 ms repeated within a round after a warm-up call),
``time.perf_counter``.  Equal-error pairs: for every run on MuJoCo's Pareto front
(fastest time for each error), mbcomp's cheapest run with an error at most MuJoCo's, and
the ratio mbcomp / MuJoCo of their median wall times (below 1: mbcomp faster).

Usage: python bench/friction_vs_mujoco.py [--quick] [--rounds N]   (needs ``pip install mujoco``)
Writes bench/results/friction_vs_mujoco.csv and friction_vs_mujoco_pairs.csv.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import write_csv  # noqa: E402
from timing import Run, fmt, measure  # noqa: E402

G = 9.81
BALL = dict(m=1.5, r=0.1, mu=0.3, v0=2.0, T=0.5)
BOX = dict(m=2.0, a=0.2, b=0.1, c=0.05, mu=0.4, T=1.0)
CASES = {"sliding ball": None, "box slides": 0.5, "box sticks": 0.3}   # slope angle (rad)
ROOT = Path(__file__).resolve().parent


def ball_exact(T: float) -> tuple[float, float]:
    """(x, x') of the sliding ball's centre at T."""
    v0, mu = BALL["v0"], BALL["mu"]
    t_roll = 2 * v0 / (7 * mu * G)
    if T <= t_roll:
        return v0 * T - mu * G * T * T / 2, v0 - mu * G * T
    x_roll = v0 * t_roll - mu * G * t_roll ** 2 / 2
    return x_roll + 5 * v0 / 7 * (T - t_roll), 5 * v0 / 7


def box_exact(theta: float, T: float) -> tuple[float, float]:
    """(x, x') of the box down the slope at T: it slides with a = g (sin - mu cos) when
    tan(theta) > mu, else it stays put."""
    a = max(G * (math.sin(theta) - BOX["mu"] * math.cos(theta)), 0.0)
    return a * T * T / 2, a * T


def exact(case: str) -> tuple[float, float]:
    return ball_exact(BALL["T"]) if case == "sliding ball" else box_exact(CASES[case], BOX["T"])


def horizon(case: str) -> float:
    return BALL["T"] if case == "sliding ball" else BOX["T"]


def error(case: str, x: float, xd: float) -> float:
    """Error of the final state (x, x') against the closed form (m and m/s, max of both)."""
    x_e, v_e = exact(case)
    return max(abs(x - x_e), abs(xd - v_e))


# ----------------------------------------------------------------------------- mbcomp

def mbcomp_systems() -> tuple[dict, dict]:
    """The compiled systems by case, and compile times (s): cold and from the cache."""
    library = ROOT.parent / "library"
    times = {}
    for name in ("sliding_ball", "box_on_slope"):
        started = time.perf_counter()
        mb.load(library / f"{name}.toml").compile(cache=False)
        times[f"{name} cold"] = time.perf_counter() - started
        mb.load(library / f"{name}.toml").compile()            # (fills the cache if empty)
        started = time.perf_counter()
        system = mb.load(library / f"{name}.toml").compile()
        times[f"{name} cached"] = time.perf_counter() - started
        times[name] = system
    ball, box = times.pop("sliding_ball"), times.pop("box_on_slope")
    return {"sliding ball": ball, "box slides": box, "box sticks": box}, times


def mbcomp_run(system, case: str, rtol: float):
    """A function running the case at rtol and returning (x, x') at the end, and the path."""
    T = horizon(case)
    kw = dict(rtol=rtol, atol=rtol / 100, t_eval=[0.0, T])
    if case == "sliding ball":
        def fn():
            res = system.simulate(T, [BALL["r"], 0, 0], [0, BALL["v0"], 0], **kw)
            return res["x"][-1], res["x_d"][-1], res.stats.get("path", ""), len(res.events)
    else:
        params = {"theta": CASES[case]}

        def fn():
            res = system.simulate(T, [BOX["c"], 0, 0], parameters=params, **kw)
            return res["x"][-1], res["x_d"][-1], res.stats.get("path", ""), len(res.events)
    return fn


# ----------------------------------------------------------------------------- MuJoCo

XML = """<mujoco><option timestep="{dt}" integrator="{integrator}" cone="elliptic" impratio="{impratio}"
 noslip_iterations="{noslip}" tolerance="1e-12" noslip_tolerance="1e-12" iterations="200" gravity="{gx} 0 {gz}"/>
<default><geom solref="{solref}" solimp="{solimp}"/></default>
<worldbody><geom type="plane" size="50 50 0.1" friction="{mu} 0 0"/>
<body pos="0 0 {z0}"><freejoint/>{geom}</body>
</worldbody></mujoco>"""

MUJOCO_SETTINGS = {
    "RK4 default": dict(integrator="RK4", impratio=1, noslip=0, solref=None, solimp="0.9 0.95 0.001"),
    "RK4 impratio": dict(integrator="RK4", impratio=100, noslip=0, solref=None, solimp="0.9 0.95 0.001"),
    "RK4 stiff": dict(integrator="RK4", impratio=100, noslip=0, solref=2, solimp="0.99 0.9999 0.001"),
    "RK4 stiff+noslip": dict(integrator="RK4", impratio=100, noslip=100, solref=2, solimp="0.99 0.9999 0.001"),
    "implicitfast stiff": dict(integrator="implicitfast", impratio=100, noslip=0, solref=2,
                               solimp="0.99 0.9999 0.001"),
}


def mujoco_xml(case: str, steps: int, setting: dict) -> str:
    """The MJCF of a case: ``solref`` None is MuJoCo's default (0.02 s, damping ratio 1), a
    number k is a time constant of k steps."""
    dt = horizon(case) / steps
    solref = "0.02 1" if setting["solref"] is None else f"{setting['solref'] * dt!r} 1"
    if case == "sliding ball":
        geom = '<geom type="sphere" size="{r}" mass="{m}" friction="{mu} 0 0"/>'.format(**BALL)
        gx, gz, z0, mu = 0.0, -G, BALL["r"], BALL["mu"]
    else:
        geom = '<geom type="box" size="{a} {b} {c}" mass="{m}" friction="{mu} 0 0"/>'.format(**BOX)
        theta = CASES[case]
        gx, gz, z0, mu = G * math.sin(theta), -G * math.cos(theta), BOX["c"], BOX["mu"]
    return XML.format(dt=repr(dt), integrator=setting["integrator"], impratio=setting["impratio"],
                      noslip=setting["noslip"], solref=solref, solimp=setting["solimp"], gx=gx, gz=gz,
                      mu=mu, z0=z0, geom=geom)


def mujoco_run(case: str, steps: int, setting: dict):
    """A function running the case (one ``mj_step`` call of ``steps`` steps from a reset) and
    returning (x, x') at the end."""
    import mujoco
    model = mujoco.MjModel.from_xml_string(mujoco_xml(case, steps, setting))
    data = mujoco.MjData(model)
    v0 = BALL["v0"] if case == "sliding ball" else 0.0

    def fn():
        mujoco.mj_resetData(model, data)
        data.qvel[0] = v0
        mujoco.mj_step(model, data, nstep=steps)
        return float(data.qpos[0]), float(data.qvel[0]), "MuJoCo C loop", 0
    return fn


# ----------------------------------------------------------------------------- tables

def front(rows: list[dict]) -> list[dict]:
    """The Pareto front of runs: by increasing time, each improving the error."""
    out, best = [], math.inf
    for row in sorted(rows, key=lambda r: r["wall_s"]):
        if math.isfinite(row["error"]) and row["error"] < best:
            out.append(row)
            best = row["error"]
    return out


def pairs(rows: list[dict], case: str) -> list[dict]:
    """Equal-error pairs: each run on MuJoCo's front against mbcomp's cheapest run with an
    error at most MuJoCo's (ratio of wall times mbcomp / MuJoCo)."""
    ours = [r for r in rows if r["case"] == case and r["tool"] == "mbcomp"]
    out = []
    for peer in front([r for r in rows if r["case"] == case and r["tool"] == "MuJoCo"]):
        good = [r for r in ours if r["error"] <= peer["error"]]
        best = min(good, key=lambda r: r["wall_s"]) if good else None
        out.append({"case": case, "mujoco_setting": peer["setting"], "mujoco_error": peer["error"],
                    "mujoco_wall_s": peer["wall_s"],
                    "mbcomp_setting": best["setting"] if best else "",
                    "mbcomp_error": best["error"] if best else math.nan,
                    "mbcomp_wall_s": best["wall_s"] if best else math.nan,
                    "ratio": best["wall_s"] / peer["wall_s"] if best else math.nan,
                    "cpu_ratio": best["cpu_s"] / peer["cpu_s"] if best else math.nan})
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer settings, three rounds")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 5; 3 with --quick)")
    args = parser.parse_args(argv)
    rounds = args.rounds or (3 if args.quick else 5)
    tolerances = (1e-2, 1e-4, 1e-7, 1e-10) if args.quick else (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8, 1e-10, 1e-12)
    steps_list = (100, 1000, 10000) if args.quick else (100, 300, 1000, 3000, 10000, 30000)
    load = os.getloadavg()[0]
    systems, compile_times = mbcomp_systems()
    runs = []
    for case in CASES:
        for rtol in tolerances:
            runs.append(Run("mbcomp", f"rtol={rtol:g}", rtol, mbcomp_run(systems[case], case, rtol), group=case))
    try:
        import mujoco
        version = mujoco.__version__
        for case in CASES:
            for name, setting in MUJOCO_SETTINGS.items():
                for steps in steps_list:
                    runs.append(Run("MuJoCo", f"{name}, steps={steps}", steps, mujoco_run(case, steps, setting),
                                    group=f"{case}|{name}"))
    except ImportError:
        version = None
        print("mujoco is not installed (pip install mujoco): mbcomp only")
    case_of = {id(run): run.group.split("|")[0] for run in runs}
    print(f"{len(runs)} settings, {rounds} interleaved rounds (load average {load:.2f} at the start)", flush=True)
    for run in runs:              # first calls (imports, caches) out of the timing
        run.fn()
    measure(runs, rounds, log=lambda s: print(s, flush=True))
    rows, paths = [], {}
    for run in runs:
        case = case_of[id(run)]
        if run.failed or run.result is None:
            print(f"{case} {run.label} {run.setting} failed: {run.failed}")
            continue
        x, xd, path, events = run.result
        if run.label == "mbcomp":
            paths[case] = path
        rows.append({"case": case, "tool": run.label, "setting": run.setting, "wall_s": run.wall, "cpu_s": run.cpu,
                     "error": error(case, x, xd), "events": events if run.label == "mbcomp" else "",
                     "path": path})
    write_csv(rows, "friction_vs_mujoco.csv")
    pair_rows = [p for case in CASES for p in pairs(rows, case)]
    write_csv(pair_rows, "friction_vs_mujoco_pairs.csv")

    print(f"\nMuJoCo {version}, "
          f"{os.cpu_count()} cores, load average {load:.2f} at the start, {os.getloadavg()[0]:.2f} at the end; "
          f"medians of {rounds} rounds")
    print("compile (s): " + ", ".join(f"{k} {v:.2f}" for k, v in compile_times.items()))
    for case in CASES:
        print(f"\n## {case}: error of the final state against the closed form; mbcomp path: {paths.get(case)}")
        print("| tool | setting | wall (ms) | CPU (ms) | error |\n|---|---|---|---|---|")
        for row in rows:
            if row["case"] == case:
                print(f"| {row['tool']} | {row['setting']} | {fmt(1e3 * row['wall_s'])} | {fmt(1e3 * row['cpu_s'])} "
                      f"| {row['error']:.1e} |")
        print(f"\nequal error ({case}): MuJoCo's front against mbcomp's cheapest run at least as accurate")
        print("| MuJoCo setting | MuJoCo error | MuJoCo (ms) | mbcomp setting | mbcomp error | mbcomp (ms) "
              "| mbcomp / MuJoCo (wall) | (CPU) |")
        print("|---|---|---|---|---|---|---|---|")
        case_pairs = [p for p in pair_rows if p["case"] == case]
        for p in case_pairs:
            print(f"| {p['mujoco_setting']} | {p['mujoco_error']:.1e} | {fmt(1e3 * p['mujoco_wall_s'])} | "
                  f"{p['mbcomp_setting'] or '-'} | {p['mbcomp_error']:.1e} | {fmt(1e3 * p['mbcomp_wall_s'])} | "
                  f"{fmt(p['ratio'], 2)} | {fmt(p['cpu_ratio'], 2)} |")
        best_peer = min((r["error"] for r in rows if r["case"] == case and r["tool"] == "MuJoCo"), default=math.inf)
        beyond = [r for r in rows if r["case"] == case and r["tool"] == "mbcomp" and r["error"] < best_peer]
        if beyond:
            print(f"errors only mbcomp reaches (below MuJoCo's best {best_peer:.1e}): "
                  + ", ".join(f"{r['setting']} {r['error']:.1e} in {fmt(1e3 * r['wall_s'])} ms" for r in beyond))
    print("\nwrote bench/results/friction_vs_mujoco.csv and friction_vs_mujoco_pairs.csv")


if __name__ == "__main__":
    main()
