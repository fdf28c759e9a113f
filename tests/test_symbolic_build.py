"""The program builder's direct constructions (symbolic.product, symbolic.total) give exactly
sympy's own expressions: the same arguments in the same order, so the same generated code."""
from __future__ import annotations

import sympy as sp
import pytest

from mbcomp.build.equations import cross
from mbcomp.core.symbolic import dot, product, total

t1, t2, t10, q0, u3 = sp.symbols("t1 t2 t10 q0 u3")


def _same(a, b) -> bool:
    return a == b and type(a) is type(b) and a.args == b.args and hash(a) == hash(b)


@pytest.mark.parametrize("x, y", [(t1, t2), (t2, t1), (t10, t2), (q0, t1), (t1, t1), (t1, sp.Integer(0)),
                                  (sp.Integer(1), t2), (sp.Float(2.5), t1), (-t1, t2), (t1 * t2, u3),
                                  (sp.Integer(3), sp.Integer(4)),
                                  # exact 0 and 1, built directly, except where sympy's 0 * x is nan
                                  (sp.Integer(0), t1 * t2 + 1), (t1 * t2 + 1, sp.Integer(1)), (sp.Integer(1), -t1),
                                  (sp.Integer(0), sp.Integer(0)), (sp.Integer(0), sp.sin(q0)), (sp.Integer(1), sp.pi),
                                  (sp.oo, sp.Integer(0)), (sp.Integer(0), sp.zoo), (sp.Integer(0), sp.Float("inf")),
                                  # a number times a symbol, times another symbol: built directly
                                  (-t2, t1), (t1, -t2), (-t1, t10), (sp.Float(0.5) * u3, q0), (q0, 3 * t1),
                                  (-t1, t1), (sp.Rational(1, 3) * t2, t1), (2 * t1 * t2, u3),
                                  (t1 * t2, u3), (u3, t10 * q0), (t1 * t2, t1), (-t1 * t2 * q0, t10),
                                  (sp.Float(1.5) * t2 * q0, t1), (t1 * t2, sp.Float(2.0))])
def test_product_is_sympys_product(x, y):
    assert _same(product(x, y), x * y)


@pytest.mark.parametrize("terms", [
    [t1 * t2 + u3, q0 * t10],                  # a sum among the terms: flattened, built directly
    [t1 + t2, u3 - q0, t10],
    [t1 + t2, -t2 + u3],                       # the sums share t2: sympy collects
    [t1 + 1, t2],                              # a number inside the sum: sympy's
    [2 * (t1 + t2), t1],                       # a multiple of a sum is not a sum
    [t1 * t2, t10 * q0, -u3 * t1],             # distinct plain terms: built directly
    [t2, t1, t10],
    [t1 * t2, t2 * t1],                        # the same symbols: sympy collects 2*t1*t2
    [t1 * t2, -t1 * t2],                       # cancel to 0
    [sp.Integer(0), t1, sp.Integer(0)],        # zeros dropped: the term itself
    [sp.Float(1.5), t1],                       # a number: sympy's own path
    [sp.Integer(0)],
    [],
    [t1 + t2, t10],                            # nested sums flattened by sympy
    [sp.cos(q0) * t1, t2],
])
def test_total_is_sympys_sum(terms):
    assert _same(total(list(terms)), sp.Add(*terms))


def test_dot_and_cross_are_the_sums_of_products():
    a = [t1, sp.Integer(0), q0]
    b = [t2, t10, sp.Integer(1)]
    assert _same(dot(a, b), sum((x * y for x, y in zip(a, b)), sp.Integer(0)))
    expected = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    for got, want in zip(cross(a, b), expected):
        assert _same(got, want)
    values = {t1: 0.3, t2: -1.2, t10: 2.0, q0: 0.7}
    va, vb = [float(sp.sympify(x).subs(values)) for x in a], [float(sp.sympify(x).subs(values)) for x in b]
    assert float(dot(a, b).subs(values)) == pytest.approx(sum(x * y for x, y in zip(va, vb)))


def _rodrigues(axis, c, s):
    """The general formula, term by term through sympy's own arithmetic."""
    x, y, z = axis
    k = 1 - c
    return [[c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k]]


@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (-1, 0, 0), (0, -1, 0), (0, 0, -1),
                                  (0.6, 0.0, 0.8), (0.0, -0.6, 0.8)])
def test_rotation_about_an_axis_is_rodrigues_formula(axis):
    """Written down directly about a coordinate axis, by the formula otherwise: the same
    expressions either way (so the same program and generated code)."""
    from mbcomp.build.equations import exact, rotation_about
    c, s = sp.symbols("c3 s3")
    exact_axis = [exact(a) for a in axis]
    for row, expected in zip(rotation_about(exact_axis, c, s), _rodrigues(exact_axis, c, s)):
        for entry, want in zip(row, expected):
            assert _same(sp.sympify(entry), sp.sympify(want)), (axis, entry, want)
