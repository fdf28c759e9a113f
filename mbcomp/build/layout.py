"""OutputLayout: where each quantity sits in the packed outputs of the generated functions.

One object describes every output array shared by the generated code and Python: the
program writes its outputs in this order, the C templates take their offsets from the
``#define``s it generates, and Python decodes with ``unpack``.  It is part of the cache key.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, Mapping

import numpy as np

#: The fields of one body's row in the ``kinematics`` output, in order, with their widths:
#: rotation (3x3, body to world, row-major), origin (m), spatial velocity ``(w, v0)`` and the
#: acceleration bias ``A_bias`` (the spatial acceleration at zero accelerations).
BODY_FIELDS = (("rotation", 9), ("origin", 3), ("velocity", 6), ("bias", 6))
BODY_ROW = sum(width for _, width in BODY_FIELDS)


def body_fields(rows: np.ndarray) -> dict[str, np.ndarray]:
    """The ``kinematics`` rows of bodies (..., BODY_ROW) split into ``rotation`` (..., 3, 3),
    ``origin`` (..., 3), ``velocity`` (..., 6) and ``bias`` (..., 6)."""
    out, start = {}, 0
    for name, width in BODY_FIELDS:
        out[name] = rows[..., start:start + width]
        start += width
    out["rotation"] = out["rotation"].reshape(rows.shape[:-1] + (3, 3))
    return out


@dataclass(frozen=True)
class Block:
    """One named quantity of a function's output: ``shape`` stored from ``offset`` on,
    ``"dense"`` (row-major) or ``"tril"`` (the lower triangle of a symmetric square matrix,
    row by row).  ``size`` and ``stop`` are computed once: ``unpack`` runs on every
    right-hand side of a scipy-stepped run."""

    name: str
    offset: int
    shape: tuple[int, ...]
    packing: Literal["dense", "tril"] = "dense"
    size: int = field(init=False, repr=False, compare=False)
    stop: int = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if self.packing == "tril":
            n = self.shape[0]
            size = n * (n + 1) // 2
        else:
            size = math.prod(self.shape)
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "stop", self.offset + size)


@lru_cache(maxsize=64)
def _tril(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.tril_indices(n)


def _blocks(*specs: tuple) -> tuple[Block, ...]:
    out, offset = [], 0
    for name, shape, *packing in specs:
        block = Block(name, offset, tuple(shape), *packing)
        out.append(block)
        offset = block.stop
    return tuple(out)


@dataclass(frozen=True)
class OutputLayout:
    """The blocks of every generated function's output (``functions[name]``, in order)."""

    functions: Mapping[str, tuple[Block, ...]]

    @classmethod
    def of(cls, nv: int, n_bodies: int, n_constraint_rows: int, n_contacts: int,
           n_drive_states: int = 0) -> "OutputLayout":
        """The layout of a model with ``nv`` speeds, ``n_bodies`` moving bodies,
        ``n_constraint_rows`` geometric constraint equations, ``n_contacts`` contacts and
        ``n_drive_states`` states of drive elements."""
        ng, nk = n_constraint_rows, n_contacts
        return cls({
            "dynamics": _blocks(("mass_matrix", (nv, nv), "tril"), ("forces", (nv,))),
            "energy": _blocks(("kinetic", ()), ("potential", ())),
            "kinematics": _blocks(("bodies", (n_bodies, BODY_ROW)), ("columns", (nv, 6))),
            "constraints": _blocks(("residual", (ng,)), ("jacobian", (ng, nv)), ("bias", (ng,))),
            "contacts": _blocks(("gap", (nk,)), ("jacobian", (nk, nv)), ("bias", (nk,))),
            "drives": _blocks(("forces", (nv,)), ("rates", (n_drive_states,))),
        })

    def block(self, function: str, name: str) -> Block:
        for block in self.functions[function]:
            if block.name == name:
                return block
        raise KeyError(f"{function} has no output block {name!r}")

    def size(self, function: str) -> int:
        """Length of the packed output of ``function``."""
        blocks = self.functions[function]
        return blocks[-1].stop if blocks else 0

    def sizes(self) -> dict[str, int]:
        return {name: self.size(name) for name in self.functions}

    def unpack(self, function: str, flat: np.ndarray) -> dict[str, np.ndarray]:
        """``{block name: array of its shape}`` from a packed output (tril blocks come back as
        full symmetric matrices; dense blocks are views of ``flat``)."""
        out = {}
        for block in self.functions[function]:
            values = flat[block.offset:block.stop]
            if block.packing == "tril":
                n = block.shape[0]
                rows, cols = _tril(n)
                matrix = np.empty((n, n))
                matrix[rows, cols] = values
                matrix[cols, rows] = values
                out[block.name] = matrix
            else:
                out[block.name] = values.reshape(block.shape)
        return out

    def c_names(self) -> dict[str, int]:
        """Every block's offset and every function's size by its C name, e.g.
        ``DYNAMICS_FORCES_OFF`` and ``DYNAMICS_SIZE``: the C templates use nothing else
        (``c_sizes.CSizes`` declares them for the shared templates)."""
        names = {}
        for function, blocks in self.functions.items():
            for block in blocks:
                names[f"{function.upper()}_{block.name.upper()}_OFF"] = block.offset
            names[f"{function.upper()}_SIZE"] = self.size(function)
        return names

    def c_defines(self) -> str:
        """``c_names`` as ``#define``s, for C compiled on its own with one model's layout."""
        return "".join(f"#define {name} {value}\n" for name, value in self.c_names().items())

    def description(self) -> str:
        """Text of the whole layout (for the cache key)."""
        return ";".join(f"{function}:" + ",".join(f"{b.name}@{b.offset}{list(b.shape)}{b.packing}" for b in blocks)
                        for function, blocks in self.functions.items())
