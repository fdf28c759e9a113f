"""The dae formulation's compiled loop with motors and contacts, against analytic results.

(The same models against scipy-stepped runs: tests/test_library.py,
``test_compiled_stepping_equals_scipy_stepping``.)"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core.expressions import Expression, parse_expression
from mbcomp.codegen.expressions_c import STACK, compile_position, compile_program, run_program

LIBRARY = Path(__file__).resolve().parents[2] / "library"


@pytest.fixture(scope="module")
def ball():
    return mb.load(LIBRARY / "bouncing_ball.toml").compile(formulation="dae")


def test_bouncing_ball_impact_times_and_apex_heights(ball):
    """Dropped from h (centre; radius r) with restitution e: first impact at
    t1 = sqrt(2 (h - r) / g), then flights of 2 e^k v1 / g; the k-th apex is e^(2k) (h - r)
    above the touching height, e^k v1 / g after the k-th impact."""
    g, h, r, e = 9.81, 1.0, 0.05, 0.8
    v1 = math.sqrt(2 * g * (h - r))
    impacts = [v1 / g]
    for k in range(1, 5):
        impacts.append(impacts[-1] + 2 * e ** k * v1 / g)
    apexes = [t + e ** (k + 1) * v1 / g for k, t in enumerate(impacts[:4])]
    result = ball.simulate(3.0, [h], [0.0], t_eval=apexes, rtol=1e-10, atol=1e-12)
    assert result.stats["integrator"] == "compiled" and result.stats["formulation"] == "dae"
    times = [ev.time for ev in result.events]
    np.testing.assert_allclose(times[:5], impacts, rtol=0, atol=1e-9)
    assert all(ev.contact == "floor" for ev in result.events[:5])
    np.testing.assert_allclose(result.q[:, 0] - r, [e ** (2 * (k + 1)) * (h - r) for k in range(4)], rtol=1e-8)
    np.testing.assert_allclose(result.qd[:, 0], 0.0, atol=1e-8)
    # each impulse reverses the speed with restitution e: m (1 + e) e^k v1
    impulses = [ev.impulse for ev in result.events[:4]]
    np.testing.assert_allclose(impulses, [0.1 * (1 + e) * e ** k * v1 for k in range(4)], rtol=1e-8)


def test_bouncing_ball_comes_to_rest_on_the_floor(ball):
    """The bounces accumulate (Zeno, by t1 (1 + 2 e / (1 - e)) = 3.96 s): the ball ends
    resting, the floor held closed, its normal force the weight."""
    result = ball.simulate(4.5, [1.0], [0.0], rtol=1e-10, atol=1e-12)
    assert result.stats["integrator"] == "compiled"
    assert result.persistent_contacts == ["floor"]
    assert abs(result.q[-1, 0] - 0.05) < 1e-9 and abs(result.qd[-1, 0]) < 1e-8
    np.testing.assert_allclose(result.reactions["floor"][-1], 0.1 * 9.81, rtol=1e-8)
    stepped = ball.simulate(4.5, [1.0], [0.0], rtol=1e-10, atol=1e-12, integrator="scipy")
    # the same bounces while they are large; the last micro-bounces (speeds near rest_speed)
    # are decided by rounding, so their number may differ by one
    large = [ev.time for ev in stepped.events if ev.impulse > 1e-3]
    assert len(large) > 20 and abs(len(result.events) - len(stepped.events)) <= 1
    np.testing.assert_allclose([ev.time for ev in result.events[:len(large)]], large, atol=1e-9)


def test_motor_crank_follows_its_prescribed_angle_and_needs_the_inverse_dynamics_torque():
    """double_pendulum_motor: phi1 = 0.5 sin(2 pi t) (a file expression, run in C). The
    angle is tracked to the integration accuracy, and the motor's reaction is the torque the
    inverse dynamics give for the prescribed motion (qdd_1 exact, bar 2 free)."""
    model = mb.load(LIBRARY / "double_pendulum_motor.toml")
    system = model.compile(formulation="dae")
    t = np.linspace(0.0, 2.0, 41)
    result = system.simulate(2.0, [0.0, 0.3], [math.pi, 0.0], t_eval=t, rtol=1e-10, atol=1e-12)
    assert result.stats["integrator"] == "compiled"
    w = 2 * math.pi
    np.testing.assert_allclose(result["phi1"], 0.5 * np.sin(w * t), atol=1e-9)
    np.testing.assert_allclose(result.qd[:, 0], 0.5 * w * np.cos(w * t), atol=1e-8)
    torque = result.reactions["motor"]
    for i in range(0, len(t), 5):
        q, qd = result.q[i], result.qd[i]
        M, f = system.tree_dynamics(q, qd, t[i])
        a1 = -0.5 * w * w * math.sin(w * t[i])
        a2 = (f[1] - M[1, 0] * a1) / M[1, 1]
        expected = M[0] @ np.array([a1, a2]) - f[0]
        assert abs(torque[i] - expected) < 1e-6 * (1 + abs(expected)), (t[i], torque[i], expected)


def test_speed_motor_slider_crank_is_kinematic():
    """slider_crank: the crank turns at omega = 2 pi rad/s (a speed motor); the piston
    follows x = r cos(theta) + sqrt(l^2 - r^2 sin(theta)^2)."""
    model = mb.load(LIBRARY / "slider_crank.toml")
    system = model.compile(formulation="dae")
    q0 = np.array([system.coords.index(c) for c in ("theta", "psi", "x")])
    q, qd = np.zeros(len(system.coords)), np.zeros(len(system.speeds))
    q[q0[2]] = 0.4
    t = np.linspace(0.0, 1.0, 21)
    result = system.simulate(1.0, q, qd, t_eval=t, rtol=1e-10, atol=1e-12)
    assert result.stats["integrator"] == "compiled"
    theta = result["theta"]
    np.testing.assert_allclose(theta, 2 * math.pi * t, atol=1e-9)
    r, l = 0.1, 0.3
    np.testing.assert_allclose(result["x"], r * np.cos(theta) + np.sqrt(l * l - (r * np.sin(theta)) ** 2), atol=1e-9)


@pytest.mark.parametrize("text", ["0.5*sin(2*pi*t)", "t**3 - 2*t", "exp(-t)*cos(3*t) + sqrt(1 + t*t)",
                                  "-(t/2)**2.5", "1.5"])
def test_motor_programs_evaluate_as_the_expressions(text):
    """The postfix programs give the expression and its exact derivatives, as Python does."""
    node = parse_expression(text, {}, allow_t=True)
    expression = Expression(text, node)
    programs = compile_position(expression)
    first = expression.diff()
    for t in (0.0, 0.37, 1.9):
        n0 = int(programs[0])
        p1 = programs[1 + 2 * n0:]
        n1 = int(p1[0])
        p2 = p1[1 + 2 * n1:]
        values = [run_program(programs, t), run_program(p1, t), run_program(p2, t)]
        assert values == [expression(t), first(t), first.diff()(t)]


def test_motor_program_rejects_what_it_cannot_run():
    node = ("t",)
    for _ in range(STACK):
        node = ("+", ("t",), node)  # STACK + 1 entries on the stack
    with pytest.raises(mb.ModelError, match="stack"):
        compile_program(node)
    assert compile_position(lambda t: t) is None  # a Python callable: no program of its own


def test_python_callable_motor_runs_compiled():
    """A position given as a Python callable runs compiled, its values called back from C
    (codegen/callbacks.py): the compiled run of the same motion as a file expression
    reproduces it."""
    from conftest import fourbar
    crank = lambda t: 1.0 + 0.8 * np.sin(3 * t)
    system = fourbar(motor=mb.Motor("drive", "A", position=crank)).compile("dae")
    assert system.integration_path() == "compiled"
    q, qd = system.assemble([1.0, -0.5, 1.5])
    t = np.linspace(0.0, 1.0, 11)
    stepped = system.simulate(1.0, q, qd, t_eval=t, rtol=1e-10, atol=1e-12)
    assert stepped.stats["integrator"] == "compiled"
    text = "1.0 + 0.8*sin(3*t)"
    expression = Expression(text, parse_expression(text, {}, allow_t=True))
    compiled = fourbar(motor=mb.Motor("drive", "A", position=expression)).compile("dae")
    assert compiled.integration_path() == "compiled"
    result = compiled.simulate(1.0, q, qd, t_eval=t, rtol=1e-10, atol=1e-12)
    assert result.stats["integrator"] == "compiled"
    np.testing.assert_allclose(result["A"], crank(t), atol=1e-9)
    np.testing.assert_allclose(result.q, stepped.q, atol=1e-8)
    np.testing.assert_allclose(result.reactions["drive"], stepped.reactions["drive"], rtol=1e-6, atol=1e-8)


def test_a_step_hook_stops_a_compiled_contact_run():
    """Interrupts reach the compiled stretches between contact events as in other loops."""
    from mbcomp.codegen.integrators import step_hook
    system = mb.load(LIBRARY / "pendulum_wall.toml").compile(formulation="dae")
    with step_hook(lambda t: t > 1.0, interval=0.0):
        with pytest.raises(mb.SimulationError, match="stopped at t = .* by a step hook"):
            system.simulate(4.0, [0.6], [0.0], rtol=1e-10, atol=1e-12, integrator="compiled")


def test_event_times_located_in_c_equal_scipys_brentq(ball, monkeypatch):
    """Brent's method in C (events_c.py) finds the same root as scipy's brentq on the same
    gap function (the C gaps on the event step's dense output)."""
    from scipy.optimize import brentq
    from mbcomp.formulations import dae_compiled
    pairs = []
    original = dae_compiled._Locator.gap_root

    def both(self, i, a, b, xtol, rtol):
        located = original(self, i, a, b, xtol, rtol)
        pairs.append((located, brentq(lambda s: self.gap(s, i), a, b, xtol=xtol, rtol=rtol)))
        return located

    monkeypatch.setattr(dae_compiled._Locator, "gap_root", both)
    result = ball.simulate(2.0, [1.0], [0.0], rtol=1e-10, atol=1e-12)
    assert len(pairs) == len(result.events) >= 3
    for located, reference in pairs:
        assert abs(located - reference) <= 4e-16 * abs(reference) + 1e-14
