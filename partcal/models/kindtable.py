"""The mechanism of the table of model kinds: its rows, adding and removing one, and a model file's body of any
kind. The built-in rows are :mod:`partcal.models.kinds`; this module imports no estimator, so that an estimator
that holds another (a kinematic model's residual, the two parts of a pose model) can look the other's kind up
without a circle of imports.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from .._validation import FieldReader
from ..errors import ModelFileError, PartcalError
from ..robot.description import MAX_JOINTS
from .base import ErrorModelBase

INPUT_SPACES = ("cartesian", "joint")


@dataclass(frozen=True)
class RegionFit:
    """How the regions of a kind are fitted together, when it is more than each region's own ``fit``
    (a row's ``region_fit``; a kind without one has every region fitted by its public
    ``fit(X, y, sample_weight=w)``, in parallel).

    Attributes
    ----------
    fit_all : callable
        ``fit_all(local, models, data, n_jobs, X, Y, seed) -> fitted models``: fit ``models`` (unfitted
        clones of ``local``, each with its region's seed) on ``data``, one ``(X, Y, weights)`` per region;
        ``X, Y`` are all the samples (in the local models' inputs) and ``seed`` the partition's.
    overlap : callable
        ``overlap(local) -> float``: how far out a region takes its samples, in kernel widths (1: the blend's).
    shares : callable
        ``shares(local) -> bool``: whether the regions share one search (its output mean counted once in the
        partition's effective parameters).
    freeze : callable
        ``freeze(local, X, Y, seed) -> local or None``: the local model with what the shared search learnt on
        ``X, Y`` kept (nested CV's inner folds repeat no search); None when there is nothing to keep.
    """

    fit_all: Callable
    overlap: Callable[[Any], float] = lambda local: 1.0
    shares: Callable[[Any], bool] = lambda local: False
    freeze: Callable = lambda local, X, Y, seed: None


@dataclass(frozen=True)
class Kind:
    """One model kind: its estimator and what it can be and answer (the table's columns).

    Every estimator implements the contract of ``ErrorModelBase`` (fit, predict with its
    spread, its model-file section, its rules). What only some kinds can do or answer is
    a column here, and callers ask through the functions of this module (``swarm_runs``,
    ``equations_of``, ``identification_of``, ...), never by testing types or attributes.

    Attributes
    ----------
    name : str
        Its name in run configs (``kind:``); also the estimator's ``kind``.
    estimator : type
        The estimator class (a subclass of ``ErrorModelBase``).
    in_config : bool
        A run config may name it (a partitioned model is made by ``partition:`` instead).
    regions : bool
        It may be the local model of a partition (``partition:`` and ``blend:`` in its entry). Its
        estimator then fits weighted samples, ``fit(X, y, sample_weight=None)``, and says the smallest
        region it can be fitted on, ``region_minimum(n_active) -> (count, why, config key)``.
    region_fit : RegionFit or None
        How its regions are fitted together (batched swarms, a shared search); None: each by its ``fit``.
    residual : bool
        It may be the residual model of a kind that takes one (``residual:``).
    takes_residual : bool
        Its config entry may give a ``residual`` model (its estimator's parameter ``residual``).
    pose_errors : bool
        It fits (n, 6) pose errors as one model; others are fitted twice in a run of pose errors
        (``models/pose.py``).
    own_prior : bool
        Its own spread holds a prior for what its data left unknown (a kinematic model's unidentified
        parameters): a calibration adds no held inputs' prior (``models/depth.py``).
    swarm : bool
        It may be fitted by particle swarms: its estimator answers ``swarm_runs()`` (best fitness per
        iteration and the least-squares RMS of every swarm; empty when none ran) and ``pso_rms_ratio()``
        (None when no swarm ran).
    equations : bool
        Its estimator answers ``equations(input_names, output_names, precision)``: one line per output,
        or None when its fitted parts have none.
    holds_regions : bool
        Its estimator answers ``regions_model()``: the partitioned model in it (itself, a residual's,
        a part's) or None.
    identified : bool
        It identifies robot parameters: its estimator answers ``identification()`` (the parameter table),
        ``is_physical()`` (every parameter physical), ``run_summary()`` (its fields of metrics.json) and
        ``reads_targets`` (``fit`` takes further targets and the orientation).
    flat_file : bool
        Its section of a model file stands at the file's top level (as partcal 0.1 wrote partitioned
        models), not under ``model``.
    """

    name: str
    estimator: type
    in_config: bool = True
    regions: bool = False
    residual: bool = True
    region_fit: RegionFit | None = None
    takes_residual: bool = False
    pose_errors: bool = False
    own_prior: bool = False
    swarm: bool = False
    equations: bool = False
    holds_regions: bool = False
    identified: bool = False
    flat_file: bool = False

    @property
    def file_kind(self) -> str:
        """Its name in model files."""
        return self.estimator.file_kind or self.name

    def config_keys(self) -> set[str]:
        """The keys its entry of a run config may hold besides ``name`` and ``kind``."""
        keys = set(self.estimator.config_keys()) | ({"residual"} if self.takes_residual else set())
        return keys | ({"partition", "blend"} if self.regions else set())


KINDS: dict[str, Kind] = {}
"""The table: kind name -> row. :mod:`partcal.models.kinds` adds the built-in rows (imported with
:mod:`partcal.models`, so the table is full before any model is read)."""

_BUILT_IN: set[str] = set()


def add_built_in(kind: Kind) -> None:
    """Add a row of partcal's own (:mod:`partcal.models.kinds`); it cannot be unregistered."""
    KINDS.setdefault(kind.name, kind)
    _BUILT_IN.add(kind.name)


def register_kind(kind: Kind) -> Kind:
    """Add a kind to the table (a name, or a model-file name, already taken is refused); returns it."""
    if not (isinstance(kind.estimator, type) and issubclass(kind.estimator, ErrorModelBase)):
        raise PartcalError(f"a model kind's estimator must subclass ErrorModelBase; got {kind.estimator!r}")
    if kind.estimator.kind != kind.name:
        raise PartcalError(f"kind {kind.name!r}: its estimator's class attribute 'kind' is "
                           f"{kind.estimator.kind!r}; they must agree")
    taken = [k.name for k in KINDS.values() if k.name == kind.name or k.file_kind == kind.file_kind]
    if taken:
        raise PartcalError(f"kind {kind.name!r} (model files: {kind.file_kind!r}) is taken by kind {taken[0]!r}")
    KINDS[kind.name] = kind
    return kind


def unregister_kind(name: str) -> None:
    """Remove a kind added by :func:`register_kind` (the built-in ones stay)."""
    if name in _BUILT_IN:
        raise PartcalError(f"kind {name!r} is built in")
    KINDS.pop(name, None)


def config_kinds() -> tuple[str, ...]:
    """The kinds a run config may name."""
    return tuple(name for name, kind in KINDS.items() if kind.in_config)


def may_be_residual(model: Any) -> bool:
    """Whether ``model`` is of a kind that may be the residual of a kind that takes one (its row's ``residual``)."""
    kind = KINDS.get(getattr(type(model), "kind", ""))
    return kind is not None and isinstance(model, kind.estimator) and kind.residual


def residual_kinds() -> tuple[str, ...]:
    """The kinds that may be a residual."""
    return tuple(name for name, kind in KINDS.items() if kind.residual)


def kind_of(model: Any) -> Kind:
    """The row of a model's kind (by its class's ``kind``)."""
    kind = KINDS.get(getattr(type(model), "kind", ""))
    if kind is None or not isinstance(model, kind.estimator):
        raise ModelFileError(f"cannot save a {type(model).__name__}: expected an estimator of a registered kind "
                             f"({', '.join(k.estimator.__name__ for k in KINDS.values())})")
    return kind


def body_of(model: ErrorModelBase) -> dict[str, Any]:
    """The part of a model file that describes the fitted model (a hybrid's residual repeats it)."""
    kind = kind_of(model)
    return {"kind": kind.file_kind, "inputs": model.inputs, "n_inputs": int(model.n_features_in_),
            "n_outputs": model.n_outputs(), **_placed(kind, model.file_section())}


def _placed(kind: Kind, section: dict[str, Any]) -> dict[str, Any]:
    return section if kind.flat_file else {"model": section}


def _section(kind: Kind, r: FieldReader) -> FieldReader:
    """The reader of a kind's section in a body read by ``r``."""
    return r if kind.flat_file else r.sub("model")


def check_body(model: ErrorModelBase, r: FieldReader) -> None:
    """A loaded model's plausibility checks (its ``check_section``) on its section of the body ``r`` reads."""
    model.check_section(_section(kind_of(model), r))


def model_from_body(r: FieldReader) -> ErrorModelBase:
    """The fitted model of :func:`body_of`'s fields, every field checked (failing through ``r``)."""
    by_file = {kind.file_kind: kind for kind in KINDS.values()}
    kind = by_file[r.choice("kind", tuple(by_file))]
    n_in, n_out = r.integer("n_inputs", 1, MAX_JOINTS), r.integer("n_outputs", 1, 6)   # 6: pose errors
    inputs = r.choice("inputs", INPUT_SPACES)
    return kind.estimator.from_file_section(_section(kind, r), inputs, n_in, n_out)


# ---------------------------------------------------------------------- what only some kinds answer
def swarm_runs(model: ErrorModelBase) -> list:
    """``(best fitness per iteration, least-squares RMS)`` of every swarm of the fit; none for a kind without."""
    return model.swarm_runs() if kind_of(model).swarm else []


def pso_rms_ratio(model: ErrorModelBase) -> float | None:
    """RMS of a particle-swarm fit over the least-squares RMS (1.0 optimal); None if no swarm ran."""
    return model.pso_rms_ratio() if kind_of(model).swarm else None


def equations_of(model: ErrorModelBase, input_names=None, output_names=("dx", "dy", "dz"),
                 precision: int | None = None) -> list[str] | None:
    """The fitted functions, one line per output; None for a model without one equation per axis."""
    if not kind_of(model).equations:
        return None
    return model.equations(input_names, output_names, precision)


def regions_of(model: ErrorModelBase):
    """The partitioned model in ``model`` (itself, a hybrid's residual, a pose model's part); None if none."""
    return model.regions_model() if kind_of(model).holds_regions else None


def identification_of(model: ErrorModelBase):
    """The identified parameter table of a model that identifies robot parameters; None for other kinds."""
    return model.identification() if kind_of(model).identified else None


def is_physical(model: ErrorModelBase) -> bool:
    """Whether every parameter of ``model`` is physical (an identification without a data-driven residual)."""
    return kind_of(model).identified and model.is_physical()


def run_summary(model: ErrorModelBase) -> dict[str, Any]:
    """A model's own fields of metrics.json (none for a kind without)."""
    return model.run_summary() if kind_of(model).identified else {}


def reads_targets(model: ErrorModelBase) -> bool:
    """Whether ``model.fit`` takes further targets and the orientation of each pose."""
    return kind_of(model).identified and model.reads_targets


def fits_pose_errors(model: ErrorModelBase) -> bool:
    """Whether ``model`` fits (n, 6) pose errors as one model (its row's ``pose_errors``)."""
    return kind_of(model).pose_errors


def own_prior(model: ErrorModelBase) -> bool:
    """Whether the spread of ``model`` holds its own prior for what its data left unknown (its row's ``own_prior``)."""
    return kind_of(model).own_prior


def regions_kinds() -> tuple[str, ...]:
    """The kinds that may be a partition's local model."""
    return tuple(name for name, kind in KINDS.items() if kind.regions)
