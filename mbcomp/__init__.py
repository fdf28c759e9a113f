"""mbcomp: compose multibody mechanisms, compile their equations of motion, simulate them."""

# Composing a model
from mbcomp.spec.model import Model
from mbcomp.spec.components import (Ball, Body, Contact, Cylindrical, Damper, Fixed, Force, Free, JointTorque, Motor, Planar,
                         Prismatic, Revolute, Slider, Spherical, Spring, TorsionSpring, Universal)
from mbcomp.spec.components import DCMotor, Drive, JointFriction, JointLimit
from mbcomp.spec.components import NoSlip, RollingBall, RollingDisc
from mbcomp.spec.components.signals import PID, Angle, Constant, Signal, Sine, Speed, Step
from mbcomp.spec.components.frame import Frame, rpy
from mbcomp.spec.servo import Servo
from mbcomp.spec.compose import Option, Parameter, Submodel

# What the 3D viewer draws for a body
from mbcomp.spec.shapes import Box, Cylinder, Mesh, Sphere

# The compiled system and its results
from mbcomp.core.result import Energy, Event, Result
from mbcomp.api.system import BodyState, System

# Errors
from mbcomp.core.errors import CompileError, ModelError, SimulationError, WriteError

# Operations that lower layers offer as methods, implemented above them (see services.py)
# Operations of rarely needed layers (files, plots, the viewer) import them on first use,
# so that ``import mbcomp`` stays quick (no sympy, scipy.integrate, matplotlib: see
# tests/test_imports.py).
from mbcomp.core import services as _services
from mbcomp.run import post as _post
from mbcomp.api.system import compile_model as _compile_model


def _on_first_use(module: str, name: str):
    """``module.name``, imported when first called."""
    def call(*args, **kwargs):
        from importlib import import_module
        return getattr(import_module(module), name)(*args, **kwargs)
    call.__name__ = call.__qualname__ = name
    return call


_services.provide("compile", _compile_model)
_services.provide("flatten_instances", _on_first_use("mbcomp.build.flatten", "flatten_instances"))
_services.provide("orient_joints", _on_first_use("mbcomp.build.flatten", "orient_joints"))
_services.provide("save", _on_first_use("mbcomp.files.toml_model", "save"))
_services.provide("energy", _post.energy)
_services.provide("reactions", _post.reactions)
_services.provide("contact_forces", _post.contact_forces)
_services.provide("constraint_violation", _post.constraint_violation)
_services.provide("plot", _on_first_use("mbcomp.face.plotting", "plot_result"))
_services.provide("animate", _on_first_use("mbcomp.face.plotting", "animate_result"))
_services.provide("view", _on_first_use("mbcomp.face.viewer", "view"))
_services.provide("export_fmu", _on_first_use("mbcomp.face.fmu", "export_fmu"))

#: Public names defined in modules imported on first use (PEP 562).
_LAZY = {"sweep": "mbcomp.run.batch"}
#: Modules that users reached as ``mbcomp.NAME`` before the package was laid out in layer
#: folders (docs/architecture.md): ``mb.io.save`` still works.
_MOVED = {"io": "mbcomp.files.toml_model", "batch": "mbcomp.run.batch", "plotting": "mbcomp.face.plotting",
          "viewer": "mbcomp.face.viewer", "urdf": "mbcomp.files.urdf", "library": "mbcomp.files.library",
          "cli": "mbcomp.face.cli", "system": "mbcomp.api.system", "result": "mbcomp.core.result",
          "errors": "mbcomp.core.errors", "components": "mbcomp.spec.components", "model": "mbcomp.spec.model",
          "compose": "mbcomp.spec.compose", "shapes": "mbcomp.spec.shapes", "rotations": "mbcomp.core.rotations"}


def __getattr__(name: str):
    """Names and submodules imported on first use: ``mbcomp.sweep``, ``mbcomp.files`` ..."""
    from importlib import import_module, util
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
    elif name in _MOVED:
        value = import_module(_MOVED[name])
    elif not name.startswith("_") and util.find_spec(f"{__name__}.{name}") is not None:
        value = import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value

__version__ = "0.1.0"

__all__ = [
    "Model", "Body", "Revolute", "Prismatic", "Spherical", "Ball", "Free", "Universal", "Cylindrical", "Planar", "Fixed", "Spring", "Damper", "Force",
    "JointTorque", "TorsionSpring", "Slider", "Motor", "Contact", "RollingDisc", "RollingBall", "NoSlip", "System", "Result", "Energy",
    "BodyState", "Event", "Frame", "rpy", "Submodel", "Parameter", "Option", "Box", "Cylinder", "Sphere", "Mesh",
    "ModelError", "CompileError", "SimulationError", "WriteError", "load", "load_urdf", "sweep",
    "Drive", "DCMotor", "JointFriction", "JointLimit", "Signal", "Angle", "Speed", "Constant", "Step", "Sine", "PID",
    "Servo",
]


def load(path):
    """Read a model: a declarative TOML model file (docs/files.md), a library model's name
    (``mbcomp library``), or a URDF robot description (``.urdf``, see ``load_urdf``)."""
    import os
    from mbcomp.files.library import resolve_model_path
    if not isinstance(path, (str, os.PathLike)):
        raise ModelError("load", f"path must be a file path or a library model's name, got {type(path).__name__} "
                                 f"{path!r:.60}")
    resolved = resolve_model_path(path)
    if resolved.suffix.lower() == ".urdf":
        return load_urdf(resolved)
    from mbcomp.files.toml_model import load as _load
    return _load(path)


def load_urdf(path, floating: bool = False, **options):
    """Read a URDF robot description into a ``Model`` (links, inertials, joints with their
    rotated frames, axes and limits, visuals as shapes; ``floating=True`` adds a ``Free``
    joint at the root).  Needs the optional ``yourdfpy`` (``pip install "mbcomp[urdf]"``)."""
    from mbcomp.files.urdf import load_urdf as _load_urdf
    return _load_urdf(path, floating=floating, **options)
