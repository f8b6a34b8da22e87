"""Workspace partitions: an adaptive octree and k-means, with their blend kernels.

``Octree`` and ``KMeansPartition`` are settings (what a user writes);
``build(X, min_samples, random_state)`` returns a fitted :class:`Partition`,
plain arrays that tell which region any point belongs to (also outside the
data's bounding box), and which kernels may weigh on it (see ``blending``).
``Partition.to_dict`` / ``from_dict`` turn it
into JSON-ready data for model files and pictures.

No region is ever left with fewer samples than ``min_samples``: an octree
cell whose children would be too small is not split, and children that are
still too small (or empty) are *orphans* whose box joins the nearest proper
sibling region; k-means merges a too-small cluster into its nearest
neighbour until every cluster is large enough.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from sklearn.cluster import KMeans

from .._validation import check_int, check_real, param_error
from ..errors import PartcalError
from .blending import R1

_BOUNDARY = 1e300   # a "box face at infinity" on the outside of the root cell


@dataclass(frozen=True)
class Octree:
    """Adaptive octree settings: split cells at their centre up to ``max_depth``.

    ``min_samples=None`` means "enough for the local model" (decided by the
    model: a multiple of its coefficient count per output).
    """

    max_depth: int = 3
    min_samples: int | None = None

    def __post_init__(self):
        check_int("Octree", "max_depth", self.max_depth, 0, 8)
        if self.min_samples is not None:
            check_int("Octree", "min_samples", self.min_samples, 1)

    def build(self, X: NDArray[np.float64], min_samples: int, random_state=None, width: float = 0.7
              ) -> "Partition":
        if X.shape[1] > 4:
            raise param_error("Octree", "inputs", "1 to 4 columns (an octree splits each into halves; "
                              "use KMeansPartition for joint space)", X.shape[1])
        return _build_octree(X, self.max_depth, min_samples, width)


@dataclass(frozen=True)
class KMeansPartition:
    """k-means regions (scikit-learn), merged until each holds ``min_samples``."""

    n_regions: int = 8
    min_samples: int | None = None

    def __post_init__(self):
        check_int("KMeansPartition", "n_regions", self.n_regions, 1, 4096)
        if self.min_samples is not None:
            check_int("KMeansPartition", "min_samples", self.min_samples, 1)

    def build(self, X: NDArray[np.float64], min_samples: int, random_state=None, width: float = 0.7
              ) -> "Partition":
        return _build_kmeans(X, self.n_regions, min_samples, random_state, width)


@dataclass(frozen=True, eq=False)
class Partition:
    """A fitted partition: regions, kernels and the data to find them quickly.

    Attributes
    ----------
    kind : "octree" or "kmeans"
    n_regions : int
    centres, sigmas : (M, d) blend kernels; ``kernel_region`` (M,) maps them to regions
    boxes : (M, 2, d) octree leaf boxes (low, high) or None
    tree : dict of octree node arrays (``centre``, ``child``, ``leaf``) or None
    cand : (M, K) candidate kernels per octree leaf, -1 padded, or None
    own : (M,) column of each leaf's own kernel in ``cand``, or None
    """

    kind: str
    n_regions: int
    centres: NDArray[np.float64]
    sigmas: NDArray[np.float64]
    kernel_region: NDArray[np.intp]
    boxes: NDArray[np.float64] | None = None
    tree: dict | None = None
    cand: NDArray[np.intp] | None = None
    own: NDArray[np.intp] | None = None

    # -------------------------------------------------------------- lookups
    def leaf_of(self, X: NDArray[np.float64]) -> NDArray[np.intp]:
        """Octree: the leaf box containing each point (nearest boundary leaf when outside)."""
        centre, child, leaf = self.tree["centre"], self.tree["child"], self.tree["leaf"]
        powers = 1 << np.arange(X.shape[1])
        node = np.zeros(X.shape[0], dtype=np.intp)
        while True:
            inner = child[node] >= 0
            if not inner.any():
                return leaf[node]
            idx = np.flatnonzero(inner)
            octant = (X[idx] > centre[node[idx]]) @ powers
            node[idx] = child[node[idx]] + octant

    def assign(self, X: NDArray[np.float64]) -> NDArray[np.intp]:
        """The region of every point, shape (n,)."""
        if self.kind == "octree":
            return self.kernel_region[self.leaf_of(X)]
        return self.kernel_region[cKDTree(self.centres).query(X)[1]]

    def candidates(self, X: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Kernels that may weigh on each point, ``(n, K)`` padded with -1, and the own column.

        The lists contain every kernel whose support reaches the point, so a
        blend over them equals the blend over all kernels.
        """
        if self.kind == "octree":
            leaf = self.leaf_of(X)
            return self.cand[leaf], self.own[leaf]
        tree = cKDTree(self.centres)
        radius = R1 * self.sigmas.max()
        k = max(1, int(tree.query_ball_point(X, radius, return_length=True).max(initial=1)))
        k = min(k, len(self.centres))
        _, idx = tree.query(X, k=k, distance_upper_bound=radius)
        idx = np.asarray(idx).reshape(len(X), k)
        idx = np.where(idx >= len(self.centres), -1, idx)
        nearest = tree.query(X)[1]
        idx[:, 0] = nearest          # the nearest centre (own region) always comes first
        return idx, np.zeros(len(X), dtype=np.intp)

    def blocks(self, X: NDArray[np.float64]):
        """Group points that share candidate kernels; yield ``(rows, kernels, own_column)``.

        Octree: one block per leaf, with that leaf's candidate list. k-means:
        one block per nearest centre, with the union of its points' lists.
        Every kernel that reaches a point of the block is in ``kernels``.
        """
        if self.kind == "octree":
            group = self.leaf_of(X)
        else:
            cand, _ = self.candidates(X)
            group = cand[:, 0]
        order = np.argsort(group.astype(np.int16 if len(self.centres) < 2**15 else np.int32), kind="stable")
        bounds = np.searchsorted(group[order], np.arange(len(self.centres) + 1))
        for g, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])):
            if a == b:
                continue
            rows = order[a:b]
            if self.kind == "octree":
                kernels = self.cand[g][self.cand[g] >= 0]
                own = int(self.own[g])
            else:
                kernels = np.unique(cand[rows])
                kernels = kernels[kernels >= 0]
                own = int(np.flatnonzero(kernels == g)[0])
            yield rows, kernels, own

    # -------------------------------------------------------------- plain data
    def to_dict(self) -> dict:
        out = {"kind": self.kind, "n_regions": int(self.n_regions), "centres": self.centres.tolist(),
               "sigmas": self.sigmas.tolist(), "kernel_region": self.kernel_region.tolist()}
        if self.kind == "octree":
            out["boxes"] = self.boxes.tolist()
            out["tree"] = {k: v.tolist() for k, v in self.tree.items()}
            out["cand"], out["own"] = self.cand.tolist(), self.own.tolist()
        return out

    @classmethod
    def from_dict(cls, data: dict) -> "Partition":
        arr = np.asarray
        kw = dict(kind=data["kind"], n_regions=int(data["n_regions"]), centres=arr(data["centres"], float),
                  sigmas=arr(data["sigmas"], float), kernel_region=arr(data["kernel_region"], np.intp))
        if data["kind"] == "octree":
            kw.update(boxes=arr(data["boxes"], float), cand=arr(data["cand"], np.intp),
                      own=arr(data["own"], np.intp),
                      tree={"centre": arr(data["tree"]["centre"], float),
                            "child": arr(data["tree"]["child"], np.intp),
                            "leaf": arr(data["tree"]["leaf"], np.intp)})
        return cls(**kw)


# ---------------------------------------------------------------------- octree
def _build_octree(X, max_depth: int, min_samples: int, width: float) -> Partition:
    d = X.shape[1]
    n_children = 2**d
    lo, hi = X.min(axis=0), X.max(axis=0)
    pad = np.maximum((hi - lo) * 1e-9, 1e-9)
    lo, hi = lo - pad, hi + pad
    node_centre, node_child, node_leaf = [(lo + hi) / 2], [-1], [-1]
    leaves = []        # (low, high, proper, ancestors)
    queue = [(0, lo, hi, np.arange(X.shape[0]), 0, ())]
    while queue:       # breadth first: a split appends its 2^d children contiguously
        node, low, high, idx, depth, ancestors = queue.pop(0)
        mid = (low + high) / 2
        if depth < max_depth and idx.size >= 2 * min_samples:
            octant = (X[idx] > mid) @ (1 << np.arange(d))
            counts = np.bincount(octant, minlength=n_children)
            if np.count_nonzero(counts >= min_samples) >= 2:
                first = len(node_centre)
                node_child[node] = first
                for o in range(n_children):
                    bits = ((o >> np.arange(d)) & 1).astype(bool)
                    c_low, c_high = np.where(bits, mid, low), np.where(bits, high, mid)
                    node_centre.append((c_low + c_high) / 2)
                    node_child.append(-1)
                    node_leaf.append(-1)
                    if counts[o] >= min_samples:
                        queue.append((first + o, c_low, c_high, idx[octant == o], depth + 1, ancestors + (node,)))
                    else:     # too few samples: an orphan box, joined to a sibling region below
                        node_leaf[first + o] = len(leaves)
                        leaves.append((c_low, c_high, False, ancestors + (node,)))
                continue
        node_leaf[node] = len(leaves)
        leaves.append((low, high, True, ancestors))
    boxes = np.array([[lw, hg] for lw, hg, _, _ in leaves])
    proper = np.array([p for _, _, p, _ in leaves])
    region = np.full(len(leaves), -1, dtype=np.intp)
    region[proper] = np.arange(proper.sum())
    box_centres = boxes.mean(axis=1)
    proper_idx = np.flatnonzero(proper)
    for i in np.flatnonzero(~proper):          # orphans join the nearest proper leaf under the same parent
        parent = leaves[i][3][-1]
        pool = np.array([j for j in proper_idx if parent in leaves[j][3]])
        region[i] = region[pool[np.argmin(np.linalg.norm(box_centres[pool] - box_centres[i], axis=1))]]
    sigmas = width * (boxes[:, 1] - boxes[:, 0]) / 2
    grown = boxes.copy()
    grown[:, 0][np.isclose(boxes[:, 0], lo)] = -_BOUNDARY     # outer faces reach to infinity
    grown[:, 1][np.isclose(boxes[:, 1], hi)] = _BOUNDARY
    cand, own = _leaf_candidates(grown, box_centres, sigmas)
    n_regions = int(proper.sum())
    tree = {"centre": np.array(node_centre), "child": np.array(node_child, dtype=np.intp),
            "leaf": np.array(node_leaf, dtype=np.intp)}
    return Partition("octree", n_regions, box_centres, sigmas, region, boxes=boxes, tree=tree, cand=cand, own=own)


def _leaf_candidates(grown, centres, sigmas, chunk: int = 256):
    """For each (grown) leaf box, every kernel whose support (radius R1 in sigmas) reaches it."""
    rows = []
    for start in range(0, len(grown), chunk):
        g = grown[start:start + chunk]                                  # (b, 2, d)
        gap = np.maximum(0.0, np.maximum(g[:, None, 0] - centres[None], centres[None] - g[:, None, 1]))
        r = np.linalg.norm(gap / sigmas[None], axis=2)                  # (b, M)
        rows.extend(np.flatnonzero(row < R1) for row in r)
    k = max(len(r) for r in rows)
    cand = np.full((len(rows), k), -1, dtype=np.intp)
    own = np.zeros(len(rows), dtype=np.intp)
    for i, r in enumerate(rows):
        cand[i, : len(r)] = r
        own[i] = int(np.flatnonzero(r == i)[0])
    return cand, own


# ---------------------------------------------------------------------- k-means
def _build_kmeans(X, n_regions: int, min_samples: int, random_state, width: float) -> Partition:
    n = X.shape[0]
    k = max(1, min(n_regions, n // max(min_samples, 1)))
    seed = int(np.random.default_rng(random_state).integers(2**31 - 1)) if not isinstance(random_state, int) \
        else random_state
    km = KMeans(n_clusters=k, random_state=seed, n_init=4).fit(X)
    centres, labels = km.cluster_centers_.copy(), km.labels_.copy()
    while True:       # merge the smallest too-small cluster into its nearest remaining centre
        counts = np.bincount(labels, minlength=len(centres))
        small = np.flatnonzero(counts < min_samples)
        if small.size == 0 or len(centres) == 1:
            break
        drop = small[np.argmin(counts[small])]
        keep = np.delete(np.arange(len(centres)), drop)
        centres = centres[keep]
        labels = cKDTree(centres).query(X)[1]
    if np.bincount(labels).min() < min_samples:
        raise PartcalError(f"KMeansPartition: {n} samples cannot make even one region of {min_samples}")
    spread = np.array([X[labels == r].std(axis=0) for r in range(len(centres))])
    floor = 1e-3 * np.maximum(X.std(axis=0), 1e-12)
    sigmas = width * np.sqrt(3.0) * np.maximum(spread, floor)
    m = len(centres)
    return Partition("kmeans", m, centres, sigmas, np.arange(m))


def check_width(value) -> float:
    """Blend widths below sqrt(3) / 3 would leave octree box corners outside every kernel."""
    return check_real("PartitionedErrorModel", "blend_width", value, 0.6, 10.0)
