"""Workspace partitions: an adaptive octree and k-means, with their blend kernels.

``Octree`` and ``KMeansPartition`` are settings (what a user writes);
``build(X, min_samples, random_state)`` returns a fitted :class:`Partition`,
plain arrays that tell which region any point belongs to (also outside the
data's bounding box), and which kernels may weigh on it (its ``lookup``, see
``lookup`` and ``blending``). ``Partition.to_dict`` turns it into JSON-ready
data for model files (read back, with every field checked, by ``partcal.study.persist``).

Inputs that never vary in the training data (``features.varying_inputs``) are
left out: an octree splits, and kernels blend, along the varying axes only,
so a joint held at -90 or at 30 degrees gives the same partition as one held
at 0, and planar data make a quadtree.

No region is ever left with fewer samples than ``min_samples``: an octree
cell whose children would be too small is not split, and children that are
still too small (or empty) are *orphans* whose box joins the nearest proper
sibling region; k-means merges a too-small cluster into its nearest
neighbour until every cluster is large enough.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from sklearn.cluster import KMeans

from .._validation import FieldReader, check_int, integer, param_error, real
from ..errors import PartcalError
from .features import varying_inputs
from .lookup import BlockPlan, Lookup, grid_lookup, octree_lookup
from .threads import one_openmp_thread


@dataclass(frozen=True)
class Octree:
    """Adaptive octree settings: split cells at their centre up to ``max_depth``.

    ``min_samples=None`` means "enough for the local model" (decided by the
    model: a multiple of its coefficient count per output).
    """

    max_depth: int = 3
    min_samples: int | None = None

    size_key = "max_depth"                       # what sets the granularity (a run config's key too)
    size_rule = integer(0, 8, default=3)
    joint_inputs = False                         # an octree splits Cartesian boxes

    def __post_init__(self):
        self.size_rule.check("Octree", "max_depth", self.max_depth)
        if self.min_samples is not None:
            check_int("Octree", "min_samples", self.min_samples, 1)

    def build(self, X: NDArray[np.float64], min_samples: int, random_state=None, width: float = 0.7
              ) -> "Partition":
        n_varying = int(varying_inputs(X).sum())
        if n_varying > 4:
            raise param_error("Octree", "inputs", "at most 4 varying columns (an octree splits each into "
                              "halves; use KMeansPartition for joint space)", n_varying)
        return _build_octree(X, self.max_depth, min_samples, width)


@dataclass(frozen=True)
class KMeansPartition:
    """k-means regions (scikit-learn), merged until each holds ``min_samples``."""

    n_regions: int = 8
    min_samples: int | None = None

    size_key = "n_regions"
    size_rule = integer(1, 4096, default=8)
    joint_inputs = True

    def __post_init__(self):
        self.size_rule.check("KMeansPartition", "n_regions", self.n_regions)
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
    active : (d,) bool, the input axes that vary in the training data; the others
        are never split nor blended along (their ``sigmas`` are meaningless)
    boxes : (M, 2, d) octree leaf boxes (low, high) or None
    tree : dict of octree node arrays (``centre``, ``child``, ``leaf``) or None

    Derived at construction (a partition never changes after it, and reading it
    builds nothing): ``kernel_centres`` and ``kernel_inv_sigmas`` (M, a), the
    kernels on the varying axes; ``lookup``, the grid of candidate kernels
    (see ``lookup``); k-means: a KD-tree over the kernel centres for
    :meth:`assign`.
    """

    kind: str
    n_regions: int
    centres: NDArray[np.float64]
    sigmas: NDArray[np.float64]
    kernel_region: NDArray[np.intp]
    active: NDArray[np.bool_]
    boxes: NDArray[np.float64] | None = None
    tree: dict | None = None
    kernel_centres: NDArray[np.float64] = field(init=False, repr=False)
    kernel_inv_sigmas: NDArray[np.float64] = field(init=False, repr=False)
    lookup: Lookup = field(init=False, repr=False)
    _centre_tree: cKDTree | None = field(init=False, repr=False)

    def __post_init__(self):
        derived = object.__setattr__       # a frozen dataclass: its derived fields are set once, here
        derived(self, "kernel_centres", np.ascontiguousarray(self.centres[:, self.active]))
        derived(self, "kernel_inv_sigmas", 1.0 / self.sigmas[:, self.active])
        derived(self, "lookup", self._build_lookup())
        derived(self, "_centre_tree", cKDTree(self.kernel_centres) if self.kind == "kmeans" else None)

    def _build_lookup(self) -> Lookup:
        """The grid of candidate kernels (see ``lookup``)."""
        if self.kind == "octree":
            low = self.boxes[:, 0][:, self.active].min(axis=0)
            high = self.boxes[:, 1][:, self.active].max(axis=0)
            extent = self.boxes[:, 1][:, self.active] - self.boxes[:, 0][:, self.active]
            depth = int(np.rint(np.log2((high - low) / extent)).max(initial=0)) if self.active.any() else 0
            return octree_lookup(low, high, depth, self.kernel_centres, self.kernel_inv_sigmas)
        return grid_lookup(self.kernel_centres, self.kernel_inv_sigmas)

    # -------------------------------------------------------------- lookups
    def leaf_of(self, X: NDArray[np.float64]) -> NDArray[np.intp]:
        """Octree: the leaf box containing each point (nearest boundary leaf when outside)."""
        centre, child, leaf = self.tree["centre"][:, self.active], self.tree["child"], self.tree["leaf"]
        Xa = X[:, self.active]
        powers = 1 << np.arange(Xa.shape[1])
        node = np.zeros(X.shape[0], dtype=np.intp)
        while True:
            inner = child[node] >= 0
            if not inner.any():
                return leaf[node]
            idx = np.flatnonzero(inner)
            octant = (Xa[idx] > centre[node[idx]]) @ powers
            node[idx] = child[node[idx]] + octant

    def assign(self, X: NDArray[np.float64]) -> NDArray[np.intp]:
        """The region of every point, shape (n,): its octree leaf's, or its nearest k-means centre's."""
        if self.kind == "octree":
            return self.kernel_region[self.leaf_of(X)]
        return self.kernel_region[self._centre_tree.query(X[:, self.active])[1]]

    def plan(self, X: NDArray[np.float64]) -> BlockPlan:
        """Points ``(n, d)`` grouped by lookup cell (see :meth:`Lookup.plan`)."""
        return self.lookup.plan(X[:, self.active])

    # -------------------------------------------------------------- plain data
    def to_dict(self) -> dict:
        out = {"kind": self.kind, "n_regions": int(self.n_regions), "centres": self.centres.tolist(),
               "sigmas": self.sigmas.tolist(), "kernel_region": self.kernel_region.tolist(),
               "active": self.active.tolist()}
        if self.kind == "octree":
            out["boxes"] = self.boxes.tolist()
            out["tree"] = {k: v.tolist() for k, v in self.tree.items()}
        return out

    @property
    def region_noun(self) -> str:
        """What a region is called: ``octree cell`` or ``k-means region``."""
        return "octree cell" if self.kind == "octree" else "k-means region"

    def region_boxes(self) -> NDArray[np.float64] | None:
        """``(n_regions, 2, d)``: each region's box (an octree's first cell of the region), or None (k-means)."""
        if self.kind != "octree":
            return None
        return self.boxes[[int(np.flatnonzero(self.kernel_region == g)[0]) for g in range(self.n_regions)]]



# ---------------------------------------------------------------------- octree
def _build_octree(X, max_depth: int, min_samples: int, width: float) -> Partition:
    active = varying_inputs(X)
    constant = (X.min(axis=0) + X.max(axis=0)) / 2
    Xa = X[:, active]
    d = Xa.shape[1]
    n_children = 2**d
    lo, hi = Xa.min(axis=0), Xa.max(axis=0)
    pad = np.maximum((hi - lo) * 1e-9, 1e-9)
    lo, hi = lo - pad, hi + pad
    node_centre, node_child, node_leaf = [(lo + hi) / 2], [-1], [-1]
    leaves = []        # (low, high, proper, ancestors)
    queue = [(0, lo, hi, np.arange(Xa.shape[0]), 0, ())]
    while queue:       # breadth first: a split appends its 2^d children contiguously
        node, low, high, idx, depth, ancestors = queue.pop(0)
        mid = (low + high) / 2
        if d and depth < max_depth and idx.size >= 2 * min_samples:
            octant = (Xa[idx] > mid) @ (1 << np.arange(d))
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
    boxes_a = np.array([[lw, hg] for lw, hg, _, _ in leaves]).reshape(len(leaves), 2, d)
    proper = np.array([p for _, _, p, _ in leaves])
    region = np.full(len(leaves), -1, dtype=np.intp)
    region[proper] = np.arange(proper.sum())
    centres_a = boxes_a.mean(axis=1)
    proper_idx = np.flatnonzero(proper)
    for i in np.flatnonzero(~proper):          # orphans join the nearest proper leaf under the same parent
        parent = leaves[i][3][-1]
        pool = np.array([j for j in proper_idx if parent in leaves[j][3]])
        region[i] = region[pool[np.argmin(np.linalg.norm(centres_a[pool] - centres_a[i], axis=1))]]
    boxes = np.broadcast_to(constant, (len(leaves), 2, X.shape[1])).copy()      # constant axes: flat boxes
    boxes[:, :, active] = boxes_a
    centres = boxes.mean(axis=1)
    sigmas = width * (boxes[:, 1] - boxes[:, 0]) / 2                           # 0 on constant axes
    tree_centre = np.broadcast_to(constant, (len(node_centre), X.shape[1])).copy()
    tree_centre[:, active] = np.array(node_centre).reshape(len(node_centre), d)
    tree = {"centre": tree_centre, "child": np.array(node_child, dtype=np.intp),
            "leaf": np.array(node_leaf, dtype=np.intp)}
    return Partition("octree", int(proper.sum()), centres, sigmas, region, active=active, boxes=boxes, tree=tree)


# ---------------------------------------------------------------------- k-means
def _build_kmeans(X, n_regions: int, min_samples: int, random_state, width: float) -> Partition:
    n = X.shape[0]
    active = varying_inputs(X)
    Xa = X[:, active]
    k = max(1, min(n_regions, n // max(min_samples, 1))) if active.any() else 1
    if k == 1:
        centres, labels = Xa.mean(axis=0, keepdims=True), np.zeros(n, dtype=np.intp)
    else:
        seed = int(np.random.default_rng(random_state).integers(2**31 - 1)) if not isinstance(random_state, int) \
            else random_state
        with one_openmp_thread():
            km = KMeans(n_clusters=k, random_state=seed, n_init=4).fit(Xa)
        centres, labels = km.cluster_centers_.copy(), km.labels_.copy()
    while True:       # merge the smallest too-small cluster into its nearest remaining centre
        counts = np.bincount(labels, minlength=len(centres))
        small = np.flatnonzero(counts < min_samples)
        if small.size == 0 or len(centres) == 1:
            break
        drop = small[np.argmin(counts[small])]
        keep = np.delete(np.arange(len(centres)), drop)
        centres = centres[keep]
        labels = cKDTree(centres).query(Xa)[1]
    if np.bincount(labels).min() < min_samples:
        raise PartcalError(f"KMeansPartition: {n} samples cannot make even one region of {min_samples}")
    m = len(centres)
    spread = np.array([Xa[labels == r].std(axis=0) for r in range(m)]).reshape(m, Xa.shape[1])
    floor = 1e-3 * np.maximum(Xa.std(axis=0), 1e-12)
    full_centres = np.tile((X.min(axis=0) + X.max(axis=0)) / 2, (m, 1))
    full_centres[:, active] = centres
    sigmas = np.zeros((m, X.shape[1]))
    sigmas[:, active] = width * np.sqrt(3.0) * np.maximum(spread, floor)
    return Partition("kmeans", m, full_centres, sigmas, np.arange(m), active=active)


BLEND_WIDTH = real(0.6, 10.0, default=0.7)       # kernel widths relative to the regions: below 0.6 they barely overlap
PARTITIONS = {"octree": Octree, "kmeans": KMeansPartition}     # a run config's partition.method -> settings


def partition_from_file(p: FieldReader, m: int, n_in: int, active: np.ndarray) -> Partition:
    """A model file's partition of ``m`` regions in ``n_in`` coordinates, with every index in range and every
    kernel width positive on the varying axes.

    Lists of candidate kernels (``cand``, ``own``) in files of partcal 0.1 are
    ignored: the lookup is rebuilt from the kernels.
    """
    kind = p.choice("kind", tuple(PARTITIONS))
    centres = p.array("centres", (None, n_in))
    k = centres.shape[0]
    sigmas = p.array("sigmas", (k, n_in))
    if not active.any():
        p.fail("active", "no input varies: there is nothing to partition")
    if np.any(sigmas[:, active] <= 0):
        p.fail("sigmas", "kernel widths must be > 0 on the varying axes")
    kernel_region = p.array("kernel_region", (k,), int)
    if np.any((kernel_region < 0) | (kernel_region >= m)) or np.unique(kernel_region).size != m:
        p.fail("kernel_region", f"must map the {k} kernels onto all regions 0..{m - 1}")
    if kind == "kmeans":
        if k != m or np.any(kernel_region != np.arange(m)):
            p.fail("kernel_region", f"a k-means partition has one kernel per region: 0..{m - 1}")
        return Partition("kmeans", m, centres, sigmas, kernel_region, active=active)
    boxes = p.array("boxes", (k, 2, n_in))
    if np.any(boxes[:, 0] > boxes[:, 1]):
        p.fail("boxes", "a low corner exceeds its high corner")
    tree = p.sub("tree")
    node_centre = tree.array("centre", (None, n_in))
    nodes, split = node_centre.shape[0], 2 ** int(active.sum())
    child, leaf = tree.array("child", (nodes,), int), tree.array("leaf", (nodes,), int)
    inner = child >= 0
    if np.any(child[inner] + split > nodes) or np.any(child < -1) or np.any(child[inner] <= np.flatnonzero(inner)):
        tree.fail("child", f"child indices must point forward to {split} nodes within the {nodes} nodes")
    if np.any(inner == (leaf >= 0)) or np.any(leaf >= k) or np.any(leaf < -1):
        tree.fail("leaf", f"every node is either split (child >= 0) or a leaf with an index in 0..{k - 1}")
    return Partition("octree", m, centres, sigmas, kernel_region, active=active, boxes=boxes,
                     tree={"centre": node_centre, "child": child, "leaf": leaf})

