"""The 3D arm of API.md: the torques that hold it still, checked three ways.

1. Applied as ``tau``, the holding torques leave zero accelerations.
2. They are the gradient of the potential energy (finite differences of ``energy``).
3. A simulation started at rest with them applied stays at rest.

Run: ``python examples/arm_holding_torques.py``.
"""
import numpy as np

import mbcomp as mb


def arm() -> mb.Model:
    m = mb.Model("arm3d", gravity=(0, 0, -9.81))
    upper = m.add(mb.Body("upper", mass=3.0, com=(0, 0, -0.1), inertia=(0.025, 0.025, 0.004)))
    lower = m.add(mb.Body("lower", mass=3.0, com=(0, 0.2, 0), inertia=(0.04, 0.002, 0.04)))
    m.add(mb.Spherical("shoulder", m.ground, upper, sequence="xy", coords=("alpha", "beta")))
    m.add(mb.Revolute("elbow", upper, lower, axis="x", parent_point=(0, 0, -0.3), coords="gamma"))
    return m


def main() -> None:
    sys = arm().compile()
    q = np.array([1.9, -0.35, -0.35])               # rad: alpha, beta, gamma
    tau = sys.holding_forces(q)                     # N m, along each coordinate
    for name, value in zip(sys.coords, tau):
        print(f"holding torque {name:6s} {value:9.4f} N m")

    # 1. Applied, they cancel gravity: no acceleration.
    qdd = sys.accelerations(q, np.zeros(3), tau=tau)
    print(f"max |qdd| with the holding torques: {np.max(np.abs(qdd)):.2e} rad/s^2")
    assert np.max(np.abs(qdd)) < 1e-10

    # 2. They are dV/dq (central differences of the potential energy).
    h = 1e-6
    grad = np.array([(sys.energy(q + h * e, np.zeros(3)).potential
                      - sys.energy(q - h * e, np.zeros(3)).potential) / (2 * h) for e in np.eye(3)])
    print(f"max |tau - dV/dq|: {np.max(np.abs(tau - grad)):.2e} N m")
    assert np.allclose(tau, grad, atol=1e-6)

    # 3. Held by them, the arm stays where it is for a second.
    res = sys.simulate(1.0, q0=q, tau=tau)
    drift = np.max(np.abs(res.q - q))
    print(f"largest motion over 1 s while held: {drift:.2e} rad ({res.stats['integrator']} {res.stats['method']})")
    assert drift < 1e-8

    # Without them it falls: the elbow's torque is the lower arm's weight times its lever arm.
    lower = sys.body_state("lower", q)
    elbow = sys.body_state("upper", q, point=(0, 0, -0.3)).position
    lever = np.cross(lower.position - elbow, (0, 0, -9.81 * 3.0))
    axis = sys.body_state("upper", q).rotation @ np.array([1.0, 0.0, 0.0])
    print(f"elbow torque from the weight of the lower arm: {-lever @ axis:.4f} N m")
    assert np.isclose(-lever @ axis, tau[2], rtol=1e-10)


if __name__ == "__main__":
    main()
