"""Error statistics: RMS per axis, 3-D RMS, maximum and percentiles of the error norm (mm)."""

from __future__ import annotations

from typing import Callable

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


LEAVE_ONE_OUT_UP_TO = 30      # cv_folds: auto -> leave one pose out up to this many poses, 5 folds above


def pose_groups(q_deg: NDArray[np.float64], decimals: int = 6) -> NDArray[np.intp]:
    """Group label of each row: rows with the same joint angles (to ``10**-decimals`` deg) are one pose.

    Labels count from 0 in the order poses first appear, so a file without
    repeats gets ``0, 1, 2, ...``.

    >>> pose_groups(np.array([[0.0, 1.0], [5.0, 0.0], [0.0, 1.0]])).tolist()
    [0, 1, 0]
    """
    q = np.round(np.asarray(q_deg, dtype=float), decimals).reshape(len(q_deg), -1)
    return _first_appearance(np.unique(q, axis=0, return_index=True, return_inverse=True))


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


def fold_rule(cv_folds: int | str, n_groups: int) -> int | str:
    """The folds a run uses: ``cv_folds`` (an int k, ``"leave_one_out"`` or ``"auto"``) for ``n_groups`` poses.

    ``auto`` leaves one pose out up to :data:`LEAVE_ONE_OUT_UP_TO` poses (on
    few poses a fifth of them held out leaves too few to fit a many-parameter
    model, and five fold scores are too few to compare models), 5 folds above.
    An int is capped at the number of poses.

    >>> fold_rule("auto", 16), fold_rule("auto", 85), fold_rule(10, 6)
    ('leave_one_out', 5, 6)
    """
    if cv_folds == "auto":
        return "leave_one_out" if n_groups <= LEAVE_ONE_OUT_UP_TO else 5
    if cv_folds == "leave_one_out":
        return cv_folds
    return min(int(cv_folds), n_groups)


def fold_name(rule: int | str) -> str:
    """``5`` -> ``'5-fold'``; ``'leave_one_out'`` -> ``'leave-one-pose-out'``."""
    return "leave-one-pose-out" if rule == "leave_one_out" else f"{rule}-fold"


def grouped_splits(groups: NDArray[np.intp], rule: int | str, random_state: int = 0
                   ) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """``(train, test)`` row indices that never split a group: ``rule`` folds of shuffled groups, or one per group.

    ``groups`` numbers the groups from 0 (see :func:`pose_groups`). With every
    row its own group, k folds are exactly scikit-learn's shuffled ``KFold``
    (:func:`kfold_splits`), so files without repeats keep their folds.

    >>> folds = grouped_splits(np.array([0, 0, 1, 2, 2, 3]), 2, random_state=0)
    >>> [test.tolist() for _, test in folds]
    [[3, 4, 5], [0, 1, 2]]
    """
    groups = np.asarray(groups, dtype=np.intp)
    n_groups = int(groups.max()) + 1
    if rule == "leave_one_out":
        chunks = [np.array([g]) for g in range(n_groups)]
    else:
        k = int(rule)
        if not 2 <= k <= n_groups:
            raise ValueError(f"{k} folds need at least {k} groups (poses), got {n_groups}")
        order = np.arange(n_groups)
        np.random.RandomState(random_state).shuffle(order)         # KFold's own shuffle, on groups
        bounds = np.cumsum([0] + [n_groups // k + (i < n_groups % k) for i in range(k)])
        chunks = [order[a:b] for a, b in zip(bounds[:-1], bounds[1:])]
    out = []
    for chunk in chunks:
        held = np.isin(groups, chunk)
        out.append((np.flatnonzero(~held), np.flatnonzero(held)))
    return out


def kfold_splits(n: int, folds: int, random_state: int = 0) -> list[tuple[NDArray[np.intp], NDArray[np.intp]]]:
    """Shuffled k-fold ``(train, test)`` index pairs for ``n`` samples (scikit-learn's ``KFold``).

    A batch run draws its folds once, from its seed, and scores every model on
    the same folds, so that the ranking compares models and not luck.

    >>> folds = kfold_splits(10, 5, random_state=0)
    >>> sorted(i for _, test in folds for i in test) == list(range(10)), [len(t) for _, t in folds]
    (True, [2, 2, 2, 2, 2])
    """
    return grouped_splits(np.arange(n), folds, random_state)


FIT_ONLY = ("targets", "orientation_deg")    # per-row data a fit reads and a prediction does not


def rows_of(per_row: dict | None, rows, *, predicting: bool = False) -> dict:
    """The per-row arguments of fit (or, ``predicting``, of predict) at ``rows``: ``{"payload_kg": (n,)}``,
    ``{"targets": {name: (offset, (n, 3) errors)}}``, ... A dict is taken key by key, a pair as
    ``(value for every row, per-row values)``, anything else by its rows."""
    def take(value):
        if isinstance(value, dict):
            return {k: take(v) for k, v in value.items()}
        if isinstance(value, tuple):
            return value[0], take(value[1])
        return value[rows]

    return {key: take(value) for key, value in (per_row or {}).items() if not (predicting and key in FIT_ONLY)}


def held_out_residuals(model, X, y, folds, *, fitted: list | None = None,
                       progress: Callable[[int, int], None] | None = None,
                       per_row: dict | None = None) -> NDArray[np.float64]:
    """``y - prediction`` of every sample by ``model`` fitted on the folds without it, shape of ``y``.

    ``fitted`` receives the model fitted on each fold; ``progress(done, total)`` is called after each fold.
    ``per_row`` holds arguments of ``fit`` and ``predict`` with one value per sample (a payload per pose),
    split with the samples.
    """
    from sklearn.base import clone

    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    resid = np.empty_like(y)
    for i, (train, test) in enumerate(folds):
        fold = clone(model).fit(X[train], y[train], **rows_of(per_row, train))
        resid[test] = y[test] - fold.predict(X[test], **rows_of(per_row, test, predicting=True))
        if fitted is not None:
            fitted.append(fold)
        if progress is not None:
            progress(i + 1, len(folds))
    return resid


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


def cross_validated_rms(model, X, y, *, folds=5, random_state=0, fitted: list | None = None,
                        per_row: dict | None = None) -> float:
    """Pooled 3-D RMS of k-fold held-out predictions, mm.

    Every sample is predicted once by a model fitted without it; the result is
    ``sqrt(mean(|e|^2))`` over all samples, comparable across models.

    Parameters
    ----------
    folds : int or list of (train, test) index arrays
        The number of shuffled folds (drawn with ``random_state``), or the
        folds themselves (see :func:`kfold_splits`, :func:`grouped_splits`).
    fitted : list, optional
        Receives the model fitted on each fold (to see, say, how many regions
        a partition kept with fewer samples).
    per_row : dict, optional
        Per-sample arguments of ``fit`` and ``predict`` (see :func:`held_out_residuals`).
    """
    splits = kfold_splits(len(X), folds, random_state) if isinstance(folds, int) else folds
    return pooled_rms(held_out_residuals(model, X, y, splits, fitted=fitted, per_row=per_row))


def select_by_cv(candidates, X, y, *, folds, fold_models: list | None = None, per_row: dict | None = None,
                 score: Callable[[NDArray[np.float64]], float] | None = None
                 ) -> tuple[int, list[float], list, list[float]]:
    """Score unfitted ``candidates`` by CV on ``folds``, then fit each on all of ``X, y``.

    Returns ``(best, scores, fitted, seconds)``: the index of the lowest score
    (the first of equals), the pooled 3-D RMS of each candidate, the fitted
    candidates and the seconds of each final fit. ``fold_models`` receives,
    per candidate, the list of its models fitted on the folds; ``per_row``:
    see :func:`held_out_residuals`; ``score`` turns held-out residuals into the
    score (default :func:`pooled_rms`; a run of pose errors scores some columns).
    """
    import time

    score = score or pooled_rms
    scores, fitted, seconds = [], [], []
    for candidate in candidates:
        folds_fitted: list = []
        scores.append(score(held_out_residuals(candidate, X, y, folds, fitted=folds_fitted, per_row=per_row)))
        if fold_models is not None:
            fold_models.append(folds_fitted)
        begin = time.perf_counter()
        fitted.append(candidate.fit(X, y, **(per_row or {})))
        seconds.append(time.perf_counter() - begin)
    return min(range(len(scores)), key=scores.__getitem__), scores, fitted, seconds


def nested_residuals(candidates, X, y, *, folds, inner: Callable[[NDArray[np.intp]], list],
                     progress: Callable[[int, int], None] | None = None, per_row: dict | None = None,
                     score: Callable[[NDArray[np.float64]], float] | None = None) -> NDArray[np.float64]:
    """Held-out residuals of "choose among ``candidates`` by CV, then fit": the choice is made inside each fold.

    For every outer ``(train, test)`` fold the candidate (an unfitted
    estimator; granularities of a partitioned model, say) is chosen by CV on
    the outer training rows alone, on the folds ``inner(train)`` returns
    (index pairs into ``train``; the first of equal scores), fitted there and
    scored on the held-out rows. Scoring the chosen candidate on the folds
    that chose it would flatter it. Each candidate may first be frozen on the
    outer training rows (``candidate.frozen(X, y)``: a Gaussian process fixes
    the hyperparameters it learns there), so the inner fits only solve; no
    fold learns anything from its held-out rows. ``per_row``: see
    :func:`held_out_residuals`; ``score``: see :func:`select_by_cv`.
    """
    score = score or pooled_rms
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    resid = np.empty_like(y)
    for i, (train, test) in enumerate(folds):
        Xt, yt, rows = X[train], y[train], rows_of(per_row, train)
        frozen = [_frozen(c, Xt, yt, rows) for c in candidates]
        splits = inner(train)
        scores = [score(held_out_residuals(c, Xt, yt, splits, per_row=rows)) for c in frozen]
        chosen = frozen[min(range(len(scores)), key=scores.__getitem__)]
        resid[test] = y[test] - _clone(chosen).fit(Xt, yt, **rows).predict(X[test], **rows_of(per_row, test,
                                                                                               predicting=True))
        if progress is not None:
            progress(i + 1, len(folds))
    return resid


def nested_cross_validated_rms(candidates, X, y, *, folds, inner_folds: int = 5, random_state=0) -> float:
    """Honest CV score (pooled 3-D RMS, mm) of "choose among ``candidates`` by CV, then fit".

    See :func:`nested_residuals`; here the inner folds are ``inner_folds``
    shuffled folds of each outer training set (drawn with ``random_state``;
    at most one per sample).
    """
    def inner(train):
        return kfold_splits(len(train), min(inner_folds, len(train)), random_state)

    return pooled_rms(nested_residuals(candidates, X, y, folds=folds, inner=inner))


def choose_simplest(scores, errors, sizes, physical) -> int:
    """The index a run picks: the simplest physical model within one standard error of the best, else the best.

    ``scores``: CV RMS per model; ``errors``: their standard errors;
    ``sizes``: parameter counts; ``physical``: whether a model is physical
    (a kinematic model without a data-driven residual). The order of
    simplicity is two-tiered: a physical model is simpler than any model
    with a data-driven part (its parameters are lengths, angles and
    stiffnesses that hold over the whole workspace), and physical models
    are ordered by parameter count. Data-driven models are not ordered
    among themselves: their effective parameter counts do not compare (a
    Gaussian process that learnt nothing has almost none): they share one
    rank, so among them the lowest score wins. A NaN standard error counts
    as 0; a NaN score never wins.

    >>> choose_simplest([0.30, 0.28, 0.50], [0.02, 0.03, 0.01], [26, 90, 10], [True, False, True])
    0
    >>> choose_simplest([0.35, 0.28, 0.30], [0.02, 0.03, 0.01], [26, 90, 10], [True, False, False])
    1
    """
    best = min(range(len(scores)), key=lambda i: (not np.isfinite(scores[i]), scores[i], i))
    se = errors[best] if np.isfinite(errors[best]) else 0.0
    within = [i for i in range(len(scores)) if physical[i] and scores[i] <= scores[best] + se]
    return min(within, key=lambda i: (sizes[i], scores[i], i)) if within else best


def _frozen(model, X, y, rows: dict):
    freeze = getattr(model, "frozen", None)
    return freeze(X, y, **rows) if freeze is not None else model


def _clone(model):
    from sklearn.base import clone

    return clone(model)


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
