"""mbcomp: compose multibody mechanisms, compile their equations of motion, simulate them."""

# Composing a model
from .model import Model
from .components import (Body, Contact, Damper, Fixed, Force, JointTorque, Motor, Prismatic, Revolute,
                         Slider, Spherical, Spring, TorsionSpring)

# What the 3D viewer draws for a body
from .shapes import Box, Cylinder, Mesh, Sphere

# The compiled system and its results
from .result import Energy, Event, Result
from .system import BodyState, System

# Many simulations at once
from .batch import sweep

# Errors
from .errors import CompileError, ModelError, SimulationError

# Operations of the model layer implemented above it (see services.py)
from . import services as _services
from .io import save as _save
from .system import compile_model as _compile_model

_services.provide("compile", _compile_model)
_services.provide("save", _save)

__version__ = "0.1.0"

__all__ = [
    "Model", "Body", "Revolute", "Prismatic", "Spherical", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "System", "Result", "Energy",
    "BodyState", "Event", "Box", "Cylinder", "Sphere", "Mesh", "ModelError", "CompileError", "SimulationError", "load", "sweep",
]


def load(path):
    """Read a declarative TOML model file into a ``Model`` (see docs/files.md)."""
    from .io import load as _load
    return _load(path)
