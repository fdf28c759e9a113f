"""Signals: sensors, sources and controllers that are compiled into the generated code.

A signal is a small expression tree evaluated inside the generated program (no Python
call per evaluation): sensors read a 1-DOF joint (``Angle``, ``Speed``), sources are
functions of time (``Constant``, ``Step``, ``Sine``), and ``PID`` is a controller with an
integral state of its own.  Signals combine with ``+``, ``-``, ``*`` and numbers.  A signal
feeds a ``JointTorque`` ``value``, a ``Drive`` ``torque`` or a ``DCMotor`` ``voltage``.

A plain Python callable of ``t`` (inside a signal) or of ``(t, q, qd)`` (as a component's
value) works too, but it is evaluated in Python at every right-hand side evaluation, so a
model with one integrates in the slower Python-stepped path (``System.integration_path``).

Every signal provides ``symbolic(ctx)``, its symbolic value, and ``symbolic_rate(ctx)``, its time
derivative when that is known without accelerations (``None`` otherwise); ``ctx`` is the
``DriveContext`` of ``drive_equations``.  Every number of a source (``Step`` time and
values, ``Sine`` amplitude, ...) is a run-time parameter of the component the signal feeds,
``"COMPONENT.ATTRIBUTE.FIELD"`` (``"pid.setpoint.time"``; see ``SignalOwner.signal_fields``),
and so are a PID's gains: changing one does not compile again.  A source built from
sub-model parameter expressions keeps them (``signal_args``), so a run-time change of
those parameters reaches it as a fresh build would.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Iterator

from mbcomp.spec.components.base import Component
from mbcomp.spec.components.values import name_of, scalar
from mbcomp.core.errors import ModelError
from mbcomp.core.params import ParameterSpec, positive
from mbcomp.core.params import nonnegative


class Signal:
    """A scalar signal (base class).  Units are those of whatever it feeds."""

    #: ``(args, kwargs)`` of the constructor call when they hold sub-model parameter
    #: expressions (``None`` otherwise): a run-time parameter change rebuilds the signal
    #: from them (``mbcomp.spec.components.expr.substitute``).
    signal_args: Any = None

    def __new__(cls, *args: Any, **kwargs: Any):
        obj = super().__new__(cls)
        if args or kwargs:
            from mbcomp.spec.components.expr import contains_expr
            if contains_expr(args) or contains_expr(kwargs):
                object.__setattr__(obj, "signal_args", (args, kwargs))
        return obj

    def source_fields(self) -> tuple[str, ...]:
        """The numbers of this source that are run-time parameters (none for others)."""
        return ()

    def source_value(self, field: str) -> float:
        """The current value of one of ``source_fields``."""
        return float(getattr(self, field))

    def source_spec(self, field: str) -> ParameterSpec:
        """What a new value of ``field`` must satisfy (the constructor's check)."""
        return ParameterSpec(field, ())

    def structure_text(self) -> str:
        """``describe`` without the numbers that are parameters: what decides the code."""
        return self.describe()

    def symbolic(self, ctx):
        raise NotImplementedError

    def symbolic_rate(self, ctx):
        """Time derivative, or None when it would need accelerations or is unknown."""
        return None

    def children(self) -> tuple["Signal", ...]:
        return ()

    def joints(self) -> list:
        """The joints this signal reads (objects or names), for reference checks."""
        return []

    def describe(self) -> str:
        """A structural description (part of the cache key)."""
        raise NotImplementedError

    def walk(self) -> Iterator["Signal"]:
        """This signal and every signal below it (depth first; a PID's inputs are its own)."""
        yield self
        for child in self.children():
            yield from child.walk()

    # -- arithmetic --------------------------------------------------------------------------
    def __add__(self, other):
        return _Combination("+", (self, as_signal(other, "signal", "+")))

    def __radd__(self, other):
        return _Combination("+", (as_signal(other, "signal", "+"), self))

    def __sub__(self, other):
        return _Combination("+", (self, _Combination("*", (_MINUS_ONE, as_signal(other, "signal", "-")))))

    def __rsub__(self, other):
        return _Combination("+", (as_signal(other, "signal", "-"), _Combination("*", (_MINUS_ONE, self))))

    def __mul__(self, other):
        return _Combination("*", (self, as_signal(other, "signal", "*")))

    def __rmul__(self, other):
        return _Combination("*", (as_signal(other, "signal", "*"), self))

    def __neg__(self):
        return _Combination("*", (_MINUS_ONE, self))

    def __repr__(self) -> str:
        return self.describe()


def as_signal(value: Any, owner: Any, what: str, *, state_callable: bool = False) -> Signal:
    """``value`` as a Signal: a Signal itself, a number (``Constant``) or a callable
    (of ``t``, or of ``(t, q, qd)`` when ``state_callable``); else a ``ModelError``."""
    if isinstance(value, Signal):
        return value
    if callable(value):
        return CallableSignal(value, state_arguments=state_callable)
    scalar(value, owner, what)   # the check, naming the owner
    return Constant(value)       # keeps a sub-model parameter expression (signal_args)


class _Literal(Signal):
    """A fixed number inside a signal (the -1 of a difference): not a parameter."""

    def __init__(self, value: float):
        self.value = float(value)

    def symbolic(self, ctx):
        return ctx.number(self.value)

    def symbolic_rate(self, ctx):
        return 0

    def describe(self):
        return repr(self.value)


_MINUS_ONE = _Literal(-1.0)


class _Combination(Signal):
    def __init__(self, op: str, args: tuple):
        self.op, self.args = op, tuple(args)

    def children(self):
        return self.args

    def symbolic(self, ctx):
        values = [ctx.signal(a) for a in self.args]
        out = values[0]
        for v in values[1:]:
            out = out + v if self.op == "+" else out * v
        return out

    def symbolic_rate(self, ctx):
        rates = [ctx.rate(a) for a in self.args]
        if any(r is None for r in rates):
            return None
        if self.op == "+":
            return sum(rates)
        a, b = self.args
        return rates[0] * ctx.signal(b) + ctx.signal(a) * rates[1]

    def describe(self):
        return "(" + f" {self.op} ".join(a.describe() for a in self.args) + ")"

    def structure_text(self):
        return "(" + f" {self.op} ".join(a.structure_text() for a in self.args) + ")"


class Angle(Signal):
    """The coordinate of a 1-DOF joint (rad for a revolute, m for a prismatic joint)."""

    def __init__(self, joint: Any):
        self.joint = joint

    def joints(self):
        return [self.joint]

    def symbolic(self, ctx):
        return ctx.q(self.joint)

    def symbolic_rate(self, ctx):
        return ctx.qd(self.joint)

    def describe(self):
        return f"Angle({name_of(self.joint)})"

    def file_table(self) -> dict:
        return {"type": "angle", "joint": name_of(self.joint)}


class Speed(Signal):
    """The speed of a 1-DOF joint (rad/s or m/s)."""

    def __init__(self, joint: Any):
        self.joint = joint

    def joints(self):
        return [self.joint]

    def symbolic(self, ctx):
        return ctx.qd(self.joint)

    def describe(self):
        return f"Speed({name_of(self.joint)})"

    def file_table(self) -> dict:
        return {"type": "speed", "joint": name_of(self.joint)}


class Constant(Signal):
    """A constant value."""

    def __init__(self, value: float):
        self.value = scalar(value, "Constant", "value")

    def source_fields(self):
        return ("value",)

    def symbolic(self, ctx):
        return ctx.field(self, "value")

    def symbolic_rate(self, ctx):
        return 0

    def describe(self):
        return f"Constant({self.value!r})"

    def structure_text(self):
        return "Constant"

    def file_table(self) -> dict:
        return {"type": "constant", "value": self.value}


class Step(Signal):
    """``before`` until ``time`` (s), ``after`` from then on."""

    def __init__(self, time: float = 0.0, after: float = 1.0, before: float = 0.0):
        self.time = scalar(time, "Step", "time")
        self.after = scalar(after, "Step", "after")
        self.before = scalar(before, "Step", "before")

    def source_fields(self):
        return ("time", "after", "before")

    def symbolic(self, ctx):
        import sympy as sp
        return sp.Piecewise((ctx.field(self, "after"), ctx.t >= ctx.field(self, "time")),
                            (ctx.field(self, "before"), True))

    def symbolic_rate(self, ctx):
        return 0

    def describe(self):
        return f"Step({self.time!r}, {self.after!r}, {self.before!r})"

    def structure_text(self):
        return "Step"

    def file_table(self) -> dict:
        return {"type": "step", "time": self.time, "after": self.after, "before": self.before}


class Sine(Signal):
    """``offset + amplitude sin(2 pi frequency t + phase)`` (frequency in Hz, phase in rad)."""

    def __init__(self, amplitude: float = 1.0, frequency: float = 1.0, phase: float = 0.0, offset: float = 0.0):
        self.amplitude = scalar(amplitude, "Sine", "amplitude")
        self.frequency = scalar(frequency, "Sine", "frequency", nonnegative=True)
        self.phase = scalar(phase, "Sine", "phase")
        self.offset = scalar(offset, "Sine", "offset")

    def source_fields(self):
        return ("amplitude", "frequency", "phase", "offset")

    def source_spec(self, field):
        return ParameterSpec(field, (), check=nonnegative) if field == "frequency" else ParameterSpec(field, ())

    def _omega(self, ctx):
        return ctx.number(2 * math.pi) * ctx.field(self, "frequency")

    def _argument(self, ctx):
        return self._omega(ctx) * ctx.t + ctx.field(self, "phase")

    def symbolic(self, ctx):
        import sympy as sp
        return ctx.field(self, "offset") + ctx.field(self, "amplitude") * sp.sin(ctx.let(self._argument(ctx)))

    def symbolic_rate(self, ctx):
        import sympy as sp
        return ctx.field(self, "amplitude") * self._omega(ctx) * sp.cos(ctx.let(self._argument(ctx)))

    def describe(self):
        return f"Sine({self.amplitude!r}, {self.frequency!r}, {self.phase!r}, {self.offset!r})"

    def structure_text(self):
        return "Sine"

    def file_table(self) -> dict:
        return {"type": "sine", "amplitude": self.amplitude, "frequency": self.frequency, "phase": self.phase,
                "offset": self.offset}


class TimeExpression(Signal):
    """An expression of the time ``t`` in the language of model files (``"6*sin(2*pi*t)"``;
    ``mbcomp.core.expressions``: numbers, ``t``, ``pi``, ``+ - * / **``, ``sin cos exp sqrt``),
    compiled into the generated code with its exact time derivative.  ``parameters`` maps
    names the text may use to their values (numbers or sub-model parameter expressions);
    each name the text uses is a run-time parameter of the component the signal feeds
    (``"motor.voltage.amp"`` for ``"amp*sin(2*pi*t)"``), the literal numbers are part of
    the code.  The text is
    parsed, never evaluated by Python."""

    def __init__(self, text: str, parameters: dict | None = None):
        from mbcomp.core.expressions import ExpressionError, names_in, parse_expression
        if not isinstance(text, str):
            raise ModelError("TimeExpression", f"text must be a string, got {text!r}")
        names = dict(parameters or {})
        try:
            self.node = parse_expression(text, names, allow_t=True, keep_names=True)
        except ExpressionError as exc:
            raise ModelError("TimeExpression", str(exc)) from None
        used = names_in(self.node)
        self.text = text
        self.values = {n: scalar(names[n], f"TimeExpression {text!r}", n) for n in sorted(used)}

    def source_fields(self):
        return tuple(self.values)

    def source_value(self, field):
        return self.values[field]

    def at(self, t: float) -> float:
        """The value at time ``t`` (s) with the current parameter values (for checks)."""
        from mbcomp.core.expressions import evaluate
        return float(evaluate(self.node, float(t), self.values))

    def _sympy(self, node, ctx):
        from mbcomp.core.expressions import to_sympy
        return to_sympy(node, ctx.t, lambda name: ctx.field(self, name))

    def symbolic(self, ctx):
        return self._sympy(self.node, ctx)

    def symbolic_rate(self, ctx):
        from mbcomp.core.expressions import differentiate
        return self._sympy(differentiate(self.node), ctx)

    def describe(self):
        return f"TimeExpression({self.text!r})"

    def structure_text(self):
        return self.describe()

    def file_table(self):
        """The text with the parameters' values in place (a file holds numbers)."""
        from mbcomp.core.expressions import replace_names, to_text
        return self.text if not self.values else to_text(replace_names(self.node, self.values))


class CallableSignal(Signal):
    """A Python callable of ``t`` (or of ``(t, q, qd)``) evaluated at run time, outside the
    generated code: a model with one steps in Python."""

    def __init__(self, function: Callable, state_arguments: bool = False):
        self.function = function
        self.state_arguments = state_arguments

    def evaluate(self, t: float, q, qd) -> float:
        from mbcomp.core.errors import SimulationError
        try:
            value = self.function(t, q, qd) if self.state_arguments else self.function(t)
            if type(value) is not float and type(value).__name__ == "Expr":
                raise SimulationError(f"signal callable {self.function!r} returned the sub-model parameter "
                                      f"expression {value!r}: inside a Python callable it would keep its "
                                      "build-time value; build the signal from mb.Step, mb.Sine, mb.Constant "
                                      "(they take parameter expressions) instead")
            value = float(value)
        except (TypeError, ValueError) as exc:
            raise SimulationError(f"signal callable {self.function!r} failed: {exc}") from None
        if not math.isfinite(value):
            raise SimulationError(f"signal callable {self.function!r} returned a non-finite value {value}")
        return value

    def symbolic(self, ctx):
        return ctx.callable_value(self)

    def describe(self):
        return "callable(t, q, qd)" if self.state_arguments else "callable(t)"


class SignalOwner:
    """Mixin of components whose attributes ``signal_attrs`` may hold signals: a copy with
    renamed references (``copy_with_references``) rebuilds those signals too, and model
    files hold them as signal tables (``file_value``)."""

    signal_attrs: tuple = ()

    def signal_fields(self) -> dict[str, tuple[Signal, str]]:
        """The run-time parameters inside this component's own signals: ``{"ATTR.FIELD":
        (source, field)}`` for a source given directly (``"setpoint.time"``), else
        ``"ATTR.KIND.FIELD"`` (``"voltage.sine.amplitude"``; ``KIND1``, ``KIND2``, ... when a
        kind repeats).  Controllers inside (a PID) keep their own."""
        found: dict[str, tuple[Signal, str]] = {}
        for attr in self.signal_attrs:
            root = getattr(self, attr, None)
            if not isinstance(root, Signal) or isinstance(root, Component):
                continue
            sources, seen = [], set()
            for s in root.walk():
                if s.source_fields() and not isinstance(s, Component) and id(s) not in seen:
                    seen.add(id(s))
                    sources.append(s)
            kinds = [type(s).__name__.lower() for s in sources]
            for k, source in enumerate(sources):
                if source is root:
                    prefix = attr
                elif kinds.count(kinds[k]) == 1:
                    prefix = f"{attr}.{kinds[k]}"
                else:
                    prefix = f"{attr}.{kinds[k]}{kinds[:k + 1].count(kinds[k])}"
                for field in source.source_fields():
                    found[f"{prefix}.{field}"] = (source, field)
        return found

    def parameter_values(self) -> dict[str, Any]:
        values = super().parameter_values()
        values.update({key: source.source_value(field) for key, (source, field) in self.signal_fields().items()})
        return values

    def signal_spec(self, key: str) -> ParameterSpec | None:
        """The ``ParameterSpec`` of a signal parameter ``"ATTR.FIELD"`` (None when not one)."""
        found = self.signal_fields().get(key)
        if found is None:
            return None
        source, field = found
        spec = source.source_spec(field)
        return ParameterSpec(key, spec.shape, spec.unit, spec.check)

    def file_value(self, key: str):
        value = super().file_value(key)
        if isinstance(value, Signal):
            if not hasattr(value, "file_table"):
                raise ModelError(self, f"{key} {value.describe()} cannot be written to a model file (files hold "
                                       f"numbers, expressions of t and the signal tables of docs/drives.md)")
            return value.file_table()
        return value

    def copy_with_references(self, name: str, references: dict):
        import copy
        new = copy.copy(self)
        for role, ref in references.items():
            if not role.startswith("signal ") and hasattr(self, role):
                object.__setattr__(new, role, ref)
        attrs = [a for a in self.signal_attrs if isinstance(getattr(self, a, None), Signal)]
        rebuilt = rebind_signals([getattr(self, a) for a in attrs], references,
                                 owner=self if isinstance(self, PID) else None)
        for attr, signal in zip(attrs, rebuilt):
            object.__setattr__(new, attr, signal)
        object.__setattr__(new, "name", name)
        return new


class PID(SignalOwner, Component, Signal):
    """A PID controller: ``u = kp e + ki integral(e) + kd de/dt`` with ``e = setpoint - measured``.

    The integral of the error is a state of the model (``"NAME.integral"``, starting at 0 or
    at ``x0``).  ``de/dt`` is the rate of the setpoint minus that of the measured signal; it
    is available when the measured signal is an ``Angle`` (its rate is the joint speed);
    with a ``Speed`` measurement ``kd`` must be 0 (and is no parameter).  ``limit`` (> 0)
    clips the output to ``[-limit, limit]``, with anti-windup by back-calculation: while the
    unclipped output ``u`` is beyond the limit, ``z' = e - (u - clip(u)) / kp`` (tracking
    time ``kp / ki``), which holds the integral term near the limit instead of letting it
    grow.  The correction is continuous, so adaptive integrators do not chatter at the
    limit (as they do with clamping, which switches the integration on and off).
    ``kp``, ``ki``, ``kd`` and ``limit`` are parameters (a sweep over them does not
    recompile).  Add the PID to the model and feed it to a drive, motor or torque.
    """

    kind = "pid"
    section = "forces"
    signal_attrs = ("measured", "setpoint")
    file_keys = ("measured", "setpoint", "kp", "ki", "kd", "limit")
    file_required = ("measured", "setpoint", "kp")
    file_options = {"measured": "signal", "setpoint": "signal"}
    params = (ParameterSpec("kp", (), "output per error", doc="proportional gain"),
              ParameterSpec("ki", (), "output per error s", default=0.0, doc="integral gain"),
              ParameterSpec("kd", (), "output s per error", default=0.0, doc="derivative gain"),
              ParameterSpec("limit", (), "output", positive, optional=True, default=None,
                            doc="output clipped to [-limit, limit]"),
              ParameterSpec("setpoint", (), "measured", doc="a number (a parameter), a signal or a callable of t"))

    def __init__(self, name: str, measured: Any, setpoint: Any, kp: float, ki: float = 0.0, kd: float = 0.0,
                 limit: float | None = None):
        Component.__init__(self, name)
        if not isinstance(measured, Signal):
            raise ModelError(self, f"measured must be a signal (Angle(joint), Speed(joint), ...), got {measured!r}")
        self.measured = measured
        if isinstance(setpoint, Signal) or callable(setpoint):
            object.__setattr__(self, "setpoint", as_signal(setpoint, self, "setpoint"))
        else:
            self.setpoint = setpoint  # a number: the parameter "NAME.setpoint"
        self.kp = kp
        self.ki = ki
        self.kd = kd
        self.limit = limit
        self.has_derivative = not isinstance(measured, Speed) and not _contains_speed(measured)
        if not self.has_derivative and self.kd != 0.0:
            raise ModelError(self, "kd needs the rate of the measured signal, which is not known for a Speed "
                                   "(it would need accelerations); use kd=0 or measure an Angle")
        names = ["kp", "ki"] + (["kd"] if self.has_derivative else []) + (["limit"] if limit is not None else []) \
            + (["setpoint"] if isinstance(self.setpoint, float) else [])
        object.__setattr__(self, "parameters", tuple(names))

    drive_element = True

    def state_names(self) -> tuple[str, ...]:
        return ("integral",)

    def signals(self) -> list[Signal]:
        return [self.measured, self._setpoint_signal()]

    def _setpoint_signal(self) -> Signal:
        return _ParameterSignal(self, "setpoint") if isinstance(self.setpoint, float) else self.setpoint

    def parameter_values(self) -> dict[str, Any]:
        return {k: v for k, v in super().parameter_values().items() if not isinstance(v, Signal)}

    def children(self):
        return ()  # the PID's inputs belong to the PID component, walked once from there

    def references(self):
        return signal_references(self.signals(), owner=self)

    def structure(self):
        return (self.measured.structure_text(), self._setpoint_signal().structure_text(), self.has_derivative,
                self.limit is not None)

    def describe(self):
        return f"PID({self.name})"

    def file_table(self) -> dict:
        return {"type": "pid", "name": self.name}


    def _raw(self, ctx):
        setpoint = self._setpoint_signal()
        e = ctx.let(ctx.signal(setpoint) - ctx.signal(self.measured))
        (z,) = ctx.states(self)
        u = ctx.param(self, "kp") * e + ctx.param(self, "ki") * z
        if self.has_derivative:
            rate_sp, rate_m = ctx.rate(setpoint), ctx.rate(self.measured)
            if rate_sp is None or rate_m is None:
                raise ModelError(self, "the rate of its setpoint or measured signal is not known (a callable or "
                                       "a Speed): the derivative term cannot be formed; use kd=0 with Speed")
            u = u + ctx.param(self, "kd") * (rate_sp - rate_m)
        return e, ctx.let(u)

    def symbolic(self, ctx):
        import sympy as sp
        _, raw = self._raw(ctx)
        if self.limit is None:
            return raw
        limit = ctx.param(self, "limit")
        return ctx.let(sp.Min(sp.Max(raw, -limit), limit))

    def drive_loads(self, ctx):
        return []

    def state_rates(self, ctx):
        import sympy as sp
        e, raw = self._raw(ctx)
        if self.limit is None:
            return [e]
        limit = ctx.param(self, "limit")
        # Back-calculation: how far the output is beyond the limit (0 inside), fed back with
        # the tracking time kp / ki (no correction for kp = 0).
        excess = ctx.let(sp.Max(raw - limit, 0) + sp.Min(raw + limit, 0))
        kp = ctx.param(self, "kp")
        return [e - excess * kp / (kp * kp + sp.Float(1e-300))]


class ControllerRef(Signal):
    """A controller's output named by the controller's name (model files refer to a ``PID``
    this way); resolved against the model's components when compiling."""

    def __init__(self, name: str):
        if not isinstance(name, str) or not name:
            raise ModelError("signal", f"a controller reference needs a name, got {name!r}")
        self.name = name

    def symbolic(self, ctx):
        return ctx.signal(ctx.component(self.name))

    def describe(self):
        return f"PID({self.name})"

    def file_table(self) -> dict:
        return {"type": "pid", "name": self.name}


#: Signal tables of model files: ``{type = "step", time = 0.2, after = 1.0}`` and so on.
SIGNAL_TYPES = {"constant": (Constant, ("value",)), "step": (Step, ("time", "after", "before")),
                "sine": (Sine, ("amplitude", "frequency", "phase", "offset")),
                "angle": (Angle, ("joint",)), "speed": (Speed, ("joint",)), "pid": (ControllerRef, ("name",))}


def signal_from_table(table: dict, where: str) -> Signal:
    """The signal a model-file table describes, else a ``ModelError`` naming ``where``
    and the key (numbers are numbers or sub-model parameter expressions, as the file
    reader turned them; joints and controllers are names)."""
    kind = table.get("type")
    if kind not in SIGNAL_TYPES:
        raise ModelError(where, f"signal type must be one of {', '.join(map(repr, SIGNAL_TYPES))}, got {kind!r}")
    cls, keys = SIGNAL_TYPES[kind]
    unknown = [k for k in table if k != "type" and k not in keys]
    if unknown:
        raise ModelError(where, f"unknown key(s) {unknown} for a {kind!r} signal; allowed: {', '.join(keys)}")
    from mbcomp.spec.components.expr import Expr
    values = {k: v for k, v in table.items() if k != "type"}
    for key, value in values.items():
        if key in ("joint", "name"):
            if not isinstance(value, str):
                raise ModelError(where, f"{key} must be a name, got {value!r}")
        elif isinstance(value, bool) or not isinstance(value, (int, float, Expr)):
            raise ModelError(where, f"{key} must be a number or a parameter expression, got {value!r}")
    if kind in ("angle", "speed", "pid") and not values:
        raise ModelError(where, f"a {kind!r} signal needs {keys[0]}")
    return cls(**values)


class _ParameterSignal(Signal):
    """A component's numeric parameter as a constant signal (a PID's numeric setpoint)."""

    def __init__(self, owner: Any, attr: str):
        self.owner, self.attr = owner, attr

    def symbolic(self, ctx):
        return ctx.param(self.owner, self.attr)

    def symbolic_rate(self, ctx):
        return 0

    def describe(self):
        return f"parameter({self.attr})"


def _contains_speed(signal: Signal) -> bool:
    return any(isinstance(s, (Speed, CallableSignal)) for s in signal.walk())


def signal_references(signals, owner: Any = None) -> dict[str, Any]:
    """References of signal trees for the compiler's checks: ``{"signal joint k": joint}``
    and ``{"signal pid k": pid}`` (the PIDs must be added to the model)."""
    refs: dict[str, Any] = {}
    for signal in signals:
        for s in signal.walk():
            for joint in s.joints():
                refs[f"signal joint {len(refs)}"] = joint
            if isinstance(s, PID) and s is not owner:
                refs[f"signal pid {len(refs)}"] = s
            if isinstance(s, ControllerRef) and (owner is None or s.name != owner.name):
                refs[f"signal pid {len(refs)}"] = s.name
    return refs


def rebind_signals(signals: list, references: dict, owner: Any = None) -> list:
    """Copies of signal trees with their references replaced as ``references`` maps the roles
    of ``signal_references`` (a sub-model's components are renamed when flattened); a PID
    mapped to a name becomes a ``ControllerRef``."""
    counter = [0]

    def mapped(kind: str, default: Any) -> Any:
        key = f"signal {kind} {counter[0]}"
        counter[0] += 1
        return references.get(key, default)

    def rebuild(s: Signal) -> Signal:
        if isinstance(s, (Angle, Speed)):
            return type(s)(mapped("joint", s.joint))
        if isinstance(s, PID) and s is not owner:
            new = mapped("pid", s)
            return ControllerRef(new) if isinstance(new, str) else new
        if isinstance(s, ControllerRef) and (owner is None or s.name != owner.name):
            new = mapped("pid", s.name)
            return ControllerRef(new if isinstance(new, str) else new.name)
        if isinstance(s, _Combination):
            return _Combination(s.op, tuple(rebuild(a) for a in s.args))
        return s

    return [rebuild(s) for s in signals]
