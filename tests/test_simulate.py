"""simulate(): closed-form solutions for every solver method (scipy's test_ivp style),
conservation, and the Result it returns."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from scipy.special import ellipj, ellipk

import mbcomp as mb
from conftest import arm_model, assert_close

METHODS = ("RK45", "DOP853", "Radau")
G = 9.81


def scaled_error(y, y_true, rtol, atol) -> float:
    """Largest error in units of the requested tolerance: |y - y_true| / (atol + rtol |y_true|)."""
    y, y_true = np.asarray(y), np.asarray(y_true)
    return float(np.max(np.abs(y - y_true) / (atol + rtol * np.abs(y_true))))


def pendulum(length=0.7, mass=1.3):
    """Point mass on a massless rod, hinge about x; theta'' = -(g / L) sin(theta)."""
    m = mb.Model("pendulum", gravity=(0, 0, -G))
    bob = m.add(mb.Body("bob", mass=mass, com=(0, 0, -length)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    return m


def pendulum_exact(t, theta0, length):
    """Exact large-amplitude solution from rest: sin(theta/2) = k cd(w t | k^2), k = sin(theta0/2)."""
    k = np.sin(theta0 / 2)
    sn, cn, dn, _ = ellipj(np.sqrt(G / length) * t, k * k)
    return 2 * np.arcsin(k * cn / dn)


def crossing_times(t, y):
    i = np.flatnonzero(np.sign(y[:-1]) * np.sign(y[1:]) < 0)
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


@pytest.fixture(scope="module")
def pendulum_system():
    return pendulum().compile()


@pytest.mark.parametrize("method", METHODS)
class TestClosedForms:
    def test_small_angle_pendulum_period(self, pendulum_system, method):
        length, theta0 = 0.7, 1e-3
        period = 2 * np.pi * np.sqrt(length / G)
        t = np.linspace(0, 3.3 * period, 3301)
        res = pendulum_system.simulate(t[-1], [theta0], method=method, t_eval=t, rtol=1e-8, atol=1e-12)
        measured = 2 * np.mean(np.diff(crossing_times(res.t, res["theta"])))
        # The first amplitude correction, theta0^2 / 16 = 6e-8, is below the tolerance.
        assert measured == pytest.approx(period, rel=1e-6)

    def test_pendulum_follows_the_elliptic_solution(self, pendulum_system, method):
        length, theta0, rtol, atol = 0.7, 1.2, 1e-7, 1e-9
        t = np.linspace(0, 2.0, 41)                     # about 1.1 periods
        res = pendulum_system.simulate(2.0, [theta0], method=method, t_eval=t, rtol=rtol, atol=atol)
        # Global error over a period: up to ~13 tolerances for RK45, 4 for DOP853, 0.3 for Radau.
        assert scaled_error(res["theta"], pendulum_exact(t, theta0, length), rtol, atol) < 30
        large_period = 4 * ellipk(np.sin(theta0 / 2) ** 2) / np.sqrt(G / length)
        assert large_period > 2 * np.pi * np.sqrt(length / G) * 1.09     # the test is not a small-angle one

    def test_free_fall_along_a_slide_in_any_gravity(self, method):
        rng = np.random.default_rng(42)
        gravity, axis = rng.normal(size=3) * 5, rng.normal(size=3)
        n = axis / np.linalg.norm(axis)
        m = mb.Model("slide", gravity=tuple(gravity))
        block = m.add(mb.Body("block", mass=2.0, com=(0.1, 0.2, 0.3), inertia=(0.1, 0.2, 0.25)))
        m.add(mb.Prismatic("rail", m.ground, block, axis=tuple(axis), coords="s"))
        sys = m.compile(backend="python")
        rtol, atol = 1e-8, 1e-10
        t = np.linspace(0, 2.0, 21)
        q0, v0 = 0.3, -1.1
        res = sys.simulate(2.0, [q0], [v0], method=method, t_eval=t, rtol=rtol, atol=atol)
        s_true = q0 + v0 * t + 0.5 * (gravity @ n) * t ** 2
        assert scaled_error(res["s"], s_true, rtol, atol) < 5
        assert scaled_error(res.qd[:, 0], v0 + (gravity @ n) * t, rtol, atol) < 5

    def test_mass_spring_damper(self, method):
        mass, k, c, x0 = 0.8, 20.0, 0.6, 0.05
        m = mb.Model("msd", gravity=(0, 0, -G))
        cart = m.add(mb.Body("cart", mass=mass))
        m.add(mb.Prismatic("slide", m.ground, cart, axis="x", coords="x"))
        m.add(mb.TorsionSpring("spring", "slide", stiffness=k, damping=c))
        rtol, atol = 1e-7, 1e-10
        t = np.linspace(0, 3.0, 61)
        res = m.compile(backend="python").simulate(3.0, [x0], method=method, t_eval=t, rtol=rtol, atol=atol)
        omega, zeta = np.sqrt(k / mass), c / (2 * np.sqrt(k * mass))
        wd = omega * np.sqrt(1 - zeta ** 2)
        x_true = x0 * np.exp(-zeta * omega * t) * (np.cos(wd * t) + zeta * omega / wd * np.sin(wd * t))
        assert scaled_error(res["x"], x_true, rtol, atol) < 20

    def test_constant_tau_spins_up_a_rotor(self, method):
        m = mb.Model("rotor")
        disc = m.add(mb.Body("disc", mass=2.0, inertia=(0.1, 0.1, 0.2)))
        m.add(mb.Revolute("spin", m.ground, disc, axis="z", coords="phi"))
        t = np.linspace(0, 1.0, 11)
        rtol, atol = 1e-8, 1e-10
        res = m.compile(backend="python").simulate(1.0, [0.0], method=method, t_eval=t, tau=[0.3],
                                                    rtol=rtol, atol=atol)
        assert scaled_error(res["phi"], 0.5 * (0.3 / 0.2) * t ** 2, rtol, atol) < 5


class TestConservation:
    @pytest.mark.parametrize("which", ["double_pendulum", "arm"])
    def test_unforced_model_keeps_its_energy(self, which, double_pendulum):
        model = double_pendulum if which == "double_pendulum" else arm_model()
        sys = model.compile()
        q0 = [1.2, -0.6] if which == "double_pendulum" else [0.8, -0.4, 1.1]
        qd0 = [0.5, -1.0] if which == "double_pendulum" else [0.3, 0.6, -0.2]
        res = sys.simulate(20.0, q0, qd0, method="DOP853", rtol=1e-12, atol=1e-12,
                           t_eval=np.linspace(0, 20, 401))
        total = res.energy().total
        swing = np.max(np.abs(res.energy().kinetic))
        assert swing > 1.0                                # the motion is not trivial
        drift = np.max(np.abs(total - total[0]))
        assert drift < 1e-8 * abs(total[0])
        assert drift < 1e-8 * swing

    def test_damped_model_never_gains_energy(self):
        m = arm_model()
        m.add(mb.TorsionSpring("elbow_damper", "elbow", stiffness=0.0, damping=0.05))
        m.add(mb.Damper("tendon", a=(m.ground, (0.0, 0.1, 0.1)), b=("lower", (0, 0.2, 0)), damping=0.5))
        res = m.compile().simulate(5.0, [0.8, -0.4, 1.1], [0.3, 0.6, -0.2], rtol=1e-10, atol=1e-12,
                                   t_eval=np.linspace(0, 5, 501))
        total = res.energy().total
        scale = np.max(np.abs(total))
        assert np.all(np.diff(total) <= 1e-10 * scale)
        assert total[-1] < total[0] - 0.01 * scale


class TestResult:
    @pytest.fixture(scope="class")
    def arm(self):
        return arm_model().compile()

    def test_t_eval_is_respected(self, arm):
        t = np.array([0.0, 0.05, 0.13, 0.5, 1.0])
        res = arm.simulate(1.0, [0.1, 0.2, 0.3], t_eval=t)
        assert np.array_equal(res.t, t)
        assert res.q.shape == (5, 3) and res.qd.shape == (5, 3)

    def test_without_t_eval_the_solver_steps_span_the_interval(self, arm):
        res = arm.simulate(0.5, [0.1, 0.2, 0.3])
        assert res.t[0] == 0.0 and res.t[-1] == 0.5
        assert np.all(np.diff(res.t) > 0)
        assert res.stats["steps"] == len(res.t) - 1

    def test_initial_state_is_the_first_sample(self, arm):
        res = arm.simulate(0.2, [0.1, 0.2, 0.3], [0.4, 0.5, 0.6])
        assert_close(res.q[0], [0.1, 0.2, 0.3], rtol=0, atol=0, name="q0")
        assert_close(res.qd[0], [0.4, 0.5, 0.6], rtol=0, atol=0, name="qd0")

    def test_series_by_coordinate_name(self, arm):
        res = arm.simulate(0.2, [0.1, 0.2, 0.3], [0.4, 0.5, 0.6], t_eval=[0.0, 0.1, 0.2])
        assert res.coords == ("alpha", "beta", "gamma")
        for i, name in enumerate(res.coords):
            assert np.array_equal(res[name], res.q[:, i])
            assert np.array_equal(res[f"{name}_d"], res.qd[:, i])
        with pytest.raises(KeyError, match="delta"):
            res["delta"]

    def test_speeds_are_the_derivative_of_positions(self, arm):
        t = np.linspace(0, 1, 2001)
        dt = t[1] - t[0]
        res = arm.simulate(1.0, [0.1, 0.2, 0.3], [0.4, 0.5, 0.6], t_eval=t, rtol=1e-10, atol=1e-12)
        q = res.q
        # Fourth-order central differences (the arm's elbow jerks at ~2e4 rad/s^3).
        dq_dt = (-q[4:] + 8 * q[3:-1] - 8 * q[1:-3] + q[:-4]) / (12 * dt)
        assert_close(dq_dt, res.qd[2:-2], rtol=0, atol=1e-6, name="dq/dt")

    def test_stats(self, arm):
        res = arm.simulate(0.5, [0.1, 0.2, 0.3], method="RK45")
        for key in ("method", "nfev", "njev", "nlu", "steps", "status", "message", "success", "wall_time"):
            assert key in res.stats, key
        assert res.stats["method"] == "RK45"
        assert res.stats["success"] is True and res.stats["status"] == 0
        assert res.stats["nfev"] >= 6 * res.stats["steps"] > 0
        assert res.stats["wall_time"] > 0

    def test_energy_series(self, arm):
        res = arm.simulate(0.3, [0.1, 0.2, 0.3], [0.4, 0.5, 0.6], t_eval=[0.0, 0.15, 0.3])
        energy = res.energy()
        for i in range(3):
            point = arm.energy(res.q[i], res.qd[i])
            assert energy.kinetic[i] == pytest.approx(point.kinetic, rel=1e-14)
            assert energy.potential[i] == pytest.approx(point.potential, rel=1e-14)
        assert_close(energy.total, energy.kinetic + energy.potential, name="total energy")

    def test_unconstrained_model_has_no_reactions_or_violation(self, arm):
        res = arm.simulate(0.2, [0.1, 0.2, 0.3], t_eval=[0.0, 0.1, 0.2])
        assert res.reactions == {}
        assert np.all(res.constraint_violation() == 0.0)
        assert res.events == []

    def test_to_csv_writes_every_coordinate(self, arm, tmp_path):
        res = arm.simulate(0.2, [0.1, 0.2, 0.3], [0.4, 0.5, 0.6], t_eval=np.linspace(0, 0.2, 7))
        path = tmp_path / "out.csv"
        res.to_csv(path)
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
        header = rows[0]
        assert header[0] == "t"
        for name in res.coords:
            assert name in header
        assert len(rows) == 1 + 7
        data = np.array(rows[1:], dtype=float)
        assert_close(data[:, 0], res.t, rtol=0, atol=0, name="t column")
        for i, name in enumerate(res.coords):
            assert_close(data[:, header.index(name)], res.q[:, i], rtol=0, atol=0, name=f"{name} column")

    def test_simulation_does_not_change_the_system(self, arm):
        before = arm.parameters
        arm.simulate(0.1, [0.1, 0.2, 0.3], parameters={"upper.mass": 9.0})
        assert arm.parameters == before

    def test_callable_tau_is_evaluated(self):
        m = mb.Model("rotor")
        disc = m.add(mb.Body("disc", mass=2.0, inertia=(0.1, 0.1, 0.2)))
        m.add(mb.Revolute("spin", m.ground, disc, axis="z", coords="phi"))
        res = m.compile(backend="python").simulate(1.0, [0.0], tau=lambda t, q, qd: [0.6 * t], t_eval=[0.5, 1.0],
                                                    rtol=1e-10, atol=1e-12)
        assert_close(res["phi"], 0.6 / 0.2 * res.t ** 3 / 6, rtol=1e-8, name="phi(t)")


class TestSettings:
    @pytest.fixture(scope="class")
    def sys(self):
        return pendulum().compile()

    @pytest.mark.parametrize("t_end", [0.0, -1.0, float("nan"), float("inf"), "soon"])
    def test_bad_t_end_is_rejected(self, sys, t_end):
        with pytest.raises(mb.ModelError, match="t_end"):
            sys.simulate(t_end, [0.1])

    @pytest.mark.parametrize("name", ["rtol", "atol"])
    @pytest.mark.parametrize("value", [0.0, -1e-6, float("nan")])
    def test_non_positive_tolerance_is_rejected(self, sys, name, value):
        with pytest.raises(mb.ModelError, match=name):
            sys.simulate(1.0, [0.1], **{name: value})

    @pytest.mark.parametrize("t_eval", [[0.0, 2.0], [0.5, 0.2], [-0.1, 0.5]], ids=["beyond", "decreasing", "negative"])
    def test_bad_t_eval_is_rejected(self, sys, t_eval):
        with pytest.raises(mb.ModelError, match="t_eval"):
            sys.simulate(1.0, [0.1], t_eval=t_eval)

    def test_unknown_method_is_rejected(self, sys):
        with pytest.raises(mb.ModelError):
            sys.simulate(1.0, [0.1], method="Euler")

    def test_wrong_initial_state_is_rejected(self, sys):
        with pytest.raises(mb.ModelError):
            sys.simulate(1.0, [0.1, 0.2])
        with pytest.raises(mb.ModelError):
            sys.simulate(1.0, [0.1], [float("nan")])

    def test_progress_is_written_to_stderr(self, sys, capsys):
        sys.simulate(0.5, [0.1], progress=True)
        captured = capsys.readouterr()
        assert "100%" in captured.err
        assert captured.out == ""

    def test_no_progress_by_default(self, sys, capsys):
        sys.simulate(0.5, [0.1])
        assert capsys.readouterr().err == ""
