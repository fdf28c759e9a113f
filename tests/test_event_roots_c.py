"""Contact events located on their step in C (``<prefix>_<what>_root``: codegen/c/brentq.h's
``mb_brentq``) in both compiled loops: every root equals the one scipy's ``brentq`` (the
oracle) finds on the same C function of the step's dense output (``<prefix>_<what>_at``),
with the same tolerances, to 1e-14 relative."""
from __future__ import annotations

import pytest
import scipy.optimize

import mbcomp as mb

from mbcomp.core.tolerances import EVENT_GAP_XTOL
from mbcomp.formulations import compiled_watch
from test_friction_compiled import cart_with_pendulum

FORMULATIONS = ("lagrange", "dae")
#: (locator method, the function it finds the zero of)
ROOTS = (("gap_root", "gap"), ("force_root", "force"), ("cone_root", "cone"))


def located_events(monkeypatch, formulation: str, mu: float, swing: float, on_step=None):
    """Run the cart with a pendulum (``swing`` rad/s) compiled, recording for every root the
    C locator found ``(kind, C root, scipy brentq root on the same C function)``; ``on_step(loc,
    a, b, rtol)`` is called on each event step with friction while its locator is live (the
    run's C configuration is undone when the run ends)."""
    found = []
    for name, what in ROOTS:
        original = getattr(compiled_watch.EventStepFunctions, name)

        def spy(self, *args, _original=original, _name=name, _what=what):
            root = _original(self, *args)
            *key, a, b, xtol, rtol = args
            oracle = scipy.optimize.brentq(lambda s: getattr(self, _what)(s, *key), a, b, xtol=xtol, rtol=rtol)
            found.append((_name, root, oracle))
            if self.has_friction and on_step is not None:
                on_step(self, a, b, rtol)
            return root
        monkeypatch.setattr(compiled_watch.EventStepFunctions, name, spy)
    system = cart_with_pendulum(formulation, mu=mu)
    res = system.simulate(1.0, [0.05, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, swing], rtol=1e-10, atol=1e-12)
    assert res.stats["path"] == "compiled"
    return found, res


def slip_roots(loc, a: float, b: float, rtol: float, out: list) -> None:
    """On a live event step: for each friction contact and each direction along x whose slip
    changes sign over [a, b], ``(C slip_root, scipy brentq on the C slip, a, b)`` into ``out``;
    a bracket without a sign change raises scipy's error, naming the quantity."""
    for i in loc.run.friction.indices:
        for direction in ((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)):
            if loc.slip(a, i, direction) < 0.0 < loc.slip(b, i, direction):
                root = loc.slip_root(i, direction, a, b, EVENT_GAP_XTOL, rtol)
                oracle = scipy.optimize.brentq(lambda s: loc.slip(s, i, direction), a, b, xtol=EVENT_GAP_XTOL,
                                               rtol=rtol)
                out.append((root, oracle, a, b))
            if loc.slip(a, i, direction) != 0.0:
                with pytest.raises(mb.SimulationError, match="slip velocity does not change sign"):
                    loc.slip_root(i, direction, a, a, EVENT_GAP_XTOL, rtol)


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_every_root_in_c_equals_scipy_brentq(monkeypatch, formulation):
    """Swung hard on rough ground the cart slips (its force reaching the cone), its edges lift
    (a normal force reaching zero) and land again (a gap closing): every event time located
    in C is scipy's root; so is ``slip_root`` wherever a contact's slip along x changes sign
    over an event step (rounding-sized slip of a sticking contact is still a smooth function
    of time on the step's dense output)."""
    slips = []
    found, res = located_events(monkeypatch, formulation, mu=0.8, swing=15.0,
                                on_step=lambda loc, a, b, rtol: slip_roots(loc, a, b, rtol, slips))
    assert [e.kind for e in res.events] == ["slip", "slip", "release", "release", "impact", "impact"]
    assert {kind for kind, _, _ in found} == {"gap_root", "force_root", "cone_root"}
    for kind, root, oracle in found:
        assert root == pytest.approx(oracle, rel=1e-14, abs=0.0), kind
    assert slips
    for root, oracle, a, b in slips:
        assert a <= root <= b
        assert root == pytest.approx(oracle, rel=1e-14, abs=0.0)
