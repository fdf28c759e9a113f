"""File expressions of time (``expressions.Expression``) evaluated in compiled loops.

A motor's position given in a model file is a small tree of numbers, ``t``, ``+ - * / **``,
negation and ``sin cos exp sqrt log`` calls.  Rather than generating C text per model
(which would make the compiled templates differ between models of the same structure),
the tree is flattened here into a postfix program of doubles that one C routine,
``mb_program``, evaluates: the same operations in the same order as
``expressions.evaluate`` (``pow`` for ``**``, as ``math.pow``), so compiled and
Python-stepped runs agree to rounding.  Both formulations' compiled loops use it
(``formulations/dae_c.py``, ``formulations/lagrange_c.py``).

Where Python's evaluation raises (division by zero, ``sqrt`` of a negative number, ``log``
of a non-positive one), ``mb_program`` gives NaN (and an overflow gives an infinity): the
loops treat a non-finite value as a failed step and the caller raises the same
``SimulationError`` as Python stepping.

Program layout: ``[n, op_1, arg_1, ..., op_n, arg_n]`` (doubles); several programs may
follow each other in one array.
"""
from __future__ import annotations

import numpy as np

from mbcomp.core import c_text
from mbcomp.core.errors import ModelError

#: Opcodes (``arg`` is read by ``NUM`` only).
NUM, TIME, NEG, ADD, SUB, MUL, DIV, POW, SIN, COS, EXP, SQRT, LOG = range(13)
_BINARY = {"+": ADD, "-": SUB, "*": MUL, "/": DIV, "**": POW}
_CALLS = {"sin": SIN, "cos": COS, "exp": EXP, "sqrt": SQRT, "log": LOG}

#: Deepest evaluation stack the C routine has room for.
STACK = 256


class NotCompilable(ModelError):
    """An expression ``mb_program`` cannot run (a node outside the language, a linked
    parameter object, a stack deeper than ``STACK``): it is evaluated in Python instead."""


def compile_program(node: tuple, owner: str = "expression") -> np.ndarray:
    """The postfix program of an expression tree (``expressions`` node tuples).
    ``NotCompilable`` (a ``ModelError``) for a node outside the language or a tree deeper
    than ``STACK``."""
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
        elif kind == "call":
            raise NotCompilable(owner, f"function {n[1]!r} has no compiled form")
        else:
            raise NotCompilable(owner, f"a {kind!r} node (a linked parameter object) has no compiled form")

    walk(node)
    if peak[0] > STACK:
        raise NotCompilable(owner, f"the expression needs a stack of {peak[0]} values (the compiled evaluator "
                                   f"has {STACK})")
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


def programs(trees: list[tuple], owner: str = "expression") -> np.ndarray:
    """The programs of several expression trees, one after the other in one array."""
    return np.concatenate([compile_program(tree, owner) for tree in trees]) if trees else np.zeros(0)


def run_program(program: np.ndarray, t: float, index: int = 0) -> float:
    """Evaluate program ``index`` of an array of programs at ``t`` in Python, with the C
    routine's rules (NaN where Python's evaluation raises): its reference, for tests."""
    import math
    start = 0
    for _ in range(index):
        start += 1 + 2 * int(program[start])
    stack: list[float] = []
    n = int(program[start])
    for k in range(n):
        op, arg = int(program[start + 1 + 2 * k]), float(program[start + 2 + 2 * k])
        if op == NUM:
            stack.append(arg)
        elif op == TIME:
            stack.append(t)
        elif op == NEG:
            stack[-1] = -stack[-1]
        elif op in (SIN, COS, EXP):
            try:
                stack[-1] = {SIN: math.sin, COS: math.cos, EXP: math.exp}[op](stack[-1])
            except OverflowError:
                stack[-1] = math.inf
        elif op == SQRT:
            stack[-1] = math.sqrt(stack[-1]) if stack[-1] >= 0.0 else math.nan
        elif op == LOG:
            stack[-1] = math.log(stack[-1]) if stack[-1] > 0.0 else math.nan
        else:
            b = stack.pop()
            a = stack.pop()
            if op == DIV:
                stack.append(a / b if b != 0.0 else math.nan)
            elif op == POW:
                try:
                    stack.append(math.pow(a, b))
                except (OverflowError, ValueError):
                    stack.append(math.nan)
            else:
                stack.append({ADD: a + b, SUB: a - b, MUL: a * b}[op])
    return stack[-1]


#: The ``#define``s of ``c/program.h``: the opcodes and the stack depth.
C_DEFINES = "".join(f"#define MB_OP_{name} {code}\n" for name, code in (
    ("NUM", NUM), ("TIME", TIME), ("NEG", NEG), ("ADD", ADD), ("SUB", SUB), ("MUL", MUL), ("DIV", DIV), ("POW", POW),
    ("SIN", SIN), ("COS", COS), ("EXP", EXP), ("SQRT", SQRT), ("LOG", LOG))) + f"#define MB_PROGRAM_STACK {STACK}\n"

#: The C evaluator (``c/program.h``, after ``C_DEFINES``): ``mb_program(&prog, t)`` returns the
#: value of the program at ``prog`` and advances ``prog`` past it (NaN on a domain error, as
#: C's libm gives).
C_PROGRAM = C_DEFINES + c_text.read("mbcomp.codegen", "program.h")
