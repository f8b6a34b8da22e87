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

import dataclasses
import logging
from numbers import Integral

import numpy as np
from joblib import Parallel, delayed
from numpy.typing import NDArray
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import FieldReader, one_of, param_error
from ..errors import DataError, PartcalError
from ..metrics import distance_outside_boxes
from .angles import InputMap
from .._validation import seed_from
from .base import ErrorModelBase
from .features import varying_inputs
from .combine import BlendWeights, FrameCombiner, combine_generic, region_weights
from .kindtable import KINDS, Kind, RegionFit, pso_rms_ratio, regions_kinds, swarm_runs
from .partition import BLEND_WIDTH, KMeansPartition, Octree, Partition, partition_from_file
from .series import ErrorModel
from .threads import one_blas_thread

log = logging.getLogger(__name__)


class PartitionedErrorModel(ErrorModelBase):
    """Error model made of local models on workspace regions.

    Parameters
    ----------
    partition : Octree or KMeansPartition, optional
        Default ``Octree()`` for Cartesian inputs, ``KMeansPartition()`` for
        joint angles.
    local : estimator, optional
        The model fitted in every region (default ``ErrorModel()``): any estimator of a kind whose
        row in the table of kinds says ``regions=True`` (``ErrorModel``,
        ``GaussianProcessErrorModel``, or a kind registered so). Its
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
    models_ : list of estimators of the local model's kind, one per region
    input_map_ : InputMap or None
        Joint-angle inputs: how they are wrapped and scaled for the partition.
    min_samples_ : int
        Smallest number of samples a region was allowed to hold.
    region_counts_ : ndarray
        Samples per region (hard assignment).
    train_inputs_ : ndarray, shape (n_samples, d)
        The training inputs, for :meth:`distance_to_data`.
    """

    def __init__(self, *, partition=None, local=None, blend="gaussian", blend_width=0.7, n_jobs=None,
                 random_state=None):
        self.partition = partition
        self.local = local
        self.blend = blend
        self.blend_width = blend_width
        self.n_jobs = n_jobs
        self.random_state = random_state

    kind = "partitioned"
    file_kind = "partitioned"
    _parameter_rules = {"blend": one_of("gaussian", "hard"), "blend_width": BLEND_WIDTH}

    @property
    def inputs(self) -> str:
        """What the local models read: ``cartesian`` or ``joint``."""
        return (self.local if self.local is not None else ErrorModel()).inputs

    def _resolved(self) -> tuple[ErrorModelBase, Octree | KMeansPartition]:
        own = type(self).__name__
        self._check_rules()
        if self.n_jobs is not None and not isinstance(self.n_jobs, Integral):
            raise param_error(own, "n_jobs", "an int or None", self.n_jobs)
        local = ErrorModel() if self.local is None else self.local
        if _local_kind(local) is None:
            raise param_error(own, "local", "an ErrorModel or a GaussianProcessErrorModel, or an estimator of "
                              f"another kind that may be a local model ({', '.join(regions_kinds())})", local)
        partition = self.partition
        if partition is None:
            partition = Octree() if local.inputs == "cartesian" else KMeansPartition()
        if not isinstance(partition, (Octree, KMeansPartition)):
            raise param_error(own, "partition", "an Octree or a KMeansPartition", partition)
        if isinstance(partition, Octree) and local.inputs == "joint":
            raise param_error(own, "partition", "a KMeansPartition for joint inputs (an octree splits "
                              "Cartesian boxes)", partition)
        return local, partition

    # ------------------------------------------------------------------ fitting
    def fit(self, X, y):
        """Partition the inputs, then fit one weighted local model per region. Returns self."""
        local, spec = self._resolved()
        fitter = _region_fit(local)
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        self.input_map_ = InputMap.fit(X, angles=True) if local.inputs == "joint" else None
        X, S = self._coordinates(X)
        need, why, _ = local.region_minimum(int(varying_inputs(X).sum()))
        min_samples = spec.min_samples or need
        if X.shape[0] < min_samples:
            raise PartcalError(f"{type(self).__name__}: a region needs at least {min_samples} samples "
                               f"({why}); got {X.shape[0]} samples in all")
        seed = seed_from(self.random_state)
        partition = spec.build(S, min_samples, seed, self.blend_width)
        self._weights, self._combiner = BlendWeights(partition), None
        with one_blas_thread():
            groups = self._training_groups(partition, S, fitter.overlap(local))
        seeds = np.random.SeedSequence(seed).spawn(partition.n_regions)
        models = [clone(local).set_params(random_state=int(s.generate_state(1)[0])) for s in seeds]
        search_seed = seed_from(self.random_state) if fitter.shares(local) else None
        self.models_ = fitter.fit_all(local, models, [(X[idx], Y[idx], w) for idx, w in groups], self.n_jobs,
                                      X, Y, search_seed)
        self.partition_ = partition
        self.min_samples_ = int(min_samples)
        self.n_outputs_ = Y.shape[1]
        labels = partition.assign(S)
        self.region_counts_ = np.bincount(labels, minlength=partition.n_regions)
        self.region_bounds_ = np.array([[X[labels == r].min(axis=0), X[labels == r].max(axis=0)]
                                        for r in range(partition.n_regions)])
        self.train_inputs_ = np.array(X, dtype=np.float64, copy=True)
        log.info("fitted %d regions (%s, min %d samples)", partition.n_regions, partition.kind, min_samples)
        return self._prepare()

    def _prepare(self) -> "PartitionedErrorModel":
        """Build everything a prediction reads (after fitting or loading); returns self.

        Every region model's own (see :meth:`ErrorModelBase._prepare`); for a
        Gaussian blend, the distance matrices of every lookup cell and, where
        the local models allow it, their series re-expressed in every cell's
        frame (:class:`FrameCombiner`); the KD-tree over the training inputs.
        """
        for model in self.models_:
            model._prepare()
        weights = combiner = None
        if self.blend == "gaussian":
            weights = self.__dict__.get("_weights")
            if weights is None or weights.partition is not self.partition_:
                weights = BlendWeights(self.partition_)
            every_cell = range(self.partition_.lookup.n_cells)
            weights.prepare(every_cell)
            if getattr(self, "input_map_", None) is None:
                combiner = FrameCombiner.build(self.partition_, self.models_)
            if combiner is not None:
                combiner.prepare(every_cell)
        self._weights, self._combiner = weights, combiner
        return super()._prepare()

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

    def _training_groups(self, partition: Partition, X, reach: float = 1.0
                         ) -> list[tuple[NDArray[np.intp], NDArray[np.float64]]]:
        """Samples and their blend weights for every region (rows with a positive weight).

        ``reach > 1`` (Gaussian-process regions only, which use the weights
        only to pick their samples): the weights of kernels ``reach`` times
        wider, so every region gets the samples that far out.
        """
        weights = self._weights
        if reach != 1.0:
            partition = dataclasses.replace(partition, sigmas=partition.sigmas * reach)
            weights = BlendWeights(partition)
        if self.blend == "hard" and reach == 1.0:
            labels = partition.assign(X)
            return [(np.flatnonzero(labels == r), np.ones(int(np.sum(labels == r))))
                    for r in range(partition.n_regions)]
        parts = [[] for _ in range(partition.n_regions)]
        plan, _, blocks = weights.blocks(X)
        for block in blocks:
            regions, W = region_weights(partition.kernel_region[block.kernels], block.weights)
            rows = plan.order[block.positions]
            for region, w in zip(regions.tolist(), W):
                keep = w > 0
                parts[region].append((rows[keep], w[keep]))
        return [(np.concatenate([r for r, _ in p]), np.concatenate([w for _, w in p])) for p in parts]

    # ------------------------------------------------------------------ prediction
    def predict(self, X) -> NDArray[np.float64]:
        """Blended prediction, shape (n, n_outputs) mm (1-D if fitted on a 1-D ``y``).

        Polynomial local models (and Fourier ones of joint angles) are evaluated
        once per block in the lookup cell's frame; other local models, and
        points outside the lookup grid, are evaluated region by region. Both
        give the same blend (tested against a sum over all kernels).
        """
        check_is_fitted(self, "models_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        with one_blas_thread():
            return self._shape_output(self._predict_blend(X, fast=True))

    def _predict_blend(self, X: NDArray[np.float64], fast: bool) -> NDArray[np.float64]:
        """Prediction ``(n, n_outputs)`` on validated inputs; ``fast=False`` forces the region-by-region way.

        Weights come from the partition's coordinates; the local models see
        their own inputs (the same, except for joint angles, which are scaled
        for the partition). Re-expressing local series in a lookup cell's
        frame needs the two to be one space, so joint-input models take the
        region-by-region way.
        """
        X, S = self._coordinates(X)
        n_out = self.n_outputs_
        out = np.empty((X.shape[0], n_out))
        if self.blend == "hard":
            labels = self.partition_.assign(S)
            for region in np.unique(labels).tolist():
                rows = np.flatnonzero(labels == region)
                out[rows] = self.models_[region].predict_validated(X[rows])
            return out
        weights, combiner = self._blend_caches(fast and S is X)
        plan, Ss, blocks = weights.blocks(S)
        Xs = Ss if S is X else np.take(X, plan.order, axis=0)
        if combiner is not None:
            combiner.prepare(plan.cells.tolist())
        sorted_out = np.empty((n_out, X.shape[0]))            # outputs by points: blocks fill columns
        region_of = self.partition_.kernel_region
        for block in blocks:
            xb = Xs[block.positions]
            if combiner is not None and block.cell >= 0:
                sorted_out[:, block.positions] = combiner.combine(block, xb)
            else:
                sorted_out[:, block.positions] = combine_generic(self.models_, region_of, xb, block.kernels,
                                                                 block.weights, n_out).T
        out[plan.order] = sorted_out.T
        return out

    def std_validated(self, X: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Blended prediction and its standard deviation, both (n, outputs) mm.

        A point's prediction is the mixture of its regions' predictive
        distributions with the blend weights ``w_r``: mean ``sum w_r m_r`` and
        variance ``sum w_r (s_r^2 + m_r^2) - mean^2``, so where regions
        disagree (near their borders) the spread grows too. A hard blend takes
        its region's.
        """
        problem = self.spread_problem()
        if problem is not None:
            raise DataError(problem)
        X, S = self._coordinates(X)
        n_out = self.n_outputs_
        if self.blend == "hard":
            mean, std = np.empty((X.shape[0], n_out)), np.empty((X.shape[0], n_out))
            labels = self.partition_.assign(S)
            for region in np.unique(labels).tolist():
                rows = np.flatnonzero(labels == region)
                mean[rows], std[rows] = self.models_[region].std_validated(X[rows])
            return mean, std
        weights, _ = self._blend_caches(False)
        plan, _, blocks = weights.blocks(S)
        parts: dict[int, list] = {}                     # region -> (rows, weights) of every block
        for block in blocks:
            rows = plan.order[block.positions]
            regions, W = region_weights(self.partition_.kernel_region[block.kernels], block.weights)
            for region, w in zip(regions.tolist(), W):
                keep = np.flatnonzero(w)
                parts.setdefault(region, []).append((rows[keep], w[keep]))
        first, second = np.zeros((X.shape[0], n_out)), np.zeros((X.shape[0], n_out))
        for region, pieces in parts.items():           # one call per region (a GP factorises its data once)
            rows, w = np.concatenate([r for r, _ in pieces]), np.concatenate([v for _, v in pieces])
            if rows.size:
                m, sd = self.models_[region].std_validated(X[rows])
                np.add.at(first, rows, w[:, None] * m)
                np.add.at(second, rows, w[:, None] * (sd**2 + m**2))
        return first, np.sqrt(np.maximum(second - first**2, 0.0))

    def spread_problem(self) -> str | None:
        return next((p for p in (m.spread_problem() for m in self.models_) if p is not None), None)

    def _blend_caches(self, frames: bool) -> tuple[BlendWeights, FrameCombiner | None]:
        """The blend weights and frame combiner of :meth:`_prepare` (the combiner only if ``frames``);
        made for this call, and not kept, if the partition was replaced since (or never prepared)."""
        weights, combiner = self.__dict__.get("_weights"), self.__dict__.get("_combiner")
        if weights is None or weights.partition is not self.partition_:
            weights = BlendWeights(self.partition_)
            combiner = FrameCombiner.build(self.partition_, self.models_) if frames else None
        return weights, combiner if frames else None

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance from each point to the nearest training input, shape (n,), input units.

        Exact (a KD-tree over the training inputs, kept in the fitted model and
        its model file). Large values mean the prediction is an extrapolation
        and should not be trusted. Models loaded from files written before
        partcal kept the training inputs fall back to the distance outside the
        nearest region's sample box, which reads far too small between and
        beyond the regions.
        """
        check_is_fitted(self, "models_")
        X = self._coordinates(validate_data(self, X, reset=False, dtype=np.float64))[0]
        if getattr(self, "train_inputs_", None) is None:
            return distance_outside_boxes(X, self.region_bounds_[:, 0], self.region_bounds_[:, 1])
        return self._distance_to_train_inputs(X)


    # ------------------------------------------------------------------ the kind: files, run, report
    def file_section(self) -> dict:
        """A partitioned model's fields (at the file's top level, as partcal 0.1 wrote them: its row's
        ``flat_file``)."""
        imap = getattr(self, "input_map_", None)
        local = self.models_[0]
        return dict(local_kind=local.kind, input_map=imap.to_dict() if imap is not None else None,
                    blend={"method": self.blend, "width": float(self.blend_width)},
                    partition=self.partition_.to_dict(), region_bounds=self.region_bounds_.tolist(),
                    region_counts=self.region_counts_.tolist(), min_samples=int(self.min_samples_),
                    regions=[m.file_section() for m in self.models_])

    @classmethod
    def from_file_section(cls, r: FieldReader, inputs: str, n_in: int, n_out: int) -> "PartitionedErrorModel":
        blend = r.sub("blend")
        model = cls(blend=blend.rule("method", cls._parameter_rules["blend"]),
                    blend_width=blend.rule("width", cls._parameter_rules["blend_width"]))
        local_kinds = {name: KINDS[name].estimator for name in regions_kinds()}
        local_cls = local_kinds[r.choice("local_kind", tuple(local_kinds))] if "local_kind" in r.doc else ErrorModel
        model.input_map_ = InputMap.from_file(r.sub("input_map"), n_in) if r.doc.get("input_map") is not None else None
        p = r.sub("partition")
        m = p.integer("n_regions", 1)
        model.region_bounds_ = r.array("region_bounds", (m, 2, n_in))
        if np.any(model.region_bounds_[:, 0] > model.region_bounds_[:, 1]):
            r.fail("region_bounds", "a low bound exceeds its high bound")
        # the partition's coordinates: the scaled varying joints under an input map, else the inputs themselves
        d = max(model.input_map_.n_active, 1) if model.input_map_ is not None else n_in
        if "active" in p.doc:
            active = p.array("active", (d,), bool)
        else:        # partcal 0.1 blended along the axes its regions span
            active = varying_inputs(model.region_bounds_.reshape(-1, n_in))
        partition = partition_from_file(p, m, d, active)
        regions = r.get("regions", list)
        if len(regions) != m:
            r.fail("regions", f"expected {m} region models (partition.n_regions); got {len(regions)}")
        model.models_ = [local_cls.from_file_section(r.sub(f"regions[{i}]", item), inputs, n_in, n_out)
                         for i, item in enumerate(regions)]
        model.partition_ = partition
        model.region_counts_ = r.array("region_counts", (m,), int)
        model.min_samples_ = r.integer("min_samples", 1)
        if np.any(model.region_counts_ < 0):
            r.fail("region_counts", "counts must be >= 0")
        model.n_features_in_, model.n_outputs_, model._y_1d = n_in, n_out, False
        model.local = clone(model.models_[0])
        return model

    def check_section(self, r: FieldReader, limit_mm: float = 1e6) -> None:
        """Every region's model is checked on the box of its own data."""
        for k, (local, item) in enumerate(zip(self.models_, r.doc["regions"])):
            local.check_section(r.sub(f"regions[{k}]", item))

    def min_samples(self, n_inputs: int) -> tuple[int, str, str]:
        local, spec = self._resolved()
        need, why, key = local.region_minimum(n_inputs)
        need = spec.min_samples or need
        return need, f"one region of {need} samples ({why} ({n_inputs} varying {local.inputs} inputs))", key

    def peak_fit_bytes(self, n: int, n_joints: int, regions: int = 1) -> tuple[float, str]:
        """The local model's fit with the fewest regions the partition may make (an octree of depth ``t``
        counted as ``2^t`` regions, a k-means one as its ``n_regions``): the largest regions."""
        local, spec = self._resolved()
        regions = 2**spec.max_depth if isinstance(spec, Octree) else spec.n_regions
        return local.peak_fit_bytes(n, n_joints, regions=regions)

    def setting_problem(self, n_inputs: int) -> tuple[str, str] | None:
        """A region may not be set smaller than the fewest samples a fit of the local model needs."""
        local, spec = self._resolved()
        if spec.min_samples is not None:
            need, why, _ = local.min_samples(n_inputs)
            if spec.min_samples < need:
                return "partition.min_samples", (f"must be at least the local model's {why.split(' (')[0]}; "
                                                 f"got {spec.min_samples}")
        return None

    def describe(self) -> str:
        local, spec = self._resolved()
        if not hasattr(self, "partition_"):
            return f"{local.describe()} in each region of a {type(spec).__name__}"
        n = self.partition_.n_regions
        return f"{local.describe()} in each of {n} {self.partition_.region_noun}{'s' if n != 1 else ''}, blended"

    @property
    def solver_name(self) -> str:
        return self._resolved()[0].solver_name

    def family(self) -> str:
        local = self._resolved()[0]
        return "Partitioned" + local.family()[len("Global"):]

    def effective_parameters(self) -> float:
        """The regions' own, summed (the blend shares them between regions: an upper bound); Gaussian
        processes with shared hyperparameters share one output mean too, counted once."""
        total = float(sum(m.effective_parameters() for m in self.models_))
        local = self._resolved()[0]
        if _region_fit(local).shares(local):
            total -= (len(self.models_) - 1) * self.n_outputs_
        return total

    def fit_notes(self) -> list[str]:
        return sorted({note for m in self.models_ for note in m.fit_notes()})

    def frozen(self, X, y) -> "PartitionedErrorModel":
        """With regions that share one search (Gaussian processes with shared hyperparameters): what it
        learns on ``X, y`` kept (the local kind's ``RegionFit.freeze``); otherwise itself."""
        local, _ = self._resolved()
        fitter = _region_fit(local)
        if not fitter.shares(local):
            return self
        X, y = np.asarray(X, dtype=float), np.asarray(y, dtype=float)
        Y = y.reshape(len(y), -1)
        coords = InputMap.fit(X, angles=True).wrap(X) if local.inputs == "joint" else X     # as fit() does
        kept = fitter.freeze(local, coords, Y, seed_from(self.random_state))
        return self if kept is None else clone(self).set_params(local=kept)

    def pso_rms_ratio(self) -> float | None:
        ratios = [pso_rms_ratio(m) for m in self.models_]
        return None if any(v is None for v in ratios) else float(max(ratios))

    def swarm_runs(self) -> list[tuple[np.ndarray, float]]:
        return [run for m in self.models_ for run in swarm_runs(m)]

    def regions_model(self) -> "PartitionedErrorModel":
        return self

    def with_granularity(self, value: int) -> "PartitionedErrorModel":
        """An unfitted copy with octree depth or k-means region count ``value`` (a candidate of a granularity
        choice, :func:`partcal.study.selection.select_granularity`)."""
        _, spec = self._resolved()
        key = "max_depth" if isinstance(spec, Octree) else "n_regions"
        return clone(self).set_params(partition=type(spec)(**{**spec.__dict__, key: value}))

    def n_outputs(self) -> int:
        return int(self.n_outputs_)

    def input_bounds(self) -> NDArray[np.float64]:
        """The box of all regions' samples (in the local models' inputs: joints wrapped)."""
        return np.stack([self.region_bounds_[:, 0].min(axis=0), self.region_bounds_[:, 1].max(axis=0)])

    def predict_validated(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.predict(X).reshape(len(X), -1)


def _local_kind(local) -> Kind | None:
    """The row of a local model's kind if that kind may be a partition's local model (its ``regions``)."""
    kind = KINDS.get(type(local).kind) if isinstance(local, ErrorModelBase) else None
    return kind if kind is not None and isinstance(local, kind.estimator) and kind.regions else None


def _region_fit(local: ErrorModelBase) -> RegionFit:
    """How the local model's regions are fitted: its kind's ``region_fit``, or each region by its public ``fit``."""
    return _local_kind(local).region_fit or EACH_REGION


def _fit_each(local, models: list, data: list[tuple], n_jobs, X=None, Y=None, seed=None) -> list:
    """Every region's model fitted on its ``(X, Y, weights)`` by its public ``fit``, in parallel."""
    return Parallel(n_jobs=n_jobs)(delayed(_fit_one)(m, *d) for m, d in zip(models, data))


def _fit_one(model, X, Y, weights):
    return model.fit(X, Y, sample_weight=weights)


EACH_REGION = RegionFit(fit_all=_fit_each)


def fold_regions(models: list[PartitionedErrorModel]) -> list[int]:
    """``[fewest, most]`` regions among fitted partitioned ``models`` (the fits on the CV folds)."""
    counts = [int(m.partition_.n_regions) for m in models]
    return [min(counts), max(counts)]
