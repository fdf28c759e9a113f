"""50 spheres dropped into a box: mbcomp (event-driven and time stepping) against MuJoCo.

The scene: N = 50 solid spheres (r = 0.05 m, 1 kg, free joints) start on a 7 x 8 grid
(0.14 m apart, so they land side by side: one layer, no stacking) at centre heights drawn
between 0.10 and 0.20 m, with horizontal speeds drawn in [-0.3, 0.3] m/s and no spin (seeded);
a box of five planes (the floor z = 0 and four walls at +-0.6 m); every contact (sphere-floor,
sphere-wall, sphere-sphere) has restitution e = 0.5 and Coulomb friction mu = 0.3; gravity
-9.81 m/s^2.  They fall, bounce (the bounces of a lone sphere end at
t0 (1 + e) / (1 - e) <= 0.55 s), slide into rolling, roll into the walls and into each
other.  The same initial state in MuJoCo: free joints, sphere geoms, plane geoms.

Two windows: a short one (0.3 s: the spheres land and make their first bounces), where
every engine runs, mbcomp's event-driven mode included; and a long one (1 s: every bounce
is over), for time stepping and MuJoCo (the event-driven mode there with --events-long: it
takes many minutes).  What is compared, for each engine (the exact answer first):

- **height error against the closed form**: a sphere that touches only the floor moves
  vertically as a lone bouncing ball (the floor's friction is horizontal: it changes only
  the horizontal and spin motion): free flight, each impact reversing the
  normal speed times e, at rest (z = r) after t0 (1 + e) / (1 - e) (<= 0.53 s here).
  Reported: max |z_i(T) - z_exact,i(T)| over the spheres that, in every run, never came
  within 1e-6 m of a wall or another sphere (their number is given);
- **resting height** (long window): max_i |z_i(T) - r| over all spheres (exact: 0);
- **penetration**: the deepest overlap over the run, of any sphere with the floor, a wall or
  another sphere (exact: 0).  mbcomp's samples are its steps (event-driven: every accepted
  step and both sides of every event; time stepping: every step); MuJoCo's every step
  (every 2e-4 s at finer steps), from a second, untimed run of the same steps;
- **energy left** E(T) / E(0) (kinetic, rotational and potential above rest): no closed
  form (the impacts and friction take it), a check that the engines dissipate alike;
- **time**: wall and processor seconds per simulated second, one-time model building
  excluded (mbcomp's compile reported apart; first calls made before the timing);
- **events**: mbcomp's events by kind (impact, stick, slip, release); MuJoCo has no events:
  the most contacts active at once and the contacts active at T.

What each engine's error is: mbcomp's event-driven mode locates every contact change and
applies Newton's impact law and Coulomb's law there, so its error is the integration
tolerance; the time-stepping mode applies the same laws once per step, so impacts land up
to a step late (positions off by up to the impact speed times dt, penetration of that
order) and resting contacts are exact.  MuJoCo's contacts are soft (a spring-damper in the
constraint solver): here the stiffest one each step resolves, a contact lasting 20 steps
(``solref = (-k, -b)``, ``solimp = 0.9999``), its damping calibrated for each step and
integrator so that a head-on impact at 1.4 m/s rebounds with e = 0.5 (as bench/contact.py
does); its penetration is the spring's
(about the impact speed times the contact's duration over pi), so it shrinks with the step;
elliptic cone, impratio 10, RK4 (and implicitfast).  BLAS runs on one thread (MuJoCo runs on
one core; on a shared machine OpenBLAS's threads made mbcomp's impacts five times slower).

Usage: python bench/spheres_vs_mujoco.py [--quick] [--rounds N] [--window 0.3] [--t-end 1] [--events-long]
Writes bench/results/spheres_vs_mujoco.csv.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import time
from collections import Counter
from pathlib import Path

# One BLAS thread: MuJoCo runs on one core, and on a shared machine OpenBLAS's threads made
# mbcomp's impacts (a dense 300 x 300 factorisation each) about five times slower.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from scipy.spatial.distance import pdist, squareform  # noqa: E402

import mbcomp as mb  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import bounce_height, write_csv  # noqa: E402
from timing import Run, fmt, measure  # noqa: E402

N, RADIUS, MASS, HALF, E, MU, G = 50, 0.05, 1.0, 0.6, 0.5, 0.3, 9.81
INERTIA = 0.4 * MASS * RADIUS ** 2


def initial_state(n: int = N, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Centres (n, 3) and linear velocities (n, 3) of the spheres at t = 0."""
    rng = np.random.default_rng(seed)
    ticks_x = (np.arange(7) - 3) * 0.14
    ticks_y = (np.arange(8) - 3.5) * 0.14
    grid = np.array([(x, y) for x in ticks_x for y in ticks_y])[:n]
    z = rng.uniform(0.10, 0.20, size=n)
    v = np.column_stack([rng.uniform(-0.3, 0.3, size=(n, 2)), np.zeros(n)])
    return np.column_stack([grid, z]), v


def z_exact(z0: float, t: float) -> float:
    """Centre height (m) at t of a sphere dropped from rest (vertically) at centre height z0
    onto the floor, touching nothing else: free flight between impacts, each impact reversing
    the normal speed times E (friction acts through the centre's normal line: it does not
    change the vertical motion); at rest on the floor (z = r) after t0 (1 + E) / (1 - E)."""
    return bounce_height(t, z0, RADIUS, E, G)


def observe(centres: np.ndarray, v_end: np.ndarray, w_end: np.ndarray) -> dict:
    """The measures of one run from its sampled centres (k, N, 3) and the end speeds (N, 3)
    (linear, angular): the end heights, which spheres ever touched another sphere or a wall
    (clearance below 1e-6 m at a sample), the deepest overlap (m; negative: the smallest
    clearance), the energy left (kinetic, and potential above resting, over its value at t = 0)."""
    floor = RADIUS - centres[:, :, 2]
    wall_clear = (HALF - np.abs(centres[:, :, :2])).min(axis=2) - RADIUS
    pair_clear = np.array([(squareform(pdist(c)) + 9 * np.eye(N)).min(axis=1) - 2 * RADIUS for c in centres])
    touched = ((wall_clear < 1e-6) | (pair_clear < 1e-6)).any(axis=0)
    deepest = float(max(floor.max(), -wall_clear.min(), -pair_clear.min()))
    p0, v0 = initial_state()
    energy0 = (0.5 * MASS * (v0 ** 2).sum(axis=1) + MASS * G * (p0[:, 2] - RADIUS)).sum()
    energy = (0.5 * MASS * (v_end ** 2).sum(axis=1) + 0.5 * INERTIA * (w_end ** 2).sum(axis=1)
              + MASS * G * (centres[-1, :, 2] - RADIUS)).sum()
    return {"z_end": centres[-1, :, 2].copy(), "touched": touched, "max_penetration_m": deepest,
            "energy_left": float(energy / energy0)}


# ----------------------------------------------------------------------------- mbcomp

def mbcomp_model(n: int = N) -> mb.Model:
    """The scene in mbcomp: free spheres, five ground planes, two ``Collision``s."""
    m = mb.Model(f"spheres{n}", gravity=(0, 0, -G))
    balls = []
    for i in range(n):
        ball = m.add(mb.Body(f"s{i}", mass=MASS, inertia=(INERTIA,) * 3, shape=mb.Sphere(RADIUS)))
        m.add(mb.Free(f"j{i}", m.ground, ball))
        balls.append(ball)
    walls = [(m.ground, mb.Plane(normal=(0, 0, 1)))]
    walls += [(m.ground, mb.Plane(normal=s * np.eye(3)[k], origin=-s * HALF * np.eye(3)[k]))
              for k in range(2) for s in (1.0, -1.0)]
    m.add(mb.Collision("pairs", balls, balls, restitution=E, friction=MU))
    m.add(mb.Collision("box", balls, walls, restitution=E, friction=MU))
    return m


def mbcomp_state(n: int = N) -> tuple[np.ndarray, np.ndarray]:
    """q0 (position and unit quaternion per sphere) and qd0 (linear and angular speeds)."""
    p, v = initial_state(n)
    q0 = np.concatenate([np.concatenate((p[i], [1.0, 0, 0, 0])) for i in range(n)])
    qd0 = np.concatenate([np.concatenate((v[i], [0.0, 0, 0])) for i in range(n)])
    return q0, qd0


def mbcomp_run(system, t_end: float, **options):
    """A function running the scene (returns the ``Result``)."""
    q0, qd0 = mbcomp_state()
    return lambda: system.simulate(t_end, q0, qd0, **options)


def mbcomp_measures(res) -> dict:
    """The measures of an mbcomp result (its samples: every step, and both sides of events)."""
    q = res.q.reshape(len(res.t), N, 7)
    qd = res.qd.reshape(len(res.t), N, 6)
    out = observe(q[:, :, :3], qd[-1, :, :3], qd[-1, :, 3:])
    kinds = Counter(ev.kind for ev in res.events)
    events = ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())) or "no events"
    if res.stats.get("max_active") is not None:
        events += f"; at most {res.stats['max_active']} contacts active at once"
    out.update(steps=res.stats.get("steps"), path=res.stats.get("path", ""), events=events)
    return out


# ----------------------------------------------------------------------------- MuJoCo

def mujoco_xml(dt: float, zeta: float, duration_steps: int = 20, n: int = N) -> str:
    """The scene in MJCF with a contact lasting about ``duration_steps`` steps (a spring-damper
    in acceleration units, damping ratio ``zeta``)."""
    duration = duration_steps * dt
    omega = math.pi / (duration * math.sqrt(1 - zeta ** 2))
    k, b = omega ** 2, 2 * zeta * omega
    p, _ = initial_state(n)
    contact = f'solref="{-k!r} {-b!r}" solimp="0.9999 0.9999 0.001 0.5 2" friction="{MU} 0 0" condim="3"'
    walls = "".join(f'<geom type="plane" size="1 1 0.1" pos="{x} {y} 0.5" zaxis="{nx} {ny} 0" {contact}/>'
                    for x, y, nx, ny in ((-HALF, 0, 1, 0), (HALF, 0, -1, 0), (0, -HALF, 0, 1), (0, HALF, 0, -1)))
    bodies = "".join(f'<body pos="{x!r} {y!r} {z!r}"><freejoint/><geom type="sphere" size="{RADIUS}" {contact}/>'
                     f'<inertial pos="0 0 0" mass="{MASS}" diaginertia="{INERTIA!r} {INERTIA!r} {INERTIA!r}"/></body>'
                     for x, y, z in p.tolist())
    return (f'<mujoco><option timestep="{dt!r}" integrator="RK4" cone="elliptic" impratio="10" tolerance="1e-10" '
            f'iterations="100" gravity="0 0 {-G}"/><size memory="64M"/><worldbody>'
            f'<geom type="plane" size="1 1 0.1" {contact}/>{walls}{bodies}</worldbody></mujoco>')


def calibrate_zeta(dt: float, integrator: str = "RK4", speed: float = 1.4) -> float:
    """The damping ratio for which MuJoCo's contact, as integrated at step ``dt`` (lasting 20
    steps) by ``integrator``, rebounds with restitution E: one sphere hitting the floor head-on
    at ``speed`` (m/s; the spheres here land at 1.0 to 1.7 m/s) without gravity, bisection on
    the rebound speed (MuJoCo never lets a contact pull, and the steps discretise the contact,
    so the linear spring-damper's formula would not give E)."""
    import mujoco

    def restitution(zeta):
        xml = mujoco_xml(dt, zeta, n=1).replace('integrator="RK4"', f'integrator="{integrator}"')
        model = mujoco.MjModel.from_xml_string(xml)
        model.opt.gravity[:] = 0.0
        data = mujoco.MjData(model)
        data.qpos[2], data.qvel[:] = RADIUS + 0.5 * speed * dt, 0.0
        data.qvel[2] = -speed
        mujoco.mj_step(model, data, nstep=60)
        return float(data.qvel[2]) / speed

    low, high = 0.0, 0.95
    for _ in range(30):
        mid = 0.5 * (low + high)
        low, high = (mid, high) if restitution(mid) > E else (low, mid)
    return 0.5 * (low + high)


def mujoco_setup(dt: float, zeta: float, integrator: str = "RK4"):
    """(model, data, reset to the initial state) of the scene at step dt."""
    import mujoco
    model = mujoco.MjModel.from_xml_string(mujoco_xml(dt, zeta).replace('integrator="RK4"',
                                                                        f'integrator="{integrator}"'))
    data = mujoco.MjData(model)
    _, v = initial_state()

    def reset():
        mujoco.mj_resetData(model, data)
        data.qvel.reshape(N, 6)[:, :3] = v
    return model, data, reset


def mujoco_run(dt: float, zeta: float, t_end: float, integrator: str):
    """A function running the scene in MuJoCo: one ``mj_step`` call (its C loop)."""
    import mujoco
    model, data, reset = mujoco_setup(dt, zeta, integrator)
    steps = int(round(t_end / dt))

    def fn():
        reset()
        mujoco.mj_step(model, data, nstep=steps)
        return float(data.time)
    return fn


def mujoco_measures(dt: float, zeta: float, t_end: float, integrator: str) -> dict:
    """The measures of the MuJoCo run from a second, untimed run of the same steps, sampled
    every step (every 2e-4 s at finer steps: the contacts last 20 steps): deterministic, so
    its end state is the timed run's."""
    import mujoco
    model, data, reset = mujoco_setup(dt, zeta, integrator)
    reset()
    chunk = max(1, int(round(2e-4 / dt)))
    samples, most = [initial_state()[0]], 0
    steps = int(round(t_end / dt))
    for done in range(0, steps, chunk):
        mujoco.mj_step(model, data, nstep=min(chunk, steps - done))
        samples.append(data.qpos.reshape(N, 7)[:, :3].copy())
        most = max(most, data.ncon)
    qvel = data.qvel.reshape(N, 6)
    out = observe(np.array(samples), qvel[:, :3], qvel[:, 3:])
    out.update(steps=steps, events=f"(soft contacts, no events) at most {most} contacts at once, {data.ncon} at T")
    return out


# ----------------------------------------------------------------------------- main

def window(t_end: float, settings: list[tuple[str, str, float, object]], rounds: int, zeta, log=print) -> list[dict]:
    """Time every setting over ``t_end`` and measure it; the height errors against the
    closed form over the spheres no run saw touch a wall or another sphere."""
    runs = [Run(label, setting, value, fn) for label, setting, value, fn in settings]
    log(f"T = {t_end} s: {len(runs)} settings, {rounds} round(s)")
    measure(runs, rounds, burst=0.0, log=log)
    rows = []
    for run in runs:
        row = {"engine": run.label, "setting": run.setting, "t_end": t_end,
               "wall_per_sim_s": run.wall / t_end, "cpu_per_sim_s": run.cpu / t_end}
        if run.failed:
            row["events"] = f"failed: {run.failed}"
        elif run.label.startswith("mbcomp"):
            row.update(mbcomp_measures(run.result))
        else:
            integrator = run.label.split()[-1]
            row.update(mujoco_measures(run.value, zeta[(run.value, integrator)], t_end, integrator))
            row["damping_ratio"] = zeta[(run.value, integrator)]
        rows.append(row)
    measured = [r for r in rows if "touched" in r]
    free = ~np.any([r["touched"] for r in measured], axis=0) if measured else np.zeros(N, bool)
    p0, _ = initial_state()
    exact = np.array([z_exact(z0, t_end) for z0 in p0[:, 2]])
    for row in measured:
        row["untouched"] = int(free.sum())
        row["height_error_m"] = float(np.abs(row["z_end"] - exact)[free].max()) if free.any() else math.nan
        row["rest_height_error_m"] = float(np.abs(row["z_end"] - RADIUS).max())
    return rows


def settled_by() -> float:
    """The time (s) by which every lone sphere's bounces are over: t0 (1 + E) / (1 - E)."""
    p0, _ = initial_state()
    return float(np.sqrt(2 * (p0[:, 2].max() - RADIUS) / G) * (1 + E) / (1 - E))


def print_table(rows: list[dict], t_end: float) -> None:
    settled = t_end > settled_by()
    print(f"\nT = {t_end} s ({'every lone sphere at rest: exact z = r' if settled else 'still bouncing'}); "
          f"height error over the {rows[0].get('untouched', '?')} spheres that touched only the floor in every run")
    print("| engine | setting | wall s / sim s | CPU s / sim s | height error vs closed form (m) | max abs(z - r) (m) "
          "| deepest overlap (m) | energy left E(T)/E(0) | steps | events / contacts |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(f"| {row['engine']} | {row['setting']} | {fmt(row['wall_per_sim_s'])} | {fmt(row['cpu_per_sim_s'])} | "
              f"{row.get('height_error_m', math.nan):.1e} | "
              f"{row.get('rest_height_error_m', math.nan):.1e}{'' if settled else ' (n/a)'} | "
              f"{row.get('max_penetration_m', math.nan):.1e} | {row.get('energy_left', math.nan):.4f} | "
              f"{row.get('steps') or '-'} | {row.get('events', '')} |")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the short window only (0.15 s), fewer settings")
    parser.add_argument("--rounds", type=int, default=1, help="rounds (each run is seconds long; default 1)")
    parser.add_argument("--window", type=float, default=None,
                        help="the short window, s, where mbcomp's event-driven mode runs too (default 0.3; 0.15 quick)")
    parser.add_argument("--t-end", type=float, default=1.0, help="the long window, s (default 1: settled)")
    parser.add_argument("--events-long", action="store_true", help="run the event-driven mode over the long window too")
    args = parser.parse_args(argv)
    short = args.window or (0.15 if args.quick else 0.3)
    load = os.getloadavg()[0]
    started = time.perf_counter()
    system = mbcomp_model().compile()
    compile_s = time.perf_counter() - started
    q0, qd0 = mbcomp_state()
    system.simulate(2e-3, q0, qd0)                                            # (first calls)
    system.simulate(2e-3, q0, qd0, contact_mode="timestepping", dt=1e-3)
    mj = [(1e-3, "RK4"), (1e-4, "RK4"), (1e-4, "implicitfast")] + ([] if args.quick else [(3e-4, "RK4")])
    zeta, version = {}, None
    try:
        import mujoco
        version = mujoco.__version__
        zeta = {(dt, integrator): calibrate_zeta(dt, integrator) for dt, integrator in mj}
    except ImportError:
        print("mujoco is not installed (pip install mujoco): mbcomp only")

    def settings(t_end: float, events: bool) -> list:
        out = []
        if events:
            out.append(("mbcomp events", "rtol=1e-6 (default)", 1e-6, mbcomp_run(system, t_end)))
        out.append(("mbcomp time stepping", "dt=1e-3", 1e-3,
                    mbcomp_run(system, t_end, contact_mode="timestepping", dt=1e-3)))
        if zeta:
            out += [(f"MuJoCo {integrator}", f"dt={dt:g}", dt, mujoco_run(dt, zeta[(dt, integrator)], t_end, integrator))
                    for dt, integrator in sorted(mj, key=lambda s: (s[1], -s[0]))]
        return out

    ratios = ", ".join(f"{integrator} dt={dt:g}: {value:.4f}" for (dt, integrator), value in zeta.items())
    print(f"mbcomp compile {compile_s:.2f} s; MuJoCo {version}, contact damping ratios {ratios} (rebound e = {E}); "
          f"{os.cpu_count()} cores, load average {load:.2f} at the start; "
          f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}", flush=True)
    log = lambda s: print(s, flush=True)  # noqa: E731
    tables = [(short, window(short, settings(short, True), args.rounds, zeta, log))]
    if not args.quick:
        tables.append((args.t_end, window(args.t_end, settings(args.t_end, args.events_long), args.rounds, zeta, log)))
    rows = [{k: v for k, v in row.items() if k not in ("z_end", "touched")} for _, table in tables for row in table]
    write_csv(rows, "spheres_vs_mujoco.csv")
    print(f"\nload average {os.getloadavg()[0]:.2f} at the end; lone spheres at rest by {settled_by():.3f} s")
    for t_end, table in tables:
        print_table(table, t_end)
    print(f"mbcomp paths: {sorted({row.get('path') for row in rows if row.get('path')})}")
    print("wrote bench/results/spheres_vs_mujoco.csv")


if __name__ == "__main__":
    main()
