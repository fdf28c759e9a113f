"""The dae formulation's C code: the KKT system solved in the compiled integrators.

The rows of the KKT system are configured per thread (``dae_configure_rows``, from
``dae_compiled.DaeRows``): geometric rows of the generated ``constraints``, motor rows
(``q_k - offset - speed t`` for a speed motor, ``q_k - s(t)`` for a position motor whose
``s`` is a file expression: its value and exact first and second derivatives run as
postfix programs, see ``expressions_c.py``) and the gaps of contacts held closed (rows of
the generated ``contacts``).  The multipliers of the last solve are kept (``dae_lam``): the
contact watch reads the held contacts' normal forces from them.  Held contacts with friction
modes switch the solve to ``c/friction.h``'s (``friction_c.py``): tangential rows of sticking
contacts, friction columns of sliding ones, least-norm multipliers.
"""
from __future__ import annotations

from mbcomp.build.c_sizes import DAE_SPEC_LONGS
from mbcomp.core import c_text, tolerances

#: Row kinds of the configured KKT rows (the first entry of each row's spec).
ROW_GEOMETRIC, ROW_MOTOR, ROW_CONTACT = 0, 1, 2
#: Longs per row in the spec (kind, index, coordinate, speed index, program start or -1) and
#: doubles per row in the data (speed, offset).
SPEC_LONGS, DATA_DOUBLES = DAE_SPEC_LONGS, 2


def c_dae_accelerations(nq: int, ng: int) -> str:
    """C source of the ``dae`` formulation's accelerations (compiled in where ``DAE_LOOP`` is
    defined: a model with constraints or contacts): the KKT system solved through the Schur
    complement, ``M = L L^T``, ``Y = L^-1 J_r^T``, ``(Y^T Y) lam = rhs - Y^T L^-1 f``,
    ``qdd = L^-T (L^-1 f + Y lam)``, on the rows configured per thread with Baumgarte gains.
    The multipliers are the least-norm ones: the Cholesky solve where its pivots show full
    rank, else ``c/least_norm.h``'s Jacobi eigen-decomposition of the Schur complement (directions below the singular tolerance dropped in motion, below
    ``RANK_TOLERANCE`` at rest), so the solve carries on through singular positions.
    Returns 0, 1 when M is not positive definite, 2 when the rows lost rank at rest (a dead
    point, where the motion is not determined: the caller's Python path names it) or are not
    finite.  ``dae_project``
    moves a state back onto the constraints after an accepted step.  The time of motor rows
    is ``dae_time`` (set by the integrators before each call).  Offsets into the packed
    outputs come from the ``OutputLayout`` defines.  The C is ``c/dae.c`` (it includes
    ``program.h``, ``brentq.h`` and ``least_norm.h``), after the ``#define``s of the row kinds, the opcodes and
    the tolerances.
    """
    from mbcomp.codegen import events_c, expressions_c
    defines = (f"#define DAE_SPEC_LONGS {SPEC_LONGS}\n#define DAE_DATA_DOUBLES {DATA_DOUBLES}\n"
               f"#define DAE_ROW_GEOMETRIC {ROW_GEOMETRIC}\n#define DAE_ROW_MOTOR {ROW_MOTOR}\n"
               f"#define DAE_ROW_CONTACT {ROW_CONTACT}\n")
    return ("\n" + defines + events_c.C_DEFINES + expressions_c.C_DEFINES + tolerances.c_defines()
            + c_text.read("mbcomp.formulations", "dae.c"))
