"""Blended prediction: weights per block of points, local models combined per block.

:class:`BlendWeights` groups points by lookup cell (``lookup``) and yields,
per block of at most ``MAX_ROWS`` points, the candidate kernels and their
normalised weights (``blending``); points outside the lookup grid come last
and are weighed against every kernel. Two ways then combine the regions'
local models:

* :func:`combine_generic` (the straightforward way, any local model):
  every region with weight in the block predicts its points, and the
  predictions are summed with the weights.
* :class:`FrameCombiner` (polynomial local models, and Fourier ones of joint
  angles): each region's series is re-expressed in the frame of the lookup
  cell (``polynomials.coef_from_scaled``), so a block needs one feature matrix
  ``Phi`` (m, T) and one product ``H = W^T C`` (m, outputs x T) of weights and
  coefficients, instead of one evaluation per region. The frame is the
  cell's own centre and half-size, so the re-expressed coefficients are
  well conditioned. Points outside the grid take the generic way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator

import numpy as np
from numpy.typing import NDArray

from .features import Basis, Scaling, lift_coefficients
from .blending import cell_distance_matrix, cell_features, normalised_weights, sq_distances
from .lookup import BlockPlan
from .partition import Partition
from .polynomials import Monomials, coef_from_scaled, expansion_size, monomials
from .series import ErrorModel

MAX_ROWS = 4096               # points per block: the (kernels, points) arrays stay in cache
MAX_REFRAME_ENTRIES = 4096    # larger term lists (high-degree cross terms) take the generic way


@dataclass(frozen=True)
class Block:
    """Points ``positions`` (a slice of the sorted order) with their kernels and weights ``(K, m)``.

    ``cell`` is the lookup cell, or -1 for points outside the grid; ``frame``
    holds the points' coordinates ``(x - o) / h`` in the cell's frame, shape
    ``(a, m)`` on the varying axes (None outside the grid).
    """

    positions: slice
    kernels: NDArray[np.intp]
    weights: NDArray[np.float64]
    cell: int
    frame: NDArray[np.float64] | None


class BlendWeights:
    """Blocks of points with their blend weights, for one partition (caches per-cell matrices)."""

    def __init__(self, partition: Partition):
        self.partition = partition
        self._cells: dict[int, tuple] = {}         # cell -> (kernels, centre, distance matrix)

    def blocks(self, X: NDArray[np.float64]) -> tuple[BlockPlan, NDArray[np.float64], Iterator[Block]]:
        """``(plan, X_sorted, blocks)``: the points sorted by cell (``plan.order``), and their blocks."""
        p = self.partition
        plan = p.plan(X)
        Xs = np.take(X, plan.order, axis=0)
        return plan, Xs, self._iterate(plan, np.ascontiguousarray(Xs[:, p.active]))

    def prepare(self, cells) -> None:
        """Compute the matrices of every cell in ``cells`` not seen yet (a fitted model: all cells), in batches
        of cells whose kernel lists hold at most a million entries together."""
        lookup = self.partition.lookup
        todo = np.array([c for c in cells if c not in self._cells], dtype=np.intp)
        sizes = lookup.indptr[todo + 1] - lookup.indptr[todo]
        ends = np.cumsum(sizes)
        start = 0
        while start < todo.size:
            stop = max(start + 1, int(np.searchsorted(ends, (ends[start - 1] if start else 0) + 1_000_000)))
            self._prepare_batch(todo[start:stop], sizes[start:stop])
            start = stop

    def _prepare_batch(self, cells: NDArray[np.intp], sizes: NDArray[np.intp]) -> None:
        """``(kernels, centre, distance matrix)`` of each of ``cells``, computed for all of them at once."""
        p, lookup = self.partition, self.partition.lookup
        first = lookup.indptr[cells]
        offsets = np.repeat(first - np.cumsum(sizes) + sizes, sizes) + np.arange(int(sizes.sum()))
        kernels, centres = lookup.kernels[offsets], lookup.centres(cells)
        A = cell_distance_matrix(p.kernel_centres[kernels], p.kernel_inv_sigmas[kernels],
                                 np.repeat(centres, sizes, axis=0), lookup.size / 2)
        bounds = np.concatenate([[0], np.cumsum(sizes)])
        for i, cell in enumerate(cells.tolist()):
            a, b = bounds[i], bounds[i + 1]
            self._cells[cell] = (kernels[a:b], centres[i], A[a:b])

    def _cell(self, cell: int) -> tuple:
        """``(kernels, centre, distance matrix)`` of one lookup cell, kept for the next blocks in it."""
        if cell not in self._cells:
            self.prepare([cell])
        return self._cells[cell]

    def _iterate(self, plan: BlockPlan, Xa) -> Iterator[Block]:
        p, lookup = self.partition, self.partition.lookup
        half = lookup.size / 2
        a_axes = Xa.shape[1]
        for cell, start, stop in zip(plan.cells.tolist(), plan.starts.tolist(), plan.stops.tolist()):
            kernels, centre, A = self._cell(cell)
            for a in range(start, stop, MAX_ROWS):
                b = min(a + MAX_ROWS, stop)
                F = cell_features(Xa[a:b], centre, half)
                yield Block(slice(a, b), kernels, normalised_weights(A @ F), cell, F[a_axes:2 * a_axes])
        n_kernels = p.kernel_centres.shape[0]
        step = max(1, 1_000_000 // n_kernels)
        for a in range(plan.far.start, plan.far.stop, step):       # outside the grid: every kernel
            b = min(a + step, plan.far.stop)
            w = normalised_weights(sq_distances(Xa[a:b], p.kernel_centres, p.kernel_inv_sigmas))
            used = np.flatnonzero(w.any(axis=1))
            yield Block(slice(a, b), used, w[used], -1, None)


def region_weights(kernel_region: NDArray[np.intp], weights: NDArray[np.float64]
                   ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Regions of a block's kernels and their weights ``(R_b, m)``: kernels of one region add up."""
    regions, column = np.unique(kernel_region, return_inverse=True)
    if regions.size == kernel_region.size:
        return kernel_region, weights
    onehot = np.zeros((regions.size, kernel_region.size))
    onehot[column, np.arange(kernel_region.size)] = 1.0
    return regions, onehot @ weights


def combine_generic(models, kernel_region, Xb, kernels, weights, n_outputs: int) -> NDArray[np.float64]:
    """Weighted sum of the predictions of every region with weight in the block, shape (m, outputs)."""
    regions, W = region_weights(kernel_region[kernels], weights)
    out = np.zeros((Xb.shape[0], n_outputs))
    for region, w in zip(regions.tolist(), W):
        keep = np.flatnonzero(w)
        if 2 * keep.size > w.size:        # most rows: evaluate all, cheaper than gathering
            out += w[:, None] * models[region].predict_validated(Xb)
        elif keep.size:
            out[keep] += w[keep, None] * models[region].predict_validated(Xb[keep])
    return out


class FrameCombiner:
    """Local series re-expressed in each lookup cell's frame: one feature matrix per block.

    Build with :meth:`build`, which returns ``None`` when the local models do
    not allow it (not ``ErrorModel`` series, Fourier series of positions, or
    term lists too large); callers then use :func:`combine_generic`.
    """

    def __init__(self, partition: Partition, basis: Basis, terms: list, coefs, centres, scales,
                 mono: Monomials | None):
        self.partition, self.basis, self.terms = partition, basis, terms
        self.coefs, self.centres, self.scales, self.monomials = coefs, centres, scales, mono
        self._cells: dict[int, NDArray[np.float64]] = {}   # cell -> (outputs * T, K) coefficients
        self._per_pair = expansion_size(terms) if mono is not None else 1   # coefficients per (cell, kernel)
        if mono is not None:       # features are the monomials' rows: coefficients in row order
            self._term_of_row = np.argsort(mono.rows(terms))
            self._frame_rows = np.searchsorted(np.flatnonzero(partition.active), mono.columns)

    @classmethod
    def build(cls, partition: Partition, models) -> "FrameCombiner | None":
        if not all(type(m) is ErrorModel and hasattr(m, "coef_") for m in models):
            return None
        basis = models[0].basis_
        if any(m.basis_ != basis or m.coef_.shape[1] != models[0].coef_.shape[1] for m in models):
            return None
        if basis.kind == "fourier" and basis.inputs != "joint":
            return None                   # phases scale with each region's range: no common frame
        d = partition.active.size
        terms = basis.terms(Scaling(np.zeros(d), np.ones(d), partition.active))
        lifted = [lift_coefficients(m.terms_, m.coef_, terms) for m in models]
        if any(c is None for c in lifted):
            return None
        mono = None
        if basis.kind == "polynomial":
            mono = monomials(terms)
            if expansion_size(terms) > MAX_REFRAME_ENTRIES or mono.n_rows != len(terms):
                return None
        return cls(partition, basis, terms, np.stack(lifted), np.stack([m.scaling_.centre for m in models]),
                   np.stack([m.scaling_.scale for m in models]), mono)

    def prepare(self, cells) -> None:
        """Re-express the series of every cell in ``cells`` not seen yet (in batches of cells)."""
        todo = [c for c in cells if c not in self._cells]
        lists = self.partition.lookup
        batch, pairs = [], 0
        for i, c in enumerate(todo):
            batch.append(c)
            pairs += lists.indptr[c + 1] - lists.indptr[c]
            if pairs * self._per_pair > 1_000_000 or i == len(todo) - 1:      # bounded temporaries
                self._prepare_batch(batch)
                batch, pairs = [], 0

    def _prepare_batch(self, cells) -> None:
        p = self.partition
        kernels = [p.lookup.candidates(c) for c in cells]
        counts = [len(k) for k in kernels]
        regions = p.kernel_region[np.concatenate(kernels)]
        coefs = self.coefs[regions]                                  # (P, T, outputs)
        if self.monomials is not None:     # u = (x - m) / s, v = (x - o) / h: u = (v - (m - o) / h) / (s / h)
            d = p.active.size
            centre, half = np.zeros((len(regions), d)), np.ones(d)
            centre[:, p.active] = np.repeat(p.lookup.centres(np.asarray(cells, dtype=np.intp)),
                                            counts, axis=0)
            half[p.active] = p.lookup.size / 2
            coefs = coef_from_scaled(self.terms, coefs, self.scales[regions] / half,
                                     (self.centres[regions] - centre) / half)[:, self._term_of_row]
        flat = coefs.transpose(2, 1, 0).reshape(-1, len(regions))     # (outputs * T, P)
        bounds = np.cumsum([0] + counts)
        for c, a, b in zip(cells, bounds[:-1], bounds[1:]):
            self._cells[c] = np.ascontiguousarray(flat[:, a:b])

    def _features(self, block: Block, Xb) -> NDArray[np.float64]:
        """Features of the block's points in the cell's frame, shape (T, m) (monomials in row order)."""
        if self.monomials is None:
            return self.basis.transform(Xb, None, self.terms).T        # Fourier of joint angles: no frame
        M = np.empty((self.monomials.n_rows, block.frame.shape[1]))
        M[0] = 1.0
        M[1:1 + self._frame_rows.size] = block.frame[self._frame_rows]
        self.monomials.fill(M)
        return M

    def combine(self, block: Block, Xb) -> NDArray[np.float64]:
        """Blended prediction of one block inside the grid, shape (outputs, m)."""
        self.prepare([block.cell])
        H = self._cells[block.cell] @ block.weights                     # (outputs * T, m)
        T = len(self.terms)
        return np.einsum("jtm,tm->jm", H.reshape(-1, T, H.shape[1]), self._features(block, Xb))
