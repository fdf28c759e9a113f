"""The evaluation calls of constrained models: the compiled KKT solve against the Python one.

``System.accelerations`` and ``System.reactions`` of a model with constraints used to solve
the KKT system in Python (numpy, ``Formulation.solve``); they call the compiled solve of the
compiled loops now (``formulations/compiled_eval.py``).  Per call (microseconds, best of
``--rounds`` timeit repeats, interleaved), both formulations, and one ``System.linearize``
(which evaluates the accelerations many times), with the Python solve reached by switching
the compiled one off (``Formulation.compiled_solve`` returning None) on a fresh System::

    python bench/evaluation_solve.py [--rounds 5]
"""
from __future__ import annotations

import argparse
import sys
import time
import timeit
from pathlib import Path

import numpy as np

from mbcomp.files.toml_model import library_models
from mbcomp.formulations.base import Formulation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scipy_methods import initial, model_of  # noqa: E402

MODELS = ("four_bar", "slider_crank", "stewart_platform", "four_bar_pid")


def start(model, system):
    """The model's initial state moved onto its constraints."""
    return system.assemble(*initial(model, system))


def per_call(fn, rounds: int) -> float:
    """Best time of one call (microseconds)."""
    number = 200
    return min(timeit.repeat(fn, number=number, repeat=rounds)) / number * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    files = library_models()
    compiled_solve = Formulation.compiled_solve
    print(f"{'model':17s} {'form':9s} {'call':13s} {'python us':>10s} {'compiled us':>11s} {'ratio':>6s} {'max diff':>9s}")
    for name in MODELS:
        model = model_of(name, files)
        for formulation in ("dae", "lagrange"):
            fast = model.compile(formulation)
            Formulation.compiled_solve = lambda self, kernel: None
            try:
                slow = model.compile(formulation)
                slow.accelerations(*start(model, slow))  # (binds the Python solve to this System)
            finally:
                Formulation.compiled_solve = compiled_solve
            q, qd = start(model, fast)
            qd = qd + 0.3
            for call in ("accelerations", "reactions"):
                times = {}
                values = {}
                for label, system in (("python", slow), ("compiled", fast)):
                    fn = getattr(system, call)
                    values[label] = fn(q, qd)
                    times[label] = per_call(lambda: fn(q, qd), args.rounds)
                if call == "accelerations":
                    diff = float(np.abs(values["compiled"] - values["python"]).max())
                else:
                    diff = max(float(np.abs(np.asarray(values["compiled"][k]) - values["python"][k]).max())
                               for k in values["python"])
                print(f"{name:17s} {formulation:9s} {call:13s} {times['python']:10.1f} {times['compiled']:11.1f} "
                      f"{times['compiled'] / times['python']:6.2f} {diff:9.1e}", flush=True)
            if fast.ndof and not name == "slider_crank":
                times = {}
                for label, system in (("python", slow), ("compiled", fast)):
                    best = np.inf
                    for _ in range(args.rounds):
                        started = time.perf_counter()
                        system.linearize(q)
                        best = min(best, time.perf_counter() - started)
                    times[label] = best * 1e6
                print(f"{name:17s} {formulation:9s} {'linearize':13s} {times['python']:10.0f} {times['compiled']:11.0f} "
                      f"{times['compiled'] / times['python']:6.2f} {'':>9s}", flush=True)


if __name__ == "__main__":
    main()
