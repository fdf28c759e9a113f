"""The impact law on the friction cone for many contacts at once: projected Gauss-Seidel
sweeps vectorised over colour classes of contacts that share no speed.

The law is ``friction.cone_impact``'s (Moreau's set-valued law with Newton's restitution,
Coulomb's disc): per contact a block of three rows (normal, two tangents),
``xi = J v+ + b_e`` with ``v+ = v + M^-1 J^T P``, ``xi_n >= 0, P_n >= 0, xi_n P_n = 0``,
``|P_t| <= mu P_n`` opposing ``xi_t``.  ``cone_impact`` forms the dense Delassus matrix
``J M^-1 J^T`` and sweeps contact by contact in Python; here the velocities are kept
(``v+``), contacts are coloured (``networkx.greedy_color`` on the graph of contacts
sharing a speed) and each colour is updated in one numpy step: the same Gauss-Seidel
(contacts of one colour do not see each other), at a cost per sweep linear in the number
of contacts.  The time-stepping mode (``run/timestepping.py``) uses it at every step.
"""
from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np
from scipy import sparse

#: Default sweeps and relative tolerance (on the velocity change of a sweep).
SWEEPS = 300
TOLERANCE = 1e-10


@dataclass(frozen=True)
class ConeSolution:
    """Impulses ``P`` (3k,) N s (normal, t1, t2 per contact), velocities after ``v`` (nv,),
    ``sweeps`` done and whether the tolerance was met (``converged``)."""

    P: np.ndarray
    v: np.ndarray
    sweeps: int
    converged: bool


def colours(J: np.ndarray) -> list[np.ndarray]:
    """Contacts (blocks of three rows of ``J`` (3k, nv)) grouped so that no two of a group
    share a speed column: a list of index arrays."""
    k = J.shape[0] // 3
    if k == 0:
        return []
    if k == 1:
        return [np.zeros(1, dtype=int)]
    J = sparse.csr_matrix(J)
    pick = sparse.csr_matrix((np.ones(J.shape[0]), (np.repeat(np.arange(k), 3), np.arange(J.shape[0]))))
    uses = (pick @ abs(J)).astype(bool).astype(float)
    touching = sparse.triu(uses @ uses.T, 1).tocoo()
    graph = nx.Graph()
    graph.add_nodes_from(range(k))
    a, b = touching.row, touching.col
    graph.add_edges_from(zip(a.tolist(), b.tolist()))
    groups: dict = {}
    for node, colour in nx.greedy_color(graph, strategy="largest_first").items():
        groups.setdefault(colour, []).append(node)
    return [np.array(sorted(g)) for _, g in sorted(groups.items())]


def cone_sweeps(J: np.ndarray, X: np.ndarray, v: np.ndarray, bias: np.ndarray, mu: np.ndarray,
                P0: np.ndarray | None = None, sweeps: int = SWEEPS, tolerance: float = TOLERANCE) -> ConeSolution:
    """Solve the cone impact law for contact rows ``J`` (3k, nv: normal, t1, t2 of each
    contact), ``X = M^-1 J^T`` (nv, 3k), velocities before ``v`` (nv,), ``bias`` (3k,) added
    to ``J v+`` (``e v_n-`` on normal rows, 0 on tangents), ``mu`` (k,).  ``P0``: a warm
    start (3k,).  Stops when a sweep changes no row velocity by more than ``tolerance`` of
    their scale, or after ``sweeps`` (``converged`` False)."""
    k = J.shape[0] // 3
    P = np.zeros(3 * k) if P0 is None else np.array(P0, dtype=float)
    if k == 0:
        return ConeSolution(P, np.array(v, dtype=float), 0, True)
    if sparse.issparse(J) or sparse.issparse(X):   # (dense arrays for small problems: less overhead)
        Js, Xs = sparse.csr_matrix(J), sparse.csc_matrix(X)
    else:
        Js, Xs = np.asarray(J, dtype=float), np.asarray(X, dtype=float)
    D = block_diagonal(Js, Xs, k)                                   # diagonal blocks of J M^-1 J^T
    scale_d = max(float(np.abs(D[:, 0, 0]).max()), 1e-300)
    d_n = np.where(D[:, 0, 0] > 1e-12 * scale_d, D[:, 0, 0], np.inf)
    top = np.linalg.eigvalsh(D[:, 1:, 1:])[:, -1]
    inv_t = np.where(top > 1e-12 * scale_d, 1.0 / np.maximum(top, 1e-300), 0.0)
    vel = np.asarray(v + Xs @ P, dtype=float)
    parts = []
    for g in colours(Js):
        rn = 3 * g
        parts.append((g, rn, Js[rn], Js[rn + 1], Js[rn + 2], Xs[:, rn], Xs[:, rn + 1], Xs[:, rn + 2]))
    scale = max(float(np.abs(Js @ v + bias).max(initial=0.0)), 1e-300)
    for sweep in range(1, sweeps + 1):
        change = 0.0
        for g, rn, Jn, Jt1, Jt2, Xn, Xt1, Xt2 in parts:
            pn = np.maximum(0.0, P[rn] - (Jn @ vel + bias[rn]) / d_n[g])
            dn = pn - P[rn]
            P[rn] = pn
            dv = Xn @ dn
            vel += dv
            xi_t = np.column_stack((Jt1 @ vel + bias[rn + 1], Jt2 @ vel + bias[rn + 2]))
            pt_old = np.column_stack((P[rn + 1], P[rn + 2]))
            pt = pt_old - inv_t[g, None] * xi_t
            size = np.linalg.norm(pt, axis=1)
            limit = mu[g] * pn
            pt *= np.where(size > limit, limit / np.maximum(size, 1e-300), 1.0)[:, None]
            step = pt - pt_old
            P[rn + 1], P[rn + 2] = pt[:, 0], pt[:, 1]
            vel += Xt1 @ step[:, 0] + Xt2 @ step[:, 1]
            change = max(change, float(np.abs(Jn @ dv).max(initial=0.0)),
                         float(np.abs(step).max(initial=0.0)) * float(top[g].max(initial=0.0)))
        if change <= tolerance * scale:
            return ConeSolution(P, vel, sweep, True)
    return ConeSolution(P, vel, sweeps, False)


def block_diagonal(J, X, k: int) -> np.ndarray:
    """(k, 3, 3): the diagonal blocks ``J_c M^-1 J_c^T`` of each contact's three rows."""
    if not sparse.issparse(J):
        return np.einsum("kin,kjn->kij", J.reshape(k, 3, -1), X.T.reshape(k, 3, -1))
    D = np.empty((k, 3, 3))
    for i in range(3):
        for j in range(3):
            D[:, i, j] = np.asarray(J[i::3].multiply(X[:, j::3].T).sum(axis=1)).ravel()
    return D
