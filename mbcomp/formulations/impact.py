"""Contacts: gaps, and Newton's impact law with every other constraint respected."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mbcomp.build.constraint_set import ConstraintValues
from mbcomp.core.errors import ModelError, SimulationError
from mbcomp.core.small_linalg import least_norm
from mbcomp.formulations.friction import cone_impact, friction_of, plane_contact_rows

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
    tangential: dict = field(default_factory=dict)  #: friction impulse (N s, world (3,)) by contact name


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
    touching = sorted(set(involved) | {i for i in range(len(contacts)) if gaps.g[i] < GAP_TOLERANCE})
    if any(friction_of(kernel, i) > 0.0 for i in touching):
        return cone_impact_solve(kernel, formulation, t, q, qd, touching, set(involved), coefficient, M, Minv,
                                 bilateral)
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


def cone_impact_solve(kernel, formulation, t, q, qd, touching, involved, coefficient, M, Minv, bilateral) -> Impact:
    """The impact law with Coulomb friction (``friction.cone_impact``) on every touching
    contact at once, consistent with the bilateral constraints: normal ``v_n+ + e v_n- >= 0``
    complementary to ``P_n >= 0`` (e = 0 on persistent contacts, and on touching contacts
    that do not approach), tangential impulses in the cone ``|P_t| <= mu P_n`` opposing the
    slip after the impact.  ``closed``: contacts that carry an impulse, and involved ones
    left at zero normal speed."""
    contacts = kernel.topology.contacts
    rows = formulation.rows_of(bilateral.J)
    Jb, gtb = bilateral.J[rows], bilateral.g_t[rows]
    cr = plane_contact_rows(kernel, q, qd, touching)
    blocks = []
    for r in range(len(touching)):
        blocks += [cr.normal[r], cr.tangent[r, 0], cr.tangent[r, 1]]
    J = np.vstack([Jb] + ([np.array(blocks)] if blocks else []))
    v_minus = J @ qd
    b = v_minus.copy()
    nb = Jb.shape[0]
    b[:nb] += gtb
    for r, i in enumerate(touching):
        k = nb + 3 * r
        e = coefficient(i) if i in involved else 0.0
        b[k] += e * min(v_minus[k], 0.0)
    G = J @ Minv @ J.T
    names = ", ".join(repr(contacts[i].name) for i in touching)
    P = cone_impact(G, b, nb, cr.mu, names, t)
    qd_plus = qd + Minv @ (J.T @ P)
    v_plus = J @ qd_plus
    scale = max(1.0, float(np.abs(v_minus).max(initial=0.0)))
    pscale = max(1e-300, float(np.abs(P).max(initial=0.0)))
    closed, impulses, tangential = [], {}, {}
    for r, i in enumerate(touching):
        k = nb + 3 * r
        if P[k] > 1e-12 * pscale or (i in involved and abs(v_plus[k]) <= 1e-9 * scale):
            closed.append(i)
        if i in involved or P[k] > 1e-12 * pscale:
            impulses[contacts[i].name] = float(P[k])
            tangential[contacts[i].name] = cr.basis[r, 1:].T @ P[k + 1:k + 3]
    loss = 0.5 * (qd @ M @ qd - qd_plus @ M @ qd_plus)
    return Impact(qd_plus, impulses, float(loss), tuple(closed), tangential)


def remove_slip(kernel, formulation, t: float, q: np.ndarray, qd: np.ndarray, closed, stick, offsets=None) -> np.ndarray:
    """Speeds after the slip left on the sticking contacts ``stick`` is removed, at a stick
    transition: the kinetic-metric projection ``qd+ = qd + M^-1 J^T P`` onto ``J_t qd+ = 0``
    for the two tangential rows of each contact in ``stick``, with every bilateral constraint's
    and every closed contact's normal speed (``closed``) unchanged.  A stop is located where
    the slip speed falls to a small threshold (``events.STOP_SPEED``), so this is the
    tangential impulse that sliding on for the last few nanoseconds would have applied;
    redundant rows share it by least norm."""
    stick = [i for i in closed if i in set(stick)]
    if not stick:
        return qd
    M, _ = kernel.dynamics(t, q, np.zeros_like(qd))
    Minv = kernel.inverse(kernel.factor(M, q))
    bilateral = formulation.constraint_values(kernel, t, q, np.zeros_like(qd), offsets)
    rows = plane_contact_rows(kernel, q, qd, list(closed))
    tangent = [rows.tangent[r] for r, i in enumerate(closed) if i in stick]
    J = np.vstack([bilateral.J, rows.normal] + tangent)
    target = J @ qd
    target[J.shape[0] - 2 * len(stick):] = 0.0
    independent = formulation.rows_of(J)
    J, target = J[independent], target[independent]
    Minv_JT = Minv @ J.T
    P = least_norm(J @ Minv_JT, target - J @ qd, 1e-10, "the slip removal at a stop")
    return qd + Minv_JT @ P
