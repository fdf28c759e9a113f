"""The N-link 3D pendulum chain of the speed issue, built in each installed peer tool.

Every peer is optional: ``available()`` lists the ones whose package imports, and each
builder raises ``ImportError`` when its package is missing.  Each built model offers

* ``accelerations(q, qd) -> qdd``   (forward dynamics at one state, for validation), and
* ``simulate(t_end, q0, qd0, ...) -> q(t_end)``   (what a user of that tool runs from Python).

The chain (see ``models.pendulum_chain`` for the mbcomp model): link i a uniform rod,
1 kg, 0.5 m, COM at its middle, inertia diag(m L^2/12, m L^2/12, 1e-4) in its own frame,
long axis along the local -z, hanging from a fixed point; revolute i about x, y, x, y, ...
(in the parent frame, which at q = 0 is the child frame); gravity -9.81 along z.

Usage: python bench/peers.py [--sympy-n10]
    builds every available peer for N = 5 and 10 (sympy: N = 5 only, N = 10 with the flag:
    the derivation takes ~100 s) and asserts that its accelerations agree with mbcomp's to
    1e-10 at random states.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import pendulum_chain  # noqa: E402

LENGTH, MASS, GRAVITY = 0.5, 1.0, 9.81
I_TRANSVERSE, I_AXIAL = MASS * LENGTH ** 2 / 12, 1e-4


def _axis(i: int) -> str:
    return "x" if i % 2 == 0 else "y"


def available() -> dict[str, bool]:
    """``{peer: importable}`` for mujoco, pinocchio and sympy.physics.mechanics."""
    found = {}
    for name, module in (("mujoco", "mujoco"), ("pinocchio", "pinocchio"), ("sympy", "sympy.physics.mechanics")):
        try:
            __import__(module)
            found[name] = True
        except ImportError:
            found[name] = False
    return found


# -- mbcomp ---------------------------------------------------------------------------------------
class MbcompChain:
    """The mbcomp model (bench/models.py), compiled once."""

    name = "mbcomp"

    def __init__(self, n: int, backend: str = "auto"):
        self.n = n
        started = time.perf_counter()
        self.system = pendulum_chain(n).compile(backend=backend)
        self.build_time = time.perf_counter() - started

    def accelerations(self, q, qd):
        return self.system.accelerations(q, qd)

    def simulate(self, t_end, q0, qd0, *, method="DOP853", tol=1e-8, dt=None, integrator="auto"):
        res = self.system.simulate(t_end, q0, qd0, method=method, rtol=tol, atol=tol, dt=dt, integrator=integrator)
        if abs(res.t[-1] - t_end) > 1e-9:
            raise RuntimeError(f"mbcomp stopped at t = {res.t[-1]}")
        return res.q[-1].copy()


# -- MuJoCo ---------------------------------------------------------------------------------------
def mujoco_xml(n: int, dt: float = 1e-3) -> str:
    """MJCF of the chain: hinges alternating x/y, explicit inertials, RK4, no contacts."""
    a = f"{I_TRANSVERSE!r} {I_TRANSVERSE!r} {I_AXIAL!r}"
    body = ""
    for i in reversed(range(n)):
        pos = "0 0 0" if i == 0 else f"0 0 {-LENGTH!r}"
        axis = "1 0 0" if _axis(i) == "x" else "0 1 0"
        body = (f'<body name="link{i}" pos="{pos}">'
                f'<joint name="joint{i}" type="hinge" axis="{axis}" damping="0" armature="0" frictionloss="0"/>'
                f'<inertial pos="0 0 {-LENGTH / 2!r}" mass="{MASS!r}" diaginertia="{a}"/>'
                f"{body}</body>")
    return (f'<mujoco model="chain{n}"><compiler angle="radian"/>'
            f'<option timestep="{dt!r}" integrator="RK4" gravity="0 0 {-GRAVITY!r}">'
            f'<flag contact="disable"/></option>'
            f"<worldbody>{body}</worldbody></mujoco>")


class MujocoChain:
    """MuJoCo model from an MJCF string; ``simulate`` steps ``mj_step`` in a Python loop."""

    name = "mujoco"

    def __init__(self, n: int):
        import mujoco
        self.mujoco = mujoco
        self.n = n
        started = time.perf_counter()
        self.model = mujoco.MjModel.from_xml_string(mujoco_xml(n))
        self.build_time = time.perf_counter() - started
        assert self.model.nq == n and self.model.nv == n
        assert self.model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
        assert self.model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
        self.data = mujoco.MjData(self.model)

    def accelerations(self, q, qd):
        d = self.data
        d.qpos[:] = q
        d.qvel[:] = qd
        self.mujoco.mj_forward(self.model, d)
        return d.qacc.copy()

    def simulate(self, t_end, q0, qd0, *, dt, loop="python"):
        """RK4 with step dt; ``loop="python"``: one ``mj_step`` call per step (what a user
        does to look at the state between steps); ``"nstep"``: a single ``mj_step(m, d, nstep)``."""
        mujoco, model = self.mujoco, self.model
        steps = int(round(t_end / dt))
        if abs(steps * dt - t_end) > 1e-9 * t_end:
            raise ValueError(f"t_end = {t_end} is not a whole number of steps dt = {dt}")
        model.opt.timestep = dt
        data = mujoco.MjData(model)
        data.qpos[:] = q0
        data.qvel[:] = qd0
        if loop == "python":
            step = mujoco.mj_step
            for _ in range(steps):
                step(model, data)
        else:
            mujoco.mj_step(model, data, nstep=steps)
        if abs(data.time - t_end) > 1e-6:
            raise RuntimeError(f"MuJoCo ended at t = {data.time}")
        return data.qpos.copy()


# -- Pinocchio ------------------------------------------------------------------------------------
class PinocchioChain:
    """Pinocchio model built programmatically; ``pin.aba`` as the right-hand side of
    scipy's ``solve_ivp``."""

    name = "pinocchio"

    def __init__(self, n: int):
        import pinocchio as pin
        self.pin = pin
        self.n = n
        started = time.perf_counter()
        model = pin.Model()
        model.gravity = pin.Motion(np.array([0.0, 0.0, -GRAVITY]), np.zeros(3))
        parent = 0
        inertia = pin.Inertia(MASS, np.array([0.0, 0.0, -LENGTH / 2]), np.diag([I_TRANSVERSE, I_TRANSVERSE, I_AXIAL]))
        for i in range(n):
            placement = pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.0 if i == 0 else -LENGTH]))
            joint = pin.JointModelRX() if _axis(i) == "x" else pin.JointModelRY()
            parent = model.addJoint(parent, joint, placement, f"joint{i}")
            model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
        self.model = model
        self.data = model.createData()
        self.build_time = time.perf_counter() - started
        assert model.nq == n and model.nv == n

    def accelerations(self, q, qd):
        return self.pin.aba(self.model, self.data, np.asarray(q, float), np.asarray(qd, float), np.zeros(self.n)).copy()

    def simulate(self, t_end, q0, qd0, *, tol):
        pin, model, n = self.pin, self.model, self.n
        data = model.createData()
        tau = np.zeros(n)
        aba = pin.aba

        def rhs(t, y):
            return np.concatenate((y[n:], aba(model, data, y[:n], y[n:], tau)))

        sol = solve_ivp(rhs, (0.0, t_end), np.concatenate((q0, qd0)), method="DOP853", rtol=tol, atol=tol)
        if sol.status != 0:
            raise RuntimeError(sol.message)
        return sol.y[:n, -1].copy()


# -- sympy.physics.mechanics ----------------------------------------------------------------------
class SympyChain:
    """Kane's equations from sympy.physics.mechanics; M(q) and forcing(q, u) lambdified with
    cse=True; qdd = solve(M, forcing) as the right-hand side of scipy's DOP853."""

    name = "sympy"

    def __init__(self, n: int):
        import sympy as sp
        import sympy.physics.mechanics as me
        self.n = n
        started = time.perf_counter()
        q = me.dynamicsymbols(f"q0:{n}")
        u = me.dynamicsymbols(f"u0:{n}")
        world = me.ReferenceFrame("N")
        origin = me.Point("O")
        origin.set_vel(world, 0)
        parent, joint_point = world, origin
        bodies, loads = [], []
        for i in range(n):
            frame = me.ReferenceFrame(f"A{i}")
            axis = parent.x if _axis(i) == "x" else parent.y
            frame.orient_axis(parent, axis, q[i])
            frame.set_ang_vel(parent, u[i] * axis)
            com = joint_point.locatenew(f"G{i}", -LENGTH / 2 * frame.z)
            com.v2pt_theory(joint_point, world, frame)
            tip = joint_point.locatenew(f"P{i}", -LENGTH * frame.z)
            tip.v2pt_theory(joint_point, world, frame)
            inertia = me.inertia(frame, I_TRANSVERSE, I_TRANSVERSE, I_AXIAL)
            bodies.append(me.RigidBody(f"B{i}", com, frame, MASS, (inertia, com)))
            loads.append((com, -MASS * GRAVITY * world.z))
            parent, joint_point = frame, tip
        kane = me.KanesMethod(world, q_ind=q, u_ind=u, kd_eqs=[q[i].diff() - u[i] for i in range(n)])
        kane.kanes_equations(bodies, loads)
        qs, us = sp.symbols(f"q0:{n}"), sp.symbols(f"u0:{n}")
        subs = dict(zip(q, qs)) | dict(zip(u, us))
        mass = me.msubs(kane.mass_matrix, subs)
        forcing = me.msubs(kane.forcing, subs)
        self.derive_time = time.perf_counter() - started
        self._mass = sp.lambdify([qs], mass, "numpy", cse=True)
        self._forcing = sp.lambdify([qs, us], forcing, "numpy", cse=True)
        self.build_time = time.perf_counter() - started

    def accelerations(self, q, qd):
        return np.linalg.solve(np.asarray(self._mass(q), float), np.asarray(self._forcing(q, qd), float).ravel())

    def simulate(self, t_end, q0, qd0, *, tol):
        n, mass, forcing, solve = self.n, self._mass, self._forcing, np.linalg.solve

        def rhs(t, y):
            q, u = y[:n], y[n:]
            return np.concatenate((u, solve(mass(q), forcing(q, u).ravel())))

        sol = solve_ivp(rhs, (0.0, t_end), np.concatenate((q0, qd0)), method="DOP853", rtol=tol, atol=tol)
        if sol.status != 0:
            raise RuntimeError(sol.message)
        return sol.y[:n, -1].copy()


BUILDERS = {"mujoco": MujocoChain, "pinocchio": PinocchioChain, "sympy": SympyChain}


def build_peers(n: int, *, sympy_n10: bool = False, log=print) -> dict:
    """``{name: model}`` of every importable peer (sympy only for N <= 5 unless asked)."""
    peers = {}
    for name, importable in available().items():
        if not importable:
            log(f"  {name}: not installed, skipped")
            continue
        if name == "sympy" and n > 5 and not sympy_n10:
            log(f"  sympy: N = {n} skipped (derivation is slow; pass --sympy-n10)")
            continue
        peers[name] = BUILDERS[name](n)
        log(f"  {name}: built in {peers[name].build_time:.3g} s")
    return peers


def validate(reference: MbcompChain, peer, states: int = 5, tol: float = 1e-10, seed: int = 0,
             relative: bool = False) -> float:
    """Max |qdd_peer - qdd_mbcomp| (rad/s^2) over random states (q uniform in [-pi, pi],
    qd in [-2, 2]); AssertionError above ``tol`` (times max(1, max |qdd|) when ``relative``:
    for long chains, whose mass matrices are ill-conditioned at random states, every pair
    of the three tools differs by ~1e-10 at N = 50)."""
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(states):
        q = rng.uniform(-np.pi, np.pi, reference.n)
        qd = rng.uniform(-2.0, 2.0, reference.n)
        a_ref = reference.accelerations(q, qd)
        a_peer = peer.accelerations(q, qd)
        diff = float(np.max(np.abs(a_peer - a_ref)))
        worst = max(worst, diff)
        bound = tol * max(1.0, float(np.max(np.abs(a_ref)))) if relative else tol
        assert diff <= bound, (f"{peer.name} N={reference.n}: accelerations differ from mbcomp by {diff:.3g} "
                                     f"at q={q.tolist()}, qd={qd.tolist()}:\n{a_peer}\nvs\n{a_ref}")
    return worst


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sympy-n10", action="store_true", help="also derive the N = 10 chain with sympy (~100 s)")
    parser.add_argument("sizes", nargs="*", type=int, default=[5, 10])
    args = parser.parse_args(argv)
    for n in args.sizes:
        print(f"N = {n}")
        ref = MbcompChain(n)
        for name, peer in build_peers(n, sympy_n10=args.sympy_n10).items():
            worst = validate(ref, peer)
            print(f"  {name}: max |qdd - qdd_mbcomp| = {worst:.2g} rad/s^2 over 5 random states (<= 1e-10) OK")


if __name__ == "__main__":
    main()
