"""A small whitelisted arithmetic language for model files: parsed with :mod:`ast`, checked
against a whitelist (numbers, names, ``+ - * / **``, unary minus, ``sin cos exp sqrt``) and
evaluated by walking the tree, never with ``eval``; exact derivatives for motor inputs."""
from __future__ import annotations

import ast
import io
import keyword
import math
import tokenize
from typing import Any, Callable

import numpy as np


def _short(value: Any, width: int = 40) -> str:
    """``repr`` cut to ``width`` characters for messages."""
    text = repr(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def _shown(text: str) -> str:
    """An expression's text for messages: the file, table and key already say where it is,
    so only its start is shown (a value is never echoed in full)."""
    return _short(text, 24)


FUNCTIONS: dict[str, Callable[[float], float]] = {"sin": math.sin, "cos": math.cos, "exp": math.exp,
                                                   "sqrt": math.sqrt}
CONSTANTS = {"pi": math.pi}
RESERVED = frozenset({"t", *FUNCTIONS, *CONSTANTS})
MAX_EXPRESSION_LENGTH = 1000
MAX_DEPTH = 60
# Internal only (derivatives of powers need it); files cannot call it.
_ALL_FUNCTIONS = dict(FUNCTIONS, log=math.log)
_BINARY = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**"}

# A node is a tuple: ("num", value) | ("t",) | (op, a, b) with op in + - * / ** | ("neg", a) |
# ("call", function name, a) | ("name", parameter name) (kept by name: ``keep_names``) |
# ("obj", parameter expression object).


class ExpressionError(ValueError):
    """An expression that is not in the whitelisted language (message says why)."""


def parse_expression(text: str, names: dict[str, float], *, allow_t: bool, keep_names: bool = False) -> tuple:
    """Parse ``text`` into a node tree; parameter names are replaced by their values
    (``keep_names``: kept as ``("name", name)`` leaves, for run-time parameters).

    Raises ``ExpressionError`` for anything outside numbers, ``t`` (when ``allow_t``),
    ``pi``, the given names, ``+ - * / **``, unary minus and ``sin cos exp sqrt`` calls.
    """
    if len(text) > MAX_EXPRESSION_LENGTH:
        raise ExpressionError(f"expression is longer than {MAX_EXPRESSION_LENGTH} characters")
    try:
        source, aliases = _alias_keywords(text.strip(), names)
        tree = ast.parse(source, mode="eval")
        if aliases:
            tree = _Unalias(aliases).visit(tree)
    except SyntaxError as exc:
        raise ExpressionError(f"{_shown(text)} is not a number or an arithmetic expression ({exc.msg})") from None
    except (RecursionError, MemoryError, ValueError):
        raise ExpressionError(f"{_shown(text)} is too deeply nested") from None
    return _convert(tree.body, text, names, allow_t, 0, keep_names)


_KEYWORD_PREFIX = "_kw_"


def _alias_keywords(text: str, names: dict[str, Any]) -> tuple[str, dict[str, str]]:
    """``text`` with every parameter name that is a Python keyword (``lambda``, the head angle
    of the bicycle papers) replaced by an identifier Python's parser accepts, and the map back.

    Only names declared in ``names`` are aliased, token by token (never inside other names),
    so any other keyword stays a syntax error."""
    wanted = {n for n in names if keyword.iskeyword(n)}
    if not wanted or not any(n in text for n in wanted):
        return text, {}
    try:
        tokens = list(tokenize.generate_tokens(io.StringIO(text).readline))
    except (tokenize.TokenError, IndentationError, SyntaxError):
        return text, {}   # ast.parse reports the syntax error
    aliases: dict[str, str] = {}
    pieces, last = [], 0
    lines = text.splitlines(keepends=True)
    starts = [sum(len(x) for x in lines[:i]) for i in range(len(lines) + 1)]
    for tok in tokens:
        if tok.type == tokenize.NAME and tok.string in wanted:
            alias = _KEYWORD_PREFIX + tok.string
            while alias in names:
                alias += "_"
            aliases[alias] = tok.string
            begin = starts[tok.start[0] - 1] + tok.start[1]
            pieces.append(text[last:begin] + alias)
            last = begin + len(tok.string)
    return "".join(pieces) + text[last:], aliases


class _Unalias(ast.NodeTransformer):
    """Puts the keyword parameter names that ``_alias_keywords`` replaced back into the tree."""

    def __init__(self, aliases: dict[str, str]):
        self.aliases = aliases

    def visit_Name(self, node: ast.Name) -> ast.Name:
        node.id = self.aliases.get(node.id, node.id)
        return node


def _convert(node: ast.AST, text: str, names: dict[str, float], allow_t: bool, depth: int,
             keep_names: bool = False) -> tuple:
    if depth > MAX_DEPTH:
        raise ExpressionError(f"{_shown(text)} is too deeply nested")
    if isinstance(node, ast.Constant):
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ExpressionError(f"{_shown(text)}: {_short(value, 20)} is not a number")
        try:
            return ("num", float(value))
        except OverflowError:
            raise ExpressionError(f"{_shown(text)}: number {_short(value, 24)} is too large") from None
    dotted = _dotted_name(node)
    if dotted is not None and dotted in names:   # a sub-model instance's parameter by its path
        return ("name", dotted) if keep_names else ("obj", names[dotted]) if not isinstance(
            names[dotted], (int, float)) and not allow_t else ("num", float(names[dotted]))
    if dotted is not None:
        known = ", ".join(sorted(names)) or "none defined"
        raise ExpressionError(f"{_shown(text)}: unknown name {_short(dotted, 40)} (parameters: {known})")
    if isinstance(node, ast.Name):
        if node.id == "t":
            if not allow_t:
                raise ExpressionError(f"{_shown(text)}: the time t is only allowed in time-varying inputs "
                                      "(motor position, force, joint_torque value)")
            return ("t",)
        if node.id in CONSTANTS:
            return ("num", CONSTANTS[node.id])
        if node.id in names:
            if keep_names:
                return ("name", node.id)
            value = names[node.id]
            # a sub-model parameter (an expression object) stays linked; numbers inline
            # A sub-model parameter (an expression object) stays linked, except in
            # expressions of t (motor positions, forces), which keep its value as built.
            linked = not allow_t and not isinstance(value, (int, float))
            return ("obj", value) if linked else ("num", float(value))
        if node.id in FUNCTIONS:
            raise ExpressionError(f"{_shown(text)}: {node.id} is a function; call it as {node.id}(...)")
        known = ", ".join(sorted(names)) or "none defined"
        raise ExpressionError(f"{_shown(text)}: unknown name {_short(node.id, 20)} (parameters: {known})")
    if isinstance(node, ast.BinOp) and type(node.op) in _BINARY:
        return (_BINARY[type(node.op)], _convert(node.left, text, names, allow_t, depth + 1, keep_names),
                _convert(node.right, text, names, allow_t, depth + 1, keep_names))
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _convert(node.operand, text, names, allow_t, depth + 1, keep_names)
        return ("neg", inner) if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.Call):
        func = node.func.id if isinstance(node.func, ast.Name) else None
        if func not in FUNCTIONS:
            shown = func if func is not None else _short(ast.unparse(node.func), 40)
            raise ExpressionError(f"{_shown(text)}: calling {shown} is not allowed (only sin, cos, exp, sqrt)")
        if node.keywords or len(node.args) != 1 or isinstance(node.args[0], ast.Starred):
            raise ExpressionError(f"{_shown(text)}: {func}() takes exactly one argument")
        return ("call", func, _convert(node.args[0], text, names, allow_t, depth + 1, keep_names))
    what = type(node).__name__
    raise ExpressionError(f"{_shown(text)}: {what} is not allowed (numbers, parameter names, t, + - * / **, "
                          "sin, cos, exp, sqrt only)")


def _dotted_name(node: ast.AST) -> str | None:
    """``"upper.length"`` for the attribute chain ``upper.length`` of plain names, else None."""
    if not isinstance(node, ast.Attribute):
        return None
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    return ".".join([node.id] + parts[::-1])


def evaluate(node: tuple, t: float = 0.0, env: dict | None = None) -> float:
    """Value of a node tree at time ``t`` (``env``: values of ``("name", ...)`` leaves);
    ``ArithmeticError`` or ``ValueError`` on a math error."""
    kind = node[0]
    if kind == "num" or kind == "obj":
        return node[1]
    if kind == "name":
        return float(env[node[1]])
    if kind == "t":
        return t
    if kind == "neg":
        return -evaluate(node[1], t, env)
    if kind == "call":
        arg = evaluate(node[2], t, env)
        if not isinstance(arg, float) and hasattr(arg, node[1]):
            return getattr(arg, node[1])()   # a parameter expression object
        return _ALL_FUNCTIONS[node[1]](arg)
    a, b = evaluate(node[1], t, env), evaluate(node[2], t, env)
    if kind == "+":
        return a + b
    if kind == "-":
        return a - b
    if kind == "*":
        return a * b
    if kind == "/":
        return a / b
    if not (isinstance(a, float) and isinstance(b, float)):
        return a ** b  # a parameter expression object
    return math.pow(a, b)  # "**": math.pow raises instead of returning a complex number


def uses_t(node: tuple) -> bool:
    """True when the tree depends on the time."""
    if node[0] == "t":
        return True
    if node[0] in ("num", "name", "obj"):
        return False
    return any(uses_t(child) for child in node[1:] if isinstance(child, tuple))


def _num(value: float) -> tuple:
    return ("num", float(value))


def _is(node: tuple, value: float) -> bool:
    return node[0] == "num" and node[1] == value


def _add(a, b):
    if _is(a, 0):
        return b
    if _is(b, 0):
        return a
    return ("+", a, b)


def _sub(a, b):
    if _is(b, 0):
        return a
    if _is(a, 0):
        return ("neg", b)
    return ("-", a, b)


def _mul(a, b):
    if _is(a, 0) or _is(b, 0):
        return _num(0)
    if _is(a, 1):
        return b
    if _is(b, 1):
        return a
    return ("*", a, b)


def _div(a, b):
    if _is(a, 0):
        return _num(0)
    if _is(b, 1):
        return a
    return ("/", a, b)


def differentiate(node: tuple) -> tuple:
    """d/dt of a node tree (exact, by the usual rules; zeros pruned)."""
    kind = node[0]
    if kind in ("num", "name"):
        return _num(0)
    if kind == "t":
        return _num(1)
    if kind == "neg":
        d = differentiate(node[1])
        return _num(0) if _is(d, 0) else ("neg", d)
    if kind == "call":
        name, arg = node[1], node[2]
        d = differentiate(arg)
        if _is(d, 0):
            return _num(0)
        outer = {"sin": ("call", "cos", arg), "cos": ("neg", ("call", "sin", arg)), "exp": node,
                 "sqrt": ("/", _num(0.5), node), "log": ("/", _num(1), arg)}[name]
        return _mul(outer, d)
    a, b = node[1], node[2]
    da, db = differentiate(a), differentiate(b)
    if kind == "+":
        return _add(da, db)
    if kind == "-":
        return _sub(da, db)
    if kind == "*":
        return _add(_mul(da, b), _mul(a, db))
    if kind == "/":
        return _div(_sub(_mul(da, b), _mul(a, db)), ("**", b, _num(2)))
    # a ** b
    if not uses_t(b):
        return _mul(_mul(b, ("**", a, _sub(b, _num(1)))), da)
    return _mul(node, _add(_mul(db, ("call", "log", a)), _div(_mul(b, da), a)))


def to_text(node: tuple) -> str:
    """The tree as (fully parenthesised) expression text."""
    kind = node[0]
    if kind == "num":
        return repr(node[1]) if node[1] >= 0 else f"({node[1]!r})"
    if kind == "t":
        return "t"
    if kind == "name":
        return node[1]
    if kind == "neg":
        return f"(-{to_text(node[1])})"
    if kind == "call":
        return f"{node[1]}({to_text(node[2])})"
    return f"({to_text(node[1])} {kind} {to_text(node[2])})"


def names_in(node: tuple) -> set[str]:
    """The parameter names a tree parsed with ``keep_names`` uses."""
    if node[0] == "name":
        return {node[1]}
    return set().union(*(names_in(child) for child in node[1:] if isinstance(child, tuple)))


def replace_names(node: tuple, values: dict) -> tuple:
    """The tree with its ``("name", ...)`` leaves replaced by the numbers in ``values``."""
    if node[0] == "name":
        return _num(values[node[1]])
    if node[0] in ("num", "t", "obj"):
        return node
    return tuple(replace_names(c, values) if isinstance(c, tuple) else c for c in node)


def to_sympy(node: tuple, t, name: Callable | None = None):
    """The tree built from sympy objects in the symbol ``t`` (no parsing of text);
    ``name(n)``: the sympy object of a ``("name", n)`` leaf."""
    import sympy as sp
    functions = {"sin": sp.sin, "cos": sp.cos, "exp": sp.exp, "sqrt": sp.sqrt, "log": sp.log}

    def build(node):
        kind = node[0]
        if kind == "num":
            return sp.Float(node[1]) if not float(node[1]).is_integer() else sp.Integer(int(node[1]))
        if kind == "t":
            return t
        if kind == "name":
            return name(node[1])
        if kind == "neg":
            return -build(node[1])
        if kind == "call":
            return functions[node[1]](build(node[2]))
        a, b = build(node[1]), build(node[2])
        return {"+": a + b, "-": a - b, "*": a * b, "/": a / b, "**": a ** b}[kind]
    return build(node)


class Expression:
    """A time-varying input read from a file: a callable ``f(t) -> float``.

    ``source`` is the text as written (``save`` writes it back); ``diff()`` gives the exact
    time derivative as another ``Expression``; ``to_sympy(t)`` builds the same expression
    from sympy objects (no parsing of text) for symbolic use.
    """

    def __init__(self, source: str, node: tuple, owner: str = "expression"):
        self.source = source
        self.node = node
        self.owner = owner

    def __call__(self, t: float) -> float:
        from mbcomp.core.errors import SimulationError
        try:
            value = evaluate(self.node, float(t))
        except (ArithmeticError, ValueError) as exc:
            raise SimulationError(f"{self.source!r} cannot be evaluated at t = {float(t):.6g} s ({exc})",
                                  self.owner) from None
        if not math.isfinite(value):
            raise SimulationError(f"{self.source!r} is not finite at t = {float(t):.6g} s", self.owner)
        return value

    def diff(self) -> "Expression":
        """The time derivative (its ``source`` is generated text)."""
        node = differentiate(self.node)
        return Expression(to_text(node), node, self.owner)

    def to_sympy(self, t):
        """The expression built from sympy objects, in the symbol ``t``."""
        return to_sympy(self.node, t)

    def __repr__(self) -> str:
        return f"Expression({self.source!r})"


class TimeVector:
    """A vector input of time read from a file: callable ``(t, q, qd) -> (n,) array``.

    Entries are numbers or ``Expression`` objects; ``source`` lists what the file wrote.
    """

    def __init__(self, entries: list, source: list):
        self.entries = entries
        self.source = source

    def __call__(self, t: float, q: Any = None, qd: Any = None) -> np.ndarray:
        return np.array([e(t) if isinstance(e, Expression) else e for e in self.entries], dtype=float)

    def __len__(self) -> int:
        return len(self.entries)

    def __repr__(self) -> str:
        return f"TimeVector({self.source!r})"
