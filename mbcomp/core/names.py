"""One naming rule for what a model names: coordinates, speeds, drive-element states and
parameters share one namespace with the names mbcomp derives from them (a coordinate's
speed column ``<name>_d`` and its symbol, the time ``t``, the energy columns), so that a
column of a CSV file or a DataFrame, a series of a Result and a symbol of
``System.equations()`` always mean one thing.  Component names are unique per model
(``Model.add``); the names here are checked when a joint is made (reserved names) and when
a model is compiled (every clash, naming both sides)."""
from __future__ import annotations

from typing import Iterable

#: Names mbcomp gives columns and symbols of its own: no coordinate, speed or state may use them.
RESERVED = {
    "t": "the time column and the time symbol",
    "kinetic": "the kinetic-energy column",
    "potential": "the potential-energy column",
    "total": "the total-energy column",
}
#: A coordinate's speed column (CSV, DataFrame, ``Result["<name>_d"]``).
SPEED_SUFFIX = "_d"


def reserved_problem(name: str) -> str | None:
    """Why ``name`` cannot name a coordinate, speed or state (None when it can)."""
    if name in RESERVED:
        return f"name {name!r} is reserved: it is {RESERVED[name]} of every result"
    return None


def speed_column(coord: str) -> str:
    """The column name of a coordinate's speed."""
    return coord + SPEED_SUFFIX


def clashes(entries: Iterable[tuple[str, str]]) -> list[str]:
    """Problems of names used twice: ``entries`` are ``(name, what uses it)`` (a coordinate of
    a joint, the speed column it derives, a state, a parameter); the reserved names take part."""
    owner: dict[str, str] = {name: what for name, what in RESERVED.items()}
    problems = []
    for name, what in entries:
        first = owner.setdefault(name, what)
        if first != what:
            problems.append(f"name {name!r} is both {first} and {what}: rename one of them")
    return problems


def model_entries(topology, drives, parameters: Iterable[str]) -> list[tuple[str, str]]:
    """Every name a compiled model uses, with what uses it: coordinates, the speed columns and
    symbols they derive, speeds that are not a coordinate's rate, drive states, parameters."""
    from mbcomp.core.errors import describe
    entries = []
    for joint in topology.tree_joints:
        for c in joint.coords:
            entries.append((c, f"a coordinate of {describe(joint)}"))
        for v in joint.speeds:
            if v in joint.coords:
                entries.append((speed_column(v), f"the speed column of coordinate {v!r} ({describe(joint)})"))
                entries.append((f"\\dot{{{v}}}", f"the speed symbol of coordinate {v!r} ({describe(joint)})"))
            else:
                entries.append((v, f"a speed of {describe(joint)}"))
    for state, (comp, _) in zip(drives.states, drives.state_owner):
        entries.append((state, f"a state of {describe(comp)}"))
    for key in parameters:
        entries.append((key, f"the parameter {key!r}"))
    return entries
