"""The C of an exported FMU: the model's own library sources (``CompiledModel.export_sources``:
the generated functions, the tree and KKT solves, DOP853) with the FMI 2.0 wrapper
(``c/fmu2.c``) appended to the template unit, after the ``#define``s and tables this module
writes: sizes, value-reference bases, start values, the dae formulation's rows and gains."""
from __future__ import annotations

import re

import numpy as np

from mbcomp.core import c_text, tolerances
from mbcomp.core.errors import ModelError
from mbcomp.face.fmu.variables import SETTINGS, Table
from mbcomp.formulations.dae_c import DATA_DOUBLES, ROW_CONTACT, SPEC_LONGS
from mbcomp.formulations.dae_compiled import motor_programs, row_tables
from mbcomp.formulations.impact import GAP_TOLERANCE

_INCLUDE = re.compile(r'^#include "fmi2_decl\.h"$', re.M)


def _table(ctype: str, name: str, values) -> str:
    """A C array with one spare entry (C has no empty arrays)."""
    values = list(values)
    if ctype == "double":
        body = ", ".join(repr(float(v)) for v in values)
    else:
        body = ", ".join(str(int(v)) for v in values)
    return f"{_HIDDEN} const {ctype} {name}[{len(values) + 1}] = {{{body}{', ' if values else ''}0}};\n"


def dae_rows(system, formulation) -> tuple[np.ndarray, np.ndarray, list[int], np.ndarray]:
    """The KKT rows of the model's constraints as the dae formulation configures them
    (``dae_compiled.row_tables``): ``(spec, data, motor speed parameter, programs)``; the speed
    motor's entry is its speed's index in ``p`` (-1: fixed, -2: not a speed motor); its
    offset (its coordinate at the start) is 0 here and set when the FMU is initialised.
    ``ModelError`` for a motor whose position is a Python callable, which an FMU cannot call."""
    kernel = system.kernel
    entries = kernel.compiled.layout.entries
    constraints = formulation.constraints
    rows = [] if constraints is None or formulation.nominal_rows is None else [int(r) for r in formulation.nominal_rows]
    callables = {r for r, program in motor_programs(formulation).items() if program is None}
    for r in rows:
        if r in callables:
            raise ModelError(constraints.groups_by_row(r), "its position is a Python callable: it cannot be "
                                                           "exported into an FMU (give it as an expression of t)")
    speeds = {r: constraints.motor_speed(kernel, r) for r in rows if r in constraints.coordinate_rows}
    speed_p = [-2 if speeds.get(r) is None else entries.get(f"{constraints.owner[r]}.speed", (-1,))[0] for r in rows]
    spec, data, programs = row_tables(formulation, kernel, rows, {r: 0.0 for r, v in speeds.items() if v is not None})
    return spec, data, speed_p, programs if (spec[:, 4] >= 0).any() else np.zeros(0)  # (row_tables pads with 0)


def restitution_indices(system) -> list[int]:
    """Where each contact's restitution sits in the parameter vector ``p``."""
    kernel = system.kernel
    entries = kernel.compiled.layout.entries
    out = []
    for contact in kernel.topology.contacts:
        key = getattr(contact, "restitution_key", f"{contact.name}.restitution")
        if key not in entries:
            raise ModelError(contact, f"its restitution ({key!r}) is not a parameter: it cannot be exported")
        out.append(entries[key][0])
    return out


#: Co-simulation without inputs or contacts: how many communication points one run of the loop
#: past the current one may fill from its dense output (``fmu_step_ahead`` in ``c/fmu2.c``).
AHEAD = 64
#: The constants the wrapper reads, defined per model in the unit ``fmu_tables``:
#: (C type, name); ``FMU_<NAME>`` in the C is ``fmu_<NAME>``.
SCALARS = (("int", "NY"), ("int", "NV"), ("int", "NP"), ("int", "NU"), ("int", "NK"), ("int", "NR0"),
           ("int", "VR_STATE"), ("int", "VR_DER"), ("int", "VR_PAR"), ("int", "VR_IN"), ("int", "VR_RTOL"),
           ("int", "VR_ATOL"), ("int", "VR_REST"), ("int", "VR_MAXSTEP"), ("int", "VR_ENV"),
           ("int", "NE"), ("int", "NX"), ("int", "ND"), ("double", "ALPHA"), ("double", "BETA"),
           ("double", "SCHUR_SCALE"), ("double", "SINGULAR_TOL"))
TABLES = (("double", "fmu_y_start"), ("double", "fmu_p_start"), ("int", "fmu_input_speed"),
          ("int", "fmu_restitution"), ("long", "fmu_spec0"), ("double", "fmu_data0"), ("int", "fmu_motor_speed_p"),
          ("double", "fmu_programs"), ("double", "fmu_env_start"), ("int", "fmu_env_exported"),
          ("int", "fmu_env_binding"), ("int", "fmu_derived_p"), ("int", "fmu_derived_prog"),
          ("double", "fmu_derive_programs"))
_HIDDEN = '__attribute__((visibility("hidden")))'


def wrapper_source() -> str:
    """The FMI wrapper (``c/fmu2.c``, its header inlined) after the package's constants and
    the declarations of the model's (``SCALARS``, ``TABLES``, ``fmu_guid``): the same text
    for every model of one kind."""
    settings = {name: start for name, start, _, _ in SETTINGS}
    defines = {"FMU_GAP_TOL": repr(GAP_TOLERANCE), "FMU_GAP_XTOL": repr(tolerances.EVENT_GAP_XTOL),
               "FMU_FORCE_XTOL": repr(tolerances.EVENT_FORCE_XTOL),
               "FMU_RTOL0": repr(settings["mbcomp.rtol"]), "FMU_ATOL0": repr(settings["mbcomp.atol"]),
               "FMU_REST0": repr(settings["mbcomp.rest_speed"]),
               "FMU_AHEAD": AHEAD, "FMU_SPEC_LONGS": SPEC_LONGS, "FMU_DATA_DOUBLES": DATA_DOUBLES, "FMU_ROW_CONTACT": ROW_CONTACT}
    text = [f"#define {k} {v}\n" for k, v in defines.items()]
    for ctype, name in SCALARS:
        text.append(f"extern const {ctype} fmu_{name} {_HIDDEN};\n#define FMU_{name} fmu_{name}\n")
    text += [f"extern const {ctype} {name}[] {_HIDDEN};\n" for ctype, name in TABLES]
    text.append(f"extern const char fmu_guid[] {_HIDDEN};\n#define FMU_GUID fmu_guid\n")
    header = c_text.raw("mbcomp.face.fmu", "fmi2_decl.h")
    wrapper = _INCLUDE.sub(lambda _: header.rstrip("\n"), c_text.raw("mbcomp.face.fmu", "fmu2.c"))
    return "\n/* ---- the FMI 2.0 interface (mbcomp face/fmu) ---- */\n" + "".join(text) + wrapper


def tables_source(system, formulation, table: Table, guid: str, derived) -> str:
    """The unit defining the model's constants that the wrapper declares."""
    kernel = system.kernel
    y0 = [v.start for v in table.variables[:table.ny]]
    p0 = [v.start for v in table.variables[table.vr_par:table.vr_env]]
    spec, data, speed_p, programs = dae_rows(system, formulation)
    alpha, beta = formulation.baumgarte
    values = {"NY": table.ny, "NV": kernel.nv, "NP": len(p0), "NU": len(table.input_speeds),
              "NK": len(kernel.topology.contacts), "NR0": len(spec), "VR_STATE": 0, "VR_DER": table.vr_der,
              "VR_PAR": table.vr_par, "VR_IN": table.vr_in, "VR_RTOL": table.vr_settings,
              "VR_ATOL": table.vr_settings + 1, "VR_REST": table.vr_settings + 2,
              "VR_MAXSTEP": table.vr_settings + 3, "VR_ENV": table.vr_env, "NE": len(derived.env),
              "NX": len(derived.exported), "ND": len(derived.entries), "ALPHA": float(alpha), "BETA": float(beta),
              "SCHUR_SCALE": float(formulation.schur_scale),
              "SINGULAR_TOL": float(formulation.singular_tolerance)}
    text = [f"{_HIDDEN} const {ctype} fmu_{name} = {values[name]!r};\n" for ctype, name in SCALARS]
    arrays = {"fmu_y_start": y0, "fmu_p_start": p0, "fmu_input_speed": table.input_speeds,
              "fmu_restitution": restitution_indices(system), "fmu_spec0": spec.reshape(-1),
              "fmu_data0": data.reshape(-1), "fmu_motor_speed_p": speed_p, "fmu_programs": programs,
              "fmu_env_start": derived.env, "fmu_env_exported": derived.exported, "fmu_env_binding": derived.bindings,
              "fmu_derived_p": [i for i, _ in derived.entries], "fmu_derived_prog": [o for _, o in derived.entries],
              "fmu_derive_programs": derived.programs}
    text += [_table(ctype, name, arrays[name]) for ctype, name in TABLES]
    text.append(f'{_HIDDEN} const char fmu_guid[] = "{guid}";\n')
    return "".join(text)


def fmu_units(system, formulation, table: Table, guid: str, derived) -> list[tuple[str, str]]:
    """The FMU's translation units ``[(file stem, text)]``: the model's library sources with
    the wrapper appended to the templates, and the model's constants (``fmu_tables``)."""
    units = []
    for name, text in system.kernel.compiled.export_sources():
        if name == "templates":
            text = text + wrapper_source()
        units.append((name, text))
    units.append(("fmu_tables", tables_source(system, formulation, table, guid, derived)))
    return units
