"""Ball (unit quaternion) and Free (floating body) joints: against Euler angles, through the
Euler singularity, torque-free motion, in closed loops with both formulations."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import mbcomp as mb

INERTIA = (1.3e-4, 1.3e-4, 2e-4)   # symmetric top about its COM, kg m^2
MASS, HEIGHT = 0.1, 0.04            # kg, pivot to COM (m)


def _top(joint, **options) -> mb.Model:
    m = mb.Model("top", gravity=(0, 0, -9.81))
    body = m.add(mb.Body("top", mass=MASS, com=(0, 0, HEIGHT), inertia=INERTIA))
    m.add(joint("pivot", m.ground, body, **options))
    return m


def _quaternion(R: np.ndarray) -> np.ndarray:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def test_ball_names_sizes_and_normalised_start():
    system = _top(mb.Ball).compile()
    assert system.coords == ("pivot_qw", "pivot_qx", "pivot_qy", "pivot_qz")
    assert system.speeds == ("pivot_wx", "pivot_wy", "pivot_wz")
    assert (system.nq, system.nv, system.ndof) == (4, 3, 3)
    assert system.mass_matrix([2.0, 0, 0, 0]).shape == (3, 3)
    # any non-zero quaternion is accepted and normalised; a dict may leave the quaternion out
    result = system.simulate(0.01, [0.0, 0.0, 0.0, -3.0], [0.0, 0.0, 1.0])
    np.testing.assert_allclose(result.q[0], [0.0, 0.0, 0.0, -1.0])
    assert system.state_vector({}).tolist() == [1.0, 0.0, 0.0, 0.0]
    with pytest.raises(mb.ModelError, match="pivot.*non-zero"):
        system.simulate(0.01, [0.0, 0.0, 0.0, 0.0])
    with pytest.raises(mb.ModelError, match="3 finite numbers"):
        system.simulate(0.01, [1.0, 0.0, 0.0, 0.0], tau=[0.0] * 4)


def test_ball_follows_euler_angles_away_from_the_singularity():
    """The same top on an "xyz" Euler joint and on a Ball, started in the same state:
    orientations agree to 1e-8 over 2 s; energy conserved; quaternion of unit length."""
    euler = _top(mb.Spherical, sequence="xyz").compile()
    ball = _top(mb.Ball).compile()
    angles, rates = np.array([0.3, -0.4, 0.2]), np.array([1.0, -2.0, 30.0])
    start = euler.body_state("top", angles, rates)
    q0 = _quaternion(start.rotation)
    w0 = start.rotation.T @ start.angular_velocity  # the child frame
    t = np.linspace(0.0, 2.0, 41)
    options = dict(rtol=1e-11, atol=1e-12, t_eval=t)
    a = euler.simulate(2.0, angles, rates, **options)
    b = ball.simulate(2.0, q0, w0, **options)
    for qa, qda, qb, qdb in zip(a.q, a.qd, b.q, b.qd):
        sa, sb = euler.body_state("top", qa, qda), ball.body_state("top", qb, qdb)
        np.testing.assert_allclose(sb.rotation, sa.rotation, atol=1e-8)
        np.testing.assert_allclose(sb.angular_velocity, sa.angular_velocity, atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(b.q, axis=1), 1.0, atol=1e-14)
    energy = b.energy().total
    assert np.ptp(energy) < 1e-10 * np.abs(b.energy().kinetic).max()
    np.testing.assert_allclose(b["pivot_wz"], b.qd[:, 2])


@pytest.mark.parametrize("integrator", ["compiled", "scipy"])
def test_heavy_top_through_the_euler_singularity(integrator):
    """A heavy symmetric top started upright (the "zxz" singularity) with a transverse
    angular velocity: its axis swings out and back through the vertical again and again.
    Energy, the vertical angular momentum and the spin are conserved to 1e-8, and the
    quaternion stays of unit length; the Euler-angle joint cannot even start there."""
    ball = _top(mb.Ball).compile()
    if integrator == "compiled" and ball.backend != "c":
        pytest.skip("no C compiler")
    q0, w0 = [1.0, 0.0, 0.0, 0.0], [4.0, 0.0, 60.0]
    result = ball.simulate(3.0, q0, w0, rtol=1e-11, atol=1e-12, integrator=integrator)
    pivot = np.diag(INERTIA) + MASS * HEIGHT ** 2 * np.diag([1.0, 1.0, 0.0])
    tilt, L_vertical = [], []
    for q, w in zip(result.q, result.qd):
        R = ball.body_state("top", q, w).rotation
        tilt.append(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))
        L_vertical.append((R @ pivot @ w)[2])
    tilt = np.array(tilt)
    # back near the vertical after leaving it, more than once
    returns = np.flatnonzero((tilt[1:-1] < tilt[:-2]) & (tilt[1:-1] <= tilt[2:]) & (tilt[1:-1] < 0.02))
    assert tilt.max() > 0.2 and len(returns) >= 2
    energy = result.energy().total
    assert np.ptp(energy) < 1e-8 * np.abs(result.energy().kinetic).max()
    assert np.ptp(L_vertical) < 1e-8 * abs(L_vertical[0])
    assert np.ptp(result["pivot_wz"]) < 1e-8 * 60.0
    np.testing.assert_allclose(np.linalg.norm(result.q, axis=1), 1.0, atol=1e-14)
    euler = _top(mb.Spherical, sequence="zxz").compile()
    with pytest.raises(mb.SimulationError, match="singular"):
        euler.simulate(0.1, [0.0, 0.0, 0.0], [0.0, 0.0, 60.0])


def _t_handle(rotation_start=None) -> mb.Model:
    """A T-handle floating in space: principal moments I1 < I2 < I3 (kg m^2)."""
    m = mb.Model("t_handle", gravity=(0, 0, 0))
    body = m.add(mb.Body("handle", mass=0.3, com=(0, 0, 0), inertia=(2e-4, 5e-4, 6.5e-4)))
    m.add(mb.Free("float", m.ground, body))
    return m


def test_free_names_and_sizes():
    system = _t_handle().compile()
    assert system.coords == ("float_x", "float_y", "float_z", "float_qw", "float_qx", "float_qy", "float_qz")
    assert system.speeds == ("float_x", "float_y", "float_z", "float_wx", "float_wy", "float_wz")
    assert (system.nq, system.nv) == (7, 6)


@pytest.mark.parametrize("integrator", ["compiled", "scipy"])
def test_free_body_torque_free_dzhanibekov_flip(integrator):
    """Spun about its intermediate axis with a small disturbance, the T-handle flips over
    and back (the Dzhanibekov effect) while its angular momentum (world frame), energy and
    linear momentum stay constant."""
    system = _t_handle().compile()
    if integrator == "compiled" and system.backend != "c":
        pytest.skip("no C compiler")
    q0 = [0.1, -0.2, 0.3, 1.0, 0.0, 0.0, 0.0]
    v0 = [0.5, 0.0, -0.2, 1e-3, 10.0, 1e-3]
    result = system.simulate(6.0, q0, v0, rtol=1e-11, atol=1e-12, integrator=integrator)
    inertia = np.diag([2e-4, 5e-4, 6.5e-4])
    momentum, axis_along_L = [], []
    for q, v in zip(result.q, result.qd):
        state = system.body_state("handle", q, v)
        L = state.rotation @ inertia @ v[3:]
        momentum.append(L)
        axis_along_L.append(state.rotation[:, 1] @ L / np.linalg.norm(L))  # body y: the intermediate axis
    momentum = np.array(momentum)
    assert np.max(np.abs(momentum - momentum[0])) < 1e-8 * np.linalg.norm(momentum[0])
    energy = result.energy().total
    assert np.ptp(energy) < 1e-8 * abs(energy[0])
    axis_along_L = np.array(axis_along_L)
    assert axis_along_L[0] > 0.99 and axis_along_L.min() < -0.99  # flipped over
    assert np.count_nonzero(np.diff(np.sign(axis_along_L))) >= 2  # and back
    np.testing.assert_allclose(result["float_x"], 0.1 + 0.5 * result.t, atol=1e-9)
    np.testing.assert_allclose(result["float_z"], 0.3 - 0.2 * result.t, atol=1e-9)


def rssr(formulation: str, **options) -> mb.System:
    """A spatial four-bar: crank (revolute about z) - coupler on a Ball - rocker (revolute
    about x), the coupler closing the loop on the rocker through a second Ball."""
    m = mb.Model("rssr", gravity=(0, 0, -9.81))
    crank = m.add(mb.Body("crank", mass=0.5, com=(0.05, 0, 0), inertia=(1e-4, 4e-4, 4e-4)))
    coupler = m.add(mb.Body("coupler", mass=0.8, com=(0.15, 0.1, 0.1), inertia=(3e-3, 3e-3, 1e-3)))
    rocker = m.add(mb.Body("rocker", mass=0.6, com=(0, 0, 0.1), inertia=(2e-3, 2e-3, 1e-4)))
    m.add(mb.Revolute("crank_pivot", m.ground, crank, axis="z"))
    m.add(mb.Ball("crank_ball", crank, coupler, parent_point=(0.1, 0, 0)))
    m.add(mb.Revolute("rocker_pivot", m.ground, rocker, axis="x", parent_point=(0.3, 0.2, 0.0)))
    m.add(mb.Ball("rocker_ball", coupler, rocker, parent_point=(0.3, 0.2, 0.2), child_point=(0, 0, 0.2)))
    return m.compile(formulation=formulation, **options)


def test_both_formulations_agree_on_a_loop_through_balls():
    lag, dae = rssr("lagrange"), rssr("dae")
    assert lag.ndof == dae.ndof == 2  # the crank angle and the coupler's spin about its axis
    q0 = lag.state_vector({"crank_pivot": 0.0, "rocker_pivot": 0.0})
    v0 = np.zeros(lag.nv)
    v0[0] = 2.0
    q0, v0 = lag.assemble(q0, v0)
    assert lag.constraint_violation(q0) < 1e-12
    t = np.linspace(0.0, 1.0, 11)
    a = lag.simulate(1.0, q0, v0, rtol=1e-10, atol=1e-12, t_eval=t)
    b = dae.simulate(1.0, q0, v0, rtol=1e-10, atol=1e-12, t_eval=t)
    assert np.max(a.constraint_violation()) < 1e-9
    assert np.max(b.constraint_violation()) < 1e-6
    for name in ("crank_pivot", "rocker_pivot"):
        np.testing.assert_allclose(a[name], b[name], atol=1e-5)
    for qa, qb in zip(a.q, b.q):
        np.testing.assert_allclose(lag.body_state("coupler", qa).position, dae.body_state("coupler", qb).position,
                                   atol=1e-5)
    energy = a.energy().total
    assert np.ptp(energy) < 1e-7 * np.abs(a.energy().kinetic).max()
