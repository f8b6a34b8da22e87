"""``PartitionedErrorModel``: one local error model per workspace region, blended.

The paper's closing proposal: split the workspace into regions, fit one
polynomial per region, and combine neighbouring models where a path crosses
from one region to the next. Here the combination is a smooth partition of
unity (``blend="gaussian"``, see ``blending``) or a hard switch
(``blend="hard"``, for comparison). Local fits use the same weights as the
prediction (weighted least squares, or a weighted fitness for the swarm), so
fitting and prediction agree.
"""

from __future__ import annotations

import logging
from numbers import Integral

import numpy as np
from joblib import Parallel, delayed
from numpy.typing import NDArray
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import check_choice, check_int, param_error
from ..errors import PartcalError
from ..metrics import cross_validated_rms, distance_outside_boxes, warn_far
from .angles import InputMap
from .base import ErrorModelBase, seed_from
from .bases import varying_inputs
from .blending import block_weights
from .gp import GaussianProcessErrorModel
from .partition import KMeansPartition, Octree, Partition, check_width
from .series import ErrorModel

log = logging.getLogger(__name__)
MIN_SAMPLES_PER_TERM = 3


class PartitionedErrorModel(ErrorModelBase):
    """Error model made of local models on workspace regions.

    Parameters
    ----------
    partition : Octree or KMeansPartition, optional
        Default ``Octree()`` for Cartesian inputs, ``KMeansPartition()`` for
        joint angles.
    local : ErrorModel or GaussianProcessErrorModel, optional
        The model fitted in every region (default ``ErrorModel()``). Its
        ``random_state`` is replaced by a per-region child of this model's
        ``random_state``. With joint-angle inputs the regions and blend
        kernels live in scaled joint space (each joint's training range is
        [-1, 1], joints that never moved left out), and a joint whose data
        straddle ±180 degrees is read in a window where they are contiguous
        (``input_map_``); the local models see those wrapped angles.
    blend : {"gaussian", "hard"}
    blend_width : float
        Kernel width relative to the region's half-size (octree) or
        spread (k-means); larger is smoother.
    n_jobs : int or None
        Regions fitted in parallel (joblib); results do not depend on it.
    random_state : None, int, RandomState or Generator

    Attributes
    ----------
    partition_ : Partition
    models_ : list of ErrorModel or GaussianProcessErrorModel, one per region
    input_map_ : InputMap or None
        Joint-angle inputs: how they are wrapped and scaled for the partition.
    min_samples_ : int
        Smallest number of samples a region was allowed to hold.
    region_counts_ : ndarray
        Samples per region (hard assignment).
    """

    def __init__(self, *, partition=None, local=None, blend="gaussian", blend_width=0.7, n_jobs=None,
                 random_state=None):
        self.partition = partition
        self.local = local
        self.blend = blend
        self.blend_width = blend_width
        self.n_jobs = n_jobs
        self.random_state = random_state

    def _resolved(self) -> tuple[ErrorModel | GaussianProcessErrorModel, Octree | KMeansPartition]:
        own = type(self).__name__
        check_choice(own, "blend", self.blend, ("gaussian", "hard"))
        check_width(self.blend_width)
        if self.n_jobs is not None and not isinstance(self.n_jobs, Integral):
            raise param_error(own, "n_jobs", "an int or None", self.n_jobs)
        local = ErrorModel() if self.local is None else self.local
        if not isinstance(local, (ErrorModel, GaussianProcessErrorModel)):
            raise param_error(own, "local", "an ErrorModel or a GaussianProcessErrorModel", local)
        partition = self.partition
        if partition is None:
            partition = Octree() if local.inputs == "cartesian" else KMeansPartition()
        if not isinstance(partition, (Octree, KMeansPartition)):
            raise param_error(own, "partition", "an Octree or a KMeansPartition", partition)
        return local, partition

    # ------------------------------------------------------------------ fitting
    def fit(self, X, y):
        """Partition the inputs, then fit one weighted local model per region. Returns self."""
        local, spec = self._resolved()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        self.input_map_ = InputMap.fit(X, angles=True) if local.inputs == "joint" else None
        X, S = self._coordinates(X)
        need, why = _region_minimum(local, int(varying_inputs(X).sum()))
        min_samples = spec.min_samples or need
        if X.shape[0] < min_samples:
            raise PartcalError(f"{type(self).__name__}: a region needs at least {min_samples} samples "
                               f"({why}); got {X.shape[0]} samples in all")
        seed = seed_from(self.random_state)
        partition = spec.build(S, min_samples, seed, self.blend_width)
        groups = self._training_groups(partition, S)
        seeds = np.random.SeedSequence(seed).spawn(partition.n_regions)
        jobs = (delayed(_fit_region)(clone(local).set_params(random_state=int(s.generate_state(1)[0])),
                                     X[idx], Y[idx], w) for (idx, w), s in zip(groups, seeds))
        self.models_ = Parallel(n_jobs=self.n_jobs)(jobs)
        self.partition_ = partition
        self.min_samples_ = int(min_samples)
        self.n_outputs_ = Y.shape[1]
        labels = partition.assign(S)
        self.region_counts_ = np.bincount(labels, minlength=partition.n_regions)
        self.region_bounds_ = np.array([[X[labels == r].min(axis=0), X[labels == r].max(axis=0)]
                                        for r in range(partition.n_regions)])
        log.info("fitted %d regions (%s, min %d samples)", partition.n_regions, partition.kind, min_samples)
        return self

    def _coordinates(self, X: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The local models' inputs (joints wrapped) and the partition's coordinates (joints also scaled)."""
        if getattr(self, "input_map_", None) is None:
            return X, X
        wrapped = self.input_map_.wrap(X)
        return wrapped, self.input_map_.scaled(wrapped)

    def assign(self, X) -> NDArray[np.intp]:
        """The region of every input ``X`` (n, d) in contract units, shape (n,)."""
        check_is_fitted(self, "models_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.partition_.assign(self._coordinates(X)[1])

    def _region_blocks(self, partition: Partition, X):
        """Yield ``(rows, regions, weights)`` per block: weights ``(m, R_b)`` of the block's regions."""
        for rows, kernels, own in partition.blocks(X):
            w = block_weights(X[rows], partition.centres[kernels], partition.sigmas[kernels], own, self.blend)
            regions, column = np.unique(partition.kernel_region[kernels], return_inverse=True)
            onehot = np.zeros((kernels.size, regions.size))
            onehot[np.arange(kernels.size), column] = 1.0
            yield rows, regions, w @ onehot          # kernels of one region add up

    def _training_groups(self, partition: Partition, X) -> list[tuple[NDArray[np.intp], NDArray[np.float64]]]:
        """Samples and their blend weights for every region (rows with a positive weight)."""
        parts = [[] for _ in range(partition.n_regions)]
        for rows, regions, w in self._region_blocks(partition, X):
            for j, region in enumerate(regions):
                keep = w[:, j] > 0
                parts[region].append((rows[keep], w[keep, j]))
        return [(np.concatenate([r for r, _ in p]), np.concatenate([w for _, w in p])) for p in parts]

    # ------------------------------------------------------------------ prediction
    def predict(self, X) -> NDArray[np.float64]:
        """Blended prediction, shape (n, n_outputs) mm (1-D if fitted on a 1-D ``y``)."""
        check_is_fitted(self, "models_")
        X, S = self._coordinates(validate_data(self, X, reset=False, dtype=np.float64))
        out = np.empty((X.shape[0], self.n_outputs_))
        for rows, regions, w in self._region_blocks(self.partition_, S):
            xb = X[rows]
            block = np.zeros((rows.size, out.shape[1]))
            for region, wr in zip(regions, np.ascontiguousarray(w.T)):
                model = self.models_[region]
                keep = np.flatnonzero(wr)
                if 2 * keep.size > wr.size:     # most rows: evaluate all, cheaper than gathering
                    block += wr[:, None] * model._predict_trusted(xb)
                elif keep.size:
                    block[keep] += wr[keep, None] * model._predict_trusted(xb[keep])
            out[rows] = block
        return self._shape_output(out)

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """How far each point lies outside the sampled workspace, shape (n,), input units.

        Zero inside the bounding box of some region's own samples; otherwise the
        distance to the nearest such box. Large values mean the prediction is an
        extrapolation and should not be trusted.
        """
        check_is_fitted(self, "models_")
        X = self._coordinates(validate_data(self, X, reset=False, dtype=np.float64))[0]
        return distance_outside_boxes(X, self.region_bounds_[:, 0], self.region_bounds_[:, 1])

    def warn_if_extrapolating(self, X, limit: float = 50.0) -> NDArray[np.bool_]:
        """Warn (``ExtrapolationWarning``) about points farther than ``limit`` from the data; return the mask."""
        return warn_far(self.distance_to_data(X), limit)

def _fit_region(model, X, Y, weights):
    return model._fit(X, Y, weights)


def _region_minimum(local, n_active: int) -> tuple[int, str]:
    """Default smallest region for a local model, and the reason (for the message)."""
    if isinstance(local, GaussianProcessErrorModel):
        local._check_params()
        return local.region_minimum(n_active)
    terms = local._check_params()[0].n_terms(n_active)
    return MIN_SAMPLES_PER_TERM * terms, f"{terms} terms per output"


def select_granularity(model: PartitionedErrorModel, X, y, grid, *, folds: int = 5, random_state=0
                       ) -> tuple[PartitionedErrorModel, list[dict]]:
    """Choose octree depth or k-means region count by k-fold cross-validation.

    Parameters
    ----------
    model : PartitionedErrorModel
        The template; its partition's ``max_depth`` / ``n_regions`` is varied.
    grid : iterable of int
        Candidate depths (octree) or region counts (k-means).

    Returns
    -------
    best : PartitionedErrorModel
        The candidate of lowest CV 3-D RMS, fitted on all of ``X, y``.
    table : list of dict
        ``{"granularity", "cv_rms_3d", "regions"}`` per candidate (regions from a fit on all data).
    """
    check_int("select_granularity", "folds", folds, 2)
    _, spec = model._resolved()
    key = "max_depth" if isinstance(spec, Octree) else "n_regions"
    table, fitted = [], []
    for value in grid:
        candidate = clone(model).set_params(partition=type(spec)(**{**spec.__dict__, key: value}))
        score = cross_validated_rms(candidate, X, y, folds=folds, random_state=random_state)
        fitted.append(candidate.fit(X, y))
        regions = candidate.partition_.n_regions
        table.append({"granularity": int(value), "cv_rms_3d": score, "regions": int(regions)})
        log.info("%s=%s: CV RMS %.4f over %d regions", key, value, score, regions)
    best = min(range(len(table)), key=lambda i: table[i]["cv_rms_3d"])
    return fitted[best], table
