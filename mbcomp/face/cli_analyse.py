"""``mbcomp analyse FILE``: equilibrium, modes and stability of a model file (docs/analysis.md)."""
from __future__ import annotations

import argparse
from typing import Any

import numpy as np


def register(commands: Any, cli: Any) -> None:
    """Add ``analyse`` to ``commands`` (the argparse subparsers of ``mbcomp``); ``cli`` is the
    command module itself (its helpers and ``CommandError``, also when run as ``__main__``)."""
    analyse = commands.add_parser(
        "analyse", help="equilibrium, natural frequencies and stability",
        description="Find the static equilibrium nearest a starting pose (the file's [initial] q, changed by "
                    "--at), then print the modes of the small motions about it (frequency, damping ratio, "
                    "shape) and whether it is stable. With --held the starting pose itself is analysed, "
                    "held by constant generalised forces (its holding forces).")
    analyse.add_argument("file", metavar="FILE", help="model file or library model name")
    analyse.add_argument("--at", action="append", default=[], metavar="NAME=VALUE",
                         help="starting value of a coordinate (rad or m); repeat or separate by commas")
    analyse.add_argument("--held", action="store_true",
                         help="analyse the starting pose held by its holding forces instead of an equilibrium")
    analyse.add_argument("--time", type=float, default=0.0, metavar="T",
                         help="time (s) at which inputs that change with time (steps, sines) are held (default 0)")
    analyse.add_argument("--formulation", choices=("lagrange", "dae"), help="default: the file's, else lagrange")
    analyse.set_defaults(handler=lambda args: cmd_analyse(args, cli))


def parse_at(values: list[str], coords: tuple[str, ...], cli: Any) -> dict[str, float]:
    """``["a=0.1,b=2", "c=-1"]`` as ``{name: value}``, checked against the coordinates."""
    CommandError, EXIT_BAD_INPUT = cli.CommandError, cli.EXIT_BAD_INPUT
    out: dict[str, float] = {}
    for item in (part.strip() for value in values for part in value.split(",")):
        if not item:
            continue
        name, sep, number = item.partition("=")
        name = name.strip()
        if not sep:
            raise CommandError(f"--at {item!r}: expected NAME=VALUE", EXIT_BAD_INPUT)
        if name not in coords:
            raise CommandError(f"--at {item!r}: {name!r} is not a coordinate; coordinates are {list(coords)}",
                               EXIT_BAD_INPUT)
        try:
            out[name] = float(number)
        except ValueError:
            raise CommandError(f"--at {item!r}: {number.strip()!r} is not a number", EXIT_BAD_INPUT) from None
        if not np.isfinite(out[name]):
            raise CommandError(f"--at {item!r}: the value must be finite", EXIT_BAD_INPUT)
    return out


def cmd_analyse(args: argparse.Namespace, cli: Any) -> int:
    """Print the equilibrium, its modes and the stability verdict."""
    CommandError, EXIT_FAILED, EXIT_OK = cli.CommandError, cli.EXIT_FAILED, cli.EXIT_OK
    from mbcomp.core.errors import ModelError, SimulationError
    model, _ = cli.load_model(args.file)
    system = cli.compile_model(model, args.formulation)
    q0, _, warnings = cli.initial_state(model, system)
    for warning in warnings:
        print(f"warning: {warning}")
    guess = dict(zip(system.coords, q0))
    guess.update(parse_at(args.at, system.coords, cli))
    q_guess = np.array([guess[c] for c in system.coords])
    print(f"{model.name}: {len(system.coords)} coordinates, {system.ndof} degrees of freedom "
          f"({system.formulation})")
    tau = None
    t = args.time
    if not np.isfinite(t):
        raise CommandError("--time must be a finite number of seconds", cli.EXIT_BAD_INPUT)
    from mbcomp.analysis import changing_inputs
    try:
        if args.held:
            q = system.assemble(q_guess, None, t)[0] if system.constraint_names else q_guess
            tau = system.holding_forces(q, t)
            print("pose held by its holding forces:")
            rows = [["coordinate", "value", "holding force"]]
            rows += [[c, fmt(v), fmt(h)] for c, v, h in zip(system.coords, q, tau)]
        else:
            q, states = system.equilibrium(q_guess, t=t, return_states=True)
            print("equilibrium:")
            rows = [["coordinate", "start", "equilibrium"]]
            rows += [[c, fmt(g), fmt(v)] for c, g, v in zip(system.coords, q_guess, q)]
        print(table(rows))
        if system.extra_states:
            if args.held:
                from mbcomp.analysis import rest_states
                states = dict(zip(system.extra_states, rest_states(system, q, t=t, tau=tau)))
            print("drive states at rest:")
            print(table([["state", "value"]] + [[name, fmt(value)] for name, value in states.items()]))
        changing = changing_inputs(system, q, t, states if system.extra_states else None)
        if changing:
            print(f"note: inputs change with time (they act on {', '.join(changing)}); analysed with them held "
                  f"at their values at t = {fmt(t)} s (--time to choose another)")
        modes = system.modes(q, t=t, tau=tau)
    except (SimulationError, ModelError) as exc:
        raise CommandError(f"analysis failed: {exc}", EXIT_FAILED) from None
    speeds = modes.speeds
    print(f"modes about it (independent coordinates {', '.join(modes.linearization.independent) or 'none'}):")
    rows = [["mode", "frequency (Hz)", "damping ratio", "eigenvalue (1/s)", "kind", "shape"]]
    for i, (f, z, lam) in enumerate(zip(modes.frequencies, modes.damping_ratios, modes.eigenvalues)):
        kind = _kind(lam, z, modes)
        text = shape_text(speeds, modes.shapes[:, i])
        scale = max(1.0, float(np.max(np.abs(modes.all_eigenvalues), initial=0.0)))
        re = 0.0 if abs(lam.real) < 1e-9 * scale else lam.real
        lam_text = fmt(re) if abs(lam.imag) < 1e-9 * scale else f"{re:.4g}{lam.imag:+.4g}j"
        rows.append([str(i + 1), fmt(f), fmt(z), lam_text, kind, text])
    if len(rows) > 1:
        print(table(rows))
    if system.extra_states:  # the drive states' eigenvalues join the mechanical ones: list them all
        values = sorted(modes.all_eigenvalues, key=lambda lam: (abs(lam), -lam.imag))
        import textwrap
        text = "eigenvalues with the drive states (1/s): " + ", ".join(
            fmt(lam.real) if abs(lam.imag) < 1e-9 * max(1.0, abs(lam)) else f"{lam.real:.4g}{lam.imag:+.4g}j"
            for lam in values)
        print(textwrap.fill(text, width=100, subsequent_indent="  ", break_on_hyphens=False))
    verdict = "stable" if modes.stable else f"UNSTABLE ({modes.unstable} growing mode{'s' * (modes.unstable > 1)})"
    print(f"stability: {verdict}")
    return EXIT_OK


#: The shape column shows at most this many components (the largest), each at least
#: ``SHAPE_FLOOR`` of the largest; the rest are counted ("+3 smaller").
SHAPE_COMPONENTS = 3
SHAPE_FLOOR = 0.05


def shape_text(speeds: tuple[str, ...], shape: np.ndarray) -> str:
    """A mode shape as its dominant components, largest first (``a=1, b=-0.43 (+2 smaller)``),
    so that the column stays narrow for models with many coordinates."""
    values = np.real(np.asarray(shape))
    order = [int(j) for j in np.argsort(-np.abs(values), kind="stable") if abs(values[j]) > 1e-9]
    shown = [j for j in order[:SHAPE_COMPONENTS] if abs(values[j]) >= SHAPE_FLOOR * abs(values[order[0]])]
    text = ", ".join(f"{speeds[j]}={values[j]:.3g}" for j in shown)
    rest = len(order) - len(shown)
    return text + (f" (+{rest} smaller)" if rest else "")


def fmt(x: float) -> str:
    return f"{x:.6g}"


def table(rows: list[list[str]], indent: str = "  ") -> str:
    """Left-aligned first column, right-aligned others (as the other commands print)."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join(indent + "  ".join(cell.rjust(w) if i else cell.ljust(w) for i, (cell, w)
                                        in enumerate(zip(row, widths))).rstrip() for row in rows)


def _kind(lam: complex, zeta: float, modes) -> str:
    scale = max(1.0, float(np.max(np.abs(modes.all_eigenvalues), initial=0.0)))
    if abs(lam) <= 1e-9 * scale:
        return "rigid (zero frequency)"
    if lam.real > 1e-7 * scale:
        return "divergent" if abs(lam.imag) <= 1e-9 * scale else "growing oscillation"
    if abs(lam.imag) <= 1e-9 * scale:
        return "decaying"
    return "oscillation" if abs(zeta) < 1e-6 else "damped oscillation"
