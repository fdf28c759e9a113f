"""Many simulations of one System: parameter studies on threads, processes or a Dask cluster."""
from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor, as_completed
from typing import Any, Iterable, Mapping

from mbcomp.core.errors import ModelError
from mbcomp.codegen.integrators import step_hook
from mbcomp.core.progress import ProgressBar
from mbcomp.core.result import Result

_CASE_KEYS = {"q0", "qd0", "t_end", "parameters", "tau", "t_eval", "method", "rtol", "atol", "max_step", "dt",
              "integrator", "rest_speed", "max_samples"}


def _check_case(case: Mapping[str, Any], index: int, defaults: Mapping[str, Any]) -> dict:
    if not isinstance(case, Mapping):
        raise ModelError(f"case {index}", f"must be a mapping of simulate() arguments, got {type(case).__name__}")
    merged = {**defaults, **case}
    unknown = sorted(set(merged) - _CASE_KEYS)
    if unknown:
        raise ModelError(f"case {index}", f"unknown key(s) {unknown}; allowed: {sorted(_CASE_KEYS)}")
    for key in ("q0", "t_end"):
        if key not in merged:
            raise ModelError(f"case {index}", f"needs {key!r} (give it in the case or as a default)")
    return merged


def _run(system, case: dict) -> Result:
    """One simulation; the Result without its System (plain data, cheap to send between
    processes: the caller binds its own System with the case's parameters)."""
    case = dict(case)
    t_end, q0 = case.pop("t_end"), case.pop("q0")
    qd0 = case.pop("qd0", None)
    return system.simulate(t_end, q0, qd0, **case).with_system(None)


def _run_stoppable(system, case: dict, stop: threading.Event) -> Result:
    """One simulation on a worker thread that ends early (SimulationError) once ``stop`` is set."""
    with step_hook(lambda t: stop.is_set()):
        return _run(system, case)


def _run_many(system, cases: list) -> list:
    """Several simulations in one task."""
    return [_run(system, case) for case in cases]


def sweep(system, cases: Iterable[Mapping[str, Any]], client: Any = None, *, threads: int | None = None,
          progress: bool = False, **defaults: Any) -> list[Result]:
    """Simulate ``system`` once per case and return the Results in case order.

    Each case is a mapping of ``System.simulate`` arguments (``q0``, ``qd0``, ``t_end``,
    ``parameters``, ``t_eval``, ``method``, ...); ``defaults`` fill what a case leaves
    out.  Without ``client`` the cases run on a thread pool (the compiled integrator
    releases the GIL); with a ``dask.distributed.Client`` they run on its workers (the
    System travels by pickling and is recompiled there, from the shared code cache
    when there is one).  Results are identical to running the cases one by one, derived
    series included (reactions of resting contacts and motors: each Result records what
    they need).  ``progress=True`` shows a bar of the finished cases (it only counts them;
    every case runs as without it).
    """
    if isinstance(cases, (str, bytes, Mapping)) or not isinstance(cases, Iterable):
        raise ModelError("sweep", f"cases must be a sequence of mappings of simulate() arguments, got {cases!r}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise ModelError("sweep", f"threads must be a positive whole number or None, got {threads!r}")
    cases = [_check_case(case, i, defaults) for i, case in enumerate(cases)]
    bar = ProgressBar(len(cases), bool(progress), desc="sweep", unit="cases")
    try:
        outputs = _sweep(system, cases, client, threads, bar)
    finally:
        bar.close()
    return [result.with_system(system.with_parameters(case.get("parameters"))) for case, result in zip(cases, outputs)]


def _sweep(system, cases: list, client: Any, threads: int | None, bar: ProgressBar) -> list:
    if client is None:
        if threads == 1 or len(cases) <= 1:
            outputs = []
            for case in cases:
                outputs.append(_run(system, case))
                bar.update_to(len(outputs))
        else:
            stop = threading.Event()
            with ThreadPoolExecutor(max_workers=threads) as pool:
                futures = [pool.submit(_run_stoppable, system, case, stop) for case in cases]
                try:
                    for done, future in enumerate(as_completed(futures), start=1):
                        if future.exception() is not None:
                            future.result()   # a failed case: stop the others now
                        bar.update_to(done)
                    outputs = [future.result() for future in futures]
                except BaseException:
                    stop.set()  # Ctrl-C or a failed case: running cases stop at their next check
                    pool.shutdown(wait=True, cancel_futures=True)
                    raise
    else:
        # Cases go to the workers in chunks (a few per worker thread): scheduling a task
        # costs milliseconds, more than a short compiled simulation.
        try:
            slots = sum(client.nthreads().values())
        except (AttributeError, TypeError):
            slots = len(client.scheduler_info().get("workers", {}))
        size = max(1, -(-len(cases) // (4 * max(slots, 1))))
        chunks = [cases[i:i + size] for i in range(0, len(cases), size)]
        remote = client.scatter(system, broadcast=True, hash=False)
        futures = [client.submit(_run_many, remote, chunk, pure=False) for chunk in chunks]
        if bar.enabled:
            from distributed import as_completed as finished
            done = 0
            for future in finished(futures):
                done += len(chunks[futures.index(future)])
                bar.update_to(done)
        outputs = [output for chunk in client.gather(futures) for output in chunk]
    return outputs
