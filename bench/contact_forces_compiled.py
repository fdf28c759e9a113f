"""``Result.contact_forces()`` of a long run: the Python solve at every sample against the
compiled solve with the held contacts' rows and friction (``dae_evaluate_friction``).

The library's ``sliding_ball`` (sliding, then rolling: its contact sticks) and
``box_on_slope`` (sliding down) over 5 s with 5001 samples, both formulations.  "python":
the formulation's Python solve at every sample where contacts were held (the evaluation
calls before they solved in C; ``Formulation.compiled_solve`` patched to give none);
"compiled": ``System.contact_forces`` as it is.  Median wall seconds of ``--rounds``
interleaved runs (``models.interleaved_medians``); both must agree to 1e-10 (checked).

Usage: python bench/contact_forces_compiled.py [--rounds 5]
Writes bench/results/contact_forces_compiled.csv.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from unittest import mock

import numpy as np

from mbcomp.files.toml_model import library_models, load
from mbcomp.formulations.base import Formulation
from mbcomp.run import post

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import interleaved_medians, write_csv  # noqa: E402

CASES = {"sliding_ball": ([0.1, 0.0, 0.0], [0.0, 2.0, 0.0]), "box_on_slope": ([0.05, 0.0, 0.0], [0.0, 0.0, 0.0])}
T_END, SAMPLES = 5.0, 5001


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for name, (q0, qd0) in CASES.items():
        for formulation in ("dae", "lagrange"):
            model = load(library_models()[name])
            compiled, plain = model.compile(formulation), model.compile(formulation)
            result = compiled.simulate(T_END, q0, qd0, t_eval=np.linspace(0.0, T_END, SAMPLES))
            held = sum(1 for c in result.closed_contacts if c)

            def python():
                with mock.patch.object(Formulation, "compiled_solve", lambda *args, **kwargs: None):
                    return post.contact_forces(plain, result)

            seconds, out = interleaved_medians({"python": python,
                                                "compiled": lambda: post.contact_forces(compiled, result)},
                                               args.rounds)
            error = max(float(np.max(np.abs(out["compiled"][k] - v))) / max(1.0, float(np.max(np.abs(v))))
                        for k, v in out["python"].items())
            assert error <= 1e-10, (name, formulation, error)
            row = {"model": name, "formulation": formulation, "samples held": held, "python s": seconds["python"],
                   "compiled s": seconds["compiled"], "ratio": seconds["python"] / seconds["compiled"],
                   "max rel diff": error}
            rows.append(row)
            print(", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()),
                  flush=True)
    print("wrote", write_csv(rows, "contact_forces_compiled.csv"))


if __name__ == "__main__":
    main()
