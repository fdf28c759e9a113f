"""Result: simulated time series (plain data) with helpers."""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from typing import Any

import numpy as np



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
    """An impact on one contact: time (s), contact name, impulse (N s, positive pushing
    apart) and the kinetic energy the whole impact lost (J)."""

    time: float
    contact: Any
    impulse: Any
    energy_loss: float = 0.0


@dataclass
class Result:
    """Simulated time series.

    ``t`` (m,) s; ``q``, ``qd`` (m, nq) in ``coords`` order; ``res["name"]`` a coordinate's
    series; ``stats`` holds the solver counters and wall time.
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
    _reactions: dict | None = field(default=None, repr=False)

    @property
    def coords(self) -> tuple[str, ...]:
        return self.system.coords

    def __getitem__(self, name: str) -> np.ndarray:
        """The series of coordinate ``name`` (or ``name_d`` / ``"d" + name`` for its speed)."""
        coords = list(self.coords)
        if name in coords:
            return self.q[:, coords.index(name)]
        for speed in (name[:-2] if name.endswith("_d") else None, name[1:] if name.startswith("d") else None):
            if speed in coords:
                return self.qd[:, coords.index(speed)]
        raise KeyError(f"no coordinate {name!r}; coordinates are {coords}")

    def energy(self) -> Energy:
        """Kinetic, potential and total energy (J) at every sample."""
        values = np.array([self.system._call("energy", q, qd) for q, qd in zip(self.q, self.qd)]).reshape(-1, 2)
        return Energy(values[:, 0], values[:, 1])

    def constraint_violation(self) -> np.ndarray:
        """max |C(q, t)| per sample (zeros for a model without constraints)."""
        return np.array([self.system._formulation.constraint_violation(self.system, t, q, self.offsets)
                         for t, q in zip(self.t, self.q)])

    @property
    def reactions(self) -> dict[str, np.ndarray]:
        """``{constraint name: (m, k) array}`` of reactions at every sample, and for every
        contact its normal force (N) while it rests closed (0 while open; impacts are
        impulses, in ``events``)."""
        if self._reactions is None:
            series: dict[str, list] = {}
            closed = self.closed_contacts or [()] * len(self.t)
            contacts = [c.name for c in self.system.topology.contacts]
            for t, q, qd, shut in zip(self.t, self.q, self.qd, closed):
                values = self.system.reactions(q, qd, t, tau=self.tau, offsets=self.offsets, contacts=shut)
                for name in contacts:
                    values.setdefault(name, 0.0)
                for name, value in values.items():
                    series.setdefault(name, []).append(np.atleast_1d(value))
            self._reactions = {k: np.array(v) for k, v in series.items()}
        return self._reactions

    def to_csv(self, path) -> None:
        """Write t, every coordinate and speed (``<name>_d``) and energies as CSV columns."""
        energy = self.energy()
        header = ["t"] + list(self.coords) + [f"{c}_d" for c in self.coords] + ["kinetic", "potential", "total"]
        with open(path, "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            for i in range(len(self.t)):
                row = [self.t[i], *self.q[i], *self.qd[i], energy.kinetic[i], energy.potential[i], energy.total[i]]
                writer.writerow([repr(float(v)) for v in row])

    def to_dataframe(self):
        """A pandas DataFrame indexed by t (needs the optional pandas)."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - optional dependency
            raise ImportError("Result.to_dataframe needs pandas: pip install pandas") from exc
        data = {c: self.q[:, i] for i, c in enumerate(self.coords)}
        data.update({f"{c}_d": self.qd[:, i] for i, c in enumerate(self.coords)})
        return pd.DataFrame(data, index=pd.Index(self.t, name="t"))

    def plot(self, *args: Any, **kwargs: Any):
        """Coordinates, speeds and energy against time (a matplotlib Figure)."""
        from .plotting import plot_result
        return plot_result(self, *args, **kwargs)

    def view(self, path=None, **kwargs: Any):
        """The motion in 3D as one self-contained HTML page (see ``mbcomp.viewer.view``): written
        to ``path`` (returns the Path), or without a path a ``Viewer`` a notebook shows inline."""
        from .viewer import view
        return view(self, path, **kwargs)

    def animate(self, path, **kwargs: Any):
        """Save a 3D stick-and-ball animation (GIF with Pillow, MP4 with ffmpeg)."""
        from .plotting import animate_result
        return animate_result(self, path, **kwargs)
