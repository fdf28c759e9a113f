"""What users assemble: bodies, joints, force elements, constraints and contacts."""
from mbcomp.spec.components.base import Component, Constraint, ForceElement
from mbcomp.spec.components.body import Body, Ground
from mbcomp.spec.components.constraints import Motor, Slider
from mbcomp.spec.components.contacts import Contact
from mbcomp.spec.components.rolling import NoSlip, RollingBall, RollingDisc
from mbcomp.spec.components.drivetrain import DCMotor, Drive, JointFriction, JointLimit
from mbcomp.spec.components.forces import Damper, Force, JointTorque, Spring, TorsionSpring
from mbcomp.spec.components.joints import Ball, Cylindrical, Fixed, Free, Joint, Planar, Prismatic, Revolute, Spherical, Universal

__all__ = [
    "Component", "Constraint", "ForceElement", "Body", "Ground", "Joint", "Revolute", "Prismatic",
    "Spherical", "Ball", "Free", "Universal", "Cylindrical", "Planar", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "Drive", "DCMotor", "JointFriction", "JointLimit",
    "RollingDisc", "RollingBall", "NoSlip",
]
