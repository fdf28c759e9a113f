"""The canonical form of printed equations: polynomial remainders modulo sin^2 + cos^2 = 1
and |quaternion| = 1, computed in polynomial rings, equal to the expanding path."""
from __future__ import annotations

import random

import pytest
import sympy as sp

from mbcomp.face.normal_form import _expanded, _reduced, canonical

a, b, x, y, z, w, u = sp.symbols("a b x y z w u", real=True)


def test_sine_squares_become_cosines_and_pythagoras_cancels():
    expr = sp.sin(a) ** 3 * sp.cos(b) + sp.sin(a) ** 2 + sp.cos(a) ** 2 + u * sp.sin(b) ** 2
    expected = sp.expand(sp.sin(a) * (1 - sp.cos(a) ** 2) * sp.cos(b) + 1 + u * (1 - sp.cos(b) ** 2))
    assert canonical(expr) == expected
    assert canonical(sp.sin(a) ** 2 + sp.cos(a) ** 2) == 1
    assert canonical((sp.sin(a) + sp.cos(a)) ** 2) == sp.expand(1 + 2 * sp.sin(a) * sp.cos(a))


def test_a_unit_quaternion_loses_its_even_powers_of_w():
    units = ((w, 1 - x ** 2 - y ** 2 - z ** 2),)
    expr = w ** 4 * u + w ** 3 * x + sp.Rational(3, 7) * w ** 2
    expected = sp.expand((1 - x ** 2 - y ** 2 - z ** 2) ** 2 * u + (1 - x ** 2 - y ** 2 - z ** 2) * w * x
                         + sp.Rational(3, 7) * (1 - x ** 2 - y ** 2 - z ** 2))
    assert canonical(expr, units) == expected
    assert canonical(w ** 2 + x ** 2 + y ** 2 + z ** 2, units) == 1


def _random_expression(rng: random.Random):
    """A random product of sums of the atoms of printed equations (trig powers, symbols, rationals)."""
    atoms = [sp.sin(a), sp.cos(a), sp.sin(b), sp.cos(b), sp.sin(a + b), x, u, w]
    factors = []
    for _ in range(rng.randint(1, 3)):
        terms = [sp.Rational(rng.randint(-9, 9), rng.randint(1, 5)) * rng.choice(atoms) ** rng.randint(0, 4)
                 for _ in range(rng.randint(1, 4))]
        factors.append(sp.Add(*terms))
    return sp.Mul(*factors)


@pytest.mark.parametrize("seed", range(25))
def test_ring_and_expanding_paths_agree(seed):
    rng = random.Random(seed)
    units = ((w, 1 - x ** 2 - y ** 2 - z ** 2),)
    expr = _random_expression(rng)
    assert _reduced(expr, units) == _expanded(expr, units)


def test_what_is_no_polynomial_takes_the_expanding_path():
    spring = sp.sqrt(x ** 2 + 1) * sp.sin(a) ** 2
    assert canonical(spring) == sp.expand(sp.sqrt(x ** 2 + 1) * (1 - sp.cos(a) ** 2))
    with pytest.raises(ValueError):
        _reduced(sp.exp(x) * sp.sin(a) ** 2, ())
    assert canonical(sp.exp(x) * sp.sin(a) ** 2) == sp.expand(sp.exp(x) * (1 - sp.cos(a) ** 2))
    assert canonical(sp.Float(0.5) * sp.sin(a) ** 2) == _expanded(sp.Float(0.5) * sp.sin(a) ** 2, ())
