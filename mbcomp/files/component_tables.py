"""The component tables of model files, read and written through the component registry.

Each component class declares its file form (``kind``, ``section``, ``file_keys``,
``file_required``, ``refs``, ``file_options`` and its ``params``; see
``mbcomp.spec.components.base.Component``).  ``read_component`` reads any registered kind:
references are resolved against the bodies and joints declared so far, numbers may be
``[parameters]`` expressions, every parameter goes through the one validator
(``mbcomp.core.params.validate``) and each problem is reported with its file, table and key.
``component_table`` writes any registered component back.  Adding a component type with a
file form is one class: nothing here changes.

A model file is data: nothing in it is ever passed to ``eval``, ``exec`` or ``sympify``.
"""
from __future__ import annotations

import json
import math
import re
from typing import Any

import numpy as np

from mbcomp.spec.components.base import Component, component_class, kinds_in
from mbcomp.spec.components.frame import Frame, rotation_matrix
from mbcomp.core.errors import ModelError, describe
from mbcomp.core.expressions import (RESERVED, Expression, ExpressionError, TimeVector, evaluate, names_in, parse_expression,
                          uses_t)
from mbcomp.core.params import ParameterError, ParameterSpec, axis_name, spd_inertia, unit_vector, validate
from mbcomp.spec.components.expr import Expr
from mbcomp.spec.shapes import shape_from_table, shape_table

__all__ = ["BAD", "Reader", "read_component", "component_table", "SECTIONS", "TYPED_SECTIONS", "toml_key",
           "toml_value", "axis_value", "type_name", "short", "close_match"]

ZERO3 = (0.0, 0.0, 0.0)


def name_of(ref: Any) -> str:
    """The name a reference stands for (a component or its name)."""
    return ref if isinstance(ref, str) else getattr(ref, "name", repr(ref))
SECTIONS = ("bodies", "joints", "forces", "constraints", "contacts")
#: Sections whose tables name their kind with a ``type`` key (the others hold one kind).
TYPED_SECTIONS = ("joints", "forces", "constraints")


class _Bad:
    """Marks a value that failed validation (its problem is already recorded)."""

    def __repr__(self) -> str:
        return "<invalid>"


BAD = _Bad()


def type_name(value: Any) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return f"an array of {len(value)}"
    if isinstance(value, dict):
        return "a table"
    return type(value).__name__


def is_valid_name(name: str) -> bool:
    return bool(name.strip()) and name == name.strip() and not any(ch in name for ch in ".[]")


class Reader:
    """Validates one parsed file and collects every problem with its location."""

    def __init__(self, label: str):
        self.label = label
        self.problems: list[str] = []
        self.parameters: dict[str, float] = {}
        self.ports: set[str] = set()   # names bound to Frames by the user of a sub-model file
        #: Sub-model instances that failed to read (their problems are recorded): a reference
        #: to one of their bodies or ports is not reported again.
        self.failed: set[str] = set()
        #: Model parameters (a file's top-level ``[parameters]``) whose values an expression
        #: of t compiled with its numbers (a motor position): ``{name: where}``.  A run-time
        #: change of one is refused (``Derivation.frozen``) rather than silently not reaching it.
        self.frozen: dict[str, str] = {}

    def freeze(self, value: Any, where: str) -> None:
        """Record the parameters that expressions in ``value`` read as compiled with their
        numbers at ``where`` (a run-time change of one is then refused, naming ``where``)."""
        if isinstance(value, Expr):
            for name in value.parameters():
                self.frozen.setdefault(name, where)
        elif isinstance(value, (list, tuple)):
            for item in value:
                self.freeze(item, where)

    # -- reporting ------------------------------------------------------------------------
    def problem(self, table: str | None, key: str | None, message: str) -> _Bad:
        where = self.label
        if table:
            where += f" [{table}]"
        if key:
            where += f" {key}"
        self.problems.append(f"{where}: {message}")
        return BAD

    def keys(self, table: str, data: dict, allowed: tuple, required: tuple = ()) -> None:
        """Unknown and missing keys of a table."""
        for key in data:
            if key not in allowed:
                hint = close_match(key, allowed)
                self.problem(table, key, "unknown key" + (f" (did you mean {hint!r}?)" if hint else "")
                             + f"; allowed: {', '.join(allowed)}")
        for key in required:
            if key not in data:
                self.problem(table, key, "missing (required)")

    # -- values -------------------------------------------------------------------------------
    def number(self, table: str, key: str, value: Any, *, time: bool = False, positive: bool = False,
               nonnegative: bool = False, low: float | None = None, high: float | None = None,
               owner: str = "") -> Any:
        """A finite float, or (``time=True`` and the text uses ``t``) an ``Expression``."""
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            what = "a number or an expression of t" if time else "a number or a parameter expression"
            return self.problem(table, key, f"must be {what}, got {type_name(value)} ({short(value)})")
        if isinstance(value, str):
            try:
                node = parse_expression(value, self.parameters, allow_t=time)
            except ExpressionError as exc:
                return self.problem(table, key, str(exc))
            if time and uses_t(node):
                used = names_in(parse_expression(value, self.parameters, allow_t=True, keep_names=True))
                model_level = {n for n in used if is_model_parameter(self.parameters[n])}
                frozen = sorted(n for n in used if n not in model_level and not isinstance(self.parameters[n], (int, float)))
                if model_level and not frozen:   # compiled with their numbers; a change is refused
                    for n in model_level:
                        self.frozen.setdefault(n, f"[{table}] {key} (an expression of t)")
                    node = parse_expression(value, {**self.parameters, **{n: float(self.parameters[n]) for n in model_level}},
                                            allow_t=True)
                if frozen:
                    return self.problem(table, key, f"the part's parameter(s) {', '.join(map(repr, frozen))} cannot "
                                        f"be used in an expression of t here: it would keep its build-time value "
                                        "while listed as a run-time parameter (drive torques, motor voltages and "
                                        "PID setpoints take them)")
                expr = Expression(value, node, owner or f"[{table}] {key}")
                try:
                    check = evaluate(node, 0.0)
                except (ArithmeticError, ValueError) as exc:
                    return self.problem(table, key, f"{short(value, 24)} cannot be evaluated at t = 0 ({exc})")
                if not math.isfinite(check):
                    return self.problem(table, key, f"{short(value, 24)} is not finite at t = 0")
                return expr
            if time:   # no t in it: a number, its parameters kept linked
                node = parse_expression(value, self.parameters, allow_t=False)
            try:
                x = evaluate(node)
            except (ArithmeticError, ValueError) as exc:
                return self.problem(table, key, f"{short(value, 24)} cannot be evaluated ({exc})")
        else:
            try:
                x = float(value)
            except OverflowError:
                return self.problem(table, key, f"{value} is too large")
        linked, x = x, float(x)   # a sub-model file's parameter expression keeps its link
        if not math.isfinite(x):
            return self.problem(table, key, f"must be finite, got {x}")
        if positive and x <= 0:
            return self.problem(table, key, f"must be positive, got {x:g}")
        if nonnegative and x < 0:
            return self.problem(table, key, f"must not be negative, got {x:g}")
        if (low is not None and x < low) or (high is not None and x > high):
            return self.problem(table, key, f"must lie in [{low:g}, {high:g}], got {x:g}")
        return linked

    def vector(self, table: str, key: str, value: Any, *, time: bool = False, owner: str = "") -> Any:
        """Three numbers (entries may be expressions)."""
        if not isinstance(value, list):
            return self.problem(table, key, f"must be a 3-vector [x, y, z], got {type_name(value)} ({short(value)})")
        if len(value) != 3:
            return self.problem(table, key, f"must have 3 components, got {len(value)}")
        out = [self.number(table, f"{key}[{i}]", v, time=time, owner=owner) for i, v in enumerate(value)]
        return BAD if any(v is BAD for v in out) else tuple(out)

    def axis(self, table: str, key: str, value: Any) -> Any:
        """``"x" | "y" | "z"`` (optionally ``"-x"``) or a non-zero 3-vector."""
        message = "must be 'x', 'y', 'z' or a 3-vector"
        if isinstance(value, str):
            if value.strip().lower().lstrip("+-") in ("x", "y", "z") and value.strip().count("-") <= 1:
                return value.strip().lower()
            return self.problem(table, key, f"{message}, got {short(value, 24)}")
        if not isinstance(value, list) or len(value) != 3:
            got = f"{len(value)} components" if isinstance(value, list) else f"{type_name(value)} ({short(value)})"
            return self.problem(table, key, f"{message}, got {got}")
        vec = self.vector(table, key, value)
        if vec is not BAD and math.sqrt(sum(v * v for v in vec)) < 1e-12:
            return self.problem(table, key, "has zero length")
        return vec

    def string(self, table: str | None, key: str, value: Any, choices: tuple | None = None) -> Any:
        if not isinstance(value, str):
            return self.problem(table, key, f"must be a string, got {type_name(value)} ({short(value)})")
        if choices is not None and value not in choices:
            return self.problem(table, key, f"must be one of {', '.join(repr(c) for c in choices)}, got {short(value, 24)}")
        return value

    def reference(self, table: str, key: str, value: Any, known: dict, kind: str) -> Any:
        """The name of a declared body (or ``"ground"``) or joint."""
        if not isinstance(value, str):
            return self.problem(table, key, f"must be the name of a {kind}, got {type_name(value)} ({short(value)})")
        if value not in known:
            if value.split(".")[0] in self.failed and self.problems:
                return BAD   # inside a sub-model that failed: its own problem says why
            names = ", ".join(known) or "none declared"
            hint = close_match(value, tuple(known))
            plural = "bodies" if kind == "body" else kind + "s"
            return self.problem(table, key, f"unknown {kind} {short(value, 24)}" + (f" (did you mean {hint!r}?)" if hint else "")
                                + f"; {plural}: {names}")
        if value in self.ports:   # a port: the Frame (or body) its user bound
            bound = known[value]
            if isinstance(bound, Frame) and bound.rotation is None and not any(float(c) for c in bound.point):
                return bound.body
            return bound
        return value

    def inertia(self, table: str, value: Any) -> Any:
        """3 principal values or a 3x3 matrix (rows)."""
        if isinstance(value, list) and value and all(isinstance(row, list) for row in value):
            if len(value) != 3 or any(len(row) != 3 for row in value):
                shape = f"{len(value)} rows of {'/'.join(str(len(r)) for r in value)}"
                return self.problem(table, "inertia", f"a matrix must be 3x3, got {shape}")
            rows = [self.vector(table, f"inertia[{i}]", row) for i, row in enumerate(value)]
            return BAD if any(r is BAD for r in rows) else [list(r) for r in rows]
        if isinstance(value, list) and len(value) != 3:
            return self.problem(table, "inertia", f"must be 3 principal values or a 3x3 matrix, got {len(value)} values")
        if not isinstance(value, list):
            return self.problem(table, "inertia", f"must be 3 principal values or a 3x3 matrix, got {type_name(value)}")
        return self.vector(table, "inertia", value)

    def attachment(self, table: str, key: str, value: Any, bodies: dict) -> Any:
        """``"body"`` or ``{body = "...", point = [x, y, z]}``."""
        if isinstance(value, str):
            body = self.reference(table, key, value, bodies, "body")
            return BAD if body is BAD else body if isinstance(body, Frame) else (body, ZERO3)
        if isinstance(value, dict):
            where = f"{table}.{key}"
            self.keys(where, value, ("body", "point"), ("body",))
            body = self.reference(where, "body", value["body"], bodies, "body") if "body" in value else BAD
            point = self.vector(where, "point", value["point"]) if "point" in value else ZERO3
            return BAD if BAD in (body, point) else (body, point)
        return self.problem(table, key, "must be a body name or {body = \"...\", point = [x, y, z]}, "
                            f"got {type_name(value)} ({short(value)})")


def short(value: Any, width: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def close_match(word: str, choices: tuple) -> str | None:
    import difflib
    found = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return found[0] if found else None


def read_rotation(r: Reader, label: str, key: str, value: Any) -> Any:
    """A 3x3 rotation matrix given as three rows of three numbers (the joint frame's axes
    in the body frame)."""
    if not isinstance(value, list) or len(value) != 3 or not all(isinstance(row, list) and len(row) == 3
                                                                  for row in value):
        return r.problem(label, key, f"must be a 3x3 matrix [[...], [...], [...]], got {short(value)}")
    rows = [r.vector(label, f"{key}[{i}]", row) for i, row in enumerate(value)]
    if any(row is BAD for row in rows):
        return BAD
    r.freeze(rows, f"[{label}] {key}")   # the code holds a joint frame's rotation as numbers
    try:
        return rotation_matrix(rows, label, key)
    except ModelError as exc:
        return r.problem(label, key, str(exc))


def is_model_parameter(value: Any) -> bool:
    """True for the expression standing for a model-level parameter (``Model.parameter``: a
    leaf named without a dot), as a file's top-level ``[parameters]`` are."""
    return isinstance(value, Expr) and value.op == "param" and "." not in value.args[0]


def read_time_input(r: Reader, label: str, key: str, value: Any, owner: str, *, vector: bool) -> Any:
    """A constant (number / 3-vector) or a ``TimeVector`` when an entry uses ``t``."""
    if vector:
        entries = r.vector(label, key, value, time=True, owner=owner)
        if entries is BAD:
            return BAD
        source = list(value)
    elif isinstance(value, list):
        if not value:
            return r.problem(label, key, "must not be empty")
        entries = [r.number(label, f"{key}[{i}]", v, time=True, owner=owner) for i, v in enumerate(value)]
        if any(e is BAD for e in entries):
            return BAD
        source = list(value)
    else:
        entry = r.number(label, key, value, time=True, owner=owner)
        if entry is BAD:
            return BAD
        entries, source = [entry], [value]
    if any(isinstance(e, Expression) for e in entries):
        return TimeVector(list(entries), source)
    if not vector and not isinstance(value, list):
        return entries[0]
    return tuple(entries)


_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key, ensure_ascii=False)


def toml_value(value: Any) -> str:
    """A TOML literal for the values this module writes (str, float, int, bool, lists)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"cannot write the non-finite number {value}")
        return repr(value)
    if isinstance(value, np.floating):
        return toml_value(float(value))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON string escapes are valid TOML basic strings
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} as TOML")


def axis_value(axis: tuple) -> Any:
    """What a file holds for a unit axis: ``"x"``, ``"-z"``, ... or the 3 numbers."""
    return axis_name(axis)


def floats(values: Any) -> list[float]:
    return [float(v) for v in values]


def input_value(value: Any, owner: str, key: str) -> Any:
    """What to write for a constant or a file-born time input; a Python callable cannot be written."""
    if isinstance(value, TimeVector):
        return [v if isinstance(v, str) else float(v) for v in value.source]
    if isinstance(value, Expression):
        return value.source
    if callable(value):
        raise ModelError(owner, f"{key} is a Python callable and cannot be written to a file "
                         "(files take numbers or expressions of t)")
    if isinstance(value, (tuple, list)):
        return floats(value)
    return float(value)




# ----------------------------------------------------------------------------------------------
# Reading a component table
# ----------------------------------------------------------------------------------------------
def section_kinds(section: str) -> dict[str, type]:
    """``{type: class}`` of the kinds a section holds (registration order)."""
    return kinds_in(section)


def read_component(r: Reader, section: str, name: str, label: str, table: dict, bodies: dict,
                   joints: dict) -> Component | None:
    """The component described by ``table`` (the file table ``[label]``), or ``None`` when
    it has problems (each recorded in ``r`` with its key).

    ``bodies`` and ``joints`` map the names declared so far to their components (or to
    the name when that component failed to read).
    """
    kinds = section_kinds(section)
    if section in TYPED_SECTIONS:
        kind = table.get("type")
        if kind is None:
            r.problem(label, "type", f"missing (required): one of {', '.join(kinds)}")
            return None
        cls = kinds.get(kind) if isinstance(kind, str) else None
        if cls is None:
            r.string(label, "type", kind, tuple(kinds))
            return None
        allowed = ("type",) + cls.file_keys
    else:
        (cls,) = kinds.values()
        allowed = cls.file_keys
    r.keys(label, table, allowed, cls.file_required)
    owner = f"{cls.kind} {name!r}"
    values: dict[str, Any] = {}
    failed = any(key not in table for key in cls.file_required)
    for key in cls.file_keys:
        if key not in table:
            continue
        value = _read_value(r, cls, label, key, table[key], owner, bodies, joints)
        if value is BAD:
            failed = True
        else:
            values[key] = value
    if failed:
        return None
    try:
        comp = cls.from_file(name, values)
    except ModelError as exc:
        key, detail = _locate(exc, cls)
        r.problem(label, key, detail)
        return None
    # Checks against what the references are (a torque's size, a motor's 1-DOF joint).
    known = {**bodies, **joints}
    resolved = {role: known.get(name_of(ref)) for role, ref in comp.references().items()}
    if all(isinstance(v, Component) for v in resolved.values()):
        problems = comp.check(resolved)
        for problem in problems:
            r.problem(label, *_locate(ModelError(comp, problem[len(describe(comp)) + 2:]
                                                 if problem.startswith(describe(comp) + ": ") else problem), cls))
        if problems:
            return None
    return comp


def _read_value(r: Reader, cls: type, label: str, key: str, value: Any, owner: str, bodies: dict,
                joints: dict) -> Any:
    """One key of a component table: a reference, a declared parameter or an option."""
    if cls.file_options.get(key) == "signal":  # drive inputs (components/signals.py)
        if isinstance(value, dict):
            return read_signal(r, label, key, value, joints)
        if isinstance(value, str) and _uses_time(r, value):
            return read_time_signal(r, label, key, value)
        if cls.spec(key) is None:
            return r.number(label, key, value, time=True, owner=owner)
    role = cls.refs.get(key)
    if role == "body":
        body = r.reference(label, key, value, bodies, "body")
        if key == "child" and body == "ground":
            return r.problem(label, key, "the ground cannot be a child (it does not move)")
        return body
    if role == "joint":
        return r.reference(label, key, value, joints, "joint")
    if role == "attachment":
        return r.attachment(label, key, value, bodies)
    if role == "component":  # a derived file form's reference (Component.refs): a body or a joint
        if isinstance(value, str) and value in joints and value not in bodies:
            return r.reference(label, key, value, joints, "joint")
        if isinstance(value, str) and value not in bodies:
            hint = close_match(value, tuple(bodies) + tuple(joints))
            return r.problem(label, key, f"unknown body or joint {value!r}" + (f" (did you mean {hint!r}?)" if hint else "")
                             + f"; bodies: {', '.join(bodies) or 'none declared'}; joints: {', '.join(joints) or 'none declared'}")
        return r.reference(label, key, value, bodies, "body")
    spec = cls.spec(key)
    if spec is not None:
        return read_parameter(r, spec, label, key, value, owner)
    option = cls.file_options.get(key)
    if option == "names":
        return read_names(r, label, key, value)
    if option == "string":
        return r.string(label, key, value)
    if option == "time":
        read = r.number(label, key, value, time=True, owner=owner)
        if read is BAD or isinstance(read, Expression):
            return read
        if not isinstance(read, (int, float)):   # linked to a part's parameters
            return r.problem(label, key, f"{value!r} uses the part's parameters: here it would keep its build-time "
                             "value while listed as a run-time parameter; write a number")
        text = value if isinstance(value, str) else repr(float(read))
        return Expression(text, ("num", float(read)), owner)  # a constant of t
    if option == "rotation":
        return read_rotation(r, label, key, value)
    if option == "shapes":  # display data: a shape table or a list of them
        return read_shapes(r, label, key, value)
    if option == "axis":  # "x", "-y" or a 3-vector
        return r.axis(label, key, value)
    if option == "axes":  # a list of axes ("x", "-y" or 3-vectors)
        if not isinstance(value, list) or not value:
            return r.problem(label, key, f"must be a list of axes, got {type_name(value)}")
        axes = [r.axis(label, f"{key}[{i}]", v) for i, v in enumerate(value)]
        return BAD if any(a is BAD for a in axes) else tuple(axes)
    raise TypeError(f"{cls.__name__}.file_keys names {key!r}, which is not a reference, parameter or option")


def _uses_time(r: Reader, text: str) -> bool:
    """True when ``text`` is an expression of t (False when it is not an expression at all:
    the number reader reports that)."""
    try:
        return uses_t(parse_expression(text, r.parameters, allow_t=True))
    except ExpressionError:
        return False


def read_time_signal(r: Reader, label: str, key: str, text: str) -> Any:
    """An expression of t feeding a drive, motor, PID or joint torque: a compiled
    ``TimeExpression`` whose parameter names are run-time parameters."""
    from mbcomp.spec.components.signals import TimeExpression
    try:
        used = names_in(parse_expression(text, r.parameters, allow_t=True, keep_names=True))
        # only the names it uses: a part's other parameters do not rebuild the component
        signal = TimeExpression(text, {n: r.parameters[n] for n in used})
        value = signal.at(0.0)
    except ExpressionError as exc:
        return r.problem(label, key, str(exc))
    except ModelError as exc:
        return r.problem(label, key, str(exc).split(": ", 1)[-1])
    except (ArithmeticError, ValueError) as exc:
        return r.problem(label, key, f"{text!r} cannot be evaluated at t = 0 ({exc})")
    if not math.isfinite(value):
        return r.problem(label, key, f"{text!r} is not finite at t = 0")
    return signal


def read_signal(r: Reader, label: str, key: str, value: dict, joints: dict) -> Any:
    """A signal table (``{type = "step", time = 0.2, after = 1.0}``, ``{type = "angle", joint =
    "elbow"}``, ``{type = "pid", name = "pid"}``, ...): its joints must be declared above; its
    numbers may be parameter expressions (``time = "step_time"``)."""
    from mbcomp.spec.components.signals import signal_from_table
    value = dict(value)
    for k, v in list(value.items()):
        if k not in ("type", "joint", "name") and isinstance(v, str):
            read = r.number(label, f"{key}.{k}", v)
            if read is BAD:
                return BAD
            value[k] = read
    try:
        signal = signal_from_table(value, f"[{label}] {key}")
    except ModelError as exc:
        return r.problem(label, key, str(exc).split(": ", 1)[-1])
    for s in signal.walk():
        for joint in s.joints():
            if r.reference(label, f"{key}.joint", joint, joints, "joint") is BAD:
                return BAD
    return signal


def read_shapes(r: Reader, label: str, key: str, value: Any) -> Any:
    """A body's shapes: one table (``{ type = "box", size = [...] }``) or a list of them."""
    tables = value if isinstance(value, list) else [value]
    shapes = []
    for i, table in enumerate(tables):
        where = key if not isinstance(value, list) else f"{key}[{i}]"
        try:
            shapes.append(shape_from_table(table, where))
        except ModelError as exc:
            return r.problem(label, where, str(exc).split(": ", 1)[-1])
    return tuple(shapes)


def read_parameter(r: Reader, spec: ParameterSpec, label: str, key: str, value: Any, owner: str = "") -> Any:
    """A declared parameter from a file: numbers or ``[parameters]`` expressions in the
    spec's shape, then the one validator; problems are located at ``[label] key``."""
    if spec.time_input:
        read = read_time_input(r, label, key, value, owner, vector=tuple(spec.shape) == (3,))
        if read is BAD or callable(read):
            return read
    elif spec.check is spd_inertia:
        read = r.inertia(label, value)
    elif spec.check is unit_vector:
        read = r.axis(label, key, value)
    elif tuple(spec.shape) == (3,):
        read = r.vector(label, key, value)
    elif tuple(spec.shape) == (-1,) and isinstance(value, list):
        entries = [r.number(label, f"{key}[{i}]", v) for i, v in enumerate(value)]
        read = BAD if any(e is BAD for e in entries) else tuple(entries)
    else:
        read = r.number(label, key, value)
    if read is BAD:
        return BAD
    try:
        validate(spec, read, owner)
    except ParameterError as exc:
        return r.problem(label, key, exc.detail)
    return read  # as read: a sub-model file's parameter expression keeps its link


def read_names(r: Reader, label: str, key: str, value: Any) -> Any:
    """A name or an array of names (coordinate names: not reserved expression words)."""
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        return r.problem(label, key, f"must be a name or an array of names, got {short(value)}")
    for n in names:
        if n in RESERVED:
            return r.problem(label, key, f"{n!r} is reserved (t, pi, sin, cos, exp, sqrt)")
    if len(set(names)) != len(names):
        return r.problem(label, key, f"repeats a name: {names}")
    return value if isinstance(value, str) else tuple(names)


def _locate(exc: ModelError, cls: type) -> tuple[str | None, str]:
    """``(file key, problem)`` of a constructor's error: the attribute it names, when that
    is one of the file keys, else ``(None, whole message)``."""
    if isinstance(exc, ParameterError) and exc.attribute in cls.file_keys:
        return exc.attribute, exc.detail
    text = str(exc)
    prefix = describe(exc.component) + ": " if exc.component is not None else ""
    detail = text[len(prefix):] if prefix and text.startswith(prefix) else text
    first = detail.split(" ", 1)
    if len(first) == 2 and first[0] in cls.file_keys:
        return first[0], first[1]
    return None, text


# ----------------------------------------------------------------------------------------------
# Writing a component table
# ----------------------------------------------------------------------------------------------
def component_table(comp: Component) -> tuple[str, dict]:
    """``(section, {key: value})`` describing ``comp`` as its file form declares."""
    cls = type(comp)
    if not cls.file_keys or component_class(cls.kind) is not cls:
        raise ModelError(comp, f"{cls.__name__} has no file representation and cannot be saved")
    table: dict[str, Any] = {"type": cls.kind} if cls.section in TYPED_SECTIONS else {}
    owner = describe(comp)
    for key in cls.file_keys:
        value = comp.file_value(key)
        if value is None:
            continue
        if isinstance(value, (dict, str)) and cls.file_options.get(key) == "signal":
            table[key] = value  # a signal's table or expression of t (components/signals.py)
            continue
        role = cls.refs.get(key)
        spec = cls.spec(key)
        if role == "attachment":
            body, point = value
            table[key] = {"body": name_of(body), "point": floats(point)} if any(point) else name_of(body)
        elif role is not None:
            if role == "component" and key not in comp.references():  # a derived file form's guess
                raise ModelError(comp, f"cannot be saved: its argument {key!r} is neither a declared parameter "
                                       "(ParameterSpec) nor one of its references(); declare file_keys and file_options")
            table[key] = name_of(value)
        elif spec is not None:
            written = _parameter_value(spec, value, owner, key)
            if key in cls.file_required or not _is_default(spec, value):
                table[key] = written
        else:
            option = cls.file_options.get(key)
            if option == "time":
                table[key] = input_value(value, owner, key)
            elif option == "rotation":
                table[key] = [floats(row) for row in value]
            elif option == "axes":
                table[key] = [axis_value(axis) for axis in value]
            elif option == "axis":
                table[key] = axis_value(value)
            elif option == "shapes":
                if value:
                    table[key] = [shape_table(shape) for shape in value]
            else:
                table[key] = value
    return cls.section, table


def _parameter_value(spec: ParameterSpec, value: Any, owner: str, key: str) -> Any:
    if spec.time_input:
        return input_value(value, owner, key)
    if spec.check is unit_vector:
        return axis_value(value)
    if spec.check is spd_inertia:
        if len(value) == 3:
            return floats(value)
        xx, yy, zz, xy, xz, yz = value
        return [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
    if isinstance(value, (tuple, list)):
        return floats(value)
    return float(value)


def _is_default(spec: ParameterSpec, value: Any) -> bool:
    """True when ``value`` equals the spec's default (it need not be written)."""
    if spec.default is None or callable(value) or not isinstance(spec.default, (int, float, tuple)):
        return False
    try:
        return bool(np.array_equal(np.asarray(value, dtype=float), np.asarray(spec.default, dtype=float)))
    except (TypeError, ValueError):
        return False
