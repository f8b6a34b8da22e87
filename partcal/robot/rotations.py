"""Changes of representation of rotations and poses, named from -> to: the one home of partcal's rotation
conventions, each named for the format or vendor that writes it.

- URDF's ``rpy`` (roll, pitch, yaw) in degrees: ``R = Rz(yaw) Ry(pitch) Rx(roll)``, turns about the fixed
  x, then y, then z axes. partcal's robot YAML (``origin``, ``base``), the virtual robot's base
  (``errors.base.rotation_deg``) and the kinematic model's base correction write rotations so.
- The measurement CSV's orientation columns (``rx_meas, ry_meas, rz_meas``; a Leica T-Mac's export):
  intrinsic X-Y-Z angles in degrees, ``R = Rx(rx) Ry(ry) Rz(rz)``.
- KUKA ``A, B, C``: Z-Y-X Euler angles in degrees, ``R = Rz(A) Ry(B) Rx(C)`` (turns about the moving z,
  then the new y, then the newest x; the same as turns about the fixed x, y, then z axes): URDF's ``rpy``
  written backwards.
- ABB quaternions ``[q1, q2, q3, q4]``: scalar first, ``q1 = cos(angle / 2)``.
- Universal Robots' rotation vectors ``[rx, ry, rz]``: axis times angle, radians (and the rotation vectors
  of pose errors and residuals).
- Any other Euler order, as scipy names it (:func:`matrices_from_euler_deg`), for telling a file's
  convention from its numbers.

Each ``*_from_matrices`` function takes an optional ``near``: the representation the rotation had before
(one per row). A rotation has several writings (``q`` and ``-q``; a rotation vector of angle near pi and
its twin on the other side; ``A = 180`` and ``A = -180``): ``near`` picks the one closest to the old
writing, so that a small change of the rotation is a small change of the numbers in a program.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation


def matrices_from_rpy_deg(rpy_deg) -> NDArray[np.float64]:
    """Rotations ``Rz(yaw) Ry(pitch) Rx(roll)`` ``(n, 3, 3)`` from URDF angles ``(n, 3)`` degrees ``roll, pitch, yaw``.

    Turns about the fixed x, then y, then z axes (a URDF origin's ``rpy``).

    >>> (matrices_from_rpy_deg([[0.0, 0.0, 90.0]])[0] @ [1.0, 0.0, 0.0]).round(12) + 0.0
    array([0., 1., 0.])
    """
    rad = np.radians(np.asarray(rpy_deg, dtype=float).reshape(-1, 3))
    c, s = np.cos(rad), np.sin(rad)
    turns = np.zeros((3, len(rad), 3, 3))            # Rx, Ry, Rz of every row
    for k, (i, j) in enumerate(((1, 2), (2, 0), (0, 1))):
        turns[k, :, k, k] = 1.0
        turns[k, :, i, i] = turns[k, :, j, j] = c[:, k]
        turns[k, :, i, j], turns[k, :, j, i] = -s[:, k], s[:, k]
    return turns[2] @ turns[1] @ turns[0]


def matrix_from_rpy_deg(rpy_deg) -> NDArray[np.float64]:
    """The rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` ``(3, 3)`` from one URDF ``rpy`` ``(3,)`` degrees: the one
    row of :func:`matrices_from_rpy_deg`.

    >>> (matrix_from_rpy_deg([0.0, 0.0, 90.0]) @ [1.0, 0.0, 0.0]).round(12) + 0.0
    array([0., 1., 0.])
    """
    return matrices_from_rpy_deg(rpy_deg)[0]


def rpy_deg_from_matrix(rotation) -> NDArray[np.float64]:
    """URDF roll, pitch, yaw ``(3,)`` degrees of a rotation ``(3, 3)``: the inverse of :func:`matrix_from_rpy_deg`,
    pitch in [-90, 90].

    Accurate near a pitch of +-90 degrees too: the yaw is taken first, then pitch and roll from what is
    left after turning it back, ``Rz(-yaw) R = Ry(pitch) Rx(roll)``, whose entries are all of order one.

    >>> rpy_deg_from_matrix(matrix_from_rpy_deg([10.0, -20.0, 30.0])).round(12).tolist()
    [10.0, -20.0, 30.0]
    """
    rot = np.asarray(rotation, dtype=float)
    yaw = np.arctan2(rot[1, 0], rot[0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    left = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ rot
    pitch = np.arctan2(-left[2, 0], left[0, 0])
    roll = np.arctan2(-left[1, 2], left[1, 1])
    return np.degrees([roll, pitch, yaw])


def matrices_from_xyz_deg(angles_deg) -> NDArray[np.float64]:
    """Rotations ``Rx(rx) Ry(ry) Rz(rz)`` from intrinsic XYZ angles ``(n, 3)`` degrees, shape ``(n, 3, 3)``.

    Turns about the moving x, then the new y, then the newest z axis (the
    same rotation as turns about the fixed z, y, then x axes). The convention
    of the measured orientation columns ``rx_meas, ry_meas, rz_meas`` and of a
    Leica T-Mac's export; :func:`matrices_from_rpy_deg` is the other order.

    >>> (matrices_from_xyz_deg([[90.0, 0.0, 90.0]])[0] @ [1.0, 0.0, 0.0]).round(12) + 0.0   # x: to y, then to z
    array([0., 0., 1.])
    """
    rad = np.radians(np.atleast_2d(np.asarray(angles_deg, dtype=float)))
    cx, cy, cz = np.cos(rad).T
    sx, sy, sz = np.sin(rad).T
    out = np.empty((rad.shape[0], 3, 3))
    out[:, 0] = np.stack([cy * cz, -cy * sz, sy], axis=1)
    out[:, 1] = np.stack([cx * sz + sx * sy * cz, cx * cz - sx * sy * sz, -sx * cy], axis=1)
    out[:, 2] = np.stack([sx * sz - cx * sy * cz, sx * cz + cx * sy * sz, cx * cy], axis=1)
    return out


def xyz_deg_from_matrices(rotations) -> NDArray[np.float64]:
    """Intrinsic XYZ angles ``(n, 3)`` degrees of rotations ``(n, 3, 3)``: the inverse of
    :func:`matrices_from_xyz_deg`, with ``rx, rz`` in [-180, 180] and ``ry`` in [-90, 90].

    >>> xyz_deg_from_matrices(matrices_from_xyz_deg([[10.0, -20.0, 30.0]])).round(12).tolist()
    [[10.0, -20.0, 30.0]]
    """
    rot = np.asarray(rotations, dtype=float).reshape(-1, 3, 3)
    ry = np.arcsin(np.clip(rot[:, 0, 2], -1.0, 1.0))
    rx = np.arctan2(-rot[:, 1, 2], rot[:, 2, 2])
    rz = np.arctan2(-rot[:, 0, 1], rot[:, 0, 0])
    return np.degrees(np.stack([rx, ry, rz], axis=1))


def matrices_from_euler_deg(order: str, angles_deg) -> NDArray[np.float64]:
    """Rotations ``(n, 3, 3)`` from Euler angles ``(n, 3)`` degrees in scipy's ``order`` (``"XYZ"`` upper case:
    intrinsic, turns about the moving axes; ``"xyz"`` lower case: extrinsic, about the fixed axes)."""
    return Rotation.from_euler(order, np.atleast_2d(np.asarray(angles_deg, dtype=float)),
                               degrees=True).as_matrix().reshape(-1, 3, 3)


def matrices_from_kuka_abc(abc_deg) -> NDArray[np.float64]:
    """Rotations ``Rz(A) Ry(B) Rx(C)`` ``(n, 3, 3)`` from KUKA angles ``(n, 3)`` degrees ``A, B, C``: URDF's
    ``rpy`` backwards (:func:`matrices_from_rpy_deg` of ``C, B, A``).

    >>> (matrices_from_kuka_abc([[90.0, 0.0, 0.0]])[0] @ [1.0, 0.0, 0.0]).round(12) + 0.0   # A turns about z
    array([0., 1., 0.])
    """
    return matrices_from_rpy_deg(np.asarray(abc_deg, dtype=float).reshape(-1, 3)[:, ::-1])


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


def matrix_from_rotation_vector(rotvec_rad) -> NDArray[np.float64]:
    """The rotation ``(3, 3)`` of one rotation vector ``(3,)`` (axis times angle, radians)."""
    return matrices_from_rotation_vectors(rotvec_rad)[0]


def rotation_vector_from_matrix(rotation) -> NDArray[np.float64]:
    """The rotation vector ``(3,)`` radians (angle in [0, pi]) of one rotation ``(3, 3)``."""
    return rotation_vectors_from_matrices(rotation)[0]


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


# ---------------------------------------------------------------------- small turns: derivatives of rotation vectors
def skew_matrices(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``[v]_x`` of each row of ``v`` (n, 3): ``[v]_x w = v x w``, shape (n, 3, 3).

    >>> skew_matrices(np.array([[1.0, 2.0, 3.0]]))[0] @ [0.0, 0.0, 1.0]
    array([ 2., -1.,  0.])
    """
    out = np.zeros((len(v), 3, 3))
    out[:, 0, 1], out[:, 0, 2], out[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    return out - out.transpose(0, 2, 1)


def left_jacobian(phi: NDArray[np.float64]) -> NDArray[np.float64]:
    """SO(3)'s left Jacobian at the rotation vector ``phi`` (3,) radians: ``exp(phi + d) = exp(J d) exp(phi)``."""
    t = float(np.linalg.norm(phi))
    k = skew_matrices(phi[None])[0]
    if t < 1e-8:
        return np.eye(3) + 0.5 * k
    return np.eye(3) + (1 - np.cos(t)) / t**2 * k + (t - np.sin(t)) / t**3 * k @ k


def log_derivative(turns: NDArray[np.float64]) -> NDArray[np.float64]:
    """How ``log(exp(w) exp(phi))`` moves with a small turn ``w`` at rotation vectors ``phi`` (n, 3): the
    inverse left Jacobian of SO(3), ``I - [phi]/2 + c [phi]^2`` with ``c = 1/t^2 - (1 + cos t)/(2 t sin t)``,
    ``t = |phi|`` (``c -> 1/12`` as ``t -> 0``), shape (n, 3, 3)."""
    t = np.linalg.norm(turns, axis=1)
    small = t < 1e-6
    safe = np.where(small, 1.0, t)
    c = np.where(small, 1.0 / 12.0, 1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)))
    skew = skew_matrices(turns)
    return np.eye(3) - 0.5 * skew + c[:, None, None] * skew @ skew
