"""The cross-path matrix: every library model gives the same numbers along every path.

For each model of ``library/`` (the parts of ``library/parts/`` enter through the library
models built from them): both formulations, both backends, a file round trip, a run-time
parameter change against a fresh build, ``sweep`` against serial runs, and ``linearize`` in
both formulations where an equilibrium exists.  Systems are compiled once per module and
shared; each run is short (0.2 s of motion), so the whole file takes about 40 s of one core.

Tolerances: the two formulations and the two backends integrate the same equations along
different arithmetic, so their trajectories agree to the integration tolerance (``TRAJ``);
a run-time change and a fresh build run the same code on the same numbers, so they agree to
rounding (``SAME``); sweeps are bit-identical to serial runs.
"""
from __future__ import annotations

import copy
from functools import lru_cache

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.analysis import operating_time
from mbcomp.files.toml_model import library_models, load

MODELS = library_models()
NAMES = sorted(MODELS)
T_END = 0.2
T_EVAL = np.linspace(0.0, T_END, 5)
RTOL, ATOL = 1e-10, 1e-12
TRAJ = 1e-6   # formulations and backends: the integrator's tolerance, amplified over 0.2 s
SAME = 1e-10  # the same equations on the same numbers

pytestmark = pytest.mark.xdist_group("cross_paths")


@lru_cache(maxsize=None)
def model_of(name: str):
    return load(MODELS[name])


@lru_cache(maxsize=None)
def system_of(name: str, formulation: str = "lagrange", backend: str = "auto"):
    return model_of(name).compile(formulation, backend=backend)


def initial_state(name: str, system) -> tuple[np.ndarray, np.ndarray]:
    """The file's ``[initial]`` values (0 elsewhere, the identity for a quaternion)."""
    model = model_of(name)
    neutral = system.topology.state_map.neutral()
    q = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
    qd = np.array([model.initial["qd"].get(c, 0.0) for c in system.speeds])
    return q, qd


def run(name: str, system, **options):
    q0, qd0 = initial_state(name, system)
    return system.simulate(T_END, q0, qd0, t_eval=T_EVAL, rtol=RTOL, atol=ATOL, **options)


def assert_same_motion(a, b, tol: float, label: str) -> None:
    scale = 1.0 + np.abs(b.q).max()
    np.testing.assert_allclose(a.q, b.q, rtol=0, atol=tol * scale, err_msg=f"{label}: q")
    np.testing.assert_allclose(a.qd, b.qd, rtol=0, atol=tol * (1.0 + np.abs(b.qd).max()) * 10,
                               err_msg=f"{label}: qd")


def changed_values(system) -> dict:
    """Run-time changes that touch every model: gravity scaled by 1.1 (turned a little when it
    is zero) and the first body's mass scaled by 1.2."""
    params = system.parameters
    gravity = np.asarray(params["gravity"], dtype=float)
    changes = {"gravity": tuple(gravity * 1.1 if np.any(gravity) else (0.0, 0.0, -1.0))}
    masses = [k for k in params if k.endswith(".mass") and np.ndim(params[k]) == 0 and params[k] > 0]
    if masses:
        changes[masses[0]] = float(params[masses[0]]) * 1.2
    return changes


def fresh_model(name: str, changes: dict):
    """The model built anew with ``changes`` written into its components (not through
    ``with_parameters``): a deep copy whose attributes are set before compiling."""
    model = copy.deepcopy(model_of(name))
    for key, value in changes.items():
        if key == "gravity":
            model.gravity = np.asarray(value, dtype=float)
            continue
        component, _, attribute = key.rpartition(".")
        object.__setattr__(model[component], attribute, value)
    return model


# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_both_formulations_give_the_same_motion(name):
    lagrange, dae = system_of(name, "lagrange"), system_of(name, "dae")
    assert lagrange.coords == dae.coords and lagrange.ndof == dae.ndof
    assert_same_motion(run(name, dae), run(name, lagrange), TRAJ, f"{name}: dae against lagrange")


#: Library models that genuinely need Python stepping: name -> reason.
NEEDS_PYTHON: dict[str, str] = {
}


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
@pytest.mark.parametrize("name", NAMES)
def test_every_model_runs_in_compiled_code(name, formulation):
    """No library model leaves the compiled loop, in either formulation, unless the user asks
    for scipy's stepping (``System.integration_path`` and ``Result.stats["path"]`` say so)."""
    if name in NEEDS_PYTHON:
        pytest.skip(NEEDS_PYTHON[name])
    system = system_of(name, formulation)
    if system.backend != "c":
        pytest.skip("no C compiler")
    assert system.integration_path() == "compiled", f"{name} ({formulation})"
    assert system.integration_path("Radau") == "scipy: scipy method 'Radau' requested (compiled loops: DOP853, RK4)"
    res = run(name, system)
    assert res.stats["integrator"] == "compiled" and res.stats["path"] == "compiled"


@pytest.mark.parametrize("name", NAMES)
def test_both_backends_give_the_same_numbers(name):
    c, python = system_of(name, "lagrange"), system_of(name, "lagrange", "python")
    q0, qd0 = initial_state(name, c)
    np.testing.assert_allclose(python.accelerations(q0, qd0), c.accelerations(q0, qd0), rtol=SAME, atol=SAME,
                               err_msg=f"{name}: accelerations")
    np.testing.assert_allclose(python.mass_matrix(q0), c.mass_matrix(q0), rtol=SAME, atol=SAME,
                               err_msg=f"{name}: mass matrix")
    assert python.energy(q0, qd0).total == pytest.approx(c.energy(q0, qd0).total, rel=SAME, abs=SAME)


@pytest.mark.parametrize("name", NAMES)
def test_a_file_round_trip_gives_the_same_model(name, tmp_path):
    system = system_of(name)
    path = tmp_path / f"{name}.toml"
    model_of(name).save(path)
    again = mb.load(path).compile()
    assert again.coords == system.coords and again.speeds == system.speeds
    # save() writes sub-model instances with their [parameters] (files.toml_model.save)
    assert list(again.parameters) == list(system.parameters), name
    for key, value in system.parameters.items():
        np.testing.assert_allclose(again.parameters[key], value, rtol=1e-15, atol=0, err_msg=f"{name}: {key}")
    q0, qd0 = initial_state(name, system)
    np.testing.assert_allclose(again.accelerations(q0, qd0), system.accelerations(q0, qd0), rtol=SAME, atol=SAME)


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
@pytest.mark.parametrize("name", NAMES)
def test_a_run_time_change_equals_a_fresh_build(name, formulation):
    system = system_of(name, formulation)
    changes = changed_values(system)
    fresh = fresh_model(name, changes).compile(formulation)
    changed = system.with_parameters(changes)
    for key, value in fresh.parameters.items():
        np.testing.assert_allclose(changed.parameters[key], value, rtol=1e-15, atol=0, err_msg=f"{name}: {key}")
    assert_same_motion(run(name, system, parameters=changes), run(name, fresh), SAME, f"{name}: {formulation}")


@pytest.mark.parametrize("name", NAMES)
def test_a_sweep_equals_serial_runs(name):
    system = system_of(name)
    q0, qd0 = initial_state(name, system)
    cases = [{"parameters": changed_values(system)}, {"parameters": None}]
    common = dict(q0=q0, qd0=qd0, t_end=T_END, t_eval=T_EVAL, rtol=RTOL, atol=ATOL)
    swept = mb.sweep(system, cases, threads=2, **common)
    for case, result in zip(cases, swept):
        serial = system.simulate(T_END, q0, qd0, t_eval=T_EVAL, rtol=RTOL, atol=ATOL, parameters=case["parameters"])
        np.testing.assert_array_equal(result.q, serial.q, err_msg=name)
        np.testing.assert_array_equal(result.qd, serial.qd, err_msg=name)


@pytest.mark.parametrize("name", NAMES)
def test_linearize_agrees_between_formulations_about_an_equilibrium(name):
    lagrange, dae = system_of(name, "lagrange"), system_of(name, "dae")
    if lagrange.ndof == 0 or lagrange.topology.contacts:
        pytest.skip(f"{name}: no free motion about an equilibrium to linearise (motors or contacts)")
    q0, _ = initial_state(name, lagrange)
    try:
        q_eq, states = lagrange.equilibrium(q0, return_states=True)
    except mb.SimulationError as exc:
        pytest.skip(f"{name}: no equilibrium near its initial state ({str(exc)[:80]})")
    rest = {"states": states} if lagrange.extra_states else {}
    t_rest = operating_time(lagrange, q_eq)  # inputs held where they settle (a Step: its final value)
    np.testing.assert_allclose(lagrange.accelerations(q_eq, np.zeros(len(lagrange.speeds)), t=t_rest, **rest), 0.0,
                               atol=1e-8)
    def spectrum(system) -> np.ndarray:  # sorted by rounded parts: real parts near 0 differ by rounding only
        eig = np.linalg.eigvals(system.linearize(q_eq).A)
        scale = 1e-6 * (1.0 + np.abs(eig).max())
        return np.array(sorted(eig, key=lambda z: (round(z.imag / scale), round(z.real / scale))))
    eig_l, eig_d = spectrum(lagrange), spectrum(dae)
    # (velocity rows, rolling and no-slip, leave more independent coordinates than speeds)
    # (the bicycle's rear wheel row is redundant: count the rank of the position rows, not the rows)
    position_rows = lagrange.constraint_values(q_eq, None).J[~lagrange.velocity_rows]
    coordinates = len(lagrange.speeds) - int(np.linalg.matrix_rank(position_rows)) \
        if lagrange.velocity_rows.any() else lagrange.ndof
    assert eig_l.shape == eig_d.shape == (coordinates + lagrange.ndof + len(lagrange.extra_states),)
    np.testing.assert_allclose(eig_d, eig_l, rtol=1e-6, atol=1e-6 * (1 + np.abs(eig_l).max()), err_msg=name)
