"""Where the recursive (articulated-body) tree dynamics beats the dense one: the crossover
behind ``compile(dynamics="auto")`` (``mbcomp.build.recursive.CROSSOVER_NV``).

For the N-link 3D pendulum chain (``models.pendulum_chain``) and N in ``--sizes``, both
programs are compiled and the cost of one call of the compiled ``accelerations`` (q, qd ->
qdd: the function the compiled integrators call once per right-hand side) is timed inside C:
a small timing loop calls it through a function pointer, so no Python overhead is counted.
For reference, one ``pin.aba`` call from Python (its Python binding overhead included) and
the public ``System.accelerations`` of both programs.  Rounds are interleaved (every variant
once per round); each figure is the best round.  The dense and recursive accelerations are
checked to agree (relative 1e-10) before timing.

Usage: python bench/recursive_crossover.py [--sizes 2 3 4 6 8 10 15 20 30 50] [--rounds 5] [--cold]
(``--cold`` also records cold compile times, wall and CPU including the C compiler, in a
fresh cache directory.)
Writes bench/results/recursive_crossover.csv.
"""
from __future__ import annotations

import argparse
import ctypes
import os
import resource
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain, write_csv  # noqa: E402

TIMER_C = r"""
#include <time.h>
typedef int (*acc_fn)(const double *, const double *, const double *, const double *,
                      const double *, double *, double *);
/* Seconds per call of fn over n calls (this thread's CPU time: the machine is shared). */
double time_calls(void *fn, long n, const double *q, const double *qd, const double *p,
                  const double *u, double *qdd, double *work) {
    acc_fn f = (acc_fn)fn;
    struct timespec a, b;
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &a);
    for (long i = 0; i < n; ++i) f(q, qd, p, u, 0, qdd, work);
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &b);
    return ((b.tv_sec - a.tv_sec) + 1e-9 * (b.tv_nsec - a.tv_nsec)) / n;
}
"""


def timer_library(tmp: Path):
    src, lib = tmp / "timer.c", tmp / "timer.so"
    src.write_text(TIMER_C)
    subprocess.run([os.environ.get("CC", "cc"), "-O1", "-shared", "-fPIC", str(src), "-o", str(lib)], check=True)
    timer = ctypes.CDLL(str(lib))
    timer.time_calls.restype = ctypes.c_double
    timer.time_calls.argtypes = [ctypes.c_void_p, ctypes.c_long] + [ctypes.c_void_p] * 6
    return timer


class Variant:
    """One compiled System and the buffers of a timed ``accelerations`` loop."""

    def __init__(self, system, timer, q, qd):
        kernel = system.kernel
        fns = kernel.compiled.functions
        n = system.nv
        self.system, self.timer = system, timer
        self.arrays = [np.array(q), np.array(qd), kernel.p, np.zeros(max(kernel.compiled.n_inputs, 1)),
                       np.empty(n), np.empty(n * (n + 1) // 2 + n + 16)]
        self.fn = ctypes.cast(fns.lib.accelerations, ctypes.c_void_p).value

    def ns_per_call(self, target: float = 0.02) -> float:
        ptrs = [a.ctypes.data for a in self.arrays]
        n = 1000
        while True:
            per = self.timer.time_calls(self.fn, n, *ptrs)
            if per * n > target:
                return 1e9 * per
            n = int(n * max(2.0, target / max(per * n, 1e-9)))


def compile_cpu() -> float:
    """CPU seconds of this process and its finished children (the C compiler) so far: on a
    shared machine a steadier measure of compile work than wall time."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def per_call_us(fn, repeat: int = 7) -> float:
    number, _ = timeit.Timer(fn).autorange()
    number = max(1, number // 10)
    return 1e6 * min(timeit.Timer(fn, timer=time.thread_time).repeat(repeat=repeat, number=number)) / number


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[2, 3, 4, 6, 8, 10, 15, 20, 30, 50])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--cold", action="store_true")
    args = ap.parse_args(argv)
    try:
        import pinocchio as pin
        from peers import PinocchioChain
    except ImportError:
        pin = None
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        timer = timer_library(tmp)
        if args.cold:
            os.environ["MBCOMP_CACHE_DIR"] = str(tmp / "cache")
        for n in args.sizes:
            model = pendulum_chain(n)
            rng = np.random.default_rng(n)
            q, qd = rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)
            row = {"n": n}
            variants = {}
            for kind in ("dense", "recursive"):
                started, cpu = time.perf_counter(), compile_cpu()
                system = model.compile(dynamics=kind)
                row[f"{kind}_compile_s"] = round(time.perf_counter() - started, 3) if args.cold else ""
                row[f"{kind}_compile_cpu_s"] = round(compile_cpu() - cpu, 3) if args.cold else ""
                variants[kind] = Variant(system, timer, q, qd)
            a, b = (variants[k].system.accelerations(q, qd) for k in ("dense", "recursive"))
            row["max_rel_diff"] = float(np.max(np.abs(a - b)) / np.max(np.abs(a)))
            assert row["max_rel_diff"] < 1e-10, row
            best = {k: np.inf for k in ("dense_ns", "recursive_ns", "dense_api_us", "recursive_api_us", "pin_aba_us")}
            if pin is not None:
                chain = PinocchioChain(n)
                tau = np.zeros(n)
                pin_call = lambda: pin.aba(chain.model, chain.data, q, qd, tau)  # noqa: E731
                assert np.allclose(pin_call(), a, rtol=1e-8, atol=1e-8 * np.max(np.abs(a)))
            for _ in range(args.rounds):
                for kind, variant in variants.items():
                    best[f"{kind}_ns"] = min(best[f"{kind}_ns"], variant.ns_per_call())
                    best[f"{kind}_api_us"] = min(best[f"{kind}_api_us"],
                                                 per_call_us(lambda s=variant.system: s.accelerations(q, qd)))
                if pin is not None:
                    best["pin_aba_us"] = min(best["pin_aba_us"], per_call_us(pin_call))
            row.update({k: round(v, 1 if k.endswith("ns") else 3) for k, v in best.items()})
            row["recursive_over_dense"] = round(best["recursive_ns"] / best["dense_ns"], 3)
            rows.append(row)
            print(row, flush=True)
    out = write_csv(rows, "recursive_crossover.csv")
    print(f"wrote {out}")
    header = f"{'N':>3} {'dense ns':>9} {'recursive ns':>12} {'rec/dense':>9} {'pin.aba us':>10} {'API dense us':>12} {'API rec us':>10}"
    print(header)
    for r in rows:
        print(f"{r['n']:>3} {r['dense_ns']:>9} {r['recursive_ns']:>12} {r['recursive_over_dense']:>9} "
              f"{r['pin_aba_us']:>10} {r['dense_api_us']:>12} {r['recursive_api_us']:>10}")


if __name__ == "__main__":
    main()
