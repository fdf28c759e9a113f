"""The one simulate driver: every library part runs in compiled code in both formulations unless a
scipy method is asked for (the library's models: ``test_cross_paths.py``); ``integration_path``
says which stepping a run takes and why; ``Result.stats`` has the same keys on every path;
``RunOptions`` checks the settings once."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.run_options import RunOptions
from mbcomp.files.library import library_parts
from mbcomp.files.toml_model import library_models, load

#: The library's parts, each a model of its own (the library's models: tests/test_cross_paths.py).
PARTS = library_parts()
STATS_KEYS = {"method", "integrator", "path", "rhs", "nfev", "njev", "nlu", "steps", "rejected", "restarts", "status",
              "message", "success", "wall_time", "rtol", "atol", "formulation"}

@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
@pytest.mark.parametrize("name", sorted(PARTS))
def test_every_library_part_runs_compiled(name, formulation):
    system = load(PARTS[name]).compile(formulation)
    if system.backend != "c":
        pytest.skip("no C compiler")
    assert system.integration_path() == "compiled", name
    # ... unless the user asks for scipy's stepping, which the answer names
    assert system.integration_path("Radau") == "scipy: scipy method 'Radau' requested (compiled loops: DOP853, RK4)"
    assert system.integration_path(integrator="scipy") == "scipy: integrator='scipy' requested"


@pytest.fixture(scope="module")
def pendulum():
    system = mb.load("double_pendulum").compile()
    if system.backend != "c":
        pytest.skip("no C compiler")
    return system


def test_a_python_callable_tau_stays_compiled(pendulum):
    tau = lambda t, q, qd: np.zeros(2)  # noqa: E731
    assert pendulum.integration_path(tau=tau) == "compiled"
    res = pendulum.simulate(0.1, [0.5, 0.2], tau=tau)
    assert res.stats["integrator"] == "compiled" and res.stats["path"] == "compiled"
    free = pendulum.simulate(0.1, [0.5, 0.2])  # a zero tau changes nothing
    np.testing.assert_array_equal(res.q, free.q)


def test_stats_have_the_same_keys_on_every_path(pendulum):
    q0 = [0.5, 0.2]
    runs = {"compiled": pendulum.simulate(0.2, q0), "scipy": pendulum.simulate(0.2, q0, integrator="scipy"),
            "radau": pendulum.simulate(0.2, q0, method="Radau"),
            "rk4": pendulum.simulate(0.2, q0, method="RK4", dt=0.01)}
    ball = mb.load("bouncing_ball").compile()
    model = load(library_models()["bouncing_ball"])
    q = np.array([model.initial["q"].get(c, 0.0) for c in ball.coords])
    runs["contacts"] = ball.simulate(0.5, q)
    for label, res in runs.items():
        assert set(res.stats) == STATS_KEYS, label
        # every step kept: one sample a step (and one more after each impact)
        assert res.stats["steps"] == len(res.t) - 1 - len(res.events), label
        assert res.stats["nfev"] > res.stats["steps"], label
    assert runs["compiled"].stats["path"] == runs["rk4"].stats["path"] == "compiled"
    assert runs["radau"].stats["path"].startswith("scipy: scipy method 'Radau'") and runs["radau"].stats["njev"] > 0
    assert runs["scipy"].stats["rejected"] is None and runs["compiled"].stats["rejected"] >= 0
    # the two steppings of DOP853 take the same steps (the compiled loop follows scipy's step for step)
    assert runs["compiled"].stats["steps"] == runs["scipy"].stats["steps"]
    np.testing.assert_allclose(runs["compiled"].q, runs["scipy"].q, rtol=0, atol=1e-6)


def test_run_options_check_every_setting_once():
    options = RunOptions.checked(2, t_eval=[0, 1, 2], rtol=1e-6)
    assert options.t_end == 2.0 and options.t_eval.dtype == float and options.method_name == "DOP853"
    assert options.replace(max_step=0.1).max_step == 0.1 and options.max_step == np.inf
    with pytest.raises(mb.ModelError, match="rtol"):
        RunOptions.checked(1.0, rtol=-1.0)
    with pytest.raises(mb.ModelError, match="integrator"):
        RunOptions.checked(1.0, integrator="fast")
    with pytest.raises(mb.ModelError, match="t_end"):
        RunOptions.checked(0.0)
    with pytest.raises(AttributeError):
        options.rtol = 1.0  # frozen
    assert RunOptions(1.0, progress=2.5).progress_delay == 2.5 and RunOptions(1.0, progress=True).progress_delay == 0.0
