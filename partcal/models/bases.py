"""Feature maps: ordinary polynomials (with or without cross terms) and Fourier polynomials.

Inputs are joint angles in degrees (``kind="joint"``) or Cartesian positions in
mm (``kind="cartesian"``). Inside, each input is centred and scaled from the
training data: polynomials use ``u = (x - centre) / half_range`` so that x and
x² are not nearly collinear; Fourier terms use the joint angle in radians (a
joint is periodic) or ``pi/2 * u`` for a position (the data span half a
period). Inputs that are constant in the training data carry no information
and are left out (the paper's q4 = q5 = 0).

Terms follow the paper: ``1, u1, u1², ..., u2, ...`` (eq. 7) and
``1, cos(phi_i), sin(phi_i), ..., cos(r phi_i), sin(r phi_i)`` (eq. 5).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from math import comb

import numpy as np
from numpy.typing import NDArray


def varying_inputs(X: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which columns of ``X`` (n, d) vary: the one rule for "this input is constant", shape (d,).

    A column varies when its range exceeds ``1e-12`` of its magnitude (or of 1
    for values near zero), so a joint held at -90 or 30 degrees is as constant
    as one held at 0. Constant inputs carry no information: bases leave them
    out, partitions do not split or blend along them, and compensation holds
    those joints where the training data had them.

    >>> varying_inputs(np.array([[0.0, 30.0, 1.0], [5.0, 30.0, 1.0 + 1e-15]])).tolist()
    [True, False, False]
    """
    lo, hi = X.min(axis=0), X.max(axis=0)
    return (hi - lo) > 1e-12 * np.maximum(1.0, np.maximum(np.abs(lo), np.abs(hi)))


@dataclass(frozen=True)
class Scaling:
    """Per-input centring and scaling learnt from training data.

    ``active`` marks the inputs that vary in the data; the others are ignored.
    """

    centre: NDArray[np.float64]
    scale: NDArray[np.float64]
    active: NDArray[np.bool_]

    @classmethod
    def fit(cls, X: NDArray[np.float64]) -> "Scaling":
        lo, hi = X.min(axis=0), X.max(axis=0)
        half = (hi - lo) / 2.0
        active = varying_inputs(X)
        return cls(centre=(hi + lo) / 2.0, scale=np.where(active, half, 1.0), active=active)

    def to_dict(self) -> dict:
        return {"centre": self.centre.tolist(), "scale": self.scale.tolist(), "active": self.active.tolist()}


@dataclass(frozen=True)
class Basis:
    """A feature map. ``kind``: ``polynomial`` or ``fourier``; ``inputs``: ``joint`` or ``cartesian``.

    ``order`` is the polynomial degree or the number of harmonics.
    """

    kind: str
    inputs: str
    order: int
    cross_terms: bool = False

    def terms(self, scaling: Scaling) -> list[tuple]:
        """The terms, as exponent tuples (polynomial) or ``(trig, input, harmonic)`` (Fourier)."""
        active = np.flatnonzero(scaling.active)
        d = scaling.active.size
        if self.kind == "fourier":
            return [("1", -1, 0)] + [(trig, int(i), q) for q in range(1, self.order + 1)
                                     for i in active for trig in ("cos", "sin")]
        if self.cross_terms:
            out = []
            for total in range(self.order + 1):
                for combo in itertools.combinations_with_replacement(active, total):
                    exps = [0] * d
                    for i in combo:
                        exps[i] += 1
                    out.append(tuple(exps))
            return out
        out = [(0,) * d]
        for i in active:
            for k in range(1, self.order + 1):
                exps = [0] * d
                exps[i] = k
                out.append(tuple(exps))
        return out

    def n_terms(self, n_active: int) -> int:
        """Number of terms per output for ``n_active`` varying inputs."""
        if self.kind == "fourier":
            return 1 + 2 * self.order * n_active
        if self.cross_terms:
            return comb(n_active + self.order, self.order)
        return 1 + self.order * n_active

    def angles(self, X: NDArray[np.float64], scaling: Scaling) -> NDArray[np.float64]:
        """The Fourier phase of every input, radians."""
        if self.inputs == "joint":
            return np.radians(X)
        return (np.pi / 2.0) * (X - scaling.centre) / scaling.scale

    def transform(self, X: NDArray[np.float64], scaling: Scaling, terms: list[tuple] | None = None
                  ) -> NDArray[np.float64]:
        """Feature matrix, shape ``(n, n_terms)``, for inputs ``(n, d)`` in contract units."""
        terms = self.terms(scaling) if terms is None else terms
        out = np.empty((X.shape[0], len(terms)))
        if self.kind == "fourier":
            phi = self.angles(X, scaling)
            for t, (trig, i, q) in enumerate(terms):
                out[:, t] = 1.0 if trig == "1" else (np.cos if trig == "cos" else np.sin)(q * phi[:, i])
            return out
        u = (X - scaling.centre) / scaling.scale
        powers = [None, u]
        for _ in range(2, self.order + 1):
            powers.append(powers[-1] * u)
        for t, exps in enumerate(terms):
            factors = [(i, k) for i, k in enumerate(exps) if k]
            if not factors:
                out[:, t] = 1.0
                continue
            i, k = factors[0]
            out[:, t] = powers[k][:, i]
            for i, k in factors[1:]:
                out[:, t] *= powers[k][:, i]
        return out


# ---------------------------------------------------------------------- raw-unit equations
def raw_polynomial(terms: list[tuple], coefs: NDArray[np.float64], scaling: Scaling) -> dict[tuple, float]:
    """Re-express a polynomial in scaled inputs as one in raw inputs.

    ``sum_t c_t prod_i ((x_i - m_i) / s_i)^a_ti`` is expanded binomially into
    ``{exponents: coefficient}`` over the raw inputs ``x_i``.

    >>> s = Scaling(np.array([10.0]), np.array([2.0]), np.array([True]))
    >>> raw_polynomial([(0,), (1,), (2,)], np.array([1.0, 2.0, 4.0]), s)   # 1 + 2u + 4u², u = (x-10)/2
    {(0,): 91.0, (1,): -19.0, (2,): 1.0}
    """
    out: dict[tuple, float] = {}
    for exps, c in zip(terms, coefs):
        parts = []   # per input: list of (power, factor) from ((x - m) / s)^a
        for i, a in enumerate(exps):
            m, s = scaling.centre[i], scaling.scale[i]
            parts.append([(j, comb(a, j) * (-m) ** (a - j) / s**a) for j in range(a + 1)])
        for choice in itertools.product(*parts):
            key = tuple(j for j, _ in choice)
            out[key] = float(out.get(key, 0.0) + c * np.prod([f for _, f in choice]))
    return dict(sorted(out.items(), key=lambda kv: (sum(kv[0]), [-k for k in kv[0]])))


# ---------------------------------------------------------------------- common frames
def lift_coefficients(terms_from: list[tuple], coef: NDArray[np.float64], terms_to: list[tuple]
                      ) -> NDArray[np.float64] | None:
    """Coefficients ``(len(terms_to), n_outputs)`` of the same series on a larger term list.

    Terms absent from ``terms_from`` get 0; ``None`` if some term of
    ``terms_from`` is not in ``terms_to``.

    >>> lift_coefficients([(0,), (2,)], np.array([[1.0], [3.0]]), [(0,), (1,), (2,)]).ravel().tolist()
    [1.0, 0.0, 3.0]
    """
    index = {t: i for i, t in enumerate(terms_to)}
    if any(t not in index for t in terms_from):
        return None
    out = np.zeros((len(terms_to), coef.shape[1]))
    out[[index[t] for t in terms_from]] = coef
    return out


class PolynomialReframe:
    """Re-express polynomials in ``u = a v + b`` (per input) as polynomials in ``v``.

    A region's polynomial uses ``u = (x - m) / s`` (its own scaling); a lookup
    cell's frame uses ``v = (x - o) / h``, so ``a = h / s`` and ``b = (o - m) / s``.
    Every monomial ``u^e`` expands binomially into monomials ``v^f`` with
    ``f <= e``; ``terms`` must therefore be closed under lowering exponents
    (both term lists of :class:`Basis` are).

    Parameters
    ----------
    terms : list of exponent tuples (length d)

    >>> rf = PolynomialReframe([(0,), (1,), (2,)])           # 1 + u + u^2 with u = 2v + 1
    >>> rf.apply(np.array([[[1.0], [1.0], [1.0]]]), np.array([[2.0]]), np.array([[1.0]])).ravel().tolist()
    [3.0, 6.0, 4.0]
    """

    def __init__(self, terms: list[tuple]):
        index = {t: i for i, t in enumerate(terms)}
        to, frm, binom, low, rest = [], [], [], [], []
        for j, e in enumerate(terms):
            for f in itertools.product(*(range(k + 1) for k in e)):
                to.append(index[f])
                frm.append(j)
                binom.append(float(np.prod([comb(k, i) for k, i in zip(e, f)])))
                low.append(f)
                rest.append(tuple(k - i for k, i in zip(e, f)))
        self.n_terms, self.n_entries = len(terms), len(to)
        self._from = np.array(frm, dtype=np.intp)
        self._binom = np.array(binom)
        d = len(terms[0]) if terms else 0
        self._low = np.array(low, dtype=float).reshape(-1, d)
        self._rest = np.array(rest, dtype=float).reshape(-1, d)
        self._scatter = np.zeros((len(terms), len(to)))
        self._scatter[to, np.arange(len(to))] = 1.0

    def apply(self, coef: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]
              ) -> NDArray[np.float64]:
        """Coefficients in ``v``, shape ``(P, T, n_outputs)``, from those in ``u`` ``(P, T, n_outputs)``.

        ``a`` and ``b`` have shape ``(P, d)``: one affine change of variable per problem.
        """
        values = np.broadcast_to(self._binom, (a.shape[0], self.n_entries)).copy()
        for i in range(a.shape[1]):
            values *= np.power(a[:, i, None], self._low[:, i]) * np.power(b[:, i, None], self._rest[:, i])
        return self._scatter @ (values[:, :, None] * coef[:, self._from, :])
