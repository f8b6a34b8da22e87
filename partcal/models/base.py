"""What partcal's estimators share: scikit-learn tags for x, y, z outputs, the distance to the
training inputs, ``_prepare`` (what reads need, built once, so that reads store nothing), one seed
rule, and what every model kind offers the rest of partcal.

A *model kind* is one estimator class. Besides ``fit`` and ``predict`` it
declares its parameters once (``_parameter_rules``, ``_requirements``: the
estimator's own check, the run-config reader and the model-file reader apply
the same rules), reads and writes its own section of a model file
(:meth:`ErrorModelBase.file_section`, :meth:`ErrorModelBase.from_file_section`)
and answers what a batch run and its report ask (:meth:`ErrorModelBase.min_samples`,
:meth:`ErrorModelBase.describe`, ...). The defaults here serve a simple kind;
``partcal.models.kinds`` is the table that names them all.
"""

from __future__ import annotations

from numbers import Integral
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import check_random_state

from .._validation import Requirement, Rule, check_params
from ..metrics import warn_far

if TYPE_CHECKING:
    from .._validation import FieldReader
    from .._yamlio import Section


class ErrorModelBase(RegressorMixin, BaseEstimator):
    """Base of every error model: multi-output tags, 1-D targets kept 1-D on the way out, and the
    defaults of what a model kind offers (see the module docstring)."""

    kind: ClassVar[str] = ""                       # its name in run configs (``kind:``) and the table of kinds
    file_kind: ClassVar[str] = ""                  # its name in model files (default: ``kind``)
    family_noun: ClassVar[str] = "models"          # the report groups models as "Global joint-input <noun>"
    _parameter_rules: ClassVar[dict[str, Rule]] = {}       # parameter -> what it accepts (and its default)
    _requirements: ClassVar[tuple[Requirement, ...]] = ()  # rules that tie parameters together

    # ------------------------------------------------------------------ parameters
    def _check_rules(self) -> dict[str, Any]:
        """Check the declared parameters (one message format); return them by name."""
        params = {name: getattr(self, name) for name in self._parameter_rules}
        check_params(type(self).__name__, self._parameter_rules, self._requirements, params)
        return params

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
        return set(cls._parameter_rules) | ({"residual"} if cls.takes_residual else set())

    takes_residual: ClassVar[bool] = False       # a config entry may give a ``residual`` model (kinematic)
    fits_pose_errors: ClassVar[bool] = False     # fits (n, 6) pose errors as one model (kinematic); others are
                                                 # fitted twice in a run of pose errors (models/pose.py)

    @classmethod
    def input_space(cls, params: dict[str, Any]) -> str:
        """What a config entry's estimator reads: ``cartesian`` (positions, mm) or ``joint`` (degrees)."""
        return params.get("inputs", "cartesian")

    # ------------------------------------------------------------------ model files
    def to_file(self) -> dict[str, Any]:
        """The fields of a model file beside ``kind``, ``inputs``, ``n_inputs`` and ``n_outputs``."""
        return {"model": self.file_section()}

    @classmethod
    def from_file(cls, r: "FieldReader", inputs: str, n_in: int, n_out: int) -> "ErrorModelBase":
        """The fitted model from the fields :meth:`to_file` wrote (``r`` reads the file's top level)."""
        return cls.from_file_section(r.sub("model"), inputs, n_in, n_out)

    def file_section(self) -> dict[str, Any]:
        """This model's fitted numbers as plain JSON values (its ``model`` section)."""
        raise NotImplementedError(f"{type(self).__name__} does not write model files")

    @classmethod
    def from_file_section(cls, r: "FieldReader", inputs: str, n_in: int, n_out: int) -> "ErrorModelBase":
        """The fitted model from its section, every field checked (failing through ``r``)."""
        raise NotImplementedError(f"{cls.__name__} does not read model files")

    def check_file(self, r: "FieldReader") -> None:
        """Checks of a loaded model as a whole (``r`` reads the fields :meth:`to_file` wrote)."""
        self.check_section(r.sub("model"))

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
    def reads_targets(self) -> bool:
        """Whether ``fit`` takes further targets and the orientation of each pose (a kinematic model's
        ``all_targets``, ``use_orientation``)."""
        return False

    @property
    def reads_payload(self) -> bool:
        """Whether ``fit`` and ``predict`` take a payload per pose (``payload_kg=``) that changes the errors."""
        return False

    def is_physical(self) -> bool:
        """Whether every parameter is physical (a kinematic model without a data-driven residual): a run
        prefers such a model when its CV score is within a standard error of the best."""
        return False

    def fit_notes(self) -> list[str]:
        """What went wrong in a fit without failing it, in words (a run warns of each); none by default."""
        return []

    def frozen(self, X, y) -> "ErrorModelBase":
        """An unfitted copy that repeats no costly search learnt on ``X, y`` (nested CV's inner folds);
        itself when there is nothing to keep."""
        return self

    def peak_fit_bytes(self, n: int, n_joints: int) -> tuple[float, str]:
        """Estimated peak memory of a fit on ``n`` poses (``n_joints`` joints), bytes, and what it assumes.
        Small by default (arrays of ``n x terms``): 0."""
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
        return getattr(self, "solver", "-")

    def family(self) -> str:
        """The report's family of this model (models of one family are compared in one sentence)."""
        inputs = "Cartesian-input" if self.input_space(self.get_params(deep=False)) == "cartesian" else "joint-input"
        return f"Global {inputs} {self.family_noun}"

    def pso_rms_ratio(self) -> float | None:
        """RMS of a particle-swarm fit over the least-squares RMS (1.0 optimal); None if no swarm ran."""
        return None

    def swarm_runs(self) -> list[tuple[np.ndarray, float]]:
        """``(best fitness per iteration, least-squares RMS)`` of every swarm of the fit (none by default)."""
        return []

    def equations(self, input_names=None, output_names=("dx", "dy", "dz"), precision: int | None = None
                  ) -> list[str] | None:
        """The fitted functions, one line per output; None for kinds without one equation per axis."""
        return None

    def regions_model(self) -> "ErrorModelBase | None":
        """The partitioned model in this model (itself, or a hybrid's residual); None if there is none."""
        return None

    def identification(self):
        """The identified parameter table of a kinematic model; None for other kinds."""
        return None

    def run_summary(self) -> dict[str, Any]:
        """Extra fields of this model's entry in metrics.json (none by default)."""
        return {}

    def n_outputs(self) -> int:
        """Outputs per prediction (3: x, y, z)."""
        return int(getattr(self, "n_outputs_", 3))

    def input_bounds(self) -> np.ndarray:
        """``(2, d)``: the smallest and largest training input per column."""
        return self.data_bounds_

    def predict_validated(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`predict` of inputs already checked as a finite ``(n, d)`` float array, ``(n, outputs)``."""
        return np.asarray(self.predict(X)).reshape(len(X), -1)

    # ------------------------------------------------------------------ spread
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
        scale = getattr(self, "spread_scale_", None)
        depth = getattr(self, "spread_depth_", None)
        if depth is not None:                               # std is (n, outputs), as std_validated's
            std = std * depth.factor(X)[:, None]
        if scale is not None:
            std = std * scale
        prior = depth.held_prior(X) if depth is not None else None
        if prior is not None:
            std = np.sqrt(std ** 2 + prior)
        return mean, std

    #: Whether the model's own spread already holds a prior for what its data left unknown (a kinematic
    #: model's unidentified parameters): then a calibration adds no held inputs' prior (models/depth.py).
    own_prior = False

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


def box_points(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The corners of the box ``[lo, hi]`` (of its first 10 inputs, the others at ``lo``) and its centre."""
    n_in = lo.size
    corners = lo + (hi - lo) * ((np.arange(2 ** min(n_in, 10))[:, None] >> np.arange(n_in)) & 1)
    return np.vstack([corners, (lo + hi) / 2])


def seed_from(random_state) -> int:
    """One integer seed from None, an int, a RandomState or a Generator."""
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(2**32))
    if isinstance(random_state, Integral):
        return int(random_state)
    return int(check_random_state(random_state).randint(2**32))
