"""The package's hand-written C: ``.c``/``.h`` files read as package data and filled in.

The C lives in ``c/`` folders beside the Python that owns it (``mbcomp/codegen/c``,
``mbcomp/build/c``, ``mbcomp/formulations/c``) and is shipped as package data.  Python
composes a translation unit from these texts:

- values Python decides (sizes, status codes, tolerances) enter as ``#define``s that the
  Python side writes before the file's text;
- a line ``#include "name.h"`` naming a file of one of the ``c/`` folders is replaced by
  that file's text (so editors and ``cc -I`` see ordinary C, and the unit is one text);
- where a file is a template instantiated more than once, ``@NAME@`` placeholders are
  replaced by :func:`fill`, which refuses a placeholder left unfilled or a value without
  a placeholder.

Every file's text is part of the code cache key (:func:`all_text`).
"""
from __future__ import annotations

import functools
import re
from importlib import resources

#: The packages whose ``c/`` folder holds C files, in the order includes are searched.
C_PACKAGES = ("mbcomp.codegen", "mbcomp.build", "mbcomp.formulations")
_INCLUDE = re.compile(r'^[ \t]*#[ \t]*include[ \t]+"([A-Za-z0-9_.]+)"[ \t]*$', re.M)
_PLACEHOLDER = re.compile(r"@([A-Z][A-Z0-9_]*)@")


def _folder(package: str):
    return resources.files(package).joinpath("c")


@functools.lru_cache(maxsize=None)
def raw(package: str, name: str) -> str:
    """The text of ``c/<name>`` of ``package`` as stored (includes not resolved)."""
    return _folder(package).joinpath(name).read_text(encoding="utf-8")


def _locate(name: str) -> str:
    found = [p for p in C_PACKAGES if _folder(p).joinpath(name).is_file()]
    if len(found) != 1:
        raise FileNotFoundError(f"C include {name!r}: found in {found or 'no'} c/ folder of {C_PACKAGES}")
    return found[0]


@functools.lru_cache(maxsize=None)
def read(package: str, name: str) -> str:
    """The text of ``c/<name>`` of ``package`` with its ``#include "x.h"`` lines of package
    files replaced by their (resolved) text; a file is inlined once per text (as an include
    guard would)."""
    seen: set[str] = set()

    def expand(text: str) -> str:
        def one(match: re.Match) -> str:
            include = match.group(1)
            if include in seen:
                return ""
            seen.add(include)
            return expand(raw(_locate(include), include)).rstrip("\n")
        return _INCLUDE.sub(one, text)

    return expand(raw(package, name))


def fill(text: str, **values: object) -> str:
    """``text`` with each ``@NAME@`` replaced by ``str(values[NAME])``; a placeholder without
    a value, or a value without a placeholder, is a ``KeyError`` (a template and its caller
    that drifted apart fail at once, not in the compiler)."""
    present = set(_PLACEHOLDER.findall(text))
    missing, unused = present - set(values), set(values) - present
    if missing or unused:
        raise KeyError(f"C template placeholders: missing values for {sorted(missing)}, "
                       f"no placeholder for {sorted(unused)}")
    return _PLACEHOLDER.sub(lambda m: str(values[m.group(1)]), text)


def files() -> list[tuple[str, str]]:
    """``(package, name)`` of every C file of the package, sorted."""
    out = []
    for package in C_PACKAGES:
        folder = _folder(package)
        if folder.is_dir():
            out.extend((package, entry.name) for entry in folder.iterdir()
                       if entry.name.endswith((".c", ".h")))
    return sorted(out)


@functools.lru_cache(maxsize=1)
def all_text() -> str:
    """Every C file's name and text, for the code cache key: a changed file never reuses an
    artefact built from the old one."""
    return "".join(f"\n/* {package}/c/{name} */\n{raw(package, name)}" for package, name in files())
