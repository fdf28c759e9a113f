"""A ball bouncing on the floor: impacts against Newton's impact law in closed form.

A ball of radius r = 0.05 m slides on a vertical prismatic joint and is dropped with
its centre at h = 1 m.  The contact point is the bottom of the ball; the floor is the
plane z = 0.  With restitution e, the first impact is at t1 = sqrt(2 (h - r) / g) with
speed v1 = g t1, each impact sends the ball back up with e times its impact speed
(impulse (1 + e) m v), and the time between impacts shrinks by e each bounce.

Run: ``python examples/bouncing_ball.py``.
"""
import numpy as np

import mbcomp as mb

MASS, RADIUS, HEIGHT, E, G = 0.1, 0.05, 1.0, 0.8, 9.81


def ball_on_floor() -> mb.Model:
    m = mb.Model("bouncing_ball", gravity=(0, 0, -G))
    ball = m.add(mb.Body("ball", mass=MASS, inertia=(0.4 * MASS * RADIUS ** 2,) * 3))
    m.add(mb.Prismatic("drop", m.ground, ball, axis="z", coords="z"))
    m.add(mb.Contact("floor", ball, point=(0, 0, -RADIUS), normal=(0, 0, 1), restitution=E))
    return m


def main() -> None:
    system = ball_on_floor().compile()
    res = system.simulate(3.0, q0=[HEIGHT])
    t1 = np.sqrt(2 * (HEIGHT - RADIUS) / G)
    v1 = G * t1
    print(" n   time (s)   expected   impulse (N s)   expected")
    for n, event in enumerate(res.events):
        v = v1 * E ** n                                             # impact speed of bounce n
        t_expected = t1 + sum(2 * v1 * E ** k / G for k in range(1, n + 1))
        print(f"{n + 1:2d} {event.time:10.6f} {t_expected:10.6f} {event.impulse:15.6f} {(1 + E) * MASS * v:10.6f}")
        assert event.contact == "floor"
        assert abs(event.time - t_expected) < 1e-7
        assert abs(event.impulse - (1 + E) * MASS * v) < 1e-7
        assert abs(event.energy_loss - 0.5 * MASS * v ** 2 * (1 - E ** 2)) < 1e-7
    assert len(res.events) >= 5

    # Between impacts energy is conserved; each impact removes the fraction 1 - e^2 of it.
    energy = res.energy().total
    touching = MASS * G * RADIUS
    after = [energy[np.searchsorted(res.t, ev.time, side="right")] for ev in res.events[:3]]
    ratios = [(b - touching) / (a - touching) for a, b in zip(after, after[1:])]
    print(f"energy above resting kept by each bounce: {np.round(ratios, 9)} (e^2 = {E ** 2})")
    assert np.allclose(ratios, E ** 2, rtol=1e-7)
    assert res.q.min() > RADIUS - 1e-9                               # never through the floor

    # The impact law on its own: a ball at the floor moving down at 2 m/s.
    impact = system.impact([RADIUS], [-2.0])
    print(f"impact at 2 m/s: speed after {impact.qd[0]:.3f} m/s, impulse {impact.impulses['floor']:.3f} N s")
    assert np.isclose(impact.qd[0], 2.0 * E) and np.isclose(impact.impulses["floor"], (1 + E) * MASS * 2.0)


if __name__ == "__main__":
    main()
