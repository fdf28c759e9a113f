"""Cost of each public evaluation call of the N-link pendulum chain against ``pin.aba``.

Per call from Python (microseconds; best of interleaved rounds, each the best of timeit
repeats), the state a float64 ndarray:
  accelerations      System.accelerations(q, qd)
  mass_matrix        System.mass_matrix(q)
  reactions          System.reactions(q, qd)            (a tree: no constraint forces)
  body_state         System.body_state("link{N-1}", q, qd)   (pose and velocity; the
                     acceleration is solved only when read)
  ctypes path        the same accelerations through mbcomp.codegen.fastcall.CtypesCalls (what runs
                     where Python's headers are missing: no extension)
  ctypes floor       the compiled function called through ctypes with pre-bound pointer
                     arguments (no checks, no output array: the floor of any ctypes call)
  checked path       System.accelerations(list(q), list(qd)) (conversion and checks)
  pin.aba            pinocchio.aba(model, data, q, v, tau)

Both this thread's CPU time (the primary figure: the machine may be shared, and wall time
then includes waiting for a core) and wall time.  Ratios are to pin.aba in the same run.

Usage: python bench/public_calls.py [N ...] [--rounds 5]     (default 5 20 50)
Writes bench/results/public_calls.csv.
"""
from __future__ import annotations

import argparse
import ctypes
import sys
import time
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain, write_csv  # noqa: E402

CALLS = ("accelerations", "mass_matrix", "reactions", "body_state", "ctypes_path", "ctypes_floor", "checked_path",
         "pin_aba")


def per_call_us(fn, target: float = 0.02, repeat: int = 5) -> tuple[float, float]:
    """(CPU, wall) microseconds per call: best of ``repeat`` timeit repeats of ~``target`` s."""
    number, took = timeit.Timer(fn).autorange()
    number = max(1, int(number * target / max(took, 1e-9)))
    cpu = min(timeit.Timer(fn, timer=time.thread_time).repeat(repeat=repeat, number=number)) / number
    wall = min(timeit.Timer(fn).repeat(repeat=repeat, number=number)) / number
    return 1e6 * cpu, 1e6 * wall


def setup(n: int) -> dict:
    """``{name: fn}``: one call each, all at the same random state (checked to agree)."""
    from mbcomp.codegen import fastcall
    rng = np.random.default_rng(1)
    q, qd = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    system = pendulum_chain(n).compile()
    kernel = system.kernel
    last = f"link{n - 1}"
    system.body_state(last, q, qd)  # the first call of a body finds it; later calls go direct
    calls = {"accelerations": lambda: system.accelerations(q, qd), "mass_matrix": lambda: system.mass_matrix(q),
             "reactions": lambda: system.reactions(q, qd), "body_state": lambda: system.body_state(last, q, qd)}
    plain = fastcall.calls(kernel.compiled.functions, kernel.layout, kernel.p, n, n, use_extension=False)
    calls["ctypes_path"] = lambda: plain.accelerations(q, qd)
    lib = kernel.compiled.functions.lib
    fn = lib.accelerations
    fn.restype = ctypes.c_int
    out, work, u = np.empty(n), np.empty(kernel.layout.size("dynamics")), np.zeros(1)
    args = tuple(ctypes.c_void_p(a.ctypes.data) for a in (q, qd, kernel.p, u)) + (None,) + tuple(
        ctypes.c_void_p(a.ctypes.data) for a in (out, work))
    calls["ctypes_floor"] = lambda keep=(q, qd, u, out, work): fn(*args)
    ql, qdl = list(q), list(qd)
    calls["checked_path"] = lambda: system.accelerations(ql, qdl)
    expected = system.accelerations(ql, qdl)
    assert np.array_equal(system.accelerations(q, qd), expected) and np.array_equal(plain.accelerations(q, qd), expected)
    fn(*args)
    assert np.array_equal(out, expected)
    try:
        import pinocchio as pin
        from peers import PinocchioChain
    except ImportError:
        return calls
    pn = PinocchioChain(n)
    model, data, tau = pn.model, pn.data, np.zeros(n)
    assert np.allclose(pin.aba(model, data, q, qd, tau), expected, rtol=1e-9, atol=1e-9), "pin.aba disagrees"
    calls["pin_aba"] = lambda: pin.aba(model, data, q, qd, tau)
    return calls


def measure(n: int, rounds: int) -> dict:
    calls = setup(n)
    row = {"N": n}
    for _ in range(rounds):
        for key, fn in calls.items():
            cpu, wall = per_call_us(fn)
            row[f"{key}_us"] = min(row.get(f"{key}_us", np.inf), cpu)
            row[f"{key}_wall_us"] = min(row.get(f"{key}_wall_us", np.inf), wall)
    if "pin_aba_us" in row:
        for key in CALLS[:-1]:
            row[f"{key}_over_aba"] = row[f"{key}_us"] / row["pin_aba_us"]
            row[f"{key}_over_aba_wall"] = row[f"{key}_wall_us"] / row["pin_aba_wall_us"]
    return row


def run(sizes=(5, 20, 50), rounds: int = 5, log=print) -> list[dict]:
    """Measure every size; print the tables; write bench/results/public_calls.csv."""
    log(time.strftime("%Y-%m-%d %H:%M") + " | one public evaluation call of the N-link chain")
    rows = [measure(n, rounds) for n in sizes]
    for wall in (False, True):
        w = "_wall" if wall else ""
        log(f"\n{'wall' if wall else 'CPU'} time per call (us); in brackets: / pin.aba, same run")
        log(f"{'N':>4} | " + " | ".join(f"{key:>16}" for key in CALLS))
        for row in rows:
            cells = []
            for key in CALLS:
                value, ratio = row.get(f"{key}{w}_us"), row.get(f"{key}_over_aba{w}")
                cells.append(f"{'-':>16}" if value is None else
                             f"{value:8.2f}" + (f" ({ratio:5.2f})" if ratio is not None else " " * 8))
            log(f"{row['N']:>4} | " + " | ".join(cells))
    write_csv([{k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()} for row in rows],
              "public_calls.csv")
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sizes", nargs="*", type=int, default=[5, 20, 50])
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (best of)")
    args = parser.parse_args(argv)
    return run(args.sizes, args.rounds)


if __name__ == "__main__":
    main()
