"""PartitionedErrorModel: continuity, reproducibility, accuracy, extrapolation."""

import dataclasses
import warnings

import numpy as np
import pytest
from conftest import ROOT, brute_force_blend
from scipy.spatial import cKDTree
from sklearn.base import clone

from partcal import PartcalError, read_measurements
from partcal.data.simulate import load_study, simulate
from partcal.metrics import ExtrapolationWarning
from partcal.models.partition import KMeansPartition, Octree
from partcal.models.partitioned import PartitionedErrorModel
from partcal.study.selection import select_granularity
from partcal.models.series import ErrorModel
from partcal.models.swarm import SwarmConfig


def smooth_field(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    X = rng.uniform([-1000, -1000, -500], [1000, 1000, 1500], size=(n, 3))
    y = np.c_[np.sin(X[:, 0] / 300), np.cos(X[:, 1] / 400), X[:, 2] / 1000 * np.sin(X[:, 0] / 500)]
    return X, y


def crossings(model, a, b, step=0.5):
    """Points on segment a-b where the hard region changes (found at a coarse step)."""
    t = np.arange(0, np.linalg.norm(b - a), step)
    P = a + t[:, None] * (b - a) / np.linalg.norm(b - a)
    return P, np.flatnonzero(np.diff(model.partition_.assign(P)))


@pytest.mark.parametrize("spec", [Octree(max_depth=2), KMeansPartition(n_regions=12)])
def test_blend_is_continuous_and_hard_jumps(spec):
    X, y = smooth_field()
    local = ErrorModel(degree=2, solver="lstsq")
    blended = PartitionedErrorModel(partition=spec, local=local, random_state=0).fit(X, y)
    hard = PartitionedErrorModel(partition=spec, local=local, blend="hard", random_state=0).fit(X, y)
    a, b = np.array([-900.0, -700, -300]), np.array([900.0, 800, 1300])
    P, cross = crossings(blended, a, b)
    assert cross.size >= 2
    coarse = np.linalg.norm(np.diff(blended.predict(P), axis=0), axis=1) / 0.5
    lipschitz = 2.0 * coarse.max()          # a bound on the slope, from a coarse scan of the segment
    direction = (b - a) / np.linalg.norm(b - a)
    worst_hard = 0.0
    for i in cross:
        for h in (1e-2, 1e-4):
            fine = P[i] + np.arange(-5000, 5001)[:, None] * h * direction      # +-0.5 mm (h=1e-4) around it
            d_blend = np.linalg.norm(np.diff(blended.predict(fine), axis=0), axis=1)
            assert d_blend.max() <= lipschitz * h
            d_hard = np.linalg.norm(np.diff(hard.predict(fine), axis=0), axis=1)
            worst_hard = max(worst_hard, d_hard.max() / (lipschitz * h))
    assert worst_hard > 100       # the hard switch jumps: far beyond any slope bound


def test_results_do_not_depend_on_n_jobs_and_follow_the_seed():
    X, y = smooth_field(1500)
    local = ErrorModel(degree=1, solver="pso")
    one = PartitionedErrorModel(partition=Octree(max_depth=1), local=local, n_jobs=1, random_state=7).fit(X, y)
    two = PartitionedErrorModel(partition=Octree(max_depth=1), local=local, n_jobs=2, random_state=7).fit(X, y)
    np.testing.assert_array_equal(one.predict(X), two.predict(X))
    other = PartitionedErrorModel(partition=Octree(max_depth=1), local=local, random_state=8).fit(X, y)
    assert not np.array_equal(one.models_[0].coef_, other.models_[0].coef_)


def test_regions_get_enough_samples_by_default():
    X, y = smooth_field(2000)
    model = PartitionedErrorModel(partition=Octree(max_depth=4), local=ErrorModel(degree=2, solver="lstsq"),
                                  random_state=0).fit(X, y)
    assert model.min_samples_ == 3 * 7               # three samples per SDP(CI) term
    assert model.region_counts_.min() >= model.min_samples_
    with pytest.raises(PartcalError, match=r"a region needs at least 21 samples \(7 terms per output\); got 15"):
        PartitionedErrorModel(local=ErrorModel(degree=2)).fit(X[:15], y[:15])


def test_extrapolation_is_flagged():
    X, y = smooth_field(1500)
    model = PartitionedErrorModel(partition=Octree(max_depth=1), local=ErrorModel(solver="lstsq")).fit(X, y)
    assert np.all(model.distance_to_data(X) == 0)
    far = np.array([[0.0, 0.0, 3500.0]])          # 2 m above the highest sample
    expected = np.linalg.norm(X - far, axis=1).min()
    assert model.distance_to_data(far)[0] == pytest.approx(expected, rel=1e-12)
    assert expected > 1999
    with pytest.warns(ExtrapolationWarning, match=r"1 of 2 points lie more than 50 input units from the nearest training "
                                                  r"sample \(up to 20\d\d\)"):
        model.warn_if_extrapolating(np.vstack([X[:1], far]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.warn_if_extrapolating(X[:10])


def holed_field(n=4000, seed=1):
    """Samples of a smooth field around an empty ball of radius 400 mm centred at the origin."""
    X, y = smooth_field(n, seed)
    keep = np.linalg.norm(X - [0, 0, 500], axis=1) > 400
    return X[keep], y[keep]


@pytest.mark.parametrize("make", [
    lambda: ErrorModel(degree=2, solver="lstsq"),
    lambda: PartitionedErrorModel(partition=Octree(max_depth=2), local=ErrorModel(degree=2, solver="lstsq")),
    lambda: PartitionedErrorModel(partition=KMeansPartition(12), local=ErrorModel(solver="lstsq"), random_state=0),
])
def test_distance_to_data_is_the_distance_to_the_nearest_sample(make):
    X, y = holed_field()
    model = make().fit(X, y)
    rng = np.random.default_rng(2)
    queries = np.vstack([rng.uniform(-3000, 3000, size=(2000, 3)), X[:50] + rng.normal(0, 5, (50, 3)),
                         [[0.0, 0.0, 500.0], [0.0, 0.0, 2000.0]]])
    nearest = cKDTree(X).query(queries)[0]
    got = model.distance_to_data(queries)
    assert np.all((got >= nearest / 2) & (got <= 2 * nearest))       # the promise
    np.testing.assert_allclose(got, nearest, rtol=1e-12, atol=1e-9)    # in fact exact
    assert got[-2] > 365 and got[-1] > 365                              # the middle of the hole, and above the data
    with pytest.warns(ExtrapolationWarning, match="2 of 2 points"):
        model.warn_if_extrapolating(queries[-2:])


SHIFTS = [-90.0, 30.0, 1e4, -1e6]


def shifted(X, column, value):
    out = X.copy()
    out[:, column] = value
    return out


@pytest.mark.parametrize("spec", [Octree(max_depth=2), KMeansPartition(n_regions=9)])
def test_a_constant_cartesian_input_changes_no_prediction_wherever_it_is_held(spec):
    X, y = smooth_field(2000)
    queries = np.random.default_rng(3).uniform([-1500, -1500, 0], [1500, 1500, 0], size=(3000, 3))
    local = ErrorModel(degree=2, solver="lstsq")
    reference = PartitionedErrorModel(partition=spec, local=local, random_state=0).fit(shifted(X, 2, 0.0), y)
    expected = reference.predict(shifted(queries, 2, 0.0))
    for value in SHIFTS:
        model = PartitionedErrorModel(partition=spec, local=local, random_state=0).fit(shifted(X, 2, value), y)
        np.testing.assert_allclose(model.predict(shifted(queries, 2, value)), expected, rtol=0, atol=1e-9)


def test_a_constant_joint_changes_no_prediction_wherever_it_is_held():
    m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    assert np.all(m.q_deg[:, 4] == 0)                       # q5 is held at 0 in the paper's data
    queries = m.q_deg + np.random.default_rng(4).normal(0, 10, m.q_deg.shape) * [1, 1, 1, 0, 0, 1]
    for local in (ErrorModel(inputs="joint", solver="lstsq"),
                  ErrorModel(inputs="joint", basis="fourier", harmonics=1, solver="lstsq")):
        template = PartitionedErrorModel(partition=KMeansPartition(3), local=local, random_state=0)
        expected = clone(template).fit(m.q_deg, m.errors_mm).predict(queries)
        for value in SHIFTS:
            model = clone(template).fit(shifted(m.q_deg, 4, value), m.errors_mm)
            np.testing.assert_allclose(model.predict(shifted(queries, 4, value)), expected, rtol=0, atol=1e-9)


SEGMENTS = [(np.array([-300.0, 100.0, 1865.0]), np.array([300.0, 100.0, 1865.0])),       # along the top, 365 mm up
            (np.array([600.0, 0.0, 500.0]), np.array([1600.0, 200.0, 700.0])),           # out through a side
            (np.array([-700.0, -700.0, 1300.0]), np.array([-1300.0, -1300.0, 1900.0]))]   # out through a corner


@pytest.mark.parametrize("spec", [Octree(max_depth=2), KMeansPartition(n_regions=12)])
def test_blend_is_continuous_along_segments_that_leave_the_data(spec):
    """Steps of 1e-3 mm out of the data and along it 365 mm away (where hard switches were): no jump."""
    X, y = smooth_field()
    model = PartitionedErrorModel(partition=spec, local=ErrorModel(degree=2, solver="lstsq"), random_state=0).fit(X, y)
    for a, b in SEGMENTS:
        length = np.linalg.norm(b - a)
        P = a + np.arange(0.0, length, 1e-3)[:, None] * (b - a) / length
        pred = model.predict(P)
        step = np.linalg.norm(np.diff(pred, axis=0), axis=1)
        assert step.max() < 1e-3                   # slopes below 1 mm/mm everywhere on the segment
        i = int(np.argmax(step))                   # refine the largest step: a jump would stay a jump
        fine = model.predict(P[i] + np.linspace(0.0, 1.0, 11)[:, None] * (P[i + 1] - P[i]))
        assert np.linalg.norm(np.diff(fine, axis=0), axis=1).max() <= 0.2 * step[i] + 1e-12
        sample = P[:: 997]                         # the fast way is the blend over all kernels
        np.testing.assert_allclose(pred[:: 997], brute_force_blend(model, sample), rtol=0, atol=1e-9)
        assert model.distance_to_data(P[-1:])[0] > 300


LOCALS = [
    ("cartesian", Octree(max_depth=2), ErrorModel(degree=2, solver="lstsq")),
    ("cartesian", KMeansPartition(n_regions=16), ErrorModel(degree=2, solver="lstsq")),
    ("cartesian", Octree(max_depth=1), ErrorModel(degree=3, cross_terms=True, solver="lstsq")),
    ("cartesian", KMeansPartition(n_regions=6), ErrorModel(basis="fourier", harmonics=2, solver="lstsq")),
    ("joint", KMeansPartition(n_regions=3), ErrorModel(inputs="joint", basis="fourier", harmonics=2, solver="lstsq")),
    ("joint", KMeansPartition(n_regions=3), ErrorModel(inputs="joint", degree=2, solver="lstsq")),
]


@pytest.mark.parametrize("inputs, spec, local", LOCALS)
def test_prediction_equals_the_blend_over_all_kernels(inputs, spec, local):
    """Every way of predicting (cell frames, region by region) against an independent brute force."""
    if inputs == "cartesian":
        X, y = smooth_field(2500)
        rng = np.random.default_rng(5)
        queries = np.vstack([rng.uniform([-1100, -1100, -600], [1100, 1100, 1600], size=(3000, 3)),
                             rng.uniform(-6000, 6000, size=(300, 3))])
    else:
        m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
        X, y = m.q_deg, m.errors_mm
        rng = np.random.default_rng(5)
        queries = np.vstack([X + rng.normal(0, 5, X.shape), X + rng.normal(0, 200, X.shape)])
    model = PartitionedErrorModel(partition=spec, local=local, random_state=0).fit(X, y)
    expected = brute_force_blend(model, queries)
    np.testing.assert_allclose(model.predict(queries), expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(model._predict_blend(queries, fast=False), expected, rtol=0, atol=1e-9)


def test_octree_works_on_the_varying_axes_and_refuses_joint_inputs():
    X, y = smooth_field(2000)
    planar = shifted(X, 2, 700.0)
    model = PartitionedErrorModel(partition=Octree(max_depth=2), local=ErrorModel(degree=2, solver="lstsq"),
                                  random_state=0).fit(planar, y)
    assert model.partition_.n_regions == 16                       # a quadtree
    np.testing.assert_allclose(model.predict(planar[:200]), brute_force_blend(model, planar[:200]), atol=1e-9)
    with pytest.raises(PartcalError, match=r"The 'partition' parameter of PartitionedErrorModel must be a "
                                           r"KMeansPartition for joint inputs"):
        PartitionedErrorModel(partition=Octree(), local=ErrorModel(inputs="joint")).fit(np.c_[X, X], y)


def test_select_granularity_reports_every_candidate():
    X, y = smooth_field(1500)
    template = PartitionedErrorModel(partition=KMeansPartition(), local=ErrorModel(solver="lstsq"), random_state=0)
    best, table = select_granularity(template, X, y, [2, 4, 8], folds=3)
    assert [row["granularity"] for row in table] == [2, 4, 8]
    chosen = min(table, key=lambda r: r["cv_rms_3d"])
    assert best.partition.n_regions == chosen["granularity"]
    assert best.partition_.n_regions == chosen["regions"]          # returned fitted on all the data
    assert table[-1]["cv_rms_3d"] < table[0]["cv_rms_3d"]      # finer is better on this smooth field


def test_select_granularity_tells_how_many_regions_the_fold_fits_kept():
    """On the 85 shipped poses an octree of FDP cells keeps 3 regions, but on each 68-pose CV fold only 1:
    its CV score is the global model's. The table says so (and a run warns, and its report notes it)."""
    from partcal.study.selection import kfold_splits

    m = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    template = PartitionedErrorModel(partition=Octree(), local=ErrorModel(solver="lstsq"), random_state=0)
    best, table = select_granularity(template, m.nominal_mm, m.errors_mm, [1, 2], folds=5)
    by_hand = []
    for train, _ in kfold_splits(85, 5, 0):
        fold = clone(template).set_params(partition=Octree(max_depth=1)).fit(m.nominal_mm[train], m.errors_mm[train])
        by_hand.append(fold.partition_.n_regions)
    assert [row["regions"] for row in table] == [3, 3] and best.region_counts_.tolist() == [44, 20, 21]
    assert table[0]["cv_regions"] == [min(by_hand), max(by_hand)] == [1, 1]


@pytest.fixture(scope="module")
def dense_sk120():
    study = load_study(ROOT / "configs" / "sk120_virtual.yaml")
    sets = {"dense": {"sample": 2000}} | {k: v for k, v in study.datasets.items() if k.startswith("test_")}
    return simulate(dataclasses.replace(study, datasets=sets))


def test_partitioning_beats_the_global_model_on_the_dense_virtual_sk120(dense_sk120):
    train = dense_sk120["dense"]
    X, y = train.nominal_mm, train.errors_mm
    tests = [m for name, m in dense_sk120.items() if name != "dense"]

    def rms_3d(model, m):
        return np.sqrt(np.mean(np.sum((m.errors_mm - model.predict(m.nominal_mm)) ** 2, axis=1)))

    for degree in (1, 2):
        local = ErrorModel(degree=degree, solver="lstsq")
        best, _ = select_granularity(PartitionedErrorModel(partition=Octree(), local=local, random_state=0),
                                     X, y, [1, 2, 3], folds=5)
        glob = ErrorModel(degree=degree, solver="lstsq").fit(X, y)
        for m in tests:
            assert rms_3d(best, m) < 0.5 * rms_3d(glob, m), (degree, m.name)


@pytest.mark.parametrize("fitness", ["rms", "max"])
def test_regional_swarms_in_one_batch_equal_solo_fits(fitness):
    # half the samples on a plane z = 500: those regions have fewer coefficients (other batch group)
    X, y = smooth_field(1200, seed=4)
    X[X[:, 0] < 0, 2] = 500.0
    local = ErrorModel(degree=1, fitness=fitness, pso=SwarmConfig(particles=20, iterations=300))
    model = PartitionedErrorModel(partition=Octree(max_depth=1, min_samples=40), local=local, blend="hard",
                                  random_state=3).fit(X, y)
    sizes = {m.coef_.shape[0] for m in model.models_}
    assert sizes == {3, 4}                                    # two dimensions, two batches
    groups = model._training_groups(model.partition_, X)
    seeds = np.random.SeedSequence(3).spawn(model.partition_.n_regions)   # the documented seed rule
    for region, ((rows, w), s) in enumerate(zip(groups, seeds)):
        solo = clone(local).set_params(random_state=int(s.generate_state(1)[0])).fit(X[rows], y[rows], sample_weight=w)
        batched = model.models_[region]
        assert np.array_equal(solo.coef_, batched.coef_), region
        assert [r.nit for r in solo.swarm_results_] == [r.nit for r in batched.swarm_results_]
        assert all(np.array_equal(a.history, b.history) for a, b in zip(solo.swarm_results_, batched.swarm_results_))
