"""The compiled fixed-step RK4 loop keeps only the output asked for: with ``t_eval`` it stores
the states (and rates) of the steps that bracket the requested times, never every step."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import assert_close, pendulum_chain

DT, T_END = 0.01, 0.5


@pytest.fixture(scope="module")
def chain():
    return pendulum_chain(3).compile()


def _hermite(t0, t1, y0, y1, f0, f1, t):
    """Cubic Hermite interpolation between two steps (the textbook basis)."""
    h = t1 - t0
    s = (t - t0) / h
    return ((2 * s ** 3 - 3 * s ** 2 + 1) * y0 + (s ** 3 - 2 * s ** 2 + s) * h * f0
            + (-2 * s ** 3 + 3 * s ** 2) * y1 + (s ** 3 - s ** 2) * h * f1)


def test_samples_on_the_grid_are_the_steps_themselves(chain):
    q0 = np.array([0.3, -0.2, 0.1])
    full = chain.simulate(T_END, q0, method="RK4", dt=DT, integrator="compiled")
    t_eval = np.array([0.0, 0.1, 0.25, T_END])
    sampled = chain.simulate(T_END, q0, method="RK4", dt=DT, integrator="compiled", t_eval=t_eval)
    rows = [int(round(t / DT)) for t in t_eval]
    np.testing.assert_array_equal(sampled.q, full.q[rows])
    np.testing.assert_array_equal(sampled.qd, full.qd[rows])
    assert sampled.stats["nfev"] == full.stats["nfev"] == 4 * int(round(T_END / DT))


def test_between_steps_the_hermite_interpolant_of_the_steps(chain):
    q0 = np.array([0.3, -0.2, 0.1])
    full = chain.simulate(T_END, q0, method="RK4", dt=DT, integrator="compiled")
    grid = full.t
    t_eval = np.array([0.013, 0.2071, np.nextafter(grid[30], -1.0), grid[30], np.nextafter(grid[30], 1.0), 0.4999,
                       0.5])
    sampled = chain.simulate(T_END, q0, method="RK4", dt=DT, integrator="compiled", t_eval=t_eval)
    for k, t in enumerate(t_eval):
        i = min(int(np.searchsorted(grid, t, side="right")) - 1, len(grid) - 2)  # the step at or before t
        y0 = np.concatenate((full.q[i], full.qd[i]))
        y1 = np.concatenate((full.q[i + 1], full.qd[i + 1]))
        f0 = np.concatenate((full.qd[i], chain.accelerations(full.q[i], full.qd[i])))
        f1 = np.concatenate((full.qd[i + 1], chain.accelerations(full.q[i + 1], full.qd[i + 1])))
        expected = _hermite(grid[i], grid[i + 1], y0, y1, f0, f1, t)
        assert_close(np.concatenate((sampled.q[k], sampled.qd[k])), expected, rtol=1e-13, atol=1e-14,
                     name=f"state at t = {t!r}")
    np.testing.assert_array_equal(sampled.q[3], full.q[30])  # on the grid: the step itself


def test_drive_states_are_interpolated_with_their_rates():
    m = pendulum_chain(2)
    m.add(mb.DCMotor("motor", "joint0", ratio=20.0, resistance=2.0, inductance=0.05, k=0.03, voltage=6.0))
    system = m.compile()
    assert system.integration_path("RK4") == "compiled" and system.extra_states == ("motor.current",)
    full = system.simulate(T_END, [0.0, 0.0], method="RK4", dt=DT)
    sampled = system.simulate(T_END, [0.0, 0.0], method="RK4", dt=DT, t_eval=[0.2, 0.305])
    np.testing.assert_array_equal(sampled.q[0], full.q[20])
    assert sampled["motor.current"][0] == full["motor.current"][20]
    # Midway between two steps: the mean of the neighbours to within the curvature of the motion.
    assert_close(sampled.q[1], 0.5 * (full.q[30] + full.q[31]), rtol=0, atol=1e-4, name="midway q")
    assert_close(sampled["motor.current"][1], 0.5 * (full["motor.current"][30] + full["motor.current"][31]),
                 rtol=1e-3, name="midway current")


def test_quaternion_samples_stay_unit():
    m = mb.Model("top")
    b = m.add(mb.Body("b", mass=1.0, com=(0, 0, 0.3), inertia=(0.01, 0.01, 0.02)))
    m.add(mb.Ball("ball", m.ground, b))
    system = m.compile()
    assert system.integration_path("RK4") == "compiled"
    q0 = np.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0])
    res = system.simulate(0.2, q0, [0.0, 0.0, 20.0], method="RK4", dt=0.01, t_eval=[0.005, 0.1, 0.155])
    assert_close(np.linalg.norm(res.q, axis=1), np.ones(3), rtol=0, atol=1e-15, name="|quaternion|")
    full = system.simulate(0.2, q0, [0.0, 0.0, 20.0], method="RK4", dt=0.01)
    np.testing.assert_array_equal(res.q[1], full.q[10])


def test_a_failing_run_still_reports_where(chain):
    with pytest.raises(mb.ModelError, match="whole number of steps"):
        chain.simulate(0.5, [0.1, 0.0, 0.0], method="RK4", dt=0.3, integrator="compiled", t_eval=[0.5])
