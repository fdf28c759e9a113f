"""Record (or compare) what ``simulate`` returns for every library model, on every run path.

For each ``library/*.toml`` model, in both formulations: the compiled loop (every step and at
``t_eval`` times), scipy's DOP853 and Radau, each with the file's initial state over a short
time.  Stores the sample times, coordinates, speeds and the step counts of ``Result.stats``.
Used to show that a change of the simulate driver leaves every run's numbers untouched::

    python bench/run_numbers.py record before.npz
    ... change the driver ...
    python bench/run_numbers.py compare before.npz
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mbcomp.files.toml_model import library_models, load

T_END = 0.3
T_EVAL = np.linspace(0.0, T_END, 7)
PATHS = {
    "compiled_steps": {},
    "compiled_eval": {"t_eval": T_EVAL},
    "scipy_dop853": {"integrator": "scipy", "t_eval": T_EVAL},
    "scipy_radau": {"integrator": "scipy", "method": "Radau", "t_eval": T_EVAL},
}
STAT_KEYS = ("nfev", "steps", "restarts")


def numbers() -> dict[str, np.ndarray]:
    """``{"model/formulation/path/what": values}``; a run that fails stores its message."""
    out: dict[str, np.ndarray] = {}
    for name, path in sorted(library_models().items()):
        model = load(path)
        for formulation in ("lagrange", "dae"):
            system = model.compile(formulation)
            neutral = system.topology.state_map.neutral()
            q0 = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
            qd0 = np.array([model.initial["qd"].get(c, 0.0) for c in system.speeds])
            for label, options in PATHS.items():
                key = f"{name}/{formulation}/{label}"
                try:
                    res = system.simulate(T_END, q0, qd0, rtol=1e-8, atol=1e-10, **options)
                except Exception as exc:  # noqa: BLE001 - recorded as the run's outcome
                    out[f"{key}/error"] = np.frombuffer(f"{type(exc).__name__}: {exc}".encode(), dtype=np.uint8)
                    continue
                out[f"{key}/t"] = np.asarray(res.t, dtype=float)
                out[f"{key}/q"] = np.asarray(res.q, dtype=float)
                out[f"{key}/qd"] = np.asarray(res.qd, dtype=float)
                out[f"{key}/stats"] = np.array([float(res.stats.get(k, -1)) for k in STAT_KEYS])
                out[f"{key}/integrator"] = np.frombuffer(str(res.stats.get("integrator")).encode(), dtype=np.uint8)
    return out


def main(argv: list[str]) -> int:
    """The same ``record``/``compare`` command as ``generated_numbers.py``, for the run numbers."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from generated_numbers import main as record_or_compare
    return record_or_compare(argv, numbers, __doc__)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
