"""Contact events during a simulation: closings located on the dense output, impacts
applied, resting contacts held closed and released when their reaction would pull, and
Coulomb friction's stick and slip transitions located the same way."""
from __future__ import annotations

import numpy as np

from mbcomp.core.errors import SimulationError
from mbcomp.core.tolerances import (CONE_FLOOR, CONE_TOLERANCE, EVENT_FORCE_XTOL, EVENT_GAP_XTOL, FORCE_ROUNDING,
                                    SLIP_FLOOR, STOP_SPEED)
from mbcomp.formulations.friction import Closed, friction_of, plane_contact_rows
from mbcomp.formulations.impact import GAP_TOLERANCE, remove_slip, solve_impact
from mbcomp.core.result import Event



class ContactWatch:
    """The contact state of one simulation: which contacts are persistent (closed and
    held as constraints), the events so far, and how to find the next one."""

    def __init__(self, kernel, formulation, rest_speed: float, offsets, tau):
        self.kernel, self.formulation = kernel, formulation
        self.rest_speed, self.offsets, self.tau = rest_speed, offsets, tau
        self.names = [c.name for c in kernel.topology.contacts]
        self.mu = [friction_of(kernel, i) for i in range(len(self.names))]
        self._closed = Closed()
        self.events: list = []
        #: Optional: evaluates ``gap(s, i)`` and ``force(s, k)`` (contact i's gap, the k-th
        #: persistent contact's force) on the step being examined, e.g. in a compiled loop.
        self.locator = None

    @property
    def persistent(self) -> Closed:
        """The contacts held closed, with their friction modes (``friction.Closed``)."""
        return self._closed

    @persistent.setter
    def persistent(self, indices) -> None:
        # Contacts that stay closed keep their friction mode; new ones get theirs in settle().
        old = self._closed
        self._closed = Closed(sorted(set(int(i) for i in indices)), old.stick, old.slip)

    def gaps(self, q, qd):
        return self.kernel.contacts(q, qd)

    # -- friction modes --------------------------------------------------------------------------
    def settle(self, t, q, qd) -> None:
        """Give every closed contact with friction a mode: a new one sticks when its slip
        speed is below ``rest_speed`` and slides along its slip otherwise; then a sticking
        contact whose force leaves the cone starts to slide (most outside first, one at a
        time, since each change moves the other forces), recorded as a ``"slip"`` event."""
        closed = self._closed
        new = [i for i in closed if self.mu[i] > 0.0 and i not in closed.stick and i not in closed.slip]
        stick, slip = set(closed.stick), dict(closed.slip)
        if new:
            rows = plane_contact_rows(self.kernel, q, qd, new)
            for r, i in enumerate(new):
                v = rows.tangent[r] @ qd
                speed = float(np.linalg.norm(v))
                if speed < self.rest_speed:
                    stick.add(i)
                else:
                    slip[i] = rows.basis[r, 1:].T @ (v / speed)
            self._closed = Closed(closed, stick, slip)
        for _ in range(2 * len(self._closed) + 2):
            excess = self.cone_excess(t, q, qd)
            if not excess:
                return
            i = max(excess, key=lambda j: excess[j][0])
            if excess[i][0] <= 0.0:
                return
            self.start_slip(t, i, excess[i][1])

    def friction_solution(self, t, q, qd):
        """The formulation's friction solve with the current modes (None without friction)."""
        if not self._closed.has_friction:
            return None
        kernel = self.kernel
        return self.formulation.solve_friction(kernel, t, q, qd, kernel.tau(self.tau, t, q, qd), self.offsets,
                                               self._closed)

    def cone_excess(self, t, q, qd) -> dict:
        """``{sticking contact: (|lam_t| - mu lam_n - tolerance, -lam_t world (3,))}``."""
        solution = self.friction_solution(t, q, qd)
        if solution is None or not self._closed.stick:
            return {}
        closed = self._closed
        normal = solution.lam[len(solution.lam) - len(closed):]
        sticking = sorted(closed.stick)
        rows = plane_contact_rows(self.kernel, q, qd, sticking)
        out = {}
        for r, i in enumerate(sticking):
            lam_t = solution.tangential[i]
            lam_n = normal[list(closed).index(i)]
            size = float(np.linalg.norm(lam_t))
            tolerance = CONE_TOLERANCE * max(abs(lam_n) * self.mu[i], size) + CONE_FLOOR
            out[i] = (size - self.mu[i] * max(lam_n, 0.0) - tolerance, -(rows.basis[r, 1:].T @ lam_t))
        return out

    def start_slip(self, t, i, direction) -> None:
        """Contact ``i`` slides from ``t`` on along the world ``direction`` (normalised)."""
        closed = self._closed
        size = float(np.linalg.norm(direction))
        slip = dict(closed.slip)
        slip[i] = np.asarray(direction, dtype=float) / size if size > 0 else np.zeros(3)
        self._closed = Closed(closed, closed.stick - {i}, slip)
        self.events.append(Event(time=float(t), contact=self.names[i], impulse=0.0, kind="slip"))

    def slip_velocity(self, q, qd, i) -> np.ndarray:
        """Contact ``i``'s slip velocity (m/s, world, in the tangent plane)."""
        rows = plane_contact_rows(self.kernel, q, qd, [i])
        return rows.basis[0, 1:].T @ (rows.tangent[0] @ qd)

    def slip_speed(self, q, qd, i, direction) -> float:
        """Contact ``i``'s slip velocity along a world ``direction`` (m/s)."""
        rows = plane_contact_rows(self.kernel, q, qd, [i])
        return float(direction @ (rows.basis[0, 1:].T @ (rows.tangent[0] @ qd)))

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
            self.settle(0.0, q, qd)
            self.release(0.0, q, qd)
        if any(speed[i] < 0 for i in closed if i not in resting):
            qd, _ = self.impact(0.0, q, qd)
            self.settle(0.0, q, qd)
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
                one = getattr(self.kernel, "gap_of", None)  # one contact's gap alone (collisions: its pair)
                return one(q, qd, i) if one is not None else self.gaps(q, qd).g[i]

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
        """``(time, what)``: the earliest time in [t_old, t_new] at which a persistent
        contact's force reaches 0 (``what`` its index) or a friction mode ends (``what`` is
        ``("slip", i)`` or ``("stick", i)``, see ``locate_friction``); None when nothing
        happens in the step."""
        if not self.persistent:
            return None
        friction = self.locate_friction(workspace, dense, t_old, t_new, q_new, qd_new)
        normal = self.locate_normal_release(workspace, dense, t_old, t_new, q_new, qd_new)
        found = [x for x in (friction, normal) if x is not None]
        return min(found, key=lambda x: x[0]) if found else None

    def locate_friction(self, workspace, dense, t_old, t_new, q_new, qd_new):
        """Earliest friction transition in [t_old, t_new]: a sticking contact whose force
        reaches the cone's surface (``("slip", i)``), or a sliding one whose slip velocity
        along its direction at ``t_old`` reaches zero (``("stick", i)``); Brent's method on
        the step's dense output, as for gaps and normal forces."""
        closed = self._closed
        if not closed.has_friction:
            return None
        from scipy.optimize import brentq

        def state(s):
            return workspace.full_state(s, dense(s))

        # On a compiled loop's event step the margins and slips come from C (friction.h).
        loc = self.locator if getattr(self.locator, "has_friction", False) else None
        rtol = 4 * np.finfo(float).eps
        found = []
        excess = self.cone_excess(t_new, q_new, qd_new)
        for i, (value, _) in excess.items():
            if value <= 0.0:
                continue

            def margin(s, i=i):
                return loc.cone(s, i) if loc is not None else self.cone_excess(s, *state(s))[i][0]

            if margin(t_old) >= 0.0:
                found.append((t_old, ("slip", i)))
            elif loc is not None:
                found.append((loc.cone_root(i, t_old, t_new, EVENT_FORCE_XTOL, rtol), ("slip", i)))
            else:
                found.append((brentq(margin, t_old, t_new, xtol=EVENT_FORCE_XTOL, rtol=rtol), ("slip", i)))
        for i in closed.slip:
            q_old, qd_old = state(t_old)
            v = self.slip_velocity(q_old, qd_old, i)
            speed = float(np.linalg.norm(v))
            direction = v / speed if speed > SLIP_FLOOR else closed.slip[i]
            along_new = self.slip_speed(q_new, qd_new, i, direction)
            if speed <= STOP_SPEED:
                # Set sliding at (nearly) zero slip: by a stick/slip transition, or held by
                # redundant sticking contacts at the cone's edge.  Nothing to stop unless it
                # slides back against its direction.
                if along_new >= -STOP_SPEED:
                    continue
            elif along_new > 0.0:
                # Still sliding forward.  In the plane the slip velocity may turn as it
                # decays (several contacts coupled), so its component along the step's start
                # direction need not cross zero: the contact stops where its slip speed
                # falls to STOP_SPEED (below it the sliding law's direction v / |v| is
                # ill-conditioned and an explicit integrator chatters there).
                if float(np.linalg.norm(self.slip_velocity(q_new, qd_new, i))) > STOP_SPEED:
                    continue

                def slower(s, i=i):
                    return float(np.linalg.norm(self.slip_velocity(*state(s), i))) - STOP_SPEED

                found.append((t_new if slower(t_new) > 0.0 else
                              brentq(slower, t_old, t_new, xtol=EVENT_GAP_XTOL, rtol=4 * np.finfo(float).eps),
                              ("stick", i)))
                continue

            def along(s, i=i, direction=direction):
                return loc.slip(s, i, direction) if loc is not None else self.slip_speed(*state(s), i, direction)

            if along(t_old) <= 0.0:
                found.append((t_old, ("stick", i)))
            elif loc is not None:
                found.append((loc.slip_root(i, direction, t_old, t_new, EVENT_GAP_XTOL, rtol), ("stick", i)))
            else:
                found.append((brentq(along, t_old, t_new, xtol=EVENT_GAP_XTOL, rtol=rtol), ("stick", i)))
        return min(found, key=lambda x: x[0]) if found else None

    def locate_normal_release(self, workspace, dense, t_old, t_new, q_new, qd_new):
        """``(time, contact index)``: the earliest time in [t_old, t_new] at which a persistent
        contact's normal force reaches 0 (None when every force still pushes at t_new)."""
        forces = self.contact_forces(t_new, q_new, qd_new)
        if forces.min() >= -FORCE_ROUNDING * np.abs(forces).max():   # (rounding: as the compiled watches)
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
        # The impact law decided every touching contact's slip: friction modes start afresh
        # from the speeds after it (settle()), not from what they were before.
        self._closed = Closed(sorted((set(self.persistent) & set(result.closed)) | set(resting)))
        for name, impulse in result.impulses.items():
            if self.names.index(name) in active:
                self.events.append(Event(time=float(t), contact=name, impulse=impulse,
                                         energy_loss=result.energy_loss))
        return result.qd, True

    def open(self, contact, t=None, q=None, qd=None):
        """Act on what ``locate_release`` found at time ``t`` (state ``q, qd``): stop holding
        ``contact`` closed (its force reached zero: a ``"release"`` event), or for
        ``("slip", i)`` let the sticking contact slide along its force's opposite, or for
        ``("stick", i)`` let the sliding contact stick (``"stick"``), or slide the other
        way when sticking needs more than the cone holds (``"slip"``).  Returns the speeds
        after it: at a stop, the slip left on the contacts that stopped (below
        ``rest_speed``; ``STOP_SPEED`` on the one that stopped first) is removed
        (``impact.remove_slip``)."""
        if isinstance(contact, tuple):
            kind, i = contact
            if kind == "slip":
                excess = self.cone_excess(t, q, qd)
                self.start_slip(t, i, excess[i][1] if i in excess else self._closed.slip.get(i, np.zeros(3)))
                return qd
            # Every sliding contact that stopped with it tries to stick too (a box sliding
            # on four corners stops on all four at once): the slip they have left (below
            # rest_speed; STOP_SPEED on contact i) is removed, and settle() lets slide again,
            # from zero slip, those whose force the cone cannot hold.
            closed = self._closed
            stopped = {i} | {j for j, d in closed.slip.items()
                             if abs(self.slip_speed(q, qd, j, d)) < self.rest_speed
                             and float(np.linalg.norm(self.slip_velocity(q, qd, j))) < self.rest_speed}
            self._closed = Closed(closed, closed.stick | stopped,
                                  {j: d for j, d in closed.slip.items() if j not in stopped})
            qd = remove_slip(self.kernel, self.formulation, t, q, qd, self._closed, stopped, self.offsets)
            before = len(self.events)
            self.settle(t, q, qd)
            slipped = {self.names.index(e.contact) for e in self.events[before:]}
            for j in sorted(stopped - slipped):
                self.events.append(Event(time=float(t), contact=self.names[j], impulse=0.0, kind="stick"))
            return qd
        self.persistent = tuple(i for i in self.persistent if i != contact)
        self.events.append(Event(time=float(t or 0.0), contact=self.names[contact], impulse=0.0, kind="release"))
        return qd

    def release(self, t, q, qd) -> bool:
        """Open the persistent contacts whose force would pull (one at a time, most pulling
        first, since releasing one changes the others' forces), each a ``"release"`` event;
        then settle the friction modes."""
        changed = False
        while self.persistent:
            forces = self.contact_forces(t, q, qd)
            if forces.min() >= -1e-12 * max(1.0, float(np.abs(forces).max())):
                break
            k = int(np.argmin(forces))
            self.events.append(Event(time=float(t), contact=self.names[self.persistent[k]], impulse=0.0,
                                     kind="release"))
            self.persistent = tuple(i for j, i in enumerate(self.persistent) if j != k)
            changed = True
        self.settle(t, q, qd)
        return changed
