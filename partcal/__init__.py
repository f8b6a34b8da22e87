"""partcal: predict and correct the positioning errors of robot manipulators."""

from importlib.metadata import PackageNotFoundError, version as _version

try:
    __version__ = _version("partcal")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.1.0"

from .errors import ConfigError, DataError, ModelFileError, PartcalError, UnreachableError
from .kinematics import Robot, available_robots, load_robot
from .measurements import Measurements, read_measurements, write_measurements
from .metrics import ExtrapolationWarning, cross_validated_rms, rms_per_axis, summary
from .models import ErrorModel
from .partition import KMeansPartition, Octree
from .partitioned import PartitionedErrorModel, select_granularity
from .predictor import Predictor, load_predictor
from .swarm import SwarmConfig, SwarmResult, minimize, minimize_batch

__all__ = [
    "__version__",
    "ConfigError", "DataError", "ModelFileError", "PartcalError", "UnreachableError",
    "Robot", "available_robots", "load_robot",
    "Measurements", "read_measurements", "write_measurements",
    "ExtrapolationWarning", "cross_validated_rms", "rms_per_axis", "summary",
    "KMeansPartition", "Octree", "PartitionedErrorModel", "select_granularity",
    "Predictor", "load_predictor",
    "ErrorModel", "SwarmConfig", "SwarmResult", "minimize", "minimize_batch",
]
