"""Partitions: regions, minimum sizes, lookup grids, blend weights against a brute force."""

import numpy as np
import pytest
from conftest import brute_force_weights, smoothstep
from hypothesis import given, settings
from hypothesis import strategies as st

from partcal import PartcalError
from partcal.models.blending import R1, cutoff, normalised_weights
from partcal.models.combine import BlendWeights
from partcal.models.partition import KMeansPartition, Octree, Partition


def cloud(seed, n=800, hole=True):
    rng = np.random.default_rng(seed)
    X = rng.uniform([-800, -600, 0], [900, 700, 1200], size=(n, 3))
    if hole:      # an empty middle leaves empty octants: orphans must be handled
        X = X[np.linalg.norm(X - [50, 50, 600], axis=1) > 350]
    return X


def brute_force_leaf(P: Partition, X):
    """The leaf box with low < x <= high on every axis (the descent sends x == mid low)."""
    low, high = P.boxes[:, 0], P.boxes[:, 1]
    inside = np.all((X[:, None, :] > low[None]) & (X[:, None, :] <= high[None]), axis=2)
    assert np.all(inside.sum(axis=1) == 1)          # every point in exactly one leaf box
    return np.argmax(inside, axis=1)


def block_weights_dense(P: Partition, X):
    """The weights the model uses (lookup cells and candidate lists), scattered to (n, M)."""
    plan, _, blocks = BlendWeights(P).blocks(X)
    out = np.zeros((len(X), len(P.centres)))
    for block in blocks:
        rows = plan.order[block.positions]
        out[np.ix_(rows, block.kernels)] = block.weights.T
    return out


SPECS = [Octree(max_depth=3), Octree(max_depth=1), KMeansPartition(n_regions=12)]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), min_samples=st.integers(5, 80), spec=st.sampled_from(SPECS))
def test_every_region_holds_enough_samples_and_every_point_one_region(seed, min_samples, spec):
    X = cloud(seed)
    P = spec.build(X, min_samples, random_state=seed)
    labels = P.assign(X)
    assert labels.shape == (len(X),) and labels.min() >= 0 and labels.max() < P.n_regions
    counts = np.bincount(labels, minlength=P.n_regions)
    assert counts.min() >= min_samples
    queries = np.random.default_rng(seed + 1).uniform(-3000, 3000, size=(300, 3))   # also far outside
    if P.kind == "octree":
        inside = np.all((queries > P.boxes[:, 0].min(0)) & (queries <= P.boxes[:, 1].max(0)), axis=1)
        np.testing.assert_array_equal(P.leaf_of(queries[inside]), brute_force_leaf(P, queries[inside]))
    else:
        dist = np.linalg.norm(queries[:, None] - P.centres[None], axis=2)
        np.testing.assert_array_equal(P.assign(queries), np.argmin(dist, axis=1))
    assert np.all((P.assign(queries) >= 0) & (P.assign(queries) < P.n_regions))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), spec=st.sampled_from(SPECS), width=st.floats(0.6, 1.5),
       reach=st.sampled_from([1.2, 3.0, 30.0]))
def test_blend_weights_are_a_partition_of_unity_equal_to_the_all_kernel_blend(seed, spec, width, reach):
    X = cloud(seed)
    P = spec.build(X, 20, random_state=seed, width=width)
    centre, half = np.array([50.0, 50, 600]), np.array([850.0, 650, 600])
    queries = np.random.default_rng(seed).uniform(centre - reach * half, centre + reach * half, size=(400, 3))
    mine, full = block_weights_dense(P, queries), brute_force_weights(P, queries)
    assert np.all(mine >= 0) and np.allclose(mine.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    # the candidate lists hold every kernel with weight, so the blend is the all-kernel one
    np.testing.assert_allclose(mine, full, rtol=0, atol=1e-12)
    assert np.all((full > 0).sum(axis=1) >= 1)


@pytest.mark.parametrize("spec", SPECS)
def test_weights_at_the_kernel_centres_are_finite(spec):
    """At a centre the expanded distance sum can round below zero; the weights must stay exact."""
    P = spec.build(cloud(0), 20, random_state=0)
    np.testing.assert_allclose(block_weights_dense(P, P.centres), brute_force_weights(P, P.centres),
                               rtol=0, atol=1e-12)


def test_weights_are_exact_far_from_the_origin_and_ignore_constant_axes():
    """Moving the data and the queries by 10^7 mm, or a constant axis anywhere, changes no weight."""
    X = cloud(5)
    rng = np.random.default_rng(5)
    queries = rng.uniform([-1500, -1500, -800], [1500, 1500, 2000], size=(500, 3))
    offset = np.array([1e7, -3e6, 5e6])
    planar = np.c_[X[:, :2], np.full(len(X), 700.0)]
    planar_q = np.c_[queries[:, :2], np.full(len(queries), 700.0)]
    for spec in (Octree(max_depth=2), KMeansPartition(9)):
        near = block_weights_dense(spec.build(X, 20, random_state=0), queries)
        far = block_weights_dense(spec.build(X + offset, 20, random_state=0), queries + offset)
        np.testing.assert_allclose(far, near, rtol=0, atol=1e-9)
        flat = block_weights_dense(spec.build(planar, 20, random_state=0), planar_q)
        for z in (-1e6, 0.0, 30.0, 1e6):
            moved = np.c_[planar[:, :2], np.full(len(X), z)]
            moved_q = np.c_[planar_q[:, :2], np.full(len(queries), z + 5.0)]   # queries off the plane too
            np.testing.assert_allclose(block_weights_dense(spec.build(moved, 20, random_state=0), moved_q),
                                       flat, rtol=0, atol=1e-12)


def test_normalised_weights_are_continuous_where_the_nearest_kernel_changes():
    """Two kernels of different widths, far out: no jump where the nearest one or the shift changes."""
    centres, inv = np.array([0.0, 10.0]), np.array([1.0, 0.5])

    def largest_step(h):
        x = np.arange(-400.0, 400.0, h)
        w = normalised_weights(((centres[:, None] - x) * inv[:, None]) ** 2)
        assert np.all(np.isfinite(w)) and np.allclose(w.sum(axis=0), 1.0)
        return np.abs(np.diff(w, axis=1)).max()

    coarse, fine = largest_step(1e-3), largest_step(1e-4)
    assert coarse < 1e-2 and fine < 0.2 * coarse           # steps shrink with the step: no jump anywhere


def test_lookup_cells_agree_with_their_boxes():
    X = cloud(2)
    for spec in SPECS:
        P = spec.build(X, 20, random_state=0)
        lookup = P.lookup
        q = np.random.default_rng(3).uniform(-2500, 2500, size=(2000, 3))
        cells = lookup.cells_of(q[:, P.active])
        inside = cells >= 0
        idx = np.stack(np.unravel_index(cells[inside], lookup.shape), axis=1)
        low = lookup.low + idx * lookup.size
        assert np.all((q[inside] >= low - 1e-9) & (q[inside] <= low + lookup.size + 1e-9))
        outside_grid = np.any((q[~inside] < lookup.low) | (q[~inside] >= lookup.low + lookup.shape * lookup.size),
                              axis=1)
        assert np.all(outside_grid)


def test_constant_axes_are_left_out():
    X = cloud(4)
    planar = np.c_[X[:, :2], np.full(len(X), -90.0), X[:, 2]]        # 4 columns, one constant
    P = Octree(max_depth=1).build(planar, 20)
    assert P.active.tolist() == [True, True, False, True] and P.n_regions == 8
    wide = np.c_[X, np.full((len(X), 3), 30.0)]                       # 6 columns, 3 varying
    assert Octree(max_depth=1).build(wide, 20).n_regions == 8
    Q = Octree(max_depth=2).build(np.c_[X[:, :2], np.full(len(X), 700.0)], 20)   # planar: a quadtree
    assert Q.n_regions <= 16 and len(Q.tree["child"]) <= 1 + 4 + 16
    np.testing.assert_array_equal(Q.boxes[:, :, 2], 700.0)


def test_cutoff_is_smooth_and_compact():
    assert cutoff(np.array([0.0, 2.0]))[1] == 1.0 and cutoff(np.array([R1, 5.0])).max() == 0.0
    r = np.linspace(2, 3, 1001)
    assert np.all(np.diff(cutoff(r)) <= 0)
    np.testing.assert_allclose(cutoff(r), smoothstep(r), rtol=0, atol=1e-14)
    h = 1e-6
    slope = (cutoff(np.array([2 + h, 3 - h])) - cutoff(np.array([2.0, 3.0]))) / h
    np.testing.assert_allclose(slope, 0.0, atol=1e-4)         # flat where it meets 1 and 0


def test_bad_settings():
    with pytest.raises(PartcalError, match=r"The 'max_depth' parameter of Octree must be an int in \[0, 8\]. Got 9 instead."):
        Octree(max_depth=9)
    with pytest.raises(PartcalError, match=r"The 'n_regions' parameter of KMeansPartition must be an int in \[1, 4096\]. Got 0 instead."):
        KMeansPartition(n_regions=0)
    with pytest.raises(PartcalError, match=r"The 'inputs' parameter of Octree must be at most 4 varying columns "
                                           r"\(.*use KMeansPartition for joint space\). Got 5 instead."):
        Octree().build(np.random.default_rng(0).uniform(size=(100, 6)) * [1, 1, 1, 1, 1, 0], 10)
