"""The first stage of a run: everything before a fit, and all of ``partcal run --check``.

:func:`prepare` reads every data set once (the run's format and row subsets
applied), registers the tracker frame once on the identification set (and on
a set measured from its own tracker position), draws the cross-validation
folds, and keeps the entries the folds can fit: a granularity no inner fold
supports is left out with a note, an entry no fold supports is refused (every
such entry named in one error). The robot is loaded once, by the config, and
every stage after this one receives it as an object: with a tracker frame it
carries the registered tool offset, and every kind that takes a robot (the
kinematic kind) is given that robot, so that its nominal model is the one the
data's errors were taken from.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..data.measurements import Measurements, read_measurements
from ..data.registration import Registration, register_measurements, registered
from ..data.simulate import load_study
from ..errors import ConfigError, DataError
from ..metrics import HELD_TOLERANCE_DEG, pooled_rms, pose_groups, repeat_scatter_mm
from ..models.features import varying_inputs
from ..robot.kinematics import Robot
from .config import ModelSpec, RunConfig
from .memory import check_memory
from .results import RunPlan
from .selection import CVPlan, measured_poses

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PreparedRun:
    """A run ready to fit: its config, the data sets in the base frame, the robot (registered), the
    registrations by data set name, the plan (folds and feasible entries) and the virtual robot that checks
    compensation (None without ``verify:``)."""

    config: RunConfig
    datasets: dict[str, Measurements]
    robot: Robot | None
    registrations: dict[str, Registration]
    plan: RunPlan
    virtual: object | None = None


def prepare(config: RunConfig) -> PreparedRun:
    """Read, register and check a run; fit nothing (``partcal run --check`` is exactly this)."""
    data, robot, registrations = load_datasets(config)
    plan = check_run(config, data, robot)
    return PreparedRun(config, data, robot, registrations, plan, _virtual_robot(config, robot))


def load_datasets(config: RunConfig) -> tuple[dict[str, Measurements], Robot | None, dict[str, Registration]]:
    """Read the identification and test sets (all with the same joints), in the base frame.

    The run's format and row subsets apply to every file. With ``frame:
    tracker`` the tracker frame (and the tool offset) is registered on the
    identification set and carried to every test set, except those measured
    from their own tracker position; the returned robot then carries the
    registered tool, and the registrations are returned by data set name.
    """
    opts = config.data_options
    robot = config.nominal_robot

    def read(name: str, path) -> Measurements:
        m = read_measurements(path, robot, name=name, fmt=opts.format, rows=opts.rows.get(name), frame=opts.frame,
                              plausibility=opts.plausibility, group_column=opts.groups if name == "identification"
                              else None)
        if m.std_mm is None and opts.noise is not None:        # data.noise: for files without std columns
            m = dataclasses.replace(m, std_mm=opts.noise.std_of(m.measured_mm))
        poses = int(measured_poses(m).max()) + 1
        if poses < len(m):
            log.warning("%s (%s): %d rows measure %d distinct poses (joint angles within %g degrees%s): repeated "
                        "measurements%s", path, name, len(m), poses, HELD_TOLERANCE_DEG,
                        " and payload" if m.payload_kg is not None else "",
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
    if "validation" in data:
        _check_held_out(config, data["identification"], data["validation"])
    if opts.frame != "tracker":
        return data, robot, {}
    return _register(config, data, robot)


def _check_held_out(config: RunConfig, ident: Measurements, validation: Measurements) -> None:
    """Refuse a validation set that measures poses of the identification set (joint angles within
    :data:`~partcal.metrics.HELD_TOLERANCE_DEG`): the models were fitted on them, so its score would not be
    held out, and the run chooses by it (``rank_by: validation``)."""
    groups = pose_groups(np.vstack([ident.q_deg, validation.q_deg]))
    seen = np.isin(groups[len(ident):], groups[:len(ident)])
    if seen.any():
        first = int(np.flatnonzero(seen)[0])
        raise ConfigError(f"{config.validation}: {int(seen.sum())} of {len(validation)} rows of the validation set "
                          f"measure poses of the identification set {config.identification} (joint angles within "
                          f"{HELD_TOLERANCE_DEG:g} degrees; the first: data row {first + 1}); a validation set is "
                          "held out only if no model saw its poses: measure other poses, or drop them")


def _register(config: RunConfig, data: dict[str, Measurements], robot: Robot):
    """Registration on the identification set, shared by the test sets (or their own, when they have one)."""
    opts = config.data_options
    ident = data["identification"]
    shared = register_measurements(robot, ident, tool_mm=opts.tool_mm, fit_tool=opts.fit_tool,
                                   source=f"{config.identification} (identification)", plausibility=opts.plausibility,
                                   loss=opts.loss, loss_scale=opts.loss_scale)
    regs = {}
    for name, m in data.items():
        if name in opts.own_frame:
            regs[name] = register_measurements(robot, m, tool_mm=shared.tool_mm, fit_tool=False,
                                               target_tools_mm=shared.target_tools_mm,
                                               probe_rotation=shared.probe_rotation,
                                               source=f"{config.tests[name]} ({name}, own tracker frame)",
                                               plausibility=opts.plausibility, loss=opts.loss,
                                               loss_scale=opts.loss_scale)
        else:
            regs[name] = shared
    robot = robot.replace(tool_mm=shared.tool_mm.copy())
    out = {name: registered(m, robot, regs[name]) for name, m in data.items()}
    for name, m in out.items():
        rms = pooled_rms(m.errors_mm)
        if regs[name] is shared and name != "identification" and rms > 10 * max(shared.rms_3d, 0.01):
            log.warning("test set %r: %.3g mm 3-D RMS after the identification set's registration (%.3g mm there): "
                        "was the tracker moved? Then give it 'registration: own'", name, rms, shared.rms_3d)
    return out, robot, regs


def check_run(config: RunConfig, data: dict[str, Measurements], robot: Robot | None = None) -> RunPlan:
    """Plan the run, and refuse before anything is fitted every model the identification set cannot support.

    Checks the identification set (at least two poses, some input that
    varies) and, for every model (and its residual), that the smallest
    cross-validation training fold holds enough samples for its terms or for
    one region. A granularity that the inner folds of nested CV cannot give
    its regions is left out with a note, as long as one remains (one left:
    no nesting, so the outer folds must hold it). Every model that cannot be
    fitted is named in one error (the config file, key path and line each).
    The entries of the plan carry ``robot`` (the run's, registered: see
    :func:`load_datasets`) and, where a kind declares ``noise_floor_mm`` and
    the config left it out, the repeat scatter of the data.
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
        if robot is not None:
            entry = entry.with_robot(robot)
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
    if repeats is not None:
        models = [_with_noise_floor(spec, repeats) for spec in models]
    return RunPlan(cv, tuple(models), tuple(notes), repeats)


def _feasible(config: RunConfig, i: int, entry: ModelSpec, ident: Measurements, cv: CVPlan
              ) -> tuple[ModelSpec, list[str]]:
    """The entry with the granularities the folds support, and notes on those left out; ConfigError if none."""
    X = model_inputs(entry.inputs, ident)
    if int(varying_inputs(X).sum()) == 0:
        what = "joint angle" if entry.inputs == "joint" else "nominal coordinate"
        config.fail(_key(config, i, "inputs"), f"every {what} of the identification set "
                                                f"{config.identification} is constant: nothing to fit")
    entry.build(None)                  # what building an estimator checks (a swarm's settings) is refused here
    if entry.params.get("all_targets") and not any(ident.nominal_of(t) is not None for t in ident.target_names[1:]):
        config.fail(_key(config, i, "all_targets"), f"the identification set {config.identification} measures one "
                                                     "target; all_targets needs further ones with their nominal "
                                                     "positions (columns x_meas@B, ..., x_nom@B, ..., or a tracker "
                                                     "registration)")
    if entry.params.get("use_orientation") and not ident.has_orientation:
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
        train = cv.smallest_train(nested=len(sizes) > 1 or len(entry.strengths) > 1)
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


def _virtual_robot(config: RunConfig, robot: Robot | None):
    """The simulated true robot of ``verify.virtual_robot`` (None without one); refused when it simulates
    another robot than the run's."""
    if config.virtual_robot is None:
        return None
    try:
        study = load_study(config.virtual_robot)
    except ConfigError as exc:
        raise ConfigError(f"{config.source}: verify.virtual_robot: {exc}") from None
    if robot is None or study.robot.nominal.name != robot.name:
        raise ConfigError(f"{config.source}: verify.virtual_robot simulates {study.robot.nominal.name!r}, "
                          f"but the run's robot is {robot.name if robot else 'not set'!r}")
    return study.robot
