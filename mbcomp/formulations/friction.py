"""Coulomb friction on closed contacts: tangential rows, the stick/slide acceleration solve
and the impact law on the friction cone, written for generic contact rows.

Everything here works on rows: a contact is a normal Jacobian row ``J_n`` (1, nv), two
tangential rows ``J_t`` (2, nv) (the touching point's velocity along an orthonormal
tangent basis), their acceleration biases, the gap, Coulomb's ``mu`` and Newton's ``e``.
``plane_contact_rows`` builds them for ``Contact`` components (a body point or sphere on a
world-fixed plane); any other source of rows (shapes colliding) can use ``solve_sliding``
and ``cone_impact`` unchanged.

The laws (docs/contacts.md):

- sticking: the tangential rows are bilateral at the acceleration level (with a velocity
  feedback ``-STICK_RATE * J_t qd`` that removes the slip left by integration error), valid
  while ``|lam_t| <= mu lam_n``;
- sliding: the friction force ``-mu lam_n s`` (``s`` the unit slip direction) is coupled
  into the solve: the normal force's column becomes ``J_n - mu s J_t`` (a non-symmetric
  KKT system).  A sliding contact whose effective normal mass is not positive (Painleve's
  paradox) is a ``SimulationError``;
- impacts: Moreau's set-valued law with Newton's restitution on the normal (Glocker's
  formulation): ``xi_n = v_n+ + e v_n- >= 0, P_n >= 0, xi_n P_n = 0`` and ``P_t`` in the
  disc of radius ``mu P_n``, opposite the post-impact slip ``v_t+`` when that is not zero.
  It is solved as a small cone complementarity problem by projected block Gauss-Seidel on
  the Delassus matrix ``J M^-1 J^T``, which handles several simultaneous and redundant
  contacts (a box landing on four corners).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mbcomp.build.layout import body_fields
from mbcomp.core.errors import SimulationError
from mbcomp.core.tolerances import (CONE_TOLERANCE, DIRECTION_SPEED, FRICTION_RCOND,  # noqa: F401 (CONE_TOLERANCE: re-exported)
                                    FRICTION_RESIDUAL, PAINLEVE, STICK_RATE)
from mbcomp.core.rotations import cross
from mbcomp.core.small_linalg import least_norm

#: Sweeps of the impact's projected Gauss-Seidel, and its relative convergence tolerance (on
#: the change of the velocities a sweep produces).
IMPACT_SWEEPS = 5000
IMPACT_TOLERANCE = 1e-13


class Closed(tuple):
    """The indices of the contacts held closed (a tuple, as formulations take them), with the
    friction mode of each: ``stick`` (a frozenset of indices whose tangential rows are
    bilateral) and ``slip`` (``{index: unit slip direction (3,), world}``).  A contact in
    neither has no friction.  Plain data: it pickles with a ``Result``."""

    def __new__(cls, indices=(), stick=(), slip=None):
        self = super().__new__(cls, tuple(int(i) for i in indices))
        kept = set(self)
        self.stick = frozenset(int(i) for i in stick if int(i) in kept)
        self.slip = {int(i): np.asarray(d, dtype=float) for i, d in (slip or {}).items() if int(i) in kept}
        return self

    def __getnewargs__(self):
        return (tuple(self),)

    @property
    def has_friction(self) -> bool:
        return bool(self.stick or self.slip)

    def mode(self, i: int) -> str:
        """``"stick"``, ``"slip"`` or ``"none"`` for contact ``i``."""
        return "stick" if i in self.stick else "slip" if i in self.slip else "none"


def has_friction(contacts) -> bool:
    """Whether a closed set carries friction modes (a ``Closed`` with sticking or sliding)."""
    return bool(getattr(contacts, "has_friction", False))


def tangent_basis(normal) -> np.ndarray:
    """(2, 3) orthonormal tangents ``t1, t2`` of a unit ``normal`` with ``t1 x t2 = normal``."""
    return _tangent_basis(tuple(float(c) for c in normal)).copy()


@lru_cache(maxsize=256)
def _tangent_basis(normal: tuple) -> np.ndarray:
    n = np.asarray(normal, dtype=float)
    e = np.eye(3)[int(np.argmin(np.abs(n)))]
    t1 = cross(n, e)
    t1 /= np.linalg.norm(t1)
    return np.array([t1, cross(n, t1)])


def _columns_cross(w: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Rows ``w_k x c`` of a (k, 3) array (np.cross costs ~0.1 ms a call)."""
    return np.column_stack((w[:, 1] * c[2] - w[:, 2] * c[1], w[:, 2] * c[0] - w[:, 0] * c[2],
                            w[:, 0] * c[1] - w[:, 1] * c[0]))


@dataclass(frozen=True)
class ContactRows:
    """Rows of some contacts at one state (k contacts, nv speeds), all world frame.

    ``normal`` (k, nv): gap-rate rows; ``tangent`` (k, 2, nv): the touching point's slip
    velocity along ``basis[:, 1:]``; ``tangent_bias`` (k, 2): ``d/dt (J_t qd) - J_t qdd``;
    ``basis`` (k, 3, 3): rows ``n, t1, t2``; ``mu`` (k,); ``point`` (k, 3) m: where the
    force acts."""

    normal: np.ndarray
    tangent: np.ndarray
    tangent_bias: np.ndarray
    basis: np.ndarray
    mu: np.ndarray
    point: np.ndarray


def friction_of(kernel, index: int) -> float:
    """Coulomb's coefficient of contact ``index`` as bound (0 for contacts without friction,
    such as joint limits)."""
    contact = kernel.topology.contacts[index]
    return float(kernel.parameters.get(getattr(contact, "friction_key", f"{contact.name}.friction"), 0.0))


def plane_contact_rows(kernel, q: np.ndarray, qd: np.ndarray, indices, normal_rows: bool = True) -> ContactRows:
    """Rows of ``Contact`` components (body point or sphere on a world-fixed plane) from the
    compiled kinematics.  The touching point is ``c = p - r n``; its velocity is
    ``v0 + w x c`` (so a rolling ball's includes ``w x (-r n)``), its rate's bias
    ``a0 + alpha x c + w x v_p`` (``n`` is fixed, ``c`` moves with ``p``).  A contact that
    is not a point on a plane (a joint limit) gets zero tangential rows and ``mu = 0``.
    ``normal_rows=False`` leaves ``normal`` zero (for callers that have the gap rows)."""
    topology = kernel.topology
    indices = list(indices)
    k, nv = len(indices), kernel.nv
    normal = kernel.contacts(q, qd).J[indices] if k and normal_rows else np.zeros((k, nv))
    tangent = np.zeros((k, 2, nv))
    bias = np.zeros((k, 2))
    basis = np.zeros((k, 3, 3))
    mu = np.zeros(k)
    point = np.zeros((k, 3))
    bodies = columns = None
    provider = getattr(kernel, "tangent_rows", None)   # other sources of contact rows (mb.Collision)
    provided = provider(q, qd, indices) if provider is not None else {}
    for row, (b, t_rows, t_bias, p, m) in provided.items():
        basis[row], tangent[row], bias[row], point[row], mu[row] = b, t_rows, t_bias, p, m
    for row, i in enumerate(indices):
        contact = topology.contacts[i]
        if row in provided or not hasattr(contact, "friction") or not hasattr(contact, "point"):
            continue
        n = np.asarray(contact.normal, dtype=float)
        basis[row, 0] = n
        basis[row, 1:] = tangent_basis(n)
        mu[row] = friction_of(kernel, i)
        if bodies is None:
            bodies, columns = kernel.kinematics(q, qd)
        body = topology.resolve(contact.body)
        local = np.asarray(kernel.parameters[f"{contact.name}.point"], dtype=float)
        radius = float(kernel.parameters.get(f"{contact.name}.radius", 0.0))
        if body is topology.ground:
            point[row] = local - radius * n
            continue
        fields = body_fields(bodies[topology.body_index(body)])
        R, origin, V, A = fields["rotation"], fields["origin"], fields["velocity"], fields["bias"]
        p = origin + R @ local
        c = p - radius * n
        point[row] = c
        w, v0 = V[:3], V[3:]
        v_p = v0 + cross(w, p)
        T = basis[row, 1:]
        idx = list(topology.speed_indices_of_body(body))
        S = columns[idx]
        J_c = (S[:, 3:] + _columns_cross(S[:, :3], c)).T  # (3, len(idx))
        tangent[row][:, idx] = T @ J_c
        bias[row] = T @ (A[3:] + cross(A[:3], c) + cross(w, v_p))
    return ContactRows(normal, tangent, bias, basis, mu, point)


def slip_direction(rows: ContactRows, row: int, qd: np.ndarray, fallback) -> np.ndarray:
    """Unit slip direction in tangent coordinates (2,): the slip velocity's, or when it is
    (nearly) zero the ``fallback`` world direction (3,) projected on the tangents."""
    v = rows.tangent[row] @ qd
    speed = float(np.linalg.norm(v))
    if speed > DIRECTION_SPEED:
        return v / speed
    d = rows.basis[row, 1:] @ np.asarray(fallback, dtype=float)
    size = float(np.linalg.norm(d))
    return d / size if size > 0 else np.zeros(2)


@dataclass(frozen=True)
class FrictionSolution:
    """Accelerations ``qdd`` (nv,), multipliers ``lam`` of the given rows (bilateral then
    normal), and each closed contact's tangential force in tangent coordinates
    ``tangential`` {contact index: (2,) N}."""

    qdd: np.ndarray
    lam: np.ndarray
    tangential: dict


def solve_sliding(Minv: np.ndarray, f: np.ndarray, J: np.ndarray, rhs: np.ndarray, W: np.ndarray,
                  where: str, t: float, sliding_rows=()) -> tuple[np.ndarray, np.ndarray]:
    """``(qdd, lam)`` of ``M qdd = f + W^T lam``, ``J qdd = rhs`` (W = J except on sliding
    normal rows, whose column carries the friction ``-mu s J_t``).  Redundant rows share
    the load by the least-norm multipliers.  ``SimulationError`` when the rows conflict or a
    sliding row's effective normal mass ``(J M^-1 W^T)_kk`` is not positive (Painleve)."""
    if J.shape[0] == 0:
        return Minv @ f, np.zeros(0)
    A = J @ Minv @ W.T
    b = rhs - J @ (Minv @ f)
    scale = max(float(np.abs(np.diag(A)).max(initial=0.0)), 1e-300)
    for k in sliding_rows:
        if A[k, k] <= PAINLEVE * scale:
            raise SimulationError(painleve_message(t, where, A[k, k]))
    lam = least_norm(A, b, FRICTION_RCOND, f"the friction solve at t = {t:g} ({where})")  # (least norm: redundant rows share the load)
    residual = float(np.abs(A @ lam - b).max(initial=0.0))
    if residual > FRICTION_RESIDUAL * max(1.0, float(np.abs(b).max(initial=0.0))):
        raise SimulationError(inconsistent_message(t, where, residual))
    return Minv @ (f + W.T @ lam), lam


def painleve_message(t: float, where: str, mass: float) -> str:
    """The error of a sliding contact without a consistent normal force (``where``: the
    closed contacts' names; ``mass``: its effective inverse mass with friction), the same
    from the Python and the compiled friction solve."""
    return (f"Painleve's paradox at t = {t:g}: the sliding contact {where} has no consistent normal force (its "
            f"effective inverse mass with friction, {mass:.3g}, is not positive); lower the friction coefficient")


def inconsistent_message(t: float, where: str, residual: float) -> str:
    """The error of held rows no forces can meet (``residual`` of the least-squares solve)."""
    return (f"the contact and constraint forces at t = {t:g} are inconsistent ({where}): no forces meet every "
            f"closed contact (residual {residual:.3g})")


def friction_solve(kernel, Minv: np.ndarray, f: np.ndarray, J: np.ndarray, rhs: np.ndarray, closed: Closed,
                   q: np.ndarray, qd: np.ndarray, t: float) -> FrictionSolution:
    """The acceleration solve with friction on the closed contacts.

    ``J`` and ``rhs`` hold the bilateral rows and then the normal rows of ``closed`` (in its
    order), as ``Formulation.constraint_values`` stacks them, with the formulation's
    acceleration targets.  Sticking contacts add their two tangential rows (target
    ``-bias_t - STICK_RATE J_t qd``); sliding ones change their normal row's force column.
    """
    indices = list(closed)
    nb = J.shape[0] - len(indices)
    rows = plane_contact_rows(kernel, q, qd, indices, normal_rows=False)
    W = J.copy()
    extra_J, extra_rhs, sliding, stick_rows = [], [], [], []
    slide_dirs = {}
    for r, i in enumerate(indices):
        if i in closed.stick:
            Jt = rows.tangent[r]
            extra_J.append(Jt)
            extra_rhs.append(-rows.tangent_bias[r] - STICK_RATE * (Jt @ qd))
            stick_rows.append(i)
        elif i in closed.slip:
            s = slip_direction(rows, r, qd, closed.slip[i])
            slide_dirs[i] = s
            W[nb + r] = J[nb + r] - rows.mu[r] * (s @ rows.tangent[r])
            sliding.append(nb + r)
    if extra_J:
        Jall = np.vstack([J] + extra_J)
        rall = np.concatenate([rhs] + extra_rhs)
        Wall = np.vstack([W] + extra_J)
    else:
        Jall, rall, Wall = J, rhs, W
    names = [kernel.topology.contacts[i].name for i in indices]
    qdd, lam = solve_sliding(Minv, f, Jall, rall, Wall, ", ".join(repr(n) for n in names), t, sliding)
    tangential = {}
    for k, i in enumerate(stick_rows):
        tangential[i] = lam[J.shape[0] + 2 * k: J.shape[0] + 2 * k + 2].copy()
    for r, i in enumerate(indices):
        if i in slide_dirs:
            tangential[i] = -rows.mu[r] * lam[nb + r] * slide_dirs[i]
    return FrictionSolution(qdd, lam[:J.shape[0]], tangential)


def world_forces(rows: ContactRows, normal_forces: np.ndarray, tangential: dict, indices) -> np.ndarray:
    """(k, 3) N, world: each contact's force on the body, ``lam_n n + T^T lam_t``."""
    out = np.zeros((len(indices), 3))
    for r, i in enumerate(indices):
        n = rows.basis[r, 0] if np.any(rows.basis[r]) else None
        if n is None:
            continue
        out[r] = normal_forces[r] * n
        if i in tangential:
            out[r] += rows.basis[r, 1:].T @ tangential[i]
    return out


# -- impacts ------------------------------------------------------------------------------------------
def cone_impact(G: np.ndarray, b: np.ndarray, nb: int, mu: np.ndarray, where: str, t: float) -> np.ndarray:
    """Impulses ``P`` of the impact law on the friction cone, by projected block Gauss-Seidel.

    Rows: ``nb`` bilateral rows first (``G P + b = 0``), then per contact ``j`` a block of
    three (normal, two tangents): ``xi = G P + b`` (``b`` holds ``J qd- + e v_n-`` on the
    normal rows, ``J qd-`` on the tangential rows) with ``xi_n >= 0, P_n >= 0, xi_n P_n = 0``
    and ``|P_t| <= mu P_n``, ``P_t = -mu P_n xi_t / |xi_t|`` when ``xi_t != 0``.  Each
    block is updated with the inverse of its diagonal (bilateral rows one by one, tangents
    with the step ``1 / lambda_max``), then projected.  ``SimulationError`` when the sweeps
    do not settle (no consistent impulses: a Painleve-type impact)."""
    n = G.shape[0]
    nk = (n - nb) // 3
    P = np.zeros(n)
    scale = max(float(np.abs(b).max(initial=0.0)), 1e-300)
    gscale = max(float(np.abs(np.diag(G)).max(initial=0.0)), 1e-300)
    inv_tt = []
    for j in range(nk):
        k = nb + 3 * j
        block = G[k + 1:k + 3, k + 1:k + 3]
        top = float(np.linalg.eigvalsh(block).max()) if np.any(block) else 0.0
        inv_tt.append(1.0 / top if top > 1e-12 * gscale else 0.0)
    for sweep in range(IMPACT_SWEEPS):
        before = P.copy()
        for r in range(nb):
            if G[r, r] > 1e-12 * gscale:
                P[r] -= (G[r] @ P + b[r]) / G[r, r]
        for j in range(nk):
            k = nb + 3 * j
            if G[k, k] > 1e-12 * gscale:
                P[k] = max(0.0, P[k] - (G[k] @ P + b[k]) / G[k, k])
            if mu[j] > 0.0 and inv_tt[j] > 0.0:
                xi_t = G[k + 1:k + 3] @ P + b[k + 1:k + 3]
                pt = P[k + 1:k + 3] - inv_tt[j] * xi_t
                size = float(np.linalg.norm(pt))
                limit = mu[j] * P[k]
                P[k + 1:k + 3] = pt if size <= limit else (pt * (limit / size) if size > 0 else 0.0)
            else:
                P[k + 1:k + 3] = 0.0
        # Converged when a sweep no longer changes the velocities it produces (G dP): how
        # redundant rows split an impulse does not matter to the motion.
        change = float(np.abs(G @ (P - before)).max(initial=0.0))
        if change <= IMPACT_TOLERANCE * max(scale, float(np.abs(G @ P).max(initial=0.0))):
            break
    else:
        raise SimulationError(f"the impact with friction at t = {t:g} ({where}) has no consistent impulses on the "
                              f"friction cone (the iteration did not settle in {IMPACT_SWEEPS} sweeps: a "
                              f"Painleve-type impact); lower the friction coefficient")
    return P
