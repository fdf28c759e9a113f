"""scipy's methods on the compiled right-hand side against the Python solve they replaced.

A scipy method (``RK45``, ``Radau``) on a constrained model used to evaluate every right-hand
side through Python (numpy's KKT solve for dae, Python coordinate partitioning for lagrange);
it now calls the C functions the compiled loops step (``formulations/compiled_rhs.py``).
Models with drive elements (``four_bar_pid``: the library four-bar whose crank a DC motor
turns, its voltage a PID on the crank angle; ``servo_arm``: a tree with two servos) used to
step the Python workspace with the drive states appended; they step the compiled right-hand
side with the drive states in it now.  This script times both in the same run (medians of
``--repeat`` runs; the Python solve is what the stepping still falls back to at singular
positions) and reports the largest difference of the samples::

    python bench/scipy_methods.py [--repeat 5] [--models four_bar_pid servo_arm]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import mbcomp as mb
from mbcomp.core.run_options import RunOptions
from mbcomp.files.toml_model import library_models, load
from mbcomp.run.paths import IntegrationPath
from mbcomp.run.simulate import run_steps
from mbcomp.run.stats import Counts
from mbcomp.run.stepping import ScipyStepping

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import interleaved_medians  # noqa: E402

MODELS = ("four_bar", "stewart_platform", "slider_crank", "arm3d", "four_bar_pid", "servo_arm")
T_END = 2.0


def model_of(name: str, files: dict):
    """A library model, or the four-bar with a PID-driven DC motor on its crank (``four_bar_pid``)."""
    if name != "four_bar_pid":
        return load(files[name])
    model = load(files["four_bar"])
    pid = model.add(mb.PID("pid", mb.Angle("A"), 1.2, kp=20.0, ki=10.0, kd=1.0, limit=12.0))
    model.add(mb.DCMotor("motor", "A", ratio=5.0, resistance=1.5, inductance=0.02, k=0.05, voltage=pid))
    return model


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
    return run_steps(stepping, kernel, formulation, options, q0, qd0, IntegrationPath("scipy", "bench"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--models", nargs="*", default=MODELS, help="the models to time (default: all)")
    args = parser.parse_args()
    files = library_models()
    print(f"{'model':18s} {'form':9s} {'method':6s} {'python s':>9s} {'compiled s':>10s} {'ratio':>6s} "
          f"{'max |dq|':>9s}")
    for name in args.models:
        model = model_of(name, files)
        for formulation in ("dae", "lagrange"):
            system = model.compile(formulation)
            q0, qd0 = initial(model, system)
            for method in ("RK45", "Radau"):
                times, results = interleaved_medians(
                    {rhs: (lambda rhs=rhs: one_run(system, q0, qd0, method, rhs == "compiled"))
                     for rhs in ("python", "compiled")}, args.repeat)
                slow, fast = times["python"], times["compiled"]
                dq = float(np.abs(results["compiled"].q - results["python"].q).max())
                print(f"{name:18s} {formulation:9s} {method:6s} {slow:9.3f} {fast:10.3f} {fast / slow:6.2f} {dq:9.1e}",
                      flush=True)


if __name__ == "__main__":
    main()
