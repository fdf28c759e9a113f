"""Rigid bodies, point masses and the ground."""
from __future__ import annotations

from typing import Any

import numpy as np

from mbcomp.core.params import ParameterSpec, positive, spd_inertia
from mbcomp.spec.components.base import Component


class Body(Component):
    """A rigid body (or a point mass) with its own frame.

    Parameters
    ----------
    name : str
    mass : float, kg, > 0
    com : (3,) m, centre of mass in the body frame
    inertia : None, (3,) principal values or (3, 3) matrix, kg m^2, about the COM in
        the body frame. ``None`` or zeros make a point mass: no rotational terms are
        generated for it.  The matrix must be symmetric positive semi-definite and its
        principal moments must satisfy the triangle inequality.  Stored as ``None``, the
        3 principal values, or the 6 entries ``xx yy zz xy xz yz``.
    shape : None, a shape (``mb.Box``, ``mb.Cylinder``, ``mb.Sphere``, ``mb.Mesh``) or a list of
        them, in the body frame: what the 3D viewer draws.  Display data only: neither a
        parameter nor structure (changing it never recompiles).
    """

    kind = "body"
    section = "bodies"
    params = (
        ParameterSpec("mass", (), "kg", positive, doc="mass"),
        ParameterSpec("com", (3,), "m", default=(0.0, 0.0, 0.0), doc="centre of mass in the body frame"),
        ParameterSpec("inertia", (3,), "kg m^2", spd_inertia, default=None, optional=True,
                      doc="inertia about the COM in the body frame (principal values or 3x3; None: point mass)"),
    )
    display = ("shape",)   #: structure-free display data (not parameters, not in structure())

    file_keys = ("mass", "com", "inertia")
    file_required = ("mass",)

    def __init__(self, name: str, mass: float = 1.0, com: Any = (0.0, 0.0, 0.0), inertia: Any = None,
                 shape: Any = None):
        super().__init__(name)
        self.mass = mass
        self.com = com
        self.inertia = inertia
        from mbcomp.spec.shapes import as_shapes
        self.shape = as_shapes(shape, self)

    def frame(self, point: Any = (0.0, 0.0, 0.0), rotation: Any = None) -> "Frame":
        """A ``Frame`` fixed on this body at ``point`` (m, body frame), optionally rotated
        (``rotation``: 3x3 matrix of the frame's axes in the body frame, or ``mb.rpy(...)``)."""
        from mbcomp.spec.components.frame import Frame
        return Frame(self, point, rotation)

    @property
    def is_point_mass(self) -> bool:
        """True when the body has no rotational inertia (no rotational terms are generated)."""
        return self.inertia is None

    @property
    def has_full_inertia(self) -> bool:
        """True when the inertia was given as a matrix with products of inertia."""
        return self.inertia is not None and len(self.inertia) == 6

    def inertia_matrix(self) -> np.ndarray:
        """(3, 3) kg m^2 inertia about the COM in the body frame (zeros for a point mass)."""
        if self.inertia is None:
            return np.zeros((3, 3))
        if len(self.inertia) == 3:
            return np.diag(self.inertia)
        xx, yy, zz, xy, xz, yz = self.inertia
        return np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])

    def structure(self) -> tuple:
        return ("point" if self.inertia is None else "full" if len(self.inertia) == 6 else "diag",)


class Ground(Body):
    """The fixed world body of a model (``Model.ground``); its frame is the world frame."""

    kind = ""
    params = ()

    def __init__(self, name: str = "ground"):
        Component.__init__(self, name)
        self.mass = 0.0
        self.com = (0.0, 0.0, 0.0)
        self.inertia = None
        self.shape = ()

    def parameter_values(self) -> dict[str, Any]:
        return {}

    def structure(self) -> tuple:
        return ("ground",)
