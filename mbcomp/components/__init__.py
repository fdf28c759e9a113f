"""What users assemble: bodies, joints, force elements, constraints and contacts."""
from .base import Component, Constraint, ForceElement
from .body import Body, Ground
from .constraints import Motor, Slider
from .contacts import Contact
from .drivetrain import DCMotor, Drive, JointFriction, JointLimit
from .forces import Damper, Force, JointTorque, Spring, TorsionSpring
from .joints import Ball, Cylindrical, Fixed, Free, Joint, Planar, Prismatic, Revolute, Spherical, Universal

__all__ = [
    "Component", "Constraint", "ForceElement", "Body", "Ground", "Joint", "Revolute", "Prismatic",
    "Spherical", "Ball", "Free", "Universal", "Cylindrical", "Planar", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "Drive", "DCMotor", "JointFriction", "JointLimit",
]
