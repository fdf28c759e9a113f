"""One validator for every number a component holds.

Each component class declares its numeric attributes as ``ParameterSpec``s (name, shape,
unit, check, default, doc).  The constructors, ``System.with_parameters`` /
``simulate(parameters=...)`` and the model-file reader all call the same
``validate(spec, value, owner)``, so a value one of them rejects is rejected by all of
them with the same message (``"Spring 'k': stiffness must not be negative, got -2"``).

``validate`` works on plain values, so derived values (a sub-model parameter expression
evaluated to a number) are checked the same way as values typed by hand.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from mbcomp.core.errors import ModelError

__all__ = ["Check", "ParameterSpec", "ParameterError", "REQUIRED", "validate", "finite", "positive", "nonnegative",
           "in_range", "unit_vector", "spd_inertia", "spec_of", "axis_name", "MAX_MAGNITUDE"]

#: The largest magnitude a parameter may have (SI units).  The equations of motion multiply up
#: to three parameters (``m c^2``, ``I + m c^2``, ``m g c``), so values up to 1e100 keep every
#: product below the float range (1.8e308) while a value whose square overflows (> 1.3e154) is
#: refused by name instead of turning into inf or NaN inside the generated code.  No physical
#: quantity of a mechanism comes near it; directions (normalised) are exempt.
MAX_MAGNITUDE = 1e100


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED = _Required()
"""Default of a parameter the user must give."""


def _show(arr: np.ndarray) -> str:
    if arr.ndim == 0:
        return f"{float(arr):g}"
    return "(" + ", ".join(f"{float(v):g}" for v in arr.reshape(-1)) + ")"


@dataclass(frozen=True)
class Check:
    """A condition on a finite float array.

    ``test(arr)`` returns the problem (text after the attribute name, e.g. ``"must be
    positive, got -2"``) or ``None``.  ``shapes`` are extra shapes accepted besides the
    spec's own; ``normalise(arr)`` turns an accepted array into the stored value (default:
    a float or a tuple of floats); ``convert(value)`` may map non-numeric spellings (an
    axis name) to numbers first; ``expects`` says what is accepted in shape messages.
    """

    describe: str
    test: Callable[[np.ndarray], "str | None"] = lambda arr: None
    shapes: tuple = ()
    normalise: "Callable[[np.ndarray], Any] | None" = None
    convert: "Callable[[Any], Any] | None" = None
    expects: str = ""

    def __call__(self, arr: np.ndarray) -> "str | None":
        return self.test(arr)


finite = Check("finite")
positive = Check("positive", lambda a: None if np.all(a > 0) else f"must be positive, got {_show(a)}")
nonnegative = Check("nonnegative", lambda a: None if np.all(a >= 0) else f"must not be negative, got {_show(a)}")


def in_range(low: float, high: float) -> Check:
    """Every entry in the closed interval ``[low, high]``."""
    return Check(f"in [{low:g}, {high:g}]",
                 lambda a: None if np.all((a >= low) & (a <= high)) else f"must lie in [{low:g}, {high:g}], got {_show(a)}")


def _axis_name(value: Any) -> Any:
    """``"x"``, ``"-y"``, ``"+z"``: the signed unit vector; anything else unchanged."""
    if isinstance(value, str):
        key = value.strip().lower()
        sign = -1.0 if key.startswith("-") else 1.0
        body = key[1:] if key[:1] in "+-" else key
        if body in ("x", "y", "z") and key.count("-") + key.count("+") <= 1:
            return tuple(sign * float(c == body) for c in "xyz")
        raise _Problem(f"must be 'x', 'y', 'z' or a 3-vector, got {value!r}")
    return value


def axis_name(axis: Any) -> Any:
    """``"x"``, ``"-y"``, ... for a signed coordinate axis, else the vector as a list."""
    values = tuple(float(c) for c in axis)
    for i, letter in enumerate("xyz"):
        unit = tuple(float(j == i) for j in range(3))
        if values == unit:
            return letter
        if values == tuple(-c + 0.0 for c in unit):
            return "-" + letter
    return list(values)


def _unit(arr: np.ndarray) -> tuple:
    """``arr`` scaled to unit length without overflow or underflow (exact axes stay exact)."""
    with np.errstate(all="ignore"):
        norm = float(np.linalg.norm(arr))
    if not 1e-150 < norm < 1e150:  # rescale first: the norm would overflow or lose digits
        arr = arr / np.max(np.abs(arr))
        norm = float(np.linalg.norm(arr))
    vec = arr / norm
    vec[np.abs(vec) < 1e-15] = 0.0
    return tuple(float(c) + 0.0 for c in vec)


unit_vector = Check("a non-zero direction (stored as a unit vector)",
                    lambda a: "has zero length (it is a direction)" if not np.any(a) else None,
                    normalise=_unit, convert=_axis_name)


def _inertia_problem(arr: np.ndarray) -> "str | None":
    matrix = _inertia_matrix(arr)
    scale = float(np.max(np.abs(matrix)))
    if scale == 0.0:
        return None  # a point mass
    unit = matrix / scale  # entries in [-1, 1]: no overflow below
    if arr.shape == (3,):  # principal values: the moments themselves (what eigvalsh gives for a diagonal)
        a, b, c = sorted(float(v) for v in np.diag(unit))
    else:
        if not np.allclose(unit, unit.T, rtol=0, atol=1e-12):
            return "matrix is not symmetric"
        try:
            a, b, c = np.linalg.eigvalsh(0.5 * (unit + unit.T))
        except np.linalg.LinAlgError:
            return "has no computable principal moments"
    with np.errstate(all="ignore"):
        moments = np.array([a, b, c]) * scale
    if not np.all(np.isfinite(moments)):
        return "is too large to handle (its principal moments overflow)"
    if a < -1e-9:
        return f"is not positive semi-definite (principal moments {_show(moments)})"
    if c > a + b + 1e-9:
        return f"violates the triangle inequality: principal moment {moments[2]:g} > {moments[0]:g} + {moments[1]:g}"
    return None


def _inertia_matrix(arr: np.ndarray) -> np.ndarray:
    if arr.shape == (3,):
        return np.diag(arr)
    if arr.shape == (6,):
        xx, yy, zz, xy, xz, yz = arr
        return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    return arr


def _inertia_value(arr: np.ndarray) -> "tuple | None":
    """None for a point mass, 3 principal values, or the 6 entries xx yy zz xy xz yz."""
    matrix = _inertia_matrix(arr)
    if not np.any(matrix):
        return None
    if arr.shape == (3,) or not np.any(matrix - np.diag(np.diag(matrix))):
        return tuple(float(v) for v in np.diag(matrix))
    return tuple(float(matrix[i, j]) for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))


spd_inertia = Check("3 principal values or a symmetric positive semi-definite 3x3 matrix meeting the "
                    "triangle inequality (zeros: a point mass)", _inertia_problem,
                    shapes=((3, 3), (6,)), normalise=_inertia_value,
                    expects="3 principal values or a 3x3 matrix")


@dataclass(frozen=True)
class ParameterSpec:
    """What one numeric attribute of a component is and which values it accepts.

    ``shape``: ``()`` a number, ``(3,)`` a 3-vector, ``(-1,)`` a number or 1-D array of
    any length (a number stays a float).  ``unit``: SI unit text (``"N/m"``; ``"q"`` means
    the unit of the joint's coordinate).  ``optional``: ``None`` is accepted (and kept).
    ``time_input``: a callable ``(t, q, qd)`` (or of ``t``) is accepted as is (it is then
    an input, not a parameter).  ``structural``: the value decides the generated code (an
    axis): it is validated like any other but is not a run-time parameter.
    """

    name: str
    shape: tuple = ()
    unit: str = ""
    check: Check = finite
    default: Any = REQUIRED
    doc: str = ""
    optional: bool = False
    time_input: bool = False
    structural: bool = False


class ParameterError(ModelError):
    """A value ``validate`` rejected: ``attribute`` is the spec's name and ``detail`` the
    problem without the owner (``"must be positive, got -1"``), for callers that locate it
    themselves (the file reader writes ``"[bodies.b] mass: must be positive, got -1"``)."""

    def __init__(self, owner: Any, attribute: str, detail: str):
        self.attribute = attribute
        self.detail = detail
        super().__init__(owner, f"{attribute} {detail}")


class _Problem(Exception):
    """A value problem raised by a ``convert`` hook (becomes a ``ModelError``)."""


def _type_name(value: Any) -> str:
    if callable(value):
        return "a callable"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, str):
        return f"the string {value!r}" if len(value) < 40 else "a string"
    if isinstance(value, (dict, set)):
        return f"a {type(value).__name__}"
    return type(value).__name__


def validate(spec: ParameterSpec, value: Any, owner: Any) -> Any:
    """``value`` checked against ``spec``: the stored form (float, tuple of floats, None or
    the callable), else a ``ModelError`` naming ``owner`` (a component or a text such as
    ``"parameter 'k.stiffness'"``) and the attribute.

    The one validator of component values: constructors, ``System.with_parameters`` and
    the file reader all call it.
    """
    name = spec.name
    if value is None and spec.optional:
        return None
    if spec.time_input and callable(value):
        return value
    check = spec.check
    plain = _plain(spec, value)
    if plain is not None:  # finite floats of the spec's shape, in range: what most values are
        problem = check(plain)
        if problem:
            raise ParameterError(owner, name, f"{problem}")
        if check.normalise is not None:
            return check.normalise(plain)
        return float(plain) if plain.ndim == 0 else tuple(float(v) for v in plain)
    if check.convert is not None:
        try:
            value = check.convert(value)
        except _Problem as exc:
            raise ParameterError(owner, name, f"{exc}") from None
    what = check.expects or {(): "a number", (3,): "a 3-vector of numbers", (-1,): "a number or an array of numbers"}.get(
        tuple(spec.shape), f"an array of shape {spec.shape}")
    if spec.time_input:
        what += " or a callable"
    if isinstance(value, (bool, str, bytes, dict, set)) or value is None:
        raise ParameterError(owner, name, f"must be {what}, got {_type_name(value)}")
    try:
        with np.errstate(all="ignore"):
            arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ParameterError(owner, name, f"must be {what}, got {_type_name(value) if callable(value) else _short(value)}") from None
    arr = _shaped(spec, arr, owner, value)
    if not np.all(np.isfinite(arr)):
        if arr.ndim == 0:
            raise ParameterError(owner, name, f"must be finite, got {_show(arr)}")
        raise ParameterError(owner, name, f"has a non-finite entry: {_show(arr)}")
    if check.normalise is not _unit and arr.size and float(np.max(np.abs(arr))) > MAX_MAGNITUDE:
        raise ParameterError(owner, name, f"is too large to handle: {_show(arr)} (magnitudes above "
                             f"{MAX_MAGNITUDE:g} overflow the equations of motion: their squares and products "
                             "exceed the float range)")
    problem = check(arr)
    if problem:
        raise ParameterError(owner, name, f"{problem}")
    if check.normalise is not None:
        return check.normalise(arr)
    if arr.ndim == 0:
        return float(arr)
    if tuple(spec.shape) == (-1,) and arr.size == 1:
        return float(arr[0])
    return tuple(float(v) for v in arr)


_NUMBER_TYPES = (float, int, np.float64)


def _plain(spec: ParameterSpec, value: Any) -> "np.ndarray | None":
    """``value`` as a float array when it is a plain Python (or numpy) number, or a tuple or
    list of them, of the spec's own shape (``()`` or ``(n,)``), finite and within
    ``MAX_MAGNITUDE``: such a value needs none of ``validate``'s conversions and messages
    (a quick path: the model files and constructors give about 80,000 of them in the tests).
    None for anything else (``validate``'s general path decides)."""
    if spec.check.convert not in (None, _axis_name):  # (an axis name's conversion leaves numbers as they are)
        return None
    shape = spec.shape
    kind = type(value)
    if kind in _NUMBER_TYPES and kind is not bool:
        if shape != ():
            return None
        numbers = (value,)
    elif (kind is tuple or kind is list) and len(shape) == 1 and len(value) == shape[0]:
        numbers = value
        if not all(type(v) in _NUMBER_TYPES for v in numbers):
            return None
    else:
        return None
    try:
        floats = [float(v) for v in numbers]
    except OverflowError:  # an int beyond the float range: the general path says so
        return None
    limit = np.inf if spec.check.normalise is _unit else MAX_MAGNITUDE
    if not all(-limit <= v <= limit and math.isfinite(v) for v in floats):
        return None
    return np.array(floats[0] if shape == () else floats)


def _shaped(spec: ParameterSpec, arr: np.ndarray, owner: Any, value: Any) -> np.ndarray:
    """``arr`` in the spec's shape (or one of its check's extra shapes), else ``ModelError``."""
    shape = tuple(spec.shape)
    if arr.shape == shape or arr.shape in spec.check.shapes:
        return arr
    if spec.check.expects:
        raise ParameterError(owner, spec.name, f"must be {spec.check.expects}, got shape {arr.shape}")
    if shape == () and arr.size == 1:
        return arr.reshape(())
    if shape == (-1,):
        if arr.ndim == 0:
            return arr.reshape(1)
        if arr.ndim == 1:
            return arr
        raise ParameterError(owner, spec.name, f"must be a number or a 1-D array, got shape {arr.shape}")
    if shape and arr.ndim == 1 and len(shape) == 1 and arr.shape != shape:
        raise ParameterError(owner, spec.name, f"must have {shape[0]} components, got {arr.size}")
    accepted = " or ".join(str(s) for s in (shape,) + tuple(spec.check.shapes))
    if shape == ():
        raise ParameterError(owner, spec.name, f"must be a number, got an array of shape {arr.shape}")
    raise ParameterError(owner, spec.name, f"must have shape {accepted}, got {arr.shape}")


def _short(value: Any, width: int = 40) -> str:
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a broken __repr__ must not hide the real problem
        text = type(value).__name__
    return text if len(text) <= width else text[: width - 3] + "..."


def spec_of(component_class: type, name: str) -> "ParameterSpec | None":
    """The ``ParameterSpec`` of attribute ``name`` of a component class (None if undeclared)."""
    for spec in getattr(component_class, "params", ()):
        if spec.name == name:
            return spec
    return None
