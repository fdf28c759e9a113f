"""A canonical form for printed equations (``mbcomp info``): expanded polynomials in the
coordinates, speeds and the sines and cosines of angles, with every ``sin(a)**2`` written
as ``1 - cos(a)**2`` and, for a unit quaternion, ``w**2`` as ``1 - x**2 - y**2 - z**2``, so
that ``sin^2 + cos^2`` terms cancel and equal equations print alike (``trigsimp`` gives the
same result 30 times slower).

The form is the remainder of the polynomial modulo those relations.  It is computed in
sympy's sparse polynomial rings over the rationals (``sympy.polys.rings``) rather than by
``expand`` on expression trees: the same result, 2-16x faster on the library's models
(the five-link pendulum: 2.2 s against 37 s).  An expression that is no such polynomial (a
spring's square root, a float) takes the expanding path.
"""
from __future__ import annotations

from typing import Any


def canonical(expr: Any, units: tuple = ()) -> Any:
    """``expr`` in the canonical form; ``units``: ``(w, 1 - x**2 - y**2 - z**2)`` of each unit
    quaternion (``w``, ``x``, ... its coordinate symbols)."""
    import sympy as sp
    expr = sp.sympify(expr)
    try:
        return _reduced(expr, units)
    except (ValueError, TypeError, sp.PolynomialError, sp.polys.polyerrors.CoercionFailed):
        return _expanded(expr, units)


def _reduced(expr, units: tuple):
    """The remainder of ``expr`` as a polynomial over QQ (lex order, the sines and each
    quaternion's ``w`` first) modulo ``sin^2 + cos^2 - 1`` and ``w^2 + x^2 + y^2 + z^2 - 1``:
    the relations have coprime leading terms, so the remainder is unique."""
    import sympy as sp
    key = sp.default_sort_key
    sines = sorted(expr.atoms(sp.sin), key=key)
    cosines = sorted(expr.atoms(sp.cos) | {sp.cos(s.args[0]) for s in sines}, key=key)
    stand_in = {atom: sp.Dummy(f"trig{k}") for k, atom in enumerate(sines + cosines)}
    plain = expr.xreplace(stand_in)
    if plain.atoms(sp.Function) or plain.atoms(sp.Float):  # (the ring would make a float a fraction)
        raise ValueError("not a polynomial with rational coefficients in the coordinates and trig atoms")
    squares = [(w, rest) for w, rest in units if plain.has(w)]
    lead = [stand_in[s] for s in sines] + [w for w, _ in squares]
    others = (plain.free_symbols | {stand_in[c] for c in cosines}) - set(lead)
    for _, rest in squares:
        others |= rest.free_symbols - set(lead)
    ring, *_ = sp.ring(lead + sorted(others, key=key), sp.QQ)
    relations = [stand_in[s] ** 2 + stand_in[sp.cos(s.args[0])] ** 2 - 1 for s in sines]
    relations += [w ** 2 - rest for w, rest in squares]
    poly = ring.from_expr(plain)
    if relations:
        poly = poly.rem([ring.from_expr(r) for r in relations])
    return poly.as_expr().xreplace({dummy: atom for atom, dummy in stand_in.items()})


def _expanded(expr, units: tuple):
    """The same form by expanding expression trees (for expressions that are no polynomial)."""
    import sympy as sp
    squares = dict(units)

    def is_even_power(e):
        return (e.is_Pow and e.exp.is_Integer and e.exp >= 2
                and (isinstance(e.base, sp.sin) or e.base in squares))

    def rewrite(e):
        n = int(e.exp)
        square = squares[e.base] if e.base in squares else 1 - sp.cos(e.base.args[0]) ** 2
        return square ** (n // 2) * e.base ** (n % 2)
    return sp.expand(sp.expand(expr).replace(is_even_power, rewrite))
