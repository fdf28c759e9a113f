"""The friction law's building blocks on their own: contact rows against finite
differences, and the cone impact law against closed forms."""
import numpy as np
import pytest

import mbcomp as mb
from mbcomp.formulations.friction import Closed, cone_impact, plane_contact_rows, tangent_basis


def chain_with_sphere_contact():
    """A 3D double pendulum whose second link carries a contact sphere (r = 0.05 m) on a
    tilted plane: the rows of a body down a chain, with rotation."""
    m = mb.Model("chain", gravity=(0, 0, -9.81))
    upper = m.add(mb.Body("upper", mass=1.0, com=(0, 0, -0.2), inertia=(0.02, 0.02, 0.001)))
    lower = m.add(mb.Body("lower", mass=0.7, com=(0, 0.1, -0.1), inertia=(0.01, 0.003, 0.01)))
    m.add(mb.Spherical("shoulder", m.ground, upper, sequence="xy", coords=("a", "b")))
    m.add(mb.Revolute("elbow", upper, lower, axis="x", parent_point=(0, 0, -0.4), coords="c"))
    m.add(mb.Contact("tip", lower, (0.02, 0.1, -0.3), normal=(0.3, -0.2, 1.0), origin=(0, 0, -2.0),
                     friction=0.4, radius=0.05))
    return m.compile()


def touching_point(system, q):
    """World position of the contact sphere's touching point, from body_state."""
    n = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])
    return system.body_state("lower", q, point=(0.02, 0.1, -0.3)).position - 0.05 * n


def test_tangent_basis_is_right_handed_and_orthonormal():
    for n in ([0, 0, 1], [1, 0, 0], np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])):
        t = tangent_basis(n)
        frame = np.vstack((n, t))
        np.testing.assert_allclose(frame @ frame.T, np.eye(3), atol=1e-15)
        np.testing.assert_allclose(np.cross(t[0], t[1]), n, atol=1e-15)


def test_tangential_rows_and_bias_match_finite_differences():
    """J_t qd is the touching point's velocity along the tangents, v_p + w x (-r n) (the
    point p - r n moves with p, n fixed), and d/dt (J_t qd) = J_t qdd + bias_t: both
    checked by central differences along q(t) = q + t qd + t^2 qdd / 2."""
    system = chain_with_sphere_contact()
    kernel = system.kernel
    rng = np.random.default_rng(3)
    q, qd, qdd = rng.uniform(-1, 1, 3), rng.uniform(-2, 2, 3), rng.uniform(-3, 3, 3)
    rows = plane_contact_rows(kernel, q, qd, [0])
    n, T = rows.basis[0, 0], rows.basis[0, 1:]
    h = 1e-6
    velocity = (touching_point(system, q + h * qd) - touching_point(system, q - h * qd)) / (2 * h)
    w = system.body_state("lower", q, qd).angular_velocity
    # The sphere's touching point is not a material point: its velocity is the material
    # velocity at p - r n, i.e. the body point's velocity plus w x (-r n).
    v_p = system.body_state("lower", q, qd, point=(0.02, 0.1, -0.3)).velocity
    np.testing.assert_allclose(rows.tangent[0] @ qd, T @ (v_p + np.cross(w, -0.05 * n)), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rows.normal[0] @ qd, n @ velocity, rtol=1e-8, atol=1e-9)

    def slip(s):
        qs, qds = q + s * qd + s * s / 2 * qdd, qd + s * qdd
        r = plane_contact_rows(kernel, qs, qds, [0])
        return r.tangent[0] @ qds

    rate = (slip(h) - slip(-h)) / (2 * h)
    np.testing.assert_allclose(rows.tangent[0] @ qdd + rows.tangent_bias[0], rate, rtol=1e-6, atol=1e-7)
    assert rows.mu[0] == 0.4
    np.testing.assert_allclose(rows.point[0], touching_point(system, q), atol=1e-14)


def test_cone_impact_on_a_particle():
    """A unit point mass hitting a plane with normal speed -w and tangential speed u
    (G = identity): P_n = (1 + e) w; it stops sliding when mu P_n >= u (P_t = -u),
    otherwise P_t = -mu P_n."""
    e, w = 0.5, 2.0
    for mu, u in ((0.5, 1.0), (0.1, 1.0)):
        v_minus = np.array([-w, u, 0.0])
        b = v_minus + np.array([e * -w, 0.0, 0.0])
        P = cone_impact(np.eye(3), b, 0, np.array([mu]), "'x'", 0.0)
        P_n = (1 + e) * w
        expected_t = -u if mu * P_n >= u else -mu * P_n
        np.testing.assert_allclose(P, [P_n, expected_t, 0.0], rtol=1e-12, atol=1e-14)


def test_cone_impact_with_a_redundant_bilateral_row():
    """A unit point mass on a rail along x (a bilateral row on y, which the contact's
    second tangent repeats) lands on the plane z = 0 at (u, 0, -w), e = 0: P_n = w and the
    x slip stops when mu w >= u.  The y rows are redundant (their split is not determined)
    and nothing moves along y."""
    w, u, mu = 2.0, 0.5, 0.4
    J = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=float)   # rail y; n, t1, t2
    v_minus = J @ np.array([u, 0.0, -w])
    P = cone_impact(J @ J.T, v_minus, 1, np.array([mu]), "'x'", 0.0)
    v_plus = np.array([u, 0.0, -w]) + J.T @ P
    np.testing.assert_allclose(v_plus, [0.0, 0.0, 0.0], atol=1e-12)   # mu w = 0.8 >= u: it sticks
    assert P[1] == pytest.approx(w, rel=1e-12) and np.hypot(P[2], P[3]) <= mu * P[1] * (1 + 1e-12)


def test_closed_keeps_its_modes_and_drops_contacts_that_left():
    closed = Closed((2, 0, 1), stick=(0, 5), slip={1: (1.0, 0.0, 0.0), 7: (0.0, 1.0, 0.0)})
    assert tuple(closed) == (2, 0, 1) and closed.stick == {0} and set(closed.slip) == {1}
    assert closed.mode(0) == "stick" and closed.mode(1) == "slip" and closed.mode(2) == "none"
    assert Closed((2,)).has_friction is False and closed.has_friction
