"""Robot geometry: DH kinematics with coupled joints, the built-in robots, test paths, false targets.

The lowest layer above the foundation: it knows joint angles and positions,
nothing about measurement files or error models.
"""

from .description import available_robots, joint_columns, load_robot
from .kinematics import IKResult, Robot, matrix_from_euler_deg
from .rotations import (matrices_from_rpy_deg, matrices_from_xyz_deg, matrix_from_rpy_deg, rpy_deg_from_matrix,
                        xyz_deg_from_matrices)

__all__ = ["IKResult", "Robot", "available_robots", "joint_columns", "load_robot",
           "matrices_from_rpy_deg", "matrices_from_xyz_deg", "matrix_from_euler_deg", "matrix_from_rpy_deg",
           "rpy_deg_from_matrix", "xyz_deg_from_matrices"]
