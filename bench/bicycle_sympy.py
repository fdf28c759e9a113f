"""The benchmark Whipple bicycle derived with sympy.physics.mechanics (Kane's method with
dependent speeds), the way a sympy user writes it: the peer of bench/bicycle_vs_sympy.py.

Same model, coordinates and conventions as library/whipple_bicycle.toml (z up, x forward;
the paper's parameters; lean and steer positive to the right; wheel angles and pitch about
the paper's y axis, -y here):

    q = (x, y, yaw, lean, pitch, rear_wheel_angle, steer, front_wheel_angle),  u = q'

The rear contact point is (x, y, 0); the rear frame pitches about the rear wheel's axle. Five
velocity constraints (the rear contact's two slip components, the front contact's three
velocity components: the third is the time derivative of the holonomic "front wheel touches
the ground") leave the independent speeds (lean, rear wheel, steer) and make
(x, y, yaw, pitch, front wheel) dependent. ``derive()`` returns the full mass matrix and
forcing of ``[kinematic; dynamic + differentiated constraints]`` (16 x 16) as sympy
matrices of the states and the parameters; ``numeric()`` lambdifies them with common
subexpression elimination.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy as sm
import sympy.physics.mechanics as me

PARAMETER_NAMES = ("w", "c", "lam", "g", "rR", "mR", "IRxx", "IRyy", "xB", "zB", "mB", "IBxx", "IByy", "IBzz",
                   "IBxz", "xH", "zH", "mH", "IHxx", "IHyy", "IHzz", "IHxz", "rF", "mF", "IFxx", "IFyy")
COORDS = ("x", "y", "yaw", "lean", "pitch", "rear_wheel_angle", "steer", "front_wheel_angle")


@dataclass
class Derived:
    """The equations ``mass(q, p) [q'; u'] = forcing(q, u, p)`` (16 rows) and the derivation's wall time (s)."""

    q: list
    u: list      # KanesMethod's order: (u4, u6, u7, u1, u2, u3, u5, u8), lean, rear wheel, steer first
    p: list
    mass: sm.Matrix
    forcing: sm.Matrix
    seconds: float


def derive() -> Derived:
    """Kane's equations of the Whipple bicycle with 5 dependent speeds (sympy's KanesMethod)."""
    start = time.perf_counter()
    q = me.dynamicsymbols("q1:9")
    u = me.dynamicsymbols("u1:9")
    p = sm.symbols(PARAMETER_NAMES)
    P = dict(zip(PARAMETER_NAMES, p))
    w, c, lam, g, rR, rF = P["w"], P["c"], P["lam"], P["g"], P["rR"], P["rF"]
    x, y, yaw, lean, pitch, th_r, steer, th_f = q

    N = me.ReferenceFrame("N")                                  # ground, z up
    A = N.orientnew("A", "Axis", (yaw, N.z))                    # heading
    B = A.orientnew("B", "Axis", (lean, A.x))                   # leaning rear wheel plane
    C = B.orientnew("C", "Axis", (-pitch, B.y))                 # rear frame (pitch about -y)
    D = C.orientnew("D", "Axis", (-th_r, C.y))                  # rear wheel
    head = sm.sin(lam) * C.x - sm.cos(lam) * C.z                # steer axis, pointing down
    E = C.orientnew("E", "Axis", (steer, head))                 # front frame
    F = E.orientnew("F", "Axis", (-th_f, E.y))                  # front wheel
    # angular velocities in terms of u (u = q')
    A.set_ang_vel(N, u[2] * N.z)
    B.set_ang_vel(A, u[3] * A.x)
    C.set_ang_vel(B, -u[4] * B.y)
    D.set_ang_vel(C, -u[5] * C.y)
    E.set_ang_vel(C, u[6] * head)
    F.set_ang_vel(E, -u[7] * E.y)

    O = me.Point("O")
    O.set_vel(N, 0)
    rear_contact = O.locatenew("Pr", x * N.x + y * N.y)
    rear_contact.set_vel(N, u[0] * N.x + u[1] * N.y)
    rear_centre = rear_contact.locatenew("Dr", rR * B.z)
    rear_centre.v2pt_theory(rear_contact, N, B)
    rear_com = rear_centre.locatenew("Bo", P["xB"] * C.x + (-P["zB"] - rR) * C.z)
    rear_com.v2pt_theory(rear_centre, N, C)
    head_point = rear_centre.locatenew("S", (w + c) * C.x - rR * C.z)
    head_point.v2pt_theory(rear_centre, N, C)
    front_centre = head_point.locatenew("Fo", -c * E.x + rF * E.z)
    front_centre.v2pt_theory(head_point, N, E)
    front_com = front_centre.locatenew("Ho", (P["xH"] - w) * E.x + (-P["zH"] - rF) * E.z)
    front_com.v2pt_theory(front_centre, N, E)
    # the front wheel's lowest point: from its centre, down along the wheel plane
    down = (N.z - me.dot(N.z, E.y) * E.y)
    front_contact = front_centre.locatenew("Pf", -rF * down / sm.sqrt(1 - me.dot(N.z, E.y) ** 2))
    rear_contact_material = rear_centre.locatenew("Pr_d", -rR * B.z)
    rear_contact_material.v2pt_theory(rear_centre, N, D)
    front_contact.v2pt_theory(front_centre, N, F)

    def inertia(frame, xx, yy, zz, xz):
        return me.inertia(frame, xx, yy, zz, 0, 0, xz)

    bodies = [
        me.RigidBody("rear_frame", rear_com, C, P["mB"], (inertia(C, P["IBxx"], P["IByy"], P["IBzz"], -P["IBxz"]),
                                                          rear_com)),
        me.RigidBody("rear_wheel", rear_centre, D, P["mR"], (inertia(C, P["IRxx"], P["IRyy"], P["IRxx"], 0),
                                                             rear_centre)),
        me.RigidBody("front_frame", front_com, E, P["mH"], (inertia(E, P["IHxx"], P["IHyy"], P["IHzz"], -P["IHxz"]),
                                                           front_com)),
        me.RigidBody("front_wheel", front_centre, F, P["mF"], (inertia(E, P["IFxx"], P["IFyy"], P["IFxx"], 0),
                                                               front_centre)),
    ]
    loads = [(body.masscenter, -body.mass * g * N.z) for body in bodies]

    velocity_constraints = [
        me.dot(rear_contact_material.vel(N), N.x), me.dot(rear_contact_material.vel(N), N.y),
        me.dot(front_contact.vel(N), N.x), me.dot(front_contact.vel(N), N.y), me.dot(front_contact.vel(N), N.z),
    ]
    independent = [u[3], u[5], u[6]]
    dependent = [u[0], u[1], u[2], u[4], u[7]]
    kane = me.KanesMethod(N, q_ind=list(q), u_ind=independent, u_dependent=dependent,
                          kd_eqs=[qi.diff() - ui for qi, ui in zip(q, u)],
                          velocity_constraints=velocity_constraints,
                          # Cramer's rule: LU's symbolic pivots are zero when upright (NaN there)
                          constraint_solver="CRAMER")
    kane.kanes_equations(bodies, loads)
    # the rows and columns of the speeds are in KanesMethod's order (independent, then dependent)
    return Derived(list(q), list(kane.u), list(p), kane.mass_matrix_full, kane.forcing_full,
                   time.perf_counter() - start)


def numeric(derived: Derived) -> tuple[Callable, float]:
    """``rhs(t, state, p)`` for solve_ivp (state = q then u in ``derived.u`` order, 16 values; p the 26 parameters in
    PARAMETER_NAMES order), lambdified with ``cse=True``, and the lambdify wall time (s)."""
    start = time.perf_counter()
    qs = sm.symbols("q1:9")
    us = sm.symbols([f"s_{ui.name}" for ui in derived.u])
    subs = dict(zip(derived.q, qs)) | dict(zip(derived.u, us))
    mass = me.msubs(derived.mass, subs)
    forcing = me.msubs(derived.forcing, subs)
    both = sm.lambdify((qs, us, derived.p), [mass, forcing], cse=True, modules="numpy")
    seconds = time.perf_counter() - start

    n = len(qs)

    def rhs(t: float, state: np.ndarray, p: np.ndarray) -> np.ndarray:
        mass_value, forcing_value = both(state[:n], state[n:], p)
        return np.linalg.solve(np.asarray(mass_value, dtype=float),
                               np.asarray(forcing_value, dtype=float).ravel())

    return rhs, seconds


if __name__ == "__main__":
    d = derive()
    print(f"derived in {d.seconds:.1f} s: mass {d.mass.shape}, forcing {d.forcing.shape}, "
          f"ops {sm.count_ops(d.forcing)}")
    rhs, s = numeric(d)
    print(f"lambdified in {s:.1f} s")
