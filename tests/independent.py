"""An independent derivation of the equations of motion of tree-structured models.

This module is a test oracle: it shares no code with ``mbcomp``'s internals.  It reads
a plain-dict description of a tree (bodies, joints, gravity, optional point-to-point
springs), derives the kinematics symbolically with sympy and projects the Newton-Euler
equations of every body onto the joint coordinates (the principle of virtual power,
a.k.a. Kane's method):

    M(q)     = sum_b  m_b Jv_b^T Jv_b + Jw_b^T I_b Jw_b
    F(q, qd) = sum_b  Jv_b^T m_b (g - dJv_b/dt qd) - Jw_b^T (I_b dJw_b/dt qd + w_b x I_b w_b)
               - dV_springs/dq

with ``Jv_b`` the Jacobian of body b's centre of mass and ``Jw_b`` the Jacobian of its
angular velocity in its own frame, both propagated joint by joint (no differentiation of
large expressions).  ``derive(..., method="lagrange")`` obtains the same quantities from
Lagrange's equations with M built from differentiated positions and rotation matrices,
so the oracle can check itself.  The oracle evaluates (``straight_line``) and differentiates
(``_derivative``) its sympy expressions with small routines of its own, each distinct
subexpression once, and multiplies matrices skipping structural zeros (``_mm``).

Description format (all vectors are 3-sequences; ``inertia`` is a 3x3 matrix about the
centre of mass in the body frame, or ``None`` for a point mass)::

    {"name": "tree", "gravity": (gx, gy, gz),
     "bodies": {"b1": {"mass": 1.0, "com": (..), "inertia": [[..], [..], [..]] | None}, ...},
     "joints": [{"name": "j1", "type": "Revolute" | "Prismatic" | "Spherical" | "Fixed",
                 "parent": "ground" | body, "child": body,
                 "axis": "x" | "y" | "z" | (ax, ay, az),        # Revolute, Prismatic
                 "sequence": "xy" | "xyz" | "zxz" | ...,        # Spherical
                 "parent_point": (..), "child_point": (..), "coords": ["q1", ...]}, ...],
     "springs": [{"name": "s", "a": (body, point), "b": (body, point),
                  "stiffness": k, "rest_length": l0}]}          # optional

Conventions: at zero coordinates a child frame is parallel to its parent frame; the
child origin is ``o_p + R_p (parent_point + axis q) - R_c child_point``; a Revolute
rotates right-handedly by q about its axis; a Spherical joint is the intrinsic Euler
product ``R_a1(q1) R_a2(q2) R_a3(q3)``.  Joints must be listed parents-first; the
coordinate vector is the concatenation of the joints' coordinates in that order.
"""
from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
import sympy as sp

GROUND = "ground"
UNIT = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}
SEQUENCES = ("xy", "yz", "zx", "xyz", "zyx", "yxz", "zxz", "xyx", "yzy")


# ----------------------------------------------------------------------------------
# Symbolic building blocks
# ----------------------------------------------------------------------------------
class _Parameters:
    """Turns the description's numbers into sympy symbols (exact zeros stay zeros).

    Keeping numbers symbolic avoids printing rounded floats into the generated code;
    the values are substituted at evaluation time.
    """

    def __init__(self) -> None:
        self.symbols: list[sp.Symbol] = []
        self.values: list[float] = []

    def scalar(self, value: float) -> sp.Expr:
        """A symbol standing for ``value`` (or exact 0)."""
        value = float(value)
        if value == 0.0:
            return sp.Integer(0)
        sym = sp.Symbol(f"p{len(self.symbols)}", real=True)
        self.symbols.append(sym)
        self.values.append(value)
        return sym

    def vector(self, values: Any) -> sp.Matrix:
        """A 3x1 column of parameter symbols."""
        values = [float(v) for v in np.asarray(values, dtype=float).reshape(3)]
        return sp.Matrix([self.scalar(v) for v in values])

    def axis(self, spec: Any) -> sp.Matrix:
        """A unit axis: exact for ``"x" | "y" | "z"``, otherwise the normalised vector."""
        if isinstance(spec, str):
            return sp.Matrix(UNIT[spec])
        vec = np.asarray(spec, dtype=float).reshape(3)
        return self.vector(vec / np.linalg.norm(vec))

    def inertia(self, matrix: Any) -> sp.Matrix:
        """A symmetric 3x3 matrix of symbols (zero for ``None``)."""
        if matrix is None:
            return sp.zeros(3, 3)
        arr = np.asarray(matrix, dtype=float)
        if arr.shape == (3,):
            arr = np.diag(arr)
        out = sp.zeros(3, 3)
        for i in range(3):
            for j in range(i, 3):
                out[i, j] = out[j, i] = self.scalar(0.5 * (arr[i, j] + arr[j, i]))
        return out


def _mm(*factors: sp.Matrix) -> sp.Matrix:
    """The matrix product of ``factors``, left to right, skipping structural zeros: sympy's
    own product multiplies every stored zero too (to keep ``0 * oo = nan``), and each such
    product asks a large expression whether it is finite, which took 40 % of a derivation."""
    out = factors[0]
    for right in factors[1:]:
        if out.cols != right.rows:
            raise ValueError(f"cannot multiply {out.shape} by {right.shape}")
        left_rows = [[(k, a) for k, a in enumerate(out.row(i)) if a != 0] for i in range(out.rows)]
        right_cols = [right.col(j) for j in range(right.cols)]
        out = sp.Matrix(out.rows, right.cols, lambda i, j: sp.Add(*[a * right_cols[j][k]
                                                                    for k, a in left_rows[i]
                                                                    if right_cols[j][k] != 0]))
    return out


def _derivative(expr: sp.Expr, x: sp.Symbol, memo: dict) -> sp.Expr:
    """``d expr / d x``, each distinct subexpression differentiated once (``memo``: per
    ``x``).  sympy's ``diff`` asks every subtree for its free symbols again at every level,
    which made a 4-body Lagrange self-check take 6 s.  Knows +, *, numeric powers, sin, cos."""
    known = memo.get(expr)
    if known is not None:
        return known
    if expr == x:
        out = sp.S.One
    elif expr.is_Atom:
        out = sp.S.Zero
    elif expr.is_Add:
        out = sp.Add(*[d for d in (_derivative(a, x, memo) for a in expr.args) if d != 0])
    elif expr.is_Mul:
        args = expr.args
        terms = []
        for i, a in enumerate(args):
            d = _derivative(a, x, memo)
            if d != 0:
                terms.append(sp.Mul(*args[:i], d, *args[i + 1:]))
        out = sp.Add(*terms)
    elif expr.is_Pow and expr.exp.is_Number:
        d = _derivative(expr.base, x, memo)
        out = sp.S.Zero if d == 0 else expr.exp * expr.base ** (expr.exp - 1) * d
    elif isinstance(expr, (sp.sin, sp.cos)):
        d = _derivative(expr.args[0], x, memo)
        slope = sp.cos(expr.args[0]) if isinstance(expr, sp.sin) else -sp.sin(expr.args[0])
        out = sp.S.Zero if d == 0 else slope * d
    else:
        raise TypeError(f"_derivative cannot differentiate {expr.func.__name__}")
    memo[expr] = out
    return out


def _jacobian(exprs: sp.Matrix, variables: list) -> sp.Matrix:
    """``d exprs / d variables`` (a column of m expressions -> m x n), by ``_derivative``."""
    column = list(exprs)
    out = sp.zeros(len(column), len(variables))
    for k, x in enumerate(variables):
        memo: dict = {}
        for i, e in enumerate(column):
            out[i, k] = _derivative(e, x, memo)
    return out


def _skew(v: sp.Matrix) -> sp.Matrix:
    """Cross-product matrix: ``_skew(v) * u == v x u``."""
    return sp.Matrix([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def rotation_about(axis: sp.Matrix, angle: sp.Expr) -> sp.Matrix:
    """Right-handed rotation by ``angle`` about the unit ``axis`` (Rodrigues' formula)."""
    c, s = sp.cos(angle), sp.sin(angle)
    return c * sp.eye(3) + s * _skew(axis) + (1 - c) * _mm(axis, axis.T)


def _cross_matrix_columns(a: sp.Matrix, J: sp.Matrix) -> sp.Matrix:
    """``a x`` applied to every column of ``J``."""
    return _mm(_skew(a), J)


@dataclass
class _JointMotion:
    """Joint-local kinematics in the parent frame, for the joint's own coordinates.

    ``rotation``/``translation``: child orientation and displacement of the joint point;
    relative angular velocity ``J_rot qd_j``, translation rate ``J_trans qd_j``; their
    time derivatives are ``J qdd_j + bias``.
    """

    rotation: sp.Matrix
    translation: sp.Matrix
    J_rot: sp.Matrix
    J_trans: sp.Matrix
    bias_rot: sp.Matrix
    bias_trans: sp.Matrix


def _joint_motion(joint: dict, params: _Parameters, q: list, qd: list) -> _JointMotion:
    """Relative kinematics of one joint (its coordinates ``q``, rates ``qd``)."""
    kind, nj = joint["type"], len(q)
    rotation, translation = sp.eye(3), sp.zeros(3, 1)
    J_rot, J_trans = sp.zeros(3, nj), sp.zeros(3, nj)
    if kind == "Revolute":
        axis = params.axis(joint["axis"])
        rotation, J_rot = rotation_about(axis, q[0]), axis
    elif kind == "Prismatic":
        axis = params.axis(joint["axis"])
        translation, J_trans = axis * q[0], axis
    elif kind == "Spherical":
        for i, (letter, angle) in enumerate(zip(joint["sequence"], q)):
            axis = sp.Matrix(UNIT[letter])
            J_rot[:, i] = _mm(rotation, axis)         # the i-th rotation axis, in the parent frame
            rotation = _mm(rotation, rotation_about(axis, angle))
    elif kind != "Fixed":
        raise ValueError(f"joint {joint.get('name')!r}: unknown type {kind!r}")
    rates = sp.Matrix(qd)
    bias_rot = _mm(_jacobian(_mm(J_rot, rates), q), rates) if nj else sp.zeros(3, 1)
    bias_trans = _mm(_jacobian(_mm(J_trans, rates), q), rates) if nj else sp.zeros(3, 1)
    return _JointMotion(rotation, translation, J_rot, J_trans, bias_rot, bias_trans)


@dataclass
class _Frame:
    """World-frame kinematics of a body frame.

    ``R``: body-to-world rotation; ``origin``: world position of the frame origin.
    Velocities are ``J qd`` (``J_v`` origin, ``J_w`` angular), accelerations
    ``J qdd + bias`` (``bias_a`` origin, ``bias_alpha`` angular).
    """

    R: sp.Matrix
    origin: sp.Matrix
    J_v: sp.Matrix
    J_w: sp.Matrix
    bias_a: sp.Matrix
    bias_alpha: sp.Matrix

    def point(self, local: sp.Matrix, rates: sp.Matrix):
        """Position, velocity Jacobian and acceleration bias of a body-fixed point."""
        arm = _mm(self.R, local)
        omega = _mm(self.J_w, rates)
        J = self.J_v - _cross_matrix_columns(arm, self.J_w)
        bias = self.bias_a + self.bias_alpha.cross(arm) + omega.cross(omega.cross(arm))
        return self.origin + arm, J, bias


def _embed(block: sp.Matrix, start: int, n: int) -> sp.Matrix:
    """A 3 x n matrix holding ``block`` in columns ``start:start+k``, zeros elsewhere."""
    out = sp.zeros(3, n)
    if block.shape[1]:
        out[:, start:start + block.shape[1]] = block
    return out


def _child_frame(parent: _Frame, motion: _JointMotion, pp: sp.Matrix, cp: sp.Matrix,
                 start: int, rates: sp.Matrix) -> _Frame:
    """Propagate velocities and accelerations across one joint (rigid-body kinematics).

    o_c = o_p + d - e with d = R_p (pp + t), e = R_c cp; differentiating
    v_c = v_p + w_p x d + R_p t' - w_c x e and w_c = w_p + R_p w_rel gives the terms below.
    """
    n = rates.shape[0]
    Rp = parent.R
    omega_p = _mm(parent.J_w, rates)
    J_rel = _embed(_mm(Rp, motion.J_rot), start, n)
    J_w = parent.J_w + J_rel
    omega_c = _mm(J_w, rates)
    bias_alpha = parent.bias_alpha + _mm(Rp, motion.bias_rot) + omega_p.cross(_mm(J_rel, rates))

    R = _mm(Rp, motion.rotation)
    d = _mm(Rp, pp + motion.translation)
    e = _mm(R, cp)
    J_t = _embed(_mm(Rp, motion.J_trans), start, n)
    t_rate = _mm(J_t, rates)
    J_v = parent.J_v - _cross_matrix_columns(d, parent.J_w) + J_t + _cross_matrix_columns(e, J_w)
    bias_a = (parent.bias_a + parent.bias_alpha.cross(d) + omega_p.cross(omega_p.cross(d))
              + 2 * omega_p.cross(t_rate) + _mm(Rp, motion.bias_trans)
              - bias_alpha.cross(e) - omega_c.cross(omega_c.cross(e)))
    return _Frame(R, parent.origin + d - e, J_v, J_w, bias_a, bias_alpha)


def joint_coordinate_count(joint: dict) -> int:
    """Number of coordinates a joint description contributes."""
    if joint["type"] == "Spherical":
        return len(joint["sequence"])
    return {"Revolute": 1, "Prismatic": 1, "Fixed": 0}[joint["type"]]


def coordinate_names(description: dict) -> list[str]:
    """All coordinate names, joint by joint in declaration order."""
    names: list[str] = []
    for joint in description["joints"]:
        coords = joint.get("coords") or []
        if len(coords) != joint_coordinate_count(joint):
            raise ValueError(f"joint {joint['name']!r} needs {joint_coordinate_count(joint)} coordinate names")
        names.extend(coords)
    return names


def _frames(description: dict, params: _Parameters, q: list, qd: list) -> dict[str, _Frame]:
    """Body frames from the ground outwards (joints must be listed parents-first)."""
    n = len(q)
    rates = sp.Matrix(qd) if n else sp.zeros(0, 1)
    frames = {GROUND: _Frame(sp.eye(3), sp.zeros(3, 1), sp.zeros(3, n), sp.zeros(3, n),
                             sp.zeros(3, 1), sp.zeros(3, 1))}
    start = 0
    for joint in description["joints"]:
        nj = joint_coordinate_count(joint)
        parent = frames.get(joint["parent"])
        if parent is None:
            raise ValueError(f"joint {joint['name']!r}: parent {joint['parent']!r} is not placed yet")
        if joint["child"] in frames:
            raise ValueError(f"joint {joint['name']!r}: child {joint['child']!r} already placed (loops unsupported)")
        motion = _joint_motion(joint, params, q[start:start + nj], qd[start:start + nj])
        pp = params.vector(joint.get("parent_point", (0, 0, 0)))
        cp = params.vector(joint.get("child_point", (0, 0, 0)))
        frames[joint["child"]] = _child_frame(parent, motion, pp, cp, start, rates)
        start += nj
    missing = set(description["bodies"]) - set(frames)
    if missing:
        raise ValueError(f"bodies not connected to the ground: {sorted(missing)}")
    return frames



# ----------------------------------------------------------------------------------
# Numeric evaluation
# ----------------------------------------------------------------------------------
def straight_line(arguments: list[list[sp.Symbol]], outputs: list) -> Callable:
    """A Python function of one array per list of ``arguments`` that evaluates ``outputs``
    (expressions, or matrices returned as flat arrays): one assignment per distinct
    subexpression, so expressions sharing subtrees cost their distinct nodes once.  Real
    inputs use ``math``, complex ones (complex steps) ``cmath``.  This replaces lambdify with
    a common-subexpression pass, whose term sorting and optimisation search took most of a
    derivation's time; it knows the operations the derivation produces (+, *, powers, sin,
    cos) and refuses others."""
    names: dict = {}
    lines = []
    for k, group in enumerate(arguments):
        for i, symbol in enumerate(group):
            names[symbol] = f"x{k}_{i}"
            lines.append(f"    x{k}_{i} = a{k}[{i}]")
    functions = {sp.sin: "sin", sp.cos: "cos"}

    def name_of(root: sp.Expr) -> str:
        stack = [(root, False)]
        while stack:
            node, ready = stack.pop()
            if node in names:
                continue
            if node.is_Number:
                names[node] = repr(float(node))
                continue
            if not ready:
                stack.append((node, True))
                stack.extend((arg, False) for arg in node.args if arg not in names)
                continue
            args = [names[arg] for arg in node.args]
            if node.is_Add:
                text = " + ".join(args)
            elif node.is_Mul:
                text = " * ".join(args)
            elif node.is_Pow and node.exp == sp.S.Half:
                text = f"sqrt({args[0]})"
            elif node.is_Pow and node.exp.is_Number:
                text = f"{args[0]} ** {args[1]}"
            elif node.func in functions:
                text = f"{functions[node.func]}({args[0]})"
            else:
                raise TypeError(f"straight_line cannot evaluate {node.func.__name__}")
            names[node] = f"t{len(names)}"
            lines.append(f"    {names[node]} = {text}")
        return names[root]

    returned = []
    for out in outputs:
        if isinstance(out, sp.MatrixBase):
            returned.append("array([" + ", ".join(name_of(entry) for entry in out) + "])")
        else:
            returned.append(name_of(sp.sympify(out)))
    source = (f"def evaluate({', '.join(f'a{k}' for k in range(len(arguments)))}):\n" + "\n".join(lines)
              + "\n    return [" + ", ".join(returned) + "]\n")
    code = compile(source, "<oracle>", "exec")
    variants = {}
    for module in (math, cmath):
        namespace = {"sin": module.sin, "cos": module.cos, "sqrt": module.sqrt, "array": np.array}
        exec(code, namespace)  # noqa: S102 - code printed above from the oracle's own expressions
        variants[module] = namespace["evaluate"]

    def evaluate(*arrays):
        complex_ = any(np.iscomplexobj(a) for a in arrays)
        return variants[cmath if complex_ else math](*arrays)
    return evaluate


# ----------------------------------------------------------------------------------
# The derived equations
# ----------------------------------------------------------------------------------
@dataclass
class Equations:
    """Numeric equations of motion ``M(q) qdd = F(q, qd)`` plus energies and kinematics.

    All callables take numpy arrays ordered like ``coords``.  Body quantities are in the
    world frame and refer to the centre of mass.
    """

    coords: list[str]
    bodies: list[str]
    _evaluate: Callable[[Any, Any], tuple] = field(repr=False)
    #: What Lagrange's method needs of the derivation (``lagrange_of``): the bodies' mass,
    #: inertia, COM and rotation, the potential, the coordinates and the parameters.
    _symbolic: tuple | None = field(default=None, repr=False)

    def mass_matrix(self, q: Any) -> np.ndarray:
        """(n, n) mass matrix."""
        return self._evaluate(q, np.zeros(len(self.coords)))[0]

    def forcing(self, q: Any, qd: Any) -> np.ndarray:
        """(n,) right-hand side F of ``M qdd = F``: gravity, springs, gyroscopic and
        convective terms."""
        return self._evaluate(q, qd)[1]

    def kinetic(self, q: Any, qd: Any) -> float:
        """Kinetic energy (J)."""
        return self._evaluate(q, qd)[2]

    def potential(self, q: Any) -> float:
        """Potential energy (J): ``-sum m g . r_com`` plus spring energy."""
        return self._evaluate(q, np.zeros(len(self.coords)))[3]

    def accelerations(self, q: Any, qd: Any, tau: Any = None) -> np.ndarray:
        """``qdd = M^-1 (F + tau)``."""
        M, F = self._evaluate(q, qd)[:2]
        if tau is not None:
            F = F + np.asarray(tau, dtype=float)
        return np.linalg.solve(M, F)

    def body_state(self, body: str, q: Any, qd: Any, qdd: Any = None) -> dict[str, np.ndarray]:
        """World-frame ``position``, ``rotation``, ``velocity``, ``angular_velocity``,
        ``acceleration`` and ``angular_acceleration`` of ``body``'s centre of mass
        (``qdd`` defaults to the free-motion accelerations)."""
        n = len(self.coords)
        q, qd = _as_vector(q, n), _as_vector(qd, n)
        qdd = self.accelerations(q, qd) if qdd is None else _as_vector(qdd, n)
        com, R, J_com, J_w, bias_com, bias_alpha = self._evaluate(q, qd)[4][self.bodies.index(body)]
        return {"position": com, "rotation": R, "velocity": J_com @ qd, "angular_velocity": J_w @ qd,
                "acceleration": J_com @ qdd + bias_com, "angular_acceleration": J_w @ qdd + bias_alpha}


def _as_vector(values: Any, n: int) -> np.ndarray:
    arr = np.asarray(values, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise ValueError(f"expected {n} values, got {arr.size}")
    return arr


def derive(description: dict, method: str = "virtual_power") -> Equations:
    """Derive the equations of motion of a tree ``description``.

    ``method="virtual_power"`` projects each body's Newton-Euler equations on the
    coordinates through velocity Jacobians propagated joint by joint.
    ``method="lagrange"`` (slower, for self-checks) uses Lagrange's equations with
    ``M`` built from differentiated positions and rotation matrices alone, so it shares
    nothing with the propagated velocities (see ``_lagrange``).
    """
    coords = coordinate_names(description)
    n = len(coords)
    q = list(sp.symbols(f"q0:{n}", real=True)) if n else []
    qd = list(sp.symbols(f"u0:{n}", real=True)) if n else []
    rates = sp.Matrix(qd) if n else sp.zeros(0, 1)
    params = _Parameters()
    frames = _frames(description, params, q, qd)
    gravity = params.vector(description.get("gravity", (0, 0, -9.81)))

    bodies = list(description["bodies"])
    mass_matrix, forcing = sp.zeros(n, n), sp.zeros(n, 1)
    kinetic, potential = sp.Integer(0), sp.Integer(0)
    kinematics, rigid = [], []
    for name in bodies:
        spec, frame = description["bodies"][name], frames[name]
        mass = params.scalar(spec["mass"])
        inertia = params.inertia(spec.get("inertia"))
        com, J_com, bias_com = frame.point(params.vector(spec.get("com", (0, 0, 0))), rates)
        J_wb = _mm(frame.R.T, frame.J_w)                     # angular velocity Jacobian, body frame
        omega_b = _mm(J_wb, rates)
        bias_alpha_b = _mm(frame.R.T, frame.bias_alpha)
        mass_matrix += mass * _mm(J_com.T, J_com) + _mm(J_wb.T, inertia, J_wb)
        forcing += _mm(J_com.T, mass * (gravity - bias_com)) \
            - _mm(J_wb.T, _mm(inertia, bias_alpha_b) + omega_b.cross(_mm(inertia, omega_b)))
        velocity = _mm(J_com, rates)
        kinetic += (mass * _mm(velocity.T, velocity)[0] + _mm(omega_b.T, inertia, omega_b)[0]) / 2
        potential += -mass * _mm(gravity.T, com)[0]
        kinematics.append([com, frame.R, J_com, frame.J_w, bias_com, frame.bias_alpha])
        rigid.append((mass, inertia, com, frame.R))

    spring_energy, spring_force = _springs(description, frames, params, rates, n)
    potential += spring_energy
    forcing += spring_force

    if method not in ("virtual_power", "lagrange"):
        raise ValueError(f"unknown method {method!r}")
    projected = _numeric(coords, bodies, params, (q, qd), mass_matrix, forcing, kinetic, potential, kinematics)
    projected._symbolic = (rigid, potential, q, params)
    return lagrange_of(projected) if method == "lagrange" else projected


def lagrange_of(projected: Equations) -> Equations:
    """The same model's equations by Lagrange's method (``derive(..., method="lagrange")``),
    from the geometry the virtual-power derivation ``projected`` already built: the
    positions and rotations are shared, the velocities and equations are not."""
    return _lagrange(projected, *projected._symbolic)


def _numeric(coords, bodies, params, variables, mass_matrix, forcing, kinetic, potential, kinematics) -> Equations:
    """Compile the symbolic results into one function with the parameter values bound
    (``straight_line``: the kinematics and the dynamics share their subexpressions)."""
    q, qd = variables
    n = len(coords)
    values = np.asarray(params.values, dtype=float)
    outputs = [mass_matrix, forcing, kinetic, potential] + [item for body in kinematics for item in body]
    function = straight_line([q, qd, params.symbols], outputs)
    shapes = [(3,), (3, 3), (3, n), (3, n), (3,), (3,)]

    def evaluate(qv, qdv):
        out = function(_as_vector(qv, n), _as_vector(qdv, n), values)
        M = np.asarray(out[0], dtype=float).reshape(n, n)
        F = np.asarray(out[1], dtype=float).reshape(n)
        body_values = [[np.asarray(v, dtype=float).reshape(shape) for v, shape in zip(out[k:k + 6], shapes)]
                       for k in range(4, len(out), 6)]
        return M, F, float(out[2]), float(out[3]), body_values

    return Equations(coords, bodies, evaluate)


def _springs(description: dict, frames: dict, params: _Parameters, rates: sp.Matrix, n: int):
    """Energy ``k (l - l0)^2 / 2`` and generalised force ``sum J_p^T f_p`` of the
    point-to-point springs (Hooke's law along the line between the points)."""
    energy, force = sp.Integer(0), sp.zeros(n, 1)
    for spring in description.get("springs", []):
        (body_a, point_a), (body_b, point_b) = spring["a"], spring["b"]
        pa, Ja, _ = frames[body_a].point(params.vector(point_a), rates)
        pb, Jb, _ = frames[body_b].point(params.vector(point_b), rates)
        delta = pb - pa
        length = sp.sqrt(_mm(delta.T, delta)[0])
        stretch = length - params.scalar(spring.get("rest_length", 0.0))
        stiffness = params.scalar(spring["stiffness"])
        energy += stiffness * stretch ** 2 / 2
        pull_on_b = -stiffness * stretch * delta / length
        force += _mm(Jb.T, pull_on_b) - _mm(Ja.T, pull_on_b)
    return energy, force


def _lagrange(projected: Equations, rigid: list, potential: sp.Expr, q: list, params: _Parameters) -> Equations:
    """Lagrange's equations ``M qdd = -dV/dq - dM/dt qd + 1/2 d(qd^T M qd)/dq``.

    ``M = sum m Jr^T Jr + Jw^T I Jw`` with ``Jr = d r_com/dq`` and the columns of ``Jw``
    from ``vee(R^T dR/dq_k)``: only first derivatives of positions and rotation matrices.
    The derivatives of M are taken numerically by complex steps (exact to round-off, as
    M is analytic in q), which avoids differentiating large expressions symbolically.
    Body kinematics are taken from ``projected``.
    """
    n = len(q)
    parts = []  # per body: m, I (body frame), J_r, J_w; M = sum m J_r^T J_r + J_w^T I J_w in numpy
    for mass, inertia, com, R in rigid:
        J_r = _jacobian(com, q)
        J_w = sp.zeros(3, n)
        for k, qk in enumerate(q):
            W = _mm(R.T, _jacobian(R.reshape(9, 1), [qk]).reshape(3, 3))                              # skew-symmetric: [column k]x
            J_w[:, k] = sp.Matrix([W[2, 1], W[0, 2], W[1, 0]])
        parts += [mass, inertia, J_r, J_w]
    gradient = _jacobian(sp.Matrix([potential]), q).T
    function = straight_line([q, params.symbols], [gradient, potential] + parts)
    values = np.asarray(params.values, dtype=float)
    step = 1e-30

    def mass(qv):
        """M at (possibly complex) q: plain transposes, no conjugates, so that M stays
        analytic in q for the complex-step derivatives below."""
        out = function(qv, values)[2:]
        M = np.zeros((n, n), dtype=complex)
        for m, inertia, J_r, J_w in zip(*[iter(out)] * 4):
            J_r = np.asarray(J_r, dtype=complex).reshape(3, n)
            J_w = np.asarray(J_w, dtype=complex).reshape(3, n)
            M += complex(m) * J_r.T @ J_r + J_w.T @ np.asarray(inertia, dtype=complex).reshape(3, 3) @ J_w
        return M

    def evaluate(qv, qdv):
        qv, qdv = _as_vector(qv, n), _as_vector(qdv, n)
        M = mass(qv).real
        M_dot = mass(qv + 1j * step * qdv).imag / step
        dT_dq = np.array([qdv @ (mass(qv + 1j * step * e).imag / step) @ qdv / 2 for e in np.eye(n)])
        grad_V, V = function(qv, values)[:2]
        F = -np.asarray(grad_V, dtype=float).reshape(n) - M_dot @ qdv + dT_dq
        return M, F, float(qdv @ M @ qdv / 2), float(V), projected._evaluate(qv, qdv)[4]

    return Equations(projected.coords, projected.bodies, evaluate)


# ----------------------------------------------------------------------------------
# The same model through mbcomp's public API
# ----------------------------------------------------------------------------------
def to_mbcomp(description: dict):
    """Build ``description`` as an ``mbcomp.Model`` using only the public API."""
    import mbcomp as mb

    model = mb.Model(description.get("name", "independent"), gravity=tuple(description.get("gravity", (0, 0, -9.81))))
    bodies = {GROUND: model.ground}
    for name, spec in description["bodies"].items():
        inertia = spec.get("inertia")
        bodies[name] = model.add(mb.Body(name, mass=spec["mass"], com=tuple(spec.get("com", (0, 0, 0))),
                                         inertia=None if inertia is None else np.asarray(inertia, dtype=float)))
    for joint in description["joints"]:
        model.add(_mbcomp_joint(mb, joint, bodies))
    for spring in description.get("springs", []):
        (body_a, point_a), (body_b, point_b) = spring["a"], spring["b"]
        model.add(mb.Spring(spring["name"], a=(bodies[body_a], tuple(point_a)), b=(bodies[body_b], tuple(point_b)),
                            stiffness=spring["stiffness"], rest_length=spring.get("rest_length", 0.0)))
    return model


def _mbcomp_joint(mb, joint: dict, bodies: dict):
    """One joint description as an mbcomp joint component."""
    common = dict(parent_point=tuple(joint.get("parent_point", (0, 0, 0))),
                  child_point=tuple(joint.get("child_point", (0, 0, 0))))
    parent, child, name, kind = bodies[joint["parent"]], bodies[joint["child"]], joint["name"], joint["type"]
    coords = list(joint.get("coords") or [])
    if kind in ("Revolute", "Prismatic"):
        axis = joint["axis"] if isinstance(joint["axis"], str) else tuple(joint["axis"])
        return getattr(mb, kind)(name, parent, child, axis=axis, coords=coords[0], **common)
    if kind == "Spherical":
        return mb.Spherical(name, parent, child, sequence=joint["sequence"], coords=tuple(coords), **common)
    if kind == "Fixed":
        return mb.Fixed(name, parent, child, **common)
    raise ValueError(f"joint {name!r}: unknown type {kind!r}")


# ----------------------------------------------------------------------------------
# Random trees
# ----------------------------------------------------------------------------------
def random_inertia(rng: np.random.Generator, mass: float) -> np.ndarray:
    """A random symmetric positive-definite inertia obeying the triangle inequality.

    Built as ``Q diag(Syy+Szz, Sxx+Szz, Sxx+Syy) Q^T`` from positive second moments S,
    which is exactly the set of physically realisable inertias.
    """
    second = mass * rng.uniform(0.005, 0.05, size=3)
    principal = np.array([second[1] + second[2], second[0] + second[2], second[0] + second[1]])
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    inertia = Q @ np.diag(principal) @ Q.T
    return 0.5 * (inertia + inertia.T)


def random_axis(rng: np.random.Generator) -> Any:
    """``"x" | "y" | "z"`` a third of the time, otherwise a random unit 3-vector."""
    if rng.random() < 1 / 3:
        return str(rng.choice(["x", "y", "z"]))
    vec = rng.normal(size=3)
    return tuple(float(v) for v in vec / np.linalg.norm(vec))


def _random_point(rng: np.random.Generator, zero_chance: float = 0.25) -> tuple:
    """A random point within 0.5 m of the origin, sometimes exactly the origin."""
    if rng.random() < zero_chance:
        return (0.0, 0.0, 0.0)
    return tuple(float(v) for v in rng.uniform(-0.5, 0.5, size=3))


def _axis_vector(axis: Any) -> np.ndarray:
    return np.array(UNIT[axis], dtype=float) if isinstance(axis, str) else np.asarray(axis, dtype=float)


def _tree_parents(rng: np.random.Generator, n_bodies: int, branched: bool) -> list[int]:
    """Parent index of every body (-1 = ground); a chain, or a tree with a branch."""
    if not branched or n_bodies < 2:
        return list(range(-1, n_bodies - 1))
    while True:
        parents = [-1] + [int(rng.integers(-1, i)) for i in range(1, n_bodies)]
        if len(set(parents)) < n_bodies:        # some body (or the ground) has two children
            return parents


def _dfs_order(parents: list[int]) -> list[int]:
    """Bodies in depth-first order from the ground, siblings in index order."""
    order: list[int] = []

    def visit(node: int) -> None:
        for child, parent in enumerate(parents):
            if parent == node:
                order.append(child)
                visit(child)

    visit(-1)
    return order


def _random_joint_type(rng: np.random.Generator, budget: int) -> str:
    """A joint type whose coordinates fit in the remaining ``budget``."""
    kinds = ["Revolute", "Prismatic", "Spherical", "Fixed"]
    weights = np.array([0.35, 0.2, 0.3, 0.15])
    if budget < 2:
        weights[2] = 0.0
    if budget < 1:
        weights[:2] = 0.0
    return str(rng.choice(kinds, p=weights / weights.sum()))


def random_tree(rng: np.random.Generator, n_bodies: int, branched: bool | None = None,
                max_coords: int = 8) -> dict:
    """A random tree description (2-5 bodies recommended) with a regular mass matrix.

    Chains or branched trees (``branched=None`` picks at random) mix all joint types;
    masses are in 0.5..3 kg; some bodies are point masses.  To keep the mass matrix
    regular, a body is a point mass only behind a Prismatic or Fixed joint, or behind a
    Revolute whose axis misses its centre of mass by > 0.1 m; Spherical children always
    get a full inertia.  Joints (and bodies) are declared depth-first from the ground.
    """
    if branched is None:
        branched = bool(rng.random() < 0.5)
    parents = _tree_parents(rng, n_bodies, branched)
    names = [f"b{i + 1}" for i in range(n_bodies)]
    bodies: dict[str, dict] = {}
    joints: list[dict] = []
    budget = max_coords
    for index in _dfs_order(parents):
        joint = _random_joint(rng, f"j{index + 1}", "ground" if parents[index] < 0 else names[parents[index]],
                              names[index], budget)
        budget -= joint_coordinate_count(joint)
        joints.append(joint)
        bodies[names[index]] = _random_body(rng, joint)
    gravity = rng.normal(size=3)
    gravity = 9.81 * gravity / np.linalg.norm(gravity)
    return {"name": f"tree{n_bodies}", "gravity": tuple(float(g) for g in gravity),
            "bodies": bodies, "joints": joints}


def _random_joint(rng: np.random.Generator, name: str, parent: str, child: str, budget: int) -> dict:
    """A random joint description with coordinate names ``<name>_<i>``."""
    kind = _random_joint_type(rng, budget)
    joint = {"name": name, "type": kind, "parent": parent, "child": child,
             "parent_point": _random_point(rng), "child_point": _random_point(rng)}
    if kind in ("Revolute", "Prismatic"):
        joint["axis"] = random_axis(rng)
    if kind == "Spherical":
        options = [s for s in SEQUENCES if len(s) <= budget]
        joint["sequence"] = str(rng.choice(options))
    joint["coords"] = [f"{name}_{i}" for i in range(joint_coordinate_count(joint))]
    return joint


def _random_body(rng: np.random.Generator, joint: dict) -> dict:
    """Mass, centre of mass and inertia for the child of ``joint`` (see ``random_tree``)."""
    mass = float(rng.uniform(0.5, 3.0))
    com = np.asarray(_random_point(rng, zero_chance=0.1))
    point_mass = joint["type"] != "Spherical" and rng.random() < 0.35
    if point_mass and joint["type"] == "Revolute":
        axis = _axis_vector(joint["axis"])
        arm = com - np.asarray(joint["child_point"])
        if np.linalg.norm(arm - arm.dot(axis) * axis) < 0.1:
            point_mass = False
    inertia = None if point_mass else random_inertia(rng, mass).tolist()
    return {"mass": mass, "com": tuple(float(c) for c in com), "inertia": inertia}


def random_state(rng: np.random.Generator, description: dict) -> tuple[np.ndarray, np.ndarray]:
    """Random ``(q, qd)`` away from Euler-angle singularities.

    Every angle has magnitude in [0.2, 1.3] rad: a 3-angle sequence is singular at a
    middle angle of +-pi/2 (distinct axes) or 0 (repeated first/last axis).
    """
    n = len(coordinate_names(description))
    magnitude = rng.uniform(0.2, 1.3, size=n)
    q = magnitude * rng.choice([-1.0, 1.0], size=n)
    qd = rng.uniform(-2.0, 2.0, size=n)
    return q, qd
