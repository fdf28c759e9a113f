"""RollingDisc: a thin uniform disc rolling without slip on the ground, against closed forms.

The disc (mass m, radius R; moments about its centre A = m R^2 / 4 about a diameter and
C = m R^2 / 2 about its axis) sits on a six-coordinate joint: the centre's x, y, z, then
yaw (about z), lean (about the rotated x) and spin (about the disc's axis y).

Upright steady rolling at spin rate Omega (speed v = R Omega) linearises to (Routh,
*Advanced Rigid Dynamics* (1884) §244; Neimark & Fufaev, *Dynamics of Nonholonomic
Systems* (1972) ch. III)::

    A psi'' = -C Omega phi'                         (no moment about the vertical)
    (A + m R^2) phi'' = m g R phi + (C + m R^2) Omega psi'     (lean about the contact line)

with psi the yaw and phi the lean (signs as this model's axes give them), so the lean obeys
``(A + m R^2) phi'' = (m g R - (C + m R^2) C Omega^2 / A) phi``: stable exactly when
``Omega^2 > m g R A / (C (C + m R^2))``, which for the uniform disc is ``Omega^2 > g / (3 R)``
(``v^2 > g R / 3``), with the lean eigenvalues ``+-sqrt(4/5 (g/R - 3 Omega^2))``.
"""
from __future__ import annotations

import numpy as np
import pytest

import mbcomp as mb
from mbcomp.spec.components.joints import Joint

R, M, G = 0.5, 1.2, 9.81
X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


class EulerFree(Joint):
    """Translations x, y, z, then yaw (z), lean (x), spin (y) rotations."""

    n_coords = 6
    coord_suffixes = ("x", "y", "z", "yaw", "lean", "spin")

    def screws(self):
        return [("P", X), ("P", Y), ("P", Z), ("R", Z), ("R", X), ("R", Y)]


def disc_model(radius: float = R) -> mb.Model:
    m = mb.Model("disc", gravity=(0, 0, -G))
    disc = m.add(mb.Body("disc", mass=M, inertia=(M * radius**2 / 4, M * radius**2 / 2, M * radius**2 / 4)))
    m.add(EulerFree("j", m.ground, disc, coords=("x", "y", "z", "yaw", "lean", "spin")))
    m.add(mb.RollingDisc("roll", disc, radius=radius, axis="y"))
    return m


@pytest.fixture(scope="module")
def systems():
    model = disc_model()
    return {f: model.compile(formulation=f) for f in ("dae", "lagrange")}


def test_counts_independent_speeds(systems):
    """Six speeds, one holonomic and two velocity rows: five coordinates, three speeds free."""
    for system in systems.values():
        assert system.ndof == 3
        assert list(system.velocity_rows) == [False, True, True]
        assert system.constraint_rows == ["roll"] * 3


@pytest.mark.parametrize("formulation", ["dae", "lagrange"])
def test_upright_disc_rolls_straight(systems, formulation):
    """Rolling upright along x at v: x = v t, spin = v t / R, heading and lean kept; the
    ground pushes up with m g (the contact force, world frame)."""
    system = systems[formulation]
    v, T = 1.5, 2.0
    q, qd = system.assemble([0, 0, R, 0, 0, 0], [v, 0, 0, 0, 0, v / R])
    np.testing.assert_allclose(qd, [v, 0, 0, 0, 0, v / R], atol=1e-12)
    res = system.simulate(T, q, qd, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.q[-1], [v * T, 0, R, 0, 0, v * T / R], atol=1e-8)
    np.testing.assert_allclose(res.reactions["roll"][-1], [0, 0, M * G], atol=1e-8)
    assert system.integration_path() == "compiled" and res.stats["integrator"] == "compiled"


def test_assemble_projects_speeds_onto_the_rolling_rows(systems):
    """A guess that slips is projected (kinetic-energy metric) onto rolling without slip:
    the contact point's velocity vanishes (the disc's centre moves as R times the spin)."""
    q, qd = systems["dae"].assemble([0, 0, R + 0.1, 0.3, 0.2, 0], [2.0, 0.5, 0, 0.1, 0, -1.0])
    cv = systems["dae"].constraint_values(q, qd)
    assert abs(cv.g[0]) < 1e-12 and np.isnan(cv.g[1:]).all()
    np.testing.assert_allclose(cv.J @ qd, 0, atol=1e-12)


@pytest.mark.parametrize("formulation", ["dae", "lagrange"])
def test_linearized_lean_eigenvalues_and_threshold(systems, formulation):
    """Eigenvalues of ``linearize`` about upright rolling: the lean pair is
    +-sqrt(4/5 (g/R - 3 Omega^2)), the other six are zero (x, y, yaw, spin and their
    speeds are ignorable or cyclic); stable just above Omega^2 = g/(3R), unstable below."""
    system = systems[formulation]
    critical = np.sqrt(G / (3 * R))
    for omega in (0.5 * critical, 0.95 * critical, 1.05 * critical, 3 * critical):
        lin = system.linearize([0, 0, R, 0, 0, 0], [R * omega, 0, 0, 0, 0, omega])
        assert lin.states == ("x", "y", "yaw", "lean", "spin", "yaw_dot", "lean_dot", "spin_dot")
        values = np.linalg.eigvals(lin.A)
        expected = np.sqrt(complex(0.8 * (G / R - 3 * omega**2)))
        largest = sorted(values, key=lambda z: (-abs(z), z.real, z.imag))[:2]
        np.testing.assert_allclose(sorted(largest, key=lambda z: (z.real, z.imag)),
                                   sorted([-expected, expected], key=lambda z: (z.real, z.imag)), atol=1e-8)
        assert np.sum(np.abs(values) < 1e-9) == 6
        modes = system.modes([0, 0, R, 0, 0, 0], qd=[R * omega, 0, 0, 0, 0, omega])
        assert modes.stable == (omega > critical)


def test_formulations_agree_and_energy_is_conserved(systems):
    """A leaning disc circles (and wobbles): dae and lagrange give the same motion, rolling
    does no work, so the energy stays put, and the contact stays closed and non-slipping."""
    runs = {}
    for formulation, system in systems.items():
        q, qd = system.assemble([0, 0, R, 0, 0.2, 0], [1.0, 0, 0, 0.5, 0.0, 2.0])
        runs[formulation] = res = system.simulate(1.5, q, qd, rtol=1e-10, atol=1e-12)
        energy = res.energy().total
        assert np.ptp(energy) < 1e-8 * abs(energy[0])
        assert np.max(res.constraint_violation()) < 1e-9
        J = np.array([system.constraint_values(qi, vi).J for qi, vi in zip(res.q[::20], res.qd[::20])])
        assert np.max(np.abs(np.einsum("mij,mj->mi", J, res.qd[::20]))) < 1e-8
    np.testing.assert_allclose(runs["dae"].q[-1], runs["lagrange"].q[-1], atol=1e-7)
    np.testing.assert_allclose(runs["dae"].reactions["roll"][-1], runs["lagrange"].reactions["roll"][-1],
                               rtol=1e-6)


def held_upright_model() -> mb.Model:
    """The disc held upright (a planar joint at the centre's height R, then the spin): the
    holonomic row is identically zero (redundant), the velocity rows leave 2 speeds free."""
    m = mb.Model("upright_disc", gravity=(0, 0, -G))
    frame = m.add(mb.Body("frame", mass=0.3, inertia=(0.01, 0.01, 0.01)))
    disc = m.add(mb.Body("disc", mass=M, inertia=(M * R**2 / 4, M * R**2 / 2, M * R**2 / 4)))
    m.add(mb.Planar("p", m.ground, frame, normal="z", parent_point=(0, 0, R)))
    m.add(mb.Revolute("spin", frame, disc, axis="y", coords="spin"))
    m.add(mb.RollingDisc("roll", disc, radius=R, axis="y"))
    return m


@pytest.mark.parametrize("formulation", ["dae", "lagrange"])
def test_redundant_holonomic_row_is_handled(formulation):
    """With the height fixed by the coordinates the normal row vanishes identically: it is
    reported redundant, not an error; the disc held upright turns at a constant yaw rate
    w and speed v, so its centre runs on a circle of radius v / w; linearize works."""
    system = held_upright_model().compile(formulation=formulation)
    assert system.ndof == 2 and system.redundant_constraints == ["roll.n"]
    v, w, T = 1.0, 0.8, 2.0
    q, qd = system.assemble([0, 0, 0, 0], [v, 0, w, v / R])
    res = system.simulate(T, q, qd, rtol=1e-10, atol=1e-12)
    x, y, yaw = res.q[-1, :3]
    np.testing.assert_allclose([x, y, yaw], [v / w * np.sin(w * T), v / w * (1 - np.cos(w * T)), w * T], atol=1e-7)
    lin = system.linearize(q, qd)
    assert lin.A.shape == (6, 6)  # x, y, yaw, spin; two speeds
    assert np.max(np.abs(np.linalg.eigvals(lin.A))) < 1e-9  # steady turning: no restoring or growing motion


def test_file_round_trip(tmp_path):
    """save -> load keeps the rolling constraint (its kind, keys and values) and the motion."""
    model = mb.Model("turntable_ball")
    table = model.add(mb.Body("table", mass=5.0, inertia=(1.0, 1.0, 2.0)))
    ball = model.add(mb.Body("ball", mass=1.0, inertia=(0.004,) * 3))
    model.add(mb.Revolute("turn", model.ground, table, axis="z", coords="phi"))
    model.add(mb.Free("fb", model.ground, ball))
    model.add(mb.RollingBall("rb", ball, radius=0.1, plane=table, origin=(0, 0, 0.05)))
    model.add(mb.NoSlip("blade", table, point=(0.2, 0, 0), direction="x"))
    disc = model.add(mb.Body("disc", mass=1.0, inertia=(0.1, 0.2, 0.1)))
    model.add(mb.Free("fd", model.ground, disc))
    model.add(mb.RollingDisc("rd", disc, radius=0.3, axis="x", center=(0, 0, 0.01)))
    path = tmp_path / "m.toml"
    model.save(path)
    text = path.read_text()
    assert 'type = "rolling_ball"' in text and 'type = "no_slip"' in text and 'type = "rolling_disc"' in text
    loaded = mb.load(path)
    assert isinstance(loaded["rb"], mb.RollingBall) and loaded["rb"].plane == "table"
    assert loaded["rd"].axis == (1.0, 0.0, 0.0) and loaded["rd"].radius == 0.3
    path2 = tmp_path / "m2.toml"
    loaded.save(path2)
    assert path2.read_text() == text
    a, b = model.compile(formulation="dae"), loaded.compile(formulation="dae")
    assert a.parameters == b.parameters and a.coords == b.coords


def test_bad_arguments_name_the_component():
    with pytest.raises(mb.ModelError, match="roll"):
        mb.RollingDisc("roll", "disc", radius=-1.0)
    with pytest.raises(mb.ModelError, match="blade"):
        mb.NoSlip("blade", "b", direction=(0, 0, 0))


def test_linearize_with_chosen_independent_speeds(systems):
    """Choosing other independent speeds (the centre's forward speed instead of the spin)
    changes the state, not the eigenvalues; the named speeds' coordinates stay independent."""
    omega = 3.0
    q, qd = [0, 0, R, 0, 0, 0], [R * omega, 0, 0, 0, 0, omega]
    default = systems["lagrange"].linearize(q, qd)
    chosen = systems["lagrange"].linearize(q, qd, independent=["x", "yaw", "lean"])
    assert chosen.independent == ("x", "yaw", "lean") and "lean" in chosen.states[:5]
    key = lambda z: (round(z.imag, 9), round(z.real, 9))
    np.testing.assert_allclose(sorted(np.linalg.eigvals(chosen.A), key=key),
                               sorted(np.linalg.eigvals(default.A), key=key), atol=1e-8)
