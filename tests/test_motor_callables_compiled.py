"""Motors whose position is a Python callable run in the compiled loops of both formulations
(``codegen/callbacks.py``'s motor callback, ``expressions_c`` ``SLOT`` programs): the same
motion as Python stepping (a model compiled without C, whose right-hand side and constraint
rows are Python's), the driven coordinate on the callable, the same errors as Python
stepping, and the compiled evaluation calls equal to the Python solve."""
from __future__ import annotations

import re

import numpy as np
import pytest

import mbcomp as mb
from conftest import G, bar
from mbcomp.codegen.expressions_c import SLOT, fill_slots, position_programs, run_program, slot_programs

TIGHT = dict(rtol=1e-10, atol=1e-12)
T = np.linspace(0.0, 1.0, 11)
A0, A1, W = 1.0, 0.5, 2.0  # the crank's law: A0 + A1 sin(W t) (rad, rad, rad/s)


def law(t):
    """The crank angle (rad) a callable motor prescribes."""
    return A0 + A1 * np.sin(W * t)


class ExactLaw:
    """``law`` with its exact derivatives (``diff()``: the callable kind
    ``ConstraintSet.exact_derivatives`` takes)."""

    def __init__(self, order: int = 0):
        self.order = order

    def __call__(self, t):
        return (A0 + A1 * np.sin(W * t), A1 * W * np.cos(W * t), -A1 * W * W * np.sin(W * t))[self.order]

    def diff(self):
        return ExactLaw(self.order + 1)


def linkage(position, name: str) -> mb.Model:
    """A four-bar (crank A, coupler, rocker, closed by the revolute C) with a pendulum hung
    from the coupler: the motor on A leaves the pendulum free (one degree of freedom)."""
    m = mb.Model(name, gravity=(0, -G, 0))
    crank, coupler, rocker = (m.add(bar(n, L)) for n, L in (("crank", 0.3), ("coupler", 0.8), ("rocker", 0.6)))
    bob = m.add(bar("bob", 0.4))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(0.3, 0, 0)))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(0.7, 0, 0)))
    m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(0.8, 0, 0), child_point=(0.6, 0, 0)))
    m.add(mb.Revolute("E", coupler, bob, axis="z", parent_point=(0.4, 0, 0)))
    m.add(mb.Motor("drive", "A", position=position))
    return m


def start(system):
    """A consistent start on the law at t = 0 (the crank's angle and speed the law's), the
    linkage and the pendulum moving (``System.assemble``)."""
    q, qd = system.assemble([law(0.0), -0.5, 1.5, -1.0], [A1 * W, 0.0, 0.0, 0.0])
    return q, qd


_SYSTEMS: dict = {}


def system(formulation: str, position=law, backend: str = "auto", tag: str = "fd"):
    key = (formulation, tag, backend)
    if key not in _SYSTEMS:
        _SYSTEMS[key] = linkage(position, f"mc_{tag}_{formulation}").compile(formulation, backend=backend)
    return _SYSTEMS[key]


@pytest.fixture(scope="module", params=["dae", "lagrange"])
def formulation(request):
    s = system(request.param)
    if s.backend != "c":
        pytest.skip("no C compiler: the callbacks come from compiled loops")
    return request.param


def test_slot_programs_read_the_callbacks_values():
    program = slot_programs(2)
    assert [run_program(program, 0.3, k, slots=np.arange(9.0)) for k in range(3)] == [6.0, 7.0, 8.0]
    filled = fill_slots(np.concatenate([program, [1.0, 1.0, 0.0]]), np.arange(9.0) * 10)  # (and a TIME program)
    assert SLOT not in filled[1::2][:3]
    assert [run_program(filled, 0.5, k) for k in range(4)] == [60.0, 70.0, 80.0, 0.5]


def test_only_callables_take_slots():
    s = system("dae")
    constraints = s.kernel.compiled.constraint_set
    programs, python_rows = position_programs(constraints)
    assert python_rows == list(programs) and len(python_rows) == 1  # the motor's row, slot 0
    expression = linkage("1 + 0.5*sin(2*t)", "mc_expr_dae").compile("dae")  # (a file expression: its own programs)
    assert position_programs(expression.kernel.compiled.constraint_set)[1] == []


class TestRuns:
    def test_path_is_compiled(self, formulation):
        s = system(formulation)
        assert s.integration_path() == "compiled"
        q, qd = start(s)
        res = s.simulate(0.2, q, qd, **TIGHT)
        assert res.stats["integrator"] == "compiled"

    @pytest.mark.parametrize("tag", ["fd", "exact"])
    def test_equals_python_stepping(self, formulation, tag):
        position = law if tag == "fd" else ExactLaw()
        s = system(formulation, position, tag=tag)
        oracle = system(formulation, position, backend="python", tag=tag)
        q, qd = start(s)
        res = s.simulate(1.0, q, qd, t_eval=T, **TIGHT)
        ref = oracle.simulate(1.0, q, qd, t_eval=T, **TIGHT)
        assert res.stats["integrator"] == "compiled" and ref.stats["rhs"] == "python"
        np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-8)
        np.testing.assert_allclose(res.qd, ref.qd, rtol=0, atol=1e-7)
        # scipy's stepping of the compiled right-hand side calls the position back the same way
        rhs = s.simulate(1.0, q, qd, t_eval=T, integrator="scipy", **TIGHT)
        assert rhs.stats["rhs"] == "compiled"
        np.testing.assert_allclose(rhs.q, ref.q, rtol=0, atol=1e-8)

    @pytest.mark.parametrize("tag", ["fd", "exact"])
    def test_driven_coordinate_follows_the_callable(self, formulation, tag):
        s = system(formulation, law if tag == "fd" else ExactLaw(), tag=tag)
        q, qd = start(s)
        res = s.simulate(1.0, q, qd, t_eval=T, **TIGHT)
        k = s.coords.index("A")
        # lagrange: the crank is a dependent coordinate solved by Newton; dae: Baumgarte keeps it
        atol = 1e-9 if formulation == "lagrange" else 1e-7
        np.testing.assert_allclose(res.q[:, k], law(T), rtol=0, atol=atol)

    def test_exact_derivatives_equal_the_expression_model(self, formulation):
        """The exact callable's values are the expression's to rounding: the same motion."""
        s = system(formulation, ExactLaw(), tag="exact")
        expr = linkage("1 + 0.5*sin(2*t)", f"mc_expr_{formulation}").compile(formulation)
        q, qd = start(s)
        res = s.simulate(1.0, q, qd, t_eval=T, **TIGHT)
        ref = expr.simulate(1.0, q, qd, t_eval=T, **TIGHT)
        np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-10)


def test_dae_projection_calls_the_position_back():
    """dae with projection=True: the compiled loop's projection after each step evaluates the
    motor row at the step's end through the same callback."""
    s = linkage(law, "mc_fd_dae_projected").compile("dae", projection=True)
    if s.backend != "c":
        pytest.skip("no C compiler")
    oracle = linkage(law, "mc_fd_dae_projected").compile("dae", projection=True, backend="python")
    q, qd = start(s)
    res = s.simulate(1.0, q, qd, t_eval=T, **TIGHT)
    ref = oracle.simulate(1.0, q, qd, t_eval=T, **TIGHT)
    assert s.integration_path() == "compiled" and res.stats["integrator"] == "compiled"
    np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res["A"], law(T), rtol=0, atol=1e-10)  # (projected onto the law)


def _raising(t):
    if t > 0.3:
        raise ValueError("encoder lost")
    return law(t)


def _nan_after(t):
    return float("nan") if t > 0.3 else law(t)


class TestErrors:
    @pytest.mark.parametrize("position, tag, text", [(_raising, "raise", "encoder lost"),
                                                     (_nan_after, "nan", "non-finite value")])
    def test_same_error_as_python_stepping(self, formulation, position, tag, text):
        s = system(formulation, position, tag=tag)
        oracle = system(formulation, position, backend="python", tag=tag)
        q, qd = start(s)
        with pytest.raises(mb.SimulationError) as compiled:
            s.simulate(1.0, q, qd, integrator="compiled", **TIGHT)
        with pytest.raises(mb.SimulationError) as python:
            oracle.simulate(1.0, q, qd, **TIGHT)
        message = str(compiled.value)
        assert message.startswith("Motor 'drive': position(0.3") and message.endswith(f"failed: {text}")
        # the same text but the time (the steps differ: where the stencil first reaches t > 0.3)
        # and the prefix of scipy's stepping
        def same(m):
            return re.sub(r"position\([^)]*\)", "position(t)", m.removeprefix("simulation stopped: "))
        assert same(message) == same(str(python.value))

    def test_a_later_run_is_unaffected(self, formulation):
        s = system(formulation, _raising, tag="raise")
        q, qd = start(s)
        with pytest.raises(mb.SimulationError):
            s.simulate(1.0, q, qd, **TIGHT)
        res = s.simulate(0.25, q, qd, t_eval=[0.0, 0.25], **TIGHT)  # (before the callable raises)
        ref = system(formulation).simulate(0.25, q, qd, t_eval=[0.0, 0.25], **TIGHT)
        np.testing.assert_allclose(res.q, ref.q, rtol=0, atol=1e-12)


class TestEvaluation:
    @pytest.mark.parametrize("t", [0.0, 0.37])
    def test_accelerations_and_reactions_equal_the_python_solve(self, formulation, t):
        s = system(formulation)
        q, qd = start(s)
        kernel, form = s.kernel, s._formulation
        applied = kernel.tau(None, t, q, qd)
        qdd = s.accelerations(q, qd, t)
        oracle = form.accelerations(kernel, t, q, qd, applied)
        np.testing.assert_allclose(qdd, oracle, rtol=1e-10, atol=1e-10)
        reactions = s.reactions(q, qd, t)
        expected = form.reactions(kernel, t, q, qd, applied, None, ())
        assert set(reactions) == set(expected)
        for name in expected:
            np.testing.assert_allclose(reactions[name], expected[name], rtol=1e-9, atol=1e-9)
        assert abs(reactions["drive"]) > 1e-3  # (the motor works: a number that could be wrong)

    def test_evaluation_error_names_the_motor(self, formulation):
        s = system(formulation, _raising, tag="raise")
        q, qd = start(s)
        with pytest.raises(mb.SimulationError, match=r"position\(0.5\) failed: encoder lost"):
            s.accelerations(q, qd, 0.5)


def test_fmu_export_refuses_a_callable_motor(tmp_path):
    s = system("dae")
    with pytest.raises(mb.ModelError, match="drive.*Python callable.*FMU"):
        s.export_fmu(tmp_path / "linkage.fmu")
