"""The 3D viewer: one self-contained HTML page per result (``Result.view``).

``view(result, path)`` writes the page; without a path it returns a ``Viewer`` that a Jupyter
notebook displays inline (the page in a sandboxed iframe) and that ``save`` writes later.
"""
from __future__ import annotations

import html
import os
from pathlib import Path
from typing import Any

from mbcomp.face.viewer.page import render_page, three_license
from mbcomp.face.viewer.scene import build_scene

__all__ = ["Viewer", "view", "render_page", "build_scene", "three_license"]


class Viewer:
    """A rendered viewer page: ``html`` (str), ``save(path)``, shown inline by Jupyter."""

    def __init__(self, page: str):
        self.html = page

    def save(self, path: str | os.PathLike) -> Path:
        """Write the page to ``path`` (any suffix; ``.html`` is customary) and return it."""
        from mbcomp.core.writing import write_file
        return write_file(path, self.html, "view")

    def _repr_html_(self) -> str:
        # An iframe keeps the page's script, style and policy apart from the notebook's.
        return (f'<iframe srcdoc="{html.escape(self.html, quote=True)}" style="width:100%;height:520px;'
                f'border:1px solid #ccd" sandbox="allow-scripts"></iframe>')

    def __repr__(self) -> str:
        return f"<mbcomp Viewer: {len(self.html) // 1024} KiB page; save(path) or display it in a notebook>"


def view(result: Any, path: str | os.PathLike | None = None, *, fps: float = 60.0, max_frames: int = 2000,
         title: str | None = None) -> Path | Viewer:
    """Draw ``result`` in 3D as one self-contained HTML page (three.js inline, no network).

    Bodies are drawn from their ``shape`` (``mb.Box``, ``mb.Cylinder``, ``mb.Sphere``,
    ``mb.Mesh``), or as a rod from each joint and attachment point to the COM with a ball at
    the COM; joints, ground anchors, springs, sliders and contacts are marked.  Body poses come
    from ``System.body_state`` at ``fps`` evenly spaced frames per simulated second (at most
    ``max_frames``); the page interpolates between them.  The page plays, pauses, scrubs,
    changes speed and orbits the camera; ``page.html#t=0.5`` opens it at t = 0.5 s.

    Returns the written ``Path`` when ``path`` is given, else a ``Viewer`` (shown inline in
    Jupyter; ``Viewer.save(path)`` writes it).
    """
    from mbcomp.core.errors import ModelError
    if not (isinstance(fps, (int, float)) and fps > 0 and fps == fps and fps != float("inf")):
        raise ModelError("view", f"fps must be a positive number, got {fps!r}")
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 2:
        raise ModelError("view", f"max_frames must be an integer >= 2, got {max_frames!r}")
    page = Viewer(render_page(build_scene(result, fps=fps, max_frames=max_frames, title=title)))
    return page if path is None else page.save(path)
