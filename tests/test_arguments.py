"""Bad arguments to the public API end in a ModelError naming the argument (never a raw
numpy/Python error, a silent NaN, garbage returned as success, or a 30 GiB allocation), and
runaway states stop in bounded time with a SimulationError saying where."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.core import checks
from mbcomp.codegen.backend import c_compiler
from conftest import pendulum_chain

Q0 = [0.3, 0.2]


@pytest.fixture(scope="module")
def chain():
    return pendulum_chain(2).compile()


INTEGRATORS = ["scipy"] + (["compiled"] if c_compiler() else [])


class TestOutputTimes:
    @pytest.mark.parametrize("integrator", INTEGRATORS)
    @pytest.mark.parametrize("t_eval, says", [
        ([0.0, np.nan, 1.0], "t_eval must be finite, got nan at index 1"),
        ([0.0, np.inf], "t_eval must be finite, got inf"),
        ([], "t_eval is empty"),
        (["a"], "t_eval must be a sequence of times"),
        ("0 1", "t_eval must be a sequence of times"),
        ([0.5, 0.2], "increasing"),
        ([-0.1, 0.5], "within"),
        ([[0.1, 0.2], [0.3, 0.4]], "one-dimensional"),
    ], ids=["nan", "inf", "empty", "strings", "a-string", "decreasing", "negative", "2d"])
    def test_bad_output_times_are_a_model_error(self, chain, integrator, t_eval, says):
        with pytest.raises(mb.ModelError, match=says):
            chain.simulate(1.0, Q0, t_eval=t_eval, integrator=integrator)

    @pytest.mark.parametrize("integrator", INTEGRATORS)
    def test_good_output_times_are_all_returned(self, chain, integrator):
        res = chain.simulate(1.0, Q0, t_eval=[0.25, 0.5, 1.0], integrator=integrator)
        assert np.array_equal(res.t, [0.25, 0.5, 1.0]) and np.all(np.isfinite(res.q))
        reference = chain.simulate(1.0, Q0, integrator="scipy", rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(res.q[-1], reference.q[-1], rtol=1e-6, atol=1e-8)


class TestSettings:
    @pytest.mark.parametrize("kwargs, says", [
        ({"rtol": "x"}, "rtol must be a number, got 'x'"),
        ({"rtol": 0.0}, "rtol must be positive"),
        ({"atol": None}, "atol must be a number"),
        ({"atol": np.nan}, "atol must be a finite number"),
        ({"rtol": [1e-6]}, "rtol must be a number"),
        ({"max_step": "x"}, "max_step must be a number"),
        ({"max_step": -1.0}, "max_step must be positive"),
        ({"rest_speed": -1e-3}, "rest_speed must be zero or positive"),
        ({"rest_speed": "fast"}, "rest_speed must be a number"),
        ({"method": "RK4", "dt": 0}, "dt must be positive, got 0"),
        ({"method": "RK4", "dt": "x"}, "dt must be a number"),
        ({"method": "RK4", "dt": True}, "dt must be a number"),
        ({"tau": "ab"}, r"tau: must be 2 finite numbers \(one per speed\), got 'ab'"),
        ({"tau": [1.0]}, "tau: must be 2 finite numbers"),
        ({"tau": [np.nan, 0.0]}, "tau: must be 2 finite numbers"),
        ({"integrator": "fast"}, "integrator must be"),
        ({"method": ["DOP853"]}, "method must be one of"),
    ])
    def test_bad_settings_are_a_model_error_naming_them(self, chain, kwargs, says):
        with pytest.raises(mb.ModelError, match=says):
            chain.simulate(1.0, Q0, **kwargs)

    @pytest.mark.parametrize("t_end", ["x", 0.0, -1.0, np.inf, np.nan, None, [1.0]])
    def test_bad_t_end(self, chain, t_end):
        with pytest.raises(mb.ModelError, match="t_end must be"):
            chain.simulate(t_end, Q0)

    @pytest.mark.skipif(c_compiler() is None, reason="RK4 is compiled only")
    def test_an_impossible_output_is_refused_up_front_with_its_size(self, chain):
        # 1e10 steps x 4 values: 298 GiB, refused before anything is allocated.
        with pytest.raises(mb.ModelError, match=r"dt = 1e-09 s over t_end = 10 s would need 1e\+10 samples.*298 GiB"):
            chain.simulate(10.0, Q0, method="RK4", dt=1e-9)

    def test_number_check(self):
        assert checks.number(2.5, "x") == 2.5 and checks.number(np.float32(1), "x") == 1.0
        assert checks.number(np.inf, "x", finite=False) == np.inf
        for bad in (True, None, "a", "2.5", [1.0], object(), 1j):
            with pytest.raises(mb.ModelError, match="x must be a number"):
                checks.number(bad, "x")


class TestBodyState:
    @pytest.mark.parametrize("point, says", [
        ([1.0, 2.0], r"point must be 3 numbers \(shape \(3,\)\), got shape \(2,\)"),
        ([[1.0, 2.0, 3.0]], r"shape \(1, 3\)"),
        ([1.0, np.nan, 0.0], "point must be finite"),
        ("abc", "point must be 3 numbers"),
        ([1.0, "b", 0.0], "point must be 3 numbers"),
    ])
    def test_bad_point(self, chain, point, says):
        with pytest.raises(mb.ModelError, match=says):
            chain.body_state("link0", Q0, point=point)

    def test_a_good_point_is_where_the_rotation_puts_it(self, chain):
        state = chain.body_state("link0", Q0, point=[0.0, 0.0, -0.5])
        # link0 hangs from the origin about x: the point (0, 0, -0.5) goes to Rx(q0) (0, 0, -0.5).
        c, s = np.cos(Q0[0]), np.sin(Q0[0])
        np.testing.assert_allclose(state.position, [0.0, 0.5 * s, -0.5 * c], atol=1e-14)


class TestRunaway:
    """An exploding state stops with a SimulationError saying where, in bounded time."""

    @pytest.mark.parametrize("integrator", INTEGRATORS)
    def test_an_absurd_initial_speed_is_a_step_size_collapse(self, chain, integrator):
        with pytest.raises(mb.SimulationError, match=r"(step size collapsed|step budget ran out) at t = .* largest speed .*e\+1[12] \(joint0\)"):
            chain.simulate(1.0, Q0, [1e12, 0.0], integrator=integrator)

    def test_a_torque_growing_as_exp_exp_t_stops_with_where(self, chain):
        def tau(t, q, qd):
            with np.errstate(over="ignore"):
                return np.array([np.exp(np.exp(10 * t)), 0.0])
        with pytest.raises(mb.SimulationError, match=r"(step size collapsed|not finite|non-finite).* t = 0\.\d+"):
            chain.simulate(1.0, Q0, tau=tau)

    def test_an_overflowing_torque_says_non_finite_and_when(self, chain):
        # exp(exp(10 t)) overflows at t = ln(709.78)/10 = 0.6565 s; a torque that jumps to
        # inf there (a step in time) is reported at that time, not integrated through.
        def tau(t, q, qd):
            return np.array([np.inf if t > 0.5 else 0.0, 0.0])
        with pytest.raises(mb.SimulationError, match=r"tau.*(inf|finite)"):
            chain.simulate(1.0, Q0, tau=tau)

    def test_a_slowly_diverging_run_is_not_stopped(self, chain):
        """The collapse check must not stop an ordinary run with many small steps."""
        res = chain.simulate(2.0, Q0, [30.0, -30.0], rtol=1e-12, atol=1e-14)
        energy = res.energy().total
        assert res.stats["success"] and abs(energy[-1] - energy[0]) < 1e-6 * abs(energy[0])


class TestResultsAndSweeps:
    def test_a_result_series_by_a_wrong_name_is_a_model_error_and_key_error(self, chain):
        res = chain.simulate(0.1, Q0)
        for name in ("nope", 5, None):
            with pytest.raises(mb.ModelError, match="coordinate"):
                res[name]
        with pytest.raises(KeyError):
            res["nope"]
        np.testing.assert_array_equal(res["joint0"], res.q[:, 0])

    def test_to_csv_needs_a_file_name_not_a_file_descriptor(self, chain, tmp_path):
        res = chain.simulate(0.1, Q0)
        with pytest.raises(mb.ModelError, match="path must be a file name"):
            res.to_csv(5)
        res.to_csv(tmp_path / "run.csv")
        rows = (tmp_path / "run.csv").read_text().splitlines()
        assert len(rows) == len(res.t) + 1 and rows[0].startswith("t,joint0,joint1")

    @pytest.mark.parametrize("values", ["x", 5, [("link0.mass", 2.0)]])
    def test_parameters_must_be_a_mapping(self, chain, values):
        with pytest.raises(mb.ModelError, match="parameters: must be a mapping"):
            chain.with_parameters(values)
        with pytest.raises(mb.ModelError, match="parameters: must be a mapping"):
            chain.simulate(0.1, Q0, parameters=values)

    @pytest.mark.parametrize("kwargs, says", [({"cases": 5}, "cases must be a sequence"),
                                              ({"cases": "abc"}, "cases must be a sequence"),
                                              ({"cases": [{"q0": Q0, "t_end": 0.1}], "threads": 0}, "threads"),
                                              ({"cases": [{"q0": Q0, "t_end": 0.1}], "threads": "x"}, "threads")])
    def test_sweep_arguments(self, chain, kwargs, says):
        cases = kwargs.pop("cases")
        with pytest.raises(mb.ModelError, match=says):
            mb.sweep(chain, cases, **kwargs)
