"""Colliding shapes in the compiled loops of both formulations (codegen/c/collide.c,
compiled/collision_c.py): the C narrow phase gives the Python one's numbers, box edges meet
as an independent computation says, and runs in compiled code follow closed forms and the
scipy stepping's events."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.compiled.collision_kernel import with_collisions
from mbcomp.core import collide

G = 9.81
FORMULATIONS = ("lagrange", "dae")


def _rot(axis, angle):
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis
    return np.array([[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                     [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                     [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]])


# -- the narrow phase --------------------------------------------------------------------------
def test_box_edges_crossing_meet_at_the_closed_form():
    """Box A (half edges 0.5) turned 45 degrees about x: its top is an edge along x at height
    0.5 sqrt(2).  Box B turned 45 degrees about y above it: its bottom is an edge along y at
    z_B - 0.5 sqrt(2).  The edges cross: the gap is z_B - sqrt(2) along +z, the points at
    (x_B, 0, 0.5 sqrt(2)) and (x_B, 0, z_B - 0.5 sqrt(2)); no corner is that close."""
    half = np.full(3, 0.5)
    for z_b, x_b in ((1.5, 0.1), (1.4, -0.2), (1.3, 0.05)):    # apart, just touching less, crossed
        a = ("box", np.zeros(3), _rot((1, 0, 0), np.pi / 4), half)
        b = ("box", np.array([x_b, 0.0, z_b]), _rot((0, 1, 0), np.pi / 4), half)
        feats = collide.features(a, b)
        edge = feats[16 + 0 * 3 + 1]                      # A's x edges against B's y edges
        assert edge.gap == pytest.approx(z_b - np.sqrt(2), abs=1e-12)
        assert np.allclose(edge.normal, [0, 0, 1], atol=1e-12)
        assert np.allclose(edge.pa, [x_b, 0, 0.5 * np.sqrt(2)], atol=1e-12)
        assert np.allclose(edge.pb, [x_b, 0, z_b - 0.5 * np.sqrt(2)], atol=1e-12)
        assert min(f.gap for f in feats[:16]) > edge.gap + 0.1   # the corners are farther
        # the gap is the boxes' distance when apart (sampled on B's bottom edge and A's top edge)
        if edge.gap > 0:
            s = np.linspace(-0.5, 0.5, 2001)
            top = np.stack((s, 0 * s, 0 * s + 0.5 * np.sqrt(2)), axis=1)
            bottom = np.stack((0 * s + x_b, s, 0 * s + z_b - 0.5 * np.sqrt(2)), axis=1)
            d = np.linalg.norm(top[:, None] - bottom[None], axis=2).min()
            assert edge.gap == pytest.approx(d, abs=1e-6)


def _crossed_boxes():
    """Two boxes on revolute/prismatic chains (the dae loop needs screw joints) whose edges
    cross, a capsule pair and a sphere on a capsule, with spheres and boxes on a plane."""
    m = mb.Model("shapes", gravity=(0, 0, -G))
    a = m.add(mb.Body("a", mass=1.0, inertia=(0.1, 0.1, 0.1),
                      shape=[mb.Box((1.0, 1.0, 1.0), rotation=_rot((1, 0, 0), np.pi / 4)),
                             mb.Capsule(0.05, 0.6, axis="x", origin=(0, 0, 1.2))]))
    b = m.add(mb.Body("b", mass=1.0, inertia=(0.1, 0.1, 0.1),
                      shape=[mb.Box((1.0, 1.0, 1.0), rotation=_rot((0, 1, 0), np.pi / 4)),
                             mb.Capsule(0.05, 0.6, axis="y", origin=(0, 0, 1.2)), mb.Sphere(0.1, origin=(0.3, 0, 1.0))]))
    m.add(mb.Revolute("ra", m.ground, a, axis="z", coords="ta"))
    m.add(mb.Prismatic("pb", m.ground, b, axis="z", parent_point=(0.0, 0.0, 1.4), coords="zb"))
    m.add(mb.Collision("ab", a, b))
    m.add(mb.Collision("floor", [a, b], (m.ground, mb.Plane(origin=(0, 0, -1.0)))))
    return m


def test_c_narrow_phase_gives_the_python_numbers():
    """Gaps, Jacobian rows and biases of every candidate feature (box corners, box edges
    crossing, capsules, spheres, planes) computed in C equal those of the Python narrow phase."""
    system = _crossed_boxes().compile(formulation="dae")
    kernel = with_collisions(system.kernel)
    lib = kernel.compiled.functions.lib
    rng = np.random.default_rng(5)
    for q in ([0.1, -0.02], [0.4, 0.01], [-0.3, -0.05]):
        q, qd = np.array(q), rng.normal(size=2)
        stretch = kernel.compiled_stretch(lib, q, qd)
        try:
            rows = stretch.evaluate(q, qd, kernel.p)
        finally:
            stretch.close()
        values = kernel.contacts(q, qd)
        index = kernel.n_own + stretch.candidates
        assert len(index) == len(kernel.features)            # (every pair is within the margin here)
        finite = np.isfinite(values.g[index]) & (np.abs(values.J[index]).sum(axis=1) > 0)
        assert finite.sum() >= 20
        assert np.allclose(rows[finite, 0], values.g[index][finite], rtol=1e-12, atol=1e-13)
        assert np.allclose(rows[finite, 2:], values.J[index][finite], rtol=1e-12, atol=1e-13)
        assert np.allclose(rows[finite, 1], values.bias[index][finite], rtol=1e-10, atol=1e-12)


def test_sliding_points_and_crossing_edges_have_the_exact_bias():
    """At a state where box edges cross and capsule axes cross (both nearest points inside
    their segments: they slide), J qd is the gap's rate and the bias is d(J qd)/dt at fixed
    qd (central differences; q moves linearly: revolute and prismatic joints)."""
    system = _crossed_boxes().compile(formulation="dae")
    kernel = with_collisions(system.kernel)
    names = [c.name for c in kernel.topology.contacts]
    q, qd, h = np.array([0.3, -0.02]), np.array([1.3, -0.4]), 1e-6
    values = kernel.contacts(q, qd)
    plus, minus = kernel.contacts(q + h * qd, qd), kernel.contacts(q - h * qd, qd)
    edge = kernel.n_own + 16 + 1        # A's x edges against B's y edges (the first pair: the boxes)
    kinds = [{type(kernel.entries[p.a].shape).__name__, type(kernel.entries[p.b].shape).__name__} for p in kernel.pairs]
    (pair,) = [k for k, pair_kinds in enumerate(kinds) if pair_kinds == {"Capsule"}]
    capsules = [kernel.pairs[pair].first]                              # capsule a vs capsule b
    checked = [edge] + capsules
    assert values.g[edge] < 0.0 and len(capsules) == 1
    for i in checked:
        assert values.J[[i]] @ qd == pytest.approx((plus.g[i] - minus.g[i]) / (2 * h), rel=1e-6), names[i]
        rate = (plus.J[[i]] @ qd - minus.J[[i]] @ qd) / (2 * h)
        assert values.bias[i] == pytest.approx(float(rate[0]), rel=1e-5, abs=1e-8), names[i]


# -- runs in compiled code -----------------------------------------------------------------------
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_newtons_cradle_runs_compiled_and_the_last_ball_leaves(formulation):
    system = mb.load("newtons_cradle").compile(formulation=formulation)
    assert system.integration_path() == "compiled"
    L, theta = 0.3, 0.5
    res = system.simulate(0.35, [theta, 0, 0, 0, 0])
    assert res.stats["path"] == "compiled"
    assert [e.contact for e in res.events][:4] == ["touch[0]", "touch[4]", "touch[7]", "touch[9]"]
    speed = np.sqrt(2 * G * L * (1 - np.cos(theta)))
    after = np.argmax(res.t > res.events[3].time)
    assert abs(res.qd[after, 4]) * L == pytest.approx(speed, rel=2e-3)   # (the row's 4.8 ms of swing)
    energy = res.energy().total
    assert np.abs(energy - energy[0]).max() < 1e-9 * abs(energy[0]) + 1e-12


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_ball_on_box_apexes_fall_as_e_to_the_2n(formulation):
    system = mb.load("ball_on_box").compile(formulation=formulation)
    assert system.integration_path() == "compiled"
    e, top, drop = 0.8, 0.25, 0.8
    res = system.simulate(2.2, [top + drop], [0.0])
    assert res.stats["path"] == "compiled" and len(res.events) >= 3
    for n, event in enumerate(res.events[:3], start=1):
        k = np.flatnonzero(res.t == event.time)[-1]          # the state just after the impact
        apex = res["z"][k] + res["z_d"][k] ** 2 / (2 * G) - top
        assert apex == pytest.approx(e ** (2 * n) * drop, rel=1e-8)


def _discs():
    """Two equal discs (spheres on planar joints) in zero gravity."""
    m = mb.Model("discs", gravity=(0, 0, 0))
    r = 0.1
    balls = []
    for name in ("a", "b"):
        ball = m.add(mb.Body(name, mass=1.0, inertia=(0.4 * r * r,) * 3, shape=mb.Sphere(r)))
        m.add(mb.Planar(f"{name}_j", m.ground, ball, normal="z"))
        balls.append(ball)
    m.add(mb.Collision("hit", balls[0], balls[1], restitution=1.0))
    return m


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_off_centre_elastic_spheres_leave_perpendicular(formulation):
    system = _discs().compile(formulation=formulation)
    assert system.integration_path() == "compiled"
    v = 2.0
    res = system.simulate(1.0, [-1.0, 0.1, 0.0, 0.0, 0.0, 0.0], [v, 0, 0, 0, 0, 0])
    assert res.stats["path"] == "compiled"
    (event,) = res.events
    assert event.time == pytest.approx((1 - np.sqrt(0.2 ** 2 - 0.1 ** 2)) / v, rel=1e-9)
    va, vb = res.qd[-1][:2], res.qd[-1][3:5]
    assert va @ vb == pytest.approx(0.0, abs=1e-10)
    assert np.allclose(va + vb, [v, 0], atol=1e-12)
    assert va @ va + vb @ vb == pytest.approx(v * v, rel=1e-12)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_box_rests_on_a_plane_on_four_corners_without_drift(formulation):
    """A box on a planar joint (x, z, a tilt about y) set down on a plane: its four bottom
    corners are held (two pairs, dependent in the plane of motion) for 10 s."""
    m = mb.Model("resting", gravity=(0, 0, -G))
    box = m.add(mb.Body("box", mass=2.0, inertia=(0.02, 0.03, 0.04), shape=mb.Box((0.4, 0.3, 0.2))))
    m.add(mb.Planar("slide", m.ground, box, normal="y"))
    m.add(mb.Collision("floor", box, (m.ground, mb.Plane(origin=(0, 0, -0.1)))))
    system = m.compile(formulation=formulation)
    assert system.integration_path() == "compiled"
    assert system.coords == ("slide_z", "slide_x", "slide_angle")
    res = system.simulate(10.0, [0.0, 0.1, 0.0], [0.0, 0.0, 0.0])
    assert res.stats["path"] == "compiled" and res.t[-1] == 10.0
    assert len(res.persistent_contacts) == 4
    assert np.abs(res.q - [0.0, 0.1, 0.0]).max() < 1e-10
    scipy = system.simulate(2.0, [0.0, 0.1, 0.0], [0.0, 0.0, 0.0], integrator="scipy")   # (the compiled rows, stepped by scipy)
    assert len(scipy.persistent_contacts) == 4 and np.abs(scipy.q - [0.0, 0.1, 0.0]).max() < 1e-10


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("name, q0, t_end", [("newtons_cradle", [0.5, 0, 0, 0, 0], 0.6), ("ball_on_box", [1.05], 2.0)])
def test_compiled_and_scipy_stepping_meet_the_same_events(formulation, name, q0, t_end):
    system = mb.load(name).compile(formulation=formulation)
    compiled = system.simulate(t_end, q0)
    scipy = system.simulate(t_end, q0, integrator="scipy")
    assert compiled.stats["path"] == "compiled" and scipy.stats["path"].startswith("scipy")
    assert [e.contact for e in compiled.events] == [e.contact for e in scipy.events]
    assert len(compiled.events) >= 2
    for a, b in zip(compiled.events, scipy.events):
        assert a.time == pytest.approx(b.time, abs=1e-9)


def test_collisions_with_friction_run_compiled():
    """(tests/test_collision_friction_compiled.py has their numbers.)"""
    m = mb.Model("rough", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.0, inertia=(1e-3,) * 3, shape=mb.Sphere(0.1)))
    m.add(mb.Planar("j", m.ground, ball, normal="y"))
    m.add(mb.Collision("floor", ball, (m.ground, mb.Plane()), friction=0.5))
    assert m.compile(formulation="dae").integration_path() == "compiled"
