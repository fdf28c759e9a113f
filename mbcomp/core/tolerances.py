"""Tolerances and thresholds shared by the Python and the C side, each named once.

Python code imports the constants; the hand-written C (the ``.c``/``.h`` files of the
package) reads them through the ``#define``s of :func:`c_defines`, which the templates
carry before any code that uses them.  Changing a number here changes both sides (and,
through the templates' text, the code cache's key).
"""
from __future__ import annotations

#: Relative pivot threshold of the mass matrix: a pivot of its Cholesky factor (squared
#: diagonal entry of ``L``; in the recursive dynamics, an articulated inertia ``D``) at or
#: below this fraction of the largest diagonal entry means a singular mass matrix.  Used by
#: the dense and recursive ``accelerations`` in C, the Python backend's recursive
#: accelerations and ``Kernel``'s diagnosis; C name ``MB_PIVOT_TOLERANCE``.
PIVOT_TOLERANCE = 1e-13

#: Relative rank tolerance of constraint rows: a row whose pivot (column-pivoted QR of the
#: Jacobian in Python; in the dae formulation's C, the square root of an eigenvalue of the
#: Schur complement ``J M^-1 J^T`` at rest, ``c/least_norm.h``) falls below this fraction of
#: the largest counts as dependent.  Rounding
#: leaves redundant rows of a planar loop at ~1e-16 relative; a mechanism within 1e-9 of a
#: dead point is treated as at it.  C name ``MB_RANK_TOLERANCE``.
RANK_TOLERANCE = 1e-9

#: Relative size (square root of an eigenvalue of the constraint Schur complement against
#: its largest, ``c/least_norm.h``) below which a constraint direction is dropped from a
#: KKT solve in motion (the dae loop, the compiled evaluation calls, an FMU) and from the
#: projections: a transient singular position.  1e-4 passes the two-four-bar linkage
#: through its singular crossings at rtol 1e-8 .. 1e-12 (smaller values stall the step
#: size near the crossings).  Passed to the C as an argument (``dae_configure_rows``).
SINGULAR_TOLERANCE = 1e-4

#: Speed (m/s or rad/s, every entry of ``qd``) below which a state on a singular position
#: counts as at rest: there a dropped constraint direction leaves the motion undetermined.
#: C name ``MB_REST_SPEED``.
REST_SPEED = 1e-9

#: Largest constraint residual (m, or rad for angle rows) the dae formulation's compiled
#: projection after an accepted step leaves uncorrected (absolute).  C name
#: ``MB_PROJECTION_RESIDUAL``.
PROJECTION_RESIDUAL = 1e-13

#: Absolute time tolerances (s) of Brent's method locating a contact event on its step: the
#: time a free contact's gap closes, and the time a held contact's normal force reaches zero
#: (the same in the compiled ``mb_brentq`` and scipy's ``brentq``; relative tolerance
#: ``4 eps``).
EVENT_GAP_XTOL = 1e-14
EVENT_FORCE_XTOL = 1e-13

# -- Coulomb friction on held contacts (formulations/friction.py, the compiled loops' friction.h) --
#: 1/s: the velocity feedback on sticking tangential rows (slip left by integration error
#: decays at this rate; at rest it is exactly zero, so nothing creeps).  C ``MB_STICK_RATE``.
STICK_RATE = 10.0

#: m/s: below this slip speed the slip direction is not taken from the slip velocity but
#: from the one the contact started sliding in.  C ``MB_DIRECTION_SPEED``.
DIRECTION_SPEED = 1e-9

#: Relative tolerance of the cone test (|lam_t| <= mu lam_n (1 + CONE_TOLERANCE) + CONE_FLOOR
#: N).  C ``MB_CONE_TOLERANCE``, ``MB_CONE_FLOOR``.
CONE_TOLERANCE = 1e-9
CONE_FLOOR = 1e-12

#: m/s: a sliding contact counts as stopped (a "stick" event) once its slip speed falls to
#: this (or its slip along its direction crosses zero, whichever comes first); a contact set
#: sliding slower than this (at a stick/slip transition) stops only when it slides back
#: faster than this.  Ten times ``DIRECTION_SPEED``, below which the sliding law's
#: direction ``v / |v|`` is not used; small enough that stopping early moves a stick time
#: by ``STOP_SPEED / deceleration`` (~1e-9 s at 10 m/s^2).  C ``MB_STOP_SPEED``.
STOP_SPEED = 1e-8

#: m/s: the slip speed below which the slip direction at a step's start is not its own
#: (the contact's direction is used instead) when a stop is watched for.  ``STOP_SPEED``: a
#: contact set sliding slower than that is watched along the direction it was set sliding
#: in, since the slip a sticking phase leaves (~1e-12 m/s, from the integration error under
#: the ``STICK_RATE`` feedback; a ball rolling off a ball) points anywhere, and taken as the
#: direction it made the contact "stop" at once, sliding "back".  C ``MB_SLIP_FLOOR``.
SLIP_FLOOR = STOP_SPEED

#: The friction solve's least-squares cut-off: singular values of its (non-symmetric) KKT
#: Schur matrix below this fraction of the largest are dropped (redundant rows share the
#: load by the least-norm multipliers).  C ``MB_FRICTION_RCOND``.
FRICTION_RCOND = 1e-10

#: A sliding contact's effective normal inverse mass with friction ``(J M^-1 W^T)_kk`` at or
#: below this fraction of the largest diagonal entry is Painleve's paradox.  C ``MB_PAINLEVE``.
PAINLEVE = 1e-9

#: Largest residual of the friction solve (relative to max(1, |rhs|)) before the held rows
#: count as inconsistent.  C ``MB_FRICTION_RESIDUAL``.
FRICTION_RESIDUAL = 1e-6

#: A held contact's normal force counts as pulling in the compiled loops' contact watch
#: when below minus this fraction of the largest held force: redundant held rows (a box's
#: four corners on a plane) leave one multiplier at zero, which rounding makes -1e-16
#: relative, and a watch stopping there would stop at every step.  C name
#: ``MB_FORCE_ROUNDING``.
FORCE_ROUNDING = 1e-9

#: ``{C name: value}`` of every constant the C files read.
C_NAMES = {"MB_PIVOT_TOLERANCE": PIVOT_TOLERANCE, "MB_RANK_TOLERANCE": RANK_TOLERANCE,
           "MB_REST_SPEED": REST_SPEED, "MB_PROJECTION_RESIDUAL": PROJECTION_RESIDUAL,
           "MB_STICK_RATE": STICK_RATE, "MB_DIRECTION_SPEED": DIRECTION_SPEED,
           "MB_CONE_TOLERANCE": CONE_TOLERANCE, "MB_CONE_FLOOR": CONE_FLOOR, "MB_STOP_SPEED": STOP_SPEED,
           "MB_SLIP_FLOOR": SLIP_FLOOR, "MB_FRICTION_RCOND": FRICTION_RCOND, "MB_PAINLEVE": PAINLEVE,
           "MB_FRICTION_RESIDUAL": FRICTION_RESIDUAL,
           "MB_FORCE_ROUNDING": FORCE_ROUNDING}


def c_defines() -> str:
    """The ``#define``s of the tolerances for the C templates (``repr`` of each float: the
    C literal is the same double).  Repeating them in one unit is allowed (identical macro
    redefinitions)."""
    return "".join(f"#define {name} {value!r}\n" for name, value in C_NAMES.items())
