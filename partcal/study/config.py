"""Batch-run configuration: YAML into frozen dataclasses, validated with key paths and lines.

The format is documented in ``docs/config.md``. Paths are relative to the YAML
file. Every problem is reported once as ``FILE: models[2].partition.max_depth
(line 31): must be an int in [0, 8]; got 9``; unknown keys are refused with a
"did you mean" when a known key is close.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .._validation import integer, one_of, real, safe_name
from .._yamlio import Section, load_yaml
from ..data.formats import MeasurementFormat, RowSelection
from ..data.noise import NoiseModel
from ..data.plausibility import Plausibility
from ..errors import PartcalError
from ..models.kinds import KINDS, config_kinds, fits_pose_errors
from ..models.partition import PARTITIONS
from ..models.partitioned import PartitionedErrorModel
from ..models.pose import PoseErrorModel
from ..calibration.prior import Prior, strengths_of
from ..robot.description import load_robot, robot_reference
from ..robot.kinematics import Robot
from ..robot.urdf import UrdfReference, is_urdf

RESERVED_NAMES = {"identification", "validation", "file", "fit_seconds", "cv_seconds", "cv", "inputs", "solver",
                  "regions", "pso_rms_ratio", "granularity", "compensation", "kind", "kinematic"}
RANK_RULES = ("cv", "validation")
PREDICTED = ("position", "pose")        # predict: what every model of a run predicts
RANKED_ON = ("position", "orientation")  # rank_on: the part of a pose error the run ranks by
FOLD_WORDS = ("auto", "leave_one_out")


@dataclass(frozen=True)
class PartitionSpec:
    method: str                      # a key of partcal.models.partition.PARTITIONS: "octree" | "kmeans"
    sizes: tuple[int, ...]           # max_depth or n_regions; several = choose by cross-validation
    min_samples: int | None = None
    blend: str = "gaussian"
    blend_width: float = 0.7

    def fewest_regions(self, size: int) -> int:
        """Regions a fit at granularity ``size`` must be able to make to be that granularity: k-means
        its ``n_regions``; an octree of depth >= 1 two (a split), of depth 0 one."""
        return size if self.method == "kmeans" else min(size + 1, 2)

    def build(self, size: int):
        cls = PARTITIONS[self.method]
        return cls(**{cls.size_key: size, "min_samples": self.min_samples})


@dataclass(frozen=True)
class ModelSpec:
    """One entry of a run's models: its kind, the kind's parameters, and how to partition.

    ``kind`` names a row of the table of kinds (``partcal.models.kinds``);
    ``params`` are that kind's estimator parameters as the config gave them
    (defaults filled in). A kind that takes one (kinematic) may carry a
    ``residual`` entry of another kind, fitted to what it leaves.
    """

    name: str
    kind: str = "series"
    params: dict = field(default_factory=dict)
    partition: PartitionSpec | None = None
    residual: "ModelSpec | None" = None
    pose: bool = False                  # the run predicts pose errors (predict: pose)

    @property
    def estimator_class(self) -> type:
        return KINDS[self.kind].estimator

    @property
    def inputs(self) -> str:
        """What the entry's model reads: ``cartesian`` (positions, mm) or ``joint`` (angles, degrees)."""
        return self.estimator_class.input_space(self.params)

    @property
    def slug(self) -> str:
        """A file-name-safe form of the name: ``SDP(CI) octree`` -> ``sdp-ci-octree``."""
        return re.sub(r"[^a-z0-9]+", "-", self.name.lower()).strip("-") or "model"

    @property
    def sizes(self) -> tuple[int, ...]:
        """Candidate granularities of this entry's partition (or its residual's); () if none."""
        part = self.partition or (self.residual.partition if self.residual is not None else None)
        return part.sizes if part is not None else ()

    @property
    def strengths(self) -> tuple[float, ...]:
        """Candidate strengths of this entry's prior (``prior_strength``: a list or ``auto``), which the run's
        cross-validation chooses among; () if there is no prior, one if it is a number."""
        if self.params.get("prior") is None:
            return ()
        return strengths_of(self.params.get("prior_strength", 1.0))

    def build(self, random_state: int | None, size: int | None = None, strength: float | None = None):
        """The estimator, unfitted (``size`` picks one granularity of the partition, or of the residual's;
        ``strength`` one prior strength); for pose errors a model of one kind for the position and one for the
        orientation (:class:`~partcal.models.pose.PoseErrorModel`), unless the kind predicts them itself
        (kinematic)."""
        params = self.params if strength is None else {**self.params, "prior_strength": float(strength)}
        model = self.estimator_class.from_params(params, random_state)
        if self.residual is not None:
            model.set_params(residual=self.residual.build(random_state, size))
        if self.partition is not None:
            p = self.partition
            model = PartitionedErrorModel(partition=p.build(size if size is not None else p.sizes[0]), local=model,
                                          blend=p.blend, blend_width=p.blend_width, random_state=random_state)
        return PoseErrorModel(model) if self.pose and not fits_pose_errors(model) else model

    def with_robot(self, robot: Robot) -> "ModelSpec":
        """This entry (and its residual) with ``robot`` as the robot of every kind that takes one (a ``robot``
        parameter): the run's robot, registered, replaces the nominal one the config named."""
        params = {**self.params, "robot": robot} if "robot" in self.params else self.params
        residual = self.residual.with_robot(robot) if self.residual is not None else None
        return dataclasses.replace(self, params=params, residual=residual)


@dataclass(frozen=True)
class DataOptions:
    """How a run reads its data: a foreign format, row subsets, and tracker registration.

    Attributes
    ----------
    format : MeasurementFormat or None
        Applies to every file of the run (``data.format``); None for the contract.
    frame : {"base", "tracker"}
        Frame of the measured positions (``data.frame``); ``tracker`` registers them.
    rows : dict of str to RowSelection
        Row subsets by data set name (``identification`` or a test set's name).
    own_frame : tuple of str
        Test sets measured from another tracker position, registered on themselves.
    tool_mm : tuple of 3 floats or None
        ``registration.tool_mm``: the target's offset in the flange frame, mm.
    fit_tool : bool
        ``registration.fit_tool``: fit the tool offset (``tool_mm`` is then the start).
    noise : NoiseModel or None
        ``data.noise``: the standard deviations of the points of files without ``std_x, std_y, std_z``.
    loss, loss_scale : str, float
        ``registration.loss`` and ``loss_scale``: the registration's robust loss (``linear``: least squares).
    """

    format: MeasurementFormat | None = None
    frame: str = "base"
    rows: dict[str, RowSelection] = field(default_factory=dict)
    own_frame: tuple[str, ...] = ()
    tool_mm: tuple[float, float, float] | None = None
    fit_tool: bool = True
    plausibility: Plausibility = Plausibility()      # data.checks: the limits of plausible data
    groups: str | None = None                         # data.groups: the column naming each row's pose
    cell: Path | None = None                          # data.cell: the cell's planes and points (measurement runs)
    more_identification: tuple[Path, ...] = ()        # data.identification: [A, B, ...]: measurements files after the first
    noise: NoiseModel | None = None                   # data.noise: {constant_mm, ppm, instrument_mm}
    loss: str = "linear"                              # registration.loss
    loss_scale: float = 3.0                           # registration.loss_scale

    @property
    def converted(self) -> bool:
        """True when the run's data are not the files verbatim (format, subset or registration)."""
        return self.format is not None or self.frame != "base" or bool(self.rows)

    def to_dict(self) -> dict:
        return {"format": self.format.to_dict() if self.format else None, "frame": self.frame,
                "rows": {k: v.to_dict() for k, v in self.rows.items()}, "own_frame": list(self.own_frame),
                "registration": ({"tool_mm": list(self.tool_mm) if self.tool_mm else None, "fit_tool": self.fit_tool}
                                 if self.frame == "tracker" else None),
                "checks": {name: getattr(self.plausibility, name) for name in Plausibility.rules},
                "groups": self.groups, **({"cell": str(self.cell)} if self.cell else {}),
                **({"more_identification": [str(p) for p in self.more_identification]}
                   if self.more_identification else {}),
                **({"noise": self.noise.to_dict()} if self.noise is not None else {}),
                **({"registration_loss": {"loss": self.loss, "loss_scale": self.loss_scale}}
                   if self.loss != "linear" else {})}


SPREAD_CALIBRATIONS = ("forward", "contiguous", "folds", "none")


@dataclass(frozen=True)
class SpreadOptions:
    """How a run calibrates every model's spread (``spread:`` in the YAML; docs/config.md).

    ``calibration``: ``forward`` (the identification rows cut into ``folds`` blocks in measurement order,
    each block after the first predicted by the model fitted on the blocks before it: data measured later,
    as a test set is; ``folds - 1`` more fits on 20% to 80% of the rows), ``contiguous`` (each block
    predicted by the model fitted on all the others; ``folds`` more fits), ``folds`` (the run's own
    cross-validation fits, none added; they mix early and late poses) or ``none`` (the model's own spread).
    ``coverage``: the share of held-out residuals the interval ``mean +- z std`` is scaled to hold.
    ``depth``: let the spread grow with the inputs' distance from the middle of the identification inputs
    where the held-out residuals do (:mod:`partcal.models.depth`).
    """

    calibration: str = "forward"
    coverage: float = 0.95
    folds: int = 5
    depth: bool = True


@dataclass(frozen=True)
class RunConfig:
    """A batch run: data, models, and where the results go."""

    name: str
    source: Path
    identification: Path
    tests: dict[str, Path]
    models: tuple[ModelSpec, ...]
    output: Path
    robot: str | None = None           # the robot as the config names it (a built-in name or a YAML path)
    seed: int = 0
    n_jobs: int = 1
    cv_folds: int | str = "auto"        # an int k, "leave_one_out", or "auto" (metrics.fold_rule)
    dask_address: str | None = None
    virtual_robot: Path | None = None
    rank_by: str = "cv"
    validation: Path | None = None
    predict: str = "position"           # position: (n, 3) mm; pose: and the orientation error, mrad (n, 6)
    rank_on: str = "position"           # the part of the errors the ranking reads (orientation: pose runs)
    spread: SpreadOptions = field(default_factory=SpreadOptions)
    lines: dict = field(default_factory=dict, compare=False, repr=False)   # key path -> line, for messages
    nominal_robot: Robot | None = field(default=None, compare=False, repr=False)   # ``robot``, loaded once

    def fail(self, where: str, message: str):
        """Raise a :class:`ConfigError` naming this file, the key path ``where`` and its line."""
        Section({}, where, self.lines, str(self.source)).fail(where, message)
    data_options: DataOptions = field(default_factory=DataOptions)

    def inputs(self) -> list[Path]:
        """The files this run reads: the config, the data sets, a robot or simulation YAML file."""
        files = [self.source, self.identification, *self.data_options.more_identification, *self.tests.values(),
                 self.validation, self.virtual_robot, self.data_options.cell]
        if self.robot is not None and Path(self.robot).suffix in (".yaml", ".yml"):
            files.append(Path(self.robot))
        elif self.robot is not None and is_urdf(self.robot):
            files.append(UrdfReference.parse(self.robot).path)
        return [Path(f) for f in files if f is not None]

    def resolved(self) -> dict:
        """The configuration with every default filled in (written beside the results)."""
        out = asdict(dataclasses.replace(self, nominal_robot=None, models=tuple(
            m.with_robot(self.robot) for m in self.models) if self.robot is not None else self.models))
        del out["lines"], out["nominal_robot"]
        out["source"] = str(self.source)
        out["validation"] = str(self.validation) if self.validation else None
        out["identification"] = str(self.identification)
        out["tests"] = {k: str(v) for k, v in self.tests.items()}
        out["output"] = str(self.output)
        out["virtual_robot"] = str(self.virtual_robot) if self.virtual_robot else None
        out["data_options"] = self.data_options.to_dict()
        for m in out["models"]:
            for entry in (m, m["residual"] or {}):
                if entry.get("partition"):
                    entry["partition"]["sizes"] = list(entry["partition"]["sizes"])
                if isinstance(entry.get("params", {}).get("prior"), dict):      # a model file's prior: its path
                    entry["params"]["prior"] = entry["params"]["prior"]["source"]
                if isinstance(entry.get("params", {}).get("prior_strength"), tuple):
                    entry["params"]["prior_strength"] = list(entry["params"]["prior_strength"])
        return out


def robot_named(reference) -> Robot:
    """The robot a run config or a command names (a built-in name, a robot YAML, a URDF reference): the one
    place the study resolves a robot's name; every later stage gets the object."""
    return load_robot(reference)


def load_config(path: str | Path) -> RunConfig:
    """Read and validate a batch-run YAML (see ``docs/config.md``)."""
    path = Path(path)
    data, lines = load_yaml(path)
    top = Section(data, "", lines, str(path))
    base = path.parent
    name = top.get("name", "str", check=safe_name)
    robot, nominal = top.get("robot", "any", default=None, check=_robot_problem), None
    if robot is not None:
        try:
            robot = robot_reference(robot, base)
            nominal = robot_named(robot)
        except PartcalError as exc:
            top.fail("robot", str(exc))
    seed = top.get("seed", "int", default=0, check=integer(0, 2**32 - 1).problem)
    n_jobs = top.get("n_jobs", "int", default=1, check=lambda v: None if v == -1 or v >= 1 else "-1 or >= 1")
    cv_folds = top.get("cv_folds", "any", default="auto", check=_fold_problem)
    rank_by = top.get("rank_by", "str", default="cv", check=one_of(*RANK_RULES).problem)
    predict = top.get("predict", "str", default="position", check=one_of(*PREDICTED).problem)
    rank_on = top.get("rank_on", "str", default="position", check=one_of(*RANKED_ON).problem)
    if rank_on == "orientation" and predict != "pose":
        top.fail("rank_on", "'orientation' needs predict: pose (the models then predict the orientation error)")
    spread = _spread(top.section("spread"))
    dask = top.section("dask")
    address = dask.get("address", "str", default=None) if dask.data else None
    dask.done()
    data_sec = top.section("data", required=True)
    ident, tests, validation, data_options = _data(data_sec, top, base, has_robot=robot is not None)
    if rank_by == "validation" and validation is None:
        top.fail("rank_by", "'validation' needs data.validation: FILE, a held-out set measured near the task")
    models_raw = top.get("models", "list", check=lambda v: None if v else "a non-empty list")
    models = tuple(dataclasses.replace(_model(Section(m, f"models[{i}]", lines, str(path)), nominal, base=base),
                                       pose=predict == "pose") for i, m in enumerate(models_raw))
    names = [m.name for m in models]
    for i, m in enumerate(models):
        if names.index(m.name) != i:
            top.fail(f"models[{i}].name", f"duplicate model name {m.name!r}")
        if [x.slug for x in models].index(m.slug) != i:
            top.fail(f"models[{i}].name", f"{m.name!r} gives the same file name ({m.slug}) as another model")
    verify = top.section("verify")
    virtual = None
    if top.has("verify"):               # an empty verify would verify nothing, silently
        virtual = _existing(verify, "virtual_robot", base)
    verify.done()
    default_out = base.parent / "reports" / name
    output = Path(os.path.normpath(base / top.get("output", "str"))) if top.has("output") else default_out
    top.done()
    return RunConfig(name=name, source=path, identification=ident, tests=tests, models=models,
                     output=Path(os.path.normpath(output)), robot=robot, seed=seed, n_jobs=n_jobs,
                     cv_folds=cv_folds, dask_address=address, virtual_robot=virtual, rank_by=rank_by,
                     validation=validation, lines=lines, data_options=data_options, predict=predict,
                     rank_on=rank_on, nominal_robot=nominal, spread=spread)


def _spread(sec: Section) -> SpreadOptions:
    """``spread: {calibration: forward | contiguous | folds | none, coverage: 0.95, folds: 5, depth: true}`` (all
    optional); ``folds`` only with ``forward`` or ``contiguous`` (the others cut no blocks)."""
    out = SpreadOptions(
        calibration=sec.get("calibration", "str", default="forward", check=one_of(*SPREAD_CALIBRATIONS).problem),
        coverage=sec.get("coverage", "float", default=0.95,
                         check=lambda v: None if 0.5 <= v < 1.0 else "a number in [0.5, 1)"),
        folds=sec.get("folds", "int", default=5, check=integer(2, 100).problem),
        depth=sec.get("depth", "bool", default=True))
    if sec.has("folds") and out.calibration not in ("forward", "contiguous"):
        sec.fail(sec.path("folds"), f"applies to calibration: forward or contiguous only (calibration: "
                                    f"{out.calibration} cuts no blocks; 'folds' reads the run's cv_folds)")
    if sec.has("depth") and out.calibration == "none":
        sec.fail(sec.path("depth"), "applies to a calibrated spread only (calibration: none keeps each model's own)")
    sec.done()
    return out


def _fold_problem(value) -> str | None:
    """``cv_folds``: an int in [2, 100], ``auto`` or ``leave_one_out``."""
    if value in FOLD_WORDS or (integer(2, 100).problem(value) is None):
        return None
    return "an int in [2, 100], 'auto' or 'leave_one_out'"


def _existing(sec: Section, key: str, base: Path) -> Path:
    rel = sec.get(key, "str")
    target = Path(os.path.normpath(base / rel))
    if not target.is_file():
        sec.fail(sec.path(key), f"no such file: {target}")
    return target


def _data(data_sec: Section, top: Section, base: Path, *, has_robot: bool
          ) -> tuple[Path, dict[str, Path], Path | None, DataOptions]:
    """The ``data`` section (files, ``validation``, ``format``, ``frame``, row subsets) and ``registration``."""
    fmt_sec = data_sec.section("format")
    fmt = MeasurementFormat.from_section(fmt_sec) if fmt_sec.data else None
    frame = data_sec.get("frame", "str", default="base", check=one_of("base", "tracker").problem)
    if frame == "tracker" and not has_robot:
        data_sec.fail(data_sec.path("frame"), "tracker needs a robot model (top-level key 'robot') to register "
                                              "the tracker frame")
    rows: dict[str, RowSelection] = {}
    more: tuple[Path, ...] = ()
    if isinstance(data_sec.data.get("identification"), list):      # several measurements files
        files = data_sec.get("identification", "list", check=lambda v: None if v and all(
            isinstance(f, str) for f in v) else "a file, or a list of files (measurements files and point CSVs)")
        paths = [_listed(data_sec, "identification", k, base) for k in range(len(files))]
        ident, more, rows["identification"] = paths[0], tuple(paths[1:]), None
    else:
        ident, rows["identification"], _ = _data_file(data_sec, "identification", base, tracker=None)
    validation = None
    if data_sec.has("validation"):
        validation, rows["validation"], _ = _data_file(data_sec, "validation", base, tracker=None)
    tests_sec = data_sec.section("tests")
    tests, own = {}, []
    for key in tests_sec.data:
        problem = safe_name(str(key))
        if problem:
            tests_sec.fail(tests_sec.path(str(key)), f"the test-set name {str(key)!r} must be {problem}")
        tests[str(key)], rows[str(key)], own_frame = _data_file(tests_sec, key, base, tracker=frame == "tracker")
        if own_frame:
            own.append(str(key))
    for reserved in RESERVED_NAMES & set(tests):     # they share a JSON object with these keys in metrics.json
        tests_sec.fail(tests_sec.path(reserved), f"a test set may not be called {reserved!r} (reserved: "
                                                 f"{', '.join(sorted(RESERVED_NAMES))})")
    groups = data_sec.get("groups", "str", default=None, check=lambda v: None if v.strip() else "a column name")
    data_sec.renamed("features", "cell")
    cell = _existing(data_sec, "cell", base) if data_sec.has("cell") else None
    checks = data_sec.section("checks")
    plausibility = Plausibility(**{key: checks.rule(key, rule) for key, rule in Plausibility.rules.items()})
    checks.done()
    noise = _noise(data_sec.section("noise")) if data_sec.has("noise") else None
    data_sec.done()
    reg = top.section("registration")
    if reg.data and frame != "tracker":
        top.fail("registration", "applies to data.frame: tracker only")
    tool = reg.get("tool_mm", "list", default=None, check=lambda v: None if len(v) == 3 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in v) else "a list of 3 numbers [x, y, z] (mm)")
    fit_tool = reg.get("fit_tool", "bool", default=True)
    loss = reg.get("loss", "str", default="linear", check=one_of("linear", "huber", "soft_l1", "cauchy").problem)
    loss_scale = reg.rule("loss_scale", real(0.0, 1e3, default=3.0, low_open=True))
    reg.done()
    return ident, tests, validation, DataOptions(format=fmt, frame=frame, rows={k: v for k, v in rows.items() if v is not None},
                                     own_frame=tuple(own), tool_mm=tuple(float(x) for x in tool) if tool else None,
                                     fit_tool=fit_tool, plausibility=plausibility, groups=groups,
                                     cell=cell, more_identification=more, noise=noise, loss=loss,
                                     loss_scale=loss_scale)


def _noise(sec: Section) -> NoiseModel:
    """``noise: {constant_mm: 0.01, ppm: 10, instrument_mm: [x, y, z]}``: at least one part > 0; the instrument
    at the origin of the measured points' frame by default."""
    constant = sec.rule("constant_mm", real(0.0, 1e3, default=0.0))
    ppm = sec.rule("ppm", real(0.0, 1e6, default=0.0))
    at = sec.get("instrument_mm", "list", default=[0.0, 0.0, 0.0], check=lambda v: None if len(v) == 3 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in v) else "a list of 3 numbers [x, y, z] (mm)")
    if constant == 0.0 and ppm == 0.0:
        sec.fail(sec.path("constant_mm"), "constant_mm or ppm must be > 0 (a standard deviation of 0 weighs a "
                                          "point infinitely)")
    sec.done()
    return NoiseModel(float(constant), float(ppm), tuple(float(x) for x in at))


def _listed(sec: Section, key: str, k: int, base: Path) -> Path:
    """Entry ``k`` of the list ``key``: an existing file, relative to the config."""
    target = Path(os.path.normpath(base / sec.data[key][k]))
    if not target.is_file():
        sec.fail(f"{sec.path(key)}[{k}]", f"no such file: {target}")
    return target


def _data_file(sec: Section, key: str, base: Path, *, tracker: bool | None
               ) -> tuple[Path, RowSelection | None, bool]:
    """A data file: a path, or ``{file, rows, every}`` (and ``registration: shared | own`` for a test set)."""
    if not isinstance(sec.data.get(key), dict):
        return _existing(sec, key, base), None, False
    entry = sec.section(key)
    path = _existing(entry, "file", base)
    selection = RowSelection.from_section(entry)
    own = False
    if tracker is not None:
        own = entry.get("registration", "str", default="shared", check=one_of("shared", "own").problem) == "own"
        if own and not tracker:
            entry.fail(entry.path("registration"), "applies to data.frame: tracker only")
    entry.done()
    return path, None if selection.is_all else selection, own


def _model_prior(sec: Section, text: str, base: Path | None, robot: Robot | None):
    """``prior: FILE.json`` of a kinematic entry: another robot's model file (of the same type) as the prior
    (:func:`~partcal.study.update.type_prior`: its row parameters with their plausible errors)."""
    from .persist import load_model
    from .update import type_prior
    from ..calibration.parameters import PLAUSIBLE_ERROR
    from ..models.kinematic import KinematicModel

    path = Path(text) if base is None or Path(text).is_absolute() else base / text
    try:
        model = load_model(path)[0]
        if not isinstance(model, KinematicModel):
            raise PartcalError("expected a model file of kind kinematic")
        if robot is not None and (model.robot_.name != robot.name or model.robot_.n_joints != robot.n_joints):
            raise PartcalError(f"its robot is {model.robot_.name!r}, the run's {robot.name!r}: a prior from another "
                               "robot of the same type")
    except PartcalError as exc:
        sec.fail(sec.path("prior"), f"'plausible' or a kinematic model file; {text!r}: {exc}")
    plausible = {**PLAUSIBLE_ERROR, **((robot if robot is not None else model.robot_).plausible_error or {})}
    return dataclasses.replace(type_prior(model, plausible), source=str(path))


def _model(sec: Section, robot: Robot | None, parent: str | None = None, base: Path | None = None) -> ModelSpec:
    """One entry of ``models`` (or the ``residual`` of a kinematic entry, named after its ``parent``).

    The kind's estimator reads its own keys (``params_from_config``, by its declared rules); this
    reads ``name``, ``kind``, the table's ``partition`` and ``blend``, and a ``residual`` entry.
    """
    if parent is None:
        name = sec.get("name", "str", check=lambda v: None if v.strip() else "a non-empty text")
    elif sec.has("name"):
        sec.fail(sec.path("name"), "a residual model takes its name from its entry; remove it")
    allowed = config_kinds() if parent is None else tuple(k for k in config_kinds() if KINDS[k].residual)
    kind = KINDS[sec.get("kind", "str", default="series", check=_kind_check(allowed, parent))]
    keys = kind.config_keys()
    for key in sec.data:
        owners = [k for k in config_kinds() if key in KINDS[k].config_keys()]
        if key not in keys and owners:
            sec.fail(sec.path(key), f"applies to kind: {' or '.join(owners)} only; this entry is kind: {kind.name}")
    name = f"{parent} residual" if parent is not None else name
    partition = _partition(sec, kind.estimator.input_space(sec.data)) if kind.regions else None
    params = kind.estimator.params_from_config(sec, {"robot": robot, "partitioned": partition is not None,
                                                     "model_prior": functools.partial(_model_prior, base=base, robot=robot)})
    residual = None
    if kind.takes_residual and sec.has("residual"):
        sub = sec.section("residual")
        if not sub.data:
            sec.fail(sec.path("residual"), "must be a model entry, e.g. {inputs: joint, degree: 2}")
        residual = _model(sub, robot, parent=name)
    spec = ModelSpec(name=name, kind=kind.name, params=params, partition=partition, residual=residual)
    _check_prior_fits(sec, spec)
    if len(spec.strengths) > 1 and len(spec.sizes) > 1:
        sec.fail(sec.path("prior_strength"), "the run's cross-validation chooses one list per entry, and this entry "
                 "has a list of granularities too; give prior_strength one number")
    sec.done()
    return spec


def _check_prior_fits(sec: Section, spec: ModelSpec) -> None:
    """A model file given as ``prior`` must hold the parameters this entry identifies (the same parametrization,
    compliance and joint harmonics): refused here, naming the key, rather than when the fit starts."""
    prior = spec.params.get("prior")
    if not isinstance(prior, Prior) or prior.names is None or spec.params.get("robot") is None:
        return
    wanted = spec.build(None).robot_parameter_names()
    if list(prior.names[:len(wanted)]) != wanted:
        first = next((k for k, (a, b) in enumerate(zip(prior.names, wanted)) if a != b), min(len(prior.names),
                                                                                           len(wanted)))
        theirs = prior.names[first] if first < len(prior.names) else "nothing"
        ours = wanted[first] if first < len(wanted) else "nothing"
        sec.fail(sec.path("prior"), f"{Path(prior.source).name!r} was identified with {len(prior.names)} "
                 f"parameters, this entry identifies {len(wanted)} (parameter {first + 1}: {theirs} there, {ours} "
                 "here): another parametrization, compliance or joint harmonics; give a model file of this entry's")


def _kind_check(allowed: tuple[str, ...], parent: str | None):
    rule = one_of(*allowed)

    def check(value):
        if rule.problem(value) is None:
            return None
        if parent is not None and value in config_kinds():
            return f"{rule.expected} (a residual is fitted to what its entry leaves; the entry is the {value} model)"
        return rule.expected
    return check


def _partition(sec: Section, inputs: str) -> PartitionSpec | None:
    """``partition`` and ``blend`` of a model entry (``blend`` needs a partition)."""
    part = sec.section("partition")
    if not part.data:
        part.done()
        if sec.has("blend"):
            sec.fail(sec.path("blend"), "needs a partition")
        return None
    method = part.get("method", "str", check=one_of(*PARTITIONS).problem)
    cls = PARTITIONS[method]
    if inputs == "joint" and not cls.joint_inputs:
        part.fail(part.path("method"), f"{method} splits the Cartesian workspace; for joint inputs use method: "
                                       f"{next(k for k, c in PARTITIONS.items() if c.joint_inputs)}")
    key, rule = cls.size_key, cls.size_rule
    raw = part.get(key, "any", default=rule.default)
    sizes = raw if isinstance(raw, list) else [raw]
    if not sizes:
        part.fail(part.path(key), "must be an int or a non-empty list of ints; got an empty list")
    for v in sizes:
        if rule.problem(v):
            part.fail(part.path(key), f"must be {rule.expected} (or a list of them, chosen by cross-validation); "
                                      f"got {v!r}")
    min_samples = part.rule("min_samples", integer(1, none=True))
    part.done()
    blend = sec.section("blend")
    method_b = blend.rule("method", PartitionedErrorModel.parameter_rule("blend"))
    width = blend.rule("width", PartitionedErrorModel.parameter_rule("blend_width"))
    blend.done()
    return PartitionSpec(method, tuple(sizes), min_samples, method_b, width)


def _robot_problem(value) -> str | None:
    """``robot:`` is a built-in name, a robot YAML or URDF path, or ``{urdf: FILE, base: LINK, tip: LINK}``."""
    if isinstance(value, str) or (isinstance(value, dict) and "urdf" in value):
        return None
    return "a built-in robot name, a robot YAML or URDF file, or {urdf: FILE.urdf, base: LINK, tip: LINK}"
