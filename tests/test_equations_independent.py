"""mbcomp's tree equations against an independent sympy derivation (``independent.py``).

Seeded random chains and branched trees mixing Revolute, Prismatic, Spherical (2- and
3-angle Euler sequences) and Fixed joints, point masses and full inertias, generic and
named axes, and gravity in an arbitrary direction are built twice: with mbcomp's public
API, and as equations derived from scratch by the oracle.  At random states the mass
matrix, accelerations (with and without applied generalised forces), holding forces,
energies and every body's world-frame kinematics must agree to 1e-10 relative.

Tests marked ``slow`` (the largest models, more of the oracle's self-checks) can be
deselected with ``-m "not slow"``; the whole file runs in well under a minute.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

try:                                    # tests/ on sys.path (pytest's default rootdir-less import)
    import independent as ind
except ImportError:                     # tests imported as a package
    from tests import independent as ind

REL = 1e-10
N_STATES = 3

# (seed, bodies, branched): chosen so that together they cover every joint type, 2- and
# 3-angle (Tait-Bryan and proper Euler) sequences, point masses and both tree shapes.
FAST_MODELS = [(1002, 4, False), (1003, 5, True), (1006, 4, False), (1009, 3, True),
               (1010, 4, False), (1014, 4, False), (1020, 2, False), (1023, 5, True)]
SLOW_MODELS = [(1007, 5, True), (1015, 5, True)]           # 8 coordinates each


def model_param(key: tuple, slow: bool = False):
    """A pytest parameter with a readable id, e.g. ``seed1003-5bodies-tree``."""
    seed, n_bodies, branched = key
    marks = [pytest.mark.slow] if slow else []
    marks.append(pytest.mark.xdist_group(f"oracle-{seed}"))  # parallel runs derive each model once
    return pytest.param(key, id=f"seed{seed}-{n_bodies}bodies-{'tree' if branched else 'chain'}", marks=marks)


MODEL_PARAMS = [model_param(k) for k in FAST_MODELS] + [model_param(k, slow=True) for k in SLOW_MODELS]


# ----------------------------------------------------------------------------------
# Fixtures (cached per model: derivation and compilation happen once)
# ----------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def description(key: tuple) -> dict:
    """The random tree for ``key = (seed, n_bodies, branched)``."""
    seed, n_bodies, branched = key
    return ind.random_tree(np.random.default_rng(seed), n_bodies, branched=branched)


@lru_cache(maxsize=None)
def oracle(key: tuple) -> ind.Equations:
    """The independently derived equations."""
    return ind.derive(description(key))


@lru_cache(maxsize=None)
def compiled(key: tuple):
    """The same model compiled by mbcomp (into the run's own new cache: the model compiles,
    and shares the compiled C templates with the models of its kind)."""
    return ind.to_mbcomp(description(key)).compile()


def states(key: tuple):
    """``N_STATES`` reproducible random states (q, qd) of the model."""
    rng = np.random.default_rng([key[0], 7])
    return [ind.random_state(rng, description(key)) for _ in range(N_STATES)]


def assert_rel(actual, expected, what: str, floor: float = 1e-3) -> None:
    """``max|actual - expected| <= REL * max(max|expected|, floor)``: relative to the size
    of the whole array (``floor`` covers arrays that are legitimately zero)."""
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, f"{what}: shape {actual.shape} != {expected.shape}"
    scale = max(float(np.max(np.abs(expected), initial=0.0)), floor)
    error = float(np.max(np.abs(actual - expected), initial=0.0))
    assert error <= REL * scale, (f"{what}: max error {error:.3e} > {REL:g} x {scale:.3e}\n"
                                  f"mbcomp:\n{actual}\nindependent:\n{expected}")


# ----------------------------------------------------------------------------------
# The comparisons
# ----------------------------------------------------------------------------------
@pytest.mark.parametrize("key", MODEL_PARAMS)
def test_coordinates(key):
    """Coordinates come depth-first from the ground, as the oracle declares them."""
    sys, eq = compiled(key), oracle(key)
    assert list(sys.coords) == eq.coords
    assert sys.ndof == len(eq.coords)


@pytest.mark.parametrize("key", MODEL_PARAMS)
def test_mass_matrix(key):
    """M(q) is the oracle's sum of m Jv^T Jv + Jw^T I Jw."""
    sys, eq = compiled(key), oracle(key)
    for i, (q, _) in enumerate(states(key)):
        M = np.asarray(sys.mass_matrix(q))
        assert_rel(M, eq.mass_matrix(q), f"mass matrix, state {i}")
        assert_rel(M, M.T, f"mass matrix symmetry, state {i}")


@pytest.mark.parametrize("key", MODEL_PARAMS)
def test_accelerations(key):
    """qdd = M^-1 F with gravity, gyroscopic and convective terms; and with tau."""
    sys, eq = compiled(key), oracle(key)
    rng = np.random.default_rng([key[0], 11])
    for i, (q, qd) in enumerate(states(key)):
        expected = eq.accelerations(q, qd)
        actual = np.asarray(sys.accelerations(q, qd))
        assert_rel(actual, expected, f"accelerations, state {i}")
        assert_rel(np.asarray(sys.mass_matrix(q)) @ actual, eq.forcing(q, qd), f"M qdd = F, state {i}")
        tau = rng.uniform(-2.0, 2.0, size=len(q))
        assert_rel(sys.accelerations(q, qd, tau=tau), eq.accelerations(q, qd, tau=tau),
                   f"accelerations with tau, state {i}")


@pytest.mark.parametrize("key", MODEL_PARAMS)
def test_holding_forces(key):
    """The forces that hold the model at rest cancel the gravity generalised force."""
    sys, eq = compiled(key), oracle(key)
    for i, (q, qd) in enumerate(states(key)):
        gravity_force = eq.forcing(q, np.zeros_like(qd))
        assert_rel(sys.holding_forces(q), -gravity_force, f"holding forces, state {i}")
        assert_rel(sys.accelerations(q, np.zeros_like(qd), tau=sys.holding_forces(q)), np.zeros_like(q),
                   f"held at rest, state {i}", floor=1.0)


@pytest.mark.parametrize("key", MODEL_PARAMS)
def test_energy(key):
    """Kinetic energy, and potential -sum m g . r_com (the same zero as the oracle)."""
    sys, eq = compiled(key), oracle(key)
    potentials = []
    for i, (q, qd) in enumerate(states(key)):
        energy = sys.energy(q, qd)
        assert_rel(energy.kinetic, eq.kinetic(q, qd), f"kinetic energy, state {i}")
        assert_rel(energy.potential, eq.potential(q), f"potential energy, state {i}", floor=1.0)
        assert_rel(energy.total, energy.kinetic + energy.potential, f"total energy, state {i}", floor=1.0)
        potentials.append((energy.potential, eq.potential(q)))
    (va, vb), (wa, wb) = potentials[0], potentials[1]
    assert_rel(va - wa, vb - wb, "potential energy difference between states", floor=1.0)


@pytest.mark.parametrize("key", MODEL_PARAMS)
def test_body_states(key):
    """Every body's COM position, rotation, velocities and accelerations (world frame)."""
    sys, eq = compiled(key), oracle(key)
    for i, (q, qd) in enumerate(states(key)):
        for body in eq.bodies:
            actual = sys.body_state(body, q, qd)
            expected = eq.body_state(body, q, qd)
            for name, value in expected.items():
                assert_rel(getattr(actual, name), value, f"{body}.{name}, state {i}", floor=1.0)


@pytest.mark.parametrize("key", MODEL_PARAMS[:2])
def test_state_by_name(key):
    """q and qd given as dicts by coordinate name mean the same as arrays."""
    sys, eq = compiled(key), oracle(key)
    q, qd = states(key)[0]
    by_name = dict(zip(eq.coords, q)), dict(zip(eq.coords, qd))
    assert_rel(sys.mass_matrix(by_name[0]), eq.mass_matrix(q), "mass matrix from a dict")
    assert_rel(sys.accelerations(*by_name), eq.accelerations(q, qd), "accelerations from dicts")


# ----------------------------------------------------------------------------------
# The oracle and the generator themselves
# ----------------------------------------------------------------------------------
@pytest.mark.parametrize("key", [model_param(k) for k in [(1009, 3, True), (1003, 5, True), (1020, 2, False)]]
                         + [model_param(k, slow=True) for k in [(1002, 4, False), (1010, 4, False)]])
def test_oracle_methods_agree(key):
    """Virtual power (propagated Jacobians, Newton-Euler bias terms) and Lagrange
    (differentiated positions and rotation matrices, derivatives of M) give the same
    equations: a check of the oracle itself."""
    projected = oracle(key)
    lagrange = ind.lagrange_of(projected)
    for i, (q, qd) in enumerate(states(key)):
        assert_rel(lagrange.mass_matrix(q), projected.mass_matrix(q), f"oracle mass matrix, state {i}")
        assert_rel(lagrange.forcing(q, qd), projected.forcing(q, qd), f"oracle forcing, state {i}")
        assert_rel(lagrange.kinetic(q, qd), projected.kinetic(q, qd), f"oracle kinetic energy, state {i}")


def test_models_cover_the_joint_zoo():
    """The chosen seeds really mix every feature the comparisons are meant to exercise."""
    joints = [j for key in FAST_MODELS + SLOW_MODELS for j in description(key)["joints"]]
    bodies = [b for key in FAST_MODELS + SLOW_MODELS for b in description(key)["bodies"].values()]
    assert {j["type"] for j in joints} == {"Revolute", "Prismatic", "Spherical", "Fixed"}
    sequences = {j["sequence"] for j in joints if j["type"] == "Spherical"}
    assert any(len(s) == 2 for s in sequences)
    assert any(len(s) == 3 and s[0] == s[2] for s in sequences), "a proper Euler sequence"
    assert any(len(set(s)) == 3 for s in sequences), "a Tait-Bryan sequence"
    axes = [j["axis"] for j in joints if "axis" in j]
    assert any(isinstance(a, str) for a in axes) and any(not isinstance(a, str) for a in axes)
    assert any(b["inertia"] is None for b in bodies) and any(b["inertia"] is not None for b in bodies)
    parents = [[j["parent"] for j in description(key)["joints"]] for key in FAST_MODELS + SLOW_MODELS]
    assert any(len(set(p)) < len(p) for p in parents), "a branched tree"
    assert any(len(set(p)) == len(p) for p in parents), "a chain"


@pytest.mark.parametrize("seed", range(40))
def test_random_tree_is_valid(seed):
    """Generated trees are small, parents-first, with physical masses and inertias."""
    rng = np.random.default_rng(seed)
    tree = ind.random_tree(rng, 2 + seed % 4)
    assert len(ind.coordinate_names(tree)) <= 8
    placed = {"ground"}
    for joint in tree["joints"]:
        assert joint["parent"] in placed and joint["child"] not in placed
        placed.add(joint["child"])
    assert list(tree["bodies"]) == [j["child"] for j in tree["joints"]], "bodies declared depth-first"
    assert np.isclose(np.linalg.norm(tree["gravity"]), 9.81)
    for body in tree["bodies"].values():
        assert 0.5 <= body["mass"] <= 3.0
        if body["inertia"] is not None:
            inertia = np.asarray(body["inertia"])
            assert np.array_equal(inertia, inertia.T)
            a, b, c = np.linalg.eigvalsh(inertia)
            assert a > 0 and c <= a + b


def test_the_oracles_evaluator_matches_sympy_on_real_and_complex_inputs():
    """``straight_line`` (the oracle's numeric evaluation) gives sympy's own values, for real
    inputs and for the complex steps of the Lagrange self-check, and refuses what it cannot
    evaluate."""
    import sympy as sp
    x, y, p = sp.symbols("x y p", real=True)
    shared = sp.sin(x) * sp.cos(y) + p ** 2
    outputs = [sp.Matrix([[shared, 0], [sp.sqrt(shared + 3) / (1 + x ** 2), shared ** -3]]), x * y - p / 7]
    evaluate = ind.straight_line([[x, y], [p]], outputs)
    for point in ([0.3, -1.2], [0.3 + 0.2j, -1.2]):   # complex: a step of 0.2j, visible at 1e-14
        values = {x: point[0], y: point[1], p: 0.8}
        got = evaluate(np.array(point), np.array([0.8]))
        expected = [np.array([complex(e.evalf(30, subs=values)) for e in outputs[0]]),
                    complex(outputs[1].evalf(30, subs=values))]
        np.testing.assert_allclose(got[0], expected[0], rtol=1e-14)
        np.testing.assert_allclose(got[1], expected[1], rtol=1e-14)
    with pytest.raises(TypeError, match="tan"):
        ind.straight_line([[x]], [sp.tan(x)])


def test_the_oracles_derivative_is_sympys():
    """``_derivative``/``_jacobian`` (the oracle's memoised differentiation) equal sympy's
    ``diff`` on the operations the derivation uses, and refuse others."""
    import sympy as sp
    x, y, p = sp.symbols("x y p", real=True)
    shared = sp.sin(x) * sp.cos(x * y) + p * x ** 3
    exprs = sp.Matrix([shared * sp.sqrt(shared ** 2 + 1), sp.cos(shared) / (1 + y ** 2), p, x * y * shared])
    J = ind._jacobian(exprs, [x, y])
    for i in range(4):
        for k, v in enumerate((x, y)):
            assert sp.simplify(J[i, k] - exprs[i].diff(v)) == 0, (i, k)
    with pytest.raises(TypeError, match="exp"):
        ind._jacobian(sp.Matrix([sp.exp(x)]), [x])
