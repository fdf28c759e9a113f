"""Composing with sub-models: a 20-link chain and a two-legged mechanism built from parts.

A ``Link`` sub-model (a uniform rod on a revolute joint) is instantiated twenty times, each
hanging from the previous one's tip; its parameters appear in ``System.parameters`` under
the instance path (``"link7.length"``), and changing all twenty lengths at run time gives
the numbers a fresh build gives, without generating or compiling code again.  Then a
``Leg`` made of two links is used twice on a torso (the right thigh shorter by a modifier).

Run: ``python examples/composition.py``.
"""
import time

import numpy as np

import mbcomp as mb


class Link(mb.Submodel):
    """A uniform rod hanging from ``parent`` on a revolute joint; exposes its tip."""
    length = mb.Parameter(0.5, unit="m", min=0.0)
    mass = mb.Parameter(1.0, unit="kg", min=0.0)
    axis = mb.Option("x", choices=("x", "y", "z"))

    def build(self, parent: mb.Frame):
        rod = self.add(mb.Body("rod", mass=self.mass, com=(0, 0, -self.length / 2),
                               inertia=(self.mass * self.length**2 / 12,) * 2 + (1e-4,)))
        self.add(mb.Revolute("joint", parent, rod, axis=self.axis, coords="angle"))
        self.tip = rod.frame((0, 0, -self.length))


class Leg(mb.Submodel):
    """Thigh and shank links from ``hip``; the shank is 0.9 x the thigh, half its mass."""
    thigh_length = mb.Parameter(0.45, unit="m", min=0.05)
    mass = mb.Parameter(6.0, unit="kg", min=0.0)

    def build(self, hip: mb.Frame):
        thigh = self.add(Link("thigh", parent=hip, length=self.thigh_length, mass=self.mass))
        shank = self.add(Link("shank", parent=thigh.tip, length=0.9 * self.thigh_length, mass=self.mass / 2))
        self.foot = shank.tip


def chain(n: int, lengths=None) -> mb.Model:
    m = mb.Model(f"chain{n}")
    parent = m.ground.frame()
    for i in range(n):
        extra = {} if lengths is None else {"length": lengths[i]}
        parent = m.add(Link(f"link{i}", parent=parent, axis="x" if i % 2 == 0 else "y", **extra)).tip
    return m


def main() -> None:
    n = 20
    started = time.perf_counter()
    system = chain(n).compile()
    print(f"{n}-link chain: {system.coords[:2]} ... compiled in {time.perf_counter() - started:.2f} s")

    lengths = 0.3 + 0.02 * np.arange(n)
    change = {f"link{i}.length": float(lengths[i]) for i in range(n)}
    started = time.perf_counter()
    changed = system.with_parameters(change)
    print(f"every link's length changed at run time in {1e3 * (time.perf_counter() - started):.1f} ms")
    assert changed.parameters["link19.joint.parent_point"] == (0.0, 0.0, -float(lengths[18]))
    q, qd = np.full(n, 0.1), np.zeros(n)
    fresh = chain(n, lengths).compile()          # the same structure: a cache hit, no code generated
    assert fresh.parameters == changed.parameters
    np.testing.assert_allclose(changed.accelerations(q, qd), fresh.accelerations(q, qd), rtol=1e-12)

    m = mb.Model("walker", gravity=(0, 0, -9.81))
    torso = m.add(mb.Body("torso", mass=20.0, com=(0, 0, 0.3), inertia=(0.6, 0.5, 0.2)))
    m.add(mb.Revolute("yaw", m.ground, torso, axis="z"))
    m.add(Leg("left", hip=torso.frame((0, 0.15, 0))))
    m.add(Leg("right", hip=torso.frame((0, -0.15, 0)), thigh={"length": 0.4}))   # a modifier for the inner thigh
    print(m.tree())
    walker = m.compile()
    print("walker coordinates:", walker.coords)
    res = walker.simulate(1.0, q0=[0.0, 0.4, -0.6, -0.3, 0.0], qd0=[1.0, 0, 0, 0, 0])
    energy = res.energy().total
    drift = np.max(np.abs(energy - energy[0]))
    print(f"walker: energy drift over 1 s {drift:.2e} J")
    assert drift < 1e-6 * np.max(np.abs(res.energy().kinetic))
    assert m["right.thigh.rod"].mass == 6.0 and walker.parameters["right.thigh.length"] == 0.4


if __name__ == "__main__":
    main()
