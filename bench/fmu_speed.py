"""FMU export: the speed of a co-simulation FMU against mbcomp's own simulate, and the time
an export takes beyond the compile.

Usage: python bench/fmu_speed.py [--rounds R] [--model NAME] (default R = 5, double_pendulum)

- **run**: the double pendulum over 10 s at rtol 1e-8 (atol 1e-10, mbcomp's defaults) with
  1001 output samples.  ``mbcomp``: ``System.simulate`` (compiled DOP853, dense output at the
  samples).  ``fmu_one_step``: the CS FMU called through FMPy's low-level ``FMU2Slave``, one
  ``fmi2DoStep`` over the 10 s (the integrator alone).  ``fmu_1000_steps``: 1000 ``fmi2DoStep``
  of 0.01 s with the outputs read after each (what an importer does; every step ends on a
  communication point, so the integrator restarts its last step there).
  ``fmpy_calls_only``: the same 2000 calls through FMPy without integrating (``getRealStatus``
  for ``doStep``): the importer's share, taken off in ``ratio_1000_steps_net``.
  ``fmpy_simulate``: FMPy's ``simulate_fmu`` with ``output_interval`` 0.01 (its Python loop and
  recording included).  Each is timed R times after one untimed run; medians.
- **export**: in a new empty code cache, ``Model.compile()`` (cold), then ``export_fmu``
  (``export_first_s``: the FMU's template unit, mbcomp's C with the FMI functions, is
  compiled once per kind of model and cached) and ``export_fmu`` again (``export_warm_s``:
  the model's generated functions and tables compiled and linked, the zip written).
  ``export_after_cache_hit_s``: a new process would compile from the cache and then needs the
  generated C again (sympy), unless a previous export cached it: timed as compile (cache hit)
  in a fresh System, then export.

Results go to ``bench/results/fmu_speed.csv`` and are printed with the ratios (targets: the
FMU within 2x of mbcomp's simulate; the export at most 1 s beyond the compile).
"""
from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def timed(fn, rounds: int) -> float:
    fn()
    samples = []
    for _ in range(rounds):
        started = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - started)
    return statistics.median(samples)


class Slave:
    """The CS FMU at ``path`` loaded once through FMPy's low-level ``FMU2Slave`` (extracted and
    its library opened here, not in the timed runs)."""

    def __init__(self, path):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        md = read_model_description(str(path))
        self.refs = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
        self.fmu.instantiate()  # (FMPy's freeInstance unloads the library: runs reset the instance instead)

    def run(self, t_end: float, steps: int, rtol: float, atol: float) -> np.ndarray:
        """Reset, initialise, ``steps`` doStep calls reading the angles after each, terminate."""
        fmu, refs = self.fmu, self.refs
        fmu.reset()
        fmu.setReal([refs["mbcomp.rtol"], refs["mbcomp.atol"]], [rtol, atol])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        outs = [refs["phi1"], refs["theta2"]]
        h = t_end / steps
        rows = []
        for k in range(steps):
            fmu.doStep(currentCommunicationPoint=k * h, communicationStepSize=h)
            rows.append(fmu.getReal(outs))
        fmu.terminate()
        return np.array(rows)

    def calls_only(self, steps: int) -> None:
        """The importer's own cost of ``run``'s loop: the same number of calls through FMPy
        (``getRealStatus`` in place of ``doStep``, and ``getReal``), nothing integrated."""
        from fmpy.fmi2 import fmi2LastSuccessfulTime
        fmu, refs = self.fmu, self.refs
        outs = [refs["phi1"], refs["theta2"]]
        for _ in range(steps):
            fmu.getRealStatus(fmi2LastSuccessfulTime)
            fmu.getReal(outs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--model", default="double_pendulum")
    args = parser.parse_args()
    os.environ["MBCOMP_CACHE_DIR"] = tempfile.mkdtemp(prefix="mbcomp-fmu-bench-")
    import mbcomp as mb
    from fmpy import simulate_fmu

    rows = {}
    # -- export time beyond the compile (a new cache: a cold compile first) ---------------------
    model = mb.load(args.model)
    started = time.perf_counter()
    system = model.compile()
    rows["compile_cold_s"] = time.perf_counter() - started
    folder = Path(tempfile.mkdtemp(prefix="mbcomp-fmu-"))
    started = time.perf_counter()
    path = system.export_fmu(folder / "cs.fmu", kind="cs")
    rows["export_first_s"] = time.perf_counter() - started
    rows["export_warm_s"] = timed(lambda: system.export_fmu(folder / "cs.fmu", kind="cs"), args.rounds)
    rows["export_me_warm_s"] = timed(lambda: system.export_fmu(folder / "me.fmu", kind="me"), 1)

    def after_hit():
        again = mb.load(args.model).compile()  # a cache hit: the generated C is not in memory
        started = time.perf_counter()
        again.export_fmu(folder / "hit.fmu", kind="cs")
        return time.perf_counter() - started
    rows["export_after_cache_hit_s"] = statistics.median(after_hit() for _ in range(args.rounds))

    # -- run speed -------------------------------------------------------------------------------
    t_end, rtol, atol = 10.0, 1e-8, 1e-10
    q0 = [model.initial["q"].get(c, 0.0) for c in system.coords]
    t_eval = np.linspace(0.0, t_end, 1001)
    ref = system.simulate(t_end, q0, t_eval=t_eval, rtol=rtol, atol=atol)
    rows["mbcomp_simulate_s"] = timed(lambda: system.simulate(t_end, q0, t_eval=t_eval, rtol=rtol, atol=atol),
                                      args.rounds)
    slave = Slave(path)
    rows["fmu_one_step_s"] = timed(lambda: slave.run(t_end, 1, rtol, atol), args.rounds)
    rows["fmu_1000_steps_s"] = timed(lambda: slave.run(t_end, 1000, rtol, atol), args.rounds)
    rows["fmpy_calls_only_s"] = timed(lambda: slave.calls_only(1000), args.rounds)
    rows["fmpy_simulate_s"] = timed(lambda: simulate_fmu(str(path), stop_time=t_end, output_interval=0.01,
                                                          start_values={"mbcomp.rtol": rtol, "mbcomp.atol": atol}),
                                    args.rounds)
    end = slave.run(t_end, 1, rtol, atol)[-1]
    rows["one_step_difference_rad"] = float(np.abs(end - ref.q[-1]).max())  # the same loop: rounding only
    got = slave.run(t_end, 1000, rtol, atol)
    rows["1000_steps_difference_rad"] = float(np.abs(got - ref.q[1:]).max())  # other steps: within the tolerance
    rows["ratio_one_step"] = rows["fmu_one_step_s"] / rows["mbcomp_simulate_s"]
    rows["ratio_1000_steps"] = rows["fmu_1000_steps_s"] / rows["mbcomp_simulate_s"]
    rows["ratio_1000_steps_net"] = (rows["fmu_1000_steps_s"] - rows["fmpy_calls_only_s"]) / rows["mbcomp_simulate_s"]
    rows["ratio_fmpy_simulate"] = rows["fmpy_simulate_s"] / rows["mbcomp_simulate_s"]
    rows["load_average"] = os.getloadavg()[0]

    out = HERE / "results" / "fmu_speed.csv"
    out.parent.mkdir(exist_ok=True)
    with open(out, "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(["quantity", "value"])
        writer.writerows(rows.items())
    width = max(map(len, rows))
    for key, value in rows.items():
        print(f"{key:<{width}}  {value:.4g}")
    print(f"targets: FMU run within 2x of simulate: one step {rows['ratio_one_step']:.2f}x, "
          f"1000 steps {rows['ratio_1000_steps']:.2f}x ({rows['ratio_1000_steps_net']:.2f}x without FMPy's own "
          f"calls); export beyond compile <= 1 s: "
          f"{rows['export_warm_s']:.2f} s warm, {rows['export_first_s']:.2f} s first; results in {out}")


if __name__ == "__main__":
    sys.exit(main())
