"""The model registry of a batch run: fit, evaluate, cross-validate, rank, verify.

Every model is fitted on the identification set, evaluated on every data set
and by cross-validation on the identification set, and ranked by its
cross-validated 3-D RMS (``rank_by: cv``: the physical model with the fewest
parameters within one standard error of the lowest, else the lowest) or by its 3-D RMS on a held-out validation set
(``rank_by: validation``); never by a test set. Every model is
cross-validated on the same folds, drawn once from the run seed, and the rows
of one pose (identical joint angles, or a group column) are always held out
together: leave-one-pose-out on few poses, 5 folds on more (``cv_folds``). A
model with a list of granularities is scored by nested cross-validation (the
granularity is chosen inside each outer training fold); a granularity no
inner fold can support is left out with a note. Models run in parallel with
joblib (``n_jobs``; a Dask cluster when the config gives its address); each
model's seed comes from the run seed and its name, so results depend neither
on ``n_jobs``, nor on the order in which jobs finish, nor on the model's place
in the list. With a virtual robot, compensation is verified end to end: the
compensated targets are commanded on the simulated true robot.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import logging
import sys
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from joblib import Parallel, delayed, parallel_config
from numpy.typing import NDArray

from ..data.measurements import Measurements, read_measurements
from ..data.registration import Registration, register_measurements, registered
from ..errors import ConfigError, DataError
from ..metrics import (choose_simplest, fold_name, fold_rule, grouped_splits, held_out_residuals, labels_as_groups,
                       nested_residuals, pooled_rms, pose_groups, repeat_scatter_mm, rms_standard_error, select_by_cv)
from ..models.bases import varying_inputs
from ..models.partitioned import fold_regions
from ..robot.description import load_robot
from ..robot.kinematics import Robot, flange_offset
from .config import ModelSpec, RunConfig
from .memory import check_memory
from .scoring import Outputs, verify_compensation

log = logging.getLogger(__name__)


@dataclass
class ModelResult:
    """One fitted model of a run with everything measured about it."""

    spec: ModelSpec
    model: object                       # any partcal error model (series, partitioned, GP, kinematic)
    fit_seconds: float                  # the final fit on the identification set, nothing else
    cv_rms_3d: float                    # on the run's shared folds; nested for granularity lists
    metrics: dict[str, dict]
    predictions: dict[str, NDArray[np.float64]]
    rms_ratio: float | None = None
    granularity: list[dict] | None = None
    compensation: dict[str, dict] = field(default_factory=dict)
    cv_seconds: float = 0.0             # cross-validation (and the granularity choice)
    nested: bool = False
    cv_regions: list[int] | None = None  # partitioned: [fewest, most] regions of the CV fold fits
    cv_se: float = float("nan")         # standard error of cv_rms_3d, over the identification poses
    effective_parameters: float = float("nan")   # what "simpler" means when two CV scores are close
    notes: list[str] = field(default_factory=list)   # fits on a bound and the like: warned, and in the report
    rank_on: str = "position"           # cv_rms_3d and cv_se are of the position (mm) or the orientation (mrad)

    def score(self, rank_by: str) -> float:
        """The number the run ranks by: the CV score, or the RMS on the validation set (3-D, mm; with ``rank_on:
        orientation`` the orientation's RMS angle, mrad)."""
        if rank_by == "cv":
            return self.cv_rms_3d
        validation = self.metrics["validation"]
        return validation["orientation"]["rms_angle"] if self.rank_on == "orientation" else validation["rms_3d"]

    @property
    def n_regions(self) -> int:
        part = partitioned_part(self.model)
        return part.partition_.n_regions if part is not None else 1


def partitioned_part(model):
    """The partitioned model in ``model``: itself, or the residual of a hybrid; None if there is none."""
    return model.regions_model()


@dataclass
class RunResult:
    config: RunConfig
    datasets: dict[str, Measurements]
    robot: Robot | None
    uncompensated: dict[str, dict]
    models: list[ModelResult]
    best: str
    seconds: float
    registrations: dict[str, Registration] = field(default_factory=dict)
    plan: "RunPlan | None" = None

    @functools.cached_property
    def design(self):
        """The observability of the identification set (:func:`partcal.study.plan.run_indices`; None without a
        robot), computed once for what ``partcal run`` prints and the report shows."""
        if self.robot is None:
            return None
        from .plan import run_indices

        return run_indices(self.robot, self.datasets["identification"].q_deg)

    @property
    def best_reason(self) -> str:
        """Which rule chose ``best``, in words (metrics.json, the report and the printed table say it)."""
        best = next(r for r in self.models if r.spec.name == self.best)
        return rank_reason(self.config, self.plan.cv if self.plan else None, best.model.is_physical())


def rank_reason(config: RunConfig, cv: "CVPlan | None", physical: bool) -> str:
    """Why a run's best model won, in words: by the validation set, as the simplest physical model within one
    standard error of the lowest CV score, or as the lowest CV score (no physical model within). The score is
    the 3-D RMS of the position, or with ``rank_on: orientation`` the orientation's RMS angle."""
    part = "orientation RMS angle" if config.rank_on == "orientation" else "3-D RMS"
    if config.rank_by == "validation":
        return f"lowest {part} on the validation set {config.validation.name} (held out, never fitted)"
    folds = fold_name(cv.rule) if cv is not None else f"{config.cv_folds}-fold"
    how = ("(the same folds for every model, a pose's rows held out together; nested for granularity lists)")
    if physical:
        return (f"physical model (kinematic, no data-driven residual) with the fewest parameters whose {folds} "
                f"cross-validated {part} on the identification set is within one standard error of the lowest {how}")
    return (f"lowest {folds} cross-validated {part} on the identification set, no physical model (kinematic, no "
            f"data-driven residual) being within one standard error of it {how}")


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
    def of(cls, config: RunConfig, ident: Measurements) -> "CVPlan":
        if ident.groups is not None:
            groups, by = labels_as_groups(ident.groups), f"column {config.data_options.groups!r}"
        else:
            payload = " and payload" if ident.payload_kg is not None else ""
            groups, by = measured_poses(ident), f"identical joint angles{payload}"
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


@dataclass(frozen=True)
class RunPlan:
    """What a run will fit: its cross-validation, the entries it can fit (granularities that no fold
    supports left out), the notes about what was left out, and the repeat scatter of the data (mm)."""

    cv: CVPlan
    models: tuple[ModelSpec, ...]
    notes: tuple[str, ...] = ()
    repeat_scatter_mm: float | None = None


def model_seed(run_seed: int, name: str) -> int:
    """A model's seed: from the run's seed and the model's name, never from its place in the list.

    >>> model_seed(0, "GP(AI)") == model_seed(0, "GP(AI)") != model_seed(1, "GP(AI)")
    True
    """
    digest = int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:8], "little")
    return int(np.random.SeedSequence([run_seed, digest]).generate_state(1)[0])


def load_datasets(config: RunConfig) -> tuple[dict[str, Measurements], Robot | None, dict[str, Registration]]:
    """Read the identification and test sets (all with the same joints), in the base frame.

    The run's format and row subsets apply to every file. With ``frame:
    tracker`` the tracker frame (and the tool offset) is registered on the
    identification set and carried to every test set, except those measured
    from their own tracker position; the returned robot then carries the
    registered tool, and the registrations are returned by data set name.
    """
    opts = config.data_options
    robot = load_robot(config.robot) if config.robot else None

    def read(name: str, path) -> Measurements:
        m = read_measurements(path, robot, name=name, fmt=opts.format, rows=opts.rows.get(name), frame=opts.frame,
                              plausibility=opts.plausibility, group_column=opts.groups if name == "identification"
                              else None)
        poses = int(measured_poses(m).max()) + 1
        if poses < len(m):
            log.warning("%s (%s): %d rows measure %d distinct poses (identical joint angles%s): repeated "
                        "measurements%s", path, name, len(m), poses, " and payload" if m.payload_kg is not None else "",
                        "; cross-validation holds out a pose's rows together" if name == "identification" else "")
        return m

    data = {"identification": read("identification", config.identification)}
    n = data["identification"].n_joints
    extra = {"validation": config.validation} if config.validation else {}
    for name, path in {**extra, **config.tests}.items():
        m = read(name, path)
        if m.n_joints != n:
            raise DataError(f"{path}: test set {name!r} has {m.n_joints} joint columns (q1..q{m.n_joints}) "
                            f"but the identification set {config.identification} has {n}")
        data[name] = m
    if opts.frame != "tracker":
        return data, robot, {}
    return _register(config, data, robot)


def _register(config: RunConfig, data: dict[str, Measurements], robot: Robot):
    """Registration on the identification set, shared by the test sets (or their own, when they have one)."""
    opts = config.data_options
    ident = data["identification"]
    shared = register_measurements(robot, ident, tool_mm=opts.tool_mm, fit_tool=opts.fit_tool,
                                   source=f"{config.identification} (identification)", plausibility=opts.plausibility)
    regs = {}
    for name, m in data.items():
        if name in opts.own_frame:
            regs[name] = register_measurements(robot, m, tool_mm=shared.tool_mm, fit_tool=False,
                                               target_tools_mm=shared.target_tools_mm,
                                               probe_rotation=shared.probe_rotation,
                                               source=f"{config.tests[name]} ({name}, own tracker frame)",
                                               plausibility=opts.plausibility)
        else:
            regs[name] = shared
    robot = robot.replace(tool_mm=shared.tool_mm.copy())
    out = {name: registered(m, robot, regs[name]) for name, m in data.items()}
    for name, m in out.items():
        rms = float(np.sqrt(np.mean(np.sum(m.errors_mm**2, axis=1))))
        if regs[name] is shared and name != "identification" and rms > 10 * max(shared.rms_3d, 0.01):
            log.warning("test set %r: %.3g mm 3-D RMS after the identification set's registration (%.3g mm there): "
                        "was the tracker moved? Then give it 'registration: own'", name, rms, shared.rms_3d)
    return out, robot, regs


def check_run(config: RunConfig, data: dict[str, Measurements]) -> RunPlan:
    """Plan the run, and refuse before anything is fitted every model the identification set cannot support.

    Checks the identification set (at least two poses, some input that
    varies) and, for every model (and its residual), that the smallest
    cross-validation training fold holds enough samples for its terms or for
    one region. A granularity that the inner folds of nested CV cannot give
    its regions is left out with a note, as long as one remains (one left:
    no nesting, so the outer folds must hold it). Every model that cannot be
    fitted is named in one error (the config file, key path and line each).
    """
    ident = data["identification"]
    if config.predict == "pose":
        for name, m in data.items():
            if not m.has_orientation:
                path = {"identification": config.identification, "validation": config.validation, **config.tests}[name]
                config.fail("predict", f"'pose' needs a measured orientation in every data set; {name} ({path}) "
                                       "has none (columns rx_meas, ry_meas, rz_meas)")
    cv = CVPlan.of(config, ident)
    if cv.n_groups < 2:
        config.fail("data.identification", f"{config.identification} holds {cv.n_groups} pose; a fit needs at "
                                           "least 2")
    if isinstance(config.cv_folds, int) and cv.n_groups < config.cv_folds:
        log.warning("cv_folds: %d folds asked, but %s holds %d poses: %d folds", config.cv_folds,
                    config.identification, cv.n_groups, cv.rule)
    problems, notes, models = [], [], []
    for i, entry in enumerate(config.models):
        try:
            spec, dropped = _feasible(config, i, entry, ident, cv)
        except ConfigError as exc:
            problems.append(str(exc))
            continue
        models.append(spec)
        notes += dropped
    if problems:
        raise ConfigError(problems[0] if len(problems) == 1 else
                          f"{len(problems)} models cannot be fitted:\n  " + "\n  ".join(problems))
    for note in notes:
        log.warning("%s", note)
    check_memory(config, len(ident), ident.n_joints)          # a Gaussian process on many samples outgrows the machine
    repeats = repeat_scatter_mm(ident.errors_mm, cv.groups)
    return RunPlan(cv, tuple(models), tuple(notes), repeats)


def _feasible(config: RunConfig, i: int, entry: ModelSpec, ident: Measurements, cv: CVPlan
              ) -> tuple[ModelSpec, list[str]]:
    """The entry with the granularities the folds support, and notes on those left out; ConfigError if none."""
    X = model_inputs(entry.inputs, ident)
    if int(varying_inputs(X).sum()) == 0:
        what = "joint angle" if entry.inputs == "joint" else "nominal coordinate"
        config.fail(_key(config, i, "inputs"), f"every {what} of the identification set "
                                                f"{config.identification} is constant: nothing to fit")
    built = entry.build(None)
    if getattr(built, "all_targets", False) and not any(ident.nominal_of(t) is not None for t in ident.target_names[1:]):
        config.fail(_key(config, i, "all_targets"), f"the identification set {config.identification} measures one "
                                                     "target; all_targets needs further ones with their nominal "
                                                     "positions (columns x_meas@B, ..., x_nom@B, ..., or a tracker "
                                                     "registration)")
    if getattr(built, "use_orientation", False) and not ident.has_orientation:
        config.fail(_key(config, i, "use_orientation"), f"the identification set {config.identification} has no "
                                                         "measured orientation (columns rx_meas, ry_meas, rz_meas)")
    sizes, notes = list(entry.sizes), []
    # an entry and its residual (fitted to what the entry leaves) must each fit in a fold
    for spec, prefix in ((entry, ""), (entry.residual, "residual.")):
        if spec is None:
            continue
        varying = int(varying_inputs(model_inputs(spec.inputs, ident)).sum())
        model = (spec if spec.residual is None else dataclasses.replace(spec, residual=None)).build(None)
        problem = model.setting_problem(varying)
        if problem is not None:
            config.fail(_key(config, i, prefix + problem[0]), problem[1])
        need, why, key = model.min_samples(varying)
        part = spec.partition
        if part is not None and len(sizes) > 1:
            inner = cv.smallest_train(nested=True)
            fits = [size for size in sizes if part.fewest_regions(size) * need <= inner]
            if len(fits) < 2:          # no nesting: one granularity, on the outer folds
                fits = [size for size in sizes if part.fewest_regions(size) * need <= cv.smallest_train()][:1]
            if not fits:               # not even one: refused below, against the outer folds
                sizes = sizes[:1]
            elif fits != sizes:
                notes.append(f"{entry.name!r}: granularity {', '.join(map(str, sorted(set(sizes) - set(fits))))} "
                             f"left out: its regions need {need} samples each, and the smallest inner training "
                             f"fold of nested cross-validation ({cv.describe()}) holds {inner}")
                sizes = fits
        train = cv.smallest_train(nested=len(sizes) > 1)
        if train < need:
            config.fail(_key(config, i, prefix + (key or "kind")),
                        f"{entry.name!r} needs {why}, but the smallest cross-validation training fold "
                        f"({cv.describe()}) holds {train} samples")
    return _with_sizes(entry, tuple(sizes)), notes


def _with_sizes(entry: ModelSpec, sizes: tuple[int, ...]) -> ModelSpec:
    """``entry`` with its (or its residual's) granularities replaced by ``sizes``."""
    if sizes == entry.sizes:
        return entry
    if entry.partition is not None:
        return dataclasses.replace(entry, partition=dataclasses.replace(entry.partition, sizes=sizes))
    return dataclasses.replace(entry, residual=_with_sizes(entry.residual, sizes))


def _with_noise_floor(entry: ModelSpec, noise_mm: float) -> ModelSpec:
    """``entry`` (and its residual) with ``noise_floor_mm`` set to the data's repeat scatter where a kind
    declares that parameter and the config left it out."""
    params = entry.params
    if "noise_floor_mm" in params and params["noise_floor_mm"] is None:
        params = {**params, "noise_floor_mm": noise_mm}
    residual = _with_noise_floor(entry.residual, noise_mm) if entry.residual is not None else None
    return dataclasses.replace(entry, params=params, residual=residual)


def _key(config: RunConfig, i: int, key: str) -> str:
    """``models[i].key`` if the config file wrote that key, else ``models[i]`` (for its line)."""
    path = f"models[{i}].{key}"
    return path if path in config.lines else f"models[{i}]"


def model_inputs(inputs: str, m: Measurements) -> NDArray[np.float64]:
    """What a model reads from a data set: nominal positions (mm) or joint angles (degrees)."""
    return m.nominal_mm if inputs == "cartesian" else m.q_deg


def measured_poses(m: Measurements) -> NDArray[np.intp]:
    """The pose of each row (:func:`partcal.metrics.pose_groups`): the same joint angles at the same payload.
    A configuration measured at two payloads is two poses, not a repeat: its rows differ by the sag."""
    return pose_groups(m.q_deg if m.payload_kg is None else np.column_stack([m.q_deg, m.payload_kg]))


def per_row_arguments(model, m: Measurements, *, fitting: bool = True) -> dict:
    """Per-pose arguments of the model's ``fit`` (or, not ``fitting``, ``predict``) from a data set: the
    payload of each pose (``payload_kg`` column) for a model that reads one (none otherwise: the model's own
    ``payload_kg``); for a fit on every target and the orientation, those too (:data:`partcal.metrics.FIT_ONLY`:
    a prediction reads neither, so a test set need not have them)."""
    args = {"payload_kg": m.payload_kg} if m.payload_kg is not None and model.reads_payload else {}
    if not (fitting and model.reads_targets):
        return args
    if model.all_targets:              # each target's offset in the flange frame, from its nominal columns
        flange = load_robot(model.robot).flange(m.q_deg)
        args["targets"] = {t: (flange_offset(flange, m.nominal_of(t)), m.measured_of(t) - m.nominal_of(t))
                           for t in m.target_names[1:] if m.nominal_of(t) is not None}
    if model.use_orientation:
        args["orientation_deg"] = m.orientation_errors_deg
    return args


SLOW_SECONDS = 5.0          # a model still cross-validating after this long reports each fold


class FoldLines:
    """Progress lines of a model's slow cross-validation, written to stderr by whichever process fits it
    (a joblib worker shares the terminal): ``partcal: GP(AI): cross-validation fold 3/5 (12 s)``."""

    def __call__(self, text: str) -> None:
        sys.stderr.write(f"partcal: {text}\n")
        sys.stderr.flush()


def fit_model(spec: ModelSpec, seed: int, data: dict[str, Measurements], cv: CVPlan,
              own_frame: tuple[str, ...] = (), lines: Callable[[str], None] | None = None,
              outputs: Outputs = Outputs()) -> ModelResult:
    """Fit one registry entry and evaluate it (runs in a joblib worker).

    ``cv`` holds the run's shared folds on the identification set (and the
    inner folds of nested CV). Data sets in ``own_frame`` are scored by
    :func:`errors_left`. Warnings of the fit are collected, not printed, so
    that the run says them once, in one format, whichever process fitted
    (:attr:`ModelResult.notes`). ``lines`` receives per-fold progress once
    the cross-validation has taken :data:`SLOW_SECONDS`. ``outputs``: what the
    model fits and what its CV score reads (:class:`Outputs`).
    """
    with _collected() as said:
        result = _fit_model(spec, seed, data, cv, own_frame, lines, outputs)
    result.notes = list(dict.fromkeys(said + result.model.fit_notes()))      # the run names the model in front
    return result


def _fit_model(spec, seed, data, cv, own_frame, lines, outputs) -> ModelResult:
    ident = data["identification"]
    X, y = model_inputs(spec.inputs, ident), outputs.errors(ident)
    rows = per_row_arguments(spec.build(seed), ident)
    granularity, nested = None, False
    start = time.perf_counter()

    def fold_done(done: int, total: int) -> None:
        elapsed = time.perf_counter() - start
        if lines is not None and elapsed > SLOW_SECONDS:
            lines(f"{spec.name}: cross-validation fold {done}/{total} ({elapsed:.0f} s)")

    cv_regions = None
    if len(spec.sizes) > 1:
        candidates = [spec.build(seed, size) for size in spec.sizes]
        resid = nested_residuals(candidates, X, y, folds=cv.folds, inner=cv.inner, progress=fold_done, per_row=rows,
                                 score=outputs.score)
        estimator, granularity, fit_seconds = choose_granularity(spec, seed, X, y, cv.folds, rows,
                                                                 outputs.score)                  # returned fitted
        cv_seconds, nested = time.perf_counter() - start - fit_seconds, True
        chosen = min(range(len(granularity)), key=lambda i: granularity[i]["cv_rms_3d"])
        cv_regions = granularity[chosen]["cv_regions"]
    else:
        fold_fits: list = []
        resid = held_out_residuals(spec.build(seed), X, y, cv.folds, fitted=fold_fits, progress=fold_done,
                                   per_row=rows)
        cv_seconds = time.perf_counter() - start
        start = time.perf_counter()
        estimator = spec.build(seed).fit(X, y, **rows)
        fit_seconds = time.perf_counter() - start
        if partitioned_part(estimator) is not None:
            cv_regions = fold_regions([partitioned_part(m) for m in fold_fits])
    if cv_regions is not None and cv_regions[0] < partitioned_part(estimator).partition_.n_regions:
        log.warning("fitted on all the identification data it has %d regions, but on the cross-validation "
                    "folds %s, so its CV score is that of a coarser model",
                    partitioned_part(estimator).partition_.n_regions, _regions_text(cv_regions))
    predictions = {name: estimator.predict(model_inputs(spec.inputs, m),
                                           **per_row_arguments(estimator, m, fitting=False))
                   for name, m in data.items()}
    for name, m in data.items():
        if "payload_kg" in rows and m.payload_kg is None:
            log.warning("%s has no payload_kg column: predicted at the entry's payload_kg (%g kg)", name,
                        estimator.payload_kg)
    metrics = {name: outputs.evaluate(m, predictions[name], name in own_frame) for name, m in data.items()}
    ratio = estimator.pso_rms_ratio()
    return ModelResult(spec, estimator, fit_seconds, outputs.score(resid), metrics, predictions, ratio, granularity,
                       cv_seconds=cv_seconds, nested=nested, cv_regions=cv_regions,
                       cv_se=rms_standard_error(outputs.ranked(resid), cv.groups),
                       effective_parameters=estimator.effective_parameters(), rank_on=outputs.rank_on)


@contextmanager
def _collected():
    """Collect partcal's log warnings and Python warnings of a block (a list of texts), printing none."""
    said: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            said.append(record.getMessage())

    logger, handler = logging.getLogger("partcal"), Collect(logging.WARNING)
    propagate = logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            warnings.simplefilter("ignore", RuntimeWarning)      # numbers are checked, never warned about
            yield said
        said += [str(w.message) for w in caught]
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def _regions_text(counts: list[int]) -> str:
    """``[1, 1]`` -> ``'1 region'``, ``[1, 3]`` -> ``'1 to 3 regions'``."""
    low, high = counts
    return (f"{low} to {high} regions" if low != high else f"{low} region{'s' if low != 1 else ''}")


def choose_granularity(spec: ModelSpec, seed: int, X, y, folds: list, per_row: dict | None = None,
                       score: Callable[[NDArray[np.float64]], float] = pooled_rms) -> tuple[object, list[dict], float]:
    """Choose the partition granularity of an entry (or of its residual) by cross-validation on ``folds``.

    The same choice as :func:`partcal.models.partitioned.select_granularity`, for any entry kind:
    returns the best candidate fitted on all of ``X, y``, a row per candidate
    (``granularity``, ``cv_rms_3d``, ``regions``, and ``cv_regions``: the fewest and most regions of
    the fits on the folds) and the seconds of that final fit. ``per_row``: a payload per pose, as for
    :func:`partcal.metrics.held_out_residuals`; ``score``: of the held-out residuals (:meth:`Outputs.score`).
    """
    fold_models: list = []
    best, scores, fitted, seconds = select_by_cv([spec.build(seed, size) for size in spec.sizes], X, y, folds=folds,
                                                 fold_models=fold_models, per_row=per_row, score=score)
    table = [{"granularity": int(size), "cv_rms_3d": score, "regions": int(partitioned_part(f).partition_.n_regions),
              "cv_regions": fold_regions([partitioned_part(m) for m in folded])}
             for size, score, f, folded in zip(spec.sizes, scores, fitted, fold_models)]
    for row in table:
        log.info("%s, granularity %s: CV RMS %.4f over %d regions", spec.name, row["granularity"], row["cv_rms_3d"],
                 row["regions"])
    return fitted[best], table, seconds[best]


@contextmanager
def _backend(config: RunConfig):
    """joblib's default backend, or Dask when the config gives a scheduler address."""
    if not config.dask_address:
        yield
        return
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(f"{config.source}: dask.address is set but the 'distributed' package is not "
                          "installed (pip install 'partcal[dask]')") from None
    try:
        client = Client(config.dask_address, timeout=10)
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"{config.source}: dask.address: cannot reach the scheduler at "
                          f"{config.dask_address}: {exc}") from None
    try:
        with parallel_config(backend="dask"):
            yield
    finally:
        client.close()


def run(config: RunConfig, progress: Callable[[int, int, str], None] | None = None) -> RunResult:
    """Fit and evaluate every model of ``config``; verify compensation when a virtual robot is given.

    ``progress(done, total, text)`` hears of each finished model (and, with
    ``done = 0``, of the plan); per-fold lines of slow models go to stderr
    unless ``progress`` is None.
    """
    start = time.perf_counter()
    data, robot, registrations = load_datasets(config)
    plan = check_run(config, data)
    virtual = _virtual_robot(config, robot)
    specs = plan.models
    if plan.repeat_scatter_mm is not None:
        specs = tuple(_with_noise_floor(spec, plan.repeat_scatter_mm) for spec in specs)
    if progress:
        progress(0, len(specs), f"cross-validation: {plan.cv.describe()}")
    own = config.data_options.own_frame
    lines = FoldLines() if progress else None
    order = _costliest_first(specs, data["identification"])
    outputs = Outputs.of(config)
    jobs = [delayed(fit_model)(specs[i], model_seed(config.seed, specs[i].name), data, plan.cv, own, lines, outputs)
            for i in order]
    results: list[ModelResult] = []
    with _backend(config):
        stream = Parallel(n_jobs=config.n_jobs, return_as="generator")(jobs)
        for result in stream:
            results.append(result)
            for note in result.notes:
                log.warning("%s: %s", result.spec.name, note)
            if progress:
                progress(len(results), len(jobs), f"{result.spec.name}: CV RMS {result.cv_rms_3d:.3f} "
                                                  f"+- {result.cv_se:.3f} {outputs.unit}, fitted in {result.fit_seconds:.2f} s, "
                                                  f"cross-validated in {result.cv_seconds:.2f} s")
    if virtual is not None:
        for result in results:
            result.compensation = verify_compensation(result, data, robot, virtual, config.seed)
    results = [results[order.index(i)] for i in range(len(specs))]        # back in the config's order
    uncompensated = {name: outputs.evaluate(m, np.zeros_like(outputs.errors(m)), name in own)
                     for name, m in data.items()}
    return RunResult(config, data, robot, uncompensated, results, choose_best(results, config.rank_by),
                     time.perf_counter() - start, registrations=registrations, plan=plan)


def _costliest_first(specs, ident: Measurements) -> list[int]:
    """The order to start the fits in: nested cross-validation first, then by the memory a fit holds (a
    Gaussian process's matrices), so that the longest fits do not start last on a busy pool."""
    def cost(spec: ModelSpec) -> tuple:
        model = spec.build(None)
        return (len(spec.sizes) > 1, model.peak_fit_bytes(len(ident), ident.n_joints)[0])

    costs = [cost(spec) for spec in specs]
    return sorted(range(len(specs)), key=lambda i: costs[i], reverse=True)


def choose_best(results: list[ModelResult], rank_by: str) -> str:
    """The name of the run's best model: lowest validation RMS, or by CV the physical model with the fewest
    parameters within one standard error of the lowest CV score, else the lowest CV score
    (:func:`choose_simplest`)."""
    if rank_by == "validation":
        return min(results, key=lambda r: r.score(rank_by)).spec.name
    sizes = [r.effective_parameters if np.isfinite(r.effective_parameters) else np.inf for r in results]
    return results[choose_simplest([r.cv_rms_3d for r in results], [r.cv_se for r in results], sizes,
                                   [r.model.is_physical() for r in results])].spec.name


def _virtual_robot(config: RunConfig, robot: Robot | None):
    if config.virtual_robot is None:
        return None
    from ..data.simulate import load_study

    study = load_study(config.virtual_robot)
    if robot is None or study.robot.nominal.name != robot.name:
        raise ConfigError(f"{config.source}: verify.virtual_robot simulates {study.robot.nominal.name!r}, "
                          f"but the run's robot is {robot.name if robot else 'not set'!r}")
    return study.robot
