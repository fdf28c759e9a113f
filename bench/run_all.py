"""Run every side-by-side benchmark of the speed issue and write the tables and the figure.

    python bench/run_all.py              # everything, ~30-40 min on 2 cores
    python bench/run_all.py --quick      # smoke run: N = 5, one round, every other setting, 100-run batch
    python bench/run_all.py --sizes 5 10 --rounds 5 --only chain calls
    python bench/run_all.py --only chain --update   # re-measure one part, keep the others' sections

Parts (each its own script, see bench/README.md): ``chain`` (work-precision, N = 5, 10, 20,
50; work_precision.py), ``fourbar`` (fourbar.py), ``contact`` (contact.py), ``batch``
(batch_rollout.py), ``calls`` (call_cost.py), ``compile`` (compile_startup.py: cold
compile, warm new process, peak memory; each in fresh processes).

Writes bench/results/*.csv, bench/results/work_precision.png and bench/results/summary.md:
the target ratios of the issue, each marked PASS or FAIL, from this one run.
"""
from __future__ import annotations

import argparse
import datetime
import importlib.util
import math
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"
sys.path.insert(0, str(HERE))

from timing import fmt  # noqa: E402

PARTS = ("chain", "fourbar", "contact", "batch", "calls", "compile")
#: The heading each part's section of summary.md starts with, and its row in the overview.
HEADINGS = {"chain": "## Work-precision", "fourbar": "## Four-bar", "contact": "## Contact", "batch": "## Batch",
            "calls": "## One public call", "compile": "## Compile"}
OVERVIEW = {"chain": "work-precision", "fourbar": "four-bar", "batch": "batch", "calls": "calls",
            "compile": "compile"}
COLD_TARGETS = {5: 0.5, 10: 0.7, 20: 1.5, 50: 4.0}


def verdict(value: float, limit: float, mbcomp_time: float = 0.0) -> str:
    """PASS / FAIL of a ratio; a level mbcomp never reached (``mbcomp_time`` nan) is a FAIL."""
    if mbcomp_time is None or not math.isfinite(mbcomp_time):
        return "**FAIL** (not reached)"
    if value is None or not math.isfinite(value):
        return "n/a"
    return "PASS" if value <= limit else "**FAIL**"


def environment() -> list[str]:
    """Lines describing what was measured where."""
    versions = []
    for name in ("mbcomp", "numpy", "scipy", "mujoco", "pinocchio", "exudyn"):
        try:
            module = __import__(name)
            versions.append(f"{name} {getattr(module, '__version__', '?')}")
        except ImportError:
            versions.append(f"{name} not installed")
    try:
        rev = subprocess.run(["git", "-C", str(HERE), "rev-parse", "--short", "HEAD"], capture_output=True,
                             text=True, check=False).stdout.strip()
    except OSError:
        rev = "?"
    load = os.getloadavg() if hasattr(os, "getloadavg") else ("?",)
    return [f"- date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC; mbcomp commit {rev or '?'}",
            f"- machine: {platform.machine()}, {os.cpu_count()} cores, load average at the start "
            f"{', '.join(f'{x:.1f}' for x in load)}; Python {platform.python_version()}",
            f"- {'; '.join(versions)}"]


def verdict_clock(choice: str, load: float | None = None, cores: int | None = None) -> str:
    """The clock the chain's verdicts use: ``"wall"`` or ``"cpu"`` as asked, or for ``"auto"``
    wall time on a machine with a free core (1-minute load average below the core count at the
    start) and process CPU time on an oversubscribed one, where a run's wall time is mostly
    waiting for a core (every tool of the chain runs on one thread, so CPU time is its work)."""
    if choice != "auto":
        return choice
    if load is None:
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else 0.0
    cores = cores or os.cpu_count() or 1
    return "wall" if load < cores else "cpu"


def chain_section(results: list[dict], clock: str = "wall") -> tuple[list[str], list[bool]]:
    """The chain's level table; times, settings and the verdicts by ``clock`` ("wall" or
    "cpu"), the ratios by both clocks."""
    from work_precision import SHORT
    why = ("wall time" if clock == "wall" else
           "process CPU time (the machine was oversubscribed at the start: wall time there is mostly waiting "
           "for a core; every tool runs on one thread)")
    lines = ["## Work-precision, N-link chain (target: mbcomp / fastest peer <= 0.5 at every level)", "",
             f"Fastest {'wall' if clock == 'wall' else 'CPU'} time (ms, median of rounds) to reach "
             "max |q - q_ref| <= level; ratio = fastest mbcomp setting / fastest peer setting, by wall and by "
             f"CPU time; the target column is judged by {why}. "
             "Figure: `work_precision.png`; every point: `work_precision_N*.csv`.", "",
             f"| N (horizon) | error <= | mbcomp (ms) | mbcomp setting | fastest peer (ms) | fastest peer | ratio "
             f"| ratio by CPU time | target ({clock}) |", "|---|---|---|---|---|---|---|---|---|"]
    oks = []
    for res in results:
        wall = {e["level"]: e for e in res["table"] if e["clock"] == "wall"}
        cpu = {e["level"]: e for e in res["table"] if e["clock"] == "cpu"}
        judged = wall if clock == "wall" else cpu
        for level, e in judged.items():
            v = verdict(e["ratio"], 0.5, e["mbcomp_time"])
            oks.append(v == "PASS")
            lines.append(f"| {res['N']} ({res['t_end']:g} s) | {level:.0e} | {fmt(e['mbcomp_time'] * 1e3)} "
                         f"| {SHORT.get(e['mbcomp_fastest'], '-')} | {fmt(e['peer_time'] * 1e3)} "
                         f"| {SHORT.get(e['fastest_peer'], '-')} | {fmt(wall[level]['ratio'], 2)} "
                         f"| {fmt(cpu[level]['ratio'], 2)} | {v} |")
        if len(wall) < 7:
            lines.append(f"| {res['N']} | below {3 * res['uncertainty']:.0e} | not resolved by the reference "
                         f"(uncertainty {res['uncertainty']:.1e} rad) | | | | | | |")
    return lines, oks


def fourbar_section(result: dict) -> tuple[list[str], list[bool]]:
    from fourbar import DAE, LAGRANGE, MUJOCO
    wall = [e for e in result["table"] if e["clock"] == "wall"]
    cpu = {e["level"]: e for e in result["table"] if e["clock"] == "cpu"}
    lines = ["## Four-bar, 10 s (target at 1e-6: lagrange <= 1 and dae <= 1 against MuJoCo's C loop)", "",
             f"mbcomp lagrange runs in: {wall[0]['lagrange_integrator']}; dae in: {wall[0]['dae_integrator']}. "
             "Times in ms (median); ratio = mbcomp / MuJoCo (rollout, RK4, stiffest equality).", "",
             "| error <= | lagrange | dae | MuJoCo | lagrange / MuJoCo | dae / MuJoCo | by CPU time | target |",
             "|---|---|---|---|---|---|---|---|"]
    oks = []
    for e in wall:
        c = cpu[e["level"]]
        if e["level"] == 1e-6:
            vl, vd = verdict(e["ratio_lagrange"], 1, e[LAGRANGE]), verdict(e["ratio_dae"], 1, e[DAE])
            targets = f"lagrange {vl}, dae {vd}"
            oks += [vl == "PASS", vd == "PASS"]
        else:
            targets = "(info)"
        lines.append(f"| {e['level']:.0e} | {fmt(e[LAGRANGE] * 1e3)} | {fmt(e[DAE] * 1e3)} "
                     f"| {fmt(e.get(MUJOCO, math.nan) * 1e3)} | {fmt(e['ratio_lagrange'], 2)} | {fmt(e['ratio_dae'], 2)} "
                     f"| {fmt(c['ratio_lagrange'], 2)}, {fmt(c['ratio_dae'], 2)} | {targets} |")
    return lines, oks


def contact_section(result: dict) -> list[str]:
    from contact import MBCOMP, MUJOCO
    wall = [e for e in result["table"] if e["clock"] == "wall"]
    best_mj = min((r["error"] for r in result["rows"] if r["label"] == MUJOCO), default=math.nan)
    lines = ["## Contact: bouncing ball, restitution 0.8, 2 s (no target; measured)", "",
             f"mbcomp runs in: {wall[0]['mbcomp_integrator']}. Error |z(2 s) - z_exact| (m). MuJoCo's soft contact "
             f"(calibrated to rebound 0.8) reached at best {fmt(best_mj, 2)} m.", "",
             "| error <= (m) | mbcomp (ms) | MuJoCo (ms) | mbcomp / MuJoCo |", "|---|---|---|---|"]
    for e in wall:
        lines.append(f"| {e['level']:.0e} | {fmt(e[MBCOMP] * 1e3)} | {fmt(e.get(MUJOCO, math.nan) * 1e3)} "
                     f"| {fmt(e['ratio'], 2)} |")
    return lines


def batch_section(result: dict) -> tuple[list[str], list[bool]]:
    rows = {r["label"]: r for r in result["rows"]}
    if not rows:
        return ["## Batch: not run (MuJoCo missing)"], []
    dop, rk4, mj = rows["mbcomp mb.sweep DOP853"], rows["mbcomp mb.sweep RK4"], rows["MuJoCo rollout RK4"]
    v1, v2 = verdict(dop["ratio_to_rollout"], 0.5), verdict(rk4["ratio_to_rollout"], 1.0)
    lines = [f"## Batch: {mj['count']} runs of the 5-link chain, 10 s, {mj['threads']} threads each "
             "(targets: <= 0.5 at 1e-6; <= 1 at the same RK4 step)", "",
             "| runner | setting | wall time (s) | CPU time (s) | max error on 20 sampled runs | / rollout | target |",
             "|---|---|---|---|---|---|---|",
             f"| MuJoCo `rollout` RK4 | {mj['value']} steps | {fmt(mj['time'])} | {fmt(mj['cpu_time'])} "
             f"| {mj['sample_error']:.1e} | 1 | |",
             f"| mbcomp `mb.sweep` DOP853 | rtol {dop['value']:.2g} | {fmt(dop['time'])} | {fmt(dop['cpu_time'])} "
             f"| {dop['sample_error']:.1e} | {fmt(dop['ratio_to_rollout'], 2)} | {v1} |",
             f"| mbcomp `mb.sweep` RK4, same step | {rk4['value']} steps | {fmt(rk4['time'])} | {fmt(rk4['cpu_time'])} "
             f"| {rk4['sample_error']:.1e} | {fmt(rk4['ratio_to_rollout'], 2)} | {v2} |"]
    return lines, [v1 == "PASS", v2 == "PASS"]


def calls_section(rows: list[dict]) -> tuple[list[str], list[bool]]:
    lines = ["## One public call (target: `System.accelerations` <= 1.5x `pin.aba`)", "",
             "| N | `System.accelerations` (us) | `pin.aba` (us) | MuJoCo set + `mj_forward` + qacc (us) | ratio "
             "| ratio by wall time | target |", "|---|---|---|---|---|---|---|"]
    oks = []
    for r in rows:
        v = verdict(r.get("ratio accelerations / aba", math.nan), 1.5)
        oks.append(v == "PASS")
        lines.append(f"| {r['N']} | {fmt(r['mbcomp System.accelerations us'])} | {fmt(r.get('pin.aba us', math.nan))} "
                     f"| {fmt(r.get('MuJoCo set + mj_forward + qacc us', math.nan))} "
                     f"| {fmt(r.get('ratio accelerations / aba', math.nan), 2)} "
                     f"| {fmt(r.get('ratio accelerations / aba (wall)', math.nan), 2)} | {v} |")
    lines.append("")
    lines.append("CPU time of the calling thread, median of interleaved rounds of ~10 ms timeit loops.")
    return lines, oks


def compile_section(rows: list[dict] | None, note: str) -> tuple[list[str], list[bool]]:
    lines = ["## Compile and start-up (targets: cold <= 0.5 / 0.7 / 1.5 / 4 s for N = 5 / 10 / 20 / 50; "
             "warm new process to a 1 s result of N = 10 <= 0.3 s; peak memory compiling N = 50 <= 300 MiB)", ""]
    if not rows:
        return lines + [note], []
    lines += ["| N | cold compile (s) | target | imports (s) | warm new process to a 1 s result (s) | peak RSS "
              "Python + C compiler (MiB) |", "|---|---|---|---|---|---|"]
    oks = []
    for r in rows:
        n = int(r["N"])
        v = verdict(r["cold_s"], COLD_TARGETS.get(n, math.inf)) if n in COLD_TARGETS else "(info)"
        if n in COLD_TARGETS:
            oks.append(v == "PASS")
        warm = f"{fmt(r['warm_total_s'])}" + (f" ({verdict(r['warm_total_s'], 0.3)})" if n == 10 else "")
        rss = f"{fmt(r['rss_total_mib'])}" + (f" ({verdict(r['rss_total_mib'], 300)})" if n == 50 else "")
        if n == 10:
            oks.append(r["warm_total_s"] <= 0.3)
        if n == 50:
            oks.append(r["rss_total_mib"] <= 300)
        lines.append(f"| {n} | {fmt(r['cold_s'])} | {v} | {fmt(r['import_s'])} | {warm} | {rss} |")
    lines += ["", note]
    return lines, oks


def run_compile(sizes, rounds, log=print):
    """Cold / warm-process compile and memory via compile_startup.py when present."""
    if importlib.util.find_spec("compile_startup") is None:
        return None, ("`bench/compile_startup.py` is not in this tree: compile time, warm start-up and memory "
                      "were not measured (see `bench/chain_compile.py` for the in-process cold/cached times).")
    # In a process of its own: a child's peak RSS (getrusage) starts from the high-water mark
    # of the process it was forked from, and this one holds the other parts' buffers.
    import csv
    log(f"compile and start-up, N = {list(sizes)} (fresh processes)")
    done = subprocess.run([sys.executable, str(HERE / "compile_startup.py"), *map(str, sizes), "--rounds", str(rounds)],
                          capture_output=True, text=True, check=False)
    if done.returncode:
        return None, f"`compile_startup.py` failed: {done.stderr[-500:]}"
    with open(RESULTS / "compile_startup.csv", newline="") as fh:
        rows = [{k: (float(v) if k not in ("tree", "warm_sympy", "warm_scipy_integrate") else v) for k, v in r.items()}
                for r in csv.DictReader(fh)]
    return rows, ("Each figure a median over rounds of fresh processes (`compile_startup.py`); peak RSS is "
                  "sampled over the whole process tree (Python and every C compiler process running at once).")


def chain_results_from_csv(sizes) -> list[dict]:
    """The chain results of the last measurement (``results/work_precision_levels.csv`` and
    ``work_precision_N*.csv``) as ``work_precision.run`` returns them, for ``--from-results``."""
    import csv
    with open(RESULTS / "work_precision_levels.csv", newline="") as fh:
        levels = list(csv.DictReader(fh))
    text = {"clock", "mbcomp_fastest", "fastest_peer"}
    out = []
    for n in sizes:
        with open(RESULTS / f"work_precision_N{n}.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        table = [{k: (v if k in text else int(v) if k == "N" else float(v) if v != "" else math.nan)
                  for k, v in e.items()} for e in levels if int(e["N"]) == n]
        if not table or not rows:
            raise SystemExit(f"no measured chain results for N = {n} in {RESULTS}")
        out.append({"N": n, "t_end": float(rows[0]["t_end"]), "rows": rows, "table": table,
                    "uncertainty": table[0]["reference_uncertainty"]})
    return out


def merge_chain_rows(lines: list[str], oks: list[bool], previous: list[str], sizes, date: str):
    """The chain table of this run with the previous summary's rows of the sizes not run
    again (``--update --sizes ...``), in order of N, and their verdicts."""
    def size_of(line):
        first = line.strip("|").split("|")[0].split()
        return int(first[0]) if first and first[0].isdigit() else None

    old_rows = [line for line in previous if line.startswith("| ") and size_of(line) not in (None, *sizes)]
    if not old_rows:
        return lines, oks
    table = [line for line in lines if line.startswith("| ") and size_of(line) is not None] + old_rows
    table.sort(key=size_of)  # (stable: the levels stay in order within a size)
    start = next(i for i, line in enumerate(lines) if line.startswith("|---"))
    kept_sizes = sorted({size_of(line) for line in old_rows})
    note = (f"Rows for N = {', '.join(map(str, kept_sizes))} are kept from the previous summary "
            f"({date.lstrip('- ') or 'undated'}; their target column as judged there); the others are from this run.")
    oks = oks + [line.rstrip().endswith("| PASS |") for line in old_rows if "level" not in line and "|" in line
                 and "not resolved" not in line]
    return lines[:start + 1] + table + ["", note], oks


def summary_intro(quick: bool, rounds: int, minutes: float, chain: bool) -> str:
    """The summary's first paragraph: how it was written and how to read the ratios (the
    chain's clock rule only when this run measured the chain)."""
    intro = (f"Written by `python bench/run_all.py{' --quick' if quick else ''}` "
             f"({'smoke run: one round, fewer settings' if quick else f'{rounds} interleaved rounds, medians'}; "
             f"{minutes:.1f} min). Ratios are mbcomp / fastest peer from this one run; a ratio below 1 means "
             "mbcomp is faster. Wall time is the primary figure on a machine with a free core; the machine may be "
             "shared, so CPU-time ratios are given too")
    return intro + (", and the chain's verdicts are judged by CPU time when it was oversubscribed (see its section)."
                    if chain else ".")


def previous_summary(path: Path) -> tuple[str, dict, dict]:
    """``(date line, {part: section lines}, {overview name: overview row})`` of an existing
    summary.md (``--update`` keeps the parts not run again); empty when there is none."""
    if not path.exists():
        return "", {}, {}
    lines = path.read_text().splitlines()
    date = next((line for line in lines if line.startswith("- date:")), "")
    sections, current = {}, None
    for line in lines:
        if line.startswith("## "):
            current = next((part for part, heading in HEADINGS.items() if line.startswith(heading)), None)
            if current is not None:
                sections[current] = []
        if current is not None:
            sections[current].append(line)
    for part in sections:
        while sections[part] and not sections[part][-1].strip():
            sections[part].pop()
    rows = {}
    for line in lines:
        cells = [c.strip() for c in line.strip("|").split("|")]
        if line.startswith("| ") and len(cells) == 3 and cells[0] in OVERVIEW.values():
            rows[cells[0]] = line
    return date, sections, rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="smoke run (a minute or two)")
    parser.add_argument("--sizes", type=int, nargs="+", default=None, help="chain sizes (default 5 10 20 50)")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds (medians)")
    parser.add_argument("--only", nargs="+", choices=PARTS, default=list(PARTS))
    parser.add_argument("--clock", choices=("auto", "wall", "cpu"), default="auto",
                        help="the clock of the chain's verdicts (auto: CPU time when the machine is oversubscribed)")
    parser.add_argument("--from-results", action="store_true",
                        help="chain: write the summary from the CSV files of the last measurement (no timing)")
    parser.add_argument("--update", action="store_true",
                        help="keep the sections of the existing summary.md for the parts not run (marked as such)")
    args = parser.parse_args(argv)
    kept_date, kept, kept_rows = previous_summary(RESULTS / "summary.md") if args.update else ("", {}, {})
    os.environ.setdefault("MPLBACKEND", "Agg")
    if "MBCOMP_CACHE_DIR" not in os.environ:
        import tempfile
        os.environ["MBCOMP_CACHE_DIR"] = tempfile.mkdtemp(prefix="mbcomp-bench-")
    quick, rounds = args.quick, (1 if args.quick else args.rounds)
    sizes = args.sizes or ([5] if quick else [5, 10, 20, 50])
    RESULTS.mkdir(exist_ok=True)
    started = time.perf_counter()
    head = environment()
    sections, verdicts = {}, {}

    def log(msg):
        print(f"[{time.perf_counter() - started:7.1f} s] {msg}", flush=True)

    if "chain" in args.only:
        import work_precision
        clock = verdict_clock(args.clock)
        if args.from_results:
            results = chain_results_from_csv(sizes)
            head.append("- chain section written from the CSV files of an earlier measurement (`--from-results`); "
                        "the machine and load lines above describe the moment it was written")
        else:
            results = [work_precision.run(n, rounds, quick, log=log) for n in sizes]
            from models import write_csv
            write_csv([e for res in results for e in res["table"]], "work_precision_levels.csv")
            work_precision.plot(results, RESULTS / "work_precision.png")
        lines, oks = chain_section(results, clock)
        if "chain" in kept:
            lines, oks = merge_chain_rows(lines, oks, kept["chain"], sizes, kept_date)
        sections["chain"] = lines
        verdicts["work-precision"] = oks
    if "fourbar" in args.only:
        import fourbar
        lines, oks = fourbar_section(fourbar.run(rounds, quick, log=log))
        sections["fourbar"] = lines
        verdicts["four-bar"] = oks
    if "contact" in args.only:
        import contact
        sections["contact"] = contact_section(contact.run(rounds, quick, log=log))
    if "batch" in args.only:
        import batch_rollout
        lines, oks = batch_section(batch_rollout.run(100 if quick else 1000, rounds, quick, log=log))
        sections["batch"] = lines
        verdicts["batch"] = oks
    if "calls" in args.only:
        import call_cost
        lines, oks = calls_section(call_cost.run([n for n in (5, 20, 50) if not quick or n in sizes] or sizes,
                                                 3 if quick else 7, log=log))
        sections["calls"] = lines
        verdicts["calls"] = oks
    if "compile" in args.only:
        rows, note = run_compile(sizes, 1 if quick else rounds, log=log)
        lines, oks = compile_section(rows, note)
        sections["compile"] = lines
        verdicts["compile"] = oks

    total = time.perf_counter() - started
    overview = ["| target | checks | passed |", "|---|---|---|"]
    for part, name in OVERVIEW.items():
        if name in verdicts:
            oks = verdicts[name]
            overview.append(f"| {name} | {len(oks)} | {sum(oks)} ({'PASS' if oks and all(oks) else '**FAIL**'}) |")
        elif name in kept_rows:
            overview.append(kept_rows[name])
    kept_parts = [part for part in PARTS if part not in sections and part in kept]
    if kept_parts:
        head.append(f"- this run measured: {', '.join(p for p in PARTS if p in sections)}; the sections "
                    f"{', '.join(kept_parts)} are kept from the previous summary ({kept_date.lstrip('- ') or 'undated'})")
    text = ["# Side-by-side benchmark summary", "", summary_intro(quick, rounds, total / 60, "chain" in sections),
            ""] + head + ["", *overview, ""]
    for part in PARTS:
        if part in sections:
            text += sections[part] + [""]
        elif part in kept:
            text += kept[part] + [""]
    (RESULTS / "summary.md").write_text("\n".join(text))
    print("\n".join(text))
    return verdicts


if __name__ == "__main__":
    main()
