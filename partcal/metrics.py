"""Error statistics: RMS per axis, 3-D RMS, maximum and percentiles of the error norm (mm)."""

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


def kfold_splits(n: int, folds: int, random_state: int = 0) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """Shuffled k-fold ``(train, test)`` index pairs for ``n`` samples (scikit-learn's ``KFold``).

    A batch run draws these once, from its seed, and scores every model on the
    same folds, so that the ranking compares models and not luck.

    >>> folds = kfold_splits(10, 5, random_state=0)
    >>> sorted(i for _, test in folds for i in test) == list(range(10)), [len(t) for _, t in folds]
    (True, [2, 2, 2, 2, 2])
    """
    from sklearn.model_selection import KFold

    return list(KFold(n_splits=folds, shuffle=True, random_state=random_state).split(np.zeros((n, 1))))


def cross_validated_rms(model, X, y, *, folds=5, random_state=0, fitted: list | None = None) -> float:
    """Pooled 3-D RMS of k-fold held-out predictions, mm.

    Every sample is predicted once by a model fitted without it; the result is
    ``sqrt(mean(|e|^2))`` over all samples, comparable across models.

    Parameters
    ----------
    folds : int or list of (train, test) index arrays
        The number of shuffled folds (drawn with ``random_state``), or the
        folds themselves (see :func:`kfold_splits`).
    fitted : list, optional
        Receives the model fitted on each fold (to see, say, how many regions
        a partition kept with fewer samples).
    """
    from sklearn.base import clone

    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    splits = kfold_splits(len(X), folds, random_state) if isinstance(folds, int) else folds
    resid = np.empty_like(y)
    for train, test in splits:
        fold = clone(model).fit(X[train], y[train])
        resid[test] = y[test] - fold.predict(X[test])
        if fitted is not None:
            fitted.append(fold)
    return float(np.sqrt(np.mean(np.sum(resid.reshape(len(y), -1) ** 2, axis=1))))


def select_by_cv(candidates, X, y, *, folds, fold_models: list | None = None
                 ) -> tuple[int, list[float], list, list[float]]:
    """Score unfitted ``candidates`` by CV on ``folds``, then fit each on all of ``X, y``.

    Returns ``(best, scores, fitted, seconds)``: the index of the lowest score
    (the first of equals), the pooled 3-D RMS of each candidate, the fitted
    candidates and the seconds of each final fit. ``fold_models`` receives,
    per candidate, the list of its models fitted on the folds.
    """
    import time

    scores, fitted, seconds = [], [], []
    for candidate in candidates:
        folds_fitted: list = []
        scores.append(cross_validated_rms(candidate, X, y, folds=folds, fitted=folds_fitted))
        if fold_models is not None:
            fold_models.append(folds_fitted)
        begin = time.perf_counter()
        fitted.append(candidate.fit(X, y))
        seconds.append(time.perf_counter() - begin)
    return min(range(len(scores)), key=scores.__getitem__), scores, fitted, seconds


def nested_cross_validated_rms(candidates, X, y, *, folds, inner_folds: int = 5, random_state=0) -> float:
    """Honest CV score of "choose among ``candidates`` by CV, then fit": the choice is made inside each fold.

    For every outer ``(train, test)`` fold the candidate (an unfitted
    estimator; granularities of a partitioned model, say) is chosen by
    ``inner_folds``-fold CV on the outer training set alone (folds drawn with
    ``random_state``; the first of equal scores), fitted there, and scored on
    the held-out test set. Returns the pooled 3-D RMS of those held-out
    predictions, mm. Scoring the chosen candidate on the folds that chose it
    would flatter it.
    """
    from sklearn.base import clone

    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    resid = np.empty_like(y)
    for train, test in folds:
        inner = kfold_splits(len(train), inner_folds, random_state)
        scores = [cross_validated_rms(c, X[train], y[train], folds=inner) for c in candidates]
        chosen = candidates[min(range(len(scores)), key=scores.__getitem__)]
        resid[test] = y[test] - clone(chosen).fit(X[train], y[train]).predict(X[test])
    return float(np.sqrt(np.mean(np.sum(resid.reshape(len(y), -1) ** 2, axis=1))))


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
