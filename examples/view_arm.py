"""A 3D arm drawn with shapes: a shoulder ball joint, an elbow hinge, a box base, a cylinder
upper arm and forearm, and a sphere for the hand.  Writes the page to the path given (else to
a temporary folder): open it in a browser to play the motion (drag to turn the view, wheel to
zoom).

Checks: the arm swings without loss, so its total energy stays constant to the solver
tolerance; the page is one self-contained file.

Run: ``python examples/view_arm.py arm.html``.
"""
import sys
import tempfile
from pathlib import Path

import numpy as np

import mbcomp as mb

m = mb.Model("arm", gravity=(0, 0, -9.81))
base = m.add(mb.Body("base", mass=5.0, com=(0, 0, 0.05), inertia=(0.02, 0.02, 0.03),
                     shape=mb.Box((0.16, 0.16, 0.08), origin=(0, 0, 0.06), color="#555b66")))
upper = m.add(mb.Body("upper", mass=2.0, com=(0, 0, -0.15), inertia=(0.015, 0.015, 0.001),
                      shape=mb.Cylinder(0.03, 0.3, axis="z", origin=(0, 0, -0.15))))
fore = m.add(mb.Body("fore", mass=1.0, com=(0, 0.12, 0), inertia=(0.006, 0.0005, 0.006),
                     shape=[mb.Cylinder(0.025, 0.22, axis="y", origin=(0, 0.11, 0)),
                            mb.Sphere(0.045, origin=(0, 0.24, 0), color="#e15759")]))
m.add(mb.Revolute("turn", m.ground, base, axis="z", parent_point=(0, 0, 0.6)))
m.add(mb.Spherical("shoulder", base, upper, sequence="xy", coords=("alpha", "beta")))
m.add(mb.Revolute("elbow", upper, fore, axis="x", parent_point=(0, 0, -0.3), coords="gamma"))

system = m.compile()
res = system.simulate(3.0, {"turn": 0.0, "alpha": 0.6, "beta": -0.3, "gamma": 1.0},
                      {"turn": 1.5, "alpha": 0.0, "beta": 0.0, "gamma": 0.0}, t_eval=np.linspace(0, 3, 301))
total = res.energy().total
assert np.ptp(total) < 1e-6 * np.abs(total).max(), np.ptp(total)

page = res.view(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp()) / "arm.html")
text = page.read_text()
assert "default-src 'none'" in text and "<script src" not in text
print(f"wrote {page} ({page.stat().st_size // 1024} KiB); energy drift {np.ptp(total):.1e} J")
