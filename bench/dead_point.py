"""A run released at rest next to a dead point: the compiled least-norm KKT solve against the
Python stepping it used to be repeated on.

A parallelogram four-bar (cranks 0.3 m, coupler 0.7 m, 1 kg bars) released at rest ``eps``
rad from its flat dead point falls along its parallelogram branch.  Within the singular
tolerance of the dead point at rest the compiled dae solve used to give up (``RankLost``)
and ``simulate`` ran the whole run again on scipy's DOP853 with the Python KKT solve
(``ScipyStepping(compiled_rhs=False)``).  The solve in C is now a least-norm one
(``formulations/c/least_norm.h``) and the run stays compiled.  This script times both in
one process (medians of ``--repeat``, interleaved) and prints each one's largest error of
the crank angle against the closed form of the branch (``theta'' = 6 g / (5 L) sin theta``)::

    python bench/dead_point.py [--repeat 3] [--t-end 2.0]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import mbcomp as mb
from mbcomp.core.run_options import RunOptions
from mbcomp.run.paths import IntegrationPath
from mbcomp.run.simulate import run_steps
from mbcomp.run.stats import Counts
from mbcomp.run.stepping import ScipyStepping

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import interleaved_medians  # noqa: E402

L, D, G = 0.3, 0.7, 9.81
DEAD = np.array([-np.pi / 2, np.pi / 2, -np.pi / 2])


def parallelogram() -> mb.Model:
    """Crank and rocker (L) along their body y axes, coupler (D) along x; DEAD lays every
    link on the x axis."""
    def bar(name, length, along):
        com = (length / 2, 0, 0) if along == "x" else (0, length / 2, 0)
        inertia = (1e-4, length ** 2 / 12, length ** 2 / 12) if along == "x" else (length ** 2 / 12, 1e-4, length ** 2 / 12)
        return mb.Body(name, mass=1.0, com=com, inertia=inertia)
    m = mb.Model("parallelogram", gravity=(0, -G, 0))
    crank, coupler, rocker = m.add(bar("crank", L, "y")), m.add(bar("coupler", D, "x")), m.add(bar("rocker", L, "y"))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(0, L, 0)))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(D, 0, 0)))
    m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(D, 0, 0), child_point=(0, L, 0)))
    return m


def branch(eps: float, times: np.ndarray) -> np.ndarray:
    sol = solve_ivp(lambda t, y: [y[1], 6 * G / (5 * L) * np.sin(y[0])], (0.0, times[-1]), [DEAD[0] + eps, 0.0],
                    t_eval=times, rtol=1e-12, atol=1e-14)
    return sol.y[0]


def compiled_run(system, q0, qd0, times):
    return system.simulate(times[-1], q0, qd0, t_eval=times)


def python_run(system, q0, qd0, times):
    """What ``simulate`` fell back to: scipy's DOP853 stepping the Python KKT solve."""
    kernel, formulation = system.kernel, system._formulation
    options = RunOptions.checked(times[-1], t_eval=times)
    stepping = ScipyStepping(kernel, formulation, options, None, np.zeros(kernel.compiled.drives.nz), Counts(),
                             compiled_rhs=False)
    return run_steps(stepping, kernel, formulation, options, q0, qd0, IntegrationPath("scipy", "bench"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--t-end", type=float, default=2.0)
    args = parser.parse_args()
    system = parallelogram().compile("dae")
    times = np.linspace(0.0, args.t_end, 201)
    print(f"{'eps':>7s} {'python s':>9s} {'compiled s':>10s} {'ratio':>7s} {'python err':>10s} {'compiled err':>12s} path")
    for eps in (1e-5, 1e-6):
        q0, qd0 = system.assemble(DEAD + np.array([eps, -eps, eps]), [0.0, 0.0, 0.0])
        exact = branch(eps, times)
        medians, results = interleaved_medians(
            {name: (lambda fn=fn: fn(system, q0, qd0, times)) for name, fn in (("python", python_run),
                                                                                ("compiled", compiled_run))},
            args.repeat)
        slow, fast = medians["python"], medians["compiled"]
        err = {k: float(np.abs(r["A"] - exact).max()) for k, r in results.items()}
        print(f"{eps:7.0e} {slow:9.3f} {fast:10.4f} {slow / fast:7.0f} {err['python']:10.1e} {err['compiled']:12.1e} "
              f"{results['compiled'].stats['path']}", flush=True)


if __name__ == "__main__":
    main()
