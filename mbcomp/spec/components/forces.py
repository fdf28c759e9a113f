"""Force elements: Spring, Damper, Force, JointTorque, TorsionSpring.

Each states its loads through the symbolic kinematics accessor ``kin`` (world-frame
point positions and velocities, joint coordinates, parameter symbols) and, when
conservative, its potential energy.  Sign convention: a load is what the element
applies to the body it names.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError, SimulationError, describe
from mbcomp.core.params import ParameterSpec, nonnegative
from mbcomp.spec.components.base import ForceElement, one_dof_joint_problems
from mbcomp.spec.components.signals import SignalOwner
from mbcomp.spec.components.frame import Frame, split_frame


def _attachment(value: Any, owner: Any, role: str) -> tuple[Any, tuple[float, float, float]]:
    """``(body, point)`` from ``(body, point)``, a ``Frame`` or a bare body (point = origin)."""
    if isinstance(value, Frame):
        return value.body, value.point
    if isinstance(value, (tuple, list)) and len(value) == 2 and not isinstance(value[0], (int, float)):
        return value[0], value[1]
    if isinstance(value, (tuple, list)):
        raise ModelError(owner, f"{role} must be (body, point), got {value!r}")
    return value, (0.0, 0.0, 0.0)


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


_POINT_A = ParameterSpec("point_a", (3,), "m", default=(0.0, 0.0, 0.0), doc="end a in body a's frame")
_POINT_B = ParameterSpec("point_b", (3,), "m", default=(0.0, 0.0, 0.0), doc="end b in body b's frame")


class _TwoPointElement(ForceElement):
    """Shared geometry of elements acting along the line between two body points."""

    section = "forces"
    refs = {"a": "attachment", "b": "attachment"}

    def __init__(self, name: str, a: Any, b: Any):
        super().__init__(name)
        self.body_a, self.point_a = _attachment(a, self, "a")
        self.body_b, self.point_b = _attachment(b, self, "b")

    @property
    def a(self):
        return (self.body_a, self.point_a)

    @property
    def b(self):
        return (self.body_b, self.point_b)

    def references(self):
        return {"a": self.body_a, "b": self.body_b}

    def line_ends(self) -> tuple:
        """Both ends, as ``(body, parameter key of the point)``: the force's line is undefined
        where they meet."""
        return (self.body_a, f"{self.name}.point_a"), (self.body_b, f"{self.name}.point_b")

    def _line(self, kin):
        """World positions, separation ``d = p_b - p_a``, its rate, and the length."""
        pa = kin.position(self.body_a, kin.param(self, "point_a"))
        pb = kin.position(self.body_b, kin.param(self, "point_b"))
        va = kin.velocity(self.body_a, kin.param(self, "point_a"))
        vb = kin.velocity(self.body_b, kin.param(self, "point_b"))
        d = [kin.let(x - y) for x, y in zip(pb, pa)]
        dd = [kin.let(x - y) for x, y in zip(vb, va)]
        import sympy as sp  # only where the equations are built
        length = kin.let(sp.sqrt(_dot(d, d)))
        return pa, pb, d, dd, length

    def _pair(self, pa, pb, force_on_b):
        return [("point", self.body_b, pb, force_on_b),
                ("point", self.body_a, pa, [-f for f in force_on_b])]


class Spring(_TwoPointElement):
    """Linear spring between two body points, with optional parallel damping.

    Tension ``k (l - rest_length) + damping * dl/dt`` (N) pulls the points together.

    Parameters
    ----------
    a, b : (body, point) with point in that body's frame (m)
    stiffness : N/m, >= 0;  rest_length : m, >= 0;  damping : N s/m, >= 0
    """

    kind = "spring"
    params = (_POINT_A, _POINT_B,
              ParameterSpec("stiffness", (), "N/m", nonnegative),
              ParameterSpec("rest_length", (), "m", nonnegative, default=0.0),
              ParameterSpec("damping", (), "N s/m", nonnegative, default=0.0))
    file_keys = ("a", "b", "stiffness", "rest_length", "damping")
    file_required = ("a", "b", "stiffness")

    def __init__(self, name: str, a: Any, b: Any, stiffness: float, rest_length: float = 0.0, damping: float = 0.0):
        super().__init__(name, a, b)
        self.stiffness = stiffness
        self.rest_length = rest_length
        self.damping = damping

    def is_conservative(self) -> bool:
        return self.damping == 0

    def loads(self, kin):
        pa, pb, d, dd, length = self._line(kin)
        k, l0, c = (kin.param(self, n) for n in ("stiffness", "rest_length", "damping"))
        inv = kin.let(1 / length)
        rate = kin.let(_dot(d, dd) * inv)
        tension = kin.let(k * (length - l0) + c * rate)
        return self._pair(pa, pb, [kin.let(-tension * x * inv) for x in d])

    def potential(self, kin):
        _, _, d, _, length = self._line(kin)
        k, l0 = kin.param(self, "stiffness"), kin.param(self, "rest_length")
        return k * (length - l0) ** 2 / 2


class Damper(_TwoPointElement):
    """Linear damper between two body points: tension ``damping * dl/dt`` (N)."""

    kind = "damper"
    params = (_POINT_A, _POINT_B, ParameterSpec("damping", (), "N s/m", nonnegative))
    file_keys = ("a", "b", "damping")
    file_required = ("a", "b", "damping")

    def __init__(self, name: str, a: Any, b: Any, damping: float):
        super().__init__(name, a, b)
        self.damping = damping

    def loads(self, kin):
        pa, pb, d, dd, length = self._line(kin)
        c = kin.param(self, "damping")
        inv2 = kin.let(1 / (length * length))
        tension = kin.let(c * _dot(d, dd) * inv2)
        return self._pair(pa, pb, [kin.let(-tension * x) for x in d])


class Force(ForceElement):
    """A force (N, world frame) at a body point (m, body frame).

    ``force`` is a constant 3-vector (a parameter) or a callable ``(t, q, qd) -> (3,)``
    evaluated at run time (``q``, ``qd`` arrays in ``System.coords`` order).
    """

    kind = "force"
    section = "forces"
    params = (ParameterSpec("point", (3,), "m", default=(0.0, 0.0, 0.0), doc="point of application, body frame"),
              ParameterSpec("force", (3,), "N", default=(0.0, 0.0, 0.0), time_input=True,
                            doc="world-frame force, or a callable (t, q, qd) -> (3,)"))
    refs = {"body": "body"}
    file_keys = ("body", "point", "force")
    file_required = ("body", "force")

    def __init__(self, name: str, body: Any, point: Any = None, force: Any = (0.0, 0.0, 0.0)):
        super().__init__(name)
        self.body, point, _ = split_frame(body, point, self, "body")
        self.point = point
        self.force = force

    @property
    def is_callable(self) -> bool:
        """True when ``force`` is evaluated at run time (an input, not a parameter)."""
        return callable(self.force)

    def references(self):
        return {"body": self.body}

    def structure(self):
        return ("callable" if self.is_callable else "constant",)

    def input_size(self, joint: Any = None) -> int:
        """Number of run-time input values (the callable's vector), 0 when constant."""
        return 3 if self.is_callable else 0

    def evaluate_input(self, t: float, q: np.ndarray, qd: np.ndarray, size: int = 3) -> np.ndarray:
        """The callable's value, checked to be a finite 3-vector."""
        return checked_output(self, self.force(t, q, qd), 3)

    def loads(self, kin):
        point = kin.position(self.body, kin.param(self, "point"))
        force = kin.input(self) if self.is_callable else kin.param(self, "force")
        return [("point", self.body, point, list(force))]


class JointTorque(SignalOwner, ForceElement):
    """Generalised force(s) on a joint's speeds (N m for angles, N for slides; for a ball
    the torque on the child in the child frame).

    ``value``: a number / array of the joint's size (a parameter) or a callable
    ``(t, q, qd)`` returning it.
    """

    kind = "joint_torque"
    section = "forces"
    signal_attrs = ("value",)
    file_options = {"value": "signal"}
    params = (ParameterSpec("value", (-1,), "N m or N (per joint coordinate)", default=0.0, time_input=True,
                            doc="one value per joint coordinate, or a callable (t, q, qd)"),)
    refs = {"joint": "joint"}
    file_keys = ("joint", "value")
    file_required = ("joint", "value")

    def __init__(self, name: str, joint: Any, value: Any = 0.0):
        super().__init__(name)
        self.joint = joint
        from mbcomp.spec.components.signals import Signal
        if isinstance(value, Signal):  # compiled with the drives (drive_equations), not a parameter
            object.__setattr__(self, "value", value)
        else:
            self.value = value

    @property
    def signal(self):
        """The ``Signal`` the value comes from, or None."""
        from mbcomp.spec.components.signals import Signal
        return self.value if isinstance(self.value, Signal) else None

    @property
    def is_callable(self) -> bool:
        """True when ``value`` is evaluated at run time (an input, not a parameter)."""
        return callable(self.value)

    @property
    def size(self) -> int | None:
        """Number of values ``value`` holds (None for a callable of unknown size; 1 for a signal)."""
        if self.signal is not None:
            return 1
        if isinstance(self.value, float):
            return 1
        try:
            return len(self.value)
        except TypeError:
            return None

    def parameter_values(self) -> dict[str, Any]:
        if self.signal is not None:   # the numbers inside the signal only
            return {key: source.source_value(field) for key, (source, field) in self.signal_fields().items()}
        return super().parameter_values()

    def references(self):
        if self.signal is not None:
            from mbcomp.spec.components.signals import signal_references
            return {"joint": self.joint, **signal_references([self.signal])}
        return {"joint": self.joint}

    def structure(self):
        if self.signal is not None:
            return ("signal", self.signal.structure_text())
        return ("callable" if self.is_callable else "constant",)

    # A signal value makes this a drive element (drive_equations): generated with the drives.
    @property
    def drive_element(self) -> bool:
        return self.signal is not None

    def signals(self) -> list:
        return [] if self.signal is None else [self.signal]

    def state_names(self) -> tuple:
        return ()

    def drive_loads(self, ctx):
        return [(self.joint, ctx.signal(self.signal))]

    def state_rates(self, ctx):
        return []

    def input_size(self, joint: Any = None) -> int:
        """Run-time input values: the resolved ``joint``'s speed count for a callable
        (0 for a constant value)."""
        if not self.is_callable:
            return 0
        return joint.nv if joint is not None else 1

    def check(self, resolved: dict) -> list[str]:
        """Problems against the resolved references (``{"joint": Joint}``); sets nothing."""
        joint = resolved["joint"]
        if self.size is not None and self.size != joint.nv:
            noun = "coordinate(s)" if joint.nv == joint.nq else "speed(s)"
            return [f"{describe(self)}: value has {self.size} entries, joint {joint.name!r} has "
                    f"{joint.nv} {noun}"]
        return []

    def evaluate_input(self, t, q, qd, size: int | None = None):
        """The callable's value, checked to be ``size`` finite numbers."""
        if size is None:
            size = self.size or int(np.size(self.value(t, q, qd)))
        return checked_output(self, self.value(t, q, qd), size)

    def loads(self, kin):
        if self.signal is not None:
            return []
        values = kin.input(self) if self.is_callable else kin.param(self, "value")
        values = values if isinstance(values, (list, tuple)) else [values]
        return [("generalized", self.joint, list(values))]


class TorsionSpring(ForceElement):
    """Spring (and damper) on a 1-DOF joint: ``tau = -stiffness (q - rest) - damping qd``.

    Units: N m/rad and N m s/rad for a revolute (N/m, N s/m for a prismatic joint).
    """

    kind = "torsion_spring"
    section = "forces"
    params = (ParameterSpec("stiffness", (), "N m/rad", nonnegative, doc="N/m on a prismatic joint"),
              ParameterSpec("rest", (), "rad", default=0.0, doc="m on a prismatic joint"),
              ParameterSpec("damping", (), "N m s/rad", nonnegative, default=0.0, doc="N s/m on a prismatic joint"))
    refs = {"joint": "joint"}
    file_keys = ("joint", "stiffness", "rest", "damping")
    file_required = ("joint", "stiffness")

    def __init__(self, name: str, joint: Any, stiffness: float, rest: float = 0.0, damping: float = 0.0):
        super().__init__(name)
        self.joint = joint
        self.stiffness = stiffness
        self.rest = rest
        self.damping = damping

    def references(self):
        return {"joint": self.joint}

    def check(self, resolved: dict) -> list[str]:
        """Problems against the resolved references (``{"joint": Joint}``); sets nothing."""
        return one_dof_joint_problems(self, resolved["joint"])

    def is_conservative(self) -> bool:
        return self.damping == 0

    def loads(self, kin):
        (q,), (qd,) = kin.q(self.joint), kin.qd(self.joint)
        k, rest, c = (kin.param(self, n) for n in ("stiffness", "rest", "damping"))
        return [("generalized", self.joint, [-k * (q - rest) - c * qd])]

    def potential(self, kin):
        (q,) = kin.q(self.joint)
        k, rest = kin.param(self, "stiffness"), kin.param(self, "rest")
        return k * (q - rest) ** 2 / 2


def checked_output(owner: Any, value: Any, size: int) -> np.ndarray:
    """A user callable's result as a finite float array of ``size``, else ``SimulationError``
    (called at every evaluation of a callable force or tau: no per-call imports or wrappers)."""
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise SimulationError(f"callable returned {value!r}, not numbers", owner) from None
    if arr.size != size:
        raise SimulationError(f"callable returned {arr.size} values, expected {size}", owner)
    total = sum(arr.tolist())  # (a Python sum of a few floats: a third of np.isfinite(arr).all()'s cost)
    if total - total != 0.0 and not np.isfinite(arr).all():  # (NaN or inf; a finite sum's overflow is checked)
        raise SimulationError(f"callable returned a non-finite value {arr.tolist()}", owner)
    return arr
