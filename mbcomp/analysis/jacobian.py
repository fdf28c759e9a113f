"""The geometric Jacobian of a body point (end effector) from the generated kinematics."""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError
from mbcomp.analysis.space import speed_names


def _resolve(system, frame: Any, point: Any):
    """``(body name, local point or None)`` from a body, its name, a ``Frame`` or a
    ``(body, point)`` pair; an explicit ``point`` (body frame, m) wins."""
    local = None
    if isinstance(frame, tuple) and len(frame) == 2:
        frame, local = frame
    elif hasattr(frame, "body") and hasattr(frame, "point") and not hasattr(frame, "mass"):
        frame, local = frame.body, frame.point
    name = getattr(frame, "name", frame)
    components = system.topology.components
    if not isinstance(name, str) or name not in components or not hasattr(components[name], "mass"):
        raise ModelError("jacobian", f"{frame!r} is not a body (or frame on a body) of this model")
    if point is not None:
        local = point
    if local is not None:
        try:
            local = np.asarray(local, dtype=float).reshape(3)
        except (TypeError, ValueError):
            raise ModelError("jacobian", f"point must be 3 numbers (body frame, m), got {local!r}") from None
        if not np.all(np.isfinite(local)):
            raise ModelError("jacobian", f"point must be finite, got {local!r}")
    return name, local


def jacobian(system, frame: Any, q: Any, point: Any = None) -> np.ndarray:
    """(6, n) Jacobian of a body point: rows 0-2 the body's angular velocity, rows 3-5 the
    point's velocity, both in the world frame, per generalised speed (n = ``len(speeds)``):
    ``jacobian(body, q) @ qd`` stacks ``(omega, v)``.

    ``frame`` is a body (object or name), a ``Frame`` on a body, or ``(body, point)``; the
    point (body frame, m) is ``point`` when given, else the frame's point, else the body's
    centre of mass (as ``body_state`` takes it).  Built from
    the generated motion columns (``S_k = (w_k, v0_k)``, ``v0_k`` the velocity of the body
    point at the world origin), so ``v_k = v0_k + w_k x p``.  Speeds that do not move the body
    (other branches, loop coordinates downstream) have zero columns.
    """
    name, local = _resolve(system, frame, point)
    q = system.state_vector(q)
    n = len(speed_names(system))
    out = np.zeros((6, n))
    topology = system.topology
    if topology.resolve(name) is topology.ground:
        return out
    p = system.body_state(name, q, point=local).position
    S = np.asarray(system.motion_columns(q), dtype=float)
    finder = getattr(topology, "speed_indices_of_body", None) or topology.coord_indices_of_body
    idx = list(finder(name))
    w, v0 = S[idx, :3], S[idx, 3:]
    out[:3, idx] = w.T
    out[3:, idx] = (v0 + np.cross(w, p)).T
    return out
