"""bench/run_all.py --update: a partial run replaces its own sections (and, for the chain, its
own sizes' rows) of summary.md and keeps the rest, with the verdicts counted again."""
from __future__ import annotations

import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parents[1] / "bench"
sys.path.insert(0, str(BENCH))

import run_all  # noqa: E402

PREVIOUS = """# Side-by-side benchmark summary

- date: 2026-11-01 10:00 UTC; mbcomp commit abc1234
- machine: x86_64

| target | checks | passed |
|---|---|---|
| work-precision | 4 | 2 (**FAIL**) |
| four-bar | 2 | 2 (PASS) |

## Work-precision, N-link chain (target: mbcomp / fastest peer <= 0.5 at every level)

| N (horizon) | error <= | mbcomp (ms) | mbcomp setting | fastest peer (ms) | fastest peer | ratio | ratio by CPU time | target |
|---|---|---|---|---|---|---|---|---|
| 5 (10 s) | 1e-04 | 1 | mb DOP853 | 5 | MJ rollout | 0.2 | 0.2 | PASS |
| 5 (10 s) | 1e-05 | 2 | mb DOP853 | 8 | MJ rollout | 0.25 | 0.2 | PASS |
| 50 (1 s) | 1e-04 | 7 | mb DOP853 | 6 | MJ rollout | 1.2 | 0.9 | **FAIL** |
| 50 (1 s) | 1e-05 | 10 | mb DOP853 | 11 | pin LSODA | 0.9 | 0.9 | **FAIL** |

## Four-bar, 10 s (target at 1e-6: lagrange <= 1 and dae <= 1 against MuJoCo's C loop)

| error <= | lagrange |
|---|---|
| 1e-06 | 9.3 |
"""

NEW_CHAIN = ["## Work-precision, N-link chain (target: mbcomp / fastest peer <= 0.5 at every level)", "",
             "| N (horizon) | error <= | mbcomp (ms) | mbcomp setting | fastest peer (ms) | fastest peer | ratio "
             "| ratio by CPU time | target |", "|---|---|---|---|---|---|---|---|---|",
             "| 50 (1 s) | 1e-04 | 2 | mb DOP853 | 6 | pin LSODA | 0.33 | 0.4 | PASS |",
             "| 50 (1 s) | 1e-05 | 5 | mb DOP853 | 8 | pin LSODA | 0.62 | 0.5 | **FAIL** |"]


def test_previous_summary_reads_sections_rows_and_date(tmp_path):
    path = tmp_path / "summary.md"
    path.write_text(PREVIOUS)
    date, sections, rows = run_all.previous_summary(path)
    assert date.startswith("- date: 2026-11-01")
    assert sorted(sections) == ["chain", "fourbar"]
    assert sections["fourbar"][-1] == "| 1e-06 | 9.3 |"
    assert rows == {"work-precision": "| work-precision | 4 | 2 (**FAIL**) |", "four-bar": "| four-bar | 2 | 2 (PASS) |"}
    assert run_all.previous_summary(tmp_path / "missing.md") == ("", {}, {})


def test_chain_rows_of_other_sizes_are_kept_in_order_with_their_verdicts(tmp_path):
    path = tmp_path / "summary.md"
    path.write_text(PREVIOUS)
    date, sections, _ = run_all.previous_summary(path)
    lines, oks = run_all.merge_chain_rows(NEW_CHAIN, [True, False], sections["chain"], [50], date)
    table = [line for line in lines if line.startswith("| ") and line[2].isdigit()]
    assert [line.split("|")[1].strip() for line in table] == ["5 (10 s)", "5 (10 s)", "50 (1 s)", "50 (1 s)"]
    assert "0.33" in table[2] and "1.2" not in "".join(table)   # N = 50: this run's rows only
    assert oks == [True, False, True, True]                     # this run's two, then the kept N = 5 rows
    assert "Rows for N = 5 are kept from the previous summary (date: 2026-11-01 10:00 UTC" in lines[-1]
    # every size run again: nothing kept, nothing changed
    assert run_all.merge_chain_rows(NEW_CHAIN, [True, False], sections["chain"], [5, 50], date) == (NEW_CHAIN,
                                                                                                   [True, False])


def test_the_verdict_clock_is_cpu_time_only_on_an_oversubscribed_machine():
    assert run_all.verdict_clock("auto", load=1.2, cores=2) == "wall"
    assert run_all.verdict_clock("auto", load=9.5, cores=2) == "cpu"
    assert run_all.verdict_clock("wall", load=9.5, cores=2) == "wall"
    assert run_all.verdict_clock("cpu", load=0.0, cores=2) == "cpu"


def test_chain_verdicts_follow_the_chosen_clock():
    """Wall ratio 0.8 (FAIL), CPU ratio 0.3 (PASS) at one level: the target column follows
    the clock, both ratios are shown."""
    peer, mb = "Pinocchio aba + Fortran LSODA", "mbcomp DOP853 (compiled)"
    table = [{"N": 50, "clock": "wall", "level": 1e-4, "mbcomp_fastest": mb, "fastest_peer": peer,
              "mbcomp_time": 8e-3, "peer_time": 1e-2, "ratio": 0.8},
             {"N": 50, "clock": "cpu", "level": 1e-4, "mbcomp_fastest": mb, "fastest_peer": peer,
              "mbcomp_time": 1.5e-3, "peer_time": 5e-3, "ratio": 0.3}]
    results = [{"N": 50, "t_end": 1.0, "table": table, "uncertainty": 1e-13}]
    wall_lines, wall_oks = run_all.chain_section(results, "wall")
    cpu_lines, cpu_oks = run_all.chain_section(results, "cpu")
    assert wall_oks[0] is False and cpu_oks[0] is True
    row = next(line for line in cpu_lines if line.startswith("| 50 (1 s) | 1e-04"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[2] == "1.5" and cells[4] == "5" and cells[6:] == ["0.8", "0.3", "PASS"]
    assert "oversubscribed" in " ".join(cpu_lines) and "oversubscribed" not in " ".join(wall_lines)


def test_the_intro_is_whole_with_or_without_the_chain():
    """A partial run without the chain once wrote only the intro's last sentence."""
    for chain in (True, False):
        intro = run_all.summary_intro(False, 3, 0.6, chain)
        assert intro.startswith("Written by `python bench/run_all.py` (3 interleaved rounds, medians; 0.6 min).")
        assert "a ratio below 1 means mbcomp is faster" in intro
        assert ("oversubscribed" in intro) == chain and intro.endswith(".")
    assert "smoke run" in run_all.summary_intro(True, 1, 2.0, True)
