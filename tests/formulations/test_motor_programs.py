"""A motor law evaluated in compiled loops (``expressions_c``): where Python's evaluation
raises, the compiled program gives NaN, and both compiled loops report the motor's error as
Python stepping does (not the singular solve the NaN would cause)."""
from __future__ import annotations

import math

import pytest

import mbcomp as mb
from mbcomp.core.expressions import parse_expression
from mbcomp.codegen.expressions_c import NotCompilable, compile_program, programs, run_program


def value(text: str, t: float) -> float:
    return run_program(compile_program(parse_expression(text, {}, allow_t=True)), t)


@pytest.mark.parametrize("text, t", [("sqrt(t - 1)", 0.0), ("1/(t - 1)", 1.0), ("(t - 3)**0.5", 1.0)])
def test_a_domain_error_is_nan(text, t):
    assert math.isnan(value(text, t))


@pytest.mark.parametrize("t", [0.0, -1.0])
def test_log_of_a_non_positive_number_is_nan(t):
    """(``log`` appears in the derivatives of powers; files cannot call it.)"""
    assert math.isnan(run_program(compile_program(("call", "log", ("t",))), t))
    assert run_program(compile_program(("call", "log", ("t",))), 2.0) == math.log(2.0)


def test_overflow_is_infinite_and_ordinary_values_are_pythons():
    assert value("exp(t)", 1000.0) == math.inf
    assert value("2*sin(t) - t**3/7", 0.3) == 2 * math.sin(0.3) - math.pow(0.3, 3) / 7


def test_programs_follow_each_other_in_one_array():
    trees = [parse_expression(text, {}, allow_t=True) for text in ("t + 1", "3*t", "cos(t)")]
    packed = programs(trees)
    assert [run_program(packed, 0.5, i) for i in range(3)] == [1.5, 1.5, math.cos(0.5)]


def test_not_compilable_is_a_model_error_naming_the_owner():
    with pytest.raises(NotCompilable, match="Motor 'm': a 'obj' node") as info:
        compile_program(("+", ("t",), ("obj", object())), "Motor 'm'")
    assert isinstance(info.value, mb.ModelError)


def two_bars(position: str) -> mb.Model:
    """Two 1 m bars in a vertical plane, the first driven by ``position`` (rad)."""
    m = mb.Model("driven_two_bars", gravity=(0, -9.81, 0))
    b1 = m.add(mb.Body("bar1", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    b2 = m.add(mb.Body("bar2", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 12, 1 / 12)))
    m.add(mb.Revolute("j1", m.ground, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(1, 0, 0)))
    m.add(mb.Motor("motor", "j1", position=position))
    return m


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_a_law_failing_mid_run_is_reported_as_in_python(formulation):
    """``0*sqrt(1 - t)`` is 0 until t = 1 s and cannot be evaluated after it."""
    system = two_bars("0.5 + 0*sqrt(1 - t)").compile(formulation)
    assert system.integration_path() == "compiled"
    errors = {}
    for integrator in ("compiled", "scipy"):
        with pytest.raises(mb.SimulationError) as info:
            system.simulate(2.0, [0.5, 0.0], [0.0, 0.0], integrator=integrator)
        errors[integrator] = str(info.value)
    for text in errors.values():
        assert "Motor 'motor'" in text and "cannot be evaluated" in text and "math domain error" in text
        t = float(text.split("position(")[1].split(")")[0])
        assert 1.0 < t < 1.1  # the first stage past t = 1 s
