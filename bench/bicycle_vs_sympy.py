"""The benchmark Whipple bicycle, 10 s: mbcomp against sympy.physics.mechanics + scipy.

The same bicycle (library/whipple_bicycle.toml; the sympy derivation in bicycle_sympy.py,
Kane's method with 5 dependent speeds as in sympy's own test of the benchmark), ridden for
10 s from the paper's figure-4 start: 4.6 m/s, upright, lean rate 0.5 rad/s (a weave that
dies out). Both models are validated first: their accelerations agree at the start state.

- mbcomp: ``Model.compile`` (cold: ``cache=False``), then ``System.simulate`` with DOP853 at
  rtol = atol = 1e-3 .. 1e-13 (half decades); each formulation, on whatever integration
  path it has (the compiled C loop, or scipy when a formulation steps in Python).
- sympy: ``KanesMethod`` derivation, ``lambdify(cse=True)`` of the full mass matrix and
  forcing (16 x 16: kinematic rows, the 3 dynamic rows and the 5 differentiated velocity
  constraints), ``numpy.linalg.solve`` for the accelerations, scipy's ``solve_ivp`` DOP853 at
  the same tolerances.

Error of a run: max |q_i(10 s) - q_ref,i(10 s)| over the angles lean, steer, yaw and pitch
(rad; the positions x, y grow to 46 m and the wheel angles to 150 rad, whose last digits
no run resolves). Reference: mbcomp's lagrange at 1e-13, cross-checked against sympy's run
at 1e-13 (their spread is the resolution; levels below 3x it are not reported). Times:
medians over interleaved rounds (timing.py), wall and process CPU time (the machine may be
shared), per-run setup included, model building excluded; the time at an error level is
interpolated along each tool's Pareto front. Ratio = mbcomp / sympy (below 1: mbcomp faster).

Usage: python bench/bicycle_vs_sympy.py [--rounds 3] [--quick]
Writes bench/results/bicycle_vs_sympy.csv (every run) and prints the level table.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
import bicycle_benchmark as bb  # noqa: E402
import bicycle_sympy  # noqa: E402
from models import write_csv  # noqa: E402
from timing import Run, fmt, measure, rounds_main, time_at  # noqa: E402

import mbcomp as mb  # noqa: E402

T_END = 10.0
SPEED, LEAN_RATE = 4.6, 0.5
LEVELS = (1e-6, 1e-9)
ANGLES = ("lean", "steer", "yaw", "pitch")
TOLERANCES = [10.0 ** (-k / 2) for k in range(6, 27)]          # 1e-3 .. 1e-13, half decades


def start_state(system) -> tuple[np.ndarray, np.ndarray]:
    """Upright, straight ahead at SPEED with a lean rate: moved onto the constraints by mbcomp."""
    p = bb.BENCHMARK
    qd = dict.fromkeys(system.speeds, 0.0)
    qd.update(x=SPEED, rear_wheel_angle=-SPEED / p["rR"], front_wheel_angle=-SPEED / p["rF"], lean=LEAN_RATE)
    return system.assemble(np.zeros(len(system.coords)), np.array([qd[s] for s in system.speeds]))


class SympyBicycle:
    """The sympy model as a simulator: ``simulate(rtol) -> q(T_END)`` in mbcomp's coordinate order."""

    def __init__(self, log=print):
        self.derived = bicycle_sympy.derive()
        log(f"  sympy: KanesMethod derivation {self.derived.seconds:.1f} s")
        self.rhs, self.lambdify_seconds = bicycle_sympy.numeric(self.derived)
        log(f"  sympy: lambdify(cse=True) {self.lambdify_seconds:.1f} s")
        self.p = np.array([bb.BENCHMARK[n] for n in bicycle_sympy.PARAMETER_NAMES])
        # the speeds in KanesMethod's order: u_k is the rate of q_k (q1..q8 = mbcomp's coords)
        self.order = [int(u.name[1:]) - 1 for u in self.derived.u]

    def state(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.concatenate([q, qd[self.order]])

    def accelerations(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The 8 speeds' rates in mbcomp's order."""
        out = np.empty(8)
        out[self.order] = self.rhs(0.0, self.state(q, qd), self.p)[8:]
        return out

    def simulate(self, q0, qd0, rtol: float, atol: float) -> np.ndarray:
        sol = solve_ivp(self.rhs, (0.0, T_END), self.state(q0, qd0), method="DOP853", rtol=rtol, atol=atol,
                        args=(self.p,))
        if not sol.success:
            raise RuntimeError(sol.message)
        return sol.y[:8, -1]


def run(rounds: int = 3, quick: bool = False, log=print) -> dict:
    log(f"Whipple bicycle, {T_END:g} s from {SPEED} m/s with lean rate {LEAN_RATE} rad/s: mbcomp vs sympy")
    model = mb.load("whipple_bicycle")
    systems, compile_seconds = {}, {}
    for formulation in ("dae", "lagrange"):
        start = time.perf_counter()
        systems[formulation] = model.compile(formulation=formulation, cache=False)
        compile_seconds[f"mbcomp {formulation}"] = time.perf_counter() - start
        log(f"  mbcomp {formulation}: cold compile {compile_seconds[f'mbcomp {formulation}']:.1f} s, "
            f"integration: {systems[formulation].integration_path()}")
    q0, qd0 = start_state(systems["dae"])

    sym = SympyBicycle(log)
    compile_seconds["sympy"] = sym.derived.seconds + sym.lambdify_seconds
    qdd_mb = systems["dae"].accelerations(q0, qd0)
    qdd_sym = sym.accelerations(q0, qd0)
    agreement = float(np.abs(qdd_mb - qdd_sym).max())
    log(f"  accelerations at the start agree to {agreement:.1e} (max |qdd| {np.abs(qdd_mb).max():.2f})")
    assert agreement < 1e-9 * max(1.0, np.abs(qdd_mb).max()), (qdd_mb, qdd_sym)

    angles = [list(systems["lagrange"].coords).index(c) for c in ANGLES]
    ref = systems["lagrange"].simulate(T_END, q0, qd0, rtol=1e-13, atol=1e-13, t_eval=[T_END]).q[-1][angles]
    check = sym.simulate(q0, qd0, 1e-13, 1e-13)[angles]
    spread = float(np.abs(ref - check).max())
    log(f"  reference: mbcomp lagrange and sympy at 1e-13 differ by {spread:.1e} rad; "
        f"lean(10 s) = {ref[0]:.8f} rad")

    tolerances = TOLERANCES[::2] if quick else TOLERANCES
    runs = []
    for formulation, system in systems.items():
        label = f"mbcomp {formulation}"
        runs += [Run(label, "rtol", tol, (lambda tol=tol, s=system: s.simulate(T_END, q0, qd0, rtol=tol, atol=tol,
                                                                              t_eval=[T_END]).q[-1][angles]),
                     group=label) for tol in tolerances]
    runs += [Run("sympy", "rtol", tol, (lambda tol=tol: sym.simulate(q0, qd0, tol, tol)[angles]), group="sympy")
             for tol in tolerances if tol >= 1e-12]

    def error(r: Run) -> float:
        e = float(np.max(np.abs(np.asarray(r.result) - ref)))
        return e if math.isfinite(e) else math.inf

    measure(runs, rounds, check=error, stop_error=min(LEVELS) / 3, max_run=60.0, log=log)
    rows = [{"label": r.label, "setting": r.setting, "value": r.value, "error": r.error if not r.failed else math.inf,
             "time": r.wall, "cpu_time": r.cpu, "rounds": len(r.walls), "failed": r.failed}
            for r in runs if not r.skipped]
    write_csv(rows, "bicycle_vs_sympy.csv")
    labels = list(dict.fromkeys(r.label for r in runs))
    table = {}
    for clock in ("wall", "cpu"):
        log(f"\n  time (s, {clock}) to reach an error level; ratio = mbcomp / sympy")
        log("  " + " | ".join(["level"] + labels + [f"{x} / sympy" for x in labels if x != "sympy"]))
        for level in LEVELS:
            if level < 3 * spread:
                log(f"  {level:g}: not resolved (reference spread {spread:.1e})")
                continue
            times = {x: time_at([(r.error, getattr(r, clock)) for r in runs if r.label == x and not r.skipped], level)
                     for x in labels}
            table[(clock, level)] = times
            ratios = [times[x] / times["sympy"] for x in labels if x != "sympy"]
            log("  " + " | ".join([f"{level:g}"] + [fmt(times[x]) for x in labels] + [fmt(x) for x in ratios]))
    log("\n  compile (s): " + ", ".join(f"{k} {v:.1f}" for k, v in compile_seconds.items()))
    return {"levels": table, "compile": compile_seconds, "spread": spread, "agreement": agreement}


if __name__ == "__main__":
    rounds_main(run, __doc__)
