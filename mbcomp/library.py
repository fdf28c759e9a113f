"""The model library: ready-made model files shipped with mbcomp, found by name."""
from __future__ import annotations

import os
import sys
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
    dirs.append(Path(__file__).resolve().parent.parent / "library")
    dirs.append(Path(sys.prefix) / "share" / "mbcomp" / "library")
    return [d for d in dirs if d.is_dir()]


def library_models() -> dict[str, Path]:
    """``{name: path}`` of every library model (first folder wins on a name clash), sorted."""
    found: dict[str, Path] = {}
    for folder in library_dirs():
        for path in sorted(folder.glob("*.toml")):
            found.setdefault(path.stem, path)
    return dict(sorted(found.items()))


def find_library_model(name: str) -> Path | None:
    """The path of library model ``name`` (with or without ``.toml``), or None."""
    stem = name[:-5] if name.endswith(".toml") else name
    return library_models().get(stem)


def find_library_part(name: str) -> Path | None:
    """The path of library part ``name`` (``library/parts/NAME.toml``), else of the library
    model ``name``, or None (what ``use = "library:NAME"`` in a model file refers to)."""
    stem = name[:-5] if name.endswith(".toml") else name
    for folder in library_dirs():
        path = folder / "parts" / f"{stem}.toml"
        if path.is_file():
            return path
    return find_library_model(stem)


def library_parts() -> dict[str, Path]:
    """``{name: path}`` of every library part (``library/parts/*.toml``), sorted."""
    found: dict[str, Path] = {}
    for folder in library_dirs():
        for path in sorted((folder / "parts").glob("*.toml")):
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
