"""The code cache: generated artefacts (``.so``, ``.py``) that run only if this user wrote them.

A cache directory is shared by every mbcomp process of a user, and a file in it is executed
(``ctypes.CDLL`` of a ``.so``, ``exec`` of a ``.py``).  So nothing is loaded unless:

1. the directory is owned by the user and not writable by group or others (otherwise a
   private fallback directory is used, with a :class:`CacheWarning`);
2. the entry's manifest ``<key>.json`` carries a valid HMAC-SHA256 made with the user's
   secret (``secret``, mode 0600, in the directory), so only this user's mbcomp wrote it;
3. the manifest names this key and the current toolchain (compiler, its ``--version``,
   flags, Python ABI, platform);
4. the artefact is a regular file owned by the user, not group/other-writable, of the
   recorded size and sha256 (a truncated or damaged file is caught here).

Any failed check means the entry is rebuilt, never loaded.  The key itself is the sha256 of
the model structure, the code templates, the toolchain and the code generator version, so
changing any of them gives a new entry.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import hmac
import json
import os
import platform
import stat
import subprocess
import sys
import sysconfig
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Iterator, Mapping

#: Bump when the manifest format changes.
MANIFEST_VERSION = 1
SECRET_NAME = "secret"
#: Longest wait (s) for another process that builds the same entry (a compiler's own limit is
#: 600 s); after it this process builds the entry itself.
BUILD_WAIT = 660.0


class CacheWarning(UserWarning):
    """The configured cache directory cannot be trusted or used: a private one is used instead."""


# -- where --------------------------------------------------------------------------------
def configured_dir() -> Path:
    """``$MBCOMP_CACHE_DIR``, else the user cache directory (``~/.cache/mbcomp``,
    ``~/Library/Caches/mbcomp`` on macOS), else, with no home directory (no ``$HOME`` and
    no passwd entry: a container run with an arbitrary uid), the per-user temporary
    directory ``<tmp>/mbcomp-<uid>``; not checked (see :func:`cache_dir`)."""
    env = os.environ.get("MBCOMP_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and sys.platform != "darwin":
        return Path(xdg) / "mbcomp"
    try:
        home = Path.home()
    except (RuntimeError, KeyError, OSError):  # no $HOME and no passwd entry for this uid
        return _per_user_temp()
    if sys.platform == "darwin":
        return home / "Library" / "Caches" / "mbcomp"
    return home / ".cache" / "mbcomp"


def _per_user_temp() -> Path:
    """``<tmp>/mbcomp-<uid>``: the private directory used when no other is configured or safe."""
    return Path(tempfile.gettempdir()) / f"mbcomp-{_uid() if _uid() is not None else 'user'}"


def _uid() -> int | None:
    return os.getuid() if hasattr(os, "getuid") else None


def directory_problem(path: Path) -> str | None:
    """Why ``path`` is not a safe cache directory for this user (None when it is).

    Safe: a directory owned by the user, not writable by group or others, readable and
    writable by the user; or a symlink owned by the user to such a directory."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return "does not exist"
    except OSError as exc:
        return f"cannot be inspected ({exc.strerror})"
    uid = _uid()
    if stat.S_ISLNK(info.st_mode):
        if uid is not None and info.st_uid != uid:
            return f"is a symlink owned by another user (uid {info.st_uid})"
        target = os.path.realpath(path)
        try:
            info = os.stat(path)
        except FileNotFoundError:
            return f"is a symlink to {str(target)!r}, which does not exist"
        except OSError as exc:
            return f"is a symlink whose target cannot be inspected ({exc.strerror})"
        if not stat.S_ISDIR(info.st_mode):
            return f"is a symlink to {str(target)!r}, which is not a directory"
        problem = directory_problem(Path(target)) if target != os.fspath(path) else None
        return f"is a symlink to {str(target)!r}, which {problem}" if problem else None
    if not stat.S_ISDIR(info.st_mode):
        return f"is not a directory (it is {_file_kind(info.st_mode)})"
    if uid is not None and info.st_uid != uid:
        return f"is owned by another user (uid {info.st_uid})"
    if uid is not None and info.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"is writable by group or others (mode {stat.filemode(info.st_mode)})"
    if not os.access(path, os.R_OK | os.W_OK | os.X_OK):
        return "is not readable and writable by you"
    return None


def _file_kind(mode: int) -> str:
    """What a file that is not a directory is, for messages."""
    for test, name in ((stat.S_ISREG, "a regular file"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return "a special file"


def _prepare(path: Path) -> str | None:
    """Create ``path`` (mode 0700) if missing; return why it is unusable, or None."""
    if os.path.islink(path):   # a symlink is checked, never created through (a dangling one says so)
        return directory_problem(path)
    try:
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
    except FileExistsError:
        return directory_problem(path) or "cannot be created (it exists)"
    except OSError as exc:
        return f"cannot be created ({exc.strerror or exc})"
    return directory_problem(path)


def cache_dir() -> Path:
    """The directory the cache uses: the configured one when it is safe, else a private
    fallback (``<tmp>/mbcomp-<uid>``, or a fresh temporary directory) with a warning."""
    configured = configured_dir()
    problem = _prepare(configured)
    if problem is None:
        return configured
    fallback = _per_user_temp()
    if fallback == configured or _prepare(fallback) is not None:
        fallback = Path(tempfile.mkdtemp(prefix="mbcomp-cache-"))
    message = (f"mbcomp: cache directory {str(configured)!r} {problem}; using the private directory "
               f"{str(fallback)!r} instead (see docs/cache.md)")
    if (str(configured), problem) not in _WARNED:   # once: one compile asks for the directory several times
        _WARNED.add((str(configured), problem))
        warnings.warn(message, CacheWarning, stacklevel=3)
    return fallback


#: ``(directory, problem)`` of the cache warnings given so far in this process (each is given once).
_WARNED: set[tuple[str, str]] = set()


# -- the per-user secret ----------------------------------------------------------------------
def _secret(directory: Path) -> bytes:
    """The user's HMAC key for ``directory`` (32 random bytes, mode 0600), made on first use.

    A secret that is not a private regular file of the user is replaced, which
    invalidates every entry signed with it."""
    path = directory / SECRET_NAME
    for _ in range(3):
        try:
            info = os.lstat(path)
        except FileNotFoundError:
            info = None
        if info is not None:
            uid = _uid()
            private = (stat.S_ISREG(info.st_mode) and info.st_size == 32
                       and (uid is None or (info.st_uid == uid and not info.st_mode & 0o077)))
            if private:
                with open(path, "rb") as fh:
                    return fh.read()
            path.unlink()
        fd, tmp = tempfile.mkstemp(dir=directory, prefix=".secret.")  # mode 0600
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(os.urandom(32))
            try:
                os.link(tmp, path)  # atomic, and never replaces another process's secret
            except FileExistsError:
                pass
        finally:
            os.unlink(tmp)
    raise OSError(f"cannot keep a private secret in {directory}")


def _sign(secret: bytes, manifest: Mapping[str, Any]) -> str:
    body = json.dumps({k: v for k, v in manifest.items() if k != "hmac"}, sort_keys=True).encode()
    return hmac.new(secret, body, hashlib.sha256).hexdigest()


# -- the key ----------------------------------------------------------------------------------
@functools.lru_cache(maxsize=8)
def _compiler_version(compiler: str) -> str:
    try:
        done = subprocess.run([compiler, "--version"], capture_output=True, timeout=60, check=False)
        return done.stdout.decode(errors="replace").strip()
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def toolchain(compiler: str | None = None, flags: tuple[str, ...] = ()) -> dict:
    """What, besides the model, decides an artefact's bytes: the compiler (path and
    ``--version``), the flags, the Python implementation and ABI, and the platform."""
    return {
        "compiler": compiler or "",
        "compiler_version": _compiler_version(compiler) if compiler else "",
        "flags": list(flags),
        "python": f"{sys.implementation.cache_tag}|{sysconfig.get_config_var('SOABI') or ''}",
        "platform": f"{sys.platform}|{platform.machine()}",
    }


def entry_key(description: str, templates: str, tools: Mapping[str, Any]) -> str:
    """sha256 (32 hex digits) of the structure description, the templates and the toolchain."""
    text = json.dumps({"structure": description, "templates": hashlib.sha256(templates.encode()).hexdigest(),
                       "toolchain": dict(tools)}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


# -- writing ----------------------------------------------------------------------------------
def write_atomic(path: Path, data: bytes, mode: int = 0o600) -> None:
    """Write via a temporary file and rename, so that concurrent runs never see half a file
    (and a process that has the old file mapped keeps it intact)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, mode)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def store(key: str, suffix: str, data: bytes, inputs: Mapping[str, Any], directory: Path | None = None) -> Path | None:
    """Write an artefact and its signed manifest; its path, or None if the cache is unusable.
    ``directory``: a cache directory chosen earlier (``cache_dir()``), e.g. by a build that
    finishes in the background; default: the one configured now."""
    try:
        directory = directory or cache_dir()
        secret = _secret(directory)
        path = directory / f"{key}{suffix}"
        manifest = {"version": MANIFEST_VERSION, "key": key, "file": path.name, "size": len(data),
                    "sha256": hashlib.sha256(data).hexdigest(), "inputs": dict(inputs)}
        manifest["hmac"] = _sign(secret, manifest)
        write_atomic(path, data)
        write_atomic(directory / f"{key}{suffix}.json", json.dumps(manifest, sort_keys=True).encode())
        return path
    except OSError:
        return None  # an unusable cache only costs a rebuild next time


@contextlib.contextmanager
def building(name: str, wait: float | None = None) -> Iterator[bool]:
    """Hold the build lock ``name`` (e.g. a hash of a model's structure) while generating an
    entry: another process (a parallel worker, a second script) compiling the same model waits
    here, then finds the entry in the cache instead of compiling it a second time.

    An exclusive ``flock`` on ``<name>.lock`` in the cache directory; the kernel releases it when
    its holder exits or crashes.  Yields whether the lock is held: False where locks are not
    available (no ``fcntl``, an unusable cache) or after waiting ``wait`` s (``BUILD_WAIT``),
    and the caller then builds unlocked, as it would without a cache."""
    try:
        import fcntl
    except ImportError:  # Windows: no flock; concurrent builds stay correct (atomic writes)
        yield False
        return
    try:
        fd = os.open(cache_dir() / f"{name}.lock", os.O_RDWR | os.O_CREAT, 0o600)
    except OSError:
        yield False
        return
    try:
        deadline = time.monotonic() + (BUILD_WAIT if wait is None else wait)
        held = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                held = True
                break
            except BlockingIOError:
                if time.monotonic() >= deadline:
                    break
                time.sleep(0.005)
            except OSError:  # a file system without locks
                break
        yield held
    finally:
        os.close(fd)  # releases the lock


# -- reading ----------------------------------------------------------------------------------
def _private_file(path: Path) -> os.stat_result | None:
    info = os.lstat(path)
    uid = _uid()  # None where ownership and mode bits do not exist (Windows)
    if not stat.S_ISREG(info.st_mode):
        return None
    if uid is not None and (info.st_uid != uid or info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)):
        return None
    return info


def verified(key: str, suffix: str, inputs: Mapping[str, Any]) -> Path | None:
    """The path of a cached artefact that passes every check (module docstring), else None.

    ``inputs`` holds the expected toolchain entries; a failed entry is removed so that it
    is rebuilt."""
    try:
        directory = cache_dir()
        path = directory / f"{key}{suffix}"
        manifest_path = directory / f"{key}{suffix}.json"
        if not path.exists() and not manifest_path.exists():
            return None
        problem = _check(directory, key, path, manifest_path, inputs)
    except OSError:
        return None
    if problem is not None:
        discard(key, suffix)
        return None
    return path


def _check(directory: Path, key: str, path: Path, manifest_path: Path, inputs: Mapping[str, Any]) -> str | None:
    """Why the entry fails verification (None when it passes)."""
    if _private_file(manifest_path) is None or _private_file(path) is None:
        return "not a private file"
    try:
        manifest = json.loads(manifest_path.read_text())
    except (ValueError, UnicodeDecodeError):
        return "unreadable manifest"
    if not isinstance(manifest, dict) or not isinstance(manifest.get("hmac"), str):
        return "malformed manifest"
    if not hmac.compare_digest(manifest["hmac"], _sign(_secret(directory), manifest)):
        return "bad signature"
    if manifest.get("version") != MANIFEST_VERSION or manifest.get("key") != key or manifest.get("file") != path.name:
        return "manifest of another entry"
    recorded = manifest.get("inputs", {})
    if any(recorded.get(name) != value for name, value in inputs.items()):
        return "built by another toolchain"
    data = path.read_bytes()
    if len(data) != manifest.get("size") or hashlib.sha256(data).hexdigest() != manifest.get("sha256"):
        return "artefact changed since it was written"
    return None


def read_text(key: str, suffix: str, inputs: Mapping[str, Any]) -> str | None:
    """The verified text of a cached artefact, or None."""
    path = verified(key, suffix, inputs)
    if path is None:
        return None
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError):
        return None


def discard(key: str, suffix: str) -> None:
    """Remove an entry (artefact and manifest); unlinking never disturbs a process that has
    the old file loaded."""
    try:
        directory = cache_dir()
    except OSError:
        return
    for name in (f"{key}{suffix}", f"{key}{suffix}.json"):
        try:
            (directory / name).unlink()
        except OSError:
            pass
