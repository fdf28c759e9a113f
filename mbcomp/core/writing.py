"""Writing output files so that a failed write is never reported as success: every byte goes
through one ``write`` and a ``close`` whose errors (a full disk shows only when the buffer is
flushed) become a ``WriteError`` naming the writer and the path."""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Iterator

from mbcomp.core.errors import WriteError


def _failed(what: str, path: Any, exc: OSError) -> WriteError:
    return WriteError(what, f"cannot write {str(path)!r}: {exc.strerror or exc}")


def write_file(path: str | os.PathLike, data: str | bytes, what: str) -> Path:
    """Write ``data`` (text as UTF-8) to ``path`` (its folder must exist); a failed open, write,
    flush or close raises ``WriteError`` (``what``: the writer, e.g. ``"to_csv"``)."""
    path = Path(path)
    try:
        with open(path, "wb") as fh:
            fh.write(data.encode("utf-8") if isinstance(data, str) else data)
    except OSError as exc:
        raise _failed(what, path, exc) from None
    return path


@contextlib.contextmanager
def staged(path: str | os.PathLike, what: str) -> Iterator[Path]:
    """A temporary file with ``path``'s suffix for a writer that wants a file name
    (matplotlib, Pillow, ffmpeg) and may not report every failed write; on a clean exit its
    bytes go to ``path`` through ``write_file``."""
    path = Path(path)
    try:
        folder = tempfile.mkdtemp(prefix="mbcomp-out-")
    except OSError as exc:
        raise _failed(what, path, exc) from None
    try:
        scratch = Path(folder) / f"output{path.suffix}"
        yield scratch
        if not scratch.exists():  # the writer wrote nothing (a test's stand-in encoder): nothing to copy
            return
        try:
            data = scratch.read_bytes()
        except OSError as exc:
            raise _failed(what, path, exc) from None
        write_file(path, data, what)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
