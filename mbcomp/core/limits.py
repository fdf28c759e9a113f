"""Limits on what one model may ask for, checked before the work starts (docs/errors.md).

Each limit has a default that no sensible model reaches and an environment variable that
raises it: the size of a model file, the sub-model instances of one model, how deeply
sub-models nest, and the steps one integration may take.  Reading a model file also goes
through here: only regular files are read (a FIFO, a device or ``/dev/zero`` is refused
before it is opened for reading), and never more bytes than the limit.
"""
from __future__ import annotations

import os
import stat
from pathlib import Path

from mbcomp.core.errors import ModelError

#: ``(environment variable, default)`` of each limit.
FILE_BYTES = ("MBCOMP_MAX_FILE_BYTES", 10_000_000)
INSTANCES = ("MBCOMP_MAX_INSTANCES", 5_000)
NESTING = ("MBCOMP_MAX_NESTING", 50)
STEPS = ("MBCOMP_MAX_STEPS", 1_000_000_000)


def _limit(spec: tuple[str, int]) -> int:
    """The limit's value: its environment variable (a positive integer, ``1e9`` accepted)
    when set, else its default."""
    variable, default = spec
    text = os.environ.get(variable, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value >= 1 and value < 1e300 and value == int(value)):
        raise ModelError(variable, f"must be a positive whole number, got {text[:20]!r}")
    return int(value)


def max_file_bytes() -> int:
    """Bytes a model or URDF file may hold (``$MBCOMP_MAX_FILE_BYTES``, default 10 MB)."""
    return _limit(FILE_BYTES)


def max_instances() -> int:
    """Sub-model instances one model may hold (``$MBCOMP_MAX_INSTANCES``, default 5 000)."""
    return _limit(INSTANCES)


def max_nesting() -> int:
    """How deeply sub-model instances may nest (``$MBCOMP_MAX_NESTING``, default 50)."""
    return _limit(NESTING)


def max_steps() -> int:
    """Steps one integration may take (``$MBCOMP_MAX_STEPS``, default 1e9): a run whose
    pace says it would need more gives up early instead of running for days."""
    return _limit(STEPS)


def _kind(mode: int) -> str:
    """What a file that is not a regular file is, for messages."""
    for test, name in ((stat.S_ISDIR, "a directory"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
                       (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def file_problem(path: str | os.PathLike) -> str | None:
    """Why ``path`` cannot be read as a model file (None when it can): it is missing, not a
    regular file (a directory, FIFO, device or socket; a symlink is followed), or larger than
    ``max_file_bytes()``.  Nothing is opened."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return "cannot read the file (no such file)"
    except (OSError, ValueError) as exc:
        return f"cannot read the file ({getattr(exc, 'strerror', None) or exc})"
    return _stat_problem(info)


def _stat_problem(info: os.stat_result) -> str | None:
    if not stat.S_ISREG(info.st_mode):
        return f"is {_kind(info.st_mode)}, not a file: only regular files are read"
    limit = max_file_bytes()
    if info.st_size > limit:
        return _too_large(info.st_size, limit)
    return None


def _too_large(size: int | None, limit: int) -> str:
    held = f"holds {size} bytes" if size is not None else "holds more"
    return (f"the file {held}, more than the limit of {limit} bytes "
            f"(set {FILE_BYTES[0]} to raise it)")


def read_file(path: str | os.PathLike, label: str) -> bytes:
    """The bytes of the model file ``path`` after ``file_problem``'s checks (again on the
    opened file, which is opened without blocking); ``ModelError`` ``"<label>: <problem>"``."""
    problem = file_problem(path)
    if problem is not None:
        raise ModelError(problems=[f"{label}: {problem}"])
    limit = max_file_bytes()
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(Path(path), flags)
    except OSError as exc:
        raise ModelError(problems=[f"{label}: cannot read the file ({exc.strerror or exc})"]) from None
    try:
        problem = _stat_problem(os.fstat(fd))  # the file opened, which may have been swapped since
        if problem is not None:
            raise ModelError(problems=[f"{label}: {problem}"])
        chunks, size = [], 0
        while size <= limit:
            chunk = os.read(fd, min(1 << 20, limit + 1 - size))
            if not chunk:
                break
            chunks.append(chunk)
            size += len(chunk)
    except OSError as exc:
        raise ModelError(problems=[f"{label}: cannot read the file ({exc.strerror or exc})"]) from None
    finally:
        os.close(fd)
    if size > limit:  # it grew while being read
        raise ModelError(problems=[f"{label}: {_too_large(None, limit)}"])
    return b"".join(chunks)
