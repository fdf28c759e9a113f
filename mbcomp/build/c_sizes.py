"""The sizes of one model, kept out of the hand-written C templates so that one compiled
templates object serves every model of the same kind.

The templates (tree solve, formulations, integrators) read every size, offset and index
table through a name: ``NQ``, ``DYNAMICS_FORCES_OFF``, ``QUAT_Q``, ...  ``CSizes.header``
declares those names as hidden (library-local) constants defined elsewhere, and
``CSizes.unit`` is the small C unit that defines them, with the per-thread buffers whose
length depends on them, for one model; so are what a model has (``HAS_DRIVES``,
``MB_HAS_NG``, ``MB_HAS_CONTACTS``, ``MB_HAS_QUAT``: tested with ``if``, not ``#if``).  The
templates' text then depends only on the kind of model (the formulations' code it needs:
trees, loops, contacts; dense or recursive dynamics), so the code cache compiles it once per
kind instead of once per size and feature set: 0.3-1.5 s of C compiler at -O1 each time it
is not compiled.
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field
from typing import Mapping

#: Library-local: each model library resolves these names to its own definitions.
HIDDEN = '__attribute__((visibility("hidden")))'

#: Longs per configured row of the dae formulation's compiled KKT solve (``dae_c.SPEC_LONGS``).
DAE_SPEC_LONGS = 5


@dataclass(frozen=True)
class CSizes:
    """One model's sizes for the C templates.

    ``values``: ``int`` constants (``NQ``, the output layout's ``*_OFF``/``*_SIZE``, ...);
    ``tables``: ``int`` arrays (quaternion and screw indices, the recursion's parents);
    ``buffers``: per-thread arrays ``{name: (C type, length)}``.  No model fact is a
    compile-time constant of the templates (``check_generic``).
    """

    values: Mapping[str, int]
    tables: Mapping[str, tuple[int, ...]] = field(default_factory=dict)
    buffers: Mapping[str, tuple[str, int]] = field(default_factory=dict)

    @classmethod
    def of(cls, layout, *, nq: int, ng: int, state_map, nz: int, drives: bool,
           aba: tuple[int, int, int] | None = None, aba_parents: tuple[int, ...] = (),
           features: int = 0) -> "CSizes":
        """The sizes of a model: ``layout`` (``OutputLayout``), ``nq`` speeds of the mass
        matrix, ``ng`` geometric constraint rows, its ``StateMap``, ``nz`` drive states
        (``drives``: it has drive elements), and for the recursive program ``aba`` =
        (speeds, inputs, output length) with ``aba_parents`` (parent speed per speed, -1 at
        the root) when the dae KKT solve runs on it; ``features``: the collision features
        (contact rows after the model's own: the dae solve's rows have room for them all, as
        the least-norm friction solve holds every closed contact)."""
        values = layout.c_names()
        ncoord, nv = state_map.nq, state_map.nv
        nk = layout.block("contacts", "gap").shape[0]
        values.update(NQ=nq, NG=ng, NCOORD=ncoord, NV=nv,
                      NQUAT=int(state_map.quat_q.size), NSCREW=int(state_map.screw_q.size))
        tables = {name: tuple(int(v) for v in getattr(state_map, attr))
                  for name, attr in (("SCREW_Q", "screw_q"), ("SCREW_V", "screw_v"),
                                     ("QUAT_Q", "quat_q"), ("QUAT_V", "quat_v"))}
        if aba is not None:
            values.update(ABA_NV=aba[0], ABA_NU=aba[1], ABA_OUT=aba[2])
            tables["ABA_PRED"] = tuple(aba_parents)
        values["MB_NCF"] = int(features)
        dae_rows = ng + nq + nk + int(features)  # DAE_NR of formulations/dae_c.py
        buffers = {
            "lag_dv": ("double", layout.size("drives") + 1),     # formulations/lagrange_c.py
            "lag_kc": ("double", layout.size("contacts") + 1),
            "dae_rows": ("long", dae_rows),                      # formulations/dae_c.py
            "dae_legacy": ("long", DAE_SPEC_LONGS * dae_rows),
            "dae_lam": ("double", dae_rows + 1),
        }
        # The length of the mechanical state (NMECH) and the number of drive states (NZ) are
        # read at run time too, so one compiled templates object serves every size of a kind.
        # (The state length was a compile-time constant for trees, whose compiled runs of 3 to
        # 10 links were 12-16 % slower with it read at run time: not the loops themselves but
        # the C library's memcpy, which a copy of unknown length called, in its AVX-512
        # version, slowing the SSE2 arithmetic after it; the templates copy with their own
        # ``mb_copy`` now, bench/state_copy.py.)
        values["NMECH"], values["NZ"] = ncoord + nv, nz
        # What the model has (drive elements, constraint rows, contacts, quaternions) is read at
        # run time too: the templates skip what a model lacks with an ``if`` on these, and
        # every model of a kind shares one object (they were compile-time switches, which
        # gave a suite run 19 template kinds instead of about 5).
        values.update(HAS_DRIVES=int(bool(drives)), MB_HAS_NG=int(ng > 0), MB_HAS_CONTACTS=int(nk > 0),
                      MB_HAS_QUAT=int(state_map.quat_q.size > 0))
        return cls(values, tables, buffers)

    def header(self) -> str:
        """C for the shared templates: every size, table and buffer declared by name
        (defined by ``unit``)."""
        lines = []
        for name in self.values:
            lines.append(f"extern const int mb_{name} {HIDDEN};\n#define {name} mb_{name}")
        lines += [f"extern const int {name}[] {HIDDEN};" for name in self.tables]
        lines += [f"extern __thread {ctype} {name}[] {HIDDEN};" for name, (ctype, _) in self.buffers.items()]
        return "\n".join(lines) + "\n"

    def unit(self) -> str:
        """The C unit of this model's sizes, tables and per-thread buffers."""
        lines = [f"{HIDDEN} const int mb_{name} = {value};" for name, value in self.values.items()]
        lines += [f"{HIDDEN} const int {name}[] = {{{', '.join(map(str, values)) or '0'}}};"
                  for name, values in self.tables.items()]
        lines += [f"{HIDDEN} __thread {ctype} {name}[{max(int(length), 1)}];"
                  for name, (ctype, length) in self.buffers.items()]
        return "\n".join(lines) + "\n"

    def check_generic(self, text: str) -> str:
        """``text`` unchanged, or an AssertionError where a preprocessor test reads a size
        (directly or through a macro defined from one): such a name reads as 0 in ``#if``.
        The verdict depends only on the text and the sizes' names: it is kept per process
        (every model of one kind compiles the same templates; the scan takes about 10 ms)."""
        problem = _size_tests(text, tuple(self.values), tuple(self.tables))
        if problem:
            raise AssertionError(problem)
        return text


_DEFINE = re.compile(r"^\s*#define (\w+)(?:\(.*?\))? (.*)$", re.M)
_NAME = re.compile(r"[A-Za-z_]\w*")
_NUMBER_DEFINE = re.compile(r"#define (\w+) -?\d+\s*$")


@functools.lru_cache(maxsize=32)
def _size_tests(text: str, values: tuple[str, ...], tables: tuple[str, ...]) -> str:
    """The first way ``text`` tests a size in the preprocessor (``CSizes.check_generic``), or ""."""
    runtime = set(values) | set(tables)
    defines = [(name, set(_NAME.findall(body))) for name, body in _DEFINE.findall(text)]
    grew = True
    while grew:  # macros defined from sizes are sizes too
        grew = False
        for name, used in defines:
            if name not in runtime and used & runtime:
                runtime.add(name)
                grew = True
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith(("#if ", "#elif ")):
            used = set(_NAME.findall(stripped.split("/*")[0][3:])) & runtime
            if used:
                return f"the C templates test sizes {sorted(used)} in {stripped!r}: test them with an if"
        match = _NUMBER_DEFINE.match(stripped)
        if match and match.group(1) in values:
            return f"the C templates define the size {match.group(1)} as a number"
    return ""
