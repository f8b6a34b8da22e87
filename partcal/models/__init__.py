"""Error models: feature bases, the particle swarm, series models, partitions and blending.

Every estimator here follows the scikit-learn contract: ``fit(X, y)`` with
inputs in contract units (positions in mm or joint angles in degrees) and
errors ``(n, 3)`` in mm, ``predict(X) -> (n, 3)`` mm.
"""

from .partition import KMeansPartition, Octree
from .partitioned import PartitionedErrorModel, select_granularity
from .series import ErrorModel
from .swarm import SwarmConfig, SwarmResult, minimize, minimize_batch

__all__ = ["ErrorModel", "KMeansPartition", "Octree", "PartitionedErrorModel", "SwarmConfig", "SwarmResult",
           "minimize", "minimize_batch", "select_granularity"]
