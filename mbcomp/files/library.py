"""The model library: ready-made model files shipped with mbcomp, found by name."""
from __future__ import annotations

import functools
import os
import site
import sys
import sysconfig
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10: the tomli backport has the same API
    import tomli as tomllib  # type: ignore[no-redef]


def library_dirs() -> list[Path]:
    """Folders searched for library models, in order: ``$MBCOMP_LIBRARY`` (one or more folders,
    ``os.pathsep``-separated), ``library/`` beside the package (a source checkout or editable
    install), and ``<prefix>/share/mbcomp/library`` (an installed data-files copy)."""
    dirs = [Path(p) for p in os.environ.get("MBCOMP_LIBRARY", "").split(os.pathsep) if p]
    dirs.append(Path(__file__).resolve().parents[2] / "library")
    dirs.extend(_installed_dirs())
    unique: list[Path] = []
    for d in dirs:
        if d.is_dir() and d.resolve() not in [u.resolve() for u in unique]:
            unique.append(d)
    return unique


@functools.lru_cache(maxsize=1)
def _installed_dirs() -> tuple[Path, ...]:
    """Where pip puts the data files: the environment's prefix, and the user base for
    ``--user`` (fixed for the process; ``sysconfig.get_paths`` takes about 0.5 ms a call)."""
    return tuple(Path(base) / "share" / "mbcomp" / "library"
                 for base in (sys.prefix, sysconfig.get_paths().get("data", sys.prefix), site.getuserbase()))


def library_models() -> dict[str, Path]:
    """``{name: path}`` of every library model (first folder wins on a name clash), sorted."""
    found: dict[str, Path] = {}
    for folder in library_dirs():
        for path in sorted(folder.glob("*.toml")):
            if _inside(path, folder):   # (a symlink out of the library is not a library model)
                found.setdefault(path.stem, path)
    return dict(sorted(found.items()))


#: Robot descriptions found in the optional ``example-robot-data`` package (URDF), by name.
ROBOTS = {"ur5": "ur_description/urdf/ur5_robot.urdf", "panda": "panda_description/urdf/panda.urdf"}


def robots_dir() -> Path | None:
    """The ``robots`` folder of the installed ``example-robot-data`` package, or None."""
    try:
        from importlib.metadata import PackageNotFoundError, distribution
        folder = Path(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots"))
    except (ImportError, PackageNotFoundError):
        return None
    return folder if folder.is_dir() else None


def library_robots() -> dict[str, Path]:
    """``{name: URDF path}`` of the robots available (``example-robot-data`` installed)."""
    folder = robots_dir()
    if folder is None:
        return {}
    return {name: folder / rel for name, rel in ROBOTS.items() if (folder / rel).is_file()}


def library_name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a library model or part (None when it can): a library name is
    a plain name or a sub-path inside the library (``"link"``, ``"parts/link"``), never an
    absolute path nor one with ``..``, so that ``library:`` never leaves the library."""
    if not isinstance(name, str) or not name.strip():
        return "is empty: give a library model or part name (see 'mbcomp library')"
    if "\x00" in name or "\\" in name:
        return "is not a library name (a plain name or name/sub-path, see 'mbcomp library')"
    if name.startswith("/") or os.path.isabs(name) or Path(name).drive or ":" in name:
        return "is an absolute path: library: names a model or part inside the library (see 'mbcomp library')"
    if any(part in ("..", ".") for part in name.split("/")):
        return "contains '..' or '.': library: names a model or part inside the library (see 'mbcomp library')"
    return None


def _inside(path: Path, folder: Path) -> bool:
    """True when ``path`` (symlinks resolved) lies inside ``folder``."""
    try:
        return path.resolve().is_relative_to(folder.resolve())
    except (OSError, ValueError, RuntimeError):
        return False


def find_library_model(name: str) -> Path | None:
    """The path of library model ``name`` (with or without ``.toml``; a sub-path inside a
    library folder also works), or of a library robot (``"ur5"``, ``"panda"``: URDF files of
    the optional ``example-robot-data``), or None.  Never a file outside the library:
    absolute paths and ``..`` are refused (``library_name_problem``)."""
    if library_name_problem(name) is not None:
        return None
    stem = name[:-5] if name.endswith(".toml") else name
    found = library_models().get(stem)
    if found is not None:
        return found
    if "/" in stem:
        for folder in library_dirs():
            candidate = folder / f"{stem}.toml"
            if candidate.is_file() and _inside(candidate, folder):
                return candidate
    return library_robots().get(name)


LIBRARY_PREFIX = "library:"


def resolve_model_path(spec: str | os.PathLike) -> Path:
    """The model file that ``spec`` names: a path that exists wins; else a library model's name
    (``"double_pendulum"``, ``"double_pendulum.toml"`` or ``"library:double_pendulum"``).

    A spec that names neither is returned unchanged as a ``Path``, so that the caller's own
    "no such file" report (with the file's name) applies to it.  A ``library:`` spec only ever
    names a file inside the library (``library_name_problem``).
    """
    text = os.fspath(spec)
    if text.startswith(LIBRARY_PREFIX):
        found = find_library_model(text[len(LIBRARY_PREFIX):])
        return found if found is not None else Path(text)
    path = Path(text)
    if path.exists() or "/" in text or os.sep in text:
        return path
    found = find_library_model(text)
    return found if found is not None else path


def find_library_part(name: str) -> Path | None:
    """The path of library part ``name`` (``library/parts/NAME.toml``), else of the library
    model ``name``, or None (what ``use = "library:NAME"`` in a model file refers to).  Only
    files inside a library folder: see ``library_name_problem``."""
    if library_name_problem(name) is not None:
        return None
    stem = name[:-5] if name.endswith(".toml") else name
    for folder in library_dirs():
        path = folder / "parts" / f"{stem}.toml"
        if path.is_file() and _inside(path, folder):
            return path
    return find_library_model(stem)


def library_parts() -> dict[str, Path]:
    """``{name: path}`` of every library part (``library/parts/*.toml``), sorted."""
    found: dict[str, Path] = {}
    for folder in library_dirs():
        for path in sorted((folder / "parts").glob("*.toml")):
            if _inside(path, folder):
                found.setdefault(path.stem, path)
    return dict(sorted(found.items()))


def read_description(path: str | os.PathLike) -> str:
    """The ``description`` of a model file without validating the rest ("" if unreadable)."""
    try:
        data = tomllib.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return ""
    value = data.get("description", "")
    return value if isinstance(value, str) else ""
