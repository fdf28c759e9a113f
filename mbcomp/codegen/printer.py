"""sympy straight-line programs -> numeric functions (Python or C source)."""
from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from mbcomp.core import c_text, tolerances

CODEGEN_VERSION = "10"


# -- printing ---------------------------------------------------------------------------
class Printer:
    """Prints the small expressions of a program as Python or C source.

    Only what the equation builder produces is supported: +, *, integer and half
    powers, sin, cos, numbers and symbols.
    """

    def __init__(self, names: dict, language: str = "python"):
        self.names = names
        self.c = language == "c"

    def number(self, e) -> str:
        text = repr(float(e))
        return f"({text})" if text.startswith("-") else text

    def __call__(self, e) -> str:
        import sympy as sp  # never at ``import mbcomp``: only code generation needs it
        if e.is_Symbol:
            return self.names[e]
        if e.is_Number:
            return self.number(e)
        if e.is_Add:
            terms = [self(arg) for arg in e.args]
            out = terms[0]
            for term in terms[1:]:
                out += f" - {term[1:]}" if term.startswith("-") else f" + {term}"
            return f"({out})"
        if e.is_Mul:
            coeff, factors = e.as_coeff_mul()
            parts = [self(f) for f in factors]
            body = "*".join(parts) if parts else "1.0"
            if coeff == 1:
                return body
            if coeff == -1:
                return f"-{body}"
            return f"{self.number(coeff)}*{body}"
        if e.is_Pow:
            base, exponent = e.args
            b = self(base)
            if exponent == 2:
                return f"({b}*{b})"
            if exponent == -1:
                return f"(1.0/{b})"
            if exponent == -2:
                return f"(1.0/({b}*{b}))"
            if exponent == sp.Rational(1, 2):
                return f"sqrt({b})"
            if exponent == sp.Rational(-1, 2):
                return f"(1.0/sqrt({b}))"
            return f"pow({b}, {self(exponent)})"
        if isinstance(e, sp.sin):
            return f"sin({self(e.args[0])})"
        if isinstance(e, sp.cos):
            return f"cos({self(e.args[0])})"
        if isinstance(e, sp.tanh):
            return f"tanh({self(e.args[0])})"
        if isinstance(e, (sp.Min, sp.Max)):  # signals: limits and clipping
            name = ("fmin" if isinstance(e, sp.Min) else "fmax") if self.c else ("min" if isinstance(e, sp.Min) else "max")
            args = [self(a) for a in e.args]
            out = args[0]
            for a in args[1:]:
                out = f"{name}({out}, {a})"
            return out
        if isinstance(e, sp.Piecewise):
            (value, cond), *rest = e.args
            other = sp.Piecewise(*rest) if len(rest) > 1 or rest and rest[0][1] is not sp.true else \
                (rest[0][0] if rest else sp.nan)
            if self.c:
                return f"(({self(cond)}) ? ({self(value)}) : ({self(other)}))"
            return f"({self(value)} if {self(cond)} else {self(other)})"
        if isinstance(e, sp.core.relational.Relational) and e.rel_op in ("<", "<=", ">", ">="):
            return f"({self(e.lhs)} {e.rel_op} {self(e.rhs)})"
        raise TypeError(f"cannot print {type(e).__name__}: {e}")


#: The libm functions ``Printer`` prints in C, declared in the generated units instead of
#: including ``<math.h>``: parsing that header costs each compiler run 13-15 ms (an empty
#: unit takes about 20 ms), and compilers know these names as built-ins either way, so the
#: machine code is the same (tests/test_codegen.py compares the objects).
C_MATH = ("double sqrt(double); double pow(double, double); double sin(double); double cos(double);\n"
          "double tanh(double); double fmin(double, double); double fmax(double, double);\n")


#: Statements per static function of a long generated function (the values crossing a
#: boundary pass through the work array).  An optimising compiler's time grows faster than a
#: function's length: measured with callgrind on the two halves of the N = 10 chain's
#: dynamics at -O1, chunks of 300 / 150 / 100 / 50 statements took 2.94 / 2.72 / 2.55 / 2.48
#: billion compiler instructions, while one right-hand side ran in 1.7 % fewer instructions
#: with 100 than with 300 (fewer spills) and the same numbers, bit for bit.
CHUNK_STATEMENTS = 100


def _names(prog, language: str) -> dict:
    names = {}
    for vec, label in ((prog.q, "q"), (prog.qd, "qd"), (prog.u, "u"), (getattr(prog, "du", ()), "u")):
        for i, s in enumerate(vec):
            names[s] = f"{label}[{i}]"
    for i, s in enumerate(prog.p):
        names[s] = f"p[{i}]"
    for s, _ in prog.assignments:
        names[s] = s.name
    return names


def python_source(prog, functions: dict) -> str:
    """Python module source: one function per entry of ``functions``
    (``{name: [output names]}``), each ``f(q, qd, p, u) -> list of floats``."""
    import sympy as sp
    names = _names(prog, "python")
    printer = Printer(names, "python")
    lines = ["from math import sin, cos, sqrt, tanh", ""]
    for fname, outputs in functions.items():
        lines.append(f"def {fname}(q, qd, p, u):")
        for symbol, expr in prog.needed(outputs):
            lines.append(f"    {symbol.name} = {printer(expr)}")
        values = [printer(sp.sympify(e)) for name in outputs for e in prog.outputs[name]]
        lines.append("    return [" + ", ".join(values) + "]")
        lines.append("")
    return "\n".join(lines)


def c_source(prog, functions: dict, chunk: int = CHUNK_STATEMENTS, cold: tuple = ()) -> str:
    """C source: ``void name(const double *q, const double *qd, const double *p,
    const double *u, double *out)`` per function, as one translation unit.

    Long programs are split into static functions of about ``chunk`` statements that
    pass only the values crossing a chunk boundary through a workspace array: a
    compiler's register allocation grows faster than linearly with function size,
    so this keeps compile time proportional to the program.  Functions named in
    ``cold`` (called per sample, not per step) are compiled without optimisation,
    which saves compile time where run time does not matter.  (``c_units`` gives the
    same functions as several units that compile in parallel.)
    """
    lines = [C_MATH]
    free = _free_symbols(prog)
    for fname, outputs in functions.items():
        attribute = _COLD_ATTRIBUTE if fname in cold else ""
        parts, main = _c_function(prog, fname, outputs, chunk, attribute, free)
        lines.extend(f"{attribute}static {text}" for text, _ in parts)
        lines.append(main)
    return "\n".join(lines)


@dataclass(frozen=True)
class CUnit:
    """One C translation unit of a model's library: its file stem, text, and whether it is
    hot (run per right-hand side: optimised) or cold (per output sample: unoptimised)."""

    name: str
    text: str
    hot: bool
    statements: int = 0  # its size, to start the longest compilations first


#: A cold function in an optimised unit.
_COLD_ATTRIBUTE = '__attribute__((optimize("O0"))) '
#: Part functions called from another unit: linked into one library, never exported from it.
_HIDDEN = '__attribute__((visibility("hidden"))) '
_ARGS = "const double *q, const double *qd, const double *p, const double *u"


#: What the hand-written C (the templates: integrators, formulations, solvers) uses of the C
#: library, declared instead of including <stdlib.h>, <string.h> and <math.h>: parsing them
#: is 8 % of the templates' compile (66 of 859 million compiler instructions, the 5-link
#: chain), and the compilers know these names as built-ins, so the machine code is the same
#: (tests/test_codegen.py).  <float.h> and <time.h> are the compiler's or cheap, and kept.
#: An undeclared call is an error (``-Werror=implicit-function-declaration``, backend.py).
C_TEMPLATE_LIBC = C_MATH + """#include <float.h>
#include <time.h>
typedef __SIZE_TYPE__ mb_size_t;
void *malloc(mb_size_t); void *calloc(mb_size_t, mb_size_t); void free(void *);
void *memcpy(void *, const void *, mb_size_t); void *memmove(void *, const void *, mb_size_t);
void *memset(void *, int, mb_size_t);
double fabs(double); double exp(double); double log(double); double nextafter(double, double);
#define NAN (__builtin_nanf(""))
#define INFINITY (__builtin_inff())
#define isfinite(x) __builtin_isfinite(x)
#define isnan(x) __builtin_isnan(x)
#define signbit(x) __builtin_signbit(x)
/* The compiled loops copy state vectors with this, not the C library's memcpy: a call of
   memcpy with a length known only at run time runs the library's widest version (AVX-512 on
   machines that have it), after which the generated SSE2 arithmetic ran 12-16 % slower
   (bench/state_copy.py).  Words when the sizes and addresses allow (every copy of doubles). */
static inline void *mb_copy(void *to, const void *from, mb_size_t n) {
    if (((n | (mb_size_t)to | (mb_size_t)from) & 7) == 0) {
        unsigned long long *d = to;
        const unsigned long long *s = from;
        for (mb_size_t i = 0; i < n / 8; ++i) d[i] = s[i];
    } else {
        unsigned char *d = to;
        const unsigned char *s = from;
        for (mb_size_t i = 0; i < n; ++i) d[i] = s[i];
    }
    return to;
}
"""


def c_prototypes(functions) -> str:
    """The C library declarations (``C_TEMPLATE_LIBC``) and the generated functions'
    declarations, for hand-written C compiled in its own unit."""
    return C_TEMPLATE_LIBC + "".join(f"void {name}({_ARGS}, double *out);\n" for name in functions)


def c_units(prog, functions: dict, cold: tuple = (), chunk: int = CHUNK_STATEMENTS, unit: int = 1500):
    """The functions of ``c_source`` as translation units of about ``unit`` statements,
    each hot or cold as a whole, yielded as they are printed (the caller compiles each
    while the next is printed).

    A function longer than ``unit`` gets units of its own, so that a compiler per core
    shares it; shorter ones are packed together, the hot ones apart from the cold ones
    (a small model: two units that compile side by side).  The chunks in the unit of their
    function stay ``static`` (the compiler inlines them and keeps the workspace in
    registers).  The same statements in the same order: the numbers are those of
    ``c_source``.  (``UnitStream`` gives the same units function by function, while the
    program is still being built.)"""
    stream = UnitStream(prog, cold=cold, chunk=chunk, unit=unit)
    for fname, outputs in functions.items():
        yield from stream.add({fname: outputs})
    yield from stream.flush()


class UnitStream:
    """``c_units`` fed function by function: the compiler prints a function's units as soon
    as the program builder has made its outputs final (``build_program(ready=...)``), so that
    they compile on another core while the rest of the program is built.

    Short functions are packed as in ``c_units``; a pack of at least ``eager`` statements is
    handed out at the end of the ``add`` that filled it instead of waiting for more (None:
    never, which gives exactly the units of ``c_units``)."""

    def __init__(self, prog, cold: tuple = (), chunk: int = CHUNK_STATEMENTS, unit: int = 1500,
                 eager: int | None = None, halve: int | None = None):
        self.prog, self.cold, self.chunk, self.unit, self.eager = prog, tuple(cold), chunk, unit, eager
        #: A hot function of more than ``halve`` statements (and at most ``unit``) gets two units
        #: of its own, one chunk each, that compile side by side (None: never).
        self.halve = halve
        self._packed = {True: ([], [0]), False: ([], [0])}  # hot / cold: texts, statements
        self._count = 0
        self._free: dict = {}

    def _free_symbols(self) -> dict:
        """``_free_symbols(prog)``, extended over the assignments added since the last call."""
        for symbol, expr in self.prog.assignments[len(self._free):]:
            self._free[symbol] = expr.free_symbols
        return self._free

    def _pack(self, hot: bool) -> CUnit:
        texts, size = self._packed[hot]
        out = CUnit(f"functions{self._count}", C_MATH + "\n" + "\n".join(texts), hot, size[0])
        self._count += 1
        texts.clear()
        size[0] = 0
        return out

    def add(self, functions: dict) -> list:
        """The units ready to compile once ``functions`` (``{name: [output names]}``, whose
        outputs are final) are printed."""
        units = []
        free = self._free_symbols()
        for fname, outputs in functions.items():
            hot = fname not in self.cold
            total = len(self.prog.needed(outputs, free))
            count = -(-total // self.unit)  # units of its own (1: packed with other functions)
            if hot and self.halve is not None and total > self.halve:
                # An optimising compiler's time grows faster than the function: two halves take
                # less time together than the whole (N = 5 chain: 0.17 s against 0.22 s), and
                # run on two cores.
                count = max(count, 2)
            # A function of several units: units of equal size (N = 20: 1024 + 1024 statements, not
            # 1500 + 548) made of equal chunks of at most ``chunk`` statements, the same
            # statements in the same order.
            unit, chunk = self.unit, self.chunk
            if count > 1:
                share = -(-total // count)
                per_unit = -(-share // chunk)
                chunk = -(-share // per_unit)
                unit = per_unit * chunk
            parts, main = _c_function(self.prog, fname, outputs, chunk, "", free)
            if total > unit:  # its own function only calls the chunks and copies the outputs out of
                # the workspace: optimising that took 1 s of 4.5 s at N = 50 and gained nothing
                main = main.replace(f"void {fname}(", f"{_COLD_ATTRIBUTE}void {fname}(", 1)
            if total <= unit:
                texts, size = self._packed[hot]
                if texts and size[0] + total > unit:
                    units.append(self._pack(hot))
                texts.append("".join(f"static {text}\n" for text, _ in parts) + main)
                size[0] += total
                continue
            groups, sizes = [[]], [0]
            for b, (text, size) in enumerate(parts):
                if groups[-1] and sizes[-1] + size > unit:
                    groups.append([])
                    sizes.append(0)
                groups[-1].append((b, text))
                sizes[-1] += size
            elsewhere = [b for group in groups[:-1] for b, _ in group]
            declarations = "".join(f"{_HIDDEN}void {fname}_part{b}({_ARGS}, double *w);\n" for b in elsewhere)
            for g, (group, size) in enumerate(zip(groups, sizes)):
                last = g == len(groups) - 1
                prefix = "static " if last else _HIDDEN
                body = "\n".join(prefix + text for _, text in group)
                if last:
                    body = declarations + "\n" + body + "\n" + main
                units.append(CUnit(f"{fname}{g}", C_MATH + "\n" + body, hot, size))
        if self.eager is not None:
            for hot, (texts, size) in self._packed.items():
                if texts and size[0] >= self.eager:
                    units.append(self._pack(hot))
        return units

    def apart(self, fname: str, outputs) -> tuple[str, int]:
        """``(C source, statements)`` of function ``fname`` (final ``outputs``) alone, as
        ``c_source`` prints it: for a library of its own (``OUTPUT_FUNCTIONS``, built in the
        background)."""
        parts, main = _c_function(self.prog, fname, outputs, self.chunk, "", self._free_symbols())
        text = C_MATH + "\n" + "".join(f"static {text}\n" for text, _ in parts) + main
        return text, sum(size for _, size in parts)

    #: A hot pack of at most this many statements left at ``flush`` (typically the empty
    #: ``constraints`` and ``drives`` of a tree) joins the cold pack: a compiler run of its own
    #: costs 40-70 ms for nothing to optimise.
    TINY_HOT = 30

    def flush(self) -> list:
        """The packs still waiting (hot first; a tiny hot pack goes with the cold one)."""
        hot_texts, hot_size = self._packed[True]
        if hot_texts and hot_size[0] <= self.TINY_HOT:
            cold_texts, cold_size = self._packed[False]
            cold_texts[:0] = hot_texts
            cold_size[0] += hot_size[0]
            hot_texts.clear()
            hot_size[0] = 0
        return [self._pack(hot) for hot, (texts, _) in self._packed.items() if texts]


def with_unit_text(units: list, name: str, text: str) -> list:
    """``units`` with ``text`` (C that needs no optimisation, e.g. a model's sizes) put in
    front of the last cold one, or as a cold unit ``name`` of its own where there is none:
    each compiler run costs 20-40 ms of start-up, and C compiled by the link command would
    sit on the build's critical path."""
    units = list(units)
    for k in range(len(units) - 1, -1, -1):
        if not units[k].hot:
            units[k] = replace(units[k], text=text + units[k].text)
            return units
    return units + [CUnit(name, text, False, 0)]


def _free_symbols(prog) -> dict:
    """``{symbol: free symbols of its expression}`` of every assignment, computed once per
    program (sympy walks the expression each time it is asked)."""
    return {symbol: expr.free_symbols for symbol, expr in prog.assignments}


def _c_function(prog, fname: str, outputs, chunk: int, main_prefix: str, free: dict | None = None):
    """``([(part text, statements)], main text)`` of one generated function: its chunks
    (``void name_partB(..., double *w) {...}``, for the caller to prefix with their linkage)
    and the function that calls them in order and writes the outputs, followed by its
    ``name_many``.  ``free``: ``_free_symbols(prog)`` when the caller has it."""
    import sympy as sp
    free = _free_symbols(prog) if free is None else free
    needed = prog.needed(outputs, free)
    results = [sp.sympify(e) for name in outputs for e in prog.outputs[name]]
    blocks = [needed[i:i + chunk] for i in range(0, len(needed), chunk)] or [[]]
    block_of = {symbol: b for b, block in enumerate(blocks) for symbol, _ in block}
    shared = {}
    for b, block in enumerate(blocks):
        for symbol, _ in block:
            for s in free[symbol]:
                if block_of.get(s, b) != b and s not in shared:
                    shared[s] = len(shared)
    for e in results:
        for s in e.free_symbols:
            if s in block_of and s not in shared:
                shared[s] = len(shared)
    names = _names(prog, "c")
    # Slots in definition order, not in the (hash-seeded) order of the symbol sets: the same
    # program always prints the same source.
    position = {symbol: k for k, (symbol, _) in enumerate(needed)}
    shared = {s: i for i, s in enumerate(sorted(shared, key=position.__getitem__))}
    names.update({s: f"w[{i}]" for s, i in shared.items()})
    printer = Printer(names, "c")
    parts = []
    for b, block in enumerate(blocks):
        lines = [f"void {fname}_part{b}({_ARGS}, double *w) {{"]
        for symbol, expr in block:
            if symbol in shared:
                lines.append(f"    w[{shared[symbol]}] = {printer(expr)};")
            else:
                lines.append(f"    const double {symbol.name} = {printer(expr)};")
        lines.append("}")
        lines.append("")
        parts.append(("\n".join(lines), len(block)))
    lines = [f"{main_prefix}void {fname}({_ARGS}, double *out) {{", f"    double w[{max(len(shared), 1)}];"]
    for b in range(len(blocks)):
        lines.append(f"    {fname}_part{b}(q, qd, p, u, w);")
    for k, e in enumerate(results):
        lines.append(f"    out[{k}] = {printer(e)};")
    lines.append("}")
    lines.append("")
    lines.append(c_many(fname, len(results)))
    return parts, "\n".join(lines)


#: ``name_many``: the function at ``m`` states in one call (rows of q, qd, u with the given
#: strides in doubles; a stride of 0 repeats the first row), ``size`` outputs per row
#: (``c/many.c``, placeholders ``@NAME@`` and ``@SIZE@``).
def c_many(name: str, size) -> str:
    """C of ``name_many`` for the function ``name`` of ``size`` outputs."""
    return c_text.fill(c_text.read("mbcomp.codegen", "many.c"), NAME=name, SIZE=size)


def c_late_stub(name: str, size: str, setter: str) -> str:
    """C of ``name`` (and ``name_many``) for a library built without it: it calls the
    separately built function once Python has passed its address to ``setter``, and writes
    NaN (``size`` values) before (a caller's finiteness check then sends it to the path that
    builds it: ``CFunctions``).  Part of the templates (after ``c_prototypes``); ``c/late_stub.c``."""
    return (c_text.fill(c_text.read("mbcomp.codegen", "late_stub.c"), NAME=name, SIZE=size, SETTER=setter)
            + c_many(name, size))


def c_dense_stub() -> str:
    """C of ``dynamics`` for a library built without the dense dynamics: it calls the
    separately built ``dynamics_dense`` once Python has set it (``set_dense_dynamics``)."""
    return c_late_stub("dynamics", "DYNAMICS_SIZE", "set_dense_dynamics")


def c_output_stubs(names) -> str:
    """C of the output functions ``names`` (``OUTPUT_FUNCTIONS``: energy, body kinematics),
    which each model builds into a library of their own (in the background): each calls its
    library's function once Python has set it (``set_<name>_impl``)."""
    return "".join(c_late_stub(name, f"{name.upper()}_SIZE", f"set_{name}_impl") for name in names)


def c_collide() -> str:
    """C of the collision features' narrow phase in the compiled loops (``c/collide.c``):
    gaps, Jacobian rows and acceleration biases of the candidate features from the body
    kinematics, configured per thread by ``mbcomp.compiled.collision_c``.  In every model's
    templates (a model without collisions never configures it)."""
    return c_text.read("mbcomp.codegen", "collide.c") + "\n\n"


def c_accelerations(nq: int | None = None) -> str:
    """C source of ``int accelerations(q, qd, p, u, tau, qdd, work)``: the tree's
    ``M qdd = f + tau`` solved by an in-place Cholesky factorisation of the packed
    lower triangle that ``dynamics`` writes.  Returns 0, or k + 1 when pivot k shows
    the mass matrix is not positive definite (same threshold as the Python path).
    ``work`` holds ``DYNAMICS_SIZE`` doubles (the offsets come from ``OutputLayout.c_names``);
    ``tau`` may be NULL.  ``nq``: define ``NQ`` here (None: the model's ``c_sizes`` unit gives it).
    The C is ``c/accelerations.c``, after the tolerances' ``#define``s (``core/tolerances.py``).
    """
    return (("" if nq is None else f"#define NQ {nq}\n") + tolerances.c_defines() + "\n"
            + c_text.read("mbcomp.codegen", "accelerations.c") + "\n\n")


# -- what the cache key needs ------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def generator_text() -> str:
    """The code generator's own text (version, printer, every C file of the package): part of the cache
    key, so that a changed generator never reuses code it did not write.  This module's whole
    file (reading it costs a tenth of a millisecond; ``inspect.getsource`` of its functions
    tokenizes it, ten milliseconds of every process that loads a model)."""
    try:
        parts = [Path(__file__).read_text(encoding="utf-8")]
    except OSError:
        try:
            parts = [inspect.getsource(obj) for obj in (Printer, _names, python_source, c_source, c_prototypes,
                                                       c_units, UnitStream, _c_function)]
        except (OSError, TypeError):
            parts = []
    return "\n".join([CODEGEN_VERSION, *parts, c_text.all_text()])


def load_python(source: str, key: str) -> dict[str, Callable]:
    """Compile generated Python source (our own output, never user text) into functions
    (each call its own namespace; the bytecode of a source compiled before is reused)."""
    namespace: dict = {}
    exec(_python_code(source, key), namespace)  # noqa: S102 - generated by codegen from the model structure
    return namespace


@functools.lru_cache(maxsize=32)
def _python_code(source: str, key: str):
    """The bytecode of generated Python source: compiling it is most of loading a model of
    the Python backend (straight-line functions of thousands of statements), and a process
    often loads one model more than once (each ``compile`` of an equal model)."""
    return compile(source, f"<mbcomp generated {key}>", "exec")
