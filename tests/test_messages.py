"""Failures say what is actually wrong: a zero-length spring is named on every path (not
"mass matrix singular" or "non-finite state"), and extreme axis lengths are directions."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen.backend import c_compiler

PATHS = [("scipy", "DOP853"), ("scipy", "RK45")] + ([("compiled", "DOP853"), ("compiled", "RK4")]
                                                   if c_compiler() else [])


def _pendulum_with_spring_at_pivot(rest_length: float) -> mb.Model:
    """A spring from the pendulum's pivot point to the ground point at the same place: its
    length is zero at every state, so its direction (and force) is undefined."""
    m = mb.Model("spring_at_pivot")
    bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -1), inertia=(0.1, 0.1, 0.1)))
    m.add(mb.Revolute("hinge", m.ground, bob, axis="x"))
    m.add(mb.Spring("sp", a=bob, b=m.ground, stiffness=10.0, rest_length=rest_length))
    return m


@pytest.mark.parametrize("integrator, method", PATHS)
@pytest.mark.parametrize("rest_length", [0.0, 0.5])
def test_a_zero_length_spring_is_named_on_every_path(integrator, method, rest_length):
    system = _pendulum_with_spring_at_pivot(rest_length).compile()
    extra = {"dt": 0.01} if method == "RK4" else {}
    with pytest.raises(mb.SimulationError, match="Spring 'sp' has zero length") as info:
        system.simulate(1.0, [0.3], integrator=integrator, method=method, **extra)
    assert "mass matrix" not in str(info.value)


@pytest.mark.parametrize("scale", [1e200, 1e-200, 1e-300])
def test_an_axis_of_any_nonzero_length_is_a_direction(scale):
    def pendulum(axis):
        m = mb.Model("p")
        bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.1)))
        m.add(mb.Revolute("hinge", m.ground, bob, axis=axis))
        return m.compile()

    scaled = pendulum((scale, 0.0, 0.0)).simulate(0.5, [0.3])
    unit = pendulum((1.0, 0.0, 0.0)).simulate(0.5, [0.3])
    np.testing.assert_allclose(scaled.q, unit.q, rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("axis", [(0.0, 0.0, 0.0), (np.nan, 0.0, 0.0), (np.inf, 0.0, 0.0)])
def test_an_axis_without_direction_is_a_model_error(axis):
    with pytest.raises(mb.ModelError, match="axis"):
        m = mb.Model("p")
        bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -0.5), inertia=(0.1, 0.1, 0.1)))
        m.add(mb.Revolute("hinge", m.ground, bob, axis=axis))
        m.compile()
