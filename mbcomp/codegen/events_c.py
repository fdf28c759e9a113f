"""Event location in compiled code: Brent's root finder in C, for any formulation's loop.

``c/brentq.h`` (``C_BRENTQ``) defines ``mb_brentq(f, ctx, a, b, xtol, rtol, maxiter,
&status)``, the same algorithm, tests and step choices as scipy's ``brentq``
(scipy/optimize/Zeros/brentq.c), so that a root located in C equals the one ``scipy.optimize.brentq`` finds on the same
function to rounding.  A formulation's C code includes it and passes its own gap or contact
force on an event step's dense output as ``f`` (see ``formulations/dae_c.py``:
``dae_gap_root``, ``dae_force_root``).  ``status``: 0 converged, 1 no sign change
between a and b, 2 not converged in ``maxiter`` iterations, 3 ``f`` returned NaN.
"""
from __future__ import annotations

from mbcomp.core import c_text

#: Iterations (scipy's default for brentq).
MAX_ITERATIONS = 100

#: The ``#define`` a unit that calls ``mb_brentq`` needs (its iteration limit).
C_DEFINES = f"#define MB_BRENTQ_ITERATIONS {MAX_ITERATIONS}\n"
#: ``mb_brentq`` (``c/brentq.h``), after ``C_DEFINES``.
C_BRENTQ = C_DEFINES + c_text.read("mbcomp.codegen", "brentq.h")
