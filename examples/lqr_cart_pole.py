"""An LQR that balances a pole on a cart, designed from ``System.linearize``.

The cart slides along x (a force on it is the input); the pole hinges about y and stands
upright at zero.  ``linearize`` gives A and B about the upright pose; scipy's continuous
algebraic Riccati solver gives the gain; the closed loop is simulated from a 0.2 rad tilt
with the nonlinear model and must come back upright.

Run: python examples/lqr_cart_pole.py
"""
import numpy as np
import scipy.linalg

import mbcomp as mb

M, m, length, g = 1.0, 0.3, 0.8, 9.81          # cart mass, pole mass, pole length (uniform rod)
model = mb.Model("cart_pole", gravity=(0, 0, -g))
cart = model.add(mb.Body("cart", mass=M))
pole = model.add(mb.Body("pole", mass=m, com=(0, 0, length / 2),
                         inertia=(m * length ** 2 / 12, m * length ** 2 / 12, 1e-6)))
model.add(mb.Prismatic("rail", model.ground, cart, axis="x", coords="x"))
model.add(mb.Revolute("hinge", cart, pole, axis="y", coords="theta"))
system = model.compile()

upright = [0.0, 0.0]
lin = system.linearize(upright, inputs="rail")          # states x, theta, x_dot, theta_dot
print("states:", lin.states, "inputs:", lin.inputs)
print("A =\n", np.round(lin.A, 4), "\nB =\n", np.round(lin.B, 4))

# The upright pose is unstable: eigenvalues 0, 0, +-s with the textbook
# s^2 = m g l (M + m) / ((M + m)(I + m l^2) - (m l)^2), l = length / 2, I = m length^2 / 12.
l, inertia = length / 2, m * length ** 2 / 12
s = np.sqrt(m * g * l * (M + m) / ((M + m) * (inertia + m * l ** 2) - (m * l) ** 2))
rates = np.sort(np.linalg.eigvals(lin.A).real)
assert np.allclose(rates, [-s, 0.0, 0.0, s], atol=1e-6), rates
print(f"open loop: divergence rate {s:.4f} 1/s (modes: {system.modes(upright)})")

# LQR: weigh the pole angle most; a force costs R
Q = np.diag([1.0, 10.0, 1.0, 1.0])
R = np.array([[0.1]])
P = scipy.linalg.solve_continuous_are(lin.A, lin.B, Q, R)
K = np.linalg.solve(R, lin.B.T @ P)                      # u = -K z
closed = np.linalg.eigvals(lin.A - lin.B @ K)
assert np.all(closed.real < 0), closed
print("gain K =", np.round(K, 3), " closed-loop eigenvalues:", np.round(closed, 3))
# With python-control installed: lin.to_control() is the same plant as a StateSpace.


def controller(t, q, qd):
    """Force on the cart from the full state; nothing on the hinge."""
    z = np.concatenate((q, qd)) - np.concatenate((upright, [0.0, 0.0]))
    return np.array([-(K @ z)[0], 0.0])


res = system.simulate(8.0, q0=[0.0, 0.2], tau=controller, t_eval=np.linspace(0, 8, 401))
theta, x = res["theta"], res["x"]
print(f"pole angle: start {theta[0]:.3f} rad, largest {np.max(np.abs(theta)):.3f} rad, end {theta[-1]:.2e} rad; "
      f"cart ends at x = {x[-1]:.2e} m")
assert abs(theta[-1]) < 1e-3 and abs(x[-1]) < 1e-2, (theta[-1], x[-1])
# without the controller the pole falls over
fallen = system.simulate(2.0, q0=[0.0, 0.2])
assert abs(fallen["theta"][-1]) > 1.0
print("uncontrolled: the pole has fallen to", round(float(fallen["theta"][-1]), 2), "rad after 2 s")
