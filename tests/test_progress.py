"""Progress bars watch a run and never change it: the same integrator, bit-identical results."""
import numpy as np
import pytest

import mbcomp as mb
from mbcomp.run import simulate as simulate_module
from mbcomp.core.progress import ProgressBar


@pytest.fixture
def watched(monkeypatch):
    """Report often (so even a short run is watched many times) and record what the bar shows."""
    shown = []
    original = ProgressBar.update_to
    monkeypatch.setattr(simulate_module, "PROGRESS_INTERVAL", 1e-4)

    def spy(self, value):
        if value is not None:
            shown.append(float(value))
        return original(self, value)

    monkeypatch.setattr(ProgressBar, "update_to", spy)
    return shown


@pytest.fixture(scope="module")
def chain():
    return mb.load("five_link_pendulum").compile()


@pytest.mark.parametrize("t_eval", [None, np.linspace(0, 40.0, 4001)])
def test_compiled_run_with_a_bar_is_bit_identical(chain, watched, capsys, t_eval):
    q0 = np.linspace(0.3, 1.1, chain.nq)
    # 40 s of a five-link chain at tight tolerances: long enough (~0.1 s) to be watched mid-run.
    plain = chain.simulate(40.0, q0, t_eval=t_eval, rtol=1e-11, atol=1e-12)
    barred = chain.simulate(40.0, q0, t_eval=t_eval, rtol=1e-11, atol=1e-12, progress=True)
    assert plain.stats["integrator"] == barred.stats["integrator"] == "compiled"
    assert np.array_equal(plain.t, barred.t) and np.array_equal(plain.q, barred.q)
    assert np.array_equal(plain.qd, barred.qd)
    assert plain.stats["nfev"] == barred.stats["nfev"]
    # The bar followed the run: it saw times strictly inside, in order, and ended at t_end.
    inside = [v for v in watched if 0.0 < v < 40.0]
    assert inside and inside == sorted(inside)
    assert max(watched) == pytest.approx(40.0)
    assert "simulating" in capsys.readouterr().err


def test_scipy_run_with_a_bar_is_bit_identical(watched):
    system = mb.load("bouncing_ball").compile()
    plain = system.simulate(1.0, [1.0], integrator="scipy")
    barred = system.simulate(1.0, [1.0], progress=True, integrator="scipy")
    assert plain.stats.get("integrator") == "scipy"
    assert np.array_equal(plain.t, barred.t) and np.array_equal(plain.q, barred.q)
    assert watched and max(watched) == pytest.approx(1.0)


def test_compiled_only_run_accepts_a_bar(chain):
    res = chain.simulate(0.2, np.zeros(chain.nq) + 0.1, integrator="compiled", progress=True)
    assert res.stats["integrator"] == "compiled" and res.t[-1] == pytest.approx(0.2)


def test_text_bar_without_tqdm(monkeypatch, capsys):
    import builtins
    real_import = builtins.__import__

    def no_tqdm(name, *args, **kwargs):
        if name == "tqdm":
            raise ImportError("no tqdm")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_tqdm)
    bar = ProgressBar(2.0, desc="simulating", unit="s")
    for value in (0.5, 0.25, 1.0, 5.0):      # never backwards, clipped at the total
        bar.update_to(value)
    bar.close()
    err = capsys.readouterr().err
    assert "[#######.......................]  25% 0.5/2 s" in err
    assert " 50% 1/2 s" in err and "100% 2/2 s" in err and err.endswith("\n")
    assert bar.value == 2.0


def test_delayed_bar_stays_quiet_on_short_runs(monkeypatch, capsys):
    monkeypatch.setattr("builtins.__import__", _without("tqdm"))
    bar = ProgressBar(1.0, delay=60.0)
    bar.update_to(0.5)
    bar.close()
    assert capsys.readouterr().err == ""


def _without(module):
    import builtins
    real_import = builtins.__import__

    def guarded(name, *args, **kwargs):
        if name == module:
            raise ImportError(f"no {module}")
        return real_import(name, *args, **kwargs)
    return guarded


def test_sweep_with_a_bar_counts_cases(watched, capsys):
    system = mb.load("double_pendulum").compile()
    cases = [{"q0": [a, 0.0]} for a in (0.1, 0.2, 0.3, 0.4)]
    plain = mb.sweep(system, cases, t_end=0.5)
    barred = mb.sweep(system, cases, t_end=0.5, progress=True)
    for a, b in zip(plain, barred):
        assert np.array_equal(a.q, b.q)
    assert max(watched) == 4 and "cases" in capsys.readouterr().err


def test_a_run_over_before_the_first_report_still_ends_the_bar(chain, monkeypatch, watched):
    monkeypatch.setattr(simulate_module, "PROGRESS_INTERVAL", 100.0)
    res = chain.simulate(0.01, np.zeros(chain.nq) + 0.1, progress=True)
    assert res.stats["integrator"] == "compiled" and watched == [0.01]
