"""Operations a lower-layer class offers as a method but a higher layer implements.

``Model.compile`` needs the compiler and ``Model.save`` the file writer, both of which
import the model layer.  Rather than importing upwards, ``Model`` looks the operation up
here, and the package registers it when it is imported (``mbcomp/__init__.py``), so the
import graph keeps one direction.
"""
from __future__ import annotations

from typing import Callable

_REGISTERED: dict[str, Callable] = {}


def provide(name: str, function: Callable) -> None:
    """Register ``function`` as the implementation of operation ``name``."""
    _REGISTERED[name] = function


def service(name: str) -> Callable:
    """The implementation of operation ``name`` (``RuntimeError`` when none is registered,
    which only happens when a module is loaded outside the ``mbcomp`` package)."""
    try:
        return _REGISTERED[name]
    except KeyError:
        raise RuntimeError(f"mbcomp operation {name!r} is not available: import the mbcomp package") from None
