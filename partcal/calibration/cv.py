"""Cross-validation on rows of measurement types, and a prior's strength chosen by it.

Rows of plane touches, fixed points and distances have no poses to group and no order to keep: the
measuring rows are cut into random folds (:func:`fold_rows`; a distance's other end comes along as an
end), each held-out row is scored by its own type's residual with the planes and points as the training
rows fitted them (:func:`~partcal.calibration.stacked.type_residuals`), and the types are put on one scale
by their stated noise (:func:`weighted_residuals`: millimetres of a 0.02 mm tracker, as the fit weighs
them). A measurement run (:mod:`partcal.study.measurement_run`) cross-validates its entries this way on its folds;
:meth:`KinematicModel.fit <partcal.models.kinematic.KinematicModel.fit>` on types chooses a list of prior
strengths this way on :data:`FOLDS` folds of its own (:func:`strength_table`), and a measurement run chooses
the same way on the run's folds.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ..metrics import rms_standard_error
from .parameters import Identification
from .measurement import END_TYPE, REFERENCE_NOISE_MM, SCALE, MeasurementRows
from .registry import MEASUREMENT_TYPES
from .stacked import type_residuals, observability
from .prior import strength_rows

FOLDS = 5
"""Cross-validation folds on types (a run's ``cv_folds: auto``; a model's own choice of a prior's strength)."""


SCALE_CHOICE = ("a list of strengths cannot be chosen on these rows: nothing here measures a length, and held-out "
                "residuals (lengths) fall as the robot shrinks, so cross-validation prefers the weakest prior (on a "
                "virtual UR10, 800 touches of three unknown planes: 36 mm against the truth, docs/models.md); give "
                "prior_strength one number, or measure a length (a plane's spacing_mm, a point's distance_mm or "
                "known_mm, a distance, tracker points)")
"""Why a list of prior strengths is refused on rows that leave the scale free (:func:`scale_free`)."""


def scale_free(robot, rows: MeasurementRows, cell: dict, **kw) -> bool:
    """Whether the rows leave a uniform scale of the robot free (nothing measures a length:
    :func:`~partcal.calibration.stacked.observability` names :data:`~partcal.calibration.measurement.SCALE`). Then no
    cross-validation of these rows can choose a prior's strength (:data:`SCALE_CHOICE`). ``kw``: as
    :func:`~partcal.calibration.stacked.observability`, without a prior."""
    notes = observability(robot, rows, cell, **kw)[0]
    return bool(notes) and notes[0].startswith(SCALE)


def measuring(rows: MeasurementRows) -> NDArray[np.intp]:
    """The indices of the rows that measure something (not the ends of distances alone)."""
    return np.flatnonzero(np.asarray(rows.types, dtype=object) != END_TYPE)


def subset(rows: MeasurementRows, keep: NDArray[np.intp]) -> MeasurementRows:
    """Rows ``keep`` and the rows their distances refer to (those as ends alone, type ``pose``)."""
    where = {name: i for i, name in enumerate(rows.ids)}
    keep = np.unique(keep)
    to = rows.texts.get("to", ("",) * len(rows))
    needed = {where[to[i]] for i in keep if to[i] in where} - set(keep.tolist())
    every = np.array(sorted(set(keep.tolist()) | needed), dtype=np.intp)
    out = rows.take(every)
    measurements = tuple(END_TYPE if i in needed else k for i, k in zip(every, out.types))
    return MeasurementRows(out.q_deg, measurements, out.ids, out.lines, out.source, out.numbers, out.texts, out.payload_kg,
                out.sources)


def fold_rows(rows: MeasurementRows, seed: int, folds: int) -> list[tuple[MeasurementRows, NDArray[np.intp]]]:
    """The measuring rows in ``folds`` random folds (drawn from ``seed``), each as (training rows, the ends their
    distances name coming along; the held-out rows' indices into ``rows``)."""
    every = measuring(rows)
    order = np.random.default_rng(seed).permutation(every)
    return [(subset(rows, np.setdiff1d(every, order[k::folds])), np.sort(order[k::folds])) for k in range(folds)]


def weighted_residuals(residuals: dict, cell: dict) -> NDArray[np.float64]:
    """Residuals of several types (type -> mm) on one scale: each divided by its type's noise and multiplied by
    :data:`~partcal.calibration.measurement.REFERENCE_NOISE_MM` (as the fit weighs them), concatenated in the dict's
    order."""
    noise = cell.get("noise") or {}
    parts = [np.asarray(r, dtype=float) * REFERENCE_NOISE_MM / noise.get(k, MEASUREMENT_TYPES[k].default_noise)
             for k, r in residuals.items()]
    return np.concatenate(parts) if parts else np.zeros(0)


def held_out(identified_on: Callable[[MeasurementRows], Identification], robot, rows: MeasurementRows, cell: dict, folds: list, *,
             errors=None, parametrization: str = "dh", payload_kg=0.0,
             before: Callable[[int], None] | None = None) -> tuple[dict, dict]:
    """Each type's held-out residuals (mm) over ``folds`` (:func:`fold_rows`), each fold's rows scored by the
    table ``identified_on(training rows)`` fitted, and the row of each residual (type -> indices into ``rows``).
    ``before(k)`` is called before fold ``k`` is fitted (progress)."""
    residuals: dict[str, list] = {}
    at: dict[str, list] = {}
    for k, (train, out) in enumerate(folds):
        if before is not None:
            before(k)
        rows_here: dict = {}
        for name, r in type_residuals(robot, rows, cell, identified_on(train), errors=errors,
                                      parametrization=parametrization, payload_kg=payload_kg, only=out,
                                      row_of=rows_here).items():
            residuals.setdefault(name, []).append(r)
            at.setdefault(name, []).append(rows_here[name])
    return ({name: np.concatenate(parts) for name, parts in residuals.items()},
            {name: np.concatenate(parts) for name, parts in at.items()})


def cv_score(residuals: dict, at: dict, cell: dict) -> tuple[float, float]:
    """The weighted RMS of held-out residuals (:func:`weighted_residuals`, mm) and its standard error over the
    rows (a row's residuals together: a point's three coordinates are one row's;
    :func:`~partcal.metrics.rms_standard_error`)."""
    weighted = weighted_residuals(residuals, cell)
    if not weighted.size:
        return float("nan"), float("nan")
    rows = np.concatenate([at[k] for k in residuals])
    groups = np.unique(rows, return_inverse=True)[1].ravel()
    return float(np.sqrt(np.mean(weighted**2))), rms_standard_error(weighted, groups)


def strength_table(identified_at: Callable[[float, MeasurementRows], Identification], strengths, robot, rows: MeasurementRows,
                   cell: dict, folds: list, **kw) -> tuple[int, list[dict]]:
    """Choose a prior's strength among ``strengths`` on ``folds`` of rows of measurement types: each strength's
    held-out weighted RMS (:func:`cv_score`; ``identified_at(strength, training rows)`` fits), the strongest
    within one standard error of the lowest (:func:`~partcal.calibration.prior.strongest_within`, the rule of a point
    run). Returns its index and a row per strength: ``prior_strength``, ``cv_weighted_rms_mm``, ``cv_se``,
    ``chosen``. ``kw``: as :func:`held_out`."""
    scores, errors = [], []
    for strength in strengths:
        score, se = cv_score(*held_out(lambda train, s=strength: identified_at(s, train), robot, rows, cell,
                                       folds, **kw), cell)
        scores.append(score)
        errors.append(se)
    return strength_rows(strengths, scores, errors, "cv_weighted_rms_mm")
