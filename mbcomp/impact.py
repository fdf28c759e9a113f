"""Contacts: gaps, and Newton's impact law with every other constraint respected."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constraint_set import ConstraintValues
from .errors import ModelError, SimulationError

#: A contact counts as closed when its gap is below this (m).
GAP_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Impact:
    """Velocities after an impact (``qd``), each active contact's impulse (N s, positive
    pushing apart) and the kinetic energy lost (J)."""

    qd: np.ndarray
    impulses: dict = field(default_factory=dict)
    energy_loss: float = 0.0


def contact_values(system, q: np.ndarray, qd: np.ndarray) -> ConstraintValues:
    """Gaps (m), gap Jacobian (nk, nq), and gap acceleration bias of every contact."""
    nk, nq = len(system.topology.contacts), system.nq
    out = system._call("contacts", q, qd)
    return ConstraintValues(out[:nk].copy(), out[nk: nk + nk * nq].reshape(nk, nq), np.zeros(nk),
                            out[nk + nk * nq:].copy())


def contact_indices(system, contacts) -> list[int]:
    """Indices of contacts given by name or object (all contacts for None)."""
    names = [c.name for c in system.topology.contacts]
    if contacts is None:
        return list(range(len(names)))
    if isinstance(contacts, str) or hasattr(contacts, "name"):
        contacts = [contacts]
    indices = []
    for c in contacts:
        name = c if isinstance(c, str) else getattr(c, "name", None)
        if name not in names:
            raise ModelError(f"contact {name!r}", f"is not a contact of this model; contacts are {names}")
        indices.append(names.index(name))
    return indices


def solve_impact(system, t: float, q: np.ndarray, qd: np.ndarray, active: list[int], restitution=None,
                 offsets=None, persistent=()) -> Impact:
    """Newton's impact law on the ``active`` contacts, consistent with every bilateral
    constraint (and the ``persistent`` contacts, which stay closed)::

        M (qd+ - qd-) = J^T P,   J_b qd+ = -g_t,   J_c qd+ = -e J_c qd-

    Contacts whose impulse would pull are released and the impact solved again.
    """
    from .formulations.base import independent_rows
    formulation = system._formulation
    contacts = system.topology.contacts
    M, _ = system._dynamics(t, q, np.zeros_like(q))
    Minv = formulation._inverse(formulation._factor(system, M, q))
    bilateral = formulation.constraint_values(system, t, q, np.zeros_like(q), offsets, tuple(persistent))
    gaps = contact_values(system, q, qd)
    def coefficient(i):
        return contacts[i].restitution if restitution is None else float(restitution)
    if restitution is not None and not 0.0 <= float(restitution) <= 1.0:
        raise ModelError("impact", f"restitution must lie in [0, 1], got {restitution}")
    active = [i for i in active if i not in persistent]
    qd_plus, impulses = qd.copy(), {}
    for _ in range(2 * len(contacts) + 2):
        Jc = gaps.J[active]
        J = np.vstack((bilateral.J, Jc))
        target = np.concatenate((-bilateral.g_t, [-coefficient(i) * (gaps.J[i] @ qd) for i in active]))
        rows = independent_rows(J)
        P = np.zeros(J.shape[0])
        if rows.size:
            Jr = J[rows]
            Minv_JT = Minv @ Jr.T
            try:
                P[rows] = np.linalg.solve(Jr @ Minv_JT, target[rows] - Jr @ qd)
            except np.linalg.LinAlgError:
                raise SimulationError(f"impact equations are singular at t = {t:g}") from None
            qd_plus = qd + Minv_JT @ P[rows]
        else:
            qd_plus = qd.copy()
        contact_impulse = P[bilateral.J.shape[0]:]
        if active and contact_impulse.min() < -1e-12 * max(1.0, np.abs(contact_impulse).max()):
            active = [i for k, i in enumerate(active) if k != int(np.argmin(contact_impulse))]
            continue
        # A closed contact left out that would now penetrate joins the impact.
        joining = [i for i in range(len(contacts)) if i not in active and i not in persistent
                   and gaps.g[i] < GAP_TOLERANCE and gaps.J[i] @ qd_plus < -1e-12]
        if not joining:
            impulses = {contacts[i].name: float(p) for i, p in zip(active, contact_impulse)}
            break
        active = active + joining
    loss = 0.5 * (qd @ M @ qd - qd_plus @ M @ qd_plus)
    return Impact(qd_plus, impulses, float(loss))
