"""The viewer page in a real browser (headless Chromium, software WebGL): it draws, it moves
with time, it shows the time, and it makes no network request.

In CI (``CI`` set) a missing Chromium is a failure, never a skip: ``.ci/run`` installs it.
"""
import os
import re

import numpy as np
import pytest

import mbcomp as mb
from browser import Browser, find_chromium

if find_chromium() is None:
    if os.environ.get("CI"):
        raise RuntimeError("CI needs Chromium for the viewer tests: .ci/run installs it with apt-get")
    pytest.skip("no Chromium here (apt-get install chromium)", allow_module_level=True)

BACKGROUND = np.array([0xf4, 0xf5, 0xf7])
pytestmark = pytest.mark.xdist_group("browser")   # one worker, one browser for the module


@pytest.fixture(scope="module")
def browser():
    with Browser() as b:
        yield b


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    system = mb.load("double_pendulum").compile()
    res = system.simulate(2.0, [1.4, -0.8])
    return res.view(tmp_path_factory.mktemp("view") / "double_pendulum.html")


def canvas(run):
    """The 3D drawing area (above the control bar)."""
    return run.screenshot[40:540].astype(int)


def test_page_draws_moves_and_stays_offline(browser, page):
    early = browser.open(page.as_uri() + "#t=0.2")
    late = browser.open(page.as_uri() + "#t=1.5")
    for run, t in ((early, "0.2000"), (late, "1.5000")):
        assert 'data-error' not in run.dom and not run.console, (re.search(r'data-error="[^"]*"', run.dom),
                                                                 run.console)
        assert 'data-rendered="1"' in run.dom
        assert f"t = {t} s" in run.dom                       # the current time is shown
        assert run.requests == [] and run.blocked == [], (run.requests, run.blocked)   # none at all
        assert "data-violations" not in run.dom
        picture = canvas(run)
        drawn = np.any(np.abs(picture - BACKGROUND) > 30, axis=2)
        assert 0.005 < drawn.mean() < 0.6, f"canvas looks blank or flooded: {drawn.mean():.4f}"
        rgb = picture.reshape(-1, 3).astype(np.uint32)
        assert len(np.unique(rgb[:, 0] << 16 | rgb[:, 1] << 8 | rgb[:, 2])) > 50     # shaded, not a flat fill
        # The bodies' colours (blue bar1, orange bar2) are on screen.
        for colour in ((0x4e, 0x79, 0xa7), (0xf2, 0x8e, 0x2b)):
            near = np.all(np.abs(picture - np.array(colour)) < 60, axis=2)
            assert near.sum() > 30, f"body colour {colour} not drawn"
    changed = np.any(np.abs(canvas(early) - canvas(late)) > 30, axis=2)
    assert changed.mean() > 0.002, "the picture does not change between t = 0.2 s and t = 1.5 s"


def test_a_request_would_be_blocked_and_seen(browser, page, tmp_path):
    """The checks above can fail: a page that asks the network is blocked by the page's policy
    (reported in the DOM), and the same request without the policy shows in the network log."""
    text = page.read_text()
    probe = '<img src="http://127.0.0.1:9/probe.png" alt="">'
    blocked = tmp_path / "blocked.html"
    blocked.write_text(text.replace('<div id="mbcomp-root">', probe + '<div id="mbcomp-root">', 1))
    run = browser.open(blocked.as_uri() + "#t=0.5")
    assert "img-src" in run.dom and "127.0.0.1:9" in run.dom and 'data-rendered="1"' in run.dom
    assert run.requests == [] and run.blocked == ["csp http://127.0.0.1:9/probe.png"]
    open_policy = tmp_path / "open.html"
    open_policy.write_text(re.sub(r'<meta http-equiv="Content-Security-Policy"[^>]*>', "",
                                  blocked.read_text(), count=1))
    run = browser.open(open_policy.as_uri() + "#t=0.5")
    assert any("127.0.0.1:9/probe.png" in url for url in run.requests), run.requests
