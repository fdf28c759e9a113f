"""The Python side of Coulomb friction in the compiled loops (``c/friction.h``).

A compiled stretch whose held contacts have friction modes (a ``friction.Closed`` with
sticking or sliding contacts) configures them in C with ``FrictionRows``: per contact its
mode, its normal row among the rows the formulation's solve holds, its body's index in
the generated ``kinematics``, ``mu``, the point and radius, the world basis ``n, t1, t2``,
the direction it started sliding in and the speeds that move its body.  From these the C
code builds the tangential rows of ``friction.plane_contact_rows`` from the compiled body
kinematics, solves the KKT system with friction of ``friction.friction_solve`` (sticking:
two bilateral tangential rows; sliding: the normal row's force column ``J_n - mu s J_t``;
least-norm multipliers) and watches the modes after every accepted step (a sticking
force leaving the cone, a sliding contact stopping), as ``events.ContactWatch`` does.

Both formulations solve the full KKT system with friction (the lagrange loop keeps its
partition on the held rows for the state and takes the independent accelerations from
it), so the compiled and the Python paths give the same numbers.  A failed solve
(Painleve's paradox, inconsistent rows) stops the loop; ``FrictionRows.failure`` gives the
``SimulationError`` the Python path raises there.
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.core.errors import SimulationError
from mbcomp.formulations.compiled_watch import pointer
from mbcomp.formulations.friction import (Closed, friction_of, inconsistent_message, painleve_message,
                                          plane_contact_rows)

#: Doubles per contact before its speed mask, doubles it reads back, modes (``friction.h``).
DATA, OUT, STICK, SLIP = 24, 21, 1, 2
#: Where a contact's collision feature index sits in its data row (-1: a point on a plane).
FEATURE = 21

_VOID, _INT = ctypes.c_void_p, ctypes.c_int


def compiled_friction_problem(kernel, formulation=None) -> str | None:
    """Why this model's friction cannot run in the compiled loops (None when it can): every
    contact with friction must be a body point or sphere on a world plane (``Contact``) or a
    collision feature (``Collision``: its rows from ``codegen/c/collide.c``); and
    ``formulation``'s compiled solve must take friction rows (its hook
    ``Formulation.compiled_friction_problem``)."""
    topology = kernel.topology
    with_friction = [c for i, c in enumerate(topology.contacts) if friction_of(kernel, i) > 0.0]
    if not with_friction:
        return None
    for contact in with_friction:
        if getattr(contact, "kind", "") == "collision":
            continue
        if not hasattr(contact, "point") or not hasattr(contact, "normal"):
            return (f"contact {contact.name!r} has friction but is not a body point or sphere on a plane: its friction "
                    f"steps in Python")
    return None if formulation is None else formulation.compiled_friction_problem()


def scratch_size(cap: int, nv: int, kinematics: int) -> int:
    """Doubles of the C friction solve's scratch for at most ``cap`` rows (``friction.h``)."""
    return kinematics + 4 * cap * nv + 2 * cap * cap + 3 * cap + 2 * nv + 8 + nv * (nv + 1) // 2 + 2 * nv + 2 * cap + 8


class FrictionRows:
    """The friction contacts of one compiled stretch, configured in C on this thread.

    ``contacts``: the held set (a ``friction.Closed``); ``normal_row``: each held contact's
    row in the solve's rows (``None``: not held there); ``nr``: how many rows the solve has.
    The arrays the C code reads and writes live as long as this object; ``close()``
    switches friction off.  ``configure=False``: not configured on the thread (the
    evaluation calls pass the arrays to ``dae_evaluate_friction`` for one solve)."""

    def __init__(self, kernel, lib, contacts: Closed, normal_row: dict, nr: int, q: np.ndarray, qd: np.ndarray,
                 configure: bool = True):
        self.kernel, self.lib = kernel, lib
        self.contacts = contacts
        topology = kernel.topology
        nv = kernel.nv
        moded = [i for i in contacts if i in contacts.stick or i in contacts.slip]
        self.indices = moded
        self.data = np.zeros((max(len(moded), 1), DATA + nv))
        self.out = np.zeros((max(len(moded), 1), OUT))
        self.fail = np.zeros(4)
        rows = plane_contact_rows(kernel, q, qd, moded, normal_rows=False)
        n_own = getattr(kernel, "n_own", len(topology.contacts))
        for j, i in enumerate(moded):
            contact = topology.contacts[i]
            d = self.data[j]
            d[0] = STICK if i in contacts.stick else SLIP
            d[1] = normal_row[i]
            d[3] = rows.mu[j]
            d[8:17] = rows.basis[j].reshape(-1)  # (a collision feature's: at the start, for the locators)
            d[17:20] = contacts.slip.get(i, np.zeros(3))
            d[20] = i
            d[FEATURE] = -1
            if getattr(contact, "kind", "") == "collision":  # its rows from collide.c's measurement
                d[2] = -1
                d[FEATURE] = i - n_own
            else:
                body = topology.resolve(contact.body)
                d[2] = -1 if body is topology.ground else topology.body_index(body)
                d[4:7] = np.asarray(kernel.parameters[f"{contact.name}.point"], dtype=float)
                d[7] = float(kernel.parameters.get(f"{contact.name}.radius", 0.0))
                if body is not topology.ground:
                    d[DATA + np.asarray(list(topology.speed_indices_of_body(body)), dtype=int)] = 1.0
            slip = rows.tangent[j] @ qd  # the slip velocity at the start: the watch's first
            self.out[j, 5:7] = slip
            self.out[j, 12:15] = rows.basis[j, 1:].T @ slip
        self.cap = nr + 2 * len(moded)
        layout = kernel.layout
        self.scratch = np.zeros(scratch_size(self.cap, nv, layout.size("kinematics")))
        kernel.compiled.functions.ensure("kinematics")  # (a late function: its library loaded once)
        bind = lib.mb_friction_configure
        bind.argtypes = [_INT, _INT, _VOID, _VOID, _VOID, _VOID]
        bind.restype = ctypes.c_int
        if configure:  # (else the caller passes the arrays for one call: dae_evaluate_friction)
            bind(len(moded), self.cap, pointer(self.data), pointer(self.out), pointer(self.scratch),
                 pointer(self.fail))

    def tangent_coordinates(self, j: int, direction) -> tuple[float, float]:
        """A world ``direction`` (3,) as the ``(e0, e1)`` of friction contact ``j`` (its
        position among ``indices``) that ``friction.h``'s ``mb_friction_along`` takes (the
        slip locators): coordinates on the contact's tangents in its data row.  A plane's
        tangents are fixed; a collision feature's turn with its normal, so its data row takes
        the direction itself as its first tangent (that row's basis serves only this) and the
        coordinates are (1, 0): the slip along it is then Python's exactly."""
        d = self.data[j]
        direction = np.asarray(direction, dtype=float)
        if d[FEATURE] >= 0:
            d[11:14], d[14:17] = direction, 0.0
            return 1.0, 0.0
        e = d[11:17].reshape(2, 3) @ direction
        return float(e[0]), float(e[1])

    def failure(self) -> SimulationError | None:
        """The error of a friction solve that failed in the loop (None when none did), with the
        Python path's words."""
        kind = int(self.fail[0])
        if kind == 0:
            return None
        names = [self.kernel.topology.contacts[i].name for i in self.contacts]
        where = ", ".join(repr(n) for n in names)
        if kind == 1:
            return SimulationError(painleve_message(float(self.fail[1]), where, float(self.fail[2])))
        return SimulationError(inconsistent_message(float(self.fail[1]), where, float(self.fail[2])))

    def close(self) -> None:
        self.lib.mb_friction_configure(0, 0, None, None, None, None)
