"""Drive trains on 1-DOF joints: geared drives, DC motors, joint friction and joint stops.

Conventions: ``joint`` is a 1-DOF joint of the spanning tree with coordinate ``q`` (rad or
m) and speed ``qd``; a drive's rotor turns at ``ratio * qd`` (``ratio`` = rotor turns per
joint turn, any sign).  A rotor of inertia ``J`` (kg m^2) behind a gear adds the reflected
inertia ``ratio**2 J`` to the joint's mass-matrix diagonal (and ``ratio**2 J qd**2 / 2`` to
the kinetic energy); a rotor torque ``tau`` reaches the joint as ``ratio * tau``.

Drive elements (``drive_element = True``) contribute through the generated ``drives``
function of ``drive_equations``: generalised forces that may depend on time, on signals
and on states of their own (a motor current), and the rates of those states.
"""
from __future__ import annotations

from typing import Any


from mbcomp.core.errors import ModelError
from mbcomp.core.params import ParameterSpec, in_range, nonnegative, positive
from mbcomp.spec.components.base import Component, ForceElement, one_dof_joint_problems
from mbcomp.spec.components.signals import SignalOwner


class _OnJoint(ForceElement):
    """A force element acting on one 1-DOF tree joint."""

    section = "forces"

    def __init__(self, name: str, joint: Any):
        super().__init__(name)
        self.joint = joint

    def references(self):
        return {"joint": self.joint}

    def check(self, resolved: dict) -> list[str]:
        """Problems against the resolved references: only 1-DOF joints."""
        return one_dof_joint_problems(self, resolved["joint"])

    def _loads(self, kin):
        return []

    def _set_input(self, attr: str, value: Any) -> None:
        """A run-time input: a number (validated parameter), a callable or a signal."""
        if _is_signal(value):
            object.__setattr__(self, attr, value)
        else:
            setattr(self, attr, value)

    def parameter_values(self) -> dict[str, Any]:
        return {k: v for k, v in super().parameter_values().items() if not _is_signal(v)}


class Drive(SignalOwner, _OnJoint):
    """A motor rotor on a 1-DOF joint through a gear.

    ``ratio`` (rotor turns per joint turn), ``rotor_inertia`` (kg m^2, reflected as
    ``ratio**2 * rotor_inertia`` on the joint's mass-matrix diagonal) and ``torque`` (N m on
    the rotor: a number, which is a parameter, a signal, or a callable ``(t, q, qd)``);
    the joint receives ``ratio * torque``.
    """

    drive_element = True
    signal_attrs = ("torque",)
    kind = "drive"
    refs = {"joint": "joint"}
    file_keys = ("joint", "ratio", "rotor_inertia", "torque")
    file_required = ("joint",)
    file_options = {"torque": "signal"}
    params = (ParameterSpec("ratio", (), "1", default=1.0, doc="rotor turns per joint turn"),
              ParameterSpec("rotor_inertia", (), "kg m^2", nonnegative, default=0.0, doc="rotor inertia"),
              ParameterSpec("torque", (), "N m", default=0.0, time_input=True,
                            doc="rotor torque: a number, a signal or a callable (t, q, qd)"))

    def __init__(self, name: str, joint: Any, ratio: float = 1.0, rotor_inertia: float = 0.0, torque: Any = 0.0):
        from mbcomp.spec.components.signals import as_signal
        super().__init__(name, joint)
        self.ratio = ratio
        self.rotor_inertia = rotor_inertia
        self._set_input("torque", torque if not callable(torque) or _is_signal(torque)
                        else as_signal(torque, self, "torque", state_callable=True))

    @property
    def torque_is_number(self) -> bool:
        return isinstance(self.torque, float)

    def signals(self) -> list:
        return [] if self.torque_is_number else [self.torque]

    def references(self):
        from mbcomp.spec.components.signals import signal_references
        return {"joint": self.joint, **signal_references(self.signals())}

    def structure(self):
        return ("number",) if self.torque_is_number else (self.torque.structure_text(),)

    def state_names(self) -> tuple[str, ...]:
        return ()

    def armature(self, kin):
        ratio, inertia = kin.param(self, "ratio"), kin.param(self, "rotor_inertia")
        return [(self.joint, ratio * ratio * inertia)]

    def drive_loads(self, ctx):
        torque = ctx.param(self, "torque") if self.torque_is_number else ctx.signal(self.torque)
        return [(self.joint, ctx.param(self, "ratio") * torque)]

    def state_rates(self, ctx):
        return []


class DCMotor(SignalOwner, _OnJoint):
    """A permanent-magnet DC motor driving a 1-DOF joint through a gear of ``ratio``.

    The armature current ``i`` (A) is a state (``"NAME.current"``)::

        L di/dt = V - R i - k * ratio * qd        (V: voltage, R: resistance (ohm),
        joint torque = ratio * k * i               L: inductance (H), k: N m/A = V s/rad)

    ``voltage`` is a number (a parameter), a signal (a ``PID`` for a servo) or a callable
    ``(t, q, qd)``; ``rotor_inertia`` (kg m^2) is reflected as in ``Drive``.  Small
    inductances make the current fast (time constant L/R): the ODE is then stiff for
    explicit integrators, which take steps of about L/R.
    """

    drive_element = True
    signal_attrs = ("voltage",)
    kind = "dc_motor"
    refs = {"joint": "joint"}
    file_keys = ("joint", "ratio", "resistance", "inductance", "k", "voltage", "rotor_inertia")
    file_required = ("joint", "ratio", "resistance", "inductance", "k", "voltage")
    file_options = {"voltage": "signal"}
    params = (ParameterSpec("ratio", (), "1", doc="rotor turns per joint turn"),
              ParameterSpec("resistance", (), "ohm", nonnegative, doc="armature resistance"),
              ParameterSpec("inductance", (), "H", positive, doc="armature inductance"),
              ParameterSpec("k", (), "N m/A", doc="torque constant (= back-EMF constant, V s/rad)"),
              ParameterSpec("voltage", (), "V", time_input=True, doc="a number, a signal or a callable (t, q, qd)"),
              ParameterSpec("rotor_inertia", (), "kg m^2", nonnegative, default=0.0, doc="rotor inertia"))

    def __init__(self, name: str, joint: Any, *, ratio: float, resistance: float, inductance: float, k: float,
                 voltage: Any, rotor_inertia: float = 0.0):
        from mbcomp.spec.components.signals import as_signal
        super().__init__(name, joint)
        self.ratio = ratio
        self.resistance = resistance
        self.inductance = inductance
        self.k = k
        self.rotor_inertia = rotor_inertia
        self._set_input("voltage", voltage if not callable(voltage) or _is_signal(voltage)
                        else as_signal(voltage, self, "voltage", state_callable=True))

    @property
    def voltage_is_number(self) -> bool:
        return isinstance(self.voltage, float)

    def signals(self) -> list:
        return [] if self.voltage_is_number else [self.voltage]

    def references(self):
        from mbcomp.spec.components.signals import signal_references
        return {"joint": self.joint, **signal_references(self.signals())}

    def structure(self):
        return ("number",) if self.voltage_is_number else (self.voltage.structure_text(),)

    def state_names(self) -> tuple[str, ...]:
        return ("current",)

    def armature(self, kin):
        ratio, inertia = kin.param(self, "ratio"), kin.param(self, "rotor_inertia")
        return [(self.joint, ratio * ratio * inertia)]

    def drive_loads(self, ctx):
        (current,) = ctx.states(self)
        return [(self.joint, ctx.param(self, "ratio") * ctx.param(self, "k") * current)]

    def state_rates(self, ctx):
        (current,) = ctx.states(self)
        (qd,) = ctx.kin.qd(self.joint)
        voltage = ctx.param(self, "voltage") if self.voltage_is_number else ctx.signal(self.voltage)
        back_emf = ctx.param(self, "k") * ctx.param(self, "ratio") * qd
        return [(voltage - ctx.param(self, "resistance") * current - back_emf) / ctx.param(self, "inductance")]


class JointFriction(_OnJoint):
    """Coulomb and viscous friction on a 1-DOF joint::

        tau = -viscous * qd - coulomb * tanh(qd / speed_scale)

    (N m or N; ``viscous`` N m s/rad or N s/m).  Coulomb friction is regularised: below
    ``speed_scale`` (rad/s or m/s, default 1e-3) the friction grows smoothly from 0 through
    zero speed instead of jumping.  A joint held by friction against a load ``F <
    coulomb`` therefore does not stick exactly: it creeps at the speed where the
    regularised friction balances the load, ``speed_scale * atanh(F / coulomb)`` (e.g.
    0.55 speed_scale at half the friction limit).  A smaller ``speed_scale`` creeps less and
    makes the equations stiffer (explicit integrators then need steps of about
    ``speed_scale * inertia / coulomb``).  All three numbers are parameters.
    """

    kind = "joint_friction"
    refs = {"joint": "joint"}
    file_keys = ("joint", "coulomb", "viscous", "speed_scale")
    file_required = ("joint",)
    params = (ParameterSpec("coulomb", (), "N m or N", nonnegative, default=0.0, doc="Coulomb friction level"),
              ParameterSpec("viscous", (), "N m s/rad or N s/m", nonnegative, default=0.0, doc="viscous coefficient"),
              ParameterSpec("speed_scale", (), "rad/s or m/s", positive, default=1e-3,
                            doc="regularisation speed of the Coulomb friction"))

    def __init__(self, name: str, joint: Any, coulomb: float = 0.0, viscous: float = 0.0,
                 speed_scale: float = 1e-3):
        super().__init__(name, joint)
        self.coulomb = coulomb
        self.viscous = viscous
        self.speed_scale = speed_scale

    def _loads(self, kin):
        (qd,) = kin.qd(self.joint)
        c, v, s = (kin.param(self, n) for n in ("coulomb", "viscous", "speed_scale"))
        import sympy as sp  # only where the equations are built
        return [("generalized", self.joint, [-v * qd - c * sp.tanh(kin.let(qd / s))])]


class JointLimit(Component):
    """A stop on a 1-DOF joint's coordinate: ``lower <= q <= upper`` (either may be None).

    Each bound is a unilateral contact with the coordinate gap ``q - lower`` (or ``upper -
    q``), handled by the contact machinery: closing is located as an event, Newton's impact
    law applies with ``restitution`` in [0, 1], a stop reached slowly holds the joint at
    rest until its reaction would pull.  Its sides appear as contacts ``"NAME.lower"`` and
    ``"NAME.upper"`` (events, reactions in N m or N).  ``lower``, ``upper`` and
    ``restitution`` are parameters; which bounds exist is structure.
    """

    kind = "joint_limit"
    section = "constraints"
    refs = {"joint": "joint"}
    file_keys = ("joint", "lower", "upper", "restitution")
    file_required = ("joint",)
    params = (ParameterSpec("lower", (), "q", optional=True, default=None, doc="lower bound of the coordinate"),
              ParameterSpec("upper", (), "q", optional=True, default=None, doc="upper bound of the coordinate"),
              ParameterSpec("restitution", (), "1", in_range(0.0, 1.0), default=0.0, doc="Newton's coefficient"))

    def __init__(self, name: str, joint: Any, lower: float | None = None, upper: float | None = None,
                 restitution: float = 0.0):
        super().__init__(name)
        self.joint = joint
        if lower is None and upper is None:
            raise ModelError(self, "needs a lower or an upper bound (or both)")
        self.lower = lower
        self.upper = upper
        if self.lower is not None and self.upper is not None and self.lower >= self.upper:
            raise ModelError(self, f"lower {self.lower} must be below upper {self.upper}")
        self.restitution = restitution

    def references(self):
        return {"joint": self.joint}

    def structure(self):
        return (self.lower is not None, self.upper is not None)

    def sides(self) -> tuple["LimitSide", ...]:
        """One contact-like gap per bound."""
        return tuple(LimitSide(self, side) for side in ("lower", "upper") if getattr(self, side) is not None)


class LimitSide:
    """One bound of a ``JointLimit`` as the contact machinery sees it (name, gap, restitution)."""

    def __init__(self, limit: JointLimit, side: str):
        self.limit, self.side = limit, side
        self.name = f"{limit.name}.{side}"
        self.restitution_key = f"{limit.name}.restitution"
        self.joint = limit.joint

    def _gap_equation(self, ground):
        from mbcomp.spec.components.primitives import CoordinateGap
        return CoordinateGap(self.joint, f"{self.limit.name}.{self.side}", 1 if self.side == "lower" else -1, "gap")

    def __repr__(self) -> str:
        return f"LimitSide({self.name!r})"


def _is_signal(value: Any) -> bool:
    from mbcomp.spec.components.signals import Signal
    return isinstance(value, Signal)
