"""Ctrl-C during a compiled integration raises KeyboardInterrupt promptly (the compiled loops
call back into Python every so often), and a sweep stops its remaining cases."""
from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import integrators
from mbcomp.codegen.backend import c_compiler
from conftest import pendulum_chain, time_limit

pytestmark = [pytest.mark.skipif(c_compiler() is None, reason="no C compiler"),
              pytest.mark.skipif(not hasattr(signal, "pthread_kill") or not hasattr(signal, "setitimer"),
                                 reason="needs signal.pthread_kill and signal.setitimer")]

#: Long enough that finishing it would take minutes: an interrupt must stop it early.
LONG = 1e6


#: A lost interrupt fails its test after this many seconds instead of hanging the suite.
TIME_LIMIT = 60.0


@pytest.fixture(autouse=True)
def _own_sigint_handler_and_a_time_limit():
    """Each test starts with Python's own Ctrl-C handler (no other test's left behind), and
    an interrupt that does not stop its run fails the test after ``TIME_LIMIT`` s (SIGALRM,
    whose handler the compiled loop's hook runs like Ctrl-C's) instead of running for hours."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with time_limit(TIME_LIMIT):
            yield
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="module")
def chain():
    return pendulum_chain(4).compile(backend="c")


def _interrupt_after(seconds: float) -> threading.Timer:
    """Send SIGINT to this process's main thread after ``seconds`` (as Ctrl-C does)."""
    main = threading.main_thread().ident
    timer = threading.Timer(seconds, signal.pthread_kill, (main, signal.SIGINT))
    timer.start()
    return timer


def _warm_up(system, method: str) -> None:
    """One short run first, so that what a process does on its first run (modules imported
    on first use) is done before the interrupt is timed: on a loaded machine it could take
    longer than the delay, and Ctrl-C would then land before the compiled loop starts."""
    system.simulate(0.01, np.full(4, 0.5), method=method, integrator="compiled", t_eval=[0.0, 0.01],
                    **({"dt": 1e-3} if method == "RK4" else {}))


def _where(exc: BaseException) -> float:
    """The simulated time the interrupt note reports."""
    notes = " ".join(getattr(exc, "__notes__", []))
    assert "interrupted at t = " in notes, notes
    return float(notes.split("interrupted at t = ")[1].split()[0])


@pytest.mark.parametrize("method, extra", [("DOP853", {"t_eval": [0.0, LONG]}), ("DOP853", {}),
                                           ("RK4", {"dt": 1e-3, "max_samples": 10 ** 7 + 1})],
                         ids=["dop853-dense", "dop853-steps", "rk4"])
def test_ctrl_c_stops_a_compiled_run(chain, method, extra):
    q0 = np.full(4, 0.5)
    _warm_up(chain, method)
    timer = _interrupt_after(0.3)
    try:
        with pytest.raises(KeyboardInterrupt) as info:
            chain.simulate(LONG if method != "RK4" else 1e4, q0, method=method, integrator="compiled", **extra)
    finally:
        timer.cancel()
    assert 0.0 < _where(info.value) < (LONG if method != "RK4" else 1e4)


def test_a_run_after_an_interrupt_is_unaffected(chain):
    q0 = np.full(4, 0.5)
    _warm_up(chain, "DOP853")
    timer = _interrupt_after(0.2)
    try:
        with pytest.raises(KeyboardInterrupt):
            chain.simulate(LONG, q0, t_eval=[0.0, LONG], integrator="compiled")
    finally:
        timer.cancel()
    a = chain.simulate(1.0, q0, integrator="compiled")
    b = chain.simulate(1.0, q0, integrator="scipy")
    np.testing.assert_allclose(a.q[-1], b.q[-1], rtol=1e-9, atol=1e-12)


def test_the_step_hook_reports_progress_and_can_stop_a_run(chain):
    """The periodic hook (also for progress displays): it gets the simulated time, and a
    true return stops the run with a SimulationError saying where."""
    seen = []

    def hook(t):
        seen.append(t)
        return len(seen) >= 3

    with pytest.raises(mb.SimulationError, match="stopped at t = "):
        with integrators.step_hook(hook, interval=0.0):
            chain.simulate(LONG, np.full(4, 0.5), t_eval=[0.0, LONG], integrator="compiled")
    assert len(seen) == 3 and 0.0 < seen[0] < seen[1] < seen[2] < LONG


def test_a_run_leaves_the_sigint_handler_as_it_found_it(chain):
    """During a run SIGINT only sets a flag; afterwards the caller's own handler is back."""
    seen = []

    def mine(signum, frame):
        seen.append(signum)

    previous = signal.signal(signal.SIGINT, mine)
    try:
        chain.simulate(0.5, np.full(4, 0.5), integrator="compiled")
        assert signal.getsignal(signal.SIGINT) is mine
        signal.raise_signal(signal.SIGINT)
        assert seen == [signal.SIGINT]
    finally:
        signal.signal(signal.SIGINT, previous)


def test_a_run_nested_in_a_hook_callback_keeps_the_outer_runs_hook(chain):
    """A callback that runs a simulation of its own: the inner run uses (and then gives
    back) the one compiled callback, the outer run keeps calling its hook and can be
    stopped by it; the inner run's result equals a run outside any hook."""
    calls, inner = [], []

    def hook(t):
        calls.append(t)
        if len(calls) == 1:
            inner.append(chain.simulate(0.5, np.full(4, 0.3), integrator="compiled").q[-1])
        return len(calls) >= 3

    with pytest.raises(mb.SimulationError, match="stopped at t = "):
        with integrators.step_hook(hook, interval=0.0):
            chain.simulate(200.0, np.full(4, 0.5), t_eval=[0.0, 200.0], integrator="compiled")  # (finite:
            # an outer run that lost its hook finishes, and pytest.raises fails)
    assert len(calls) == 3 and calls[0] < calls[1] < calls[2]
    np.testing.assert_array_equal(inner[0], chain.simulate(0.5, np.full(4, 0.3), integrator="compiled").q[-1])


def test_a_sweep_stops_its_remaining_cases_on_ctrl_c(chain):
    cases = [{"q0": np.full(4, 0.1 * i), "t_end": LONG, "t_eval": [0.0, LONG]} for i in range(1, 9)]
    timer = _interrupt_after(0.5)
    try:
        with pytest.raises(KeyboardInterrupt):
            mb.sweep(chain, cases, threads=2, integrator="compiled")
    finally:
        timer.cancel()
    # Every worker has stopped: no compiled run is still going.
    assert not [t for t in threading.enumerate() if t.name.startswith("ThreadPoolExecutor")]
