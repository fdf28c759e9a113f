"""O(N) forward dynamics: the articulated-body algorithm as a straight-line program.

The dense path builds ``M_bar`` (O(N^2) code) and factorises it at run time (O(N^3));
this module instead appends Featherstone's articulated-body algorithm (ABA) to the
same symbolic program, so that the accelerations come out of O(N) generated code
with no run-time linear algebra.  It reuses what ``equations.build_program`` already
computes: the world-frame motion columns ``S_k`` of every speed, each body's spatial
inertia about the world origin, and each body's bias wrench
``I A_bias + V x* (I V) - f_ext`` (``A_bias``: its spatial acceleration at zero
accelerations).

World-frame spatial quantities about one origin add without transformation, so the
recursion needs no coordinate changes.  Every speed is a node of the recursion (a
joint with several speeds is a chain of massless one-speed nodes; the three columns
of a ball segment are eliminated one after the other, which is an LDL^T of the
segment's positive-definite 3x3 block).  With ``da`` the body's acceleration minus
its bias acceleration:

    backward, k = nv-1 .. 0:  U = I^A S,  D = S.U + armature,  u = tau + Q - S.p^A
                              I^a = I^A - U U^T / D,  p^a = p^A + U u / D  (to the predecessor)
    forward,  k = 0 .. nv-1:  qdd_k = (u - U.da_pred) / D,  da_k = da_pred + S qdd_k

``Q`` is the generalised force of force elements that act on speeds directly (joint
torques, torsion springs, friction) and ``tau`` the run-time generalised force (drives,
user torques).  The result equals ``M_bar^-1 (f_bar + tau)`` of the dense path up to
rounding.  The pivots ``D`` are output as well: a pivot that is not positive means the
mass matrix is singular there, and the compiled ``accelerations`` reports it as the
dense path does.
"""
from __future__ import annotations

from typing import Literal

import numpy as np

from mbcomp.core import c_text, tolerances
from mbcomp.core.errors import ModelError
from mbcomp.core.tolerances import PIVOT_TOLERANCE

#: ``compile(dynamics=...)``: how the tree accelerations are computed.
DYNAMICS = ("auto", "dense", "recursive")

#: ``dynamics="auto"`` chooses the recursive program from this many speeds on.  Measured by
#: ``bench/recursive_crossover.py`` (``results/recursive_crossover.csv``): on the pendulum
#: chain one compiled evaluation costs, recursive over dense, 0.82-0.97 for N = 2..8, 0.83 at
#: 10, 0.77 at 15, 0.73 at 20, 0.45 at 30, 0.30 at 50, while cold compiling costs 15-25% more
#: CPU up to N = 20 (the generated ``aba`` on top of the mass matrix) and less from N = 50 on.
#: From about 12 speeds the evaluation is a fifth cheaper or more: worth the compile time.
CROSSOVER_NV = 12


#: ``dynamics="auto"`` with ``formulation="dae"`` and constraints: the recursive program from
#: this many speeds on.  Measured on a pendulum chain whose tip runs on a rail (2 constraint
#: rows), compiled RK4 with the dense projection after each step: recursive over dense 1.09 at
#: N = 10, 1.00 at 15, 0.96 at 20, 0.76 at 30.
DAE_CROSSOVER_NV = 20


def choose(dynamics: str, topology, owner: str = "compile", formulation: str | None = None,
           ) -> Literal["dense", "recursive"]:
    """The tree dynamics to generate: ``"dense"`` (mass matrix and Cholesky) or
    ``"recursive"`` (articulated-body program).

    ``"auto"`` picks the recursive program for trees without constraints (closed loops,
    sliders, motors) with at least ``CROSSOVER_NV`` speeds, and for constrained models under
    the ``"dae"`` formulation with at least ``DAE_CROSSOVER_NV`` speeds (its compiled KKT solve
    then applies ``M^-1`` by the recursion) and no contacts: the recursive KKT solve has no
    friction rows, so a contact's friction (a parameter, which a run may turn on) would step
    in Python.  ``lagrange`` with constraints works on the dense mass matrix: there the
    recursive program would only add compile time.
    """
    if dynamics not in DYNAMICS:
        raise ModelError(owner, f"dynamics must be one of {', '.join(map(repr, DYNAMICS))}, got {dynamics!r}")
    if dynamics != "auto":
        return dynamics
    if not topology.cut_joints and not topology.constraints:
        return "recursive" if topology.nv >= CROSSOVER_NV else "dense"
    return "recursive" if formulation == "dae" and topology.nv >= DAE_CROSSOVER_NV and not topology.contacts \
        else "dense"


#: Compile the dense ``dynamics`` function without optimisation when the recursive program
#: serves the integrators of a tree (see ``cold_functions``).
DENSE_COLD = True


def cold_functions(dynamics: str, topology) -> tuple[str, ...]:
    """Generated functions that need no optimisation: with the recursive program on a tree
    without constraints or contacts, the dense ``dynamics`` (mass matrix and forces) is only
    called per Python call (``mass_matrix``, ``tree_dynamics``, analyses), never per step, and
    compiling it without optimisation saves most of the compile time the recursive program adds."""
    plain_tree = not (topology.cut_joints or topology.constraints or topology.contacts)
    return ("dynamics",) if DENSE_COLD and dynamics == "recursive" and plain_tree else ()


def _inertia_matrix(I) -> list:
    """The symmetric 6x6 matrix of a ``SpatialInertia`` (``I V = (Ibar w + h x v, m v - h x w)``)."""
    import sympy as sp  # only when the program is built
    m, (hx, hy, hz), Ib = I.mass, I.h, I.Ibar
    z = sp.Integer(0)
    hcross = [[z, -hz, hy], [hz, z, -hx], [-hy, hx, z]]  # [h]x: the block acting on v
    top = [list(Ib[i]) + hcross[i] for i in range(3)]
    bottom = [[hcross[j][i] for j in range(3)] + [m if i == j else z for j in range(3)] for i in range(3)]
    return top + bottom


def _add(A, B) -> list:
    from mbcomp.core.symbolic import total  # sympy's own sums (zeros dropped without sympy's Add)
    return [[total([a, b]) for a, b in zip(ra, rb)] for ra, rb in zip(A, B)]


def _matvec(A, x) -> list:
    from mbcomp.core.symbolic import dot  # sympy: only when the program is built
    return [dot(row, x) for row in A]


def _dot(a, b):
    from mbcomp.core.symbolic import dot  # sympy: only when the program is built
    return dot(a, b)


def speed_tree(topology) -> tuple[list, dict]:
    """``(pred, attach)``: ``pred[k]`` is the speed whose node precedes speed ``k`` in the
    recursion (None at the ground); ``attach[body name]`` is the node (speed index) that
    carries the body, None for a body welded to the ground."""
    pred: list = [None] * topology.nv
    attach: dict = {topology.ground.name: None}
    for body, joint in zip(topology.bodies, topology.tree_joints):
        before = attach[topology.parent_of[body.name].name]
        for k in range(*topology.v_slice[joint.name].indices(topology.nv)):
            pred[k] = before
            before = k
        attach[body.name] = before
    return pred, attach


def aba_outputs(prog, kin, topology, inertia: dict, wrench: dict, generalized: list, armature: dict,
                factors: bool = False) -> None:
    """Append output ``"aba"`` to ``prog``: the tree accelerations (nv) followed by the pivots
    ``D`` (nv), from the run-time generalised forces ``tau``, which become the extra inputs
    ``prog.u[n_inputs:]`` (the compiled ``accelerations`` passes ``[u, tau]``).  With
    ``factors`` (a model with constraints: the dae formulation's KKT solve) also ``W = U / D``
    and ``S`` of every speed (6 nv each, speed-major), with which ``aba_solve`` in C applies
    ``M^-1`` to any generalised force in O(N).

    ``inertia[body]``: world-frame ``SpatialInertia`` about the origin; ``wrench[body]``: the
    body's own bias wrench (not summed over its subtree); ``generalized[k]``: the generalised
    forces of force elements on speed ``k``; ``armature[k]``: reflected rotor inertia added to
    the mass-matrix diagonal.
    """
    import sympy as sp  # only when the program is built (a cached model loads without it)
    from mbcomp.core.symbolic import product, total  # sympy's own expressions, built directly
    nv = topology.nv
    tau = [sp.Symbol(f"tau{k}") for k in range(nv)]
    prog.tau_offset = len(prog.u)
    prog.u = list(prog.u) + tau
    pred, attach = speed_tree(topology)
    zero6 = [sp.Integer(0)] * 6
    IA: list = [None] * nv  # articulated inertia of each node (6x6, symmetric)
    pA: list = [None] * nv  # its bias force
    for body in topology.bodies:
        node = attach[body.name]
        if node is None:
            continue  # welded to the ground: carried by no speed
        I = _inertia_matrix(inertia[body.name])
        IA[node] = I if IA[node] is None else _add(IA[node], I)
        own = wrench[body.name]
        pA[node] = list(own) if pA[node] is None else [total([a, b]) for a, b in zip(pA[node], own)]
    U, W, D, u = [None] * nv, [None] * nv, [None] * nv, [None] * nv
    for k in reversed(range(nv)):
        if IA[k] is None:  # a massless end of the tree (every pivot of it is zero: reported)
            IA[k], pA[k] = [[sp.Integer(0)] * 6 for _ in range(6)], zero6
        Ik = [[prog.let(IA[k][i][j]) if j >= i else None for j in range(6)] for i in range(6)]
        Ik = [[Ik[i][j] if j >= i else Ik[j][i] for j in range(6)] for i in range(6)]
        p = prog.lets(pA[k])
        S = kin.S[k]
        U[k] = prog.lets(_matvec(Ik, S))
        D[k] = prog.let(_dot(S, U[k]) + armature.get(k, 0))
        inv = prog.let(1 / D[k])
        W[k] = prog.lets([x * inv for x in U[k]])
        u[k] = prog.let(tau[k] + generalized[k] - _dot(S, p))
        parent = pred[k]
        if parent is None:
            continue
        Ia = [[total([Ik[i][j], -product(W[k][i], U[k][j])]) for j in range(6)] for i in range(6)]
        pa = [total([a, product(w, u[k])]) for a, w in zip(p, W[k])]
        IA[parent] = Ia if IA[parent] is None else _add(IA[parent], Ia)
        pA[parent] = pa if pA[parent] is None else [total([a, b]) for a, b in zip(pA[parent], pa)]
    qdd, da = [None] * nv, [None] * nv
    for k in range(nv):
        before = zero6 if pred[k] is None else da[pred[k]]
        qdd[k] = prog.let(u[k] / D[k] - _dot(W[k], before))
        da[k] = prog.lets([total([a, product(s, qdd[k])]) for a, s in zip(before, kin.S[k])])
    prog.outputs["aba"] = qdd + D
    if factors:
        prog.outputs["aba"] += [w for k in range(nv) for w in W[k]] + [x for k in range(nv) for x in kin.S[k]]


def aba_sizes(topology, n_inputs: int, factors: bool) -> tuple[tuple[int, int, int], tuple[int, ...]]:
    """``((ABA_NV, ABA_NU, ABA_OUT), ABA_PRED)`` of the C templates for the recursive program:
    speeds, inputs, length of ``aba``'s output (with the factors the dae KKT solve reads when
    ``factors``) and each speed's parent speed (-1 at a root)."""
    nv = topology.nv
    pred, _ = speed_tree(topology)
    return (nv, n_inputs, 14 * nv if factors else 2 * nv), tuple(-1 if k is None else int(k) for k in pred)


def c_dae(topology, ng: int) -> str:
    """C source of the dae formulation's compiled KKT solve on the recursive program, for a
    model with ``ng`` geometric constraint rows (placed after the formulation's own code, whose
    ``dae_accelerations`` it replaces through ``MBCOMP_RECURSIVE_DAE``; the projection after
    each step stays dense).  ``X = M^-1 J_r^T`` column by column by ``aba_solve`` (O(N) each),
    ``(J_r X) lam = rhs - J_r qdd_free``, ``qdd = qdd_free + X lam``: the same Schur complement
    as the dense code, with the same row selection, Baumgarte terms and rank handling.
    The C is ``c/recursive_dae.c``."""
    if ng == 0:
        return ""
    return "\n" + tolerances.c_defines() + c_text.read("mbcomp.build", "recursive_dae.c")


def c_accelerations(nv: int, n_inputs: int, dense: str, factors: bool = False) -> str:
    """C source of ``int accelerations(q, qd, p, u, tau, qdd, work)`` by the generated ``aba``
    (same contract as the dense one: 0, or k + 1 when pivot k is not positive against the
    largest, the same relative threshold as the Cholesky pivots; ``tau`` may be NULL; ``work``
    is not used).  ``dense`` is the dense template, kept as ``dense_accelerations`` for the
    factorisation helpers the dae formulation's code shares.  With ``factors`` (constraints)
    the ``aba`` output carries the factors and ``c_dae`` replaces the dense KKT solve.
    The C is ``c/recursive_accelerations.c`` (threshold ``tolerances.PIVOT_TOLERANCE``)."""
    renamed = dense.replace("int accelerations(", "int dense_accelerations(")
    if renamed.count("int dense_accelerations(") != 1:
        raise AssertionError("the dense accelerations template changed: cannot rename it")
    return (renamed + ("\n#define MBCOMP_RECURSIVE_DAE 1" if factors else "") + "\n" + tolerances.c_defines()
            + c_text.read("mbcomp.build", "recursive_accelerations.c"))


class PythonAccelerations:
    """The Python backend's ``accelerations`` by the generated ``aba`` function (the same
    call contract as the compiled one: ``(status, qdd)`` with status 0, or k + 1 for a pivot
    that is not positive)."""

    def __init__(self, aba, nv: int):
        self.aba, self.nv = aba, nv

    @staticmethod
    def bind_parameters(p):
        """The parameter vector itself (no pointer to bind in Python)."""
        return p

    def __call__(self, q, qd, p, u, tau) -> tuple[int, np.ndarray]:
        nv = self.nv
        extended = list(u) + ([0.0] * nv if tau is None else list(np.asarray(tau, dtype=float)))
        try:
            out = self.aba(np.asarray(q, dtype=float).tolist(), np.asarray(qd, dtype=float).tolist(),
                           p.tolist(), extended)
        except (ZeroDivisionError, OverflowError, ValueError):
            return 1, np.full(nv, np.nan)  # a zero pivot: the caller's dense path diagnoses it
        pivots = np.asarray(out[nv:2 * nv], dtype=float)
        scale = max(float(np.max(np.abs(pivots))) if nv else 0.0, 1e-300)
        bad = np.flatnonzero(~(pivots > PIVOT_TOLERANCE * scale))
        return (int(bad[0]) + 1 if len(bad) else 0), np.asarray(out[:nv], dtype=float)
