"""The lagrange formulation's C code: coordinate partitioning stepped in the compiled loop.

The compiled DOP853 loop integrates the reduced state ``y = [q_i, qd_i]`` (the independent
coordinates and their speeds); everything else follows in C, as in ``LagrangeWorkspace``:

- the dependent coordinates by Newton on ``g(q, t) = 0`` (the rows chosen independent),
  started from the last accepted state advanced by its speeds;
- the dependent speeds from ``J_d qd_d = -(J_i qd_i + g_t)``;
- velocity rows (rolling, no-slip: ``g`` has no position part) remove speeds only: the
  coordinates are then partitioned on the position rows alone (``lag_prows``, ``lag_qdep``,
  ``lag_qind``), the speeds on all rows, and ``y = [x_qi, qd_i]`` holds more coordinates
  than speeds (the rates of the independent coordinates may be dependent speeds);
- the accelerations from ``(B^T M B) qdd_i = B^T (f + tau - M c)``, ``B = [I; -J_d^-1 J_i]``,
  ``c = -J_d^-1 bias`` on the dependent rows;
- after each accepted step, the condition of ``J_d`` (largest singular value of ``J``, or its
  regular size, over the smallest of ``J_d``): above the limit the loop pauses and Python
  chooses the partition afresh.

Drive elements add their forces (the generated ``drives`` at time t); their states follow in
the reduced state, ``y = [q_i, qd_i, z]``, with contacts too.
Motor rows (``q_k - offset - speed t``, or ``q_k - s(t)`` for a position given as an
expression of t: ``s`` and its exact derivatives run as postfix programs, ``expressions_c.py``)
are evaluated here, the geometric rows come from the generated ``constraints``.  Outputs are full ``[q, qd]`` rows.  The partition, the motor data
and the accepted-state buffer (``[t, q, qd]``, written after every accepted step) are
numpy arrays that Python owns and configures per thread with ``lagrange_configure``.
Quaternions (``Ball``/``Free`` joints) are stepped in the chart of ``statemap.Chart``: the
reduced state holds the independent chart coordinates (a screw coordinate itself, a rotation
vector about Python's chart base for a ball) and their speeds; Newton runs on ``J D`` (``D``
the right Jacobian of each rotation vector), the rates are ``x' = D^-1 v``, and the loop
pauses for Python to re-centre the chart once a rotation vector exceeds ``CHART_LIMIT``.

Contacts: a contact held closed (persistent) is one more row (its gap).  With
``lagrange_watch`` configured, the loop checks every accepted step for a free contact whose
gap closes (the test of ``events.ContactWatch``) and a held contact whose normal force
(from ``J^T lam = M qdd - f - tau`` on the chosen rows) would pull; such a step is not
taken: the loop returns EVENT with the step's end state and dense output in the watch
buffer, and Python locates and applies the event (``events.ContactWatch``).  Held contacts
with friction modes (``friction_c.py``, ``c/friction.h``): the accelerations come from the
full KKT system with friction (the partition still gives the state), the held contacts'
forces from its multipliers, and the watch also stops at a stick or slip transition.
"""
from __future__ import annotations

# The loop's statuses: TRIAL_FAILED, a trial state without dependent coordinates (Newton
# failed or the dependent block is singular; like ``TrialStateError``, the step is retried
# from the last accepted state); PAUSED, after an accepted step for Python to look at the
# partition.
from mbcomp.codegen.expressions_c import C_PROGRAM
from mbcomp.codegen.integrators import EVENT, PAUSED, TRIAL_FAILED


def c_lagrange(nv: int, ng: int) -> str:
    """C source of the lagrange formulation's reduced right-hand side (``lagrange_rhs``),
    full-state reconstruction (``lagrange_full``), per-step bookkeeping (``lagrange_accept``),
    configuration (``lagrange_configure``) and prescribed motion without degrees of freedom
    (``lagrange_prescribed``), for a model with ``nv`` speeds and ``ng`` geometric
    constraint rows (offsets from the ``OutputLayout`` defines)."""
    from mbcomp.codegen import events_c
    from mbcomp.core import c_text, tolerances
    return (C_PROGRAM + events_c.C_DEFINES + tolerances.c_defines()
            + c_text.fill(c_text.read("mbcomp.formulations", "lagrange.c"), TRIAL=TRIAL_FAILED, PAUSED=PAUSED, EVENT=EVENT))

