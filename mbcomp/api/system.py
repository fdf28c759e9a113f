"""System: the compiled model's numeric API (immutable; parameters rebind, never recompile)."""
from __future__ import annotations

import copy
from typing import Any, Mapping

import numpy as np

from mbcomp.spec.components.values import name_of
from mbcomp.core import checks
from mbcomp.core.rotations import cross
from mbcomp.core.errors import ModelError
from mbcomp.codegen.fastcall import DECLINE
from mbcomp.compiled.kernel import Kernel
from mbcomp.compiled.collision_kernel import with_collisions
from mbcomp.build.layout import body_fields
from mbcomp.core.result import Energy  # noqa: F401 - its old home; mbcomp.Energy
from mbcomp.core.params import validate


class BodyState:
    """Pose and motion of a body (at its COM or a given point), all in the world frame.

    position (m), velocity (m/s), acceleration (m/s^2), rotation (3x3, body to world),
    angular_velocity (rad/s), angular_acceleration (rad/s^2).  The accelerations are
    solved for on first access, so pose and velocity stay available where the
    dynamics are singular (an Euler-angle joint at gimbal lock).
    """

    def __init__(self, position, velocity, rotation, angular_velocity, accelerations):
        self.position, self.velocity = position, velocity
        self.rotation, self.angular_velocity = rotation, angular_velocity
        self._accelerations = accelerations
        self._solved = None

    def _solve(self):
        if self._solved is None:
            self._solved = self._accelerations()
        return self._solved

    @property
    def acceleration(self) -> np.ndarray:
        return self._solve()[0]

    @property
    def angular_acceleration(self) -> np.ndarray:
        return self._solve()[1]

    def __repr__(self) -> str:
        return f"BodyState(position={self.position}, velocity={self.velocity})"


class System:
    """A compiled model: the numeric API of API.md.  Never modified by any call.

    ``q`` is always every tree coordinate in ``coords`` order (array or ``{name: value}``);
    ``qd`` the speeds in ``speeds`` order (a screw coordinate's speed is its rate and
    shares its name; a ball has 4 coordinates, a quaternion, and 3 speeds, an angular
    velocity); accelerations, mass matrices, holding forces and ``tau`` are in speed
    space (``tau``: an array of ``len(speeds)`` or a callable ``(t, q, qd)``).
    """

    def __init__(self, compiled, formulation, parameters: dict):
        object.__setattr__(self, "_compiled", compiled)
        object.__setattr__(self, "_formulation", formulation)
        object.__setattr__(self, "_parameters", dict(parameters))
        # (with collisions, the kernel's contacts include their features: compiled/collision_kernel.py)
        object.__setattr__(self, "_kernel", with_collisions(Kernel(compiled, parameters)))
        object.__setattr__(self, "_p", self._kernel.p)
        object.__setattr__(self, "_fast", None)  # (calls, tree calls, body points): _bind_fast()

    def __setattr__(self, name, value):
        raise AttributeError("System is immutable: use with_parameters() for new parameter values")

    def __reduce__(self):
        model, formulation, options, backend = self._compiled.recipe
        return rebuild_system, (model, formulation, options, backend, self._parameters)

    # -- description -----------------------------------------------------------------
    @property
    def coords(self) -> tuple[str, ...]:
        return self._compiled.topology.coords

    @property
    def nq(self) -> int:
        return self._compiled.topology.nq

    @property
    def speeds(self) -> tuple[str, ...]:
        """Names of the generalised speeds (``qd``), ``nv`` of them."""
        return self._compiled.topology.speeds

    @property
    def nv(self) -> int:
        return self._compiled.topology.nv

    def integrate(self, q: Any, dv: Any) -> np.ndarray:
        """The coordinates reached from ``q`` by the step ``dv`` in speed space: ``q + dv`` on
        screw coordinates, a rotation by the vector ``dv`` (rad, child frame) on a ball's
        quaternion (the result normalised)."""
        return self.topology.state_map.integrate(self.state_vector(q), self.speed_vector(dv, "dv"))

    def difference(self, q0: Any, q1: Any) -> np.ndarray:
        """The step ``dv`` (speed space) with ``integrate(q0, dv) = q1`` (the shorter rotation
        for a ball)."""
        return self.topology.state_map.difference(self.state_vector(q0, "q0"), self.state_vector(q1, "q1"))

    def coordinate_rates(self, q: Any, qd: Any) -> np.ndarray:
        """``q' = G(q) qd``: the coordinates' rates for the speeds ``qd`` (``qd`` itself without
        ball joints; a ball's quaternion rate ``q (0, w) / 2``)."""
        return self.topology.state_map.qdot(self.state_vector(q), self._velocity(qd))

    @property
    def extra_states(self) -> tuple[str, ...]:
        """States of drive elements (motor currents, PID integrals): ``"component.state"``."""
        return self._compiled.drives.states

    @property
    def states(self) -> tuple[str, ...]:
        """Every state of a simulation: coordinates, the speeds (``NAME_d`` for a coordinate's
        rate, a ball's by their own names), then the states of drive elements (``extra_states``)."""
        return (tuple(self.coords) + tuple(f"{c}_d" if c in self.coords else c for c in self.speeds)
                + self.extra_states)

    def extra_state_vector(self, x0: Any = None) -> np.ndarray:
        """Initial values of ``extra_states`` from ``{name: value}`` (missing ones 0)."""
        names = self.extra_states
        z = np.zeros(len(names))
        if x0 is None:
            return z
        if not isinstance(x0, Mapping):
            raise ModelError("x0", f"must be a dict {{state name: value}}, got {x0!r}")
        for key, value in x0.items():
            if key not in names:
                raise ModelError("x0", f"unknown state {key!r}; the states of drive elements are {list(names)}")
            try:
                z[names.index(key)] = float(value)
            except (TypeError, ValueError):
                raise ModelError("x0", f"{key!r} must be a number, got {value!r}") from None
            if not np.isfinite(z[names.index(key)]):
                raise ModelError("x0", f"{key!r} must be finite, got {value!r}")
        return z

    def integration_path(self, method: Any = "DOP853", tau: Any = None, integrator: str = "auto") -> str:
        """Which stepping ``simulate`` takes with these arguments: ``"compiled"`` (the loop
        compiled with the model: no Python between steps), else ``"scipy: <why>"``, scipy's
        stepping of the compiled right-hand side, and the reason (a scipy method asked for,
        a Python callable in the model or in ``tau``, ``integrator="scipy"``, a formulation
        option that steps in Python, no C compiler).  ``Result.stats["path"]`` records it."""
        from mbcomp.core.run_options import RunOptions
        from mbcomp.run.paths import choose_path
        options = RunOptions(1.0, method=method, integrator=integrator)
        return str(choose_path(self._kernel, self._formulation, options, tau))

    @property
    def has_drives(self) -> bool:
        """True when drive elements (drives, motors, signal torques, PIDs) act on the model."""
        return bool(self._compiled.drives.elements)

    def drive_outputs(self, t: float, q: np.ndarray, qd: np.ndarray, z: np.ndarray):
        """``(tau_drive, z_rates)``: the drive elements' generalised forces (nv, speed space)
        and the rates of their states (nz) at time ``t`` (s), with states ``z`` in
        ``extra_states`` order (raw arrays, unchecked: the simulation's hot path)."""
        return self._kernel.drive_outputs(t, q, qd, z)

    def _applied(self, tau: Any, t: float, q: np.ndarray, qd: np.ndarray, states: Any = None):
        """``tau`` plus the drive elements' generalised forces (their states from ``states``:
        a dict by name or an array in ``extra_states`` order; 0 when not given)."""
        tau = self._kernel.tau(tau, t, q, qd)
        if not self._compiled.drives.elements:
            return tau
        if states is None or isinstance(states, Mapping):
            z = self.extra_state_vector(states)
        else:
            z = np.asarray(states, dtype=float).reshape(-1)
            if z.shape != (len(self.extra_states),):
                raise ModelError("states", f"must give {len(self.extra_states)} values {list(self.extra_states)}")
        drive = self.drive_outputs(t, q, qd, z)[0]
        return drive if tau is None else tau + drive

    @property
    def ndof(self) -> int:
        """Degrees of freedom left after constraints."""
        return self._formulation.ndof

    @property
    def redundant_constraints(self) -> list[str]:
        """Constraint equations found dependent on the others (by rank) and left out."""
        return list(self._formulation.redundant)

    @property
    def constraint_names(self) -> list[str]:
        """Every constraint (loop-closing joints, sliders, motors) by name."""
        cs = self._formulation.constraints
        return [] if cs is None else [name for name, _, _ in cs.groups]

    @property
    def formulation(self) -> str:
        return self._formulation.name

    @property
    def topology(self):
        return self._kernel.topology   # (the compiled topology, with collision features among the contacts)

    @property
    def kernel(self) -> Kernel:
        """The numeric core under this System (raw arrays in, no checks): generated-function
        calls, tree solve, diagnosis; for analyses and extensions built on the System."""
        return self._kernel

    @property
    def name(self) -> str:
        """The name of the model this System was compiled from."""
        return self._compiled.model_name

    @property
    def parameters(self) -> dict[str, Any]:
        """``{"component.attribute": value}`` (a copy; use ``with_parameters`` to change)."""
        return dict(self._parameters)

    def parameter(self, key: str, default: Any = None) -> Any:
        """The value of one parameter ``"component.attribute"`` (no copy of the whole table)."""
        return self._parameters.get(key, default)

    @property
    def backend(self) -> str:
        return self._compiled.functions.name

    @property
    def compile_time(self) -> float:
        return self._compiled.compile_time

    def with_parameters(self, values: Mapping[str, Any] | None) -> "System":
        """A new System with some parameter values replaced (shares the compiled code).

        Each value is checked by the same ``ParameterSpec`` validation as the component's
        constructor (``mbcomp.core.params.validate``); a ``ModelError`` names the component and
        the attribute."""
        if values is not None and not isinstance(values, Mapping):
            raise ModelError("parameters", f"must be a mapping {{'component.attribute': value}}, got {values!r}")
        if not values:
            return self
        derivation = getattr(self._compiled, "derivation", None)
        merged = dict(self._parameters)
        if derivation is not None and any(key in derivation.parameters for key in values):
            # Sub-model parameters: every component value derived from them follows, as a
            # fresh build gives it (the components' constructors validated those values);
            # component values given in the same call win.
            changes = {k: v for k, v in values.items() if k in derivation.parameters}
            merged.update(derivation.apply(self._parameters, changes))
            values = {k: v for k, v in values.items() if k not in changes}
        for key, value in values.items():
            found = self._compiled.parameter_spec(key) if key in merged else None
            if found is None:
                known = set(merged) | set(getattr(derivation, "parameters", None) or ())
                raise ModelError(f"System {self._compiled.model_name!r}", unknown_parameter(key, known))
            owner, spec = found
            new = validate(spec, value, owner)  # the constructors' validator
            if np.shape(new) != np.shape(merged[key]):
                raise ModelError(owner, f"{spec.name} {new!r} changes the model's structure (shape "
                                 f"{np.shape(merged[key])} -> {np.shape(new)}); change the model and compile again")
            merged[key] = new
        return System(self._compiled, self._formulation, merged)

    # -- state handling -------------------------------------------------------------------
    def state_vector(self, values: Any, what: str = "q") -> np.ndarray:
        """``values`` (array or ``{coordinate: value}``) as a checked float array of length nq.

        Quaternions are normalised (any non-zero one is accepted); in a dict, a ball's
        quaternion may be left out entirely (the identity)."""
        state_map = self.topology.state_map
        arr = self._checked_vector(values, what, self.coords, "coordinate",
                                   None if state_map.identity else state_map.neutral())
        return arr if state_map.identity else state_map.normalize(arr)

    def speed_vector(self, values: Any, what: str = "qd") -> np.ndarray:
        """``values`` (array or ``{speed: value}``) as a checked float array of length nv."""
        return self._checked_vector(values, what, self.speeds, "speed")

    def _checked_vector(self, values: Any, what: str, coords: tuple, noun: str, neutral=None) -> np.ndarray:
        if type(values) is np.ndarray and values.dtype == np.float64 and values.shape == (len(coords),):
            total = float(values.sum())  # fast path: a finite sum means finite entries
            if total - total == 0.0:
                return values
        if isinstance(values, Mapping):
            unknown = [k for k in values if k not in coords]
            if unknown:
                raise ModelError(f"{what}", f"unknown {noun}(s) {unknown}; {noun}s are {list(coords)}")
            missing = [c for c in coords if c not in values]
            if missing and neutral is not None:
                values = self._default_quaternions(values, missing, neutral)
                missing = [c for c in coords if c not in values]
            if missing:
                raise ModelError(f"{what}", f"missing {noun}(s) {missing}")
            values = [values[c] for c in coords]
        try:
            arr = np.asarray(values, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise ModelError(f"{what}", f"must be {len(coords)} numbers, got {values!r}") from None
        if arr.shape != (len(coords),):
            raise ModelError(f"{what}", f"has length {arr.size}, the model has {len(coords)} {noun}s {list(coords)}")
        if not np.all(np.isfinite(arr)):
            bad = [coords[i] for i in np.flatnonzero(~np.isfinite(arr))]
            raise ModelError(f"{what}", f"is not finite for {bad}")
        return arr

    def _default_quaternions(self, values: Mapping, missing: list, neutral: np.ndarray) -> dict:
        """``values`` with every wholly missing quaternion set to the identity."""
        values = dict(values)
        for start in self.topology.state_map.quat_q:
            names = self.coords[start:start + 4]
            if all(n in missing for n in names):
                values.update({n: neutral[start + i] for i, n in enumerate(names)})
        return values

    def _velocity(self, qd: Any) -> np.ndarray:
        return np.zeros(self.nv) if qd is None else self.speed_vector(qd, "qd")

    # -- the fast path of the evaluation calls ------------------------------------------------------
    def _bind_fast(self) -> tuple:
        """``(calls, tree, points)``: the kernel's fast calls where the coordinates need no
        normalising (no quaternions; else a stand-in that always declines), the same for the
        accelerations and reactions where the formulation adds nothing to the tree's (no
        constraints, no drive elements), and a dict of body points (``body_state``).  Every
        call returns None for inputs it does not take, and the checked path runs."""
        fast = self._fast
        if fast is None:
            calls = self._kernel.fast_calls() if self.topology.state_map.identity else None
            calls = calls or DECLINE
            tree = calls if self._formulation.constraints is None and not self._compiled.drives.elements else DECLINE
            fast = (calls, tree, {})
            object.__setattr__(self, "_fast", fast)
        return fast

    # -- public API -------------------------------------------------------------------------------
    def mass_matrix(self, q: Any, t: float = 0.0) -> np.ndarray:
        """(nv, nv) tree mass matrix ``M_bar = T^T M T`` (kg, kg m, kg m^2 by speed type)."""
        M = (self._fast or self._bind_fast())[0].mass_matrix(q)
        if M is not None:
            return M
        q = self.state_vector(q)
        M, _ = self._kernel.dynamics(t, q, np.zeros(self.nv))
        return self._kernel.check_finite(M, "mass matrix", q)

    def accelerations(self, q: Any, qd: Any, t: float = 0.0, tau: Any = None, states: Any = None) -> np.ndarray:
        """(nv,) accelerations (rates of the speeds), consistent with every constraint (drive
        elements act with their ``states``, by name; 0 when not given).

        A float64 ndarray of the right length takes a direct call of the compiled code
        (``mbcomp.codegen.fastcall``); anything else is converted and checked.  With
        constraints, the compiled KKT solve of the compiled loops answers
        (``Formulation.compiled_solve``; the dae formulation's includes its Baumgarte terms),
        the Python solve where there is no C or at a dead point at rest."""
        if tau is None and states is None:
            qdd = (self._fast or self._bind_fast())[1].accelerations(q, qd)
            if qdd is not None:
                return qdd
        q, qd = self.state_vector(q), self._velocity(qd)
        applied = self._applied(tau, t, q, qd, states)
        solved = self._compiled_solution(t, q, qd, applied)
        if solved is not None:
            return solved[0]
        return self._formulation.accelerations(self._kernel, t, q, qd, applied)

    def _compiled_solution(self, t: float, q: np.ndarray, qd: np.ndarray, applied, offsets: dict | None = None):
        """``(qdd, lam)`` from the compiled KKT solve (``Formulation.compiled_solve``: the C of
        the compiled loops), or None where the formulation's Python solve answers: no
        constraints, no C, a dead point at rest, a failure it explains."""
        solver = self.__dict__.get("_solver", False)
        if solver is False:  # (bound on first use)
            solver = self._formulation.compiled_solve(self._kernel)
            object.__setattr__(self, "_solver", solver)
        return None if solver is None else solver.solve(t, q, qd, applied, offsets)

    def reactions(self, q: Any, qd: Any, t: float = 0.0, tau: Any = None, offsets: dict | None = None,
                  contacts: Any = (), states: Any = None) -> dict[str, np.ndarray]:
        """``{constraint name: reaction}``: a motor's torque (N m) or force (N) along its
        coordinate; a slider's force (N) on the body along the line's two normals; a
        loop-closing joint's force on its child (N, world x y z) then its torques (N m);
        and the normal force (N) of each contact in ``contacts`` held closed.  The multipliers
        come from the compiled KKT solve, as in ``accelerations`` (with held contacts their
        rows and friction modes too: ``contact_forces``)."""
        if tau is None and states is None and offsets is None and not contacts and \
                (self._fast or self._bind_fast())[1].check(q, qd):
            return {}  # a tree without drive elements and no contact held closed: no reactions
        from mbcomp.formulations.impact import contact_indices
        q, qd = self.state_vector(q), self._velocity(qd)
        closed = (contacts if isinstance(contacts, tuple) else tuple(contacts)) if contacts and all(
            isinstance(i, (int, np.integer)) for i in contacts) \
            else tuple(contact_indices(self._kernel, contacts)) if contacts else ()
        applied = self._applied(tau, t, q, qd, states)
        solved = self._compiled_contact_solution(t, q, qd, applied, offsets, closed) if closed \
            else self._compiled_solution(t, q, qd, applied, offsets)
        if solved is not None:
            return self._formulation.reactions_of(self._kernel, q, solved[1], closed)
        return self._formulation.reactions(self._kernel, t, q, qd, applied, offsets, closed)

    def _compiled_contact_solution(self, t: float, q: np.ndarray, qd: np.ndarray, applied, offsets: dict | None,
                                   contacts: tuple):
        """``(qdd, lam, tangential, basis)`` from the compiled KKT solve with the held ``contacts``
        (and their friction modes: ``Formulation.compiled_solve``), or None where the Python
        solve answers (as ``_compiled_solution``; Painleve's paradox, a singular set of held
        contacts); ``basis``: the contacts' world bases, or None (``CompiledSolve.basis``).
        One solver per set of contacts and modes, kept for the next call."""
        solvers = self.__dict__.get("_contact_solvers")
        if solvers is None:
            solvers = {}
            object.__setattr__(self, "_contact_solvers", solvers)
        key = (tuple(int(i) for i in contacts), tuple(sorted(getattr(contacts, "stick", ()))),
               tuple(sorted(getattr(contacts, "slip", {}))))
        solver = solvers.get(key, False)
        if solver is False:
            if len(solvers) >= 64:  # (a long run's sets: the oldest go)
                solvers.pop(next(iter(solvers)))
            solver = solvers[key] = self._formulation.compiled_solve(self._kernel, contacts, q, qd)
        solved = None if solver is None else solver.solution(t, q, qd, applied, offsets, contacts)
        return None if solved is None else (*solved, solver.basis)

    def contact_forces(self, q: Any, qd: Any, t: float = 0.0, tau: Any = None, offsets: dict | None = None,
                       contacts: Any = (), states: Any = None) -> dict[str, np.ndarray]:
        """``{contact name: (3,) N}``: the force (world frame, on the body: normal plus
        friction) of each contact in ``contacts`` held closed (indices, or a run's closed set
        with its friction modes, as ``Result.closed_contacts`` records them).  The compiled
        KKT solve with the contacts' rows and friction answers (``dae_evaluate_friction``),
        the Python solve where there is no C and where it explains a failure (Painleve's
        paradox, a singular set of held contacts)."""
        q, qd = self.state_vector(q), self._velocity(qd)
        closed = contacts if contacts and all(isinstance(i, (int, np.integer)) for i in contacts) else ()
        applied = self._applied(tau, t, q, qd, states)
        solved = self._compiled_contact_solution(t, q, qd, applied, offsets, closed) if closed else None
        if solved is not None:
            return self._formulation.contact_forces_of(self._kernel, q, qd, solved[1], solved[2], closed, solved[3])
        return self._formulation.contact_forces(self._kernel, t, q, qd, applied, offsets, closed)

    def holding_forces(self, q: Any, t: float = 0.0) -> np.ndarray:
        """(nv,) generalised forces that, applied, hold the system at rest at ``q``
        (minus the gravity, spring and applied generalised forces at zero speed)."""
        q = self.state_vector(q)
        qd = np.zeros(self.nv)
        _, f = self._kernel.dynamics(t, q, qd)
        return self._kernel.check_finite(-f, "holding forces", q)

    def energy(self, q: Any, qd: Any, t: float = 0.0) -> Energy:
        """Kinetic and potential energy (J); the potential counts gravity and springs."""
        q, qd = self.state_vector(q), self._velocity(qd)
        kinetic, potential = self._kernel.call("energy", q, qd)
        return Energy(float(kinetic), float(potential))

    def evaluate_series(self, name: str, q: Any, qd: Any = None, what: str = "evaluate_series") -> np.ndarray:
        """The generated function ``name`` ("energy", "constraints", "kinematics", ...) at many
        states (rows of ``q`` (m, nq), ``qd`` (m, nv); zero speeds when None) in one call: (m, size)."""
        q = np.asarray(q, dtype=float)
        qd = np.zeros((len(q), self.nv)) if qd is None else np.asarray(qd, dtype=float)
        if q.ndim != 2 or qd.ndim != 2 or len(q) != len(qd) or q.shape[1] != self.nq or qd.shape[1] != self.nv:
            raise ModelError(what, f"q and qd must be (m, {self.nq}) and (m, {self.nv}) arrays of states, got "
                             f"shapes {q.shape} and {qd.shape}")
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(qd))):
            raise ModelError(what, "the states must be finite")
        return self._kernel.evaluate_series(name, q, qd)

    def energy_series(self, q: Any, qd: Any) -> Energy:
        """Kinetic and potential energy (J) at many states (rows of ``q``, ``qd``): arrays of
        shape (m,), from one call of the generated code."""
        out = self.evaluate_series("energy", q, qd, what="energy_series")
        return Energy(out[:, 0].copy(), out[:, 1].copy())

    def constraint_violation_series(self, t: Any, q: Any, offsets: dict | None = None) -> np.ndarray:
        """max |g(q, t)| at many samples (``t`` (m,), rows of ``q``): the geometric rows
        from one call of the generated code."""
        t = np.asarray(t, dtype=float).reshape(-1)
        return self._formulation.constraint_violation_series(self._kernel, t, np.asarray(q, dtype=float), offsets)

    def body_state(self, body: Any, q: Any, qd: Any = None, t: float = 0.0, point: Any = None,
                   tau: Any = None) -> BodyState:
        """Position, velocity, acceleration of the COM (or body ``point``, m, body frame),
        rotation, angular velocity and acceleration, all in the world frame."""
        calls, _, points = self._fast or self._bind_fast()
        name = body if type(body) is str else name_of(body)
        known = points.get(name) if point is None else None
        if known is not None:  # a body seen before: one direct call of the compiled kinematics
            out = calls.body(q, qd, known[0], known[1])
            if out is not None:
                position, velocity, R, w, kin = out
                layout, index, idx = self._kernel.layout, known[0], known[2]

                def deferred():  # decode the kinematics only when an acceleration is asked for
                    bodies, columns = layout.unpack("kinematics", kin).values()
                    return self._point_accelerations(body_fields(bodies[index])["bias"], columns, idx, position,
                                                     velocity, w, q, qd, t, tau)()
                return BodyState(position, velocity, R, w, deferred)
        if name not in self.topology.components or not hasattr(self.topology.components[name], "mass"):
            raise ModelError(f"body {name!r}", "is not a body of this model")
        q, qd = self.state_vector(q), self._velocity(qd)
        comp = self.topology.components[name]
        local = np.asarray(comp.com, dtype=float) if point is None else checks.vector(
            point, 3, "point", where=f"body_state of {name!r}")
        if point is None and name in (b.name for b in self.topology.bodies):
            local = np.asarray(self._parameters[f"{name}.com"], dtype=float)
        if comp is self.topology.ground:
            zero = np.zeros(3)
            return BodyState(local.copy(), zero, np.eye(3), zero.copy(), lambda: (np.zeros(3), np.zeros(3)))
        index, idx = self.topology.body_index(comp), self.topology.speed_indices_of_body(comp)
        if point is None:
            points[name] = (index, np.array(local, dtype=float), idx)  # its COM, for the next call
        per_body, columns = self._kernel.kinematics(q, qd)
        row = body_fields(per_body[index])
        R, origin, V, A_bias = row["rotation"], row["origin"], row["velocity"], row["bias"]
        w, v0 = V[:3].copy(), V[3:]
        position = origin + R @ local
        velocity = v0 + cross(w, position)
        return BodyState(position, velocity, R, w,
                         self._point_accelerations(A_bias, columns, idx, position, velocity, w, q, qd, t, tau))

    def _point_accelerations(self, A_bias, columns, idx, position, velocity, w, q, qd, t, tau):
        """The deferred ``(acceleration, angular acceleration)`` of a body point (BodyState)."""
        def accelerations():
            qdd = self.accelerations(q, qd, t, tau)
            A = A_bias + columns[idx].T @ qdd[idx]
            alpha, a0 = A[:3], A[3:]
            return a0 + cross(alpha, position) + cross(w, velocity), alpha.copy()
        return accelerations

    def motion_columns(self, q: Any) -> np.ndarray:
        """(nv, 6) world-frame motion columns ``S_k = (w_k, v0_k)`` of the speeds (the columns of T)."""
        return self._kernel.kinematics(self.state_vector(q), np.zeros(self.nv))[1]

    def assemble(self, q: Any, qd: Any = None, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``(q, qd)`` moved onto the constraints: positions by Newton (minimum-norm steps from
        the guess), speeds by mass-orthogonal projection.  ``SimulationError`` naming the
        constraints that cannot be met."""
        q, qd = self.state_vector(q), self._velocity(qd)
        return self._formulation.assemble(self._kernel, q, qd, t)

    def constraint_violation(self, q: Any, t: float = 0.0, offsets: dict | None = None) -> float:
        """max |g(q, t)| over the position-level constraint equations (``offsets``: the start
        values of speed motors, as a ``Result`` records them)."""
        return self._formulation.constraint_violation(self._kernel, t, self.state_vector(q), offsets)

    def simulate(self, t_end: float, q0: Any, qd0: Any = None, *, method: Any = "DOP853",
                 rtol: float = 1e-8, atol: float = 1e-10, t_eval: Any = None, tau: Any = None,
                 parameters: Mapping[str, Any] | None = None, progress: bool = False,
                 max_step: float = np.inf, rest_speed: float = 1e-4, integrator: str = "auto",
                 dt: float | None = None, x0: Mapping[str, float] | None = None, max_samples: int | None = None,
                 contact_mode: str = "events"):
        """Integrate from ``(q0, qd0)`` at t = 0 to ``t_end`` (s) and return a ``Result``.

        ``method`` is a scipy ``solve_ivp`` method name or ``OdeSolver`` subclass;
        contacts are watched between steps and impacts applied where gaps close;
        a contact closing slower than ``rest_speed`` (m/s) stays closed until its
        reaction would pull.  ``integrator="auto"`` runs ``"DOP853"`` (and the fixed-step
        ``"RK4"`` with step ``dt``) entirely in compiled code when the model allows it
        (C backend; a tree, or a ``dae`` model whose constraints are all loops and sliders; no
        contacts, motors or callable inputs); ``"scipy"``
        forces scipy's stepping, ``"compiled"`` insists on the compiled loop.
        ``x0`` gives initial values of ``extra_states`` by name (default 0).
        ``t_eval=None`` keeps every step, at most ``max_samples`` (default
        ``mbcomp.core.checks.MAX_SAMPLES``) of them: a run that needs more stops with a
        ``SimulationError`` naming ``t_eval`` and ``max_samples``.
        ``contact_mode="timestepping"`` (with a step ``dt``, s) runs Moreau-Jean time
        stepping instead of locating contact events: first order, for dense contact
        (docs/contacts.md, "Time stepping for dense contact"); ``method``, ``rtol``,
        ``atol``, ``max_step``, ``rest_speed`` and ``integrator`` do not apply to it.
        """
        from mbcomp.run.simulate import simulate
        system = self.with_parameters(parameters)
        q0, qd0 = system.state_vector(q0, "q0"), system._velocity(qd0)
        result = simulate(system._kernel, system._formulation, t_end, q0, qd0, method=method, rtol=rtol,
                          atol=atol, t_eval=t_eval, tau=tau, progress=progress, max_step=max_step,
                          rest_speed=rest_speed, integrator=integrator, dt=dt, z0=system.extra_state_vector(x0),
                          max_samples=max_samples, contact_mode=contact_mode)
        return result.with_system(system)

    def export_fmu(self, path: Any, kind: str = "cs", inputs: Any = (), outputs: Any = None) -> Any:
        """Write this System as an FMI 2.0 FMU at ``path`` (returns the path).

        ``kind``: ``"cs"`` (co-simulation: mbcomp's compiled DOP853 inside ``fmi2DoStep``,
        contact events and impacts handled within a step, tolerances as the parameters
        ``mbcomp.rtol``/``mbcomp.atol``) or ``"me"`` (model exchange: the states ``[q, v, z]``,
        their derivatives and one event indicator per contact for the importer's solver).
        Constraints run as in the ``dae`` formulation (Baumgarte stabilisation) whichever
        formulation this System uses.  ``inputs``: joint names, each one real input (the
        generalised force on the joint, added to ``tau``); ``outputs``: the coordinates,
        speed columns and drive states that are outputs (None: all).  The FMU needs neither
        Python nor mbcomp (docs/fmu.md)."""
        from mbcomp.core import services
        system = self
        if self._formulation.name != "dae" and (self._formulation.constraints is not None or self.topology.contacts):
            model, _, options, backend = self._compiled.recipe
            system = compile_model(model, formulation="dae", backend=backend,
                                   dynamics=options.get("dynamics", "auto")).with_parameters(self._parameters)
            system._compiled.initial = getattr(self._compiled, "initial", None)
        return services.service("export_fmu")(system, system._formulation, path, kind=kind, inputs=inputs,
                                              outputs=outputs)

    def impact(self, q: Any, qd: Any, contacts: Any = None, restitution: float | None = None, t: float = 0.0):
        """Newton's impact law with ``contacts`` active (names or objects; default: every
        contact that is closed and closing), consistent with every other constraint.

        Returns ``.qd`` after the impact, ``.impulses`` ``{contact: N s}`` (positive pushes
        apart) and ``.energy_loss`` (J).  ``restitution`` overrides the contacts' own.
        """
        from mbcomp.formulations.impact import GAP_TOLERANCE, contact_indices, solve_impact
        q, qd = self.state_vector(q), self._velocity(qd)
        indices = contact_indices(self._kernel, contacts)
        if contacts is None:
            values = self._kernel.contacts(q, qd)
            indices = [i for i in indices if values.g[i] < GAP_TOLERANCE and values.J[i] @ qd < 0]
        return solve_impact(self._kernel, self._formulation, t, q, qd, indices, restitution)

    def gaps(self, q: Any) -> dict[str, float]:
        """``{contact: gap}`` (m), negative when penetrated."""
        q = self.state_vector(q)
        values = self._kernel.contacts(q, np.zeros(self.nv))
        return {c.name: float(g) for c, g in zip(self.topology.contacts, values.g)}

    # -- analysis (mbcomp.analysis) ----------------------------------------------------------
    def tree_dynamics(self, q: Any, qd: Any = None, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """``(M, f)``: tree mass matrix and generalised forces (gravity, springs, applied forces,
        velocity terms) with ``M qdd = f + tau + J^T lam``; constraints are not applied."""
        q, qd = self.state_vector(q), self._velocity(qd)
        return self._kernel.checked_dynamics(t, q, qd)

    def constraint_values(self, q: Any, qd: Any = None, t: float = 0.0):
        """Every constraint equation at a state: ``.g`` (residuals), ``.J`` (Jacobian, one column
        per speed), ``.g_t`` (``gdot = J qd + g_t``) and ``.bias`` (``gddot = J qdd + bias``).
        Rows are in ``constraint_rows`` order; a speed motor holds its present position."""
        q, qd = self.state_vector(q), self._velocity(qd)
        offsets = self._formulation.motor_offsets(q, t)
        return self._formulation.constraint_values(self._kernel, t, q, qd, offsets)

    @property
    def velocity_rows(self) -> np.ndarray:
        """Which rows of ``constraint_values`` constrain speeds only (rolling and no-slip rows,
        non-holonomic: their ``g`` is NaN), as a boolean mask."""
        cs = self._formulation.constraints
        return np.zeros(0, dtype=bool) if cs is None else cs.velocity_rows.copy()

    @property
    def constraint_rows(self) -> list[str]:
        """The constraint owning each row of ``constraint_values`` (by name)."""
        cs = self._formulation.constraints
        return [] if cs is None else list(cs.owner)

    def equilibrium(self, q_guess: Any, tau: Any = None, t: float | None = None, return_states: bool = False) -> Any:
        """``q`` at rest with every constraint met and the drive states (currents, PID integrals)
        at rest, near ``q_guess``; ``return_states=True``: ``(q, {state: value})`` (see
        ``mbcomp.analysis``)."""
        from mbcomp.analysis import equilibrium
        return equilibrium(self, q_guess, tau=tau, t=t, return_states=return_states)

    def linearize(self, q: Any, qd: Any = None, t: float | None = None, inputs: Any = None, tau: Any = None,
                  independent: Any = None, states: Any = None):
        """State-space ``.A``, ``.B`` in the independent coordinates (see ``mbcomp.analysis``)."""
        from mbcomp.analysis import linearize
        return linearize(self, q, qd, t=t, inputs=inputs, tau=tau, independent=independent, states=states)

    def modes(self, q: Any, t: float | None = None, tau: Any = None, states: Any = None, qd: Any = None):
        """Natural frequencies, damping ratios, shapes and stability about ``q`` at rest, or about
        the steady motion ``(q, qd)`` (see ``mbcomp.analysis``)."""
        from mbcomp.analysis import modes
        return modes(self, q, t=t, tau=tau, states=states, qd=qd)

    def jacobian(self, frame: Any, q: Any, point: Any = None) -> np.ndarray:
        """(6, n) angular then linear velocity (world) of a body point per speed (see ``mbcomp.analysis``)."""
        from mbcomp.analysis import jacobian
        return jacobian(self, frame, q, point=point)

    def inverse_dynamics(self, q: Any, qd: Any, qdd: Any, t: float = 0.0, actuated: Any = None):
        """Generalised forces producing ``qdd`` (and the reactions; see ``mbcomp.analysis``)."""
        from mbcomp.analysis import inverse_dynamics
        return inverse_dynamics(self, q, qd, qdd, t=t, actuated=actuated)

    # -- display ----------------------------------------------------------------------------------
    def equations(self, values: Mapping[str, Any] | None = None):
        """Symbolic ``(M, f)`` with ``M qdd = f`` in terms of q, the speeds and parameter symbols
        (a screw coordinate's speed is shown as its rate).  ``values``: numbers (or sympy
        numbers) for parameter symbols by name (``"top.mass"``, ``"gravity[2]"``), put in while
        the equations are expanded, which keeps them small."""
        import sympy as sp
        prog = self._compiled.program
        n = self.nv
        tri = prog.outputs["mass_matrix"]
        by_name = {str(s): s for s in prog.p}
        substitute = {by_name[k]: sp.sympify(v) for k, v in (values or {}).items() if k in by_name}
        values = prog.expand(list(tri) + list(prog.outputs["forces"]), substitute)
        M = sp.zeros(n, n)
        k = 0
        for i in range(n):
            for j in range(i + 1):
                M[i, j] = M[j, i] = values[k]
                k += 1
        f = sp.Matrix(values[len(tri):])
        names = {s: sp.Symbol(c) for s, c in zip(prog.q, self.coords)}
        names.update({s: sp.Symbol(f"\\dot{{{c}}}" if c in self.coords else c) for s, c in zip(prog.qd, self.speeds)})
        return M.xreplace(names), f.xreplace(names)

    def _repr_latex_(self) -> str | None:
        if self.nv > 4:
            return None
        import sympy as sp
        M, f = self.equations()
        qdd = sp.Matrix([sp.Symbol(f"\\ddot{{{c}}}" if c in self.coords else f"\\dot{{{c}}}") for c in self.speeds])
        return "$" + sp.latex(M) + sp.latex(qdd) + " = " + sp.latex(f) + "$"

    def __repr__(self) -> str:
        return (f"System({self._compiled.model_name!r}, coords={list(self.coords)}, ndof={self.ndof}, "
                f"formulation={self.formulation!r}, backend={self.backend!r})")


def unknown_parameter(key: Any, known: Any) -> str:
    """The message for a parameter name that is not one: a few close matches ("did you mean"),
    and how many there are, instead of every name."""
    import difflib
    names = sorted(str(k) for k in known)
    close = difflib.get_close_matches(str(key), names, n=3, cutoff=0.6)
    if not close:  # a misspelt attribute of the right component, or the right attribute elsewhere
        component, _, attribute = str(key).rpartition(".")
        close = [n for n in names if component and n.startswith(component + ".")][:3] or \
            [n for n in names if attribute and n.endswith("." + attribute)][:3]
    hint = f"; did you mean {' or '.join(map(repr, close))}?" if close else ""
    return f"unknown parameter {key!r}{hint} ({len(names)} parameters: sys.parameters lists them)"


def compile_model(model, *, formulation: Any = "lagrange", cache: bool = True, backend: str = "auto",
                  dynamics: str = "auto", **options: Any) -> System:
    """Model -> System (see ``Model.compile``)."""
    from mbcomp.compiled.compiler import CompiledModel
    from mbcomp.formulations import FORMULATIONS, get_formulation
    from mbcomp.formulations.analysis_cache import cached_analyse
    formulation_class = get_formulation(formulation)
    initial = getattr(model, "initial", None)  # a model file's [initial] (the start values of an exported FMU)
    model = model.flat()  # sub-models expanded, joints oriented along the tree
    # The library carries every registered formulation's C code: one library serves them all.
    snippets = tuple(cls.c_source for cls in FORMULATIONS.values())
    compiled = CompiledModel(model, cache=cache, backend=backend, c_snippets=snippets, dynamics=dynamics,
                             formulation=getattr(formulation_class, "name", None))
    # How to rebuild this System elsewhere (pickling for process pools and clusters).
    derivation = getattr(model, "derivation", None)
    # How to rebuild this System elsewhere (pickling for process pools and clusters); a
    # model with sub-models keeps how its values follow their parameters.
    compiled.recipe = (compiled.flat_model if derivation is None else copy.deepcopy(model), formulation,
                       {**options, "dynamics": dynamics}, backend)
    compiled.derivation = derivation
    compiled.initial = initial
    parameters = dict(compiled.default_parameters)
    if derivation is not None:
        parameters.update(derivation.values())  # sub-model parameters, by path
    formulation = formulation_class(compiled, **options)
    info = cached_analyse(formulation, Kernel(compiled, parameters), getattr(compiled, "key", None) if cache else None,
                          parameters, options)
    return System(compiled, formulation.with_info(info), parameters)


def rebuild_system(model, formulation, options, backend, parameters) -> System:
    """Unpickle: compile the model again (a cache hit where the cache is shared)."""
    return compile_model(model, formulation=formulation, backend=backend, **options).with_parameters(parameters)
