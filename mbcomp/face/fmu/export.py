"""Writing a model as an FMI 2.0 FMU: co-simulation or model exchange, self-contained.

The FMU holds ``modelDescription.xml``, ``sources/`` (the C it was built from: the model's
generated functions and mbcomp's hand-written C, with the FMI wrapper) and
``binaries/<platform>/<identifier>.so`` compiled here with the C compiler mbcomp uses.
Constraints and contacts run as in the ``dae`` formulation (the KKT solve with Baumgarte
stabilisation; projection after each step in co-simulation), so the state is ``[q, v, z]``
whichever formulation the System uses.
"""
from __future__ import annotations

import hashlib
import io
import re
import sys
import uuid
import zipfile
from pathlib import Path

from mbcomp.codegen import cache
from mbcomp.codegen.backend import C_FLAGS, COLD_FLAGS, CBuild, c_compiler
from mbcomp.core.errors import CompileError, ModelError
from mbcomp.core.writing import write_file
from mbcomp.face.fmu.derived import derived_parameters
from mbcomp.face.fmu.description import model_description
from mbcomp.face.fmu.sources import fmu_units
from mbcomp.face.fmu.variables import build_table

KINDS = ("cs", "me")
#: Flags added to mbcomp's own: only the FMI functions are exported from the library.
FMU_FLAGS = ("-fvisibility=hidden",)


def platform_folder() -> str:
    """The FMI 2.0 name of this platform's binaries folder (``linux64``, ``darwin64``, ``win64``)."""
    bits = "64" if sys.maxsize > 2 ** 32 else "32"
    if sys.platform.startswith("linux"):
        return f"linux{bits}"
    if sys.platform == "darwin":
        return f"darwin{bits}"
    if sys.platform.startswith("win"):
        return f"win{bits}"
    raise ModelError("export_fmu", f"no FMI platform name for {sys.platform!r}")


def identifier(name: str) -> str:
    """A C identifier from a model name (the FMU's ``modelIdentifier`` and file stem)."""
    ident = re.sub(r"\W", "_", name, flags=re.ASCII) or "model"
    return ident if not ident[0].isdigit() else f"m_{ident}"


def check_exportable(system) -> None:
    """``ModelError`` for what compiled code cannot run: Python callables among forces,
    drives or signals."""
    kernel = system.kernel
    if kernel.n_inputs:
        raise ModelError(f"Model {system.name!r}", "has forces or torques given as Python callables: an FMU "
                         "cannot call Python (use an input joint, export_fmu(inputs=...))")
    if kernel.compiled.drives.callables:
        raise ModelError(f"Model {system.name!r}", "its drives or signals use Python callables: an FMU cannot "
                         "call Python")


def export_fmu(system, formulation, path, kind: str = "cs", inputs=(), outputs=None,
               stop_time: float | None = None) -> Path:
    """Write ``system`` as an FMI 2.0 FMU at ``path`` and return the path.

    ``formulation``: the System's ``dae`` formulation (the rows and gains the C configures).
    ``kind``: ``"cs"`` (co-simulation: DOP853 inside ``fmi2DoStep``, tolerances as the
    parameters ``mbcomp.rtol``/``mbcomp.atol``) or ``"me"`` (model exchange: the state
    ``[q, v, z]``, its derivatives, one event indicator per contact).  ``inputs``: joint
    names, each one input (the generalised force on it, N m or N, added to ``tau``).
    ``outputs``: the coordinates, speed columns and drive states that are outputs (None: all).
    """
    if kind not in KINDS:
        raise ModelError("export_fmu", f"kind must be 'cs' or 'me', got {kind!r}")
    if isinstance(inputs, str):
        inputs = (inputs,)
    check_exportable(system)
    compiler = c_compiler()
    if compiler is None:
        raise ModelError("export_fmu", "an FMU is compiled C: no C compiler was found (set $CC)")
    derived = derived_parameters(system)
    table = build_table(system, kind, tuple(inputs), None if outputs is None else tuple(outputs), derived)
    ident = identifier(system.name)
    digest = hashlib.sha256("\n".join([system.kernel.compiled.description, kind, repr(table)]).encode()).digest()
    guid = "{" + str(uuid.UUID(bytes=digest[:16])) + "}"
    units = fmu_units(system, formulation, table, guid, derived)
    build = CBuild(compiler)
    try:
        for name, text in units:
            flags = (COLD_FLAGS if name in ("sizes", "fmu_tables") else C_FLAGS) + FMU_FLAGS
            # the templates with the wrapper depend only on the kind of model: cached, shared
            use_cache = getattr(system.kernel.compiled, "use_cache", True)
            shared = cache.toolchain(compiler, flags) if name == "templates" and use_cache else None
            build.add(name, text, flags, statements=text.count(";"), shared=shared)
    except BaseException:
        build.cancel()
        raise
    library = build.finish()
    if library is None:
        raise CompileError(f"Model {system.name!r}", "the C compiler failed on the FMU's sources")
    from mbcomp import __version__
    xml = model_description(table, model_name=system.name, identifier=ident, guid=guid, kind=kind,
                            n_contacts=len(system.kernel.topology.contacts), version=__version__,
                            stop_time=stop_time)
    path = Path(path)
    suffix = {"linux": ".so", "darwin": ".dylib", "win": ".dll"}
    extension = next((v for k, v in suffix.items() if sys.platform.startswith(k)), ".so")
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.writestr(f"binaries/{platform_folder()}/{ident}{extension}", library)
        for name, text in units:
            zf.writestr(f"sources/{name}.c", text)
    write_file(path, buffer.getvalue(), "export_fmu")
    return path
