"""Changes of representation of rotations and poses, named from -> to, batched.

The conventions of the robot vendors' programs (docs/predictor.md, "Robot programs"):

- KUKA ``A, B, C``: Z-Y-X Euler angles in degrees, ``R = Rz(A) Ry(B) Rx(C)`` (turns about the moving z,
  then the new y, then the newest x; the same as turns about the fixed x, y, then z axes).
- ABB quaternions ``[q1, q2, q3, q4]``: scalar first, ``q1 = cos(angle / 2)``.
- Universal Robots' rotation vectors ``[rx, ry, rz]``: axis times angle, radians.

Each ``*_from_matrices`` function takes an optional ``near``: the representation the rotation had before
(one per row). A rotation has several writings (``q`` and ``-q``; a rotation vector of angle near pi and
its twin on the other side; ``A = 180`` and ``A = -180``): ``near`` picks the one closest to the old
writing, so that a small change of the rotation is a small change of the numbers in a program.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation


def matrices_from_kuka_abc(abc_deg) -> NDArray[np.float64]:
    """Rotations ``Rz(A) Ry(B) Rx(C)`` ``(n, 3, 3)`` from KUKA angles ``(n, 3)`` degrees ``A, B, C``.

    >>> (matrices_from_kuka_abc([[90.0, 0.0, 0.0]])[0] @ [1.0, 0.0, 0.0]).round(12) + 0.0   # A turns about z
    array([0., 1., 0.])
    """
    abc = np.atleast_2d(np.asarray(abc_deg, dtype=float))
    return Rotation.from_euler("ZYX", abc, degrees=True).as_matrix().reshape(-1, 3, 3)


def kuka_abc_from_matrices(rotations, near=None) -> NDArray[np.float64]:
    """KUKA angles ``(n, 3)`` degrees ``A, B, C`` of rotations ``(n, 3, 3)``: ``B`` in [-90, 90].

    ``near`` (n, 3) degrees: ``A`` and ``C`` are moved by whole turns to lie within 180 degrees of it (so
    ``A = 180`` stays 180, not -180).

    >>> kuka_abc_from_matrices(matrices_from_kuka_abc([[30.0, -20.0, 170.0]])).round(9).tolist()
    [[30.0, -20.0, 170.0]]
    """
    R = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    B = np.degrees(np.arcsin(np.clip(-R[:, 2, 0], -1.0, 1.0)))
    A = np.degrees(np.arctan2(R[:, 1, 0], R[:, 0, 0]))
    C = np.degrees(np.arctan2(R[:, 2, 1], R[:, 2, 2]))
    out = np.stack([A, B, C], axis=1)
    if near is not None:
        near = np.asarray(near, dtype=float).reshape(-1, 3)
        for k in (0, 2):
            out[:, k] = near[:, k] + (out[:, k] - near[:, k] + 180.0) % 360.0 - 180.0
    return out


def matrices_from_quaternions(quaternions) -> NDArray[np.float64]:
    """Rotations ``(n, 3, 3)`` from quaternions ``(n, 4)`` scalar first (ABB's ``q1, q2, q3, q4``), normalised.

    >>> (matrices_from_quaternions([[0.0, 0.0, 0.0, 1.0]])[0] @ [1.0, 0.0, 0.0]).round(12) + 0.0  # half a turn about z
    array([-1.,  0.,  0.])
    """
    q = np.atleast_2d(np.asarray(quaternions, dtype=float))
    return Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix().reshape(-1, 3, 3)


def quaternions_from_matrices(rotations, near=None) -> NDArray[np.float64]:
    """Unit quaternions ``(n, 4)`` scalar first of rotations ``(n, 3, 3)``.

    ``q`` and ``-q`` are the same rotation: with ``near`` (n, 4), the one on its side (``q . near >= 0``);
    without, the one with ``q1 >= 0``.
    """
    R = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    q = Rotation.from_matrix(R).as_quat()[:, [3, 0, 1, 2]]
    ref = np.tile([1.0, 0.0, 0.0, 0.0], (len(q), 1)) if near is None else np.asarray(near, dtype=float).reshape(-1, 4)
    q[np.einsum("ij,ij->i", q, ref) < 0] *= -1.0
    return q


def matrices_from_rotation_vectors(rotvecs_rad) -> NDArray[np.float64]:
    """Rotations ``(n, 3, 3)`` from rotation vectors ``(n, 3)`` (axis times angle, radians)."""
    return Rotation.from_rotvec(np.atleast_2d(np.asarray(rotvecs_rad, dtype=float))).as_matrix().reshape(-1, 3, 3)


def rotation_vectors_from_matrices(rotations, near=None) -> NDArray[np.float64]:
    """Rotation vectors ``(n, 3)`` radians (angle in [0, pi]) of rotations ``(n, 3, 3)``.

    With ``near`` (n, 3): of the writings ``r`` and ``r - 2 pi r / |r|`` (the same rotation, the second of
    angle ``|r| - 2 pi``), the one closest to ``near``. Near half a turn the two are nearly opposite
    vectors, and a small change of the rotation can swap which one is in [0, pi].
    """
    R = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    r = Rotation.from_matrix(R).as_rotvec()
    if near is None:
        return r
    near = np.asarray(near, dtype=float).reshape(-1, 3)
    angle = np.linalg.norm(r, axis=1, keepdims=True)
    twin = r - 2.0 * np.pi * np.divide(r, angle, out=np.zeros_like(r), where=angle > 0)
    swap = np.linalg.norm(twin - near, axis=1) < np.linalg.norm(r - near, axis=1)
    r[swap] = twin[swap]
    return r


def poses_from(positions, rotations) -> NDArray[np.float64]:
    """Homogeneous poses ``(n, 4, 4)`` from positions ``(n, 3)`` and rotations ``(n, 3, 3)``."""
    p = np.asarray(positions, dtype=float).reshape(-1, 3)
    out = np.zeros((len(p), 4, 4))
    out[:, :3, :3], out[:, :3, 3], out[:, 3, 3] = np.asarray(rotations, dtype=float).reshape(-1, 3, 3), p, 1.0
    return out


def inverse_poses(poses) -> NDArray[np.float64]:
    """The inverse of rigid poses ``(n, 4, 4)``: ``[R^T, -R^T p]``."""
    T = np.asarray(poses, dtype=float).reshape(-1, 4, 4)
    Rt = T[:, :3, :3].transpose(0, 2, 1)
    return poses_from(-np.einsum("nij,nj->ni", Rt, T[:, :3, 3]), Rt)
