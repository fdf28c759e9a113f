"""Drive elements during a Python-stepped simulation.

The states of drive elements (motor currents, PID integrals) ride at the end of the
integrator's state vector, after whatever the formulation integrates (``[q, qd]`` or the
independent coordinates).  ``DriveTorque`` is the ``tau`` the formulation sees: the user's
``tau`` plus the drives' generalised forces at the current drive states; evaluating it also
yields the states' rates.  ``DriveWorkspace`` wraps a formulation's workspace so that its
right-hand side returns ``[formulation rates, state rates]``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.spec.components.forces import checked_output


class DriveTorque:
    """Callable ``(t, q, qd) -> tau``: user tau + drive forces at the states ``z`` last set."""

    def __init__(self, system, tau: Any, z0: np.ndarray):
        """``tau``: None, an array (nv) or a callable ``(t, q, qd)``."""
        self.system, self.tau = system, tau
        self.z = np.array(z0, dtype=float)
        self.rates = np.zeros_like(self.z)

    def __call__(self, t, q, qd) -> np.ndarray:
        forces, self.rates = self.system.drive_outputs(t, q, qd, self.z)
        if self.tau is None:
            return forces
        if callable(self.tau):
            return forces + checked_output("tau", self.tau(t, q, qd), len(forces))
        return forces + self.tau


class DriveWorkspace:
    """A formulation workspace with the drive states appended to its state vector."""

    def __init__(self, inner, torque: DriveTorque, m: int | None = None):
        """``m``: the length of the formulation's part of the state (default: that of
        ``inner.y0``; a compiled stretch's event step gives its own)."""
        object.__setattr__(self, "inner", inner)
        object.__setattr__(self, "torque", torque)
        object.__setattr__(self, "m", inner.y0.size if m is None else int(m))
        object.__setattr__(self, "z_accepted", torque.z.copy())

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value):
        setattr(self.inner, name, value)

    @property
    def y0(self) -> np.ndarray:
        return np.concatenate((self.inner.y0, self.torque.z))

    def rhs(self, t, y):
        self.torque.z = y[self.m:]
        mechanical = self.inner.rhs(t, y[: self.m])  # evaluates the torque: rates set
        return np.concatenate((mechanical, self.torque.rates))

    def full_state(self, t, y):
        self.torque.z = np.array(y[self.m:])
        return self.inner.full_state(t, y[: self.m])

    def after_step(self, t, y):
        object.__setattr__(self, "z_accepted", np.array(y[self.m:]))
        self.torque.z = self.z_accepted.copy()
        corrected = self.inner.after_step(t, y[: self.m])
        return None if corrected is None else np.concatenate((corrected, y[self.m:]))

    def retreat(self):
        t, y = self.inner.retreat()
        self.torque.z = self.z_accepted.copy()
        return t, np.concatenate((y, self.z_accepted))
