"""``GaussianProcessErrorModel``: position errors by Gaussian-process regression.

The model is scikit-learn's ``GaussianProcessRegressor``: a constant times
an anisotropic RBF (or Matern) kernel, plus white noise, on inputs scaled to
[-1, 1] (joint angles wrapped where their data straddle ±180 degrees, see
``angles``). The hyperparameters (amplitude, one length scale per input,
noise) maximise the log marginal likelihood, from the default start and
``restarts`` seeded random starts; x, y and z share them, each normalised to
zero mean and unit variance. The search is partcal's own
(:mod:`partcal.models.likelihood`: the same optimum, one Cholesky for the
three outputs and an analytic gradient, a quarter of scikit-learn's time per
step), except for the Matern kernel of smoothness 0.5; a fit whose
hyperparameters make it white noise or an interpolator of noisy data says so
(:meth:`GaussianProcessErrorModel.fit_notes`).

After fitting, the model is plain numbers: the scaled training inputs, the
dual coefficients ``alpha = (K + noise)^-1 y`` and the kernel parameters.
Prediction is ``k(x, X_train) @ alpha``, computed here in blocks with numpy
(the same function scikit-learn evaluates), so a model file needs no pickle.

A global GP costs O(n^3) to fit; as the local model of a
``PartitionedErrorModel`` one GP per region makes that cheap (see
docs/models.md).
"""

from __future__ import annotations

import hashlib
import logging
import warnings
from collections import OrderedDict

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from sklearn.base import clone
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel
from joblib import Parallel, delayed
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import FieldReader, integer, one_of, real
from ..metrics import distance_outside_boxes
from . import likelihood
from .angles import InputMap
from .._validation import seed_from
from .base import ErrorModelBase, check_sample_weight
from .kindtable import RegionFit
from .threads import one_blas_thread

log = logging.getLogger(__name__)
INPUTS = ("cartesian", "joint")
KERNELS = ("rbf", "matern")
NUS = (0.5, 1.5, 2.5)
LENGTH_BOUNDS = (1e-2, 1e3)        # on inputs scaled to [-1, 1]
AMPLITUDE_BOUNDS = (1e-3, 1e3)     # on normalised outputs
NOISE_BOUNDS = (1e-12, 1.0)
SHARED_HYPER_SAMPLES = (500, 2000)  # a partition's shared search: a tenth of the samples, within these bounds
HYPERPARAMETERS = ("shared", "per_region")
SAMPLES_PER_INPUT = 10             # default smallest region: 10 samples per varying input
AUTO_RESTARTS = ((200, 4), (500, 1))    # restarts: None -> 4 extra starts on a search of <= 200 samples, ...
GLOBAL_HYPER_SAMPLES = 1000        # hyper_samples: None -> a global GP searches on at most 1,000 samples
AT_BOUND = 1.05                    # a hyperparameter within 5% of a bound sits on it
INTERPOLATING = 1e-8               # noise variance (outputs scaled to unit variance) of a GP that interpolates
WHITE_NOISE = 0.05                 # neighbours correlated less than this (median): the GP predicts the mean
NEAR_MEAN = 0.5                    # fewer effective parameters per output beyond the mean: a near-constant fit
OPTIMUM_RATIO = 10.0               # a CV fold's GP whose noise or length scales differ this much found another optimum
_BLOCK = 2048


class GaussianProcessErrorModel(ErrorModelBase):
    """Gaussian-process error model on Cartesian positions or joint angles.

    Parameters
    ----------
    inputs : {"cartesian", "joint"}
        What ``X`` holds: positions in mm, or joint angles in degrees.
    kernel : {"rbf", "matern"}
        Anisotropic squared-exponential, or Matern of smoothness ``nu``.
    nu : {0.5, 1.5, 2.5}
        Matern smoothness (ignored for ``rbf``).
    restarts : int in [0, 20] or None
        Extra starts of the marginal-likelihood optimiser, drawn from the
        hyperparameter bounds with ``random_state``. None (the default): as
        many as are cheap (:data:`AUTO_RESTARTS`: 4 on a search of up to 200
        samples, 1 up to 500); a single start often ends on a bound (every
        length scale at its smallest: white noise).
    noise_floor_mm : float >= 0 or None
        The smallest noise standard deviation (mm) the search may settle on:
        the scatter of repeated measurements of one pose, say. Without it the
        noise term can sink to nothing and the GP then reproduces noisy
        training data exactly. A batch run sets it from the data's repeated
        poses when the config does not; None: no floor beyond
        ``NOISE_BOUNDS``.
    hyper_samples : int >= 20 or None
        Most samples the marginal-likelihood search sees: a seeded random
        subset when there are more, which keeps every input's smallest and
        largest value; the GP is then solved on all samples with
        the hyperparameters found. The search costs O(n^3) per step and takes
        dozens of steps, the solve one step, so this is where a large fit's
        time goes. None: at most 1,000 for a global GP (``GLOBAL_HYPER_SAMPLES``;
        on 2,000 virtual poses a search on 500 loses 1% and is 50 times faster,
        but on the UR10's 1,000 real poses a search on 500 found an
        interpolating optimum, 10% worse on held-out poses); for the shared hyperparameters of
        a partition, a tenth of the samples, but at least 500 and at most 2,000
        (``SHARED_HYPER_SAMPLES``; fewer search samples than that miss fine
        structure and read it as noise).
    hyperparameters : {"shared", "per_region"}
        As the local model of a ``PartitionedErrorModel``: one set of
        hyperparameters learnt from the whole training set (a subset of
        ``hyper_samples``) and used by every region, which then only solves
        for its dual coefficients; or each region's own search on its own
        samples. A global GP ignores it.
    region_overlap : float in [1, 3]
        As the local model of a ``PartitionedErrorModel``: each region's GP
        trains on the samples within ``region_overlap`` times the reach of its
        region's blend kernels (1: exactly the samples the blend gives the
        region any weight). More overlap gives every GP more data (more
        accurate where regions meet, and where data are sparse for the
        input dimension) at the cost of larger solves and slower predictions.
        A global GP ignores it.
    fixed_kernel : dict or None
        Set by :meth:`frozen`, not by hand: an input map and kernel
        hyperparameters learnt elsewhere; ``fit`` then only solves.
    random_state : None, int, RandomState or Generator

    Attributes
    ----------
    input_map_ : InputMap
    X_train_ : ndarray, shape (n, d_active)
        Training inputs in scaled coordinates.
    dual_coef_ : ndarray, shape (n, n_outputs)
        ``alpha`` of the normalised outputs.
    y_mean_, y_std_ : ndarray, shape (n_outputs,)
        Output normalisation, mm.
    amplitude_ : float
        Kernel variance (normalised outputs).
    length_scale_ : ndarray, shape (d_active,)
        In scaled input units (1 = half the training range).
    noise_ : float
        White-noise variance (normalised outputs).
    log_marginal_likelihood_ : float

    Examples
    --------
    >>> X = np.random.default_rng(0).uniform(-500, 500, (60, 3))
    >>> y = np.c_[np.sin(X[:, 0] / 300), X[:, 1] / 1000, np.cos(X[:, 2] / 400)]
    >>> model = GaussianProcessErrorModel(random_state=0).fit(X, y)
    >>> bool(np.abs(model.predict(X) - y).max() < 1e-3)
    True
    """

    def __init__(self, *, inputs="cartesian", kernel="rbf", nu=2.5, restarts=None, noise_floor_mm=None,
                 hyper_samples=None, hyperparameters="shared", region_overlap=1.0, fixed_kernel=None,
                 random_state=None):
        self.inputs = inputs
        self.kernel = kernel
        self.nu = nu
        self.restarts = restarts
        self.noise_floor_mm = noise_floor_mm
        self.hyper_samples = hyper_samples
        self.hyperparameters = hyperparameters
        self.region_overlap = region_overlap
        self.fixed_kernel = fixed_kernel
        self.random_state = random_state

    kind = "gaussian_process"
    file_kind = "gaussian_process"
    family_noun = "Gaussian processes"
    _parameter_rules = {
        "inputs": one_of(*INPUTS),
        "kernel": one_of(*KERNELS),
        "nu": one_of(*NUS, default=2.5),
        "restarts": integer(0, 20, none=True),
        "noise_floor_mm": real(0.0, 1e3, default=None, none=True),
        "hyper_samples": integer(20, none=True),
        "hyperparameters": one_of(*HYPERPARAMETERS),
        "region_overlap": real(1.0, 3.0, default=1.0),
    }
    _damage_field = "dual_coef"

    def region_minimum(self, n_active: int) -> tuple[int, str, str]:
        """Smallest region a partition may give this model, why (for messages), and the config key that sets it."""
        self._check_rules()
        return SAMPLES_PER_INPUT * max(n_active, 1), f"{SAMPLES_PER_INPUT} per varying input", "partition"

    # ------------------------------------------------------------------ fitting
    def fit(self, X, y, sample_weight=None):
        """Fit the GP to errors ``y`` (n, 3) mm at inputs ``X`` (n, d). Returns self.

        ``sample_weight`` (n,): only the samples of positive weight are fitted (a partition's region takes
        the samples within its reach); the weights' sizes do not matter to a Gaussian process.
        """
        if sample_weight is not None:
            sample_weight = check_sample_weight(type(self).__name__, sample_weight, len(np.asarray(X)))
        return self._fit(X, y, sample_weight)

    def _fit(self, X, y, sample_weight, shared: "GaussianProcessErrorModel | None" = None):
        """Fit; in a partition, the samples of weight 0 (outside the region's reach) are left out.

        ``shared``: a fitted GP whose input map, output normalisation and
        kernel this one takes as they are (a partition's shared
        hyperparameters); only the dual coefficients are solved for.
        """
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        if sample_weight is not None:
            keep = np.asarray(sample_weight, dtype=float) > 0
            X, Y = X[keep], Y[keep]
        if shared is None:
            fixed = self.fixed_kernel
            self.input_map_ = InputMap.fit(X, angles=self.inputs == "joint") if fixed is None else fixed["input_map"]
            Z = self.input_map_.transform(X)
            gpr = self._search(Z, Y) if fixed is None else \
                _solved(self._kernel_of(fixed["amplitude"], fixed["length_scale"], fixed["noise"]), Z, Y)
            mean, std = _output_normalisation(Y)          # what gpr (fitted on Y, normalize_y) divided by
            self.y_mean_ = np.broadcast_to(mean, (Y.shape[1],)).astype(float)
            self.y_std_ = np.broadcast_to(std, (Y.shape[1],)).astype(float)
        else:
            self.input_map_ = shared.input_map_
            self.y_mean_, self.y_std_ = shared.y_mean_.copy(), shared.y_std_.copy()
            Z = self.input_map_.transform(X)
            gpr = GaussianProcessRegressor(shared.sklearn_kernel(), optimizer=None)
            gpr.fit(Z, (Y - self.y_mean_) / self.y_std_)
        params = gpr.kernel_.get_params()
        self.X_train_ = np.ascontiguousarray(gpr.X_train_)          # the layout a loaded file has:
        self.dual_coef_ = np.ascontiguousarray(gpr.alpha_.reshape(len(Z), -1))   # same sums, same bits
        self.amplitude_ = float(params["k1__k1__constant_value"])
        self.length_scale_ = np.broadcast_to(params["k1__k2__length_scale"], (Z.shape[1],)).astype(float)
        self.noise_ = float(params["k2__noise_level"])
        self.log_marginal_likelihood_ = float(gpr.log_marginal_likelihood_value_)
        self.noise_bounds_ = self._noise_bounds(Y) if shared is None else shared.noise_bounds_
        wrapped = self.input_map_.wrap(X)
        self.data_bounds_ = np.stack([wrapped.min(axis=0), wrapped.max(axis=0)])
        self.n_train_ = int(len(Z))
        return self._prepare()

    def fit_shared(self, X, Y) -> "GaussianProcessErrorModel":
        """Fit as the hyperparameters a partition's regions share; returns self.

        The search runs on at most ``hyper_samples`` samples of ``X, Y`` (by
        default a tenth of them, within ``SHARED_HYPER_SAMPLES``); the subset
        keeps every input's smallest and largest value, so the input map, and
        with it the meaning of the length scales, is that of all of ``X``.
        """
        self._check_rules()
        X, Y = np.asarray(X, dtype=float), np.asarray(Y, dtype=float)
        low, high = SHARED_HYPER_SAMPLES
        subset = _search_subset(X, int(self.hyper_samples or min(max(len(X) // 10, low), high)),
                                seed_from(self.random_state))
        n = len(X) if isinstance(subset, slice) else len(subset)
        return clone(self).set_params(hyper_samples=n)._fit(X[subset], Y[subset], None)

    def _search(self, Z: NDArray[np.float64], Y: NDArray[np.float64]) -> GaussianProcessRegressor:
        """Hyperparameters by marginal likelihood (on at most ``hyper_samples`` of the samples), then the solve on all.

        BLAS runs on one thread: the search is a long chain of ``n x n``
        factorisations, and OpenBLAS's threads, on a machine whose cores are
        busy, made each up to 50 times slower (``benchmarks/bench_gp.py``).
        """
        seed = seed_from(self.random_state) % 2**32
        limit = GLOBAL_HYPER_SAMPLES if self.hyper_samples is None else int(self.hyper_samples)
        subset = _search_subset(Z, limit, seed)
        Zs, Ys = Z[subset], Y[subset]
        kernel = self._kernel(Z.shape[1], self._noise_bounds(Y))
        restarts = self.restarts_for(len(Zs))
        with one_blas_thread():
            if self.kernel == "rbf" or float(self.nu) in likelihood.NUS:
                theta = _searched(Zs, Ys, None if self.kernel == "rbf" else float(self.nu), kernel, restarts, seed)
                gpr = _solved(kernel.clone_with_theta(theta), Zs, Ys)
            else:
                gpr = self._sklearn_search(Zs, Ys, kernel, restarts, seed)
            if isinstance(subset, np.ndarray):
                log.info("GP hyperparameters from %d of %d samples: %s", len(subset), len(Z), gpr.kernel_)
                gpr = _solved(gpr.kernel_, Z, Y)
        return gpr

    @staticmethod
    def _sklearn_search(Z, Y, kernel, restarts: int, seed: int) -> GaussianProcessRegressor:
        """scikit-learn's own search (the kernels :mod:`partcal.models.likelihood` does not differentiate)."""
        gpr = GaussianProcessRegressor(kernel, normalize_y=True, n_restarts_optimizer=restarts, random_state=seed)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            gpr.fit(Z, Y)
        for w in caught:          # bounds reached: fit_notes() says what it means
            if not issubclass(w.category, ConvergenceWarning):
                warnings.warn(w.message, w.category, stacklevel=3)
        return gpr

    def _prepare(self) -> "GaussianProcessErrorModel":
        """Precompute what every prediction needs (after fitting or loading); returns self
        (see :meth:`ErrorModelBase._prepare`).

        The training inputs are divided by the length scales and centred (so
        that the expansion below loses little to rounding), and augmented so
        that one matrix product gives the exponent ``-|a - b|^2 / 2 = a.b -
        |a|^2 / 2 - |b|^2 / 2`` for a whole block of queries.
        """
        B = self.X_train_ / self.length_scale_
        centre = B.mean(axis=0)
        B = B - centre
        augmented = np.vstack([B.T, np.ones(len(B)), -0.5 * np.einsum("ij,ij->i", B, B)])
        self._cache = (np.ascontiguousarray(augmented), self.dual_coef_ * self.amplitude_, centre)
        return super()._prepare()

    def restarts_for(self, n_search: int) -> int:
        """Extra optimiser starts for a search on ``n_search`` samples: ``restarts``, or the cheap default."""
        if self.restarts is not None:
            return int(self.restarts)
        return next((r for most, r in AUTO_RESTARTS if n_search <= most), 0)

    def _noise_bounds(self, Y: NDArray[np.float64]) -> tuple[float, float]:
        """Bounds of the white-noise variance on normalised outputs: ``noise_floor_mm`` over the smallest
        output scale, squared, below (at most half the outputs' variance), ``NOISE_BOUNDS`` otherwise."""
        low, high = NOISE_BOUNDS
        if self.noise_floor_mm:
            scale = float(np.min(np.std(Y, axis=0)))
            low = max(low, min((float(self.noise_floor_mm) / scale) ** 2 if scale > 0 else high, 0.5 * high))
        return low, high

    def _kernel(self, d: int, noise_bounds: tuple[float, float] = NOISE_BOUNDS):
        shape = RBF(np.ones(d), LENGTH_BOUNDS) if self.kernel == "rbf" else \
            Matern(np.ones(d), LENGTH_BOUNDS, nu=float(self.nu))
        noise = min(max(1e-4, 2.0 * noise_bounds[0]), noise_bounds[1])
        return ConstantKernel(1.0, AMPLITUDE_BOUNDS) * shape + WhiteKernel(noise, noise_bounds)

    def _kernel_of(self, amplitude: float, length_scale, noise: float):
        """This model's kind of kernel with the given hyperparameters, as a scikit-learn object."""
        scales = np.array(length_scale, dtype=float)
        shape = RBF(scales) if self.kernel == "rbf" else Matern(scales, nu=float(self.nu))
        return ConstantKernel(amplitude) * shape + WhiteKernel(noise)

    def frozen(self, X, y) -> "GaussianProcessErrorModel":
        """An unfitted copy whose fits only solve, with the input map and hyperparameters learnt on ``X, y``.

        Nested cross-validation freezes a candidate on each outer training
        set, so its inner folds do not repeat the search (see
        :func:`partcal.study.selection.nested_residuals`).
        """
        fitted = clone(self).fit(X, y)
        return clone(self).set_params(fixed_kernel=fitted.learnt_kernel())

    def learnt_kernel(self) -> dict:
        """The fitted input map and kernel hyperparameters (what :meth:`frozen` keeps)."""
        check_is_fitted(self, "dual_coef_")
        return {"input_map": self.input_map_, "amplitude": self.amplitude_,
                "length_scale": self.length_scale_.copy(), "noise": self.noise_}

    def fit_notes(self) -> list[str]:
        """What makes the fit not what a GP should be, in words: a near-constant or white-noise fit, or a noise
        term at (or within 1e-8 of) its lower bound, which reproduces noisy training data exactly."""
        check_is_fitted(self, "dual_coef_")
        if self.fixed_kernel is not None:
            return []
        notes = []
        learnt = self.effective_parameters() / self.n_outputs() - 1.0
        if self.n_train_ > 1 and learnt < NEAR_MEAN:
            notes.append(f"amplitude negligible next to the noise ({learnt:.2f} effective parameters per output "
                         "beyond the mean): the fit predicts nearly the mean of the training errors everywhere")
        elif self.n_train_ > 1 and self._neighbour_correlation() < WHITE_NOISE:
            notes.append("length scales shorter than the spacing of the data: a white-noise fit that predicts the "
                         "mean between the training poses")
        low = getattr(self, "noise_bounds_", NOISE_BOUNDS)[0]
        if self.noise_ <= max(low * AT_BOUND, INTERPOLATING) and low <= NOISE_BOUNDS[0] * AT_BOUND:
            notes.append("the noise term at or near its lower bound: the GP reproduces its training data exactly "
                         "(set noise_floor_mm to the measurement scatter)")
        return notes

    def optimum_gap(self, other: ErrorModelBase) -> str | None:
        """How far this fit's hyperparameters lie from ``other``'s (another fit of the same entry: a CV fold's
        against the final fit), in words, when markedly: a noise variance (normalised outputs) or a geometric
        mean of the length scales :data:`OPTIMUM_RATIO` times larger or smaller; None otherwise."""
        noise = self.noise_ / other.noise_ if other.noise_ > 0 else np.inf
        scales = float(np.exp(np.mean(np.log(self.length_scale_ / other.length_scale_))))
        if max(noise, 1 / noise, scales, 1 / scales) < OPTIMUM_RATIO:
            return None
        return (f"noise variance {self.noise_:.3g} against {other.noise_:.3g}, length scales x{scales:.3g} (geometric "
                "mean)")

    def search_gap(self, other: ErrorModelBase) -> str | None:
        """:meth:`optimum_gap` when both fits searched their hyperparameters (no ``fixed_kernel``)."""
        if not isinstance(other, GaussianProcessErrorModel) or self.fixed_kernel is not None \
                or other.fixed_kernel is not None:
            return None
        return self.optimum_gap(other)

    def _neighbour_correlation(self) -> float:
        """Median kernel correlation of a training input with its nearest other training input."""
        scaled = self.X_train_ / self.length_scale_
        d = cKDTree(scaled).query(scaled, k=2)[0][:, 1]
        return float(np.median(self._shape(-0.5 * d * d)))

    def effective_parameters(self) -> float:
        """Effective degrees of freedom: ``trace(K (K + noise I)^-1)`` per output plus its mean, times the outputs."""
        check_is_fitted(self, "dual_coef_")
        scaled = self.X_train_ / self.length_scale_
        sq = np.einsum("ij,ij->i", scaled, scaled)
        K = self.amplitude_ * self._shape(np.minimum(scaled @ scaled.T - 0.5 * (sq[:, None] + sq[None, :]), 0.0))
        eig = np.clip(np.linalg.eigvalsh(K), 0.0, None)
        return float((np.sum(eig / (eig + self.noise_)) + 1.0) * self.n_outputs())

    def sklearn_kernel(self):
        """The fitted kernel as a scikit-learn object (rebuilt from the stored numbers)."""
        check_is_fitted(self, "dual_coef_")
        return self._kernel_of(self.amplitude_, self.length_scale_, self.noise_)

    # ------------------------------------------------------------------ prediction
    def predict(self, X) -> NDArray[np.float64]:
        """Posterior mean of the errors, shape (n, n_outputs) mm (1-D if fitted on a 1-D ``y``)."""
        check_is_fitted(self, "dual_coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._shape_output(self._predict_trusted(X))

    def predict_validated(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """Prediction ``(n, n_outputs)`` on validated arrays (the hot path of blends)."""
        return self._predict_trusted(X)

    def _predict_trusted(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """Prediction ``(n, n_outputs)`` on validated arrays."""
        augmented, coef, centre = self._cache
        A = self.input_map_.transform(X) / self.length_scale_ - centre
        out = np.empty((A.shape[0], coef.shape[1]))
        a = np.empty((min(_BLOCK, A.shape[0]), A.shape[1] + 2))
        for start in range(0, A.shape[0], _BLOCK):
            block = A[start:start + _BLOCK]
            a = a[:len(block)]
            a[:, :-2] = block
            a[:, -2] = -0.5 * np.einsum("ij,ij->i", block, block)
            a[:, -1] = 1.0
            out[start:start + _BLOCK] = self._shape(a @ augmented) @ coef      # exponent -d^2/2, (m, n)
        return out * self.y_std_ + self.y_mean_

    def std_validated(self, X: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Posterior mean and the standard deviation of a measurement at ``X``, both (n, outputs) mm.

        ``var = amplitude + noise - k(X)^T (K + noise I)^-1 k(X)`` in the
        normalised outputs (``k`` the kernel without its white noise, ``K`` the
        training inputs' kernel matrix, factorised here by Cholesky, not kept),
        times each output's scale squared: the posterior variance plus the
        noise the fit learnt. Far from the data it tends to ``amplitude +
        noise``, the prior's.
        """
        from scipy.linalg import cho_factor, cho_solve

        kernel = self.sklearn_kernel()
        Z, Ztrain = self.input_map_.transform(X), self.X_train_
        factor = cho_factor(kernel(Ztrain), lower=True)
        var = np.empty(len(Z))
        for start in range(0, len(Z), _BLOCK):
            cross = kernel.k1(Ztrain, Z[start:start + _BLOCK])                   # (n_train, m), no white noise
            var[start:start + _BLOCK] = self.amplitude_ + self.noise_ - np.einsum(
                "ij,ij->j", cross, cho_solve(factor, cross))
        std = np.sqrt(np.maximum(var, 0.0))[:, None] * self.y_std_[None, :]
        return self._predict_trusted(X), std

    def spread_problem(self) -> str | None:
        return None

    def _shape(self, exponent: NDArray[np.float64]) -> NDArray[np.float64]:
        """Kernel values from ``-d^2 / 2`` of scaled distances ``d`` (in place where possible)."""
        if self.kernel == "rbf":
            return np.exp(exponent, out=exponent)      # rounding may give +1e-16: exp is 1 there, as it should
        d = np.sqrt(np.maximum(-2.0 * exponent, 0.0))
        if self.nu == 0.5:
            return np.exp(-d)
        if self.nu == 1.5:
            k = np.sqrt(3.0) * d
            return (1.0 + k) * np.exp(-k)
        k = np.sqrt(5.0) * d
        return (1.0 + k + k * k / 3.0) * np.exp(-k)

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance of each point outside the bounding box of the training inputs, shape (n,)."""
        check_is_fitted(self, "dual_coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return distance_outside_boxes(self.input_map_.wrap(X), self.data_bounds_[:1], self.data_bounds_[1:])


    # ------------------------------------------------------------------ the kind: config, files, run
    @classmethod
    def params_from_config(cls, sec, context: dict) -> dict:
        """The declared keys; ``nu`` only with the Matern kernel, the region keys only under a partition."""
        params = super().params_from_config(sec, context)
        if sec.has("nu") and params["kernel"] != "matern":
            sec.fail(sec.path("nu"), "applies to kernel: matern only")
        for key in ("hyperparameters", "region_overlap"):
            if sec.has(key) and not context.get("partitioned"):
                sec.fail(sec.path(key), "applies to a partitioned GP only (add 'partition')")
        return params

    def peak_fit_bytes(self, n: int, n_joints: int, regions: int = 1) -> tuple[float, str]:
        """Peak memory of a fit on ``n`` poses, as a global GP or the local model of ``regions`` regions.

        In 8-byte numbers, for ``d`` inputs: the hyperparameter search on ``s`` samples holds about
        ``(d + 9) s^2`` (the kernel matrix, its gradient per hyperparameter, its Cholesky factor, its
        inverse, the likelihood gradient's products), the solve on a GP's ``m`` samples ``3 m^2``
        (kernel, factor, a copy). A region is taken to hold ``min(n, 2 overlap n / regions)`` samples:
        twice its share, for uneven regions. The final fit is the peak (CV folds fit fewer samples).
        """
        d = 3 if self.inputs == "cartesian" else n_joints
        solve = n if regions <= 1 else min(n, -(-2 * self.region_overlap * n // regions))
        if regions <= 1:
            search = self.hyper_samples or GLOBAL_HYPER_SAMPLES
        elif self.hyperparameters == "shared":
            search = self.hyper_samples or min(max(n // 10, SHARED_HYPER_SAMPLES[0]), SHARED_HYPER_SAMPLES[1])
        else:
            search = self.hyper_samples or solve
        search, solve = int(min(search, n)), int(solve)
        return 8.0 * max((d + 9) * search**2, 3 * solve**2), f"hyperparameter search on {search} samples, " \
                                                              f"solve on {solve}"

    def describe(self) -> str:
        kernel = "RBF" if self.kernel == "rbf" else f"Matern {self.nu}"
        return f"Gaussian process ({kernel} kernel) of {self.inputs} inputs"

    @property
    def solver_name(self) -> str:
        return "marginal-likelihood"

    def n_outputs(self) -> int:
        return int(self.dual_coef_.shape[1])

    def file_section(self) -> dict:
        return {"kernel": self.kernel, "nu": float(self.nu), "restarts": self.restarts,
                "noise_floor_mm": self.noise_floor_mm,
                "hyper_samples": None if self.hyper_samples is None else int(self.hyper_samples),
                "hyperparameters": self.hyperparameters, "region_overlap": float(self.region_overlap),
                "input_map": self.input_map_.to_dict(), "x_train": self.X_train_.tolist(),
                "dual_coef": self.dual_coef_.tolist(), "y_mean": self.y_mean_.tolist(),
                "y_std": self.y_std_.tolist(), "amplitude": self.amplitude_,
                "length_scale": self.length_scale_.tolist(), "noise": self.noise_,
                "log_marginal_likelihood": self.log_marginal_likelihood_, "data_bounds": self.data_bounds_.tolist()}

    @classmethod
    def from_file_section(cls, r: FieldReader, inputs: str, n_in: int, n_out: int) -> "GaussianProcessErrorModel":
        """A GP from its section (files written before the search settings existed: how GPs were fitted then)."""
        rules = cls._parameter_rules
        imap = InputMap.from_file(r.sub("input_map"), n_in)
        d = max(imap.n_active, 1)
        n = len(r.get("x_train", list))
        older = {"hyper_samples": None, "hyperparameters": "per_region", "region_overlap": 1.0, "noise_floor_mm": None}
        params = {key: r.rule(key, rules[key]) if key in r.doc or key not in older else older[key]
                  for key in ("kernel", "nu", "restarts", *older)}
        model = cls(inputs=inputs, **params)
        model.input_map_ = imap
        model.X_train_ = r.array("x_train", (n, d))
        model.dual_coef_ = r.array("dual_coef", (n, n_out))
        model.y_mean_, model.y_std_ = r.array("y_mean", (n_out,)), r.array("y_std", (n_out,))
        if np.any(model.y_std_ <= 0):
            r.fail("y_std", "the output scales must be > 0")
        model.amplitude_, model.noise_ = r.number("amplitude", 0.0), r.number("noise", 0.0)
        model.length_scale_ = r.array("length_scale", (d,))
        if model.amplitude_ <= 0 or np.any(model.length_scale_ <= 0):
            r.fail("length_scale", "expected a positive amplitude and positive length scales")
        model.log_marginal_likelihood_ = r.number("log_marginal_likelihood")
        model.data_bounds_ = r.array("data_bounds", (2, n_in))
        model.n_features_in_, model.n_train_, model._y_1d = n_in, n, False
        return model._prepare()


def _output_normalisation(Y: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The mean and scale ``(k,)`` of outputs ``Y`` (n, k) that scikit-learn's GP with ``normalize_y`` takes: the
    standard deviation, or 1 where it is below ten machine epsilons (a constant output), the same sums."""
    mean, std = np.mean(Y, axis=0), np.std(Y, axis=0)
    std[std < 10 * np.finfo(std.dtype).eps] = 1.0
    return mean, std


def fit_regions(local: GaussianProcessErrorModel, models: list, data: list[tuple], n_jobs, X, Y, seed
                ) -> list[GaussianProcessErrorModel]:
    """Fit every region's GP to its ``(X, Y, weights)``, in parallel; with ``hyperparameters="shared"`` the
    hyperparameters are first searched once on all of ``X, Y`` (seeded by ``seed``) and every region only
    solves with them (the Gaussian-process row's :class:`~partcal.models.kindtable.RegionFit`)."""
    shared = None
    if local.hyperparameters == "shared":
        shared = clone(local).set_params(random_state=seed).fit_shared(X, Y)
        log.info("shared GP hyperparameters: %s", shared.sklearn_kernel())
    return Parallel(n_jobs=n_jobs)(delayed(_fit_region)(m, *d, shared) for m, d in zip(models, data))


def _fit_region(model: GaussianProcessErrorModel, X, Y, weights, shared) -> GaussianProcessErrorModel:
    """One region's fit (its rules were checked on the partition's local model, whose clone it is)."""
    return model._fit(X, Y, weights, shared=shared)


def _freeze(local: GaussianProcessErrorModel, X, Y, seed) -> GaussianProcessErrorModel | None:
    """``local`` with the shared hyperparameters searched on ``X, Y`` fixed; None unless its regions share a
    search that is not fixed already."""
    if local.hyperparameters != "shared" or local.fixed_kernel is not None:
        return None
    shared = clone(local).set_params(random_state=seed).fit_shared(X, Y)
    return clone(local).set_params(fixed_kernel=shared.learnt_kernel())


GP_REGIONS = RegionFit(fit_all=fit_regions, overlap=lambda local: float(local.region_overlap),
                       shares=lambda local: local.hyperparameters == "shared", freeze=_freeze)


def _solved(kernel, Z: NDArray[np.float64], Y: NDArray[np.float64]) -> GaussianProcessRegressor:
    """scikit-learn's GP with ``kernel`` as it is (no search), solved on ``Z, Y`` (outputs normalised)."""
    return GaussianProcessRegressor(kernel, normalize_y=True, optimizer=None).fit(Z, Y)


_SEARCHED: OrderedDict = OrderedDict()     # the last searches of this process: key -> log hyperparameters
_SEARCHED_KEPT = 16


def _searched(Z: NDArray[np.float64], Y: NDArray[np.float64], nu: float | None, kernel, restarts: int, seed: int
              ) -> NDArray[np.float64]:
    """The searched hyperparameters (log) of inputs ``Z``, outputs ``Y`` (normalised here, as scikit-learn does).

    A search already made in this process on the same numbers with the same
    settings is not made again: cross-validation fits the candidates of a
    granularity list on the same folds, and nested CV freezes them there too.
    """
    mean, std = Y.mean(axis=0), Y.std(axis=0)
    Yn = (Y - mean) / np.where(std > 0, std, 1.0)
    key = hashlib.sha256(b"".join([np.ascontiguousarray(Z).tobytes(), np.ascontiguousarray(Yn).tobytes(),
                                   repr((nu, kernel.theta.tolist(), kernel.bounds.tolist(), restarts, seed)).encode()])
                         ).hexdigest()
    if key in _SEARCHED:
        _SEARCHED.move_to_end(key)
        return _SEARCHED[key].copy()
    theta, _ = likelihood.search(Z, Yn, nu=nu, start=kernel.theta, bounds=kernel.bounds, restarts=restarts, seed=seed)
    _SEARCHED[key] = theta
    if len(_SEARCHED) > _SEARCHED_KEPT:
        _SEARCHED.popitem(last=False)
    return theta.copy()


def _search_subset(X: NDArray[np.float64], n: int, seed: int) -> NDArray[np.intp] | slice:
    """Rows for a hyperparameter search on at most ``n`` of ``X``: all (a slice), or a seeded random subset
    that keeps every column's smallest and largest value (so the subset spans what all of ``X`` spans)."""
    if len(X) <= n:
        return slice(None)
    ends = np.unique(np.r_[X.argmin(axis=0), X.argmax(axis=0)])
    rest = np.setdiff1d(np.arange(len(X)), ends)
    pick = np.random.default_rng(seed).choice(rest, max(n - len(ends), 0), replace=False)
    return np.sort(np.r_[ends, pick])
