"""mbcomp: compose multibody mechanisms, compile their equations of motion, simulate them."""

# Composing a model
from .model import Model
from .components import (Ball, Body, Contact, Cylindrical, Damper, Fixed, Force, Free, JointTorque, Motor, Planar,
                         Prismatic, Revolute, Slider, Spherical, Spring, TorsionSpring, Universal)
from .components import DCMotor, Drive, JointFriction, JointLimit
from .components.signals import PID, Angle, Constant, Signal, Sine, Speed, Step
from .components.frame import Frame, rpy
from .compose import Option, Parameter, Submodel

# The compiled system and its results
from .result import Energy, Event, Result
from .system import BodyState, System

# Many simulations at once
from .batch import sweep

# Errors
from .errors import CompileError, ModelError, SimulationError

# Operations that lower layers offer as methods, implemented above them (see services.py)
from . import services as _services
from . import post as _post
from .io import save as _save
from .plotting import animate_result as _animate_result, plot_result as _plot_result
from .system import compile_model as _compile_model

_services.provide("compile", _compile_model)
_services.provide("save", _save)
_services.provide("energy", _post.energy)
_services.provide("reactions", _post.reactions)
_services.provide("constraint_violation", _post.constraint_violation)
_services.provide("plot", _plot_result)
_services.provide("animate", _animate_result)

__version__ = "0.1.0"

__all__ = [
    "Model", "Body", "Revolute", "Prismatic", "Spherical", "Ball", "Free", "Universal", "Cylindrical", "Planar", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "System", "Result", "Energy",
    "BodyState", "Event", "Frame", "rpy", "Submodel", "Parameter", "Option", "ModelError", "CompileError", "SimulationError", "load", "sweep",
    "Drive", "DCMotor", "JointFriction", "JointLimit", "Signal", "Angle", "Speed", "Constant", "Step", "Sine", "PID",
]


def load(path):
    """Read a declarative TOML model file into a ``Model`` (see docs/files.md)."""
    from .io import load as _load
    return _load(path)
