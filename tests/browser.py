"""A small headless-Chromium driver for tests: the Chrome DevTools protocol over a pipe
(``--remote-debugging-pipe``: JSON messages ending in a NUL byte on file descriptors 3 and 4),
so no websocket package is needed.

``Browser().open(url)`` loads a page, waits until it says it has drawn, and returns a
screenshot, the serialised DOM and every request the page made (the protocol's network events,
the page document itself left out).  Chromium's own background traffic is switched off and
name resolution fails for every host, so nothing leaves the machine whatever a page tries.
"""
from __future__ import annotations

import base64
import fcntl
import io
import json
import os
import select
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass

import numpy as np

CANDIDATES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
         "--hide-scrollbars", "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--no-first-run", "--disable-default-apps", "--disable-extensions", "--mute-audio",
         "--host-resolver-rules=MAP * ~NOTFOUND")


def find_chromium() -> str | None:
    """The path of a Chromium-family browser, or None."""
    for name in CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    return None


@dataclass
class PageRun:
    screenshot: np.ndarray      # (h, w, 3) uint8
    dom: str                    # the serialised DOM once the page has drawn
    requests: list[str]         # URLs the page asked for, besides its own document, not blocked
    blocked: list[str]          # "reason url" of requests the browser refused (e.g. "csp ...")
    console: list[str]          # console messages and uncaught exceptions


class Browser:
    """One headless Chromium for several pages (start-up is the slow part)."""

    def __init__(self, width: int = 800, height: int = 600, timeout: float = 60.0):
        browser = find_chromium()
        if browser is None:
            raise RuntimeError("no Chromium found (apt-get install chromium)")
        self.timeout = timeout
        self._tmp = tempfile.TemporaryDirectory()
        to_browser_r, self._to_browser = os.pipe()
        self._from_browser, from_browser_w = os.pipe()

        def wire() -> None:   # in the child: the protocol pipes on fds 3 (in) and 4 (out)
            high_r = fcntl.fcntl(to_browser_r, fcntl.F_DUPFD, 10)
            high_w = fcntl.fcntl(from_browser_w, fcntl.F_DUPFD, 10)
            os.dup2(high_r, 3)
            os.dup2(high_w, 4)

        command = [browser, *FLAGS, "--remote-debugging-pipe", f"--window-size={width},{height}",
                   f"--user-data-dir={self._tmp.name}/profile", "about:blank"]
        self._proc = subprocess.Popen(command, preexec_fn=wire, pass_fds=(3, 4),
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                      env=dict(os.environ, HOME=self._tmp.name))
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._next_id = 0
        self._events: list[dict] = []
        targets = self.call("Target.getTargets")["targetInfos"]
        page = next(t for t in targets if t["type"] == "page")
        self.session = self.call("Target.attachToTarget", targetId=page["targetId"], flatten=True)["sessionId"]
        for domain in ("Page", "Network", "Runtime"):
            self.call(f"{domain}.enable", session=True)
        self.call("Emulation.setDeviceMetricsOverride", session=True, width=width, height=height,
                  deviceScaleFactor=1, mobile=False)

    # -- the protocol ---------------------------------------------------------------------------
    def _read_message(self, deadline: float) -> dict:
        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._from_browser], [], [], left)[0]:
                raise TimeoutError("Chromium did not answer in time")
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                raise RuntimeError("Chromium closed the protocol pipe")
            self._buffer += chunk
        message, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(message)

    def call(self, method: str, session: bool = False, **params) -> dict:
        """Send one command and wait for its answer (events arriving meanwhile are kept)."""
        self._next_id += 1
        message = {"id": self._next_id, "method": method, "params": params}
        if session:
            message["sessionId"] = self.session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + self.timeout
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            if "method" in reply:
                self._events.append(reply)

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page."""
        return self.call("Runtime.evaluate", session=True, expression=expression,
                         returnByValue=True)["result"].get("value")

    # -- pages -----------------------------------------------------------------------------------
    def open(self, url: str, ready: str = "document.body && document.body.dataset.rendered === '1'") -> PageRun:
        """Load ``url``, wait until ``ready`` is true (or any uncaught error), then capture."""
        from PIL import Image

        self.call("Page.navigate", session=True, url="about:blank")
        self._events.clear()
        self.call("Page.navigate", session=True, url=url)
        deadline = time.monotonic() + self.timeout
        while not self.evaluate(f"!!({ready}) || !!(document.body && document.body.dataset.error)"):
            if time.monotonic() > deadline:
                raise TimeoutError(f"{url} did not draw within {self.timeout} s")
            time.sleep(0.05)
        # Two more animation frames: whatever was asked to render has reached the screen.
        self.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
        shot = base64.b64decode(self.call("Page.captureScreenshot", session=True, format="png")["data"])
        dom = self.evaluate("document.documentElement.outerHTML")
        document = url.split("#", 1)[0]
        asked, refused, console = {}, {}, []
        for event in self._events:
            params = event.get("params", {})
            if event["method"] == "Network.requestWillBeSent":
                if params["request"]["url"].split("#", 1)[0] not in (document, "about:blank"):
                    asked[params["requestId"]] = params["request"]["url"]
            elif event["method"] == "Network.loadingFailed" and params.get("blockedReason"):
                refused[params["requestId"]] = params["blockedReason"]
            elif event["method"] == "Runtime.consoleAPICalled":
                console.append(" ".join(str(a.get("value", a.get("description", ""))) for a in params["args"]))
            elif event["method"] == "Runtime.exceptionThrown":
                console.append(str(params["exceptionDetails"].get("exception", {}).get("description")))
        image = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB"))
        requests = [url for rid, url in asked.items() if rid not in refused]
        blocked = [f"{refused[rid]} {url}" for rid, url in asked.items() if rid in refused]
        return PageRun(image, dom, requests, blocked, console)

    def close(self) -> None:
        if self._proc.poll() is None:
            try:
                self.call("Browser.close")
            except (RuntimeError, TimeoutError, OSError):
                pass
            try:
                self._proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        for fd in (self._to_browser, self._from_browser):
            try:
                os.close(fd)
            except OSError:
                pass
        self._tmp.cleanup()

    def __enter__(self) -> "Browser":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
