"""sympy straight-line programs -> numeric functions (Python or C source)."""
from __future__ import annotations

import functools
import inspect
from typing import Callable

import sympy as sp

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


def c_source(prog, functions: dict, chunk: int = 300, cold: tuple = ()) -> str:
    """C source: ``void name(const double *q, const double *qd, const double *p,
    const double *u, double *out)`` per function.

    Long programs are split into static functions of about ``chunk`` statements that
    pass only the values crossing a chunk boundary through a workspace array: a
    compiler's register allocation grows faster than linearly with function size,
    so this keeps compile time proportional to the program.  Functions named in
    ``cold`` (called per sample, not per step) are compiled without optimisation,
    which saves compile time where run time does not matter.
    """
    lines = ["#include <math.h>", ""]
    for fname, outputs in functions.items():
        needed = prog.needed(outputs)
        results = [sp.sympify(e) for name in outputs for e in prog.outputs[name]]
        blocks = [needed[i:i + chunk] for i in range(0, len(needed), chunk)] or [[]]
        block_of = {symbol: b for b, block in enumerate(blocks) for symbol, _ in block}
        shared = {}
        for b, block in enumerate(blocks):
            for _, expr in block:
                for s in expr.free_symbols:
                    if block_of.get(s, b) != b and s not in shared:
                        shared[s] = len(shared)
        for e in results:
            for s in e.free_symbols:
                if s in block_of and s not in shared:
                    shared[s] = len(shared)
        names = _names(prog, "c")
        names.update({s: f"w[{i}]" for s, i in shared.items()})
        printer = Printer(names, "c")
        args = "const double *q, const double *qd, const double *p, const double *u"
        attribute = '__attribute__((optimize("O0"))) ' if fname in cold else ""
        for b, block in enumerate(blocks):
            lines.append(f"{attribute}static void {fname}_part{b}({args}, double *w) {{")
            for symbol, expr in block:
                if symbol in shared:
                    lines.append(f"    w[{shared[symbol]}] = {printer(expr)};")
                else:
                    lines.append(f"    const double {symbol.name} = {printer(expr)};")
            lines.append("}")
            lines.append("")
        lines.append(f"{attribute}void {fname}({args}, double *out) {{")
        lines.append(f"    double w[{max(len(shared), 1)}];")
        for b in range(len(blocks)):
            lines.append(f"    {fname}_part{b}(q, qd, p, u, w);")
        for k, e in enumerate(results):
            lines.append(f"    out[{k}] = {printer(e)};")
        lines.append("}")
        lines.append("")
        lines.append(MANY_TEMPLATE.format(name=fname, size=len(results)))
    return "\n".join(lines)


#: ``name_many``: the function at ``m`` states in one call (rows of q, qd, u with the given
#: strides in doubles; a stride of 0 repeats the first row), ``size`` outputs per row.
MANY_TEMPLATE = """void {name}_many(long m, const double *q, long sq, const double *qd, long sqd, const double *p,
                const double *u, long su, double *out) {{
    for (long i = 0; i < m; ++i) {name}(q + i * sq, qd + i * sqd, p, u + i * su, out + i * {size});
}}
"""


def c_accelerations(nq: int) -> str:
    """C source of ``int accelerations(q, qd, p, u, tau, qdd, work)``: the tree's
    ``M qdd = f + tau`` solved by an in-place Cholesky factorisation of the packed
    lower triangle that ``dynamics`` writes.  Returns 0, or k + 1 when pivot k shows
    the mass matrix is not positive definite (same threshold as the Python path).
    ``work`` holds ``DYNAMICS_SIZE`` doubles (the offsets come from ``OutputLayout.c_defines``);
    ``tau`` may be NULL.
    """
    return f"""
#define NQ {nq}
#define IDX(i, j) ((i) * ((i) + 1) / 2 + (j))
/* M = L L^T in place on the packed lower triangle; 0, or k + 1 when pivot k is not
   positive against the largest diagonal entry. */
static int mass_cholesky(double *L) {{
    double scale = 1e-300;
    for (int i = 0; i < NQ; ++i) if (fabs(L[IDX(i, i)]) > scale) scale = fabs(L[IDX(i, i)]);
    for (int j = 0; j < NQ; ++j) {{
        double s = L[IDX(j, j)];
        for (int k = 0; k < j; ++k) s -= L[IDX(j, k)] * L[IDX(j, k)];
        if (!(s > 1e-13 * scale)) return j + 1;
        const double d = sqrt(s);
        L[IDX(j, j)] = d;
        for (int i = j + 1; i < NQ; ++i) {{
            double t = L[IDX(i, j)];
            for (int k = 0; k < j; ++k) t -= L[IDX(i, k)] * L[IDX(j, k)];
            L[IDX(i, j)] = t / d;
        }}
    }}
    return 0;
}}

/* b <- L^-1 b and b <- L^-T b with the packed factor. */
static void lower_solve(const double *L, double *b) {{
    for (int i = 0; i < NQ; ++i) {{
        double s = b[i];
        for (int k = 0; k < i; ++k) s -= L[IDX(i, k)] * b[k];
        b[i] = s / L[IDX(i, i)];
    }}
}}

static void upper_solve(const double *L, double *b) {{
    for (int i = NQ - 1; i >= 0; --i) {{
        double s = b[i];
        for (int k = i + 1; k < NQ; ++k) s -= L[IDX(k, i)] * b[k];
        b[i] = s / L[IDX(i, i)];
    }}
}}

int accelerations(const double *q, const double *qd, const double *p, const double *u,
                  const double *tau, double *qdd, double *work) {{
    double *L = work + DYNAMICS_MASS_MATRIX_OFF, *f = work + DYNAMICS_FORCES_OFF;
    dynamics(q, qd, p, u, work);
    for (int i = 0; i < NQ; ++i) qdd[i] = f[i] + (tau ? tau[i] : 0.0);
    const int status = mass_cholesky(L);
    if (status) return status;
    lower_solve(L, qdd);
    upper_solve(L, qdd);
    return 0;
}}
"""


# -- what the cache key needs ------------------------------------------------------------------
@functools.lru_cache(maxsize=1)
def generator_text() -> str:
    """The code generator's own text (version, printer, source templates): part of the cache
    key, so that a changed generator never reuses code it did not write."""
    try:
        parts = [inspect.getsource(obj) for obj in (Printer, _names, python_source, c_source)]
    except (OSError, TypeError):
        parts = []
    return "\n".join([CODEGEN_VERSION, *parts, MANY_TEMPLATE])


def load_python(source: str, key: str) -> dict[str, Callable]:
    """Compile generated Python source (our own output, never user text) into functions."""
    namespace: dict = {}
    code = compile(source, f"<mbcomp generated {key}>", "exec")
    exec(code, namespace)  # noqa: S102 - generated by codegen from the model structure
    return namespace
