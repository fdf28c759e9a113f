"""Many simulations at once: mb.sweep on threads and on a local Dask cluster; pickling Systems."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

import mbcomp as mb
from conftest import pendulum_chain


@pytest.fixture(scope="module")
def chain():
    return pendulum_chain(3).compile()


def _cases():
    return [{"q0": np.full(3, a), "parameters": {"link0.mass": 1.0 + a}} for a in np.linspace(0.1, 0.6, 6)]


def _serial(system, cases, t_end=2.0):
    return [system.simulate(t_end, c["q0"], parameters=c["parameters"]) for c in cases]


class TestSweep:
    def test_threads_give_the_serial_results(self, chain):
        cases = _cases()
        serial = _serial(chain, cases)
        swept = mb.sweep(chain, cases, t_end=2.0)
        for a, b in zip(serial, swept):
            np.testing.assert_array_equal(a.t, b.t)
            np.testing.assert_array_equal(a.q, b.q)

    def test_results_carry_their_parameters(self, chain):
        cases = _cases()[:2]
        swept = mb.sweep(chain, cases, t_end=0.5)
        assert swept[1].system.parameters["link0.mass"] == pytest.approx(cases[1]["parameters"]["link0.mass"])
        # The energy helper uses the case's parameters: a heavier link 0 changes the potential.
        e0 = swept[0].energy().potential[0]
        e1 = swept[1].energy().potential[0]
        assert e0 != pytest.approx(e1)

    def test_bad_case_is_named(self, chain):
        with pytest.raises(mb.ModelError, match="case 1"):
            mb.sweep(chain, [{"q0": np.zeros(3)}, {"q0": np.zeros(3), "colour": "red"}], t_end=1.0)
        with pytest.raises(mb.ModelError, match="needs 't_end'"):
            mb.sweep(chain, [{"q0": np.zeros(3)}])


class TestPickling:
    def test_system_survives_pickling(self, chain):
        again = pickle.loads(pickle.dumps(chain.with_parameters({"link1.mass": 2.0})))
        q, qd = np.array([0.3, -0.2, 0.1]), np.array([0.5, 0.0, -1.0])
        expected = chain.with_parameters({"link1.mass": 2.0}).accelerations(q, qd)
        np.testing.assert_allclose(again.accelerations(q, qd), expected, rtol=1e-14)


def test_dask_cluster_on_loopback_matches_serial(chain):
    distributed = pytest.importorskip("distributed", exc_type=ImportError)
    cases = _cases()[:4]
    serial = _serial(chain, cases)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = mb.sweep(chain, cases, client=client, t_end=2.0)
    for a, b in zip(serial, remote):
        np.testing.assert_array_equal(a.q, b.q)


def _motor_and_resting_block() -> mb.Model:
    """A rod turned at constant speed by a motor (about y, gravity -z) beside a block on a
    vertical prismatic joint resting on a floor contact."""
    m = mb.Model("motor_and_block")
    rod = m.add(mb.Body("rod", mass=2.0, com=(0.5, 0, 0), inertia=(1e-3, 1 / 6, 1 / 6)))
    m.add(mb.Revolute("hinge", m.ground, rod, axis="y", coords="theta"))
    m.add(mb.Motor("motor", "hinge", speed=1.5))
    block = m.add(mb.Body("block", mass=1.0, inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Prismatic("rail", m.ground, block, axis="z", parent_point=(3, 0, 0), coords="z"))
    m.add(mb.Contact("floor", block, normal=(0, 0, 1), origin=(3, 0, 0), restitution=0.0))
    return m


def test_sweep_keeps_motor_and_resting_contact_reactions():
    """Reactions after a sweep equal the serial run's: the block's floor force is its weight
    m g (held closed all along), the motor's torque balances gravity on the rod."""
    system = _motor_and_resting_block().compile()
    cases = [{"q0": {"theta": 0.3 * k, "z": 0.0}, "parameters": {"block.mass": 1.0 + k}, "t_eval": np.linspace(0, 0.5, 11)}
             for k in range(3)]
    serial = [system.simulate(0.5, c["q0"], parameters=c["parameters"], t_eval=c["t_eval"]) for c in cases]
    swept = mb.sweep(system, cases, t_end=0.5, threads=2)
    for case, a, b in zip(cases, serial, swept):
        np.testing.assert_array_equal(a.q, b.q)
        assert b.closed_contacts == a.closed_contacts and b.offsets == a.offsets
        for name in ("motor", "floor"):
            np.testing.assert_allclose(b.reactions[name], a.reactions[name], rtol=1e-12, atol=1e-12)
        mass = case["parameters"]["block.mass"]
        np.testing.assert_allclose(b.reactions["floor"][:, 0], mass * 9.81, rtol=1e-9)
        # Constant speed about a fixed axis: the motor torque is minus gravity's, m g (L/2) cos(theta).
        theta = b["theta"]
        np.testing.assert_allclose(np.abs(b.reactions["motor"][:, 0]), 2.0 * 9.81 * 0.5 * np.abs(np.cos(theta)),
                                   rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(b.constraint_violation(), a.constraint_violation(), atol=1e-12)


def test_result_pickles_without_its_system(chain):
    res = chain.simulate(0.3, np.array([0.2, 0.1, 0.0]), parameters={"link0.mass": 2.0})
    again = pickle.loads(pickle.dumps(res))
    assert again.system is None and again.coords == res.coords
    assert again.parameters["link0.mass"] == 2.0
    np.testing.assert_array_equal(again.q, res.q)
    with pytest.raises(ValueError, match="with_system"):
        again.energy()
    # Bound to the default-parameter System, it still uses the run's own parameter values.
    np.testing.assert_allclose(again.with_system(chain).energy().total, res.energy().total, rtol=1e-14)


class TestCompiledBatches:
    """Batches over initial conditions and parameters in the compiled loops, on threads:
    every run identical to the same run made alone."""

    def test_rk4_over_states_and_parameters(self, chain):
        rng = np.random.default_rng(5)
        cases = [{"q0": rng.uniform(-0.5, 0.5, 3), "qd0": rng.uniform(-0.5, 0.5, 3),
                  "parameters": {"link2.mass": float(rng.uniform(0.5, 2.0))}} for _ in range(12)]
        options = {"t_end": 1.0, "method": "RK4", "dt": 0.01, "t_eval": [0.5, 0.995, 1.0], "integrator": "compiled"}
        swept = mb.sweep(chain, cases, threads=3, **options)
        for case, b in zip(cases, swept):
            a = chain.simulate(options["t_end"], case["q0"], case["qd0"], method="RK4", dt=0.01,
                               t_eval=options["t_eval"], parameters=case["parameters"], integrator="compiled")
            np.testing.assert_array_equal(a.t, b.t)
            np.testing.assert_array_equal(a.q, b.q)
            np.testing.assert_array_equal(a.qd, b.qd)
            assert b.system.parameters["link2.mass"] == case["parameters"]["link2.mass"]
        # Different parameters give different runs (the batch does not mix them up).
        assert not np.array_equal(swept[0].q, swept[1].q)

    def test_dae_loop_reactions_after_a_threaded_sweep(self):
        from conftest import fourbar
        system = fourbar().compile(formulation="dae")
        assert system.integration_path() == "compiled"
        q0, qd0 = system.assemble(np.array([1.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0]))
        cases = [{"q0": q0, "qd0": qd0 * k} for k in (0.5, 1.0, 1.5, 2.0)]
        swept = mb.sweep(system, cases, t_end=0.3, t_eval=np.linspace(0, 0.3, 7), threads=2)
        for case, b in zip(cases, swept):
            a = system.simulate(0.3, case["q0"], case["qd0"], t_eval=np.linspace(0, 0.3, 7))
            np.testing.assert_array_equal(a.q, b.q)
            for name, value in a.reactions.items():
                np.testing.assert_array_equal(b.reactions[name], value)
        assert swept[0].reactions  # the loop closure carries forces
