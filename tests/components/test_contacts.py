"""Contact: construction and validation, gaps against hand geometry, parameters, the
``System.impact`` interface and the errors users get (bad input, penetrated start)."""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

import mbcomp as mb

G = 9.81


@functools.lru_cache(maxsize=None)
def slide(formulation="lagrange", e=0.5, origin=(0.0, 0.0, 0.0), point=(0.0, 0.0, 0.0)):
    """A 2 kg block on a vertical slide (coordinate z) above a floor."""
    m = mb.Model("block", gravity=(0, 0, -G))
    b = m.add(mb.Body("block", mass=2.0))
    m.add(mb.Prismatic("z", m.ground, b, axis="z", coords="z"))
    m.add(mb.Contact("floor", b, point=point, normal=(0, 0, 1), origin=origin, restitution=e))
    return m.compile(formulation=formulation)


M_CARRIAGE, M_BALL = 0.5, 1.5  # the x slide carries both, the z slide the ball alone
N_SLOPE = np.array([-1.0, 0.0, 2.0]) / math.sqrt(5.0)
O_SLOPE = np.array([1.0, 0.0, 0.0])


@functools.lru_cache(maxsize=None)
def projectile(formulation="lagrange", e=0.7):
    """A 1.5 kg ball on a 0.5 kg carriage sliding along x, itself free along z: thrown at a
    plane through (1, 0, 0) with normal (-1, 0, 2)/sqrt(5) (a slope rising to the right)."""
    m = mb.Model("projectile", gravity=(0, 0, -G))
    carriage = m.add(mb.Body("carriage", mass=M_CARRIAGE))
    ball = m.add(mb.Body("ball", mass=M_BALL))
    m.add(mb.Prismatic("x", m.ground, carriage, axis="x", coords="x"))
    m.add(mb.Prismatic("z", carriage, ball, axis="z", coords="z"))
    m.add(mb.Contact("slope", ball, normal=tuple(N_SLOPE * 3.0), origin=tuple(O_SLOPE), restitution=e))
    return m.compile(formulation=formulation)


# ----------------------------------------------------------------------------------------------
# Construction and validation
# ----------------------------------------------------------------------------------------------
class TestConstruction:
    def test_defaults(self):
        c = mb.Contact("c", "body")
        assert c.point == (0.0, 0.0, 0.0) and c.origin == (0.0, 0.0, 0.0)
        assert c.normal == (0.0, 0.0, 1.0)
        assert c.restitution == 0.0

    def test_normal_is_made_unit(self):
        c = mb.Contact("c", "body", normal=(3.0, 0.0, 4.0))
        np.testing.assert_allclose(c.normal, (0.6, 0.0, 0.8), rtol=1e-15)
        c = mb.Contact("c", "body", normal=(0, 0, 1e-3))
        assert c.normal == (0.0, 0.0, 1.0)

    @pytest.mark.parametrize("e", [0.0, 0.25, 1.0, 1])
    def test_restitution_in_range_is_accepted(self, e):
        assert mb.Contact("c", "body", restitution=e).restitution == float(e)

    @pytest.mark.parametrize("kwargs, message", [
        (dict(restitution=-0.1), r"restitution must lie in \[0, 1\], got -0.1"),
        (dict(restitution=1.01), r"restitution must lie in \[0, 1\], got 1.01"),
        (dict(restitution=float("nan")), "restitution must be finite"),
        (dict(restitution=float("inf")), "restitution must be finite"),
        (dict(restitution="hard"), "restitution must be a number"),
        (dict(restitution=None), "restitution must be a number"),
        (dict(restitution=True), "restitution must be a number"),
        (dict(normal=(0, 0, 0)), "normal has zero length"),
        (dict(normal=(0, 0)), "normal must have 3 components"),
        (dict(normal=(0, float("nan"), 1)), "normal .* non-finite"),
        (dict(point=(0, np.inf, 0)), "point .* non-finite"),
        (dict(origin=(1, 2)), "origin must have 3 components"),
    ])
    def test_bad_values_raise_a_model_error_naming_the_contact(self, kwargs, message):
        with pytest.raises(mb.ModelError, match=message) as info:
            mb.Contact("bumper", "body", **kwargs)
        assert "Contact 'bumper'" in str(info.value)
        assert isinstance(info.value, ValueError)

    def test_unknown_body_is_reported_at_compile_with_every_problem(self):
        m = mb.Model("m")
        b = m.add(mb.Body("b", mass=1.0))
        m.add(mb.Prismatic("z", m.ground, b, axis="z"))
        m.add(mb.Contact("c1", "nobody"), mb.Contact("c2", "ghost"))
        with pytest.raises(mb.ModelError) as info:
            m.compile()
        text = str(info.value)
        assert "Contact 'c1': body 'nobody' is not in the model" in text
        assert "Contact 'c2': body 'ghost' is not in the model" in text

    def test_duplicate_name_is_refused_by_add(self):
        m = mb.Model("m")
        b = m.add(mb.Body("b", mass=1.0))
        m.add(mb.Contact("c", b))
        with pytest.raises(mb.ModelError, match="Contact 'c'.*already used"):
            m.add(mb.Contact("c", b))

    def test_body_by_name_or_object_gives_the_same_system(self):
        gaps = []
        for by_name in (False, True):
            m = mb.Model("m", gravity=(0, 0, -G))
            b = m.add(mb.Body("b", mass=1.0))
            m.add(mb.Prismatic("z", m.ground, b, axis="z"))
            m.add(mb.Contact("c", "b" if by_name else b, point=(0, 0, -0.1)))
            gaps.append(m.compile().gaps([0.3]))
        assert gaps[0] == gaps[1] == {"c": pytest.approx(0.2, abs=1e-15)}


# ----------------------------------------------------------------------------------------------
# Gaps
# ----------------------------------------------------------------------------------------------
class TestGaps:
    def test_gap_of_a_body_point_above_the_floor(self):
        system = slide(point=(0.0, 0.0, -0.1), origin=(0.0, 0.0, 0.2))
        for z in (-1.0, 0.0, 0.3, 2.5):
            assert system.gaps([z]) == {"floor": pytest.approx(z - 0.1 - 0.2, abs=1e-14)}
        assert system.gaps({"z": 0.1})["floor"] == pytest.approx(-0.2, abs=1e-14)  # negative: penetrated

    def test_gap_on_a_rotating_body_with_a_slanted_normal(self):
        m = mb.Model("arm")
        arm = m.add(mb.Body("arm", mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 0.1, 0.1)))
        m.add(mb.Revolute("hinge", m.ground, arm, axis="z"))
        normal = np.array([1.0, 2.0, 0.0]) / math.sqrt(5)
        origin = np.array([0.2, -0.4, 0.0])
        m.add(mb.Contact("c", arm, point=(0.8, 0.1, 0), normal=(1, 2, 0), origin=tuple(origin)))
        system = m.compile()
        for th in (-1.0, 0.0, 0.4, 2.0):
            p = np.array([0.8 * math.cos(th) - 0.1 * math.sin(th), 0.8 * math.sin(th) + 0.1 * math.cos(th), 0.0])
            assert system.gaps([th])["c"] == pytest.approx(normal @ (p - origin), abs=1e-14)

    def test_moving_the_plane_is_a_parameter(self):
        system = slide()
        assert {"floor.point", "floor.origin", "floor.restitution"} <= set(system.parameters)
        moved = system.with_parameters({"floor.origin": (0.0, 0.0, 0.25), "floor.point": (0.0, 0.0, -0.05)})
        assert moved.gaps([1.0])["floor"] == pytest.approx(0.7, abs=1e-14)
        assert system.gaps([1.0])["floor"] == pytest.approx(1.0, abs=1e-14)  # unchanged
        res = system.simulate(0.5, [1.0], rtol=1e-10, atol=1e-12, parameters={"floor.origin": (0.0, 0.0, 0.5)})
        assert res.events[0].time == pytest.approx(math.sqrt(2 * 0.5 / G), abs=1e-9)


# ----------------------------------------------------------------------------------------------
# The impact interface
# ----------------------------------------------------------------------------------------------
class TestImpactInterface:
    def test_block_impact_by_hand(self):
        system = slide(e=0.5)
        impact = system.impact([0.0], [-3.0])
        assert impact.qd == pytest.approx([1.5], rel=1e-14)
        assert impact.impulses == {"floor": pytest.approx(2.0 * 4.5, rel=1e-14)}
        assert impact.energy_loss == pytest.approx(0.5 * 2.0 * (9.0 - 2.25), rel=1e-14)

    def test_contacts_by_name_object_or_list(self):
        system = slide(e=0.5)
        contact = system.topology.contacts[0]
        results = [system.impact([0.0], [-3.0], contacts=c) for c in ("floor", ["floor"], contact, None)]
        for r in results:
            assert r.qd == pytest.approx([1.5], rel=1e-14) and list(r.impulses) == ["floor"]

    def test_default_skips_open_or_separating_contacts(self):
        system = slide(e=0.5)
        open_ = system.impact([0.2], [-3.0])
        assert open_.impulses == {} and open_.qd == pytest.approx([-3.0]) and open_.energy_loss == 0.0
        separating = system.impact([0.0], [3.0])
        assert separating.impulses == {} and separating.qd == pytest.approx([3.0])

    def test_named_separating_contact_gets_no_pulling_impulse(self):
        system = slide(e=0.5)
        impact = system.impact([0.0], [3.0], contacts="floor")
        assert impact.impulses.get("floor", 0.0) == 0.0
        assert impact.qd == pytest.approx([3.0])

    def test_state_as_a_dict(self):
        system = slide(e=1.0)
        assert system.impact({"z": 0.0}, {"z": -2.0}).qd == pytest.approx([2.0], rel=1e-14)

    @pytest.mark.parametrize("contacts", ["wall", ["floor", "wall"]])
    def test_unknown_contact_is_a_model_error(self, contacts):
        with pytest.raises(mb.ModelError, match="'wall'.*not a contact of this model.*floor"):
            slide().impact([0.0], [-1.0], contacts=contacts)

    def test_a_body_is_not_a_contact(self):
        system = slide()
        with pytest.raises(mb.ModelError, match="'block'.*not a contact"):
            system.impact([0.0], [-1.0], contacts=["block"])

    @pytest.mark.parametrize("e", [-0.5, 1.5, float("nan")])
    def test_restitution_override_out_of_range(self, e):
        with pytest.raises(mb.ModelError, match="restitution"):
            slide().impact([0.0], [-1.0], restitution=e)

    def test_bad_state_is_a_model_error(self):
        with pytest.raises(mb.ModelError, match="length"):
            slide().impact([0.0, 1.0], [-1.0])

    def test_restitution_is_a_parameter(self):
        system = slide(e=0.5)
        changed = system.with_parameters({"floor.restitution": 0.2})
        assert changed.parameters["floor.restitution"] == 0.2
        assert changed.impact([0.0], [-3.0]).qd == pytest.approx([0.6], rel=1e-14)
        res = system.simulate(0.2, [0.0], [-1.0], parameters={"floor.restitution": 0.2})
        assert res.events[0].impulse == pytest.approx(2.0 * 1.2, rel=1e-12)

    @pytest.mark.parametrize("e", [-0.1, 2.0])
    def test_restitution_parameter_out_of_range_is_refused(self, e):
        with pytest.raises(mb.ModelError, match="restitution"):
            slide().with_parameters({"floor.restitution": e})


# ----------------------------------------------------------------------------------------------
# An oblique impact: the event time from the ballistic path, the jump from the impact law
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_projectile_hits_a_slope(formulation):
    e = 0.7
    system = projectile(formulation, e)
    x0, z0, vx, vz = 0.0, 0.0, 2.0, 1.0
    # gap(t) = n . (p(t) - o) with p(t) = (x0 + vx t, 0, z0 + vz t - g t^2 / 2)
    nx, nz = N_SLOPE[0], N_SLOPE[2]
    a, b, c = -nz * G / 2, nx * vx + nz * vz, nx * (x0 - O_SLOPE[0]) + nz * (z0 - O_SLOPE[2])
    assert c > 0
    t_hit = min(r.real for r in np.roots([a, b, c]) if abs(r.imag) < 1e-14 and r.real > 0)
    res = system.simulate(t_hit + 0.01, [x0, z0], [vx, vz], rtol=1e-11, atol=1e-13)
    assert len(res.events) >= 1
    ev = res.events[0]
    assert ev.contact == "slope"
    assert ev.time == pytest.approx(t_hit, abs=1e-9)
    i = np.flatnonzero(res.t == ev.time)
    v_before = res.qd[i[0]]
    np.testing.assert_allclose(v_before, [vx, vz - G * t_hit], rtol=1e-8)
    # Impulse P along n with the slides' mass matrix: M dv = n P, n . v+ = -e n . v-.
    M = np.diag([M_CARRIAGE + M_BALL, M_BALL])
    n = np.array([nx, nz])
    P = -(1 + e) * (n @ v_before) / (n @ np.linalg.solve(M, n))
    np.testing.assert_allclose(system.mass_matrix(res.q[i[0]]), M, rtol=1e-14)
    assert ev.impulse == pytest.approx(P, rel=1e-8)
    np.testing.assert_allclose(res.qd[i[-1]], v_before + np.linalg.solve(M, n * P), rtol=1e-8)


# ----------------------------------------------------------------------------------------------
# Starting states
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_penetrated_start_is_a_simulation_error_naming_the_contact(formulation):
    system = slide(formulation, point=(0.0, 0.0, -0.1))
    with pytest.raises(mb.SimulationError, match=r"Contact 'floor'.*penetrates.*0\.05") as info:
        system.simulate(0.1, [0.05])
    assert isinstance(info.value, RuntimeError)


@pytest.mark.parametrize("formulation", ["lagrange", "dae"])
def test_penetrated_start_is_not_fixed_silently_in_a_loop(formulation):
    """A closed loop is assembled first; the contact is checked on the assembled state."""
    m = mb.Model("four_bar_stop", gravity=(0, -G, 0))
    bodies = [m.add(mb.Body(n, mass=1.0, com=(0.5, 0, 0), inertia=(1e-3, 0.1, 0.1))) for n in ("l", "r", "top")]
    m.add(mb.Revolute("A", m.ground, bodies[0], axis="z"))
    m.add(mb.Revolute("D", m.ground, bodies[1], axis="z", parent_point=(1.2, 0, 0)))
    m.add(mb.Revolute("B", bodies[0], bodies[2], axis="z", parent_point=(1, 0, 0)))
    m.add(mb.Revolute("C", bodies[2], bodies[1], axis="z", parent_point=(1, 0, 0), child_point=(1, 0, 0)))
    m.add(mb.Contact("stop", bodies[2], point=(0.5, 0, 0), normal=(0, 1, 0), origin=(0, -5, 0)))
    system = m.compile(formulation=formulation)
    q, _ = system.assemble([1.2, -1.2, 1.4])
    y = system.body_state("top", q, point=(0.5, 0, 0)).position[1]
    # The stop 1 cm above the top bar's midpoint: penetrated by 0.01 m.
    with pytest.raises(mb.SimulationError, match=r"Contact 'stop'.*penetrates.*0\.01"):
        system.simulate(0.1, q, parameters={"stop.origin": (0.0, y + 0.01, 0.0)})
    # 1 cm below it, the same start runs.
    res = system.simulate(0.05, q, parameters={"stop.origin": (0.0, y - 0.01, 0.0)})
    assert res.t[-1] == 0.05


def test_no_contacts_no_events():
    m = mb.Model("free", gravity=(0, 0, -G))
    b = m.add(mb.Body("b", mass=1.0))
    m.add(mb.Prismatic("z", m.ground, b, axis="z"))
    system = m.compile()
    res = system.simulate(0.5, [0.0])
    assert res.events == [] and res.persistent_contacts == []
    assert system.gaps([0.0]) == {}
    assert np.min(res["z"]) < -1.0  # nothing stops it
