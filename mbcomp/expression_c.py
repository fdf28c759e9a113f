"""Time expressions (``expressions.py`` node trees) evaluated in compiled loops.

A motor's prescribed position read from a model file is a whitelisted expression tree of
``t``.  The compiled loops evaluate it, and its exact first and second time derivatives, in
C: each tree is flattened here into a stack program (postfix: operands first), and one
small C evaluator (``C_EVALUATOR``, included by the formulations' C code) runs the programs
from arrays the Python side owns.  The generated library therefore does not depend on the
expression (a model with another motor law reuses the same compiled code), and the C code
computes the same operations in the same order as ``expressions.evaluate`` (results equal to
rounding; the C library's ``sin``, ``cos``, ``exp``, ``log``, ``sqrt`` and ``pow``).

Errors: where Python's evaluation raises (division by zero, ``sqrt`` of a negative number,
overflow), C produces a NaN or an infinity; the evaluator reports a non-finite result and
the caller raises the same ``SimulationError`` as Python stepping by evaluating the
expression in Python at that time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Opcodes of the stack program (``C_EVALUATOR`` uses the same numbers).
OPCODES = {"num": 0, "t": 1, "+": 2, "-": 3, "*": 4, "/": 5, "**": 6, "neg": 7,
           "sin": 8, "cos": 9, "exp": 10, "sqrt": 11, "log": 12}

#: The evaluator's stack size: deeper programs are not compiled (Python evaluates them).
STACK_SIZE = 256


class NotCompilable(ValueError):
    """A tree the C evaluator cannot run (the message says why)."""


def _emit(node: tuple, ops: list[int], args: list[float]) -> int:
    """Append ``node``'s postfix program; returns the stack depth it needs."""
    kind = node[0]
    if kind == "num":
        ops.append(OPCODES["num"])
        args.append(float(node[1]))
        return 1
    if kind == "t":
        ops.append(OPCODES["t"])
        args.append(0.0)
        return 1
    if kind == "neg":
        depth = _emit(node[1], ops, args)
        ops.append(OPCODES["neg"])
        args.append(0.0)
        return depth
    if kind == "call":
        if node[1] not in OPCODES:
            raise NotCompilable(f"function {node[1]!r} has no compiled form")
        depth = _emit(node[2], ops, args)
        ops.append(OPCODES[node[1]])
        args.append(0.0)
        return depth
    if kind in ("+", "-", "*", "/", "**"):
        left = _emit(node[1], ops, args)
        right = _emit(node[2], ops, args)
        ops.append(OPCODES[kind])
        args.append(0.0)
        return max(left, 1 + right)
    raise NotCompilable(f"a {kind!r} node (a linked parameter object) has no compiled form")


@dataclass(frozen=True)
class StackPrograms:
    """Several stack programs in two arrays: program ``i`` is ``ops[start[i]:start[i + 1]]``
    (opcodes, int64) with ``args`` (float64: the constants of ``num`` entries)."""

    ops: np.ndarray
    args: np.ndarray
    start: np.ndarray

    def __len__(self) -> int:
        return len(self.start) - 1

    def evaluate(self, i: int, t: float) -> float:
        """Program ``i`` at time ``t`` in numpy (the C evaluator's reference; for tests)."""
        stack: list[float] = []
        binary = {2: np.add, 3: np.subtract, 4: np.multiply, 5: np.divide, 6: np.power}
        unary = {7: np.negative, 8: np.sin, 9: np.cos, 10: np.exp, 11: np.sqrt, 12: np.log}
        with np.errstate(all="ignore"):
            for op, arg in zip(self.ops[self.start[i]:self.start[i + 1]], self.args[self.start[i]:self.start[i + 1]]):
                if op == 0:
                    stack.append(float(arg))
                elif op == 1:
                    stack.append(float(t))
                elif op in binary:
                    b = stack.pop()
                    stack.append(float(binary[op](stack.pop(), b)))
                else:
                    stack.append(float(unary[op](stack.pop())))
        return stack[0]


def stack_programs(trees: list[tuple]) -> StackPrograms:
    """The stack programs of ``trees`` (``expressions`` node trees) in one ``StackPrograms``.
    ``NotCompilable`` for a tree with nodes the evaluator lacks or deeper than its stack."""
    ops: list[int] = []
    args: list[float] = []
    start = [0]
    for tree in trees:
        depth = _emit(tree, ops, args)
        if depth > STACK_SIZE:
            raise NotCompilable(f"the expression needs a stack of {depth} values (the compiled evaluator has "
                                f"{STACK_SIZE})")
        start.append(len(ops))
    return StackPrograms(np.asarray(ops, dtype=np.int64), np.asarray(args, dtype=float),
                         np.asarray(start, dtype=np.int64))


C_EVALUATOR = r"""
#ifndef MBC_STACK_EVALUATOR
#define MBC_STACK_EVALUATOR 1
#include <math.h>
/* Run the stack program ops[0..n) (constants in args) at time t: its value, NaN or an
   infinity where the arithmetic fails (the caller checks isfinite). */
static double mbc_stack_eval(const long *ops, const double *args, long n, double t) {
    double s[@STACK@];
    int k = 0;
    for (long i = 0; i < n; ++i) {
        switch (ops[i]) {
        case 0: s[k++] = args[i]; break;
        case 1: s[k++] = t; break;
        case 2: --k; s[k - 1] = s[k - 1] + s[k]; break;
        case 3: --k; s[k - 1] = s[k - 1] - s[k]; break;
        case 4: --k; s[k - 1] = s[k - 1] * s[k]; break;
        case 5: --k; s[k - 1] = s[k] == 0.0 ? NAN : s[k - 1] / s[k]; break;
        case 6: --k; s[k - 1] = pow(s[k - 1], s[k]); break;
        case 7: s[k - 1] = -s[k - 1]; break;
        case 8: s[k - 1] = sin(s[k - 1]); break;
        case 9: s[k - 1] = cos(s[k - 1]); break;
        case 10: s[k - 1] = exp(s[k - 1]); break;
        case 11: s[k - 1] = s[k - 1] < 0.0 ? NAN : sqrt(s[k - 1]); break;
        case 12: s[k - 1] = s[k - 1] <= 0.0 ? NAN : log(s[k - 1]); break;
        default: return NAN;
        }
    }
    return k == 1 ? s[0] : NAN;
}
#endif
""".replace("@STACK@", str(STACK_SIZE))
