"""Fuzz the public API's arguments: whatever a user passes, a call either works (finite
numbers) or raises one of the project's errors (ModelError, SimulationError); never a raw
numpy/Python exception, a hang or NaN returned as an answer."""
from __future__ import annotations

import math

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", exc_type=ImportError)
from hypothesis import HealthCheck, given, settings, strategies as st  # noqa: E402

import mbcomp as mb  # noqa: E402
from conftest import pendulum_chain  # noqa: E402

PROJECT_ERRORS = (mb.ModelError, mb.SimulationError)
FUZZ = settings(max_examples=100, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@pytest.fixture(scope="module")
def chain():
    return pendulum_chain(2).compile()


# -- values a user might pass by mistake -------------------------------------------------------------
scalars = st.one_of(
    st.none(), st.booleans(), st.text(max_size=5), st.binary(max_size=3),
    st.integers(min_value=-10 ** 30, max_value=10 ** 30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.complex_numbers(max_magnitude=10), st.just(object()), st.just(print),
)
junk = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4), st.tuples(inner, inner),
                                                     st.dictionaries(st.text(max_size=3), inner, max_size=3)),
                    max_leaves=8)


def bad_or(good):
    """Either a sensible value or anything at all (sensible values keep runs short)."""
    return st.one_of(good, junk)


small_time = st.floats(min_value=1e-3, max_value=0.05)
vector2 = st.lists(st.floats(min_value=-3, max_value=3), min_size=2, max_size=2)
tolerance = st.floats(min_value=1e-10, max_value=1e-3)


def bounded(value, limit: float = 0.05):
    """Numbers that would make a valid but long run are clipped (the fuzz is about types)."""
    if isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > limit:
        return limit
    return value


def _finite(*arrays) -> bool:
    return all(np.all(np.isfinite(np.asarray(a, dtype=float))) for a in arrays)


@FUZZ
@given(t_end=bad_or(small_time), q0=bad_or(vector2), qd0=bad_or(vector2), rtol=bad_or(tolerance),
       atol=bad_or(tolerance), t_eval=bad_or(st.lists(small_time, min_size=1, max_size=3).map(sorted)),
       max_step=bad_or(st.floats(min_value=1e-3, max_value=1.0)), tau=bad_or(vector2),
       method=bad_or(st.sampled_from(["DOP853", "RK45", "RK4", "Radau", "nope"])),
       integrator=bad_or(st.sampled_from(["auto", "scipy", "compiled"])),
       dt=bad_or(st.sampled_from([None, 1e-3, 1e-2])), rest_speed=bad_or(st.floats(min_value=0, max_value=1)))
def test_simulate_arguments(chain, t_end, q0, qd0, rtol, atol, t_eval, max_step, tau, method, integrator, dt,
                            rest_speed):
    t_end = bounded(t_end)
    if isinstance(dt, (int, float)) and not isinstance(dt, bool) and 0 < dt < 1e-3:
        dt = 1e-3  # valid, merely slow
    if isinstance(rtol, float) and 0 < rtol < 1e-12 or isinstance(atol, float) and 0 < atol < 1e-14:
        rtol, atol = 1e-8, 1e-10  # valid, merely slow
    try:
        res = chain.simulate(t_end, q0, qd0, rtol=rtol, atol=atol, t_eval=t_eval, max_step=max_step, tau=tau,
                             method=method, integrator=integrator, dt=dt, rest_speed=rest_speed)
    except PROJECT_ERRORS:
        return
    assert res.stats["success"] and _finite(res.t, res.q, res.qd)


@FUZZ
@given(body=bad_or(st.sampled_from(["link0", "link1", "ground"])), q=bad_or(vector2), qd=bad_or(vector2),
       t=bad_or(st.floats(min_value=0, max_value=1)), point=bad_or(st.lists(st.floats(-1, 1), min_size=3, max_size=3)))
def test_body_state_arguments(chain, body, q, qd, t, point):
    try:
        state = chain.body_state(body, q, qd, t=t, point=point)
        values = [state.position, state.velocity, state.rotation, state.angular_velocity]
    except PROJECT_ERRORS:
        return
    assert _finite(*values)


@FUZZ
@given(q=bad_or(vector2), qd=bad_or(vector2), t=bad_or(st.floats(min_value=0, max_value=1)), tau=bad_or(vector2))
def test_evaluation_arguments(chain, q, qd, t, tau):
    for call in (lambda: chain.accelerations(q, qd, t, tau), lambda: chain.energy(q, qd).total,
                 lambda: chain.holding_forces(q, t), lambda: chain.reactions(q, qd, t, tau)):
        try:
            value = call()
        except PROJECT_ERRORS:
            continue
        assert isinstance(value, dict) or _finite(value)


@FUZZ
@given(values=st.dictionaries(st.sampled_from(["link0.mass", "link1.com", "joint1.parent_point", "link0.inertia",
                                               "nothing.here"]), junk, max_size=2))
def test_with_parameters_arguments(chain, values):
    try:
        changed = chain.with_parameters(values)
    except PROJECT_ERRORS:
        return
    assert _finite(changed.accelerations([0.3, 0.2], [0.0, 0.0]))


# -- limits: sub-model trees, load specs and URDF joint graphs (issue "Limits") -----------------------
import importlib.util  # noqa: E402
import os  # noqa: E402
from pathlib import Path  # noqa: E402
from unittest import mock  # noqa: E402


def tree_class(fanouts: list[int]) -> type:
    """A Submodel whose instances add ``fanouts[0]`` instances of the next level, and so on."""
    class Level(mb.Submodel):
        def build(self, parent):
            if not fanouts:
                self.add(mb.Body("b", mass=1.0))
                return
            inner = tree_class(fanouts[1:])
            for k in range(fanouts[0]):
                self.add(inner(f"n{k}", parent=parent))
    return Level


@FUZZ
@given(fanouts=st.lists(st.integers(0, 6), max_size=7))
def test_submodel_trees_hold_their_instances_or_name_the_limit(fanouts):
    """1 + f0 + f0 f1 + ... instances nested len(fanouts) + 1 deep: built exactly, or refused
    with the limit named (instances checked as they are added, nesting first)."""
    expected, level = 1, 1
    for f in fanouts:
        level *= f
        expected += level
    depth = 1 + len([f for f in np.cumprod(fanouts) if f > 0]) if fanouts else 1
    model = mb.Model("tree")
    with mock.patch.dict(os.environ, {"MBCOMP_MAX_INSTANCES": "300", "MBCOMP_MAX_NESTING": "5"}):
        try:
            model.add(tree_class(list(fanouts))("top", parent=model.ground.frame()))
        except mb.ModelError as exc:
            assert ("nest more than 5 deep" in str(exc) and depth > 5) or \
                   ("more than 300 sub-model instances" in str(exc) and expected > 300), (str(exc), expected, depth)
            return
    assert expected <= 300 and depth <= 5 and model.registry.instances == expected


load_specs = st.one_of(
    st.text(max_size=12), st.sampled_from(["/dev/zero", "/dev/null", "/", ".", "/dev/stdin", "/proc/self/mem"]),
    st.builds(lambda parts: "library:" + "/".join(parts),
              st.lists(st.sampled_from(["..", ".", "", "/", "etc", "passwd", "parts", "link", "~", "\\", "c:"]),
                       max_size=5)))


@FUZZ
@given(spec=load_specs)
def test_load_specs_end_in_a_model_or_a_model_error(spec):
    """Whatever names a model: a ModelError or a model; a ``library:`` spec only ever gives a
    file inside a library folder."""
    try:
        model = mb.load(spec)
    except mb.ModelError:
        return
    if spec.startswith("library:"):
        folders = [d.resolve() for d in mb.library.library_dirs()]
        assert any(Path(model.path).resolve().is_relative_to(d) for d in folders), model.path


INERTIAL = '<inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial>'


@pytest.mark.skipif(importlib.util.find_spec("yourdfpy") is None, reason="yourdfpy reads URDF")
@settings(FUZZ, max_examples=60)
@given(edges=st.lists(st.tuples(st.integers(0, 4), st.integers(0, 4), st.booleans()), max_size=6))
def test_urdf_joint_graphs_load_exactly_when_they_are_trees(tmp_path_factory, edges):
    """Random joints among 5 links: the model loads iff the joints form one tree (networkx's
    arborescence test), with one body per moving joint; otherwise a ModelError, never a crash."""
    import warnings
    import networkx as nx
    graph = nx.MultiDiGraph()
    graph.add_nodes_from(range(5))
    graph.add_edges_from((a, b) for a, b, _ in edges)
    text = ['<?xml version="1.0"?>\n<robot name="r">'] + [f'<link name="l{k}">{INERTIAL}</link>' for k in range(5)]
    text += [f'<joint name="j{k}" type="{"fixed" if fixed else "continuous"}"><parent link="l{a}"/>'
             f'<child link="l{b}"/><axis xyz="0 0 1"/></joint>' for k, (a, b, fixed) in enumerate(edges)]
    path = tmp_path_factory.mktemp("urdf") / "r.urdf"
    path.write_text("".join(text) + "</robot>")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            model = mb.load(path)
        except mb.ModelError:
            assert not nx.is_arborescence(graph)
            return
    assert nx.is_arborescence(graph)
    assert len(model.bodies) == sum(not fixed for _, _, fixed in edges)

# -- limits: what a run keeps ----------------------------------------------------------------------------
@FUZZ
@given(max_samples=bad_or(st.integers(min_value=2, max_value=60)), t_end=st.floats(min_value=0.01, max_value=0.5))
def test_max_samples_bounds_what_a_run_keeps(chain, max_samples, t_end):
    try:
        res = chain.simulate(t_end, [1.0, -0.5], max_samples=max_samples)
    except mb.SimulationError as exc:
        assert "max_samples" in str(exc) and "t_eval" in str(exc)
        return
    except mb.ModelError as exc:
        assert "max_samples" in str(exc)
        return
    limit = mb.core.checks.MAX_SAMPLES if max_samples is None else max_samples
    assert 2 <= len(res.t) <= limit and res.t[-1] == t_end and _finite(res.q, res.qd)


# -- names: one rule, no mixed columns or symbols ------------------------------------------------------------
name_parts = st.sampled_from(["a", "a_d", "t", "total", "kinetic", "=cmd|' /C calc'!A0", "+x", "-y", "@z", "\tq",
                              "link1.mass", "gravity[2]", "\\dot{a}", "_d", "<!--<script>", "x\u2028y", "b"])
coordinate_name = st.one_of(name_parts, st.builds(lambda a, b: a + b, name_parts, name_parts))


def _two_rods(c1, c2) -> mb.Model:
    m = mb.Model("names", gravity=(0, 0, -9.81))
    link0 = m.add(mb.Body("link0", mass=1.0, com=(0, 0, -0.5)))
    link1 = m.add(mb.Body("link1", mass=1.0, com=(0, 0, -0.5)))
    m.add(mb.Revolute("joint0", m.ground, link0, axis="x", coords=c1))
    m.add(mb.Revolute("joint1", link0, link1, axis="x", coords=c2, parent_point=(0, 0, -1)))
    return m


@settings(max_examples=30, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(c1=coordinate_name, c2=coordinate_name)
def test_coordinate_names_never_mix_columns_or_symbols(tmp_path, c1, c2):
    import csv
    try:
        system = _two_rods(c1, c2).compile(backend="python", cache=False)
    except mb.ModelError:
        return
    # accepted: every name is its own column and its own symbol
    res = system.simulate(0.05, [0.3, -0.2], t_eval=[0.0, 0.05])
    path = tmp_path / "names.csv"
    res.to_csv(path)
    with open(path, newline="") as fh:
        header = next(csv.reader(fh))
    assert len(set(header)) == len(header)
    assert not any(cell.startswith(("=", "+", "-", "@", "\t", "\r")) for cell in header)
    columns = [cell[1:] if cell.startswith("'") and cell[1:2] in ("=", "+", "-", "@", "\t", "\r") else cell
               for cell in header]
    assert columns[1:5] == [c1, c2, c1 + "_d", c2 + "_d"]
    parameters = {f"{k}[{i}]" for k, v in system.parameters.items() for i in range(np.size(v))} | set(system.parameters)
    assert not {c1, c2, c1 + "_d", c2 + "_d"} & (parameters | {"t", "kinetic", "potential", "total"})
    np.testing.assert_allclose(res[c1], res.q[:, 0])
    np.testing.assert_allclose(res[c2], res.q[:, 1])


# -- output that others read: CSV cells, the viewer's scene data -------------------------------------------
@FUZZ
@given(text=st.text(max_size=12))
def test_spreadsheet_cells_never_start_a_formula(text):
    from mbcomp.core.result import spreadsheet_safe
    safe = spreadsheet_safe(text)
    assert not safe.startswith(("=", "+", "-", "@", "\t", "\r"))
    assert safe == text or (safe == "'" + text)


@FUZZ
@given(names=st.lists(st.text(max_size=12), min_size=1, max_size=4))
def test_scene_json_holds_any_name(names):
    import json
    import re
    from mbcomp.face.viewer.page import scene_json
    scene = {"title": names[0], "bodies": [{"name": n} for n in names]}
    data = scene_json(scene)
    assert not re.search("[<>&\u2028\u2029]", data)
    assert json.loads(data) == scene
