"""Motors whose position is a Python callable: the compiled loop calling the position back
against the path such a model took before.

A motor given ``position=<Python callable>`` used to keep the run in scipy's DOP853
stepping of the Python solve (``run/paths.py``: "motor ... prescribes its position by a
Python callable"); the compiled loops now read ``s, s', s''`` from a callback into Python
once per evaluated time (``codegen/callbacks.py``).  This script times both on a four-bar
with a pendulum hung from its coupler, driven by a callable motor on the crank (finite
differences, and a callable with exact derivatives), in both formulations, and, for scale,
the same motion given as a file expression (compiled programs, no callback).  Medians of
``--repeat`` interleaved runs (``models.interleaved_medians``), the ratio old/new and the
largest difference of the samples::

    python bench/motor_callables_compiled.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from mbcomp.core.run_options import RunOptions
from mbcomp.run.paths import IntegrationPath
from mbcomp.run.simulate import run_steps
from mbcomp.run.stats import Counts
from mbcomp.run.stepping import ScipyStepping

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), os.pardir, "tests"))
from models import interleaved_medians  # noqa: E402
from test_motor_callables_compiled import A1, W, ExactLaw, law, linkage  # noqa: E402  (the tests' linkage and laws)

T_END = 5.0


def old_path(system, q0, qd0):
    """The path before: scipy's DOP853 stepping of the Python solve."""
    kernel, formulation = system.kernel, system._formulation
    options = RunOptions.checked(T_END, rtol=1e-8, atol=1e-10, t_eval=np.linspace(0, T_END, 51))
    stepping = ScipyStepping(kernel, formulation, options, None, np.zeros(0), Counts(), compiled_rhs=False)
    return run_steps(stepping, kernel, formulation, options, q0, qd0,
                     IntegrationPath("scipy", "bench: the old path of callable motors"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    t_eval = np.linspace(0, T_END, 51)
    print(f"{'case':<28} {'old (s)':>9} {'compiled (s)':>13} {'ratio':>7} {'expression (s)':>15} {'max |dq|':>10}")
    for formulation in ("dae", "lagrange"):
        expression = linkage("1 + 0.5*sin(2*t)", f"bench_mc_expr_{formulation}").compile(formulation)
        for label, position in (("finite differences", law), ("exact derivatives", ExactLaw())):
            system = linkage(position, f"bench_mc_{formulation}_{label[:5]}").compile(formulation)
            assert system.integration_path() == "compiled", system.integration_path()
            q0, qd0 = system.assemble([law(0.0), -0.5, 1.5, -1.0], [A1 * W, 0.0, 0.0, 0.0])
            runs = {
                "old": lambda: old_path(system, q0, qd0),
                "compiled": lambda: system.simulate(T_END, q0, qd0, rtol=1e-8, atol=1e-10, t_eval=t_eval),
                "expression": lambda: expression.simulate(T_END, q0, qd0, rtol=1e-8, atol=1e-10, t_eval=t_eval),
            }
            seconds, results = interleaved_medians(runs, args.repeat)
            assert results["compiled"].stats["integrator"] == "compiled"
            dq = float(np.max(np.abs(results["compiled"].q - results["old"].q)))
            print(f"{formulation + ' ' + label:<28} {seconds['old']:9.4f} {seconds['compiled']:13.4f} "
                  f"{seconds['old'] / seconds['compiled']:7.1f} {seconds['expression']:15.4f} {dq:10.2e}")


if __name__ == "__main__":
    main()
