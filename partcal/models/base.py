"""What partcal's estimators share: scikit-learn tags for x, y, z outputs, the distance to the
training inputs, ``_prepare`` (what reads need, built once, so that reads store nothing), and one
seed rule."""

from __future__ import annotations

from numbers import Integral

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import check_random_state

from ..metrics import warn_far


class ErrorModelBase(RegressorMixin, BaseEstimator):
    """Base of every error model: multi-output tags, and 1-D targets kept 1-D on the way out."""

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


def seed_from(random_state) -> int:
    """One integer seed from None, an int, a RandomState or a Generator."""
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(2**32))
    if isinstance(random_state, Integral):
        return int(random_state)
    return int(check_random_state(random_state).randint(2**32))
