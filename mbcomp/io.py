"""Declarative TOML model files: load (validated, every problem reported at once) and save.

A model file is data: it is parsed with ``tomllib`` and nothing in it is ever passed to
``eval``, ``exec`` or ``sympify``.  Where a number goes, a file may also write a string
holding a small arithmetic expression of ``[parameters]`` names (``"m*L**2/12"``); the
time-varying inputs (motor ``position``, ``force``, joint torque ``value``) may also use
the time ``t`` (``expressions.py`` parses and evaluates them).  The schema is documented
in ``docs/files.md``.
"""
from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Any, Callable

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10: the tomli backport has the same API
    import tomli as tomllib  # type: ignore[no-redef]

import numpy as np

from .components import (Ball, Body, Contact, Cylindrical, Damper, Fixed, Force, Free, JointTorque, Motor, Planar,
                         Prismatic, Revolute, Slider, Spherical, Spring, TorsionSpring, Universal)
from .components._values import name_of
from .errors import ModelError
from .expressions import RESERVED, Expression, ExpressionError, TimeVector, evaluate, parse_expression, uses_t
from .library import find_library_model, find_library_part, library_dirs, library_models, library_parts, read_description
from .model import Model
from .compose import FileSubmodel, Parameter, Submodel, copy_component, PORT_REQUIRED as _PORT_REQUIRED
from .components.frame import Frame, rotation_matrix

__all__ = ["load", "save", "dumps", "parse_expression", "Expression", "ExpressionError", "TimeVector",
           "library_dirs", "library_models", "find_library_model", "read_description"]

# ----------------------------------------------------------------------------------------------
# Schema
# ----------------------------------------------------------------------------------------------
TOP_KEYS = ("name", "description", "gravity", "parameters", "ports", "submodels", "bodies", "joints", "forces",
            "constraints", "contacts", "initial", "simulation")
PART_SECTIONS = ("bodies", "joints", "forces", "constraints", "contacts")
BODY_KEYS = ("mass", "com", "inertia")
JOINT_COMMON = ("type", "parent", "child", "parent_point", "child_point", "parent_rotation", "child_rotation",
                "coords")
JOINT_KEYS = {"revolute": JOINT_COMMON + ("axis",), "prismatic": JOINT_COMMON + ("axis",),
              "spherical": JOINT_COMMON + ("sequence",), "ball": JOINT_COMMON + ("speeds",),
              "free": JOINT_COMMON + ("speeds",), "universal": JOINT_COMMON + ("axes",),
              "cylindrical": JOINT_COMMON + ("axis",), "planar": JOINT_COMMON + ("normal",),
              "fixed": ("type", "parent", "child", "parent_point",
                                                                    "child_point", "parent_rotation",
                                                                    "child_rotation")}
FORCE_KEYS = {"spring": ("type", "a", "b", "stiffness", "rest_length", "damping"),
              "damper": ("type", "a", "b", "damping"),
              "force": ("type", "body", "point", "force"),
              "joint_torque": ("type", "joint", "value"),
              "torsion_spring": ("type", "joint", "stiffness", "rest", "damping")}
CONSTRAINT_KEYS = {"slider": ("type", "body", "point", "origin", "axis"),
                   "motor": ("type", "joint", "speed", "position")}
CONTACT_KEYS = ("body", "point", "normal", "origin", "restitution")
SIMULATION_KEYS = ("t_end", "method", "rtol", "atol", "formulation", "n_samples")
METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
FORMULATIONS = ("lagrange", "dae")
ZERO3 = (0.0, 0.0, 0.0)

# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------
class _Bad:
    """Marks a value that failed validation (its problem is already recorded)."""

    def __repr__(self) -> str:
        return "<invalid>"


BAD = _Bad()


def _type_name(value: Any) -> str:
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


def _is_valid_name(name: str) -> bool:
    return bool(name.strip()) and name == name.strip() and not any(ch in name for ch in ".[]")


class _Reader:
    """Validates one parsed file and collects every problem with its location."""

    def __init__(self, label: str):
        self.label = label
        self.speeds_seen: dict[str, str] = {}  # speeds that are not a coordinate's rate (a ball's)
        self.problems: list[str] = []
        self.parameters: dict[str, float] = {}
        self.ports: set[str] = set()   # names bound to Frames by the user of a sub-model file

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
                hint = _close_match(key, allowed)
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
            return self.problem(table, key, f"must be {what}, got {_type_name(value)} ({_short(value)})")
        if isinstance(value, str):
            try:
                node = parse_expression(value, self.parameters, allow_t=time)
            except ExpressionError as exc:
                return self.problem(table, key, str(exc))
            if time and uses_t(node):
                expr = Expression(value, node, owner or f"[{table}] {key}")
                try:
                    check = evaluate(node, 0.0)
                except (ArithmeticError, ValueError) as exc:
                    return self.problem(table, key, f"{value!r} cannot be evaluated at t = 0 ({exc})")
                if not math.isfinite(check):
                    return self.problem(table, key, f"{value!r} is not finite at t = 0")
                return expr
            try:
                x = evaluate(node)
            except (ArithmeticError, ValueError) as exc:
                return self.problem(table, key, f"{value!r} cannot be evaluated ({exc})")
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
            return self.problem(table, key, f"must be a 3-vector [x, y, z], got {_type_name(value)} ({_short(value)})")
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
            return self.problem(table, key, f"{message}, got {value!r}")
        if not isinstance(value, list) or len(value) != 3:
            got = f"{len(value)} components" if isinstance(value, list) else f"{_type_name(value)} ({_short(value)})"
            return self.problem(table, key, f"{message}, got {got}")
        vec = self.vector(table, key, value)
        if vec is not BAD and math.sqrt(sum(v * v for v in vec)) < 1e-12:
            return self.problem(table, key, "has zero length")
        return vec

    def string(self, table: str | None, key: str, value: Any, choices: tuple | None = None) -> Any:
        if not isinstance(value, str):
            return self.problem(table, key, f"must be a string, got {_type_name(value)} ({_short(value)})")
        if choices is not None and value not in choices:
            return self.problem(table, key, f"must be one of {', '.join(repr(c) for c in choices)}, got {value!r}")
        return value

    def reference(self, table: str, key: str, value: Any, known: dict, kind: str) -> Any:
        """The name of a declared body (or ``"ground"``) or joint."""
        if not isinstance(value, str):
            return self.problem(table, key, f"must be the name of a {kind}, got {_type_name(value)} ({_short(value)})")
        if value not in known:
            names = ", ".join(known) or "none declared"
            hint = _close_match(value, tuple(known))
            plural = "bodies" if kind == "body" else kind + "s"
            return self.problem(table, key, f"unknown {kind} {value!r}" + (f" (did you mean {hint!r}?)" if hint else "")
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
            return self.problem(table, "inertia", f"must be 3 principal values or a 3x3 matrix, got {_type_name(value)}")
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
                            f"got {_type_name(value)} ({_short(value)})")


def _short(value: Any, width: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def _close_match(word: str, choices: tuple) -> str | None:
    import difflib
    found = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.6)
    return found[0] if found else None


def _parse_toml(path: Path, label: str) -> dict:
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ModelError(problems=[f"{label}: cannot read the file ({exc.strerror or exc})"]) from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ModelError(problems=[f"{label}:{line}: the file is not UTF-8 text"]) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)
        found = re.search(r"\(at line (\d+), column (\d+)\)", message)
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", message)
        message = re.sub(r"\s*\(at end of document\)", "", message)
        if found:
            where = f"{label}:{found.group(1)}:{found.group(2)}"
        else:
            where = f"{label}:{text.count(chr(10)) + 1}"
        raise ModelError(problems=[f"{where}: TOML syntax error: {message}"]) from None


def load(path: str | os.PathLike) -> Model:
    """Read a TOML model file into a ``Model`` (schema: docs/files.md and docs/composition.md).

    Every problem (unknown or missing key, wrong type, wrong vector length, non-finite
    number, reference to an undeclared body or joint, disallowed expression, TOML syntax)
    is collected and reported in one ``ModelError``, each with the file, table and key:
    ``arm.toml [joints.elbow] axis: must be 'x', 'y', 'z' or a 3-vector, got 'w'``.

    ``[submodels.NAME]`` tables instantiate other files (``use = "part.toml"``, beside or
    below this file, or ``"library:NAME"``) with port bindings and parameter overrides.
    A file read as a model on its own binds its ``"external"`` ports to the ground.

    The returned model also carries the file's extras as attributes: ``description``
    (str), ``named_parameters`` ({name: float}), ``initial`` (``{"q": {coord: value},
    "qd": {coord: value}}``), ``simulation`` (dict of the ``[simulation]`` settings) and
    ``path`` (the file read).
    """
    path = Path(path)
    label = str(path)
    data = _parse_toml(path, label)
    reader = _Reader(label)
    model = _read_model(reader, data, path)
    if reader.problems:
        raise ModelError(problems=reader.problems)
    return model


def _read_model(r: _Reader, data: dict, path: Path) -> Model:
    r.keys("", data, TOP_KEYS)

    name = data.get("name", path.stem or "model")
    if not isinstance(name, str) or not name.strip():
        r.problem(None, "name", f"must be a non-empty string, got {_short(name)}")
        name = path.stem or "model"
    description = data.get("description", "")
    if not isinstance(description, str):
        r.problem(None, "description", f"must be a string, got {_type_name(description)}")
        description = ""

    _read_parameters(r, data.get("parameters", {}))
    gravity = (0.0, 0.0, -9.81)
    if "gravity" in data:
        g = r.vector("", "gravity", data["gravity"])
        gravity = g if g is not BAD else gravity

    model = Model(name.strip() if isinstance(name, str) else "model", gravity=gravity)
    sections = _sections(r, data, ("initial", "simulation"))
    bodies: dict[str, Any] = {"ground": model.ground}
    external, exposed = _read_ports(r, data.get("ports", {}))
    for port in external:   # read on its own, a part hangs from the ground
        bodies[port] = model.ground
        r.ports.add(port)
    context = _FileContext(path, (path.resolve(),), {})
    coords_seen = _read_parts(r, data, model, bodies, context, exposed)

    model.description = description
    model.named_parameters = {k: float(v) for k, v in r.parameters.items()}
    # With a broken joint the coordinate names are incomplete: check the values only.
    model.initial = _read_initial(r, sections["initial"], coords_seen, r.speeds_seen)
    model.simulation = _read_simulation(r, sections["simulation"])
    model.path = path
    return model


def _sections(r: _Reader, data: dict, extra: tuple = ()) -> dict:
    sections = {}
    for section in PART_SECTIONS + ("submodels",) + extra:
        value = data.get(section, {})
        if not isinstance(value, dict):
            r.problem(None, section, f"must be a table ([{section}] or [{section}.NAME]), got {_type_name(value)}")
            value = {}
        sections[section] = value
    return sections


def _read_parts(r: _Reader, data: dict, target: Any, bodies: dict, context: "_FileContext",
                exposed: dict) -> dict | None:
    """Read bodies, sub-model instances, joints, forces, constraints and contacts into
    ``target`` (a Model or a sub-model instance being built); returns the coordinate names
    seen (``None`` when a joint could not be read) and sets the exposed ports on a sub-model."""
    sections = _sections(r, data)
    used_names: dict[str, str] = {"ground": "the ground"}
    used_names.update({port: "a port" for port in r.ports})
    joints: dict[str, Any] = {}

    def named_tables(section: str):
        """(name, table label, table) of a section's entries, checking names and types."""
        for comp_name, table in sections[section].items():
            label = f"{section}.{_toml_key(comp_name)}"
            if not isinstance(table, dict):
                r.problem(None, f"{section}.{comp_name}",
                          f"must be a table [{section}.{comp_name}], got {_type_name(table)}")
                continue
            if not _is_valid_name(comp_name):
                r.problem(label, None, f"name {comp_name!r} may not contain '.', '[', ']' or edge spaces")
                continue
            if comp_name in used_names:
                r.problem(label, None, f"name {comp_name!r} is already used by {used_names[comp_name]}")
                continue
            used_names[comp_name] = f"[{label}]"
            yield comp_name, label, table

    scope = getattr(target, "path", None) if not isinstance(target, Model) else None
    for comp_name, label, table in named_tables("bodies"):
        body = _read_body(r, comp_name, label, table)
        bodies[comp_name] = body if body is not None else comp_name
        if body is not None:
            target.add(body)
            if scope:
                bodies[f"{scope}.{comp_name}"] = body   # its full name, for inner parts

    def expose(ports: dict) -> None:
        for port, spec in ports.items():
            frame = _port_frame(r, port, spec, bodies)
            if frame is BAD:
                continue
            bodies[port] = frame
            r.ports.add(port)
            if not isinstance(target, Model):
                setattr(target, port, frame)

    # Ports on this file's own bodies first (sub-models may bind to them), the rest after.
    own = {p: s for p, s in exposed.items() if (s if isinstance(s, str) else s.get("body")) in bodies}
    expose(own)
    coords_seen: dict[str, str] = {}
    all_joints_read = True
    for comp_name, label, table in named_tables("submodels"):
        instance = _read_submodel(r, comp_name, label, table, bodies, context)
        if instance is None:
            all_joints_read = False
            continue
        try:
            target.add(instance)
        except ModelError as exc:
            r.problems.extend(p if p.startswith(r.label.split(" ")[0]) else f"{r.label} [{label}]: {p}"
                              for p in exc.problems)
            all_joints_read = False
            continue
        for key, value in vars(instance).items():
            if isinstance(value, Frame):
                for port in {f"{comp_name}.{key}", f"{instance.path}.{key}"}:
                    bodies[port] = value
                    r.ports.add(port)
        for full, member in _instance_bodies(instance, instance.path):
            bodies[full] = member
            r.ports.add(full)
        for full, member in _instance_joints(instance, comp_name):
            joints[full] = member
        for coord in _instance_coords(instance, comp_name):
            coords_seen[coord] = f"[{label}]"

    for comp_name, label, table in named_tables("joints"):
        joint = _read_joint(r, comp_name, label, table, bodies)
        joints[comp_name] = joint if joint is not None else comp_name
        if joint is None:
            all_joints_read = False
            continue
        for coord in joint.coords:
            if coord in coords_seen:
                r.problem(label, "coords", f"coordinate {coord!r} is already a coordinate of {coords_seen[coord]}")
            coords_seen[coord] = f"[{label}]"
        r.speeds_seen.update({speed: f"[{label}]" for speed in joint.speeds if speed not in joint.coords})
        _add_component(r, target, joint, label)

    for comp_name, label, table in named_tables("forces"):
        _add_component(r, target, _read_force(r, comp_name, label, table, bodies, joints), label)
    for comp_name, label, table in named_tables("constraints"):
        _add_component(r, target, _read_constraint(r, comp_name, label, table, bodies, joints), label)
    for comp_name, label, table in named_tables("contacts"):
        _add_component(r, target, _read_contact(r, comp_name, label, table, bodies), label)

    expose({p: s for p, s in exposed.items() if p not in own})
    return coords_seen if all_joints_read else None


def _instance_bodies(instance: Any, path: str) -> list:
    """``(path, body)`` of every body inside a sub-model instance (nested ones too)."""
    out = []
    for local, member in instance.members().items():
        if isinstance(member, Submodel):
            out += _instance_bodies(member, f"{path}.{local}")
        elif isinstance(member, Body):
            out.append((f"{path}.{local}", member))
    return out


def _instance_joints(instance: Any, path: str) -> list:
    """``(path, joint)`` of every joint inside a sub-model instance (nested ones too)."""
    out = []
    for local, member in instance.members().items():
        if isinstance(member, Submodel):
            out += _instance_joints(member, f"{path}.{local}")
        elif isinstance(member, (Revolute, Prismatic, Spherical, Fixed)):
            out.append((f"{path}.{local}", member))
    return out


def _instance_coords(instance: Any, path: str) -> list[str]:
    """The (prefixed) coordinate names of a sub-model instance, for [initial] checks."""
    out = []
    for local, member in instance.members().items():
        if isinstance(member, Submodel):
            out += _instance_coords(member, f"{path}.{local}")
        elif isinstance(member, (Revolute, Prismatic, Spherical, Fixed)):
            out += [f"{path}.{c}" for c in member.coords]
    return out


# -- ports and sub-models ----------------------------------------------------------------------
PORT_KEYS = ("body", "point", "rotation")


def _read_ports(r: _Reader, table: Any) -> tuple[list[str], dict]:
    """``[ports]``: ``NAME = "external"`` (bound by the user of the file) or an exposed
    frame ``NAME = {body = "...", point = [...], rotation = [[...]]}`` (or a body name)."""
    if not isinstance(table, dict):
        r.problem(None, "ports", f"must be a table [ports], got {_type_name(table)}")
        return [], {}
    external, exposed = [], {}
    for port, spec in table.items():
        if not _is_valid_name(port) or not port.isidentifier():
            r.problem("ports", port, f"{port!r} is not a valid port name (letters, digits, _)")
        elif spec == "external":
            external.append(port)
        elif isinstance(spec, (str, dict)):
            exposed[port] = spec
        else:
            r.problem("ports", port, f'must be "external", a body name or {{body = "...", point = [x, y, z]}}, '
                      f"got {_type_name(spec)} ({_short(spec)})")
    return external, exposed


def _port_frame(r: _Reader, port: str, spec: Any, bodies: dict) -> Any:
    """The Frame an exposed port stands for."""
    where = f"ports.{_toml_key(port)}"
    if isinstance(spec, str):
        body = r.reference("ports", port, spec, bodies, "body")
        return body if body is BAD or isinstance(body, Frame) else Frame(bodies.get(body, body))
    r.keys(where, spec, PORT_KEYS, ("body",))
    body = r.reference(where, "body", spec["body"], bodies, "body") if "body" in spec else BAD
    point = r.vector(where, "point", spec["point"]) if "point" in spec else ZERO3
    rotation = _read_rotation(r, where, "rotation", spec["rotation"]) if "rotation" in spec else None
    if BAD in (body, point) or rotation is BAD:
        return BAD
    if isinstance(body, Frame):
        return r.problem(where, "body", "must be a body of this file, not another port")
    try:
        return Frame(bodies.get(body, body), point, rotation)
    except ModelError as exc:
        return r.problem(where, None, str(exc))


class _FileContext:
    """Where a file is read from: its path, the chain of files including it (for cycles)
    and the sub-model classes made so far (one per file)."""

    def __init__(self, path: Path, chain: tuple, classes: dict):
        self.path, self.chain, self.classes = path, chain, classes


def _resolve_use(r: _Reader, label: str, use: Any, context: _FileContext) -> Path | None:
    if not isinstance(use, str) or not use.strip():
        r.problem(label, "use", f'must be a file name ("part.toml") or "library:NAME", got {_short(use)}')
        return None
    if use.startswith("library:"):
        found = find_library_part(use[len("library:"):])
        if found is None:
            r.problem(label, "use", f"no library part or model {use[len('library:'):]!r}; parts: "
                      f"{', '.join(library_parts())}; models: {', '.join(library_models())}")
        return found
    base = context.path.resolve().parent
    target = (base / use).resolve()
    if not target.is_relative_to(base):
        r.problem(label, "use", f"{use!r} leaves the directory of {context.path.name}: a file may use files "
                  "beside or below it, or library:NAME")
        return None
    if not target.is_file():
        r.problem(label, "use", f"file {use!r} not found beside {context.path.name}")
        return None
    return target


def _read_submodel(r: _Reader, name: str, label: str, table: dict, bodies: dict, context: _FileContext):
    """A sub-model instance from ``[submodels.NAME]``: ``use``, port bindings, parameter
    overrides (numbers or expressions of this file's parameters) and dicts of modifiers
    for the part's own sub-models."""
    if "use" not in table:
        if table and all(key in PART_SECTIONS + ("submodels",) for key in table):
            return _inline_class(r, label, table, bodies, context)(name)
        r.problem(label, "use", 'missing (required): the part file ("part.toml" or "library:NAME"), or the '
                  "part's own [bodies], [joints], ... tables")
        return None
    path = _resolve_use(r, label, table["use"], context)
    if path is None:
        return None
    resolved = path.resolve()
    if resolved in context.chain:
        cycle = " -> ".join(str(p) for p in context.chain[context.chain.index(resolved):] + (resolved,))
        r.problem(label, "use", f"files use each other in a cycle: {cycle}")
        return None
    cls = context.classes.get(resolved)
    if cls is None:
        try:
            cls = _part_class(path, _FileContext(path, context.chain + (resolved,), context.classes))
        except ModelError as exc:
            r.problems.extend(exc.problems)
            return None
        context.classes[resolved] = cls
    params, ports = cls.declared_parameters(), cls.port_names()
    modifiers: dict[str, Any] = {}
    ok = True
    for key, value in table.items():
        if key == "use":
            continue
        if key in ports:
            bound = r.reference(label, key, value, bodies, "body")
            if bound is BAD:
                ok = False
            else:
                modifiers[key] = bodies.get(bound, bound) if isinstance(bound, str) else bound
        elif key in params:
            x = r.number(label, key, value)
            ok = ok and x is not BAD
            modifiers[key] = x
        elif isinstance(value, dict):
            inner = {k: r.number(f"{label}.{key}", k, v) for k, v in value.items()}
            ok = ok and not any(v is BAD for v in inner.values())
            modifiers[key] = inner
        else:
            r.problem(label, key, f"unknown key; {path.name} has parameters {sorted(params)} and ports {sorted(ports)}")
            ok = False
    missing = [p for p in ports if p not in table]
    if missing:
        r.problem(label, None, f"port(s) {missing} of {path.name} are not bound")
        ok = False
    if not ok:
        return None
    try:
        return cls(name, **modifiers)
    except ModelError as exc:
        r.problem(label, None, str(exc))
        return None


def _part_class(path: Path, context: _FileContext) -> type:
    """A ``Submodel`` class for a part file: its [parameters] become Parameters (a number,
    or a table {value, unit, min, max, doc}), its external [ports] the ports of build."""
    label = str(path)
    data = _parse_toml(path, label)
    r = _Reader(label)
    r.keys("", data, TOP_KEYS)
    params_table = data.get("parameters", {})
    declared: dict[str, Any] = {}
    if not isinstance(params_table, dict):
        r.problem(None, "parameters", f"must be a table [parameters], got {_type_name(params_table)}")
        params_table = {}
    for key, value in params_table.items():
        if not key.isidentifier() or key in RESERVED:
            r.problem("parameters", key, f"{key!r} is not a valid parameter name")
            continue
        spec = value if isinstance(value, dict) else {"value": value}
        r.keys(f"parameters.{key}", spec, ("value", "unit", "min", "max", "doc"), ("value",))
        default = r.number("parameters", key, spec.get("value", BAD)) if "value" in spec else BAD
        if default is BAD:
            continue
        try:
            declared[key] = Parameter(float(default), unit=spec.get("unit"), min=spec.get("min"),
                                      max=spec.get("max"), doc=str(spec.get("doc", "")))
        except ModelError as exc:
            r.problem("parameters", key, str(exc))
    external, exposed = _read_ports(r, data.get("ports", {}))
    if r.problems:
        raise ModelError(problems=r.problems)
    name = data.get("name", path.stem)

    def port_names(cls) -> dict:
        return {p: _PORT_REQUIRED for p in external}

    def build(self, **ports: Any) -> None:
        reader = _Reader(label)
        reader.parameters = {key: getattr(self, key) for key in declared}
        reader.ports = set(ports)
        bodies: dict[str, Any] = {"ground": "ground", **ports}
        _read_parts(reader, data, self, bodies, context, exposed)
        if reader.problems:
            raise ModelError(problems=reader.problems)

    namespace = {**declared, "build": build, "port_names": classmethod(port_names),
                 "__doc__": data.get("description", f"Part read from {path.name}"), "source": path}
    return type(_class_name(name), (FileSubmodel,), namespace)


def _inline_class(r: _Reader, label: str, table: dict, bodies: dict, context: _FileContext) -> type:
    """A ``Submodel`` class for a part written inline (as ``save`` writes Python sub-models):
    its tables name their own components locally and anything else by its full path."""
    outer = dict(bodies)
    where = f"{r.label} {label}"

    def build(self) -> None:
        reader = _Reader(where)
        reader.parameters = dict(r.parameters)
        _read_parts(reader, table, self, dict(outer), context, {})
        if reader.problems:
            raise ModelError(problems=reader.problems)

    return type("InlinePart", (FileSubmodel,), {"build": build, "__doc__": f"Part written inline in {where}"})


def _class_name(name: Any) -> str:
    text = "".join(ch if ch.isalnum() else "_" for ch in str(name)) or "Part"
    return text if text[0].isalpha() else "Part_" + text


def _add_component(r: _Reader, model: Model, component: Any, label: str) -> None:
    if component is None:
        return
    try:
        model.add(component)
    except ModelError as exc:
        r.problem(label, None, str(exc))


def _construct(r: _Reader, label: str, factory: Callable, *args: Any, **kwargs: Any) -> Any:
    """Build a component; a ModelError from its own checks becomes a located problem."""
    try:
        return factory(*args, **kwargs)
    except ModelError as exc:
        r.problem(label, None, str(exc))
        return None


def _read_parameters(r: _Reader, table: Any) -> None:
    if not isinstance(table, dict):
        r.problem(None, "parameters", f"must be a table [parameters], got {_type_name(table)}")
        return
    for key, value in table.items():
        if not key.isidentifier() or key in RESERVED:
            why = "is reserved" if key in RESERVED else "is not a valid name (letters, digits, _)"
            r.problem("parameters", key, f"{key!r} {why}")
            continue
        if isinstance(value, dict):   # {value = ..., unit, min, max, doc} as part files declare them
            r.keys(f"parameters.{key}", value, ("value", "unit", "min", "max", "doc"), ("value",))
            value = value.get("value", BAD)
            if value is BAD:
                continue
        x = r.number("parameters", key, value)
        if x is not BAD:
            r.parameters[key] = x


def _read_body(r: _Reader, name: str, label: str, table: dict) -> Body | None:
    r.keys(label, table, BODY_KEYS, ("mass",))
    mass = r.number(label, "mass", table["mass"], positive=True) if "mass" in table else BAD
    com = r.vector(label, "com", table["com"]) if "com" in table else ZERO3
    inertia = r.inertia(label, table["inertia"]) if "inertia" in table else None
    if BAD in (mass, com) or inertia is BAD:
        return None
    return _construct(r, label, Body, name, mass=mass, com=com, inertia=inertia)


def _read_coords(r: _Reader, label: str, value: Any, count: int) -> Any:
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        return r.problem(label, "coords", f"must be a name or an array of {count} names, got {_short(value)}")
    if len(names) != count:
        return r.problem(label, "coords", f"must name {count} coordinate(s), got {len(names)}")
    for n in names:
        if not n.strip() or n != n.strip():
            return r.problem(label, "coords", f"{n!r} is not a valid coordinate name")
        if n in RESERVED:
            return r.problem(label, "coords", f"{n!r} is reserved (t, pi, sin, cos, exp, sqrt)")
    if len(set(names)) != len(names):
        return r.problem(label, "coords", f"repeats a name: {names}")
    return tuple(names)


def _read_joint(r: _Reader, name: str, label: str, table: dict, bodies: dict):
    kind = table.get("type")
    if kind is None:
        r.problem(label, "type", f"missing (required): one of {', '.join(JOINT_KEYS)}")
        return None
    if kind not in JOINT_KEYS:
        r.string(label, "type", kind, tuple(JOINT_KEYS))
        return None
    r.keys(label, table, JOINT_KEYS[kind],
           ("parent", "child") + (("axis",) if kind in ("revolute", "prismatic", "cylindrical") else ()))
    parent = r.reference(label, "parent", table["parent"], bodies, "body") if "parent" in table else BAD
    child = r.reference(label, "child", table["child"], bodies, "body") if "child" in table else BAD
    if child == "ground":
        child = r.problem(label, "child", "the ground cannot be a child (it does not move)")
    parent_point = r.vector(label, "parent_point", table["parent_point"]) if "parent_point" in table else ZERO3
    child_point = r.vector(label, "child_point", table["child_point"]) if "child_point" in table else ZERO3
    # A port (a Frame): the point is an offset in the port frame's axes.
    if isinstance(parent, Frame) and parent_point is not BAD:
        parent, parent_point = _offset_frame(parent, parent_point), None
    if isinstance(child, Frame) and child_point is not BAD:
        child, child_point = _offset_frame(child, child_point), None
    values = [parent, child, parent_point, child_point]
    options = {}
    if kind in ("revolute", "prismatic", "cylindrical"):
        axis = r.axis(label, "axis", table["axis"]) if "axis" in table else BAD
        values.append(axis)
        options["axis"] = axis
        count = 2 if kind == "cylindrical" else 1
    elif kind in ("ball", "free"):
        count = 4 if kind == "ball" else 7
        if "speeds" in table:
            speeds = table["speeds"]
            if not isinstance(speeds, list) or not all(isinstance(n, str) for n in speeds):
                speeds = r.problem(label, "speeds", f"must be a list of names, got {_short(speeds)}")
            values.append(speeds)
            options["speeds"] = speeds
    elif kind == "universal":
        axes = table.get("axes", ["x", "y"])
        if not isinstance(axes, list) or len(axes) != 2:
            axes = r.problem(label, "axes", f"must be two axes such as [\"x\", \"y\"], got {_short(axes)}")
        else:
            axes = tuple(r.axis(label, f"axes[{i}]", a) for i, a in enumerate(axes))
            axes = BAD if BAD in axes else axes
        values.append(axes)
        options["axes"] = axes
        count = 2
    elif kind == "planar":
        normal = r.axis(label, "normal", table["normal"]) if "normal" in table else "z"
        values.append(normal)
        options["normal"] = normal
        count = 3
    elif kind == "spherical":
        sequence = table.get("sequence", "xyz")
        if not isinstance(sequence, str) or not re.fullmatch(r"[xyz]{1,3}", sequence) or \
                any(a == b for a, b in zip(sequence, sequence[1:])):
            sequence = r.problem(label, "sequence", "must be 1 to 3 axes from x, y, z without consecutive repeats "
                                 f"(e.g. 'xy', 'xyz', 'zxz'), got {_short(sequence)}")
            count = None
        else:
            count = len(sequence)
        values.append(sequence)
        options["sequence"] = sequence
    else:
        count = 0
    if "coords" in table and count is not None:
        coords = _read_coords(r, label, table["coords"], count)
        values.append(coords)
        options["coords"] = coords
    if any(v is BAD for v in values) or count is None:
        return None
    factory = {"revolute": Revolute, "prismatic": Prismatic, "spherical": Spherical, "fixed": Fixed, "ball": Ball,
               "free": Free, "universal": Universal, "cylindrical": Cylindrical, "planar": Planar}[kind]
    rotations = {key: _read_rotation(r, label, key, table[key]) for key in ("parent_rotation", "child_rotation")
                 if key in table}
    if any(v is BAD for v in rotations.values()):
        return None
    if rotations:
        try:
            parent = _framed(parent, parent_point, rotations.get("parent_rotation"))
            child = _framed(child, child_point, rotations.get("child_rotation"))
        except ModelError as exc:
            r.problem(label, None, str(exc))
            return None
        return _construct(r, label, factory, name, parent, child, **options)
    return _construct(r, label, factory, name, parent, child, parent_point=parent_point,
                      child_point=child_point, **options)


def _framed(end: Any, point: Any, rotation: Any) -> Frame:
    """A joint end as a Frame: a body with a point and rotation, or a port Frame turned
    further by ``rotation`` (given in the port frame's axes)."""
    if isinstance(end, Frame):
        R = end.rotation_matrix if rotation is None else end.rotation_matrix @ np.asarray(rotation)
        return Frame(end.body, end.point, R)
    return Frame(end, ZERO3 if point is None else point, rotation)


def _offset_frame(frame: Frame, offset: tuple) -> Frame:
    """``frame`` moved by ``offset`` (given in the frame's own axes); expressions stay linked."""
    R = frame.rotation_matrix
    point = tuple(frame.point[i] + sum(float(R[i][j]) * offset[j] for j in range(3)) for i in range(3))
    return Frame(frame.body, point, frame.rotation)


def _read_rotation(r: _Reader, label: str, key: str, value: Any) -> Any:
    """A 3x3 rotation matrix given as three rows of three numbers (the joint frame's axes
    in the body frame)."""
    if not isinstance(value, list) or len(value) != 3 or not all(isinstance(row, list) and len(row) == 3
                                                                  for row in value):
        return r.problem(label, key, f"must be a 3x3 matrix [[...], [...], [...]], got {_short(value)}")
    rows = [r.vector(label, f"{key}[{i}]", row) for i, row in enumerate(value)]
    if any(row is BAD for row in rows):
        return BAD
    try:
        return rotation_matrix(rows, label, key)
    except ModelError as exc:
        return r.problem(label, key, str(exc))


def _time_input(r: _Reader, label: str, key: str, value: Any, owner: str, *, vector: bool) -> Any:
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


def _read_force(r: _Reader, name: str, label: str, table: dict, bodies: dict, joints: dict):
    kind = table.get("type")
    if kind is None:
        r.problem(label, "type", f"missing (required): one of {', '.join(FORCE_KEYS)}")
        return None
    if kind not in FORCE_KEYS:
        r.string(label, "type", kind, tuple(FORCE_KEYS))
        return None
    required = {"spring": ("a", "b", "stiffness"), "damper": ("a", "b", "damping"), "force": ("body", "force"),
                "joint_torque": ("joint", "value"), "torsion_spring": ("joint", "stiffness")}[kind]
    r.keys(label, table, FORCE_KEYS[kind], required)
    owner = f"{kind} {name!r}"
    got = lambda key, read, default=BAD: read(table[key]) if key in table else default  # noqa: E731
    if kind in ("spring", "damper"):
        a = got("a", lambda v: r.attachment(label, "a", v, bodies))
        b = got("b", lambda v: r.attachment(label, "b", v, bodies))
        damping = got("damping", lambda v: r.number(label, "damping", v, nonnegative=True),
                      0.0 if kind == "spring" else BAD)
        if kind == "damper":
            if BAD in (a, b, damping):
                return None
            return _construct(r, label, Damper, name, a=a, b=b, damping=damping)
        stiffness = got("stiffness", lambda v: r.number(label, "stiffness", v, nonnegative=True))
        rest = got("rest_length", lambda v: r.number(label, "rest_length", v, nonnegative=True), 0.0)
        if BAD in (a, b, damping, stiffness, rest):
            return None
        return _construct(r, label, Spring, name, a=a, b=b, stiffness=stiffness, rest_length=rest, damping=damping)
    if kind == "force":
        body = got("body", lambda v: r.reference(label, "body", v, bodies, "body"))
        point = got("point", lambda v: r.vector(label, "point", v), ZERO3)
        force = got("force", lambda v: _time_input(r, label, "force", v, owner, vector=True))
        if BAD in (body, point) or force is BAD:
            return None
        return _construct(r, label, Force, name, body, point=point, force=force)
    joint = got("joint", lambda v: r.reference(label, "joint", v, joints, "joint"))
    if kind == "joint_torque":
        value = got("value", lambda v: _time_input(r, label, "value", v, owner, vector=False))
        if joint is BAD or value is BAD:
            return None
        size = len(value) if isinstance(value, (tuple, TimeVector)) else 1
        n_coords = _coordinate_count(joints.get(joint))
        n_speeds = getattr(joints.get(joint), "nv", n_coords)
        if n_coords is not None and size != n_speeds:
            noun = "coordinate(s)" if n_speeds == n_coords else "speed(s)"
            r.problem(label, "value", f"has {size} entr{'y' if size == 1 else 'ies'}, joint {joint!r} has "
                      f"{n_speeds} {noun}")
            return None
        return _construct(r, label, JointTorque, name, joint, value=value)
    joint = _one_dof(r, label, joint, joints, "a torsion spring")
    stiffness = got("stiffness", lambda v: r.number(label, "stiffness", v, nonnegative=True))
    rest = got("rest", lambda v: r.number(label, "rest", v), 0.0)
    damping = got("damping", lambda v: r.number(label, "damping", v, nonnegative=True), 0.0)
    if BAD in (joint, stiffness, rest, damping):
        return None
    return _construct(r, label, TorsionSpring, name, joint, stiffness=stiffness, rest=rest, damping=damping)


def _coordinate_count(joint: Any) -> int | None:
    """Coordinates of a joint read from the file (None when it failed to read)."""
    return joint.n_coords if hasattr(joint, "n_coords") else None


def _one_dof(r: _Reader, label: str, joint: Any, joints: dict, what: str) -> Any:
    """``joint`` unless it is known to have other than one coordinate."""
    if joint is BAD:
        return BAD
    n_coords = _coordinate_count(joints.get(joint))
    if n_coords is not None and n_coords != 1:
        kind = type(joints[joint]).__name__.lower()
        return r.problem(label, "joint", f"{what} needs a 1-DOF joint; {joint!r} is a {kind} joint with "
                         f"{n_coords} coordinate(s)")
    return joint


def _read_constraint(r: _Reader, name: str, label: str, table: dict, bodies: dict, joints: dict):
    kind = table.get("type")
    if kind is None:
        r.problem(label, "type", f"missing (required): one of {', '.join(CONSTRAINT_KEYS)}")
        return None
    if kind not in CONSTRAINT_KEYS:
        r.string(label, "type", kind, tuple(CONSTRAINT_KEYS))
        return None
    if kind == "slider":
        r.keys(label, table, CONSTRAINT_KEYS[kind], ("body", "axis"))
        body = r.reference(label, "body", table["body"], bodies, "body") if "body" in table else BAD
        point = r.vector(label, "point", table["point"]) if "point" in table else ZERO3
        origin = r.vector(label, "origin", table["origin"]) if "origin" in table else ZERO3
        axis = r.axis(label, "axis", table["axis"]) if "axis" in table else BAD
        if BAD in (body, point, origin, axis):
            return None
        return _construct(r, label, Slider, name, body, point=point, origin=origin, axis=axis)
    r.keys(label, table, CONSTRAINT_KEYS[kind], ("joint",))
    joint = r.reference(label, "joint", table["joint"], joints, "joint") if "joint" in table else BAD
    joint = _one_dof(r, label, joint, joints, "a motor")
    if ("speed" in table) == ("position" in table):
        r.problem(label, None, "a motor needs exactly one of speed (rad/s or m/s) or position (an expression of t)")
        return None
    if "speed" in table:
        speed = r.number(label, "speed", table["speed"])
        if BAD in (joint, speed):
            return None
        return _construct(r, label, Motor, name, joint, speed=speed)
    value = table["position"]
    position = r.number(label, "position", value, time=True, owner=f"motor {name!r}")
    if position is BAD or joint is BAD:
        return None
    if not isinstance(position, Expression):  # a constant position: hold the joint there
        text = value if isinstance(value, str) else repr(float(value))
        position = Expression(text, ("num", float(position)), f"motor {name!r}")
    return _construct(r, label, Motor, name, joint, position=position)


def _read_contact(r: _Reader, name: str, label: str, table: dict, bodies: dict):
    r.keys(label, table, CONTACT_KEYS, ("body", "normal"))
    body = r.reference(label, "body", table["body"], bodies, "body") if "body" in table else BAD
    point = r.vector(label, "point", table["point"]) if "point" in table else ZERO3
    normal = r.axis(label, "normal", table["normal"]) if "normal" in table else BAD
    origin = r.vector(label, "origin", table["origin"]) if "origin" in table else ZERO3
    restitution = (r.number(label, "restitution", table["restitution"], low=0.0, high=1.0)
                   if "restitution" in table else 0.0)
    if BAD in (body, point, normal, origin, restitution):
        return None
    if isinstance(normal, str):
        from .rotations import unit_axis
        normal = unit_axis(normal)
    return _construct(r, label, Contact, name, body, point=point, normal=normal, origin=origin,
                      restitution=restitution)


def _read_initial(r: _Reader, table: dict, coords: dict | None, speeds: dict | None = None) -> dict:
    initial: dict[str, dict[str, float]] = {"q": {}, "qd": {}}
    r.keys("initial", table, ("q", "qd"))
    known = coords
    for which in ("q", "qd"):
        coords = known if which == "q" or known is None else {**known, **(speeds or {})}
        values = table.get(which, {})
        label = f"initial.{which}"
        if not isinstance(values, dict):
            r.problem("initial", which, "must be a table of coordinate values ({ name = value, ... }), "
                      f"got {_type_name(values)}")
            continue
        for coord, value in values.items():
            if coords is not None and coord not in coords:
                hint = _close_match(coord, tuple(coords))
                r.problem(label, coord, "unknown coordinate" + (f" (did you mean {hint!r}?)" if hint else "")
                          + f"; coordinates: {', '.join(coords) or 'none'}")
                continue
            x = r.number(label, coord, value)
            if x is not BAD:
                initial[which][coord] = x
    return initial


def _read_simulation(r: _Reader, table: dict) -> dict:
    r.keys("simulation", table, SIMULATION_KEYS)
    out: dict[str, Any] = {}
    for key, value in table.items():  # in file order
        if key in ("t_end", "rtol", "atol"):
            x = r.number("simulation", key, value, positive=True)
        elif key == "method":
            x = r.string("simulation", key, value, METHODS)
        elif key == "formulation":
            x = r.string("simulation", key, value, FORMULATIONS)
        elif key == "n_samples":
            if isinstance(value, bool) or not isinstance(value, int) or value < 2:
                x = r.problem("simulation", key, f"must be an integer >= 2, got {_short(value)}")
            else:
                x = value
        else:
            continue  # reported as an unknown key
        if x is not BAD:
            out[key] = x
    return out


# ----------------------------------------------------------------------------------------------
# Writing
# ----------------------------------------------------------------------------------------------
_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _toml_key(key: str) -> str:
    return key if _BARE_KEY.match(key) else json.dumps(key, ensure_ascii=False)


def _toml_value(value: Any) -> str:
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
        return _toml_value(float(value))
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # JSON string escapes are valid TOML basic strings
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} as TOML")


def _axis_value(axis: tuple) -> Any:
    for name, unit in (("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0)), ("z", (0.0, 0.0, 1.0))):
        if tuple(axis) == unit:
            return name
        if tuple(axis) == tuple(-c + 0.0 for c in unit):
            return "-" + name
    return [float(c) for c in axis]


def _floats(values: Any) -> list[float]:
    return [float(v) for v in values]


def _input_value(value: Any, owner: str, key: str) -> Any:
    """What to write for a constant or a file-born time input; a Python callable cannot be written."""
    if isinstance(value, TimeVector):
        return [v if isinstance(v, str) else float(v) for v in value.source]
    if isinstance(value, Expression):
        return value.source
    if callable(value):
        raise ModelError(owner, f"{key} is a Python callable and cannot be written to a file "
                         "(files take numbers or expressions of t)")
    if isinstance(value, (tuple, list)):
        return _floats(value)
    return float(value)


def _component_table(comp: Any) -> tuple[str, dict]:
    """(section, {key: value}) describing a component as the file schema does."""
    if isinstance(comp, Body):
        table: dict[str, Any] = {"mass": comp.mass, "com": _floats(comp.com)}
        if comp.inertia is not None:
            if len(comp.inertia) == 3:
                table["inertia"] = _floats(comp.inertia)
            else:
                table["inertia"] = [_floats(row) for row in comp.inertia_matrix()]
        return "bodies", table
    if isinstance(comp, (Revolute, Prismatic, Spherical, Fixed, Ball, Free, Universal, Cylindrical, Planar)):
        kind = {Revolute: "revolute", Prismatic: "prismatic", Spherical: "spherical", Fixed: "fixed", Ball: "ball",
                Free: "free", Universal: "universal", Cylindrical: "cylindrical", Planar: "planar"}[type(comp)]
        table = {"type": kind, "parent": name_of(comp.parent), "child": name_of(comp.child)}
        if kind in ("revolute", "prismatic", "cylindrical"):
            table["axis"] = _axis_value(comp.axis)
        if kind == "spherical":
            table["sequence"] = comp.sequence
        if kind == "universal":
            table["axes"] = [_axis_value(a) for a in comp.axes]
        if kind == "planar":
            table["normal"] = _axis_value(comp.normal)
        if kind in ("ball", "free") and comp.speeds != comp.default_speeds:
            table["speeds"] = list(comp.speeds)
        if any(comp.parent_point):
            table["parent_point"] = _floats(comp.parent_point)
        if any(comp.child_point):
            table["child_point"] = _floats(comp.child_point)
        for key in ("parent_rotation", "child_rotation"):
            if getattr(comp, key, None) is not None:
                table[key] = [_floats(row) for row in getattr(comp, key)]
        if comp.n_coords:
            table["coords"] = comp.coords[0] if comp.n_coords == 1 else list(comp.coords)
        return "joints", table
    if isinstance(comp, (Spring, Damper)):
        kind = "spring" if isinstance(comp, Spring) else "damper"
        table = {"type": kind}
        for key, body, point in (("a", comp.body_a, comp.point_a), ("b", comp.body_b, comp.point_b)):
            table[key] = ({"body": name_of(body), "point": _floats(point)} if any(point) else name_of(body))
        if kind == "spring":
            table.update(stiffness=comp.stiffness, rest_length=comp.rest_length, damping=comp.damping)
        else:
            table["damping"] = comp.damping
        return "forces", table
    if isinstance(comp, Force):
        table = {"type": "force", "body": name_of(comp.body)}
        if any(comp.point):
            table["point"] = _floats(comp.point)
        table["force"] = _input_value(comp.force, f"Force {comp.name!r}", "force")
        return "forces", table
    if isinstance(comp, JointTorque):
        return "forces", {"type": "joint_torque", "joint": name_of(comp.joint),
                          "value": _input_value(comp.value, f"JointTorque {comp.name!r}", "value")}
    if isinstance(comp, TorsionSpring):
        return "forces", {"type": "torsion_spring", "joint": name_of(comp.joint), "stiffness": comp.stiffness,
                          "rest": comp.rest, "damping": comp.damping}
    if isinstance(comp, Slider):
        return "constraints", {"type": "slider", "body": name_of(comp.body), "point": _floats(comp.point),
                               "origin": _floats(comp.origin), "axis": _axis_value(comp.axis)}
    if isinstance(comp, Motor):
        table = {"type": "motor", "joint": name_of(comp.joint)}
        if comp.speed is not None:
            table["speed"] = comp.speed
        else:
            table["position"] = _input_value(comp.position, f"Motor {comp.name!r}", "position")
        return "constraints", table
    if isinstance(comp, Contact):
        return "contacts", {"body": name_of(comp.body), "point": _floats(comp.point),
                            "normal": _axis_value(comp.normal), "origin": _floats(comp.origin),
                            "restitution": comp.restitution}
    raise ModelError(comp, f"{type(comp).__name__} has no file representation and cannot be saved")


def dumps(model: Model) -> str:
    """The TOML text of ``model`` (see ``save``)."""
    lines = ["# mbcomp model file (schema: docs/files.md)"]
    description = getattr(model, "description", "")
    if description:
        lines.append(f"description = {_toml_value(description)}")
    lines.append(f"name = {_toml_value(model.name)}")
    lines.append(f"gravity = {_toml_value(_floats(model.gravity))}")
    parameters = getattr(model, "named_parameters", None) or {}
    if parameters:
        lines += ["", "[parameters]"] + [f"{_toml_key(k)} = {_toml_value(float(v))}" for k, v in parameters.items()]
    if model.registry is not None:
        lines += _part_lines(model, model.entries, "", "")
    else:
        lines += _section_lines([c for c in model.components.values() if c is not model.ground], "")
    initial = getattr(model, "initial", None) or {}
    for which in ("q", "qd"):
        values = initial.get(which) or {}
        if values:
            lines += ["", f"[initial.{which}]"] + [f"{_toml_key(k)} = {_toml_value(float(v))}"
                                                   for k, v in values.items()]
    simulation = getattr(model, "simulation", None) or {}
    if simulation:
        lines += ["", "[simulation]"] + [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in simulation.items()]
    return "\n".join(lines) + "\n"


def _section_lines(components: list, prefix: str) -> list[str]:
    """TOML tables of ``components`` under ``prefix`` (``""`` or ``"submodels.NAME."``)."""
    lines = []
    sections: dict[str, list[tuple[str, dict]]] = {}
    for comp in components:
        section, table = _component_table(comp)
        sections.setdefault(section, []).append((comp.name, table))
    for section in PART_SECTIONS:
        for name, table in sections.get(section, []):
            lines += ["", f"[{prefix}{section}.{_toml_key(name)}]"]
            lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items()]
    return lines


def _part_lines(model: Model, members: list, scope: str, prefix: str) -> list[str]:
    """A model with sub-model instances, nested as ``[submodels.NAME...]`` tables: each
    instance's components under their local names, references outside it by full path."""
    names = model.registry.names
    known = set(names.values())

    def written(ref: Any) -> Any:
        if isinstance(ref, str):
            full = f"{scope}.{ref}" if scope and f"{scope}.{ref}" in known else ref
        else:
            full = names.get(id(ref), getattr(ref, "name", ref))
        if scope and full.startswith(scope + ".") and "." not in full[len(scope) + 1:]:
            return full[len(scope) + 1:]
        return full

    components = [copy_component(c, c.name, {role: written(ref) for role, ref in c.references().items()})
                  for c in members if not isinstance(c, Submodel)]
    lines = _section_lines(components, prefix)
    for item in members:
        if isinstance(item, Submodel):
            head = f"{prefix}submodels.{_toml_key(item.name)}"
            lines += ["", f"# sub-model instance {item.path!r}, written with its values", f"[{head}]"]
            lines += _part_lines(model, list(item.members().values()), item.path, head + ".")
    return lines


def save(model: Model, path: str | os.PathLike) -> None:
    """Write ``model`` as a TOML model file that ``load`` reads back to the same model.

    Numbers are written in full precision (parameter expressions of the original file are
    written as their values); time expressions read from a file are written as their text,
    with the file's ``[parameters]``.  The extras ``description``, ``initial`` and
    ``simulation`` are written when the model has them.  Raises ``ModelError`` for what a
    file cannot hold (a Python callable as a force, torque or motor position).
    """
    text = dumps(model)
    Path(path).write_text(text, encoding="utf-8")
