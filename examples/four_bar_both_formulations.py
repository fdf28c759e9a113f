"""A four-bar linkage in both formulations: same accelerations, reactions and motion.

Crank AB, coupler BC and rocker DC are uniform bars turning about z under gravity -y.
The tree is ground -> crank -> coupler and ground -> rocker; the revolute joint C
(coupler to rocker) closes the loop, so the compiler turns it into constraint
equations and one degree of freedom is left.

``lagrange`` integrates the one independent coordinate and solves the others from the
loop (exact closure); ``dae`` integrates all three with Lagrange multipliers and
Baumgarte stabilisation (closure to the stabilisation's accuracy).  At a consistent
state both give the same accelerations and loop forces; over a run, the same motion.

Run: ``python examples/four_bar_both_formulations.py``.
"""
import numpy as np

import mbcomp as mb

A, B, C, D, RHO = 0.1, 0.35, 0.3, 0.4, 2.0      # crank, coupler, rocker, ground (m); kg/m


def four_bar() -> mb.Model:
    m = mb.Model("four_bar", gravity=(0, -9.81, 0))

    def bar(name, length):
        inertia = (1e-6, RHO * length ** 3 / 12, RHO * length ** 3 / 12)
        return m.add(mb.Body(name, mass=RHO * length, com=(length / 2, 0, 0), inertia=inertia))

    crank, coupler, rocker = bar("crank", A), bar("coupler", B), bar("rocker", C)
    m.add(mb.Revolute("A", m.ground, crank, axis="z", coords="theta1"))
    m.add(mb.Revolute("B", crank, coupler, axis="z", parent_point=(A, 0, 0), coords="theta2"))
    m.add(mb.Revolute("D", m.ground, rocker, axis="z", parent_point=(D, 0, 0), coords="theta4"))
    m.add(mb.Revolute("C", coupler, rocker, axis="z", parent_point=(B, 0, 0), child_point=(C, 0, 0)))
    return m


def main() -> None:
    model = four_bar()
    lagrange, dae = model.compile("lagrange"), model.compile("dae")
    print(f"coordinates {lagrange.coords}, {lagrange.ndof} degree of freedom; "
          f"loop C: {len(lagrange.redundant_constraints)} of its 5 equations are redundant in the plane")
    assert lagrange.ndof == dae.ndof == 1

    # A consistent state: crank at 90 degrees turning at 3 rad/s.
    q, qd = lagrange.assemble([np.pi / 2, -1.0, 1.9], [3.0, 0.0, 0.0])
    print(f"assembled q = {np.round(q, 6)}, violation {lagrange.constraint_violation(q):.1e}")
    for name, a, b in (("accelerations", lagrange.accelerations(q, qd), dae.accelerations(q, qd)),
                       ("loop force C", lagrange.reactions(q, qd)["C"], dae.reactions(q, qd)["C"])):
        print(f"{name:14s} lagrange {np.round(a[:3], 6)}  dae {np.round(b[:3], 6)}")
        assert np.allclose(a, b, rtol=1e-8, atol=1e-8)

    t_eval = np.linspace(0.0, 2.0, 201)
    runs = {name: system.simulate(2.0, q, qd, t_eval=t_eval, rtol=1e-10, atol=1e-12) for name, system in
            (("lagrange", lagrange), ("dae", dae))}
    for name, res in runs.items():
        energy = res.energy().total
        print(f"{name:8s} crank angle at 2 s {res['theta1'][-1]:9.5f} rad, "
              f"energy drift {np.ptp(energy):.1e} J, max violation {res.constraint_violation().max():.1e}")
        assert np.ptp(energy) < 1e-7
    gap = np.max(np.abs(runs["lagrange"].q - runs["dae"].q))
    print(f"largest difference between the two runs: {gap:.1e} rad")
    assert gap < 1e-6
    assert runs["lagrange"].constraint_violation().max() < 1e-10   # exact closure
    assert runs["dae"].constraint_violation().max() < 1e-6          # Baumgarte-held closure


if __name__ == "__main__":
    main()
