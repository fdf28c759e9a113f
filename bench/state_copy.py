"""Compiled runs with the templates' own state copies (``mb_copy``) against the C library's
memcpy, side by side in one run.

Usage: python bench/state_copy.py [--rounds R] [--runs K] [--models NAME ...]

The compiled loops (DOP853, RK4, the lagrange reduced loop) copy state vectors whose length
the templates read at run time.  Called with such a length, the C library's memcpy runs its
widest version (AVX-512 ``__memmove_evex_unaligned_erms`` on this kind of machine), after
which the generated SSE2 arithmetic of the right-hand side ran 12-16 % slower; the inline
word copy of ``codegen.C_TEMPLATE_LIBC`` avoids it.  Each model runs both variants
interleaved, ``R`` rounds, each variant in a fresh process that compiles the model into an
empty cache of its own and runs it ``K`` times, as a script does; the best wall time of
each variant counts, and the trajectories must be bit-identical.  Prints one row per model
and method: ms with ``mb_copy``, ms with memcpy, their ratio.  (The slowdown needs the
compile in the same process: loaded from a cache another process filled, and with both
variants in one process, memcpy ran as fast on this machine: what slows the arithmetic is
probably the state the processor is left in by the library's AVX-512 code, not the copies.)
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ["MBCOMP_CACHE_DIR"] = tempfile.mkdtemp(prefix="state-copy-")  # each process its own

import mbcomp as mb  # noqa: E402
from mbcomp.codegen import printer as codegen  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain as chain  # noqa: E402

OWN = codegen.C_TEMPLATE_LIBC
#: The same prelude with the copies left to the C library.
LIBC = OWN.split("/* The compiled loops copy")[0] + "#define mb_copy memcpy\n"


def cases(names):
    """``(label, model builder, formulation, q0, qd0)`` for each model asked for."""
    spin = [np.cos(0.2), np.sin(0.2), 0.0, 0.0]
    table = {
        "chain3": (lambda: chain(3), "lagrange", [0.3] * 3, [0.0] * 3),
        "chain5": (lambda: chain(5), "lagrange", [0.3] * 5, [0.0] * 5),
        "chain10": (lambda: chain(10), "lagrange", [0.3] * 10, [0.0] * 10),
        "double_pendulum": (lambda: mb.load("double_pendulum"), "lagrange", None, None),
        "arm3d": (lambda: mb.load("arm3d"), "lagrange", None, None),
        "spinning_top": (lambda: mb.load("spinning_top"), "lagrange", spin, [0.0, 0.0, 30.0]),
        "four_bar/lagrange": (lambda: mb.load("four_bar"), "lagrange", None, None),
        "four_bar/dae": (lambda: mb.load("four_bar"), "dae", None, None),
    }
    return [(name, *table[name]) for name in names]


#: The compiled methods each model runs (the lagrange formulation of a loop has no RK4 loop).
METHODS = {"chain3": ("DOP853", "RK4"), "chain5": ("DOP853", "RK4"), "chain10": ("DOP853", "RK4"),
           "double_pendulum": ("DOP853", "RK4"), "arm3d": ("DOP853", "RK4"), "spinning_top": ("DOP853", "RK4"),
           "four_bar/lagrange": ("DOP853",), "four_bar/dae": ("DOP853", "RK4")}


def compile_with(prelude: str, build, formulation: str):
    codegen.C_TEMPLATE_LIBC = prelude
    try:
        return build().compile(formulation)
    finally:
        codegen.C_TEMPLATE_LIBC = OWN


def run(system, q0, qd0, method):
    kw = {} if method == "DOP853" else {"method": "RK4", "dt": 1e-3}
    args = () if q0 is None else (q0, qd0)
    start = time.perf_counter()
    res = system.simulate(10.0, *args, **kw)
    return time.perf_counter() - start, res


def child(name: str, variant: str, rounds: int) -> None:
    """Print ``{method: [best seconds, trajectory digest]}`` of one model and variant as JSON."""
    (_, build, formulation, q0, qd0), = cases([name])
    system = compile_with(OWN if variant == "own" else LIBC, build, formulation)
    if q0 is None:  # every coordinate at 0.3 rad (assembled onto the loop's constraints), at rest
        q0, qd0 = system.assemble(np.full(len(system.coords), 0.3), np.zeros(system.nv))
    out = {}
    for method in METHODS[name]:
        best, digest = np.inf, ""
        for _ in range(rounds):
            seconds, res = run(system, q0, qd0, method)
            assert res.stats["integrator"] == "compiled", res.stats
            best = min(best, seconds)
            digest = hashlib.sha256(res.q.tobytes() + res.qd.tobytes()).hexdigest()
        out[method] = [best, digest]
    print(json.dumps(out))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3, help="fresh processes per model and variant")
    parser.add_argument("--runs", type=int, default=10, help="runs per process (the best counts)")
    parser.add_argument("--models", nargs="*", default=list(METHODS))
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(*args.child, args.runs)
        return
    print(f"{'model':20s} {'method':7s} {'mb_copy ms':>10s} {'memcpy ms':>10s} {'ratio':>6s}")
    for name in args.models:
        best: dict = {}
        for _ in range(args.rounds):  # interleaved: a noisy spell hits both variants
            for variant in ("own", "libc"):
                done = subprocess.run([sys.executable, __file__, "--runs", str(args.runs), "--child", name, variant],
                                      capture_output=True, text=True, check=True)
                for method, (seconds, digest) in json.loads(done.stdout.splitlines()[-1]).items():
                    entry = best.setdefault(method, {"own": np.inf, "libc": np.inf, "digests": set()})
                    entry[variant] = min(entry[variant], seconds)
                    entry["digests"].add(digest)
        for method, entry in best.items():
            assert len(entry["digests"]) == 1, f"{name} {method}: the two variants' trajectories differ"
            print(f"{name:20s} {method:7s} {entry['own'] * 1e3:10.3f} {entry['libc'] * 1e3:10.3f} "
                  f"{entry['libc'] / entry['own']:6.2f}", flush=True)


if __name__ == "__main__":
    main()
