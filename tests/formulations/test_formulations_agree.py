"""``lagrange`` and ``dae`` agree: accelerations and reactions at consistent states, and
whole trajectories (DESIGN.md: "Both formulations must agree to solver precision").

Each model is a mechanism with a closed loop, a slider or both; consistent states come
from ``assemble``.  The accelerations are also checked independently of either
formulation: a second-order Taylor step ``q + h qd + h^2/2 qdd`` must leave the
constraints at O(h^3).
"""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from conftest import assert_close, bar, fourbar

G = 9.81


def slider_crank():
    """Crank 0.2 m and rod 0.6 m; the rod end slides along an inclined line (Slider)."""
    m = mb.Model("slider_crank", gravity=(0, -G, 0))
    crank, rod = m.add(bar("crank", 0.2)), m.add(bar("rod", 0.6, mass=0.5))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(0.2, 0, 0)))
    m.add(mb.Slider("piston", rod, point=(0.6, 0, 0), origin=(0, 0.05, 0), axis=(1.0, 0.2, 0)))
    return m


def prismatic_slider_crank():
    """The slider-crank with a piston body on a prismatic joint, pinned to the rod by the
    loop-closing revolute 'wrist'."""
    m = mb.Model("prismatic_slider_crank", gravity=(0, -G, 0))
    crank, rod = m.add(bar("crank", 0.2)), m.add(bar("rod", 0.6, mass=0.5))
    piston = m.add(mb.Body("piston", mass=0.3, com=(0, 0, 0), inertia=(1e-3, 1e-3, 1e-3)))
    m.add(mb.Revolute("A", m.ground, crank, axis="z"))
    m.add(mb.Revolute("B", crank, rod, axis="z", parent_point=(0.2, 0, 0)))
    m.add(mb.Prismatic("P", m.ground, piston, axis="x"))
    m.add(mb.Revolute("wrist", rod, piston, axis="z", parent_point=(0.6, 0, 0)))
    return m


def double_pendulum_on_slider():
    """A cart free to translate in x-y (two prismatic joints) kept on an inclined line by a
    Slider, carrying a double pendulum: 4 coordinates, 3 DOF."""
    m = mb.Model("dpend_on_slider", gravity=(0, -G, 0))
    carriage = m.add(mb.Body("carriage", mass=0.5))
    cart = m.add(mb.Body("cart", mass=2.0, inertia=(0.01, 0.01, 0.01)))
    b1, b2 = m.add(bar("bar1", 0.7)), m.add(bar("bar2", 0.5, mass=0.6))
    m.add(mb.Prismatic("px", m.ground, carriage, axis="x"))
    m.add(mb.Prismatic("py", carriage, cart, axis="y"))
    m.add(mb.Revolute("j1", cart, b1, axis="z"))
    m.add(mb.Revolute("j2", b1, b2, axis="z", parent_point=(0.7, 0, 0)))
    m.add(mb.Slider("rail", cart, point=(0, 0, 0), origin=(0, 0, 0), axis=(np.cos(-0.3), np.sin(-0.3), 0)))
    return m


# (builder, ndof, [(q guess, qd guess)], loop points for the Taylor check)
CASES = {
    "fourbar": (fourbar, 1, [([1.0, -0.5, 1.5], [1.0, 0, 0]), ([-1.0, 2.0, 3.0], [0, -2.0, 0]),
                             ([0.3, 0.5, 2.0], [3.0, 0, 0])]),
    "slider_crank": (slider_crank, 1, [([0.5, -0.6], [2.0, 0]), ([2.5, -2.0], [-4.0, 0]), ([-1.0, 1.2], [0, 1.0])]),
    "prismatic_slider_crank": (prismatic_slider_crank, 1, [([0.5, -0.6, 0.75], [2.0, 0, 0]),
                                                           ([2.5, -2.0, 0.5], [-4.0, 0, 0])]),
    "dpend_on_slider": (double_pendulum_on_slider, 3, [([0.2, 0.0, -1.0, 0.5], [0.5, 0, 1.0, -2.0]),
                                                       ([-0.5, 0.3, 1.0, -2.0], [-1.0, 0, -3.0, 0.5])]),
}


@pytest.fixture(scope="module", params=sorted(CASES))
def pair(request):
    """(name, lagrange system, dae system, consistent states) for one model."""
    builder, ndof, guesses = CASES[request.param]
    model = builder()
    lagrange, dae = model.compile("lagrange"), model.compile("dae")
    assert lagrange.ndof == dae.ndof == ndof
    assert lagrange.redundant_constraints == dae.redundant_constraints
    states = [lagrange.assemble(q, qd) for q, qd in guesses]
    return request.param, lagrange, dae, states


def test_assembled_states_are_consistent_for_both(pair):
    _, lagrange, dae, states = pair
    for q, qd in states:
        assert lagrange.constraint_violation(q) < 1e-10
        assert dae.constraint_violation(q) < 1e-10
        q2, qd2 = dae.assemble(q, qd)
        assert_close(q2, q, atol=1e-12, name="dae keeps a consistent q")
        assert_close(qd2, qd, atol=1e-10, name="dae keeps a consistent qd")


def test_accelerations_agree(pair):
    _, lagrange, dae, states = pair
    for q, qd in states:
        a, b = lagrange.accelerations(q, qd), dae.accelerations(q, qd)
        assert_close(a, b, rtol=1e-8, atol=1e-8 * max(1.0, np.max(np.abs(b))), name="qdd")


def test_accelerations_with_applied_forces_agree(pair):
    _, lagrange, dae, states = pair
    rng = np.random.default_rng(3)
    for q, qd in states:
        tau = rng.normal(0.0, 2.0, lagrange.nq)
        a, b = lagrange.accelerations(q, qd, tau=tau), dae.accelerations(q, qd, tau=tau)
        assert_close(a, b, rtol=1e-8, atol=1e-8 * max(1.0, np.max(np.abs(b))), name="qdd with tau")


def test_reactions_agree(pair):
    _, lagrange, dae, states = pair
    for q, qd in states:
        ra, rb = lagrange.reactions(q, qd), dae.reactions(q, qd)
        assert sorted(ra) == sorted(rb) == sorted(lagrange.constraint_names)
        for name in ra:
            scale = max(1.0, np.max(np.abs(rb[name])))
            assert_close(ra[name], rb[name], rtol=1e-8, atol=1e-8 * scale, name=f"reaction {name}")
            assert np.max(np.abs(rb[name])) > 1e-3   # a loaded constraint, not two zeros


def test_accelerations_keep_the_constraints_to_third_order(pair):
    """C(q + h qd + h^2/2 qdd) = O(h^3) for the true qdd; the tree's unconstrained
    accelerations leave O(h^2).  Halving h must divide the violation by ~8 (the cart's
    slider is linear in q, so there it is zero to rounding)."""
    _, lagrange, dae, states = pair
    for q, qd in states:
        qdd = dae.accelerations(q, qd)
        taylor = lambda h: dae.constraint_violation(q + h * qd + 0.5 * h * h * qdd)
        v1, v2 = taylor(2e-3), taylor(1e-3)
        assert v1 < 1e-6 and (v2 < v1 / 6.0 or v1 < 1e-14), (v1, v2)   # (a linear constraint: exact)


def test_trajectories_agree_over_5_s(pair):
    """Integrated at rtol=1e-10, atol=1e-12 from the same consistent state."""
    name, lagrange, dae, states = pair
    q, qd = states[0]
    t = np.linspace(0.0, 5.0, 51)
    ra = lagrange.simulate(5.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
    rb = dae.simulate(5.0, q, qd, rtol=1e-10, atol=1e-12, t_eval=t)
    assert_close(ra.t, t, atol=0, name="times")
    assert_close(ra.q, rb.q, atol=1e-7, rtol=0, name=f"{name} q(t)")
    assert_close(ra.qd, rb.qd, atol=1e-6 * max(1.0, np.max(np.abs(rb.qd))), rtol=0, name=f"{name} qd(t)")
    assert np.max(np.ptp(rb.q, axis=0)) > 0.3   # it moved
    Ea, Eb = ra.energy(), rb.energy()
    scale = np.max(Eb.kinetic)
    assert np.max(np.abs(Ea.total - Ea.total[0])) < 1e-8 * scale
    assert np.max(np.abs(Eb.total - Eb.total[0])) < 1e-8 * scale
    for i in (10, 50):
        for key, value in ra.reactions.items():
            assert_close(value[i], rb.reactions[key][i], atol=1e-6 * max(1.0, np.max(np.abs(value))),
                         rtol=0, name=f"reaction {key} at t = {t[i]}")
