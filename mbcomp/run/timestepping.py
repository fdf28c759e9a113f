"""Moreau-Jean time stepping for dense contact: fixed steps, contact impulses at every step.

``System.simulate(..., contact_mode="timestepping", dt=...)`` runs this instead of the
event-driven driver (docs/contacts.md, "Time stepping for dense contact").  One step from
``(t, q, v)`` (``q`` coordinates, ``v`` speeds; quaternions stepped on the group by
``StateMap.integrate``):

1. midpoint ``q_m = q (+) dt/2 v``;
2. ``M, f`` at ``(t + dt/2, q_m, v)`` (gravity, springs, inputs, velocity terms: explicit);
   free velocity ``v_f = v + dt M^-1 f``;
3. contact rows at ``q_m`` (``Contact`` rows and ``Collision`` features alike:
   ``friction.plane_contact_rows``); a contact is active when its gap predicted at the
   step's end without it, ``g(q_m) + dt/2 min(J_n v_f, 0)``, is below ``GAP_TOLERANCE``;
4. Newton's law at velocity level and Coulomb's cone on the active contacts,
   ``xi_n = J_n v+ + e min(J_n v, 0) >= 0 _|_ P_n >= 0``, ``|P_t| <= mu P_n``
   (``cone_sweeps``, the law of ``friction.cone_impact``), ``v+ = v_f + M^-1 J^T P``;
5. ``q+ = q_m (+) dt/2 v+``.

First order in ``dt`` (impacts fall within a step); no event location, so the cost of a
step does not depend on how many contacts close in it.  The mass matrix is inverted block
by block (the tree's branches from the ground), so the cost per step grows about linearly
with the number of free bodies.
"""
from __future__ import annotations

import time

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from mbcomp.compiled.collision_kernel import with_collisions
from mbcomp.core import checks
from mbcomp.core.errors import ModelError, SimulationError
from mbcomp.core.result import Result
from mbcomp.core.run_options import RunOptions
from mbcomp.formulations.cone_sweeps import cone_sweeps
from mbcomp.formulations.friction import plane_contact_rows
from mbcomp.run.stats import Counts, run_stats
from mbcomp.formulations.impact import GAP_TOLERANCE, restitution_of

#: Below this many speeds the mass matrix and contact rows stay dense arrays (sparse
#: matrices cost more than they save on small models).
DENSE_SPEEDS = 60

class BlockInverse:
    """``M^-1`` of a tree's mass matrix, one dense inverse per independent block (a branch
    from the ground: entries between branches are structurally zero).  The blocks are found
    once from ``M``'s sparsity at the start."""

    def __init__(self, M: np.ndarray):
        count, label = connected_components(sparse.csr_matrix(M != 0.0), directed=False)
        groups: dict = {}
        for b in range(count):
            idx = np.flatnonzero(label == b)
            groups.setdefault(len(idx), []).append(idx)
        self.groups = [np.array(g) for g in groups.values()]   # (blocks, size) per size
        rows, cols = [], []
        for g in self.groups:
            rows.append(np.repeat(g, g.shape[1], axis=1).ravel())
            cols.append(np.tile(g, (1, g.shape[1])).ravel())
        self.rows, self.cols = np.concatenate(rows), np.concatenate(cols)
        self.n = M.shape[0]

    def __call__(self, M: np.ndarray) -> sparse.csr_matrix:
        """``M^-1`` (sparse, or dense up to ``DENSE_SPEEDS`` speeds); ``SimulationError`` when a block is not positive definite."""
        values = []
        for g in self.groups:
            blocks = M[g[:, :, None], g[:, None, :]]
            try:
                np.linalg.cholesky(blocks)
            except np.linalg.LinAlgError:
                raise SimulationError("the mass matrix is not positive definite in time stepping") from None
            values.append(np.linalg.inv(blocks).ravel())
        if self.n <= DENSE_SPEEDS:
            out = np.zeros((self.n, self.n))
            out[self.rows, self.cols] = np.concatenate(values)
            return out
        return sparse.csr_matrix((np.concatenate(values), (self.rows, self.cols)), shape=(self.n, self.n))


def simulate_timestepping(kernel, formulation, options: RunOptions, q0: np.ndarray, qd0: np.ndarray, *,
                          tau=None, z0=None) -> Result:
    """Moreau-Jean steps of ``options.dt`` (s) from ``(q0, qd0)`` at t = 0 to ``options.t_end``
    (module docstring).  Samples: every step, or the step nearest each of ``options.t_eval``.
    Trees only (``ModelError`` for loop constraints, motors or drive elements)."""
    t_end, dt, t_eval, max_samples = options.t_end, options.dt, options.t_eval, options.max_samples
    if kernel.compiled.drives.elements:
        raise ModelError("simulate", "contact_mode='timestepping' does not run drive elements; use the events mode")
    offsets = formulation.motor_offsets(q0, 0.0)
    bilateral = formulation.constraint_values(kernel, 0.0, q0, np.zeros_like(qd0), offsets)
    if bilateral.J.shape[0]:
        raise ModelError("simulate", "contact_mode='timestepping' runs trees only (this model has "
                         f"{bilateral.J.shape[0]} constraint rows: loops or motors); use the events mode")
    n_steps = int(np.ceil(t_end / dt - 1e-9))
    if t_eval is not None:
        keep = np.unique(np.clip(np.rint(t_eval / dt).astype(int), 0, n_steps))
    else:
        checks.output_size(n_steps + 1, len(q0) + len(qd0), f"dt = {dt:g} s over t_end = {t_end:g} s")
        checks.StepBudget(max_samples, len(q0) + len(qd0) + 1, t_end).check_rows(
            n_steps + 1, f"dt = {dt:g} s over t_end = {t_end:g} s")
        keep = np.arange(n_steps + 1)
    kernel = with_collisions(kernel)
    state_map = kernel.topology.state_map
    q, v = np.array(q0, dtype=float), np.array(qd0, dtype=float)
    M, _ = kernel.dynamics(0.0, q, v)
    invert = BlockInverse(M)
    warm: dict = {}
    times, qs, vs = [], [], []
    wanted = set(keep.tolist())
    counts = {"contact_solves": 0, "sweeps": 0, "unconverged": 0, "max_active": 0}
    started = time.perf_counter()
    t = 0.0
    for step in range(n_steps + 1):
        if step in wanted:
            times.append(t)
            qs.append(q.copy())
            vs.append(v.copy())
        if step == n_steps:
            break
        h = min(dt, t_end - t)
        q_m = state_map.integrate(q, 0.5 * h * v)
        force = kernel.tau(tau, t + 0.5 * h, q_m, v) if tau is not None else None
        M, f = kernel.dynamics(t + 0.5 * h, q_m, v, force)
        Minv = invert(M)
        v_free = v + h * (Minv @ f)
        gaps = kernel.contacts(q_m, v)
        approach = gaps.J @ v
        predicted = gaps.g + 0.5 * h * np.minimum(gaps.J @ v_free, 0.0)    # the gap at the step's end
        active = np.flatnonzero(predicted <= GAP_TOLERANCE)
        if active.size:
            rows = plane_contact_rows(kernel, q_m, v, active)
            k = active.size
            J = np.empty((3 * k, kernel.nv))
            J[0::3], J[1::3], J[2::3] = rows.normal, rows.tangent[:, 0], rows.tangent[:, 1]
            Js = J if kernel.nv <= DENSE_SPEEDS else sparse.csr_matrix(J)
            X = Minv @ Js.T
            bias = np.zeros(3 * k)
            e = np.array([restitution_of(kernel, int(i)) for i in active])
            bias[0::3] = e * np.minimum(approach[active], 0.0)
            P0 = np.concatenate([warm.get(int(i), np.zeros(3)) for i in active])
            solution = cone_sweeps(Js, X, v_free, bias, rows.mu, P0)
            warm = {int(i): solution.P[3 * r:3 * r + 3] for r, i in enumerate(active)}
            v_new = solution.v
            counts["contact_solves"] += 1
            counts["sweeps"] += solution.sweeps
            counts["unconverged"] += int(not solution.converged)
            counts["max_active"] = max(counts["max_active"], k)
        else:
            warm = {}
            v_new = v_free
        q = state_map.integrate(q_m, 0.5 * h * v_new)
        v = v_new
        t = t + h if step < n_steps - 1 else t_end
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(v))):
            raise SimulationError(f"time stepping reached a non-finite state at t = {t:g} s (dt = {dt:g} s "
                                  "may be too large for the model's stiffness)")
    stats = run_stats(options, formulation.name, Counts(nfev=n_steps, steps=n_steps, rejected=0),
                      time.perf_counter() - started, integrator="timestepping", method="Moreau-Jean",
                      path="timestepping", message="The time stepping reached the end of the interval.")
    stats.update(counts, dt=dt)
    topology = kernel.topology
    return Result(system=None, t=np.array(times), q=np.array(qs), qd=np.array(vs), stats=stats, tau=tau,
                  offsets=offsets, coords=tuple(topology.coords), speeds=tuple(topology.speeds),
                  parameters=dict(kernel.parameters), formulation=formulation.name,
                  extra_states=tuple(kernel.compiled.drives.states))
