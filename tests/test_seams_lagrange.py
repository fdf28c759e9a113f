"""Compiled lagrange stepping of loops through Ball joints (quaternions in the chart), and
the compiled path for every library model in both formulations."""
from __future__ import annotations

import numpy as np
import pytest

from mbcomp.files.toml_model import library_models, load

MODELS = library_models()


def _start(model, system):
    neutral = system.topology.state_map.neutral()
    q = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
    return q, np.zeros(system.nv)


@pytest.fixture(scope="module")
def stewart():
    model = load(MODELS["stewart_platform"])
    return model, {f: model.compile(f) for f in ("lagrange", "dae")}


@pytest.mark.parametrize("name", sorted(MODELS))
def test_every_library_model_runs_compiled_in_both_formulations(name):
    model = load(MODELS[name])
    for formulation in ("lagrange", "dae"):
        system = model.compile(formulation)
        path = system.integration_path()
        if "collisions" in path:
            continue   # colliding shapes step in Python (docs/contacts.md)
        assert path == "compiled", (name, formulation, path)   # (friction too: formulations/friction_c.py)


def _spinning(system, q0):
    """The platform from its file state with the plate turning (a consistent start)."""
    qd = np.zeros(system.nv)
    qd[list(system.speeds).index("leg0.ankle_wz")] = 0.8
    qd[list(system.speeds).index("leg0.ankle_wx")] = 0.5
    return system.assemble(q0, qd)


def test_stewart_platform_lagrange_follows_dae(stewart):
    """Loops through five ball joints: compiled lagrange (partitioned, quaternion in the chart)
    and compiled dae give the same motion to the integration tolerance; the ball's
    quaternion stays unit and the loops closed."""
    model, systems = stewart
    lag, dae = systems["lagrange"], systems["dae"]
    q0, qd0 = _spinning(dae, _start(model, dae)[0])
    t = np.linspace(0.0, 2.0, 41)
    runs = {f: s.simulate(2.0, q0, qd0, t_eval=t, rtol=1e-10, atol=1e-12) for f, s in systems.items()}
    assert [r.stats["integrator"] for r in runs.values()] == ["compiled", "compiled"]
    a, b = runs["lagrange"], runs["dae"]
    assert np.ptp(a["leg0.ankle_qz"]) > 0.03  # the ball turns
    np.testing.assert_allclose(a.q, b.q, atol=1e-7)
    np.testing.assert_allclose(a.qd, b.qd, atol=1e-6)
    quat = a.q[:, 3:7]
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-12)
    assert np.max(a.constraint_violation()) < 1e-10
    E = a.energy()
    assert np.ptp(E.total) < 1e-7 * np.max(E.kinetic)


def test_stewart_platform_chart_recentred_in_the_compiled_loop(stewart, monkeypatch):
    """With a small chart limit the loop pauses for Python to re-centre the ball's chart many
    times; the motion is the one without re-centring, and the one Python stepping gives."""
    model, systems = stewart
    lag = systems["lagrange"]
    q0, qd0 = _spinning(lag, _start(model, lag)[0])
    t = np.linspace(0.0, 0.5, 11)
    plain = lag.simulate(0.5, q0, qd0, t_eval=t, rtol=1e-10, atol=1e-12)
    monkeypatch.setattr(type(lag._formulation), "chart_limit", 0.02)
    small = lag.simulate(0.5, q0, qd0, t_eval=t, rtol=1e-10, atol=1e-12)
    stepped = lag.simulate(0.5, q0, qd0, t_eval=t, rtol=1e-10, atol=1e-12, integrator="scipy")
    assert small.stats["integrator"] == "compiled" and small.stats["restarts"] >= 3
    assert plain.stats["restarts"] == 0
    np.testing.assert_allclose(small.q, plain.q, atol=1e-8)
    np.testing.assert_allclose(stepped.q, small.q, atol=1e-8)
