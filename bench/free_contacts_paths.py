"""Contacts on Free joints, and with drive elements: processor time per simulated second.

The scene of ``bench/spheres_vs_mujoco.py`` (N spheres on Free joints dropped into a box of
five planes, restitution 0.5) without friction (collision features with friction step in
Python in both formulations: not what is measured here), event-driven, default tolerances,
over a short window, in the ``dae`` and ``lagrange`` formulations on the path
``integration_path()`` chooses; and a DC-motor-driven pendulum hitting a wall (restitution
0.9) for 5 s.  The ``dae`` runs of free spheres, and both formulations' runs of the motor
model, stepped in Python before the contact runs carried quaternion states and drive
states (formulations/dae_compiled.py, run/stepping.py); run this script against an older
tree for the numbers before.

Reports, per case: the path, processor seconds per simulated second (the fairer number on
a shared machine; compilation excluded, a warm-up run first), steps and events.

Usage: python bench/free_contacts_paths.py [--spheres 50] [--window 0.3]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # (an impact's dense factorisation: one thread)

import numpy as np  # noqa: E402

import mbcomp as mb  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import spheres_vs_mujoco as scene  # noqa: E402


def frictionless_spheres(n: int) -> mb.Model:
    """``spheres_vs_mujoco``'s scene of n spheres, its collisions without friction."""
    m = mb.Model(f"spheres{n}_frictionless", gravity=(0, 0, -scene.G))
    balls = []
    for i in range(n):
        ball = m.add(mb.Body(f"s{i}", mass=scene.MASS, inertia=(scene.INERTIA,) * 3, shape=mb.Sphere(scene.RADIUS)))
        m.add(mb.Free(f"j{i}", m.ground, ball))
        balls.append(ball)
    walls = [(m.ground, mb.Plane(normal=(0, 0, 1)))]
    walls += [(m.ground, mb.Plane(normal=s * np.eye(3)[k], origin=-s * scene.HALF * np.eye(3)[k]))
              for k in range(2) for s in (1.0, -1.0)]
    m.add(mb.Collision("pairs", balls, balls, restitution=scene.E))
    m.add(mb.Collision("box", balls, walls, restitution=scene.E))
    return m


def spheres_state(n: int) -> tuple[np.ndarray, np.ndarray]:
    """q0, qd0 of ``spheres_vs_mujoco.initial_state`` for n spheres (unit quaternions, no spin)."""
    p, v = scene.initial_state(n)
    q0 = np.concatenate([np.concatenate((p[i], [1.0, 0, 0, 0])) for i in range(n)])
    qd0 = np.concatenate([np.concatenate((v[i], [0.0, 0, 0])) for i in range(n)])
    return q0, qd0


def motor_wall() -> mb.Model:
    """A 1 kg rod on a hinge, turned by a geared DC motor (6 V) into a wall (e = 0.9)."""
    m = mb.Model("motor_wall", gravity=(0, 0, -9.81))
    rod = m.add(mb.Body("rod", mass=1.0, com=(0, 0, -0.5), inertia=(0.01, 0.01, 0.0)))
    hinge = m.add(mb.Revolute("hinge", m.ground, rod, axis="x", coords="th"))
    m.add(mb.DCMotor("motor", hinge, ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=6.0))
    m.add(mb.Contact("wall", rod, (0, 0, -1.0), origin=(0, 0.3, 0), normal=(0, -1, 0), restitution=0.9))
    return m


def measure(system, t_end: float, q0, qd0) -> dict:
    """One warm-up run (2 % of the window), then the run: processor s per simulated s."""
    system.simulate(0.02 * t_end, q0, qd0)
    started = time.process_time()
    res = system.simulate(t_end, q0, qd0)
    cpu = time.process_time() - started
    return {"path": res.stats["path"], "cpu_per_s": cpu / t_end, "steps": res.stats.get("steps"),
            "events": len(res.events)}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spheres", type=int, default=50, help="spheres in the box (default 50)")
    parser.add_argument("--window", type=float, default=0.3, help="simulated s of the spheres (default 0.3: the first bounces)")
    parser.add_argument("--formulations", nargs="+", default=["dae", "lagrange"])
    args = parser.parse_args(argv)
    rows = []
    for formulation in args.formulations:
        system = frictionless_spheres(args.spheres).compile(formulation=formulation)
        rows.append((f"{args.spheres} free spheres, {args.window:g} s", formulation,
                     measure(system, args.window, *spheres_state(args.spheres))))
        print(rows[-1], flush=True)
        system = motor_wall().compile(formulation=formulation)
        rows.append(("DC motor pendulum at a wall, 5 s", formulation, measure(system, 5.0, [0.0], [0.0])))
        print(rows[-1], flush=True)
    print("\n| case | formulation | path | CPU s per simulated s | steps | events |\n|---|---|---|---|---|---|")
    for case, formulation, r in rows:
        print(f"| {case} | {formulation} | {r['path']} | {r['cpu_per_s']:.3g} | {r['steps']} | {r['events']} |")


if __name__ == "__main__":
    main()
