"""Linearisation about an operating point, in the independent tangent coordinates."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from mbcomp.core.errors import SimulationError, format_state
from mbcomp.analysis.space import Chart, force_vector, joint_speed_indices, speed_names, speed_vector
from mbcomp.analysis.space import drive_state_vector

#: An entry of ``A`` below this fraction of its row's largest (or of 1) is the differences'
#: noise, and is set to zero (ignorable coordinates then give exact zero eigenvalues).
IGNORABLE = 1e-9

#: Relative step of the central differences (fourth order: truncation ~ h^4, rounding ~ eps/h).
STEP = 1e-3


@dataclass(frozen=True)
class Linearization:
    """``dz/dt = A z + B u`` for small deviations ``z`` of the state and ``u`` of the inputs.

    ``states``: the independent tangent coordinates (named after their speeds; for joints
    other than ``Ball`` these are the coordinates themselves) then their speeds, named
    ``"<speed>_dot"``, then the states of drive elements (``"component.state"``).  ``inputs``: the speeds whose generalised forces are inputs (N or N m).
    ``basis`` (n, k) maps independent speed (or position) deviations to all speeds, so a
    deviation of all coordinates is ``basis @ z[:k]``.  With velocity constraints (rolling,
    no-slip) the independent coordinates (from the position rows) outnumber the independent
    speeds ``independent`` (from all rows): the states are those coordinates, then the speeds,
    and ``basis`` maps the independent speeds only.  ``q``, ``qd``, ``t``: the operating point;
    ``operating_states``: the drive states there (``system.extra_states`` order).
    """

    A: np.ndarray
    B: np.ndarray
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    independent: tuple[str, ...]
    basis: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    t: float = 0.0
    state_derivative: np.ndarray = field(default=None, repr=False)
    operating_states: np.ndarray = field(default=None, repr=False)

    @property
    def C(self) -> np.ndarray:
        """Full-state output (identity)."""
        return np.eye(self.A.shape[0])

    @property
    def D(self) -> np.ndarray:
        return np.zeros((self.A.shape[0], self.B.shape[1]))

    def to_control(self):
        """A ``control.StateSpace`` (python-control, optional) with the state and input names;
        outputs are the states.  Same as ``control.ss(lin.A, lin.B, lin.C, lin.D)``.

        python-control refuses ``'.'`` in signal names, so the hierarchical names of
        sub-models (``"shoulder.angle"``) are given to it as ``control_names()`` maps them
        (``"shoulder_angle"``); the returned object carries both directions of that map:
        ``sys_c.mbcomp_names`` (control name -> mbcomp name) and ``sys_c.control_names``
        (mbcomp name -> control name)."""
        try:
            import control
        except ImportError:
            raise ImportError("to_control() needs python-control (pip install control); without it use "
                              "lin.A, lin.B, lin.C, lin.D directly") from None
        names = self.control_names()
        out = control.ss(self.A, self.B, self.C, self.D, states=[names[s] for s in self.states],
                         inputs=[names[u] for u in self.inputs], outputs=[names[s] for s in self.states])
        out.control_names = dict(names)
        out.mbcomp_names = {c: m for m, c in names.items()}
        return out

    def control_names(self) -> dict[str, str]:
        """``{mbcomp name: python-control name}`` for the states and inputs: every ``'.'``
        becomes ``'_'``; a name that would then clash with another gets ``_2``, ``_3``, ..."""
        mapping: dict[str, str] = {}
        used: set[str] = set()
        for name in dict.fromkeys(tuple(self.states) + tuple(self.inputs)):
            base = name.replace(".", "_")
            candidate, k = base, 1
            while candidate in used:
                k += 1
                candidate = f"{base}_{k}"
            used.add(candidate)
            mapping[name] = candidate
        return mapping


def _central(fun, z0: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Columns d fun / d z_j by the fourth-order central stencil (-2, -1, +1, +2)."""
    cols = []
    for j, h in enumerate(steps):
        e = np.zeros_like(z0)
        e[j] = h
        fm2, fm1, fp1, fp2 = (fun(z0 + s * e) for s in (-2, -1, 1, 2))
        cols.append((fm2 - 8 * fm1 + 8 * fp1 - fp2) / (12 * h))
    return np.column_stack(cols) if cols else np.zeros((len(fun(z0)), 0))


def linearize(system, q: Any, qd: Any = None, t: float | None = None, inputs: Sequence[str] | str | None = None,
              tau: Any = None, independent: Sequence[str] | None = None, step: float = STEP,
              states: Any = None) -> Linearization:
    """Linearise the equations of motion about ``(q, qd)`` at time ``t`` (``tau``: constant or
    callable generalised forces kept at the operating point, e.g. holding forces).

    Constrained models are reduced to their independent coordinates the way sympy's
    ``Linearizer`` does: the dependent tangent coordinates follow from ``g = 0`` (Newton) and
    the dependent speeds from ``J v + g_t = 0`` at every perturbed state, so ``A`` describes the
    motion on the constraint manifold; ``independent`` (joint or speed names) chooses them,
    by default they are those the ``lagrange`` formulation picks (pivoted QR).  Both
    formulations give the same ``A`` (the ``dae`` stabilisation vanishes on the manifold).

    Derivatives are fourth-order central differences of the compiled accelerations (relative
    step ``step``; error ~1e-10 relative); ``B`` is exact (the accelerations are linear in the
    forces).  ``inputs``: joints (all their speeds) or speeds whose generalised forces are inputs.

    ``t=None`` (the default): 0, or where inputs that change with time have settled
    (``operating_time``: after a ``Step``), as ``equilibrium`` takes it.

    States of drive elements (motor currents, PID integrals; ``system.extra_states``) follow
    the mechanical ones in the state vector (rows and columns of ``A``), at the values
    ``states`` (``{name: value}`` or an array in ``extra_states`` order); when not given, the
    values at which they rest at ``(q, qd)`` (``mbcomp.analysis.rest_states``: exact at an
    equilibrium, so a PID-held pose needs no integral computed by hand).  ``.operating_states``
    holds the values used.
    """
    q = system.state_vector(q)
    from mbcomp.analysis.equilibrium import operating_time
    t = operating_time(system, q, t)
    n = len(speed_names(system))
    v0 = speed_vector(system, qd)
    chart = Chart(system, q, t, independent)
    if chart.constrained:
        q, v0 = system.assemble(q, v0, t)
        chart = Chart(system, q, t, independent)
    k, kq = chart.k, chart.kq
    names = speed_names(system)
    ind, qind = chart.ind, chart.qind
    v0i = v0[ind]
    input_idx = [] if inputs is None else joint_speed_indices(system, inputs, "inputs")

    extra_names = tuple(getattr(system, "extra_states", ()))
    if not extra_names:
        w0 = np.zeros(0)
    elif states is None:
        from mbcomp.analysis.equilibrium import rest_states
        w0 = rest_states(system, q, v0, t, tau)
    else:
        w0 = drive_state_vector(system, states)

    def derivative(z: np.ndarray, u: np.ndarray | None = None) -> np.ndarray:
        qz, x = chart.position(z[:kq])
        v = chart.velocity(qz, z[kq:kq + k])
        extra = force_vector(system, tau, t, qz, v)
        if u is not None:
            extra = u if extra is None else extra + u
        if not extra_names:
            a = system.accelerations(qz, v, t, tau=extra)
            return np.concatenate((chart.rate(qz, x, v)[qind], a[ind]))
        w = z[kq + k:]
        a = system.accelerations(qz, v, t, tau=extra, states=w)
        return np.concatenate((chart.rate(qz, x, v)[qind], a[ind], system.drive_outputs(t, qz, v, w)[1]))

    z0 = np.concatenate((np.zeros(kq), v0i, w0))
    f0 = derivative(z0)
    steps = np.concatenate((np.full(kq, step), step * np.maximum(1.0, np.abs(v0i)),
                            step * np.maximum(1.0, np.abs(w0))))
    A = _central(derivative, z0, steps)
    # Entries below the differences' noise (~1e-11 of their row's scale) are zero: a coordinate
    # the rates do not depend on (an ignorable one: position and heading on the ground, a
    # wheel's angle) would otherwise split the repeated zero eigenvalues it brings by the
    # noise's square root (~1e-6), as a defective eigenvalue does.
    rows_scale = np.maximum(1.0, np.max(np.abs(A), axis=1, initial=0.0))
    A[np.abs(A) < IGNORABLE * rows_scale[:, None]] = 0.0
    if len(names) == len(system.coords) and qind is ind:  # speeds are coordinate rates: dx/dt = v exactly
        A[:k] = 0.0
        A[:k, k:2 * k] = np.eye(k)
    B = np.zeros((len(z0), len(input_idx)))
    for c, j in enumerate(input_idx):
        u = np.zeros(n)
        u[j] = 1.0
        B[:, c] = (derivative(z0, u) - derivative(z0, -u)) / 2.0
    if not np.all(np.isfinite(A)) or not np.all(np.isfinite(B)):
        raise SimulationError(f"the linearisation is not finite at q = {format_state(q)}")
    ind_names = tuple(names[i] for i in ind)
    coordinate_names = tuple(names[i] for i in qind)
    return Linearization(A=A, B=B, states=coordinate_names + tuple(f"{s}_dot" for s in ind_names) + extra_names,
                         inputs=tuple(names[i] for i in input_idx), independent=ind_names,
                         basis=chart.basis(q), q=q, qd=v0, t=float(t), state_derivative=f0,
                         operating_states=w0)
