"""The rank-checked Levenberg-Marquardt fit over any stacked residuals (:func:`fit_parameters`): weights,
a robust loss, a prior's rows, implausible values kept nominal, and the uncertainty of what it identifies.
"""

from __future__ import annotations

import logging

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..errors import DataError
from ..metrics import ROBUST_LOSSES, held_joints, loss_weights, pooled_rms
from .identifiability import identifiable_parameters
from .parameters import PLAUSIBLE_ERROR, Identification

log = logging.getLogger(__name__)

LOSSES = ROBUST_LOSSES
"""The losses of robust identification: scipy ``least_squares``' (``linear`` is least squares)."""

DOWNWEIGHTED = 0.5
"""A measurement row whose worst coordinate the robust loss weighs below this (its ``rho'``) is named as
down-weighted (:attr:`Identification.robust`)."""


def fit_parameters(jac_at, v0: NDArray[np.float64], jac0: NDArray[np.float64], wanted: NDArray[np.bool_],
                   names: list[tuple[str, str]], rcond: float, size: int, n_poses: int, *,
                   row_weight: NDArray[np.float64] | None = None, loss: str = "linear", loss_scale: float = 3.0,
                   reference_mm: float | None = None, held: NDArray[np.bool_] | None = None,
                   row_of: NDArray[np.intp] | None = None, weighted_by: NDArray[np.float64] | None = None,
                   prior_rows: int = 0) -> tuple[Identification, NDArray[np.float64]]:
    """The rank-checked fit of :func:`identify` over any stacked residuals, and the residuals it leaves.

    ``jac_at(values, jacobian=True)`` gives the residuals and their Jacobian; ``v0`` is the start (the
    nominal values); ``jac0`` the Jacobian the rank rule reads (at ``v0``, on consistent data);
    ``wanted`` the parameters asked for; ``names`` every parameter's ``(name, unit)``; ``size`` the number
    of geometric parameters (the rows', tool and base: the first ``size``). The table's ``rms_mm`` is the
    3-D RMS of the residuals read as points; callers replace it with their own figure.

    ``row_weight`` (one per residual, :func:`row_weights`) weighs the residuals (weighted least squares: the
    covariance and ``sigma`` are the weighted residuals'; the residuals returned are not weighted). ``loss``
    (:data:`LOSSES`) fits by scipy's trust-region reflective method with that loss, its ``f_scale``
    ``loss_scale`` times ``reference_mm`` (the weighted residuals' stated standard deviation) or, without it,
    times the robust spread of the least-squares fit's residuals; the covariance then weighs each residual by
    the loss's weight (:func:`loss_weights`), and the rows it weighs below :data:`DOWNWEIGHTED` are named in
    the table's ``robust``: ``row_of`` gives the measurement row of each residual (-1: none, such as a prior's;
    default: the first ``3 n_poses`` residuals, three per row), and ``weighted_by`` the weights ``jac_at`` has
    already put on its residuals (to say each row's residual in mm). ``held``: the parameters a prior holds (its
    rows are in ``jac_at``, the last ``prior_rows`` of ``jac0``), never pruned as implausible.
    """
    if loss not in LOSSES:
        raise DataError(f"loss must be one of {', '.join(LOSSES)}; got {loss!r}")
    if row_weight is not None:
        jac_at, jac0 = _weighted(jac_at, row_weight), jac0 * row_weight[:, None]
    units = [unit for _, unit in names]
    free, rank = identifiable_parameters(jac0, wanted, rcond, units, jac0.shape[0] - prior_rows)

    limits = np.full(v0.size, np.nan)
    limits[:size - 9] = [PLAUSIBLE_ERROR[unit] * IMPLAUSIBLE for unit in units[:size - 9]]     # the rows' parameters
    if held is not None:
        limits[held] = np.nan                                   # the prior prices their distance instead
    v, evaluations = v0.copy(), 0
    resid0 = jac_at(v0, jacobian=False)[0]
    while free.size:
        v = v0.copy()
        v[free] += np.linalg.lstsq(jac0[:, free], -resid0, rcond=None)[0]     # Gauss-Newton from nominal: cheap
        worst = _implausible(jac_at, v, v0, free, limits)
        if worst is None:
            v, nfev = _solve(jac_at, v0, free)
            evaluations += nfev
            if loss != "linear":
                v, nfev = _robust_solve(jac_at, v0, v, free, loss, loss_scale, reference_mm)
                evaluations += nfev
            worst = _implausible(jac_at, v, v0, free, limits)
            if worst is None:
                break
        k = free[worst]
        log.info("%s comes out %+.4g %s from nominal", names[k][0], v[k] - v0[k], units[k])
        log.warning("%s comes out beyond %g %s from nominal (%g times a plausible manufacturing error), and the "
                    "data do not fix it (nominal is within %g standard errors): kept nominal and the rest refitted",
                    names[k][0], limits[k], units[k], IMPLAUSIBLE, UNFIXED)
        free = np.delete(free, worst)
    if free.size == 0:
        v = v0.copy()
    resid, jac = jac_at(v)
    robust, counted = None, None
    if loss != "linear":
        scale = loss_scale * (reference_mm if reference_mm is not None else _robust_spread(jac_at, v))
        counted = loss_weights(resid / scale, loss)
        weights = np.ones(resid.size)
        for w in (row_weight, weighted_by):
            if w is not None:
                weights[:w.size] *= w
        if row_of is None:
            row_of = np.repeat(np.arange(n_poses), 3)
        robust = _downweighted(resid / weights, counted, row_of, loss, scale)
    std, condition, covariance, sigma = _uncertainty(jac[:, free], resid, counted)
    std_full = np.full(v.size, np.nan)
    std_full[free] = std
    status = np.where(wanted, "unidentifiable", "fixed").astype(object)
    status[free] = "identified"
    prior_std, absorbed = _prior(jac, free, status, units, size)
    result = Identification(tuple(n for n, _ in names), tuple(u for _, u in names), v0, v, std_full,
                            tuple(str(s) for s in status), rank, condition, pooled_rms(resid[:resid.size // 3 * 3]
                                                                                       .reshape(-1, 3)),
                            n_poses, evaluations, covariance=covariance, sigma_mm=sigma, prior_std=prior_std,
                            prior_absorbed=absorbed, robust=robust)
    return result, (resid if row_weight is None else resid / row_weight)


def _weighted(jac_at, row_weight: NDArray[np.float64]):
    """``jac_at`` with its residuals and Jacobian rows multiplied by ``row_weight``."""
    def weighted(v, jacobian=True):
        resid, jac = jac_at(v, jacobian)
        return resid * row_weight, (None if jac is None else jac * row_weight[:, None])
    return weighted


SCALE_PASSES = 4
"""Without a stated noise, the robust fit re-estimates its scale from its own residuals at most this many times
(the least-squares fit's residuals, which the outliers spread, start it), until it changes by less than 5 %."""


def _robust_solve(jac_at, v0: NDArray[np.float64], v: NDArray[np.float64], free: NDArray[np.intp], loss: str,
                  loss_scale: float, reference_mm: float | None) -> tuple[NDArray[np.float64], int]:
    """The robust fit from the least-squares values ``v``: ``f_scale`` is ``loss_scale`` times the stated
    standard deviation ``reference_mm``, or, without one, times the robust spread of the residuals, taken
    again after each fit (:data:`SCALE_PASSES`)."""
    evaluations, scale = 0, None
    for _ in range(1 if reference_mm is not None else SCALE_PASSES):
        new = loss_scale * (reference_mm if reference_mm is not None else _robust_spread(jac_at, v))
        if scale is not None and abs(new - scale) < 0.05 * scale:
            break
        scale = new
        v, nfev = _solve(jac_at, v0, free, loss=loss, f_scale=scale, start=v)
        evaluations += nfev
    return v, evaluations


def _robust_spread(jac_at, v: NDArray[np.float64]) -> float:
    """The robust standard deviation of one residual at ``v``: 1.4826 times the median absolute residual."""
    spread = 1.4826 * float(np.median(np.abs(jac_at(v, jacobian=False)[0])))
    return spread if spread > 0 else 1e-12


def _downweighted(plain: NDArray[np.float64], counted: NDArray[np.float64], row_of: NDArray[np.intp], loss: str,
                  scale: float) -> dict:
    """The ``robust`` entry of a table: the loss, its scale and the rows it weighs below :data:`DOWNWEIGHTED`
    (each row's weight its worst residual's; its residual the norm of its residuals, unweighted: a point's 3-D
    miss, mm). ``plain`` are the unweighted residuals, ``row_of`` the row of each (-1: none)."""
    live = np.flatnonzero(row_of >= 0)
    rows = row_of[live]
    n = int(rows.max()) + 1 if rows.size else 0
    weight = np.ones(n)
    np.minimum.at(weight, rows, counted[live])
    norm = np.zeros(n)
    np.add.at(norm, rows, plain[live] ** 2)
    low = np.flatnonzero(weight < DOWNWEIGHTED)
    return {"loss": loss, "scale_mm": float(scale),
            "downweighted": [{"row": int(i), "residual_mm": float(np.sqrt(norm[i])), "weight": float(weight[i])}
                             for i in low]}


def _prior(jac: NDArray[np.float64], free: NDArray[np.intp], status, units: list[str], size: int
           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The prior standard deviations of the geometric parameters the data do not identify (their plausible
    error, :data:`PLAUSIBLE_ERROR`; NaN for the rest), shape (P,), and how the identified parameters absorb
    them on the identification data, ``A = (J_i^T J_i)^-1 J_i^T J_u``, shape (K, U), from the stacked Jacobian
    ``jac`` at the solution (see :attr:`Identification.prior_absorbed`)."""
    prior = np.full(len(units), np.nan)
    unknown = [k for k in range(size) if status[k] == "unidentifiable" and units[k] in PLAUSIBLE_ERROR]
    prior[unknown] = [PLAUSIBLE_ERROR[units[k]] for k in unknown]
    if free.size == 0 or not unknown:
        return prior, np.zeros((free.size, len(unknown)))
    return prior, np.linalg.lstsq(jac[:, free], jac[:, unknown], rcond=None)[0]


def prior_variance(jac_identified: NDArray[np.float64], jac_prior: NDArray[np.float64],
                   absorbed: NDArray[np.float64], prior_std: NDArray[np.float64]) -> NDArray[np.float64]:
    """The variance a prediction gets from the parameters the data do not identify, shape (m,).

    ``diag(J P J^T)`` with ``J = J_u - J_i A``: ``J_u`` (m, U) the prediction's Jacobian over those
    parameters, ``J_i`` (m, K) over the identified ones, ``A`` (K, U) ``absorbed`` (how the fit made up for
    them on its data) and ``P = diag(prior_std**2)``. Where the identified parameters stand in for an
    unidentified one everywhere, ``J`` is nil; where the data left it unseen, it grows.

    >>> float(prior_variance(np.zeros((1, 0)), np.array([[2.0]]), np.zeros((0, 1)), np.array([0.5]))[0])
    1.0
    """
    effective = jac_prior - jac_identified @ absorbed
    return np.sum(effective**2 * prior_std**2, axis=1)


def held_still(q_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """The joint angles with every held joint (:func:`partcal.metrics.held_joints`: readings within
    :data:`~partcal.metrics.HELD_TOLERANCE_DEG`) set to its median: a joint that never moves fixes none of its
    own parameters, and its encoder's jitter must not pretend to (on 105 SK120 poses with q4, q5 read back
    with 0.001 degrees of noise, a[4] came out 32,140 mm). Exactly held joints are returned unchanged."""
    held = held_joints(q_deg)
    if not held.any() or len(q_deg) < 2:
        return q_deg
    out = q_deg.copy()
    out[:, held] = np.median(q_deg[:, held], axis=0)
    return out


IMPLAUSIBLE = 10.0
"""A DH parameter identified more than this many plausible errors (:data:`PLAUSIBLE_ERROR`: 10 mm, 1 degree)
from nominal, and not fixed by the data (:data:`UNFIXED`), is a trade-off of nearly equivalent parameters under
unmodelled errors: :func:`identify` keeps it nominal and refits the rest. A large value the data do fix is kept:
a DH model absorbs unmodelled errors that way (on the virtual SK120, a[5] at -21 mm, 46 standard errors out,
stands for part of the unmodelled compliance)."""

UNFIXED = 3.0
"""... and within this many standard errors of nominal (the data do not fix it: on the real UR10, the second wrist's
offset and twist wandered 4 to 60 degrees at 0.05 to 0.3 of their standard errors)."""

def _implausible(jac_at, v: NDArray[np.float64], v0: NDArray[np.float64], free: NDArray[np.intp],
                 limits: NDArray[np.float64]) -> int | None:
    """The position in ``free`` of the parameter farthest beyond its plausible range (``limits``, NaN: none)
    among those the data do not fix (nominal within :data:`UNFIXED` standard errors of ``v``); None if none."""
    beyond = np.abs(v - v0)[free] / limits[free]
    if not np.nanmax(beyond, initial=0.0) > 1.0:
        return None
    resid, jac = jac_at(v)
    std = _uncertainty(jac[:, free], resid)[0]
    loose = (beyond > 1.0) & ~(np.abs(v - v0)[free] >= UNFIXED * std)     # no standard error (NaN): not fixed
    return int(np.flatnonzero(loose)[np.argmax(beyond[loose])]) if loose.any() else None


def _solve(jac_at, v0: NDArray[np.float64], free: NDArray[np.intp], *, loss: str = "linear", f_scale: float = 1.0,
           start: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], int]:
    """The values that minimise the residuals of ``jac_at`` over the parameters ``free`` (the others kept at
    ``v0``), by Levenberg-Marquardt from ``v0`` (with a ``loss`` other than ``linear``: scipy's
    trust-region reflective method with that loss and ``f_scale``, from ``start``); and the number of
    evaluations."""
    def values_of(x):
        v = v0.copy()
        v[free] = x
        return v

    robust = {} if loss == "linear" else {"method": "trf", "loss": loss, "f_scale": f_scale}
    x0 = v0[free] if start is None else start[free]
    sol = least_squares(lambda x: jac_at(values_of(x), jacobian=False)[0], x0,
                        jac=lambda x: jac_at(values_of(x))[1][:, free], **{"method": "lm", **robust},
                        x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=200 * (free.size + 1))
    log.debug("least squares: %s (%d evaluations)", sol.message, sol.nfev)
    return values_of(sol.x), int(sol.nfev)


def _uncertainty(jac: NDArray[np.float64], resid: NDArray[np.float64], counted: NDArray[np.float64] | None = None
                 ) -> tuple[NDArray[np.float64], float, NDArray[np.float64], float]:
    """Standard errors ``sqrt(diag(sigma^2 (J^T J)^-1))``, the condition number of the unit-column ``J``, the
    covariance ``sigma^2 (J^T J)^-1`` itself and ``sigma`` (the residual standard deviation per coordinate).
    ``counted`` (a robust loss's weight of each residual, :func:`loss_weights`) multiplies the rows of ``J`` and
    the residuals by its square root first (iteratively reweighted least squares' covariance)."""
    if counted is not None and not np.all(counted == 1.0):
        root = np.sqrt(counted)
        jac, resid = jac * root[:, None], resid * root
    dof = resid.size - jac.shape[1]
    sigma2 = float(np.sum(resid**2)) / dof if dof > 0 else np.nan
    if jac.shape[1] == 0:
        return np.zeros(0), 1.0, np.zeros((0, 0)), float(np.sqrt(sigma2))
    r = scipy.linalg.qr(jac, mode="r")[0][:jac.shape[1]]         # J = Q R: R has J's singular values, and J D's R D
    _, s, vt = np.linalg.svd(r, full_matrices=False)
    scaled = vt.T / s
    covariance = sigma2 * scaled @ scaled.T
    std = np.sqrt(np.diagonal(covariance))
    s_unit = np.linalg.svd(r / np.linalg.norm(jac, axis=0), compute_uv=False)
    return std, float(s_unit[0] / s_unit[-1]) if s_unit[-1] > 0 else np.inf, covariance, float(np.sqrt(sigma2))
