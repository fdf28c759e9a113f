"""Kernel: the numeric core under System, checked against closed forms of a pendulum."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.compiled.kernel import Kernel

G, L, MASS = 9.81, 0.8, 2.0


@pytest.fixture(scope="module")
def pendulum():
    """A point-like bob on a massless rod about x, hanging along -z (I_com tiny)."""
    m = mb.Model("kernel_pendulum", gravity=(0, 0, -G))
    bob = m.add(mb.Body("bob", mass=MASS, com=(0, 0, -L), inertia=(1e-6, 1e-6, 1e-6)))
    m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="theta"))
    return m.compile()


def test_dynamics_energy_and_tree_solve(pendulum):
    kernel = pendulum.kernel
    theta, rate = 0.4, 1.3
    q, qd = np.array([theta]), np.array([rate])
    M, f = kernel.dynamics(0.0, q, qd)
    inertia = MASS * L ** 2 + 1e-6
    assert M[0, 0] == pytest.approx(inertia, rel=1e-12)
    assert f[0] == pytest.approx(-MASS * G * L * np.sin(theta), rel=1e-12)
    assert kernel.tree_accelerations(0.0, q, qd, None)[0] == pytest.approx(f[0] / inertia, rel=1e-12)
    assert kernel.tree_solve(M, f, q)[0] == pytest.approx(f[0] / inertia, rel=1e-12)
    kinetic, potential = kernel.energy(q, qd)
    assert kinetic == pytest.approx(0.5 * inertia * rate ** 2, rel=1e-12)
    assert potential == pytest.approx(-MASS * G * L * np.cos(theta), rel=1e-12)
    # tau adds to the generalised forces
    _, f_tau = kernel.dynamics(0.0, q, qd, kernel.tau([0.5], 0.0, q, qd))
    assert f_tau[0] == pytest.approx(f[0] + 0.5)


def test_kinematics_and_point_position(pendulum):
    kernel = pendulum.kernel
    theta = 0.4
    q = np.array([theta])
    expected = np.array([0.0, L * np.sin(theta), -L * np.cos(theta)])  # rotation about x
    np.testing.assert_allclose(kernel.point_position("bob", (0, 0, -L), q), expected, atol=1e-14)
    per_body, columns = kernel.kinematics(q, np.array([2.0]))
    assert per_body.shape == (1, 24) and columns.shape == (1, 6)
    np.testing.assert_allclose(columns[0], [1, 0, 0, 0, 0, 0], atol=1e-14)  # (w, v0) of the pivot axis
    np.testing.assert_allclose(per_body[0, 12:15], [2.0, 0, 0], atol=1e-14)  # angular velocity


def test_parameters_are_immutable_and_rebound(pendulum):
    kernel = pendulum.kernel
    with pytest.raises(ValueError):
        kernel.p[0] = 1.0
    with pytest.raises(TypeError):
        kernel.parameters["bob.mass"] = 3.0
    heavier = kernel.with_parameters({**kernel.parameters, "bob.mass": 2 * MASS})
    q, qd = np.array([0.4]), np.zeros(1)
    assert heavier.dynamics(0.0, q, qd)[0][0, 0] == pytest.approx(2 * MASS * L ** 2 + 1e-6, rel=1e-12)
    assert kernel.dynamics(0.0, q, qd)[0][0, 0] == pytest.approx(MASS * L ** 2 + 1e-6, rel=1e-12)


def test_failures_are_explained(pendulum):
    kernel = pendulum.kernel
    with pytest.raises(mb.SimulationError, match="mass matrix is singular"):
        kernel.factor(np.zeros((1, 1)), np.zeros(1))
    with pytest.raises(mb.SimulationError, match="not finite"):
        kernel.check_finite(np.array([np.nan]), "mass matrix", np.zeros(1))
    with pytest.raises(mb.ModelError, match="tau"):
        kernel.tau([1.0, 2.0], 0.0, np.zeros(1), np.zeros(1))


def test_the_system_is_a_facade_over_its_kernel(pendulum):
    q, qd = np.array([0.7]), np.array([-0.3])
    kernel = pendulum.kernel
    assert isinstance(kernel, Kernel)
    np.testing.assert_array_equal(pendulum.mass_matrix(q), kernel.dynamics(0.0, q, qd)[0])
    np.testing.assert_array_equal(pendulum.accelerations(q, qd), kernel.tree_accelerations(0.0, q, qd, None))


def test_cholesky_and_inverse_agree_with_numpy_and_refuse_an_indefinite_matrix():
    rng = np.random.default_rng(3)
    for n in (1, 3, 7):
        A = rng.normal(size=(n, n))
        M = A @ A.T + n * np.eye(n)
        L = Kernel.cholesky(M)
        np.testing.assert_allclose(L, np.linalg.cholesky(M), rtol=1e-14, atol=1e-14)
        assert np.all(np.triu(L, 1) == 0.0)
        np.testing.assert_allclose(Kernel.inverse(L), np.linalg.inv(M), rtol=1e-12, atol=1e-14)
    assert Kernel.cholesky(np.diag([1.0, -1e-3, 2.0])) is None
    assert Kernel.cholesky(np.zeros((0, 0))).shape == (0, 0) and Kernel.inverse(np.zeros((0, 0))).shape == (0, 0)


def test_generated_calls_return_new_arrays_and_follow_new_parameters(pendulum):
    """The compiled calls copy into bound buffers: each result is a new array, and a new
    parameter vector (twice the mass) is seen at once."""
    system = pendulum
    kernel = system.kernel
    q, qd = np.array([0.4]), np.array([0.0])
    first = kernel.call("energy", q, qd)
    second = kernel.call("energy", q, qd)
    assert first is not second and np.array_equal(first, second)
    second[:] = 0.0
    assert np.array_equal(kernel.call("energy", q, qd), first)
    heavier = system.with_parameters({name: 2 * value for name, value in system.parameters.items()
                                      if name.endswith(".mass")})
    ratio = heavier.kernel.call("energy", q, qd)[1] / first[1]  # potential energy: twice the mass
    assert ratio == pytest.approx(2.0, rel=1e-12)
