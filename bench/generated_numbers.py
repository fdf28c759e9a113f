"""Record (or compare) every generated number of every library model.

For each ``library/*.toml`` model this evaluates each generated function (mass matrix
and forces, energy, kinematics, constraints, contacts) at a few random states with the
C and the Python backends, and hashes the generated C and Python source of those
functions.  Used to show that a change of the compiler leaves the equations of the
existing joints untouched::

    python bench/generated_numbers.py record before.npz
    ... change the compiler ...
    python bench/generated_numbers.py compare before.npz
"""
from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np

import mbcomp as mb
from mbcomp.codegen import printer as codegen
from mbcomp.codegen.backend import FUNCTIONS

LIBRARY = Path(__file__).resolve().parent.parent / "library"
STATES = 3


def numbers() -> dict[str, np.ndarray]:
    """``{"model/backend/function/state": values}`` plus ``"model/source/lang"`` hashes."""
    out: dict[str, np.ndarray] = {}
    for path in sorted(LIBRARY.glob("*.toml")):
        model = mb.load(path)
        name = path.stem
        for backend in ("c", "python"):
            system = model.compile(cache=False, backend=backend)
            compiled = system._compiled
            nq = len(system.coords)
            nv = len(getattr(system, "speeds", system.coords))
            rng = np.random.default_rng(7)
            p = system._p
            u = np.zeros(compiled.n_inputs)
            for s in range(STATES):
                q = rng.uniform(-1.0, 1.0, nq)
                qd = rng.uniform(-2.0, 2.0, nv)
                for fn in (f for f in FUNCTIONS if f not in ("drives",)):  # drives take their own inputs
                    out[f"{name}/{backend}/{fn}/{s}"] = np.asarray(compiled.functions(fn, q, qd, p, u), dtype=float)
        prog = compiled.program
        for lang, text in (("c", codegen.c_source(prog, FUNCTIONS)), ("python", codegen.python_source(prog, FUNCTIONS))):  # noqa: E501
            digest = hashlib.sha256(text.encode()).hexdigest()
            out[f"{name}/source/{lang}"] = np.frombuffer(bytes.fromhex(digest), dtype=np.uint8)
    return out


def main(argv: list[str], numbers=None, usage: str | None = None) -> int:
    """``record FILE`` or ``compare FILE`` for ``numbers()`` (this script's, or another
    bench script's function returning ``{key: array}``): exit code 1 when any array differs."""
    numbers = numbers or globals()["numbers"]
    if len(argv) != 3 or argv[1] not in ("record", "compare"):
        print(usage or __doc__)
        return 2
    current = numbers()
    if argv[1] == "record":
        np.savez_compressed(argv[2], **current)
        print(f"recorded {len(current)} arrays")
        return 0
    before = dict(np.load(argv[2]))
    differing, worst, count = [], 0.0, 0
    for key in sorted(set(before) | set(current)):
        a, b = before.get(key), current.get(key)
        if a is None or b is None or a.shape != b.shape:
            differing.append(f"{key}: present/shape differs")
            continue
        count += a.size
        if not np.array_equal(a, b, equal_nan=True):
            worst = max(worst, float(np.nanmax(np.abs(a.astype(float) - b.astype(float)))))
            differing.append(key)
    print(f"compared {len(before)} arrays ({count} numbers): {len(differing)} differ, largest difference {worst:.3g}")
    for key in differing[:20]:
        print("  ", key)
    return 1 if differing else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
