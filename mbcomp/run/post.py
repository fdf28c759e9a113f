"""Series derived from a simulation: functions of ``(system, result)``.

Each reads what the run used from the result itself (parameter values, speed-motor start
values, the contacts held closed at each sample), so a result computed elsewhere (a
sweep on threads or on a cluster) gives the same numbers as the serial run.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.core.result import Energy


def bound_system(system: Any, result: Any) -> Any:
    """``system`` with the result's parameter values (itself when they already agree)."""
    if not result.parameters or system.parameters == result.parameters:
        return system
    return system.with_parameters(result.parameters)


def energy(system: Any, result: Any) -> Energy:
    """Kinetic and potential energy (J) at every sample, arrays of shape (m,)."""
    system = bound_system(system, result)
    if len(result.t) == 0:
        return Energy(np.zeros(0), np.zeros(0))
    return system.energy_series(result.q, result.qd)


def constraint_violation(system: Any, result: Any) -> np.ndarray:
    """max |C(q, t)| per sample (zeros for a model without constraints); speed motors are
    measured from the run's own start values."""
    system = bound_system(system, result)
    return system.constraint_violation_series(result.t, result.q, result.offsets)


def reactions(system: Any, result: Any) -> dict[str, np.ndarray]:
    """``{constraint name: (m, k) array}`` of reactions at every sample, and for every contact
    its normal force (N) while the run held it closed (0 while open)."""
    system = bound_system(system, result)
    series: dict[str, list] = {}
    closed = result.closed_contacts or [()] * len(result.t)
    contacts = [c.name for c in system.topology.contacts]
    z = getattr(result, "z", None)
    states = z if getattr(result, "extra_states", ()) and z is not None and len(z) == len(result.t) \
        else [None] * len(result.t)
    for t, q, qd, shut, z in zip(result.t, result.q, result.qd, closed, states):
        values = system.reactions(q, qd, t, tau=result.tau, offsets=result.offsets, contacts=shut,
                                  **({} if z is None else {"states": z}))
        for name in contacts:
            values.setdefault(name, 0.0)
        for name, value in values.items():
            series.setdefault(name, []).append(np.atleast_1d(value))
    return {k: np.array(v) for k, v in series.items()}


def contact_forces(system: Any, result: Any) -> dict[str, np.ndarray]:
    """``{contact name: (m, 3) array}``: each contact's force on its body (N, world frame,
    normal plus friction) at every sample where the run held it closed, zero elsewhere."""
    system = bound_system(system, result)
    names = [c.name for c in system.topology.contacts]
    out = {name: np.zeros((len(result.t), 3)) for name in names}
    closed = result.closed_contacts or [()] * len(result.t)
    z = getattr(result, "z", None)
    states = z if getattr(result, "extra_states", ()) and z is not None and len(z) == len(result.t) \
        else [None] * len(result.t)
    for k, (t, q, qd, shut, zk) in enumerate(zip(result.t, result.q, result.qd, closed, states)):
        if not shut:
            continue
        values = system.contact_forces(q, qd, t, tau=result.tau, offsets=result.offsets, contacts=shut,
                                       **({} if zk is None else {"states": zk}))
        for name, force in values.items():
            out[name][k] = force
    return out
