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

# Errors
from .errors import CompileError, ModelError, SimulationError, WriteError

# Operations that lower layers offer as methods, implemented above them (see services.py)
# Operations of rarely needed layers (files, plots, the viewer) import them on first use,
# so that ``import mbcomp`` stays quick (no sympy, scipy.integrate, matplotlib: see
# tests/test_imports.py).
from . import services as _services
from . import post as _post
from .system import compile_model as _compile_model


def _on_first_use(module: str, name: str):
    """``module.name``, imported when first called."""
    def call(*args, **kwargs):
        from importlib import import_module
        return getattr(import_module(module, __name__), name)(*args, **kwargs)
    call.__name__ = call.__qualname__ = name
    return call


_services.provide("compile", _compile_model)
_services.provide("save", _on_first_use(".io", "save"))
_services.provide("energy", _post.energy)
_services.provide("reactions", _post.reactions)
_services.provide("constraint_violation", _post.constraint_violation)
_services.provide("plot", _on_first_use(".plotting", "plot_result"))
_services.provide("animate", _on_first_use(".plotting", "animate_result"))
_services.provide("view", _on_first_use(".viewer", "view"))

#: Public names defined in modules imported on first use (PEP 562).
_LAZY = {"sweep": ".batch"}


def __getattr__(name: str):
    """Names and submodules imported on first use: ``mbcomp.sweep``, ``mbcomp.io`` ..."""
    from importlib import import_module, util
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name], __name__), name)
    elif not name.startswith("_") and util.find_spec(f"{__name__}.{name}") is not None:
        value = import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value

__version__ = "0.1.0"

__all__ = [
    "Model", "Body", "Revolute", "Prismatic", "Spherical", "Ball", "Free", "Universal", "Cylindrical", "Planar", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "System", "Result", "Energy",
    "BodyState", "Event", "Frame", "rpy", "Submodel", "Parameter", "Option", "Box", "Cylinder", "Sphere", "Mesh",
    "ModelError", "CompileError", "SimulationError", "WriteError", "load", "load_urdf", "sweep",
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
