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

A motor whose position is a Python callable (or an expression the evaluator cannot run)
runs compiled too: its three programs are one ``SLOT`` instruction each, which reads value
``arg`` of the motors' slots ``mb_motor_slot`` (``c/inputs.h``) fills by calling back into
Python once per evaluated time (``codegen/callbacks.py``: ``s, s', s''`` of each such motor,
``ConstraintSet.position_derivatives``, the values Python stepping uses).

Program layout: ``[n, op_1, arg_1, ..., op_n, arg_n]`` (doubles); several programs may
follow each other in one array.
"""
from __future__ import annotations

import numpy as np

from mbcomp.core import c_text
from mbcomp.core.errors import ModelError

#: Opcodes (``arg`` is read by ``NUM``, the number, and ``SLOT``, the slot's index).
NUM, TIME, NEG, ADD, SUB, MUL, DIV, POW, SIN, COS, EXP, SQRT, LOG, SLOT = range(14)
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


def slot_programs(j: int) -> np.ndarray:
    """The three programs (``s, s', s''``) of the j-th motor whose position Python evaluates:
    slots ``3 j``, ``3 j + 1``, ``3 j + 2`` of the values the motor callback fills."""
    return np.array([v for k in range(3) for v in (1.0, float(SLOT), float(3 * j + k))], dtype=float)


def position_programs(constraints) -> tuple[dict[int, np.ndarray], list[int]]:
    """The programs of every motor row of ``constraints`` (a ``ConstraintSet``) that prescribes
    its position: ``({row: programs}, python_rows)``.  A position given as an expression of
    t runs as its own programs (the expression and the exact derivatives Python stepping
    uses, ``ConstraintSet.exact_derivatives``); any other (a Python callable, an expression
    the evaluator cannot run) as ``slot_programs(j)``, j its index in ``python_rows``."""
    out: dict[int, np.ndarray] = {}
    python_rows: list[int] = []
    for r in constraints.coordinate_rows:
        eq = constraints.equations[r]
        if eq.speed is not None:
            continue
        exact = constraints.exact_derivatives.get(r)
        nodes = [getattr(f, "node", None) for f in (eq.position, *(exact or ()))]
        if exact is not None and all(node is not None for node in nodes):
            try:
                out[r] = programs(nodes, constraints.owner[r])
                continue
            except NotCompilable:
                pass
        out[r] = slot_programs(len(python_rows))
        python_rows.append(r)
    return out, python_rows


def python_positions(constraints) -> list[int]:
    """The motor rows whose position Python evaluates for the compiled code (``SLOT``
    programs), in slot order; empty without constraints."""
    return [] if constraints is None else position_programs(constraints)[1]


def fill_slots(program: np.ndarray, values) -> np.ndarray:
    """A copy of an array of programs whose ``SLOT`` instructions push the numbers ``values``
    (indexed by slot) instead: for one evaluation at a known time, without the callback."""
    out = np.array(program, dtype=float)
    start = 0
    while start < out.size:
        n = int(out[start])
        for k in range(n):
            at = start + 1 + 2 * k
            if int(out[at]) == SLOT:
                out[at], out[at + 1] = float(NUM), float(values[int(out[at + 1])])
        start += 1 + 2 * n
    return out


def programs(trees: list[tuple], owner: str = "expression") -> np.ndarray:
    """The programs of several expression trees, one after the other in one array."""
    return np.concatenate([compile_program(tree, owner) for tree in trees]) if trees else np.zeros(0)


def run_program(program: np.ndarray, t: float, index: int = 0, slots=None) -> float:
    """Evaluate program ``index`` of an array of programs at ``t`` in Python, with the C
    routine's rules (NaN where Python's evaluation raises; ``slots``: the values ``SLOT``
    reads): its reference, for tests."""
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
        elif op == SLOT:
            stack.append(math.nan if slots is None else float(slots[int(arg)]))
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
    ("SIN", SIN), ("COS", COS), ("EXP", EXP), ("SQRT", SQRT), ("LOG", LOG), ("SLOT", SLOT))) + f"#define MB_PROGRAM_STACK {STACK}\n"

#: The C evaluator (``c/program.h``, after ``C_DEFINES``): ``mb_program(&prog, t)`` returns the
#: value of the program at ``prog`` and advances ``prog`` past it (NaN on a domain error, as
#: C's libm gives).
C_PROGRAM = C_DEFINES + c_text.read("mbcomp.codegen", "program.h")
