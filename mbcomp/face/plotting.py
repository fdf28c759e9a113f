"""Plots and animations of simulation results (matplotlib, headless-safe)."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from mbcomp.build.layout import body_fields

__all__ = ["plot_result", "animate_result", "render_frame", "work_precision_plot"]

PLOT_KINDS = ("q", "qd", "energy", "drift", "reactions")

# Floor for log-scale drift plots: exact zeros (an unconstrained sample) cannot be drawn.
_DRIFT_FLOOR = 1e-17


# ----------------------------------------------------------------------------------------------
# Figures without global state
# ----------------------------------------------------------------------------------------------
def _new_figure(figsize: tuple[float, float] | None = None, **kwargs: Any):
    """A matplotlib Figure that never needs a display.

    When the user already works with pyplot (it is imported), the figure is made by pyplot so
    ``plt.show()`` and notebooks display it with the user's backend (which matplotlib itself
    falls back to Agg without a display).  Otherwise the figure is a bare ``Figure`` on an Agg
    canvas: no GUI, no global figure registry, nothing to close.
    """
    if "matplotlib.pyplot" in sys.modules:
        import matplotlib.pyplot as plt
        return plt.figure(figsize=figsize, **kwargs)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=figsize, **kwargs)
    FigureCanvasAgg(fig)
    return fig


def _save(fig, path: Any, dpi: float | None = None) -> None:
    if path is not None:
        from mbcomp.core.writing import staged
        with staged(path, "savefig") as scratch:  # (a failed write is an error, not a silent empty file)
            fig.savefig(scratch, dpi=dpi if dpi is not None else "figure", format=Path(path).suffix[1:].lower() or "png")


# ----------------------------------------------------------------------------------------------
# Time histories
# ----------------------------------------------------------------------------------------------
def _coordinate_kinds(system, speeds: bool = False) -> list[str]:
    """``"length"``, ``"angle"`` or ``"quaternion"`` for every coordinate, in ``system.coords``
    order (with ``speeds``: ``"length"`` or ``"angle"`` for every speed, ``system.speeds`` order)."""
    topology = system.topology
    kinds = ["angle"] * (topology.nv if speeds else topology.nq)
    for joint in topology.tree_joints:
        start = (topology.v_slice if speeds else topology.q_slice)[joint.name].start
        for kind, _, sq, sv in joint.walk():
            part = sv if speeds else sq
            for index in range(start + part.start, start + part.stop):
                kinds[index] = {"P": "length", "R": "angle"}.get(kind, "angle" if speeds else "quaternion")
    return kinds


def _has_constraints(system) -> bool:
    topology = system.topology
    return bool(getattr(topology, "constraints", ())) or bool(getattr(topology, "cut_joints", ()))


def _reaction_unit(system, name: str) -> str:
    """Unit of the reaction of constraint ``name``: motor torque/force, slider force, loop forces."""
    topology = system.topology
    comp = topology.components.get(name)
    return comp.reaction_unit(topology.resolve) if comp is not None else "N, N m"


def _parse_what(what: str | Sequence[str], states: Sequence[str] = ()) -> list[str]:
    kinds = [what] if isinstance(what, str) else list(what)
    if "states" in kinds:  # every state of the drive elements, one panel each
        at = kinds.index("states")
        kinds[at:at + 1] = list(states)
    unknown = [k for k in kinds if k not in PLOT_KINDS and k not in states]
    if unknown:
        raise ValueError(f"plot_result: unknown quantity {unknown}; choose from {list(PLOT_KINDS)}"
                         + (f", 'states' or a state name {list(states)}" if states else ""))
    return list(dict.fromkeys(kinds))       # keep the order, drop repeats


def _pieces(t: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` index ranges between repeated sample times (an impact repeats its time
    with the speeds before and after)."""
    breaks = np.flatnonzero(np.diff(t) <= 0) + 1
    return list(zip([0, *breaks], [*breaks, len(t)]))


def _smooth_series(result: Any, max_points: int = 3000):
    """``(t, q, qd)`` refined between the solver's samples, or None when that is not possible.

    Cubic Hermite interpolation: q from the samples' q and qd, qd from qd and the accelerations
    at the samples (the order of a solver's dense output, so the curves follow the motion
    instead of straight chords between large steps).  Each piece between impacts is refined
    on its own, so jumps in qd stay vertical.
    """
    from scipy.interpolate import CubicHermiteSpline
    t = np.asarray(result.t, dtype=float)
    q, qd = np.asarray(result.q, dtype=float), np.asarray(result.qd, dtype=float)
    per_step = min(max_points // max(len(t), 1), 12)
    if len(t) < 2 or per_step < 2 or q.shape[1] == 0:
        return None
    system = result.system
    state_map = system.topology.state_map
    rate = state_map.qdot(q, qd)  # q' (a ball's quaternion rate from its angular velocity)
    try:
        qdd = np.array([system.accelerations(q[i], qd[i], t[i], tau=getattr(result, "tau", None))
                        for i in range(len(t))])
    except Exception:                    # noqa: BLE001 - a model we cannot evaluate: plot samples
        return None
    if not np.all(np.isfinite(qdd)):
        return None
    ts, qs, qds = [], [], []
    for start, stop in _pieces(t):
        piece = t[start:stop]
        if len(piece) == 1:
            ts.append(piece), qs.append(q[start:stop]), qds.append(qd[start:stop])
            continue
        fine = np.concatenate([np.linspace(a, b, per_step, endpoint=False) for a, b in zip(piece[:-1], piece[1:])]
                              + [piece[-1:]])
        ts.append(fine)
        qs.append(CubicHermiteSpline(piece, q[start:stop], rate[start:stop], axis=0)(fine))
        qds.append(CubicHermiteSpline(piece, qd[start:stop], qdd[start:stop], axis=0)(fine))
    return np.concatenate(ts), state_map.normalize(np.concatenate(qs)), np.concatenate(qds)


def plot_result(result: Any, what: str | Sequence[str] = ("q", "qd", "energy"), *, path: Any = None,
                figsize: tuple[float, float] | None = None, smooth: bool = True):
    """Time histories of a simulation, one subplot per quantity, sharing the time axis.

    Parameters
    ----------
    result : Result
        What ``System.simulate`` returned.
    what : str or sequence of str
        Quantities to plot, in order, from ``"q"`` (coordinates; angles in rad and lengths in m
        on separate subplots, each line labelled by coordinate name), ``"qd"`` (speeds, rad/s and
        m/s), ``"energy"`` (kinetic, potential, total, J), ``"drift"`` (constraint violation
        max |C(q)|, m or rad, log scale), ``"reactions"`` (constraint reactions: N, N m),
        ``"states"`` (every state of the drive elements, one panel each) or a state's name
        (``"motor.current"``, A; ``"pid.integral"``).
        The drift subplot is added whenever the system has constraints or loop-closing joints,
        because drift is what tells whether those results can be trusted.
    path : str or Path, optional
        Save the figure there (the format follows the suffix, e.g. PNG).
    figsize : (width, height), optional
        Inches; by default 9 wide and 2.3 per subplot.
    smooth : bool
        Draw q, qd and energy between the solver's samples by cubic Hermite interpolation (q
        from q and qd, qd from qd and the accelerations), as a solver's dense output would;
        solvers such as DOP853 take large steps, and straight chords between them misrepresent
        the motion.  ``False`` draws the samples joined by straight lines.  Drift and reactions
        are always drawn at the samples.

    Returns
    -------
    matplotlib.figure.Figure
        Impact events, if any, are marked by dotted vertical lines.

    Examples
    --------
    >>> fig = res.plot(("q", "energy"), path="pendulum.png")     # doctest: +SKIP
    """
    system = result.system
    extra = tuple(getattr(result, "extra_states", ()))
    kinds = _parse_what(what, extra)
    if "drift" not in kinds and _has_constraints(system):
        kinds.append("drift")
    t = np.asarray(result.t, dtype=float)
    coords = list(system.coords)
    coord_kinds = _coordinate_kinds(system)
    speeds = list(getattr(system, "speeds", coords))
    speed_kinds = _coordinate_kinds(system, speeds=True)

    # One panel per (quantity, unit): mixing rad and m on one axis hides the smaller one.
    panels: list[tuple[str, Any]] = []
    for kind in kinds:
        if kind in ("q", "qd"):
            present = [k for k in ("angle", "length", "quaternion") if k in (coord_kinds if kind == "q" else speed_kinds)]
            panels.extend((kind, unit_kind) for unit_kind in present)
        else:
            panels.append((kind, None))
    if not panels:
        raise ValueError("plot_result: nothing to plot (the system has no coordinates)")

    if figsize is None:
        figsize = (9.0, max(2.3 * len(panels), 3.0))
    fig = _new_figure(figsize=figsize)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    dense = _smooth_series(result) if smooth and any(k in kinds for k in ("q", "qd", "energy")) else None
    t_line, q_line, qd_line = dense if dense is not None else (t, np.asarray(result.q), np.asarray(result.qd))
    for ax, (kind, unit_kind) in zip(axes, panels):
        if kind in ("q", "qd"):
            values = q_line if kind == "q" else qd_line
            names, unit_kinds = (coords, coord_kinds) if kind == "q" else (speeds, speed_kinds)
            for i, name in enumerate(names):
                if unit_kinds[i] == unit_kind:
                    ax.plot(t_line, values[:, i], label=name if kind == "q" or name not in coords else f"d{name}/dt")
            if kind == "q":
                ax.set_ylabel({"angle": "angle (rad)", "length": "position (m)"}.get(unit_kind, "quaternion (1)"))
            else:
                ax.set_ylabel("angular speed (rad/s)" if unit_kind == "angle" else "speed (m/s)")
        elif kind == "energy":
            if dense is None:
                energy = result.energy()
                kinetic, potential = np.asarray(energy.kinetic), np.asarray(energy.potential)
            else:
                values = np.array([(e.kinetic, e.potential) for e in
                                   (system.energy(qi, qdi, ti) for ti, qi, qdi in zip(t_line, q_line, qd_line))])
                kinetic, potential = values[:, 0], values[:, 1]
            ax.plot(t_line, kinetic, label="kinetic")
            ax.plot(t_line, potential, label="potential")
            ax.plot(t_line, kinetic + potential, label="total", color="black", linewidth=1.2)
            ax.set_ylabel("energy (J)")
        elif kind in extra:  # a drive element's state (a motor current, a PID integral)
            ax.plot(t, np.asarray(result[kind], dtype=float), label=kind)
            ax.set_ylabel("current (A)" if kind.endswith(".current") else kind)
        elif kind == "drift":
            drift = np.asarray(result.constraint_violation(), dtype=float).reshape(-1)
            ax.semilogy(t, np.maximum(np.abs(drift), _DRIFT_FLOOR), label="max |C(q)|", color="tab:red")
            if not np.any(drift):
                ax.text(0.5, 0.5, "no drift: the constraints hold exactly (or there are none)",
                        transform=ax.transAxes, ha="center", va="center", color="gray")
            ax.set_ylabel("constraint drift (m, rad)")
        elif kind == "reactions":
            reactions = result.reactions
            units = []
            for name, series in reactions.items():
                series = np.asarray(series, dtype=float).reshape(len(t), -1)
                unit = _reaction_unit(system, name)
                units.append(unit)
                for k in range(series.shape[1]):
                    label = name if series.shape[1] == 1 else f"{name}[{k}]"
                    ax.plot(t, series[:, k], label=f"{label} ({unit})")
            if not reactions:
                ax.text(0.5, 0.5, "no constraints: no reactions", transform=ax.transAxes,
                        ha="center", va="center", color="gray")
            unit_text = ", ".join(dict.fromkeys(u for us in units for u in us.split(", "))) or "N, N m"
            ax.set_ylabel(f"reaction ({unit_text})")
        for event in getattr(result, "events", None) or ():
            ax.axvline(float(event.time), color="gray", linestyle=":", linewidth=0.8)
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            # Outside, right of the panel: a legend inside would hide the curves somewhere.
            entries = len(ax.get_legend_handles_labels()[0])
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, frameon=False,
                      fontsize="small" if entries <= 12 else "x-small", ncol=1 + (entries - 1) // 15)
    axes[-1].set_xlabel("time (s)")
    model_name = getattr(getattr(system, "_compiled", None), "model_name", None)
    if model_name:
        axes[0].set_title(f"{model_name}: {result.stats.get('method', '')}".rstrip(": "))
    fig.tight_layout()
    _save(fig, path)
    return fig


# ----------------------------------------------------------------------------------------------
# 3D stick-and-ball scene
# ----------------------------------------------------------------------------------------------
def _local(system, comp, attr: str) -> np.ndarray:
    """A component's body-frame point as the system's current parameter value (parameters can
    be rebound without recompiling, so the component's own attribute may be stale)."""
    value = system.parameters.get(f"{comp.name}.{attr}", getattr(comp, attr))
    return np.asarray(value, dtype=float).reshape(3)


class _Scene:
    """Everything drawn in the animation, as body-frame points resolved per configuration.

    Each body is a stick figure: segments from its hub (where its tree joint attaches it) to its
    COM and to every other point of interest on it (outgoing joints, loop-closing joints, spring,
    slider and contact points).  ``points(q)`` returns the world position of every such point at
    one configuration.
    """

    def __init__(self, system):
        self.system = system
        topology = system.topology
        self.ground = topology.ground
        self.bodies = list(topology.bodies)
        self.names = [topology.ground.name] + [b.name for b in self.bodies]
        self.index_of = {name: i for i, name in enumerate(self.names)}
        self.locals: list[np.ndarray] = []         # body-frame points, one row each
        self.owner: list[int] = []                 # index into self.names
        self.sticks: list[tuple[int, int, int]] = []   # (point a, point b, body index)
        self.links: list[tuple[int, int]] = []     # joint gaps: prismatic travel, loop closures
        self.springs: list[tuple[int, int]] = []
        self.ground_marks: list[int] = []
        self.joint_marks: list[int] = []
        self.com_points: list[int] = []
        self.sliders: list[tuple[np.ndarray, np.ndarray]] = []

        def add(body: Any, local: np.ndarray) -> int:
            self.locals.append(np.asarray(local, dtype=float))
            self.owner.append(self.index_of[topology.resolve(body).name])
            return len(self.locals) - 1

        hubs: dict[str, int] = {}
        extras: dict[str, list[int]] = {b.name: [] for b in self.bodies}

        def attach(body: Any, local: np.ndarray) -> int:
            index = add(body, local)
            name = topology.resolve(body).name
            if name == self.ground.name:
                self.ground_marks.append(index)
            else:
                extras[name].append(index)
            return index

        for body, joint in zip(self.bodies, topology.tree_joints):
            on_parent = attach(joint.parent, _local(system, joint, "parent_point"))
            hub = add(body, _local(system, joint, "child_point"))
            hubs[body.name] = hub
            self.joint_marks.append(hub)
            self.links.append((on_parent, hub))
        for joint in getattr(topology, "cut_joints", ()):
            a = attach(joint.parent, _local(system, joint, "parent_point"))
            b = attach(joint.child, _local(system, joint, "child_point"))
            self.joint_marks.extend((a, b))
            self.links.append((a, b))
        for comp in getattr(topology, "forces", ()):
            ends = [role for role, how in comp.refs.items() if how == "attachment"]
            if len(ends) == 2:
                a, b = (attach(getattr(comp, f"body_{role}"), _local(system, comp, f"point_{role}")) for role in ends)
                self.springs.append((a, b))
        for comp in tuple(getattr(topology, "constraints", ())) + tuple(getattr(topology, "contacts", ())):
            if comp.refs.get("body") == "body" and comp.spec("point") is not None:
                attach(comp.body, _local(system, comp, "point"))
            if comp.kind == "slider":
                self.sliders.append((_local(system, comp, "origin"), np.asarray(comp.axis, dtype=float)))
        for k, body in enumerate(self.bodies):
            com = add(body, _local(system, body, "com"))
            self.com_points.append(com)
            hub = hubs[body.name]
            for other in [com] + extras[body.name]:
                self.sticks.append((hub, other, k))
        if not self.ground_marks:
            self.ground_marks.append(add(self.ground, np.zeros(3)))
        self.locals_array = np.array(self.locals).reshape(-1, 3)
        self.owner_array = np.array(self.owner, dtype=int)
        masses = np.array([float(system.parameters.get(f"{b.name}.mass", b.mass)) for b in self.bodies])
        # Ball area grows with mass^(2/3) (volume ~ mass), within readable bounds.
        scale = (masses / masses.max()) ** (2.0 / 3.0) if masses.size else masses
        self.ball_sizes = np.clip(40.0 + 200.0 * scale, 30.0, 260.0)
        self._fast: bool | None = None

    # -- kinematics -----------------------------------------------------------------------------
    def _poses_public(self, q: np.ndarray):
        """(R_WB, p_WB) of every body through the public ``body_state`` (ground first)."""
        rotations, origins = [np.eye(3)], [np.zeros(3)]
        for body in self.bodies:
            state = self.system.body_state(body, q, point=(0.0, 0.0, 0.0))
            rotations.append(state.rotation)
            origins.append(state.position)
        return np.array(rotations), np.array(origins)

    def _poses_fast(self, q: np.ndarray):
        """The same from one evaluation of the generated kinematics (no accelerations)."""
        kernel = self.system.kernel
        per_body = body_fields(kernel.kinematics(q, np.zeros(kernel.nv))[0])
        rotations = np.concatenate([np.eye(3)[None], per_body["rotation"]])
        origins = np.concatenate([np.zeros((1, 3)), per_body["origin"]])
        return rotations, origins

    def poses(self, q: np.ndarray):
        if self._fast is None:
            # Use the fast path only once it agrees with the public API at this configuration.
            # (body_state also evaluates accelerations, which can fail off the constraints, e.g.
            # at a drifted sample; then the kinematics alone are all there is to go on.)
            try:
                reference = self._poses_public(q)
            except Exception as exc:     # noqa: BLE001 - fall back to the kinematics below
                reference, failure = None, exc
            try:
                fast = self._poses_fast(q)
            except Exception:            # noqa: BLE001 - any failure means: use the public API
                fast = None
            if reference is None:
                if fast is None:
                    raise failure
                self._fast = True
                return fast
            self._fast = fast is not None and all(np.allclose(a, b, rtol=1e-9, atol=1e-9)
                                                  for a, b in zip(fast, reference))
            return reference
        return self._poses_fast(q) if self._fast else self._poses_public(q)

    def points(self, q: np.ndarray) -> np.ndarray:
        """(npoints, 3) world positions (m) of every scene point at configuration ``q``."""
        rotations, origins = self.poses(np.asarray(q, dtype=float))
        R = rotations[self.owner_array]
        return origins[self.owner_array] + np.einsum("nij,nj->ni", R, self.locals_array)

    def all_points(self, qs: np.ndarray) -> np.ndarray:
        """(nframes, npoints, 3) world positions for a sequence of configurations."""
        return np.array([self.points(q) for q in qs])


def _limits(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre and half-width (m) of one cube that holds every point of the whole motion."""
    flat = points.reshape(-1, 3)
    flat = flat[np.all(np.isfinite(flat), axis=1)]
    if flat.size == 0:
        return np.zeros(3), 1.0
    low, high = flat.min(axis=0), flat.max(axis=0)
    centre = (low + high) / 2
    half = 0.55 * float(np.max(high - low))
    return centre, max(half, 0.05)


_NAMED_VIEWS = {
    # (elev, azim, vertical axis, axis looked along): the plane of the name, face-on.
    "xy": (90.0, -90.0, "z", 2),
    "xz": (0.0, -90.0, "z", 1),
    "yz": (0.0, 0.0, "z", 0),
}


def _resolve_view(view: Any, points: np.ndarray, system) -> tuple[float, float, str, int | None]:
    """``(elev, azim, vertical_axis, normal)`` for ``view``; ``normal`` is the index of the
    axis looked along for a face-on (orthographic) view, else None.

    ``None`` picks automatically: a planar motion is shown face-on (orthographic), anything
    else from an oblique angle with "up" opposite to gravity.
    """
    if isinstance(view, str):
        key = view.lower()
        if key in _NAMED_VIEWS:
            return _NAMED_VIEWS[key]
        if key in ("iso", "3d"):
            view = None
            points = None
        else:
            raise ValueError(f"view must be 'xy', 'xz', 'yz', 'iso' or (elev, azim) in degrees, got {view!r}")
    elif view is not None:
        try:
            elev, azim = (float(v) for v in view)
        except (TypeError, ValueError):
            raise ValueError(f"view must be 'xy', 'xz', 'yz', 'iso' or (elev, azim) in degrees, got {view!r}") from None
        return elev, azim, "z", None
    if points is not None:
        flat = points.reshape(-1, 3)
        extent = np.ptp(flat, axis=0) if flat.size else np.zeros(3)
        flat_axes = np.flatnonzero(extent <= 1e-9 * max(float(extent.max()), 1e-12))
        if extent.max() > 0 and flat_axes.size == 1:
            return _NAMED_VIEWS[{0: "yz", 1: "xz", 2: "xy"}[int(flat_axes[0])]]
    gravity = np.asarray(system.parameters.get("gravity", (0.0, 0.0, -9.81)), dtype=float)
    vertical = "xyz"[int(np.argmax(np.abs(gravity)))] if np.any(gravity) else "z"
    return 22.0, -58.0, vertical, None


def _clip_line(origin: np.ndarray, axis: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray | None:
    """The (2, 3) end points of the line ``origin + s axis`` inside the box [low, high] (slab
    method), or None when the line misses the box."""
    s_min, s_max = -np.inf, np.inf
    for k in range(3):
        if abs(axis[k]) < 1e-12:
            if not low[k] <= origin[k] <= high[k]:
                return None
            continue
        a, b = sorted(((low[k] - origin[k]) / axis[k], (high[k] - origin[k]) / axis[k]))
        s_min, s_max = max(s_min, a), min(s_max, b)
    if not s_min < s_max:
        return None
    return np.array([origin + s_min * axis, origin + s_max * axis])


class _Drawing:
    """The matplotlib artists of one scene, created once and moved per frame."""

    def __init__(self, ax, scene: _Scene, first: np.ndarray, centre: np.ndarray, half: float,
                 normal: int | None = None):
        import matplotlib as mpl
        self.ax, self.scene = ax, scene
        colors = mpl.colormaps["tab10"].colors
        self.body_colors = [colors[k % len(colors)] for k in range(len(scene.bodies))]

        for index in (0, 1, 2):
            getattr(ax, f"set_{'xyz'[index]}lim")(centre[index] - half, centre[index] + half)
        # Face-on: the axis looked along is a point, so its ticks would pile up; zoom in on the plane.
        ax.set_box_aspect((1, 1, 1), zoom=1.0 if normal is None else 1.35)
        for index, letter in enumerate("xyz"):
            if index == normal:
                getattr(ax, f"set_{letter}ticks")([])
            else:
                getattr(ax, f"set_{letter}label")(f"{letter} (m)")

        for origin, axis in scene.sliders:     # guide lines across the view (mplot3d does not clip)
            ends = _clip_line(origin, axis, centre - half, centre + half)
            if ends is not None:
                ax.plot(*ends.T, color="0.6", linewidth=1.0, linestyle="--")
        ground = first[scene.ground_marks]
        ax.plot(*ground.T, linestyle="none", marker="^", markersize=11, color="0.15",
                markeredgecolor="black", label="ground")
        self.sticks = self._collection(first, scene.sticks, linewidths=3.0,
                                       colors=[self.body_colors[k] for _, _, k in scene.sticks])
        self.links = self._collection(first, scene.links, colors="0.35", linewidths=1.5, linestyles="dotted")
        self.springs = self._collection(first, scene.springs, colors="tab:gray", linewidths=1.2,
                                        linestyles="dashed")
        joints = first[scene.joint_marks] if scene.joint_marks else np.empty((0, 3))
        (self.joint_line,) = ax.plot(*joints.T, linestyle="none", marker="o", markersize=4.5,
                                     markerfacecolor="white", markeredgecolor="black")
        self.balls = []
        for k, body in enumerate(scene.bodies):
            p = first[scene.com_points[k]]
            (ball,) = ax.plot([p[0]], [p[1]], [p[2]], linestyle="none", marker="o",
                              markersize=float(np.sqrt(scene.ball_sizes[k])), color=self.body_colors[k],
                              markeredgecolor="black", label=body.name)
            self.balls.append(ball)
        # Time at the top left, legend at the top right: both clear of the 3D box and its labels.
        self.title = ax.figure.text(0.03, 0.97, "", ha="left", va="top", fontsize="large")
        if len(scene.bodies) <= 8:
            ax.figure.legend(loc="upper right", ncol=min(len(scene.bodies) + 1, 4), fontsize="small",
                             frameon=False, bbox_to_anchor=(0.99, 0.99))

    def _collection(self, points: np.ndarray, pairs: list, **style: Any):
        """A Line3DCollection of the segments ``pairs`` (None when there are none: mplot3d
        cannot add an empty collection)."""
        from mpl_toolkits.mplot3d.art3d import Line3DCollection
        if not pairs:
            return None
        collection = Line3DCollection(self._segments(points, pairs), **style)
        self.ax.add_collection3d(collection, autolim=False)
        return collection

    @staticmethod
    def _segments(points: np.ndarray, pairs: Iterable[tuple]) -> list[np.ndarray]:
        return [np.array([points[p[0]], points[p[1]]]) for p in pairs]

    def moving(self) -> list:
        """The artists that change from frame to frame (the rest is drawn once)."""
        return [a for a in (self.sticks, self.links, self.springs, self.joint_line, *self.balls, self.title)
                if a is not None]

    def draw_moving(self) -> None:
        """Draw the moving artists over the restored background, in the order a full draw of
        the 3D axes gives them (collections sorted by depth, as ``Axes3D.draw`` does)."""
        ax = self.ax
        artists = [a for a in self.moving() if a is not self.title]
        collections = [a for a in artists if hasattr(a, "do_3d_projection") and not hasattr(a, "set_data_3d")]
        if ax.computed_zorder and collections:
            base = max(axis.get_zorder() for axis in (ax.xaxis, ax.yaxis, ax.zaxis)) + 1
            for i, artist in enumerate(sorted(collections, key=lambda a: a.do_3d_projection(), reverse=True)):
                artist.zorder = base + i
        else:
            for artist in collections:
                artist.do_3d_projection()
        for artist in sorted(artists, key=lambda a: a.get_zorder()):
            ax.draw_artist(artist)
        ax.figure.draw_artist(self.title)

    def update(self, points: np.ndarray, t: float) -> None:
        scene = self.scene
        for collection, pairs in ((self.sticks, scene.sticks), (self.links, scene.links),
                                  (self.springs, scene.springs)):
            if collection is not None:
                collection.set_segments(self._segments(points, pairs))
        if scene.joint_marks:
            joints = points[scene.joint_marks]
            self.joint_line.set_data_3d(joints[:, 0], joints[:, 1], joints[:, 2])
        for k, ball in enumerate(self.balls):
            p = points[scene.com_points[k]]
            ball.set_data_3d([p[0]], [p[1]], [p[2]])
        self.title.set_text(f"t = {t:.3f} s")


def _scene_figure(scene: _Scene, points: np.ndarray, view: Any, figsize: tuple[float, float] | None):
    fig = _new_figure(figsize=figsize or (6.0, 6.0))
    ax = fig.add_subplot(projection="3d")
    elev, azim, vertical, normal = _resolve_view(view, points, scene.system)
    ax.view_init(elev=elev, azim=azim, vertical_axis=vertical)
    if normal is not None:
        ax.set_proj_type("ortho")
    return fig, ax, normal


def _frame_times(t: np.ndarray, fps: float, duration: float | None, frames: Any) -> np.ndarray:
    """Simulation times (s) shown by the animation frames."""
    t0, t1 = float(t[0]), float(t[-1])
    if frames is not None and not np.isscalar(frames):
        times = np.asarray(frames, dtype=float).reshape(-1)
        if times.size == 0 or np.any(times < t0 - 1e-12) or np.any(times > t1 + 1e-12):
            raise ValueError(f"frames must be times within the result's [{t0}, {t1}] s")
        return times
    if frames is not None:
        count = int(frames)
        if count < 1:
            raise ValueError(f"frames must be at least 1, got {frames!r}")
    else:
        playback = (t1 - t0) if duration is None else float(duration)
        if not np.isfinite(playback) or playback < 0:
            raise ValueError(f"duration must be a non-negative number of seconds, got {duration!r}")
        count = max(int(round(playback * fps)) + 1, 1)
    return np.linspace(t0, t1, count) if t1 > t0 else np.full(count, t0)


def _resample(t: np.ndarray, q: np.ndarray, times: np.ndarray, qd: np.ndarray | None = None) -> np.ndarray:
    """q at ``times``: cubic Hermite interpolation through the samples and their speeds ``qd``
    (third-order accurate, so sparse solver output still animates smoothly), or linear without
    ``qd``.  Repeated sample times (before/after an impact) split the series into pieces that
    are interpolated separately, since ``qd`` jumps there while ``q`` is continuous.
    """
    from scipy.interpolate import CubicHermiteSpline
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float).reshape(len(t), -1)
    times = np.asarray(times, dtype=float)
    out = np.repeat(q[:1], len(times), axis=0)
    for start, stop in _pieces(t):
        piece = t[start:stop]
        inside = (times >= piece[0]) & (times <= piece[-1])   # later pieces win at a shared time
        if not np.any(inside) or q.shape[1] == 0:
            continue
        if len(piece) == 1:
            out[inside] = q[start]
        elif qd is not None:
            spline = CubicHermiteSpline(piece, q[start:stop], np.asarray(qd, dtype=float)[start:stop], axis=0)
            out[inside] = spline(times[inside])
        else:
            out[inside] = np.column_stack([np.interp(times[inside], piece, q[start:stop, i])
                                           for i in range(q.shape[1])])
    return out


def render_frame(result: Any, index: int = 0, path: Any = None, *, view: Any = None,
                 figsize: tuple[float, float] | None = None):
    """Draw the mechanism at one sample of ``result`` as a 3D stick-and-ball figure.

    The axis limits are the animation's (they hold the whole motion), so single frames and
    animations of one result look alike.

    Parameters
    ----------
    result : Result
    index : int
        Sample index into ``result.t`` (negative counts from the end).
    path : str or Path, optional
        Save the figure there (PNG by suffix).
    view : None, "xy", "xz", "yz", "iso" or (elev, azim) in degrees
        Camera; ``None`` shows planar motions face-on and others obliquely, up against gravity.
    figsize : (width, height) in inches, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    t = np.asarray(result.t, dtype=float)
    q = np.asarray(result.q, dtype=float)
    n = len(t)
    if not -n <= int(index) < n:
        raise IndexError(f"index {index} is out of range for a result with {n} samples")
    scene = _Scene(result.system)
    everything = scene.all_points(q)
    centre, half = _limits(everything)
    fig, ax, normal = _scene_figure(scene, everything, view, figsize)
    drawing = _Drawing(ax, scene, everything[int(index)], centre, half, normal)
    drawing.update(everything[int(index)], float(t[int(index)]))
    fig.tight_layout()
    _save(fig, path)
    return fig


def animate_result(result: Any, path: Any, *, fps: float = 30, duration: float | None = None,
                   view: Any = None, frames: Any = None, dpi: float = 80,
                   figsize: tuple[float, float] | None = None) -> Path:
    """Save a 3D stick-and-ball animation of a simulation (GIF, or MP4 with ffmpeg).

    Each body is a ball at its COM (area by mass) joined by sticks to its joint locations and
    attachment points; ground attachments are black triangles, joints white circles, springs
    dashed lines, prismatic travel and loop closures dotted lines.  The axis limits are fixed
    from the whole motion, so the picture does not jump.  The result is resampled (cubic
    Hermite interpolation of q with qd) at evenly spaced frame times, since solver steps are not
    evenly spaced.

    Parameters
    ----------
    result : Result
    path : str or Path
        ``.gif`` (written with Pillow) or ``.mp4`` (needs ``ffmpeg`` on the PATH).
    fps : float
        Frames per second of playback.
    duration : float, optional
        Playback length in seconds; by default the simulated time span (real time).
    view : None, "xy", "xz", "yz", "iso" or (elev, azim) in degrees
        Camera; ``None`` shows planar motions face-on and others obliquely, up against gravity.
    frames : int or sequence of float, optional
        Number of frames (overrides ``duration``), or the simulation times (s) to show.
    dpi : float
        Resolution of the frames (pixels = figsize * dpi).
    figsize : (width, height) in inches, optional

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    ValueError
        An unsupported file suffix or bad ``fps``/``duration``/``frames``/``view``.
    RuntimeError
        ``.mp4`` was asked for but ffmpeg is not available.

    Examples
    --------
    >>> res.animate("pendulum.gif", fps=20)        # doctest: +SKIP
    """
    from matplotlib import animation

    path = Path(path)
    suffix = path.suffix.lower()
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be positive, got {fps!r}")
    if suffix == ".gif":
        writer = animation.PillowWriter(fps=fps)
    elif suffix == ".mp4":
        if not animation.FFMpegWriter.isAvailable():
            raise RuntimeError(f"cannot write {path}: MP4 needs ffmpeg on the PATH "
                               f"(install ffmpeg, or save as .gif, which needs only Pillow)")
        writer = animation.FFMpegWriter(fps=fps)
    else:
        raise ValueError(f"cannot write {path}: the animation format follows the suffix, "
                         f"use .gif or .mp4 (got {path.suffix or 'none'!r})")
    t = np.asarray(result.t, dtype=float)
    times = _frame_times(t, fps, duration, frames)
    state_map = result.system.topology.state_map
    q_samples = np.asarray(result.q, dtype=float)
    q = state_map.normalize(_resample(t, q_samples, times, state_map.qdot(q_samples, np.asarray(result.qd, dtype=float))))
    scene = _Scene(result.system)
    points = scene.all_points(q)
    centre, half = _limits(points)
    fig, ax, normal = _scene_figure(scene, points, view, figsize)
    drawing = _Drawing(ax, scene, points[0], centre, half, normal)
    fig.tight_layout()
    from mbcomp.core.writing import staged
    try:
        with staged(path, "animate") as scratch:  # (a failed write is an error, not a silent empty file)
            if suffix == ".gif":
                _write_gif(fig, drawing, points, times, scratch, fps, dpi)
            else:
                with writer.saving(fig, str(scratch), dpi):
                    for k, time in enumerate(times):
                        drawing.update(points[k], float(time))
                        writer.grab_frame()
    finally:
        _close(fig)
    return path


def _write_gif(fig, drawing: "_Drawing", points: np.ndarray, times: np.ndarray, path: Path, fps: float,
               dpi: float) -> None:
    """The GIF of the animation: frames drawn by ``_blitter``, encoded by ``_encode_gif``."""
    try:
        _encode_gif(_blitter(fig, drawing, points, times, dpi), len(times), path, fps)
    finally:
        for artist in drawing.moving():
            artist.set_animated(False)


def _blitter(fig, drawing: "_Drawing", points: np.ndarray, times: np.ndarray, dpi: float):
    """``frame(k)``: the RGB pixels (h, w, 3) of frame k.  The still parts (axes, ticks,
    labels, legend, ground) are drawn once and each frame draws only the moving artists over
    them (blitting), which takes a third to a fifth of the time of drawing every frame in
    full; the pixels are those of a full drawing (tests/test_animation_blit.py)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig.set_dpi(dpi)
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    drawing.update(points[0], float(times[0]))
    for artist in drawing.moving():
        artist.set_animated(True)
    canvas.draw()                                  # the background, without the moving artists
    background = canvas.copy_from_bbox(fig.bbox)

    def frame(k: int) -> np.ndarray:
        canvas.restore_region(background)
        drawing.update(points[k], float(times[k]))
        drawing.draw_moving()
        return np.array(np.asarray(canvas.buffer_rgba())[..., :3])
    return frame


def _encode_gif(frame, count: int, path: Path, fps: float) -> None:
    """Write ``count`` frames (``frame(k)``: RGB pixels) as a looping GIF.  One 256-colour
    palette, fitted to the first and the last frame (median cut, as Pillow's own GIF writer
    fits one to every frame), serves every frame, each pixel taking its nearest colour (by
    Pillow's lookup, of reduced precision: within a few levels): 1-2 ms a frame where fitting
    a palette takes about 40 ms (640 x 480), and the still parts keep their colours from
    frame to frame."""
    from PIL import Image

    ends = np.concatenate([frame(0), frame(count - 1)])
    palette = Image.fromarray(ends, "RGB").convert("P", palette=Image.Palette.ADAPTIVE)
    frames = [Image.fromarray(frame(k), "RGB").quantize(palette=palette, dither=Image.Dither.NONE)
              for k in range(count)]
    frames[0].save(path, format="GIF", save_all=True, append_images=frames[1:], duration=int(1000 / fps), loop=0)


def _close(fig) -> None:
    """Release a figure made through pyplot (a bare Figure needs nothing)."""
    if "matplotlib.pyplot" in sys.modules:
        import matplotlib.pyplot as plt
        plt.close(fig)


# ----------------------------------------------------------------------------------------------
# Benchmarks
# ----------------------------------------------------------------------------------------------
def work_precision_plot(rows: Iterable[Mapping[str, Any]], path: Any = None, title: str | None = None):
    """Work-precision diagram: wall time against error, log-log, one line per label.

    Parameters
    ----------
    rows : iterable of mappings
        Each ``{"label": str, "error": float, "time": float}``: a method (or setting) name, the
        error it reached (in the benchmark's own measure, e.g. max |q - q_ref| in rad) and the
        wall time it took (s).  Points with a non-positive or non-finite error or time cannot
        be drawn on log axes and are left out.
    path : str or Path, optional
        Save the figure there (PNG by suffix).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        Lower left is better: less time for less error.
    """
    groups: dict[str, list[tuple[float, float]]] = {}
    for row in rows:
        try:
            label, error, wall = str(row["label"]), float(row["error"]), float(row["time"])
        except KeyError as exc:
            raise ValueError(f"work_precision_plot: every row needs 'label', 'error' and 'time'; "
                             f"{dict(row)!r} lacks {exc}") from None
        groups.setdefault(label, [])
        if np.isfinite(error) and np.isfinite(wall) and error > 0 and wall > 0:
            groups[label].append((error, wall))
    fig = _new_figure(figsize=(7.0, 5.0))
    ax = fig.add_subplot()
    for label, points in groups.items():
        if not points:
            continue
        points.sort()
        errors, walls = np.array(points).T
        ax.loglog(errors, walls, marker="o", label=label)
    ax.set_xlabel("error")
    ax.set_ylabel("wall time (s)")
    ax.grid(True, which="both", alpha=0.3)
    if title:
        ax.set_title(title)
    if any(groups.values()):
        ax.legend(fontsize="small")
    else:
        ax.text(0.5, 0.5, "no drawable points", transform=ax.transAxes, ha="center", va="center", color="gray")
    fig.tight_layout()
    _save(fig, path)
    return fig
