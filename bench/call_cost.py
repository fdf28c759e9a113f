"""Cost of one public forward-dynamics call from Python: mbcomp ``System.accelerations(q, qd)``
against Pinocchio ``pin.aba(model, data, q, v, tau)`` (and MuJoCo: set qpos/qvel,
``mj_forward``, copy qacc), for the N-link chain.

Both are the ordinary public calls with numpy arrays in and out (a random state, the same
for every tool); the results are checked to agree before timing.  Per call: a timeit loop
of ~10 ms; ``rounds`` interleaved rounds (every tool once per round, so that a noisy spell
hits them alike), median over the rounds, as this thread's CPU time and as wall time.

Usage: python bench/call_cost.py [N ...] [--rounds 7]    (default N = 5 20 50)
Writes bench/results/call_cost.csv.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
import timeit
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import write_csv  # noqa: E402
from peers import MbcompChain, available  # noqa: E402
from timing import fmt  # noqa: E402


def per_call(fn, number: int) -> tuple[float, float]:
    """(CPU us, wall us) per call of one timeit loop of ``number`` calls."""
    cpu = timeit.Timer(fn, timer=time.thread_time).timeit(number) / number
    wall = timeit.Timer(fn).timeit(number) / number
    return 1e6 * cpu, 1e6 * wall


def calls_for(n: int) -> dict:
    """``{tool: fn}`` of one call each, at one random state; results checked to agree."""
    rng = np.random.default_rng(3)
    q, qd = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    system = MbcompChain(n).system
    expected = system.accelerations(q, qd)
    calls = {"mbcomp System.accelerations": lambda: system.accelerations(q, qd)}
    found = available()
    if found["pinocchio"]:
        import pinocchio as pin
        from peers import PinocchioChain
        pn = PinocchioChain(n)
        model, data, tau = pn.model, pn.data, np.zeros(n)
        assert np.allclose(pin.aba(model, data, q, qd, tau), expected, rtol=1e-9, atol=1e-9)
        calls["pin.aba"] = lambda: pin.aba(model, data, q, qd, tau)
    if found["mujoco"]:
        import mujoco
        from peers import MujocoChain
        mj = MujocoChain(n)
        m, d = mj.model, mj.data

        def mj_call():
            d.qpos[:] = q
            d.qvel[:] = qd
            mujoco.mj_forward(m, d)
            return d.qacc.copy()
        assert np.allclose(mj_call(), expected, rtol=1e-9, atol=1e-9)
        calls["MuJoCo set + mj_forward + qacc"] = mj_call
    return calls


def run(sizes=(5, 20, 50), rounds: int = 7, log=print) -> list[dict]:
    log(f"public call cost, N = {list(sizes)}")
    rows = []
    for n in sizes:
        calls = calls_for(n)
        numbers = {}
        for key, fn in calls.items():
            count, _ = timeit.Timer(fn).autorange()
            numbers[key] = max(1, int(count * 0.01 / 0.2))
        cpu = {key: [] for key in calls}
        wall = {key: [] for key in calls}
        for _ in range(rounds):
            for key, fn in calls.items():
                c, w = per_call(fn, numbers[key])
                cpu[key].append(c)
                wall[key].append(w)
        row = {"N": n}
        for key in calls:
            row[f"{key} us"] = statistics.median(cpu[key])
            row[f"{key} wall us"] = statistics.median(wall[key])
        if "pin.aba" in calls:
            row["ratio accelerations / aba"] = row["mbcomp System.accelerations us"] / row["pin.aba us"]
            row["ratio accelerations / aba (wall)"] = (row["mbcomp System.accelerations wall us"]
                                                       / row["pin.aba wall us"])
        rows.append(row)
        log(f"  N = {n}: accelerations {fmt(row['mbcomp System.accelerations us'])} us, "
            f"aba {fmt(row.get('pin.aba us', float('nan')))} us, ratio {fmt(row.get('ratio accelerations / aba', float('nan')), 2)}")
    write_csv(rows, "call_cost.csv")
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("sizes", nargs="*", type=int, default=[5, 20, 50])
    parser.add_argument("--rounds", type=int, default=7)
    args = parser.parse_args(argv)
    return run(args.sizes, args.rounds)


if __name__ == "__main__":
    main()
