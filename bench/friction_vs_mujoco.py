"""Coulomb friction against MuJoCo: error of the final state against the closed form, and time.

Two cases with exact answers (tests/test_friction.py derives them):

- a solid ball (1.5 kg, r = 0.1 m, mu = 0.3) launched sliding at v0 = 2 m/s without spin:
  it rolls from t = 2 v0 / (7 mu g) on at 5 v0 / 7.  Error: |x'(T) - 5 v0 / 7| and
  |x(T) - x_exact(T)| at T = 0.5 s;
- a box (2 kg) on a slope of 0.5 rad with mu = 0.4 (gravity tilted, the floor flat): it
  slides with a = g (sin - mu cos).  Error: |x(T) - a T^2 / 2| at T = 1 s.

mbcomp: ``library/sliding_ball.toml`` and ``library/box_on_slope.toml`` (Coulomb's law with
stick/slip events, scipy's DOP853 in Python), rtol = 1e-4 .. 1e-10 (atol = rtol / 100).
MuJoCo: a sphere / box on a plane with ``friction = mu``, elliptic cone, its default soft
contact, RK4 with a fixed step; a sweep of steps.  MuJoCo's friction is a regularised
(soft) cone: its error floor is the contact's softness, not the step.

Usage: python bench/friction_vs_mujoco.py [--quick]   (needs ``pip install mujoco``)
Writes bench/results/friction_vs_mujoco.csv.
"""
from __future__ import annotations

import csv
import math
import sys
import time
from pathlib import Path

import numpy as np

import mbcomp as mb

G = 9.81
BALL = dict(m=1.5, r=0.1, mu=0.3, v0=2.0, T=0.5)
BOX = dict(m=2.0, a=0.2, b=0.1, c=0.05, mu=0.4, theta=0.5, T=1.0)
ROOT = Path(__file__).resolve().parent


def ball_exact(T: float) -> tuple[float, float]:
    """(x, x') of the sliding ball's centre at T."""
    v0, mu = BALL["v0"], BALL["mu"]
    t_roll = 2 * v0 / (7 * mu * G)
    if T <= t_roll:
        return v0 * T - mu * G * T * T / 2, v0 - mu * G * T
    x_roll = v0 * t_roll - mu * G * t_roll ** 2 / 2
    return x_roll + 5 * v0 / 7 * (T - t_roll), 5 * v0 / 7


def box_exact(T: float) -> float:
    a = G * (math.sin(BOX["theta"]) - BOX["mu"] * math.cos(BOX["theta"]))
    return a * T * T / 2


def best_time(fn, rounds: int) -> tuple[float, object]:
    best, out = math.inf, None
    for _ in range(rounds):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def mbcomp_runs(rounds: int, tolerances) -> list[dict]:
    rows = []
    ball = mb.load(ROOT.parent / "library" / "sliding_ball.toml").compile()
    box = mb.load(ROOT.parent / "library" / "box_on_slope.toml").compile()
    x_ball, v_ball = ball_exact(BALL["T"])
    x_box = box_exact(BOX["T"])
    for rtol in tolerances:
        kw = dict(rtol=rtol, atol=rtol / 100, t_eval=[0.0, BALL["T"]])
        wall, res = best_time(lambda: ball.simulate(BALL["T"], [BALL["r"], 0, 0], [0, BALL["v0"], 0], **kw), rounds)
        rows.append(dict(case="sliding ball", tool="mbcomp", setting=f"rtol={rtol:g}", wall_s=wall,
                         error=max(abs(res["x"][-1] - x_ball), abs(res["x_d"][-1] - v_ball))))
        kw = dict(rtol=rtol, atol=rtol / 100, t_eval=[0.0, BOX["T"]])
        wall, res = best_time(lambda: box.simulate(BOX["T"], [BOX["c"], 0, 0], **kw), rounds)
        rows.append(dict(case="box on slope", tool="mbcomp", setting=f"rtol={rtol:g}", wall_s=wall,
                         error=abs(res["x"][-1] - x_box)))
    return rows


BALL_XML = """<mujoco><option timestep="{dt}" integrator="RK4" cone="elliptic" gravity="0 0 -9.81"/>
<worldbody><geom type="plane" size="50 50 0.1" friction="{mu} 0 0"/>
<body pos="0 0 {r}"><freejoint/><geom type="sphere" size="{r}" mass="{m}" friction="{mu} 0 0"/></body>
</worldbody></mujoco>"""

BOX_XML = """<mujoco><option timestep="{dt}" integrator="RK4" cone="elliptic" gravity="{gx} 0 {gz}"/>
<worldbody><geom type="plane" size="50 50 0.1" friction="{mu} 0 0"/>
<body pos="0 0 {c}"><freejoint/><geom type="box" size="{a} {b} {c}" mass="{m}" friction="{mu} 0 0"/></body>
</worldbody></mujoco>"""


def mujoco_runs(rounds: int, steps_list) -> list[dict]:
    import mujoco
    rows = []
    x_ball, v_ball = ball_exact(BALL["T"])
    x_box = box_exact(BOX["T"])
    for steps in steps_list:
        dt = BALL["T"] / steps
        model = mujoco.MjModel.from_xml_string(BALL_XML.format(dt=dt, **BALL))
        data = mujoco.MjData(model)

        def run_ball():
            mujoco.mj_resetData(model, data)
            data.qvel[0] = BALL["v0"]
            for _ in range(steps):
                mujoco.mj_step(model, data)
            return data.qpos[0], data.qvel[0]
        wall, (x, v) = best_time(run_ball, rounds)
        rows.append(dict(case="sliding ball", tool="MuJoCo RK4", setting=f"steps={steps}", wall_s=wall,
                         error=max(abs(x - x_ball), abs(v - v_ball))))
        dt = BOX["T"] / steps
        gx, gz = G * math.sin(BOX["theta"]), -G * math.cos(BOX["theta"])
        model = mujoco.MjModel.from_xml_string(BOX_XML.format(dt=dt, gx=gx, gz=gz, **BOX))
        data = mujoco.MjData(model)

        def run_box():
            mujoco.mj_resetData(model, data)
            for _ in range(steps):
                mujoco.mj_step(model, data)
            return data.qpos[0]
        wall, x = best_time(run_box, rounds)
        rows.append(dict(case="box on slope", tool="MuJoCo RK4", setting=f"steps={steps}", wall_s=wall,
                         error=abs(x - x_box)))
    return rows


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    rounds = 1 if quick else 3
    tolerances = (1e-4, 1e-7, 1e-10) if quick else (1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
    steps = (100, 1000, 10000) if quick else (100, 300, 1000, 3000, 10000, 30000)
    rows = mbcomp_runs(rounds, tolerances)
    try:
        rows += mujoco_runs(rounds, steps)
    except ImportError:
        print("mujoco is not installed (pip install mujoco): mbcomp only")
    out = ROOT / "results" / "friction_vs_mujoco.csv"
    out.parent.mkdir(exist_ok=True)
    with open(out, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["case", "tool", "setting", "wall_s", "error"])
        writer.writeheader()
        writer.writerows(rows)
    for case in ("sliding ball", "box on slope"):
        print(f"\n{case}: error of the final state against the closed form")
        print(f"{'tool':<12} {'setting':<14} {'wall (ms)':>10} {'error':>10}")
        for row in rows:
            if row["case"] == case:
                print(f"{row['tool']:<12} {row['setting']:<14} {1e3 * row['wall_s']:>10.2f} {row['error']:>10.2e}")
    print(f"\nwrote {out.relative_to(ROOT.parent)}")


if __name__ == "__main__":
    main(sys.argv[1:])
