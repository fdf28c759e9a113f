"""A parameter study without recompiling: pendulum periods for several lengths and masses.

A point mass on a massless rod (the rod length is the bob's ``com``) is compiled once;
``mb.sweep`` runs one simulation per case on a thread pool, each binding its own
parameter values.  The periods match the exact large-amplitude period
T = 4 sqrt(L / g) K(sin^2(phi0 / 2)) (K: complete elliptic integral of the first kind)
and do not depend on the mass.

Run: ``python examples/parameter_sweep.py``.
"""
import time

import numpy as np
from scipy.special import ellipk

import mbcomp as mb

G, PHI0 = 9.81, 1.0          # m/s^2; release angle, rad


def pendulum() -> mb.Model:
    m = mb.Model("pendulum", gravity=(0, 0, -G))
    bob = m.add(mb.Body("bob", mass=1.0, com=(0, 0, -1.0)))          # a point mass 1 m below the pivot
    m.add(mb.Revolute("pivot", m.ground, bob, axis="x", coords="phi"))
    return m


def period(t: np.ndarray, phi: np.ndarray) -> float:
    """Mean time between upward zero crossings (linear interpolation between samples)."""
    i = np.flatnonzero((phi[:-1] < 0) & (phi[1:] >= 0))
    crossings = t[i] - phi[i] * (t[i + 1] - t[i]) / (phi[i + 1] - phi[i])
    return float(np.mean(np.diff(crossings)))


def main() -> None:
    started = time.perf_counter()
    system = pendulum().compile()
    print(f"compiled once in {time.perf_counter() - started:.2f} s; parameters: {sorted(system.parameters)}")

    cases = [{"parameters": {"bob.com": (0, 0, -length), "bob.mass": mass}}
             for length in (0.25, 0.5, 1.0, 2.0) for mass in (0.5, 5.0)]
    started = time.perf_counter()
    results = mb.sweep(system, cases, q0=[PHI0], t_end=12.0, t_eval=np.linspace(0, 12, 4801))
    print(f"{len(cases)} simulations in {time.perf_counter() - started:.3f} s")

    print("length (m)  mass (kg)  period (s)  exact (s)")
    for case, res in zip(cases, results):
        length = -case["parameters"]["bob.com"][2]
        mass = case["parameters"]["bob.mass"]
        exact = 4 * np.sqrt(length / G) * ellipk(np.sin(PHI0 / 2) ** 2)
        measured = period(res.t, res["phi"])
        print(f"{length:10.2f} {mass:10.1f} {measured:11.6f} {exact:10.6f}")
        assert abs(measured - exact) < 1e-5 * exact
        assert res.system.parameters["bob.mass"] == mass          # each Result keeps its values
    # The mass does not matter: the two runs of each length coincide.
    for light, heavy in zip(results[::2], results[1::2]):
        assert np.allclose(light.q, heavy.q, atol=1e-9)


if __name__ == "__main__":
    main()
