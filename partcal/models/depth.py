"""How far a prediction's inputs lie from the middle of the training inputs, and the spread's growth with it.

A model's residual scatter is seldom the same everywhere: a polynomial, a kinematic model with
what it leaves, a GP with few poses all fit worse towards the edges of the data than in their
middle, and worse still beyond them. :class:`DepthSpread` measures the *depth* ``d`` of an
input: its Mahalanobis distance from the training inputs' mean, in their own covariance (an
input the training data held still, a wrist at q4 = 0, counts with the smallest standard
deviation ``l`` of the inputs that moved, so turning it is leaving the data; held is the data
layer's rule, a span of at most 0.01 degree or mm, so a joint that jitters is held too; so does a
combination of inputs the data held, q6 = q1 or a tilted plane, and no direction counts with less
than ``l / 10``). The spread is
multiplied by ``sqrt(1 + beta d^2)``: 1 at the middle, growing linearly with ``d`` far out.
``beta`` (between 0 and :data:`BETA_MAX`) is fitted to held-out residuals by
:func:`partcal.study.spread.depth_from_scores`; ``beta = 0`` is a spread the same everywhere.

No held-out residual can say what happens where a held input moves: the data never did. For a
model that knows nothing of the robot (a series, a GP, a partitioned model), the held inputs'
*prior* is that the error may then change as much as the training errors scatter: the variance
``v_k (1 - exp(-D^2 / 2 l^2))`` is added, ``v_k`` the variance of output ``k``'s training errors
and ``D`` how far the held inputs moved (nil where they are where the data held them, all of
``v_k`` once they have moved a few ``l``). A kinematic model has its own prior for what its data
did not identify and takes none of this.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..metrics import HELD_TOLERANCE_DEG, held_joints

BETA_MAX = 4.0          # at one standard deviation of the data from their middle, at most sqrt(5) times as wide


@dataclass(frozen=True)
class DepthSpread:
    """The training inputs' ``centre`` (d,) and ``whiten`` (d, d) (``|(x - centre) whiten|`` is the depth),
    ``beta``: how fast the spread grows with the depth; the inputs the data ``held`` (d,) still, the
    ``length`` ``l`` of their prior and the ``held_variance`` ``v_k`` it reaches (outputs,), None for none."""

    centre: NDArray[np.float64]
    whiten: NDArray[np.float64]
    beta: float = 0.0
    held: NDArray[np.bool_] | None = None
    length: float = 1.0
    held_variance: NDArray[np.float64] | None = None

    @classmethod
    def of_inputs(cls, X, beta: float = 0.0, y=None) -> "DepthSpread | None":
        """The depth of the training inputs ``X`` (n, d), and with their errors ``y`` the held inputs' prior;
        None with fewer than two rows.

        >>> DepthSpread.of_inputs([[0.0, 5.0], [2.0, 5.0]]).depth([[1.0, 5.0], [3.0, 5.0], [1.0, 6.0]]).tolist()
        [0.0, 2.0, 1.0]
        """
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or len(X) < 2:
            return None
        spread = X.std(axis=0)
        moved = ~held_joints(X)
        floor = float(spread[moved].min()) if moved.any() else 1.0
        w, v = np.linalg.eigh(np.atleast_2d(np.cov(X, rowvar=False, bias=True)))
        # a direction the data held still (a held input, or inputs moved together: q6 = q1, a tilted plane)
        # counts with the least moved input's scatter, as a held input does; no direction with less than a
        # tenth of it, so a step off a nearly held combination is not thousands of standard deviations
        w = np.where(w <= HELD_TOLERANCE_DEG ** 2, floor ** 2, np.maximum(w, (0.1 * floor) ** 2))
        held_variance = None
        if y is not None and not moved.all():
            held_variance = np.asarray(y, dtype=float).reshape(len(X), -1).var(axis=0)
        return cls(X.mean(axis=0), v / np.sqrt(w), float(beta), ~moved, floor, held_variance)

    def depth(self, X) -> NDArray[np.float64]:
        """Depth of every input row, in standard deviations of the training inputs, shape (n,)."""
        return np.linalg.norm((np.asarray(X, dtype=float) - self.centre) @ self.whiten, axis=1)

    def factor(self, X) -> NDArray[np.float64]:
        """What the spread of each row is multiplied by: ``sqrt(1 + beta d^2)``, shape (n,)."""
        return np.sqrt(1.0 + self.beta * self.depth(X) ** 2)

    def held_prior(self, X) -> NDArray[np.float64] | None:
        """The variance the held inputs' prior adds to each output of each row, (n, outputs); None without one.

        >>> d = DepthSpread.of_inputs([[0.0, 5.0], [2.0, 5.0]], y=[[1.0], [3.0]])
        >>> d.held_prior([[1.0, 5.0], [1.0, 6.0]]).round(4).tolist()     # l = 1: 1 - exp(-1/2) of v = 1
        [[0.0], [0.3935]]
        """
        if self.held_variance is None or self.held is None or not self.held.any():
            return None
        moved = (np.asarray(X, dtype=float)[:, self.held] - self.centre[self.held]) / self.length
        return -np.expm1(-0.5 * np.sum(moved ** 2, axis=1))[:, None] * self.held_variance

    def to_dict(self) -> dict:
        return {"centre": self.centre.tolist(), "whiten": self.whiten.tolist(), "beta": self.beta,
                "held": None if self.held is None else self.held.tolist(), "length": self.length,
                "held_variance": None if self.held_variance is None else self.held_variance.tolist()}
