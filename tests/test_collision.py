"""Colliding shapes (mb.Collision): contact rows against finite differences, and runs
against closed forms: an off-centre elastic collision of equal spheres, a ball bouncing on
a box, a box resting on a plane, Newton's cradle, many spheres in a box of planes; files."""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.compiled.collision_kernel import with_collisions

G = 9.81
FORMULATIONS = ("lagrange", "dae")


def free_body(m, name, shape, mass=1.0, inertia=(1e-3, 1e-3, 1e-3)):
    body = m.add(mb.Body(name, mass=mass, inertia=inertia, shape=shape))
    m.add(mb.Free(name + "_j", m.ground, body))
    return body


def ball_inertia(mass, r):
    return (0.4 * mass * r * r,) * 3


# -- contact rows ----------------------------------------------------------------------------
def _pair_model():
    m = mb.Model("pairs", gravity=(0, 0, 0))
    a = free_body(m, "a", [mb.Box((0.4, 0.3, 0.2)), mb.Capsule(0.05, 0.3, axis="y", origin=(0, 0, 0.2))])
    b = free_body(m, "b", [mb.Sphere(0.1), mb.Plane(normal=(0, 0, 1), origin=(0, 0, -0.3))])
    m.add(mb.Collision("ab", a, b))
    m.add(mb.Collision("floor", [a, b], (m.ground, mb.Plane(origin=(0, 0, -0.2)))))
    return m


def test_jacobian_and_bias_are_the_rates_of_the_gaps():
    """J qd is the gap's rate and d(J qd)/dt at fixed qd the bias, by central differences
    along the motion (features measured on both sides of the state)."""
    system = _pair_model().compile()
    kernel = with_collisions(system.kernel)
    names = [c.name for c in kernel.topology.contacts]
    rng = np.random.default_rng(3)
    q = np.concatenate(([0.0, 0.0, 0.0], [1, 0, 0, 0], [0.15, 0.05, 0.22], [1, 0, 0, 0])).astype(float)
    q[3:7] = [np.cos(0.1), np.sin(0.1), 0, 0]
    qd = rng.normal(size=12) * 0.5
    sm = kernel.topology.state_map
    h = 1e-6
    values = kernel.contacts(q, qd)
    measured = [i for i in range(len(names)) if np.any(values.J[[i]])]
    assert len(measured) >= 12        # box/capsule vs sphere/plane, the box's corners vs the floor
    plus, minus = q + h * sm.qdot(q, qd), q - h * sm.qdot(q, qd)
    g_rate = (kernel.contacts(plus, qd).g - kernel.contacts(minus, qd).g) / (2 * h)
    Jqd = values.J @ qd
    for i in measured:
        assert Jqd[i] == pytest.approx(g_rate[i], rel=1e-5, abs=1e-7), names[i]
    bias_rate = (kernel.contacts(plus, qd).J @ qd - kernel.contacts(minus, qd).J @ qd) / (2 * h)
    exact = [i for i in measured if names[i].startswith("floor")]   # fixed normals and corners: exact
    assert len(exact) >= 8
    for i in exact:
        assert values.bias[i] == pytest.approx(bias_rate[i], rel=1e-4, abs=1e-6), names[i]


def test_sphere_sphere_bias_is_exact():
    m = mb.Model("two", gravity=(0, 0, 0))
    a = free_body(m, "a", mb.Sphere(0.1))
    b = free_body(m, "b", mb.Sphere(0.2))
    m.add(mb.Collision("c", a, b))
    kernel = with_collisions(m.compile().kernel)
    q = np.array([0, 0, 0, 1, 0, 0, 0, 0.2, 0.15, 0.05, 1, 0, 0, 0], dtype=float)
    qd = np.array([0.3, -0.2, 0.1, 1.0, 2.0, -1.0, -0.4, 0.5, 0.2, 0.3, -1.0, 0.5])
    sm, h = kernel.topology.state_map, 1e-6
    rate = lambda x: kernel.contacts(x, qd).J @ qd    # noqa: E731
    fd = (rate(q + h * sm.qdot(q, qd)) - rate(q - h * sm.qdot(q, qd))) / (2 * h)
    assert kernel.contacts(q, qd).bias[0] == pytest.approx(fd[0], rel=1e-6)


# -- runs against closed forms -----------------------------------------------------------------
def _two_spheres(restitution=1.0):
    m = mb.Model("billiards", gravity=(0, 0, 0))
    r = 0.1
    a = free_body(m, "a", mb.Sphere(r), inertia=ball_inertia(1.0, r))
    b = free_body(m, "b", mb.Sphere(r), inertia=ball_inertia(1.0, r))
    m.add(mb.Collision("hit", a, b, restitution=restitution))
    return m


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_off_centre_elastic_collision_of_equal_spheres(formulation):
    """One sphere at rest, the other arriving off centre (impact parameter 0.1 = r): the
    outgoing velocities are perpendicular, momentum and energy are conserved, and the struck
    sphere leaves along the line of centres at the contact, 30 degrees off the incoming line."""
    system = _two_spheres().compile(formulation=formulation)
    q0 = [-1, 0.1, 0, 1, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0]
    v = 2.0
    res = system.simulate(1.0, q0, [v, 0, 0, 0, 0, 0] + [0] * 6)
    (event,) = res.events
    assert event.contact == "hit"
    assert event.time == pytest.approx((1 - np.sqrt(0.2 ** 2 - 0.1 ** 2)) / v, rel=1e-9)
    va, vb = res.qd[-1][:3], res.qd[-1][6:9]
    assert va @ vb == pytest.approx(0.0, abs=1e-10)
    assert np.allclose(va + vb, [v, 0, 0], atol=1e-12)
    assert va @ va + vb @ vb == pytest.approx(v * v, rel=1e-12)
    assert np.allclose(vb, v * np.cos(np.pi / 6) * np.array([np.cos(np.pi / 6), -0.5, 0]), atol=1e-10)
    assert event.energy_loss == pytest.approx(0.0, abs=1e-12)


def _ball_over_box(restitution, box_on_body=False):
    m = mb.Model("ball_box", gravity=(0, 0, -G))
    r = 0.05
    ball = m.add(mb.Body("ball", mass=0.5, inertia=ball_inertia(0.5, r), shape=mb.Sphere(r)))
    m.add(mb.Prismatic("drop", m.ground, ball, axis="z", coords="z"))
    block = mb.Box((0.4, 0.4, 0.2), origin=(0.03, -0.02, 0.1))
    m.add(mb.Collision("hit", ball, (m.ground, block), restitution=restitution))
    return m


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_ball_on_a_box_bounces_to_e_squared_of_its_drop(formulation):
    e, drop = 0.8, 0.8
    system = _ball_over_box(e).compile(formulation=formulation)
    top = 0.2 + 0.05           # the ball's centre touches at the box's top plus its radius
    res = system.simulate(1.2, [top + drop], [0.0])
    first, second = res.events[:2]
    assert first.time == pytest.approx(np.sqrt(2 * drop / G), rel=1e-9)
    after = res.t > first.time
    k = np.argmax(after)
    z, zd = res["z"][k], res["z_d"][k]
    apex = z + zd ** 2 / (2 * G) - top
    assert apex == pytest.approx(e ** 2 * drop, rel=1e-7)
    assert second.time - first.time == pytest.approx(2 * e * np.sqrt(2 * drop / G), rel=1e-7)


def test_ball_on_a_moving_box_exchanges_momentum():
    """A ball dropped on a box that rests on a plane (the box a free body): the box takes
    the ball's impulse and passes it to the plane (plastic below), and nothing sinks."""
    m = mb.Model("stack", gravity=(0, 0, -G))
    ball = free_body(m, "ball", mb.Sphere(0.05), mass=0.5, inertia=ball_inertia(0.5, 0.05))
    block = free_body(m, "block", mb.Box((0.4, 0.4, 0.2)), mass=2.0, inertia=(0.03, 0.03, 0.05))
    m.add(mb.Collision("hit", ball, block, restitution=0.5))
    m.add(mb.Collision("floor", [ball, block], (m.ground, mb.Plane())))
    res = m.compile().simulate(0.3, [0, 0, 0.6, 1, 0, 0, 0, 0, 0, 0.1, 1, 0, 0, 0], [0] * 12)
    hits = [e for e in res.events if e.contact == "hit"]
    assert hits and hits[0].time == pytest.approx(np.sqrt(2 * 0.35 / G), rel=1e-8)
    assert np.abs(res.q[:, 9] - 0.1).max() < 1e-8       # the block stays on the floor
    assert res.q[:, 2].min() > 0.25 - 1e-8              # the ball never enters the block


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_box_rests_on_a_plane_without_drift(formulation):
    m = mb.Model("resting", gravity=(0, 0, -G))
    box = free_body(m, "box", mb.Box((0.4, 0.3, 0.2)), mass=2.0, inertia=(0.02, 0.03, 0.04))
    m.add(mb.Collision("floor", box, (m.ground, mb.Plane(origin=(0, 0, -0.1)))))
    res = m.compile(formulation=formulation).simulate(10.0, [0.1, 0.2, 0.0, 1, 0, 0, 0], [0] * 6)
    assert res.t[-1] == 10.0
    assert np.abs(res.q[:, :3] - [0.1, 0.2, 0.0]).max() < 1e-9
    assert np.abs(res.qd).max() < (1e-9 if formulation == "lagrange" else 1e-5)   # dae: Baumgarte's small wobble
    closed = set(res.persistent_contacts)
    # (four coplanar corners are redundant: the formulation may hold any set that carries the box)
    assert len(closed) >= 2 and all(name.startswith("floor[") for name in closed)


def test_tilted_box_falls_flat_and_comes_to_rest():
    m = mb.Model("tilted", gravity=(0, 0, -G))
    box = free_body(m, "box", mb.Box((0.4, 0.3, 0.2)), mass=2.0, inertia=(0.02, 0.03, 0.04))
    m.add(mb.Collision("floor", box, (m.ground, mb.Plane())))
    q0 = [0, 0, 0.5, np.cos(0.2), np.sin(0.2), 0, 0]
    res = m.compile().simulate(3.0, q0, [0] * 6)
    assert res.q[-1][2] == pytest.approx(0.1, abs=1e-8)
    assert abs(res.q[-1][4]) < 1e-8 and abs(res.q[-1][5]) < 1e-8       # flat
    corners = with_collisions(m.compile().kernel)
    assert min(corners.contacts(q, np.zeros(6)).g.min() for q in res.q) > -1e-7


def _cradle(gap):
    m = mb.Model("cradle", gravity=(0, 0, 0))
    r = 0.05
    balls = []
    for i in range(3):
        balls.append(m.add(mb.Body(f"b{i}", mass=1.0, inertia=ball_inertia(1.0, r), shape=mb.Sphere(r))))
        m.add(mb.Prismatic(f"p{i}", m.ground, balls[-1], axis="x", coords=f"x{i}"))
    m.add(mb.Collision("touch", balls, balls, restitution=1.0))
    return m.compile(), [-0.3, 2 * r + gap, 4 * r + 2 * gap]


def test_newtons_cradle_touching_balls_take_one_simultaneous_impact():
    """Balls touching at rest: the arriving ball's impact is solved with Newton's law on every
    contact at once (the resting contact with e = 0), so balls 2 and 3 leave together:
    (-1/3, 2/3, 2/3) v. Momentum and energy are conserved, but the last ball alone does not
    take the whole speed, unlike a real cradle."""
    system, q0 = _cradle(0.0)
    res = system.simulate(0.5, q0, [1.0, 0, 0])
    assert [e.contact for e in res.events] == ["touch[0]"]
    assert np.allclose(res.qd[-1], [-1 / 3, 2 / 3, 2 / 3], atol=1e-12)
    assert 0.5 * res.qd[-1] @ res.qd[-1] == pytest.approx(0.5, rel=1e-12)


def test_newtons_cradle_with_small_gaps_transmits_the_speed():
    """A millimetre between the balls: two sequential two-ball elastic impacts, each swapping
    the speeds of equal masses, and the last ball leaves with the whole speed."""
    system, q0 = _cradle(1e-3)
    res = system.simulate(0.5, q0, [1.0, 0, 0])
    assert [e.contact for e in res.events] == ["touch[0]", "touch[2]"]
    assert res.events[1].time - res.events[0].time == pytest.approx(1e-3, rel=1e-6)
    assert np.allclose(res.qd[-1], [0, 0, 1], atol=1e-12)


def test_many_spheres_in_a_box_of_planes_keep_energy_and_stay_apart():
    """Spheres in zero gravity in a box of six planes, all elastic: the kinetic energy stays
    put and no two shapes overlap at any sample."""
    n, r, half = 8, 0.05, 0.4
    rng = np.random.default_rng(7)
    m = mb.Model("gas", gravity=(0, 0, 0))
    balls = [free_body(m, f"s{i}", mb.Sphere(r), inertia=ball_inertia(1.0, r)) for i in range(n)]
    walls = [(m.ground, mb.Plane(normal=s * np.eye(3)[k], origin=-s * half * np.eye(3)[k]))
             for k in range(3) for s in (1.0, -1.0)]
    m.add(mb.Collision("gas", balls, balls, restitution=1.0))
    m.add(mb.Collision("walls", balls, walls, restitution=1.0))
    grid = np.array([(x, y, z) for x in (-0.2, 0.0, 0.2) for y in (-0.2, 0.0, 0.2) for z in (-0.2, 0.2)])[:n]
    q0 = np.concatenate([np.concatenate((p, [1, 0, 0, 0])) for p in grid])
    v = rng.normal(size=(n, 3))
    qd0 = np.concatenate([np.concatenate((vi, [0, 0, 0])) for vi in v])
    system = m.compile()
    res = system.simulate(0.6, q0, qd0, rtol=1e-9)
    kinetic = 0.5 * (res.qd.reshape(len(res.t), n, 6)[:, :, :3] ** 2).sum(axis=(1, 2))
    assert np.allclose(kinetic, kinetic[0], rtol=1e-9)
    assert len(res.events) >= n
    kernel = with_collisions(system.kernel)
    assert min(kernel.contacts(q, np.zeros(6 * n)).g.min() for q in res.q[::5]) > -1e-7


# -- model checks and files --------------------------------------------------------------------
def test_bad_collisions_are_named():
    m = mb.Model("bad")
    plain = m.add(mb.Body("plain", mass=1.0, inertia=(1, 1, 1), shape=mb.Cylinder(0.1, 0.2)))
    m.add(mb.Free("f", m.ground, plain))
    m.add(mb.Collision("c", plain, (m.ground, mb.Plane())))
    with pytest.raises(mb.ModelError, match="'c'.*no collision shape"):
        m.compile().simulate(0.1, [0, 0, 1, 1, 0, 0, 0], [0] * 6)
    with pytest.raises(mb.ModelError, match="does not collide"):
        mb.Collision("d", (plain, mb.Cylinder(0.1, 0.2)), m.ground)
    with pytest.raises(mb.ModelError, match="restitution"):
        mb.Collision("e", plain, m.ground, restitution=1.5)


def test_integration_path_of_collisions():
    """Colliding shapes step in the compiled loops (their features measured in C:
    codegen/c/collide.c), on free joints in both formulations."""
    assert _two_spheres().compile().integration_path() == "compiled"
    assert _two_spheres().compile(formulation="dae").integration_path() == "compiled"


def test_collisions_are_saved_and_read_back(tmp_path):
    m = _pair_model()
    m.add(mb.Collision("elastic", m["a"], m["b"], restitution=0.9, friction=0.2))
    path = tmp_path / "pairs.toml"
    m.save(path)
    text = path.read_text()
    assert "[collisions.floor]" in text and 'type = "plane"' in text and 'type = "capsule"' in text
    again = mb.load(path)
    assert again["floor"].b[0][1] == mb.Plane(origin=(0, 0, -0.2))
    assert again["elastic"].restitution == 0.9 and again["elastic"].friction == 0.2
    assert [e[0] for e in again["floor"].a] == ["a", "b"]
    q0 = [0, 0, 0.5, 1, 0, 0, 0, 0.05, 0.0, 0.2, 1, 0, 0, 0]
    one = m.compile().simulate(0.5, q0, [0] * 12)
    two = again.compile().simulate(0.5, q0, [0] * 12)
    assert np.array_equal(one.q, two.q) and [e.contact for e in one.events] == [e.contact for e in two.events]


# -- friction ----------------------------------------------------------------------------------
@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_a_sliding_ball_starts_rolling_at_the_closed_form_time(formulation):
    """A ball launched sliding without spin on a Plane with Coulomb friction mu (the
    collision's): it sticks (rolls) at t = 2 v0 / (7 mu g) with speed 5 v0 / 7."""
    mu, v0, r = 0.3, 2.0, 0.1
    m = mb.Model("rolling", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=1.5, inertia=ball_inertia(1.5, r), shape=mb.Sphere(r)))
    m.add(mb.Planar("plane", m.ground, ball, normal="y", coords=["z", "x", "phi"]))
    m.add(mb.Collision("floor", ball, (m.ground, mb.Plane()), friction=mu))
    res = m.compile(formulation=formulation).simulate(0.3, [r, 0.0, 0.0], [0.0, v0, 0.0], rtol=1e-10, atol=1e-12)
    sticks = [e for e in res.events if e.kind == "stick"]
    assert len(sticks) == 1 and sticks[0].contact == "floor"
    assert sticks[0].time == pytest.approx(2 * v0 / (7 * mu * G), rel=1e-7)
    assert res["x_d"][-1] == pytest.approx(5 * v0 / 7, rel=1e-8)
    forces = res.contact_forces["floor"]
    assert forces[-1] == pytest.approx([0.0, 0.0, 1.5 * G], abs=1e-6)   # rolling: no friction force


def test_the_viewer_draws_collision_shapes_and_hits():
    from mbcomp.face.viewer.scene import build_scene
    m = mb.Model("drawn", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=0.5, inertia=ball_inertia(0.5, 0.05),
                         shape=[mb.Sphere(0.05), mb.Capsule(0.01, 0.2, axis="x")]))
    m.add(mb.Prismatic("drop", m.ground, ball, axis="z", coords="z"))
    m.add(mb.Collision("hit", (ball, mb.Sphere(0.05)), (m.ground, mb.Plane(extent=1.0)), restitution=0.5))
    res = m.compile().simulate(0.5, [0.5], [0.0])
    page = build_scene(res)
    kinds = [s["type"] for s in page["bodies"][0]["shapes"]]
    assert kinds == ["sphere", "capsule"]                       # the pair's own sphere is the body's
    (floor,) = page["ground"]
    assert floor["type"] == "box" and floor["size"] == [1.0, 1.0, 0.01] and floor["place"][2] == pytest.approx(-0.005)
    (hit,) = page["hits"]
    assert hit["t"] == pytest.approx(np.sqrt(2 * 0.45 / G), rel=1e-9) and np.allclose(hit["p"], 0.0, atol=1e-9)


def test_a_sweep_over_the_restitution_of_a_collision():
    system = _ball_over_box(0.8).compile()
    values = (0.2, 0.5, 0.8)
    runs = mb.sweep(system, [{"parameters": {"hit.restitution": e}} for e in values], q0=[1.05], qd0=[0.0],
                    t_end=0.6, threads=2)
    for e, res in zip(values, runs):
        k = np.argmax(res.t > res.events[0].time)
        assert res["z"][k] + res["z_d"][k] ** 2 / (2 * G) - 0.25 == pytest.approx(e ** 2 * 0.8, rel=1e-7)
    alone = system.simulate(0.6, [1.05], [0.0], parameters={"hit.restitution": 0.5})
    assert np.array_equal(alone.q, runs[1].q)


def test_a_box_sliding_on_its_corners_stops_where_coulomb_says():
    """A box launched at v0 on a Plane with friction mu (collision corners): it slides
    v0^2 / (2 mu g) and sticks at t = v0 / (mu g)."""
    mu, v0 = 0.4, 1.0
    m = mb.Model("slide", gravity=(0, 0, -G))
    box = m.add(mb.Body("box", mass=2.0, inertia=(0.02, 0.03, 0.04), shape=mb.Box((0.4, 0.3, 0.2))))
    m.add(mb.Planar("plane", m.ground, box, normal="y", coords=["z", "x", "phi"]))
    m.add(mb.Collision("floor", box, (m.ground, mb.Plane(origin=(0, 0, -0.1))), friction=mu))
    res = m.compile().simulate(0.4, [0.0, 0.0, 0.0], [0.0, v0, 0.0], rtol=1e-10, atol=1e-12)
    sticks = [e for e in res.events if e.kind == "stick"]
    assert sticks and sticks[0].time == pytest.approx(v0 / (mu * G), rel=1e-6)
    assert res["x"][-1] == pytest.approx(v0 ** 2 / (2 * mu * G), rel=1e-6)
    assert np.abs(res["z"]).max() < 1e-9 and np.abs(res["phi"]).max() < 1e-9
