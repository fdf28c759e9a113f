"""Contacts: gaps, and Newton's impact law with every other constraint respected."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mbcomp.build.constraint_set import ConstraintValues
from mbcomp.core.errors import ModelError, SimulationError

#: A contact counts as closed when its gap is below this (m).
GAP_TOLERANCE = 1e-9


@dataclass(frozen=True)
class Impact:
    """Velocities after an impact (``qd``), each active contact's impulse (N s, positive
    pushing apart) and the kinetic energy lost (J)."""

    qd: np.ndarray
    impulses: dict = field(default_factory=dict)
    energy_loss: float = 0.0
    closed: tuple = ()  #: indices of the contacts that carry an impulse (the final active set)


def contact_values(kernel, q: np.ndarray, qd: np.ndarray) -> ConstraintValues:
    """Gaps (m), gap Jacobian (nk, nv), and gap acceleration bias of every contact."""
    return kernel.contacts(q, qd)


def contact_indices(kernel, contacts) -> list[int]:
    """Indices of contacts given by name or object (all contacts for None)."""
    names = [c.name for c in kernel.topology.contacts]
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


def restitution_of(kernel, index: int) -> float:
    """The contact's restitution as currently bound (a parameter, so it can be rebound)."""
    contact = kernel.topology.contacts[index]
    return float(kernel.parameters[getattr(contact, "restitution_key", f"{contact.name}.restitution")])


def solve_impact(kernel, formulation, t: float, q: np.ndarray, qd: np.ndarray, active: list[int], restitution=None,
                 offsets=None, persistent=()) -> Impact:
    """Newton's impact law on the ``active`` contacts, consistent with every bilateral
    constraint, with complementarity on every contact involved::

        M (qd+ - qd-) = J^T P,   J_b qd+ = -g_t,   J_c qd+ = -e min(J_c qd-, 0),   P >= 0

    ``persistent`` (closed, resting) contacts take part with e = 0 and may let go; a closed
    contact the impact would drive in joins.  A contact whose impulse would pull is
    released and the impact solved again.  ``restitution``: one value for every contact,
    or ``{contact index: e}``; by default each contact's own.
    """
    contacts = kernel.topology.contacts
    if restitution is not None and not isinstance(restitution, dict) and not 0.0 <= float(restitution) <= 1.0:
        raise ModelError("impact", f"restitution must lie in [0, 1], got {restitution}")
    persistent = set(persistent)

    def coefficient(i):
        if i in persistent:
            return 0.0
        if isinstance(restitution, dict):
            return float(restitution.get(i, restitution_of(kernel, i)))
        return restitution_of(kernel, i) if restitution is None else float(restitution)

    M, _ = kernel.dynamics(t, q, np.zeros_like(qd))
    Minv = kernel.inverse(kernel.factor(M, q))
    bilateral = formulation.constraint_values(kernel, t, q, np.zeros_like(qd), offsets)
    gaps = contact_values(kernel, q, qd)
    approach = gaps.J @ qd
    involved = sorted(set(active) | persistent)
    nb = bilateral.J.shape[0]
    seen = set()
    for _ in range(4 * len(contacts) + 4):
        J = np.vstack((bilateral.J, gaps.J[involved]))
        target = np.concatenate((-bilateral.g_t, [-coefficient(i) * min(approach[i], 0.0) for i in involved]))
        rows = formulation.rows_of(J)
        P = np.zeros(J.shape[0])
        qd_plus = qd.copy()
        if rows.size:
            Jr = J[rows]
            Minv_JT = Minv @ Jr.T
            try:
                P[rows] = np.linalg.solve(Jr @ Minv_JT, target[rows] - Jr @ qd)
            except np.linalg.LinAlgError:
                raise SimulationError(f"impact equations are singular at t = {t:g}") from None
            qd_plus = qd + Minv_JT @ P[rows]
        impulse = P[nb:]
        scale = max(1.0, float(np.abs(impulse).max(initial=0.0)))
        if involved and impulse.min() < -1e-12 * scale:
            involved = [i for k, i in enumerate(involved) if k != int(np.argmin(impulse))]
            continue
        after = gaps.J @ qd_plus
        joining = [i for i in range(len(contacts)) if i not in involved and gaps.g[i] < GAP_TOLERANCE
                   and after[i] < -1e-12 * max(1.0, float(np.abs(approach).max(initial=0.0)))]
        if not joining:
            break
        key = (tuple(involved), tuple(joining))
        if key in seen:
            raise SimulationError(f"the impact at t = {t:g} has no consistent set of contacts (the contacts "
                                  f"{[contacts[i].name for i in joining]} keep joining and leaving)")
        seen.add(key)
        involved = sorted(set(involved) | set(joining))
    else:
        raise SimulationError(f"the impact at t = {t:g} did not settle on a set of contacts")
    loss = 0.5 * (qd @ M @ qd - qd_plus @ M @ qd_plus)
    impulses = {contacts[i].name: float(p) for i, p in zip(involved, impulse)}
    return Impact(qd_plus, impulses, float(loss), tuple(involved))
