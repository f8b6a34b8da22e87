"""The second stage of a run: fit every planned entry, score it on the shared folds and on every data set.

Each entry's estimator is built once (one per granularity for a list of
them) and cloned for every fold and for the final fit. Entries run in
parallel with joblib (``n_jobs``; a Dask cluster when the config gives its
address); workers the entries leave spare fit an entry's folds side by side
(:func:`worker_split`); each entry's seed comes from the run seed and its name
(:func:`model_seed`), so results depend neither on ``n_jobs``, nor on the
order in which jobs finish, nor on the entry's place in the list. A fit's
warnings are collected in whichever process fits it and said by the run,
prefixed with the model's name.
"""

from __future__ import annotations

import hashlib
import logging
import sys
import time
from contextlib import contextmanager
from typing import Callable

import numpy as np
from numpy.typing import NDArray
from joblib import Parallel, delayed, parallel_config

from ..data.measurements import Measurements
from ..errors import ConfigError, held_warnings
from ..metrics import rms_standard_error
from ..models.kinds import identification_of, kind_of, pso_rms_ratio, reads_targets, regions_of
from ..models.partitioned import fold_regions
from ..calibration.prior import strength_note
from ..robot.kinematics import Robot, flange_offset
from .config import ModelSpec, SpreadOptions
from .prepare import PreparedRun, model_inputs
from .results import ModelResult
from .scoring import Outputs, spread_summary
from .selection import CVPlan, choose_granularity, choose_strength, fits_on_folds, nested_residuals, strength_rule
from .spread import run_spread

log = logging.getLogger(__name__)

SLOW_SECONDS = 5.0          # a model still cross-validating after this long reports each fold
LARGE_ROWS = 10_000         # a model fitted on this many identification rows or more says when it starts


def model_seed(run_seed: int, name: str) -> int:
    """A model's seed: from the run's seed and the model's name, never from its place in the list.

    >>> model_seed(0, "GP(AI)") == model_seed(0, "GP(AI)") != model_seed(1, "GP(AI)")
    True
    """
    digest = int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:8], "little")
    return int(np.random.SeedSequence([run_seed, digest]).generate_state(1)[0])


def per_row_arguments(model, m: Measurements, robot: Robot | None = None, *, fitting: bool = True) -> dict:
    """Per-pose arguments of the model's ``fit`` (or, not ``fitting``, ``predict``) from a data set: the
    payload of each pose (``payload_kg`` column) for a model that reads one (none otherwise: the model's own
    ``payload_kg``); for a fit on every target and the orientation, those too
    (:data:`partcal.study.selection.FIT_ONLY`: a prediction reads neither, so a test set need not have them);
    for an identified model (kinematic), each row's standard deviations (``std_x..std_z`` or ``data.noise``)
    when the data set has them.
    ``robot`` (the run's, registered) places each further target on the flange."""
    args = {"payload_kg": m.payload_kg} if m.payload_kg is not None and model.reads_payload else {}
    if fitting and m.std_mm is not None and kind_of(model).identified:       # weighted identification
        args["std_mm"] = m.std_mm
    if not (fitting and reads_targets(model)):
        return args
    if model.all_targets:              # each target's offset in the flange frame, from its nominal columns
        flange = robot.flange(m.q_deg)
        args["targets"] = {t: (flange_offset(flange, m.nominal_of(t)), m.measured_of(t) - m.nominal_of(t))
                           for t in m.target_names[1:] if m.nominal_of(t) is not None}
    if model.use_orientation:
        args["orientation_deg"] = m.orientation_errors_deg
    return args


class FoldLines:
    """Progress lines of a model's slow cross-validation, written to stderr by whichever process fits it
    (a joblib worker shares the terminal): ``partcal: GP(AI): cross-validation fold 3/5 (12 s)``."""

    def __call__(self, text: str) -> None:
        sys.stderr.write(f"partcal: {text}\n")
        sys.stderr.flush()


def fit_all(prepared: PreparedRun, outputs: Outputs,
            progress: Callable[[int, int, str], None] | None = None) -> list[ModelResult]:
    """Fit and score every entry of the plan, in the plan's order.

    ``progress(done, total, text)`` hears of each finished model; per-fold
    lines of slow models go to stderr unless ``progress`` is None.
    """
    config, plan = prepared.config, prepared.plan
    specs = plan.models
    own = config.data_options.own_frame
    lines = FoldLines() if progress else None
    order = _costliest_first(specs, prepared.datasets["identification"])
    model_jobs, fold_jobs = worker_split(config.n_jobs, len(specs), bool(config.dask_address))
    jobs = [delayed(fit_model)(specs[i], model_seed(config.seed, specs[i].name), prepared.datasets, plan.cv,
                               prepared.robot, own, lines, outputs, fold_jobs, config.spread) for i in order]
    results: list[ModelResult] = []
    with _backend(config):
        for result in Parallel(n_jobs=model_jobs, return_as="generator")(jobs):
            results.append(result)
            for note in result.notes:
                log.warning("%s: %s", result.spec.name, note)
            if progress:
                progress(len(results), len(jobs), f"{result.spec.name}: CV RMS {result.cv_rms_3d:.3f} "
                                                  f"+- {result.cv_se:.3f} {outputs.unit}, fitted in "
                                                  f"{result.fit_seconds:.2f} s, cross-validated in "
                                                  f"{result.cv_seconds:.2f} s")
    return [results[order.index(i)] for i in range(len(specs))]        # back in the config's order


def worker_split(n_jobs: int, n_models: int, distributed: bool = False) -> tuple[int, int]:
    """How a run's ``n_jobs`` workers are shared: ``(models at a time, folds at a time per model)``.

    Models come first: with at least as many models as workers, each worker fits one model (its folds
    one after another). With fewer, the spare workers fit a model's folds (and its final fit) side by
    side, ``n_jobs // models`` per model, so that the workers never exceed ``n_jobs``; a run of one model
    on two workers fits two folds at a time. ``-1`` is every core (joblib's count); on a Dask cluster
    the models are spread and the folds stay in order.

    >>> worker_split(1, 1), worker_split(2, 1), worker_split(2, 12), worker_split(4, 3), worker_split(4, 1, True)
    ((1, 1), (1, 2), (2, 1), (3, 1), (4, 1))
    """
    from joblib import effective_n_jobs

    workers = effective_n_jobs(n_jobs) if n_jobs == -1 else int(n_jobs)
    models = max(1, min(workers, n_models))
    return (n_jobs if distributed else models), (1 if distributed else max(1, workers // models))


def fit_model(spec: ModelSpec, seed: int, data: dict[str, Measurements], cv: CVPlan, robot: Robot | None = None,
              own_frame: tuple[str, ...] = (), lines: Callable[[str], None] | None = None,
              outputs: Outputs = Outputs(), n_jobs: int = 1, spread: SpreadOptions = SpreadOptions()
              ) -> ModelResult:
    """Fit one planned entry and evaluate it (runs in a joblib worker).

    ``cv`` holds the run's shared folds on the identification set (and the
    inner folds of nested CV); ``robot`` is the run's (registered). Data sets
    in ``own_frame`` are scored by :func:`~partcal.study.scoring.errors_left`.
    Warnings of the fit are collected, not printed, so that the run says them
    once, in one format, whichever process fitted
    (:attr:`ModelResult.notes`). ``lines`` receives per-fold progress once
    the cross-validation has taken :data:`SLOW_SECONDS`. ``outputs``: what the
    model fits and what its CV score reads. ``n_jobs``: folds fitted at a time (:func:`worker_split`).
    ``spread``: how the model's spread is calibrated on the identification set
    (:func:`~partcal.study.spread.run_spread`).
    """
    with held_warnings() as said:
        result = _fit_model(spec, seed, data, cv, robot, own_frame, lines, outputs, n_jobs, spread)
    result.notes = list(dict.fromkeys(said + result.model.fit_notes()))      # the run names the model in front
    if result.prior_strength is not None:
        result.notes.append(strength_note(result.prior_strength, "the run's cross-validation"))
    return result


def _fit_model(spec, seed, data, cv, robot, own_frame, lines, outputs, n_jobs=1,
               spread: SpreadOptions = SpreadOptions()) -> ModelResult:
    ident = data["identification"]
    X, y = model_inputs(spec.inputs, ident), outputs.errors(ident)
    candidates = [spec.build(seed, size) for size in spec.sizes] or [spec.build(seed)]   # built once, then cloned
    rows = per_row_arguments(candidates[0], ident, robot)
    granularity, nested, cv_regions, fold_fits, strengths = None, False, None, [], None
    start = time.perf_counter()

    def fold_done(done: int, total: int) -> None:
        elapsed = time.perf_counter() - start
        if lines is not None and elapsed > SLOW_SECONDS:
            lines(f"{spec.name}: cross-validation fold {done}/{total} ({elapsed:.0f} s)")

    def final_done(spent: float) -> None:
        elapsed = time.perf_counter() - start
        if lines is not None and elapsed > SLOW_SECONDS:
            lines(f"{spec.name}: final fit on all {len(X)} rows done in {spent:.0f} s ({elapsed:.0f} s)")

    if lines is not None and len(X) >= LARGE_ROWS:
        lines(f"{spec.name}: fitting {len(cv.folds)} cross-validation folds and the final fit on {len(X)} rows, "
              f"{min(n_jobs, len(cv.folds) + 1)} at a time")

    if len(candidates) > 1:
        resid = nested_residuals(candidates, X, y, folds=cv.folds, inner=cv.inner, progress=fold_done, per_row=rows,
                                 score=outputs.score, n_jobs=n_jobs)
        estimator, granularity = choose_granularity(candidates, spec.sizes, X, y, cv.folds, per_row=rows,
                                                    score=outputs.score, n_jobs=n_jobs)   # returned fitted
        for row in granularity:
            log.info("%s, granularity %s: CV RMS %.4f over %d regions", spec.name, row["granularity"],
                     row["cv_rms_3d"], row["regions"])
        chosen = min(range(len(granularity)), key=lambda i: granularity[i]["cv_rms_3d"])
        fit_seconds = granularity[chosen].pop("fit_seconds")
        for row in granularity:
            row.pop("fit_seconds", None)
        cv_seconds, nested = time.perf_counter() - start - fit_seconds, True
        cv_regions = granularity[chosen]["cv_regions"]
    elif len(spec.strengths) > 1:
        candidates = [spec.build(seed, strength=s) for s in spec.strengths]
        rule = strength_rule(spec.strengths, cv.groups, outputs.score, outputs.ranked)
        resid = nested_residuals(candidates, X, y, folds=cv.folds, inner=cv.inner, progress=fold_done, per_row=rows,
                                 score=outputs.score, n_jobs=n_jobs, choose=rule)
        estimator, strengths, fit_seconds = choose_strength(candidates, spec.strengths, X, y, cv, per_row=rows,
                                                            score=outputs.score, ranked=outputs.ranked, n_jobs=n_jobs)
        cv_seconds, nested = time.perf_counter() - start - fit_seconds, True
    else:
        # the folds and the final fit, side by side when n_jobs allows
        resid, estimator, fit_seconds = fits_on_folds(candidates[0], X, y, cv.folds, fitted=fold_fits,
                                                      progress=fold_done, per_row=rows, n_jobs=n_jobs, final=True,
                                                      on_final=final_done)
        cv_seconds = time.perf_counter() - start - fit_seconds
        if regions_of(estimator) is not None:
            cv_regions = fold_regions([regions_of(m) for m in fold_fits])
        _note_other_optima(fold_fits, estimator)
    start = time.perf_counter()
    calibrated = run_spread(spread, estimator, X, y, cv_folds=cv.folds, fold_fits=fold_fits, per_row=rows)
    if calibrated is not None:
        calibrated.apply(estimator)
    spread_seconds = time.perf_counter() - start
    _name_downweighted(estimator)
    part = regions_of(estimator)
    if cv_regions is not None and cv_regions[0] < part.partition_.n_regions:
        log.warning("fitted on all the identification data it has %d regions, but on the cross-validation "
                    "folds %s, so its CV score is that of a coarser model", part.partition_.n_regions,
                    _regions_text(cv_regions))
    predictions = {name: estimator.predict(model_inputs(spec.inputs, m),
                                           **per_row_arguments(estimator, m, robot, fitting=False))
                   for name, m in data.items()}
    for name, m in data.items():
        if "payload_kg" in rows and m.payload_kg is None:
            log.warning("%s has no payload_kg column: predicted at the entry's payload_kg (%g kg)", name,
                        estimator.payload_kg)
    metrics = {name: outputs.evaluate(m, predictions[name], name in own_frame) for name, m in data.items()}
    spreads = spreads_of(estimator, spec, data, robot)
    for name, std in spreads.items():
        metrics[name]["spread"] = spread_summary(data[name], predictions[name], std, name in own_frame)
    return ModelResult(spec, estimator, fit_seconds, outputs.score(resid), metrics, predictions,
                       pso_rms_ratio(estimator), granularity, cv_seconds=cv_seconds, nested=nested,
                       cv_regions=cv_regions, cv_se=rms_standard_error(outputs.ranked(resid), cv.groups),
                       effective_parameters=estimator.effective_parameters(), rank_on=outputs.rank_on,
                       spreads=spreads, spread_seconds=spread_seconds, prior_strength=strengths)


def _name_downweighted(estimator) -> None:
    """One warning line per identification row a robust loss weighed below 0.5 (its final fit's; the run
    puts the model's name before it)."""
    table = identification_of(estimator)
    if table is None or table.robust is None:
        return
    for d in table.robust["downweighted"]:
        log.warning("identification set, data row %d: down-weighted by the %s loss (residual %.4g mm, weight "
                    "%.3g)", d["row"] + 1, table.robust["loss"], d["residual_mm"], d["weight"])


def spreads_of(estimator, spec: ModelSpec, data: dict[str, Measurements], robot: Robot | None = None
               ) -> dict[str, NDArray[np.float64]]:
    """The standard deviation of the model's every prediction on every data set, like its predictions;
    none for a kind without a spread."""
    if estimator.spread_problem() is not None:
        return {}
    return {name: estimator.std_scaled(model_inputs(spec.inputs, m),
                                       **per_row_arguments(estimator, m, robot, fitting=False))[1]
            for name, m in data.items()}


def _note_other_optima(fold_fits: list, estimator) -> None:
    """Warn about CV folds whose Gaussian process (the model, or a hybrid's residual) found hyperparameters far
    from the final fit's: its CV score is then that of another optimum than the model written."""
    for k, fold in enumerate(fold_fits):
        gap = fold.search_gap(estimator)
        if gap is not None:
            log.warning("cross-validation fold %d of %d: its Gaussian process found another optimum than the final "
                        "fit's (%s): the CV score is partly that of other hyperparameters", k + 1, len(fold_fits), gap)


def _regions_text(counts: list[int]) -> str:
    """``[1, 1]`` -> ``'1 region'``, ``[1, 3]`` -> ``'1 to 3 regions'``."""
    low, high = counts
    return (f"{low} to {high} regions" if low != high else f"{low} region{'s' if low != 1 else ''}")


@contextmanager
def _backend(config):
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


def _costliest_first(specs, ident: Measurements) -> list[int]:
    """The order to start the fits in: nested cross-validation first, then by the memory a fit holds (a
    Gaussian process's matrices), so that the longest fits do not start last on a busy pool."""
    def cost(spec: ModelSpec) -> tuple:
        model = spec.build(None)
        return (len(spec.sizes) > 1, model.peak_fit_bytes(len(ident), ident.n_joints)[0])

    costs = [cost(spec) for spec in specs]
    return sorted(range(len(specs)), key=lambda i: costs[i], reverse=True)
