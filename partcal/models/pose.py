"""Pose errors from two models of one kind: one on the position, one on the orientation.

A run of pose errors (``predict: pose``) fits six columns: the position error (mm) and the
orientation error (a rotation vector, mrad). Series models fit each column on its own, but a
Gaussian process shares its hyperparameters over its outputs, so six columns would let the
orientation choose the length scales of the position (on the IPA UR10 a hybrid's GP residual
left 0.560 mm on held-out poses instead of 0.504). :class:`PoseErrorModel` fits two copies of
a model instead, each with its own search: the position predictions of a pose run are exactly
those of a position run, and the orientation is added beside them. A kinematic model predicts
the orientation from its identified geometry and wraps its residual in the same way.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted

from ..errors import DataError
from ..metrics import ORIENTATION, POSITION
from .base import ErrorModelBase
from .kindtable import body_of, check_body, equations_of, model_from_body, pso_rms_ratio, regions_of, swarm_runs

if TYPE_CHECKING:
    from .._validation import FieldReader

PARTS = ("position", "orientation")


class PoseErrorModel(ErrorModelBase):
    """Pose errors (n, 6): ``model`` fitted on the position errors (mm), a copy on the orientation errors (mrad).

    Parameters
    ----------
    model : estimator
        Any error model of three outputs (series, partitioned, Gaussian process), unfitted; both
        parts are clones of it (its ``random_state`` included).
    orientation : estimator, optional
        The orientation's model, when it differs (:meth:`frozen` gives each its own); default a
        clone of ``model``.

    Attributes
    ----------
    position_, orientation_ : estimator
        The fitted parts, each of three outputs.
    """

    kind = "pose"
    file_kind = "pose"

    def __init__(self, model=None, orientation=None):
        self.model = model
        self.orientation = orientation

    # ------------------------------------------------------------------ fit and predict
    def fit(self, X, y, **per_row) -> "PoseErrorModel":
        """Fit the parts on ``y[:, :3]`` and ``y[:, 3:]``; ``per_row`` (a payload per pose) goes to both."""
        y = np.asarray(y, dtype=float)
        if y.ndim != 2 or y.shape[1] != 6:
            raise DataError(f"Expected pose errors y with shape (n, 6) (mm, then mrad), got shape {y.shape}.")
        self.position_ = clone(self.model).fit(X, y[:, POSITION], **per_row)
        self.orientation_ = clone(self.orientation if self.orientation is not None else self.model).fit(
            X, y[:, ORIENTATION], **per_row)
        self.n_features_in_, self.n_outputs_, self._y_1d = self.position_.n_features_in_, 6, False
        return self

    def predict(self, X, **per_row) -> NDArray[np.float64]:
        """Predicted pose errors, shape (n, 6): mm, then mrad."""
        check_is_fitted(self, "position_")
        return np.hstack([self.position_.predict(X, **per_row), self.orientation_.predict(X, **per_row)])

    def predict_validated(self, X: NDArray[np.float64], **per_row) -> NDArray[np.float64]:
        return np.hstack([self.position_.predict_validated(X, **per_row),
                          self.orientation_.predict_validated(X, **per_row)])

    def std_validated(self, X: NDArray[np.float64], **per_row) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Each part's prediction and standard deviation, side by side: (n, 6) mm then mrad, twice."""
        position, orientation = (part.std_validated(X, **per_row) for part in self._parts())
        return np.hstack([position[0], orientation[0]]), np.hstack([position[1], orientation[1]])

    def spread_problem(self) -> str | None:
        return next((p for p in (part.spread_problem() for part in self._parts()) if p is not None), None)

    def _prepare(self) -> "PoseErrorModel":
        for part in self._parts():
            part._prepare()
        return self

    def _parts(self) -> tuple:
        return self.position_, self.orientation_

    @property
    def train_inputs_(self):
        """The training inputs the parts share (a model file keeps them once, for :meth:`distance_to_data`)."""
        return getattr(self.position_, "train_inputs_", None) if hasattr(self, "position_") else None

    @train_inputs_.setter
    def train_inputs_(self, value) -> None:
        for part in self._parts():
            part.train_inputs_ = value

    # ------------------------------------------------------------------ what the parts share
    @property
    def inputs(self) -> str:
        return self.model.inputs

    @classmethod
    def input_space(cls, params: dict[str, Any]) -> str:
        return params["model"].inputs

    def distance_to_data(self, X) -> NDArray[np.float64]:
        return self.position_.distance_to_data(X)

    def input_bounds(self) -> np.ndarray:
        return self.position_.input_bounds()

    def warn_if_extrapolating(self, X, limit: float = 50.0) -> NDArray[np.bool_]:
        return self.position_.warn_if_extrapolating(X, limit)

    @property
    def reads_payload(self) -> bool:
        return self.model.reads_payload

    def min_samples(self, n_inputs: int) -> tuple[int, str, str | None]:
        return self.model.min_samples(n_inputs)

    def setting_problem(self, n_inputs: int) -> tuple[str, str] | None:
        return self.model.setting_problem(n_inputs)

    def peak_fit_bytes(self, n: int, n_joints: int) -> tuple[float, str]:
        return self.model.peak_fit_bytes(n, n_joints)      # the parts are fitted one after the other

    def frozen(self, X, y) -> "PoseErrorModel":
        """Each part frozen on its own columns (a Gaussian process keeps the hyperparameters it learnt there)."""
        y = np.asarray(y, dtype=float)
        turn = self.orientation if self.orientation is not None else self.model
        return PoseErrorModel(self.model.frozen(X, y[:, POSITION]), turn.frozen(X, y[:, ORIENTATION]))

    def effective_parameters(self) -> float:
        return float(sum(part.effective_parameters() for part in self._parts()))

    def fit_notes(self) -> list[str]:
        return [f"{name} part: {note}" for name, part in zip(PARTS, self._parts()) for note in part.fit_notes()]

    def describe(self) -> str:
        return f"{self.position_.describe()}, one for the position and one for the orientation"

    def family(self) -> str:
        return self.position_.family()

    @property
    def solver_name(self) -> str:
        return self.position_.solver_name

    # ------------------------------------------------------------------ what its parts answer (the table's columns)
    def pso_rms_ratio(self) -> float | None:
        return pso_rms_ratio(self.position_)

    def swarm_runs(self) -> list[tuple[np.ndarray, float]]:
        return swarm_runs(self.position_) + swarm_runs(self.orientation_)

    def equations(self, input_names=None, output_names=("dx", "dy", "dz"), precision: int | None = None
                  ) -> list[str] | None:
        position = equations_of(self.position_, input_names, output_names[:3], precision)
        turn = equations_of(self.orientation_, input_names, ("drx", "dry", "drz"), precision)
        return None if position is None or turn is None else position + turn

    def regions_model(self):
        return regions_of(self.position_)

    def n_outputs(self) -> int:
        return 6

    # ------------------------------------------------------------------ model files
    def file_section(self) -> dict[str, Any]:
        return {name: body_of(part) for name, part in zip(PARTS, self._parts())}

    @classmethod
    def from_file_section(cls, r: "FieldReader", inputs: str, n_in: int, n_out: int) -> "PoseErrorModel":
        """Both parts, each a model of 3 outputs on the same inputs as the file says."""
        if n_out != 6:
            r.fail("", f"a model of pose errors has 6 outputs (n_outputs); the file says {n_out}")
        parts = []
        for name in PARTS:
            part = model_from_body(r.sub(name))
            if part.n_outputs() != 3 or part.inputs != inputs or part.n_features_in_ != n_in:
                r.sub(name).fail("n_outputs", f"a model of 3 outputs on the {n_in} {inputs} inputs of the file; got "
                                              f"{part.n_outputs()} outputs on {part.n_features_in_} {part.inputs} "
                                              "inputs")
            parts.append(part)
        model = cls(model=parts[0], orientation=parts[1])
        model.position_, model.orientation_ = parts
        model.n_features_in_, model.n_outputs_, model._y_1d = n_in, 6, False
        return model

    def check_section(self, r: "FieldReader", limit_mm: float = 1e6) -> None:
        """Each part's own checks, on its section."""
        for name, part in zip(PARTS, self._parts()):
            check_body(part, r.sub(name))
