"""mbcomp: compose multibody mechanisms, compile their equations of motion, simulate them."""

# Composing a model
from .model import Model
from .components import (Ball, Body, Contact, Cylindrical, Damper, Fixed, Force, Free, JointTorque, Motor, Planar,
                         Prismatic, Revolute, Slider, Spherical, Spring, TorsionSpring, Universal)
from .components import DCMotor, Drive, JointFriction, JointLimit
from .components.signals import PID, Angle, Constant, Signal, Sine, Speed, Step
from .components.frame import Frame, rpy
from .servo import Servo
from .compose import Option, Parameter, Submodel

# What the 3D viewer draws for a body
from .shapes import Box, Cylinder, Mesh, Sphere

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
from .viewer import view as _view
_services.provide("view", _view)

__version__ = "0.1.0"

__all__ = [
    "Model", "Body", "Revolute", "Prismatic", "Spherical", "Ball", "Free", "Universal", "Cylindrical", "Planar", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "System", "Result", "Energy",
    "BodyState", "Event", "Frame", "rpy", "Submodel", "Parameter", "Option", "Box", "Cylinder", "Sphere", "Mesh",
    "ModelError", "CompileError", "SimulationError", "load", "load_urdf", "sweep",
    "Drive", "DCMotor", "JointFriction", "JointLimit", "Signal", "Angle", "Speed", "Constant", "Step", "Sine", "PID",
    "Servo",
]


def load(path):
    """Read a model: a declarative TOML model file (docs/files.md), a library model's name
    (``mbcomp library``), or a URDF robot description (``.urdf``, see ``load_urdf``)."""
    import os
    from .library import resolve_model_path
    if not isinstance(path, (str, os.PathLike)):
        raise ModelError("load", f"path must be a file path or a library model's name, got {type(path).__name__} "
                                 f"{path!r:.60}")
    resolved = resolve_model_path(path)
    if resolved.suffix.lower() == ".urdf":
        return load_urdf(resolved)
    from .io import load as _load
    return _load(path)


def load_urdf(path, floating: bool = False, **options):
    """Read a URDF robot description into a ``Model`` (links, inertials, joints with their
    rotated frames, axes and limits, visuals as shapes; ``floating=True`` adds a ``Free``
    joint at the root).  Needs the optional ``yourdfpy`` (``pip install "mbcomp[urdf]"``)."""
    from .urdf import load_urdf as _load_urdf
    return _load_urdf(path, floating=floating, **options)
