"""``GaussianProcessErrorModel``: position errors by Gaussian-process regression.

scikit-learn's ``GaussianProcessRegressor`` fits the model: a constant times
an anisotropic RBF (or Matern) kernel, plus white noise, on inputs scaled to
[-1, 1] (joint angles wrapped where their data straddle ±180 degrees, see
``angles``). The hyperparameters (amplitude, one length scale per input,
noise) maximise the log marginal likelihood, from the default start and
``restarts`` seeded random starts; x, y and z share them, each normalised to
zero mean and unit variance.

After fitting, the model is plain numbers: the scaled training inputs, the
dual coefficients ``alpha = (K + noise)^-1 y`` and the kernel parameters.
Prediction is ``k(x, X_train) @ alpha``, computed here in blocks with numpy
(the same function scikit-learn evaluates), so a model file needs no pickle.

A global GP costs O(n^3) to fit; as the local model of a
``PartitionedErrorModel`` one GP per region makes that cheap (see
docs/models.md).
"""

from __future__ import annotations

import logging
import warnings

import numpy as np
from numpy.typing import NDArray
from sklearn.exceptions import ConvergenceWarning
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import check_choice, check_int, param_error
from ..metrics import distance_outside_boxes
from .angles import InputMap
from .base import ErrorModelBase, seed_from

log = logging.getLogger(__name__)
INPUTS = ("cartesian", "joint")
KERNELS = ("rbf", "matern")
NUS = (0.5, 1.5, 2.5)
LENGTH_BOUNDS = (1e-2, 1e3)        # on inputs scaled to [-1, 1]
AMPLITUDE_BOUNDS = (1e-3, 1e3)     # on normalised outputs
NOISE_BOUNDS = (1e-12, 1.0)
REGION_MIN_WEIGHT = 1e-3           # a region's GP skips samples it weighs less than this (of its largest)
SAMPLES_PER_INPUT = 10             # default smallest region: 10 samples per varying input
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
    restarts : int in [0, 20]
        Extra starts of the marginal-likelihood optimiser, drawn from the
        hyperparameter bounds with ``random_state``.
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

    def __init__(self, *, inputs="cartesian", kernel="rbf", nu=2.5, restarts=1, random_state=None):
        self.inputs = inputs
        self.kernel = kernel
        self.nu = nu
        self.restarts = restarts
        self.random_state = random_state

    def _check_params(self) -> None:
        own = type(self).__name__
        check_choice(own, "inputs", self.inputs, INPUTS)
        check_choice(own, "kernel", self.kernel, KERNELS)
        if self.kernel == "matern" and self.nu not in NUS:
            raise param_error(own, "nu", "one of 0.5, 1.5, 2.5", self.nu)
        check_int(own, "restarts", self.restarts, 0, 20)

    def region_minimum(self, n_active: int) -> tuple[int, str]:
        """Smallest region a partition may give this model, and why (for messages)."""
        return SAMPLES_PER_INPUT * max(n_active, 1), f"{SAMPLES_PER_INPUT} per varying input"

    # ------------------------------------------------------------------ fitting
    def fit(self, X, y):
        """Fit the GP to errors ``y`` (n, 3) mm at inputs ``X`` (n, d). Returns self."""
        return self._fit(X, y, None)

    def _fit(self, X, y, sample_weight):
        """Fit; in a partition, samples weighing less than ``REGION_MIN_WEIGHT`` of the largest are skipped."""
        self._check_params()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        if sample_weight is not None:
            w = np.asarray(sample_weight, dtype=float)
            keep = w >= REGION_MIN_WEIGHT * w.max()
            X, Y = X[keep], Y[keep]
        self.input_map_ = InputMap.fit(X, angles=self.inputs == "joint")
        Z = self.input_map_.transform(X)
        gpr = GaussianProcessRegressor(self._kernel(Z.shape[1]), normalize_y=True,
                                       n_restarts_optimizer=int(self.restarts),
                                       random_state=seed_from(self.random_state) % 2**32)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            gpr.fit(Z, Y)
        for w in caught:          # bounds reached are normal (noise-free data): a log line, not a warning
            if issubclass(w.category, ConvergenceWarning):
                log.info("GP hyperparameters: %s", w.message)
            else:
                warnings.warn(w.message, w.category, stacklevel=2)
        params = gpr.kernel_.get_params()
        self.X_train_ = np.ascontiguousarray(gpr.X_train_)          # the layout a loaded file has:
        self.dual_coef_ = np.ascontiguousarray(gpr.alpha_.reshape(len(Z), -1))   # same sums, same bits
        self.y_mean_ = np.broadcast_to(gpr._y_train_mean, (Y.shape[1],)).astype(float)
        self.y_std_ = np.broadcast_to(gpr._y_train_std, (Y.shape[1],)).astype(float)
        self.amplitude_ = float(params["k1__k1__constant_value"])
        self.length_scale_ = np.broadcast_to(params["k1__k2__length_scale"], (Z.shape[1],)).astype(float)
        self.noise_ = float(params["k2__noise_level"])
        self.log_marginal_likelihood_ = float(gpr.log_marginal_likelihood_value_)
        wrapped = self.input_map_.wrap(X)
        self.data_bounds_ = np.stack([wrapped.min(axis=0), wrapped.max(axis=0)])
        self.n_train_ = int(len(Z))
        return self._prepare()

    def _prepare(self) -> "GaussianProcessErrorModel":
        """Precompute what every prediction needs (after fitting or loading); returns self.

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
        return self

    def _kernel(self, d: int):
        shape = RBF(np.ones(d), LENGTH_BOUNDS) if self.kernel == "rbf" else \
            Matern(np.ones(d), LENGTH_BOUNDS, nu=float(self.nu))
        return ConstantKernel(1.0, AMPLITUDE_BOUNDS) * shape + WhiteKernel(1e-4, NOISE_BOUNDS)

    def sklearn_kernel(self):
        """The fitted kernel as a scikit-learn object (rebuilt from the stored numbers)."""
        check_is_fitted(self, "dual_coef_")
        shape = RBF(self.length_scale_.copy()) if self.kernel == "rbf" else \
            Matern(self.length_scale_.copy(), nu=float(self.nu))
        return ConstantKernel(self.amplitude_) * shape + WhiteKernel(self.noise_)

    # ------------------------------------------------------------------ prediction
    def predict(self, X) -> NDArray[np.float64]:
        """Posterior mean of the errors, shape (n, n_outputs) mm (1-D if fitted on a 1-D ``y``)."""
        check_is_fitted(self, "dual_coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._shape_output(self._predict_trusted(X))

    def _predict_trusted(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """Prediction ``(n, n_outputs)`` on validated arrays (the hot path of blends)."""
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

