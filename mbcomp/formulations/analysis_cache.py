"""What ``analyse`` finds about a model's constraints, kept in the code cache beside the model.

The analysis searches for consistent configurations (least squares from several guesses, then
a pivoted QR): in a new process it costs the import of ``scipy.optimize`` and ``scipy.linalg``
and the search itself, 0.3-0.9 s for a four-bar, every time a model with constraints is
compiled, cache hit or not.  Its result depends on the compiled code (the model's cache key),
the parameter values (the consistent configuration depends on the lengths), the formulation
and its options, and the analysis code itself: all of them are in this entry's key, so a
change of any of them analyses again.  Only a successful analysis is kept (a failure raises
every time, naming the constraints).
"""
from __future__ import annotations

import hashlib
import inspect
import json
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from mbcomp.codegen import cache
from mbcomp.build import constraint_set
from mbcomp.formulations.base import FormulationInfo, analyse

#: The cached entry's file suffix.
SUFFIX = ".analysis.json"


def cached_analyse(formulation, kernel, model_key: str | None, parameters: Mapping[str, Any],
                   options: Mapping[str, Any]) -> FormulationInfo:
    """``analyse(formulation, kernel)``, from the code cache when the same analysis was kept
    (``model_key``: the compiled model's cache key; None: no cache)."""
    key = None if model_key is None or formulation.constraints is None else \
        _key(formulation, kernel, model_key, parameters, options)
    if key is not None:
        info = _read(key)
        if info is not None:
            return info
    info = analyse(formulation, kernel)
    if key is not None:
        cache.store(key, SUFFIX, json.dumps(_as_data(info)).encode(), {})
    return info


def _key(formulation, kernel, model_key: str, parameters: Mapping[str, Any],
         options: Mapping[str, Any]) -> str | None:
    """The entry's key, or None when an input has no stable text (a Python callable, say: the
    analysis then runs every time).  The code it hashes: the analysis, the constraint set, the
    formulation, the kernel that evaluates the compiled functions and the state map."""
    try:
        values = {name: np.asarray(value, dtype=float).tolist() for name, value in sorted(parameters.items())}
        modules = (inspect.getmodule(FormulationInfo), constraint_set, inspect.getmodule(type(formulation)),
                   inspect.getmodule(type(kernel)), inspect.getmodule(type(kernel.topology.state_map)))
        sources = [Path(inspect.getfile(module)).read_bytes() for module in modules]
    except (TypeError, ValueError, OSError):
        return None
    identity = json.dumps({"formulation": type(formulation).__name__, "options": repr(sorted(options.items())),
                           "parameters": values, "code": [hashlib.sha256(s).hexdigest() for s in sources]},
                          sort_keys=True)
    if " at 0x" in identity:  # an option's text names an object's address: not stable between processes
        return None
    return cache.entry_key(f"{model_key}\nconstraint analysis", identity, {})


def _as_data(info: FormulationInfo) -> dict:
    rows = None if info.nominal_rows is None else [int(r) for r in info.nominal_rows]
    return {"ndof": info.ndof, "nominal_rank": info.nominal_rank, "nominal_rows": rows,
            "jacobian_scale": info.jacobian_scale, "schur_scale": info.schur_scale, "redundant": list(info.redundant)}


def _read(key: str) -> FormulationInfo | None:
    """The kept analysis, or None (none kept, or not readable as one)."""
    text = cache.read_text(key, SUFFIX, {})
    if text is None:
        return None
    try:
        data = json.loads(text)
        rows = None
        if data["nominal_rows"] is not None:
            rows = np.array(data["nominal_rows"], dtype=int)
            rows.flags.writeable = False
        return FormulationInfo(ndof=int(data["ndof"]), nominal_rank=data["nominal_rank"], nominal_rows=rows,
                               jacobian_scale=float(data["jacobian_scale"]), schur_scale=float(data["schur_scale"]),
                               redundant=tuple(data["redundant"]))
    except (ValueError, KeyError, TypeError):
        cache.discard(key, SUFFIX)
        return None
