"""A ready-made servo drive: DC motor + gear + PID on a 1-DOF joint, as a sub-model part.

``Servo(name, joint=<joint>, setpoint=0.0, ...)`` adds ``NAME.pid`` (a ``PID`` on the
joint's ``Angle``) and ``NAME.motor`` (a ``DCMotor`` whose voltage the PID sets) to the
model.  The motor and gain numbers are sub-model parameters (``"NAME.kp"``, ...), so a
parameter sweep over them does not recompile; ``setpoint`` (a number or a signal) and
``limit`` (the voltage limit, None for none) are options (structure).  The states are
``"NAME.motor.current"`` and ``"NAME.pid.integral"``.
"""
from __future__ import annotations

from typing import Any

from mbcomp.spec.components.drivetrain import DCMotor
from mbcomp.spec.components.signals import PID, Angle
from mbcomp.spec.compose import Option, Parameter, Submodel


class Servo(Submodel):
    """DC motor (armature R, L, torque constant k, rotor inertia) through a gear of ``ratio``,
    its voltage set by a PID on the joint angle (see ``docs/drives.md``)."""

    ratio = Parameter(50.0, unit="1", doc="rotor turns per joint turn")
    resistance = Parameter(1.2, unit="ohm", min=0.0, doc="armature resistance")
    inductance = Parameter(0.01, unit="H", min=0.0, doc="armature inductance (> 0)")
    k = Parameter(0.05, unit="N m/A", doc="torque constant (= back-EMF constant, V s/rad)")
    rotor_inertia = Parameter(2e-5, unit="kg m^2", min=0.0, doc="rotor inertia")
    kp = Parameter(150.0, unit="V/rad", doc="proportional gain")
    ki = Parameter(600.0, unit="V/(rad s)", doc="integral gain")
    kd = Parameter(10.0, unit="V s/rad", doc="derivative gain")
    setpoint = Option(0.0)
    limit = Option(None)

    def build(self, joint: Any) -> None:
        pid = self.add(PID("pid", Angle(joint), self.setpoint, kp=self.kp, ki=self.ki, kd=self.kd, limit=self.limit))
        self.add(DCMotor("motor", joint, ratio=self.ratio, resistance=self.resistance, inductance=self.inductance,
                         k=self.k, voltage=pid, rotor_inertia=self.rotor_inertia))
