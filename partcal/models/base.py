"""The contract every model kind implements, and what partcal's estimators share.

A *model kind* is one estimator class, a subclass of :class:`ErrorModelBase`,
and one row of the table of kinds (:mod:`partcal.models.kinds`). The contract
here is what every kind has:

- ``fit(X, y, ...)`` (returns self; the declared parameter rules,
  ``_parameter_rules`` and ``_requirements``, are checked before it runs,
  whatever the kind's ``fit`` does), ``predict(X)``, ``distance_to_data(X)``;
- the spread: ``predict_with_std`` (a kind with one implements
  ``std_validated`` and ``spread_problem``; the default says it has none) and
  the calibrated spread the estimator keeps (``set_spread``,
  ``spread_scale_``, ``spread_depth_``);
- its section of a model file (``file_section``, ``from_file_section``,
  ``check_section``);
- its rules as a run config reads them (``params_from_config``,
  ``from_params``, ``config_keys``, ``input_space``);
- what a run and its report ask of every model, each with a default a simple
  kind keeps (``min_samples``, ``describe``, ``family``, ...).

What only some kinds can answer (swarm runs, equations, an identification, the
partitioned model within, ...) is not here: the kind's row states it and
callers ask through the table (:mod:`partcal.models.kindtable`).
``_prepare`` builds what reads need, once, so that reads store nothing.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, RegressorMixin

from .._validation import Requirement, Rule, check_params, param_error
from ..metrics import warn_far

if TYPE_CHECKING:
    from .._validation import FieldReader
    from .._yamlio import Section


class ErrorModelBase(RegressorMixin, BaseEstimator):
    """Base of every error model: the contract every kind implements (see the module docstring),
    multi-output tags, and 1-D targets kept 1-D on the way out."""

    kind: ClassVar[str] = ""                       # its name in run configs (``kind:``) and the table of kinds
    file_kind: ClassVar[str] = ""                  # its name in model files (default: ``kind``)
    family_noun: ClassVar[str] = "models"          # the report groups models as "Global joint-input <noun>"
    _parameter_rules: ClassVar[dict[str, Rule]] = {}       # parameter -> what it accepts (and its default)
    _requirements: ClassVar[tuple[Requirement, ...]] = ()  # rules that tie parameters together

    def __init_subclass__(cls, **kwargs):
        """Every ``fit`` a kind defines checks the declared parameters first (scikit-learn's ``_fit_context``):
        no kind has to remember to."""
        super().__init_subclass__(**kwargs)
        fit = cls.__dict__.get("fit")
        if fit is not None and not getattr(fit, "checks_rules", False):
            cls.fit = _checking_rules(fit)

    # ------------------------------------------------------------------ the estimator
    def fit(self, X, y):
        """Fit to errors ``y`` (n, outputs) at inputs ``X`` (n, d) in contract units; returns self. A kind whose
        row says ``regions=True`` also takes ``sample_weight`` (n,)."""
        raise NotImplementedError(f"{type(self).__name__} does not implement fit")

    def predict(self, X) -> NDArray[np.float64]:
        """Predicted errors, shape (n, outputs) (1-D if fitted on a 1-D ``y``)."""
        raise NotImplementedError(f"{type(self).__name__} does not implement predict")

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance from each input to the training data, shape (n,), input units (mm or degrees)."""
        raise NotImplementedError(f"{type(self).__name__} does not implement distance_to_data")

    # ------------------------------------------------------------------ parameters
    def _check_rules(self) -> dict[str, Any]:
        """Check the declared parameters (one message format); return them by name."""
        params = {name: getattr(self, name) for name in self._parameter_rules}
        check_params(type(self).__name__, self._parameter_rules, self._requirements, params)
        return params

    @classmethod
    def parameter_rule(cls, name: str) -> Rule:
        """The declared rule of parameter ``name`` (what it accepts, its default), for a reader that reads the
        parameter from a section of its own (the partition's ``blend:`` of a run config)."""
        return cls._parameter_rules[name]

    @classmethod
    def params_from_config(cls, sec: "Section", context: dict) -> dict[str, Any]:
        """This kind's parameters from its entry of a run config: every declared rule, read as a key of
        ``sec`` (defaults filled in), then the requirements. ``context`` holds the run's ``robot``."""
        params = {name: sec.rule(name, rule) for name, rule in cls._parameter_rules.items()}
        sec.requirements(cls._requirements, params)
        return params

    @classmethod
    def from_params(cls, params: dict[str, Any], random_state=None) -> "ErrorModelBase":
        """The unfitted estimator of a config entry's ``params`` (what :meth:`params_from_config` returned)."""
        return cls(**params, random_state=random_state)

    @classmethod
    def config_keys(cls) -> set[str]:
        """The keys of this kind's entry in a run config (besides ``name``, ``kind`` and the table's)."""
        return set(cls._parameter_rules)

    @classmethod
    def input_space(cls, params: dict[str, Any]) -> str:
        """What a config entry's estimator reads: ``cartesian`` (positions, mm) or ``joint`` (degrees)."""
        return params.get("inputs", "cartesian")

    # ------------------------------------------------------------------ model files
    def file_section(self) -> dict[str, Any]:
        """This model's fitted numbers as plain JSON values (its ``model`` section)."""
        raise NotImplementedError(f"{type(self).__name__} does not write model files")

    @classmethod
    def from_file_section(cls, r: "FieldReader", inputs: str, n_in: int, n_out: int) -> "ErrorModelBase":
        """The fitted model from its section, every field checked (failing through ``r``)."""
        raise NotImplementedError(f"{cls.__name__} does not read model files")

    def check_section(self, r: "FieldReader", limit_mm: float = 1e6) -> None:
        """Refuse a loaded model that predicts non-finite errors, or errors over ``limit_mm``, at the
        corners and centre of the box of its data (its numbers are then damaged)."""
        with np.errstate(all="ignore"):
            pred = self.predict_validated(box_points(*self.input_bounds()))
        if not np.all(np.isfinite(pred)) or np.abs(pred).max() > limit_mm:
            worst = f"{np.abs(pred).max():.3g}" if np.all(np.isfinite(pred)) else "a non-finite value"
            r.fail(self._damage_field, f"predicts {worst} mm within the box of its data (limit {limit_mm:g} mm): "
                                       "the fitted numbers are damaged")

    _damage_field: ClassVar[str] = ""           # the field a damaged model's message names ("": the section)

    # ------------------------------------------------------------------ what a run and its report ask
    def min_samples(self, n_inputs: int) -> tuple[int, str, str | None]:
        """Fewest samples a fit on ``n_inputs`` varying inputs needs: ``(count, why, parameter)``, the
        parameter (a key of the config entry) that sets it, or None."""
        return 1, "one sample", None

    def effective_parameters(self) -> float:
        """Effective degrees of freedom of the fitted model over all its outputs (the trace of its hat
        matrix: the coefficient count of a linear model); a run prefers the fewer among physical models
        whose CV scores are within a standard error. NaN when unknown (never preferred as simpler)."""
        return float("nan")

    @property
    def reads_payload(self) -> bool:
        """Whether ``fit`` and ``predict`` take a payload per pose (``payload_kg=``) that changes the errors."""
        return False

    def fit_notes(self) -> list[str]:
        """What went wrong in a fit without failing it, in words (a run warns of each); none by default."""
        return []

    def frozen(self, X, y) -> "ErrorModelBase":
        """An unfitted copy that repeats no costly search learnt on ``X, y`` (nested CV's inner folds);
        itself when there is nothing to keep."""
        return self

    def search_gap(self, other: "ErrorModelBase") -> str | None:
        """How far the hyperparameters this fit searched lie from ``other``'s (another fit of the same entry: a CV
        fold's against the final fit), in words, when markedly; None when they do not, or nothing was searched."""
        return None

    def peak_fit_bytes(self, n: int, n_joints: int, regions: int = 1) -> tuple[float, str]:
        """Estimated peak memory of a fit on ``n`` poses (``n_joints`` joints), as a global model or the local
        model of ``regions`` regions, bytes, and what it assumes. Small by default (arrays of ``n x terms``): 0."""
        return 0.0, ""

    def setting_problem(self, n_inputs: int) -> tuple[str, str] | None:
        """A setting this model cannot be fitted with on ``n_inputs`` varying inputs: ``(config key, what it
        must be)``; None if there is none."""
        return None

    def describe(self) -> str:
        """This model in words, for messages and the report."""
        return f"a {self.kind or type(self).__name__} model"

    @property
    def solver_name(self) -> str:
        """How the model is fitted (metrics.json ``solver``)."""
        return "-"

    def family(self) -> str:
        """The report's family of this model (models of one family are compared in one sentence)."""
        inputs = "Cartesian-input" if self.input_space(self.get_params(deep=False)) == "cartesian" else "joint-input"
        return f"Global {inputs} {self.family_noun}"

    def n_outputs(self) -> int:
        """Outputs per prediction (3: x, y, z)."""
        return int(getattr(self, "n_outputs_", 3))

    def input_bounds(self) -> np.ndarray:
        """``(2, d)``: the smallest and largest training input per column (``data_bounds_``, which every kind's
        ``fit`` sets and its file section restores)."""
        if not hasattr(self, "data_bounds_"):
            raise AttributeError(f"{type(self).__name__} has no data_bounds_: a kind's fit sets it and its file "
                                 "section restores it (docs/architecture.md, 'Adding a model kind')")
        return self.data_bounds_

    def predict_validated(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`predict` of inputs already checked as a finite ``(n, d)`` float array, ``(n, outputs)``."""
        return np.asarray(self.predict(X)).reshape(len(X), -1)

    # ------------------------------------------------------------------ spread
    #: The calibrated spread (:func:`partcal.study.spread.calibrate_spread`, or a model file's): one scale per
    #: output and the growth with the inputs' depth (:class:`~partcal.models.depth.DepthSpread`); None when the
    #: spread is the model's own.
    spread_scale_: NDArray[np.float64] | None = None
    spread_depth_: Any = None

    def set_spread(self, scale, depth=None) -> "ErrorModelBase":
        """Keep a calibrated spread: ``scale`` (one per output, or None) and ``depth`` (a ``DepthSpread`` or
        None); :meth:`std_scaled` and :meth:`predict_with_std` apply them from now on. Returns self."""
        self.spread_scale_ = None if scale is None else np.asarray(scale, dtype=float)
        self.spread_depth_ = depth
        return self

    def predict_with_std(self, X, **per_row) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Predicted errors and the standard deviation of each, both ``(n, outputs)`` (mm; mrad for a pose
        model's orientation).

        The standard deviation is that of the error a measurement at ``X``
        would show: the model's own uncertainty at ``X`` (its fitted numbers
        from data of limited size and noise) and the scatter the model does not
        explain (the noise and what it cannot describe, from its fit). It
        grows where the model extrapolates. ``per_row``: as for ``predict``
        (a payload per pose).
        """
        from sklearn.utils.validation import check_is_fitted, validate_data

        check_is_fitted(self)
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.std_scaled(X, **per_row)

    def std_scaled(self, X: NDArray[np.float64], **per_row) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`std_validated` times the calibrated scales ``spread_scale_`` (one per output) and the growth
        with the inputs' depth ``spread_depth_`` (:class:`~partcal.models.depth.DepthSpread`), with the held
        inputs' prior added, when the model has them (:func:`partcal.study.spread.calibrate_spread`)."""
        mean, std = self.std_validated(X, **per_row)
        scale, depth = self.spread_scale_, self.spread_depth_
        if depth is not None:                               # std is (n, outputs), as std_validated's
            std = std * depth.factor(X)[:, None]
        if scale is not None:
            std = std * scale
        prior = depth.held_prior(X) if depth is not None else None
        if prior is not None:
            std = np.sqrt(std ** 2 + prior)
        return mean, std

    def std_validated(self, X: NDArray[np.float64], **per_row) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`predict_with_std` of inputs already checked as a finite ``(n, d)`` float array."""
        from ..errors import DataError

        raise DataError(self.spread_problem() or f"a {self.kind or type(self).__name__} model gives no standard "
                                                 "deviation of its predictions")

    def spread_problem(self) -> str | None:
        """Why this fitted model cannot give a standard deviation (a model file written before partcal kept what
        it needs); None when it can."""
        return f"a {self.kind or type(self).__name__} model gives no standard deviation of its predictions"

    def warn_if_extrapolating(self, X, limit: float = 50.0) -> NDArray[np.bool_]:
        """Warn (one ``ExtrapolationWarning``) about inputs farther than ``limit`` (mm or degrees) from the
        training data (see ``distance_to_data``); return their mask."""
        return warn_far(self.distance_to_data(X), limit)

    def _shape_output(self, out: NDArray[np.float64]) -> NDArray[np.float64]:
        return out[:, 0] if self._y_1d else out

    def prepared(self):
        """The model with what its reads need built from its fitted attributes (:meth:`_prepare`); for code that
        set those attributes itself, as the model-file reader does (``fit`` builds them already)."""
        return self._prepare()

    def _prepare(self):
        """Build what reads need from the fitted attributes; returns self.

        Called at the end of ``fit``, and after a model file has set the
        fitted attributes directly. Reads (``predict``, ``distance_to_data``,
        ...) only use what is built here and never store anything: the
        estimator is the same object before and after any read. Here: the
        KD-tree over ``train_inputs_`` (when the model keeps them).
        """
        inputs = getattr(self, "train_inputs_", None)
        self._train_tree = None if inputs is None else (inputs, cKDTree(inputs))
        return self

    def _distance_to_train_inputs(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """Distance from each point to the nearest row of ``train_inputs_`` (the KD-tree of :meth:`_prepare`,
        or one built for this call if ``train_inputs_`` was replaced since)."""
        kept = getattr(self, "_train_tree", None)
        tree = kept[1] if kept is not None and kept[0] is self.train_inputs_ else cKDTree(self.train_inputs_)
        return tree.query(X)[0]

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.multi_output = True
        tags.target_tags.single_output = True
        return tags


def _checking_rules(fit):
    """``fit`` with the estimator's declared parameters checked before it runs."""
    @functools.wraps(fit)
    def checked_fit(self, *args, **kwargs):
        self._check_rules()
        return fit(self, *args, **kwargs)

    checked_fit.checks_rules = True
    return checked_fit


def check_sample_weight(owner: str, sample_weight, n: int) -> NDArray[np.float64]:
    """``sample_weight`` as a float array ``(n,)`` of finite values >= 0, not all 0, or one clear refusal."""
    try:
        w = np.asarray(sample_weight, dtype=float)
        w = np.full(n, float(w)) if w.ndim == 0 else w
    except (TypeError, ValueError):
        raise param_error(owner, "sample_weight", f"{n} numbers (one weight per sample)", sample_weight) from None
    if w.shape != (n,):
        raise param_error(owner, "sample_weight", f"{n} numbers (one weight per sample)", f"shape {w.shape}")
    if not np.all(np.isfinite(w) & (w >= 0)):
        raise param_error(owner, "sample_weight", "finite weights >= 0", w[~(np.isfinite(w) & (w >= 0))][:5].tolist())
    if not w.sum() > 0:
        raise param_error(owner, "sample_weight", "weights not all zero", "every weight zero")
    return w


def box_points(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The corners of the box ``[lo, hi]`` (of its first 10 inputs, the others at ``lo``) and its centre."""
    n_in = lo.size
    corners = lo + (hi - lo) * ((np.arange(2 ** min(n_in, 10))[:, None] >> np.arange(n_in)) & 1)
    return np.vstack([corners, (lo + hi) / 2])
