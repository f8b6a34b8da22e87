"""What partcal's estimators share: scikit-learn tags for x, y, z outputs, and one seed rule."""

from __future__ import annotations

from numbers import Integral

import numpy as np
from numpy.typing import NDArray
from sklearn.base import BaseEstimator, RegressorMixin
from sklearn.utils import check_random_state


class ErrorModelBase(RegressorMixin, BaseEstimator):
    """Base of every error model: multi-output tags, and 1-D targets kept 1-D on the way out."""

    def _shape_output(self, out: NDArray[np.float64]) -> NDArray[np.float64]:
        return out[:, 0] if self._y_1d else out

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
