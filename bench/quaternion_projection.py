"""projection=True on quaternion coordinates: the compiled DOP853 loop's projection against
the path such a run took before.

A dae model with ``Ball``/``Free`` joints and ``projection=True`` used to step in scipy with
the Python projection after each accepted step ("projection=True on quaternion coordinates
... steps in Python"); ``dae_project`` (formulations/c/dae.c) now steps each quaternion by the
exp-map of its Newton step in the compiled loop.  This script times both (the old path is
``integrator="scipy"``) on the spatial four-bar of the tests (two Ball joints), 5 s at
rtol 1e-10, medians of ``--repeat`` interleaved runs (``models.interleaved_medians``), and
prints the ratio old/new, the largest difference of the samples and the constraint
residuals::

    python bench/quaternion_projection.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), os.pardir, "tests"))
from models import interleaved_medians  # noqa: E402
from test_quaternion_projection_compiled import _rssr  # noqa: E402  (the tests' four-bar)

T_END = 5.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    system = _rssr(projection=True)
    q0 = system.state_vector({"crank_pivot": 0.0, "rocker_pivot": 0.0})
    v0 = np.zeros(system.nv)
    v0[0] = 2.0
    q0, v0 = system.assemble(q0, v0)
    t = np.linspace(0.0, T_END, 51)
    options = dict(rtol=1e-10, atol=1e-12, t_eval=t)
    assert system.integration_path() == "compiled"
    runs = {"scipy + Python projection (old)": lambda: system.simulate(T_END, q0, v0, integrator="scipy", **options),
            "compiled DOP853 + dae_project (new)": lambda: system.simulate(T_END, q0, v0, **options)}
    runs[next(iter(runs))]()  # (warm-up: the library is loaded once)
    medians, results = interleaved_medians(runs, args.repeat)
    (old_name, old), (new_name, new) = results.items()
    for name, seconds in medians.items():
        steps = system.simulate(T_END, q0, v0, rtol=1e-10, atol=1e-12,
                                **({"integrator": "scipy"} if "old" in name else {}))
        print(f"{name:40s} {seconds * 1e3:9.2f} ms   max |g| at steps {np.max(steps.constraint_violation()):.2e}")
    print(f"ratio old/new: {medians[old_name] / medians[new_name]:.1f}x")
    print(f"max |q_old - q_new| over the samples: {np.max(np.abs(old.q - new.q)):.2e}")


if __name__ == "__main__":
    main()
