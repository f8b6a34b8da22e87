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
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm
from sklearn.base import clone

from ..errors import DataError
from .selection import rows_of


def contiguous_folds(n: int, folds: int) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """``(train, test)`` rows of ``folds`` contiguous blocks of ``n`` rows (in measurement order).

    >>> [test.tolist() for _, test in contiguous_folds(5, 2)]
    [[0, 1, 2], [3, 4]]
    """
    if not 2 <= folds <= n:
        raise DataError(f"calibrating a spread needs between 2 and {n} folds (the rows); got {folds}")
    rows = np.arange(n)
    return [(np.setdiff1d(rows, block), block) for block in np.array_split(rows, folds)]


def held_out_scores(model, X, y, folds, per_row: dict | None = None) -> NDArray[np.float64]:
    """``|y - mean| / std`` of every row predicted by ``model`` fitted on the folds without it, shape of ``y``."""
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    scores = np.empty_like(y)
    for train, test in folds:
        fold = clone(model).fit(X[train], y[train], **rows_of(per_row, train))
        mean, std = fold.predict_with_std(X[test], **rows_of(per_row, test, predicting=True))
        scores[test] = np.abs(y[test] - mean) / std
    return scores


def calibrate_spread(model, X, y, *, folds: int = 5, coverage: float = 0.95, per_row: dict | None = None):
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
    """
    if not 0.0 < coverage < 1.0:
        raise DataError(f"the coverage of a calibrated spread must lie in (0, 1); got {coverage!r}")
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    scores = held_out_scores(model, X, y, contiguous_folds(len(X), folds), per_row)
    scale = np.quantile(scores.reshape(len(X), -1), coverage, axis=0) / norm.ppf(0.5 + coverage / 2)
    model.fit(X, y, **(per_row or {}))
    model.spread_scale_ = scale
    return model
