"""A motor-driven slider-crank: the motor's torque, its power, and what it reproduces.

Crank (r = 0.1 m), connecting rod (l = 0.3 m) and piston on a prismatic guide along x;
the pin between rod and piston closes the loop.  A ``Motor`` turns the crank at one
revolution per second, so no degree of freedom is left: the piston follows
x = r cos(theta) + sqrt(l^2 - r^2 sin^2(theta)), and the motor's reaction is the torque
it applies to the crank.  Checks:

1. the piston follows the closed form;
2. the motor's work equals the change of the mechanism's energy (power = dE/dt);
3. that torque, applied as ``tau`` to the same model without the motor, reproduces
   the motion (API.md's definition of a motor's reaction).

Run: ``python examples/slider_crank_motor_torque.py``.
"""
import numpy as np
from scipy.integrate import cumulative_trapezoid

import mbcomp as mb

R, L, OMEGA = 0.1, 0.3, 2 * np.pi          # m, m, rad/s


def slider_crank(motor: bool) -> mb.Model:
    m = mb.Model("slider_crank", gravity=(0, -9.81, 0))
    crank = m.add(mb.Body("crank", mass=0.5, com=(R / 2, 0, 0), inertia=(1e-5, 0.5 * R ** 2 / 12, 0.5 * R ** 2 / 12)))
    rod = m.add(mb.Body("rod", mass=0.4, com=(L / 2, 0, 0), inertia=(1e-5, 0.4 * L ** 2 / 12, 0.4 * L ** 2 / 12)))
    piston = m.add(mb.Body("piston", mass=1.0, inertia=(1e-3, 1e-3, 1e-3)))
    pin = m.add(mb.Revolute("crank_pin", m.ground, crank, axis="z", coords="theta"))
    m.add(mb.Revolute("rod_pin", crank, rod, axis="z", parent_point=(R, 0, 0), coords="psi"))
    m.add(mb.Prismatic("guide", m.ground, piston, axis="x", coords="x"))
    m.add(mb.Revolute("wrist_pin", rod, piston, axis="z", parent_point=(L, 0, 0)))
    if motor:
        m.add(mb.Motor("motor", pin, speed=OMEGA))
    return m


def main() -> None:
    driven = slider_crank(motor=True).compile()
    print(f"{driven.coords}, {driven.ndof} degrees of freedom, constraints {driven.constraint_names}")
    t = np.linspace(0.0, 1.0, 1001)
    res = driven.simulate(1.0, q0=[0.0, 0.0, R + L], t_eval=t)

    theta = res["theta"]
    piston = R * np.cos(theta) + np.sqrt(L ** 2 - (R * np.sin(theta)) ** 2)
    print(f"piston vs closed form: {np.max(np.abs(res['x'] - piston)):.1e} m")
    assert np.allclose(theta, OMEGA * t, atol=1e-9) and np.allclose(res["x"], piston, atol=1e-9)

    torque = res.reactions["motor"][:, 0]                        # N m on the crank
    work = cumulative_trapezoid(torque * res["dtheta"], t, initial=0.0)
    energy = res.energy().total
    print(f"motor torque from {torque.min():.3f} to {torque.max():.3f} N m; "
          f"work over the turn {work[-1]:.2e} J, energy change {energy[-1] - energy[0]:.2e} J")
    mismatch = np.max(np.abs(work - (energy - energy[0])))
    print(f"max |work - energy change| over the turn: {mismatch:.1e} J (peak power {np.abs(torque * OMEGA).max():.2f} W)")
    assert mismatch < 1e-4

    # The same torque, applied to the free mechanism, drives it the same way.
    free = slider_crank(motor=False).compile()

    def motor_torque(t, q, qd):
        tau = np.zeros(3)
        tau[0] = driven.reactions(q, qd, t)["motor"]
        return tau

    replay = free.simulate(1.0, q0=[0.0, 0.0, R + L], qd0=res.qd[0], t_eval=t, tau=motor_torque)
    gap = np.max(np.abs(replay.q - res.q))
    print(f"free mechanism driven by the motor torque: {gap:.1e} rad from the prescribed motion")
    assert gap < 1e-5


if __name__ == "__main__":
    main()
