"""Error statistics: RMS per axis, 3-D RMS, maximum and percentiles of the error norm (mm); the pose of each
row (repeats grouped) and the scatter of repeats; the standard error of a pooled RMS; distances from the data
and extrapolation warnings. Folds, held-out residuals and the choice of a run's model are in
:mod:`partcal.study.selection`, the layer that fits estimators."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def rms_per_axis(errors_mm: NDArray[np.float64]) -> NDArray[np.float64]:
    """Root mean square of each column, shape (3,).

    >>> rms_per_axis(np.array([[3.0, 0, 1], [-3.0, 0, 1]])).tolist()
    [3.0, 0.0, 1.0]
    """
    return np.sqrt(np.mean(np.square(errors_mm), axis=0))


def summary(errors_mm: NDArray[np.float64]) -> dict:
    """``{"rms": [x, y, z], "rms_3d", "max_3d", "p95_3d"}`` of an ``(n, 3)`` error array, in mm.

    >>> summary(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]]))["rms_3d"]
    3.5355339059327378
    """
    norms = np.linalg.norm(errors_mm, axis=1)
    return {
        "rms": rms_per_axis(errors_mm).tolist(),
        "rms_3d": float(np.sqrt(np.mean(np.square(norms)))),
        "max_3d": float(norms.max()),
        "p95_3d": float(np.percentile(norms, 95)),
    }


MRAD_PER_RAD = 1000.0
MRAD_PER_DEG = MRAD_PER_RAD * np.pi / 180.0
POSITION, ORIENTATION = slice(0, 3), slice(3, 6)   # the columns of a pose error: mm, then a rotation vector, mrad


def orientation_summary(errors_mrad: NDArray[np.float64]) -> dict:
    """``{"rms": [x, y, z], "rms_angle", "max_angle", "p95_angle"}`` of ``(n, 3)`` orientation errors (rotation
    vectors, base frame), in mrad: :func:`summary` read as angles (the norm of a rotation vector is its angle)."""
    s = summary(errors_mrad)
    return {"rms": s["rms"], "rms_angle": s["rms_3d"], "max_angle": s["max_3d"], "p95_angle": s["p95_3d"]}


HELD_TOLERANCE_DEG = 0.01
"""Joint angles this close (degrees) are the same: a repeated pose, or a joint held still whose encoder reads
back a little noise (a few thousandths of a degree). Distinct poses of a calibration differ by far more."""


def pose_groups(q_deg: NDArray[np.float64], tolerance_deg: float = HELD_TOLERANCE_DEG) -> NDArray[np.intp]:
    """Group label of each row: rows whose joint angles all agree to ``tolerance_deg`` are one pose.

    Two rows are one pose when every column differs by at most
    ``tolerance_deg`` (default :data:`HELD_TOLERANCE_DEG`); a pose is every
    row linked to another this way (single linkage). Labels count from 0 in
    the order poses first appear, so a file without repeats gets ``0, 1, 2, ...``.

    >>> pose_groups(np.array([[0.0, 1.0], [5.0, 0.0], [0.0, 1.0]])).tolist()
    [0, 1, 0]
    >>> pose_groups(np.array([[0.0, 1.0], [5.0, 0.0], [0.002, 0.999]])).tolist()     # read back with jitter
    [0, 1, 0]
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    q = np.asarray(q_deg, dtype=float).reshape(len(q_deg), -1)
    pairs = cKDTree(q).query_pairs(r=tolerance_deg, p=np.inf, output_type="ndarray") if len(q) > 1 else \
        np.zeros((0, 2), dtype=np.intp)
    link = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(q), len(q)))
    labels = connected_components(link, directed=False)[1]
    return _first_appearance(np.unique(labels, return_index=True, return_inverse=True))


def held_joints(q_deg: NDArray[np.float64], tolerance_deg: float = HELD_TOLERANCE_DEG) -> NDArray[np.bool_]:
    """Which joints never move (their readings span at most ``tolerance_deg``), shape (N,).

    >>> held_joints(np.array([[10.0, 0.0], [20.0, 0.003], [30.0, -0.002]])).tolist()
    [False, True]
    """
    q = np.asarray(q_deg, dtype=float)
    return np.ptp(q, axis=0) <= tolerance_deg


def labels_as_groups(labels) -> NDArray[np.intp]:
    """Group numbers (from 0, in order of first appearance) of any labels, a user's group column say.

    >>> labels_as_groups(["b", "a", "b"]).tolist()
    [0, 1, 0]
    """
    return _first_appearance(np.unique(np.asarray(labels), return_index=True, return_inverse=True))


def _first_appearance(unique) -> NDArray[np.intp]:
    _, first, inverse = unique
    rank = np.empty(len(first), dtype=np.intp)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[np.ravel(inverse)]


def repeat_scatter_mm(errors_mm: NDArray[np.float64], groups: NDArray[np.intp]) -> float | None:
    """Standard deviation of one coordinate between repeated measurements of a pose, mm; None without repeats.

    Pooled over the poses measured more than once: ``sqrt(sum |e - mean of its pose|^2 / (3 (n - G)))``
    over their ``n`` rows in ``G`` poses.

    >>> repeat_scatter_mm(np.array([[1.0, 0, 0], [-1.0, 0, 0], [5.0, 5, 5]]), np.array([0, 0, 1]))
    0.816496580927726
    """
    groups = np.asarray(groups, dtype=np.intp)
    counts = np.bincount(groups)
    repeated = counts[groups] > 1
    if not repeated.any():
        return None
    e, g = np.asarray(errors_mm, dtype=float)[repeated], groups[repeated]
    means = np.stack([np.bincount(g, weights=e[:, j], minlength=len(counts)) for j in range(e.shape[1])], axis=1)
    spread = e - means[g] / counts[g][:, None]
    dof = e.shape[1] * (len(e) - len(np.unique(g)))
    return float(np.sqrt(np.sum(spread**2) / dof))


def pooled_rms(resid: NDArray[np.float64]) -> float:
    """3-D RMS of residuals ``(n, m)``: ``sqrt(mean(|e|^2))`` over the rows."""
    return float(np.sqrt(np.mean(np.sum(resid.reshape(len(resid), -1) ** 2, axis=1))))


def rms_standard_error(resid: NDArray[np.float64], groups: NDArray[np.intp]) -> float:
    """Standard error of :func:`pooled_rms` of held-out residuals, from its spread over the groups (poses).

    The mean square is a ratio of sums over ``G`` groups (``s_g``: the group's
    sum of ``|e|^2``, ``n_g`` its rows); its standard error is that of a ratio
    estimator, ``sqrt(sum((s_g - MSE n_g)^2) / (G (G - 1))) / mean(n_g)``, and
    the RMS's follows by the delta method, divided by ``2 RMS``.

    >>> e = np.array([[1.0, 0, 0], [3.0, 0, 0]])
    >>> round(rms_standard_error(e, np.array([0, 1])), 4)     # MSE 5 +- 4, RMS 2.236 +- 4 / (2 * 2.236)
    0.8944
    """
    sq = np.sum(resid.reshape(len(resid), -1) ** 2, axis=1)
    groups = np.asarray(groups, dtype=np.intp)
    s, n = np.bincount(groups, weights=sq), np.bincount(groups).astype(float)
    if len(s) < 2:
        return float("nan")
    mse = s.sum() / n.sum()
    se_mse = np.sqrt(np.sum((s - mse * n) ** 2) / (len(s) * (len(s) - 1))) / n.mean()
    return float(se_mse / (2.0 * np.sqrt(mse))) if mse > 0 else 0.0


def within_one_standard_error(scores, errors) -> list[int]:
    """The indices whose CV score is within one standard error of the lowest one (its own standard error; a NaN
    one counts as 0, a NaN score is never within): the candidates the one-standard-error rule chooses among,
    the simplest of them (Hastie, Tibshirani and Friedman, *The Elements of Statistical Learning*, 7.10).

    >>> within_one_standard_error([0.30, 0.28, 0.50, float("nan")], [0.02, 0.03, 0.01, 0.0])
    [0, 1]
    """
    finite = [i for i in range(len(scores)) if np.isfinite(scores[i])]
    if not finite:
        return []
    best = min(finite, key=lambda i: (scores[i], i))
    se = errors[best] if np.isfinite(errors[best]) else 0.0
    return [i for i in finite if scores[i] <= scores[best] + se]


class ExtrapolationWarning(UserWarning):
    """Predictions were requested far from the data a model was fitted on."""


def distance_outside_boxes(X: NDArray[np.float64], low: NDArray[np.float64], high: NDArray[np.float64],
                           chunk: int = 20_000) -> NDArray[np.float64]:
    """Distance from each point to the nearest of ``R`` axis-aligned boxes (0 inside one), shape (n,).

    ``low`` and ``high`` have shape ``(R, d)``.

    >>> distance_outside_boxes(np.array([[3.0, 0.0]]), np.array([[0.0, 0.0]]), np.array([[1.0, 1.0]])).tolist()
    [2.0]
    """
    out = np.empty(X.shape[0])
    for start in range(0, X.shape[0], chunk):
        x = X[start:start + chunk, None, :]
        gap = np.maximum(0.0, np.maximum(low[None] - x, x - high[None]))
        out[start:start + chunk] = np.sqrt(np.einsum("nrd,nrd->nr", gap, gap)).min(axis=1)
    return out


def warn_far(distances: NDArray[np.float64], limit: float, stacklevel: int = 3) -> NDArray[np.bool_]:
    """Issue one :class:`ExtrapolationWarning` for points farther than ``limit``; return the mask."""
    import warnings

    far = distances > limit
    if far.any():
        warnings.warn(f"{int(far.sum())} of {len(far)} points lie more than {limit:g} input units from the "
                      f"nearest training sample (up to {distances.max():.4g}); no data there support their "
                      "predicted errors", ExtrapolationWarning, stacklevel=stacklevel)
    return far


ROBUST_LOSSES = ("linear", "huber", "soft_l1", "cauchy")
"""The losses of robust registration and identification: scipy ``least_squares``' (``linear``: least squares)."""


def loss_weights(scaled: NDArray[np.float64], loss: str) -> NDArray[np.float64]:
    """The weight ``rho'(z**2)`` a loss gives residuals ``z`` (in units of its ``f_scale``): what iteratively
    reweighted least squares multiplies their squares by.

    Examples
    --------
    >>> loss_weights(np.array([0.5, 2.0]), "huber").tolist(), loss_weights(np.array([3.0]), "cauchy").tolist()
    ([1.0, 0.5], [0.1])
    """
    z2 = np.asarray(scaled, dtype=float) ** 2
    if loss == "huber":
        return np.where(z2 <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z2, 1.0)))
    if loss == "soft_l1":
        return 1.0 / np.sqrt(1.0 + z2)
    if loss == "cauchy":
        return 1.0 / (1.0 + z2)
    return np.ones_like(z2)
