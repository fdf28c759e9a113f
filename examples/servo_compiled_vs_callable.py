"""A PID-controlled DC motor on a pendulum: compiled signals against a Python controller.

The same servo is built twice: once with a ``PID`` block (compiled into the generated code,
so the whole simulation runs in the compiled DOP853 loop), once with the controller written
as a Python callable ``voltage(t, q, qd)`` (a PD law; the integral would need a state, so
this one is a PD servo in both models: ``ki = 0``).  Both give the same motion; the script
prints both run times and checks that the held angle matches the PD law's static balance
``kp (setpoint - angle) k ratio / R = m g l sin(angle)``.

Run: ``python examples/servo_compiled_vs_callable.py``.
"""
import time

import numpy as np
from scipy.optimize import brentq

import mbcomp as mb

G, MASS, LENGTH = 9.81, 1.0, 0.5
RATIO, R, L, K = 20.0, 2.0, 0.05, 0.03
KP, KD, SETPOINT = 60.0, 6.0, 0.6


def servo(voltage=None) -> mb.Model:
    m = mb.Model("servo" if voltage is None else "servo_callable", gravity=(0, 0, -G))
    rod = m.add(mb.Body("rod", mass=MASS, com=(0, 0, -LENGTH)))
    joint = m.add(mb.Revolute("hinge", m.ground, rod, axis="x", coords="angle"))
    if voltage is None:
        voltage = m.add(mb.PID("pid", mb.Angle(joint), SETPOINT, kp=KP, kd=KD))
    m.add(mb.DCMotor("motor", joint, ratio=RATIO, resistance=R, inductance=L, k=K, voltage=voltage))
    return m


def python_controller(t, q, qd):
    return KP * (SETPOINT - q[0]) - KD * qd[0]


def main() -> None:
    compiled = servo().compile()
    python = servo(python_controller).compile()
    print("PID block:      ", compiled.integration_path())
    print("Python callable:", python.integration_path())
    t = np.linspace(0.0, 5.0, 501)
    runs = {}
    for name, system in (("compiled", compiled), ("python", python)):
        system.simulate(0.1, [0.0])  # warm up (binds the compiled code)
        started = time.perf_counter()
        for _ in range(3):
            res = system.simulate(5.0, [0.0], t_eval=t)
        runs[name] = (res, (time.perf_counter() - started) / 3)
        print(f"{name:9s} {runs[name][1] * 1e3:8.2f} ms per 5 s simulation ({res.stats['integrator']}, "
              f"{res.stats['nfev']} evaluations)")
    print(f"speed-up {runs['python'][1] / runs['compiled'][1]:.0f}x")
    a, b = runs["compiled"][0], runs["python"][0]
    assert np.max(np.abs(a["angle"] - b["angle"])) < 1e-6
    assert np.max(np.abs(a["motor.current"] - b["motor.current"])) < 1e-5
    held = brentq(lambda x: KP * (SETPOINT - x) * K * RATIO / R - MASS * G * LENGTH * np.sin(x), 0.0, SETPOINT)
    print(f"held at {a['angle'][-1]:.6f} rad, static balance {held:.6f} rad")
    assert abs(a["angle"][-1] - held) < 1e-5


if __name__ == "__main__":
    main()
