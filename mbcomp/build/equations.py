"""Equations of motion by the virtual-power (TMT) route, built as a straight-line program.

The kinematics are propagated along the tree in world-frame spatial (Plücker)
coordinates referred to the world origin: a body's spatial velocity is
``V = (w, v0)`` with ``v0`` the velocity of the body point at the origin, so the
velocity of a point at world position ``p`` is ``v0 + w x p``.  Each coordinate
``k`` has a motion column ``S_k`` (a column of ``T``); the reduced mass matrix
``M_bar = T^T M T`` is accumulated with composite inertias (every world-frame
spatial inertia adds without transformation), and ``f_bar = T^T (f - M g)`` is
the backward sum of body wrenches projected on the columns.  Every intermediate
is materialised into its own symbol, so expressions stay small (no ``simplify``)
and shared work is shared by construction; sympy prunes zero and one terms.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import sympy as sp

from mbcomp.spec.components import Body
from mbcomp.core.symbolic import dot, product, total  # noqa: F401 - dot and product are this module's too
from mbcomp.spec.components.values import name_of


def exact(value: float) -> sp.Expr:
    """A sympy number, exact for integers so that 0 and 1 prune."""
    value = float(value)
    return sp.Integer(int(value)) if value.is_integer() else sp.Float(value)


def cross(a, b):
    return [total([product(a[1], b[2]), -product(a[2], b[1])]), total([product(a[2], b[0]), -product(a[0], b[2])]),
            total([product(a[0], b[1]), -product(a[1], b[0])])]


def matvec(R, v):
    return [dot(row, v) for row in R]


# -- parameters: in param_layout.py (no sympy there: a cached model loads without it) --
from mbcomp.build.param_layout import ParameterLayout, input_layout, parameter_layout, parameter_values  # noqa: E402,F401


# -- the straight-line program --------------------------------------------------------
@dataclass
class Program:
    """Assignments ``(symbol, expression)`` in order, and named output lists."""

    q: list
    qd: list
    p: list
    u: list
    assignments: list = field(default_factory=list)
    outputs: dict = field(default_factory=dict)
    _memo: dict = field(default_factory=dict)

    def let(self, expr: Any) -> sp.Expr:
        """Materialise ``expr`` into a fresh symbol (atoms and repeats are reused)."""
        expr = sp.sympify(expr)
        if expr.is_Atom or (expr.is_Mul and len(expr.args) == 2 and expr.args[0] == -1 and expr.args[1].is_Atom):
            return expr
        found = self._memo.get(expr)
        if found is not None:
            return found
        symbol = sp.Symbol(f"t{len(self.assignments)}")
        self.assignments.append((symbol, expr))
        self._memo[expr] = symbol
        return symbol

    def lets(self, exprs) -> list:
        return [self.let(e) for e in exprs]

    def needed(self, names, free: dict | None = None) -> list:
        """The assignments the given outputs depend on (dead code removed), in order;
        ``free`` maps each assigned symbol to its expression's free symbols when the caller
        has computed them once (the code generator, over many functions)."""
        wanted = set()
        for name in names:
            for expr in self.outputs[name]:
                wanted |= sp.sympify(expr).free_symbols
        keep = []
        for symbol, expr in reversed(self.assignments):
            if symbol in wanted:
                keep.append((symbol, expr))
                wanted |= expr.free_symbols if free is None else free[symbol]
        keep.reverse()
        return keep

    def expand(self, exprs: list, substitute: dict | None = None) -> list:
        """``exprs`` with every intermediate substituted back (for display of small models):
        each needed intermediate is expanded once, in order, from the ones before it.
        ``substitute``: values of inputs (symbol -> number) put in as the intermediates are
        expanded, so that numbers fold on the way and the expressions stay small."""
        exprs = [sp.sympify(e) for e in exprs]
        wanted = set().union(*(e.free_symbols for e in exprs)) if exprs else set()
        needed = []
        for symbol, value in reversed(self.assignments):
            if symbol in wanted:
                needed.append((symbol, value))
                wanted |= value.free_symbols
        expanded: dict = dict(substitute or {})
        for symbol, value in reversed(needed):
            expanded[symbol] = value.xreplace(expanded)
        return [e.xreplace(expanded) for e in exprs]


class SpatialInertia:
    """World-frame spatial inertia about the origin: mass, ``h = m c``, ``Ibar`` (3x3)."""

    def __init__(self, mass, h, Ibar):
        self.mass, self.h, self.Ibar = mass, h, Ibar

    def apply(self, V):
        """Momentum ``I V = (Ibar w + h x v, m v - h x w)`` of spatial velocity ``V = (w, v)``."""
        w, v = V[:3], V[3:]
        n = [total([a, b]) for a, b in zip(matvec(self.Ibar, w), cross(self.h, v))]
        f = [total([product(self.mass, a), -b]) for a, b in zip(v, cross(self.h, w))]
        return n + f

    def __add__(self, other):
        return SpatialInertia(self.mass + other.mass, [total([a, b]) for a, b in zip(self.h, other.h)],
                              [[total([a, b]) for a, b in zip(r1, r2)] for r1, r2 in zip(self.Ibar, other.Ibar)])

    def materialise(self, prog: Program):
        Ibar = [[None] * 3 for _ in range(3)]
        for i in range(3):
            for j in range(i, 3):
                Ibar[i][j] = Ibar[j][i] = prog.let(self.Ibar[i][j])
        return SpatialInertia(prog.let(self.mass), prog.lets(self.h), Ibar)


def motion_cross(V, S):
    """``V x_m S``: rate of change of a motion column ``S`` carried by a frame moving with ``V``."""
    w, v = V[:3], V[3:]
    w2, v2 = S[:3], S[3:]
    return cross(w, w2) + [a + b for a, b in zip(cross(w, v2), cross(v, w2))]


def force_cross(V, F):
    """``V x_f F``: rate of change of a spatial force/momentum carried with ``V``."""
    w, v = V[:3], V[3:]
    n, f = F[:3], F[3:]
    return [a + b for a, b in zip(cross(w, n), cross(v, f))] + cross(w, f)


def rotation_about(axis, c, s):
    """Rodrigues' rotation with exact axis entries and cos/sin symbols ``c``, ``s``.  About
    a coordinate axis (``±x``, ``±y``, ``±z``: most joints) the same matrix is written down
    directly: sympy takes about 2 ms per joint to find that the general formula prunes to it."""
    nonzero = [i for i, a in enumerate(axis) if a != 0]
    if len(nonzero) == 1 and abs(axis[nonzero[0]]) == 1:
        i = nonzero[0]
        j, k = (i + 1) % 3, (i + 2) % 3
        sine = axis[i] * s
        R = [[sp.Integer(0)] * 3 for _ in range(3)]
        R[i][i], R[j][j], R[k][k], R[k][j], R[j][k] = sp.Integer(1), c, c, sine, -sine
        return R
    x, y, z = axis
    k = 1 - c
    return [[c + x * x * k, x * y * k - z * s, x * z * k + y * s],
            [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
            [z * x * k - y * s, z * y * k + x * s, c + z * z * k]]


class Kinematics:
    """Symbolic kinematics accessor handed to components (world frame, SI units)."""

    def __init__(self, topology, layout: ParameterLayout, inputs: dict, prog: Program):
        self.topology, self.layout, self.inputs, self.prog = topology, layout, inputs, prog
        self.R, self.origin, self.V, self.A = {}, {}, {}, {}
        self.S: list = [None] * topology.nv  # motion column of each speed
        self.let = prog.let

    def param(self, comp, attr: str):
        return self.layout.symbols(f"{comp.name}.{attr}")

    def input(self, comp) -> list:
        start, size = self.inputs[comp.name]
        return self.prog.u[start:start + size]

    def q(self, joint) -> list:
        sl = self.topology.q_slice[name_of(joint)]
        return self.prog.q[sl]

    def qd(self, joint) -> list:
        """The joint's speeds (its coordinates' rates for a screw joint)."""
        sl = self.topology.v_slice[name_of(joint)]
        return self.prog.qd[sl]

    def rotation(self, body):
        return self.R[name_of(body)]

    def position(self, body, point) -> list:
        """World position (m) of a point given in the body frame."""
        name = name_of(body)
        if name == self.topology.ground.name:
            return list(point)
        return self.prog.lets([o + r for o, r in zip(self.origin[name], matvec(self.R[name], point))])

    def velocity(self, body, point) -> list:
        """World velocity (m/s) of a body point: ``v0 + w x p``."""
        name = name_of(body)
        if name == self.topology.ground.name:
            return [sp.Integer(0)] * 3
        V = self.V[name]
        p = self.position(body, point)
        return self.prog.lets([a + b for a, b in zip(V[3:], cross(V[:3], p))])

    def angular_velocity(self, body) -> list:
        name = name_of(body)
        return [sp.Integer(0)] * 3 if name == self.topology.ground.name else self.V[name][:3]


def _vector(kin, spec) -> list:
    """A parameter key's symbols, or a constant vector as exact numbers."""
    return kin.layout.symbols(spec) if isinstance(spec, str) else [exact(v) for v in spec]


def _point_terms(kin, body, spec):
    """World position, velocity, bias acceleration and Jacobian columns ``{k: 3-vector}``
    of a body point: ``v = sum_k (w_k x p + v0_k) qd_k`` over the speeds, ``a = J qdd + bias``."""
    prog = kin.prog
    p = kin.position(body, _vector(kin, spec))
    name = name_of(body)
    if name == kin.topology.ground.name:
        zero = [sp.Integer(0)] * 3
        return p, zero, zero, {}
    V, A = kin.V[name], kin.A[name]
    v = prog.lets([a + b for a, b in zip(V[3:], cross(V[:3], p))])
    acc = prog.lets([a0 + x + y for a0, x, y in zip(A[3:], cross(A[:3], p), cross(V[:3], v))])
    columns = {k: prog.lets([a + b for a, b in zip(cross(kin.S[k][:3], p), kin.S[k][3:])])
               for k in kin.topology.speed_indices_of_body(body)}
    return p, v, acc, columns


def _rotation_terms(kin, body):
    """Rotation, angular velocity, bias angular acceleration and Jacobian columns."""
    name = name_of(body)
    if name == kin.topology.ground.name:
        zero = [sp.Integer(0)] * 3
        return kin.R[name], zero, zero, {}
    return kin.R[name], kin.V[name][:3], kin.A[name][:3], {k: kin.S[k][:3] for k in kin.topology.speed_indices_of_body(body)}


def _combine(nv, *terms):
    """Row of length nv from ``(vector, {k: column})`` pairs: sum of ``vector . column``."""
    row = [sp.Integer(0)] * nv
    for vector, columns in terms:
        for k, column in columns.items():
            row[k] += dot(vector, column)
    return row


def _body_motion(kin, body):
    """Angular velocity, spatial velocity's ``v0``, bias spatial acceleration ``(alpha, a0)``
    and motion columns ``{k: S_k}`` of a body (zeros and none for the ground)."""
    name = name_of(body)
    if name == kin.topology.ground.name:
        zero = [sp.Integer(0)] * 3
        return zero, zero, zero, zero, {}
    V, A = kin.V[name], kin.A[name]
    return V[:3], V[3:], A[:3], A[3:], {k: kin.S[k] for k in kin.topology.speed_indices_of_body(body)}


def _rolling_point(kin, eq):
    """World position ``c`` of a rolling equation's contact point and its rate ``c'``
    (the geometric point's, which slides over the rolling body's surface)."""
    prog = kin.prog
    kind = eq.contact[0]
    w_p = _body_motion(kin, eq.plane)[0]
    n = prog.lets(matvec(kin.rotation(eq.plane), [exact(c) for c in eq.normal]))
    n_rate = prog.lets(cross(w_p, n))
    if kind == "point":
        point = _vector(kin, eq.contact[1])
        return kin.position(eq.body, point), kin.velocity(eq.body, point)
    center = _vector(kin, eq.contact[1])
    r = kin.layout.symbols(eq.contact[2])
    C = kin.position(eq.body, center)
    C_rate = kin.velocity(eq.body, center)
    if kind == "ball":  # c = C - r n
        c = prog.lets([x - r * y for x, y in zip(C, n)])
        return c, prog.lets([x - r * y for x, y in zip(C_rate, n_rate)])
    # disc: d = -u / |u| with u = n - (n.a) a (the in-plane direction towards the plane), c = C + r d
    w_b = _body_motion(kin, eq.body)[0]
    a = prog.lets(matvec(kin.rotation(eq.body), [exact(x) for x in eq.contact[3]]))
    a_rate = prog.lets(cross(w_b, a))
    k = prog.let(dot(n, a))
    k_rate = prog.let(dot(n_rate, a) + dot(n, a_rate))
    u = prog.lets([x - k * y for x, y in zip(n, a)])
    u_rate = prog.lets([x - k_rate * y - k * z for x, y, z in zip(n_rate, a, a_rate)])
    s = prog.let(sp.sqrt(dot(u, u)))
    d = prog.lets([-x / s for x in u])
    s_rate = prog.let(dot(u, u_rate) / s)
    d_rate = prog.lets([-(x + y * s_rate) / s for x, y in zip(u_rate, d)])
    c = prog.lets([x + r * y for x, y in zip(C, d)])
    return c, prog.lets([x + r * y for x, y in zip(C_rate, d_rate)])


def _rolling_row(kin, eq, nv):
    """``(g, Jacobian row, bias)`` of a ``RollingEquation`` (see ``primitives``): the row
    ``e . (v_b(c) - v_a(c))`` with ``v_X(c) = v0_X + w_X x c`` the material velocity of
    body X at the contact point, and its rate's part without accelerations::

        e . (a0_b + alpha_b x c - a0_a - alpha_a x c + (w_b - w_a) x c') + (w_f x e) . v_rel
    """
    prog = kin.prog
    c, c_rate = _rolling_point(kin, eq)
    wb, vb, alb, ab, Sb = _body_motion(kin, eq.body)
    wa, va, ala, aa, Sa = _body_motion(kin, eq.plane)
    wf = _body_motion(kin, eq.frame)[0]
    e = prog.lets(matvec(kin.rotation(eq.frame), [exact(x) for x in eq.direction]))
    rel = prog.lets([x + y - z - t for x, y, z, t in zip(vb, cross(wb, c), va, cross(wa, c))])
    row = [sp.Integer(0)] * nv
    for sign, columns in ((1, Sb), (-1, Sa)):
        for k, S in columns.items():
            row[k] += sign * dot(e, [x + y for x, y in zip(S[3:], cross(S[:3], c))])
    w_rel = [x - y for x, y in zip(wb, wa)]
    acc = [p - q + x - y + z for p, q, x, y, z in zip(ab, aa, cross(alb, c), cross(ala, c), cross(w_rel, c_rate))]
    bias = dot(e, acc) + dot(cross(wf, e), rel)
    if eq.origin is None:
        g = sp.Integer(0)
    else:
        o = kin.position(eq.plane, _vector(kin, eq.origin))
        g = dot(e, [x - y for x, y in zip(c, o)])
    return g, row, bias


def constraint_outputs(prog: Program, kin, equations, output: str = "constraints") -> None:
    """Output ``output``: residual g, Jacobian rows (row-major) and acceleration bias of the
    geometric constraint equations (point and dot), as ``constraint_set`` documents."""
    from mbcomp.spec.components.primitives import CoordinateGap, DotEquation, PointEquation, RollingEquation
    nv = kin.topology.nv
    g_out, J_out, bias_out = [], [], []
    for eq in equations:
        if isinstance(eq, PointEquation):
            pa, va, aa, Ja = _point_terms(kin, eq.body_a, eq.point_a)
            pb, vb, ab, Jb = _point_terms(kin, eq.body_b, eq.point_b)
            Rf, wf, alf, Jwf = _rotation_terms(kin, eq.frame)
            n = prog.lets(matvec(Rf, [exact(c) for c in eq.normal]))
            d = prog.lets([x - y for x, y in zip(pb, pa)])
            wn = prog.lets(cross(wf, n))
            g = dot(n, d)
            if getattr(eq, "offset", None) is not None:
                g = g - kin.layout.symbols(eq.offset)
            row = _combine(nv, (n, Jb), ([-c for c in n], Ja), (cross(n, d), Jwf))
            bias = (dot(n, [x - y for x, y in zip(ab, aa)]) + 2 * dot(wn, [x - y for x, y in zip(vb, va)])
                    + dot([x + y for x, y in zip(cross(alf, n), cross(wf, wn))], d))
        elif isinstance(eq, DotEquation):
            Ra, wa, ala, Jwa = _rotation_terms(kin, eq.body_a)
            Rb, wb, alb, Jwb = _rotation_terms(kin, eq.body_b)
            ua = prog.lets(matvec(Ra, [exact(c) for c in eq.u_a]))
            ub = prog.lets(matvec(Rb, [exact(c) for c in eq.u_b]))
            axis = prog.lets(cross(ub, ua))
            g = dot(ua, ub)
            row = _combine(nv, (axis, Jwb), ([-c for c in axis], Jwa))
            rate = [x + y for x, y in zip(cross(cross(wb, ub), ua), cross(ub, cross(wa, ua)))]
            bias = dot([x - y for x, y in zip(alb, ala)], axis) + dot([x - y for x, y in zip(wb, wa)], rate)
        elif isinstance(eq, RollingEquation):
            g, row, bias = _rolling_row(kin, eq, nv)
        elif isinstance(eq, CoordinateGap):  # on a 1-DOF screw joint: its speed is its rate
            k = kin.topology.q_slice[name_of(eq.joint)].start
            kv = kin.topology.v_slice[name_of(eq.joint)].start  # a 1-DOF screw joint: its speed
            g = eq.sign * (prog.q[k] - kin.layout.symbols(eq.bound))
            row = [sp.Integer(eq.sign if i == kv else 0) for i in range(nv)]
            bias = sp.Integer(0)
        else:
            continue
        g_out.append(prog.let(g))
        J_out.extend(prog.lets(row))
        bias_out.append(prog.let(bias))
    prog.outputs[output] = g_out + J_out + bias_out


def build_program(topology, layout: ParameterLayout, inputs: dict, equations=(), drives=None,
                  recursive: bool = False, factors: bool = False, ready=None, dense: bool = True) -> Program:
    """The whole model as one straight-line program over coordinates ``q`` (nq) and
    speeds ``qd`` (nv; a screw coordinate's speed is its rate).

    Outputs: ``"mass_matrix"`` (nv x nv, lower triangle, row-major), ``"forces"`` (f_bar:
    gravity, force elements, convective and gyroscopic terms; ``M_bar qdd = f_bar + tau``
    with ``qdd`` the speeds' rates), ``"energy"`` (kinetic, potential), and
    ``"kinematics"`` (per body R, origin, V, A-bias; per speed S); with ``recursive``
    also ``"aba"`` (``recursive.aba_outputs``: the accelerations by the O(N)
    articulated-body recursion, with the run-time generalised forces as extra inputs; with
    ``factors`` also what the dae formulation's KKT solve needs).

    ``dense=False`` (with ``recursive``) leaves out the dense ``"mass_matrix"`` and
    ``"forces"`` (the composite-inertia pass): a compiled program whose right-hand side is
    the recursion builds them only when they are first asked for (``CompiledModel``).

    ``ready(prog, names)``, when given, is called as soon as the outputs ``names`` are final
    (the rest of the program only appends assignments), so that a code generator can print
    and compile them while the rest is built.  It must not change the program.
    """
    ready = ready or (lambda prog, names: None)
    nq, nv = topology.nq, topology.nv
    n_inputs = sum(size for _, size in inputs.values())
    prog = Program(q=[sp.Symbol(f"q{i}") for i in range(nq)], qd=[sp.Symbol(f"qd{i}") for i in range(nv)],
                   p=[], u=[sp.Symbol(f"u{i}") for i in range(n_inputs)])
    kin = Kinematics(topology, layout, inputs, prog)
    zero = [sp.Integer(0)] * 6
    ground = topology.ground.name
    kin.R[ground] = [[sp.Integer(int(i == j)) for j in range(3)] for i in range(3)]
    kin.origin[ground] = [sp.Integer(0)] * 3
    kin.V[ground], kin.A[ground] = zero, zero
    gravity = layout.symbols("gravity")

    inertia: dict[str, SpatialInertia] = {}
    external: dict[str, list] = {}
    for body, joint in zip(topology.bodies, topology.tree_joints):
        parent = topology.parent_of[body.name].name
        R = kin.R[parent]
        pos = prog.lets([o + r for o, r in zip(kin.origin[parent], matvec(R, kin.param(joint, "parent_point")))])
        V, A = kin.V[parent], kin.A[parent]
        q0, v0 = topology.q_slice[joint.name].start, topology.v_slice[joint.name].start
        R = _rotate_frame(prog, R, getattr(joint, "parent_rotation", None))
        for kind, axis, sq, sv in joint.walk():
            if kind == "B":
                R, V, A = _ball_segment(prog, kin, prog.q[q0 + sq.start:q0 + sq.stop], v0 + sv.start, R, pos, V, A)
                continue
            i, k = q0 + sq.start, v0 + sv.start
            axis_world = prog.lets(matvec(R, [exact(a) for a in axis]))
            if kind == "R":
                S = axis_world + prog.lets(cross(pos, axis_world))
                c, s = prog.let(sp.cos(prog.q[i])), prog.let(sp.sin(prog.q[i]))
                local = rotation_about([exact(a) for a in axis], c, s)
                R = [[prog.let(dot(R[r], [local[m][col] for m in range(3)])) for col in range(3)] for r in range(3)]
            else:
                S = [sp.Integer(0)] * 3 + axis_world
                pos = prog.lets([total([x, product(a, prog.q[i])]) for x, a in zip(pos, axis_world)])
            kin.S[k] = S
            A = prog.lets([total([a, product(b, prog.qd[k])]) for a, b in zip(A, motion_cross(V, S))])
            V = prog.lets([total([a, product(b, prog.qd[k])]) for a, b in zip(V, S)])
        R = _rotate_frame(prog, R, getattr(joint, "child_rotation", None), transpose=True)
        kin.R[body.name] = R
        child_point = matvec(R, kin.param(joint, "child_point"))
        kin.origin[body.name] = prog.lets([total([x, -r]) for x, r in zip(pos, child_point)])
        kin.V[body.name], kin.A[body.name] = V, A

        mass = kin.param(body, "mass")
        com = kin.position(body, kin.param(body, "com"))
        cc = dot(com, com)
        Ibar = [[mass * ((cc if i == j else 0) - com[i] * com[j]) for j in range(3)] for i in range(3)]
        if not body.is_point_mass:
            I_B = _body_inertia_symbols(body, kin)
            RI = [[dot(R[i], [I_B[k][j] for k in range(3)]) for j in range(3)] for i in range(3)]
            for i in range(3):
                for j in range(3):
                    Ibar[i][j] = Ibar[i][j] + dot(RI[i], R[j])
        inertia[body.name] = SpatialInertia(mass, [mass * c for c in com], Ibar).materialise(prog)
        weight = [mass * g for g in gravity]
        external[body.name] = prog.lets(cross(com, weight) + weight)

    kinematics = []
    for body in topology.bodies:
        kinematics += [e for row in kin.R[body.name] for e in row] + kin.origin[body.name] + kin.V[body.name] + kin.A[body.name]
    for S in kin.S:
        kinematics += S
    prog.outputs["kinematics"] = kinematics
    ready(prog, ["kinematics"])

    generalized = [sp.Integer(0)] * nv
    potential = []  # terms, summed once at the end (a growing sum rebuilt per body is O(N^2))
    for body in topology.bodies:
        potential.append(-(inertia[body.name].mass * dot(kin.position(body, kin.param(body, "com")), gravity)))
    for element in topology.forces:
        for load in element.loads(kin):
            if load[0] == "generalized":
                sl = topology.v_slice[name_of(load[1])]
                for k, value in zip(range(sl.start, sl.stop), load[2]):
                    generalized[k] += value
                continue
            target = name_of(load[1])
            if target == ground:
                continue
            wrench = cross(load[2], load[3]) + list(load[3]) if load[0] == "point" else list(load[2]) + [0, 0, 0]
            external[target] = prog.lets([a + b for a, b in zip(external[target], wrench)])
        potential.append(element.potential(kin))

    # Backward pass: composite inertias and wrenches, projected on the motion columns.
    composite = {b.name: inertia[b.name] for b in topology.bodies}
    wrench = {}
    kinetic = []  # terms, as the potential's
    for body in topology.bodies:
        I = inertia[body.name]
        V = kin.V[body.name]
        momentum = prog.lets(I.apply(V))
        kinetic.append(dot(V, momentum) / 2)
        body_force = [total([total([a, b]), -e]) for a, b, e in zip(I.apply(kin.A[body.name]), force_cross(V, momentum),
                                                                   external[body.name])]
        wrench[body.name] = prog.lets(body_force)
    own_wrench = dict(wrench)  # each body's own, before the subtree sums (recursive program)
    for body in reversed(topology.bodies) if dense else ():
        parent = topology.parent_of[body.name].name
        if parent != ground:
            composite[parent] = (composite[parent] + composite[body.name]).materialise(prog)
            wrench[parent] = prog.lets([total([a, b]) for a, b in zip(wrench[parent], wrench[body.name])])

    owner = [None] * nv
    for body, joint in zip(topology.bodies, topology.tree_joints):
        for i in range(*topology.v_slice[joint.name].indices(nv)):
            owner[i] = body
    columns_of_chain = {}
    for body in topology.bodies:
        columns_of_chain[body.name] = topology.speed_indices_of_body(body)
    M = {}
    forces = []
    for i in range(nv) if dense else ():
        body = owner[i]
        F = prog.lets(composite[body.name].apply(kin.S[i]))
        for j in columns_of_chain[body.name]:
            if j <= i:
                M[i, j] = prog.let(dot(kin.S[j], F))
        forces.append(prog.let(generalized[i] - dot(kin.S[i], wrench[body.name])))
    armature = {}
    for element in topology.forces:  # reflected rotor inertias of drives (drivetrain.py)
        for joint, value in element.armature(kin) if hasattr(element, "armature") else ():
            i = topology.v_slice[name_of(joint)].start  # a 1-DOF screw joint: its speed index
            armature[i] = armature.get(i, 0) + value
            if dense:
                M[i, i] = prog.let(M[i, i] + value)
            kinetic.append(value * prog.qd[i] ** 2 / 2)
    if dense:
        prog.outputs["mass_matrix"] = [M.get((i, j), sp.Integer(0)) for i in range(nv) for j in range(i + 1)]
        prog.outputs["forces"] = forces
        ready(prog, ["mass_matrix", "forces"])
    prog.outputs["energy"] = [prog.let(sp.Add(*kinetic)), prog.let(sp.Add(*potential))]
    ready(prog, ["energy"])
    if recursive:
        from mbcomp.build.recursive import aba_outputs
        aba_outputs(prog, kin, topology, inertia, own_wrench, generalized, armature, factors=factors)
        ready(prog, ["aba"])
    constraint_outputs(prog, kin, equations)
    constraint_outputs(prog, kin, [c.gap_equation(topology.ground) for c in topology.contacts], "contacts")
    from mbcomp.build.drive_equations import drive_outputs
    drive_outputs(prog, kin, drives)
    prog.kin = kin
    return prog


def _ball_segment(prog: Program, kin: Kinematics, quat: list, k0: int, R, pos, V, A):
    """A free rotation about the point ``pos`` (world): the quaternion ``quat`` rotates the
    frame ``R``; speeds ``k0 .. k0 + 2`` are the angular velocity in the rotated frame.

    The motion columns ``S_k = (R' e_k, pos x R' e_k)`` are fixed in the child, so their
    rate is ``V_child x_m S_k`` and the acceleration bias of the segment is
    ``sum_k (V x_m S_k) w_k`` with the velocity ``V`` before it (``S w x_m S w = 0``).
    Returns the new ``R``, ``V`` and ``A``.
    """
    w, x, y, z = quat
    s = prog.let(2 / (w * w + x * x + y * y + z * z))  # any non-zero quaternion rotates rigidly
    local = [[1 - s * (y * y + z * z), s * (x * y - w * z), s * (x * z + w * y)],
             [s * (x * y + w * z), 1 - s * (x * x + z * z), s * (y * z - w * x)],
             [s * (x * z - w * y), s * (y * z + w * x), 1 - s * (x * x + y * y)]]
    local = [prog.lets(row) for row in local]
    R = [[prog.let(dot(R[r], [local[m][col] for m in range(3)])) for col in range(3)] for r in range(3)]
    omega = prog.qd[k0:k0 + 3]
    for j in range(3):
        axis_world = [R[r][j] for r in range(3)]
        kin.S[k0 + j] = axis_world + prog.lets(cross(pos, axis_world))
    Sw = prog.lets([sum((kin.S[k0 + j][r] * omega[j] for j in range(3)), sp.Integer(0)) for r in range(6)])
    A = prog.lets([a + b for a, b in zip(A, motion_cross(V, Sw))])
    V = prog.lets([a + b for a, b in zip(V, Sw)])
    return R, V, A


def _rotate_frame(prog: Program, R, rotation, transpose: bool = False):
    """``R @ rotation`` (or ``R @ rotation^T``) for a joint's constant frame rotation
    (rotated ``Frame``s); ``None`` (identity) leaves ``R`` and the program untouched."""
    if rotation is None:
        return R
    C = [[exact(rotation[j][i] if transpose else rotation[i][j]) for j in range(3)] for i in range(3)]
    return [[prog.let(dot(R[r], [C[m][col] for m in range(3)])) for col in range(3)] for r in range(3)]


def _body_inertia_symbols(body: Body, kin: Kinematics):
    values = kin.param(body, "inertia")
    if len(values) == 3:
        z = sp.Integer(0)
        return [[values[0], z, z], [z, values[1], z], [z, z, values[2]]]
    xx, yy, zz, xy, xz, yz = values
    return [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]]
