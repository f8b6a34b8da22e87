"""The exception hierarchy: every user error is a :class:`PartcalError`.

User errors (bad files, bad parameters, bad arrays) subclass ``ValueError`` so
that code written for scikit-learn conventions keeps working; the command
line turns any of them into exit code 2 and one line on stderr.
"""

from __future__ import annotations


class PartcalError(ValueError):
    """Base class of every error caused by the user's input."""


class DataError(PartcalError):
    """A measurement file or array is malformed (names file, row and column)."""


class ConfigError(PartcalError):
    """A YAML file (run config, robot, virtual robot) is malformed."""


class RobotFileError(ConfigError):
    """A robot description (a URDF) is malformed or does not hold the chain asked for (names the file, the
    element and its line, and what was expected)."""


class UnreachableError(PartcalError):
    """Inverse kinematics found no joint angles for one or more targets.

    Attributes
    ----------
    indices : list of int
        0-based indices of the targets that were not reached.
    distances_mm : list of float
        Remaining position error of each of those targets, in mm.
    """

    def __init__(self, message: str, indices=(), distances_mm=()):
        super().__init__(message)
        self.indices = list(indices)
        self.distances_mm = list(distances_mm)


class ModelFileError(PartcalError):
    """A model file is damaged, foreign, or of an unsupported version."""
