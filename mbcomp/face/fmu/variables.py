"""The variables of an exported FMU and their value references.

One table shared by ``modelDescription.xml`` (``description.py``) and the C wrapper
(``sources.py`` writes the value-reference bases as ``#define``s): the states
``y = [q, v, z]`` first (value references ``0 .. ny-1``), in model exchange their derivatives
(``ny .. 2 ny - 1``), then every entry of the parameter vector ``p`` in the parameter
layout's order, the inputs (one generalised force per joint named), and the integrator's
settings (co-simulation).  The value reference of the ``k``-th variable is ``k``: its index
in ``ModelVariables`` is ``k + 1``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from mbcomp.core.errors import ModelError
from mbcomp.core.names import speed_column

#: Integrator settings of a co-simulation FMU: (name, start, unit, description).
SETTINGS = (("mbcomp.rtol", 1e-8, "", "DOP853's relative tolerance"),
            ("mbcomp.atol", 1e-10, "", "DOP853's absolute tolerance"),
            ("mbcomp.rest_speed", 1e-4, "m/s", "a contact closing slower than this stays closed"),
            ("mbcomp.max_step", 0.0, "s", "the largest step (0: no limit)"))


@dataclass(frozen=True)
class Variable:
    """One FMI scalar variable (a Real)."""

    name: str
    causality: str            #: "output", "local", "parameter" or "input"
    variability: str          #: "continuous", "fixed" or "tunable"
    start: float | None
    unit: str = ""
    description: str = ""
    initial: str | None = None
    derivative: int | None = None  #: 1-based index of the state this is the derivative of


@dataclass(frozen=True)
class Table:
    """Every variable in value-reference order, with the bases of each group."""

    variables: tuple
    ny: int
    vr_der: int
    vr_par: int
    vr_in: int
    vr_settings: int
    input_speeds: tuple = field(default=())  #: speed index driven by each input
    vr_env: int = 0                          #: the model parameters (``derived.py``) start here

    @property
    def outputs(self) -> list[int]:
        return [k for k, v in enumerate(self.variables) if v.causality == "output"]


def _joint_units(topology) -> tuple[dict, dict]:
    """Units of the coordinates and speeds, by name."""
    q_units, v_units = {}, {}
    for joint in topology.tree_joints:
        q_units.update(zip(joint.coords, joint.coord_units))
        v_units.update(zip(joint.speeds, joint.speed_units))
    return q_units, v_units


#: A unit name the FMU declares: SI symbols, products (space), powers (^), quotients (/).
_UNIT = re.compile(r"^[A-Za-z][A-Za-z0-9^]*(?:[ /][A-Za-z][A-Za-z0-9^]*)*$")
_WORDS = {"or", "per", "output", "measured", "error", "q"}


def parameter_unit(compiled, key: str) -> str:
    """The unit of parameter ``key`` where its specification gives one: ``"q"`` (the unit of
    the joint's coordinate) and ``"N m or N"`` (by the joint's kind) resolved through the
    component's joint; "" where there is none or it is not a unit (``"output per error"``)."""
    found = compiled.parameter_spec(key)
    if found is None:
        return ""
    owner, spec = found
    unit = re.sub(r"\s*\(.*\)\s*$", "", spec.unit or "").strip()
    if unit == "q" or " or " in unit:
        joint = getattr(owner, "joint", None)
        joint = compiled.topology.components.get(getattr(joint, "name", joint))
        units = getattr(joint, "coord_units", None) if joint is not None else None
        if not units or units[0] not in ("rad", "m"):
            return ""
        if unit == "q":
            unit = units[0]
        else:
            choices = unit.split(" or ")
            unit = choices[0] if units[0] == "rad" or len(choices) < 2 else choices[1]
    if not _UNIT.match(unit) or _WORDS & set(re.split(r"[ /]", unit)):
        return ""
    return unit


def build_table(system, kind: str, inputs=(), outputs=None, derived=None) -> Table:
    """The variables of ``system``'s FMU of ``kind`` ("cs" or "me"): ``inputs`` names joints
    that get an input (their generalised force: N m on a rotation, N on a translation);
    ``outputs`` names the coordinates, speed columns and drive states that are outputs (None:
    all of them; the others are local variables); ``derived``: the model parameters
    (``derived.derived_parameters``; None: none)."""
    from mbcomp.face.fmu.derived import Derived
    derived = derived if derived is not None else Derived()
    kernel = system.kernel
    compiled, topology = kernel.compiled, kernel.topology
    state_map = topology.state_map
    q0 = np.zeros(kernel.nq) if state_map.identity else state_map.neutral()
    initial = getattr(compiled, "initial", None) or {}
    q_start = dict(zip(system.coords, q0))
    q_start.update({k: float(v) for k, v in (initial.get("q") or {}).items() if k in q_start})
    v_start = {v: 0.0 for v in system.speeds}
    v_start.update({k: float(v) for k, v in (initial.get("qd") or {}).items() if k in v_start})
    q_units, v_units = _joint_units(topology)
    speed_names = [speed_column(v) if v in system.coords else v for v in system.speeds]
    state_names = list(system.coords) + speed_names + list(system.extra_states)
    wanted = set(state_names) if outputs is None else set(outputs)
    unknown = sorted(wanted - set(state_names))
    if unknown:
        raise ModelError("export_fmu", f"outputs {unknown} are not coordinates, speed columns or states of the "
                         f"model (they are {state_names})")
    variables = []

    def state(name, start, unit, what):
        variables.append(Variable(name, "output" if name in wanted else "local", "continuous", float(start), unit, what,
                                  initial="exact"))

    for name in system.coords:
        state(name, q_start[name], q_units.get(name, ""), "coordinate")
    for v, name in zip(system.speeds, speed_names):
        state(name, v_start[v], v_units.get(v, ""), "speed")
    for name in system.extra_states:
        state(name, 0.0, "", "drive state")
    ny = len(variables)
    if kind == "me":
        for k, base in enumerate(list(variables)):
            unit = f"{base.unit}/s" if base.unit else ""
            variables.append(Variable(f"der({base.name})", "local", "continuous", None, unit,
                                      f"rate of {base.name}", derivative=k + 1))
    vr_par = len(variables)
    p = kernel.p
    for key, (start, shape) in compiled.layout.entries.items():
        unit = parameter_unit(compiled, key)
        if not shape:
            variables.append(Variable(key, "parameter", "fixed", float(p[start]), unit, "parameter"))
        else:
            for i in range(shape[0]):
                variables.append(Variable(f"{key}[{i + 1}]", "parameter", "fixed", float(p[start + i]), unit,
                                          "parameter"))
    vr_env = len(variables)
    for name, value, unit in zip(derived.names, derived.values, derived.units):
        unit = re.sub(r"\s*\(.*\)\s*$", "", unit).strip()
        unit = unit if _UNIT.match(unit) and not _WORDS & set(re.split(r"[ /]", unit)) else ""
        variables.append(Variable(name, "parameter", "fixed", float(value), unit,
                                  "model parameter (the component values computed from it follow)"))
    vr_in = len(variables)
    speeds = []
    for joint_name in inputs:
        joint = topology.components.get(joint_name)
        if joint is None or joint_name not in topology.v_slice:
            joints = [j.name for j in topology.tree_joints]
            raise ModelError("export_fmu", f"input {joint_name!r} is not a joint of the tree (joints: {joints})")
        window = topology.v_slice[joint_name]
        units = ["N" if u == "m/s" else "N m" for u in joint.speed_units]
        indices = range(window.start, window.stop)
        for j, index in enumerate(indices):
            name = f"{joint_name}.tau" if len(indices) == 1 else f"{joint_name}.tau[{j + 1}]"
            variables.append(Variable(name, "input", "continuous", 0.0, units[j],
                                      "generalised force on the joint (added to tau)"))
            speeds.append(index)
    vr_settings = len(variables)
    if kind == "cs":
        for name, start, unit, what in SETTINGS:
            variables.append(Variable(name, "parameter", "tunable", float(start), unit, what))
    names = [v.name for v in variables]
    clashes = sorted({n for n in names if names.count(n) > 1})
    if clashes:
        raise ModelError("export_fmu", f"variable names {clashes} are used twice (rename the joint or parameter)")
    return Table(tuple(variables), ny, ny, vr_par, vr_in, vr_settings, tuple(speeds), vr_env)
