"""Rigid frames from corresponding points: the best proper rotation and translation (Kabsch)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array


def kabsch(source, target) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The proper rotation ``R`` and translation ``t`` minimising ``sum |R @ s + t - p|^2``.

    Parameters
    ----------
    source, target : array-like, shape (n, 3)
        Corresponding points (n >= 3), e.g. mm.

    Returns
    -------
    R : ndarray, shape (3, 3)
        det(R) = +1 (a reflection is never returned).
    t : ndarray, shape (3,)

    Examples
    --------
    >>> s = np.array([[0., 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    >>> R, t = kabsch(s, s[:, [1, 0, 2]] * [-1, 1, 1] + 5)
    >>> (np.round(R, 12) + 0.0).tolist(), (np.round(t, 12) + 0.0).tolist()
    ([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [5.0, 5.0, 5.0])
    """
    s = check_array(source, "source", columns=3, min_rows=3)
    p = check_array(target, "target", columns=3, min_rows=3)
    s0, p0 = s.mean(axis=0), p.mean(axis=0)
    u, _, vt = np.linalg.svd((s - s0).T @ (p - p0))
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, p0 - rot @ s0
