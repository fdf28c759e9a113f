"""Models with Python callables: the compiled loop calling them back against the path they took before.

A model with a callable torque, a callable drive signal, or a run with a callable ``tau``
used to leave the compiled loop for scipy's DOP853 stepping of the Python solve
(``run/paths.py``); the compiled loop now calls the callables back at every evaluation
(``codegen/callbacks.py``).  This script times both on the same model in the same process
(medians of ``--repeat`` runs, interleaved) and reports the ratio and the largest difference
of the samples.  The old path is the ``ScipyStepping`` of the Python solve
(``compiled_rhs=False``), which ``simulate`` still takes with ``integrator="scipy"`` on a tree::

    python bench/callables_compiled.py [--repeat 3]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

import mbcomp as mb
from mbcomp.core.run_options import RunOptions
from mbcomp.files.toml_model import library_models, load
from mbcomp.run.paths import IntegrationPath
from mbcomp.run.simulate import run_steps
from mbcomp.run.stats import Counts
from mbcomp.run.stepping import CompiledStepping, ScipyStepping

sys.path.insert(0, str(Path(__file__).resolve().parent))
from models import interleaved_medians  # noqa: E402

T_END = 5.0
DAMPING = 0.05  # N m s/rad, the callables' law: -DAMPING qd on every joint


def initial(model, system):
    neutral = system.topology.state_map.neutral()
    q = np.array([model.initial["q"].get(c, neutral[i]) for i, c in enumerate(system.coords)])
    qd = np.array([model.initial["qd"].get(c, 0.0) for c in system.speeds])
    return q, qd


def with_callable_torques(name: str, formulation: str):
    """The library model ``name`` with a callable damping torque on each of its tree joints
    (1-DOF revolutes): ``(model, system)``."""
    model = load(library_models()[name])
    plain = model.compile(formulation)
    for joint in plain.topology.tree_joints:
        i = plain.topology.q_slice[joint.name].start
        model.add(mb.JointTorque(f"damp_{joint.name}", joint.name, lambda t, q, qd, i=i: [-DAMPING * qd[i]]))
    return model, model.compile(formulation)


def one_run(system, q0, qd0, tau, compiled: bool):
    kernel, formulation = system.kernel, system._formulation
    options = RunOptions.checked(T_END, rtol=1e-8, atol=1e-10, t_eval=np.linspace(0, T_END, 51))
    z0 = np.zeros(kernel.compiled.drives.nz)
    if compiled:
        stepping = CompiledStepping(kernel, formulation, options, tau, z0, Counts())
        path = IntegrationPath("compiled")
    else:
        stepping = ScipyStepping(kernel, formulation, options, tau, z0, Counts(), compiled_rhs=False)
        path = IntegrationPath("scipy", "bench: the old path of models with Python callables")
    return run_steps(stepping, kernel, formulation, options, q0, qd0, path)


def cases():
    """``(label, system, q0, qd0, tau)``."""
    for name, formulation in (("double_pendulum", "lagrange"), ("five_link_pendulum", "lagrange"),
                              ("four_bar", "lagrange"), ("four_bar", "dae")):
        model, system = with_callable_torques(name, formulation)
        q0, qd0 = initial(model, system)
        q0, qd0 = system.assemble(q0, qd0)
        yield f"{name} torques", formulation, system, q0, qd0, None
    model = load(library_models()["five_link_pendulum"])
    system = model.compile()
    q0, qd0 = initial(model, system)
    yield "five_link_pendulum tau", "lagrange", system, q0, qd0, lambda t, q, qd: -DAMPING * qd


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    print(f"{'model':26s} {'form':9s} {'old s':>8s} {'compiled s':>10s} {'speed-up':>8s} {'max |dq|':>9s}")
    for label, formulation, system, q0, qd0, tau in cases():
        times, results = interleaved_medians(
            {path: (lambda path=path: one_run(system, q0, qd0, tau, path == "compiled")) for path in ("old", "compiled")},
            args.repeat)
        slow, fast = times["old"], times["compiled"]
        dq = float(np.abs(results["compiled"].q - results["old"].q).max())
        print(f"{label:26s} {formulation:9s} {slow:8.3f} {fast:10.4f} {slow / fast:8.1f} {dq:9.1e}", flush=True)


if __name__ == "__main__":
    main()
