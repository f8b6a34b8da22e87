"""Measured data: the CSV contract, and the virtual robot that produces data sets.

Above ``partcal.robot`` (it computes nominal positions by forward kinematics),
beside ``partcal.models`` (neither imports the other).
"""

from .measurements import Measurements, read_measurements, write_measurements

__all__ = ["Measurements", "read_measurements", "write_measurements"]
