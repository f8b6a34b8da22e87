"""Partitions: regions, minimum sizes, brute-force agreement, blend weights."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from partcal import PartcalError
from partcal.models.blending import R1, block_weights, cutoff
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


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), spec=st.sampled_from(SPECS), width=st.floats(0.6, 1.5))
def test_blend_weights_are_a_partition_of_unity_equal_to_the_all_kernel_blend(seed, spec, width):
    X = cloud(seed)
    P = spec.build(X, 20, random_state=seed, width=width)
    queries = np.random.default_rng(seed).uniform([-1500, -1500, -800], [1500, 1500, 2000], size=(400, 3))
    for rows, kernels, own in P.blocks(queries):
        w = block_weights(queries[rows], P.centres[kernels], P.sigmas[kernels], own, "gaussian")
        assert np.all(w >= 0) and np.allclose(w.sum(axis=1), 1.0)
        # brute force over ALL kernels: the candidate list must not change the function
        z = (queries[rows, None, :] - P.centres[None]) / P.sigmas[None]
        r = np.sqrt((z**2).sum(axis=2))
        raw = np.exp(-0.5 * r**2) * cutoff(r)
        reached = raw.sum(axis=1) > 0
        full = raw[reached] / raw[reached].sum(axis=1, keepdims=True)
        mine = np.zeros_like(raw)
        mine[:, kernels] = w
        np.testing.assert_allclose(mine[reached], full, atol=1e-12)
        assert np.all(raw[~reached] == 0)       # unreached points fall back to their own region only


def test_partition_round_trips_as_plain_data():
    X = cloud(3)
    for spec in SPECS:
        P = spec.build(X, 20, random_state=0)
        Q = Partition.from_dict(P.to_dict())
        q = np.random.default_rng(1).uniform(-2000, 2000, size=(500, 3))
        np.testing.assert_array_equal(P.assign(q), Q.assign(q))


def test_cutoff_is_smooth_and_compact():
    assert cutoff(np.array([0.0, 2.0]))[1] == 1.0 and cutoff(np.array([R1, 5.0])).max() == 0.0
    r = np.linspace(2, 3, 1001)
    assert np.all(np.diff(cutoff(r)) <= 0)
    h = 1e-6
    slope = (cutoff(np.array([2 + h, 3 - h])) - cutoff(np.array([2.0, 3.0]))) / h
    np.testing.assert_allclose(slope, 0.0, atol=1e-4)         # flat where it meets 1 and 0


def test_bad_settings():
    with pytest.raises(PartcalError, match=r"The 'max_depth' parameter of Octree must be an int in \[0, 8\]. Got 9 instead."):
        Octree(max_depth=9)
    with pytest.raises(PartcalError, match=r"The 'n_regions' parameter of KMeansPartition must be an int in \[1, 4096\]. Got 0 instead."):
        KMeansPartition(n_regions=0)
    with pytest.raises(PartcalError, match="use KMeansPartition for joint space"):
        Octree().build(np.zeros((100, 6)) + np.arange(6), 10)
