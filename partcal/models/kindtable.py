"""The mechanism of the table of model kinds: its rows, adding and removing one, and a model file's body of any
kind. The built-in rows are :mod:`partcal.models.kinds`; this module imports no estimator, so that an estimator
that holds another (a kinematic model's residual, the two parts of a pose model) can look the other's kind up
without a circle of imports.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .._validation import FieldReader
from ..errors import ModelFileError, PartcalError
from ..robot.description import MAX_JOINTS
from .base import ErrorModelBase

INPUT_SPACES = ("cartesian", "joint")


@dataclass(frozen=True)
class Kind:
    """One model kind.

    Attributes
    ----------
    name : str
        Its name in run configs (``kind:``); also the estimator's ``kind``.
    estimator : type
        The estimator class (a subclass of ``ErrorModelBase``).
    in_config : bool
        A run config may name it (a partitioned model is made by ``partition:`` instead).
    regions : bool
        It may be the local model of a partition (``partition:`` and ``blend:`` in its entry).
    residual : bool
        It may be the residual model of a kind that takes one (``residual:``).
    """

    name: str
    estimator: type
    in_config: bool = True
    regions: bool = False
    residual: bool = True

    @property
    def file_kind(self) -> str:
        """Its name in model files."""
        return self.estimator.file_kind or self.name

    def config_keys(self) -> set[str]:
        """The keys its entry of a run config may hold besides ``name`` and ``kind``."""
        keys = set(self.estimator.config_keys())
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
            "n_outputs": model.n_outputs(), **model.to_file()}


def model_from_body(r: FieldReader) -> ErrorModelBase:
    """The fitted model of :func:`body_of`'s fields, every field checked (failing through ``r``)."""
    by_file = {kind.file_kind: kind for kind in KINDS.values()}
    kind = by_file[r.choice("kind", tuple(by_file))]
    n_in, n_out = r.integer("n_inputs", 1, MAX_JOINTS), r.integer("n_outputs", 1, 6)   # 6: pose errors
    inputs = r.choice("inputs", INPUT_SPACES)
    return kind.estimator.from_file(r, inputs, n_in, n_out)
