"""Model selection in one place: folds, held-out residuals, nested CV, the granularity choice and the rule
that picks a run's best model.

A run draws its folds once (:class:`CVPlan`: the pose of each identification
row, the fold rule, the folds) and scores every model on them by its
held-out residuals (:func:`held_out_residuals`); a model with a list of
granularities is scored by nested cross-validation (:func:`nested_residuals`:
the granularity is chosen inside each outer training fold) and fitted with the
granularity :func:`choose_granularity` picks on the outer folds. A prior's
list of strengths is chosen the same way, by :func:`strength_rule` (the
strongest within one standard error of the lowest score) instead of the
lowest score (:func:`choose_strength`). The run's best
model is the simplest physical model within one standard error of the lowest
CV score, else the lowest (:func:`choose_simplest`, :func:`choose_best`), or
the lowest RMS on a validation set.

This is the study layer: it fits estimators (clones of them) on folds;
:mod:`partcal.metrics` below holds the statistics it computes with.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
from numpy.typing import NDArray
from sklearn.base import clone

from .._validation import check_int
from ..data.measurements import Measurements
from ..metrics import (HELD_TOLERANCE_DEG, labels_as_groups, pooled_rms, pose_groups, rms_standard_error,
                       within_one_standard_error)
from ..models.kinds import is_physical, regions_of
from ..models.partitioned import fold_regions
from ..calibration.prior import strength_rows, strongest_within
from ..models.threads import one_blas_thread

if TYPE_CHECKING:
    from .config import RunConfig

LEAVE_ONE_OUT_UP_TO = 30      # cv_folds: auto -> leave one pose out up to this many poses, 5 folds above


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


FIT_ONLY = ("targets", "orientation_deg", "std_mm")    # per-row data a fit reads and a prediction does not


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
                       per_row: dict | None = None, n_jobs: int = 1) -> NDArray[np.float64]:
    """``y - prediction`` of every sample by ``model`` fitted on the folds without it, shape of ``y``.

    ``fitted`` receives the model fitted on each fold; ``progress(done, total)`` is called after each fold.
    ``per_row`` holds arguments of ``fit`` and ``predict`` with one value per sample (a payload per pose),
    split with the samples. ``n_jobs`` folds are fitted at a time (joblib; see :func:`fits_on_folds`): the
    residuals are the same for any ``n_jobs``.
    """
    return fits_on_folds(model, X, y, folds, fitted=fitted, progress=progress, per_row=per_row, n_jobs=n_jobs)[0]


def fits_on_folds(model, X, y, folds, *, fitted: list | None = None,
                  progress: Callable[[int, int], None] | None = None, per_row: dict | None = None,
                  n_jobs: int = 1, final: bool = False, on_final: Callable[[float], None] | None = None
                  ) -> tuple[NDArray[np.float64], object, float]:
    """Held-out residuals of ``model`` on ``folds`` (see :func:`held_out_residuals`) and, with ``final``, the
    model fitted on all of ``X, y`` and the seconds of that fit; ``(residuals, final model or None, seconds)``.

    The ``k`` fold fits (and the final one) are independent: with ``n_jobs > 1`` they run on that many
    joblib workers, the final fit first (the longest) beside the folds, and each result is put in its
    place, so the residuals, fold models and final model are those of ``n_jobs = 1``, where the folds run
    in order and the final fit after them. Large arrays reach the workers memory-mapped (joblib's
    default), not copied once per fold. ``on_final(seconds)`` is called when the final fit is done.
    """
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    resid = np.empty_like(y)
    tasks = [(train, test) for train, test in folds] + ([(np.arange(len(X)), None)] if final else [])
    models: list = [None] * len(tasks)
    seconds = [0.0] * len(tasks)
    if n_jobs == 1 or len(tasks) < 2:
        results = (_fit_fold(k, model, X, y, train, test, per_row) for k, (train, test) in enumerate(tasks))
    else:
        from joblib import Parallel, delayed

        order = ([len(tasks) - 1] if final else []) + list(range(len(folds)))      # the final fit first
        results = Parallel(n_jobs=min(n_jobs, len(tasks)), return_as="generator_unordered")(
            delayed(_fit_fold)(k, model, X, y, *tasks[k], per_row) for k in order)
    done = 0
    for k, fold, part, spent in results:
        models[k], seconds[k] = fold, spent
        if k < len(folds):
            resid[folds[k][1]] = part
            done += 1
            if progress is not None:
                progress(done, len(folds))
        elif on_final is not None:
            on_final(spent)
    if fitted is not None:
        fitted.extend(models[:len(folds)])
    return resid, (models[-1] if final else None), (seconds[-1] if final else 0.0)


def _fit_fold(k: int, model, X, y, train, test, per_row):
    """Fit a clone of ``model`` on the rows ``train``; its residuals on ``test`` (None: none), and the seconds.

    BLAS runs on one thread here, in this process or a worker alike: a QR or product split over another
    number of threads rounds differently (1e-14 relative on 100,000 poses), and the results must not
    depend on where, or beside what, a fold was fitted."""
    with one_blas_thread():
        begin = time.perf_counter()
        fold = clone(model).fit(X[train], y[train], **rows_of(per_row, train))
        spent = time.perf_counter() - begin
        part = None if test is None else y[test] - fold.predict(X[test], **rows_of(per_row, test, predicting=True))
    return k, fold, part, spent


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
                 score: Callable[[NDArray[np.float64]], float] | None = None, n_jobs: int = 1
                 ) -> tuple[int, list[float], list, list[float]]:
    """Score unfitted ``candidates`` by CV on ``folds``, then fit each on all of ``X, y``.

    Returns ``(best, scores, fitted, seconds)``: the index of the lowest score
    (the first of equals), the pooled 3-D RMS of each candidate, the fitted
    candidates and the seconds of each final fit. ``fold_models`` receives,
    per candidate, the list of its models fitted on the folds; ``per_row``:
    see :func:`held_out_residuals`; ``score`` turns held-out residuals into the
    score (default :func:`pooled_rms`; a run of pose errors scores some columns); ``n_jobs``: folds fitted
    at a time (:func:`fits_on_folds`).
    """
    score = score or pooled_rms
    scores, fitted, seconds = [], [], []
    for candidate in candidates:
        folds_fitted: list = []
        scores.append(score(held_out_residuals(candidate, X, y, folds, fitted=folds_fitted, per_row=per_row,
                                               n_jobs=n_jobs)))
        if fold_models is not None:
            fold_models.append(folds_fitted)
        begin = time.perf_counter()
        fitted.append(candidate.fit(X, y, **(per_row or {})))
        seconds.append(time.perf_counter() - begin)
    return min(range(len(scores)), key=scores.__getitem__), scores, fitted, seconds


def nested_residuals(candidates, X, y, *, folds, inner: Callable[[NDArray[np.intp]], list],
                     progress: Callable[[int, int], None] | None = None, per_row: dict | None = None,
                     score: Callable[[NDArray[np.float64]], float] | None = None, n_jobs: int = 1,
                     choose: Callable[[list, NDArray[np.intp]], int] | None = None) -> NDArray[np.float64]:
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
    :func:`held_out_residuals`; ``score``: see :func:`select_by_cv`; ``n_jobs``: inner folds fitted at a
    time. ``choose(residuals, rows)``: the rule that picks a candidate from their held-out residuals on the
    rows ``rows`` of ``X`` (:func:`strength_rule`); default the lowest ``score``.
    """
    score = score or pooled_rms
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    resid = np.empty_like(y)
    for i, (train, test) in enumerate(folds):
        Xt, yt, rows = X[train], y[train], rows_of(per_row, train)
        frozen = [_frozen(c, Xt, yt, rows) for c in candidates]
        splits = inner(train)
        each = [held_out_residuals(c, Xt, yt, splits, per_row=rows, n_jobs=n_jobs) for c in frozen]
        scores = [score(r) for r in each]
        chosen = frozen[choose(each, train) if choose is not None else min(range(len(scores)), key=scores.__getitem__)]
        resid[test] = y[test] - clone(chosen).fit(Xt, yt, **rows).predict(X[test], **rows_of(per_row, test,
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


def strength_rule(strengths: Sequence[float], groups: NDArray[np.intp],
                  score: Callable[[NDArray[np.float64]], float] = pooled_rms,
                  ranked: Callable[[NDArray[np.float64]], NDArray[np.float64]] = lambda r: r
                  ) -> Callable[[list, NDArray[np.intp]], int]:
    """The rule that chooses a prior's strength from the held-out residuals of one candidate per strength:
    the strongest within one standard error of the lowest ``score``
    (:func:`~partcal.calibration.prior.strongest_within`, the run's own rule for the simplest model), the standard
    error over the poses ``groups`` of the rows scored (:func:`~partcal.metrics.rms_standard_error` of
    ``ranked`` residuals, as a run's CV score has it). ``choose(residuals, rows)`` -> the index."""
    def choose(residuals: list, rows: NDArray[np.intp]) -> int:
        poses = labels_as_groups(groups[rows])
        return strongest_within(strengths, [score(r) for r in residuals],
                                [rms_standard_error(ranked(r), poses) for r in residuals])
    return choose


def choose_strength(candidates: Sequence, strengths: Sequence[float], X, y, cv: "CVPlan", *,
                    per_row: dict | None = None, score: Callable[[NDArray[np.float64]], float] = pooled_rms,
                    ranked: Callable[[NDArray[np.float64]], NDArray[np.float64]] = lambda r: r,
                    n_jobs: int = 1) -> tuple[object, list[dict], float]:
    """Choose a prior's strength among unfitted ``candidates`` (one per strength) by the run's folds and
    :func:`strength_rule`; the chosen candidate fitted on all of ``X, y``, a row per strength
    (``prior_strength``, ``cv_rms_3d``, ``cv_se``, ``chosen``) and the seconds of the final fit. The score of
    the chosen strength on the folds that chose it flatters it: :func:`nested_residuals` with the same rule
    gives the honest one."""
    each = [held_out_residuals(c, X, y, cv.folds, per_row=per_row, n_jobs=n_jobs) for c in candidates]
    best, table = strength_rows(strengths, [score(r) for r in each],
                                [rms_standard_error(ranked(r), cv.groups) for r in each])
    begin = time.perf_counter()
    fitted = clone(candidates[best]).fit(X, y, **(per_row or {}))
    return fitted, table, time.perf_counter() - begin


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
    within = [i for i in within_one_standard_error(scores, errors) if physical[i]]
    return min(within, key=lambda i: (sizes[i], scores[i], i)) if within else best


def _frozen(model, X, y, rows: dict):
    return model.frozen(X, y, **rows)



def choose_granularity(candidates: Sequence, granularities: Sequence[int], X, y, folds: list, *,
                       per_row: dict | None = None, score: Callable[[NDArray[np.float64]], float] | None = None,
                       n_jobs: int = 1) -> tuple[object, list[dict]]:
    """Choose among unfitted partitioned ``candidates`` (one per granularity) by cross-validation on ``folds``.

    A candidate is a partitioned model or any model that holds one (``regions_of``,
    is one (a hybrid with a partitioned residual). Returns the best candidate
    fitted on all of ``X, y`` (the first of equal scores) and a row per
    candidate: ``granularity``, ``cv_rms_3d`` (``score`` of its held-out
    residuals, default :func:`partcal.metrics.pooled_rms`), ``regions`` (of
    the fit on all the data), ``cv_regions`` (the fewest and most regions of
    the fits on the folds, which can be fewer: a partition merges regions that
    lack samples) and ``fit_seconds`` (the fit on all the data).

    The CV score of the chosen candidate is optimistic: the same folds chose
    it. :func:`nested_residuals` gives an honest one.
    """
    fold_models: list = []
    best, scores, fitted, seconds = select_by_cv(list(candidates), X, y, folds=folds, fold_models=fold_models,
                                                 per_row=per_row, score=score, n_jobs=n_jobs)
    table = [{"granularity": int(size), "cv_rms_3d": s, "regions": int(regions_of(f).partition_.n_regions),
              "cv_regions": fold_regions([regions_of(m) for m in folded]), "fit_seconds": t}
             for size, s, f, folded, t in zip(granularities, scores, fitted, fold_models, seconds)]
    return fitted[best], table


def select_granularity(model, X, y, grid, *, folds=5, random_state=0) -> tuple[object, list[dict]]:
    """Choose the octree depth or k-means region count of a :class:`~partcal.models.PartitionedErrorModel` by
    cross-validation.

    Parameters
    ----------
    model : PartitionedErrorModel
        The template; its partition's ``max_depth`` / ``n_regions`` is varied.
    X, y : array_like
        Inputs (mm or degrees) and errors ``(n, 3)`` mm.
    grid : iterable of int
        Candidate depths (octree) or region counts (k-means).
    folds : int or list of (train, test) index arrays
        Shuffled folds drawn with ``random_state``, or the folds themselves.

    Returns
    -------
    best : PartitionedErrorModel
        The candidate of lowest CV 3-D RMS (the first of equals), fitted on all of ``X, y``.
    table : list of dict
        A row per candidate (see :func:`choose_granularity`).
    """
    X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
    if isinstance(folds, int):
        check_int("select_granularity", "folds", folds, 2)
        folds = kfold_splits(len(X), folds, random_state)
    values = [int(v) for v in grid]
    return choose_granularity([model.with_granularity(v) for v in values], values, X, y, folds)


def measured_poses(m: Measurements) -> NDArray[np.intp]:
    """The pose of each row (:func:`partcal.metrics.pose_groups`): the same joint angles at the same payload.
    A configuration measured at two payloads is two poses, not a repeat: its rows differ by the sag."""
    return pose_groups(m.q_deg if m.payload_kg is None else np.column_stack([m.q_deg, m.payload_kg]))


@dataclass(frozen=True)
class CVPlan:
    """How a run cross-validates: the pose (group) of each identification row, the fold rule and the folds.

    ``inner(train)`` gives the folds of nested CV inside an outer training set:
    the same rule on its poses (leave-one-pose-out stays so; k folds become at
    most one per pose).
    """

    groups: NDArray[np.intp]
    rule: int | str
    folds: list
    seed: int
    grouped_by: str

    @classmethod
    def of(cls, config: "RunConfig", ident: Measurements) -> "CVPlan":
        if ident.groups is not None:
            groups, by = labels_as_groups(ident.groups), f"column {config.data_options.groups!r}"
        else:
            payload = " and payload" if ident.payload_kg is not None else ""
            groups, by = measured_poses(ident), f"joint angles within {HELD_TOLERANCE_DEG:g} degrees{payload}"
        rule = fold_rule(config.cv_folds, int(groups.max()) + 1)
        folds = grouped_splits(groups, rule, config.seed) if int(groups.max()) >= 1 else []
        return cls(groups, rule, folds, config.seed, by)

    @property
    def n_groups(self) -> int:
        return int(self.groups.max()) + 1

    def inner(self, train: NDArray[np.intp]) -> list:
        groups = labels_as_groups(self.groups[train])
        n = int(groups.max()) + 1
        if n < 2:
            return []
        return grouped_splits(groups, self.rule if self.rule == "leave_one_out" else fold_rule(self.rule, n), self.seed)

    def smallest_train(self, nested: bool = False) -> int:
        """Rows of the smallest training fold (of the inner folds with ``nested``); 0 if there is none."""
        return self._smallest_inner_train if nested else min((len(train) for train, _ in self.folds), default=0)

    @functools.cached_property
    def _smallest_inner_train(self) -> int:
        sizes = [len(inner) for train, _ in self.folds for inner, _ in self.inner(train) or [((), ())]]
        return min(sizes, default=0)

    def describe(self) -> str:
        """``'leave-one-pose-out over 16 poses (160 rows: ...)'``: what the output says of the folds."""
        n = len(self.groups)
        text = f"{fold_name(self.rule)} over {self.n_groups} poses"
        if n > self.n_groups:
            text += f" ({n} rows; the rows of one pose, by {self.grouped_by}, are held out together)"
        return text

    def to_dict(self) -> dict:
        return {"rule": fold_name(self.rule), "folds": len(self.folds), "poses": self.n_groups,
                "rows": len(self.groups), "grouped_by": self.grouped_by}


def choose_best(results: list, rank_by: str) -> str:
    """The name of the run's best model (``results``: :class:`~partcal.study.results.ModelResult`): the lowest
    validation RMS, or by CV the physical model with the fewest parameters within one standard error of the
    lowest CV score, else the lowest CV score (:func:`choose_simplest`)."""
    if rank_by == "validation":
        return min(results, key=lambda r: r.score(rank_by)).spec.name
    sizes = [r.effective_parameters if np.isfinite(r.effective_parameters) else np.inf for r in results]
    return results[choose_simplest([r.cv_rms_3d for r in results], [r.cv_se for r in results], sizes,
                                   [is_physical(r.model) for r in results])].spec.name


def rank_reason(config: "RunConfig", cv: CVPlan | None, physical: bool) -> str:
    """Why a run's best model won, in words: by the validation set, as the simplest physical model within one
    standard error of the lowest CV score, or as the lowest CV score (no physical model within). The score is
    the 3-D RMS of the position, or with ``rank_on: orientation`` the orientation's RMS angle."""
    part = "orientation RMS angle" if config.rank_on == "orientation" else "3-D RMS"
    if config.rank_by == "validation":
        return f"lowest {part} on the validation set {config.validation.name} (held out, never fitted)"
    folds = fold_name(cv.rule) if cv is not None else f"{config.cv_folds}-fold"
    how = ("(the same folds for every model, a pose's rows held out together; nested for lists of granularities or prior strengths)")
    if physical:
        return (f"physical model (kinematic, no data-driven residual) with the fewest parameters whose {folds} "
                f"cross-validated {part} on the identification set is within one standard error of the lowest {how}")
    return (f"lowest {folds} cross-validated {part} on the identification set, no physical model (kinematic, no "
            f"data-driven residual) being within one standard error of it {how}")
