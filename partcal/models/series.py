"""``ErrorModel``: position errors as a polynomial or Fourier series of the inputs.

A scikit-learn regressor. The coefficients of each output (x, y, z) are found
by least squares (``solver="lstsq"``, the exact optimum of the RMS) or by a
particle swarm (``solver="pso"``, the paper's method) minimising a fitness:
``rms`` (the paper's), ``max`` (largest absolute error: a Chebyshev fit that
bounds the worst case) or ``mae`` (mean absolute error).

The swarm searches orthonormal coordinates of the feature matrix
(``Phi = U S V^T``, coefficients ``V S^-1 z``). In them the sum of squared
errors is ``|z|^2 - 2 z.b + |y|^2`` with ``b = U^T y``: the RMS of every
particle costs O(terms), whatever the number of samples, and the RMS surface
is a sphere, which a swarm searches well. The search box ``|z_k| <=
bound_scale |y|`` contains the least-squares optimum (``|b| <= |y|``). Every
PSO fit of an RMS model records ``rms_ratio_``, its RMS over the
least-squares RMS on the same data (1.0 is optimal).
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import check_choice, check_int, param_error
from ..errors import PartcalError
from ..metrics import distance_outside_boxes, warn_far
from .base import ErrorModelBase, seed_from
from .bases import Basis, Scaling, SeriesPlan, raw_polynomial
from .swarm import SwarmConfig, SwarmResult, minimize_batch

log = logging.getLogger(__name__)
INPUTS = ("cartesian", "joint")
BASES = ("polynomial", "fourier")
SOLVERS = ("pso", "lstsq")
FITNESSES = ("rms", "max", "mae")


class ErrorModel(ErrorModelBase):
    """Position-error model, linear in its coefficients.

    Parameters
    ----------
    inputs : {"cartesian", "joint"}
        What ``X`` holds: positions in mm (CI) or joint angles in degrees (AI).
    basis : {"polynomial", "fourier"}
    degree : int in [1, 8]
        Polynomial degree (1 = the paper's FDP, 2 = SDP).
    harmonics : int in [1, 8]
        Fourier harmonics ``r`` (eq. 5).
    cross_terms : bool
        Polynomial only: all products of inputs up to ``degree`` instead of
        the paper's sum of one-input polynomials.
    solver : {"pso", "lstsq"}
    pso : SwarmConfig, optional
        Swarm settings; default ``SwarmConfig()``.
    fitness : {"rms", "max", "mae"}
        What the swarm minimises (least squares always minimises the RMS).
    random_state : None, int, numpy RandomState or Generator

    Attributes
    ----------
    coef_ : ndarray, shape (n_terms, n_outputs)
        Coefficients of the scaled features (see :meth:`equations` for raw units).
    scaling_ : Scaling
    terms_ : list
    train_rms_ : ndarray, shape (n_outputs,)
        RMS error per output on the training data.
    lstsq_rms_ : ndarray, shape (n_outputs,)
        The least-squares RMS on the same data.
    rms_ratio_ : float
        3-D RMS of this fit over that of least squares (1.0 for lstsq).
    swarm_results_ : list of SwarmResult
        One per output for ``solver="pso"``, with the best-fitness history.

    Examples
    --------
    >>> X = np.random.default_rng(0).uniform(-500, 500, (50, 3))
    >>> y = 0.5 + 0.002 * X
    >>> model = ErrorModel(degree=1, solver="lstsq").fit(X, y)
    >>> bool(np.abs(model.predict(X) - y).max() < 1e-9)
    True
    """

    def __init__(self, *, inputs="cartesian", basis="polynomial", degree=1, harmonics=1,
                 cross_terms=False, solver="pso", pso=None, fitness="rms", random_state=None):
        self.inputs = inputs
        self.basis = basis
        self.degree = degree
        self.harmonics = harmonics
        self.cross_terms = cross_terms
        self.solver = solver
        self.pso = pso
        self.fitness = fitness
        self.random_state = random_state

    # ------------------------------------------------------------------ parameters
    def _check_params(self) -> tuple[Basis, SwarmConfig]:
        own = type(self).__name__
        check_choice(own, "inputs", self.inputs, INPUTS)
        check_choice(own, "basis", self.basis, BASES)
        check_int(own, "degree", self.degree, 1, 8)
        check_int(own, "harmonics", self.harmonics, 1, 8)
        check_choice(own, "solver", self.solver, SOLVERS)
        check_choice(own, "fitness", self.fitness, FITNESSES)
        if not isinstance(self.cross_terms, (bool, np.bool_)):
            raise param_error(own, "cross_terms", "a bool", self.cross_terms)
        if self.cross_terms and self.basis != "polynomial":
            raise param_error(own, "cross_terms", "False for the fourier basis", self.cross_terms)
        if self.solver == "lstsq" and self.fitness != "rms":
            raise param_error(own, "fitness", "'rms' with solver='lstsq' (use solver='pso')", self.fitness)
        if self.pso is not None and not isinstance(self.pso, SwarmConfig):
            raise param_error(own, "pso", "a SwarmConfig or None", self.pso)
        order = self.degree if self.basis == "polynomial" else self.harmonics
        return Basis(self.basis, self.inputs, order, bool(self.cross_terms)), self.pso or SwarmConfig()

    # ------------------------------------------------------------------ fitting
    def fit(self, X, y):
        """Fit the coefficients to errors ``y`` (n, 3) mm at inputs ``X`` (n, d). Returns self."""
        return self._fit(X, y, None)

    def _fit(self, X, y, sample_weight):
        basis, swarm = self._check_params()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        scaling = Scaling.fit(X)
        terms = basis.terms(scaling)
        n, m = X.shape[0], len(terms)
        if n < m:
            raise PartcalError(
                f"{type(self).__name__} with {m} terms per output ({self._describe()}) needs at least "
                f"{m} samples; got {n} sample{'s' if n != 1 else ''}")
        weights = np.ones(n) if sample_weight is None else np.asarray(sample_weight, dtype=float)
        phi = basis.transform(X, scaling, terms)
        sqrt_w = np.sqrt(weights)
        U, s, Vt = np.linalg.svd(phi * sqrt_w[:, None], full_matrices=False)
        keep = s > s[0] * max(n, m) * np.finfo(float).eps
        U, s, Vt = U[:, keep], s[keep], Vt[keep]
        to_coef = Vt.T / s                                          # z -> coefficients
        Yw = Y * sqrt_w[:, None]
        z_ls = U.T @ Yw                                             # (r, outputs)
        coef_ls = to_coef @ z_ls
        total_w = weights.sum()
        lstsq_sse = np.maximum((Yw * Yw).sum(axis=0) - (z_ls * z_ls).sum(axis=0), 0.0)
        self.swarm_results_ = []
        if self.solver == "lstsq":
            coef = coef_ls
        else:
            seeds = np.random.SeedSequence(seed_from(self.random_state)).spawn(Y.shape[1])
            self.swarm_results_ = self._swarm(phi @ to_coef, Y, Yw, z_ls, weights, swarm, seeds)
            coef = to_coef @ np.stack([res.x for res in self.swarm_results_], axis=1)
        self.coef_ = coef
        self.scaling_, self.terms_, self.basis_ = scaling, terms, basis
        self._plan = SeriesPlan.build(basis, scaling, terms, coef)
        self._plan_of = (coef, scaling, terms)
        self.data_bounds_ = np.stack([X.min(axis=0), X.max(axis=0)])
        resid = Y - phi @ coef
        self.train_rms_ = np.sqrt((weights[:, None] * resid**2).sum(axis=0) / total_w)
        self.lstsq_rms_ = np.sqrt(lstsq_sse / total_w)
        best = np.sqrt(lstsq_sse.sum() / total_w)
        self.rms_ratio_ = float(np.sqrt((self.train_rms_**2).sum()) / best) if best > 0 else 1.0
        return self

    def _swarm(self, A, Y, Yw, B, weights, cfg: SwarmConfig, seeds) -> list[SwarmResult]:
        """Minimise the fitness of every output at once, over the orthonormal coordinates ``z``.

        ``A`` maps ``z`` to predictions, ``B`` (r, outputs) is the least-squares
        optimum ``U^T y`` of each output.
        """
        total_w = weights.sum()
        yy = (Yw * Yw).sum(axis=0)
        if self.fitness == "rms":
            def fun(Z, which):
                sse = np.einsum("bpk,bpk->bp", Z, Z) - 2.0 * np.einsum("bpk,kb->bp", Z, B[:, which])
                return np.sqrt(np.maximum(sse + yy[which, None], 0.0) / total_w)
            x0 = None
        else:
            w_max = weights.max()

            def fun(Z, which):
                r = np.abs(Y.T[which, None, :] - np.einsum("nk,bpk->bpn", A, Z))   # (b, particles, n)
                if self.fitness == "max":
                    return (r * weights).max(axis=2) / w_max
                return (r @ weights) / total_w
            x0 = B.T        # the least-squares fit as one particle: never worse than it
        half = cfg.bound_scale * np.maximum(np.sqrt(yy), 1e-12)[:, None] * np.ones((1, B.shape[0]))
        return minimize_batch(fun, -half, half, cfg, x0=x0,
                              random_states=[np.random.default_rng(s) for s in seeds])

    # ------------------------------------------------------------------ prediction
    def predict(self, X) -> NDArray[np.float64]:
        """Predicted errors, shape (n, n_outputs) mm (1-D if fitted on a 1-D ``y``)."""
        check_is_fitted(self, "coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._shape_output(self._predict_trusted(X))

    def _predict_trusted(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """Prediction ``(n, n_outputs)`` on validated arrays (no checks: the hot path of blends).

        Evaluated by the compiled :class:`SeriesPlan` in cache-sized chunks; it
        equals ``basis_.transform(X) @ coef_`` to rounding (tested).
        """
        return self._series_plan().evaluate(X)

    def _series_plan(self) -> SeriesPlan:
        """The compiled series, built in ``fit``; rebuilt if ``coef_``, ``scaling_`` or ``terms_``
        were replaced since (model files set them directly)."""
        plan, source = self.__dict__.get("_plan"), self.__dict__.get("_plan_of", ())
        now = (self.coef_, self.scaling_, self.terms_)
        if plan is None or len(source) != 3 or any(a is not b for a, b in zip(source, now)):
            plan = self._plan = SeriesPlan.build(self.basis_, self.scaling_, self.terms_, self.coef_)
            self._plan_of = now
        return plan

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance of each point outside the bounding box of the training inputs, shape (n,).

        0 inside; a large value means the prediction is an extrapolation.
        """
        check_is_fitted(self, "coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return distance_outside_boxes(X, self.data_bounds_[:1], self.data_bounds_[1:])

    def warn_if_extrapolating(self, X, limit: float = 50.0) -> NDArray[np.bool_]:
        """Warn (``ExtrapolationWarning``) about points farther than ``limit``; return the mask."""
        return warn_far(self.distance_to_data(X), limit)

    def equations(self, input_names=None, output_names=("dx", "dy", "dz"), precision: int = 6) -> list[str]:
        """The fitted functions in raw units (mm, degrees), one line per output.

        Polynomials are expanded into powers of the raw inputs, like the
        paper's eqs. (9)-(20); Fourier terms are written with their phase.
        """
        check_is_fitted(self, "coef_")
        d = self.n_features_in_
        if input_names is None:
            input_names = ["x", "y", "z"] if self.inputs == "cartesian" and d == 3 else (
                [f"q{i + 1}" for i in range(d)] if self.inputs == "joint" else [f"x{i + 1}" for i in range(d)])
        outs = list(output_names)[: self.coef_.shape[1]] + [f"e{k + 1}" for k in range(len(output_names), self.coef_.shape[1])]
        return [f"{name} = {self._equation(a, input_names, precision)}" for a, name in enumerate(outs)]

    def _equation(self, a: int, names, precision: int) -> str:
        fmt = f"{{:+.{precision}g}}"
        parts = []
        if self.basis == "polynomial":
            for exps, c in raw_polynomial(self.terms_, self.coef_[:, a], self.scaling_).items():
                mono = "*".join(f"{names[i]}^{k}" if k > 1 else names[i] for i, k in enumerate(exps) if k)
                parts.append(fmt.format(c) + (f"*{mono}" if mono else ""))
        else:
            s = self.scaling_
            for (trig, i, q), c in zip(self.terms_, self.coef_[:, a]):
                if trig == "1":
                    parts.append(fmt.format(c))
                    continue
                if self.inputs == "joint":
                    arg = f"{q * np.pi / 180:.{precision}g}*{names[i]}"
                else:
                    k = q * np.pi / 2 / s.scale[i]
                    arg = f"{k:.{precision}g}*{names[i]} {-k * s.centre[i]:+.{precision}g}"
                parts.append(f"{fmt.format(c)}*{trig}({arg})")
        text = " ".join(f"{p[0]} {p[1:]}" for p in parts)        # "+0.5*x" -> "+ 0.5*x"
        return text[2:] if text.startswith("+ ") else "-" + text[2:]

    def _describe(self) -> str:
        if self.basis == "polynomial":
            kind = {1: "first", 2: "second"}.get(self.degree, f"degree-{self.degree}")
            return f"{kind}-degree polynomial{' with cross terms' if self.cross_terms else ''} of {self.inputs} inputs"
        return f"Fourier series with {self.harmonics} harmonic(s) of {self.inputs} inputs"
