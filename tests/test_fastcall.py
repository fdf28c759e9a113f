"""The fast path of the public evaluation calls (mbcomp.codegen.fastcall): the same numbers as the
checked path, bad input still a clear ModelError, failures still explained, thread-safe."""
from __future__ import annotations

import threading

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.codegen import fastcall
from conftest import assert_close, pendulum_chain

N = 4


@pytest.fixture(scope="module")
def chain():
    return pendulum_chain(N).compile()


@pytest.fixture(scope="module")
def state():
    rng = np.random.default_rng(3)
    return rng.uniform(-1, 1, N), rng.uniform(-1, 1, N)


def _independent_accelerations(system, q, qd):
    M, f = system.tree_dynamics(q, qd)
    return np.linalg.solve(M, f)


class TestSameNumbers:
    def test_accelerations_equal_the_checked_path(self, chain, state):
        q, qd = state
        fast = chain.accelerations(q, qd)
        checked = chain.accelerations(list(q), list(qd))  # a list: converted, checked path
        np.testing.assert_array_equal(fast, checked)
        assert_close(fast, _independent_accelerations(chain, q, qd), rtol=1e-12, name="qdd")

    def test_zero_speeds_by_default(self, chain, state):
        q, _ = state
        np.testing.assert_array_equal(chain.accelerations(q, None), chain.accelerations(q, np.zeros(N)))

    def test_mass_matrix_equals_the_checked_path(self, chain, state):
        q, _ = state
        M = chain.mass_matrix(q)
        np.testing.assert_array_equal(M, chain.mass_matrix(list(q)))
        np.testing.assert_array_equal(M, M.T)
        assert_close(M, chain.tree_dynamics(q)[0], rtol=0, atol=0, name="M")
        # The first link's inertia about the pivot x axis includes every link below it.
        assert M[0, 0] > N * 0.25 ** 2

    def test_body_state_equals_the_checked_path(self, chain, state):
        q, qd = state
        first = chain.body_state("link2", q, qd)   # first call: checked path, remembers the body
        second = chain.body_state("link2", q, qd)  # direct call of the compiled kinematics
        com = chain.body_state("link2", q, qd, point=(0, 0, -0.25))  # a point: checked path
        for other in (first, com):
            for name in ("position", "velocity", "rotation", "angular_velocity", "acceleration",
                         "angular_acceleration"):
                assert_close(getattr(second, name), getattr(other, name), rtol=1e-14, atol=1e-14, name=name)

    def test_body_state_velocity_by_differences(self, chain, state):
        q, qd = state
        chain.body_state("link3", q, qd)
        h = 1e-6
        plus, minus = chain.body_state("link3", q + h * qd, qd), chain.body_state("link3", q - h * qd, qd)
        here = chain.body_state("link3", q, qd)
        assert_close(here.velocity, (plus.position - minus.position) / (2 * h), rtol=1e-7, atol=1e-8,
                     name="velocity")

    def test_reactions_of_a_tree(self, chain, state):
        q, qd = state
        assert chain.reactions(q, qd) == {} == chain.reactions(list(q), list(qd))

    def test_results_are_fresh_arrays(self, chain, state):
        q, qd = state
        a = chain.accelerations(q, qd)
        expected = a.copy()
        a[:] = 0.0
        np.testing.assert_array_equal(chain.accelerations(q, qd), expected)
        M = chain.mass_matrix(q)
        M[:] = 0.0
        assert chain.mass_matrix(q)[0, 0] > 0

    def test_inputs_the_fast_path_declines_give_the_same_numbers(self, chain, state):
        q, qd = state
        expected = chain.accelerations(q, qd)
        wide = np.zeros((N, 2))
        wide[:, 0] = q
        variants = [q.astype(np.float32).astype(np.float64), wide[:, 0], q.astype(">f8"), q.tolist(),
                    dict(zip(chain.coords, q))]
        for variant in variants[1:]:
            np.testing.assert_array_equal(chain.accelerations(variant, qd), expected)
        assert np.all(np.isfinite(chain.accelerations(q.astype(np.float32), qd)))
        assert_close(chain.accelerations(np.zeros(N, dtype=int), np.zeros(N, dtype=int)),
                     chain.accelerations(np.zeros(N), np.zeros(N)), rtol=0, atol=0, name="int input")

    def test_with_parameters_gets_its_own_calls(self, chain, state):
        q, qd = state
        heavy = chain.with_parameters({"link3.mass": 3.0})
        M, M_heavy = chain.mass_matrix(q), heavy.mass_matrix(q)
        assert M_heavy[3, 3] > M[3, 3]
        np.testing.assert_array_equal(heavy.accelerations(q, qd), heavy.accelerations(list(q), list(qd)))


class TestBadInput:
    @pytest.mark.parametrize("bad, match", [
        (np.zeros(N - 1), "length"), (np.zeros(N + 1), "length"), (np.full(N, np.nan), "not finite"),
        (np.array([0.0, np.inf, 0.0, 0.0]), "not finite"), (np.zeros((N, 1)), None), ("abcd", "numbers"),
    ])
    def test_bad_q_raises_model_error(self, chain, bad, match):
        for call in (lambda: chain.accelerations(bad, np.zeros(N)), lambda: chain.mass_matrix(bad),
                     lambda: chain.body_state("link0", bad), lambda: chain.reactions(bad, np.zeros(N))):
            if bad.shape == (N, 1) if isinstance(bad, np.ndarray) else False:
                call()  # a column of N numbers is accepted (flattened), as before
                continue
            with pytest.raises(mb.ModelError, match=match):
                call()

    def test_bad_qd_raises_model_error(self, chain, state):
        q, _ = state
        chain.body_state("link1", q)  # remembered: the next calls try the fast path first
        for bad in (np.zeros(N - 1), np.full(N, np.nan)):
            with pytest.raises(mb.ModelError, match="qd"):
                chain.accelerations(q, bad)
            with pytest.raises(mb.ModelError, match="qd"):
                chain.body_state("link1", q, bad)
            with pytest.raises(mb.ModelError, match="qd"):
                chain.reactions(q, bad)

    def test_unknown_body_still_named(self, chain, state):
        with pytest.raises(mb.ModelError, match="nobody"):
            chain.body_state("nobody", state[0])


class TestFailuresExplained:
    def test_euler_singularity_still_named(self):
        m = mb.Model("gimbal")
        b = m.add(mb.Body("b", mass=1.0, com=(0.1, 0.2, -0.5), inertia=(0.1, 0.2, 0.25)))
        m.add(mb.Spherical("wrist", m.ground, b, sequence="zxz"))
        system = m.compile()
        assert system.backend == "c"
        with pytest.raises(mb.SimulationError, match="Spherical 'wrist'.*singularity"):
            system.accelerations(np.array([0.3, 0.0, -0.4]), np.array([0.1, 0.2, 0.3]))
        M = system.mass_matrix(np.array([0.3, 0.0, -0.4]))  # available at the singularity: rank 2
        assert np.linalg.matrix_rank(M) == 2

    def test_zero_length_spring_still_named(self):
        m = mb.Model("spring")
        b = m.add(mb.Body("b", mass=1.0, inertia=(1e-3, 1e-3, 1e-3)))
        m.add(mb.Prismatic("slide", m.ground, b, axis="x", coords="x"))
        m.add(mb.Spring("s", m.ground, b, stiffness=10.0, rest_length=0.1))
        system = m.compile()
        with pytest.raises(mb.SimulationError, match="zero length"):
            system.accelerations(np.zeros(1), np.zeros(1))
        assert_close(system.accelerations(np.array([0.3]), np.zeros(1)), [-10.0 * 0.2], name="spring")


class TestWhereItApplies:
    def test_quaternions_are_normalised_on_the_checked_path(self):
        m = mb.Model("top")
        b = m.add(mb.Body("b", mass=1.0, com=(0, 0, 0.3), inertia=(0.01, 0.01, 0.02)))
        m.add(mb.Ball("ball", m.ground, b))
        system = m.compile()
        unit = np.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0])
        w = np.array([0.1, 0.2, 3.0])
        np.testing.assert_array_equal(system.accelerations(2.0 * unit, w), system.accelerations(unit, w))
        assert_close(system.body_state("b", 2.0 * unit).position, system.body_state("b", unit).position,
                     rtol=1e-15, name="position")

    def test_constraints_go_through_the_formulation(self):
        from conftest import fourbar
        system = fourbar().compile()
        q, qd = system.assemble(np.array([1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0]))
        qdd = system.accelerations(q, qd)
        cv = system.constraint_values(q, qd)
        assert_close(cv.J @ qdd + cv.bias, np.zeros(len(cv.g)), atol=1e-9, name="constraint accelerations")
        assert system.reactions(q, qd)  # the loop carries a force

    def test_python_backend_has_no_fast_calls(self, state):
        system = pendulum_chain(N).compile(backend="python", cache=False)
        assert system.kernel.fast_calls() is None
        q, qd = state
        assert_close(system.accelerations(q, qd), pendulum_chain(N).compile().accelerations(q, qd),
                     rtol=1e-12, name="qdd")

    def test_ctypes_fallback_gives_the_same_numbers(self, chain, state):
        q, qd = state
        kernel = chain.kernel
        slow = fastcall.calls(kernel.compiled.functions, kernel.layout, kernel.p, kernel.nq, kernel.nv,
                              use_extension=False)
        assert isinstance(slow, fastcall.CtypesCalls)
        np.testing.assert_array_equal(slow.accelerations(q, qd), chain.accelerations(q, qd))
        np.testing.assert_array_equal(slow.mass_matrix(q), chain.mass_matrix(q))
        local = np.array([0.0, 0.0, -0.25])
        x, v, R, w, _ = slow.body(q, qd, 2, local)
        state2 = chain.body_state("link2", q, qd)
        for got, want in ((x, state2.position), (v, state2.velocity), (R, state2.rotation),
                          (w, state2.angular_velocity)):
            assert_close(got, want, rtol=1e-14, atol=1e-15, name="body kinematics")
        assert slow.accelerations(list(q), qd) is None and slow.mass_matrix(q[:2]) is None
        assert slow.accelerations(q, np.full(N, np.nan)) is None and not slow.check(q, q[:1])

    def test_extension_declines_what_it_cannot_take(self, chain, state):
        q, qd = state
        fast = chain.kernel.fast_calls()
        if isinstance(fast, fastcall.CtypesCalls):
            pytest.skip("no Python headers: the ctypes path is in use")
        assert fast.accelerations(q.tolist(), qd) is None
        assert fast.accelerations(q, qd[:2]) is None
        assert fast.accelerations(q.astype(np.float32), qd) is None
        assert fast.accelerations(np.zeros((N, 2))[:, 0], qd) is None  # strided
        assert fast.mass_matrix(np.full(N, np.inf)) is None
        assert fast.body(q, qd, 99, np.zeros(3)) is None and fast.body(q, qd, 0, [0, 0, 0]) is None
        with pytest.raises(TypeError):
            fast.accelerations(q)

    def test_environment_switch_disables_the_extension(self, monkeypatch):
        monkeypatch.setenv("MBCOMP_FASTCALL", "ctypes")
        assert fastcall.extension() is None


def _hammer(calls: dict, states: list, threads: int = 4, repeats: int = 25) -> list:
    """Call every ``calls[name](q, qd)`` at every state from several threads at once; the
    indices of the states whose results differed from a serial pass."""
    expected = [{name: fn(q, qd) for name, fn in calls.items()} for q, qd in states]
    failures = []

    def worker(seed):
        order = np.random.default_rng(seed).permutation(len(states))
        for _ in range(repeats):
            for i in order:
                q, qd = states[i]
                if not all(np.array_equal(fn(q, qd), expected[i][name]) for name, fn in calls.items()):
                    failures.append(i)

    pool = [threading.Thread(target=worker, args=(seed,)) for seed in range(threads)]
    for thread in pool:
        thread.start()
    for thread in pool:
        thread.join()
    return failures


@pytest.fixture(scope="module")
def states():
    rng = np.random.default_rng(11)
    return [(rng.uniform(-1, 1, N), rng.uniform(-1, 1, N)) for _ in range(40)]


def test_concurrent_calls_from_threads_give_the_serial_numbers(chain, states):
    chain.body_state("link1", states[0][0])
    calls = {"qdd": chain.accelerations, "M": lambda q, qd: chain.mass_matrix(q),
             "v": lambda q, qd: chain.body_state("link1", q, qd).velocity}
    assert _hammer(calls, states) == []


def test_concurrent_calls_through_ctypes_give_the_serial_numbers(chain, states):
    kernel = chain.kernel
    slow = fastcall.calls(kernel.compiled.functions, kernel.layout, kernel.p, kernel.nq, kernel.nv,
                          use_extension=False)
    local = np.array([0.0, 0.0, -0.25])
    calls = {"qdd": slow.accelerations, "M": lambda q, qd: slow.mass_matrix(q),
             "v": lambda q, qd: slow.body(q, qd, 1, local)[1]}
    assert _hammer(calls, states) == []
