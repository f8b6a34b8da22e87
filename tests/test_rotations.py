"""partcal.robot.rotations: each convention against scipy's own reading of it (an independent implementation)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from partcal.robot import kinematics
from partcal.robot.rotations import (kuka_abc_from_matrices, matrices_from_euler_deg, matrices_from_kuka_abc,
                                     matrices_from_rotation_vectors, matrices_from_rpy_deg, matrices_from_xyz_deg,
                                     matrix_from_rotation_vector, matrix_from_rpy_deg, rotation_vector_from_matrix,
                                     rotation_vectors_from_matrices, rpy_deg_from_matrix, xyz_deg_from_matrices)

ANGLES = np.random.default_rng(7).uniform(-179.0, 179.0, (200, 3)) * [1.0, 0.5, 1.0]     # the middle one in (-90, 90)


def test_rpy_is_urdfs_fixed_axes_xyz():
    """URDF rpy: turns about the fixed x, y, z axes (scipy's lower-case ``xyz``), one row and many alike."""
    many = matrices_from_rpy_deg(ANGLES)
    np.testing.assert_allclose(many, Rotation.from_euler("xyz", ANGLES, degrees=True).as_matrix(), atol=1e-14)
    for angles, rot in zip(ANGLES[:20], many[:20]):
        np.testing.assert_array_equal(matrix_from_rpy_deg(angles), rot)        # one formula: the same bits
        np.testing.assert_allclose(rpy_deg_from_matrix(rot), angles, atol=1e-9)


def test_kuka_abc_is_rpy_backwards():
    """KUKA A, B, C = Rz(A) Ry(B) Rx(C): scipy's intrinsic ``ZYX``, and URDF's rpy of (C, B, A)."""
    rot = matrices_from_kuka_abc(ANGLES)
    np.testing.assert_allclose(rot, Rotation.from_euler("ZYX", ANGLES, degrees=True).as_matrix(), atol=1e-14)
    np.testing.assert_array_equal(rot, matrices_from_rpy_deg(ANGLES[:, ::-1]))
    np.testing.assert_allclose(kuka_abc_from_matrices(rot), ANGLES, atol=1e-9)


def test_measurement_xyz_is_intrinsic_xyz():
    rot = matrices_from_xyz_deg(ANGLES)
    np.testing.assert_allclose(rot, Rotation.from_euler("XYZ", ANGLES, degrees=True).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(xyz_deg_from_matrices(rot), ANGLES, atol=1e-9)
    np.testing.assert_array_equal(matrices_from_euler_deg("XYZ", ANGLES),
                                  Rotation.from_euler("XYZ", ANGLES, degrees=True).as_matrix())


def test_rotation_vectors_one_and_many():
    rotvecs = np.radians(ANGLES) / 2.0
    many = matrices_from_rotation_vectors(rotvecs)
    # hand: a quarter turn about z takes x to y
    np.testing.assert_allclose(matrix_from_rotation_vector([0.0, 0.0, np.pi / 2]) @ [1.0, 0, 0], [0, 1.0, 0],
                               atol=1e-15)
    np.testing.assert_array_equal(matrix_from_rotation_vector(rotvecs[3]), many[3])
    np.testing.assert_allclose(rotation_vectors_from_matrices(many), rotvecs, atol=1e-12)
    np.testing.assert_array_equal(rotation_vector_from_matrix(many[3]), rotation_vectors_from_matrices(many)[3])


@pytest.mark.parametrize("name", ["matrix_from_euler_deg", "matrices_from_xyz_deg", "xyz_deg_from_matrices",
                                  "rpy_deg_from_matrix"])
def test_the_old_import_paths_still_work(name):
    """Names that lived in kinematics before rotations.py held every convention are the same functions there."""
    from partcal.robot import rotations

    old = getattr(kinematics, name)
    assert old is getattr(rotations, "matrix_from_rpy_deg" if name == "matrix_from_euler_deg" else name)
