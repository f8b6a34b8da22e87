"""partcal: predict and correct the positioning errors of robot manipulators.

The public names below are imported on first use (PEP 562), so that the
command line starts quickly and ``partcal --version`` does not load
scikit-learn; ``from partcal import ErrorModel`` works as usual.
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

try:
    __version__ = _version("partcal")
except PackageNotFoundError:  # running from a source tree without installing
    __version__ = "0.1.0"

_EXPORTS = {
    "errors": ["ConfigError", "DataError", "ModelFileError", "PartcalError", "RobotFileError", "UnreachableError"],
    "robot.kinematics": ["Robot"],
    "robot.floor": ["Floor"],
    "robot.urdf": ["robot_from_urdf"],
    "robot.description": ["available_robots", "load_robot"],
    "data.measurements": ["Measurements", "read_measurements", "write_measurements"],
    "data.formats": ["MeasurementFormat", "RowSelection", "load_format"],
    "data.registration": ["Registration", "register_tracker"],
    "data.programs": ["read_program"],
    "metrics": ["ExtrapolationWarning", "rms_per_axis", "summary"],
    "models.series": ["ErrorModel"],
    "models.gp": ["GaussianProcessErrorModel"],
    "models.kinematic": ["KinematicModel"],
    "models.design": ["PlannedModel"],
    "models.swarm": ["SwarmConfig", "SwarmResult", "minimize", "minimize_batch"],
    "models.partition": ["KMeansPartition", "Octree"],
    "models.partitioned": ["PartitionedErrorModel"],
    "models.pose": ["PoseErrorModel"],
    "study.predictor": ["Predictor", "load_predictor"],
    "study.programs": ["ProgramFrames", "compensate_program"],
    "study.plan": ["evaluate_poses", "plan_poses"],
    "study.selection": ["cross_validated_rms", "select_granularity"],
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}
__all__ = ["__version__", *_WHERE]


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'partcal' has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
