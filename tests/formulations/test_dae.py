"""The ``dae`` formulation: options, the Baumgarte law, drift over long runs, projection."""
from __future__ import annotations

import functools

import numpy as np
import pytest

import mbcomp as mb
from conftest import assert_close, bar, fourbar
from mbcomp.formulations.dae import DEFAULT_BAUMGARTE

G = 9.81


def slider_crank(y0=0.0):
    """Crank 0.2 m, rod 0.6 m; the rod end stays on the line y = y0 (Slider 'piston')."""
    m = mb.Model("slider_crank", gravity=(0, -G, 0))
    crank, rod = m.add(bar("crank", 0.2)), m.add(bar("rod", 0.6, mass=0.5))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(0.2, 0, 0)))
    m.add(mb.Slider("piston", rod, point=(0.6, 0, 0), origin=(0, y0, 0), axis="x"))
    return m


class TestOptions:
    def test_default_gains(self):
        s = fourbar().compile("dae")
        assert s.formulation == "dae"
        assert DEFAULT_BAUMGARTE == (5.0, 5.0)

    @pytest.mark.parametrize("gains", [(-1.0, 5.0), (5.0, float("nan")), (1.0,), "fast"], ids=str)
    def test_bad_gains_are_rejected(self, gains):
        with pytest.raises(mb.ModelError, match="baumgarte"):
            fourbar().compile("dae", baumgarte=gains)

    def test_unknown_option_is_rejected(self):
        with pytest.raises(mb.ModelError, match="stabilisation"):
            fourbar().compile("dae", stabilisation=True)


class TestBaumgarte:
    @pytest.mark.parametrize("gains", [(0.0, 0.0), (5.0, 5.0), (10.0, 3.0), (1.0, 20.0)], ids=str)
    def test_constraint_error_obeys_the_stabilisation_law(self, gains):
        """Off the constraint, with g = y of the slider point: g'' = -2 alpha g' - beta^2 g.
        g, g' and g'' are read from body_state (positions, velocities, accelerations of the
        point), not from the constraint code."""
        alpha, beta = gains
        y0 = 0.03
        s = slider_crank(y0).compile("dae", baumgarte=gains)
        q, qd = np.array([0.5, -0.6]), np.array([1.5, -0.7])   # not assembled: g and g' nonzero
        tip = s.body_state("rod", q, qd, point=(0.6, 0, 0))
        g, gd, gdd = tip.position[1] - y0, tip.velocity[1], tip.acceleration[1]
        assert abs(g) > 0.005 and abs(gd) > 0.1
        assert_close(gdd, -2 * alpha * gd - beta ** 2 * g, rtol=1e-9, atol=1e-9, name="g''")

    def test_gains_do_not_change_consistent_accelerations(self):
        states = fourbar().compile("lagrange").assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        reference = fourbar().compile("dae", baumgarte=(0, 0)).accelerations(*states)
        for gains in ((5, 5), (50, 50)):
            qdd = fourbar().compile("dae", baumgarte=gains).accelerations(*states)
            assert_close(qdd, reference, rtol=1e-9, atol=1e-9, name=f"qdd with gains {gains}")

    def test_constraint_error_decays_as_predicted(self):
        """Started 3 cm off the line and at rest, with (alpha, beta) = (5, 5) the error is
        critically damped: g(t) = g0 (1 + 5 t) exp(-5 t)."""
        y0 = 0.03
        s = slider_crank(y0).compile("dae", baumgarte=(5.0, 5.0))
        q = np.array([0.5, -0.6])
        g0 = s.body_state("rod", q, point=(0.6, 0, 0)).position[1] - y0
        # simulate() assembles its start; follow the law with a hand-rolled RK4 instead.
        state = np.concatenate((q, np.zeros(2)))

        def rhs(y):
            return np.concatenate((y[2:], s.accelerations(y[:2], y[2:])))

        h, n = 2e-3, 500
        for _ in range(n):
            k1 = rhs(state)
            k2 = rhs(state + h / 2 * k1)
            k3 = rhs(state + h / 2 * k2)
            k4 = rhs(state + h * k3)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        g = s.body_state("rod", state[:2], point=(0.6, 0, 0)).position[1] - y0
        t = h * n
        assert_close(g, g0 * (1 + 5 * t) * np.exp(-5 * t), rtol=1e-3, atol=1e-7, name="g(1 s)")


def energy_error(res):
    """max |E(t) - E(0)| relative to the largest kinetic energy of the run."""
    E = res.energy()
    return np.max(np.abs(E.total - E.total[0])) / np.max(E.kinetic)


@functools.lru_cache(maxsize=None)
def run_without_gains():
    """The four-bar under dae without Baumgarte gains, stepped by scipy (no projection) for
    20 s from the same start as the drift tests: the drift they compare against."""
    s0 = fourbar().compile("dae", baumgarte=(0, 0))
    q, qd = s0.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
    return s0.simulate(20.0, q, qd, rtol=1e-6, atol=1e-8, integrator="scipy")


class TestDrift:
    def test_fourbar_over_100_s_with_default_gains(self):
        """Large swings, no damping, rtol=1e-7: measured max |C| 4.1e-8 and relative energy
        error 1.6e-6 (about 4 s of wall time; bench/constraints_drift.py has the other gains
        and tolerances)."""
        s = fourbar().compile("dae")
        q, qd = s.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        res = s.simulate(100.0, q, qd, rtol=1e-7, atol=1e-9, t_eval=np.linspace(0, 100, 2001))
        assert np.max(res.constraint_violation()) < 1e-6
        assert energy_error(res) < 1e-5
        assert np.ptp(res["A"]) > 4.0   # large swings through the bottom

    @pytest.mark.xdist_group("dae-without-gains")
    def test_gains_hold_drift_that_grows_without_them(self):
        s5 = fourbar().compile("dae")
        q, qd = s5.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        # Python stepping (no projection after each step), where the gains do the work.
        free = np.max(run_without_gains().constraint_violation())
        held = np.max(s5.simulate(20.0, q, qd, rtol=1e-6, atol=1e-8, integrator="scipy").constraint_violation())
        assert held < free / 100, (held, free)

    def test_compiled_loop_projects_onto_the_constraints_after_each_step(self):
        """The compiled loop moves the state back onto the constraints after every accepted
        step: no drift at the steps even without gains."""
        s0 = fourbar().compile("dae", baumgarte=(0, 0))
        q, qd = s0.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        res = s0.simulate(20.0, q, qd, rtol=1e-6, atol=1e-8)
        assert res.stats["integrator"] == "compiled"
        assert np.max(res.constraint_violation()) < 1e-11


class TestProjection:
    @pytest.mark.xdist_group("dae-without-gains")
    def test_projection_removes_drift_without_gains(self):
        """Without Baumgarte terms, projecting after every step keeps |C| at the level of one
        step's drift instead of letting it accumulate (measured 1.8e-7 against 9.1e-5)."""
        projected = fourbar().compile("dae", baumgarte=(0, 0), projection=True)
        q, qd = projected.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        a = run_without_gains()  # no projection
        b = projected.simulate(20.0, q, qd, rtol=1e-6, atol=1e-8)
        assert np.max(b.constraint_violation()) < np.max(a.constraint_violation()) / 100
        assert energy_error(b) < 1e-4
        assert_close(b.q[-1], a.q[-1], atol=1e-2, rtol=0, name="same motion")

    def test_projected_run_reports_projected_states(self):
        s = fourbar().compile("dae", baumgarte=(0, 0), projection=True)
        q, qd = s.assemble([1.0, -0.5, 1.5], [1.0, 0, 0])
        res = s.simulate(5.0, q, qd, rtol=1e-6, atol=1e-8)
        assert np.max(res.constraint_violation()) < 1e-9


def test_compiled_loop_hook_says_why_not():
    """Each formulation says whether it can step in the compiled integrators, and why not."""
    from conftest import fourbar
    dae = fourbar().compile("dae")
    assert dae._formulation.compiled_loop() is None
    # projection=True: the compiled DOP853 loop projects after every accepted step
    projected = fourbar().compile("dae", projection=True)._formulation
    assert projected.compiled_loop() is None and projected.compiled_methods == ("DOP853",)
    assert "projection" in projected.compiled_method_problem("RK4")
    assert fourbar().compile("lagrange")._formulation.compiled_loop() is None
    # motors run compiled in both: speed motors, and positions given as Python callables
    # (their values called back from C, codegen/callbacks.py)
    position = mb.Motor("drive", "A", position=lambda t: 0.1 * t)
    assert fourbar(motor=position).compile("lagrange")._formulation.compiled_loop() is None
    assert fourbar(motor=mb.Motor("drive", "A", speed=2.0)).compile("dae")._formulation.compiled_loop() is None
    assert fourbar(motor=position).compile("dae")._formulation.compiled_loop() is None


def test_analyse_returns_its_findings_and_changes_nothing():
    """analyse() is a pure study of the constraints: a frozen FormulationInfo."""
    import dataclasses
    from mbcomp.formulations import DaeFormulation
    from mbcomp.formulations.base import FormulationInfo, analyse
    from mbcomp.compiled.kernel import Kernel
    system = fourbar().compile("dae")
    compiled = system.kernel.compiled
    fresh = DaeFormulation(compiled)
    before = dict(vars(fresh))
    info = analyse(fresh, Kernel(compiled, compiled.default_parameters))
    assert vars(fresh) == before and fresh.ndof == 3  # untouched: still the unanalysed tree's count
    assert isinstance(info, FormulationInfo) and info.ndof == 1 == system.ndof  # a four-bar has 1 DOF
    # a planar loop closed by a revolute: 5 equations, only the 2 in-plane ones independent
    assert info.nominal_rank == 2 and info.redundant == ("C.z", "C.t1", "C.t2")
    with pytest.raises(dataclasses.FrozenInstanceError):
        info.ndof = 2
    with pytest.raises(ValueError):
        info.nominal_rows[0] = 3


def test_projection_on_quaternion_coordinates_runs_compiled_and_holds_the_contact():
    """projection=True on a Free joint with a held contact runs in the compiled loop (its
    projection steps the quaternion by the exp-map, as Python stepping's state map), keeps
    the resting, spinning ball on the floor to the Newton level and moves as the
    Python-stepped projected run."""
    m = mb.Model("resting_ball", gravity=(0, 0, -9.81))
    ball = m.add(mb.Body("ball", mass=1.0, inertia=(0.004,) * 3))
    m.add(mb.Free("free", m.ground, ball))
    m.add(mb.Contact("floor", ball, (0, 0, 0), normal=(0, 0, 1), restitution=0.0, radius=0.1))
    projected = m.compile("dae", projection=True)
    assert projected.integration_path() == "compiled"
    assert m.compile("dae").integration_path() == "compiled"
    q0, v0 = [0, 0, 0.1, 1, 0, 0, 0], [0.3, 0, 0, 0, 0, 2.0]
    res = projected.simulate(0.5, q0, v0)
    assert res.stats["integrator"] == "compiled"
    python = projected.simulate(0.5, q0, v0, integrator="scipy")
    np.testing.assert_allclose(res.q[-1], python.q[-1], atol=1e-9)
    np.testing.assert_allclose(res.q[-1, 3:], [np.cos(0.5), 0, 0, np.sin(0.5)], atol=1e-9)  # 2 rad/s for 0.5 s
    np.testing.assert_allclose(res.q[:, 2], 0.1, atol=1e-9)
