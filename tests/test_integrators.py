"""Compiled integration loops: identical to scipy's DOP853, RK4 of order 4, clear failures."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import pendulum_chain


@pytest.fixture(scope="module")
def chain():
    system = pendulum_chain(4).compile()
    if system.backend != "c":
        pytest.skip("no C compiler: the compiled loops need the C backend")
    return system


Q0, QD0 = np.full(4, 0.3), np.zeros(4)


class TestCompiledDop853:
    @pytest.mark.parametrize("tol", [1e-6, 1e-9])
    def test_takes_the_same_steps_as_scipy(self, chain, tol):
        """Same algorithm: the same number of steps and evaluations.  Step sizes agree only to
        ~1e-9 because the error estimate cancels many digits, so rounding differences of the
        stage sums (numpy's dot vs a C loop) move them slightly."""
        compiled = chain.simulate(3.0, Q0, QD0, rtol=tol, atol=tol)
        stepped = chain.simulate(3.0, Q0, QD0, rtol=tol, atol=tol, integrator="scipy")
        assert compiled.stats["integrator"] == "compiled" and stepped.stats["integrator"] == "scipy"
        assert compiled.stats["nfev"] == stepped.stats["nfev"]
        np.testing.assert_allclose(compiled.t, stepped.t, rtol=0, atol=1e-7)
        np.testing.assert_allclose(compiled.q[-1], stepped.q[-1], rtol=0, atol=100 * tol)

    def test_dense_output_at_t_eval_matches_scipy(self, chain):
        t_eval = np.linspace(0.0, 3.0, 37)
        compiled = chain.simulate(3.0, Q0, QD0, rtol=1e-9, atol=1e-9, t_eval=t_eval)
        stepped = chain.simulate(3.0, Q0, QD0, rtol=1e-9, atol=1e-9, t_eval=t_eval, integrator="scipy")
        np.testing.assert_array_equal(compiled.t, t_eval)
        np.testing.assert_allclose(compiled.q, stepped.q, rtol=0, atol=1e-8)
        np.testing.assert_allclose(compiled.qd, stepped.qd, rtol=0, atol=1e-8)

    def test_constant_tau_is_applied(self, chain):
        tau = np.array([0.5, 0.0, -0.2, 0.1])
        compiled = chain.simulate(1.0, Q0, QD0, tau=tau)
        stepped = chain.simulate(1.0, Q0, QD0, tau=tau, integrator="scipy")
        free = chain.simulate(1.0, Q0, QD0)
        np.testing.assert_allclose(compiled.q[-1], stepped.q[-1], atol=1e-10)
        assert np.abs(compiled.q[-1] - free.q[-1]).max() > 1e-3

    def test_long_runs_grow_the_step_buffer(self, chain):
        result = chain.simulate(60.0, Q0, QD0, rtol=1e-10, atol=1e-10)
        assert len(result.t) > 256  # more steps than the first buffer holds
        assert np.all(np.diff(result.t) > 0)
        energy = result.energy().total
        assert np.ptp(energy) < 1e-7 * np.abs(energy).max()


class TestRK4:
    def test_fourth_order_convergence(self, chain):
        reference = chain.simulate(1.0, Q0, QD0, rtol=1e-12, atol=1e-12).q[-1]
        errors = [np.abs(chain.simulate(1.0, Q0, QD0, method="RK4", dt=dt).q[-1] - reference).max()
                  for dt in (0.01, 0.005)]
        assert 2 ** 3.7 < errors[0] / errors[1] < 2 ** 4.3

    def test_t_eval_by_hermite_interpolation(self, chain):
        t_eval = np.linspace(0, 1.0, 7)
        result = chain.simulate(1.0, Q0, QD0, method="RK4", dt=1e-3, t_eval=t_eval)
        reference = chain.simulate(1.0, Q0, QD0, rtol=1e-12, atol=1e-12, t_eval=t_eval)
        np.testing.assert_allclose(result.q, reference.q, atol=1e-9)

    def test_needs_dt_that_divides_t_end(self, chain):
        with pytest.raises(mb.ModelError, match="dt"):
            chain.simulate(1.0, Q0, QD0, method="RK4")
        with pytest.raises(mb.ModelError, match="whole number of steps"):
            chain.simulate(1.0, Q0, QD0, method="RK4", dt=0.3)

    def test_rk4_refused_where_no_compiled_loop_runs(self):
        from conftest import fourbar
        system = fourbar().compile("dae", projection=True)  # (only the DOP853 loop projects)
        q, qd = system.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
        with pytest.raises(mb.ModelError, match="RK4.*projection"):
            system.simulate(1.0, q, qd, method="RK4", dt=0.01)


class TestWhenCompiledLoopsApply:
    def test_callable_inputs_run_compiled(self, chain):
        tau = np.array([0.1, -0.2, 0.0, 0.3])
        result = chain.simulate(0.5, Q0, QD0, tau=lambda t, q, qd: tau)
        assert result.stats["integrator"] == "compiled"
        np.testing.assert_array_equal(result.q, chain.simulate(0.5, Q0, QD0, tau=tau).q)  # the same sums in C

    def test_insisting_on_compiled_says_why_not(self, chain):
        with pytest.raises(mb.ModelError, match="Radau"):
            chain.simulate(0.5, Q0, QD0, method="Radau", integrator="compiled")

    def test_singular_mass_matrix_is_reported_from_the_compiled_loop(self):
        m = mb.Model("gimbal", gravity=(0, 0, -9.81))
        body = m.add(mb.Body("top", mass=1.0, com=(0, 0, 0.1), inertia=(0.01, 0.01, 0.02)))
        m.add(mb.Spherical("pivot", m.ground, body, sequence="zxz"))
        system = m.compile()
        with pytest.raises(mb.SimulationError, match="Spherical 'pivot'.*singularity"):
            system.simulate(1.0, [0.0, 0.0, 0.0], [0.0, 0.0, 10.0])


def test_compiled_jacobian_matches_finite_differences_of_the_accelerations(chain):
    from mbcomp.codegen.integrators import compiled_jacobian
    jac = compiled_jacobian(chain.kernel, None)
    q, qd = np.array([0.3, -0.2, 0.5, 0.1]), np.array([1.0, 0.0, -2.0, 0.5])
    y = np.concatenate((q, qd))
    J = jac(0.0, y)

    def f(y):
        return np.concatenate((y[4:], chain.accelerations(y[:4], y[4:])))

    h = 1e-6
    numeric = np.column_stack([(f(y + h * e) - f(y - h * e)) / (2 * h) for e in np.eye(8)])
    np.testing.assert_allclose(J, numeric, rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(J[:4, 4:], np.eye(4))  # d(q)/dt = qd exactly


class TestCompiledDae:
    """Closed loops in the dae formulation run in the compiled loops too."""

    @pytest.fixture(scope="class")
    def loop(self):
        from conftest import fourbar
        system = fourbar().compile("dae")
        if system.backend != "c":
            pytest.skip("no C compiler")
        return system

    def test_same_steps_and_motion_as_python_stepping(self, loop):
        q, qd = loop.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
        compiled = loop.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12)
        stepped = loop.simulate(3.0, q, qd, rtol=1e-10, atol=1e-12, integrator="scipy")
        assert compiled.stats["integrator"] == "compiled" and stepped.stats["integrator"] == "scipy"
        # The compiled loop also projects onto the constraints after each step (one more
        # evaluation per step), so its step count differs a little from Python stepping.
        assert abs(compiled.stats["nfev"] - stepped.stats["nfev"]) < 0.2 * stepped.stats["nfev"]
        np.testing.assert_allclose(compiled.q[-1], stepped.q[-1], atol=1e-8)
        assert compiled.constraint_violation().max() < 1e-10

    def test_compiled_kkt_solve_matches_the_python_one_off_the_constraints(self, loop):
        """Baumgarte terms included: at a state that violates the loop by ~1e-2."""
        import ctypes
        lib = loop.kernel.compiled.functions.lib
        with loop._formulation.compiled_setup(lib):
            q, qd = loop.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
            q = q + 0.01
            out, work, u = np.empty(3), np.empty(4096), np.zeros(1)
            pointer = lambda a: ctypes.c_void_p(a.ctypes.data)
            lib.dae_accelerations.restype = ctypes.c_int
            status = lib.dae_accelerations(pointer(q), pointer(qd), pointer(loop.kernel.p), pointer(u), None,
                                           pointer(out), pointer(work))
        assert status == 0
        np.testing.assert_allclose(out, loop.accelerations(q, qd), rtol=1e-10, atol=1e-10)

    def test_projection_runs_in_the_compiled_loop_which_projects_every_step(self, loop):
        """The compiled dae loop moves the state back onto the constraints after every accepted
        step (c/dae.c dae_project) whatever the option: projection=True runs there, with the
        numbers of projection=False, and its constraint residual stays at the Newton level
        where scipy's unprojected stepping drifts."""
        from conftest import fourbar
        q, qd = loop.assemble([1.0, -0.5, 1.5], [1.0, 0.0, 0.0])
        assert fourbar().compile("lagrange").simulate(0.2, q, qd).stats["integrator"] == "compiled"
        projected = fourbar().compile("dae", baumgarte=(0, 0), projection=True)
        assert projected.integration_path() == "compiled"
        a = projected.simulate(2.0, q, qd, rtol=1e-6, atol=1e-8)
        b = fourbar().compile("dae", baumgarte=(0, 0)).simulate(2.0, q, qd, rtol=1e-6, atol=1e-8)
        c = fourbar().compile("dae", baumgarte=(0, 0)).simulate(2.0, q, qd, rtol=1e-6, atol=1e-8,
                                                               integrator="scipy")
        assert a.stats["integrator"] == "compiled" and np.array_equal(a.q, b.q)
        assert np.max(a.constraint_violation()) < 1e-10 < np.max(c.constraint_violation())
        with pytest.raises(mb.ModelError, match="RK4.*projection"):
            projected.simulate(0.2, q, qd, method="RK4", dt=0.01)
