"""The model registry of a batch run: fit, evaluate, cross-validate, rank, verify.

Every model is fitted on the identification set, evaluated on every data set
and by k-fold cross-validation on the identification set, and ranked by its
cross-validated 3-D RMS (never by a test set). Models run in parallel with
joblib (``n_jobs``; a Dask cluster when the config gives its address); each
gets its own child seed, so results do not depend on ``n_jobs`` or the order
in which jobs finish. With a virtual robot, compensation is verified end to
end: the compensated targets are commanded on the simulated true robot.
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from joblib import Parallel, delayed, parallel_config
from numpy.typing import NDArray

from ..data.measurements import Measurements, read_measurements
from ..errors import ConfigError, DataError
from ..metrics import cross_validated_rms, summary
from ..models.bases import varying_inputs
from ..models.kinematic import KinematicModel
from ..models.partitioned import PartitionedErrorModel
from ..robot.kinematics import Robot, load_robot
from .config import ModelSpec, RunConfig
from .predictor import Predictor

log = logging.getLogger(__name__)


@dataclass
class ModelResult:
    """One fitted model of a run with everything measured about it."""

    spec: ModelSpec
    model: object           # any partcal error model (series, partitioned, GP, kinematic)
    fit_seconds: float
    cv_rms_3d: float
    metrics: dict[str, dict]
    predictions: dict[str, NDArray[np.float64]]
    rms_ratio: float | None = None
    granularity: list[dict] | None = None
    compensation: dict[str, dict] = field(default_factory=dict)

    @property
    def n_regions(self) -> int:
        part = partitioned_part(self.model)
        return part.partition_.n_regions if part is not None else 1


def partitioned_part(model) -> PartitionedErrorModel | None:
    """The partitioned model in ``model``: itself, or the residual of a hybrid; None if there is none."""
    if isinstance(model, KinematicModel):
        model = model.residual_
    return model if isinstance(model, PartitionedErrorModel) else None


@dataclass
class RunResult:
    config: RunConfig
    datasets: dict[str, Measurements]
    robot: Robot | None
    uncompensated: dict[str, dict]
    models: list[ModelResult]
    best: str
    seconds: float


def load_datasets(config: RunConfig) -> tuple[dict[str, Measurements], Robot | None]:
    """Read the identification and test sets; all must have the same joints."""
    robot = load_robot(config.robot) if config.robot else None
    data = {"identification": read_measurements(config.identification, robot, name="identification")}
    n = data["identification"].n_joints
    for name, path in config.tests.items():
        m = read_measurements(path, robot, name=name)
        if m.n_joints != n:
            raise DataError(f"{path}: test set {name!r} has {m.n_joints} joint columns (q1..q{m.n_joints}) "
                            f"but the identification set {config.identification} has {n}")
        data[name] = m
    return data, robot


def model_inputs(inputs: str, m: Measurements) -> NDArray[np.float64]:
    """What a model reads from a data set: nominal positions (mm) or joint angles (degrees)."""
    return m.nominal_mm if inputs == "cartesian" else m.q_deg


def fit_model(spec: ModelSpec, seed: int, data: dict[str, Measurements], folds: int) -> ModelResult:
    """Fit one registry entry and evaluate it (runs in a joblib worker)."""
    ident = data["identification"]
    X, y = model_inputs(spec.inputs, ident), ident.errors_mm
    granularity = None
    start = time.perf_counter()
    if len(spec.sizes) > 1:
        estimator, granularity = choose_granularity(spec, seed, X, y, folds)       # returned fitted
        cv = min(row["cv_rms_3d"] for row in granularity)
    else:
        estimator = spec.build(seed).fit(X, y)
        cv = None
    fit_seconds = time.perf_counter() - start
    if cv is None:
        cv = cross_validated_rms(spec.build(seed), X, y, folds=folds, random_state=seed)
    predictions = {name: estimator.predict(model_inputs(spec.inputs, m)) for name, m in data.items()}
    metrics = {name: summary(m.errors_mm - predictions[name]) for name, m in data.items()}
    locals_ = estimator.models_ if isinstance(estimator, PartitionedErrorModel) else [estimator]
    ratio = float(max(m.rms_ratio_ for m in locals_)) if spec.solver == "pso" else None
    return ModelResult(spec, estimator, fit_seconds, cv, metrics, predictions, ratio, granularity)


def choose_granularity(spec: ModelSpec, seed: int, X, y, folds: int) -> tuple[object, list[dict]]:
    """Choose the partition granularity of an entry (or of its residual) by k-fold cross-validation.

    The same choice as :func:`partcal.models.partitioned.select_granularity`, for any entry kind:
    returns the best candidate fitted on all of ``X, y`` and a row per candidate.
    """
    table, fitted = [], []
    for size in spec.sizes:
        score = cross_validated_rms(spec.build(seed, size), X, y, folds=folds, random_state=seed)
        fitted.append(spec.build(seed, size).fit(X, y))
        regions = partitioned_part(fitted[-1]).partition_.n_regions
        table.append({"granularity": int(size), "cv_rms_3d": score, "regions": int(regions)})
        log.info("%s, granularity %s: CV RMS %.4f over %d regions", spec.name, size, score, regions)
    best = min(range(len(table)), key=lambda i: table[i]["cv_rms_3d"])
    return fitted[best], table


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
    data, robot = load_datasets(config)
    virtual = _virtual_robot(config, robot)
    seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(config.seed).spawn(len(config.models))]
    jobs = [delayed(fit_model)(spec, seed, data, config.cv_folds) for spec, seed in zip(config.models, seeds)]
    results: list[ModelResult] = []
    with _backend(config):
        stream = Parallel(n_jobs=config.n_jobs, return_as="generator")(jobs)
        for result in stream:
            results.append(result)
            if progress:
                progress(len(results), len(jobs), f"{result.spec.name}: CV RMS {result.cv_rms_3d:.3f} mm, "
                                                  f"fitted in {result.fit_seconds:.2f} s")
    if virtual is not None:
        for result in results:
            result.compensation = verify_compensation(result, data, robot, virtual, config.seed)
    uncompensated = {name: summary(m.errors_mm) for name, m in data.items()}
    best = min(results, key=lambda r: r.cv_rms_3d).spec.name
    return RunResult(config, data, robot, uncompensated, results, best, time.perf_counter() - start)


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
