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
      the training data, ``v = x - centre``, with coefficients ``c / scale^a``:
      the same polynomial as the scaled basis without the division, and without
      the lost digits of monomials about the origin (``x^8`` with ``x`` near
      2000 mm). Each monomial is one product of a lower one and an input row
      (precomputed powers), and runs of them are one numpy call.
    - Fourier series evaluate ``cos`` and ``sin`` once per input and the higher
      harmonics by the angle-addition recurrence.

    Attributes
    ----------
    kind : {"polynomial", "fourier"}
    columns : ndarray of int, shape (k,)
        The input columns the series uses.
    shift, gain : ndarray, shape (k,)
        Row ``1 + j`` is ``(x[:, columns[j]] - shift[j]) * gain[j]`` (gain 1 for polynomials).
    products : tuple of (dest, length, left, right, right_step)
        Polynomial rows ``M[dest:dest+length] = M[left:left+length] * M[right + right_step * i]``.
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
    products: tuple
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
        columns = np.array(sorted({i for exps in terms for i, a in enumerate(exps) if a}), dtype=np.intp)
        k = columns.size
        wanted = {tuple(int(exps[i]) for i in columns) for exps in terms}
        higher = set()                     # every monomial of degree >= 2 needed, with its parents
        for exps in wanted:
            while sum(exps) >= 2 and exps not in higher:
                higher.add(exps)
                j = next(i for i, a in enumerate(exps) if a)
                exps = tuple(a - (i == j) for i, a in enumerate(exps))
        rows = {(0,) * k: 0} | {tuple(int(j == i) for j in range(k)): 1 + i for i in range(k)}
        ops = []
        for degree in range(2, max((sum(e) for e in higher), default=1) + 1):
            # a monomial is its lowest input times a parent; sorted by (input, parent row), the
            # parents and inputs of consecutive rows advance in steps of one (or the input stays)
            level = []
            for exps in higher:
                if sum(exps) == degree:
                    j = next(i for i, a in enumerate(exps) if a)
                    parent = tuple(a - (i == j) for i, a in enumerate(exps))
                    level.append((j, rows[parent], exps))
            for j, parent_row, exps in sorted(level):
                rows[exps] = len(rows)
                ops.append((rows[exps], parent_row, 1 + j))
        table = np.zeros((len(rows), coef.shape[1]))
        for exps, c in zip(terms, coef):
            a = tuple(int(exps[i]) for i in columns)
            table[rows[a]] += c / np.prod(scaling.scale[columns] ** np.array(a, dtype=float))
        return cls("polynomial", columns, scaling.centre[columns].astype(float), np.ones(k),
                   _merge_runs(ops), 0, table, _chunk_rows(len(rows)))

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
        return cls("fourier", columns, shift, gain, (), top, table, _chunk_rows(table.shape[0]))

    def evaluate(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """The series at inputs ``X`` (n, d) in contract units: shape (n, n_outputs)."""
        n, k = X.shape[0], self.columns.size
        out = np.empty((n, self.coef.shape[1]))
        M = np.empty((self.coef.shape[0], min(self.chunk, max(n, 1))))
        M[0] = 1.0
        runs = _runs(self.columns)                    # consecutive used columns: one strided subtraction each
        for start in range(0, n, M.shape[1]):
            m = min(M.shape[1], n - start)
            rows = M[:, :m]
            xs = X[start:start + m].T
            for first, count, row in runs:
                np.subtract(xs[first:first + count], self.shift[row - 1:row - 1 + count, None],
                            out=rows[row:row + count])
            if self.kind == "fourier":
                self._harmonics(rows, k)
            else:
                for dest, length, left, right, step in self.products:
                    np.multiply(rows[left:left + length], rows[right:right + length] if step else rows[right],
                                out=rows[dest:dest + length])
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


def _merge_runs(ops: list[tuple[int, int, int]]) -> tuple:
    """Join products ``(dest, left, right)`` whose rows advance together into ``(dest, n, left, right, step)``.

    >>> _merge_runs([(4, 1, 1), (5, 2, 2), (6, 3, 3), (7, 4, 1), (8, 5, 1)])
    ((4, 3, 1, 1, 1), (7, 2, 4, 1, 0))
    """
    runs: list[list[int]] = []
    for dest, left, right in ops:
        if runs:
            d0, n, l0, r0, step = runs[-1]
            if n == 1 and (dest, left) == (d0 + 1, l0 + 1) and right - r0 in (0, 1):
                runs[-1] = [d0, 2, l0, r0, right - r0]
                continue
            if n > 1 and (dest, left, right) == (d0 + n, l0 + n, r0 + step * n):
                runs[-1][1] += 1
                continue
        runs.append([dest, 1, left, right, 1])
    return tuple(tuple(run) for run in runs)


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
