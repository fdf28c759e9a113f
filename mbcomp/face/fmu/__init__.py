"""Exporting a model as an FMI 2.0 FMU (co-simulation or model exchange): ``export_fmu``."""
from mbcomp.face.fmu.export import export_fmu

__all__ = ["export_fmu"]
