"""The Python side of the dae formulation's compiled loop (``dae_c.py``).

``DaeRows`` configures the KKT rows the compiled solve uses on this thread: geometric rows,
motor rows (speed motors; position motors, run as postfix programs, ``expressions_c``: a
file expression's own, a Python callable's read from the motor callback of
``codegen/callbacks.py``) and the gaps of contacts held closed.

``DaeRun`` is one compiled stretch of a run with contacts (``Formulation.contact_run``,
stepped by ``run/stepping.CompiledStepping``): the loop steps the full state ``[q, v, z]`` (q:
the nq coordinates, quaternions of ``Ball``/``Free`` joints normalised after each step; v: the
nv speeds; z: the drive elements' states) and checks every accepted step for a contact
event (a free contact closing, a held contact's force pulling); at one it stops with the
step's end and dense output, Python locates the event with the gaps and forces evaluated
in C (``locator``), applies the impact law (``events.ContactWatch``) and starts the next
stretch with the new set of held contacts.  Held contacts with friction modes add the
friction law of ``friction_c.py`` (``c/friction.h``) to the solve and to the watch; the
stretch then holds every constraint and contact row (the least-norm multipliers of the
Python path's friction solve share the load of redundant rows).
"""
from __future__ import annotations

import ctypes

import numpy as np

from mbcomp.core.errors import SimulationError
from mbcomp.codegen.callbacks import constant_tau
from mbcomp.codegen.expressions_c import position_programs
from mbcomp.formulations.compiled_watch import ContactWatching, EventStepFunctions, pointer
from mbcomp.formulations.dae_c import DATA_DOUBLES, ROW_CONTACT, ROW_GEOMETRIC, ROW_MOTOR, SPEC_LONGS
from mbcomp.formulations.friction import has_friction
from mbcomp.formulations.friction_c import FrictionRows

_VOID, _INT, _DBL, _LONG = ctypes.c_void_p, ctypes.c_int, ctypes.c_double, ctypes.c_long


_ptr = pointer


def _bind_configure(lib):
    """``dae_configure_rows`` with its argument types."""
    configure = lib.dae_configure_rows
    configure.argtypes = [_INT, _VOID, _VOID, _VOID, _DBL, _DBL, _DBL, _DBL]
    configure.restype = ctypes.c_int
    return configure


def motor_programs(formulation) -> dict[int, np.ndarray | None]:
    """Per motor row with a position function: its own programs (value, first and second
    derivative, ``expressions_c.position_programs``), or None for a position Python
    evaluates (a Python callable: the compiled loops read it through the motor callback,
    code that cannot call Python, an FMU, cannot run it)."""
    constraints = formulation.constraints
    if constraints is None:
        return {}
    programs, python_rows = position_programs(constraints)
    return {r: None if r in python_rows else program for r, program in programs.items()}


def row_tables(formulation, kernel, rows, offsets: dict | None, contacts: tuple = ()):
    """``(spec, data, programs)``: the arrays ``dae_configure_rows`` (and ``dae_evaluate``)
    read for the KKT rows ``rows`` (equation indices of the formulation's constraints; ``nc``
    and on: the held ``contacts``, in order); ``offsets``: the speed motors' start values.
    A motor whose position is a Python callable runs ``SLOT`` programs: its values come from
    the motor callback of ``codegen/callbacks.py`` (``expressions_c.position_programs``)."""
    constraints = formulation.constraints
    topology = kernel.topology
    nc = 0 if constraints is None else constraints.nc
    rows = [int(r) for r in rows]
    spec = np.zeros((len(rows), SPEC_LONGS), dtype=np.int64)
    data = np.zeros((len(rows), DATA_DOUBLES))
    programs: list[np.ndarray] = []
    start = 0
    compiled = position_programs(constraints)[0] if constraints is not None else {}
    for k, r in enumerate(rows):
        spec[k, 4] = -1
        if r >= nc:
            spec[k, :2] = (ROW_CONTACT, contacts[r - nc])
            continue
        eq = constraints.equations[r]
        if r not in constraints.coordinate_rows:
            spec[k, :2] = (ROW_GEOMETRIC, constraints.geometric_rows.index(r))
            continue
        joint = eq.joint if isinstance(eq.joint, str) else eq.joint.name
        spec[k, :4] = (ROW_MOTOR, r, topology.q_slice[joint].start, topology.v_slice[joint].start)
        speed = constraints.motor_speed(kernel, r)
        if speed is not None:
            if offsets is None or r not in offsets:
                raise SimulationError(f"motor {constraints.owner[r]!r}: no start value for its coordinate")
            data[k] = (speed, offsets[r])
            continue
        program = compiled[r]
        spec[k, 4] = start
        programs.append(program)
        start += len(program)
    return (np.ascontiguousarray(spec), np.ascontiguousarray(data),
            np.ascontiguousarray(np.concatenate(programs) if programs else np.zeros(1)))


def set_quaternion_projection(lib, formulation) -> None:
    """Tell this thread's compiled dae code whether its DOP853 loop projects a model with
    quaternion coordinates after each accepted step (``dae_quaternion_projection``, c/dae.c):
    on only with the run's ``projection=True`` (models without quaternions are projected
    whatever this).  Call after configuring the rows: switching them off switches it off."""
    on = bool(formulation.projection) and formulation.compiled.topology.state_map.quat_q.size > 0
    switch = lib.dae_quaternion_projection
    switch.argtypes, switch.restype = [_INT], None
    switch(int(on))


class DaeRows:
    """The configured KKT rows of one compiled dae run: ``rows`` are equation indices of
    the formulation's constraints (``nc`` and on: the held contacts, in ``contacts`` order).
    The arrays the C code reads live as long as this object; ``close()`` switches it off."""

    def __init__(self, formulation, kernel, lib, rows, offsets: dict | None, contacts: tuple = ()):
        self.formulation, self.lib = formulation, lib
        self.spec, self.data, self.programs = row_tables(formulation, kernel, rows, offsets, contacts)
        self.nr = len(self.spec)
        configure = _bind_configure(lib)
        alpha, beta = formulation.baumgarte
        if configure(self.nr, _ptr(self.spec), _ptr(self.data), _ptr(self.programs), alpha, beta,
                     float(formulation.schur_scale), float(formulation.singular_tolerance)):
            raise SimulationError(f"the compiled dae solve has room for fewer rows than {self.nr}")
        set_quaternion_projection(lib, formulation)

    def close(self) -> None:
        self.lib.dae_configure_rows(-1, None, None, None, 0.0, 0.0, 0.0, 0.0)

    def __enter__(self) -> "DaeRows":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class DaeRun(ContactWatching):
    """One compiled stretch of a dae run with contacts, from ``(q0, qd0)`` at ``t0`` with the
    held contacts ``contacts``; the interface ``run/stepping.CompiledStepping`` steps
    (``y0``, ``ni``, ``watch_contacts``, ``event_step``, ``locator``, ``sync``, ``workspace``)."""

    WATCH = "dae_watch"

    #: The loop steps the full state (``integrators.dop853_segment`` reads failures from y).
    full_state_loop = True

    def __init__(self, formulation, kernel, lib, q0: np.ndarray, qd0: np.ndarray, tau, t0: float = 0.0,
                 contacts: tuple = (), offsets: dict | None = None):
        self.formulation, self.kernel, self.lib = formulation, kernel, lib
        self.contacts = contacts if isinstance(contacts, tuple) else tuple(contacts)  # (a friction.Closed keeps its modes)
        self.n = kernel.nv
        self.workspace = formulation.workspace_class(formulation, kernel, t0, q0, qd0, tau, self.contacts)
        if offsets is not None:
            self.workspace.offsets = offsets
        self.tau = constant_tau(tau)  # (a callable tau: the input callback's)
        self.restarts = 0
        self.gaps = self.event = self.held = None
        nc = 0 if formulation.constraints is None else formulation.constraints.nc
        self.friction = None
        if has_friction(self.contacts):  # every row, as the Python path's least-norm friction solve
            rows = np.arange(nc + len(self.contacts))
        else:
            rows = self._rows(t0, q0)
        self.dae_rows = None
        if rows is not None and len(rows):
            self.dae_rows = DaeRows(formulation, kernel, lib, rows, self.workspace.offsets, self.contacts)
        else:  # the tree's own accelerations
            _bind_configure(lib)(-1, None, None, None, 0.0, 0.0, 0.0, 0.0)
        if has_friction(self.contacts):
            self.friction = FrictionRows(kernel, lib, self.contacts, {i: nc + r for r, i in enumerate(self.contacts)},
                                         len(rows), q0, qd0)
        self.nc = nc
        # collision features: the C narrow phase on this stretch's candidates (compiled/collision_c.py)
        self.collisions = kernel.compiled_stretch(lib, q0, qd0, self.contacts)
        if self.collisions is not None:
            self.step_cap = self.collisions.step_cap

    def _rows(self, t0, q0):
        """The KKT rows at the stretch's start: the nominal rows without held contacts, else
        the independent rows of the constraints and held contacts (as ``solve_constrained``);
        None when there are none (the tree's own accelerations)."""
        formulation = self.formulation
        if not self.contacts:
            if formulation.constraints is None:
                return None
            return formulation.nominal_rows
        cv = formulation.constraint_values(self.kernel, t0, q0, np.zeros(self.n), self.workspace.offsets,
                                           self.contacts)
        return formulation.rows_of(cv.J)

    @property
    def ni(self) -> int:
        return self.n

    @property
    def loop_ny(self) -> int:
        """The loop's state ``[q, v, z]``: nq coordinates (quaternions: more than the nv
        speeds), nv speeds, the drive states."""
        return self.kernel.topology.nq + self.n + self.kernel.compiled.drives.nz

    @property
    def y0(self) -> np.ndarray:
        return np.ascontiguousarray(self.workspace.y0, dtype=float)

    def locator(self, t_old: float, y_old: np.ndarray) -> "_Locator":
        return _Locator(self, t_old, y_old)

    def sync(self) -> None:
        """(The full state is the loop's own: nothing to bring over.)"""

    def friction_failure(self) -> SimulationError | None:
        """The error of a friction solve that stopped the loop (Painleve), or None."""
        return None if self.friction is None else self.friction.failure()

    def close(self) -> None:
        if self.friction is not None:
            self.friction.close()
        if self.dae_rows is not None:
            self.dae_rows.close()
        if self.collisions is not None:
            self.collisions.close()
        if self.event is not None:
            self.lib.dae_watch(0, None, None, 0.0, None)

    def __enter__(self) -> "DaeRun":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _Locator(EventStepFunctions):
    """``gap(s, i)`` and ``force(s, k)`` (contact i's gap, the k-th held contact's normal
    force) on the event step of a ``DaeRun``, from its dense output, computed in C."""

    def __init__(self, run: DaeRun, t_old: float, y_old: np.ndarray):
        super().__init__(run, t_old, y_old, "dae")
        rows = [] if run.dae_rows is None else run.dae_rows.spec
        # configured row of each held contact (None: dropped as dependent, its force is 0)
        self.row_of = {}
        for k, spec in enumerate(rows):
            if spec[0] == ROW_CONTACT:
                self.row_of[int(spec[1])] = k

    def force_row(self, k: int) -> int | None:
        """The configured row of the k-th held contact (None: dropped as dependent)."""
        return self.row_of.get(self.run.contacts[k])

    def gap(self, s: float, i: int) -> float:
        value = self._gap(float(s), *self.args, int(i), self.p)
        if value != value:
            raise SimulationError(f"the gap cannot be evaluated at t = {s:.6g} s")
        return value

    def force(self, s: float, k: int) -> float:
        row = self.force_row(k)
        if row is None:
            return 0.0
        value = self._force(float(s), *self.args, row, self.p, self.tau)
        if value != value:
            raise SimulationError(f"the contact force cannot be evaluated at t = {s:.6g} s")
        return value
