"""A Stewart platform built from one UPS leg sub-model used six times.

The top plate rests on six legs: a universal joint at the base, a sprung prismatic leg, a
ball joint at the plate.  The plate hangs on the first leg's ball in the spanning tree and
the other five balls close loops, so the ball's quaternion is a coordinate of a closed loop:
both formulations step it in the compiled loop (``integration_path()``), and they agree.
The same model is ``library/stewart_platform.toml`` with ``library/parts/ups_leg.toml``.

Run: ``python examples/stewart_platform.py``.
"""
import time

import numpy as np
from scipy.spatial.transform import Rotation

import mbcomp as mb


class UPSLeg(mb.Submodel):
    """A cylinder on a universal joint at ``base``, a piston sliding along it on a spring,
    a ball joint from the piston's end to ``top``; along the base frame's z at zero angles."""
    cylinder_length = mb.Parameter(0.4, unit="m", min=0.0)
    piston_length = mb.Parameter(0.4, unit="m", min=0.0)
    cylinder_mass = mb.Parameter(1.0, unit="kg", min=0.0)
    piston_mass = mb.Parameter(0.5, unit="kg", min=0.0)
    stiffness = mb.Parameter(2000.0, unit="N/m", min=0.0)
    rest = mb.Parameter(0.4, unit="m")

    def build(self, base: mb.Frame, top: mb.Frame):
        lc, lp, mc, mp = self.cylinder_length, self.piston_length, self.cylinder_mass, self.piston_mass
        cylinder = self.add(mb.Body("cylinder", mass=mc, com=(0, 0, lc / 2),
                                    inertia=(mc * lc**2 / 12, mc * lc**2 / 12, 1e-3)))
        piston = self.add(mb.Body("piston", mass=mp, com=(0, 0, lp / 2),
                                  inertia=(mp * lp**2 / 12, mp * lp**2 / 12, 1e-3)))
        self.add(mb.Universal("hip", base, cylinder, axes=("x", "y")))
        slide = self.add(mb.Prismatic("slide", cylinder, piston, axis="z", coords="extension"))
        self.add(mb.Ball("ankle", piston.frame((0, 0, lp)), top))
        self.add(mb.TorsionSpring("spring", slide, stiffness=self.stiffness, rest=self.rest))


BASE_RADIUS, TOP_RADIUS, HEIGHT = 0.5, 0.3, 0.7  # m


def attachment_points():
    """``(base point, plate point)`` of each leg: pairs 120 degrees apart."""
    points = []
    for i in range(6):
        k, side = divmod(i, 2)
        sign = -1 if side == 0 else 1
        ab, at = np.radians(120 * k + 15 * sign), np.radians(120 * k + 45 * sign)
        points.append((np.array([BASE_RADIUS * np.cos(ab), BASE_RADIUS * np.sin(ab), 0.0]),
                       np.array([TOP_RADIUS * np.cos(at), TOP_RADIUS * np.sin(at), 0.0])))
    return points


def stewart_platform() -> mb.Model:
    m = mb.Model("stewart_platform", gravity=(0, 0, -9.81))
    plate = m.add(mb.Body("plate", mass=10.0, com=(0, 0, 0), inertia=(0.25, 0.25, 0.45)))
    for i, (b, p) in enumerate(attachment_points()):
        m.add(UPSLeg(f"leg{i}", base=m.ground.frame(tuple(b)), top=plate.frame(tuple(p))))
    return m


def initial_guess(system) -> np.ndarray:
    """Each leg pointed at its plate point with the plate level at HEIGHT (``assemble``
    makes it exact)."""
    names = list(system.coords)
    q = system.topology.state_map.neutral()
    for i, (b, p) in enumerate(attachment_points()):
        d = p + (0.0, 0.0, HEIGHT) - b
        length = np.linalg.norm(d)
        d /= length
        a, c = np.arctan2(-d[1], d[2]), np.arcsin(d[0])
        q[names.index(f"leg{i}.hip_x")], q[names.index(f"leg{i}.hip_y")] = a, c
        q[names.index(f"leg{i}.extension")] = length - 0.4
        if f"leg{i}.ankle_qw" in names:  # the ball in the tree: the plate level
            x, y, z, w = Rotation.from_euler("XY", [a, c]).inv().as_quat()
            for suffix, value in zip(("qw", "qx", "qy", "qz"), (w, x, y, z)):
                q[names.index(f"leg{i}.ankle_{suffix}")] = value
    return q


def main() -> None:
    model = stewart_platform()
    runs = {}
    for formulation in ("lagrange", "dae"):
        system = model.compile(formulation)
        qd = np.zeros(system.nv)
        qd[list(system.speeds).index("leg0.ankle_wz")] = 0.8  # the plate turning
        q0, qd0 = system.assemble(initial_guess(system), qd)
        print(f"{formulation}: {system.ndof} degrees of freedom, {system.integration_path()}")
        started = time.perf_counter()
        runs[formulation] = system.simulate(2.0, q0, qd0, t_eval=np.linspace(0, 2, 201))
        print(f"  2 s in {1e3 * (time.perf_counter() - started):.0f} ms")
    lag, dae = runs["lagrange"], runs["dae"]
    difference = np.max(np.abs(lag.q - dae.q))
    print(f"largest coordinate difference between the formulations: {difference:.1e}")
    assert difference < 1e-6
    energy = lag.energy().total
    print(f"energy drift (lagrange): {np.ptp(energy):.1e} J")
    assert np.ptp(energy) < 1e-5


if __name__ == "__main__":
    main()
