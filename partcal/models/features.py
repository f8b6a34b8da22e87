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
Polynomial features are filled by ``polynomials.Monomials``; a fitted series
is compiled into a :class:`SeriesPlan` for fast prediction.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from math import comb

import numpy as np
from numpy.typing import NDArray

from .polynomials import Monomials, coef_centred, monomials


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
    return _varying(*column_bounds(X))


def column_bounds(X: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Smallest and largest value of every column of ``X`` (n, d), each shape (d,).

    Reduced along contiguous rows of ``X.T``: reducing a C-ordered (n, 3) array
    along axis 0 runs an inner loop of length 3 per row, about 10 times slower.
    """
    columns = np.ascontiguousarray(X.T)
    return columns.min(axis=1), columns.max(axis=1)


def _varying(lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
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
    def fit(cls, X: NDArray[np.float64], bounds=None) -> "Scaling":
        """From training inputs ``X`` (n, d), or from their :func:`column_bounds` if given."""
        lo, hi = column_bounds(X) if bounds is None else bounds
        half = (hi - lo) / 2.0
        active = _varying(lo, hi)
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
        if self.kind == "fourier":
            out = np.empty((X.shape[0], len(terms)))
            phi = self.angles(X, scaling)
            for t, (trig, i, q) in enumerate(terms):
                out[:, t] = 1.0 if trig == "1" else (np.cos if trig == "cos" else np.sin)(q * phi[:, i])
            return out
        mono = monomials(terms)
        M = np.empty((mono.n_rows, X.shape[0]))
        M[0] = 1.0
        used, u = mono.columns, M[1:1 + mono.columns.size]
        np.subtract(X.T[used], scaling.centre[used, None], out=u)           # u = (x - centre) / scale
        u /= scaling.scale[used, None]
        mono.fill(M)
        return np.ascontiguousarray(M[mono.rows(terms)].T)


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



# ---------------------------------------------------------------------- fast evaluation
_CHUNK_BYTES = 1 << 19      # the feature rows of one chunk: 512 KiB, stays in a core's L2 cache


@dataclass(frozen=True, eq=False)
class SeriesPlan:
    """A fitted series compiled for fast evaluation: ``evaluate(X)`` equals ``transform(X) @ coef``.

    The prediction is evaluated in chunks of rows that stay in cache, never
    forming the ``(n, n_terms)`` feature matrix, so memory stays bounded
    whatever ``n``. Each chunk holds the ``(n_rows, chunk)`` table ``M`` of
    row 0 = 1, rows ``1..k`` = the used inputs, then the higher features, and
    the result is one small product ``M.T @ coef_rows``.

    - Polynomials are evaluated in raw units (mm or degrees) about the centre of
      the training data, ``v = x - centre``, with coefficients ``c / scale^a``
      (:func:`coef_centred`): the same polynomial as the
      scaled basis without the division, and without the lost digits of
      monomials about the origin (``x^8`` with ``x`` near 2000 mm). The
      monomials are filled by :class:`Monomials`, runs of rows in one numpy call.
    - Fourier series evaluate ``cos`` and ``sin`` once per input and the higher
      harmonics by the angle-addition recurrence.

    Attributes
    ----------
    kind : {"polynomial", "fourier"}
    columns : ndarray of int, shape (k,)
        The input columns the series uses.
    shift, gain : ndarray, shape (k,)
        Row ``1 + j`` is ``(x[:, columns[j]] - shift[j]) * gain[j]`` (gain 1 for polynomials).
    monomials : Monomials or None
        Polynomials: how the higher rows are computed from the inputs.
    harmonics : int
        Fourier: the highest harmonic.
    coef : ndarray, shape (n_rows, n_outputs)
    chunk : int
        Rows of ``X`` evaluated at a time.
    """

    kind: str
    columns: NDArray[np.intp]
    shift: NDArray[np.float64]
    gain: NDArray[np.float64]
    monomials: Monomials | None
    harmonics: int
    coef: NDArray[np.float64]
    chunk: int

    @classmethod
    def build(cls, basis: Basis, scaling: Scaling, terms: list[tuple], coef: NDArray[np.float64]) -> "SeriesPlan":
        """Compile ``basis`` with ``terms`` and coefficients ``coef`` (n_terms, n_outputs)."""
        coef = np.asarray(coef, dtype=float)
        if basis.kind == "fourier":
            return cls._fourier(basis, scaling, terms, coef)
        return cls._polynomial(scaling, terms, coef)

    @classmethod
    def _polynomial(cls, scaling: Scaling, terms: list[tuple], coef) -> "SeriesPlan":
        mono = monomials(terms)
        distinct, centred = coef_centred(terms, coef, scaling.scale)
        table = np.zeros((mono.n_rows, coef.shape[1]))
        table[mono.rows(distinct)] = centred
        k = mono.columns.size
        return cls("polynomial", mono.columns, scaling.centre[mono.columns].astype(float), np.ones(k),
                   mono, 0, table, _chunk_rows(mono.n_rows))

    @classmethod
    def _fourier(cls, basis: Basis, scaling: Scaling, terms: list[tuple], coef) -> "SeriesPlan":
        columns = np.array(sorted({i for trig, i, _ in terms if trig != "1"}), dtype=np.intp)
        k, top = columns.size, max([q for trig, _, q in terms if trig != "1"], default=0)
        place = {int(i): j for j, i in enumerate(columns)}
        table = np.zeros((1 + 2 * k * top, coef.shape[1]))
        for (trig, i, q), c in zip(terms, coef):     # rows: 1 | cos h=1 | sin h=1 | cos h=2 | ...
            row = 0 if trig == "1" else 1 + 2 * k * (q - 1) + (k if trig == "sin" else 0) + place[i]
            table[row] += c
        if basis.inputs == "joint":
            shift, gain = np.zeros(k), np.full(k, np.pi / 180.0)
        else:
            shift, gain = scaling.centre[columns].astype(float), (np.pi / 2.0) / scaling.scale[columns]
        return cls("fourier", columns, shift, gain, None, top, table, _chunk_rows(table.shape[0]))

    def evaluate(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """The series at inputs ``X`` (n, d) in contract units: shape (n, n_outputs)."""
        n, k = X.shape[0], self.columns.size
        out = np.empty((n, self.coef.shape[1]))
        M = np.empty((self.coef.shape[0], min(self.chunk, max(n, 1))))
        M[0] = 1.0
        runs = _runs(self.columns)                    # consecutive used columns: one strided subtraction each
        shifts = [self.shift[row - 1:row - 1 + count, None] for _, count, row in runs]
        products = self.monomials.views(M) if self.monomials is not None else None    # views of whole chunks
        for start in range(0, n, M.shape[1]):
            m = min(M.shape[1], n - start)
            rows = M[:, :m]
            xs = X[start:start + m].T
            for (first, count, row), shift in zip(runs, shifts):
                np.subtract(xs[first:first + count], shift, out=rows[row:row + count])
            if self.kind == "fourier":
                self._harmonics(rows, k)
            else:
                self.monomials.fill(rows, products if m == M.shape[1] else None)
            np.matmul(rows.T, self.coef, out=out[start:start + m])
        return out

    def _harmonics(self, rows: NDArray[np.float64], k: int) -> None:
        """Fill ``cos(h phi)``, ``sin(h phi)`` for h = 1..harmonics from the shifted inputs in ``rows[1:k+1]``."""
        # cos and sin from t = tan(phi / 2): cos = (1 - t^2) / (1 + t^2), sin = 2 t / (1 + t^2).
        # numpy vectorises tan for float64 but not sin and cos: this is about 5 times faster.
        cos1, sin1 = rows[1:1 + k], rows[1 + k:1 + 2 * k]
        cos1 *= 0.5 * self.gain[:, None]
        np.tan(cos1, out=sin1)                      # t
        tmp = np.multiply(sin1, sin1)               # t^2
        np.subtract(1.0, tmp, out=cos1)
        tmp += 1.0
        np.divide(1.0, tmp, out=tmp)
        cos1 *= tmp
        sin1 *= tmp
        sin1 *= 2.0
        for h in range(2, self.harmonics + 1):      # cos(a + b), sin(a + b) with a = (h - 1) phi, b = phi
            top = 1 + 2 * k * (h - 1)
            c_prev, s_prev = rows[top - 2 * k:top - k], rows[top - k:top]
            c_new, s_new = rows[top:top + k], rows[top + k:top + 2 * k]
            np.multiply(c_prev, cos1, out=c_new)
            np.multiply(s_prev, sin1, out=tmp)
            c_new -= tmp
            np.multiply(s_prev, cos1, out=s_new)
            np.multiply(c_prev, sin1, out=tmp)
            s_new += tmp


def _runs(columns: NDArray[np.intp]) -> list[tuple[int, int, int]]:
    """Runs of consecutive columns as ``(first column, count, first row)``, rows from 1.

    >>> _runs(np.array([0, 1, 2, 5]))
    [(0, 3, 1), (5, 1, 4)]
    """
    runs: list[tuple[int, int, int]] = []
    for row, c in enumerate(columns, start=1):
        if runs and runs[-1][0] + runs[-1][1] == c:
            runs[-1] = (runs[-1][0], runs[-1][1] + 1, runs[-1][2])
        else:
            runs.append((int(c), 1, row))
    return runs


def _chunk_rows(n_rows: int) -> int:
    """Rows of ``X`` per chunk so that the chunk's feature table fills about ``_CHUNK_BYTES``."""
    return int(min(16384, max(512, 2 ** int(np.log2(max(_CHUNK_BYTES // (8 * n_rows), 1))))))
