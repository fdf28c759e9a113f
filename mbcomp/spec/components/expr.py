"""Parameter expressions: what ``self.length`` is inside a sub-model's ``build``.

An ``Expr`` is a small arithmetic tree over sub-model parameters (leaves named by their
instance path, ``"upper.length"``) that also carries its current value, so that a
component given one validates and stores a number exactly as it would for a float,
while the compiler keeps the expression: a run-time parameter change re-evaluates it
(no code generated again).  Arithmetic (``+ - * / **``, unary minus, ``abs``) and the
functions of this module (``sqrt``, ``sin``, ``cos``, ``tan``, ``exp``, ``log``; numpy's
``np.sqrt`` and friends dispatch to them) keep the link; anything that turns the value
into a plain float (``math.sqrt``, ``float()``) makes it a constant.  Comparisons are
refused: a decision on a parameter would be structure (use an ``Option``).
"""
from __future__ import annotations

import math
import operator
from typing import Any, Mapping

from mbcomp.core.errors import ModelError

_BINARY = {"+": operator.add, "-": operator.sub, "*": operator.mul, "/": operator.truediv, "**": operator.pow}
_UNARY = {"neg": operator.neg, "abs": abs, "sqrt": math.sqrt, "sin": math.sin, "cos": math.cos,
          "tan": math.tan, "exp": math.exp, "log": math.log}


class Expr:
    """An arithmetic expression of sub-model parameters with its current ``value``."""

    __slots__ = ("op", "args", "value")

    def __init__(self, op: str, args: tuple, value: float):
        self.op, self.args, self.value = op, args, float(value)

    @staticmethod
    def parameter(path: str, value: float) -> "Expr":
        """The leaf standing for parameter ``path`` (current value ``value``)."""
        return Expr("param", (path,), value)

    # -- evaluation -------------------------------------------------------------------------
    def evaluate(self, env: Mapping[str, float]) -> float:
        """The value with the parameters in ``env`` (missing ones keep their current value)."""
        if self.op == "param":
            return float(env.get(self.args[0], self.value))
        vals = [a.evaluate(env) if isinstance(a, Expr) else a for a in self.args]
        try:
            return float(_BINARY[self.op](*vals) if self.op in _BINARY else _UNARY[self.op](vals[0]))
        except (ValueError, ZeroDivisionError, OverflowError) as exc:
            raise ModelError(f"expression {self}", f"cannot be evaluated ({exc})") from None

    def parameters(self) -> set[str]:
        """The parameter paths this expression reads."""
        if self.op == "param":
            return {self.args[0]}
        return set().union(*(a.parameters() for a in self.args if isinstance(a, Expr)))

    def __float__(self) -> float:
        return self.value

    def __index__(self):
        raise TypeError(f"parameter expression {self} is not an integer: use an Option for counts")

    # -- arithmetic ---------------------------------------------------------------------------
    def _binary(self, op: str, other: Any, swap: bool = False) -> "Expr":
        if not isinstance(other, (Expr, int, float)) or isinstance(other, bool):
            try:
                other = float(other)
            except (TypeError, ValueError):
                return NotImplemented
        a, b = (other, self) if swap else (self, other)
        va, vb = (x.value if isinstance(x, Expr) else float(x) for x in (a, b))
        try:
            value = _BINARY[op](va, vb)
        except ZeroDivisionError:
            raise ModelError(f"expression {a} {op} {b}", "divides by zero") from None
        except OverflowError:
            raise ModelError(f"expression {a} {op} {b}", f"overflows the float range with the values {va:g} "
                                                         f"and {vb:g}") from None
        if isinstance(value, complex):
            raise ModelError(f"expression {a} {op} {b}", "has no real value")
        return Expr(op, (a, b), value)

    def __add__(self, o): return self._binary("+", o)
    def __radd__(self, o): return self._binary("+", o, True)
    def __sub__(self, o): return self._binary("-", o)
    def __rsub__(self, o): return self._binary("-", o, True)
    def __mul__(self, o): return self._binary("*", o)
    def __rmul__(self, o): return self._binary("*", o, True)
    def __truediv__(self, o): return self._binary("/", o)
    def __rtruediv__(self, o): return self._binary("/", o, True)
    def __pow__(self, o): return self._binary("**", o)
    def __rpow__(self, o): return self._binary("**", o, True)
    def __neg__(self): return Expr("neg", (self,), -self.value)
    def __pos__(self): return self
    def __abs__(self): return Expr("abs", (self,), abs(self.value))

    def _unary(self, op: str) -> "Expr":
        try:
            return Expr(op, (self,), _UNARY[op](self.value))
        except (ValueError, OverflowError) as exc:
            raise ModelError(f"{op}({self})", f"cannot be evaluated ({exc})") from None

    def sqrt(self): return self._unary("sqrt")
    def sin(self): return self._unary("sin")
    def cos(self): return self._unary("cos")
    def tan(self): return self._unary("tan")
    def exp(self): return self._unary("exp")
    def log(self): return self._unary("log")

    def _refuse(self, other):
        raise ModelError(f"parameter expression {self}",
                         "cannot be compared: a choice made on a parameter would be structure; "
                         "use an Option (or float(...) to freeze the value)")

    __lt__ = __le__ = __gt__ = __ge__ = _refuse

    def __bool__(self):
        self._refuse(None)

    def __eq__(self, other):
        return isinstance(other, Expr) and self.op == other.op and self.args == other.args

    def __hash__(self):
        return hash((self.op, self.args))

    def __reduce__(self):
        return Expr, (self.op, self.args, self.value)

    def __repr__(self) -> str:
        if self.op == "param":
            return self.args[0]
        if self.op in _BINARY:
            return f"({self.args[0]!r} {self.op} {self.args[1]!r})"
        return f"{'-' if self.op == 'neg' else self.op}({self.args[0]!r})"


def sqrt(x): return x.sqrt() if isinstance(x, Expr) else math.sqrt(x)
def sin(x): return x.sin() if isinstance(x, Expr) else math.sin(x)
def cos(x): return x.cos() if isinstance(x, Expr) else math.cos(x)


def parameters_in(value: Any) -> set[str]:
    """The parameter paths the ``Expr``s in ``value`` (nested sequences) read."""
    if isinstance(value, Expr):
        return value.parameters()
    if isinstance(value, (tuple, list)):
        return set().union(*(parameters_in(v) for v in value)) if value else set()
    return set()


def contains_expr(value: Any) -> bool:
    """True when ``value`` (numbers, sequences, mappings, Frames) holds an ``Expr``."""
    if isinstance(value, Expr):
        return True
    if isinstance(value, (str, bytes, int, float)) or value is None:
        return False
    if _signal_args(value) is not None:   # a signal source built from parameter expressions
        return True
    if isinstance(value, (tuple, list)):
        return any(contains_expr(v) for v in value)
    if isinstance(value, dict):
        return any(contains_expr(v) for v in value.values())
    point = getattr(value, "point", None)
    if point is not None and type(value).__name__ == "Frame":
        return contains_expr(point) or bool(getattr(value, "rotation_parameters", ()))
    if hasattr(value, "dtype") and getattr(value, "dtype", None) == object:
        return any(contains_expr(v) for v in value.ravel().tolist())
    return False


def substitute(value: Any, env: Mapping[str, float]) -> Any:
    """``value`` with every ``Expr`` replaced by its number under ``env`` (structure kept)."""
    return map_exprs(value, lambda e: e.evaluate(env))


def map_exprs(value: Any, replace: Any) -> Any:
    """``value`` with every ``Expr`` ``e`` replaced by ``replace(e)``, structure kept (a signal
    is built again from its replaced arguments, a ``Frame`` keeps its body and rotation, an
    object array becomes a float array)."""
    if isinstance(value, Expr):
        return replace(value)
    if isinstance(value, (str, bytes, int, float)) or value is None:
        return value
    args = _signal_args(value)
    if args is not None:
        return type(value)(*map_exprs(args[0], replace), **map_exprs(args[1], replace))
    if isinstance(value, tuple):
        return tuple(map_exprs(v, replace) for v in value)
    if isinstance(value, list):
        return [map_exprs(v, replace) for v in value]
    if isinstance(value, dict):
        return {k: map_exprs(v, replace) for k, v in value.items()}
    if type(value).__name__ == "Frame":
        frame = object.__new__(type(value))
        frame.body, frame.point, frame.rotation = value.body, map_exprs(value.point, replace), value.rotation
        return frame
    if hasattr(value, "dtype") and getattr(value, "dtype", None) == object:
        import numpy as np
        return np.array(map_exprs(value.tolist(), replace), dtype=float)
    return value


def _signal_args(value: Any) -> Any:
    """``(args, kwargs)`` of a signal built from parameter expressions (``Signal.signal_args``),
    else None (components, such as a PID inside a signal, follow their own)."""
    args = getattr(type(value), "signal_args", _NOT_A_SIGNAL)
    if args is _NOT_A_SIGNAL:
        return None
    return getattr(value, "signal_args", None)


_NOT_A_SIGNAL = object()
