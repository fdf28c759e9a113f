"""The benchmark bicycle's eigenvalues against its forward speed (the figure of Meijaard et al.
2007), from mbcomp's linearisation of the library's 3D rolling model, and a hands-free ride
in the 3D viewer.

``System.linearize(q, qd)`` about the steady motion (upright, straight ahead at speed v, the
wheels rolling at -v/r) gives A for the 3 independent speeds and the 7 independent
coordinates. The ignorable coordinates (x, y, yaw, wheel angles) and the forward speed give
zero eigenvalues; the other four are the paper's weave (an oscillating pair), capsize and
castering modes. The bicycle balances itself where every real part is negative.

Checks: the weave and capsize speeds found by root-finding on mbcomp's eigenvalues are the
paper's (4.2924 and 6.0243 m/s); a ride at 4.6 m/s with a push on the lean (the paper's
figure 4) straightens up with its energy conserved.

Run: ``python examples/bicycle_eigenvalues.py [out_dir]``: writes bicycle_eigenvalues.png and
bicycle_ride.html (open it in a browser) to out_dir (else a temporary folder).
"""
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy.optimize import brentq

import mbcomp as mb

out = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(tempfile.mkdtemp())
out.mkdir(parents=True, exist_ok=True)
model = mb.load("whipple_bicycle")
bike = model.compile(formulation="dae")      # compiled integration of rolling constraints
p = model.named_parameters


def steady_motion(v, lean_rate=0.0):
    """Upright, heading along x at v m/s; the wheels turn about the paper's y axis (right)."""
    qd = dict.fromkeys(bike.speeds, 0.0)
    qd.update(x=v, rear_wheel_angle=-v / p["rR"], front_wheel_angle=-v / p["rF"], lean=lean_rate)
    return np.zeros(len(bike.coords)), np.array([qd[s] for s in bike.speeds])


def eigenvalues(v):
    """The four lean-steer eigenvalues (1/s): A's eigenvalues without the ignorable zeros,
    taken from the block of the lean and steer states (no other state feeds it)."""
    lin = bike.linearize(*steady_motion(v))
    states = list(lin.states)
    rows = [states.index(s) for s in ("lean", "steer", "lean_dot", "steer_dot")]
    return np.linalg.eigvals(lin.A[np.ix_(rows, rows)])


def weave_real(v):
    return max(x.real for x in eigenvalues(v) if abs(x.imag) > 1e-9)


def capsize_real(v):
    return min((x.real for x in eigenvalues(v) if abs(x.imag) <= 1e-9), key=abs)


weave_speed = brentq(weave_real, 4.0, 4.6, xtol=1e-8)
capsize_speed = brentq(capsize_real, 5.8, 6.2, xtol=1e-8)
assert abs(weave_speed - 4.29238253634111) < 1e-6 and abs(capsize_speed - 6.02426201538837) < 1e-6
print(f"self-stable from {weave_speed:.4f} m/s (weave) to {capsize_speed:.4f} m/s (capsize)")

speeds = np.linspace(0.0, 10.0, 101)
values = np.array([np.sort_complex(eigenvalues(v)) for v in speeds])
fig, ax = plt.subplots(figsize=(6.4, 4.4))
ax.plot(speeds, values.real, "k.", markersize=3)
ax.plot(speeds, np.where(np.abs(values.imag) > 1e-9, np.abs(values.imag), np.nan), ".", color="#3b6ea5",
        markersize=3)
ax.plot([], [], "k.", label="real part")
ax.plot([], [], ".", color="#3b6ea5", label="|imaginary part|")
ax.axvspan(weave_speed, capsize_speed, color="#cde5cd", label="self-stable", zorder=0)
ax.axhline(0.0, color="0.5", linewidth=0.5)
ax.set(xlim=(0, 10), ylim=(-10, 10), xlabel="forward speed v (m/s)", ylabel="eigenvalue (1/s)",
       title="Benchmark bicycle: lean and steer eigenvalues")
ax.legend(loc="lower left")
fig.savefig(out / "bicycle_eigenvalues.png", dpi=120)

# Hands-free at 4.6 m/s after a push on the lean (0.5 rad/s): the weave dies out.
ride = bike.simulate(5.0, *steady_motion(4.6, lean_rate=0.5), t_eval=np.linspace(0, 5, 251))
energy = ride.energy()
drift = np.ptp(energy.total)
assert drift < 1e-6 * np.abs(energy.kinetic).max(), drift     # rolling without slip does no work
lean = np.abs(ride["lean"])
assert lean[ride.t > 4.0].max() < 0.5 * lean.max()
page = ride.view(out / "bicycle_ride.html")
print(f"largest lean {lean.max():.3f} rad, {lean[-1]:.4f} rad after 5 s; energy drift {drift:.1e} J")
print(f"wrote {out / 'bicycle_eigenvalues.png'} and {page}")
