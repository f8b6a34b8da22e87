"""Measured data: the CSV contract, foreign formats, and the virtual robot that produces data sets.

Above ``partcal.robot`` (it computes nominal positions by forward kinematics),
beside ``partcal.models`` (neither imports the other).
"""

from .formats import MeasurementFormat, RowSelection, load_format
from .measurements import Measurements, read_measurements, write_measurements

__all__ = ["MeasurementFormat", "Measurements", "RowSelection", "load_format", "read_measurements",
           "write_measurements"]
