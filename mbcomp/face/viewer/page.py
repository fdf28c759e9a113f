"""One self-contained HTML page: three.js, the viewer script and the scene data all inline.

The page loads nothing: a Content-Security-Policy (``default-src 'none'``, inline script and
style only) forbids every request, so it opens the same offline, from a file or in a notebook.
three.js (MIT, ``three.LICENSE`` beside this file) ships in the package as its minified ES
module; its closing ``export {...}`` becomes one object handed to the viewer script, so both run
in a single inline module script.
"""
from __future__ import annotations

import functools
import html
import json
import re
from importlib import resources

from mbcomp.core.errors import ModelError

THREE_FILE = "three.module.min.js"
VIEWER_FILE = "viewer.js"
CSP = ("default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
       "img-src data: blob:; base-uri 'none'; form-action 'none'")

_EXPORT = re.compile(r"export\s*\{([^{}]*)\}\s*;?\s*$")


def _read(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


@functools.lru_cache(maxsize=1)
def three_script() -> str:
    """three.js as a script that defines ``const __mbcompThree = {Name: value, ...}`` in place
    of the module's final ``export {...}`` clause."""
    source = _read(THREE_FILE)
    found = _EXPORT.search(source)
    if found is None or source.count("export{") + source.count("export {") != 1:
        raise ModelError("viewer", f"{THREE_FILE} is not the expected single-export three.js module build")
    pairs = []
    for item in found.group(1).split(","):
        words = item.split()
        if len(words) == 1:
            local = exported = words[0]
        elif len(words) == 3 and words[1] == "as":
            local, exported = words[0], words[2]
        else:
            raise ModelError("viewer", f"{THREE_FILE}: unexpected export item {item.strip()!r}")
        pairs.append(f"{exported}:{local}")
    return source[: found.start()] + "const __mbcompThree={" + ",".join(pairs) + "};\n"


def three_license() -> str:
    """The MIT licence text of the bundled three.js."""
    return _read("three.LICENSE")


def _safe_script(text: str, what: str) -> str:
    """Script text that cannot end its <script> element early."""
    if re.search(r"</script|<!--", text, re.IGNORECASE):
        raise ModelError("viewer", f"{what} holds '</script' or '<!--' and cannot be inlined")
    return text


STYLE = """
html, body { margin: 0; height: 100%; overflow: hidden; font: 14px system-ui, sans-serif; color: #222; }
#mbcomp-root { position: absolute; inset: 0; }
#mbcomp-bar { position: absolute; left: 0; right: 0; bottom: 0; display: flex; gap: 10px;
  align-items: center; padding: 8px 12px; background: rgba(255,255,255,0.85); border-top: 1px solid #ccd; }
#mbcomp-bar button, #mbcomp-bar select { font: inherit; padding: 3px 10px; }
#mbcomp-slider { flex: 1; }
#mbcomp-time { min-width: 9em; font-variant-numeric: tabular-nums; text-align: right; }
#mbcomp-title { position: absolute; left: 12px; top: 8px; font-weight: 600; }
#mbcomp-help { position: absolute; right: 12px; top: 8px; color: #667; font-size: 12px; }
#mbcomp-error { display: none; position: absolute; left: 12px; top: 36px; color: #b00; white-space: pre-wrap; }
"""

SPEEDS = (0.1, 0.25, 0.5, 1, 2, 4)


#: Characters of the scene JSON written as ``\uXXXX`` escapes: ``<``, ``>`` and ``&`` (no name
#: can open or close a tag, a comment (``<!--``) or a character reference inside the script
#: element) and the line separators U+2028/U+2029.  JSON.parse reads the same strings back.
_JSON_ESCAPES = {"<": "\\u003c", ">": "\\u003e", "&": "\\u0026", "\u2028": "\\u2028", "\u2029": "\\u2029"}


def scene_json(scene: dict) -> str:
    """The scene as JSON safe inside a ``<script>`` element whatever the names hold."""
    data = json.dumps(scene, separators=(",", ":"), allow_nan=False)
    return re.sub("[<>&\u2028\u2029]", lambda match: _JSON_ESCAPES[match.group()], data)


def render_page(scene: dict) -> str:
    """The complete HTML document for ``scene`` (a ``build_scene`` dict)."""
    data = scene_json(scene)
    options = "".join(f'<option value="{s}"{" selected" if s == 1 else ""}>{s}x</option>' for s in SPEEDS)
    title = html.escape(str(scene.get("title", "mbcomp")))
    script = (_safe_script(three_script(), THREE_FILE) + "\n(function (THREE) {\n"
              + _safe_script(_read(VIEWER_FILE), VIEWER_FILE) + "\n})(__mbcompThree);\n")
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CSP}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{title} - mbcomp</title>
<style>{STYLE}</style>
</head>
<body>
<div id="mbcomp-root"></div>
<div id="mbcomp-title"></div>
<div id="mbcomp-help">drag: turn &middot; right-drag: pan &middot; wheel: zoom &middot; space: play/pause</div>
<div id="mbcomp-error"></div>
<div id="mbcomp-bar">
<button id="mbcomp-play" type="button">play</button>
<input id="mbcomp-slider" type="range" aria-label="time">
<span id="mbcomp-time">t = 0 s</span>
<label>speed <select id="mbcomp-speed">{options}</select></label>
</div>
<script type="application/json" id="mbcomp-scene">{data}</script>
<script type="module">
{script}
</script>
<!-- The script above includes three.js ({THREE_FILE}), under this licence:
{three_license().replace("--", "- -").strip()}
-->
</body>
</html>
"""
