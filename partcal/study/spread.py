"""A model's spread calibrated on held-out residuals, in the order the data were measured.

A model's own standard deviation (:meth:`~partcal.models.base.ErrorModelBase.predict_with_std`)
takes the scatter it leaves on its training data as the scatter of new data. Data measured later
often scatter more: a tracker session drifts (the IPA UR10's series B drifts by some 0.4 mm in z
over its 1495 poses), and a model fitted on the early poses does not see it. :func:`calibrate_spread`
measures that: the data are cut into ``folds`` contiguous blocks in measurement order, each block
is predicted, with its spread, by the model fitted on the others, and each output's spread is
scaled so that ``coverage`` of the held-out residuals lie within the interval
(``|r| <= z s``, ``z`` the normal quantile): ``scale_k = quantile(|r_k| / s_k, coverage) / z``.
The scales are kept as ``spread_scale_`` (written to model files) and multiply the model's own
standard deviation from then on.

A run does this for every model (:func:`run_scale`, the YAML's ``spread:`` key, docs/config.md). By
default (``calibration: forward``) each block is predicted by the model fitted on the blocks measured
*before* it (:func:`forward_folds`), as a test set measured after the identification set will be: on the
IPA UR10 this brings every model's intervals to 92.9-98.1% of held-out series B, where the blocks on
both sides (``contiguous``) leave a kinematic model with compliance at 88% (``benchmarks/bench_coverage.py``,
docs/predictor.md). ``folds`` reuses the run's cross-validation fits (no fit added, but shuffled folds
mix early and late poses, so a drift goes unseen); ``none`` keeps each model's own spread. Only
identification data are used: the test sets never set a scale.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm
from sklearn.base import clone

from ..errors import DataError, PartcalError, held_warnings
from ..models.depth import BETA_MAX, DepthSpread
from ..models.kinds import own_prior
from .selection import rows_of

log = logging.getLogger(__name__)


def contiguous_folds(n: int, folds: int) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """``(train, test)`` rows of ``folds`` contiguous blocks of ``n`` rows (in measurement order).

    >>> [test.tolist() for _, test in contiguous_folds(5, 2)]
    [[0, 1, 2], [3, 4]]
    """
    if not 2 <= folds <= n:
        raise DataError(f"calibrating a spread needs between 2 and {n} folds (the rows); got {folds}")
    rows = np.arange(n)
    return [(np.setdiff1d(rows, block), block) for block in np.array_split(rows, folds)]


def forward_folds(n: int, folds: int) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """``(train, test)`` rows: ``n`` rows cut into ``folds`` contiguous blocks (measurement order), each block
    after the first held out from a model fitted on all the blocks before it (data measured later, predicted
    from the earlier).

    >>> [(train.tolist(), test.tolist()) for train, test in forward_folds(6, 3)]
    [([0, 1], [2, 3]), ([0, 1, 2, 3], [4, 5])]
    """
    blocks = contiguous_folds(n, folds)
    return [(np.arange(test[0]), test) for _, test in blocks[1:]]


def held_out_scores(model, X, y, folds, per_row: dict | None = None, *, skip_unfittable: bool = False
                    ) -> NDArray[np.float64]:
    """``|y - mean| / std`` of every row predicted by ``model`` fitted on the folds without it, shape of ``y``.

    With ``skip_unfittable`` a fold whose training rows the model refuses (a :class:`PartcalError`: too few
    poses for its regions, say), or whose fit has no spread (a series fitted on as many rows as terms, whose
    zero residuals would make the scale astronomical), leaves its rows NaN instead of raising. The warnings of these fits on part
    of the rows are not the model's (a kinematic fit on a few early poses keeps parameters nominal that all
    the rows fix): they are said once, as one warning that names the spread calibration.
    """
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    scores = np.full_like(y, np.nan)
    with held_warnings(exclusive=True) as said:
        for train, test in folds:
            try:
                fold = clone(model).fit(X[train], y[train], **rows_of(per_row, train))
            except PartcalError as exc:
                if not skip_unfittable:
                    raise
                log.info("spread calibration: a fit on %d rows was refused (%s); its block is left out",
                         len(train), exc)
                continue
            if skip_unfittable and fold.spread_problem() is not None:     # fitted with no residual to go by
                log.info("spread calibration: the fit on %d rows has no spread (%s); its block is left out",
                         len(train), fold.spread_problem())
                continue
            scores[test] = _scores(fold, X, y, test, per_row)
    if said:
        log.warning("spread calibration: its %d fits on part of the identification rows gave %d warning%s "
                    "(theirs, not those of the model fitted on all the rows), the first: %s", len(folds),
                    len(said), "" if len(said) == 1 else "s", said[0])
    return scores


def fitted_scores(fitted: list, X, y, folds, per_row: dict | None = None) -> NDArray[np.float64]:
    """``|y - mean| / std`` of every row predicted by the model of its fold already fitted without it (``fitted``,
    one per fold: a run's cross-validation fits), shape of ``y``; rows no fold holds out stay NaN."""
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    scores = np.full_like(y, np.nan)
    for fold, (_, test) in zip(fitted, folds):
        scores[test] = _scores(fold, X, y, test, per_row)
    return scores


def _scores(fold, X, y, test, per_row: dict | None) -> NDArray[np.float64]:
    """``|y - mean| / std`` of the rows ``test`` predicted by the fitted ``fold``, shape of ``y[test]`` (a 1-D
    ``y`` against the model's (m, 1) prediction)."""
    mean, std = fold.predict_with_std(X[test], **rows_of(per_row, test, predicting=True))
    shape = y[test].shape
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs(y[test] - mean.reshape(shape)) / std.reshape(shape)


def scale_from_scores(scores: NDArray[np.float64], coverage: float) -> NDArray[np.float64]:
    """The scale of each output that makes ``coverage`` of the held-out ``scores`` (n, outputs) fall within
    ``z`` standard deviations: ``quantile(score, coverage) / z``; 1 for an output without finite scores
    (a pose model's orientation that has no spread) and where the quantile is not a finite positive number.

    >>> scale_from_scores(np.array([[0.5], [1.0], [1.5], [2.0]]), 0.5).round(4).tolist()
    [1.8533]
    """
    flat = np.asarray(scores, dtype=float).reshape(len(scores), -1)
    flat = np.where(np.isfinite(flat), flat, np.nan)
    z = norm.ppf(0.5 + coverage / 2)
    scale = np.ones(flat.shape[1])
    for k in range(flat.shape[1]):
        column = flat[~np.isnan(flat[:, k]), k]
        value = np.quantile(column, coverage) / z if column.size else np.nan
        scale[k] = value if np.isfinite(value) and value > 0 else 1.0
    return scale


def held_out_depths(X, folds) -> NDArray[np.float64]:
    """The depth (:class:`~partcal.models.depth.DepthSpread`) of every held-out row among the training rows of
    its fold, shape (n,); NaN for rows no fold holds out and for folds of fewer than two training rows."""
    X = np.asarray(X, dtype=float)
    depths = np.full(len(X), np.nan)
    for train, test in folds:
        fold = DepthSpread.of_inputs(X[train])
        if fold is not None:
            depths[test] = fold.depth(X[test])
    return depths


BETA_GRID = np.concatenate([[0.0], np.logspace(-3, np.log10(BETA_MAX), 25)])     # the betas tried


def depth_from_scores(scores: NDArray[np.float64], depths: NDArray[np.float64], coverage: float
                      ) -> tuple[float, NDArray[np.float64]]:
    """``(beta, scale)``: how fast the spread grows with the depth, and each output's scale.

    ``beta`` (on a grid from 0 to :data:`~partcal.models.depth.BETA_MAX`) maximises the likelihood of the held-out
    ``scores`` (n, outputs) as half-normal with standard deviation ``c_k sqrt(1 + beta d^2)`` (``c_k`` of output
    ``k`` at its maximum-likelihood value), a proper score, so a wider spread out at the edges is chosen only
    when the residuals there are larger; the scales then make ``coverage`` of the scores divided by
    ``sqrt(1 + beta d^2)`` fall within ``z`` (:func:`scale_from_scores`). Rows without a finite depth do not
    take part in choosing ``beta``.

    >>> d = np.linspace(0.0, 3.0, 400)
    >>> scores = np.abs(np.random.default_rng(0).normal(size=(400, 1))) * np.sqrt(1 + 2.0 * d ** 2)[:, None]
    >>> float(depth_from_scores(scores, d, 0.95)[0]) > 1.0, float(depth_from_scores(scores[:, :1] * 0 + 1, d, 0.95)[0])
    (True, 0.0)
    """
    flat = np.asarray(scores, dtype=float).reshape(len(scores), -1)
    depths = np.asarray(depths, dtype=float)
    usable = np.isfinite(flat) & (flat > 0) & np.isfinite(depths)[:, None]
    best_beta, best = 0.0, -np.inf
    for beta in BETA_GRID:
        g2 = 1.0 + beta * depths ** 2
        loglik = 0.0
        for k in range(flat.shape[1]):
            rows = usable[:, k]
            if rows.sum() < 2:
                continue
            c2 = np.mean(flat[rows, k] ** 2 / g2[rows])
            loglik -= 0.5 * (rows.sum() * np.log(c2) + np.log(g2[rows]).sum())
        if loglik > best + 1e-9 * max(1.0, abs(loglik)):       # a wider growth only when it is clearly likelier
            best_beta, best = float(beta), loglik
    growth = np.sqrt(1.0 + best_beta * np.where(np.isfinite(depths), depths, 0.0) ** 2)
    return best_beta, scale_from_scores(flat / growth[:, None], coverage)


@dataclass(frozen=True)
class CalibratedSpread:
    """A calibrated spread: each output's ``scale`` and, when it grows with the inputs' depth, ``depth``."""

    scale: NDArray[np.float64]
    depth: DepthSpread | None = None

    def apply(self, model):
        """Give ``model`` this spread (its :meth:`~partcal.models.base.ErrorModelBase.set_spread`); returns it."""
        return model.set_spread(self.scale, self.depth)


def calibrated(scores, X, folds, coverage: float, depth: bool = True, y=None) -> CalibratedSpread:
    """The spread the held-out ``scores`` of ``folds`` call for: growing with the depth (``beta`` > 0) only when
    they show it, and only with ``depth``; with the training errors ``y`` (of a model without a prior of its
    own, the row's ``own_prior`` in the table of kinds) also the prior of inputs the data held still."""
    if not depth:
        return CalibratedSpread(scale_from_scores(scores, coverage))
    beta, scale = depth_from_scores(scores, held_out_depths(X, folds), coverage)   # beta 0: scale_from_scores's
    whole = DepthSpread.of_inputs(X, beta, y)
    kept = whole is not None and (beta > 0 or whole.held_variance is not None)     # it changes some spread
    return CalibratedSpread(scale, whole if kept else None)


def calibrate_spread(model, X, y, *, folds: int = 5, coverage: float = 0.95, per_row: dict | None = None,
                     depth: bool = True):
    """Fit ``model`` on ``X, y`` and scale its spread so that held-out blocks reach ``coverage``; returns it.

    Parameters
    ----------
    model : estimator
        An unfitted partcal error model (any kind with a spread).
    X, y : array-like
        The training inputs and errors, rows in measurement order.
    folds : int
        Contiguous blocks held out in turn.
    coverage : float in (0, 1)
        The share of held-out residuals the interval ``mean +- z std`` is made to hold.
    per_row : dict, optional
        Per-row arguments of ``fit`` and ``predict`` (a payload per pose).
    depth : bool
        Let the spread grow with the inputs' depth where the held-out residuals do (:func:`depth_from_scores`).
    """
    if not 0.0 < coverage < 1.0:
        raise DataError(f"the coverage of a calibrated spread must lie in (0, 1); got {coverage!r}")
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    blocks = contiguous_folds(len(X), folds)
    scores = held_out_scores(model, X, y, blocks, per_row)
    model.fit(X, y, **(per_row or {}))
    return calibrated(scores, X, blocks, coverage, depth, None if own_prior(model) else y).apply(model)


def run_spread(options, model, X, y, *, cv_folds: list, fold_fits: list | None = None,
               per_row: dict | None = None) -> CalibratedSpread | None:
    """The calibrated spread of a run's model fitted on ``X, y`` (the identification set), by the run's
    ``spread`` options (:class:`~partcal.study.config.SpreadOptions`); None when ``calibration: none`` or the
    model has no spread.

    ``forward`` fits a clone of ``model`` on the rows before each of ``options.folds`` contiguous blocks
    (:func:`forward_folds`), ``contiguous`` on each block's complement (:func:`contiguous_folds`; at most
    one block per row); ``folds`` reads the run's cross-validation: ``fold_fits`` (the models already
    fitted on ``cv_folds``) when given, else clones fitted on ``cv_folds`` (a nested CV keeps no fits of the
    chosen granularity). A block whose fit the model refuses (too few rows) is left out; with none left, or
    no spread on any, the model keeps its own spread (None, warned). With ``options.depth`` the spread grows
    with the inputs' depth as far as the held-out residuals show (:func:`depth_from_scores`).
    """
    if options.calibration == "none" or model.spread_problem() is not None or len(X) < 2:
        return None
    if options.calibration == "folds" and fold_fits:
        folds = cv_folds
        scores = fitted_scores(fold_fits, X, y, cv_folds, per_row)
    else:
        blocks = {"contiguous": contiguous_folds, "forward": forward_folds}.get(options.calibration)
        folds = cv_folds if blocks is None else blocks(len(X), min(options.folds, len(X)))
        if not folds:
            return None
        scores = held_out_scores(clone(model), X, y, folds, per_row, skip_unfittable=True)
    if not np.isfinite(scores).any():
        log.warning("the spread could not be calibrated (no held-out block could be predicted with a spread): "
                    "the model's own spread is kept")
        return None
    return calibrated(scores, X, folds, options.coverage, options.depth, None if own_prior(model) else y)
