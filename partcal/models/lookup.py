"""Lookup grid: which blend kernels may carry weight in each cell of a uniform grid.

A blended prediction needs, per point, only the kernels that carry weight
there (see ``blending``). A :class:`Lookup` is a uniform grid over the box
the kernels reach, with a list of candidate kernels per cell that is an exact
superset of the kernels carrying weight anywhere in the cell: kernel ``k`` is
listed unless its smallest distance ``L_k`` (in its own widths) to the cell
box is at least ``R1 + max(0, min_j U_j - RS)``, where ``U_j`` is the largest
distance from kernel ``j`` to the box. Inside the cell ``r_min <= min_j U_j``,
so the cutoff never reaches farther than that.

Points are located by integer arithmetic, grouped by cell
(:meth:`Lookup.plan`), and each group is blended over its cell's short list,
so prediction costs about the same for 8 regions as for 512. Points outside
the grid (farther than every kernel's support) are left to the caller, which
blends them over all kernels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .blending import R1, RS

CELL_CAP = 32_000          # cells per grid: group keys fit in int16 (a radix sort)
MIN_CELLS = 512            # octree grids: at least this many cells in the root box
KMEANS_CELLS = 2048        # k-means grids: at least this many cells in the kernels' box
_TOLERANCE = 1e-9          # widths: a point on a cell face may be rounded into the neighbour


@dataclass(frozen=True)
class BlockPlan:
    """Points grouped by lookup cell.

    Attributes
    ----------
    order : (n,) the points' indices, sorted by cell, points outside the grid last
    cells, starts, stops : (B,) each non-empty cell and its slice of ``order``
    far : slice of ``order`` holding the points outside the grid
    """

    order: NDArray[np.intp]
    cells: NDArray[np.intp]
    starts: NDArray[np.intp]
    stops: NDArray[np.intp]
    far: slice


@dataclass(frozen=True, eq=False)
class Lookup:
    """A uniform grid on the kernels' axes with candidate kernels per cell (CSR lists).

    Attributes
    ----------
    low, size : (a,) grid origin and cell size, input units
    shape : (a,) cells per axis; cells are numbered in C order
    indptr : (C + 1,) and kernels : the candidate kernels of cell ``c`` are
        ``kernels[indptr[c]:indptr[c + 1]]``
    """

    low: NDArray[np.float64]
    size: NDArray[np.float64]
    shape: NDArray[np.intp]
    indptr: NDArray[np.intp]
    kernels: NDArray[np.intp]

    @property
    def n_cells(self) -> int:
        return int(np.prod(self.shape))

    def cells_of(self, X: NDArray[np.float64]) -> NDArray[np.intp]:
        """Cell of every point ``(n, a)``, -1 outside the grid."""
        idx = np.floor((X - self.low) / self.size)
        inside = np.all((idx >= 0) & (idx < self.shape), axis=1)
        strides = np.array([np.prod(self.shape[i + 1:]) for i in range(len(self.shape))], dtype=float)
        return np.where(inside, idx @ strides, -1).astype(np.intp)

    def centres(self, cells: NDArray[np.intp]) -> NDArray[np.float64]:
        """Centres of cells, shape (len(cells), a); every cell's half-size is ``size / 2``."""
        index = np.stack(np.unravel_index(cells, self.shape), axis=1).astype(float)
        return self.low + (index + 0.5) * self.size

    def candidates(self, cell: int) -> NDArray[np.intp]:
        return self.kernels[self.indptr[cell]:self.indptr[cell + 1]]

    def plan(self, X: NDArray[np.float64]) -> BlockPlan:
        """Group points ``(n, a)`` by cell (a stable radix sort on the cell number)."""
        n_cells = self.n_cells
        key = self.cells_of(X)
        key[key < 0] = n_cells
        order = np.argsort(key.astype(np.int16), kind="stable")
        counts = np.bincount(key, minlength=n_cells + 1)
        bounds = np.r_[0, np.cumsum(counts)]
        cells = np.flatnonzero(counts[:n_cells])
        return BlockPlan(order, cells, bounds[cells], bounds[cells + 1], slice(int(bounds[n_cells]), len(key)))


def octree_lookup(root_low, root_high, depth: int, centres, inv_sigmas) -> Lookup:
    """A grid aligned with the octree, extended by whole cells over the box the kernels reach.

    Cells are those of octree level ``depth``, or finer until the root box
    holds ``MIN_CELLS`` (shorter candidate lists), coarser if needed to stay
    under ``CELL_CAP``.
    """
    reach_low, reach_high = _reach(centres, inv_sigmas)
    a = len(root_low)
    level = max(depth, int(np.ceil(np.log2(MIN_CELLS) / max(a, 1))))
    while level > 0 and 2 ** (level * a) > CELL_CAP // 2:
        level -= 1
    size = (root_high - root_low) / 2**level
    limit = np.floor((CELL_CAP ** (1.0 / max(a, 1)) - 2**level) / 2)        # margin cells per side
    below = np.minimum(np.ceil(np.maximum(root_low - reach_low, 0.0) / size), limit)
    above = np.minimum(np.ceil(np.maximum(reach_high - root_high, 0.0) / size), limit)
    shape = (2**level + below + above).astype(np.intp)
    return _with_candidates(root_low - below * size, size, shape, centres, inv_sigmas)


def grid_lookup(centres, inv_sigmas) -> Lookup:
    """A grid over the box the kernels reach: ``max(KMEANS_CELLS, 2 M)`` cells (at most ``CELL_CAP``),
    shaped like the kernels (cell sides in proportion to the typical kernel width per axis)."""
    low, high = _reach(centres, inv_sigmas)
    extent = np.maximum(high - low, 1e-300)
    in_widths = extent * np.median(inv_sigmas, axis=0)
    target = min(CELL_CAP, max(KMEANS_CELLS, 2 * centres.shape[0]))
    scale = (target / np.prod(in_widths)) ** (1.0 / max(len(extent), 1))
    shape = np.maximum(np.round(in_widths * scale), 1)
    while np.prod(shape) > CELL_CAP:
        shape = np.maximum(np.floor(shape * 0.9), 1)
    shape = shape.astype(np.intp)
    return _with_candidates(low, extent / shape, shape, centres, inv_sigmas)


def _reach(centres, inv_sigmas):
    """The box where some kernel is within ``R1`` of its widths."""
    radius = R1 / inv_sigmas
    return (centres - radius).min(axis=0), (centres + radius).max(axis=0)


def _with_candidates(low, size, shape, centres, inv_sigmas) -> Lookup:
    """Candidate lists of every cell (see the module docstring), computed in chunks of cells."""
    n_cells, m = int(np.prod(shape)), centres.shape[0]
    if len(shape) == 0:                     # no input varies: one cell, every kernel
        return Lookup(np.zeros(0), np.ones(0), np.zeros(0, np.intp), np.array([0, m]), np.arange(m))
    chunk = max(1, 2_000_000 // max(m * max(len(shape), 1), 1))
    rows, cols = [], []
    for start in range(0, n_cells, chunk):
        idx = np.stack(np.unravel_index(np.arange(start, min(start + chunk, n_cells)), shape), axis=1)
        lo = low + idx * size                                                       # (b, a)
        hi = lo + size
        near = np.maximum(0.0, np.maximum(lo[:, None] - centres[None], centres[None] - hi[:, None]))
        far = np.maximum(np.abs(lo[:, None] - centres[None]), np.abs(hi[:, None] - centres[None]))
        lower = np.sqrt(np.einsum("bka,bka->bk", near * inv_sigmas, near * inv_sigmas))
        upper = np.sqrt(np.einsum("bka,bka->bk", far * inv_sigmas, far * inv_sigmas))
        reach = R1 + np.maximum(upper.min(axis=1) - RS, 0.0) + _TOLERANCE
        r, c = np.nonzero(lower < reach[:, None])
        rows.append(r + start)
        cols.append(c)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    indptr = np.r_[0, np.cumsum(np.bincount(rows, minlength=n_cells))].astype(np.intp)
    return Lookup(np.asarray(low, float), np.asarray(size, float), np.asarray(shape, np.intp), indptr,
                  cols.astype(np.intp))
