"""Blend weights: a partition of unity over kernels that is continuous everywhere.

Each region owns one or more *kernels*: a centre ``c`` and per-axis widths
``sigma``, over the inputs that vary in the training data (constant inputs
are left out, see ``features.varying_inputs``). With ``r_k = |(x - c_k) / sigma_k|``
the raw weight of kernel ``k`` at ``x`` is

    g_k(x) = exp(-(r_k^2 - r_min^2) / 2) * S(r_k - s(x)),   s(x) = max(0, r_min(x) - RS),

where ``r_min`` is the distance to the nearest kernel and ``S`` the smooth
cutoff: 1 below ``R0 = 2``, 0 above ``R1 = 3``, a quintic smoothstep between
(continuous value, slope and curvature). Weights are normalised to sum to one.

* Where the nearest kernel is within ``RS = 2.5`` widths (everywhere in the
  sampled workspace) ``s = 0``; the common factor ``exp(r_min^2 / 2)`` cancels
  in the normalisation, so the weights are those of Gaussians cut off at
  ``r = 3``: every kernel vanishes beyond 3 widths, and a point needs only the
  few kernels that reach it.
* Farther out the cutoff moves outward with the nearest kernel: it keeps a
  weight of at least ``S(RS) = 1/2`` before normalisation, and only kernels
  within ``R1 - RS = 0.5`` widths of the nearest one carry weight. Nothing
  switches: ``r_min`` and ``s`` are continuous functions of ``x``, so the
  weights, and the blended prediction, are continuous everywhere, also far
  outside the data. The exponent is taken relative to the nearest kernel, so
  nothing underflows however far the point is.

Squared distances come in ``(K, m)`` arrays (kernels by points): reductions
over the kernels then run along contiguous rows. They are summed from
``(x - c) / sigma`` directly (:func:`sq_distances`), or, in the hot path,
expanded about the centre of a small lookup cell (:func:`cell_distance_matrix`
and :func:`cell_features`): there every term is below about 50, so rounding
stays below 1e-13 whatever the magnitude of the coordinates, unlike an
expansion about the origin, which cancels catastrophically.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

R0, R1 = 2.0, 3.0
RS = 2.5          # beyond this distance of the nearest kernel, the cutoff follows it outward


def cutoff(r: NDArray[np.float64], out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """1 below ``R0``, 0 above ``R1``, quintic smoothstep between (C2); ``out`` may be ``r`` itself.

    >>> cutoff(np.array([1.0, 2.5, 3.0])).tolist()
    [1.0, 0.5, 0.0]
    """
    t = np.subtract(R1, r, out=out)
    t /= R1 - R0
    np.clip(t, 0.0, 1.0, out=t)
    t2 = t * t
    poly = t2 * 6.0
    poly -= 15.0 * t
    poly += 10.0
    poly *= t2
    t *= poly
    return t


def sq_distances(X: NDArray[np.float64], centres: NDArray[np.float64], inv_sigmas: NDArray[np.float64]
                 ) -> NDArray[np.float64]:
    """``r^2 = sum(((x - c) / sigma)^2)``, summed directly, shape ``(K, m)``.

    Parameters
    ----------
    X : (m, d) points, on the kernels' axes only
    centres, inv_sigmas : (K, d) kernel centres and reciprocal widths
    """
    r2 = np.zeros((centres.shape[0], X.shape[0]))
    for i in range(X.shape[1]):
        t = np.subtract.outer(centres[:, i], X[:, i])
        t *= inv_sigmas[:, i, None]
        t *= t
        r2 += t
    return r2


def cell_distance_matrix(centres: NDArray[np.float64], inv_sigmas: NDArray[np.float64],
                         origin: NDArray[np.float64], half: NDArray[np.float64]) -> NDArray[np.float64]:
    """Matrix ``A`` (K, 2d + 1) with ``A @ cell_features(X, origin, half) = r^2`` (K, m).

    ``origin`` is the cell centre (d,), or one per kernel (K, d) to build the
    rows of several cells at once.

    With ``v = (x - o) / h`` and ``rho = h / sigma``, ``r^2 = sum(rho^2 (v - (c - o) / h)^2)``,
    expanded about the cell centre ``o``; ``h`` is the cell's half-size.
    """
    rho2 = (half * inv_sigmas) ** 2
    rel = (centres - origin) / half
    return np.hstack([rho2, -2.0 * rel * rho2, np.sum(rel * rel * rho2, axis=1, keepdims=True)])


def cell_features(X: NDArray[np.float64], origin: NDArray[np.float64], half: NDArray[np.float64]
                  ) -> NDArray[np.float64]:
    """``[v^2; v; 1]`` with ``v = (x - o) / h``, shape ``(2d + 1, m)`` (see :func:`cell_distance_matrix`)."""
    d = X.shape[1]
    out = np.empty((2 * d + 1, X.shape[0]))
    v = out[d:2 * d]
    np.subtract(X.T, origin[:, None], out=v)
    v /= half[:, None]
    np.multiply(v, v, out=out[:d])
    out[2 * d] = 1.0
    return out


def normalised_weights(r2: NDArray[np.float64]) -> NDArray[np.float64]:
    """Blend weights ``(K, m)`` from squared distances ``(K, m)``; overwrites ``r2``.

    Columns are non-negative and sum to one; the nearest kernel of every
    point always carries weight. ``K`` must list every kernel that may carry
    weight at these points (the nearest one included).

    >>> w = normalised_weights(np.array([[0.25], [0.25]]))      # midway between two equal kernels
    >>> w.ravel().tolist()
    [0.5, 0.5]
    """
    np.maximum(r2, 0.0, out=r2)             # expanded sums may round to -1e-16 at a kernel's centre
    r2min = r2.min(axis=0)
    if r2min.size and r2min.max() <= RS * RS:      # inside: no shift, exp(-r^2 / 2) cannot underflow
        w = np.multiply(r2, -0.5)
        np.exp(w, out=w)
        np.sqrt(r2, out=r2)
        w *= cutoff(r2, out=r2)
    else:
        shift = np.sqrt(r2min)
        shift -= RS
        np.maximum(shift, 0.0, out=shift)
        w = np.subtract(r2, r2min, out=np.empty_like(r2))
        w *= -0.5
        np.exp(w, out=w)
        np.sqrt(r2, out=r2)
        r2 -= shift
        w *= cutoff(r2, out=r2)
    w /= w.sum(axis=0)
    return w
