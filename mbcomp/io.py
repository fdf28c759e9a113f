"""Declarative TOML model files: load (validated, every problem reported at once) and save.

A model file is data: it is parsed with ``tomllib`` and nothing in it is ever passed to
``eval``, ``exec`` or ``sympify``.  Where a number goes, a file may also write a string
holding a small arithmetic expression of ``[parameters]`` names (``"m*L**2/12"``); the
time-varying inputs (motor ``position``, ``force``, joint torque ``value``) may also use
the time ``t`` (``expressions.py`` parses and evaluates them).  The schema is documented
in ``docs/files.md``.
"""
from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10: the tomli backport has the same API
    import tomli as tomllib  # type: ignore[no-redef]

from .errors import ModelError
from .expressions import RESERVED, Expression, ExpressionError, TimeVector, evaluate, parse_expression  # noqa: F401 - re-exported
from .fileform import (BAD, Reader, close_match, component_table, floats, is_valid_name, read_component,
                       short, toml_key, toml_value, type_name)
from .library import find_library_model, library_dirs, library_models, read_description
from .model import Model

__all__ = ["load", "save", "dumps", "parse_expression", "Expression", "ExpressionError", "TimeVector",
           "library_dirs", "library_models", "find_library_model", "read_description"]

# ----------------------------------------------------------------------------------------------
# Schema
# ----------------------------------------------------------------------------------------------
TOP_KEYS = ("name", "description", "gravity", "parameters", "bodies", "joints", "forces", "constraints",
            "contacts", "initial", "simulation")
SIMULATION_KEYS = ("t_end", "method", "rtol", "atol", "formulation", "n_samples")
METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
FORMULATIONS = ("lagrange", "dae")

# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------
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
    """Read a TOML model file into a ``Model`` (schema: docs/files.md).

    Every problem (unknown or missing key, wrong type, wrong vector length, non-finite
    number, reference to an undeclared body or joint, disallowed expression, TOML syntax)
    is collected and reported in one ``ModelError``, each with the file, table and key:
    ``arm.toml [joints.elbow] axis: must be 'x', 'y', 'z' or a 3-vector, got 'w'``.

    The returned model also carries the file's extras as attributes: ``description``
    (str), ``named_parameters`` ({name: float}), ``initial`` (``{"q": {coord: value},
    "qd": {coord: value}}``), ``simulation`` (dict of the ``[simulation]`` settings) and
    ``path`` (the file read).
    """
    path = Path(path)
    label = str(path)
    data = _parse_toml(path, label)
    reader = Reader(label)
    model = _read_model(reader, data, path)
    if reader.problems:
        raise ModelError(problems=reader.problems)
    return model


def _read_model(r: Reader, data: dict, path: Path) -> Model:
    r.keys("", data, TOP_KEYS)

    name = data.get("name", path.stem or "model")
    if not isinstance(name, str) or not name.strip():
        r.problem(None, "name", f"must be a non-empty string, got {short(name)}")
        name = path.stem or "model"
    description = data.get("description", "")
    if not isinstance(description, str):
        r.problem(None, "description", f"must be a string, got {type_name(description)}")
        description = ""

    _read_parameters(r, data.get("parameters", {}))
    gravity = (0.0, 0.0, -9.81)
    if "gravity" in data:
        g = r.vector("", "gravity", data["gravity"])
        gravity = g if g is not BAD else gravity

    model = Model(name.strip() if isinstance(name, str) else "model", gravity=gravity)
    sections = {}
    for section in ("bodies", "joints", "forces", "constraints", "contacts", "initial", "simulation"):
        value = data.get(section, {})
        if not isinstance(value, dict):
            r.problem(None, section, f"must be a table ([{section}] or [{section}.NAME]), got {type_name(value)}")
            value = {}
        sections[section] = value

    used_names: dict[str, str] = {"ground": "the ground"}
    bodies: dict[str, Any] = {"ground": model.ground}
    joints: dict[str, Any] = {}

    def named_tables(section: str):
        """(name, table label, table) of a section's entries, checking names and types."""
        for comp_name, table in sections[section].items():
            label = f"{section}.{toml_key(comp_name)}"
            if not isinstance(table, dict):
                r.problem(None, f"{section}.{comp_name}",
                          f"must be a table [{section}.{comp_name}], got {type_name(table)}")
                continue
            if not is_valid_name(comp_name):
                r.problem(label, None, f"name {comp_name!r} may not contain '.', '[', ']' or edge spaces")
                continue
            if comp_name in used_names:
                r.problem(label, None, f"name {comp_name!r} is already used by {used_names[comp_name]}")
                continue
            used_names[comp_name] = f"[{label}]"
            yield comp_name, label, table

    for comp_name, label, table in named_tables("bodies"):
        body = read_component(r, "bodies", comp_name, label, table, bodies, joints)
        bodies[comp_name] = body if body is not None else comp_name
        if body is not None:
            model.add(body)

    coords_seen: dict[str, str] = {}
    all_joints_read = True
    for comp_name, label, table in named_tables("joints"):
        joint = read_component(r, "joints", comp_name, label, table, bodies, joints)
        joints[comp_name] = joint if joint is not None else comp_name
        if joint is None:
            all_joints_read = False
            continue
        for coord in joint.coords:
            if coord in coords_seen:
                r.problem(label, "coords", f"coordinate {coord!r} is already a coordinate of {coords_seen[coord]}")
            coords_seen[coord] = f"[{label}]"
        _add_component(r, model, joint, label)

    for section in ("forces", "constraints", "contacts"):
        for comp_name, label, table in named_tables(section):
            _add_component(r, model, read_component(r, section, comp_name, label, table, bodies, joints), label)

    model.description = description
    model.named_parameters = dict(r.parameters)
    # With a broken joint the coordinate names are incomplete: check the values only.
    model.initial = _read_initial(r, sections["initial"], coords_seen if all_joints_read else None)
    model.simulation = _read_simulation(r, sections["simulation"])
    model.path = path
    return model


def _add_component(r: Reader, model: Model, component: Any, label: str) -> None:
    if component is None:
        return
    try:
        model.add(component)
    except ModelError as exc:
        r.problem(label, None, str(exc))


def _read_parameters(r: Reader, table: Any) -> None:
    if not isinstance(table, dict):
        r.problem(None, "parameters", f"must be a table [parameters], got {type_name(table)}")
        return
    for key, value in table.items():
        if not key.isidentifier() or key in RESERVED:
            why = "is reserved" if key in RESERVED else "is not a valid name (letters, digits, _)"
            r.problem("parameters", key, f"{key!r} {why}")
            continue
        x = r.number("parameters", key, value)
        if x is not BAD:
            r.parameters[key] = x


def _read_initial(r: Reader, table: dict, coords: dict | None) -> dict:
    initial: dict[str, dict[str, float]] = {"q": {}, "qd": {}}
    r.keys("initial", table, ("q", "qd"))
    for which in ("q", "qd"):
        values = table.get(which, {})
        label = f"initial.{which}"
        if not isinstance(values, dict):
            r.problem("initial", which, "must be a table of coordinate values ({ name = value, ... }), "
                      f"got {type_name(values)}")
            continue
        for coord, value in values.items():
            if coords is not None and coord not in coords:
                hint = close_match(coord, tuple(coords))
                r.problem(label, coord, "unknown coordinate" + (f" (did you mean {hint!r}?)" if hint else "")
                          + f"; coordinates: {', '.join(coords) or 'none'}")
                continue
            x = r.number(label, coord, value)
            if x is not BAD:
                initial[which][coord] = x
    return initial


def _read_simulation(r: Reader, table: dict) -> dict:
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
                x = r.problem("simulation", key, f"must be an integer >= 2, got {short(value)}")
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
def dumps(model: Model) -> str:
    """The TOML text of ``model`` (see ``save``)."""
    lines = ["# mbcomp model file (schema: docs/files.md)"]
    description = getattr(model, "description", "")
    if description:
        lines.append(f"description = {toml_value(description)}")
    lines.append(f"name = {toml_value(model.name)}")
    lines.append(f"gravity = {toml_value(floats(model.gravity))}")
    parameters = getattr(model, "named_parameters", None) or {}
    if parameters:
        lines += ["", "[parameters]"] + [f"{toml_key(k)} = {toml_value(float(v))}" for k, v in parameters.items()]
    sections: dict[str, list[tuple[str, dict]]] = {}
    for comp in model.components.values():
        if comp is model.ground:
            continue
        section, table = component_table(comp)
        sections.setdefault(section, []).append((comp.name, table))
    for section in ("bodies", "joints", "forces", "constraints", "contacts"):
        for name, table in sections.get(section, []):
            lines += ["", f"[{section}.{toml_key(name)}]"]
            lines += [f"{toml_key(k)} = {toml_value(v)}" for k, v in table.items()]
    initial = getattr(model, "initial", None) or {}
    for which in ("q", "qd"):
        values = initial.get(which) or {}
        if values:
            lines += ["", f"[initial.{which}]"] + [f"{toml_key(k)} = {toml_value(float(v))}"
                                                   for k, v in values.items()]
    simulation = getattr(model, "simulation", None) or {}
    if simulation:
        lines += ["", "[simulation]"] + [f"{toml_key(k)} = {toml_value(v)}" for k, v in simulation.items()]
    return "\n".join(lines) + "\n"


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
