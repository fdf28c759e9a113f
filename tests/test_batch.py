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
    distributed = pytest.importorskip("distributed")
    cases = _cases()[:4]
    serial = _serial(chain, cases)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        remote = mb.sweep(chain, cases, client=client, t_end=2.0)
    for a, b in zip(serial, remote):
        np.testing.assert_array_equal(a.q, b.q)
