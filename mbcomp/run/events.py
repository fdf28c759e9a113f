"""Contact events during a simulation: closings located on the dense output, impacts
applied, resting contacts held closed and released when their reaction would pull."""
from __future__ import annotations

import numpy as np

from mbcomp.core.errors import SimulationError
from mbcomp.core.tolerances import EVENT_FORCE_XTOL, EVENT_GAP_XTOL
from mbcomp.formulations.impact import GAP_TOLERANCE, solve_impact
from mbcomp.core.result import Event


class ContactWatch:
    """The contact state of one simulation: which contacts are persistent (closed and
    held as constraints), the events so far, and how to find the next one."""

    def __init__(self, kernel, formulation, rest_speed: float, offsets, tau):
        self.kernel, self.formulation = kernel, formulation
        self.rest_speed, self.offsets, self.tau = rest_speed, offsets, tau
        self.names = [c.name for c in kernel.topology.contacts]
        self.persistent: tuple = ()
        self.events: list = []
        #: Optional: evaluates ``gap(s, i)`` and ``force(s, k)`` (contact i's gap, the k-th
        #: persistent contact's force) on the step being examined, e.g. in a compiled loop.
        self.locator = None

    def gaps(self, q, qd):
        return self.kernel.contacts(q, qd)

    def start(self, q, qd):
        """Check the initial state; close contacts resting on their surface; returns the
        (possibly impacted) speeds."""
        values = self.gaps(q, qd)
        for i, gap in enumerate(values.g):
            if gap < -GAP_TOLERANCE:
                raise SimulationError(f"initial state penetrates the contact by {-gap:.3g} m (gap {gap:.3g} m); "
                                      f"move the body out of contact", self.kernel.topology.contacts[i])
        speed = values.J @ qd
        closed = [i for i in range(len(self.names)) if values.g[i] < GAP_TOLERANCE]
        resting = [i for i in closed if abs(speed[i]) < self.rest_speed]
        if resting:
            self.persistent = tuple(resting)
            qd = solve_impact(self.kernel, self.formulation, 0.0, q, qd, [], offsets=self.offsets, persistent=self.persistent).qd
            self.release(0.0, q, qd)
        if any(speed[i] < 0 for i in closed if i not in resting):
            qd, _ = self.impact(0.0, q, qd)
        return qd

    # -- locating events on a step ----------------------------------------------------------
    def locate_closing(self, workspace, dense, t_old, t_new, g_old, g_new):
        """Earliest time in (t_old, t_new] at which a free contact's gap closes, or None."""
        earliest = None
        for i in range(len(self.names)):
            if i in self.persistent or not (g_new[i] < 0.0 <= g_old[i] or g_new[i] < -GAP_TOLERANCE < g_old[i]):
                continue

            def gap(s, i=i):
                if self.locator is not None:
                    return self.locator.gap(s, i)
                q, qd = workspace.full_state(s, dense(s))
                return self.gaps(q, qd).g[i]

            if gap(t_old) <= 0.0:
                te = t_old
            elif self.locator is not None:  # on the compiled loop's event step (Brent's method in C for dae)
                te = self.locator.gap_root(i, t_old, t_new, EVENT_GAP_XTOL, 4 * np.finfo(float).eps)
            else:
                from scipy.optimize import brentq
                te = brentq(gap, t_old, t_new, xtol=EVENT_GAP_XTOL, rtol=4 * np.finfo(float).eps)
            if earliest is None or te < earliest:
                earliest = te
        return earliest

    def contact_forces(self, t, q, qd):
        """Normal forces (N) of the persistent contacts at a state (positive pushing)."""
        kernel = self.kernel
        _, lam = self.formulation.solve(kernel, t, q, qd, kernel.tau(self.tau, t, q, qd), self.offsets,
                                           self.persistent)
        return lam[len(lam) - len(self.persistent):]

    def locate_release(self, workspace, dense, t_old, t_new, q_new, qd_new):
        """``(time, contact index)``: the earliest time in [t_old, t_new] at which a persistent
        contact's force reaches 0 (None when every force still pushes at t_new)."""
        if not self.persistent:
            return None
        forces = self.contact_forces(t_new, q_new, qd_new)
        if forces.min() >= 0.0:
            return None
        k = int(np.argmin(forces))

        def force(s):
            if self.locator is not None:
                return self.locator.force(s, k)
            q, qd = workspace.full_state(s, dense(s))
            return self.contact_forces(s, q, qd)[k]

        contact = self.persistent[k]
        if force(t_old) <= 0.0:
            return t_old, contact
        if self.locator is not None:  # on the compiled loop's event step (Brent's method in C for dae)
            return self.locator.force_root(k, t_old, t_new, EVENT_FORCE_XTOL, 4 * np.finfo(float).eps), contact
        from scipy.optimize import brentq
        return brentq(force, t_old, t_new, xtol=EVENT_FORCE_XTOL, rtol=4 * np.finfo(float).eps), contact

    # -- acting on events --------------------------------------------------------------------------
    def impact(self, t, q, qd):
        """Apply the impact of the contacts closed and closing at ``(t, q, qd)``; contacts
        leaving slower than ``rest_speed`` are closed for good (a plastic impact on them,
        which the event records)."""
        values = self.gaps(q, qd)
        speed = values.J @ qd
        active = [i for i in range(len(self.names)) if i not in self.persistent
                  and values.g[i] < GAP_TOLERANCE + 1e-7 and speed[i] < 0]
        if not active:
            return qd, False
        result = solve_impact(self.kernel, self.formulation, t, q, qd, active, offsets=self.offsets, persistent=self.persistent)
        after = self.gaps(q, result.qd).J @ result.qd
        resting = [i for i in result.closed if abs(after[i]) < self.rest_speed and i not in self.persistent]
        if resting:
            result = solve_impact(self.kernel, self.formulation, t, q, qd, active, restitution={i: 0.0 for i in resting},
                                  offsets=self.offsets, persistent=self.persistent)
        self.persistent = tuple(sorted((set(self.persistent) & set(result.closed)) | set(resting)))
        for name, impulse in result.impulses.items():
            if self.names.index(name) in active:
                self.events.append(Event(time=float(t), contact=name, impulse=impulse,
                                         energy_loss=result.energy_loss))
        return result.qd, True

    def open(self, contact: int) -> None:
        """Stop holding ``contact`` closed (its force reached zero)."""
        self.persistent = tuple(i for i in self.persistent if i != contact)

    def release(self, t, q, qd) -> bool:
        """Open the persistent contacts whose force would pull (one at a time, most pulling
        first, since releasing one changes the others' forces)."""
        changed = False
        while self.persistent:
            forces = self.contact_forces(t, q, qd)
            if forces.min() >= -1e-12 * max(1.0, float(np.abs(forces).max())):
                break
            k = int(np.argmin(forces))
            self.persistent = tuple(i for j, i in enumerate(self.persistent) if j != k)
            changed = True
        return changed
