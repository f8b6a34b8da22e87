"""A run on measurement types: plane contacts, fixed points, distances (and tracker points) in one file.

When a run's identification file has a ``measurement`` column (docs/data.md, "Measurement types"), its rows
are not 3-D errors and only kinematic models can learn from them: each kinematic entry is identified
from every type at once (:func:`partcal.calibration.stacked.identify_measurements`), cross-validated on
held-out rows of the same types (their residuals, mm of contact, coincidence or length), and scored on
the test sets: a measurements file by its residuals, a point CSV by the usual 3-D RMS, after a rigid fit
when the identification data fix no frame (no tracker points among them). What the data cannot
identify (a uniform scale, a plane's offset against the tool, the base frame of distances) is named
in the run's output, ``run --check`` and the report. A model that learns a 3-D error field (series,
partitioned, Gaussian process, a kinematic model's residual) is refused, naming it: such data carry
no error field.

The models are the same kinematic models: their files work with ``predict``, ``compensate``,
``export`` and the predictor unchanged.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import yaml
from numpy.typing import NDArray

from .. import __version__
from .._yamlio import load_yaml
from ..data.measurements import Measurements, read_measurements
from ..data.measurement_rows import has_measurement_column, read_cell, read_measurement_rows
from ..errors import DataError, PartcalError
from ..metrics import pooled_rms
from ..calibration.tracker_points import TRACKER_FRAME
from ..models.kinematic import KinematicModel
from ..calibration.cv import fold_rows, FOLDS, held_out, SCALE_CHOICE, scale_free, strength_table, weighted_residuals
from ..calibration.parameters import nominal_identification
from ..calibration.checks import check_measured
from ..calibration.prior import strength_note
from ..calibration.measurement import END_TYPE, MeasurementRows
from ..calibration.registry import MEASUREMENT_TYPES, built_types
from ..calibration.stacked import freedom, observability, type_residuals
from ..robot.frames import kabsch
from ..robot.kinematics import Robot
from .config import ModelSpec, RunConfig, SpreadOptions
from .fitting import SLOW_SECONDS, FoldLines
from .outputs import check_writable, replace_folder
from .persist import save_model


def identification_files(config: RunConfig) -> list[Path]:
    """The run's identification files: one, or the list ``data.identification: [A, B, ...]``."""
    return [config.identification, *config.data_options.more_identification]


def uses_measurement_types(config: RunConfig) -> bool:
    """Whether the run identifies from measurement types: an identification file has a ``measurement`` column.
    A list of identification files must hold one (several point CSVs are one file's rows: join them)."""
    files = identification_files(config)
    measurements = any(has_measurement_column(f, config.data_options.format) for f in files)
    if len(files) > 1 and not measurements:
        config.fail("data.identification", "a list of identification files is for measurement types (files with "
                                           "a 'measurement' column, and point CSVs beside them); these are all point "
                                           "CSVs: join them into one file")
    if not measurements and config.data_options.cell is not None:
        config.fail("data.cell", "the cell's planes and points are read by runs on measurement types; no "
                                     "identification file here has a 'measurement' column (docs/data.md, 'Measurement "
                                     "types'): remove it, or identify from a measurements file")
    return measurements


def point_rows(m: Measurements, source: str) -> MeasurementRows:
    """A point CSV's rows as rows of type ``point``: the primary target's, then each further target's (column
    ``target``), the measured orientation on the primary rows. Their lines are data-row numbers (the reader has
    refused whatever a line would be named for)."""
    n = len(m)
    names = m.target_names
    x = np.vstack([m.measured_of(t) for t in names])
    numbers = {"x_meas": x[:, 0], "y_meas": x[:, 1], "z_meas": x[:, 2]}
    if m.has_orientation:
        angles = np.vstack([m.measured_orientation_deg, np.full((n * (len(names) - 1), 3), np.nan)])
        numbers.update({c: angles[:, k] for k, c in enumerate(("rx_meas", "ry_meas", "rz_meas"))})
    texts = {"target": tuple(t if k else "" for k, t in enumerate(names) for _ in range(n))} if len(names) > 1 else {}
    ids = tuple(f"{i + 1}" + (f"@{t}" if k else "") for k, t in enumerate(names) for i in range(n))
    payload = None if m.payload_kg is None else np.tile(m.payload_kg, len(names))
    return MeasurementRows(np.tile(m.q_deg, (len(names), 1)), ("point",) * (n * len(names)), ids,
                tuple(range(1, n + 1)) * len(names), source, numbers, texts, payload)


def joined(parts: list[MeasurementRows], names: list[str] | None = None) -> MeasurementRows:
    """The rows of several files as one set: ids (and the ``to`` that name them) prefixed by their file's stem
    (or by ``names``), so that each file's references stay its own; a ``to`` naming no row of its own file names
    the row of that id in another (a ballbar's poses in one file, its distances in another), refused naming file
    and line when several have it. Columns a file lacks are empty on its rows."""
    if len(parts) == 1:
        return parts[0]
    names = [Path(p.source).stem for p in parts] if names is None else names
    numbers = {c for p in parts for c in p.numbers}
    texts = {c for p in parts for c in p.texts}
    out_numbers = {c: np.concatenate([p.numbers.get(c, np.full(len(p), np.nan)) for p in parts]) for c in numbers}
    out_texts = {c: tuple(v for p in parts for v in p.texts.get(c, ("",) * len(p))) for c in texts if c != "to"}
    ids = tuple(f"{name}:{i}" for name, p in zip(names, parts) for i in p.ids)
    if "to" in texts:
        to = []
        for name, p in zip(names, parts):
            own = set(p.ids)
            for r, t in enumerate(p.texts.get("to", ("",) * len(p))):
                elsewhere = [other for other, q in zip(names, parts) if q is not p and t in q.ids]
                if t in own or not elsewhere:
                    to.append(f"{name}:{t}" if t in own else t)
                elif len(elsewhere) == 1:
                    to.append(f"{elsewhere[0]}:{t}")
                else:
                    raise DataError(f"{p.where(r)}: column 'to': {t!r} names no row of its file and a row of "
                                    f"{len(elsewhere)} others ({', '.join(elsewhere)}): give the rows ids of their "
                                    "own")
        out_texts["to"] = tuple(to)
    payloads = [p.payload_kg for p in parts]
    payload = None if all(x is None for x in payloads) else np.concatenate(
        [x if x is not None else np.zeros(len(p)) for x, p in zip(payloads, parts)])
    return MeasurementRows(np.vstack([p.q_deg for p in parts]), tuple(k for p in parts for k in p.types), ids,
                tuple(line for p in parts for line in p.lines), ", ".join(p.source for p in parts), out_numbers,
                out_texts, payload, tuple(s for p in parts for s in (p.sources or (p.source,) * len(p))))


def beside_identification(rows: MeasurementRows, test: MeasurementRows) -> tuple[MeasurementRows, NDArray[np.intp]]:
    """A types test set among the identification rows, and the indices of its rows there: the types are built on
    both (a test set need not hold what an identification needs of its rows, such as three touches per plane or
    the point a visited one is tied to), and the test rows' residuals picked out."""
    both = joined([rows, test], names=["identification", "test"])
    return both, np.arange(len(rows), len(both))


@dataclass(frozen=True, eq=False)
class MeasurementRunData:
    """What a measurement run reads: the identification rows, the cell's cell, the test sets (measurements files or
    point CSVs), the robot, and the kinematic entries."""

    rows: MeasurementRows
    cell: dict
    tests: dict
    robot: Robot
    models: tuple[ModelSpec, ...]
    descriptions: dict
    fixes_frame: bool


def prepare_measurement_run(config: RunConfig) -> MeasurementRunData:
    """Read and check everything a measurement run needs (all of ``run --check``); nothing fitted."""
    robot = config.nominal_robot
    if robot is None:
        config.fail("robot", f"the identification file {config.identification} holds measurement types, whose "
                             "residuals come from the robot's forward kinematics: name a robot")
    opts = config.data_options
    _refuse_unused(config)
    cell = read_cell(opts.cell) if opts.cell is not None else {}
    if opts.frame == "tracker":             # the tracker's pose is the point type's unknowns, fitted with the robot
        cell = {**cell, TRACKER_FRAME: True}
    parts = []
    _distinct_stems(config)
    files = [f for f in identification_files(config) if has_measurement_column(f, opts.format)]
    ids = {f: read_measurement_rows(f, robot, opts.format).ids for f in files} if len(files) > 1 else {}
    for path in identification_files(config):
        if path in files:
            elsewhere = {i for other, own in ids.items() if other != path for i in own}
            parts.append(read_measurement_rows(path, robot, opts.format, cell or None, ids_elsewhere=elsewhere))
            check_measured(parts[-1])
        else:
            parts.append(point_rows(read_measurements(path, robot, fmt=opts.format, frame=opts.frame,
                                                      plausibility=opts.plausibility), str(path)))
    rows = joined(parts)
    measurements = built_types(rows, cell)
    for i, spec in enumerate(config.models):
        problem = _entry_problem(spec, measurements)
        if problem is not None:
            config.fail(f"models[{i}]", problem)
        if len(spec.strengths) > 1 and _scale_free(spec, robot, rows, cell):
            config.fail(f"models[{i}].prior_strength", SCALE_CHOICE)
    tests = {}
    for name, path in config.tests.items():
        if has_measurement_column(path, opts.format):
            tests[name] = read_measurement_rows(path, robot, opts.format, cell or None)
            check_measured(tests[name])
            built_types(beside_identification(rows, tests[name])[0], cell)
        else:
            tests[name] = read_measurements(path, robot, fmt=opts.format, name=name, frame=opts.frame,
                                            rows=opts.rows.get(name), plausibility=opts.plausibility)
    return MeasurementRunData(rows, cell, tests, robot, config.models,
                     {k.name: f"{k.describe()}; noise {k.noise:g} {k.unit}" for k in measurements},
                     any(m.fixes_frame for m in measurements))


def _distinct_stems(config: RunConfig) -> None:
    """Refuse two identification files of one name: the rows of a list are named ``<file stem>:<id>``
    (:func:`joined`), so one file listed twice would count its rows twice and two files of one stem would give
    their rows the same ids (and a distance's ``to`` two rows)."""
    seen: dict[str, Path] = {}
    for path in identification_files(config):
        other = seen.setdefault(path.stem, path)
        if other is not path:
            what = "is listed twice" if other.resolve() == path.resolve() else f"has the name of {other}"
            config.fail("data.identification", f"{path} {what}: each file of the list names its rows "
                                               f"'{path.stem}:<id>', so its rows would be counted twice or their "
                                               "ids taken for another file's: list each file once, with a name "
                                               "of its own")


def _refuse_unused(config: RunConfig) -> None:
    """Refuse, naming the key, what a measurement run would otherwise ignore: settings of point runs it has no use for,
    and row subsets of its measurements files (read whole: a distance's ``to`` names rows by id). A point test set's
    ``rows``/``every`` apply as in a point run."""
    opts = config.data_options
    unused = {"data.validation": config.validation is not None, "verify": config.virtual_robot is not None,
              "predict": config.predict != "position", "rank_by": config.rank_by != "cv",
              "data.groups": opts.groups is not None, "spread": config.spread != SpreadOptions(),
              "dask": config.dask_address is not None,
              "registration": opts.tool_mm is not None or not opts.fit_tool}
    for key, given in unused.items():
        if given:
            config.fail(key, "a run on measurement types does not use it (it identifies kinematic models of tool "
                             "positions, ranks them by cross-validation on the identification rows and scores the "
                             "test sets; docs/config.md, 'Runs on measurement types'): remove it")
    for name in opts.rows:
        if name == "identification" or has_measurement_column(config.tests[name], opts.format):
            where = "data.identification" if name == "identification" else f"data.tests.{name}"
            config.fail(where, "row subsets (rows:, every:) apply to point CSVs; a measurements file is read "
                               "whole (a distance's 'to' names rows by id): split the file instead")


def _scale_free(spec: ModelSpec, robot: Robot, rows: MeasurementRows, cell: dict) -> bool:
    """Whether the rows leave the scale free for this entry (:func:`~partcal.calibration.cv.scale_free`)."""
    model = spec.with_robot(robot).build(None)
    errors, parametrization = model.joint_settings(robot)
    return scale_free(robot, rows, cell, base=bool(model.base), tool=bool(model.tool), rcond=float(model.rcond),
                      errors=errors, payload_kg=_read_payload(rows), parametrization=parametrization)


def _entry_problem(spec: ModelSpec, measurements: list) -> str | None:
    """Why an entry cannot learn from the types present (None: it can)."""
    present = ", ".join(k.name for k in measurements)
    if spec.estimator_class is not KinematicModel:
        return (f"model {spec.name!r} (kind {spec.kind!r}) learns a 3-D error field from tracker points; the "
                f"identification file holds measurement types ({present}), which carry no error field: only "
                "kinematic models learn from them")
    if spec.residual is not None:
        return (f"model {spec.name!r}: its residual model learns a 3-D error field from tracker points; the "
                f"identification file holds measurement types ({present}): fit the kinematic model alone")
    for key in ("all_targets", "use_orientation"):
        if spec.params.get(key):
            return (f"model {spec.name!r}: {key} is for point runs; in a run on measurement types every kinematic "
                    "entry reads the point rows' further targets (column target) and orientation (rx_meas, "
                    "ry_meas, rz_meas) by itself: leave the key out")
    return None


def check_measurement_run(config: RunConfig, source: str | Path) -> str:
    """``partcal run --check`` of a measurement run: the data read and checked, what each type cannot identify
    named (judged at the nominal robot, on consistent data); nothing fitted."""
    data = prepare_measurement_run(config)
    check_folds(config, data)
    check_writable(config.output, config.inputs(), create=False)
    measurements = "; ".join(data.descriptions.values())
    lines = [f"{source}: OK: {len(data.models)} kinematic models; identification: {measurements}; "
             f"cross-validation: {_folds(config, data.rows)} folds; nothing fitted"]
    for spec in data.models:
        notes, held = entry_observability(spec, data)
        lines.append(f"{spec.name}: held nominal (not identifiable from these rows): {', '.join(held) or 'none'}")
        lines += [f"  {note}" for note in notes]
    return "\n".join(lines)


def _settings(spec: ModelSpec, data: MeasurementRunData) -> dict:
    """What an entry's identification is told of its model (:func:`~partcal.calibration.stacked.observability`'s
    keywords), without fitting."""
    model = spec.with_robot(data.robot).build(None)
    errors, parametrization = model.joint_settings(data.robot)
    return dict(base=bool(model.base), tool=bool(model.tool), rcond=float(model.rcond), errors=errors,
                parametrization=parametrization, payload_kg=_read_payload(data.rows))


def entry_observability(spec: ModelSpec, data: MeasurementRunData) -> tuple[list[str], list[str]]:
    """What an entry cannot identify from the run's rows, without fitting (the rank rule at the nominal
    robot, on consistent data): the notes in words, and the parameters held nominal."""
    model = spec.with_robot(data.robot).build(None)
    errors, parametrization = model.joint_settings(data.robot)
    prior = model.prior_at(data.robot, 1.0)         # any strength > 0 holds the same parameters
    return observability(data.robot, data.rows, data.cell, base=bool(model.base), tool=bool(model.tool),
                         rcond=float(model.rcond), errors=errors, parametrization=parametrization, prior=prior)


# ---------------------------------------------------------------------- fitting and scoring
@dataclass
class MeasurementModelResult:
    """One kinematic entry of a measurement run: the model, its residuals on the data, its cross-validated ones."""

    spec: ModelSpec
    model: KinematicModel
    fit_seconds: float
    fit_rms: dict
    cv_rms: dict
    cv_pooled: float
    tests: dict
    notes: list = field(default_factory=list)
    cv_residuals: dict = field(default_factory=dict)      # type -> held-out residuals (mm), every fold
    prior_strength: list | None = None   # a list of prior strengths: each one's CV score (run's folds), chosen marked


@dataclass
class MeasurementRunResult:
    """A finished measurement run."""

    config: RunConfig
    data: MeasurementRunData
    models: list
    uncompensated: dict
    best: str
    seconds: float


def _folds(config: RunConfig, rows: MeasurementRows) -> int:
    measuring = int(np.sum(np.asarray(rows.types, dtype=object) != END_TYPE))
    k = FOLDS if config.cv_folds in ("auto", None) else config.cv_folds
    return min(measuring, k if isinstance(k, int) else measuring)


def check_folds(config: RunConfig, data: MeasurementRunData) -> None:
    """Refuse, naming ``cv_folds``, folds whose training rows the types refuse (a plane left fewer touches than
    its unknowns, a point one visit), before anything is fitted."""
    folds = _folds(config, data.rows)
    for k, (train, _) in enumerate(fold_rows(data.rows, config.seed, folds)):
        try:
            built_types(train, data.cell)
        except DataError as exc:
            config.fail("cv_folds", f"cross-validation fold {k + 1} of {folds} (random, seed {config.seed}) holds "
                                    f"out rows without which the rest are refused: {exc}; use fewer folds, or more "
                                    "rows of that feature")
        for spec in data.models:          # a fold's fit must leave a residual to give the entry a spread
            residuals, free = freedom(data.robot, train, data.cell, **_settings(spec, data))
            if residuals <= free:
                config.fail("cv_folds", f"cross-validation fold {k + 1} of {folds}: its training rows give "
                                        f"{residuals} residuals for the {free} parameters they identify for model "
                                        f"{spec.name!r}: no residual is left for a spread; use fewer folds or "
                                        "more rows")


def _rms(values: NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(values**2))) if values.size else float("nan")


def fit_entry(spec: ModelSpec, data: MeasurementRunData, seed: int, folds: int,
              say: Callable[[str], None] | None = None) -> MeasurementModelResult:
    """Fit one entry on every row, cross-validate it on random folds of the measuring rows, score the tests.
    ``say`` hears of each fold once the entry has taken :data:`~partcal.study.fitting.SLOW_SECONDS`.

    A list of prior strengths (``prior_strength: [..]`` or ``auto``) is chosen on the run's folds
    (:func:`~partcal.calibration.cv.strength_table`: the strongest within one standard error of the lowest
    weighted RMS), the chosen strength fitted on every row; the entry's CV figure is then nested: each fold's
    training rows choose again on folds of their own (the model's choice,
    :meth:`KinematicModel.fit <partcal.models.kinematic.KinematicModel.fit>`)."""
    def fitted(rows: MeasurementRows, strength: float | None = None) -> KinematicModel:
        model = spec.with_robot(data.robot).build(seed, strength=strength)
        return model.fit(rows.q_deg, None, rows=rows, cell=data.cell)

    unfitted = spec.with_robot(data.robot).build(seed)
    errors, parametrization = unfitted.joint_settings(data.robot)
    kw = dict(errors=errors, parametrization=parametrization, payload_kg=_read_payload(data.rows))
    cuts = fold_rows(data.rows, seed, folds)
    strengths, table = spec.strengths, None
    start = time.process_time()
    if len(strengths) > 1:
        best, table = strength_table(lambda s, rows: fitted(rows, s).identification_, strengths, data.robot,
                                     data.rows, data.cell, cuts, **kw)
        start = time.process_time()
        model = fitted(data.rows, strengths[best])
    else:
        model = fitted(data.rows)
    seconds = time.process_time() - start
    fit_rms = dict(model.identification_.target_rms_mm)          # each type's RMS on the rows it was fitted on
    began = time.perf_counter()

    def before(k: int) -> None:
        if say is not None and time.perf_counter() - began + seconds > SLOW_SECONDS:
            say(f"{spec.name}: cross-validation fold {k + 1}/{folds} ({time.perf_counter() - began:.0f} s)")

    cv = held_out(lambda rows: fitted(rows).identification_, data.robot, data.rows, data.cell, cuts,
                  before=before, **kw)[0]
    tests = {name: _score(model, test, data) for name, test in data.tests.items()}
    notes = model.fit_notes() + ([strength_note(table, "the run's cross-validation", "cv_weighted_rms_mm",
                                                "CV weighted RMS")] if table else []) + _downweighted(model)
    return MeasurementModelResult(spec, model, seconds, fit_rms, {k: _rms(r) for k, r in cv.items()},
                            _weighted_rms(cv, data.cell), tests, notes, cv, prior_strength=table)


def _weighted_rms(residuals: dict, cell: dict) -> float:
    """One figure of residuals of several types (:func:`~partcal.calibration.cv.weighted_residuals`), RMS; mm of a
    tracker's 0.02 mm noise."""
    every = weighted_residuals(residuals, cell)
    return float(np.sqrt(np.mean(every**2))) if every.size else float("nan")


def _read_payload(rows: MeasurementRows):
    """The payload per row as a fit on ``rows`` reads it: the rows' own when they differ, else none (at one
    payload a compliance is not identified: KinematicModel's fit does the same)."""
    payload = rows.payload_kg
    return payload if payload is not None and np.ptp(payload) > 0 else 0.0


def _score(model: KinematicModel, test, data: MeasurementRunData) -> dict:
    """A test set's figures: a measurements file's residual RMS per type; a point CSV's 3-D RMS (after a rigid fit when
    the identification data fix no frame)."""
    if isinstance(test, MeasurementRows):
        both, only = beside_identification(data.rows, test)
        placed: list[str] = []
        residuals = type_residuals(data.robot, both, data.cell, model.identification_, only=only,
                                   errors=model.joint_errors_, parametrization=model.parametrization_,
                                   payload_kg=_read_payload(both), fitted_here=placed)
        return {"rms_by_type": {k: _rms(r) for k, r in residuals.items()},
                **({"fitted_on_test": sorted({n.split(".")[0] for n in placed})} if placed else {})}
    predicted = test.nominal_mm + model.predict(test.q_deg)
    return _point_figures(predicted, test, data.fixes_frame)


def _point_figures(predicted: NDArray[np.float64], test: Measurements, fixes_frame: bool) -> dict:
    if fixes_frame:
        return {"rms_3d": pooled_rms(test.measured_mm - predicted), "rigid_fit": False}
    rot, t = kabsch(predicted, test.measured_mm)
    return {"rms_3d": pooled_rms(test.measured_mm - (predicted @ rot.T + t)), "rigid_fit": True}


def _downweighted(model: KinematicModel) -> list[str]:
    """A note per row the robust loss weighed below one half, naming its file and line."""
    robust = model.identification_.robust
    if robust is None:
        return []
    return [f"{d['where']}: down-weighted by the {robust['loss']} loss (residual {d['residual_mm']:.4g} "
            f"{MEASUREMENT_TYPES[d['type']].unit}, weight {d['weight']:.3g})" for d in robust["downweighted"]]


def _nominal_cv(data: MeasurementRunData, seed: int, folds: int) -> float:
    """The nominal robot's weighted RMS on the same held-out rows (the cell's unknowns placed on the rows, the
    robot as it is): what no calibration leaves, the figure a calibration must beat."""
    table = nominal_identification(data.robot)
    cv = held_out(lambda rows: table, data.robot, data.rows, data.cell, fold_rows(data.rows, seed, folds),
                  payload_kg=_read_payload(data.rows))[0]
    return _weighted_rms(cv, data.cell)


def _worse_than_none(r: "MeasurementModelResult", uncompensated: dict) -> list[str]:
    """Notes of a model that does worse than no calibration: on held-out rows, or on a test set of points."""
    notes = []
    if r.cv_pooled >= uncompensated["cv_weighted_rms_mm"]:
        notes.append(f"worse than none: held out, it leaves {r.cv_pooled:.4g} mm (weighted), the nominal robot "
                     f"{uncompensated['cv_weighted_rms_mm']:.4g}: these rows do not calibrate it (too few, or the "
                     "notes above)")
    for name, figures in r.tests.items():
        if "rms_3d" in figures and name in uncompensated and figures["rms_3d"] >= uncompensated[name]["rms_3d"]:
            notes.append(f"worse than none on test set {name!r}: {figures['rms_3d']:.4g} mm against "
                         f"{uncompensated[name]['rms_3d']:.4g} uncompensated")
    return notes


def run_measurements(config: RunConfig, progress: Callable[[int, int, str], None] | None = None) -> MeasurementRunResult:
    """Fit, cross-validate and score every kinematic entry of a measurement run; the best by cross-validation."""
    start = time.perf_counter()
    data = prepare_measurement_run(config)
    check_folds(config, data)
    folds = _folds(config, data.rows)
    if progress:
        progress(0, len(data.models), f"cross-validation: {folds} random folds of the identification rows")
    results = []
    for i, spec in enumerate(data.models):
        try:
            results.append(fit_entry(spec, data, config.seed, folds, FoldLines() if progress else None))
        except PartcalError as exc:
            raise type(exc)(f"model {spec.name!r}: {exc}") from None
        if progress:
            progress(i + 1, len(data.models), f"{spec.name}: cross-validated residual "
                                             f"{results[-1].cv_pooled:.4f} mm (weighted)")
    uncompensated = {name: _point_figures(test.nominal_mm, test, data.fixes_frame)
                     for name, test in data.tests.items() if isinstance(test, Measurements)}
    uncompensated["cv_weighted_rms_mm"] = _nominal_cv(data, config.seed, folds)
    for r in results:
        r.notes += _worse_than_none(r, uncompensated)
    best = min(results, key=lambda r: r.cv_pooled).spec.name
    return MeasurementRunResult(config, data, results, uncompensated, best, time.perf_counter() - start)


# ---------------------------------------------------------------------- writing
def measurement_run_metrics(result: MeasurementRunResult) -> dict:
    """metrics.json of a measurement run."""
    data = result.data
    folds = _folds(result.config, data.rows)
    return {"partcal_version": __version__, "run": result.config.name, "seed": result.config.seed,
            "cv": {"rule": f"{folds} random folds of the measuring rows", "folds": folds},
            "measurement_types": dict(data.descriptions),
            "frame_fixed": data.fixes_frame, "uncompensated": result.uncompensated, "best": result.best,
            "seconds": round(result.seconds, 3),
            "models": {r.spec.name: {"fit_rms_by_type": r.fit_rms, "cv_rms_by_type": r.cv_rms,
                                     "cv_weighted_rms_mm": r.cv_pooled, "tests": r.tests,
                                     "fit_seconds": round(r.fit_seconds, 4), "notes": r.notes,
                                     **({"prior_strength": r.prior_strength} if r.prior_strength else {}),
                                     **r.model.run_summary()}
                       for r in result.models}}


def write_measurement_run(result: MeasurementRunResult, render: Callable | None = None) -> Path:
    """Write a measurement run's outputs atomically (metrics.json, model files and the files each type writes beside
    them, such as a camera's ``camera_info`` YAML, resolved config, report)."""
    cfg = result.config

    def fill(folder: Path) -> None:
        (folder / "models").mkdir()
        for r in result.models:
            save_model(r.model, folder / "models" / f"{r.spec.slug}.json", name=r.spec.name, robot=result.data.robot,
                       extra={"cv_weighted_rms_mm": r.cv_pooled, "fit_seconds": round(r.fit_seconds, 4),
                              "seed": cfg.seed, "run": cfg.name, **_cell_field(cfg)})
            table = getattr(r.model, "identification_", None)
            for name in (n for n in result.data.descriptions if n in MEASUREMENT_TYPES and table is not None):
                for filename, text in MEASUREMENT_TYPES[name].files(result.data.cell, table.names, table.value).items():
                    (folder / "models" / f"{r.spec.slug}_{filename}").write_text(text)
        (folder / "metrics.json").write_text(json.dumps(measurement_run_metrics(result), indent=1) + "\n")
        resolved = {"partcal_version": __version__, **cfg.resolved()}
        (folder / "config.resolved.yaml").write_text(yaml.safe_dump(resolved, sort_keys=False))
        if render is not None:
            render(result, folder)

    replace_folder(cfg.output, fill)
    return cfg.output


def _cell_field(config: RunConfig) -> dict:
    """The cell file's content as the model file keeps it (``fit.cell``: what partcal check and update read rows of
    measurement types against); nothing when the run reads no cell."""
    if config.data_options.cell is None:
        return {}
    data, _ = load_yaml(config.data_options.cell)
    return {"cell": json.loads(json.dumps(data or {}, default=float))}


def _figure(t: dict) -> str:
    """A test set's figure as the table prints it: a point set's 3-D RMS, a measurements file's residual RMS per type."""
    if "rms_3d" in t:
        return f"{t['rms_3d']:.4f}" + (" (rigid)" if t.get("rigid_fit") else "")
    return ", ".join(f"{k} {v:.4f}" for k, v in t["rms_by_type"].items())


def measurement_run_table(result: MeasurementRunResult) -> str:
    """The lines a measurement run prints: per model the fit's and the held-out residuals of each type and the
    test sets' figures, then what the data cannot identify."""
    lines = []
    measurements = list(result.data.descriptions)
    tests = list(result.data.tests)
    header = ["model", *(f"fit {k}" for k in measurements), *(f"CV {k}" for k in measurements), *tests]
    rows = []
    if result.uncompensated:
        rows.append(["uncompensated", *([""] * (2 * len(measurements))),
                     *(_figure(result.uncompensated[t]) if t in result.uncompensated else "" for t in tests)])
    for r in result.models:
        rows.append([r.spec.name + (" *" if r.spec.name == result.best else ""),
                     *(f"{r.fit_rms.get(k, float('nan')):.4f}" for k in measurements),
                     *(f"{r.cv_rms.get(k, float('nan')):.4f}" for k in measurements), *(_figure(r.tests[t]) for t in tests)])
    widths = [max(len(str(x)) for x in col) for col in zip(header, *rows)]
    for row in [header, *rows]:
        lines.append("  ".join(str(c).ljust(w) for c, w in zip(row, widths)))
    others = [f"{k} in {MEASUREMENT_TYPES[k].unit}" for k in measurements
              if k in MEASUREMENT_TYPES and MEASUREMENT_TYPES[k].unit != "mm"]
    lines.append(f"residuals in mm{' (' + ', '.join(others) + ')' if others else ''} (RMS); * best by "
                 "cross-validation" + (
        "; test sets of points scored after a rigid fit (the identification data fix no frame)"
        if not result.data.fixes_frame and any(isinstance(t, Measurements) for t in result.data.tests.values())
        else ""))
    common = [n for n in dict.fromkeys(result.models[0].notes if result.models else [])
              if all(n in r.notes for r in result.models)]
    lines += [f"note: {n}" for n in common]
    lines += [f"note: {r.spec.name}: {n}" for r in result.models for n in dict.fromkeys(r.notes) if n not in common]
    return "\n".join(lines)


__all__ = ["uses_measurement_types", "prepare_measurement_run", "check_measurement_run", "run_measurements", "write_measurement_run", "measurement_run_metrics",
           "measurement_run_table", "MeasurementRunResult", "MeasurementModelResult"]
