"""Blend weights: a smooth partition of unity over regions, or hard assignment.

Each region owns one or more *kernels*: a centre ``c`` and per-axis widths
``sigma``. A kernel's raw weight at ``x`` is a Gaussian cut off smoothly,

    g(r) = exp(-r^2 / 2) * S(r),   r = |(x - c) / sigma|,

with ``S = 1`` for ``r <= R0 = 2``, falling to ``0`` at ``r = R1 = 3`` along a
quintic smoothstep (continuous value, slope and curvature). Weights are
normalised to sum to one, as in local model networks. Because every kernel
vanishes beyond ``R1``, a point needs only the kernels whose support reaches
it; the partitions supply those candidate lists, so prediction costs the same
for 8 regions as for 512, and the blend is the same function as if all
kernels were summed: exactly continuous wherever some kernel reaches.

Far outside every kernel's support (beyond 3 widths of the sampled
workspace) no kernel reaches; there the point is given wholly to its own
region (hard assignment), and the extrapolation flags of the model say so.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

R0, R1 = 2.0, 3.0


def cutoff(r: NDArray[np.float64]) -> NDArray[np.float64]:
    """1 below ``R0``, 0 above ``R1``, quintic smoothstep between (C2)."""
    t = np.clip((R1 - r) / (R1 - R0), 0.0, 1.0)
    return t * t * t * (t * (6.0 * t - 15.0) + 10.0)


def block_weights(X: NDArray[np.float64], centres: NDArray[np.float64], sigmas: NDArray[np.float64],
                  own: NDArray[np.intp] | int, blend: str) -> NDArray[np.float64]:
    """Normalised weights of ``K`` kernels at ``m`` points, shape ``(m, K)``.

    Parameters
    ----------
    X : (m, d) points of one block
    centres, sigmas : (K, d) the block's candidate kernels
    own : column of the points' own kernel (int, or one per point)
    blend : "gaussian" or "hard"

    >>> w = block_weights(np.array([[0.5]]), np.array([[0.0], [1.0]]), np.array([[0.7], [0.7]]), 0, "gaussian")
    >>> w.round(6).tolist()          # midway between two equal kernels
    [[0.5, 0.5]]
    """
    m, k = X.shape[0], centres.shape[0]
    own_col = np.broadcast_to(own, (m,))
    if blend == "hard":
        w = np.zeros((m, k))
        w[np.arange(m), own_col] = 1.0
        return w
    inv2 = 1.0 / (sigmas * sigmas)                     # r^2 = sum (x - c)^2 / s^2, expanded into matmuls
    r2 = (X * X) @ inv2.T - 2.0 * X @ (centres * inv2).T + np.sum(centres * centres * inv2, axis=1)
    raw = np.zeros((m, k))
    near = r2 < R1 * R1
    r2n = r2[near]
    raw[near] = np.exp(-0.5 * r2n) * cutoff(np.sqrt(r2n))
    total = raw.sum(axis=1, keepdims=True)
    out = np.divide(raw, total, out=np.zeros_like(raw), where=total > 0)
    empty = total[:, 0] <= 0
    if empty.any():      # no kernel reaches: the point belongs wholly to its own region
        out[np.flatnonzero(empty), own_col[empty]] = 1.0
    return out
