"""The model registry of a batch run: fit, evaluate, cross-validate, rank, verify.

Every model is fitted on the identification set, evaluated on every data set
and by k-fold cross-validation on the identification set, and ranked by its
cross-validated 3-D RMS (``rank_by: cv``) or by its 3-D RMS on a held-out
validation set (``rank_by: validation``); never by a test set. Every model is
cross-validated on the same folds, drawn once from the run seed; a model
with a list of granularities is scored by nested cross-validation (the
granularity is chosen inside each outer training fold). Models run in parallel with
joblib (``n_jobs``; a Dask cluster when the config gives its address); each
gets its own child seed, so results do not depend on ``n_jobs`` or the order
in which jobs finish. With a virtual robot, compensation is verified end to
end: the compensated targets are commanded on the simulated true robot.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from joblib import Parallel, delayed, parallel_config
from numpy.typing import NDArray

from ..data.measurements import Measurements, read_measurements
from ..data.registration import Registration, kabsch, register_tracker, registered
from ..errors import ConfigError, DataError
from ..metrics import cross_validated_rms, kfold_splits, nested_cross_validated_rms, select_by_cv, summary
from ..models.bases import varying_inputs
from ..models.partitioned import fold_regions
from ..robot.description import load_robot
from ..robot.kinematics import Robot
from .config import ModelSpec, RunConfig
from .memory import check_memory
from .predictor import Predictor

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

    def score(self, rank_by: str) -> float:
        """The number the run ranks by: CV 3-D RMS, or 3-D RMS on the validation set (mm)."""
        return self.cv_rms_3d if rank_by == "cv" else self.metrics["validation"]["rms_3d"]

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

    @property
    def best_reason(self) -> str:
        """Which rule chose ``best``, in words (metrics.json, the report and the printed table say it)."""
        return rank_reason(self.config)


def rank_reason(config: RunConfig) -> str:
    """The ranking rule of a run, in words."""
    if config.rank_by == "validation":
        return f"lowest 3-D RMS on the validation set {config.validation.name} (held out, never fitted)"
    return (f"lowest {config.cv_folds}-fold cross-validated 3-D RMS on the identification set (the same folds "
            "for every model; nested for granularity lists)")


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
        return read_measurements(path, robot, name=name, fmt=opts.format, rows=opts.rows.get(name), frame=opts.frame,
                                 plausibility=opts.plausibility)

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
    shared = register_tracker(robot, ident.q_deg, ident.measured_mm, tool_mm=opts.tool_mm, fit_tool=opts.fit_tool,
                              source=f"{config.identification} (identification)", plausibility=opts.plausibility)
    regs = {}
    for name, m in data.items():
        if name in opts.own_frame:
            regs[name] = register_tracker(robot, m.q_deg, m.measured_mm, tool_mm=shared.tool_mm, fit_tool=False,
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


def check_run(config: RunConfig, data: dict[str, Measurements]) -> None:
    """Refuse, before anything is fitted, every model the identification set cannot support.

    Checks the identification set (at least two poses, some input that
    varies) and, for every model, that the smallest cross-validation training
    fold (the inner folds of nested CV for granularity lists) holds enough
    samples for its terms (series models) or for one region (partitioned
    models). Errors name the config file, the key path and its line.
    """
    ident = data["identification"]
    n, k = len(ident), config.cv_folds
    if n < 2:
        config.fail("data.identification", f"{config.identification} holds {n} pose; a fit needs at least 2")
    if n < k:
        config.fail("cv_folds", f"{k} folds need at least {k} identification poses; "
                                f"{config.identification} holds {n}")
    smallest = n - -(-n // k)                  # the smallest training fold: n - ceil(n / k)
    for i, entry in enumerate(config.models):
        X = model_inputs(entry.inputs, ident)
        if int(varying_inputs(X).sum()) == 0:
            what = "joint angle" if entry.inputs == "joint" else "nominal coordinate"
            config.fail(_key(config, i, "inputs"), f"every {what} of the identification set "
                                                    f"{config.identification} is constant: nothing to fit")
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
            train = smallest
            if spec.partition is not None and len(spec.partition.sizes) > 1:    # nested CV: inner folds smaller
                train = smallest - -(-smallest // k)
            if train < need:
                config.fail(_key(config, i, prefix + (key or "kind")),
                            f"{entry.name!r} needs {why}, but the smallest cross-validation training fold "
                            f"of the {n}-pose identification set holds {train} samples")
    check_memory(config, n, ident.n_joints)          # a Gaussian process on many samples outgrows the machine


def _key(config: RunConfig, i: int, key: str) -> str:
    """``models[i].key`` if the config file wrote that key, else ``models[i]`` (for its line)."""
    path = f"models[{i}].{key}"
    return path if path in config.lines else f"models[{i}]"


def model_inputs(inputs: str, m: Measurements) -> NDArray[np.float64]:
    """What a model reads from a data set: nominal positions (mm) or joint angles (degrees)."""
    return m.nominal_mm if inputs == "cartesian" else m.q_deg


def fit_model(spec: ModelSpec, seed: int, data: dict[str, Measurements], folds: list, run_seed: int = 0,
              own_frame: tuple[str, ...] = ()) -> ModelResult:
    """Fit one registry entry and evaluate it (runs in a joblib worker).

    ``folds`` are the run's shared ``(train, test)`` index pairs on the
    identification set; ``run_seed`` draws the inner folds of nested CV.
    Data sets in ``own_frame`` are scored by :func:`errors_left`.
    """
    ident = data["identification"]
    X, y = model_inputs(spec.inputs, ident), ident.errors_mm
    granularity, nested = None, False
    start = time.perf_counter()
    cv_regions = None
    if len(spec.sizes) > 1:
        candidates = [spec.build(seed, size) for size in spec.sizes]
        cv = nested_cross_validated_rms(candidates, X, y, folds=folds, inner_folds=len(folds), random_state=run_seed)
        estimator, granularity, fit_seconds = choose_granularity(spec, seed, X, y, folds)      # returned fitted
        cv_seconds, nested = time.perf_counter() - start - fit_seconds, True
        chosen = min(range(len(granularity)), key=lambda i: granularity[i]["cv_rms_3d"])
        cv_regions = granularity[chosen]["cv_regions"]
    else:
        fold_fits: list = []
        cv = cross_validated_rms(spec.build(seed), X, y, folds=folds, fitted=fold_fits)
        cv_seconds = time.perf_counter() - start
        start = time.perf_counter()
        estimator = spec.build(seed).fit(X, y)
        fit_seconds = time.perf_counter() - start
        if partitioned_part(estimator) is not None:
            cv_regions = fold_regions([partitioned_part(m) for m in fold_fits])
    if cv_regions is not None and cv_regions[0] < partitioned_part(estimator).partition_.n_regions:
        log.warning("%s: fitted on all the identification data it has %d regions, but on the cross-validation "
                    "folds %s, so its CV score is that of a coarser model", spec.name,
                    partitioned_part(estimator).partition_.n_regions, _regions_text(cv_regions))
    predictions = {name: estimator.predict(model_inputs(spec.inputs, m)) for name, m in data.items()}
    metrics = {name: summary(errors_left(m, predictions[name], name in own_frame)) for name, m in data.items()}
    ratio = estimator.pso_rms_ratio()
    return ModelResult(spec, estimator, fit_seconds, cv, metrics, predictions, ratio, granularity,
                       cv_seconds=cv_seconds, nested=nested, cv_regions=cv_regions)


def _regions_text(counts: list[int]) -> str:
    """``[1, 1]`` -> ``'1 region'``, ``[1, 3]`` -> ``'1 to 3 regions'``."""
    low, high = counts
    return (f"{low} to {high} regions" if low != high else f"{low} region{'s' if low != 1 else ''}")


def errors_left(m: Measurements, predicted: NDArray[np.float64], own_frame: bool = False) -> NDArray[np.float64]:
    """The errors a model leaves on a data set, (n, 3) mm: measured - nominal - predicted.

    A set registered in its own tracker frame (``registration: own``) is known
    only up to a rigid transform: its registration on the nominal model has
    already absorbed the rigid part of the robot's errors, and a model's
    prediction would count it again. There the errors left are the measured
    positions minus the model's positions (nominal + predicted) moved by their
    best rigid fit to them; with ``predicted = 0`` the same gives the
    uncompensated figure, so both sides are scored alike.
    """
    if not own_frame:
        return m.errors_mm - predicted
    model_mm = m.nominal_mm + predicted
    rot, shift = kabsch(model_mm, m.measured_mm)
    return m.measured_mm - (model_mm @ rot.T + shift)


def choose_granularity(spec: ModelSpec, seed: int, X, y, folds: list) -> tuple[object, list[dict], float]:
    """Choose the partition granularity of an entry (or of its residual) by cross-validation on ``folds``.

    The same choice as :func:`partcal.models.partitioned.select_granularity`, for any entry kind:
    returns the best candidate fitted on all of ``X, y``, a row per candidate
    (``granularity``, ``cv_rms_3d``, ``regions``, and ``cv_regions``: the fewest and most regions of
    the fits on the folds) and the seconds of that final fit.
    """
    fold_models: list = []
    best, scores, fitted, seconds = select_by_cv([spec.build(seed, size) for size in spec.sizes], X, y, folds=folds,
                                                 fold_models=fold_models)
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
    """Fit and evaluate every model of ``config``; verify compensation when a virtual robot is given."""
    start = time.perf_counter()
    data, robot, registrations = load_datasets(config)
    check_run(config, data)
    virtual = _virtual_robot(config, robot)
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(config.seed).spawn(len(config.models))]
    folds = kfold_splits(len(data["identification"]), config.cv_folds, config.seed)    # one split for every model
    own = config.data_options.own_frame
    jobs = [delayed(fit_model)(spec, seed, data, folds, config.seed, own) for spec, seed in zip(config.models, seeds)]
    results: list[ModelResult] = []
    with _backend(config):
        stream = Parallel(n_jobs=config.n_jobs, return_as="generator")(jobs)
        for result in stream:
            results.append(result)
            if progress:
                progress(len(results), len(jobs), f"{result.spec.name}: CV RMS {result.cv_rms_3d:.3f} mm, "
                                                  f"fitted in {result.fit_seconds:.2f} s, cross-validated in "
                                                  f"{result.cv_seconds:.2f} s")
    if virtual is not None:
        for result in results:
            result.compensation = verify_compensation(result, data, robot, virtual, config.seed)
    uncompensated = {name: summary(errors_left(m, np.zeros_like(m.errors_mm), name in own)) for name, m in data.items()}
    best = min(results, key=lambda r: r.score(config.rank_by)).spec.name
    return RunResult(config, data, robot, uncompensated, results, best, time.perf_counter() - start,
                     registrations=registrations)


def _virtual_robot(config: RunConfig, robot: Robot | None):
    if config.virtual_robot is None:
        return None
    from ..data.simulate import load_study

    study = load_study(config.virtual_robot)
    if robot is None or study.robot.nominal.name != robot.name:
        raise ConfigError(f"{config.source}: verify.virtual_robot simulates {study.robot.nominal.name!r}, "
                          f"but the run's robot is {robot.name if robot else 'not set'!r}")
    return study.robot


def verify_compensation(result: ModelResult, data: dict[str, Measurements], robot: Robot, virtual,
                        seed: int) -> dict[str, dict]:
    """Command the compensated test targets on the virtual robot; compare before, predicted and after.

    ``predicted_residual`` is the model's error on the measured test set (what
    compensation should leave); ``after`` is what the true robot, measured by
    the simulated tracker, really misses by when given the false targets.
    """
    predictor = Predictor(result.model, {"name": result.spec.name, "inputs": result.spec.inputs,
                                         "n_inputs": result.model.n_features_in_, "kind": "run"}, robot)
    out = {}
    for k, (name, m) in enumerate(data.items()):
        if name == "identification":
            continue
        targets = m.nominal_mm
        comp = predictor.compensate_full(targets, m.q_deg if result.spec.inputs == "joint" else None)
        if result.spec.inputs == "joint":
            q_cmd = comp.joints_deg
        else:     # the controller turns the false target into joints with its nominal model
            fixed = tuple(int(j) + 1 for j in np.flatnonzero(~varying_inputs(m.q_deg)))
            q_cmd = robot.inverse(comp.commanded_mm, m.q_deg, fixed=fixed).q_deg
        rng = np.random.default_rng([seed, k])
        reached = virtual.measure(q_cmd, rng)
        out[name] = {"before": summary(m.errors_mm),
                     "predicted_residual": summary(m.errors_mm - result.predictions[name]),
                     "after": summary(reached - targets),
                     "converged": int(comp.converged.sum()), "n": len(targets)}
    return out
