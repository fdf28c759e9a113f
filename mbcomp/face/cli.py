"""The ``mbcomp`` command: run, inspect and list model files (see docs/cli.md)."""
from __future__ import annotations

import argparse
import functools
import shutil
import sys
import warnings
from pathlib import Path
from typing import Sequence

EXIT_OK, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
DEFAULT_T_END = 5.0
DEFAULT_SAMPLES = 501
MAX_PRINTED_COORDS = 3  # equations of motion are printed up to this many coordinates


class CommandError(Exception):
    """A user-facing failure: the message is printed and the command exits with ``code``."""

    def __init__(self, message: str, code: int = EXIT_FAILED):
        super().__init__(message)
        self.code = code


# ----------------------------------------------------------------------------------------------
# Argument parsing
# ----------------------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mbcomp",
        description="Compose, compile and simulate multibody models from TOML files.",
        epilog="FILE is a path to a .toml model file or the name of a library model "
               "(see 'mbcomp library'). Documentation: docs/cli.md and docs/files.md.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    commands.required = True

    run = commands.add_parser("run", help="simulate a model and print a summary",
                              description="Compile and simulate a model file; print coordinates, final "
                                          "state, energy drift and solver statistics.")
    run.add_argument("file", metavar="FILE", help="model file or library model name")
    run.add_argument("--t-end", type=float, metavar="T", help="end time in s (default: the file's, else %g)" % DEFAULT_T_END)
    run.add_argument("--formulation", choices=("lagrange", "dae"), help="default: the file's, else lagrange")
    run.add_argument("--method", metavar="M", help="solve_ivp method: RK45, RK23, DOP853, Radau, BDF, LSODA "
                                                   "(default: the file's, else DOP853)")
    run.add_argument("--rtol", type=float, metavar="R", help="relative tolerance (default 1e-8)")
    run.add_argument("--atol", type=float, metavar="A", help="absolute tolerance (default 1e-10)")
    run.add_argument("--samples", type=int, metavar="N",
                     help="output samples, evenly spaced (default: the file's n_samples, else %d)" % DEFAULT_SAMPLES)
    run.add_argument("--out", metavar="CSV", help="write t, coordinates, speeds and energies as CSV")
    run.add_argument("--plot", metavar="PNG", help="save a plot of the coordinates and energy")
    run.add_argument("--animate", metavar="GIF", help="save an animation (GIF, or MP4 with ffmpeg)")
    run.add_argument("--html", metavar="HTML", help="save a 3D viewer of the motion: one self-contained "
                                                   "HTML page (opens offline in any browser)")
    run.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="show a progress bar on stderr (default: on a terminal, for runs longer than 2 s)")
    run.set_defaults(handler=cmd_run)

    info = commands.add_parser("info", help="describe a model and print its equations of motion",
                               description="Print the model's components, coordinates, degrees of freedom, "
                                           "constraints and (for up to %d coordinates) its equations of "
                                           "motion M(q) q'' = f(q, q', t)." % MAX_PRINTED_COORDS)
    info.add_argument("file", metavar="FILE", help="model file or library model name")
    info.add_argument("--simplify", action="store_true",
                      help="trigonometric simplification of the equations (slower)")
    info.add_argument("--no-equations", dest="equations", action="store_false",
                      help="skip the equations of motion")
    info.set_defaults(handler=cmd_info)

    library = commands.add_parser("library", help="list the ready-made models",
                                  description="List the library models with their descriptions, or print "
                                              "one model file (to copy and edit).")
    library.add_argument("name", nargs="?", help="print this model's file")
    library.set_defaults(handler=cmd_library)

    export = commands.add_parser("export", help="write a model as an FMI 2.0 FMU",
                                 description="Compile a model and write it as a self-contained FMI 2.0 FMU: "
                                             "co-simulation (mbcomp's DOP853 inside) or model exchange "
                                             "(docs/fmu.md).")
    export.add_argument("file", metavar="FILE", help="model file or library model name")
    export.add_argument("--fmu", metavar="OUT", required=True, help="the FMU file to write (.fmu)")
    export.add_argument("--kind", choices=("cs", "me"), default="cs",
                        help="cs: co-simulation (default), me: model exchange")
    export.add_argument("--input", metavar="JOINT", action="append", default=[],
                        help="a joint whose generalised force is an input of the FMU (repeatable)")
    export.set_defaults(handler=cmd_export)

    from mbcomp.face.cli_analyse import register
    register(commands, sys.modules[__name__])
    return parser


def _version() -> str:
    try:
        from mbcomp import __version__
        return __version__
    except ImportError:  # pragma: no cover
        return "unknown"


# ----------------------------------------------------------------------------------------------
# Shared steps
# ----------------------------------------------------------------------------------------------
def resolve_model_file(spec: str) -> Path:
    """A path that exists, else a library model of that name; ``CommandError`` otherwise
    (also for what ``mb.load`` refuses to read: a FIFO, a device, a file over the size limit)."""
    from mbcomp.files.toml_model import library_models
    from mbcomp.files.library import resolve_model_path
    from mbcomp.core.limits import file_problem
    path = resolve_model_path(spec)
    if path.exists() or path.is_symlink():
        problem = file_problem(path)
        if problem is not None:
            raise CommandError(f"{spec}: {problem}", EXIT_BAD_INPUT)
        return path
    from mbcomp.files.library import ROBOTS, robots_dir
    if str(spec) in ROBOTS and robots_dir() is None:
        raise CommandError(f"{spec} is a robot of the optional example-robot-data package, which is not installed: "
                           f"pip install \"mbcomp[robots]\" (example-robot-data and yourdfpy)", EXIT_BAD_INPUT)
    names = ", ".join(library_models()) or "none found"
    raise CommandError(f"{spec}: no such file, and no library model of that name (library: {names})",
                       EXIT_BAD_INPUT)


def load_model(spec: str):
    """(model, path): the loader's ``ModelError`` becomes a ``CommandError`` exiting 2."""
    from mbcomp.core.errors import ModelError
    from mbcomp.files.toml_model import load
    path = resolve_model_file(spec)
    if path.suffix.lower() == ".urdf":
        from mbcomp.files.urdf import load_urdf as load
    try:
        return load(path), path
    except ModelError as exc:
        problems = getattr(exc, "problems", [])
        raise CommandError(problems[0] if len(problems) == 1 else str(exc), EXIT_BAD_INPUT) from None


def compile_model(model, formulation: str | None = None):
    from mbcomp.core.errors import ModelError
    try:
        return model.compile(formulation or model.simulation.get("formulation", "lagrange"))
    except ModelError as exc:
        raise CommandError(f"cannot compile {model.name!r}: {exc}") from None


def initial_state(model, system) -> tuple[list[float], list[float], list[str]]:
    """q0, qd0 in ``system.coords`` order from the file's [initial] (0 where not given),
    and warnings for values of coordinates the compiled system does not have."""
    q_values, qd_values = model.initial.get("q", {}), model.initial.get("qd", {})
    speeds = getattr(system, "speeds", system.coords)
    neutral = system.topology.state_map.neutral()  # a ball's quaternion defaults to the identity
    q0 = [float(q_values.get(c, neutral[i])) for i, c in enumerate(system.coords)]
    qd0 = [float(qd_values.get(c, 0.0)) for c in speeds]
    extra = [c for c in q_values if c not in system.coords] + [c for c in qd_values if c not in speeds]
    warnings = [f"[initial] value for {c!r} ignored: not a coordinate of the compiled system "
                "(a loop-closing joint's coordinate?)" for c in dict.fromkeys(extra)]
    return q0, qd0, warnings


from mbcomp.face.cli_analyse import fmt as _fmt, table as _table  # noqa: E402 - one table printer for all commands


# ----------------------------------------------------------------------------------------------
# mbcomp run
# ----------------------------------------------------------------------------------------------
def cmd_run(args: argparse.Namespace) -> int:
    import numpy as np
    from mbcomp.core.errors import ModelError, SimulationError

    model, path = load_model(args.file)
    settings = dict(model.simulation)
    t_end = args.t_end if args.t_end is not None else settings.get("t_end", DEFAULT_T_END)
    method = args.method or settings.get("method", "DOP853")
    rtol = args.rtol if args.rtol is not None else settings.get("rtol", 1e-8)
    atol = args.atol if args.atol is not None else settings.get("atol", 1e-10)
    samples = args.samples if args.samples is not None else settings.get("n_samples", DEFAULT_SAMPLES)
    if not (t_end > 0 and np.isfinite(t_end)):
        raise CommandError(f"--t-end must be a positive number, got {t_end}", EXIT_BAD_INPUT)
    if samples < 2:
        raise CommandError(f"--samples must be at least 2, got {samples}", EXIT_BAD_INPUT)
    for option, value in (("--rtol", rtol), ("--atol", atol)):
        if not (value > 0 and np.isfinite(value)):
            raise CommandError(f"{option} must be a positive number, got {value}", EXIT_BAD_INPUT)
    # Default: on a terminal, a bar for runs that take longer than a couple of seconds.
    progress = args.progress if args.progress is not None else (2.0 if sys.stderr.isatty() else False)

    if args.plot or args.animate:
        import matplotlib
        matplotlib.use("Agg")  # files only: no display needed
    system = compile_model(model, args.formulation)
    q0, qd0, warnings = initial_state(model, system)
    for warning in warnings:
        print(f"mbcomp: warning: {warning}", file=sys.stderr)
    from mbcomp.core import checks
    try:  # (before the output times are allocated: they and the output must fit)
        checks.output_size(samples, len(q0) + len(qd0) + len(getattr(system, "extra_states", ())) + 1,
                           f"--samples {samples}" if args.samples is not None else
                           f"the file's n_samples = {samples}", fix="ask for fewer samples (--samples)")
    except ModelError as exc:
        raise CommandError(str(exc), EXIT_BAD_INPUT) from None
    t_eval = np.linspace(0.0, t_end, samples)
    try:
        result = system.simulate(t_end, q0, qd0, method=method, rtol=rtol, atol=atol, t_eval=t_eval,
                                 progress=progress)
    except (ModelError, SimulationError) as exc:
        raise CommandError(f"simulation of {model.name!r} failed: {exc}") from None

    print(run_summary(model, path, system, result))
    outputs = []
    if args.out:
        _write(lambda: result.to_csv(args.out), args.out)
        outputs.append(f"wrote {args.out} ({len(result.t)} rows)")
    if args.plot:
        _write(lambda: _save_plot(result, args.plot), args.plot)
        outputs.append(f"wrote {args.plot}")
    if args.animate:
        _write(lambda: result.animate(args.animate), args.animate)
        outputs.append(f"wrote {args.animate}")
    if args.html:
        _write(lambda: result.view(args.html), args.html)
        outputs.append(f"wrote {args.html} (open it in a browser)")
    for line in outputs:
        print(line)
    return EXIT_OK


def _save_plot(result, path: str) -> None:
    import matplotlib.pyplot as plt
    from mbcomp.core.writing import staged
    figure = result.plot()
    try:
        with staged(path, "--plot") as scratch:  # (matplotlib does not report every failed write)
            figure.savefig(scratch, dpi=100, format=Path(path).suffix[1:].lower() or "png")
    finally:
        plt.close(figure)


def _write(action, path: str) -> None:
    """Run an output step; file-system and missing-feature errors become messages."""
    from mbcomp.core.errors import WriteError
    try:
        action()
    except WriteError as exc:
        raise CommandError(str(exc)) from None
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}") from None
    except (ImportError, NotImplementedError, RuntimeError, ValueError) as exc:
        raise CommandError(f"cannot write {path}: {exc}") from None


def run_summary(model, path: Path, system, result) -> str:
    """The text ``mbcomp run`` prints after a simulation."""
    import numpy as np
    stats = result.stats
    lines = [f"model        {model.name} ({path})"]
    lines.append(f"coordinates  {', '.join(system.coords)} ({system.nq} coordinate{'s' * (system.nq != 1)}, "
                 f"{system.ndof} degree{'s' * (system.ndof != 1)} of freedom)")
    lines.append(f"compiled     formulation {system.formulation}, backend {system.backend}, "
                 f"{system.compile_time:.2f} s")
    counters = [f"{stats['nfev']} evaluations" if stats.get("nfev") is not None else None,
                f"{stats['steps']} steps" if stats.get("steps") else None,
                f"{stats['wall_time']:.3g} s wall" if stats.get("wall_time") is not None else None]
    lines.append(f"simulated    t = 0 .. {_fmt(result.t[-1])} s, {stats.get('method', '?')}, rtol {stats.get('rtol')}, "
                 f"atol {stats.get('atol')}: " + ", ".join(c for c in counters if c))
    speeds = list(getattr(system, "speeds", system.coords))
    rows = [["coordinate", "q", "qd"]] + [[c, _fmt(result.q[-1, i]),
                                           _fmt(result.qd[-1, speeds.index(c)]) if c in speeds else ""]
                                          for i, c in enumerate(system.coords)]
    rows += [[c, "", _fmt(result.qd[-1, i])] for i, c in enumerate(speeds) if c not in system.coords]
    lines.append(f"final state (t = {_fmt(result.t[-1])} s)")
    lines.append(_table(rows))
    try:
        energy = result.energy()
        total = np.asarray(energy.total, dtype=float)
        drift = float(np.max(np.abs(total - total[0])))
        scale = max(abs(float(total[0])), float(np.max(np.abs(energy.kinetic))), 1e-300)
        conservative = _is_conservative(model)
        label = "drift" if conservative else "change (the model is not conservative)"
        lines.append(f"energy       initial {_fmt(total[0])} J, final {_fmt(total[-1])} J, max {label} "
                     f"{drift:.3g} J ({drift / scale:.3g} relative)")
    except Exception as exc:  # energy is a report, not the result: never fail the run on it
        lines.append(f"energy       unavailable ({exc})")
    if _has_constraints(model) or getattr(system.topology, "cut_joints", ()):
        try:
            violation = np.asarray(result.constraint_violation(), dtype=float)
            lines.append(f"constraints  max violation {float(np.max(violation)):.3g}")
        except Exception as exc:
            lines.append(f"constraints  violation unavailable ({exc})")
    events = list(getattr(result, "events", []) or [])
    if events:   # counted by kind (impact, stick, slip, release), each with its first time
        kinds: dict[str, list] = {}
        for event in events:
            kinds.setdefault(getattr(event, "kind", "impact"), []).append(event.time)
        lines.append("events       " + "; ".join(f"{len(times)} {kind}{'s' * (len(times) != 1)}, first at t = "
                                                  f"{_fmt(times[0])} s" for kind, times in kinds.items()))
    return "\n".join(lines)


def _is_conservative(model) -> bool:
    return all(comp.is_conservative() for comp in model.components.values())


def _has_constraints(model) -> bool:
    from mbcomp.spec.components import Constraint
    return any(isinstance(c, Constraint) for c in model.components.values())


# ----------------------------------------------------------------------------------------------
# mbcomp info
# ----------------------------------------------------------------------------------------------
def describe_components(model, cut_joints: Sequence[str] = ()) -> list[str]:
    """One line per component group, in the file's vocabulary (``cut_joints``: the names of
    the joints that close loops; their coordinates are not among the system's)."""
    comps = [c for c in model.components.values() if c is not model.ground]
    by_section: dict[str, list] = {}
    for comp in comps:
        by_section.setdefault(comp.section, []).append(comp)
    lines = []
    bodies = by_section.get("bodies", [])
    lines.append(f"bodies       {len(bodies)}: " + ", ".join(
        f"{b.name} ({b.mass:g} kg{', point mass' if b.is_point_mass else ''})" for b in bodies))
    joints = by_section.get("joints", [])
    if joints:
        lines.append("joints")
        for j in joints:
            coords = f" [{', '.join(j.coords)}]" if j.coords else ""
            if j.name in cut_joints:
                coords = ", closes a loop"
            ends = " -> ".join(_name(ref) for ref in j.references().values())
            lines.append(f"  {j.name}: {j.summary()}, {ends}{coords}")
    for title in ("forces", "constraints", "contacts"):
        group = by_section.get(title, [])
        lines.append(f"{title:<12} " + (", ".join(f"{c.name} ({c.summary()})" for c in group)
                                         if group else "none"))
    return lines


def _name(ref) -> str:
    return ref if isinstance(ref, str) else ref.name


def numeric_equations(system, simplify: bool = False):
    """``(M, f)`` with the parameter values substituted as exact rationals, in a canonical
    expanded form; speeds renamed ``<coord>'`` (sympy's ASCII pretty printer shows them plainly)."""
    import sympy as sp
    numbers = {}
    for key, value in system.parameters.items():
        entries = value if isinstance(value, (tuple, list)) else (value,)
        for i, x in enumerate(entries):
            name = f"{key}[{i}]" if isinstance(value, (tuple, list)) else key
            numbers[name] = sp.nsimplify(float(x), rational=True)
    M, f = system.equations(numbers)  # (the numbers go in while expanding: small expressions)
    symbols = {str(s): s for s in M.free_symbols | f.free_symbols}
    values = {}
    for coord in system.coords:
        speed = symbols.get(f"\\dot{{{coord}}}")
        if speed is not None:
            values[speed] = sp.Symbol(f"{coord}'")
    # Quaternions are unit length (the integrators normalise them): the rotation's 1/|q|^2
    # is 1 and w^2 = 1 - x^2 - y^2 - z^2, so the printed equations are polynomials whose
    # expansion stays small (without this, expanding a Ball joint's equations takes minutes).
    units = []
    for start in system.topology.state_map.quat_q:
        quat = [symbols.get(system.coords[start + k]) for k in range(4)]
        if all(s is not None for s in quat):
            w, x, y, z = quat
            values[w * w + x * x + y * y + z * z] = sp.Integer(1)
            units.append((w, 1 - x * x - y * y - z * z))
    from mbcomp.face.normal_form import canonical as normal_form
    canonical = functools.partial(normal_form, units=tuple(units))
    M, f = M.xreplace(values).applyfunc(canonical), f.xreplace(values).applyfunc(canonical)
    if simplify:
        M, f = M.applyfunc(sp.trigsimp), f.applyfunc(sp.trigsimp)
    return M, f


def cmd_info(args: argparse.Namespace) -> int:
    model, path = load_model(args.file)
    print(f"model        {model.name} ({path})")
    if getattr(model, "description", ""):
        print(f"description  {model.description}")
    try:
        system = compile_model(model)
    except CommandError:
        for line in describe_components(model):
            print(line)
        raise
    cut = [j.name for j in getattr(system.topology, "cut_joints", ())]
    for line in describe_components(model, cut):
        print(line)
    tree = model.tree()
    if tree.children:   # sub-model instances with their parameters
        print("instances")
        for child in tree.children:
            for line in child.lines("  "):
                print(line)
    print(f"coordinates  {', '.join(system.coords) or 'none'} ({system.nq})")
    if tuple(system.speeds) != tuple(system.coords):
        print(f"speeds       {', '.join(system.speeds)} ({system.nv}; a ball's: its angular velocity in the child frame)")
    print(f"degrees of freedom  {system.ndof}")
    if getattr(system, "extra_states", ()):  # states of drive elements (motor currents, PID integrals)
        print(f"extra states  {', '.join(system.extra_states)} ({system.integration_path()})")
    if system.constraint_names:
        print(f"constraint equations  {', '.join(system.constraint_names)}"
              + (f" (loop closures: {', '.join(cut)})" if cut else ""))
        print(f"redundant    {', '.join(system.redundant_constraints) or 'none'}"
              + (" (dependent on the others, found by rank and left out)" if system.redundant_constraints else ""))
    constraints = [c for c in model.components.values() if c.section == "constraints"]
    if not args.equations:
        return EXIT_OK
    print()
    if system.nv > MAX_PRINTED_COORDS:
        print(f"equations of motion: {system.nv} speeds are too many to print legibly; in Python:\n"
              f"  M, f = mbcomp.load({str(path)!r}).compile().equations()   # M qdd = f (sympy)")
        return EXIT_OK
    M, f = numeric_equations(system, simplify=args.simplify)
    width = shutil.get_terminal_size((100, 24)).columns
    qdd = ", ".join(f"{c}''" if c in system.coords else f"{c}'" for c in system.speeds)
    print(f"equations of motion  M(q) v' = f(q, v, t),  v' = [{qdd}]" if system.speeds != system.coords else
          f"equations of motion  M(q) q'' = f(q, q', t),  q'' = [{qdd}]")
    if constraints or cut:
        print("(tree equations; the constraints add their reactions C_q^T lambda to f)")
    for i in range(system.nv):
        for j in range(i, system.nv):
            if M[i, j] != 0:
                _print_entry(f"M[{i},{j}]", M[i, j], width)
    if system.nv > 1:
        print("(M is symmetric; entries not shown are zero or mirror the ones shown)")
    for i in range(system.nv):
        _print_entry(f"f[{i}]", f[i], width)
    return EXIT_OK


def _print_entry(label: str, expr, width: int) -> None:
    """``label = expr`` in sympy's one-line form (``x**2``), broken only between top-level
    terms into indented lines of at most ``width`` characters: no pretty-printer wrap marks."""
    import sympy as sp
    text = sp.sstr(sp.N(expr, 6), full_prec=False)
    head = f"{label} = "
    if len(head) + len(text) <= width:
        print(head + text)
        return
    print(f"{label} =")
    for line in _wrap_terms(text, max(width - 4, 40)):
        print("    " + line)


def _wrap_terms(text: str, width: int) -> list[str]:
    """``text`` split before its top-level `` + `` and `` - `` (outside parentheses), the
    pieces gathered into lines of at most ``width`` (a longer single term keeps its own line)."""
    pieces, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        depth += ch in "([" and 1 or (-1 if ch in ")]" else 0)
        if depth == 0 and i > start and text.startswith((" + ", " - "), i):
            pieces.append(text[start:i])
            start = i + 1
    pieces.append(text[start:])
    lines = [pieces[0]]
    for piece in pieces[1:]:
        if len(lines[-1]) + 1 + len(piece) <= width:
            lines[-1] += " " + piece
        else:
            lines.append(piece)
    return lines


# ----------------------------------------------------------------------------------------------
# mbcomp library
# ----------------------------------------------------------------------------------------------
def cmd_library(args: argparse.Namespace) -> int:
    from mbcomp.files.toml_model import library_dirs, library_models, read_description
    models = library_models()
    if args.name:
        from mbcomp.files.library import library_robots
        path = models.get(args.name[:-5] if args.name.endswith(".toml") else args.name)
        path = path if path is not None else library_robots().get(args.name)
        if path is None:
            raise CommandError(f"no library model {args.name!r}; available: {', '.join(models) or 'none'}",
                               EXIT_BAD_INPUT)
        sys.stdout.write(path.read_text(encoding="utf-8"))
        return EXIT_OK
    if not models:
        raise CommandError("no library found (looked in $MBCOMP_LIBRARY and the library/ folder beside "
                           "the package)")
    width = max(len(name) for name in models)
    for name, path in models.items():
        print(f"{name.ljust(width)}  {read_description(path) or '(no description)'}")
    from mbcomp.files.library import library_parts, library_robots
    robots = library_robots()
    for name, path in robots.items():
        print(f"{name.ljust(width)}  robot arm from URDF ({path.name}, example-robot-data package)")
    parts = library_parts()
    if parts:
        print("\nparts (for [submodels] in model files, see docs/composition.md):")
        for name, path in parts.items():
            print(f"  {name.ljust(width - 2)}  {read_description(path) or '(no description)'}")
    print(f"\n{len(models)} models in {', '.join(str(d) for d in library_dirs())}"
          f"{f' and {len(robots)} URDF robots' if robots else ''}; "
          "run one with 'mbcomp run NAME', copy one with 'mbcomp library NAME > my.toml'")
    return EXIT_OK


# ----------------------------------------------------------------------------------------------
def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning during a command as one clean line (``mbcomp: warning: ...``), without the
    source file and line Python's default display adds."""
    text = " ".join(str(message).split())
    print(f"mbcomp: warning: {text}", file=sys.stderr if file is None else file)


def cmd_export(args: argparse.Namespace) -> int:
    """``mbcomp export FILE --fmu OUT [--kind cs|me] [--input JOINT ...]``."""
    from mbcomp.core.errors import ModelError, WriteError
    model, _ = load_model(args.file)
    system = compile_model(model)
    try:
        path = system.export_fmu(args.fmu, kind=args.kind, inputs=tuple(args.input))
    except (ModelError, WriteError) as exc:
        raise CommandError(f"cannot export {model.name!r}: {exc}", EXIT_BAD_INPUT) from None
    print(f"wrote {path} (FMI 2.0 {'co-simulation' if args.kind == 'cs' else 'model exchange'}, "
          f"{len(system.coords)} coordinates, {len(args.input)} inputs)")
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``mbcomp`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings():  # restores the warning display afterwards
            warnings.showwarning = _show_warning
            code = args.handler(args)
    except CommandError as exc:
        print(f"mbcomp: {exc}" if "\n" not in str(exc) else f"mbcomp: error: {exc}", file=sys.stderr)
        code = exc.code
    except KeyboardInterrupt:
        print("mbcomp: interrupted", file=sys.stderr)
        code = EXIT_INTERRUPTED
    except BrokenPipeError:  # e.g. 'mbcomp library | head'
        code = EXIT_OK
    sys.stdout.flush()
    return code


if __name__ == "__main__":
    sys.exit(main())
