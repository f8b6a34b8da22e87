"""Gaussian priors on identified parameters: MAP identification as extra residual rows.

A prior holds some of the parameters (``index``) near a ``mean`` with a covariance ``C``. With the
measurements' noise ``sigma`` (mm per coordinate), the maximum a posteriori values minimise

    ``|r(v)|^2 / sigma^2 + (v - m)^T C^-1 (v - m)``

which is the least squares of the residuals ``r(v)`` stacked with the rows ``sigma L^-1 (v - m)``
(``C = L L^T``): rows in the residuals' units (mm), appended to them by :meth:`Prior.augmented`, so
that every fit (Levenberg-Marquardt, the rank rule, the standard errors) reads them as more
measurements. A parameter the prior holds is identifiable through it (the rank rule sees its row),
and its distance from the mean is priced by the prior instead of pruned
(:func:`~partcal.calibration.identification.identify`).

Two sources of priors: a datasheet-like one (:func:`plausible_prior`: each row parameter's plausible
error, :data:`~partcal.calibration.parameters.PLAUSIBLE_ERROR`, with a strength) and an identified
model (:func:`model_prior`: its values and covariance, inflated).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..metrics import within_one_standard_error

EIGEN_FLOOR = 1e-12
"""Eigenvalues of a prior covariance below this fraction of the largest are raised to it (a covariance
read from a file may be singular to rounding; the prior then holds that direction very firmly)."""


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on the parameters ``index`` of a parameter vector.

    Attributes
    ----------
    index : ndarray of int, shape (k,)
        Positions of the parameters held, in the parameter vector.
    mean : ndarray, shape (k,)
        Their prior means (mm, degrees).
    root : ndarray, shape (k, k)
        ``W`` of the rows ``W (v[index] - mean)``: ``W^T W = sigma^2 C^-1`` (mm per unit).
    names : tuple of str, optional
        The names of the whole parameter vector it was made for (a model file's table), checked against
        the fit's; None: not checked.
    source : str, optional
        Where it came from (a model file's path), for the run's resolved config.
    """

    index: NDArray[np.intp]
    mean: NDArray[np.float64]
    root: NDArray[np.float64]
    names: tuple[str, ...] | None = None
    source: str | None = None

    @property
    def size(self) -> int:
        """The number of prior rows."""
        return int(self.root.shape[0])

    @classmethod
    def from_std(cls, index, mean, std, noise_mm: float) -> "Prior":
        """Independent parameters of standard deviations ``std`` (k,) under measurement noise ``noise_mm``.

        >>> Prior.from_std([1], [0.5], [2.0], 0.1).rows(np.array([0.0, 4.5])).tolist()
        [0.2]
        """
        std = np.asarray(std, dtype=float)
        if not (np.all(np.isfinite(std)) and np.all(std > 0) and noise_mm >= 0):
            raise DataError(f"a prior needs standard deviations > 0 and a noise >= 0; got {std!r}, {noise_mm!r}")
        return cls(np.asarray(index, dtype=np.intp), np.asarray(mean, dtype=float), np.diag(noise_mm / std))

    @classmethod
    def from_covariance(cls, index, mean, covariance, noise_mm: float) -> "Prior":
        """Parameters of covariance ``covariance`` (k, k) under measurement noise ``noise_mm``."""
        cov = np.asarray(covariance, dtype=float)
        k = len(np.atleast_1d(index))
        if cov.shape != (k, k) or not np.all(np.isfinite(cov)):
            raise DataError(f"a prior covariance must be a finite ({k}, {k}) matrix; got shape {cov.shape}")
        cov = (cov + cov.T) / 2.0
        eig, vec = np.linalg.eigh(cov)
        if eig.size and eig[-1] <= 0:
            raise DataError("a prior covariance must be positive definite; got one with no positive eigenvalue")
        eig = np.maximum(eig, EIGEN_FLOOR * (eig[-1] if eig.size else 1.0))
        return cls(np.asarray(index, dtype=np.intp), np.asarray(mean, dtype=float),
                   noise_mm * (vec / np.sqrt(eig)).T)

    def rows(self, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """The prior rows ``W (v[index] - mean)``, shape (k,), mm."""
        return self.root @ (values[self.index] - self.mean)

    def jacobian(self, n_values: int) -> NDArray[np.float64]:
        """The rows' Jacobian over the whole parameter vector, shape (k, n_values)."""
        jac = np.zeros((self.size, n_values))
        jac[:, self.index] = self.root
        return jac

    def augmented(self, jac_at):
        """``jac_at`` (values, jacobian=True) -> (residuals, Jacobian or None) with the prior rows appended."""
        def with_rows(values, jacobian=True):
            resid, jac = jac_at(values, jacobian=jacobian)
            resid = np.concatenate([resid, self.rows(values)])
            return resid, None if jac is None else np.vstack([jac, self.jacobian(values.size)])
        return with_rows

    def check_names(self, names: list[str]) -> None:
        """Refuse a fit whose parameters (``names``, table order) are not those the prior was made for."""
        if self.names is not None and tuple(self.names) != tuple(names):
            raise DataError(f"the prior was made for the parameters {', '.join(self.names)}; this fit has "
                            f"{', '.join(names)} (another parametrization, compliance or joint harmonics)")
        if self.index.size and int(self.index.max()) >= len(names):
            raise DataError(f"the prior holds parameter {int(self.index.max())}; this fit has {len(names)}")

    def held(self, n_values: int) -> NDArray[np.bool_]:
        """Which of ``n_values`` parameters the prior holds, shape (n_values,)."""
        mask = np.zeros(n_values, dtype=bool)
        mask[self.index] = True
        return mask


STRENGTH_GRID = tuple(round(0.1 * 10 ** (k / 4), 3) for k in range(11))
"""``prior_strength: auto``: 0.1 to 31.6, four to a decade (0.1, 0.178, 0.316, 0.562, 1, 1.778, ...)."""


def strength_problem(value) -> str | None:
    """What a ``prior_strength`` must be (a number >= 0, ``auto``, or a non-empty list of numbers to choose
    from, each once), or None; a bad item of a list is named.

    >>> strength_problem([0.3, 1, 3]) is None, strength_problem("auto") is None, strength_problem(-1)
    (True, True, 'a number >= 0, auto, or a non-empty list of numbers >= 0')
    >>> strength_problem([1, -1]), strength_problem([1, 3, 1])
    ('a non-empty list of numbers >= 0 (item 2 is -1)', 'a list of different numbers (item 3 repeats 1)')
    """
    def number(v) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and bool(np.isfinite(v)) and v >= 0

    if isinstance(value, str) and value == "auto":
        return None
    if not isinstance(value, (list, tuple)):
        return None if number(value) else "a number >= 0, auto, or a non-empty list of numbers >= 0"
    if not value:
        return "a number >= 0, auto, or a non-empty list of numbers >= 0"
    for k, v in enumerate(value, 1):
        if not number(v):
            return f"a non-empty list of numbers >= 0 (item {k} is {v!r})"
        if v in value[:k - 1]:
            return f"a list of different numbers (item {k} repeats {v!r})"
    return None


def strengths_of(value) -> tuple[float, ...]:
    """The strengths a ``prior_strength`` names: ``auto`` the grid :data:`STRENGTH_GRID`, a list its numbers
    (sorted, each once), a number itself.

    >>> strengths_of([3, 1, 3]), strengths_of(0.5), len(strengths_of("auto"))
    ((1.0, 3.0), (0.5,), 11)
    """
    if isinstance(value, str):
        return STRENGTH_GRID
    if isinstance(value, (list, tuple)):
        return tuple(sorted({float(v) for v in value}))
    return (float(value),)


def strongest_within(strengths, scores, errors) -> int:
    """The index of the strongest prior whose CV score is within one standard error of the lowest (the
    one-standard-error rule: a stronger prior is a simpler model, fewer parameters effectively free); the
    lowest score when none is finite enough to compare.

    >>> strongest_within([0.3, 1, 3, 10], [0.4166, 0.4168, 0.4240, 0.4652], [0.0096, 0.0097, 0.0097, 0.0101])
    2
    """
    within = within_one_standard_error(scores, errors)
    if not within:
        return int(np.nanargmin(scores)) if np.isfinite(scores).any() else 0
    return max(within, key=lambda i: (strengths[i], -i))


def strength_rows(strengths, scores, errors, score: str = "cv_rms_3d") -> tuple[int, list[dict]]:
    """The strength :func:`strongest_within` chooses, and a row per strength as runs and fits report them:
    ``prior_strength``, the CV figure under ``score``, its standard error ``cv_se``, ``chosen``.

    >>> strength_rows([1, 3], [0.41, 0.415], [0.01, 0.01])[1][1]
    {'prior_strength': 3.0, 'cv_rms_3d': 0.415, 'cv_se': 0.01, 'chosen': True}
    """
    best = strongest_within(list(strengths), scores, errors)
    return best, [{"prior_strength": float(s), score: float(r), "cv_se": float(e), "chosen": k == best}
                  for k, (s, r, e) in enumerate(zip(strengths, scores, errors))]


def strength_note(table: list[dict], chosen_by: str, score: str = "cv_rms_3d", label: str = "CV 3-D RMS") -> str:
    """What a fit or a run says of the prior strength ``chosen_by`` chose (``table``: :func:`strength_rows`;
    ``score`` and ``label`` name its CV figure), and whether the lowest score lies at the weakest strength tried.

    >>> table = strength_rows([0.3, 1, 3], [0.412, 0.41, 0.415], [0.01, 0.01, 0.01])[1]
    >>> print(strength_note(table, "the run's cross-validation"))  # doctest: +NORMALIZE_WHITESPACE
    prior strength 3 chosen by the run's cross-validation, the strongest within one standard error of the
    lowest (CV 3-D RMS: 0.3: 0.4120 +- 0.0100, 1: 0.4100 +- 0.0100, 3: 0.4150 +- 0.0100)
    >>> strength_note(table[1:], "5-block CV").endswith("the lowest is at the weakest strength tried: weaker ones, "
    ...                                                 "not tried, may do better")
    True
    """
    chosen = next(row["prior_strength"] for row in table if row["chosen"])
    lowest = min(range(len(table)), key=lambda k: table[k][score])
    weakest = min(range(len(table)), key=lambda k: table[k]["prior_strength"])
    return (f"prior strength {chosen:g} chosen by {chosen_by}, the strongest within one standard error of the "
            f"lowest ({label}: " + ", ".join(f"{row['prior_strength']:g}: {row[score]:.4f} +- {row['cv_se']:.4f}"
                                              for row in table) + ")"
            + ("; the lowest is at the weakest strength tried: weaker ones, not tried, may do better"
               if lowest == weakest and len(table) > 1 and table[weakest]["prior_strength"] > 0 else ""))


def plausible_prior(units: list[str], n_rows: int, nominal: NDArray[np.float64], strength: float,
                    plausible: dict[str, float]) -> Prior | None:
    """The datasheet-like prior: each of the first ``n_rows`` parameters (the DH or complete rows' ones) of
    unit ``mm`` or ``deg`` at its ``nominal`` value with its plausible error (``plausible``: per unit) as the
    standard deviation, rows weighted by ``strength`` (mm: one plausible error off costs as much as a residual
    of ``strength`` mm in one coordinate). None when ``strength`` is 0 (no prior)."""
    if strength == 0:
        return None
    index = [k for k in range(n_rows) if units[k] in plausible]
    return Prior.from_std(index, nominal[index], [plausible[units[k]] for k in index], strength)
