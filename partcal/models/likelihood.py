"""The hyperparameter search of partcal's Gaussian processes: log marginal likelihood, its analytic
gradient, and L-BFGS-B from seeded starts.

The kernel is ``amplitude * shape(r) + noise * I`` with ``r`` the distance of
inputs divided by one length scale each, and ``shape`` the RBF ``exp(-r^2 / 2)``
or a Matern of smoothness 1.5 or 2.5. Its hyperparameters are searched in
logarithms, as scikit-learn does, within the same bounds and from the same
seeded starts, so the optimum found is scikit-learn's (given the same
stopping rule, :data:`SEARCH_FTOL`); what differs is the cost of one step. The x, y and z outputs share one Cholesky factor, and the
gradient needs the inverse of the kernel matrix (from that factor, LAPACK's
``potri``) and, per length scale, two products with an ``n x n`` matrix:
never the ``n x n x hyperparameters`` array of kernel derivatives.
scikit-learn's own search stays the reference (``tests/test_gp.py``) and
serves the kernels this module does not (Matern 0.5).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack
from scipy.optimize import minimize

JITTER = 1e-10                 # scikit-learn's default ``alpha``: added to the diagonal of every kernel matrix
# L-BFGS-B stops when a step gains less than this fraction of the likelihood (scipy's default: 2.2e-9).
# Likelihoods of a few thousand nats: steps below 0.01 nat change nothing a GP predicts (UR10, 800
# poses: 43 steps instead of 57, held-out RMS 0.55280 mm against 0.55264).
SEARCH_FTOL = 1e-6
COVER_SCALES = (10.0, 0.1)     # length scales (inputs scaled to [-1, 1]) of the two starts every search adds
NUS = (1.5, 2.5)               # the Matern smoothnesses with a closed-form gradient here (and the RBF: None)


def shape_and_slope(r2: NDArray[np.float64], nu: float | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The kernel shape ``k(r)`` at squared scaled distances ``r2``, and ``-k'(r) / r`` (finite at 0).

    ``d k / d log(l_j) = (-k'(r) / r) * (x_j - x'_j)^2 / l_j^2``: the second array times one squared
    scaled difference is a length scale's derivative.

    >>> k, g = shape_and_slope(np.array([0.0, 1.0]), None)      # RBF: k = exp(-r^2/2), -k'/r = k
    >>> np.allclose(k, np.exp([0.0, -0.5])) and np.allclose(g, k)
    True
    """
    if nu is None:
        k = np.exp(-0.5 * r2)
        return k, k
    r = np.sqrt(r2)
    if nu == 1.5:
        s = math.sqrt(3.0) * r
        e = np.exp(-s)
        return (1.0 + s) * e, 3.0 * e
    s = math.sqrt(5.0) * r
    e = np.exp(-s)
    return (1.0 + s + s * s / 3.0) * e, (5.0 / 3.0) * (1.0 + s) * e


def log_marginal_likelihood(theta: NDArray[np.float64], X: NDArray[np.float64], Y: NDArray[np.float64],
                            nu: float | None) -> tuple[float, NDArray[np.float64]]:
    """Log marginal likelihood of outputs ``Y`` (n, m) (normalised) at inputs ``X`` (n, d), and its gradient.

    ``theta`` = log of ``(amplitude, length scale 1..d, noise)``. The outputs are
    independent GPs sharing the kernel, so the likelihood is their sum. Returns
    ``(-inf, 0)`` where the kernel matrix is not positive definite.
    """
    amp, scales, noise = np.exp(theta[0]), np.exp(theta[1:-1]), np.exp(theta[-1])
    U = X / scales
    sq = np.einsum("ij,ij->i", U, U)
    r2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * (U @ U.T), 0.0)
    shape, slope = shape_and_slope(r2, nu)
    K = amp * shape
    K[np.diag_indices_from(K)] += noise + JITTER
    L, info = lapack.dpotrf(K.T, lower=1, clean=1, overwrite_a=1)      # K.T: K in LAPACK's column order
    if info != 0:
        return -np.inf, np.zeros_like(theta)
    alpha, _ = lapack.dpotrs(L, Y, lower=1)
    n, m = Y.shape
    lml = -0.5 * float(np.einsum("ij,ij->", Y, alpha)) - m * float(np.log(np.diag(L)).sum()) \
        - 0.5 * n * m * math.log(2.0 * math.pi)
    inv, _ = lapack.dpotri(L, lower=1)
    inv = np.tril(inv) + np.tril(inv, -1).T
    W = alpha @ alpha.T - m * inv                 # d lml / d theta_k = tr(W dK/dtheta_k) / 2
    grad = np.empty_like(theta)
    grad[0] = 0.5 * amp * float(np.einsum("ij,ij->", W, shape))
    M = amp * W * slope
    row = M.sum(axis=1)
    grad[1:-1] = (U * U).T @ row - np.einsum("ij,ij->j", U, M @ U)     # sum_ab M_ab (u_a - u_b)^2 / 2, per input
    grad[-1] = 0.5 * noise * float(np.trace(W))
    return lml, grad


def search(X: NDArray[np.float64], Y: NDArray[np.float64], *, nu: float | None, start: NDArray[np.float64],
           bounds: NDArray[np.float64], restarts: int, seed: int) -> tuple[NDArray[np.float64], float]:
    """The hyperparameters (log, as ``theta``) of highest likelihood, and that likelihood.

    L-BFGS-B from ``start`` and from ``restarts`` starts drawn uniformly within
    ``bounds`` (log, shape (p, 2)) by ``RandomState(seed)``: scikit-learn's
    ``GaussianProcessRegressor`` with ``n_restarts_optimizer`` does the same.
    Then from ``start`` with every length scale long and short
    (:data:`COVER_SCALES`): the search's known poor optimum (short length
    scales, a large noise: a white-noise fit) is where the default start
    can end on real data, and the best likelihood of all starts is kept, so
    these starts change a result only by finding a better likelihood.
    """
    def objective(theta):
        lml, grad = log_marginal_likelihood(theta, X, Y, nu)
        return -lml, -grad

    rng = np.random.RandomState(seed)
    start = np.asarray(start, dtype=float)
    starts = [start] + [rng.uniform(bounds[:, 0], bounds[:, 1]) for _ in range(restarts)] + \
        [np.clip(np.r_[start[0], np.full(len(start) - 2, np.log(scale)), start[-1]], bounds[:, 0], bounds[:, 1])
         for scale in COVER_SCALES]
    best_theta, best = starts[0], np.inf
    for theta0 in starts:
        res = minimize(objective, theta0, jac=True, method="L-BFGS-B", bounds=bounds, options={"ftol": SEARCH_FTOL})
        if res.fun < best:
            best_theta, best = res.x, float(res.fun)
    return best_theta, -best
