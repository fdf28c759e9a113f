"""scipy's methods on the compiled right-hand side against the Python solve they replaced.

A scipy method (``RK45``, ``Radau``) on a constrained model used to evaluate every right-hand
side through Python (numpy's KKT solve for dae, Python coordinate partitioning for lagrange);
it now calls the C functions the compiled loops step (``formulations/compiled_rhs.py``).
This script times both in the same run (medians of ``--repeat`` runs; the Python solve is
what the stepping still falls back to at singular positions) and reports the largest
difference of the samples::

    python bench/scipy_methods.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from mbcomp.core.run_options import RunOptions
from mbcomp.files.toml_model import library_models, load
from mbcomp.run.paths import IntegrationPath
from mbcomp.run.simulate import run_steps
from mbcomp.run.stats import Counts
from mbcomp.run.stepping import ScipyStepping

MODELS = ("four_bar", "stewart_platform", "slider_crank", "arm3d")
T_END = 2.0


def initial(model, system):
    neutral = system.topology.state_map.neutral()
    q = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
    qd = np.array([model.initial["qd"].get(c, 0.0) for c in system.speeds])
    return q, qd


def one_run(system, q0, qd0, method: str, compiled_rhs: bool):
    kernel, formulation = system.kernel, system._formulation
    options = RunOptions.checked(T_END, method=method, rtol=1e-8, atol=1e-10, t_eval=np.linspace(0, T_END, 21))
    stepping = ScipyStepping(kernel, formulation, options, None, np.zeros(kernel.compiled.drives.nz), Counts(),
                             compiled_rhs=compiled_rhs)
    started = time.perf_counter()
    res = run_steps(stepping, kernel, formulation, options, q0, qd0, IntegrationPath("scipy", "bench"))
    return time.perf_counter() - started, res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    files = library_models()
    print(f"{'model':18s} {'form':9s} {'method':6s} {'python s':>9s} {'compiled s':>10s} {'ratio':>6s} "
          f"{'max |dq|':>9s}")
    for name in MODELS:
        model = load(files[name])
        for formulation in ("dae", "lagrange"):
            system = model.compile(formulation)
            q0, qd0 = initial(model, system)
            for method in ("RK45", "Radau"):
                times = {True: [], False: []}
                results = {}
                for _ in range(args.repeat):
                    for compiled_rhs in (False, True):  # (interleaved: the machine's load hits both alike)
                        seconds, results[compiled_rhs] = one_run(system, q0, qd0, method, compiled_rhs)
                        times[compiled_rhs].append(seconds)
                slow, fast = float(np.median(times[False])), float(np.median(times[True]))
                dq = float(np.abs(results[True].q - results[False].q).max())
                print(f"{name:18s} {formulation:9s} {method:6s} {slow:9.3f} {fast:10.3f} {fast / slow:6.2f} {dq:9.1e}",
                      flush=True)


if __name__ == "__main__":
    main()
