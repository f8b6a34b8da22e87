"""Error models: series models, Gaussian processes, the kinematic model (on :mod:`partcal.calibration`), partitions and
blending.

Every estimator here follows the scikit-learn contract: ``fit(X, y)`` with
inputs in contract units (positions in mm or joint angles in degrees) and
errors ``(n, 3)`` in mm, ``predict(X) -> (n, 3)`` mm; a kinematic model and a
:class:`PoseErrorModel` also take pose errors ``(n, 6)``: mm, then mrad.
"""

from .gp import GaussianProcessErrorModel
from ..calibration.identification import identify
from ..calibration.parameters import Identification
from .kinematic import KinematicModel
from .partition import KMeansPartition, Octree
from .partitioned import PartitionedErrorModel
from .pose import PoseErrorModel
from .series import ErrorModel
from .swarm import SwarmConfig, SwarmResult, minimize, minimize_batch
from . import kinds  # noqa: E402,F401  (the built-in rows of the table of kinds, before any model is read)

__all__ = ["ErrorModel", "GaussianProcessErrorModel", "Identification", "KMeansPartition", "KinematicModel", "Octree",
           "PartitionedErrorModel", "PoseErrorModel", "SwarmConfig", "SwarmResult", "identify", "minimize",
           "minimize_batch"]
