"""Inverse dynamics: the generalised forces (and constraint reactions) a motion needs."""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from mbcomp.core.errors import ModelError, SimulationError, format_state
from mbcomp.analysis.space import joint_speed_indices, model_forces, speed_names


class GeneralisedForces(np.ndarray):
    """An array of generalised forces (N or N m per speed; (n,) or (m, n) for m samples)
    that also carries ``.reactions``: ``{constraint name: reaction}`` (motor torques, slider
    and loop forces, as ``System.reactions`` reports them; (m, k) arrays for m samples).
    Arithmetic on it gives plain arrays."""

    reactions: dict

    def __array_finalize__(self, obj):
        self.reactions = getattr(obj, "reactions", {})

    def __array_wrap__(self, out, context=None, return_scalar=False):
        return np.asarray(out) if not return_scalar else out[()]


def _samples(system, values: Any, width: int, what: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(what, f"must be numbers, got {values!r}") from None
    if arr.ndim not in (1, 2) or arr.shape[-1] != width:
        raise ModelError(what, f"must have shape ({width},) or (m, {width}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ModelError(what, "must be finite")
    return arr.reshape(-1, width)


def inverse_dynamics(system, q: Any, qd: Any, qdd: Any, t: Any = 0.0, actuated: Any = None) -> GeneralisedForces:
    """Generalised forces ``tau`` that produce the accelerations ``qdd`` at ``(q, qd)``.

    One sample (``q`` (nq,), ``qd`` and ``qdd`` (n,)) or a trajectory of m samples ((m, nq),
    (m, n), (m, n); ``t`` a number or m times).  Without constraints ``tau = M qdd - f`` (f: the
    model's own forces, drive elements included with their states at zero).
    With constraints ``M qdd = f + tau + J^T lam`` leaves a choice: by default ``tau`` is the
    smallest (Euclidean norm) generalised force, orthogonal to the constraint forces, and a
    fully driven mechanism (motors on every degree of freedom) needs ``tau = 0``: its motor
    torques are among the reactions; ``actuated`` (joint or speed names) puts ``tau`` on those
    speeds only (``SimulationError`` when they cannot produce the motion).  The motion should
    satisfy the constraints (``J qdd + bias = 0``); the reactions are ``.reactions``.
    Feeding ``tau`` back to ``accelerations`` reproduces ``qdd``.
    """
    n = len(speed_names(system))
    single = np.ndim(qdd) == 1
    Q = system.state_vector(q)[None] if isinstance(q, Mapping) else _samples(system, q, len(system.coords), "q")
    V = _samples(system, qd, n, "qd")
    A = _samples(system, qdd, n, "qdd")
    m = max(len(Q), len(V), len(A))
    for arr, what in ((Q, "q"), (V, "qd"), (A, "qdd")):
        if len(arr) not in (1, m):
            raise ModelError(what, f"has {len(arr)} samples, the others {m}")
    times = np.broadcast_to(np.asarray(t, dtype=float), (m,)) if np.ndim(t) else np.full(m, float(t))
    names = system.constraint_names
    rows_owner = system.constraint_rows
    cols = None if actuated is None else joint_speed_indices(system, actuated, "actuated")
    tau = np.zeros((m, n))
    lams = np.zeros((m, len(rows_owner)))
    for i in range(m):
        qi, vi, ai = Q[i % len(Q)], V[i % len(V)], A[i % len(A)]
        M, f = model_forces(system, qi, vi, times[i])
        r = M @ ai - f
        if not names:
            if cols is not None:
                _check_actuated(r, cols, qi)
                tau[i, cols] = r[cols]
            else:
                tau[i] = r
            continue
        J = system.constraint_values(qi, vi, times[i]).J
        if cols is None:
            lam = np.linalg.lstsq(J.T, r, rcond=None)[0]
            tau[i] = r - J.T @ lam
        else:
            K = np.hstack((J.T, np.eye(n)[:, cols]))
            sol = np.linalg.lstsq(K, r, rcond=None)[0]
            lam, ta = sol[: J.shape[0]], sol[J.shape[0]:]
            _check_actuated(r - K @ sol, None, qi, scale=np.abs(r).max(initial=0.0))
            tau[i, cols] = ta
        lams[i] = lam
    out = (tau[0] if single and m == 1 else tau).view(GeneralisedForces)
    reactions = {}
    for name in names:
        idx = [r for r, owner in enumerate(rows_owner) if owner == name]
        value = lams[:, idx]
        reactions[name] = (value[0, 0] if len(idx) == 1 else value[0]) if single and m == 1 else \
            (value[:, 0] if len(idx) == 1 else value)
    out.reactions = reactions
    return out


def _check_actuated(r: np.ndarray, cols, q: np.ndarray, scale: float | None = None) -> None:
    """Raise when a residual force is left that the actuated speeds cannot supply."""
    if cols is not None:
        rest = np.delete(r, cols)
        scale = np.abs(r).max(initial=0.0)
    else:
        rest = r
    if np.abs(rest).max(initial=0.0) > 1e-9 * max(scale, 1.0):
        raise SimulationError(f"the actuated joints cannot produce this motion at q = {format_state(q)}: "
                              f"a generalised force of {np.abs(rest).max():.3g} is left on the other speeds")
