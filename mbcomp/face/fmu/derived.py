"""Model parameters in an exported FMU: a model file's top-level ``[parameters]`` and
sub-model parameters (``System.parameters`` entries such as ``"L"`` or ``"upper.length"``)
that component values are computed from.

mbcomp recomputes the derived values in Python on a change (``Derivation.apply``: the
components are built again with the new numbers).  The FMU has no Python: each derived
entry of the parameter vector ``p``, and each parameter bound to an expression of earlier
ones (``m = rho*width*thickness*L``), becomes a postfix program over the model parameters
that the C evaluates when the FMU is initialised (``fmu_derive`` in ``c/fmu2.c``).  A value
set by the importer wins over its expression, as in ``System.with_parameters``.

Only what the programs reproduce is exported: each model parameter is changed once here
(``Derivation.apply``, the components rebuilt) and every value it changes is compared with
the programs' values; a parameter whose change the programs do not reproduce (a
constructor that transforms its argument), or that is compiled into code (an expression of
``t``), is not a variable of the FMU.
"""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass, field

import numpy as np

from mbcomp.core.errors import ModelError

#: Opcodes of the programs (``fmu_eval`` in ``c/fmu2.c``): ``[n, op, arg, ...]``; ``PARAM``
#: reads model parameter ``arg``.
NUM, PARAM, NEG, ABS, SQRT, SIN, COS, TAN, EXP, LOG, ADD, SUB, MUL, DIV, POW = range(15)
_UNARY = {"neg": NEG, "abs": ABS, "sqrt": SQRT, "sin": SIN, "cos": COS, "tan": TAN, "exp": EXP, "log": LOG}
_BINARY = {"+": ADD, "-": SUB, "*": MUL, "/": DIV, "**": POW}


class NoProgram(Exception):
    """An expression outside the programs' language."""


def program(value, index: dict[str, int]) -> list[float]:
    """The postfix program of ``value`` (a number or an ``Expr``) over the parameters ``index``."""
    ops: list[float] = []

    def walk(e) -> None:
        op = getattr(e, "op", None)
        if op is None:
            ops.extend((NUM, float(e)))
        elif op == "param":
            if e.args[0] not in index:
                raise NoProgram(e.args[0])
            ops.extend((PARAM, index[e.args[0]]))
        elif op in _BINARY:
            walk(e.args[0])
            walk(e.args[1])
            ops.extend((_BINARY[op], 0.0))
        elif op in _UNARY:
            walk(e.args[0])
            ops.extend((_UNARY[op], 0.0))
        else:
            raise NoProgram(op)
    walk(value)
    return [len(ops) // 2, *ops]


def run(prog: list[float], env: list[float]) -> float:
    """Python's evaluation of a program (as the C's; the check against ``Derivation.apply``)."""
    stack: list[float] = []
    for k in range(int(prog[0])):
        op, arg = int(prog[1 + 2 * k]), prog[2 + 2 * k]
        if op == NUM:
            stack.append(float(arg))
        elif op == PARAM:
            stack.append(env[int(arg)])
        elif op in (ADD, SUB, MUL, DIV, POW):
            b, a = stack.pop(), stack.pop()
            try:
                stack.append(a + b if op == ADD else a - b if op == SUB else a * b if op == MUL
                             else a / b if op == DIV else math.pow(a, b))
            except (ZeroDivisionError, ValueError, OverflowError):
                stack.append(math.nan)
        else:
            x = stack.pop()
            f = {NEG: lambda v: -v, ABS: abs, SQRT: math.sqrt, SIN: math.sin, COS: math.cos, TAN: math.tan,
                 EXP: math.exp, LOG: math.log}[op]
            try:
                stack.append(f(x))
            except (ValueError, OverflowError):
                stack.append(math.nan)
    return stack[-1]


@dataclass
class Derived:
    """The exported model parameters and how ``p`` follows them."""

    names: list = field(default_factory=list)      #: model parameters that are FMU variables
    values: list = field(default_factory=list)     #: their values
    units: list = field(default_factory=list)
    env: list = field(default_factory=list)        #: every model parameter, in instantiation order
    exported: list = field(default_factory=list)   #: index in ``env`` of each exported one
    bindings: list = field(default_factory=list)   #: per env entry: program offset, or -1 (not following)
    entries: list = field(default_factory=list)    #: (index in p, program offset) of each derived entry
    programs: list = field(default_factory=list)   #: the programs, one after another


def _arguments(comp) -> dict:
    """The component's constructor arguments by name (as ``expression_args`` keeps them)."""
    args, kwargs = comp.expression_args
    try:
        bound = inspect.signature(type(comp)).bind_partial(*args, **kwargs)
    except TypeError:
        return dict(kwargs)
    out = {}
    for name, value in bound.arguments.items():
        kind = inspect.signature(type(comp)).parameters[name].kind
        if kind is inspect.Parameter.VAR_KEYWORD:
            out.update(value)
        elif kind is not inspect.Parameter.VAR_POSITIONAL:
            out[name] = value
    return out


def derived_parameters(system) -> Derived:
    """The model parameters of ``system`` that the FMU can take (see the module docstring)."""
    out = Derived()
    compiled = system.kernel.compiled
    derivation = getattr(compiled, "derivation", None)
    if derivation is None or not derivation.parameters:
        return out
    layout = compiled.layout.entries
    current = dict(system.parameters)
    names = list(derivation.parameters)
    index = {name: k for k, name in enumerate(names)}
    out.env = [float(current[name]) for name in names]

    def add(prog: list[float]) -> int:
        offset = len(out.programs)
        out.programs.extend(prog)
        return offset

    for name in names:
        binding = derivation.parameters[name].binding
        follows = getattr(binding, "op", None) is not None and current[name] == binding.evaluate(current)
        try:
            out.bindings.append(add(program(binding, index)) if follows else -1)
        except NoProgram:
            out.bindings.append(-1)
    derived_p: dict[int, list[float]] = {}
    for full, comp, _ in derivation.components:
        arguments = _arguments(comp)
        for attr in comp.parameter_values():
            key = f"{full}.{attr}"
            if key not in layout or attr not in arguments:
                continue
            start, shape = layout[key]
            value = arguments[attr]
            values = [value] if not shape else list(value) if isinstance(value, (tuple, list)) else None
            if values is None or len(values) != (shape[0] if shape else 1):
                continue
            try:
                for i, v in enumerate(values):
                    if getattr(v, "op", None) is not None:
                        derived_p[start + i] = program(v, index)
            except NoProgram:
                continue
    if derivation.gravity is not None and "gravity" in layout:
        start, _ = layout["gravity"]
        for i, v in enumerate(derivation.gravity):
            if getattr(v, "op", None) is not None:
                try:
                    derived_p[start + i] = program(v, index)
                except NoProgram:
                    pass
    for p_index, prog in sorted(derived_p.items()):
        out.entries.append((p_index, add(prog)))
    p_keys = {}
    for key, (start, shape) in layout.items():
        for i in range(shape[0] if shape else 1):
            p_keys[start + i] = (key, i if shape else None)
    for k, name in enumerate(names):
        if name in layout:  # (a name that is also a component value: not this parameter)
            continue
        if _reproduced(derivation, current, names, k, out, derived_p, p_keys, system.kernel.p):
            out.names.append(name)
            out.values.append(out.env[k])
            out.exported.append(k)
            out.units.append(getattr(derivation.parameters[name].spec, "unit", "") or "")
    return out


def _reproduced(derivation, current, names, k, out, derived_p, p_keys, p) -> bool:
    """Whether changing model parameter ``names[k]`` gives, through the programs, what
    ``Derivation.apply`` gives (every model parameter and every value of ``p``)."""
    value = out.env[k]
    new = value * (1.0 + 1e-3) + 1e-4
    try:
        updates = derivation.apply(current, {names[k]: new})
    except (ModelError, ValueError, TypeError):
        return False
    env = list(out.env)
    env[k] = new
    for j in range(len(env)):
        if j != k and out.bindings[j] >= 0:
            offset = out.bindings[j]
            env[j] = run(out.programs[offset:], env)
    for j, name in enumerate(names):
        if name in updates and not _close(updates[name], env[j]):
            return False
    p_new = np.array(p, dtype=float)
    for p_index, prog in derived_p.items():
        p_new[p_index] = run(prog, env)
    for p_index, (key, i) in p_keys.items():
        if key in updates:
            expected = updates[key] if i is None else updates[key][i]
            if not _close(expected, p_new[p_index]):
                return False
        elif p_new[p_index] != p[p_index] and not _close(p_new[p_index], p[p_index]):
            return False
    return True


def _close(a, b) -> bool:
    a, b = float(a), float(b)
    return abs(a - b) <= 1e-12 * max(1.0, abs(a), abs(b))
