"""The constraint analysis (consistent configuration, rank, redundant rows) is kept in the code
cache: a later compile of the same model with the same parameter values reads it instead of
searching again, with exactly the numbers of the search; other values, a failure or a damaged
entry analyse afresh."""
from __future__ import annotations

import pytest

import mbcomp as mb
from conftest import fourbar, run_in_new_process
from mbcomp.formulations import analysis_cache
from mbcomp.formulations.analysis_cache import SUFFIX


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    path = tmp_path / "cache"
    monkeypatch.setenv("MBCOMP_CACHE_DIR", str(path))
    return path


def entries(path):
    return sorted(p.name for p in path.glob(f"*{SUFFIX}"))


def same_info(a, b):
    assert (a.ndof, a.nominal_rank, a.jacobian_scale, a.schur_scale, a.redundant) == \
        (b.ndof, b.nominal_rank, b.jacobian_scale, b.schur_scale, b.redundant)
    assert list(a.nominal_rows) == list(b.nominal_rows)


def test_a_second_compile_reads_the_analysis_with_the_numbers_of_the_search(cache_dir, monkeypatch):
    first = fourbar().compile(backend="python")
    assert len(entries(cache_dir)) == 1
    searched = fourbar().compile(backend="python", cache=False)._formulation.info   # analysed, not kept
    same_info(first._formulation.info, searched)
    monkeypatch.setattr(analysis_cache, "analyse", lambda *a: pytest.fail("analysed again"))
    again = fourbar().compile(backend="python")
    same_info(again._formulation.info, searched)
    assert again.ndof == 1 and again._formulation.info.nominal_rows.flags.writeable is False


def test_other_parameter_values_and_formulations_analyse_afresh(cache_dir):
    fourbar().compile(backend="python")
    longer = fourbar(L2=0.9).compile(backend="python")         # the same structure: one model key
    dae = fourbar().compile("dae", backend="python")
    assert len(entries(cache_dir)) == 3
    same_info(longer._formulation.info, fourbar(L2=0.9).compile(backend="python", cache=False)._formulation.info)
    same_info(dae._formulation.info, fourbar().compile("dae", backend="python", cache=False)._formulation.info)
    assert longer._formulation.info.schur_scale != fourbar().compile(backend="python")._formulation.info.schur_scale


def test_a_failed_analysis_is_not_kept(cache_dir):
    for _ in range(2):  # a coupler too short to reach the rocker: no configuration closes the loop
        with pytest.raises(mb.ModelError, match="cannot all be met"):
            fourbar(L1=0.1, L2=0.1, L3=0.1, d=2.0).compile(backend="python")
    assert entries(cache_dir) == []


def test_a_damaged_entry_is_analysed_again(cache_dir):
    expected = fourbar().compile(backend="python")._formulation.info
    (entry,) = entries(cache_dir)
    (cache_dir / entry).write_text('{"ndof": "one"}')   # (its manifest's hash no longer matches)
    same_info(fourbar().compile(backend="python")._formulation.info, expected)
    assert entries(cache_dir) == [entry]


def test_a_new_process_compiles_a_loop_without_the_search(cache_dir):
    expected = fourbar().compile(backend="python")._formulation.info
    out = run_in_new_process(
        "from conftest import fourbar\n"
        "info = fourbar().compile(backend='python')._formulation.info\n"
        "print(json.dumps({'optimize': 'scipy.optimize' in sys.modules, 'schur': info.schur_scale,"
        " 'rows': [int(r) for r in info.nominal_rows]}))\n")
    assert not out["optimize"]
    assert out["schur"] == expected.schur_scale and out["rows"] == list(expected.nominal_rows)
