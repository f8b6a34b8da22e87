"""Polynomials as arrays of coefficients: the one change of variables and the one monomial evaluator.

A polynomial is a list of terms (exponent tuples, one exponent per input) and
coefficients ``(n_terms, n_outputs)``. Two operations serve every model kind:

* :func:`coef_from_scaled` re-expresses a polynomial in scaled inputs
  ``u = (v - shift) / scale`` as one in ``v``: raw units for printed
  equations, centred inputs for fast prediction (:func:`coef_centred`), a
  lookup cell's frame for blended prediction.
* :class:`Monomials` evaluates monomials as rows of a table, each row the
  product of two earlier ones: fitted feature matrices, fast prediction and
  blended prediction all fill their monomials with it.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass
from math import comb

import numpy as np
from numpy.typing import NDArray


# ---------------------------------------------------------------------- change of variables
def lowered_terms(terms: list[tuple]) -> list[tuple]:
    """The distinct ``terms`` in their order, then the lower monomials they expand into.

    A monomial ``u^e`` in ``u = (v - shift) / scale`` expands into every
    ``v^f`` with ``f <= e`` (per input); a term list closed under lowering
    exponents (both lists of ``features.Basis``) comes back unchanged.

    >>> lowered_terms([(0, 0), (1, 1)])
    [(0, 0), (1, 1), (0, 1), (1, 0)]
    """
    out = list(dict.fromkeys(tuple(int(k) for k in e) for e in terms))
    seen = set(out)
    for e in list(out):
        for f in itertools.product(*(range(k + 1) for k in e)):
            if f not in seen:
                seen.add(f)
                out.append(f)
    return out


@functools.lru_cache(maxsize=64)
def _expansion(terms: tuple) -> tuple:
    """Every pair (term ``e``, lower monomial ``f``) of the binomial expansion, as arrays.

    ``(source term, C(e, f), e - f, e, scatter)``, one entry per pair;
    ``scatter`` (len(lowered_terms), entries) adds the entries into their ``f``.
    """
    index = {f: i for i, f in enumerate(lowered_terms(list(terms)))}
    d = len(terms[0]) if terms else 0
    to, source, binom, rest, exps = [], [], [], [], []
    for j, e in enumerate(terms):
        for f in itertools.product(*(range(k + 1) for k in e)):
            to.append(index[f])
            source.append(j)
            binom.append(float(np.prod([comb(k, i) for k, i in zip(e, f)])))
            rest.append([k - i for k, i in zip(e, f)])
            exps.append(e)
    scatter = np.zeros((len(index), len(to)))
    scatter[to, np.arange(len(to))] = 1.0
    return (np.array(source, dtype=np.intp), np.array(binom), np.array(rest, dtype=float).reshape(-1, d),
            np.array(exps, dtype=float).reshape(-1, d), scatter)


def expansion_size(terms: list[tuple]) -> int:
    """Number of (term, lower monomial) pairs that :func:`coef_from_scaled` computes for ``terms``."""
    return int(_expansion(tuple(map(tuple, terms)))[0].size)


def coef_from_scaled(terms: list[tuple], coef: NDArray[np.float64], scale: NDArray[np.float64],
                     shift: NDArray[np.float64]) -> NDArray[np.float64]:
    """Coefficients in ``v`` of a polynomial in the scaled inputs ``u = (v - shift) / scale``.

    The one change of variables for polynomials: ``sum_t coef_t prod_i
    u_i^e_ti`` is expanded binomially, ``u^e = sum_{f <= e} C(e, f) v^f
    (-shift)^(e - f) / scale^e``, into coefficients of :func:`lowered_terms`
    of ``terms``. With ``(scale, shift)`` the model's ``features.Scaling``,
    ``v`` is the raw input (mm, degrees); with ``shift = 0``, the centred
    input ``x - centre``; with a lookup cell's frame ``v = (x - o) / h``,
    ``scale = s / h`` and ``shift = (m - o) / h``.

    Parameters
    ----------
    terms : list of exponent tuples (length d)
    coef : ndarray, shape (n_terms, n_outputs), or (P, n_terms, n_outputs) for P problems
    scale, shift : ndarray, shape (d,), or (P, d)

    Returns
    -------
    ndarray, shape (len(lowered_terms(terms)), n_outputs), or (P, ..., n_outputs)

    >>> coef_from_scaled([(0,), (1,), (2,)], np.array([[1.0], [2.0], [4.0]]), np.array([2.0]), np.array([10.0])
    ...                  ).ravel().tolist()         # 1 + 2u + 4u², u = (x - 10)/2
    [91.0, -19.0, 1.0]
    """
    source, binom, rest, exps, scatter = _expansion(tuple(map(tuple, terms)))
    coef = np.asarray(coef, dtype=float)
    single = coef.ndim == 2
    if single:
        coef, scale, shift = coef[None], np.asarray(scale)[None], np.asarray(shift)[None]
    num = np.broadcast_to(binom, (coef.shape[0], binom.size)).copy()
    den = np.ones_like(num)
    for i in range(exps.shape[1]):
        num *= np.power(-shift[:, i, None], rest[:, i])
        den *= np.power(scale[:, i, None], exps[:, i])
    out = scatter @ (coef[:, source, :] * num[:, :, None] / den[:, :, None])
    return out[0] if single else out


def coef_centred(terms: list[tuple], coef: NDArray[np.float64], scale: NDArray[np.float64]
                 ) -> tuple[list[tuple], NDArray[np.float64]]:
    """The distinct ``terms`` and their coefficients ``(n_distinct, n_outputs)`` in ``x - centre``.

    :func:`coef_from_scaled` without shift: each monomial maps onto itself
    alone (``c / scale^e``), so the lower monomials get nothing.
    """
    distinct = list(dict.fromkeys(tuple(int(k) for k in e) for e in terms))
    return distinct, coef_from_scaled(terms, coef, scale, np.zeros_like(scale))[:len(distinct)]


# ---------------------------------------------------------------------- monomials
@dataclass(frozen=True, eq=False)
class Monomials:
    """The one monomial evaluator: monomials of some inputs as the rows of a table ``M`` (n_rows, m).

    Row 0 is 1 and rows ``1..k`` hold the inputs ``columns`` (the caller
    writes them: scaled, centred or in a cell's frame); :meth:`fill` computes
    every further row as the product of two earlier ones. A power of one
    input is ``u^k = u^(k-1) * u``; a monomial of several inputs is the
    monomial of all but its last input times the power of that input,
    ``u1^2 u3 = (u1^2) * u3``. That is the order in which the fitted feature
    matrices have always been computed, so they keep their last bit. Rows of
    one degree whose operands advance together are one numpy call.

    Build with :func:`monomials`, which caches one per term list.

    Attributes
    ----------
    columns : ndarray of int, shape (k,)
        The inputs used (indices into the exponent tuples).
    row_of : dict
        Exponent tuple (length d) -> row; holds every term and every intermediate.
    n_rows : int
    runs : tuple of (out, left, right)
        Row indices (int or slice): ``M[out] = M[left] * M[right]``, in order.
    """

    columns: NDArray[np.intp]
    row_of: dict
    n_rows: int
    runs: tuple

    def rows(self, terms: list[tuple]) -> list[int]:
        """The rows of ``terms``."""
        return [self.row_of[tuple(e)] for e in terms]

    def fill(self, M: NDArray[np.float64], views: list | None = None) -> None:
        """Compute rows ``1 + k ..`` of ``M`` (n_rows, m) in place from rows 0 (ones) and ``1..k`` (inputs).

        ``views``: ``self.views(M)``, when ``M`` is filled again and again (saves making them each time).
        """
        for out, left, right in self.views(M) if views is None else views:
            np.multiply(left, right, out=out)

    def views(self, M: NDArray[np.float64]) -> list[tuple]:
        """The operands of every run as views of ``M``: ``(out, left, right)``."""
        return [(M[out], M[left], M[right]) for out, left, right in self.runs]


@functools.lru_cache(maxsize=64)
def _monomials(terms: tuple) -> Monomials:
    d = len(terms[0]) if terms else 0
    columns = sorted({i for e in terms for i, a in enumerate(e) if a})
    unit = [tuple(int(j == i) for j in range(d)) for i in columns]
    row_of = {(0,) * d: 0} | {e: 1 + j for j, e in enumerate(unit)}
    needed: dict[tuple, tuple] = {}          # monomial -> its two factors
    todo = [e for e in terms if sum(e) >= 2]
    while todo:
        e = todo.pop()
        if e not in needed and e not in row_of:
            needed[e] = _factors(e)
            todo.extend(f for f in needed[e] if sum(f) >= 2)
    runs = []
    for degree in range(2, max((sum(e) for e in needed), default=1) + 1):
        level = {(row_of[a], row_of[b]): e for e, (a, b) in needed.items() if sum(e) == degree}
        for left, ls, right, rs, n in _longest_runs(set(level)):
            runs.append((len(row_of), n, left, ls, right, rs))
            for i in range(n):
                pair = (left + ls * i, right + rs * i)
                row_of[level[pair] if pair in level else level[pair[::-1]]] = len(row_of)
    return Monomials(np.array(columns, dtype=np.intp), row_of, len(row_of), tuple(_indices(r) for r in runs))


def monomials(terms: list[tuple]) -> Monomials:
    """The compiled :class:`Monomials` of polynomial ``terms`` (exponent tuples), cached.

    >>> mono = monomials([(0, 0), (1, 0), (2, 0), (1, 1)])          # 1, u1, u1², u1 u2
    >>> M = np.array([[1.0], [3.0], [5.0], [0.0], [0.0]])           # rows 1, 2: u1 = 3, u2 = 5
    >>> mono.fill(M)
    >>> M[mono.rows([(2, 0), (1, 1)]), 0].tolist()
    [9.0, 15.0]
    """
    return _monomials(tuple(map(tuple, terms)))


def _factors(e: tuple) -> tuple[tuple, tuple]:
    """The two lower monomials whose product is ``e`` (degree >= 2): see :class:`Monomials`."""
    used = [i for i, k in enumerate(e) if k]
    last = used[-1]
    if len(used) == 1:
        return tuple(k - (i == last) for i, k in enumerate(e)), tuple(int(i == last) for i in range(len(e)))
    return tuple(0 if i == last else k for i, k in enumerate(e)), tuple(k if i == last else 0 for i, k in enumerate(e))


def _longest_runs(products: set[tuple[int, int]]) -> list[tuple[int, int, int, int, int]]:
    """Cover products ``(a, b)`` (rows ``M[a] * M[b]``) with few runs, the longest first.

    A run ``(left, left_step, right, right_step, n)`` is the ``n`` products
    ``M[left + left_step * i] * M[right + right_step * i]`` (steps >= 0, the
    operands of a product in either order): one numpy call.

    >>> _longest_runs({(1, 1), (2, 2), (3, 3), (1, 4), (1, 5)})
    [(1, 1, 1, 1, 3), (1, 0, 4, 1, 2)]
    """
    left = set(products)
    out = []
    while left:
        have = left | {(b, a) for a, b in left}
        rights: dict[int, list[int]] = {}
        for a, b in sorted(have):
            rights.setdefault(a, []).append(b)
        best = (1, min(left), (0, 0))
        for a, bs in rights.items():       # steps tried: the same left with the next right, and (1, 1)
            for j, b in enumerate(bs):
                for steps in ([(0, bs[j + 1] - b)] if j + 1 < len(bs) else []) + [(1, 1)]:
                    n = 1
                    while (a + steps[0] * n, b + steps[1] * n) in have:
                        n += 1
                    if n > best[0]:
                        best = (n, (a, b), steps)
        n, (a, b), (ls, rs) = best
        out.append((a, ls, b, rs, n))
        for i in range(n):
            pair = (a + ls * i, b + rs * i)
            left.discard(pair)
            left.discard(pair[::-1])
    return out


def _indices(run: tuple) -> tuple:
    """``(out, left, right)`` row indices of a run: ints for one row or a fixed operand, else slices."""
    out, n, left, ls, right, rs = run
    if n == 1:
        return out, left, right
    side = [x if s == 0 else slice(x, x + s * (n - 1) + 1, s) for x, s in ((left, ls), (right, rs))]
    return (slice(out, out + n), *side)
