"""Result, Event and Energy: plain data of a simulation (the derived series are computed in
``post.py``, reached through the registered services so that this module imports nothing above it)."""
from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from mbcomp.core.errors import ModelError, UnknownNameError
from mbcomp.core.services import service



#: First characters that make a spreadsheet read a cell as a formula (OWASP's CSV injection list).
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def spreadsheet_safe(text: str) -> str:
    """A text cell a spreadsheet shows as text: one starting like a formula gets a leading
    ``'`` (``=cmd|' /C calc'!A0`` -> ``'=cmd|' /C calc'!A0``)."""
    return "'" + text if text.startswith(FORMULA_START) else text


@dataclass(frozen=True)
class Energy:
    """Kinetic, potential (gravity + springs) and total energy, J."""

    kinetic: Any
    potential: Any

    @property
    def total(self):
        return self.kinetic + self.potential


@dataclass
class Event:
    """A contact event: time (s), contact name, impulse (N s along the normal, positive
    pushing apart; 0 for events that are not impacts), the kinetic energy the whole impact
    lost (J), and its ``kind``: ``"impact"`` (a closing contact's impulse), ``"stick"``
    (a sliding contact starts to stick), ``"slip"`` (a sticking contact, or one whose slip
    reverses, starts to slide) or ``"release"`` (a closed contact opens: its normal force
    reached zero)."""

    time: float
    contact: Any
    impulse: Any
    energy_loss: float = 0.0
    kind: str = "impact"


@dataclass
class Result:
    """Simulated time series: plain data that pickles without its System.

    ``t`` (m,) s; ``q`` (m, nq) in ``coords`` order; ``qd`` (m, nv) in ``speeds`` order (a
    screw coordinate's speed is its rate; a ball has 4 coordinates, 3 speeds);
    ``res["name"]`` a coordinate's or a speed's series; ``stats`` holds the solver
    counters and wall time.  Everything the derived series need is recorded here: the
    parameter values (``parameters``), the speed motors' start values (``offsets``) and
    the contacts held closed at each sample (``closed_contacts``), so ``energy()``,
    ``reactions`` and ``constraint_violation()`` give the same numbers whichever System
    of the same model computes them.

    ``system`` is the System that produced the result; it is left out when the result is
    pickled (``with_system`` binds one again).
    """

    system: Any
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    stats: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    tau: Any = None
    offsets: dict = field(default_factory=dict, repr=False)
    persistent_contacts: list = field(default_factory=list)
    closed_contacts: list = field(default_factory=list, repr=False)  #: persistent contact indices per sample
    coords: tuple = ()  #: coordinate names (from the System when not given)
    speeds: tuple = ()  #: speed names, the columns of ``qd`` (from the System when not given)
    parameters: dict = field(default_factory=dict, repr=False)  #: parameter values of the run
    formulation: str = ""
    _reactions: dict | None = field(default=None, repr=False, compare=False)
    _contact_forces: dict | None = field(default=None, repr=False, compare=False)
    z: np.ndarray | None = field(default=None, repr=False)  #: (m, nz) drive-element states
    extra_states: tuple = ()  #: names of the columns of ``z`` (motor currents, PID integrals)

    def _z(self) -> np.ndarray:
        if self.z is None or self.z.shape != (len(self.t), len(self.extra_states)):
            return np.zeros((len(self.t), len(self.extra_states)))
        return self.z

    def __post_init__(self):
        if self.system is not None:
            if not self.coords:
                self.coords = tuple(self.system.coords)
            if not self.speeds:
                self.speeds = tuple(getattr(self.system, "speeds", self.coords))
            if not self.parameters:
                self.parameters = self.system.parameters
            if not self.formulation:
                self.formulation = self.system.formulation
            if not self.extra_states:
                self.extra_states = tuple(getattr(self.system, "extra_states", ()))
        self.coords = tuple(self.coords)
        self.speeds = tuple(self.speeds) or self.coords
        self.extra_states = tuple(self.extra_states)

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["system"] = None  # plain data: the System is not part of a pickled result
        return state

    def with_system(self, system) -> "Result":
        """This result bound to ``system`` (the same model; its own parameter values are kept
        in ``parameters``), e.g. after unpickling, for ``energy()``, ``reactions`` and plots."""
        if system is not None and tuple(system.coords) != self.coords:
            raise ValueError(f"with_system: the System's coordinates {list(system.coords)} are not this "
                             f"result's {list(self.coords)}")
        return replace(self, system=system, _reactions=None, _contact_forces=None)

    def _bound_system(self, what: str):
        if self.system is None:
            raise ValueError(f"Result.{what} needs the System that produced the result (this one has none, e.g. "
                             f"after unpickling): use res.with_system(system)")
        return self.system

    def __getitem__(self, name: str) -> np.ndarray:
        """The series of coordinate ``name``, of a speed that is not a coordinate's rate (a
        ball's ``NAME_wx``), or ``name_d`` / ``"d" + name`` for a coordinate's speed."""
        coords, speeds = list(self.coords), list(self.speeds)
        if not isinstance(name, str):
            raise UnknownNameError("Result", f"a series is named by a coordinate name (str), got {name!r}; "
                                             f"coordinates are {coords}")
        if name in coords:
            return self.q[:, coords.index(name)]
        if name in speeds:
            return self.qd[:, speeds.index(name)]
        if name in self.extra_states:
            return self._z()[:, self.extra_states.index(name)]
        for speed in (name[:-2] if name.endswith("_d") else None, name[1:] if name.startswith("d") else None):
            if speed in speeds:
                return self.qd[:, speeds.index(speed)]
        raise UnknownNameError("Result", f"no coordinate or speed {name!r}; coordinates are {coords}, speeds {speeds}"
                       + (f", states {list(self.extra_states)}" if self.extra_states else ""))

    def energy(self) -> Energy:
        """Kinetic, potential and total energy (J) at every sample."""
        return service("energy")(self._bound_system("energy()"), self)

    def constraint_violation(self) -> np.ndarray:
        """max |C(q, t)| per sample (zeros for a model without constraints)."""
        return service("constraint_violation")(self._bound_system("constraint_violation()"), self)

    @property
    def reactions(self) -> dict[str, np.ndarray]:
        """``{constraint name: (m, k) array}`` of reactions at every sample, and for every
        contact its normal force (N) while it rests closed (0 while open; impacts are
        impulses, in ``events``)."""
        if self._reactions is None:
            self._reactions = service("reactions")(self._bound_system("reactions"), self)
        return self._reactions

    @property
    def contact_forces(self) -> dict[str, np.ndarray]:
        """``{contact name: (m, 3) array}``: the force (N, world frame) each contact applies
        to its body, normal plus friction, at every sample where the run held it closed
        (zero elsewhere; impacts are impulses, in ``events``)."""
        if getattr(self, "_contact_forces", None) is None:
            self._contact_forces = service("contact_forces")(self._bound_system("contact_forces"), self)
        return self._contact_forces

    def to_csv(self, path) -> None:
        """Write t, every coordinate and speed (``<name>_d``) and energies as CSV columns."""
        energy = self.energy()
        header = (["t"] + list(self.coords) + [f"{c}_d" if c in self.coords else c for c in self.speeds]
                  + list(self.extra_states) + ["kinetic", "potential", "total"])
        z = self._z()
        if not isinstance(path, (str, os.PathLike)):
            raise ModelError("to_csv", f"path must be a file name (str or path), got {path!r}")
        text = io.StringIO(newline="")
        writer = csv.writer(text)
        writer.writerow([spreadsheet_safe(name) for name in header])
        for i in range(len(self.t)):
            row = [self.t[i], *self.q[i], *self.qd[i], *z[i], energy.kinetic[i], energy.potential[i],
                   energy.total[i]]
            writer.writerow([repr(float(v)) for v in row])
        from mbcomp.core.writing import write_file
        write_file(path, text.getvalue(), "to_csv")

    def to_dataframe(self):
        """A pandas DataFrame indexed by t (needs the optional pandas)."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - optional dependency
            raise ImportError("Result.to_dataframe needs pandas: pip install pandas") from exc
        data = {c: self.q[:, i] for i, c in enumerate(self.coords)}
        data.update({f"{c}_d" if c in self.coords else c: self.qd[:, i] for i, c in enumerate(self.speeds)})
        data.update({name: self._z()[:, i] for i, name in enumerate(self.extra_states)})
        return pd.DataFrame(data, index=pd.Index(self.t, name="t"))

    def plot(self, *args: Any, **kwargs: Any):
        """Coordinates, speeds and energy against time (a matplotlib Figure)."""
        return service("plot")(self, *args, **kwargs)

    def view(self, path=None, **kwargs: Any):
        """The motion in 3D as one self-contained HTML page (see ``mbcomp.face.viewer.view``): written
        to ``path`` (returns the Path), or without a path a ``Viewer`` a notebook shows inline."""
        return service("view")(self, path, **kwargs)

    def animate(self, path, **kwargs: Any):
        """Save a 3D stick-and-ball animation (GIF with Pillow, MP4 with ffmpeg)."""
        return service("animate")(self, path, **kwargs)
