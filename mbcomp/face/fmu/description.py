"""``modelDescription.xml`` of an exported FMU (FMI 2.0), from the variable table."""
from __future__ import annotations

import datetime
import xml.etree.ElementTree as ET

from mbcomp.face.fmu.variables import Table


def _number(x: float) -> str:
    return repr(float(x))


def model_description(table: Table, *, model_name: str, identifier: str, guid: str, kind: str, n_contacts: int,
                      description: str = "", version: str = "", stop_time: float | None = None,
                      tolerance: float = 1e-8) -> bytes:
    """The XML text (UTF-8): the interface of ``kind`` ("cs": ``CoSimulation`` with a
    variable communication step; "me": ``ModelExchange``), the units used, the variables of
    ``table`` and the model structure (outputs; in model exchange the derivatives and the
    initial unknowns); one event indicator per contact."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": model_name, "guid": guid,
        "description": description or f"mbcomp model {model_name}",
        "generationTool": f"mbcomp {version}".strip(),
        "generationDateAndTime": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "variableNamingConvention": "flat",
        "numberOfEventIndicators": str(n_contacts if kind == "me" else 0)})
    common = {"modelIdentifier": identifier, "canNotUseMemoryManagementFunctions": "true",
              "canGetAndSetFMUstate": "false", "canSerializeFMUstate": "false",
              "providesDirectionalDerivative": "false"}
    if kind == "cs":
        ET.SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true",
                                             "canInterpolateInputs": "false", "maxOutputDerivativeOrder": "0",
                                             "canRunAsynchronuously": "false", "canBeInstantiatedOnlyOncePerProcess": "false"})
    else:
        ET.SubElement(root, "ModelExchange", {**common, "completedIntegratorStepNotNeeded": "true",
                                              "canBeInstantiatedOnlyOncePerProcess": "false"})
    units = sorted({v.unit for v in table.variables if v.unit})
    if units:
        defs = ET.SubElement(root, "UnitDefinitions")
        for unit in units:
            ET.SubElement(defs, "Unit", {"name": unit})
    experiment = {"startTime": "0.0", "tolerance": _number(tolerance)}
    if stop_time is not None:
        experiment["stopTime"] = _number(stop_time)
    ET.SubElement(root, "DefaultExperiment", experiment)
    variables = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(table.variables):
        attributes = {"name": v.name, "valueReference": str(vr), "causality": v.causality,
                      "variability": v.variability}
        if v.description:
            attributes["description"] = v.description
        if v.initial is not None:
            attributes["initial"] = v.initial
        element = ET.SubElement(variables, "ScalarVariable", attributes)
        real = {}
        if v.start is not None:
            real["start"] = _number(v.start)
        if v.unit:
            real["unit"] = v.unit
        if v.derivative is not None:
            real["derivative"] = str(v.derivative)
        ET.SubElement(element, "Real", real)
    structure = ET.SubElement(root, "ModelStructure")
    outputs = table.outputs
    if outputs:
        block = ET.SubElement(structure, "Outputs")
        for k in outputs:
            ET.SubElement(block, "Unknown", {"index": str(k + 1)})
    derivatives = [k for k, v in enumerate(table.variables) if v.derivative is not None]
    if derivatives:
        block = ET.SubElement(structure, "Derivatives")
        for k in derivatives:
            ET.SubElement(block, "Unknown", {"index": str(k + 1)})
        block = ET.SubElement(structure, "InitialUnknowns")
        for k in derivatives:
            ET.SubElement(block, "Unknown", {"index": str(k + 1)})
    ET.indent(root)
    return b'<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="utf-8") + b"\n"
