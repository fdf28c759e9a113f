"""Declarative TOML model files: load (validated, every problem reported at once) and save.

A model file is data: it is parsed with ``tomllib`` and nothing in it is ever passed to
``eval``, ``exec`` or ``sympify``.  Where a number goes, a file may also write a string
holding a small arithmetic expression of ``[parameters]`` names (``"m*L**2/12"``); the
time-varying inputs (motor ``position``, ``force``, joint torque ``value``) may also use
the time ``t`` (``expressions.py`` parses and evaluates them).  The schema is documented
in ``docs/files.md``.
"""
from __future__ import annotations

import keyword
import os
import re
from pathlib import Path
from typing import Any

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10: the tomli backport has the same API
    import tomli as tomllib  # type: ignore[no-redef]

from mbcomp.spec.components import Body, Joint
from mbcomp.core.errors import ModelError
from mbcomp.core.expressions import RESERVED, Expression, ExpressionError, TimeVector, evaluate, parse_expression  # noqa: F401 - re-exported
from mbcomp.files.component_tables import (BAD, ZERO3, Reader, close_match, component_table, floats, is_valid_name, read_component,
                       read_rotation, short, toml_key, toml_value, type_name)
from mbcomp.files.library import (find_library_model, find_library_part, library_dirs, library_models, library_parts,
                      read_description, resolve_model_path)
from mbcomp.spec.model import Model
from mbcomp.files.library import LIBRARY_PREFIX, library_name_problem
from mbcomp.core.limits import INSTANCES, NESTING, max_instances, max_nesting, read_file
from mbcomp.spec.compose import FileSubmodel, Parameter, Submodel, copy_component, PORT_REQUIRED as _PORT_REQUIRED
from mbcomp.spec.components.frame import Frame
from mbcomp.spec.components.expr import Expr, map_exprs
import numpy as np
from mbcomp.files.component_tables import read_shapes
from mbcomp.spec.shapes import shape_table

__all__ = ["load", "save", "dumps", "parse_expression", "Expression", "ExpressionError", "TimeVector",
           "library_dirs", "library_models", "find_library_model", "read_description"]

# ----------------------------------------------------------------------------------------------
# Schema
# ----------------------------------------------------------------------------------------------
TOP_KEYS = ("name", "description", "gravity", "parameters", "ports", "submodels", "bodies", "joints", "forces",
            "constraints", "contacts", "initial", "simulation")
PART_SECTIONS = ("bodies", "joints", "forces", "constraints", "contacts")
SIMULATION_KEYS = ("t_end", "method", "rtol", "atol", "formulation", "n_samples")
METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
FORMULATIONS = ("lagrange", "dae")
MAX_SAMPLES = 10_000_000  # output samples a file may ask for (each holds q and qd)

# ----------------------------------------------------------------------------------------------
# Reading
# ----------------------------------------------------------------------------------------------
def _parse_toml(path: Path, label: str) -> dict:
    """The TOML data of a model file: a regular file of at most ``max_file_bytes()`` (a FIFO
    or a device is refused before it is read), UTF-8, valid TOML; else a ``ModelError``."""
    raw = read_file(path, label)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise ModelError(problems=[f"{label}:{line}: the file is not UTF-8 text"]) from None
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise ModelError(problems=[f"{label}: arrays or tables are nested too deeply to read"]) from None
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
    except ValueError:  # an integer too long to convert (Python reads at most 4300 digits)
        found = re.search(r"\d{4301,}", text)
        if found is None:
            raise ModelError(problems=[f"{label}: a value cannot be read"]) from None
        line_start = text.rfind("\n", 0, found.start()) + 1
        key = text[line_start:found.start()].split("=")[0].strip()
        line = text[: found.start()].count("\n") + 1
        raise ModelError(problems=[f"{label}:{line} {key}: an integer of {len(found.group(0))} digits is too long "
                                   "(at most 4300)"]) from None


def load(path: str | os.PathLike) -> Model:
    """Read a TOML model file into a ``Model`` (schema: docs/files.md and docs/composition.md).

    ``path`` is a file, or the name of a library model (``"double_pendulum"``, also
    ``"library:double_pendulum"``; see ``mbcomp library``); an existing file wins.

    Every problem (unknown or missing key, wrong type, wrong vector length, non-finite
    number, reference to an undeclared body or joint, disallowed expression, TOML syntax)
    is collected and reported in one ``ModelError``, each with the file, table and key:
    ``arm.toml [joints.elbow] axis: must be 'x', 'y', 'z' or a 3-vector, got 'w'``.

    ``[submodels.NAME]`` tables instantiate other files (``use = "part.toml"``, beside or
    below this file, or ``"library:NAME"``) with port bindings and parameter overrides.
    A file read as a model on its own binds its ``"external"`` ports to the ground.

    Only regular files within ``MBCOMP_MAX_FILE_BYTES`` are read (a FIFO or a device is
    refused unopened), and the sub-model instances the files would build, and how deeply
    they nest, are counted before anything is built (``mbcomp.core.limits``, docs/errors.md).

    The returned model also carries the file's extras as attributes: ``description``
    (str), ``named_parameters`` ({name: float}), ``initial`` (``{"q": {coord: value},
    "qd": {coord: value}}``), ``simulation`` (dict of the ``[simulation]`` settings) and
    ``path`` (the file read).
    """
    spec = os.fspath(path)
    path = resolve_model_path(path)
    label = str(path)
    if isinstance(spec, str) and spec.startswith(LIBRARY_PREFIX) and not path.exists():
        name = spec[len(LIBRARY_PREFIX):]
        problem = library_name_problem(name) or "is not a library model"
        raise ModelError(problems=[f"{short(spec)} {problem} "
                                   f"(library: {', '.join(library_models()) or 'none found'})"])
    if not path.exists() and "/" not in label and os.sep not in label and not label.endswith(".toml"):
        names = ", ".join(library_models()) or "none found"
        raise ModelError(problems=[f"{label}: cannot read the file (no such file), and no library model "
                                   f"of that name (library: {names})"])
    data = _parse_toml(path, label)
    reader = Reader(label)
    files = _Files(path, data)
    reader.frozen = files.frozen
    try:
        files.check_limits(label)   # before anything is built: milliseconds even for 2**29 instances
        model = _read_model(reader, data, path, files)
    except ModelError:
        raise
    except RecursionError:
        raise ModelError(problems=reader.problems + [f"{label}: values or sub-models are nested too deeply to "
                                                     f"read (sub-models nest at most {max_nesting()} deep; "
                                                     f"{NESTING[0]} sets it)"]) from None
    except (ArithmeticError, LookupError, TypeError, ValueError, OSError, MemoryError) as exc:
        # A safety net: a file is data, and no file may end in a raw exception.
        raise ModelError(problems=reader.problems + [f"{label}: cannot be read ({type(exc).__name__}: {exc})"]) from None
    if reader.problems:
        raise ModelError(problems=reader.problems)
    return model


def _read_model(r: Reader, data: dict, path: Path, files: "_Files") -> Model:
    r.keys("", data, TOP_KEYS + ("ground_shape",))   # shapes fixed to the ground: a model's own

    name = data.get("name", path.stem or "model")
    if not isinstance(name, str) or not name.strip():
        r.problem(None, "name", f"must be a non-empty string, got {short(name)}")
        name = path.stem or "model"
    description = data.get("description", "")
    if not isinstance(description, str):
        r.problem(None, "description", f"must be a string, got {type_name(description)}")
        description = ""

    name = name.strip() if isinstance(name, str) else "model"
    model = Model(name)
    _read_parameters(r, data.get("parameters", {}), model)
    if "gravity" in data:
        g = r.vector("", "gravity", data["gravity"])
        try:
            if g is not BAD:
                model.set_gravity(g)
        except ModelError as exc:   # e.g. a magnitude that would overflow: located at its key
            r.problem(None, "gravity", getattr(exc, "detail", str(exc)))
    sections = _sections(r, data, ("initial", "simulation"))
    bodies: dict[str, Any] = {"ground": model.ground}
    external, exposed = _read_ports(r, data.get("ports", {}))
    for port in external:   # read on its own, a part hangs from the ground
        bodies[port] = model.ground
        r.ports.add(port)
    context = _FileContext(path, (path.resolve(),), {}, files)
    coords_seen = _read_parts(r, data, model, bodies, context, exposed)

    if "ground_shape" in data:
        shapes = read_shapes(r, "", "ground_shape", data["ground_shape"])
        if shapes is not BAD:
            model.ground.shape = shapes
    model.description = description
    # the file's own [parameters] (instances' parameters, seen by their paths, are the System's)
    model.named_parameters = {k: float(v) for k, v in r.parameters.items() if "." not in k}
    model.frozen_parameters = dict(r.frozen)
    # With a broken joint the coordinate names are incomplete: check the values only.
    model.initial = _read_initial(r, sections["initial"], coords_seen, getattr(r, "speeds_seen", {}))
    model.simulation = _read_simulation(r, sections["simulation"])
    model.path = path
    return model


def _sections(r: Reader, data: dict, extra: tuple = ()) -> dict:
    sections = {}
    for section in PART_SECTIONS + ("submodels",) + extra:
        value = data.get(section, {})
        if not isinstance(value, dict):
            r.problem(None, section, f"must be a table ([{section}] or [{section}.NAME]), got {type_name(value)}")
            value = {}
        sections[section] = value
    return sections


def _read_parts(r: Reader, data: dict, target: Any, bodies: dict, context: "_FileContext",
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

    scope = getattr(target, "path", None) if not isinstance(target, Model) else None
    for comp_name, label, table in named_tables("bodies"):
        body = read_component(r, "bodies", comp_name, label, table, bodies, joints)
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
    own = {p: s for p, s in exposed.items() if _port_body(s) in bodies}
    expose(own)
    coords_seen: dict[str, str] = {}
    speeds_seen: dict[str, str] = {}  # speeds that are not a coordinate's rate (a ball's)
    all_joints_read = True
    for comp_name, label, table in named_tables("submodels"):
        _see_instance_parameters(r, target)
        instance = _read_submodel(r, comp_name, label, table, bodies, context)
        if instance is None:
            r.failed.add(comp_name)
            all_joints_read = False
            continue
        try:
            target.add(instance)
        except ModelError as exc:
            r.problems.extend(p if p.startswith(r.label.split(" ")[0]) else f"{r.label} [{label}]: {p}"
                              for p in exc.problems)
            r.failed.add(comp_name)
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

    _see_instance_parameters(r, target)
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
        speeds_seen.update({speed: f"[{label}]" for speed in joint.speeds if speed not in joint.coords})
        _add_component(r, target, joint, label)

    for comp_name, label, table in named_tables("forces"):
        _add_component(r, target, read_component(r, "forces", comp_name, label, table, bodies, joints), label)
    for comp_name, label, table in named_tables("constraints"):
        _add_component(r, target, read_component(r, "constraints", comp_name, label, table, bodies, joints), label)
    for comp_name, label, table in named_tables("contacts"):
        _add_component(r, target, read_component(r, "contacts", comp_name, label, table, bodies, joints), label)

    expose({p: s for p, s in exposed.items() if p not in own})
    r.speeds_seen = speeds_seen  # a ball's speeds, which [initial.qd] may name
    return coords_seen if all_joints_read else None


def _see_instance_parameters(r: Reader, target: Any) -> None:
    """Let expressions name the parameters of the sub-model instances built so far by their
    paths (``"upper.length"``): the values stay linked, so they follow a run-time change."""
    registry = target.registry if isinstance(target, Model) else getattr(target, "_registry", None)
    if registry is None:
        return
    for path, entry in registry.parameters.items():
        r.parameters.setdefault(path, Expr.parameter(path, entry.value))


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
        elif isinstance(member, Joint):
            out.append((f"{path}.{local}", member))
    return out


def _instance_coords(instance: Any, path: str) -> list[str]:
    """The (prefixed) coordinate names of a sub-model instance, for [initial] checks."""
    out = []
    for local, member in instance.members().items():
        if isinstance(member, Submodel):
            out += _instance_coords(member, f"{path}.{local}")
        elif isinstance(member, Joint):
            out += [f"{path}.{c}" for c in member.coords]
    return out


# -- ports and sub-models ----------------------------------------------------------------------
PORT_KEYS = ("body", "point", "rotation")


def _read_ports(r: Reader, table: Any) -> tuple[list[str], dict]:
    """``[ports]``: ``NAME = "external"`` (bound by the user of the file) or an exposed
    frame ``NAME = {body = "...", point = [...], rotation = [[...]]}`` (or a body name)."""
    if not isinstance(table, dict):
        r.problem(None, "ports", f"must be a table [ports], got {type_name(table)}")
        return [], {}
    external, exposed = [], {}
    for port, spec in table.items():
        if not is_valid_name(port) or not port.isidentifier():
            r.problem("ports", port, f"{port!r} is not a valid port name (letters, digits, _)")
        elif spec == "external":
            external.append(port)
        elif isinstance(spec, (str, dict)):
            exposed[port] = spec
        else:
            r.problem("ports", port, f'must be "external", a body name or {{body = "...", point = [x, y, z]}}, '
                      f"got {type_name(spec)} ({short(spec)})")
    return external, exposed


def _port_frame(r: Reader, port: str, spec: Any, bodies: dict) -> Any:
    """The Frame an exposed port stands for."""
    where = f"ports.{toml_key(port)}"
    if isinstance(spec, str):
        body = r.reference("ports", port, spec, bodies, "body")
        return body if body is BAD or isinstance(body, Frame) else Frame(bodies.get(body, body))
    r.keys(where, spec, PORT_KEYS, ("body",))
    body = r.reference(where, "body", spec["body"], bodies, "body") if "body" in spec else BAD
    point = r.vector(where, "point", spec["point"]) if "point" in spec else ZERO3
    rotation = read_rotation(r, where, "rotation", spec["rotation"]) if "rotation" in spec else None
    if BAD in (body, point) or rotation is BAD:
        return BAD
    if isinstance(body, Frame):
        return r.problem(where, "body", "must be a body of this file, not another port")
    try:
        return Frame(bodies.get(body, body), point, rotation)
    except ModelError as exc:
        return r.problem(where, None, str(exc))


class _FileContext:
    """Where a file is read from: its path, the chain of files including it (for cycles),
    the sub-model classes made so far (one per file) and the files of this load."""

    def __init__(self, path: Path, chain: tuple, classes: dict, files: "_Files"):
        self.path, self.chain, self.classes, self.files = path, chain, classes, files


def _port_body(spec: Any) -> str | None:
    """The body name an exposed port names (None when it names none)."""
    body = spec if isinstance(spec, str) else spec.get("body") if isinstance(spec, dict) else None
    return body if isinstance(body, str) else None


def _use_target(use: Any, path: Path, explain: bool = True) -> tuple[Path | None, str | None]:
    """``(file, None)`` that ``use = ...`` in the file ``path`` names, or ``(None, why not)``:
    a file beside or below ``path``, or ``library:NAME`` inside the library.  Nothing outside
    is ever read (``explain=False``: skip composing the message)."""
    if not isinstance(use, str) or not use.strip():
        return None, f'must be a file name ("part.toml") or "library:NAME", got {short(use)}'
    if use.startswith(LIBRARY_PREFIX):
        name = use[len(LIBRARY_PREFIX):]
        problem = library_name_problem(name)
        if problem is not None:
            return None, f"{short(use)} {problem}"
        found = find_library_part(name)
        if found is None and explain:
            return None, (f"no library part or model {short(name)}; parts: {', '.join(library_parts())}; "
                          f"models: {', '.join(library_models())}")
        return found, None
    base = path.resolve().parent
    try:
        target = (base / use).resolve()
        found = target.exists()
    except (OSError, ValueError, RuntimeError) as exc:
        return None, f"{short(use)} is not a usable file name ({type(exc).__name__})"
    if not target.is_relative_to(base):
        return None, (f"{short(use)} leaves the directory of {path.name}: a file may use files beside or below "
                      "it, or library:NAME")
    if not found:
        return None, f"file {short(use)} not found beside {path.name}"
    return target, None   # (a FIFO or a device is refused when it is read)


def _resolve_use(r: Reader, label: str, use: Any, context: _FileContext) -> Path | None:
    target, problem = _use_target(use, context.path)
    if problem is not None:
        r.problem(label, "use", problem)
    return target


class _Files:
    """The files one ``load`` reads, each read once (by resolved path), and the limits on the
    sub-model instances their ``use`` graph builds, checked before anything is built."""

    def __init__(self, path: Path, data: dict):
        self.top = path
        self.data: dict[Path, Any] = {path.resolve(): data}
        #: parameters compiled with their numbers, across every file of the load (Reader.frozen)
        self.frozen: dict[str, str] = {}

    def data_of(self, path: Path, label: str) -> dict:
        """The parsed data of ``path`` (read once; a file that failed fails again)."""
        key = path.resolve()
        found = self.data.get(key)
        if found is None:
            try:
                found = _parse_toml(path, label)
            except ModelError as exc:
                found = exc
            self.data[key] = found
        if isinstance(found, ModelError):
            raise ModelError(problems=found.problems)
        return found

    def check_limits(self, label: str) -> None:
        """``ModelError`` when the model would hold more than ``max_instances()`` sub-model
        instances or nest them more than ``max_nesting()`` deep.  Counted on the ``use``
        graph with multiplicities, each file once: milliseconds even for 2**29 instances.
        Files that cannot be read or used count as nothing here (the reader reports them)."""
        limit, deepest = max_instances(), max_nesting()
        memo: dict[Path, tuple[int, int, tuple]] = {}

        def too_deep(chain: tuple) -> ModelError:
            names = [p.name if isinstance(p, Path) else p for p in chain]
            if len(names) > 7:
                names = names[:3] + [f"... ({len(names) - 5} more)"] + names[-2:]
            return ModelError(problems=[f"{label}: sub-models nest more than {deepest} deep (set {NESTING[0]} to "
                                        f"raise the limit): {' -> '.join(names)}"])

        def table(data: Any, where: Path, level: int, chain: tuple) -> tuple[int, int, tuple]:
            subs = data.get("submodels") if isinstance(data, dict) else None
            count, depth, longest = 0, 0, ()
            if not isinstance(subs, dict):
                return count, depth, longest
            for name, entry in subs.items():
                if not isinstance(entry, dict):
                    continue
                below, step = (0, 0, ()), f"[submodels.{toml_key(str(name))}]"
                if "use" in entry:
                    target, _ = _use_target(entry["use"], where, explain=False)
                    if target is not None and target.resolve() not in chain:
                        below = use(target.resolve(), level + 1, chain + (target.resolve(),))
                elif entry and all(key in PART_SECTIONS + ("submodels",) for key in entry):
                    if level + 1 > deepest:
                        raise too_deep(chain + (step,))
                    below = table(entry, where, level + 1, chain + (step,))
                count += 1 + below[0]
                if 1 + below[1] > depth:
                    depth, longest = 1 + below[1], below[2]
            return count, depth, longest

        def use(target: Path, level: int, chain: tuple) -> tuple[int, int, tuple]:
            if level > deepest:
                raise too_deep(chain)
            if target not in memo:
                try:
                    data = self.data_of(target, str(target))
                except ModelError:
                    data = {}
                memo[target] = table(data, target, level, chain)
            count, depth, longest = memo[target]
            if level + depth > deepest:
                raise too_deep(chain + longest)
            return count, depth, (target,) + longest

        top = self.top.resolve()
        counts = {}
        data = self.data[top]
        subs = data.get("submodels") if isinstance(data, dict) else None
        if isinstance(subs, dict):
            for name, entry in subs.items():
                counts[name] = table({"submodels": {name: entry}}, self.top, 0, (top,))[0]
        total = sum(counts.values())
        if total > limit:
            name, most = max(counts.items(), key=lambda item: item[1])
            alone = f"; [submodels.{toml_key(str(name))}] alone builds {most}" if len(counts) > 1 else ""
            raise ModelError(problems=[f"{label}: would build {total} sub-model instances, more than the limit of "
                                       f"{limit} per model (set {INSTANCES[0]} to raise it){alone}"])


def _read_submodel(r: Reader, name: str, label: str, table: dict, bodies: dict, context: _FileContext):
    """A sub-model instance from ``[submodels.NAME]``: ``use``, port bindings, parameter
    overrides (numbers or expressions of this file's parameters) and dicts of modifiers
    for the part's own sub-models."""
    if "use" not in table:
        if table and all(key in PART_SECTIONS + ("submodels", "parameters") for key in table):
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
            cls = _part_class(path, _FileContext(path, context.chain + (resolved,), context.classes, context.files))
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
    data = context.files.data_of(path, label)
    r = Reader(label)
    r.keys("", data, TOP_KEYS)
    declared, _ = _declare_parameters(r, data.get("parameters", {}), "parameters")
    external, exposed = _read_ports(r, data.get("ports", {}))
    if r.problems:
        raise ModelError(problems=r.problems)
    name = data.get("name", path.stem)

    def port_names(cls) -> dict:
        return {p: _PORT_REQUIRED for p in external}

    def build(self, **ports: Any) -> None:
        reader = Reader(label)
        reader.frozen = context.files.frozen
        reader.parameters = {key: getattr(self, key) for key in declared}
        reader.ports = set(ports)
        bodies: dict[str, Any] = {"ground": "ground", **ports}
        _read_parts(reader, data, self, bodies, context, exposed)
        if reader.problems:
            raise ModelError(problems=reader.problems)

    namespace = {**declared, "build": build, "port_names": classmethod(port_names),
                 "__doc__": data.get("description", f"Part read from {path.name}"), "source": path}
    return type(_class_name(name), (FileSubmodel,), namespace)


def _declare_parameters(r: Reader, params_table: Any, label: str) -> tuple[dict, dict]:
    """``Parameter``s of a part's ``[parameters]`` (a number, or a table {value, unit, min,
    max, doc}) and the values given as expressions of ``r``'s names (an inline part's
    parameters bound to the enclosing instance's: ``{name: Expr}``, the modifiers)."""
    declared: dict[str, Any] = {}
    bound: dict[str, Any] = {}
    if not isinstance(params_table, dict):
        r.problem(None, label, f"must be a table [{label}], got {type_name(params_table)}")
        return declared, bound
    for key, value in params_table.items():
        if not key.isidentifier() or key in RESERVED:
            r.problem(label, key, f"{key!r} is not a valid parameter name")
            continue
        spec = value if isinstance(value, dict) else {"value": value}
        r.keys(f"{label}.{key}", spec, ("value", "unit", "min", "max", "doc"), ("value",))
        default = r.number(label, key, spec.get("value", BAD)) if "value" in spec else BAD
        if default is BAD:
            continue
        try:
            declared[key] = Parameter(float(default), unit=spec.get("unit"), min=spec.get("min"),
                                      max=spec.get("max"), doc=str(spec.get("doc", "")))
        except ModelError as exc:
            r.problem(label, key, str(exc))
            continue
        if isinstance(default, Expr):
            bound[key] = default
    return declared, bound


def _inline_class(r: Reader, label: str, table: dict, bodies: dict, context: _FileContext) -> Any:
    """A ``Submodel`` class for a part written inline (as ``save`` writes sub-model instances):
    its tables name their own components locally and anything else by its full path; its
    ``[parameters]`` are run-time parameters under the instance's path, as a part file's (a
    value may be an expression of the enclosing scope's parameters, and follows them)."""
    outer = dict(bodies)
    where = f"{r.label} {label}"
    declared, bound = _declare_parameters(r, table.get("parameters", {}), f"{label}.parameters")

    def build(self) -> None:
        reader = Reader(where)
        reader.frozen = r.frozen
        reader.parameters = {**r.parameters, **{key: getattr(self, key) for key in declared}}
        _see_instance_parameters(reader, self)
        _read_parts(reader, table, self, dict(outer), context, {})
        if reader.problems:
            raise ModelError(problems=reader.problems)

    namespace = {**declared, "build": build, "__doc__": f"Part written inline in {where}"}
    cls = type("InlinePart", (FileSubmodel,), namespace)
    return lambda name: cls(name, **bound)


def _class_name(name: Any) -> str:
    text = "".join(ch if ch.isalnum() else "_" for ch in str(name)) or "Part"
    return text if text[0].isalpha() else "Part_" + text


def _add_component(r: Reader, model: Model, component: Any, label: str) -> None:
    if component is None:
        return
    try:
        model.add(component)
    except ModelError as exc:
        r.problem(label, None, str(exc))


def _read_parameters(r: Reader, table: Any, model: Model) -> None:
    """The file's own ``[parameters]`` (a number, an expression of earlier ones, or a table
    {value, unit, min, max, doc}): run-time parameters of ``model`` (``Model.parameter``),
    which the file's expressions name and follow."""
    if not isinstance(table, dict):
        r.problem(None, "parameters", f"must be a table [parameters], got {type_name(table)}")
        return
    for key, value in table.items():
        if not key.isidentifier() or key in RESERVED:
            why = "is reserved" if key in RESERVED else "is not a valid name (letters, digits, _)"
            r.problem("parameters", key, f"{key!r} {why}")
            continue
        spec: dict = {}
        if isinstance(value, dict):   # {value = ..., unit, min, max, doc} as part files declare them
            r.keys(f"parameters.{key}", value, ("value", "unit", "min", "max", "doc"), ("value",))
            spec, value = value, value.get("value", BAD)
            if value is BAD:
                continue
        x = r.number("parameters", key, value)
        if x is BAD:
            continue
        try:
            r.parameters[key] = model.parameter(key, x, unit=spec.get("unit"), min=spec.get("min"),
                                                max=spec.get("max"), doc=str(spec.get("doc", "")))
        except ModelError as exc:
            r.problem("parameters", key, getattr(exc, "detail", str(exc)))


def _read_initial(r: Reader, table: dict, coords: dict | None, speeds: dict | None = None) -> dict:
    """``[initial]``: ``q`` by coordinate name, ``qd`` by coordinate (its rate) or by speed
    name (a ball's angular velocity components)."""
    initial: dict[str, dict[str, float]] = {"q": {}, "qd": {}}
    r.keys("initial", table, ("q", "qd"))
    known = coords
    for which in ("q", "qd"):
        coords = known if which == "q" or known is None else {**known, **(speeds or {})}
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
                initial[which][coord] = float(x)   # a start value, not a link to the parameters
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
            if isinstance(value, bool) or not isinstance(value, int) or not 2 <= value <= MAX_SAMPLES:
                x = r.problem("simulation", key, f"must be an integer from 2 to {MAX_SAMPLES:.0e}, got {short(value)}")
            else:
                x = value
        else:
            continue  # reported as an unknown key
        if x is not BAD:
            out[key] = float(x) if key in ("t_end", "rtol", "atol") else x
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
    binding = getattr(model, "gravity_binding", None)
    texts = [_expr_text(g, "") for g in binding] if binding is not None else None
    if texts is not None and all(t is not None for t in texts):   # follows model parameters
        lines.append(f"gravity = {toml_value([t if isinstance(g, Expr) else float(g) for t, g in zip(texts, binding)])}")
    else:
        lines.append(f"gravity = {toml_value(floats(model.gravity))}")
    if model.ground.shape:
        lines.append(f"ground_shape = {toml_value([shape_table(s) for s in model.ground.shape])}")
    declared = {p: e for p, e in (model.registry.parameters.items() if model.registry is not None else ()) if "." not in p}
    parameters = getattr(model, "named_parameters", None) or {}
    if declared:   # model-level run-time parameters (Model.parameter), with their bindings
        lines += ["", "[parameters]"] + [_parameter_line(name, entry, "") for name, entry in declared.items()]
    elif parameters:
        lines += ["", "[parameters]"] + [f"{toml_key(k)} = {toml_value(float(v))}" for k, v in parameters.items()]
    if model.registry is not None:
        lines += _part_lines(model, model.entries, "", "")
    else:
        lines += _section_lines([c for c in model.components.values() if c is not model.ground], "")
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


def _section_lines(components: list, prefix: str, tables: dict | None = None) -> list[str]:
    """TOML tables of ``components`` under ``prefix`` (``""`` or ``"submodels.NAME."``);
    ``tables``: ``{id(component): (table, notes)}`` written instead of ``component_table``'s
    (values as parameter expressions, and comments on the values written as numbers)."""
    lines = []
    sections: dict[str, list[tuple[str, dict, list]]] = {}
    for comp in components:
        section, table = component_table(comp)
        table, notes = (tables or {}).get(id(comp), (table, []))
        sections.setdefault(section, []).append((comp.name, table, notes))
    for section in PART_SECTIONS:
        for name, table, notes in sections.get(section, []):
            lines += [""] + [f"# {note}" for note in notes] + [f"[{prefix}{section}.{toml_key(name)}]"]
            lines += [f"{toml_key(k)} = {toml_value(v)}" for k, v in table.items()]
    return lines


# -- parameter expressions of sub-model instances -------------------------------------------------
_WRITABLE_OPS = {"+", "-", "*", "/", "**", "neg", "sqrt", "sin", "cos", "exp"}


def _expr_text(expr: Any, scope: str) -> str | None:
    """``expr`` (an ``Expr``) in the file's expression language, seen from instance ``scope``
    (``""``: the top level): its own parameters by local name, any other instance's by its
    path (``"upper.length"``); ``None`` when the language cannot say it (tan, log, abs, or
    a path that is not a chain of names)."""
    if not isinstance(expr, Expr):
        x = float(expr)
        return repr(x) if x >= 0 else f"({x!r})"
    if expr.op == "param":
        path = expr.args[0]
        if scope and path.startswith(scope + ".") and path[len(scope) + 1:].isidentifier():
            return path[len(scope) + 1:]
        parts = path.split(".")
        if len(parts) == 1 and not scope:   # a model-level parameter (Model.parameter), seen from the top
            # (a keyword such as the bicycle's `lambda` is fine: the file declares it, and a
            # declared parameter may be named like a keyword, mbcomp.core.expressions)
            return path if path.isidentifier() and path not in RESERVED else None
        if len(parts) < 2 or not all(p.isidentifier() and not keyword.iskeyword(p) for p in parts):
            return None
        return path
    if expr.op not in _WRITABLE_OPS:
        return None
    args = [_expr_text(a, scope) for a in expr.args]
    if any(a is None for a in args):
        return None
    if expr.op == "neg":
        return f"(-{args[0]})"
    if expr.op in ("sqrt", "sin", "cos", "exp"):
        return f"{expr.op}({args[0]})"
    return f"({args[0]} {expr.op} {args[1]})"


def _marked(value: Any, markers: dict) -> Any:
    """``value`` with every ``Expr`` replaced by its marker: a float a few ulps from its value
    (validation passes as for the value), distinct for each expression."""
    def marker(expr: Expr) -> float:
        if expr not in markers:
            x, k = expr.value, len(markers) + 1
            markers[expr] = float(x + k * (np.spacing(x) if x else 5e-324))
        return markers[expr]
    return map_exprs(value, marker)


def _expression_table(comp: Any, copy: Any, written: Any, scope: str) -> tuple[dict, list[str]] | None:
    """The file table of ``copy`` (``comp`` with its references as written) whose values
    built from sub-model parameters are written as expressions of them (seen from
    ``scope``), and notes on those written as numbers; None when ``comp`` has no such values.

    The component is built again with each expression replaced by a marker number; a value
    of its table equal to a marker is that expression (the constructor passed it through),
    any other value that moved is derived from them inside the constructor (written as its
    number, with a note)."""
    if comp.expression_args is None:
        return None
    _, plain = component_table(copy)
    markers: dict = {}
    args, kwargs = comp.expression_args
    try:
        rebuilt = type(comp)(*_marked(args, markers), **_marked(kwargs, markers))
        refs = {role: written(ref) for role, ref in rebuilt.references().items()}
        _, marked = component_table(copy_component(rebuilt, copy.name, refs))
    except (ModelError, TypeError, ValueError, ArithmeticError):
        return plain, [f"{copy.name}: values from sub-model parameters written as numbers "
                       "(the component cannot be rebuilt with them marked)"]
    by_marker = {m: e for e, m in markers.items()}
    notes: list[str] = []

    def merge(key: str, new: Any, old: Any) -> Any:
        if isinstance(new, float) and new in by_marker:
            text = _expr_text(by_marker[new], scope)
            if text is not None:
                return text
            notes.append(f"{key} = {toml_value(old)}: the value of {by_marker[new]!r}, which a file cannot "
                         "write as an expression (it will not follow a parameter change)")
            return old
        if isinstance(new, (list, tuple)) and isinstance(old, (list, tuple)) and len(new) == len(old):
            return [merge(key, n, o) for n, o in zip(new, old)]
        if isinstance(new, dict) and isinstance(old, dict) and new.keys() == old.keys():
            return {k: merge(key, new[k], old[k]) for k in new}
        if new != old and not isinstance(new, str):
            notes.append(f"{key} = {toml_value(old)}: derived from sub-model parameters inside the component, "
                         "written as its value (it will not follow a parameter change)")
        return old

    def derived(new: Any, old: Any) -> bool:
        """A value the constructor computed from marked arguments (not passed through)."""
        if isinstance(new, (list, tuple)) and isinstance(old, (list, tuple)) and len(new) == len(old):
            return any(derived(n, o) for n, o in zip(new, old))
        return isinstance(new, float) and new not in by_marker and new != old

    table = {}
    for key, new in marked.items():
        given = _given_text(kwargs.get(key), scope) if key in plain and derived(new, plain[key]) else None
        if given is not None:   # e.g. a normalised axis: the argument as given derives the same value
            table[key] = given
        elif key in plain:
            table[key] = merge(key, new, plain[key])
        elif _mentions(new, by_marker):   # a default value, here linked to parameters
            table[key] = merge(key, new, _unmarked(new, by_marker))
    for key, old in plain.items():
        table.setdefault(key, old)
    return table, list(dict.fromkeys(notes))


def _given_text(value: Any, scope: str) -> Any:
    """A constructor argument holding expressions (a vector such as a joint axis that the
    constructor normalises) as file values: numbers stay, expressions become their text;
    None when it holds none or one a file cannot write."""
    if isinstance(value, Expr):
        return _expr_text(value, scope)
    if isinstance(value, (list, tuple)) and any(isinstance(v, Expr) for v in value):
        parts = [_given_text(v, scope) if isinstance(v, Expr) else v for v in value]
        ok = all(p is not None and (isinstance(p, str) or (isinstance(p, (int, float)) and not isinstance(p, bool)))
                 for p in parts)
        return [p if isinstance(p, str) else float(p) for p in parts] if ok else None
    return None


def _mentions(value: Any, by_marker: dict) -> bool:
    if isinstance(value, float):
        return value in by_marker
    if isinstance(value, (list, tuple)):
        return any(_mentions(v, by_marker) for v in value)
    if isinstance(value, dict):
        return any(_mentions(v, by_marker) for v in value.values())
    return False


def _unmarked(value: Any, by_marker: dict) -> Any:
    if isinstance(value, float):
        return by_marker[value].value if value in by_marker else value
    if isinstance(value, (list, tuple)):
        return [_unmarked(v, by_marker) for v in value]
    if isinstance(value, dict):
        return {k: _unmarked(v, by_marker) for k, v in value.items()}
    return value


def _parameter_lines(model: Model, item: Submodel, outer_scope: str, head: str) -> list[str]:
    """``[<head>.parameters]`` of instance ``item``: its parameters by local name, each a
    number or (bound by the enclosing part) an expression seen from ``outer_scope``."""
    declared = item.declared_parameters()
    if not declared:
        return []
    return ["", f"[{head}.parameters]"] + [_parameter_line(key, model.registry.parameters[f"{item.path}.{key}"],
                                                                   outer_scope) for key in declared]


def _parameter_line(key: str, entry: Any, outer_scope: str) -> str:
    """One line of a ``[parameters]`` table: a parameter's number, or (bound to others) its
    expression seen from ``outer_scope``, with its unit, bounds and doc when declared."""
    spec = entry.spec
    value: Any = float(entry.value)
    comment = ""
    if isinstance(entry.binding, Expr):
        text = _expr_text(entry.binding, outer_scope)
        if text is None:
            comment = f"# {key}: the value of {entry.binding!r}, which a file cannot write as an expression\n"
        else:
            value = text
    extra = {k: v for k, v in (("unit", spec.unit), ("min", spec.min), ("max", spec.max), ("doc", spec.doc))
             if v not in (None, "")}
    if extra:
        table = {"value": value, **{k: (float(v) if k in ("min", "max") else str(v)) for k, v in extra.items()}}
        return f"{comment}{toml_key(key)} = {toml_value(table)}"
    return f"{comment}{toml_key(key)} = {toml_value(value)}"


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

    components, tables = [], {}
    for c in members:
        if isinstance(c, Submodel):
            continue
        copy = copy_component(c, c.name, {role: written(ref) for role, ref in c.references().items()})
        components.append(copy)
        table = _expression_table(c, copy, written, scope)
        if table is not None:
            tables[id(copy)] = table
    lines = _section_lines(components, prefix, tables)
    for item in members:
        if isinstance(item, Submodel):
            head = f"{prefix}submodels.{toml_key(item.name)}"
            lines += ["", f"# sub-model instance {item.path!r}, written inline", f"[{head}]"]
            lines += _parameter_lines(model, item, scope, head)
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
    from mbcomp.core.writing import write_file
    write_file(path, text, "save")
