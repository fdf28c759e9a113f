"""The N-link 3D pendulum chain of the speed issue, built in each installed peer tool.

Every peer is optional: ``available()`` lists the ones whose package imports, and each
builder raises ``ImportError`` when its package is missing.  Each built model offers

* ``accelerations(q, qd) -> qdd``   (forward dynamics at one state, for validation), and
* ``simulate(t_end, q0, qd0, ...) -> q(t_end)``   (what a user of that tool runs from Python).

The chain (see ``models.pendulum_chain`` for the mbcomp model): link i a uniform rod,
1 kg, 0.5 m, COM at its middle, inertia diag(m L^2/12, m L^2/12, 1e-4) in its own frame,
long axis along the local -z, hanging from a fixed point; revolute i about x, y, x, y, ...
(in the parent frame, which at q = 0 is the child frame); gravity -9.81 along z.

Peers and their fastest settings (each a compiled loop where the tool has one):

* MuJoCo: RK4 with step dt, run as ``mj_step`` in a Python loop, as one ``mj_step(m, d,
  nstep)`` call, or through ``mujoco.rollout`` (MuJoCo's C loop; many initial states on a
  thread pool);
* Pinocchio: ``pin.aba`` as the right-hand side of scipy's ``solve_ivp`` (DOP853), of
  ``scipy.integrate.ode`` with Hairer's Fortran ``dop853`` and of ``odeint`` (Fortran LSODA);
* Exudyn: its C++ ``ObjectKinematicTree`` (minimal coordinates) under its C++ solvers, the
  adaptive ``DOPRI5`` and the fixed-step ``RK67``/``RK44`` (the "fast" module, no range checks);
* sympy.physics.mechanics: Kane's equations, lambdified (slow; not in the default set).

Usage: python bench/peers.py [--sympy-n10] [N ...]
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
    for name, module in (("mujoco", "mujoco"), ("pinocchio", "pinocchio"), ("exudyn", "exudyn"),
                         ("sympy", "sympy.physics.mechanics")):
        if name == "exudyn":
            sys.exudynFast = True   # Exudyn's fastest module (no range checks); read at its import
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
        does to look at the state between steps); ``"nstep"``: a single ``mj_step(m, d, nstep)``;
        ``"rollout"``: ``mujoco.rollout`` (see ``mujoco_rollout``)."""
        if loop == "rollout":
            return mujoco_rollout(self.model, [self.data], t_end, np.atleast_2d(q0), np.atleast_2d(qd0), dt=dt)[0]
        return mujoco_step(self.model, t_end, q0, qd0, dt=dt, loop=loop)


def mujoco_steps(t_end: float, dt: float) -> int:
    """The whole number of steps dt in t_end (ValueError when it is not one)."""
    steps = int(round(t_end / dt))
    if steps < 1 or abs(steps * dt - t_end) > 1e-9 * t_end:
        raise ValueError(f"t_end = {t_end} is not a whole number of steps dt = {dt}")
    return steps


def mujoco_step(model, t_end, q0, qd0, *, dt, loop="nstep"):
    """q(t_end) from ``mj_step`` (a Python loop, or one ``nstep`` call) with step ``dt``;
    RuntimeError when MuJoCo reset the state (its reaction to a diverging step)."""
    import mujoco
    steps = mujoco_steps(t_end, dt)
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
    if abs(data.time - t_end) > 1e-6 * max(1.0, t_end) or data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number:
        raise RuntimeError(f"MuJoCo diverged (ended at t = {data.time})")
    return data.qpos.copy()


#: Steps per ``rollout`` call: rollout returns the state after every step, so long runs go
#: in pieces (each piece starts from the last state of the one before) into one buffer.
ROLLOUT_CHUNK = 2000


def mujoco_rollout(model, datas, t_end, q0s, qd0s, *, dt, chunk: int = ROLLOUT_CHUNK):
    """Final positions ``(batch, nq)`` of one run per row of ``q0s``/``qd0s`` with
    ``mujoco.rollout`` (MuJoCo's C loop; the rows go to a thread pool of ``len(datas)``
    threads).  RuntimeError when a run did not reach ``t_end`` (MuJoCo resets a diverging
    state)."""
    import mujoco
    from mujoco import rollout
    steps = mujoco_steps(t_end, dt)
    model.opt.timestep = dt
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    batch = len(q0s)
    data = datas[0]
    state = np.empty((batch, nstate))
    for i in range(batch):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = q0s[i]
        data.qvel[:] = qd0s[i]
        mujoco.mj_getState(model, data, state[i], spec)
    out = np.empty((batch, min(chunk, steps), nstate))
    done = 0
    while done < steps:
        nstep = min(chunk, steps - done)
        buffer = out[:, :nstep] if nstep == out.shape[1] else np.empty((batch, nstep, nstate))
        rollout.rollout(model, datas if len(datas) > 1 else data, state, nstep=nstep, state=buffer)
        state = buffer[:, -1].copy()
        done += nstep
    if np.any(np.abs(state[:, 0] - t_end) > 1e-6 * max(1.0, t_end)) or not np.all(np.isfinite(state)):
        raise RuntimeError(f"MuJoCo rollout diverged (a run ended at t = {state[:, 0].min()})")
    return state[:, 1:1 + model.nq].copy()


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

    def simulate(self, t_end, q0, qd0, *, tol, solver="solve_ivp"):
        """q(t_end) with rtol = atol = ``tol``; ``solver``: ``"solve_ivp"`` (DOP853 in
        Python), ``"dop853"`` (``scipy.integrate.ode``: Hairer's Fortran DOP853) or
        ``"lsoda"`` (``odeint``: Fortran LSODA)."""
        pin, model, n = self.pin, self.model, self.n
        data = model.createData()
        tau = np.zeros(n)
        aba = pin.aba
        y0 = np.concatenate((q0, qd0))

        def rhs(t, y):
            return np.concatenate((y[n:], aba(model, data, y[:n], y[n:], tau)))

        if solver == "solve_ivp":
            sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=tol, atol=tol)
            if sol.status != 0:
                raise RuntimeError(sol.message)
            return sol.y[:n, -1].copy()
        if solver == "dop853":
            from scipy.integrate import ode
            integrator = ode(rhs).set_integrator("dop853", rtol=tol, atol=tol, nsteps=10 ** 8)
            integrator.set_initial_value(y0, 0.0)
            y = integrator.integrate(t_end)
            if not integrator.successful():
                raise RuntimeError(f"dop853 failed (code {integrator.get_return_code()})")
            return y[:n].copy()
        if solver == "lsoda":
            from scipy.integrate import odeint
            y, info = odeint(rhs, y0, (0.0, t_end), rtol=tol, atol=tol, mxstep=10 ** 8, tfirst=True,
                             full_output=True)
            if info["message"] != "Integration successful.":
                raise RuntimeError(info["message"])
            return y[-1, :n].copy()
        raise ValueError(f"unknown solver {solver!r}")


# -- Exudyn ---------------------------------------------------------------------------------------
class ExudynChain:
    """Exudyn's ``ObjectKinematicTree`` (minimal coordinates, C++) on a ``NodeGenericODE2``;
    ``simulate`` runs ``SolveDynamic`` with one of Exudyn's C++ explicit solvers (no solution
    files, no sensors)."""

    name = "exudyn"

    def __init__(self, n: int, q0=None, qd0=None):
        available()                     # sets sys.exudynFast before the first import
        import exudyn as exu
        self.exu = exu
        self.n = n
        started = time.perf_counter()
        self.mbs = self._build(np.zeros(n) if q0 is None else q0, np.zeros(n) if qd0 is None else qd0)
        self.build_time = time.perf_counter() - started

    def _build(self, q0, qd0):
        exu = self.exu
        from exudyn.itemInterface import NodeGenericODE2, ObjectKinematicTree
        n = self.n
        self._container = exu.SystemContainer()     # the MainSystem lives as long as its container
        mbs = self._container.AddSystem()
        node = mbs.AddNode(NodeGenericODE2(referenceCoordinates=[0.0] * n, initialCoordinates=list(map(float, q0)),
                                           initialCoordinates_t=list(map(float, qd0)), numberOfODE2Coordinates=n))
        joints = [exu.JointType.RevoluteX if _axis(i) == "x" else exu.JointType.RevoluteY for i in range(n)]
        mbs.AddObject(ObjectKinematicTree(
            nodeNumber=node, jointTypes=joints, linkParents=list(range(-1, n - 1)),
            jointTransformations=exu.Matrix3DList([np.eye(3)] * n),
            jointOffsets=exu.Vector3DList([[0.0, 0.0, 0.0]] + [[0.0, 0.0, -LENGTH]] * (n - 1)),
            linkInertiasCOM=exu.Matrix3DList([np.diag([I_TRANSVERSE, I_TRANSVERSE, I_AXIAL])] * n),
            linkCOMs=exu.Vector3DList([[0.0, 0.0, -LENGTH / 2]] * n), linkMasses=[MASS] * n,
            gravity=[0.0, 0.0, -GRAVITY]))
        mbs.Assemble()
        return mbs

    def _settings(self, t_end, solver, tol, steps):
        exu = self.exu
        settings = exu.SimulationSettings()
        ti = settings.timeIntegration
        ti.endTime = float(t_end)
        ti.verboseMode = 0
        ti.solverType = getattr(exu.DynamicSolverType, solver)
        if tol is not None:
            ti.automaticStepSize = True
            ti.numberOfSteps = 10
            ti.absoluteTolerance = ti.relativeTolerance = float(tol)
            ti.minimumStepSize = 1e-12
        else:
            ti.automaticStepSize = False
            ti.numberOfSteps = int(steps)
        settings.solution.file.write = False
        settings.solution.sensors.active = False
        settings.show.computationTime = False
        settings.show.statistics = False
        return settings

    def accelerations(self, q, qd):
        exu = self.exu
        mbs = ExudynChain(self.n, q, qd).mbs
        solver = exu.MainSolverExplicit()
        settings = self._settings(1.0, "RK44", None, 1)
        solver.InitializeSolver(mbs, settings)
        solver.ComputeODE2RHS(mbs)
        rhs = np.array(solver.GetSystemResidual())[:self.n]
        solver.ComputeMassMatrix(mbs)
        mass = np.array(solver.GetSystemMassMatrix())[:self.n, :self.n]
        return np.linalg.solve(mass, rhs)

    def prepare(self, q0, qd0):
        """Rebuild the system with this initial state (outside the timed runs)."""
        self.mbs = self._build(q0, qd0)
        self._q0 = np.array(q0, float)

    def simulate(self, t_end, q0, qd0, *, solver="DOPRI5", tol=None, steps=None):
        """q(t_end): ``tol`` for the adaptive ``DOPRI5`` (rtol = atol), ``steps`` for the
        fixed-step ``RK44``/``RK67``.  The initial state is the one of ``prepare``."""
        if not np.array_equal(np.asarray(q0, float), getattr(self, "_q0", None)) or np.any(qd0):
            self.prepare(q0, qd0)
        settings = self._settings(t_end, solver, tol, steps)
        with _quiet():
            self.exu.SolveDynamic(self.mbs, settings, solverType=settings.timeIntegration.solverType)
        data = self.mbs.systemData
        if abs(data.GetTime() - t_end) > 1e-6 * max(1.0, t_end):
            raise RuntimeError(f"Exudyn stopped at t = {data.GetTime()}")
        q = np.array(data.GetODE2Coordinates())
        if not np.all(np.isfinite(q)):
            raise RuntimeError("Exudyn diverged")
        return q


class _quiet:
    """Silence Exudyn's deprecation warnings and prints during a run."""

    def __enter__(self):
        import warnings
        self._warnings = warnings.catch_warnings()
        self._warnings.__enter__()
        warnings.simplefilter("ignore")

    def __exit__(self, *exc):
        self._warnings.__exit__(*exc)
        return False


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


BUILDERS = {"mujoco": MujocoChain, "pinocchio": PinocchioChain, "exudyn": ExudynChain, "sympy": SympyChain}


def build_peers(n: int, *, sympy_n10: bool = False, sympy: bool = True, log=print) -> dict:
    """``{name: model}`` of every importable peer (sympy only for N <= 5 unless asked, and
    not at all with ``sympy=False``)."""
    peers = {}
    for name, importable in available().items():
        if not importable:
            log(f"  {name}: not installed, skipped")
            continue
        if name == "sympy" and not sympy:
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
