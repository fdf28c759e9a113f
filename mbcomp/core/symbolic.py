"""sympy's own products and sums, built directly where sympy's general constructors would only
find that nothing combines: most of the symbolic work of a large model's program.

``product(x, y)`` equals ``x * y`` and ``total(terms)`` equals ``sympy.Add(*terms)``: the same
arguments in the same canonical order, so the same program and the same generated code.
sympy is imported with this module: import it only where a program is built."""
from __future__ import annotations

from functools import cmp_to_key

import sympy as sp
from sympy.core.basic import Basic

_ZERO = sp.S.Zero
_ONE = sp.S.One
_ORDER = cmp_to_key(Basic.compare)  # sympy's canonical order of the arguments of a sum
#: ``Mul(*args, evaluate=False)`` and ``Add(...)`` without the general constructor's cache
#: lookup, argument conversion and post-processor scan: the arguments here are already sympy
#: symbols and numbers in canonical order, so the result is the same expression (a sixth of
#: the symbolic work of the N = 20 chain's program went into those steps).
_MUL = sp.Mul._from_args
_ADD = sp.Add._from_args


def product(x, y):
    """``x * y``, the same expression as sympy's, built directly when both are distinct
    symbols (the common case of the program's dot products: sympy's general ``Mul``
    takes ~8x longer to find that nothing combines), a product of distinct symbols (with at
    most a number) times another symbol, or when one is an exact 0 or 1 (the entries of
    coordinate axes: a quarter of the products; sympy takes ~35 us for ``0 * x``)."""
    if getattr(x, "is_Symbol", False) and getattr(y, "is_Symbol", False) and x != y:
        return _MUL((x, y) if Basic.compare(x, y) < 0 else (y, x))
    if getattr(y, "is_Symbol", False) and _symbols_product(x, y):   # a * b * c, -s * x: at most a number
        return _times_symbol(x, y)                                    # and distinct symbols
    if getattr(x, "is_Symbol", False) and _symbols_product(y, x):
        return _times_symbol(y, x)
    if x is _ONE and isinstance(y, Basic):
        return y
    if y is _ONE and isinstance(x, Basic):
        return x
    if (x is _ZERO and _finite(y)) or (y is _ZERO and _finite(x)):
        return _ZERO
    return x * y


def _symbols_product(e, other) -> bool:
    """``e`` is a plain product (``_plain_term``: symbols, at most a leading finite number)
    without ``other``: ``e * other`` is then the same product with ``other`` among its symbols."""
    if not (getattr(e, "is_Mul", False) and _plain_term(e)) or other in e.args:
        return False
    first = e.args[0]
    return not first.is_Number or first.is_finite is True


def _times_symbol(e, symbol):
    """``e * symbol`` for ``_symbols_product(e, symbol)``: sympy's order, the number first."""
    args = e.args
    start = 1 if args[0].is_Number else 0
    return _MUL((*args[:start], *sorted((*args[start:], symbol), key=_ORDER)))


def _finite(e) -> bool:
    """``e`` is an expression that ``0 * e`` reduces to 0 (anything but an infinite or
    undefined number, for which sympy gives nan)."""
    return isinstance(e, Basic) and not (e.is_number and e.is_finite is not True)


def _plain_term(e) -> bool:
    """A symbol, or a product of symbols with at most a leading number: a term that sympy's
    ``Add`` keeps as it is unless another term has the same symbols."""
    if e.is_Symbol:
        return True
    if not e.is_Mul:
        return False
    args = e.args
    return all(a.is_Symbol for a in args[1:]) and (args[0].is_Symbol or args[0].is_Number)


def total(terms: list):
    """``sympy.Add(*terms)``, built directly when every term is plain (``_plain_term``) and no
    two share their symbols: then sympy's sum is those terms in its canonical order.  A term
    that is itself a sum counts as its terms (sympy's sum flattens nested sums the same way)."""
    terms = [sp.sympify(t) for t in terms]
    terms = [t for t in terms if t is not _ZERO]
    if len(terms) < 2:
        return terms[0] if terms else _ZERO
    given, terms = terms, [a for t in terms for a in (t.args if t.is_Add else (t,))]
    seen = set()
    for t in terms:
        if not _plain_term(t):
            return sp.Add(*given)
        key = t.as_coeff_Mul()[1]
        if key in seen:
            return sp.Add(*given)
        seen.add(key)
    terms.sort(key=_ORDER)
    return _ADD(terms)


def dot(a, b):
    """``sum(x * y)`` as one sum (the same canonical sum as adding term by term, without
    building every partial sum)."""
    return total([product(x, y) for x, y in zip(a, b)])
