"""Static equilibrium on the constraint manifold."""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.optimize

from mbcomp.core.errors import SimulationError, format_state
from mbcomp.core.errors import ModelError
from mbcomp.formulations.base import independent_rows
from mbcomp.analysis.space import Chart, difference, force_vector, integrate, model_forces, speed_names
from mbcomp.analysis.space import speed_vector

#: Accept an equilibrium when the reduced generalised force is below this fraction of the
#: loads (the largest generalised force at the guess, or 1), and the constraints hold to
#: ``POSITION_TOLERANCE``.
FORCE_TOLERANCE = 1e-9
POSITION_TOLERANCE = 1e-10


def equilibrium(system, q_guess: Any, tau: Any = None, t: float | None = None, max_evaluations: int = 2000,
                return_states: bool = False) -> Any:
    """Configuration ``q`` near ``q_guess`` where the system rests: every constraint met, the
    generalised forces (gravity, springs, drives, ``tau``) balanced by constraint reactions and
    every drive state (motor current, PID integral) at rest::

        f(q, z) + tau + J(q)^T lam = 0,   g(q) = 0,   dz/dt(q, z) = 0   (unknowns: x, lam, z)

    Solved as a nonlinear least-squares problem by scipy's trust-region reflective method
    (a globalised Newton: from a poor guess it cannot step away), then checked on the
    *reduced* residual ``N^T (f + tau)`` (N spans the motions the constraints allow) and on
    the drive states' rates.  A PID with an integral therefore rests with its joint on the
    setpoint, a DC motor with the current that holds the load.  A drive state that nothing
    depends on (the integral of a PID with ``ki = 0``) is left at 0: it drifts without effect.
    ``tau``: constant generalised forces (array, one per speed) or a callable ``(t, q, qd)``.
    Which equilibrium is found (a pendulum has two) depends on the guess; stable or not
    (see ``modes``).  Inputs that change with time (a ``Step`` setpoint, a ``Sine`` voltage)
    are held at their values at ``t``; by default (``t=None``) at the values they settle to
    (after every step), or at t = 0 when they never settle (``operating_time``;
    ``changing_inputs`` names them).  ``return_states=True``
    returns ``(q, {state: value})`` with the drive states (``system.extra_states``) at rest.
    ``SimulationError`` when none is found near the guess, or when a motor prescribes motion
    (such a model is never at rest).
    """
    q0 = system.state_vector(q_guess, "q_guess")
    t = operating_time(system, q0, t)
    n = len(speed_names(system))
    zero = np.zeros(n)
    if system.constraint_names:
        q0, _ = system.assemble(q0, None, t)  # onto the constraints first (raises when impossible)
    drives = DriveRest(system, t, tau, q0)
    z_start = drives.rest(q0)
    m = len(drives.active)

    f0 = drives.forces(q0, z_start)
    scale = max(float(np.max(np.abs(f0), initial=0.0)), 1.0)
    rows = np.arange(0)
    sigma0 = 1.0
    if system.constraint_names:
        J0 = system.constraint_values(q0, None, t).J
        rows = independent_rows(J0)
        sigma0 = float(np.linalg.norm(J0[rows], 2)) if len(rows) else 1.0
    r = len(rows)

    def split(y):
        z = z_start.copy()
        z[drives.active] = y[n:]
        return integrate(system, q0, y[:n]), z

    def residual(y):
        q, z = split(y)
        f = drives.forces(q, z)
        rates = drives.rates(q, z) / drives.row_scale
        if not r:
            return np.concatenate((f / scale, rates))
        cv = system.constraint_values(q, None, t)
        J = cv.J[rows]
        if np.linalg.svd(J, compute_uv=False)[-1] < SINGULAR * sigma0:
            raise _Singular(y)  # at a dead point: the search would creep towards it for ever
        projected = f - J.T @ np.linalg.solve(J @ J.T, J @ f)
        g = cv.g[rows]  # (velocity rows, rolling and no-slip, have no position residual: NaN)
        return np.concatenate((projected / scale, np.where(np.isfinite(g), g, 0.0), rates))

    def solved(q, z):
        worst = float(np.max(np.abs(reduced_forces(system, q, t, tau, states=z)), initial=0.0))
        violation = system.constraint_violation(q, t) if r else 0.0
        still = float(np.max(np.abs(drives.rates(q, z)), initial=0.0))
        ok = (worst <= FORCE_TOLERANCE * scale and violation <= POSITION_TOLERANCE
              and still <= FORCE_TOLERANCE * drives.rate_scale)
        return ok, worst

    drives.check_never_at_rest(q0)
    y0 = np.concatenate((zero, z_start[drives.active]))
    z = z_start
    try:
        # 1. Newton on the projected force, the constraints and the state rates, globalised by a trust region.
        q, z = split(_least_squares(residual, y0, max_evaluations, n))
        if r:
            q, _ = system.assemble(q, None, t)
        ok, worst = solved(q, z)
        if not ok:
            # 2. It stopped where the force is smallest but not zero (a fold of the force field):
            # pseudo-transient continuation follows the overdamped motion towards a stable rest.
            def dead(q):
                return bool(r) and np.linalg.svd(system.constraint_values(q, None, t).J[rows],
                                                 compute_uv=False)[-1] < SINGULAR * sigma0

            q, z = _continuation(system, q0, z_start, drives, t, tau, solved, dead)
            if dead(q):
                raise _Singular(np.concatenate((difference(system, q0, q), z[drives.active])))
            # close to it now: Newton finishes from there
            start = np.concatenate((difference(system, q0, q), z[drives.active]))
            polished, z_polished = split(_least_squares(residual, start, max_evaluations, n))
            if r:
                polished, _ = system.assemble(polished, None, t)
            if solved(polished, z_polished)[0] or not solved(q, z)[0]:
                q, z = polished, z_polished
            ok, worst = solved(q, z)
    except _Singular as stop:
        q, z = split(stop.y)
        ok, worst = False, float("nan")
        try:
            worst = float(np.max(np.abs(reduced_forces(system, q, t, tau, states=z)), initial=0.0))
        except (SimulationError, np.linalg.LinAlgError):
            pass
    except (SimulationError, np.linalg.LinAlgError) as exc:
        raise SimulationError(f"no equilibrium found near q = {format_state(q0)}: the search left the region "
                              f"where the model can be evaluated ({exc})") from None
    if not ok or not np.all(np.isfinite(q)) or not np.all(np.isfinite(z)):
        hint = "try another guess, or the loads have no balance"
        if r and np.all(np.isfinite(q)):
            J_end = system.constraint_values(q, None, t).J
            lost = r - len(independent_rows(J_end))
            smallest = np.linalg.svd(J_end[rows], compute_uv=False)
            largest = np.linalg.svd(system.constraint_values(q0, None, t).J[rows], compute_uv=False)
            lost += int(smallest[-1] < 1e-4 * largest[0])  # nearly singular: where a dead point is near
            if lost > 0 or np.max(np.abs(q - q0), initial=0.0) > 1e3:
                hint = ("the search runs into a singular position of the mechanism (the constraint Jacobian loses "
                        "rank: a dead point, where an equilibrium cannot be found this way)")
        if m and np.all(np.isfinite(q)) and np.all(np.isfinite(z)):
            still = float(np.max(np.abs(drives.rates(q, z)), initial=0.0))
            if still > FORCE_TOLERANCE * drives.rate_scale:
                hint += f"; the drive states do not come to rest there (largest rate {still:.3g})"
        contacts = getattr(system.topology, "contacts", ())
        if contacts:
            hint += (f"; contacts ({', '.join(c.name for c in contacts)}) are not loads of the static analysis, "
                     f"so a body resting on one has no equilibrium here")
        raise SimulationError(f"no equilibrium found near q = {format_state(q0)}: the closest point reached, "
                              f"q = {format_state(q)}, leaves an unbalanced generalised force of {worst:.3g} "
                              f"(loads up to {scale:.3g}); {hint}")
    if return_states:
        return q, dict(zip(drives.names, (float(v) for v in z)))
    return q


def rest_states(system, q: Any, qd: Any = None, t: float | None = None, tau: Any = None) -> np.ndarray:
    """The drive states (``system.extra_states`` order: currents in A, PID integrals) at which
    the model rests at ``(q, qd)``: their rates vanish and the accelerations as far as they can
    (a least-squares fit; exact at an equilibrium).  ``modes`` and ``linearize`` take them
    when no ``states`` are given; states nothing depends on stay 0.  ``t`` as in ``equilibrium``."""
    q = system.state_vector(q)
    t = operating_time(system, q, t)
    v = speed_vector(system, qd)
    return DriveRest(system, t, tau, q).rest(q, v)


class DriveRest:
    """The drive states of a system at rest: which of them act (``active``: a state whose
    change moves a force or a rate), their rates and the forces with them."""

    def __init__(self, system, t: float, tau: Any, q: np.ndarray | None = None):
        self.system, self.t, self.tau = system, float(t), tau
        self.names = tuple(getattr(system, "extra_states", ()))
        self.nz = len(self.names)
        self.n = len(speed_names(system))
        self.active = np.arange(0)
        self.rate_scale = 1.0
        self.row_scale = np.ones(0)
        if self.nz and q is not None:
            self.active = self._acting(q)

    def _outputs(self, q, v, z):
        forces, rates = self.system.drive_outputs(self.t, q, v, z)
        return np.asarray(forces, dtype=float), np.asarray(rates, dtype=float)

    def _acting(self, q0: np.ndarray) -> np.ndarray:
        """States whose change changes a drive force or a state rate (tested at ``q0`` and at a
        pose and states nearby chosen at random, so that no coincidence hides one)."""
        acting = np.zeros(self.nz, dtype=bool)
        rng = np.random.default_rng(0)
        v = np.zeros(self.n)
        for q, z in ((q0, np.zeros(self.nz)),
                     (integrate(self.system, q0, rng.uniform(-0.3, 0.3, self.n)), rng.uniform(-1.0, 1.0, self.nz))):
            base = np.concatenate(self._outputs(q, v, z))
            size = max(1.0, float(np.max(np.abs(base), initial=0.0)))
            for j in range(self.nz):
                e = np.zeros(self.nz)
                e[j] = 1.0
                column = np.concatenate(self._outputs(q, v, z + e)) - base
                acting[j] |= bool(np.any(np.abs(column) > 1e-13 * size))
        return np.flatnonzero(acting)

    def forces(self, q: np.ndarray, z: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Generalised forces at rest (or at speeds ``v``): tree, drives at states ``z``, ``tau``."""
        v = np.zeros(self.n) if v is None else v
        _, f = self.system.tree_dynamics(q, v, self.t)
        if self.nz or getattr(self.system, "has_drives", False):
            f = f + self._outputs(q, v, z)[0]
        extra = force_vector(self.system, self.tau, self.t, q, v)
        return f if extra is None else f + extra

    def rates(self, q: np.ndarray, z: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Rates of the acting drive states."""
        if not len(self.active):
            return np.zeros(0)
        v = np.zeros(self.n) if v is None else v
        return self._outputs(q, v, z)[1][self.active]

    def rest(self, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """States at rest for a fixed ``(q, v)`` (least squares over the acting ones); also sets
        ``rate_scale`` (the size of the rates' terms, for the tolerances) and ``row_scale``
        (each acting state's rate's own terms: the search weighs the rates by it, so that a
        slow rate, a PID's integral of the error beside a motor current's fast one, is not
        drowned, which left the search creeping along a narrow valley for thousands of steps)."""
        z = np.zeros(self.nz)
        if not len(self.active):
            return z
        v = np.zeros(self.n) if v is None else v
        accel_scale = max(1.0, float(np.max(np.abs(self.system.accelerations(q, v, self.t, tau=force_vector(
            self.system, self.tau, self.t, q, v), states=z)), initial=0.0)))

        def residual(y):
            w = z.copy()
            w[self.active] = y
            extra = force_vector(self.system, self.tau, self.t, q, v)
            a = self.system.accelerations(q, v, self.t, tau=extra, states=w)
            return np.concatenate((a / accel_scale, self.rates(q, w, v)))

        y = scipy.optimize.least_squares(residual, np.zeros(len(self.active)), method="lm", xtol=1e-15,
                                         ftol=1e-15, gtol=1e-15).x
        z[self.active] = y
        # the rates' own size: each rate's terms (its change per unit of every acting state times
        # that state's value, and its value with the states at 0)
        r0 = np.abs(self.rates(q, np.zeros(self.nz), v))
        terms = [r0]
        for j in self.active:
            e = np.zeros(self.nz)
            e[j] = 1.0
            slope = self.rates(q, z + e, v) - self.rates(q, z, v)
            terms.append(np.abs(slope) * max(1.0, abs(z[j])))
        self.rate_scale = max(1.0, float(np.max(np.concatenate(terms), initial=0.0)))
        self.row_scale = np.maximum(1.0, np.max(np.vstack(terms), axis=0))
        return z

    def check_never_at_rest(self, q: np.ndarray) -> None:
        """``SimulationError`` when a motor prescribes motion at ``q`` (the constraints' time
        rate at rest is not zero): such a model has no rest at any pose."""
        system = self.system
        if not system.constraint_names:
            return
        cv = system.constraint_values(q, np.zeros(self.n), self.t)
        moving = np.abs(np.asarray(cv.g_t, dtype=float)) > POSITION_TOLERANCE
        if np.any(moving):
            owners = sorted({system.constraint_rows[i] for i in np.flatnonzero(moving)})
            what = f"{'constraint' if len(owners) == 1 else 'constraints'} {', '.join(map(repr, owners))}"
            raise SimulationError(f"no equilibrium: {what} prescribe{'s' * (len(owners) == 1)} motion in time "
                                  f"(a motor's position or speed), so the model is never at rest; analyse it "
                                  f"with the motor held at a fixed position, or linearise about the motion")

    def changing(self, q: np.ndarray, z: np.ndarray, scale: float = 1.0) -> list[str]:
        """The speeds and drive states whose forces or rates at rest at ``(q, z)`` change with
        time (a time-varying voltage, torque or setpoint; the user's ``tau`` held at ``t``)."""
        system, t = self.system, self.t
        held = force_vector(system, self.tau, t, q, np.zeros(self.n))
        frozen = DriveRest(system, t, held)
        frozen.active, frozen.rate_scale = self.active, self.rate_scale
        f_now, r_now = frozen.forces(q, z), frozen.rates(q, z)
        changed: list[str] = []
        for dt in (0.7071067811865476, 3.141592653589793, 12.345678):
            frozen.t = t + dt
            changed += [speed_names(system)[i] for i in
                        np.flatnonzero(np.abs(frozen.forces(q, z) - f_now) > 1e3 * FORCE_TOLERANCE * scale)]
            changed += [self.names[self.active[i]] for i in
                        np.flatnonzero(np.abs(frozen.rates(q, z) - r_now) > 1e3 * FORCE_TOLERANCE * self.rate_scale)]
        return list(dict.fromkeys(changed))


#: Where inputs that change with time are looked at for the values they settle to (s).
SETTLED_TIME = 1e6


def operating_time(system, q: Any, t: float | None = None) -> float:
    """The time at which an analysis without a given ``t`` holds the model's inputs: 0 when
    they are constant, else ``SETTLED_TIME`` when they have settled by then (a ``Step``: its
    final value), else 0 (a ``Sine`` never settles).  A given ``t`` is returned as it is."""
    if t is not None:
        try:
            t = float(t)
        except (TypeError, ValueError):
            raise ModelError("t", f"must be a number of seconds, got {t!r}") from None
        if not np.isfinite(t):
            raise ModelError("t", f"must be finite, got {t!r}")
        return t
    if not changing_inputs(system, q, 0.0):
        return 0.0
    return SETTLED_TIME if not changing_inputs(system, q, SETTLED_TIME) else 0.0


def changing_inputs(system, q: Any, t: float = 0.0, states: Any = None) -> list[str]:
    """The speeds and drive states whose loads at rest at ``q`` change with time (signals,
    voltages, setpoints that depend on ``t``): an equilibrium found at ``t`` holds them at
    their values at ``t``; empty when the model's loads are constant."""
    q = system.state_vector(q)
    from mbcomp.analysis.space import drive_state_vector
    drives = DriveRest(system, t, None, q)
    z = drive_state_vector(system, states)
    return drives.changing(q, z, max(1.0, float(np.max(np.abs(drives.forces(q, z)), initial=0.0))))


#: The search stops at a dead point: where the constraint Jacobian's smallest singular value
#: falls below this fraction of its norm at the guess.
SINGULAR = 1e-5


class _Singular(Exception):
    """The equilibrium search reached a singular position (``y``: its unknowns there)."""

    def __init__(self, y: np.ndarray):
        super().__init__("singular position")
        self.y = np.array(y)


#: "Near the guess": each tangent coordinate stays within this distance of the guess (rad or m).
SEARCH_RADIUS = 2 * np.pi

#: Largest pseudo-transient step per iteration (rad or m).
MAX_STEP = 0.5


def _least_squares(residual, x0: np.ndarray, max_evaluations: int, bounded: int | None = None) -> np.ndarray:
    """Trust-region least squares, the first ``bounded`` unknowns (the tangent coordinates;
    default all) within ``SEARCH_RADIUS`` of the start, then Newton polish."""
    radius = np.full(len(x0), np.inf)
    radius[:len(x0) if bounded is None else bounded] = SEARCH_RADIUS
    solution = scipy.optimize.least_squares(residual, x0, method="trf", jac="3-point",
                                            bounds=(x0 - radius, x0 + radius),
                                            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=max_evaluations)
    x = solution.x
    for _ in range(4):  # Newton polish (the trust region stops on its own tolerances)
        res = residual(x)
        if np.max(np.abs(res), initial=0.0) < 1e-15:
            break
        x = x - np.linalg.lstsq(_jacobian(residual, x), res, rcond=None)[0]
    return x


def _continuation(system, q0: np.ndarray, z0: np.ndarray, drives: "DriveRest", t: float, tau: Any, solved,
                  dead=None, max_steps: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-transient continuation (Kelley and Keyes) on the independent coordinates and the
    acting drive states: ``(I / h - da/dx) dx = a`` with ``a`` the accelerations at rest (and
    the states' rates); the pseudo time step ``h`` grows as they shrink (switched evolution
    relaxation), so the iteration follows the overdamped motion far away and becomes Newton
    near the equilibrium."""
    q, z = q0.copy(), z0.copy()
    zero = np.zeros(len(speed_names(system)))
    active = drives.active

    def accel(chart, z, s):
        qx, _ = chart.position(s[:chart.k])
        w = z.copy()
        w[active] = w[active] + s[chart.k:]
        extra = force_vector(system, tau, t, qx, zero)
        a = system.accelerations(qx, zero, t, tau=extra, **({"states": w} if drives.nz else {}))[chart.ind]
        return np.concatenate((a, drives.rates(qx, w)))

    chart = Chart(system, q, t)
    if chart.kq != chart.k:
        return q, z  # velocity rows: more coordinates than speeds, no square iteration (Newton's result stands)
    size = chart.k + len(active)
    a = accel(chart, z, np.zeros(size))
    D = _jacobian(lambda s: accel(chart, z, s), np.zeros(size), 1e-6)
    h = 0.1 / max(float(np.linalg.norm(D, 2)), 1e-12)
    for _ in range(max_steps):
        if solved(q, z)[0] or (h > 1e6 and np.linalg.norm(a) < 1e-6 * max(1.0, np.linalg.norm(D))):
            return q, z  # solved, or Newton-like steps close to the solution: the caller polishes
        if dead is not None and dead(q):
            return q, z  # at a dead point of the mechanism: the caller reports it
        try:
            dx = np.linalg.solve(np.eye(size) / h - D, a)
            if float(np.max(np.abs(dx[:chart.k]), initial=0.0)) > MAX_STEP:
                h *= 0.5
                continue
            q_new, _ = chart.position(dx[:chart.k])
            z_new = z.copy()
            z_new[active] = z_new[active] + dx[chart.k:]
            new_chart = Chart(system, q_new, t)
            a_new = accel(new_chart, z_new, np.zeros(size))
        except (SimulationError, np.linalg.LinAlgError):
            h *= 0.25
            continue
        if np.linalg.norm(a_new) > 2.0 * np.linalg.norm(a) and h > 1e-12:
            h *= 0.25  # too bold: the step made things worse
            continue
        h = min(h * max(np.linalg.norm(a) / max(np.linalg.norm(a_new), 1e-300), 0.5), 1e12)
        q, z, chart, a = q_new, z_new, new_chart, a_new
        D = _jacobian(lambda s: accel(chart, z, s), np.zeros(size), 1e-6)
    return q, z


def reduced_forces(system, q: np.ndarray, t: float = 0.0, tau: Any = None, states: Any = None) -> np.ndarray:
    """``N^T (f + tau)`` at rest: the generalised forces along the independent speeds, zero at
    an equilibrium (N from ``Chart.basis``; without constraints simply ``f + tau``).
    ``states``: the drive states (``system.extra_states`` order or ``{name: value}``; default 0)."""
    n = len(speed_names(system))
    _, f = model_forces(system, q, np.zeros(n), t, states)
    extra = force_vector(system, tau, t, q, np.zeros(n))
    if extra is not None:
        f = f + extra
    if not system.constraint_names:
        return f
    chart = Chart(system, q, t)
    return chart.basis(q).T @ f


def _jacobian(fun, z: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central-difference Jacobian (for the final Newton steps only)."""
    cols = []
    for j in range(len(z)):
        step = h * max(1.0, abs(z[j]))
        e = np.zeros_like(z)
        e[j] = step
        cols.append((fun(z + e) - fun(z - e)) / (2 * step))
    return np.column_stack(cols)
