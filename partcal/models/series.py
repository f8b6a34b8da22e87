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
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from joblib import Parallel, delayed, effective_n_jobs
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import FieldReader, Requirement, boolean, integer, is_int, one_of, param_error
from ..errors import DataError, PartcalError
from ..metrics import distance_outside_boxes
from .._validation import seed_from
from .base import ErrorModelBase, check_sample_weight
from .kindtable import RegionFit
from .features import Basis, Scaling, SeriesPlan, column_bounds
from .polynomials import coef_centred, coef_from_scaled, lowered_terms
from .swarm import RULES, TOPOLOGIES, SwarmConfig, SwarmResult, minimize_batch

log = logging.getLogger(__name__)
try:        # numpy's einsum without its Python wrapper: a quarter of the cost of a small swarm's RMS
    from numpy._core.multiarray import c_einsum as _einsum
except ImportError:  # pragma: no cover - other numpy layouts
    _einsum = np.einsum
INPUTS = ("cartesian", "joint")
BASES = ("polynomial", "fourier")
SOLVERS = ("pso", "lstsq")
FITNESSES = ("rms", "max", "mae")
# a run config's solver section: these keys are SwarmConfig's (checked by it), as YAML types
SWARM_KEYS = {"particles": "int", "iterations": "int", "c1": "float", "c2": "float", "rule": "str",
              "topology": "str", "neighbours": "int", "inertia": "list", "vmax": "float",
              "bound_scale": "float", "stop_fitness": "float", "patience": "int", "ftol": "float"}
MIN_SAMPLES_PER_TERM = 3           # a partition's default smallest region: 3 samples a term
_DEFAULT_SWARM = SwarmConfig()      # frozen: one validated instance instead of a new one per call


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
    train_inputs_ : ndarray, shape (n_samples, d)
        The training inputs, for :meth:`distance_to_data` (set by :meth:`fit`).

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

    kind = "series"
    file_kind = "global"
    _parameter_rules = {
        "inputs": one_of(*INPUTS),
        "basis": one_of(*BASES),
        "degree": integer(1, 8, default=1),
        "harmonics": integer(1, 8, default=1),
        "cross_terms": boolean(False),
        "solver": one_of(*SOLVERS),
        "fitness": one_of(*FITNESSES),
    }
    _requirements = (
        Requirement("cross_terms", "false for the fourier basis",
                    lambda p: not p["cross_terms"] or p["basis"] == "polynomial"),
        Requirement("fitness", "'rms' with solver 'lstsq' (least squares minimises the RMS; use solver 'pso')",
                    lambda p: p["solver"] != "lstsq" or p["fitness"] == "rms"),
    )

    # ------------------------------------------------------------------ parameters
    def _check_params(self) -> tuple[Basis, SwarmConfig]:
        self._check_rules()
        if self.pso is not None and not isinstance(self.pso, SwarmConfig):
            raise param_error(type(self).__name__, "pso", "a SwarmConfig or None", self.pso)
        order = self.degree if self.basis == "polynomial" else self.harmonics
        return Basis(self.basis, self.inputs, order, bool(self.cross_terms)), self.pso or _DEFAULT_SWARM

    # ------------------------------------------------------------------ fitting
    def fit(self, X, y, sample_weight=None):
        """Fit the coefficients to errors ``y`` (n, 3) mm at inputs ``X`` (n, d), each sample weighted by
        ``sample_weight`` (n,) (weighted least squares, a weighted fitness for the swarm; a partition's
        region). Returns self."""
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)   # once, with y
        if sample_weight is not None:
            sample_weight = check_sample_weight(type(self).__name__, sample_weight, len(X))
        self._fit(X, y, sample_weight, trusted=True)
        kept = X if sample_weight is None else X[sample_weight > 0]
        self.train_inputs_ = np.array(kept, copy=True)
        return self._prepare()

    def _fit(self, X, y, sample_weight, trusted: bool = False):
        problem = self._setup(X, y, sample_weight, trusted)
        results = [] if self.solver == "lstsq" else fit_swarms([(self, problem)])[0]
        return self._complete(problem, results)

    def _setup(self, X, y, sample_weight, trusted: bool = False) -> "_Problem":
        """Validate, scale and decompose: the least-squares problem of this fit (no swarm yet).

        ``trusted``: ``X`` (n, d) and ``y`` (n, outputs) were validated by the caller
        (:meth:`fit`, a partitioned model's regions), so the checks are skipped.
        """
        basis, _ = self._check_params()
        if trusted:
            self.n_features_in_ = X.shape[1]
        else:
            X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        self._y_1d = y.ndim == 1
        Y = y.reshape(len(y), -1)
        weights = np.ones(len(X)) if sample_weight is None else np.asarray(sample_weight, dtype=float)
        held = X if sample_weight is None else X[weights > 0]       # samples of weight 0 do not set the scaling
        bounds = column_bounds(held)
        scaling = Scaling.fit(held, bounds)
        terms = basis.terms(scaling)
        n, m = X.shape[0], len(terms)
        if n < m:
            raise PartcalError(
                f"{type(self).__name__} with {m} terms per output ({self.describe()}) needs at least "
                f"{m} samples; got {n} sample{'s' if n != 1 else ''}")
        phi = basis.transform(X, scaling, terms)
        sqrt_w = np.sqrt(weights)
        Yw = Y * sqrt_w[:, None]
        # [Phi W^1/2, W^1/2 Y] = Q R (R only: Q is never formed); Phi W^1/2 = Q1 R11 and R11 = Ur S V^T, so
        # U = Q1 Ur and U^T W^1/2 Y = Ur^T R12: the SVD of an (m, m) matrix instead of the (n, m) one
        R = np.linalg.qr(np.hstack([phi * sqrt_w[:, None], Yw]), mode="r")
        Ur, s, Vt = np.linalg.svd(R[:m, :m])
        keep = s > s[0] * max(n, m) * np.finfo(float).eps
        Ur, s, Vt = Ur[:, keep], s[keep], Vt[keep]
        z_ls = Ur.T @ R[:m, m:]                                     # (r, outputs)
        yy = np.diagonal(Yw.T @ Yw).copy()                         # BLAS: faster than summing axis 0
        return _Problem(X, Y, weights, basis, scaling, terms, phi, Vt.T / s, z_ls, yy,
                        np.maximum(yy - (z_ls * z_ls).sum(axis=0), 0.0), np.stack(bounds))

    def _complete(self, problem: "_Problem", results: list[SwarmResult]) -> "ErrorModel":
        """Set the fitted attributes from the swarm results (least squares without them)."""
        z = problem.z_ls if not results else problem.z_ls + np.stack([res.x for res in results], axis=1)
        coef = problem.to_coef @ z
        self.swarm_results_ = results
        self.coef_ = coef
        self.scaling_, self.terms_, self.basis_ = problem.scaling, problem.terms, problem.basis
        # compiled here, not on first use: scikit-learn's contract is that predict() leaves __dict__ alone
        self._plan = SeriesPlan.build(problem.basis, problem.scaling, problem.terms, coef)
        self._plan_of = (coef, problem.scaling, problem.terms)
        w = problem.weights
        self.data_bounds_ = problem.bounds
        resid = problem.Y - problem.phi @ coef
        total_w = w.sum()
        self.train_rms_ = np.sqrt(np.diagonal((w[:, None] * resid).T @ resid) / total_w)
        self.lstsq_rms_ = np.sqrt(problem.lstsq_sse / total_w)
        best = np.sqrt(problem.lstsq_sse.sum() / total_w)
        self.rms_ratio_ = float(np.sqrt((self.train_rms_**2).sum()) / best) if best > 0 else 1.0
        self.coef_covariance_, self.noise_var_ = spread_of(problem.to_coef, w, resid)
        self.residual_dof_ = float(w.sum() ** 2 / np.sum(w**2) - problem.to_coef.shape[1])   # n_eff - rank
        return self

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

    def std_validated(self, X: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Prediction and its standard deviation, both (n, outputs) mm: ``sigma_k sqrt(1 + h(x))``.

        ``h(x) = phi(x)^T (Phi^T W Phi)^-1 phi(x)`` is the leverage of the inputs
        (the coefficients' least-squares covariance over the noise, grown fast
        outside the data) and ``sigma_k^2`` the residual variance of output ``k``.
        """
        problem = self.spread_problem()
        if problem is not None:
            raise DataError(problem)
        phi = self.basis_.transform(X, self.scaling_, self.terms_)
        leverage = np.einsum("ij,jk,ik->i", phi, self.coef_covariance_, phi)
        std = np.sqrt(np.maximum(1.0 + leverage, 0.0)[:, None] * self.noise_var_[None, :])
        return self._predict_trusted(X), std

    def spread_problem(self) -> str | None:
        if getattr(self, "coef_covariance_", None) is None:
            return ("this series model's file was written before partcal kept the least-squares covariance of the "
                    "coefficients, so its predictions have no standard deviation: fit it again (partcal run)")
        if getattr(self, "residual_dof_", 1.0) < 0.5:      # as many samples as terms: residuals all but zero
            return (f"this series model was fitted on no more samples than its {self.coef_covariance_.shape[0]} "
                    "terms, so its residuals cannot tell the scatter of new data: its predictions have no "
                    "standard deviation")
        return None

    def _prepare(self) -> "ErrorModel":
        """The compiled series (kept if it is that of the current coefficients) and the base's KD-tree;
        returns self (see :meth:`ErrorModelBase._prepare`)."""
        self._plan, self._plan_of = self._series_plan(), (self.coef_, self.scaling_, self.terms_)
        return super()._prepare()

    def _series_plan(self) -> SeriesPlan:
        """The compiled series of :meth:`_prepare` (or of ``fit``); built for this call, not kept, if
        ``coef_``, ``scaling_`` or ``terms_`` were replaced since."""
        plan, source = self.__dict__.get("_plan"), self.__dict__.get("_plan_of", ())
        now = (self.coef_, self.scaling_, self.terms_)
        if plan is None or len(source) != 3 or any(a is not b for a, b in zip(source, now)):
            plan = SeriesPlan.build(self.basis_, self.scaling_, self.terms_, self.coef_)
        return plan

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance from each point to the nearest training input, shape (n,), input units.

        Exact (a KD-tree over ``train_inputs_``, which the model file keeps);
        a large value means the prediction is an extrapolation. Models fitted
        on weights only (regions of a ``PartitionedErrorModel``) and models
        loaded from files written before partcal kept the training inputs fall
        back to the distance outside the bounding box of the training inputs,
        which reads 0 in holes of the data.
        """
        check_is_fitted(self, "coef_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        if getattr(self, "train_inputs_", None) is None:
            return distance_outside_boxes(X, self.data_bounds_[:1], self.data_bounds_[1:])
        return self._distance_to_train_inputs(X)


    def equations(self, input_names=None, output_names=("dx", "dy", "dz"), precision: int | None = None
                  ) -> list[str]:
        """The fitted functions in raw units (mm, degrees), one line per output.

        Polynomials are expanded into powers of the raw inputs, like the
        paper's eqs. (9)-(20), when that form is exact to 1e-9 mm over the
        data; otherwise (high degrees of inputs far from zero, such as joint
        angles near -170 degrees) into powers of the centred inputs, e.g.
        ``(q3 + 170.5)^4``, which lose no digits. Fourier terms are written
        with their phase.
        Numbers are written in full (``repr``) precision, so the printed
        equations reproduce :meth:`predict` (to 1e-6 mm up to degree 8);
        ``precision`` rounds them to that many significant digits for reading.
        """
        check_is_fitted(self, "coef_")
        d = self.n_features_in_
        if input_names is None:
            input_names = ["x", "y", "z"] if self.inputs == "cartesian" and d == 3 else (
                [f"q{i + 1}" for i in range(d)] if self.inputs == "joint" else [f"x{i + 1}" for i in range(d)])
        n_out = self.coef_.shape[1]
        outs = list(output_names)[:n_out] + [f"e{k + 1}" for k in range(len(output_names), n_out)]
        return [f"{name} = {self._equation(a, input_names, precision)}" for a, name in enumerate(outs)]

    def _equation(self, a: int, names, precision: int | None) -> str:
        """The right-hand side for output ``a``: signed terms joined, ``"0.5*x - 0.25*y"``."""
        if self.basis == "fourier":
            parts = self._fourier_terms(a, names, precision)
        else:
            parts = self._raw_terms(a, names, precision) or self._centred_terms(a, names, precision)
        text = " ".join(f"{p[0]} {p[1:]}" for p in parts)        # "+0.5*x" -> "+ 0.5*x"
        return text[2:] if text.startswith("+ ") else "-" + text[2:]

    def _raw_terms(self, a: int, names, precision: int | None) -> list[str] | None:
        """The paper's form, powers of the raw inputs, if exact to 1e-9 mm over the data; else None."""
        s = self.scaling_
        terms = lowered_terms(self.terms_)
        coef = coef_from_scaled(self.terms_, self.coef_[:, a:a + 1], s.scale, s.centre)[:, 0]
        reach = np.abs(self.data_bounds_).max(axis=0)          # largest |input| in the data
        rounding = 1e3 * np.finfo(float).eps * sum(abs(c) * np.prod(reach ** np.array(e)) for e, c in zip(terms, coef))
        if rounding > 1e-9:             # expanding would cancel digits
            return None
        parts = []
        for exps, c in sorted(zip(terms, coef), key=lambda tc: (sum(tc[0]), [-k for k in tc[0]])):
            mono = "*".join(f"{names[i]}^{k}" if k > 1 else names[i] for i, k in enumerate(exps) if k)
            parts.append(_number(c, precision) + (f"*{mono}" if mono else ""))
        return parts

    def _centred_terms(self, a: int, names, precision: int | None) -> list[str]:
        """Powers of the centred inputs, ``(q3 + 170.5)^4``, which lose no digits."""
        s = self.scaling_
        terms, coef = coef_centred(self.terms_, self.coef_[:, a:a + 1], s.scale)
        parts = []
        for exps, c in zip(terms, coef[:, 0]):
            factors = []
            for i, k in enumerate(exps):
                if k:
                    shift = _number(-s.centre[i], precision)
                    shifted = f"({names[i]} {shift[0]} {shift[1:]})"
                    factors.append(f"{shifted}^{k}" if k > 1 else shifted)
            parts.append(_number(c, precision) + ("*" + "*".join(factors) if factors else ""))
        return parts

    def _fourier_terms(self, a: int, names, precision: int | None) -> list[str]:
        """Fourier terms with their phase: ``0.1*cos(0.0349*q1)`` or ``0.1*sin(0.00157*x -1.2)``."""
        s, parts = self.scaling_, []
        for (trig, i, q), c in zip(self.terms_, self.coef_[:, a]):
            if trig == "1":
                parts.append(_number(c, precision))
                continue
            if self.inputs == "joint":
                arg = f"{_number(q * np.pi / 180, precision, sign=False)}*{names[i]}"
            else:
                k = q * np.pi / 2 / s.scale[i]
                arg = f"{_number(k, precision, sign=False)}*{names[i]} {_number(-k * s.centre[i], precision)}"
            parts.append(f"{_number(c, precision)}*{trig}({arg})")
        return parts

    def describe(self) -> str:
        if self.basis == "polynomial":
            kind = {1: "first", 2: "second"}.get(self.degree, f"degree-{self.degree}")
            return f"{kind}-degree polynomial{' with cross terms' if self.cross_terms else ''} of {self.inputs} inputs"
        return f"Fourier series with {self.harmonics} harmonic(s) of {self.inputs} inputs"

    # ------------------------------------------------------------------ the kind: config, files, run
    @classmethod
    def params_from_config(cls, sec, context: dict) -> dict:
        """The basis keys of a config entry, and its ``solver`` section: ``method``, ``fitness`` and the
        swarm settings (``swarm``, checked by :class:`SwarmConfig`)."""
        rules = cls._parameter_rules
        params = {key: sec.rule(key, rules[key]) for key in ("inputs", "basis", "degree", "harmonics", "cross_terms")}
        solver = sec.section("solver")
        params["solver"] = solver.rule("method", rules["solver"])
        params["fitness"] = solver.rule("fitness", rules["fitness"])
        for req in cls._requirements:
            (solver if req.param == "fitness" else sec).requirements((req,), params)
        params["swarm"] = _swarm_settings(solver, params["solver"])
        solver.done()
        return params

    @classmethod
    def from_params(cls, params: dict, random_state=None) -> "ErrorModel":
        params = dict(params)
        swarm = params.pop("swarm", {})
        pso = SwarmConfig(**swarm) if params["solver"] == "pso" and swarm else None
        return cls(**params, pso=pso, random_state=random_state)

    def file_section(self) -> dict:
        return {"basis": self.basis, "order": self.basis_.order, "cross_terms": bool(self.cross_terms),
                "solver": self.solver, "fitness": self.fitness, "scaling": self.scaling_.to_dict(),
                "terms": [list(t) for t in self.terms_], "coef": self.coef_.tolist(),
                "data_bounds": self.data_bounds_.tolist(), "train_rms": self.train_rms_.tolist(),
                "lstsq_rms": self.lstsq_rms_.tolist(), "rms_ratio": self.rms_ratio_,
                **({"coef_covariance": self.coef_covariance_.tolist(), "noise_var": self.noise_var_.tolist()}
                   if getattr(self, "coef_covariance_", None) is not None else {})}

    @classmethod
    def from_file_section(cls, r: FieldReader, inputs: str, n_in: int, n_out: int) -> "ErrorModel":
        """A series model from its section: the scaling must be the one its data bounds give, and the
        terms exactly those of its basis and order."""
        rules = cls._parameter_rules
        params = {"basis": r.rule("basis", rules["basis"]), "cross_terms": r.rule("cross_terms", rules["cross_terms"]),
                  "solver": r.rule("solver", rules["solver"]), "fitness": r.rule("fitness", rules["fitness"])}
        order = r.rule("order", rules["degree" if params["basis"] == "polynomial" else "harmonics"])
        r.requirements(cls._requirements, params)
        bounds = r.array("data_bounds", (2, n_in))
        if np.any(bounds[0] > bounds[1]):
            r.fail("data_bounds", "a low bound exceeds its high bound")
        scaling = _scaling_from(r.sub("scaling"), bounds, n_in)
        basis = Basis(params["basis"], inputs, order, params["cross_terms"])
        want = basis.terms(scaling)
        terms = _terms_from(r, params["basis"])
        if terms != want:
            r.fail("terms", f"are not the {len(want)} terms of a {basis.kind} basis of order {order} over the varying "
                            f"inputs (exponents beyond the degree, or a basis that does not match)")
        model = cls(inputs=inputs, degree=order if basis.kind == "polynomial" else 1,
                    harmonics=order if basis.kind == "fourier" else 1, **params)
        model.coef_, model.scaling_, model.terms_, model.basis_ = r.array("coef", (len(terms), n_out)), scaling, terms, basis
        model.n_features_in_, model._y_1d, model.data_bounds_ = n_in, False, bounds
        model.train_rms_ = r.array("train_rms", (n_out,))
        model.lstsq_rms_ = r.array("lstsq_rms", (n_out,))
        model.rms_ratio_ = r.number("rms_ratio", 0.0)
        if np.any(model.train_rms_ < 0) or np.any(model.lstsq_rms_ < 0):
            r.fail("train_rms", "RMS values must be >= 0")
        model.swarm_results_ = []
        model.coef_covariance_ = model.noise_var_ = None          # files before the spread: none
        if "coef_covariance" in r.doc:
            model.coef_covariance_ = r.array("coef_covariance", (len(terms), len(terms)))
            model.noise_var_ = r.array("noise_var", (n_out,))
            if np.any(model.noise_var_ < 0) or np.any(np.diagonal(model.coef_covariance_) < 0):
                r.fail("noise_var", "variances must be >= 0")
        return model

    _damage_field = "coef"

    def min_samples(self, n_inputs: int) -> tuple[int, str, str]:
        terms = self._check_params()[0].n_terms(n_inputs)
        return terms, f"{terms} terms per output ({n_inputs} varying {self.inputs} inputs)", (
            "degree" if self.basis == "polynomial" else "harmonics")

    def region_minimum(self, n_active: int) -> tuple[int, str, str]:
        """Smallest region a partition may give this model (``MIN_SAMPLES_PER_TERM`` samples a term), why,
        and the config key that sets it."""
        terms, _, key = self.min_samples(n_active)
        return MIN_SAMPLES_PER_TERM * terms, f"{terms} terms per output", key

    @property
    def solver_name(self) -> str:
        return self.solver

    @classmethod
    def config_keys(cls) -> set[str]:
        return {"inputs", "basis", "degree", "harmonics", "cross_terms", "solver"}

    def n_outputs(self) -> int:
        return int(self.coef_.shape[1])

    def effective_parameters(self) -> float:
        """Coefficients over all outputs (terms x outputs)."""
        return float(self.coef_.size)

    def pso_rms_ratio(self) -> float | None:
        return float(self.rms_ratio_) if self.solver == "pso" else None

    def swarm_runs(self) -> list[tuple[np.ndarray, float]]:
        return [(res.history, float(self.lstsq_rms_[a])) for a, res in enumerate(self.swarm_results_)]

    def predict_validated(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        return self._predict_trusted(X)


def _swarm_settings(solver, method: str) -> dict:
    """The swarm keys of a config entry's ``solver`` section (checked by :class:`SwarmConfig`)."""
    swarm = {}
    for key, kind in SWARM_KEYS.items():
        if not solver.has(key):
            continue
        if method != "pso":
            solver.fail(solver.path(key), "applies to method: pso only")
        if solver.data[key] is None and key in ("patience", "stop_fitness"):
            solver.get(key, "any")
            swarm[key] = None
        elif key in ("rule", "topology"):
            swarm[key] = solver.rule(key, one_of(*(RULES if key == "rule" else TOPOLOGIES)))
        elif key == "inertia":
            swarm[key] = tuple(solver.get(key, "list"))
        else:
            swarm[key] = solver.get(key, kind)
    if swarm:
        try:
            SwarmConfig(**swarm)
        except PartcalError as exc:
            solver.fail(solver.where, str(exc))
    return swarm


def _scaling_from(s: FieldReader, bounds: NDArray[np.float64], n_in: int) -> Scaling:
    """A file's ``scaling``, which must be what the fit derived from the same data bounds."""
    scaling = Scaling(s.array("centre", (n_in,)), s.array("scale", (n_in,)), s.array("active", (n_in,), bool))
    expected = Scaling.fit(bounds)
    if not np.array_equal(scaling.active, expected.active):
        s.fail("active", f"must mark the inputs that vary within data_bounds: {expected.active.tolist()}")
    for key in ("centre", "scale"):
        if not np.allclose(getattr(scaling, key), getattr(expected, key), rtol=1e-12, atol=0):
            s.fail(key, f"disagrees with data_bounds (expected {getattr(expected, key).tolist()})")
    return scaling


def _terms_from(r: FieldReader, basis: str) -> list[tuple]:
    """A file's terms as tuples, with the element types checked (no strings for numbers, no booleans)."""
    out = []
    for i, t in enumerate(r.get("terms", list)):
        ok = isinstance(t, list) and (
            all(is_int(k) for k in t) if basis == "polynomial"
            else len(t) == 3 and t[0] in ("1", "cos", "sin") and is_int(t[1]) and is_int(t[2]))
        if not ok:
            r.fail(f"terms[{i}]", "expected a list of integer exponents" if basis == "polynomial"
                   else "expected [\"1\"|\"cos\"|\"sin\", input, harmonic]")
        out.append(tuple(t) if basis == "polynomial" else (t[0], int(t[1]), int(t[2])))
    return out


def _number(value: float, precision: int | None, sign: bool = True) -> str:
    """``value`` in full (``repr``) or to ``precision`` significant digits; with its sign if ``sign``."""
    text = repr(float(value)) if precision is None else f"{float(value):.{precision}g}"
    return "+" + text if sign and not text.startswith("-") else text


# ---------------------------------------------------------------------- swarms of many fits
def spread_of(to_coef: NDArray[np.float64], weights: NDArray[np.float64], resid: NDArray[np.float64]
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The coefficients' covariance over the noise, ``(Phi^T W Phi)^+ = V S^-2 V^T`` (terms, terms), and each
    output's residual variance (outputs,), from the weighted residuals ``resid`` (n, outputs).

    The variance is the weighted mean square times ``n_eff / (n_eff - r)`` (``n_eff = (sum w)^2 / sum w^2``,
    ``r`` the rank), the unbiased estimate for unit weights.
    """
    rank = to_coef.shape[1]
    n_eff = weights.sum() ** 2 / np.sum(weights**2)
    mean_square = (weights[:, None] * resid**2).sum(axis=0) / weights.sum()
    return to_coef @ to_coef.T, mean_square * n_eff / max(n_eff - rank, 1.0)


@dataclass(frozen=True, eq=False)
class _Problem:
    """The weighted least-squares problem of one fit, in the orthonormal coordinates ``z``.

    ``Phi W^1/2 = U S V^T``; coefficients are ``to_coef @ z`` (``to_coef = V S^-1``,
    (terms, r)); ``z_ls = U^T W^1/2 Y`` (r, outputs) is the least-squares optimum,
    ``yy`` (outputs,) the weighted sum of squares of ``Y`` and ``lstsq_sse`` its
    residual, so the weighted sum of squared errors at ``z`` is
    ``|z - z_ls|^2 + lstsq_sse``.
    """

    X: NDArray[np.float64]
    Y: NDArray[np.float64]
    weights: NDArray[np.float64]
    basis: Basis
    scaling: Scaling
    terms: list
    phi: NDArray[np.float64]
    to_coef: NDArray[np.float64]
    z_ls: NDArray[np.float64]
    yy: NDArray[np.float64]
    lstsq_sse: NDArray[np.float64]
    bounds: NDArray[np.float64]          # (2, d): smallest and largest input


def fit_swarms(jobs: list[tuple[ErrorModel, _Problem]]) -> list[list[SwarmResult]]:
    """Run the swarms of many PSO fits (every output of every model) in as few batches as possible.

    Fits with the same fitness, swarm settings and number of coordinates share
    one :func:`minimize_batch` loop. Each output of each model keeps its own
    random stream (a child of the model's ``random_state``) and stopping test,
    and its fitness depends on its own data only, so every result is exactly
    what the model would get fitted alone.

    A swarm searches the offset ``z - z_ls`` from the least-squares optimum,
    in the box ``|z_k| <= bound_scale |y|`` (the same box as in ``z``, moved):
    the RMS is then ``sqrt((|offset|^2 + lstsq_sse) / sum(w))``.

    Returns
    -------
    list of list of SwarmResult
        Per job, one result per output; ``x`` is the offset from ``z_ls``.
    """
    out: list[list[SwarmResult]] = [[] for _ in jobs]
    groups: dict[tuple, list[int]] = {}
    for k, (model, problem) in enumerate(jobs):
        key = (model.fitness, model._check_params()[1], problem.z_ls.shape[0])
        groups.setdefault(key, []).append(k)
    for (fitness, cfg, _), members in groups.items():
        owner = np.concatenate([np.full(jobs[k][1].Y.shape[1], j) for j, k in enumerate(members)])
        problems = [jobs[k][1] for k in members]
        B = np.concatenate([p.z_ls.T for p in problems])               # (outputs of all, r)
        yy = np.concatenate([p.yy for p in problems])
        seeds = [g for k in members
                 for g in np.random.SeedSequence(seed_from(jobs[k][0].random_state)).spawn(jobs[k][1].Y.shape[1])]
        half = cfg.bound_scale * np.maximum(np.sqrt(yy), 1e-12)[:, None] * np.ones((1, B.shape[1]))
        fun = _rms_fitness(problems) if fitness == "rms" else _residual_fitness(problems, owner, fitness)
        results = minimize_batch(fun, -half - B, half - B, cfg, x0=None if fitness == "rms" else 0.0 * B,
                                 random_states=[np.random.default_rng(s) for s in seeds])
        for j, res in zip(owner, results):
            out[members[j]].append(res)
    return out


def fit_regions(local: ErrorModel, models: list[ErrorModel], data: list[tuple], n_jobs, X=None, Y=None, seed=None
                ) -> list[ErrorModel]:
    """Fit every region's model to its ``(X, Y, weights)``; swarms of all regions in one batch (the series
    row's :class:`~partcal.models.kindtable.RegionFit`).

    PSO fits run their swarms together (:func:`fit_swarms`: one vectorised loop
    for all regions and outputs, grouped by dimension), in ``n_jobs`` slices of
    regions when asked. Every region keeps its own seed, so each model is
    exactly the one a solo fit gives, whatever ``n_jobs``. ``X, Y, seed`` (all
    the samples, the partition's seed) are not needed here.
    """
    if not all(m.solver == "pso" for m in models):              # no swarms: region by region
        return Parallel(n_jobs=n_jobs)(delayed(_fit_region)(m, *d) for m, d in zip(models, data))
    workers = max(1, min(len(models), effective_n_jobs(n_jobs)))
    cuts = np.linspace(0, len(models), workers + 1).round().astype(int)
    slices = [(models[a:b], data[a:b]) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]
    if len(slices) == 1:
        return _fit_batch(*slices[0])
    return [m for part in Parallel(n_jobs=n_jobs)(delayed(_fit_batch)(*sl) for sl in slices) for m in part]


def _fit_region(model: ErrorModel, X, Y, weights) -> ErrorModel:
    return model._fit(X, Y, weights)


def _fit_batch(models: list[ErrorModel], data: list[tuple]) -> list[ErrorModel]:
    problems = [m._setup(*d, trusted=True) for m, d in zip(models, data)]
    results = fit_swarms(list(zip(models, problems)))
    return [m._complete(p, r) for m, p, r in zip(models, problems, results)]


SERIES_REGIONS = RegionFit(fit_all=fit_regions)


def _rms_fitness(problems: list[_Problem]):
    """The weighted RMS of every output at offset ``d``: ``sqrt(|d|^2 / sum(w) + lstsq_sse / sum(w))``, O(r)."""
    total = np.concatenate([np.full(p.Y.shape[1], p.weights.sum()) for p in problems])
    floor = np.concatenate([p.lstsq_sse for p in problems]) / total
    cache: list = [None, None, None]         # the rows of the last ``which`` (the same array until it changes)

    def fun(D, which):               # D (b, particles, r), a view of swarm memory (b, r, particles)
        if which is not cache[0]:
            cache[:] = [which, 1.0 / total[which][:, None], floor[which][:, None]]
        D = D.transpose(0, 2, 1)
        f = _einsum("bkp,bkp->bp", D, D)
        f *= cache[1]
        f += cache[2]
        return np.sqrt(f, out=f)
    return fun


def _residual_fitness(problems: list[_Problem], owner: NDArray[np.intp], fitness: str):
    """Largest or mean weighted absolute residual, from every sample: O(samples x r) per particle.

    The outputs of one model are evaluated together, and each model alone, so
    a model's fitness is the same in any batch. The least-squares fit is one
    particle of each swarm, so the result is never worse than it.
    """
    A = [p.phi @ p.to_coef for p in problems]                         # z -> predictions, (n, r)
    R0 = [(p.Y - a @ p.z_ls).T for p, a in zip(problems, A)]           # least-squares residuals (outputs, n)

    def fun(Z, which):
        out = np.empty(Z.shape[:2])
        models = owner[which]
        for j in np.unique(models):
            rows = np.flatnonzero(models == j)
            p = problems[j]
            first = np.flatnonzero(owner == j)[0]
            axes = which[rows] - first
            r = np.abs(R0[j][axes, None, :] - np.einsum("nk,bpk->bpn", A[j], Z[rows]))   # (b, particles, n)
            if fitness == "max":
                out[rows] = (r * p.weights).max(axis=2) / p.weights.max()
            else:
                out[rows] = (r @ p.weights) / p.weights.sum()
        return out
    return fun
