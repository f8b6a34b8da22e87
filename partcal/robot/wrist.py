"""Joints that turn about one line share one turn: the straight wrist, and the split nearest a reference.

With axis 5 at 0 (a tool pointing straight down, common in real programs) a spherical wrist's axes 4 and 6
lie on one line. The pose then fixes only their shared turn (``q4 + q6`` on the SK120 and most arms); any
split of it, ``q4 + s`` and ``q6 - s``, is the same pose. An IK solver leaves the split wherever its steps
happen to put it, so a configuration written with the target (KUKA ``T``, ABB ``cf4 cf6``) may be met or
not by chance. :func:`nearest_split` moves the split along that self-motion to the one nearest a
reference (the written configuration, the seed, the joints before), inside the joint limits and optional
bounds, without changing the pose.

Two joints share a turn where their columns of the pose Jacobian are parallel: the same axis line (the
angular parts parallel, the tool point's velocities then equal), ``J_j = c J_k``; moving ``q_j`` by ``s``
and ``q_k`` by ``-c s`` leaves the pose as it was.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .ik import pose_jacobian
from .kinematics import pose_errors

SHARED_TOL = 2e-4
"""How parallel two joints' Jacobian columns must be to share one turn: the part of one column not along the
other, relative to its length (position rows divided by the robot's reach). On the SK120 it is the sine of
axis 5's angle: 2e-4 takes axis 5 within about 0.01 degrees of 0. A program writes a straight-down tool to its
printed precision (KUKA's A B C to 1e-4 degrees, an ABB quaternion of 4 decimals to 0.006 degrees), so the wrist
of such a target is straight to that and no nearer; a configuration written for it names the shared turn, not
a split. A split moved along the self-motion is checked on the pose itself (:func:`nearest_split`)."""


def shared_turns(robot, q_deg: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """For each joint solution, the first pair of joints that share one turn, if any.

    Parameters
    ----------
    robot : Robot
    q_deg : ndarray, shape (n, N)
        Joint angles, degrees.

    Returns
    -------
    j, k : ndarray of int, shape (n,)
        0-based joints ``j < k`` turning about one line (-1 where none do).
    c : ndarray, shape (n,)
        ``J_j = c J_k``: moving ``q_j`` by ``s`` and ``q_k`` by ``-c s`` keeps the pose (0 where none).
    """
    q = np.asarray(q_deg, dtype=float)
    n, N = q.shape
    j_out, k_out, c_out = np.full(n, -1), np.full(n, -1), np.zeros(n)
    if n == 0:
        return j_out, k_out, c_out
    free = np.arange(N)
    p, _, frames = robot.walk(robot.rotors(q.T), record=robot.moving_rows(free))
    J = pose_jacobian(robot, p, frames, free, robot.reach_mm).transpose(2, 0, 1) / robot.reach_mm   # (n, N, 6)
    turns = np.linalg.norm(J[:, :, 3:], axis=2) > 0                    # a slide shares no turn
    for j in range(N):
        for k in range(j + 1, N):
            a, b = J[:, j], J[:, k]
            bb = np.einsum("ni,ni->n", b, b)
            c = np.einsum("ni,ni->n", a, b) / np.maximum(bb, 1e-300)
            off = np.linalg.norm(a - c[:, None] * b, axis=1) / np.maximum(np.linalg.norm(a, axis=1), 1e-300)
            hit = (j_out < 0) & turns[:, j] & turns[:, k] & (off <= SHARED_TOL) & (np.abs(c) > 0.1)
            j_out[hit], k_out[hit], c_out[hit] = j, k, c[hit]
    return j_out, k_out, c_out


def nearest_split(robot, q_deg: NDArray[np.float64], reference_deg: NDArray[np.float64], low=None, high=None, *,
                  tol_mm: float = 1e-6, tol_deg: float = 1e-6) -> NDArray[np.float64]:
    """Joint solutions with the turn two joints share split as near the reference as the pose allows.

    Parameters
    ----------
    robot : Robot
    q_deg : ndarray, shape (n, N)
        Joint solutions, degrees.
    reference_deg : ndarray, shape (n, N) or (N,)
        The joints to be near (a seed, the joints before, the middle of a written configuration).
    low, high : ndarray, shape (n, N), optional
        Bounds each joint should stay within as well as its limits (a written configuration's range; -inf and
        inf where free). Where they leave no split, the limits alone bound it.
    tol_mm, tol_deg : float
        A row is moved only where its pose stays within these of the pose it had (the self-motion is exact on
        a straight wrist, first-order near one).

    Returns
    -------
    ndarray, shape (n, N)
        ``q_deg`` with the shared turn of each row that has one moved to the split nearest the reference
        (the least squares distance over the two joints), rows without one unchanged.

    Examples
    --------
    The SK120 with its wrist straight (axis 5 at 0): axes 4 and 6 share ``q4 + q6 = -5.8``. Nearest axes 4
    and 6 at 10 and -10 degrees, the turn splits 7.1 and -12.9; with axis 4 kept at 0 or above and near 0,
    all of it goes to axis 6. The pose is the same.

    >>> from partcal.robot import load_robot
    >>> sk120 = load_robot("motoman_sk120")
    >>> q = np.array([[35.0, -118.0, -152.0, -2.9, 0.0, -2.9]])
    >>> nearest_split(sk120, q, [0, -120, -150, 10, 0, -10]).round(9).tolist()
    [[35.0, -118.0, -152.0, 7.1, 0.0, -12.9]]
    >>> low = np.array([[-np.inf, -np.inf, -np.inf, 0.0, -np.inf, -np.inf]])
    >>> nearest_split(sk120, q, [0, -120, -150, -3, 0, 0], low, np.full((1, 6), np.inf)).round(9).tolist()
    [[35.0, -118.0, -152.0, 0.0, 0.0, -5.8]]
    """
    q = np.array(q_deg, dtype=float)
    ref = np.broadcast_to(np.asarray(reference_deg, dtype=float), q.shape)
    j, k, c = shared_turns(robot, q)
    rows = np.flatnonzero(j >= 0)
    if rows.size == 0:
        return q
    jj, kk, cc = j[rows], k[rows], c[rows]
    qj, qk = q[rows, jj], q[rows, kk]
    s = ((ref[rows, jj] - qj) - cc * (ref[rows, kk] - qk)) / (1.0 + cc * cc)      # the least squares split
    limits = robot.limits_deg
    bounds = [(limits[jj, 0], limits[jj, 1], limits[kk, 0], limits[kk, 1])]
    if low is not None and high is not None:
        lo, hi = np.asarray(low, dtype=float)[rows], np.asarray(high, dtype=float)[rows]
        pick = np.arange(rows.size)
        bounds.insert(0, (np.maximum(limits[jj, 0], lo[pick, jj]), np.minimum(limits[jj, 1], hi[pick, jj]),
                          np.maximum(limits[kk, 0], lo[pick, kk]), np.minimum(limits[kk, 1], hi[pick, kk])))
    chosen = np.full(rows.size, np.nan)
    for lj, hj, lk, hk in bounds:                     # the written bounds first, else the limits alone
        s_lo, s_hi = _interval(qj, lj, hj, qk, lk, hk, cc)
        fits = np.isnan(chosen) & (s_lo <= s_hi)
        chosen[fits] = np.clip(s, s_lo, s_hi)[fits]
    ok = ~np.isnan(chosen)
    moved = q[rows].copy()
    moved[ok, jj[ok]] += chosen[ok]
    moved[ok, kk[ok]] -= cc[ok] * chosen[ok]
    dp, turn = pose_errors(robot.forward(moved), robot.forward(q[rows]))
    same = ok & (dp <= tol_mm) & (turn <= tol_deg)
    q[rows[same]] = moved[same]
    return q


def _interval(qj, lj, hj, qk, lk, hk, c) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The shifts ``s`` keeping ``qj + s`` in ``[lj, hj]`` and ``qk - c s`` in ``[lk, hk]`` (empty: lo > hi)."""
    a, b = (qk - hk) / c, (qk - lk) / c            # qk - c s in [lk, hk]: s between these (order by c's sign)
    return np.maximum(lj - qj, np.minimum(a, b)), np.minimum(hj - qj, np.maximum(a, b))
