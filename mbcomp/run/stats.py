"""``Result.stats``: built in one place, with the same keys on every run path."""
from __future__ import annotations

from dataclasses import dataclass

from mbcomp.core.run_options import RunOptions

#: The message of a run that reached ``t_end`` (scipy's words).
FINISHED = "The solver successfully reached the end of the integration interval."
#: ... of a run with nothing to integrate.
PRESCRIBED = "No degree of freedom: the motion follows from the constraints."


@dataclass
class Counts:
    """What a run counted: right-hand side evaluations (``nfev``), Jacobians (``njev``) and LU
    decompositions (``nlu``) of scipy's implicit methods, accepted ``steps``, ``rejected``
    steps (None where the stepping does not count them: scipy's solvers), and ``restarts``
    (the integrator started afresh: after an event, a projection, a new partition, a retreat)."""

    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    steps: int = 0
    rejected: int | None = None
    restarts: int = 0


def run_stats(options: RunOptions, formulation: str, counts: Counts, wall_time: float, *, integrator: str,
              method: str, path: str, message: str = FINISHED, rhs: str = "python") -> dict:
    """The ``Result.stats`` of a finished run.  ``integrator``: ``"compiled"`` (the loop
    compiled with the model), ``"scipy"`` (scipy's stepping of the compiled right-hand side)
    or ``"none"`` (nothing to integrate); ``path``: ``System.integration_path``'s answer for
    the run (``"compiled"`` or ``"scipy: <why>"``); ``rhs``: what evaluated the right-hand
    side, ``"compiled"`` (one C function per evaluation: the compiled loops, or scipy's
    stepping of the compiled right-hand side) or ``"python"`` (the formulation's Python
    workspace, which calls the compiled model's pieces); ``wall_time`` in s."""
    return {"method": method, "integrator": integrator, "path": path, "rhs": rhs,
            "nfev": int(counts.nfev), "njev": int(counts.njev), "nlu": int(counts.nlu),
            "steps": int(counts.steps), "rejected": None if counts.rejected is None else int(counts.rejected),
            "restarts": int(counts.restarts), "status": 0, "message": message, "success": True,
            "wall_time": float(wall_time), "rtol": options.rtol, "atol": options.atol, "formulation": formulation}
