"""Speed space and the constraint manifold, as the analysis functions see them.

Positions are handled in *tangent coordinates* ``x`` (one per generalised speed) about a
reference configuration ``q0``: ``q(x) = integrate(q0, x)``.  For every joint but a
quaternion ``Ball`` this is ``q0 + x``; for a ``Ball`` it is the rotation by the vector
``x`` (its speeds are angular velocities), so the analysis never works on the four
quaternion numbers directly.

With constraints, the speeds split into independent and dependent ones (a column-pivoted QR
of the constraint Jacobian, as the ``lagrange`` formulation does, or the user's choice):
the dependent tangent coordinates follow from ``g(q(x)) = 0`` by Newton, the dependent
speeds from ``J v + g_t = 0``.  ``Chart`` holds that split.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Sequence

import numpy as np

from mbcomp.core.errors import ModelError, SimulationError, format_state
from mbcomp.formulations.base import independent_rows
from mbcomp.formulations.lagrange import partition

#: Newton tolerance for the dependent tangent coordinates (m or rad).
CHART_TOLERANCE = 1e-13


def speed_names(system) -> tuple[str, ...]:
    """The generalised speeds' names (the coordinates' where every speed is a coordinate rate)."""
    return tuple(getattr(system, "speeds", system.coords))


def integrate(system, q: np.ndarray, dx: np.ndarray) -> np.ndarray:
    """``q`` moved by the tangent vector ``dx`` (one entry per speed)."""
    if len(speed_names(system)) == len(system.coords):
        return q + dx
    return np.asarray(system.integrate(q, dx), dtype=float)


def difference(system, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """The tangent vector ``dx`` with ``integrate(q0, dx) = q1``."""
    if len(speed_names(system)) == len(system.coords):
        return q1 - q0
    return np.asarray(system.difference(q0, q1), dtype=float)


def speed_vector(system, values: Any, what: str = "qd") -> np.ndarray:
    """A speed vector (array or ``{speed: value}``) as a checked float array; None is zero."""
    names = speed_names(system)
    if values is None:
        return np.zeros(len(names))
    if hasattr(system, "speed_vector"):
        return system.speed_vector(values, what)
    if len(names) == len(system.coords):
        return system.state_vector(values, what)
    if isinstance(values, dict):
        unknown = [k for k in values if k not in names]
        if unknown:
            raise ModelError(what, f"unknown speed(s) {unknown}; speeds are {list(names)}")
        values = [float(values.get(name, 0.0)) for name in names]
    try:
        arr = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError(what, f"must be {len(names)} numbers, got {values!r}") from None
    if arr.shape != (len(names),) or not np.all(np.isfinite(arr)):
        raise ModelError(what, f"must be {len(names)} finite numbers (speeds {list(names)}), got {values!r}")
    return arr


def joint_speed_indices(system, names: Sequence[str] | str, what: str) -> list[int]:
    """Speed indices named by joints (all of a joint's speeds) or by speeds/coordinates."""
    if isinstance(names, str):
        names = [names]
    speeds = speed_names(system)
    topology = system.topology
    slices = getattr(topology, "v_slice", None) or topology.q_slice
    out: list[int] = []
    for name in names:
        name = getattr(name, "name", name)
        if name in slices:
            out.extend(range(*slices[name].indices(len(speeds))))
        elif name in speeds:
            out.append(speeds.index(name))
        else:
            raise ModelError(what, f"{name!r} is neither a joint nor a speed of this model; joints: "
                                   f"{sorted(slices)}, speeds: {list(speeds)}")
    if len(set(out)) != len(out):
        raise ModelError(what, f"names a speed twice: {list(names)}")
    return out


def force_vector(system, tau: Any, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """``tau`` (None, an array or a callable ``(t, q, qd)``) as a float array of generalised forces."""
    if tau is None:
        return None
    if callable(tau):
        value = tau(t, q, v)
    else:
        value = tau
    n = len(speed_names(system))
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError("tau", f"must be {n} numbers, got {value!r}") from None
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ModelError("tau", f"must be {n} finite numbers, got {value!r}")
    return arr


def model_forces(system, q: np.ndarray, v: np.ndarray, t: float = 0.0, states: Any = None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``(M, f)``: the tree's mass matrix and generalised forces, with the forces of drive
    elements (constant drive torques, friction, motors and PIDs at the drive states ``states``,
    default 0) included in ``f``."""
    M, f = system.tree_dynamics(q, v, t)
    if getattr(system, "has_drives", False):
        f = f + system.drive_outputs(t, q, v, drive_state_vector(system, states))[0]
    return M, f


def drive_state_vector(system, states: Any) -> np.ndarray:
    """Drive states (None: 0; ``{name: value}``; or an array in ``system.extra_states`` order)
    as a checked float array."""
    names = tuple(getattr(system, "extra_states", ()))
    if states is None or isinstance(states, Mapping):
        return system.extra_state_vector(states) if names else np.zeros(0)
    try:
        z = np.asarray(states, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError("states", f"must be {len(names)} numbers {list(names)} or a dict, got {states!r}") from None
    if z.shape != (len(names),) or not np.all(np.isfinite(z)):
        raise ModelError("states", f"must be {len(names)} finite numbers {list(names)}, got {states!r}")
    return z


class Chart:
    """Independent tangent coordinates of the constraint manifold about ``q0`` at time ``t``.

    ``ind``/``dep``: speed indices; ``rows``: the independent constraint rows used.
    ``position(xi)`` gives the full ``q`` and tangent ``x``; ``velocity(q, vi)`` the full speeds;
    ``basis(q)`` the (n, k) matrix ``N`` with ``v = N vi`` (for ``g_t = 0``).

    Velocity (non-holonomic: rolling, no-slip) rows remove speeds but not coordinates: the
    independent tangent coordinates ``qind`` (``kq`` of them) then come from the position rows
    ``prows`` alone, and the independent speeds ``ind`` (``k``) from all rows; without
    velocity rows the two are the same (``qind is ind``).
    """

    def __init__(self, system, q0: np.ndarray, t: float = 0.0, independent: Sequence[str] | None = None):
        self.system, self.q0, self.t = system, np.asarray(q0, dtype=float), float(t)
        self.n = len(speed_names(system))
        self.constrained = bool(system.constraint_names)
        if not self.constrained:
            self.rows = np.arange(0)
            self.dep, self.ind = np.arange(0), np.arange(self.n)
        else:
            #: rows with a position residual (velocity rows have none: NaN)
            self.position_mask = ~np.asarray(getattr(system, "velocity_rows", np.zeros(0, dtype=bool)), dtype=bool)
            cv = self._values(self.q0)
            if self.position_mask.shape != cv.g.shape:
                self.position_mask = np.ones(cv.g.shape, dtype=bool)
            self.rows = independent_rows(cv.J)
            if independent is None:
                self.dep, self.ind = partition(cv.J[self.rows])
            else:
                ind = np.array(sorted(joint_speed_indices(system, independent, "independent")), dtype=int)
                if len(ind) != self.n - len(self.rows):
                    raise ModelError("independent", f"must name {self.n - len(self.rows)} speed(s) (the degrees "
                                                    f"of freedom at this configuration), got {list(independent)}")
                self.ind, self.dep = ind, np.setdiff1d(np.arange(self.n), ind)
                block = cv.J[np.ix_(self.rows, self.dep)]
                if block.size and np.linalg.matrix_rank(block) < len(self.dep):
                    raise ModelError("independent", f"{list(independent)} cannot be chosen independent here: the "
                                                    f"remaining coordinates are not determined by the constraints")
        self.prows, self.qdep, self.qind = self.rows, self.dep, self.ind
        if self.constrained and not self.position_mask.all():
            positions = np.flatnonzero(self.position_mask)
            self.prows = positions[independent_rows(cv.J[positions])] if positions.size else np.arange(0)
            self.qdep, self.qind = partition(cv.J[self.prows]) if self.prows.size else (np.arange(0), np.arange(self.n))
            if independent is not None and self.prows.size:
                # the named speeds' coordinates stay independent: the dependent ones come from the others
                others = np.setdiff1d(np.arange(self.n), self.ind)
                block = cv.J[np.ix_(self.prows, others)]
                if np.linalg.matrix_rank(block) < len(self.prows):
                    raise ModelError("independent", f"{list(independent)} cannot be chosen independent here: the "
                                                    f"other coordinates do not determine the position constraints")
                self.qdep = np.sort(others[partition(block)[0]])
                self.qind = np.setdiff1d(np.arange(self.n), self.qdep)
        self.k = len(self.ind)
        self.kq = len(self.qind)

    def _values(self, q: np.ndarray, v: np.ndarray | None = None):
        cv = self.system.constraint_values(q, v, self.t)
        mask = getattr(self, "position_mask", None)
        if not np.all(np.isfinite(cv.g if mask is None else cv.g[mask])):
            raise SimulationError("a constraint is not finite here (a speed motor without a position?)")
        return cv

    def position(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full ``(q, x)`` with independent tangent coordinates ``xi`` (dependent by Newton)."""
        x = np.zeros(self.n)
        x[self.qind] = xi
        q = integrate(self.system, self.q0, x)
        if not len(self.qdep):
            return q, x
        residual = np.inf
        polished = False
        for _ in range(40):
            cv = self._values(q)
            g = cv.g[self.prows]
            residual = float(np.max(np.abs(g)))
            if residual < CHART_TOLERANCE and polished:
                return q, x
            polished = residual < CHART_TOLERANCE  # one more step: the linearisation divides by small steps
            try:
                x[self.qdep] -= np.linalg.solve(cv.J[np.ix_(self.prows, self.qdep)], g)
            except np.linalg.LinAlgError:
                break
            q = integrate(self.system, self.q0, x)
        raise SimulationError(f"the dependent coordinates cannot be found near q = {format_state(q)} "
                              f"(residual {residual:.3g}): the constraints are singular or unreachable there")

    def basis(self, q: np.ndarray) -> np.ndarray:
        """(n, k) ``N``: full speeds from the independent ones (``J N = 0``)."""
        N = np.zeros((self.n, self.k))
        N[self.ind, np.arange(self.k)] = 1.0
        if len(self.dep):
            J = self._values(q).J[self.rows]
            N[self.dep] = -np.linalg.solve(J[:, self.dep], J[:, self.ind])
        return N

    def velocity(self, q: np.ndarray, vi: np.ndarray) -> np.ndarray:
        """Full speeds with independent ones ``vi`` and ``J v + g_t = 0``."""
        v = np.zeros(self.n)
        v[self.ind] = vi
        if len(self.dep):
            cv = self._values(q)
            J = cv.J[self.rows]
            v[self.dep] = -np.linalg.solve(J[:, self.dep], J[:, self.ind] @ vi + cv.g_t[self.rows])
        return v

    def rate(self, q: np.ndarray, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``dx/dt`` of the tangent coordinates for speeds ``v`` at ``q = q(x)``: ``v`` itself
        unless a speed is not a coordinate rate (a ``Ball``), then by a fourth-order central
        difference of ``difference(q0, integrate(q, s v))`` in s."""
        if len(speed_names(self.system)) == len(self.system.coords):
            return v.copy()
        h = 1e-3 / max(1.0, float(np.max(np.abs(v), initial=0.0)))
        fm2, fm1, fp1, fp2 = (difference(self.system, self.q0, integrate(self.system, q, s * h * v))
                              for s in (-2, -1, 1, 2))
        return (fm2 - 8 * fm1 + 8 * fp1 - fp2) / (12 * h)
