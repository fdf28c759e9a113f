"""Natural modes and stability about an equilibrium."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from mbcomp.core.errors import SimulationError, format_state
from mbcomp.analysis.linear import Linearization, linearize

#: An eigenvalue counts as growing when its real part exceeds this fraction of the largest
#: eigenvalue magnitude (or of 1/s): the derivatives carry ~1e-10 relative error.
STABILITY_TOLERANCE = 1e-7

#: ``q`` counts as an equilibrium when its accelerations are below this fraction of the
#: linearised stiffness (``||A21||``, or 1/s^2): about 1e-6 of a coordinate unit away.
EQUILIBRIUM_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Modes:
    """The linearised motion about an equilibrium, one mode per degree of freedom.

    Each mode is a conjugate pair of eigenvalues of ``A`` (oscillatory) or a pair of real ones
    (paired by shape: a divergent saddle ``+a, -a``, an overdamped pair, a rigid-body motion).
    ``eigenvalues``: the mode's representative, the one with the largest real part (1/s);
    ``frequencies`` = ``|lambda| / 2 pi`` (Hz) and ``damping_ratios`` = ``-Re(lambda) / |lambda|``
    (as MATLAB's ``damp``): 0 for undamped oscillation, 1 or more when decaying without
    oscillation, -1 for a divergent (statically unstable) mode whose growth rate is
    ``2 pi f``; 0 for a zero eigenvalue (ratios below 1e-9, the derivatives' noise, read 0).  Sorted by frequency.  ``shapes`` (n, k): each mode's
    position shape over all speeds, largest entry 1 (complex only when damping or gyroscopic
    terms twist it).  ``stable``: no eigenvalue grows (undamped oscillation counts as stable);
    ``all_eigenvalues``: the 2k eigenvalues of ``A``.
    """

    frequencies: np.ndarray
    damping_ratios: np.ndarray
    eigenvalues: np.ndarray
    shapes: np.ndarray
    stable: bool
    all_eigenvalues: np.ndarray
    speeds: tuple[str, ...]
    linearization: Linearization

    @property
    def unstable(self) -> int:
        """Number of modes with a growing eigenvalue."""
        scale = max(1.0, float(np.max(np.abs(self.all_eigenvalues), initial=0.0)))
        return int(np.sum(self.eigenvalues.real > STABILITY_TOLERANCE * scale))

    def __repr__(self) -> str:
        rows = ", ".join(f"{f:.4g} Hz (zeta {z:.3g})" for f, z in zip(self.frequencies, self.damping_ratios))
        return f"Modes([{rows}], stable={self.stable})"


def modes(system, q: Any, t: float | None = None, tau: Any = None, states: Any = None, qd: Any = None) -> Modes:
    """Modes of the motion about the equilibrium ``q`` (``tau``: generalised forces held constant,
    e.g. ``system.holding_forces(q)`` to study a pose held by constant torques; ``states``: values
    of drive-element states, default those at rest there (``rest_states``); their eigenvalues
    join the mechanical ones, so a model with drive states has more modes than degrees of
    freedom; ``t`` as in ``linearize``).  ``SimulationError`` when ``q`` is not an equilibrium (find one
    with ``equilibrium``).

    ``qd``: the speeds of a steady motion (a disc or bicycle rolling upright at constant speed):
    the modes of the motion about it, whose independent speeds must then be constant (their
    accelerations vanish), while coordinates that do not enter the equations (position and
    heading on the ground, wheel angles: ignorable) may change.  With velocity (rolling,
    no-slip) constraints there are more independent coordinates than speeds, and ``shapes``
    are then speed shapes (each mode's deviation of all speeds, largest entry 1)."""
    lin = linearize(system, q, qd, t=t, tau=tau, states=states)
    k = len(lin.independent)
    kq = len(lin.states) - k - len(lin.operating_states)  # independent coordinates (k without velocity rows)
    A = lin.A
    stiffness = max(1.0, float(np.linalg.norm(A[kq:kq + k, :kq]))) if k else 1.0
    accel = lin.state_derivative[kq:kq + k]
    rates = lin.state_derivative[kq + k:]
    # a drive state nothing depends on (a PID integral with ki = 0: its column of A is zero)
    # drifts without effect; the others must rest too
    size = max(1.0, float(np.max(np.abs(A), initial=0.0)))
    acting = np.any(np.abs(A[:, kq + k:]) > 1e-12 * size, axis=0) if rates.size else np.zeros(0, dtype=bool)
    rate_scale = max(1.0, float(np.linalg.norm(A[kq + k:]))) if rates.size else 1.0
    if (np.max(np.abs(accel), initial=0.0) > EQUILIBRIUM_TOLERANCE * stiffness
            or np.max(np.abs(rates[acting]), initial=0.0) > EQUILIBRIUM_TOLERANCE * rate_scale):
        moving = f"accelerations {format_state(accel)}"
        if rates.size:
            moving += f", drive state rates {format_state(rates)}"
        hint = "find one with equilibrium(), or hold the pose with tau=holding_forces(q)"
        if np.max(np.abs(rates[acting]), initial=0.0) > EQUILIBRIUM_TOLERANCE * rate_scale:
            hint = ("the drive states cannot rest there (a PID with an integral rests only on its setpoint); find "
                    "the equilibrium with equilibrium()")
        if qd is not None:
            raise SimulationError(f"(q, qd) = ({format_state(lin.q)}, {format_state(lin.qd)}) is not a steady "
                                  f"motion: the independent speeds change ({moving})")
        raise SimulationError(f"q = {format_state(lin.q)} is not an equilibrium ({moving}): {hint}")
    values, vectors = scipy.linalg.eig(A) if k else (np.zeros(0, complex), np.zeros((0, 0), complex))
    scale = max(1.0, float(np.max(np.abs(values), initial=0.0)))
    shape_rows = slice(0, k) if kq == k else slice(kq, kq + k)  # positions, or speeds when they differ
    groups = _pair(values, vectors[shape_rows] if k else vectors, scale)
    reps, shapes = [], []
    for members in groups:
        best = max(members, key=lambda i: (values[i].real, values[i].imag))
        reps.append(values[best])
        shape = lin.basis @ vectors[shape_rows, best]
        peak = shape[np.argmax(np.abs(shape))] if shape.size else 1.0
        shapes.append(shape / peak if abs(peak) > 0 else shape)
    reps = np.array(reps, dtype=complex)
    order = np.lexsort((-reps.real, np.abs(reps)))
    reps = reps[order]
    shape_matrix = np.column_stack([shapes[i] for i in order]) if shapes else np.zeros((len(lin.basis), 0))
    if shape_matrix.size and np.max(np.abs(shape_matrix.imag)) < 1e-9:
        shape_matrix = shape_matrix.real
    magnitude = np.abs(reps)
    damping = np.where(magnitude > 1e-12 * scale, -reps.real / np.where(magnitude > 0, magnitude, 1.0), 0.0)
    damping = np.where(np.abs(damping) < 1e-9, 0.0, damping)  # finite-difference noise on undamped modes
    stable = bool(np.all(values.real <= STABILITY_TOLERANCE * scale))
    from mbcomp.analysis.space import speed_names
    return Modes(frequencies=magnitude / (2 * np.pi), damping_ratios=damping, eigenvalues=reps,
                 shapes=shape_matrix, stable=stable, all_eigenvalues=values,
                 speeds=speed_names(system), linearization=lin)


def _pair(values: np.ndarray, positions: np.ndarray, scale: float) -> list[list[int]]:
    """Group eigenvalue indices into modes: conjugate pairs, and real eigenvalues paired by
    the similarity of their position shapes."""
    tol = 1e-9 * scale
    groups, real = [], []
    used = set()
    for i, lam in enumerate(values):
        if abs(lam.imag) <= tol:
            real.append(i)
        elif lam.imag > 0 and i not in used:
            partner = min((j for j in range(len(values)) if j != i and j not in used and values[j].imag < 0),
                          key=lambda j: abs(values[j] - np.conj(lam)), default=None)
            used.update({i} if partner is None else {i, partner})
            groups.append([i] if partner is None else [i, partner])
    for i, lam in enumerate(values):  # a negative-imaginary eigenvalue left without partner
        if abs(lam.imag) > tol and i not in used:
            groups.append([i])
    unit = positions / np.maximum(np.linalg.norm(positions, axis=0), 1e-300)
    remaining = list(real)
    while remaining:
        i = remaining.pop(0)
        if not remaining:
            groups.append([i])
            break
        j = max(remaining, key=lambda c: abs(np.vdot(unit[:, i], unit[:, c])))
        remaining.remove(j)
        groups.append([i, j])
    return groups
