"""Batch-run configuration: YAML into frozen dataclasses, validated with key paths and lines.

The format is documented in ``docs/config.md``. Paths are relative to the YAML
file. Every problem is reported once as ``FILE: models[2].partition.max_depth
(line 31): must be an int in [0, 8]; got 9``; unknown keys are refused with a
"did you mean" when a known key is close.
"""

from __future__ import annotations

import os
import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .._validation import safe_name
from .._yamlio import Section, load_yaml, range_check
from ..data.formats import MeasurementFormat, RowSelection
from ..data.plausibility import Plausibility
from ..errors import PartcalError
from ..models.gp import GaussianProcessErrorModel
from ..models.kinematic import KinematicModel
from ..models.partition import KMeansPartition, Octree
from ..models.partitioned import PartitionedErrorModel
from ..models.series import ErrorModel
from ..models.swarm import RULES, TOPOLOGIES, SwarmConfig
from ..robot.description import load_robot, robot_reference

RESERVED_NAMES = {"identification", "validation", "file", "fit_seconds", "cv_seconds", "cv", "inputs", "solver",
                  "regions", "pso_rms_ratio", "granularity", "compensation", "kind", "kinematic"}
RANK_RULES = ("cv", "validation")
_SWARM_KEYS = {"particles": "int", "iterations": "int", "c1": "float", "c2": "float", "rule": "str",
               "topology": "str", "neighbours": "int", "inertia": "list", "vmax": "float",
               "bound_scale": "float", "stop_fitness": "float", "patience": "int", "ftol": "float"}


@dataclass(frozen=True)
class PartitionSpec:
    method: str                      # "octree" | "kmeans"
    sizes: tuple[int, ...]           # max_depth or n_regions; several = choose by cross-validation
    min_samples: int | None = None
    blend: str = "gaussian"
    blend_width: float = 0.7

    def build(self, size: int):
        cls = Octree if self.method == "octree" else KMeansPartition
        key = "max_depth" if self.method == "octree" else "n_regions"
        return cls(**{key: size, "min_samples": self.min_samples})


@dataclass(frozen=True)
class GaussianProcessSpec:
    """``kind: gaussian_process`` settings (docs/models.md)."""

    kernel: str = "rbf"
    nu: float = 2.5
    restarts: int = 1
    hyper_samples: int | None = None
    hyperparameters: str = "shared"
    region_overlap: float = 1.0


@dataclass(frozen=True)
class KinematicSpec:
    """``kind: kinematic`` settings: the run's robot and what to identify."""

    robot: str
    base: bool = True
    tool: bool = True
    rcond: float = 1e-6


@dataclass(frozen=True)
class ModelSpec:
    """One entry of the registry: what to fit, how, and how to partition.

    ``kind`` is ``series`` (the polynomial/Fourier ``ErrorModel``),
    ``gaussian_process`` or ``kinematic``; a kinematic entry may carry a
    ``residual`` entry (any other kind) fitted to what it leaves.
    """

    name: str
    inputs: str = "cartesian"
    basis: str = "polynomial"
    degree: int = 1
    harmonics: int = 1
    cross_terms: bool = False
    solver: str = "pso"
    fitness: str = "rms"
    swarm: dict = field(default_factory=dict)
    partition: PartitionSpec | None = None
    kind: str = "series"
    gp: GaussianProcessSpec | None = None
    kinematic: KinematicSpec | None = None
    residual: "ModelSpec | None" = None

    @property
    def slug(self) -> str:
        """A file-name-safe form of the name: ``SDP(CI) octree`` -> ``sdp-ci-octree``."""
        return re.sub(r"[^a-z0-9]+", "-", self.name.lower()).strip("-") or "model"

    @property
    def sizes(self) -> tuple[int, ...]:
        """Candidate granularities of this entry's partition (or its residual's); () if none."""
        part = self.partition or (self.residual.partition if self.residual is not None else None)
        return part.sizes if part is not None else ()

    def local(self, random_state: int | None) -> ErrorModel | GaussianProcessErrorModel:
        if self.kind == "gaussian_process":
            gp = self.gp
            return GaussianProcessErrorModel(inputs=self.inputs, kernel=gp.kernel, nu=gp.nu, restarts=gp.restarts,
                                             hyper_samples=gp.hyper_samples, hyperparameters=gp.hyperparameters,
                                             region_overlap=gp.region_overlap, random_state=random_state)
        pso = SwarmConfig(**self.swarm) if self.solver == "pso" else None
        return ErrorModel(inputs=self.inputs, basis=self.basis, degree=self.degree, harmonics=self.harmonics,
                          cross_terms=self.cross_terms, solver=self.solver, pso=pso, fitness=self.fitness,
                          random_state=random_state)

    def build(self, random_state: int | None, size: int | None = None):
        """The estimator, unfitted (``size`` picks one granularity of the partition, or of the residual's)."""
        if self.kind == "kinematic":
            k = self.kinematic
            residual = self.residual.build(random_state, size) if self.residual is not None else None
            return KinematicModel(robot=load_robot(k.robot), base=k.base, tool=k.tool, rcond=k.rcond,
                                  residual=residual, random_state=random_state)
        local = self.local(random_state)
        if self.partition is None:
            return local
        p = self.partition
        return PartitionedErrorModel(partition=p.build(size if size is not None else p.sizes[0]), local=local,
                                     blend=p.blend, blend_width=p.blend_width, random_state=random_state)


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
    """

    format: MeasurementFormat | None = None
    frame: str = "base"
    rows: dict[str, RowSelection] = field(default_factory=dict)
    own_frame: tuple[str, ...] = ()
    tool_mm: tuple[float, float, float] | None = None
    fit_tool: bool = True
    plausibility: Plausibility = Plausibility()      # data.checks: the limits of plausible data

    @property
    def converted(self) -> bool:
        """True when the run's data are not the files verbatim (format, subset or registration)."""
        return self.format is not None or self.frame != "base" or bool(self.rows)

    def to_dict(self) -> dict:
        return {"format": self.format.to_dict() if self.format else None, "frame": self.frame,
                "rows": {k: v.to_dict() for k, v in self.rows.items()}, "own_frame": list(self.own_frame),
                "registration": ({"tool_mm": list(self.tool_mm) if self.tool_mm else None, "fit_tool": self.fit_tool}
                                 if self.frame == "tracker" else None),
                "checks": {"max_error_of_reach": self.plausibility.max_error_of_reach,
                           "nominal_tolerance_mm": self.plausibility.nominal_tolerance_mm}}


@dataclass(frozen=True)
class RunConfig:
    """A batch run: data, models, and where the results go."""

    name: str
    source: Path
    identification: Path
    tests: dict[str, Path]
    models: tuple[ModelSpec, ...]
    output: Path
    robot: str | None = None
    seed: int = 0
    n_jobs: int = 1
    cv_folds: int = 5
    dask_address: str | None = None
    virtual_robot: Path | None = None
    rank_by: str = "cv"
    validation: Path | None = None
    lines: dict = field(default_factory=dict, compare=False, repr=False)   # key path -> line, for messages

    def fail(self, where: str, message: str):
        """Raise a :class:`ConfigError` naming this file, the key path ``where`` and its line."""
        Section({}, where, self.lines, str(self.source)).fail(where, message)
    data_options: DataOptions = field(default_factory=DataOptions)

    def inputs(self) -> list[Path]:
        """The files this run reads: the config, the data sets, a robot or simulation YAML file."""
        files = [self.source, self.identification, *self.tests.values(), self.validation, self.virtual_robot]
        if self.robot is not None and Path(self.robot).suffix in (".yaml", ".yml"):
            files.append(Path(self.robot))
        return [Path(f) for f in files if f is not None]

    def resolved(self) -> dict:
        """The configuration with every default filled in (written beside the results)."""
        out = asdict(self)
        del out["lines"]
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
        return out


def load_config(path: str | Path) -> RunConfig:
    """Read and validate a batch-run YAML (see ``docs/config.md``)."""
    path = Path(path)
    data, lines = load_yaml(path)
    top = Section(data, "", lines, str(path))
    base = path.parent
    name = top.get("name", "str", check=safe_name)
    robot = top.get("robot", "str", default=None)
    if robot is not None:
        robot_ref = robot_reference(robot, base)
        try:
            load_robot(robot_ref)
        except PartcalError as exc:
            top.fail("robot", str(exc))
        robot = robot_ref
    seed = top.get("seed", "int", default=0, check=range_check(0, 2**32 - 1, integer=True))
    n_jobs = top.get("n_jobs", "int", default=1, check=lambda v: None if v == -1 or v >= 1 else "-1 or >= 1")
    cv_folds = top.get("cv_folds", "int", default=5, check=range_check(2, 100, integer=True))
    rank_by = top.get("rank_by", "str", default="cv", check=_choice_check(*RANK_RULES))
    dask = top.section("dask")
    address = dask.get("address", "str", default=None) if dask.data else None
    dask.done()
    data_sec = top.section("data", required=True)
    ident, tests, validation, data_options = _data(data_sec, top, base, has_robot=robot is not None)
    if rank_by == "validation" and validation is None:
        top.fail("rank_by", "'validation' needs data.validation: FILE, a held-out set measured near the task")
    models_raw = top.get("models", "list", check=lambda v: None if v else "a non-empty list")
    models = tuple(_model(Section(m, f"models[{i}]", lines, str(path)), robot)
                   for i, m in enumerate(models_raw))
    names = [m.name for m in models]
    for i, m in enumerate(models):
        if names.index(m.name) != i:
            top.fail(f"models[{i}].name", f"duplicate model name {m.name!r}")
        if [x.slug for x in models].index(m.slug) != i:
            top.fail(f"models[{i}].name", f"{m.name!r} gives the same file name ({m.slug}) as another model")
    verify = top.section("verify")
    virtual = None
    if verify.data:
        virtual = _existing(verify, "virtual_robot", base)
    verify.done()
    default_out = base.parent / "reports" / name
    output = Path(os.path.normpath(base / top.get("output", "str"))) if top.has("output") else default_out
    top.done()
    return RunConfig(name=name, source=path, identification=ident, tests=tests, models=models,
                     output=Path(os.path.normpath(output)), robot=robot, seed=seed, n_jobs=n_jobs,
                     cv_folds=cv_folds, dask_address=address, virtual_robot=virtual, rank_by=rank_by,
                     validation=validation, lines=lines, data_options=data_options)


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
    frame = data_sec.get("frame", "str", default="base", check=_choice_check("base", "tracker"))
    if frame == "tracker" and not has_robot:
        data_sec.fail(data_sec.path("frame"), "tracker needs a robot model (top-level key 'robot') to register "
                                              "the tracker frame")
    rows: dict[str, RowSelection] = {}
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
    checks = data_sec.section("checks")
    plausibility = Plausibility(checks.get("max_error_of_reach", "float", default=0.05, check=range_check(1e-6, 1)),
                                checks.get("nominal_tolerance_mm", "float", default=0.01, check=range_check(1e-9)))
    checks.done()
    data_sec.done()
    reg = top.section("registration")
    if reg.data and frame != "tracker":
        top.fail("registration", "applies to data.frame: tracker only")
    tool = reg.get("tool_mm", "list", default=None, check=lambda v: None if len(v) == 3 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in v) else "a list of 3 numbers [x, y, z] (mm)")
    fit_tool = reg.get("fit_tool", "bool", default=True)
    reg.done()
    return ident, tests, validation, DataOptions(format=fmt, frame=frame, rows={k: v for k, v in rows.items() if v is not None},
                                     own_frame=tuple(own), tool_mm=tuple(float(x) for x in tool) if tool else None,
                                     fit_tool=fit_tool, plausibility=plausibility)


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
        own = entry.get("registration", "str", default="shared", check=_choice_check("shared", "own")) == "own"
        if own and not tracker:
            entry.fail(entry.path("registration"), "applies to data.frame: tracker only")
    entry.done()
    return path, None if selection.is_all else selection, own


KIND_KEYS = {
    "series": {"inputs", "basis", "degree", "harmonics", "cross_terms", "solver", "partition", "blend"},
    "gaussian_process": {"inputs", "kernel", "nu", "restarts", "hyper_samples", "hyperparameters", "region_overlap",
                         "partition", "blend"},
    "kinematic": {"base", "tool", "rcond", "residual"},
}
KINDS = tuple(KIND_KEYS)


def _model(sec: Section, robot: str | None, parent: str | None = None) -> ModelSpec:
    """One entry of ``models`` (or the ``residual`` of a kinematic entry, named after its ``parent``)."""
    if parent is None:
        name = sec.get("name", "str", check=lambda v: None if v.strip() else "a non-empty text")
    elif sec.has("name"):
        sec.fail(sec.path("name"), "a residual model takes its name from its entry; remove it")
    kind = sec.get("kind", "str", default="series", check=_choice_check(*KINDS))
    if parent is not None and kind == "kinematic":
        sec.fail(sec.path("kind"), "a residual must be 'series' or 'gaussian_process' (the kinematic model is "
                                   "its entry)")
    for key in sec.data:
        if key not in KIND_KEYS[kind] and any(key in keys for keys in KIND_KEYS.values()):
            owners = " or ".join(k for k, keys in KIND_KEYS.items() if key in keys)
            sec.fail(sec.path(key), f"applies to kind: {owners} only; this entry is kind: {kind}")
    name = f"{parent} residual" if parent is not None else name
    if kind == "kinematic":
        return _kinematic_entry(sec, name, robot)
    if kind == "gaussian_process":
        return _gp_entry(sec, name)
    return _series_entry(sec, name)


def _series_entry(sec: Section, name: str) -> ModelSpec:
    """A series model: the basis keys, then ``solver``, ``partition`` and ``blend``."""
    choice = _choice_check
    kw = dict(
        name=name,
        inputs=sec.get("inputs", "str", default="cartesian", check=choice("cartesian", "joint")),
        basis=sec.get("basis", "str", default="polynomial", check=choice("polynomial", "fourier")),
        degree=sec.get("degree", "int", default=1, check=range_check(1, 8, integer=True)),
        harmonics=sec.get("harmonics", "int", default=1, check=range_check(1, 8, integer=True)),
        cross_terms=sec.get("cross_terms", "bool", default=False),
    )
    if kw["cross_terms"] and kw["basis"] != "polynomial":
        sec.fail(sec.path("cross_terms"), "must be false for the fourier basis")
    method, fitness, swarm = _solver(sec.section("solver"))
    kw.update(solver=method, fitness=fitness, swarm=swarm)
    partition = _partition(sec, kw["inputs"])
    sec.done()
    return ModelSpec(**kw, partition=partition)


def _gp_entry(sec: Section, name: str) -> ModelSpec:
    """``kind: gaussian_process``: inputs, kernel, nu, the search's settings, and optionally partition and blend."""
    inputs = sec.get("inputs", "str", default="cartesian", check=_choice_check("cartesian", "joint"))
    kernel = sec.get("kernel", "str", default="rbf", check=_choice_check("rbf", "matern"))
    nu = sec.get("nu", "float", default=2.5, check=lambda v: None if v in (0.5, 1.5, 2.5) else "0.5, 1.5 or 2.5")
    if sec.has("nu") and kernel != "matern":
        sec.fail(sec.path("nu"), "applies to kernel: matern only")
    restarts = sec.get("restarts", "int", default=1, check=range_check(0, 20, integer=True))
    hyper_samples = sec.get("hyper_samples", "int", default=None, check=range_check(20, None, integer=True))
    hyperparameters = sec.get("hyperparameters", "str", default="shared", check=_choice_check("shared", "per_region"))
    overlap = sec.get("region_overlap", "float", default=1.0, check=range_check(1.0, 3.0))
    partition = _partition(sec, inputs)
    for key in ("hyperparameters", "region_overlap"):
        if sec.has(key) and partition is None:
            sec.fail(sec.path(key), "applies to a partitioned GP only (add 'partition')")
    sec.done()
    return ModelSpec(name=name, inputs=inputs, solver="marginal-likelihood", kind="gaussian_process",
                     gp=GaussianProcessSpec(kernel, nu, restarts, hyper_samples, hyperparameters, overlap),
                     partition=partition)


def _kinematic_entry(sec: Section, name: str, robot: str | None) -> ModelSpec:
    """``kind: kinematic``: what to identify, and an optional ``residual`` model entry."""
    if robot is None:
        sec.fail(sec.path("kind"), "kind: kinematic needs the run's robot (top-level key 'robot')")
    spec = KinematicSpec(robot=robot, base=sec.get("base", "bool", default=True),
                         tool=sec.get("tool", "bool", default=True),
                         rcond=sec.get("rcond", "float", default=1e-6,
                                       check=lambda v: None if 0 < v <= 1 else "a number in (0, 1]"))
    residual = None
    if sec.has("residual"):
        sub = sec.section("residual")
        if not sub.data:
            sec.fail(sec.path("residual"), "must be a model entry, e.g. {inputs: joint, degree: 2}")
        residual = _model(sub, robot, parent=name)
    sec.done()
    return ModelSpec(name=name, inputs="joint", solver="levenberg-marquardt", kind="kinematic", kinematic=spec,
                     residual=residual)


def _solver(solver: Section) -> tuple[str, str, dict]:
    """``solver``: the method, the fitness and the swarm settings (checked by ``SwarmConfig``)."""
    choice = _choice_check
    method = solver.get("method", "str", default="pso", check=choice("pso", "lstsq"))
    fitness = solver.get("fitness", "str", default="rms", check=choice("rms", "max", "mae"))
    if method == "lstsq" and fitness != "rms":
        solver.fail(solver.path("fitness"), "must be 'rms' with method: lstsq (least squares minimises the RMS)")
    swarm = {}
    for key, kind in _SWARM_KEYS.items():
        if not solver.has(key):
            continue
        if method != "pso":
            solver.fail(solver.path(key), "applies to method: pso only")
        if solver.data[key] is None and key in ("patience", "stop_fitness"):
            solver.get(key, "any")
            swarm[key] = None
        elif key == "rule":
            swarm[key] = solver.get(key, "str", check=choice(*RULES))
        elif key == "topology":
            swarm[key] = solver.get(key, "str", check=choice(*TOPOLOGIES))
        elif key == "inertia":
            swarm[key] = tuple(solver.get(key, "list"))
        else:
            swarm[key] = solver.get(key, kind)
    if swarm:
        try:
            SwarmConfig(**swarm)
        except PartcalError as exc:
            solver.fail(solver.where, str(exc))
    solver.done()
    return method, fitness, swarm


def _partition(sec: Section, inputs: str) -> PartitionSpec | None:
    """``partition`` and ``blend`` of a model entry (``blend`` needs a partition)."""
    choice = _choice_check
    part = sec.section("partition")
    if not part.data:
        part.done()
        if sec.has("blend"):
            sec.fail(sec.path("blend"), "needs a partition")
        return None
    kind = part.get("method", "str", check=choice("octree", "kmeans"))
    if kind == "octree" and inputs == "joint":
        part.fail(part.path("method"), "octree splits the Cartesian workspace; for joint inputs use method: kmeans")
    size_key = "max_depth" if kind == "octree" else "n_regions"
    low, high = (0, 8) if kind == "octree" else (1, 4096)
    raw = part.get(size_key, "any", default=3 if kind == "octree" else 8)
    sizes = raw if isinstance(raw, list) else [raw]
    if not sizes:
        part.fail(part.path(size_key), "must be an int or a non-empty list of ints; got an empty list")
    for v in sizes:
        if not isinstance(v, int) or isinstance(v, bool) or not low <= v <= high:
            part.fail(part.path(size_key), f"must be an int in [{low}, {high}] (or a list of them, chosen "
                                          f"by cross-validation); got {v!r}")
    min_samples = part.get("min_samples", "int", default=None, check=range_check(1, integer=True))
    part.done()
    blend = sec.section("blend")
    bmethod = blend.get("method", "str", default="gaussian", check=choice("gaussian", "hard"))
    width = blend.get("width", "float", default=0.7, check=range_check(0.6, 10.0))
    blend.done()
    return PartitionSpec(kind, tuple(sizes), min_samples, bmethod, width)


def _choice_check(*allowed: str):
    def check(value):
        return None if value in allowed else "one of " + ", ".join(repr(a) for a in allowed)
    return check
