"""A contact case against MuJoCo: a ball bouncing on the floor, restitution 0.8, 2 s.

A ball (0.1 kg, radius 0.05 m) on a vertical slide, dropped with its centre at 1 m; three
bounces in 2 s.  The exact motion is known in closed form (free flight between impacts,
each impact reversing the speed times e), so the error of a run is |z(2 s) - z_exact|
(m), for every tool against the same exact answer.

- mbcomp: ``Contact`` with restitution 0.8 (Newton's impact law at located events);
  rtol = 1e-3 .. 1e-12 (atol = rtol / 100).
- MuJoCo: sphere on a plane, frictionless (condim 1), RK4 with t_end / steps; its contacts
  are soft, so each setting uses the stiffest contact its step resolves: a spring-damper in
  acceleration units (``solref`` = (-k, -b), ``solimp`` 0.9999) lasting 20 steps, with the
  damping ratio calibrated (bisection, once) so that MuJoCo's rebound is 0.8.  Its error is then
  the softness (each bounce lasts 20 steps) as much as the integration.

Medians of interleaved rounds (timing.py).  No target ratio: the issue asks for the case
to be measured.  Usage: python bench/contact.py [--rounds 3] [--quick]
Writes bench/results/contact.csv and contact_levels.csv.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

import mbcomp as mb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import bounce_height, write_csv  # noqa: E402
from timing import Run, fmt, measure, rounds_main, time_at  # noqa: E402

MASS, RADIUS, HEIGHT, E, G, T_END = 0.1, 0.05, 1.0, 0.8, 9.81, 2.0
LEVELS = (1e-2, 1e-3, 1e-4, 1e-6)
TOLERANCES = [10.0 ** (-k / 2) for k in range(6, 25)]
STEPS = [200, 300, 500, 700, 1000, 1500, 2000, 3000, 5000, 7000, 10000, 15000, 20000, 30000, 50000, 70000,
         100000, 150000, 200000, 300000, 500000]
MBCOMP, MUJOCO = "mbcomp (impact law)", "MuJoCo RK4 (soft contact; rollout)"


def exact_height(t: float) -> float:
    """Centre height (m) of the ideal bouncing ball at time t."""
    return bounce_height(t, HEIGHT, RADIUS, E, G)


def mbcomp_ball() -> mb.Model:
    m = mb.Model("bouncing_ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=MASS, inertia=(0.4 * MASS * RADIUS ** 2,) * 3))
    m.add(mb.Prismatic("drop", m.ground, ball, axis="z", coords="z"))
    m.add(mb.Contact("floor", ball, point=(0, 0, -RADIUS), normal=(0, 0, 1), restitution=E))
    return m


def mujoco_xml(dt: float, duration_steps: int = 20, zeta: float | None = None) -> str:
    """The ball in MJCF with a contact lasting about ``duration_steps`` steps, damping ratio
    ``zeta`` (default: the linear spring-damper's value for restitution E)."""
    duration = duration_steps * dt
    if zeta is None:
        zeta = -math.log(E) / math.sqrt(math.pi ** 2 + math.log(E) ** 2)
    omega = math.pi / (duration * math.sqrt(1 - zeta ** 2))
    k, b = omega ** 2, 2 * zeta * omega
    inertia = 0.4 * MASS * RADIUS ** 2
    return (f'<mujoco model="ball"><option timestep="{dt!r}" integrator="RK4" solver="Newton" tolerance="1e-12" '
            f'gravity="0 0 {-G!r}"/><worldbody>'
            f'<geom name="floor" type="plane" size="1 1 0.1" condim="1" solref="{-k!r} {-b!r}" '
            f'solimp="0.9999 0.9999 0.001 0.5 2"/>'
            f'<body name="ball"><joint name="drop" type="slide" axis="0 0 1"/>'
            f'<geom type="sphere" size="{RADIUS!r}" condim="1" mass="{MASS!r}" solref="{-k!r} {-b!r}" '
            f'solimp="0.9999 0.9999 0.001 0.5 2"/>'
            f'<inertial pos="0 0 0" mass="{MASS!r}" diaginertia="{inertia!r} {inertia!r} {inertia!r}"/>'
            f'</body></worldbody></mujoco>')


def calibrate_zeta(log=print) -> float:
    """The damping ratio for which MuJoCo's contact rebounds with restitution E (MuJoCo never
    lets a contact pull, so a linear spring-damper's formula gives too much rebound): a ball
    hits the floor at 1 m/s (contact of 200 steps of 1e-5 s), bisection on the rebound speed."""
    import mujoco

    def restitution(zeta):
        model = mujoco.MjModel.from_xml_string(mujoco_xml(1e-5, 200, zeta))
        model.opt.gravity[:] = 0.0
        data = mujoco.MjData(model)
        data.qpos[0], data.qvel[0] = RADIUS + 1e-4, -1.0
        mujoco.mj_step(model, data, nstep=600)
        return float(data.qvel[0])

    low, high = 0.0, 0.95
    for _ in range(30):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if restitution(mid) > E else (low, mid)
    zeta = 0.5 * (low + high)
    log(f"  MuJoCo contact damping ratio {zeta:.4f} gives restitution {restitution(zeta):.6f}")
    return zeta


def run(rounds: int = 3, quick: bool = False, log=print) -> dict:
    log("contact: bouncing ball, e = 0.8, 2 s")
    z_exact = exact_height(T_END)
    system = mbcomp_ball().compile()
    integrator = system.simulate(0.5, [HEIGHT]).stats.get("integrator", "?")
    log(f"  mbcomp integrator: {integrator}")
    tolerances = TOLERANCES[::2] if quick else TOLERANCES
    runs = [Run(MBCOMP, "rtol", tol, (lambda tol=tol: system.simulate(T_END, [HEIGHT], rtol=tol, atol=tol / 100)
                                      .q[-1][0]), group=MBCOMP) for tol in tolerances]
    try:
        import mujoco
        from peers import mujoco_rollout
    except ImportError:
        mujoco = None
        log("  mujoco: not installed, skipped")
    if mujoco is not None:
        zeta = calibrate_zeta(log)

        def mj_run(steps):
            model = mujoco.MjModel.from_xml_string(mujoco_xml(T_END / steps, zeta=zeta))
            model.qpos0[:] = 0.0
            data = mujoco.MjData(model)
            return lambda: mujoco_rollout(model, [data], T_END, np.array([[HEIGHT]]), np.zeros((1, 1)),
                                          dt=T_END / steps)[0][0]
        runs += [Run(MUJOCO, "steps", steps, mj_run(steps), group=MUJOCO) for steps in (STEPS[::2] if quick else STEPS)]

    def error(r: Run) -> float:
        e = abs(float(r.result) - z_exact)
        return e if math.isfinite(e) else math.inf

    measure(runs, rounds, check=error, stop_error=min(LEVELS) / 3, max_run=3.0 if quick else 10.0, log=log)
    rows = [{"label": r.label, "setting": r.setting, "value": r.value, "error": r.error if not r.failed else math.inf,
             "time": r.wall, "cpu_time": r.cpu, "rounds": len(r.walls), "failed": r.failed}
            for r in runs if not r.skipped]
    write_csv(rows, "contact.csv")
    table = []
    for clock in ("wall", "cpu"):
        for level in LEVELS:
            entry = {"clock": clock, "level": level, "mbcomp_integrator": integrator}
            for label in (MBCOMP, MUJOCO):
                entry[label] = time_at([(r.error, getattr(r, clock)) for r in runs if r.label == label], level)
            entry["ratio"] = entry[MBCOMP] / entry.get(MUJOCO, math.nan)
            table.append(entry)
    write_csv(table, "contact_levels.csv")
    for e in table[:len(LEVELS)]:
        log(f"  error <= {e['level']:.0e} m: mbcomp {fmt(e[MBCOMP] * 1e3)} ms, MuJoCo "
            f"{fmt(e.get(MUJOCO, math.nan) * 1e3)} ms, ratio {fmt(e['ratio'], 2)}")
    return {"rows": rows, "table": table}


def main(argv=None):
    return rounds_main(run, __doc__, argv)


if __name__ == "__main__":
    main()
