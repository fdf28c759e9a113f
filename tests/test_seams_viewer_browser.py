"""The viewer page plays on open: opened without a time in its address and never touched, the
shown time and the picture move on by themselves (headless Chromium, as in
tests/test_viewer_browser.py)."""
import base64
import io
import os
import re
import time

import numpy as np
import pytest

import mbcomp as mb
from browser import Browser, find_chromium

if find_chromium() is None:
    if os.environ.get("CI"):
        raise RuntimeError("CI needs Chromium for the viewer tests: .ci/run installs it with apt-get")
    pytest.skip("no Chromium here (apt-get install chromium)", allow_module_level=True)

pytestmark = pytest.mark.xdist_group("browser")


def shown_time(browser: Browser) -> float:
    """The time in the page's time label (what the user reads), in s."""
    text = browser.evaluate("document.getElementById('mbcomp-time').textContent")
    return float(re.fullmatch(r"t = (\S+) s", text).group(1))


def screenshot(browser: Browser) -> np.ndarray:
    from PIL import Image
    data = base64.b64decode(browser.call("Page.captureScreenshot", session=True, format="png")["data"])
    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))[40:540].astype(int)


def test_the_page_plays_on_open_without_being_touched(tmp_path):
    system = mb.load("double_pendulum").compile()
    page = system.simulate(20.0, [1.4, -0.8]).view(tmp_path / "pendulum.html")
    with Browser() as browser:
        run = browser.open(page.as_uri())
        assert 'data-error' not in run.dom and not run.console, run.console
        assert "pause" in browser.evaluate("document.getElementById('mbcomp-play').textContent")
        first_time = shown_time(browser)
        first_picture = screenshot(browser)
        deadline = time.monotonic() + 20.0
        while shown_time(browser) < first_time + 0.3 and time.monotonic() < deadline:
            time.sleep(0.1)
        later_time = shown_time(browser)
        later_picture = screenshot(browser)
    assert later_time > first_time + 0.3, (first_time, later_time)          # the clock runs
    changed = np.any(np.abs(first_picture - later_picture) > 30, axis=2)
    assert changed.mean() > 0.002, "the picture stands still while the page says it plays"
