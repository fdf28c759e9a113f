"""The constraint equations of a compiled model: residual, Jacobian, acceleration bias.

Geometric equations (point and dot primitives) are generated with the rest of the
model (``equations.constraint_outputs``); motor equations are evaluated here.

For every equation ``g(q, t)``: ``gdot = J qd + g_t`` and ``gddot = J qdd + bias``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mbcomp.spec.components.values import name_of
from mbcomp.spec.components.constraints import LoopClosure
from mbcomp.spec.components.primitives import CoordinateEquation, RollingEquation
from mbcomp.core.errors import SimulationError


@dataclass
class ConstraintValues:
    """``g`` (position residual, NaN for speed-only rows), ``J``, ``g_t`` and ``bias``."""

    g: np.ndarray
    J: np.ndarray
    g_t: np.ndarray
    bias: np.ndarray


def _derivatives(f, t: float, h: float = 1e-3, exact=None):
    """Value, first and second derivative of a function of time: exact when the function
    provides ``diff()`` (file expressions), else 5-point stencils (error O(h^4))."""
    if exact is not None:
        values = [float(f(t)), float(exact[0](t)), float(exact[1](t))]
        if not all(map(math.isfinite, values)):
            raise ValueError("non-finite value")
        return tuple(values)
    values = [float(f(t + k * h)) for k in (-2, -1, 0, 1, 2)]
    fm2, fm1, f0, fp1, fp2 = values
    if not all(map(math.isfinite, values)):
        raise ValueError("non-finite value")
    d1 = (fm2 - 8 * fm1 + 8 * fp1 - fp2) / (12 * h)
    d2 = (-fm2 + 16 * fm1 - 30 * f0 + 16 * fp1 - fp2) / (12 * h * h)
    return f0, d1, d2


class ConstraintSet:
    """All constraint equations of a model in a fixed order, with names for reactions."""

    def __init__(self, topology):
        self.topology = topology
        ground = topology.ground
        self.groups: list[tuple[str, Any, list]] = []   # (reaction name, component, equations)
        for joint in topology.cut_joints:
            closure = LoopClosure(joint)
            self.groups.append((joint.name, closure, closure.equations(ground)))
        for comp in topology.constraints:
            self.groups.append((comp.name, comp, comp.equations(ground)))
        self.equations = [eq for _, _, eqs in self.groups for eq in eqs]
        self.owner = [name for name, _, eqs in self.groups for _ in eqs]
        self.labels = [f"{name}.{eq.label}" if eq.label else name for name, _, eqs in self.groups for eq in eqs]
        self.nc = len(self.equations)
        self.slices = {}
        start = 0
        for name, _, eqs in self.groups:
            self.slices[name] = slice(start, start + len(eqs))
            start += len(eqs)
        #: Rows that constrain speeds only (rolling and no-slip rows): ``g`` is NaN there.
        self.velocity_rows = np.array([isinstance(eq, RollingEquation) and eq.speed_only for eq in self.equations],
                                      dtype=bool)
        self._velocity_index = np.flatnonzero(self.velocity_rows)
        self.position_rows = np.array([not (isinstance(eq, CoordinateEquation) and eq.speed is not None)
                                       for eq in self.equations], dtype=bool) & ~self.velocity_rows
        self.coordinate_rows = [r for r, eq in enumerate(self.equations) if isinstance(eq, CoordinateEquation)]
        self.exact_derivatives = {}
        for r in self.coordinate_rows:
            position = self.equations[r].position
            if position is not None and callable(getattr(position, "diff", None)):
                first = position.diff()
                self.exact_derivatives[r] = (first, first.diff())
        self.geometric_rows = [r for r in range(self.nc) if r not in set(self.coordinate_rows)]
        self._geometric_index = np.array(self.geometric_rows, dtype=np.intp)  # (indexes faster than the list)

    # -- evaluation -------------------------------------------------------------------------------
    def evaluate(self, kernel, q: np.ndarray, qd: np.ndarray, t: float,
                 motor_offsets: dict | None = None) -> ConstraintValues:
        """Residuals, Jacobian (nc, nv: over the speeds), explicit time rates and acceleration bias.

        Point and dot equations come from the generated ``constraints`` function;
        motor rows are ``q_k - s(t)`` with s's derivatives by finite differences.
        """
        nv, nc = self.topology.nv, self.nc
        if not self.coordinate_rows:  # every row geometric, in the generated function's order
            g, J, bias = kernel.constraints(q, qd)   # (views of a new array: this call's own)
            if self._velocity_index.size:
                g[self._velocity_index] = np.nan
            return ConstraintValues(g, J, np.zeros(nc), bias)
        g, J, g_t, bias = np.zeros(nc), np.zeros((nc, nv)), np.zeros(nc), np.zeros(nc)
        rows = self._geometric_index
        if rows.size:
            g[rows], J[rows], bias[rows] = kernel.constraints(q, qd)
            g[self._velocity_index] = np.nan
        for r in self.coordinate_rows:
            eq = self.equations[r]
            k = self.topology.q_slice[name_of(eq.joint)].start
            J[r, self.topology.v_slice[name_of(eq.joint)].start] = 1.0  # a 1-DOF screw joint
            speed = self.motor_speed(kernel, r)
            if speed is not None and motor_offsets is not None and r in motor_offsets:
                g[r] = q[k] - motor_offsets[r] - speed * t
                g_t[r] = -speed
            elif speed is not None:
                g[r] = np.nan  # a speed motor without a start value constrains qd only
                g_t[r] = -speed
            else:
                s, s1, s2 = self.position_derivatives(r, t)
                g[r] = q[k] - s
                g_t[r] = -s1
                bias[r] = -s2
        return ConstraintValues(g, J, g_t, bias)

    def position_derivatives(self, r: int, t: float) -> tuple[float, float, float]:
        """``(s, s', s'')`` of the position motor of row ``r`` at ``t`` (s; m or rad, per s,
        per s^2): exact where the position has ``diff()`` (``exact_derivatives``), else the
        5-point stencils of ``_derivatives``.  The values both Python stepping and the
        compiled loops' callback (``codegen/callbacks.py``) use; ``SimulationError`` naming
        the motor and the time when the position raises or is not finite."""
        try:
            return _derivatives(self.equations[r].position, t, exact=self.exact_derivatives.get(r))
        except Exception as exc:  # the user's callable failed
            raise SimulationError(f"position({t:g}) failed: {exc}", self.groups_by_row(r)) from None

    def residual_series(self, kernel, t: np.ndarray, q: np.ndarray, motor_offsets: dict | None = None) -> np.ndarray:
        """Residuals ``g`` at many samples, (m, nc): the geometric rows from one call of the
        generated code, motor rows in numpy (NaN for speed motors without start values)."""
        m = len(q)
        G = np.zeros((m, self.nc))
        rows = self.geometric_rows
        if rows and m:
            G[:, rows] = kernel.evaluate_series("constraints", q)[:, :len(rows)]
            G[:, self._velocity_index] = np.nan
        for r in self.coordinate_rows:
            eq = self.equations[r]
            k = self.topology.q_slice[name_of(eq.joint)].start
            speed = self.motor_speed(kernel, r)
            if speed is not None:
                G[:, r] = q[:, k] - motor_offsets[r] - speed * t if motor_offsets and r in motor_offsets else np.nan
                continue
            try:
                G[:, r] = q[:, k] - np.array([float(eq.position(ti)) for ti in t])
            except Exception as exc:  # the user's callable failed
                raise SimulationError(f"position(t) failed: {exc}", self.groups_by_row(r)) from None
        return G

    def motor_speed(self, kernel, r: int) -> float | None:
        """The speed of the speed motor of row ``r`` with the System's parameter values (a
        run-time change of ``motor.speed`` takes effect), None for other rows."""
        eq = self.equations[r]
        if not isinstance(eq, CoordinateEquation) or eq.speed is None:
            return None
        return float(kernel.parameters.get(f"{self.owner[r]}.speed", eq.speed))

    def explain_position_failure(self, rows, t: float) -> None:
        """After compiled code found a motor's prescribed position (or a derivative) not
        finite at ``t`` (s): raise the ``SimulationError`` Python stepping raises there,
        naming the motor; ``rows``: the position motors' rows."""
        for r in rows:
            self.position_derivatives(r, t)  # (raises as evaluate does)
        raise SimulationError(f"a motor's prescribed position is not finite at t = {t:.6g} s in compiled code: "
                              f"motors {[self.owner[r] for r in rows]}")

    def groups_by_row(self, r: int):
        for name, comp, _ in self.groups:
            if r < self.slices[name].stop:
                return comp
        return None

    def split_reactions(self, lam: np.ndarray, kernel=None, q: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Multipliers by constraint name (a float for a one-row constraint, an array
        otherwise).  A rolling disc's or ball's three (along the plane's normal and two
        tangents) become the contact force on the disc/ball, a world-frame 3-vector (N):
        with ``kernel`` and ``q`` when the plane is a body (its rotation at ``q``)."""
        out = {}
        for name, comp, eqs in self.groups:
            value = lam[self.slices[name]]
            if hasattr(comp, "plane_directions"):
                value = comp.plane_directions() @ value
                plane = getattr(comp, "plane", None)
                if plane is not None and name_of(plane) != self.topology.ground.name:
                    if kernel is None or q is None:
                        raise SimulationError(f"the reaction of {name!r} needs the configuration (its plane moves)")
                    value = self._rotation(kernel, plane, q) @ value
            out[name] = float(value[0]) if len(eqs) == 1 else value.copy()
        return out

    def _rotation(self, kernel, body, q: np.ndarray) -> np.ndarray:
        """The rotation matrix (body to world) of ``body`` at ``q``."""
        from mbcomp.build.layout import body_fields
        rows, _ = kernel.kinematics(q, np.zeros(self.topology.nv))
        return body_fields(rows[self.topology.body_index(self.topology.resolve(body))])["rotation"]
