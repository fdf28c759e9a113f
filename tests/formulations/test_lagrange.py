"""The ``lagrange`` formulation: dependent coordinates by Newton, motors eliminated,
residuals at Newton tolerance over long runs, kinematics against closed forms."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import assert_close, bar, fourbar

G = 9.81
L1, L2, L3, D = 0.3, 0.8, 0.6, 0.7   # crank, coupler, rocker, base


def slider_crank():
    m = mb.Model("slider_crank", gravity=(0, -G, 0))
    crank, rod = m.add(bar("crank", 0.2)), m.add(bar("rod", 0.6, mass=0.5))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(0.2, 0, 0)))
    m.add(mb.Slider("piston", rod, point=(0.6, 0, 0), origin=(0, 0, 0), axis="x"))
    return m


def rocker_angle(crank, near):
    """Closed-form four-bar position: the rocker angle for a crank angle, on the branch
    nearest ``near``.  The rocker tip lies on the circle of radius L2 about the crank tip
    and on the circle of radius L3 about (D, 0)."""
    b = np.array([L1 * np.cos(crank), L1 * np.sin(crank)])
    d = np.array([D, 0.0])
    dist = np.linalg.norm(b - d)
    a = (L3 ** 2 - L2 ** 2 + dist ** 2) / (2 * dist)        # from d towards b
    h = np.sqrt(L3 ** 2 - a ** 2)
    e = (b - d) / dist
    tips = [d + a * e + s * h * np.array([-e[1], e[0]]) for s in (1, -1)]
    angles = np.array([np.arctan2(p[1], p[0] - D) for p in tips])
    angles = near + np.angle(np.exp(1j * (angles - near)))   # unwrap next to ``near``
    return angles[np.argmin(np.abs(angles - near))]


def energy_error(res):
    E = res.energy()
    return np.max(np.abs(E.total - E.total[0])) / np.max(E.kinetic)


class TestDependentCoordinates:
    def test_assembled_fourbar_matches_the_closed_form(self):
        s = fourbar().compile("lagrange")
        for guess in ([1.0, -0.5, 1.5], [-1.0, 2.0, 3.0], [0.3, 0.5, 2.0]):
            q, _ = s.assemble(guess)
            assert_close(q[2], rocker_angle(q[0], q[2] + 0.1), atol=1e-10, name="rocker angle")

    def test_residual_stays_at_newton_tolerance_over_100_s(self):
        """Swinging about the hanging position, no damping, rtol=1e-7 (about 6 s of wall
        time): every recorded state satisfies the loop to < 1e-10 m (measured 9.7e-13)."""
        s = fourbar().compile("lagrange")
        q, qd = s.assemble([-1.24, 2.50, 2.22], [0, 0, 0])
        res = s.simulate(100.0, q, qd, rtol=1e-7, atol=1e-9, t_eval=np.linspace(0, 100, 2001))
        assert np.max(res.constraint_violation()) < 1e-10
        assert energy_error(res) < 1e-5
        assert np.ptp(res["A"]) > 1.0

    def test_large_swings_complete(self):
        """5 s of large swings and full turns from (1.0, -0.5, 1.5) with the crank at several
        speeds and tolerances: every run completes, on the constraint, without jumps in q."""
        s = fourbar().compile("lagrange")
        for speed, rtol in ((1.0, 1e-8), (4.0, 1e-6), (0.0, 1e-7)):
            q, qd = s.assemble([1.0, -0.5, 1.5], [speed, 0, 0])
            res = s.simulate(5.0, q, qd, rtol=rtol, atol=rtol * 1e-2)
            assert np.max(res.constraint_violation()) < 1e-10
            assert energy_error(res) < 1e-4
            assert np.max(np.abs(np.diff(res.q, axis=0))) < 1.5   # no 2 pi or branch jumps between steps

    def test_full_turn_slider_crank(self):
        """The crank turns over nearly four times in 3 s; the run stays on the constraint at
        Newton tolerance, conserves energy and agrees with dae."""
        lagrange, dae = slider_crank().compile("lagrange"), slider_crank().compile("dae")
        q, qd = lagrange.assemble([0.5, -0.6], [8.0, 0.0])
        t = np.linspace(0, 3, 301)
        a = lagrange.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        b = dae.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
        assert np.all(np.diff(a["A"]) > 0) and a["A"][-1] > 3 * 2 * np.pi
        assert np.max(a.constraint_violation()) < 1e-10
        assert energy_error(a) < 1e-8
        assert_close(a.q, b.q, atol=1e-7, rtol=0, name="q(t)")


class TestMotorsInLoops:
    def test_position_motor_drives_the_fourbar_kinematically(self):
        """ndof = 0: the rocker follows the closed-form four-bar position for the
        prescribed crank angle."""
        crank = lambda t: 1.0 + 0.8 * np.sin(3 * t)
        s = fourbar(motor=mb.Motor("drive", "A", position=crank)).compile("lagrange")
        assert s.ndof == 0
        q, qd = s.assemble([1.0, -0.5, 1.5])
        res = s.simulate(2.0, q, qd, t_eval=np.linspace(0, 2, 41))
        assert_close(res["A"], crank(res.t), atol=1e-10, name="crank")
        expected = []
        near = q[2]
        for a in res["A"]:
            near = rocker_angle(a, near)
            expected.append(near)
        assert_close(res["D"], expected, atol=1e-9, name="rocker")
        assert np.max(res.constraint_violation()) < 1e-10

    @pytest.mark.parametrize("formulation", ["lagrange", "dae"])
    def test_speed_motor_work_equals_energy_change(self, formulation):
        """The crank driven at 3 rad/s through full turns: the motor's work (Simpson's rule
        on torque * speed; measured error 1e-7 relative with 601 samples) equals the change of
        the mechanism's energy."""
        from scipy.integrate import cumulative_simpson
        s = fourbar(motor=mb.Motor("drive", "A", speed=3.0)).compile(formulation)
        q, qd = s.assemble([1.0, -0.5, 1.5])
        res = s.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=np.linspace(0, 3, 601))
        assert_close(res["A"], q[0] + 3.0 * res.t, atol=1e-8, name="crank angle")
        power = res.reactions["drive"][:, 0] * res["A_d"]
        work = cumulative_simpson(power, x=res.t, initial=0.0)
        E = res.energy().total
        assert np.max(np.abs(work)) > 1.0
        assert np.max(np.abs(work - (E - E[0]))) < 1e-6 * np.max(np.abs(work))

    def test_motor_torque_agrees_between_formulations(self):
        lagrange = fourbar(motor=mb.Motor("drive", "A", speed=3.0)).compile("lagrange")
        dae = fourbar(motor=mb.Motor("drive", "A", speed=3.0)).compile("dae")
        for guess in ([1.0, -0.5, 1.5], [-1.0, 2.0, 3.0]):
            q, qd = lagrange.assemble(guess)
            ra, rb = lagrange.reactions(q, qd), dae.reactions(q, qd)
            assert_close(ra["drive"], rb["drive"], rtol=1e-8, atol=1e-8, name="motor torque")
            assert_close(ra["C"], rb["C"], rtol=1e-8, atol=1e-8, name="loop force")
            assert_close(lagrange.accelerations(q, qd), dae.accelerations(q, qd), rtol=1e-8, atol=1e-8, name="qdd")
