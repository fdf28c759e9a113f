"""Errors that name the component and what is wrong with it."""
from __future__ import annotations

from typing import Any


def describe(component: Any) -> str:
    """``"Revolute 'elbow'"`` for a component, the text itself for a string."""
    if component is None:
        return ""
    if isinstance(component, str):
        return component
    name = getattr(component, "name", None)
    return f"{type(component).__name__} {name!r}" if name is not None else type(component).__name__


class ModelError(ValueError):
    """An invalid model: raised by ``Model.add`` or ``Model.compile``.

    ``ModelError(joint, "axis has zero length")`` reads
    ``"Revolute 'elbow': axis has zero length"``.  Several problems may be
    collected into one error (``problems`` keeps them as a list).
    """

    def __init__(self, component: Any = None, message: str = "", problems: list[str] | None = None):
        if problems:
            self.problems = list(problems)
            text = "model has %d problem%s:\n  - " % (len(problems), "s" * (len(problems) > 1))
            text += "\n  - ".join(problems)
        else:
            prefix = describe(component)
            text = f"{prefix}: {message}" if prefix else message
            self.problems = [text]
        self.component = component
        super().__init__(text)


class CompileError(ModelError):
    """A model whose structure cannot be compiled (collects every problem found)."""


class UnknownNameError(ModelError, KeyError):
    """A name that is not there (a coordinate of a Result, ...): a ``ModelError`` that is
    also the ``KeyError`` a lookup by name is expected to raise."""

    __str__ = ModelError.__str__


class SimulationError(RuntimeError):
    """Evaluation or simulation failed: the message says which component and why."""

    def __init__(self, message: str, component: Any = None):
        prefix = describe(component)
        super().__init__(f"{prefix}: {message}" if prefix else message)
        self.component = component


class TrialStateError(SimulationError):
    """A workspace cannot evaluate a trial state of the integrator (e.g. Newton for dependent
    coordinates fails far from the last accepted state): the step is retried shorter from
    the state ``Workspace.retreat()`` returns."""


def format_state(values) -> str:
    """A coordinate vector for messages: 6 significant digits, small values kept visible."""
    return "[" + ", ".join(f"{float(v):.6g}" for v in values) + "]"


class WriteError(ModelError, OSError):
    """An output file could not be written (a full disk, a missing permission, an error that
    only shows when the file is flushed or closed): a ``ModelError`` naming the writer and
    the path, and an ``OSError`` as before."""
