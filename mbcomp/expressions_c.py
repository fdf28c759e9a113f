"""File expressions of time (``expressions.Expression``) evaluated in compiled loops.

A motor's position given in a model file is a small tree of numbers, ``t``, ``+ - * / **``,
negation and ``sin cos exp sqrt log`` calls.  Rather than generating C text per model
(which would make the compiled templates differ between models of the same structure),
the tree is flattened here into a postfix program of doubles that one C routine,
``mb_program``, evaluates: the same operations in the same order as
``expressions.evaluate`` (``pow`` for ``**``, as ``math.pow``), so compiled and
Python-stepped runs agree to rounding.

Program layout: ``[n, op_1, arg_1, ..., op_n, arg_n]`` (doubles); several programs may
follow each other in one array.
"""
from __future__ import annotations

import numpy as np

from .errors import ModelError

#: Opcodes (``arg`` is read by ``NUM`` only).
NUM, TIME, NEG, ADD, SUB, MUL, DIV, POW, SIN, COS, EXP, SQRT, LOG = range(13)
_BINARY = {"+": ADD, "-": SUB, "*": MUL, "/": DIV, "**": POW}
_CALLS = {"sin": SIN, "cos": COS, "exp": EXP, "sqrt": SQRT, "log": LOG}

#: Deepest evaluation stack the C routine has room for.
STACK = 64


def compile_program(node: tuple, owner: str = "expression") -> np.ndarray:
    """The postfix program of an expression tree (``expressions`` node tuples).
    ``ModelError`` for a node outside the language or a tree deeper than ``STACK``."""
    ops: list[float] = []
    depth = 0

    def emit(op: int, arg: float = 0.0, change: int = 0) -> None:
        nonlocal depth
        ops.extend((float(op), float(arg)))
        depth += change
        if depth > peak[0]:
            peak[0] = depth

    peak = [0]

    def walk(n: tuple) -> None:
        kind = n[0]
        if kind == "num":
            emit(NUM, n[1], 1)
        elif kind == "t":
            emit(TIME, 0.0, 1)
        elif kind == "neg":
            walk(n[1])
            emit(NEG)
        elif kind == "call" and n[1] in _CALLS:
            walk(n[2])
            emit(_CALLS[n[1]])
        elif kind in _BINARY:
            walk(n[1])
            walk(n[2])
            emit(_BINARY[kind], 0.0, -1)
        else:
            raise ModelError(owner, f"cannot evaluate {kind!r} in compiled code")

    walk(node)
    if peak[0] > STACK:
        raise ModelError(owner, f"expression needs {peak[0]} stack entries, more than the compiled {STACK}")
    return np.array([len(ops) // 2, *ops], dtype=float)


def compile_position(expression) -> np.ndarray | None:
    """Programs of a motor position ``s(t)`` and its exact first and second derivatives, one
    after the other; None when ``expression`` is not a file expression (a Python callable)."""
    node = getattr(expression, "node", None)
    if node is None or not callable(getattr(expression, "diff", None)):
        return None
    first = expression.diff()
    second = first.diff()
    owner = getattr(expression, "owner", "expression")
    return np.concatenate([compile_program(e.node, owner) for e in (expression, first, second)])


def run_program(program: np.ndarray, t: float) -> float:
    """Evaluate one program at ``t`` in Python (the C routine's reference, for tests)."""
    import math
    stack: list[float] = []
    n = int(program[0])
    for k in range(n):
        op, arg = int(program[1 + 2 * k]), float(program[2 + 2 * k])
        if op == NUM:
            stack.append(arg)
        elif op == TIME:
            stack.append(t)
        elif op == NEG:
            stack[-1] = -stack[-1]
        elif op in (SIN, COS, EXP, SQRT, LOG):
            stack[-1] = {SIN: math.sin, COS: math.cos, EXP: math.exp, SQRT: math.sqrt, LOG: math.log}[op](stack[-1])
        else:
            b = stack.pop()
            a = stack.pop()
            stack.append({ADD: a + b, SUB: a - b, MUL: a * b}.get(op) if op in (ADD, SUB, MUL)
                         else a / b if op == DIV else math.pow(a, b))
    return stack[-1]


#: The C evaluator: ``mb_program(&prog, t)`` returns the value of the program at ``prog``
#: and advances ``prog`` past it (NaN on a domain error, as C's libm gives).
C_PROGRAM = f"""
#ifndef MB_PROGRAM_DEFINED
#define MB_PROGRAM_DEFINED 1
static double mb_program(const double **prog, double t) {{
    const double *pc = *prog;
    const long n = (long)pc[0];
    double st[{STACK} + 1];
    int sp = -1;
    for (long k = 0; k < n; ++k) {{
        const int op = (int)pc[1 + 2 * k];
        switch (op) {{
        case {NUM}: st[++sp] = pc[2 + 2 * k]; break;
        case {TIME}: st[++sp] = t; break;
        case {NEG}: st[sp] = -st[sp]; break;
        case {SIN}: st[sp] = sin(st[sp]); break;
        case {COS}: st[sp] = cos(st[sp]); break;
        case {EXP}: st[sp] = exp(st[sp]); break;
        case {SQRT}: st[sp] = sqrt(st[sp]); break;
        case {LOG}: st[sp] = log(st[sp]); break;
        default: {{
            const double b = st[sp--], a = st[sp];
            st[sp] = op == {ADD} ? a + b : op == {SUB} ? a - b : op == {MUL} ? a * b : op == {DIV} ? a / b : pow(a, b);
        }}
        }}
    }}
    *prog = pc + 1 + 2 * n;
    return sp >= 0 ? st[sp] : NAN;
}}
#endif
"""
