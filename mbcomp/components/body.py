"""Rigid bodies, point masses and the ground."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import ModelError
from .base import Component
from ._values import scalar, vector3


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
        principal moments must satisfy the triangle inequality.
    shape : None, a shape (``mb.Box``, ``mb.Cylinder``, ``mb.Sphere``, ``mb.Mesh``) or a list of
        them, in the body frame: what the 3D viewer draws.  Display data only: neither a
        parameter nor structure (changing it never recompiles).
    """

    parameters = ("mass", "com", "inertia")
    display = ("shape",)   #: structure-free display data (not parameters, not in structure())

    def __init__(self, name: str, mass: float = 1.0, com: Any = (0.0, 0.0, 0.0), inertia: Any = None,
                 shape: Any = None):
        super().__init__(name)
        self.mass = scalar(mass, self, "mass", positive=True)
        self.com = vector3(com, self, "com")
        self.inertia = self._check_inertia(inertia)
        from ..shapes import as_shapes
        self.shape = as_shapes(shape, self)

    def frame(self, point: Any = (0.0, 0.0, 0.0), rotation: Any = None) -> "Frame":
        """A ``Frame`` fixed on this body at ``point`` (m, body frame), optionally rotated
        (``rotation``: 3x3 matrix of the frame's axes in the body frame, or ``mb.rpy(...)``)."""
        from .frame import Frame
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

    def parameter_values(self) -> dict[str, Any]:
        values = {"mass": self.mass, "com": self.com}
        if self.inertia is not None:
            values["inertia"] = self.inertia
        return values

    def structure(self) -> tuple:
        return ("point" if self.inertia is None else "full" if len(self.inertia) == 6 else "diag",)

    def _check_inertia(self, inertia: Any):
        """None (point mass), 3 principal values, or the 6 entries xx yy zz xy xz yz."""
        if inertia is None:
            return None
        try:
            arr = np.asarray(inertia, dtype=float)
        except (TypeError, ValueError):
            raise ModelError(self, f"inertia must be 3 principal values or a 3x3 matrix, got {inertia!r}") from None
        if arr.shape == (3,):
            matrix = np.diag(arr)
        elif arr.shape == (3, 3):
            matrix = arr
        else:
            raise ModelError(self, f"inertia must be 3 principal values or a 3x3 matrix, got shape {arr.shape}")
        if not np.all(np.isfinite(matrix)):
            raise ModelError(self, "inertia has a non-finite entry")
        scale = max(float(np.max(np.abs(matrix))), 1e-300)
        if not np.allclose(matrix, matrix.T, rtol=0, atol=1e-12 * scale):
            raise ModelError(self, "inertia matrix is not symmetric")
        if np.all(matrix == 0):
            return None
        moments = np.linalg.eigvalsh(0.5 * (matrix + matrix.T))
        tol = 1e-9 * scale
        if moments[0] < -tol:
            raise ModelError(self, f"inertia is not positive semi-definite (principal moments {moments.round(12).tolist()})")
        a, b, c = moments
        if c > a + b + tol:
            raise ModelError(self, f"inertia violates the triangle inequality: principal moment {c:g} > {a:g} + {b:g}")
        if arr.shape == (3,):
            return tuple(float(v) for v in arr)
        if np.count_nonzero(matrix - np.diag(np.diag(matrix))) == 0:
            return tuple(float(v) for v in np.diag(matrix))
        return tuple(float(matrix[i, j]) for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))


class Ground(Body):
    """The fixed world body of a model (``Model.ground``); its frame is the world frame."""

    parameters = ()

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
