"""Drive elements in the generated program: their generalised forces and state rates.

The generated function ``drives(q, qd, p, u)`` returns ``[tau_drive (nv), z_rates (nz)]``
where ``u = [t, z (nz), callable values]``: the time, the states of the drive elements
(motor currents, PID integrals) in ``DriveLayout.states`` order, then the values of the
Python callables the model uses (evaluated outside the generated code, in
``DriveLayout.callables`` order).  ``tau_drive`` enters the mechanics like a ``tau``
argument, so every formulation takes it unchanged.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from mbcomp.core.errors import CompileError, describe


def name_of(ref: Any) -> str:
    return ref if isinstance(ref, str) else ref.name


@dataclass(frozen=True)
class DriveLayout:
    """Which components contribute through ``drives`` and where their values live in ``u``."""

    elements: tuple            #: drive-element components, in model order
    states: tuple              #: global state names ``"component.local"``
    state_owner: tuple         #: (component, local name) per state
    callables: tuple           #: CallableSignal objects, values after the states in u

    @property
    def nz(self) -> int:
        return len(self.states)

    @property
    def n_u(self) -> int:
        return 1 + self.nz + len(self.callables)

    def description(self) -> str:
        return "drives|" + ",".join(c.name for c in self.elements) + "|" + ",".join(self.states) + \
            f"|{len(self.callables)}"

    def inputs(self, t: float, z: np.ndarray, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The ``u`` vector of ``drives`` at a state (callables evaluated here, in Python)."""
        u = np.empty(self.n_u)
        u[0] = t
        u[1:1 + self.nz] = z
        for k, signal in enumerate(self.callables):
            u[1 + self.nz + k] = signal.evaluate(t, q, qd)
        return u


def drive_layout(topology) -> DriveLayout:
    """Collect the drive elements of a topology, their states and callables, and check
    that every signal reads a 1-DOF tree joint (one ``CompileError`` listing problems)."""
    from mbcomp.spec.components.joints import Joint
    problems = []
    elements = tuple(c for c in topology.components.values() if getattr(c, "drive_element", False))
    states, owners, callables, seen = [], [], [], set()
    for comp in elements:
        for local in comp.state_names():
            states.append(f"{comp.name}.{local}")
            owners.append((comp, local))
        for signal in comp.signals():
            for s in signal.walk():
                for ref in s.joints():
                    joint = topology.components.get(name_of(ref))
                    if not isinstance(joint, Joint):
                        continue  # reported by the reference check
                    if joint.n_coords != 1 or joint.name not in topology.q_slice:
                        problems.append(f"{describe(comp)}: signal {s.describe()} needs a 1-DOF joint of the "
                                        f"tree, {describe(joint)} is not one")
                if hasattr(s, "evaluate") and id(s) not in seen:
                    seen.add(id(s))
                    callables.append(s)
    clash = [n for n in states if n in topology.coords]
    problems += [f"state name {n!r} is also a coordinate name" for n in clash]
    if problems:
        raise CompileError(problems=problems)
    return DriveLayout(elements=elements, states=tuple(states), state_owner=tuple(owners), callables=tuple(callables))


class DriveContext:
    """What drive elements and signals build their expressions from (symbolic)."""

    def __init__(self, prog, kin, layout: DriveLayout):
        self.prog, self.kin, self.layout = prog, kin, layout
        self.let = prog.let
        nz = layout.nz
        self.t = prog.du[0]
        self._states = {}
        for k, (comp, local) in enumerate(layout.state_owner):
            self._states.setdefault(comp.name, []).append(prog.du[1 + k])
        self._callables = {id(s): prog.du[1 + nz + k] for k, s in enumerate(layout.callables)}
        self._values: dict = {}
        self._rates: dict = {}
        self._busy: set = set()
        self._owner = None          # the component whose signals are being built
        self._fields: dict = {}     # component name -> {(id(source), field): parameter key}

    def number(self, value: float):
        """A sympy number, exact for integers so that 0 and 1 prune."""
        import sympy as sp
        value = float(value)
        return sp.Integer(int(value)) if value.is_integer() else sp.Float(value)

    def param(self, comp, attr: str):
        return self.kin.param(comp, attr)

    def field(self, source, field: str):
        """The parameter symbol of number ``field`` of a signal source, as the component
        the signal feeds lists it (``SignalOwner.signal_fields``)."""
        owner = self._owner
        if owner is None or not hasattr(owner, "signal_fields"):
            return self.number(source.source_value(field))
        keys = self._fields.get(owner.name)
        if keys is None:
            keys = {(id(s), f): key for key, (s, f) in owner.signal_fields().items()}
            self._fields[owner.name] = keys
        key = keys.get((id(source), field))
        if key is None:
            return self.number(source.source_value(field))
        return self.kin.layout.symbols(f"{owner.name}.{key}")

    def owned_by(self, comp):
        """Build ``comp``'s signals: their sources' numbers are ``comp``'s parameters."""
        self._owner = comp

    def component(self, name: str):
        """A component of the model by its (flattened) name (a ``ControllerRef``'s PID)."""
        comp = self.kin.topology.components.get(name)
        if comp is None or not hasattr(comp, "state_names"):
            raise CompileError(problems=[f"signal PID({name}): {name!r} is not a controller of the model"])
        return comp

    def states(self, comp) -> list:
        return self._states[comp.name]

    def q(self, joint):
        return self.kin.q(joint)[0]

    def qd(self, joint):
        return self.kin.qd(joint)[0]

    def callable_value(self, signal):
        return self._callables[id(signal)]

    def _key_owner(self, signal):
        """``(cache key, owner)``: a controller is its own owner; a source belongs to the
        component being built (the same source under two components is two parameters)."""
        from mbcomp.spec.components.base import Component
        owner = signal if isinstance(signal, Component) else self._owner
        return ((None if owner is None else owner.name), id(signal)), owner

    def signal(self, signal):
        """The signal's value as a program symbol (each signal built once per owner)."""
        key, owner = self._key_owner(signal)
        if key not in self._values:
            if key in self._busy:
                raise CompileError(problems=[f"signal {signal.describe()} depends on itself (an algebraic loop "
                                             f"between controllers)"])
            self._busy.add(key)
            previous, self._owner = self._owner, owner
            try:
                self._values[key] = self.let(signal.symbolic(self))
            finally:
                self._owner = previous
            self._busy.discard(key)
        return self._values[key]

    def rate(self, signal):
        key, owner = self._key_owner(signal)
        if key not in self._rates:
            previous, self._owner = self._owner, owner
            try:
                rate = signal.symbolic_rate(self)
            finally:
                self._owner = previous
            self._rates[key] = None if rate is None else self.let(rate)
        return self._rates[key]


def drive_outputs(prog, kin, layout: DriveLayout | None) -> None:
    """Outputs ``"drive_forces"`` (nv: generalised forces on the speeds) and ``"state_rates"``
    (nz) of the program."""
    import sympy as sp  # the warm path (drive_layout) never needs it
    nv = kin.topology.nv
    if layout is None:
        prog.du = [sp.Symbol("du0")]
        prog.outputs["drive_forces"] = [sp.Integer(0)] * nv
        prog.outputs["state_rates"] = []
        return
    prog.du = [sp.Symbol(f"du{i}") for i in range(layout.n_u)]
    ctx = DriveContext(prog, kin, layout)
    forces = [sp.Integer(0)] * nv
    rates = []
    for comp in layout.elements:
        ctx.owned_by(comp)
        for joint, value in comp.drive_loads(ctx):
            k = kin.topology.v_slice[name_of(joint)].start  # a 1-DOF screw joint: its speed
            forces[k] = forces[k] + value
        element_rates = comp.state_rates(ctx)
        if len(element_rates) != len(comp.state_names()):
            raise RuntimeError(f"{describe(comp)} gave {len(element_rates)} rates for {len(comp.state_names())} states")
        rates += element_rates
    prog.outputs["drive_forces"] = [prog.let(f) for f in forces]
    prog.outputs["state_rates"] = [prog.let(r) for r in rates]
