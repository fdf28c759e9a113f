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
_ORDER = cmp_to_key(Basic.compare)  # sympy's canonical order of the arguments of a sum


def product(x, y):
    """``x * y``, the same expression as sympy's, built directly when both are distinct
    symbols (the common case of the program's dot products: sympy's general ``Mul``
    takes ~8x longer to find that nothing combines)."""
    if getattr(x, "is_Symbol", False) and getattr(y, "is_Symbol", False) and x != y:
        return sp.Mul(*((x, y) if Basic.compare(x, y) < 0 else (y, x)), evaluate=False)
    return x * y


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
    two share their symbols: then sympy's sum is those terms in its canonical order."""
    terms = [sp.sympify(t) for t in terms]
    terms = [t for t in terms if t is not _ZERO]
    if len(terms) < 2:
        return terms[0] if terms else _ZERO
    seen = set()
    for t in terms:
        if not _plain_term(t):
            return sp.Add(*terms)
        key = t.as_coeff_Mul()[1]
        if key in seen:
            return sp.Add(*terms)
        seen.add(key)
    terms.sort(key=_ORDER)
    return sp.Add(*terms, evaluate=False)


def dot(a, b):
    """``sum(x * y)`` as one sum (the same canonical sum as adding term by term, without
    building every partial sum)."""
    return total([product(x, y) for x, y in zip(a, b)])
