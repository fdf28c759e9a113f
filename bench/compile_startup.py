"""Cold compile, warm-process start-up and compile memory of the N-link chain, each in a fresh process.

Usage: python bench/compile_startup.py [N ...] [--rounds R] [--bytecode] [--trees DIR ...]
(default N = 5 10 20 50, R = 3; ``--trees`` compares source trees of mbcomp, e.g. before and
after a change, interleaved in the same run; default: the mbcomp this script imports;
``--bytecode``: the children keep Python's bytecode cache (in a temporary directory) even
where ``PYTHONDONTWRITEBYTECODE`` is set, as an installed package has it)

For every N, R times, interleaved (a noisy spell hits all sizes alike):

- **cold**: a new Python process with an empty code cache imports mbcomp (timed apart),
  builds the chain and compiles it (C backend): ``cold_s`` excludes the imports;
  ``cold_with_outputs_s`` adds the wait for the output functions (energy, body states),
  which the compile leaves building in the background.  sympy,
  which mbcomp imports only when it generates code, is an import as well: the child imports
  it before compiling (``sympy_import_s``, as the compile would at its start) and
  ``cold_with_sympy_s`` is ``cold_s`` plus that import, what a script that compiles first
  waits.  Memory: the parent samples the resident memory of the child and of every process
  below it (the C compiler driver, ``cc1``, the assembler, the linker: several compilers run
  at once) every few milliseconds on Linux; ``rss_total_mib`` is the peak of that sum,
  ``rss_compiler_mib`` the peak of the compiler processes together, ``rss_python_mib`` the
  child's own peak (``getrusage``).  (``getrusage(RUSAGE_CHILDREN)`` cannot give the
  compiler's memory: a child started by ``vfork``/``posix_spawn`` inherits the parent's
  high-water mark until it ``exec``s, so it reports the Python process again.)
- **warm**: a new process with the cache now filled runs the whole user script: import
  mbcomp, build the chain, compile (a cache hit), simulate 1 s (compiled DOP853, rtol 1e-8).
  ``warm_total_s`` is the wall time from starting the interpreter to its exit, seen by the
  parent; the phases are timed inside it; ``warm_sympy`` says whether sympy got imported.

Medians over the rounds go to ``bench/results/compile_startup.csv`` (every round to
``compile_startup_rounds.csv``) and are printed as a table.
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

CHILD = r"""
import json, resource, sys, time
started = time.perf_counter()
import mbcomp
imported = time.perf_counter()
if {mode!r} == "cold":
    import sympy  # what the first compile would import (an import, timed apart)
sympy_imported = time.perf_counter()
sys.path.insert(0, {here!r})
from models import chain_initial_state, pendulum_chain
n, mode = {n}, {mode!r}
model = pendulum_chain(n)
built = time.perf_counter()
system = model.compile(backend="c")
compiled = time.perf_counter()
if mode == "cold":  # the output functions (energy, body states) build in the background
    getattr(system._compiled, "wait_for_background", lambda: None)()  # (older trees: with the model)
outputs = time.perf_counter()
out = {{"import_s": imported - started, "sympy_import_s": sympy_imported - imported,
        "build_s": built - sympy_imported, "compile_s": compiled - built, "outputs_s": outputs - compiled,
        "cache_hit": bool(system._compiled.cache_hit), "mbcomp": mbcomp.__file__}}
if mode == "warm":
    q, qd = chain_initial_state(n)
    result = system.simulate(1.0, q, qd)
    done = time.perf_counter()
    out.update(simulate_s=done - compiled, in_process_s=done - started, q_end=float(result.q[-1][-1]),
               sympy="sympy" in sys.modules, scipy_integrate="scipy.integrate" in sys.modules)
own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
out["cpu_s"] = own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime  # this process and the compilers
kib = 1024 if sys.platform != "darwin" else 1024 * 1024
out["rss_python_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / kib
out["rss_compiler_mib"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / kib
print("RESULT " + json.dumps(out))
"""


#: Where the children keep Python's bytecode with ``--bytecode`` (None: as the environment says).
BYTECODE: str | None = None


def run_child(n: int, mode: str, cache: str, tree: str | None) -> dict:
    """One fresh interpreter (``mode`` "cold" or "warm") with ``cache`` as its code cache
    and mbcomp imported from ``tree`` (None: as this process would)."""
    env = {**os.environ, "MBCOMP_CACHE_DIR": cache, "MPLBACKEND": "Agg"}
    if tree is not None:
        env["PYTHONPATH"] = tree
    if BYTECODE is not None:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = os.path.join(BYTECODE, Path(tree or "default").name)
    started = time.perf_counter()
    with tempfile.TemporaryFile("w+") as stdout, tempfile.TemporaryFile("w+") as stderr:
        child = subprocess.Popen([sys.executable, "-c", CHILD.format(here=str(HERE), n=n, mode=mode)],
                                 stdout=stdout, stderr=stderr, text=True, env=env,
                                 cwd=tree or tempfile.gettempdir())  # "-c" puts the working directory first on the path
        total, compilers = tree_peak_rss(child) if mode == "cold" else (float("nan"), float("nan"))
        child.wait()
        wall = time.perf_counter() - started
        stdout.seek(0)
        stderr.seek(0)
        text, errors = stdout.read(), stderr.read()
    lines = [line for line in text.splitlines() if line.startswith("RESULT ")]
    if child.returncode or not lines:
        raise RuntimeError(f"N = {n} {mode}: the child failed:\n{errors[-3000:]}")
    out = json.loads(lines[-1][len("RESULT "):])
    out["wall_s"] = wall
    out["tree_rss_mib"], out["compilers_rss_mib"] = total, compilers
    return out


def _rss_mib(pid: int) -> float:
    """Resident memory of process ``pid`` (MiB; 0 when it is gone)."""
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (OSError, ValueError, IndexError):
        return 0.0


def _descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (Linux ``/proc/<pid>/task/<tid>/children``)."""
    found, todo = [], [pid]
    while todo:
        p = todo.pop()
        try:
            tasks = os.listdir(f"/proc/{p}/task")
        except OSError:
            continue
        for tid in tasks:
            try:
                with open(f"/proc/{p}/task/{tid}/children") as f:
                    kids = [int(k) for k in f.read().split()]
            except OSError:
                continue
            found += kids
            todo += kids
    return found


def tree_peak_rss(child: subprocess.Popen, period: float = 0.003) -> tuple[float, float]:
    """``(peak of the resident memory of child and all its descendants together, peak of the
    descendants alone)`` in MiB, sampled every ``period`` s until the child exits (NaN where
    ``/proc`` cannot tell)."""
    if not os.path.exists(f"/proc/{child.pid}/task"):
        return float("nan"), float("nan")
    total = below = 0.0
    while child.poll() is None:
        own = _rss_mib(child.pid)
        rest = sum(_rss_mib(k) for k in _descendants(child.pid))
        total, below = max(total, own + rest), max(below, rest)
        time.sleep(period)
    return total, below


def measure(n: int, tree: str | None) -> dict:
    """One round for size ``n``: cold in an empty cache, then warm from it."""
    with tempfile.TemporaryDirectory(prefix="mbcomp-bench-cache-") as cache:
        cold = run_child(n, "cold", cache, tree)
        assert not cold["cache_hit"], "the cold run found its code in an empty cache"
        warm = run_child(n, "warm", cache, tree)
        assert warm["cache_hit"], "the warm run did not find the code the cold run stored"
    cold_s = cold["compile_s"] + cold["build_s"]
    return {"tree": Path(tree).name if tree else "", "N": n, "import_s": cold["import_s"],
            "sympy_import_s": cold["sympy_import_s"], "cold_s": cold_s,
            "cold_with_sympy_s": cold_s + cold["sympy_import_s"], "cold_with_outputs_s": cold_s + cold["outputs_s"],
            "cold_total_cpu_s": cold["cpu_s"],
            "rss_python_mib": cold["rss_python_mib"], "rss_compiler_mib": cold["compilers_rss_mib"],
            "rss_total_mib": cold["tree_rss_mib"],
            "warm_total_s": warm["wall_s"], "warm_import_s": warm["import_s"],
            "warm_load_s": warm["build_s"] + warm["compile_s"], "warm_simulate_s": warm["simulate_s"],
            "warm_sympy": warm["sympy"], "warm_scipy_integrate": warm["scipy_integrate"]}


def run(sizes: list[int], rounds: int, trees: list[str | None]) -> list[dict]:
    from models import write_csv
    every = []
    for r in range(rounds):
        for n, tree in [(n, tree) for n in sizes for tree in trees]:
            row = {"round": r, **measure(n, tree)}
            every.append(row)
            print(", ".join(f"{k}={v:.3g}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()),
                  flush=True)
    medians = []
    for n in sizes:
        for tree in trees:
            rows = [row for row in every if row["N"] == n and row["tree"] == (Path(tree).name if tree else "")]
            medians.append({k: (statistics.median(row[k] for row in rows) if isinstance(rows[0][k], float)
                                else rows[0][k]) for k in rows[0] if k != "round"})
    write_csv(every, "compile_startup_rounds.csv")
    write_csv(medians, "compile_startup.csv")
    print()
    print("| tree | N | imports: mbcomp + sympy (s) | cold compile (s) | with the output functions (s) "
          "| with sympy's import (s) | peak RSS: Python, compilers, whole tree (MiB) "
          "| new process, warm cache, to a 1 s result (s) | of which imports (s) | sympy imported |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for m in medians:
        print(f"| {m['tree']} | {m['N']} | {m['import_s']:.2f} + {m['sympy_import_s']:.2f} | {m['cold_s']:.2f} "
              f"| {m['cold_with_outputs_s']:.2f} "
              f"| {m['cold_with_sympy_s']:.2f} | {m['rss_python_mib']:.0f}, {m['rss_compiler_mib']:.0f}, "
              f"{m['rss_total_mib']:.0f} | {m['warm_total_s']:.2f} "
              f"| {m['warm_import_s']:.2f} | {'yes' if m['warm_sympy'] else 'no'} |")
    return medians


if __name__ == "__main__":
    args = sys.argv[1:]
    rounds = 3
    if "--rounds" in args:
        i = args.index("--rounds")
        rounds = int(args[i + 1])
        del args[i:i + 2]
    if "--bytecode" in args:
        args.remove("--bytecode")
        BYTECODE = tempfile.mkdtemp(prefix="mbcomp-bench-pyc-")
    trees: list[str | None] = [None]
    if "--trees" in args:
        i = args.index("--trees")
        trees = [str(Path(t).resolve()) for t in args[i + 1:]]
        del args[i:]
    run([int(a) for a in args] or [5, 10, 20, 50], rounds, trees)
