"""A closed loop against MuJoCo: the four-bar over 10 s, mbcomp lagrange and dae against
MuJoCo's C loop with an equality constraint.

The four-bar is the crank-rocker of ``constraints_work_precision.py`` (bars 0.3, 0.8, 0.6 m
on a 0.7 m base, 1 kg each, planar, gravity -y), released at crank angle 1 rad with the
crank turning at 1 rad/s (assembled by mbcomp).  In MuJoCo it is the open chain crank ->
coupler -> rocker (hinges A, B, C) closed by a ``connect`` equality between a site at the
rocker's free end and a world site at the base pivot D; the constraint is made as stiff as
MuJoCo allows (``solref`` time constant 2 dt, its lower limit, and ``solimp`` 0.9999): with
the default ``solref`` (0.02 s) the error never goes below ~1 rad.  RK4, Newton solver.

Error of a run: max of |crank angle - ref| and |coupler angle - ref| at 10 s (rad), both
coordinates shared by the two models; reference: mbcomp lagrange at rtol 1e-12 (cross-check:
dae at 1e-12).  Settings: mbcomp rtol = 1e-3 .. 1e-12 (atol = rtol / 100), MuJoCo RK4 with
t_end / steps, steps from 500.  Medians of interleaved rounds (timing.py).

Usage: python bench/fourbar.py [--rounds 3] [--quick]
Writes bench/results/fourbar.csv (every point) and fourbar_levels.csv.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from constraints_work_precision import fourbar  # noqa: E402
from models import write_csv  # noqa: E402
from timing import Run, fmt, measure, rounds_main, time_at  # noqa: E402

T_END = 10.0
G = 9.81
LEVELS = (1e-4, 1e-5, 1e-6)
TOLERANCES = [10.0 ** (-k / 2) for k in range(6, 25)]       # 1e-3 .. 1e-12
STEPS = [500, 700, 1000, 1500, 2000, 3000, 5000, 7000, 10000, 15000, 20000, 30000, 50000, 70000, 100000,
         150000]
LAGRANGE, DAE, MUJOCO = "mbcomp lagrange", "mbcomp dae", "MuJoCo RK4 (rollout)"


def _bar(length: float, com_x: float) -> str:
    i = length ** 2 / 12
    return f'<inertial pos="{com_x!r} 0 0" mass="1" diaginertia="1e-4 {i!r} {i!r}"/>'


def mujoco_xml(dt: float) -> str:
    """MJCF of the four-bar (the rocker's frame sits at C with the axes of mbcomp's rocker)."""
    return (f'<mujoco model="fourbar"><compiler angle="radian"/>'
            f'<option timestep="{dt!r}" integrator="RK4" solver="Newton" tolerance="1e-12" gravity="0 {-G!r} 0">'
            f'<flag contact="disable"/></option><worldbody><site name="D" pos="0.7 0 0"/>'
            f'<body name="crank"><joint name="A" type="hinge" axis="0 0 1"/>{_bar(0.3, 0.15)}'
            f'<body name="coupler" pos="0.3 0 0"><joint name="B" type="hinge" axis="0 0 1"/>{_bar(0.8, 0.4)}'
            f'<body name="rocker" pos="0.8 0 0"><joint name="C" type="hinge" axis="0 0 1"/>{_bar(0.6, -0.3)}'
            f'<site name="Dr" pos="-0.6 0 0"/></body></body></body></worldbody>'
            f'<equality><connect site1="Dr" site2="D" solref="{2 * dt!r} 1" solimp="0.9999 0.9999 0.001 0.5 2"/>'
            f'</equality></mujoco>')


def to_mujoco(q, qd):
    """mbcomp's (A, B, D) (D absolute) to MuJoCo's (A, B, C) (C relative to the coupler)."""
    (a, b, d), (ad, bd, dd) = q, qd
    return np.array([a, b, d - a - b]), np.array([ad, bd, dd - ad - bd])


def validate_mujoco(system, q, qd) -> float:
    """|qdd_A, qdd_B| of MuJoCo (stiff equality, assembled state) against mbcomp; also the
    mapping of the third coordinate.  Returns the largest difference (rad/s^2)."""
    import mujoco
    model = mujoco.MjModel.from_xml_string(mujoco_xml(1e-5))
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = to_mujoco(q, qd)
    mujoco.mj_forward(model, data)
    gap = float(np.max(np.abs(data.site_xpos[0] - data.site_xpos[1])))
    assert gap < 1e-12, f"MuJoCo four-bar not closed at the assembled state: {gap}"
    a_mb = system.accelerations(q, qd)
    a_mj = data.qacc
    mapped = np.array([a_mb[0], a_mb[1], a_mb[2] - a_mb[0] - a_mb[1]])
    diff = float(np.max(np.abs(a_mj - mapped)))
    # MuJoCo's equality is soft: the acceleration agrees to ~(1 - impedance) = 1e-4 relative.
    assert diff <= 1e-3 * max(1.0, float(np.max(np.abs(mapped)))), (a_mj, mapped)
    return diff


def run(rounds: int = 3, quick: bool = False, log=print) -> dict:
    log("four-bar, 10 s: mbcomp lagrange and dae against MuJoCo")
    model = fourbar()
    lag = model.compile("lagrange")
    dae = model.compile("dae")
    q0, qd0 = lag.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
    ref = lag.simulate(T_END, q0, qd0, rtol=1e-12, atol=1e-14).q[-1][:2]
    check = dae.simulate(T_END, q0, qd0, rtol=1e-12, atol=1e-14).q[-1][:2]
    spread = float(np.max(np.abs(ref - check)))
    log(f"  reference: lagrange and dae at rtol 1e-12 differ by {spread:.1e} rad")
    tolerances = TOLERANCES[::2] if quick else TOLERANCES
    runs = []
    for label, system in ((LAGRANGE, lag), (DAE, dae)):
        runs += [Run(label, "rtol", tol, (lambda tol=tol, s=system: s.simulate(T_END, q0, qd0, rtol=tol,
                                                                              atol=tol / 100).q[-1][:2]),
                     group=label) for tol in tolerances]
    integrators = {label: system.simulate(1.0, q0, qd0).stats.get("integrator", "?")
                   for label, system in ((LAGRANGE, lag), (DAE, dae))}
    log(f"  integrator used: {integrators}")
    try:
        import mujoco
        from peers import mujoco_rollout
    except ImportError:
        mujoco = None
        log("  mujoco: not installed, skipped")
    if mujoco is not None:
        log(f"  MuJoCo accelerations agree with mbcomp to {validate_mujoco(lag, q0, qd0):.1e} rad/s^2 "
            f"(soft equality, impedance 0.9999)")
        mq0, mqd0 = to_mujoco(q0, qd0)
        steps_list = STEPS[::2] if quick else STEPS

        def mj_run(steps):
            """One setting: the model (its solref depends on dt) is built here, outside the timed call."""
            model_ = mujoco.MjModel.from_xml_string(mujoco_xml(T_END / steps))
            data_ = mujoco.MjData(model_)
            return lambda: mujoco_rollout(model_, [data_], T_END, mq0[None], mqd0[None], dt=T_END / steps)[0][:2]

        for steps in steps_list:
            fn = mj_run(steps)
            runs.append(Run(MUJOCO, "steps", steps, fn, group=MUJOCO))

    def error(r: Run) -> float:
        e = float(np.max(np.abs(np.asarray(r.result) - ref)))
        return e if math.isfinite(e) else math.inf

    measure(runs, rounds, check=error, stop_error=min(LEVELS) / 3, max_run=3.0 if quick else 10.0, log=log)
    rows = [{"label": r.label, "setting": r.setting, "value": r.value, "error": r.error if not r.failed else math.inf,
             "time": r.wall, "cpu_time": r.cpu, "rounds": len(r.walls), "failed": r.failed}
            for r in runs if not r.skipped]
    write_csv(rows, "fourbar.csv")
    table = []
    for clock in ("wall", "cpu"):
        for level in LEVELS:
            entry = {"clock": clock, "level": level}
            for label in (LAGRANGE, DAE, MUJOCO):
                entry[label] = time_at([(r.error, getattr(r, clock)) for r in runs if r.label == label], level)
            for label, key in ((LAGRANGE, "ratio_lagrange"), (DAE, "ratio_dae")):
                entry[key] = entry[label] / entry[MUJOCO] if MUJOCO in entry else math.nan
            entry["reference_uncertainty"] = spread
            entry["lagrange_integrator"] = integrators[LAGRANGE]
            entry["dae_integrator"] = integrators[DAE]
            table.append(entry)
    write_csv(table, "fourbar_levels.csv")
    for e in table[:len(LEVELS)]:
        log(f"  error <= {e['level']:.0e}: lagrange {fmt(e[LAGRANGE] * 1e3)} ms, dae {fmt(e[DAE] * 1e3)} ms, "
            f"MuJoCo {fmt(e.get(MUJOCO, math.nan) * 1e3)} ms; ratios {fmt(e['ratio_lagrange'], 2)}, "
            f"{fmt(e['ratio_dae'], 2)}")
    return {"rows": rows, "table": table}


def main(argv=None):
    return rounds_main(run, __doc__, argv)


if __name__ == "__main__":
    main()
