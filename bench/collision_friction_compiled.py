"""Colliding shapes with Coulomb friction in the compiled loops against Python stepping.

Three settings, in both formulations, over 1 s at rtol = 1e-10, atol = 1e-12:

- ``ball on box``: a ball (Sphere shape, planar) launched sliding at 2 m/s on a ground Box
  shape with mu = 0.3 (one sphere-box feature): it rolls from t = 2 v0 / (7 mu g) on;
- ``box sliding``: a box (Box shape) resting flat on a ground Box tilted by 0.5 rad with
  mu = 0.4 < tan(0.5): it slides on four box-box corner features (25 features in the pair);
- ``box sticking``: the same tilted by 0.3 rad: it stays put.

Each runs three ways, in turn, ``--rounds`` times (medians of wall time of ``simulate``,
systems compiled and warmed up first): the compiled loop (``integrator="auto"``,
``stats["path"] == "compiled"``); scipy's DOP853 stepping the compiled right-hand side
(``integrator="scipy"``); and scipy's DOP853 stepping the Python right-hand side with the
Python friction solve (``stats["rhs"] == "python"``: the only path collision features with
friction had before they ran compiled; reached here by telling the stepping the model
cannot run compiled).  All three must agree on the events (checked).

Usage: python bench/collision_friction_compiled.py [--rounds 3]
Writes bench/results/collision_friction_compiled.csv.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import mbcomp as mb
from mbcomp.run import stepping

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import write_csv  # noqa: E402

G, T_END, RTOL, ATOL = 9.81, 1.0, 1e-10, 1e-12


def ball_on_box(formulation: str):
    r, mass = 0.1, 1.5
    m = mb.Model("ball_on_box", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=mass, inertia=(0.4 * mass * r * r,) * 3, shape=mb.Sphere(r)))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=["z", "x", "phi"]))
    m.add(mb.Collision("floor", ball, (m.ground, mb.Box((20.0, 2.0, 0.2), origin=(0, 0, -0.1))), friction=0.3))
    return m.compile(formulation=formulation), [r, 0.0, 0.0], [0.0, 2.0, 0.0]


def box_on_incline(formulation: str, theta: float):
    c, s = math.cos(theta), math.sin(theta)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    m = mb.Model("box_on_incline", gravity=(0, 0, -G))
    box = m.add(mb.Body("box", mass=2.0, inertia=(0.02, 0.03, 0.04), shape=mb.Box((0.4, 0.3, 0.2))))
    m.add(mb.Planar("plane", m.ground, box, normal="y", coords=["z", "x", "phi"]))
    normal = R[:, 2]
    m.add(mb.Collision("slope", box, (m.ground, mb.Box((8.0, 2.0, 0.4), origin=-0.2 * normal, rotation=R)),
                       friction=0.4))
    centre = 0.1 * normal
    return m.compile(formulation=formulation), [centre[2], centre[0], theta], [0.0, 0.0, 0.0]


CASES = {"ball on box": ball_on_box, "box sliding": lambda f: box_on_incline(f, 0.5),
         "box sticking": lambda f: box_on_incline(f, 0.3)}
WAYS = ("compiled", "scipy, compiled rhs", "scipy, python rhs")


@contextlib.contextmanager
def python_rhs():
    """The stepping's view that the model cannot run compiled: scipy steps the Python rhs."""
    original = stepping.why_not_compiled
    stepping.why_not_compiled = lambda *args: "bench: the Python right-hand side"
    try:
        yield
    finally:
        stepping.why_not_compiled = original


def run(system, q0, qd0, way):
    integrator = "auto" if way == "compiled" else "scipy"
    with python_rhs() if way == "scipy, python rhs" else contextlib.nullcontext():
        start = time.perf_counter()
        res = system.simulate(T_END, q0, qd0, rtol=RTOL, atol=ATOL, integrator=integrator, method="DOP853")
        return time.perf_counter() - start, res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    rows = []
    for formulation in ("dae", "lagrange"):
        for case, build in CASES.items():
            system, q0, qd0 = build(formulation)
            results = {way: run(system, q0, qd0, way)[1] for way in WAYS}  # warm-up
            assert results["compiled"].stats["path"] == "compiled", results["compiled"].stats["path"]
            assert results["scipy, compiled rhs"].stats["rhs"] == "compiled"
            assert results["scipy, python rhs"].stats["rhs"] == "python"
            base = results["compiled"]
            diffs = {}
            for way in WAYS[1:]:
                other = results[way]
                assert [e.kind for e in base.events] == [e.kind for e in other.events], (case, way)
                diffs[way] = max((abs(a.time - b.time) for a, b in zip(base.events, other.events)), default=0.0)
            times = {way: [] for way in WAYS}
            for _ in range(args.rounds):
                for way in WAYS:
                    times[way].append(run(system, q0, qd0, way)[0])
            med = {way: statistics.median(v) for way, v in times.items()}
            rows.append({"formulation": formulation, "case": case, "compiled_s": med[WAYS[0]],
                         "scipy_compiled_rhs_s": med[WAYS[1]], "scipy_python_rhs_s": med[WAYS[2]],
                         "speedup_vs_python_rhs": med[WAYS[2]] / med[WAYS[0]],
                         "speedup_vs_scipy_compiled_rhs": med[WAYS[1]] / med[WAYS[0]],
                         "events": len(base.events), "steps_compiled": base.stats["steps"],
                         "event_time_diff_python_s": diffs[WAYS[2]]})
            print(f"{formulation:9s} {case:13s} compiled {med[WAYS[0]] * 1e3:8.2f} ms  scipy+C rhs "
                  f"{med[WAYS[1]] * 1e3:8.2f} ms  scipy+Python rhs {med[WAYS[2]] * 1e3:8.2f} ms  "
                  f"x{med[WAYS[2]] / med[WAYS[0]]:6.1f} vs Python  (events {len(base.events)}, "
                  f"|dt_event| {diffs[WAYS[2]]:.1e} s)")
    print("wrote", write_csv(rows, "collision_friction_compiled.csv"))


if __name__ == "__main__":
    main()
