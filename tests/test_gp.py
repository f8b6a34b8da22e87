"""Gaussian-process error models: scikit-learn's numbers, angle wrapping, regions, model files."""

import json

import numpy as np
import pytest
from conftest import ROOT
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, Matern, WhiteKernel

from partcal import (
    ErrorModel,
    GaussianProcessErrorModel,
    KMeansPartition,
    PartcalError,
    PartitionedErrorModel,
    read_measurements,
)
from partcal.study.persist import load_model, model_to_dict, save_model

IDENT = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
RECTANGLE = read_measurements(ROOT / "data" / "sk120" / "test_rectangle.csv")


def unit_scaled(X, train):
    """Each varying column of X to [-1, 1] over the training range (written out, not partcal's map)."""
    lo, hi = train.min(axis=0), train.max(axis=0)
    moving = hi > lo
    return (X[:, moving] - (hi + lo)[moving] / 2) / ((hi - lo)[moving] / 2)


def same_stopping_rule(objective, theta0, bounds):
    """scikit-learn's L-BFGS-B, stopped as partcal's search stops (``likelihood.SEARCH_FTOL``)."""
    from scipy.optimize import minimize

    from partcal.models.likelihood import SEARCH_FTOL

    res = minimize(objective, theta0, jac=True, method="L-BFGS-B", bounds=bounds, options={"ftol": SEARCH_FTOL})
    return res.x, res.fun


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")   # scikit-learn's own fit, below
@pytest.mark.parametrize("kernel, nu, shape", [("rbf", 2.5, RBF(np.ones(4), (1e-2, 1e3))),
                                               ("matern", 2.5, Matern(np.ones(4), (1e-2, 1e3), nu=2.5))])
def test_fit_and_prediction_are_scikit_learns(kernel, nu, shape):
    """Same kernel, bounds, restarts and seed given to scikit-learn directly: same hyperparameters, same means
    (partcal's own gradient steps, models/likelihood.py, agree with scikit-learn's to rounding)."""
    q, y = IDENT.q_deg, IDENT.errors_mm
    model = GaussianProcessErrorModel(inputs="joint", kernel=kernel, nu=nu, restarts=1, random_state=3).fit(q, y)
    reference = GaussianProcessRegressor(ConstantKernel(1.0, (1e-3, 1e3)) * shape + WhiteKernel(1e-4, (1e-12, 1.0)),
                                         normalize_y=True, n_restarts_optimizer=1, random_state=3,
                                         optimizer=same_stopping_rule)
    reference.fit(unit_scaled(q, q), y)                     # q4 = q5 = 0 never move: four inputs
    np.testing.assert_allclose(model.log_marginal_likelihood_, reference.log_marginal_likelihood_value_, rtol=1e-9)
    expected = reference.predict(unit_scaled(RECTANGLE.q_deg, q))
    np.testing.assert_allclose(model.predict(RECTANGLE.q_deg), expected, rtol=0, atol=1e-5)      # mm: 0.01 um
    assert model.X_train_.shape == (85, 4) and model.length_scale_.shape == (4,)


@pytest.mark.parametrize("kernel", ["rbf", "matern"])
def test_model_files_round_trip_bit_for_bit(tmp_path, kernel):
    model = GaussianProcessErrorModel(inputs="cartesian", kernel=kernel, random_state=0).fit(IDENT.nominal_mm,
                                                                                          IDENT.errors_mm)
    path = tmp_path / "gp.json"
    save_model(model, path, name="GP(CI)")
    loaded, doc = load_model(path)
    assert doc["kind"] == "gaussian_process" and "pickle" not in path.read_text()
    assert np.array_equal(loaded.predict(RECTANGLE.nominal_mm), model.predict(RECTANGLE.nominal_mm))
    again = tmp_path / "again.json"
    save_model(loaded, again, name="GP(CI)")
    assert json.loads(again.read_text()) | {"partcal_version": 0} == doc | {"partcal_version": 0}
    assert again.read_text() == path.read_text()
    assert (doc["model"]["hyperparameters"], doc["model"]["hyper_samples"], doc["model"]["region_overlap"]) == (
        "shared", None, 1.0)
    for key in ("hyperparameters", "hyper_samples", "region_overlap"):     # a file from before these settings
        del doc["model"][key]
    del doc["checksum"]
    older = tmp_path / "older.json"
    older.write_text(json.dumps(doc))
    old_model = load_model(older)[0]
    assert (old_model.hyperparameters, old_model.hyper_samples, old_model.region_overlap) == ("per_region", None, 1.0)
    assert np.array_equal(old_model.predict(RECTANGLE.nominal_mm), model.predict(RECTANGLE.nominal_mm))


def straddling(n=300, seed=0):
    """Joint data whose q1 runs through 180 degrees: raw values 150..180 and -180..-150."""
    rng = np.random.default_rng(seed)
    unwrapped = np.c_[rng.uniform(150, 210, n), rng.uniform(-150, -110, n), rng.uniform(-40, 40, n)]
    rad = np.radians(unwrapped)
    y = np.c_[np.sin(rad[:, 0]) + rad[:, 1], np.cos(rad[:, 0] + rad[:, 2]), rad[:, 2] * np.sin(rad[:, 0])]
    raw = unwrapped.copy()
    raw[:, 0] = np.where(raw[:, 0] > 180, raw[:, 0] - 360, raw[:, 0])
    return raw, unwrapped, y


MAKERS = {
    "GP": lambda inputs: GaussianProcessErrorModel(inputs=inputs, restarts=0),
    "SDP k-means": lambda inputs: PartitionedErrorModel(partition=KMeansPartition(3), local=ErrorModel(
        inputs=inputs, degree=2, solver="lstsq"), random_state=0),
    "GP k-means": lambda inputs: PartitionedErrorModel(partition=KMeansPartition(3), local=GaussianProcessErrorModel(
        inputs=inputs, restarts=0), random_state=0),
}


@pytest.mark.parametrize("name", MAKERS)
def test_a_joint_through_180_degrees_is_read_where_its_data_are_contiguous(name):
    """Fitted on raw angles that jump from 180 to -180, a model equals one fitted on the unwrapped angles.

    (Up to rounding: wrapping moves an angle by an ulp, and a GP's optimiser then stops a little elsewhere.)
    The same arrays read as plain numbers (no wrapping) give another model.
    """
    make = MAKERS[name]
    raw, unwrapped, y = straddling(150)
    wrapped, plain = make("joint").fit(raw, y), make("joint").fit(unwrapped, y)
    query_raw, query, _ = straddling(50, seed=1)
    np.testing.assert_allclose(wrapped.predict(query_raw), plain.predict(query), rtol=0, atol=1e-5)
    seam = np.array([[180.0, -130.0, 0.0], [-180.0, -130.0, 0.0]])          # one pose, written two ways
    np.testing.assert_array_equal(*wrapped.predict(seam))
    if name == "SDP k-means":      # dense GPs interpolate either way; polynomials over a torn range do not
        naive = make("cartesian").fit(raw, y)
        assert np.abs(naive.predict(query_raw) - plain.predict(query)).max() > 1e-3


def test_joint_space_regions_are_scaled_per_joint():
    """k-means regions do not change when one joint's angles are stretched: every joint spans [-1, 1]."""
    _, q, y = straddling()
    model = PartitionedErrorModel(partition=KMeansPartition(4), local=ErrorModel(inputs="joint", solver="lstsq"),
                                  random_state=0)
    stretched = q * [1, 4, 1] + [0, 300, 0]                     # q2: 40 degrees of range become 160
    labels = model.fit(q, y).assign(q)
    np.testing.assert_array_equal(model.fit(stretched, y).assign(stretched), labels)


@pytest.fixture(scope="module")
def regional_gp():
    return PartitionedErrorModel(partition=KMeansPartition(2), local=GaussianProcessErrorModel(inputs="joint"),
                                 random_state=0).fit(IDENT.q_deg, IDENT.errors_mm)


def test_one_gp_per_region_is_blended_and_round_trips(tmp_path, regional_gp):
    model = regional_gp
    assert model.partition_.n_regions == 2 and all(isinstance(m, GaussianProcessErrorModel) for m in model.models_)
    assert model.min_samples_ == 40                          # ten per varying joint (q1, q2, q3, q6)
    path = tmp_path / "gp-kmeans.json"
    save_model(model, path)
    loaded, doc = load_model(path)
    assert doc["local_kind"] == "gaussian_process" and doc["input_map"]["active"] == [True] * 3 + [False] * 2 + [True]
    assert np.array_equal(loaded.predict(RECTANGLE.q_deg), model.predict(RECTANGLE.q_deg))
    assert model_to_dict(loaded) | {"partcal_version": 0} == model_to_dict(model) | {"partcal_version": 0}
    rms = np.sqrt(np.mean(np.sum((RECTANGLE.errors_mm - model.predict(RECTANGLE.q_deg)) ** 2, axis=1)))
    assert rms < 0.5 * np.sqrt(np.mean(np.sum(RECTANGLE.errors_mm**2, axis=1)))


def test_bad_parameters_are_refused():
    X, y = IDENT.nominal_mm, IDENT.errors_mm
    with pytest.raises(PartcalError, match=r"The 'kernel' parameter of GaussianProcessErrorModel must be one of "
                                           r"'rbf', 'matern'\. Got 'linear' instead\."):
        GaussianProcessErrorModel(kernel="linear").fit(X, y)
    with pytest.raises(PartcalError, match=r"The 'nu' parameter of GaussianProcessErrorModel must be one of 0\.5, "
                                           r"1\.5, 2\.5\. Got 2 instead\."):
        GaussianProcessErrorModel(kernel="matern", nu=2).fit(X, y)
    with pytest.raises(PartcalError, match=r"a region needs at least 40 samples \(10 per varying input\); got 30"):
        PartitionedErrorModel(local=GaussianProcessErrorModel(inputs="joint")).fit(IDENT.q_deg[:30], y[:30])
    with pytest.raises(PartcalError, match=r"The 'local' parameter of PartitionedErrorModel must be an ErrorModel "
                                           r"or a GaussianProcessErrorModel"):
        PartitionedErrorModel(local="gp").fit(X, y)


def dual_coefficients(Z, Y, amplitude, length_scale, noise):
    """``(K + noise I)^-1 Y`` of an RBF kernel, by Cholesky, written out (scikit-learn adds 1e-10 to the diagonal)."""
    from scipy.linalg import cho_factor, cho_solve

    d = (Z[:, None, :] - Z[None, :, :]) / length_scale
    K = amplitude * np.exp(-0.5 * np.sum(d * d, axis=2)) + (noise + 1e-10) * np.eye(len(Z))
    return cho_solve(cho_factor(K, lower=True), Y)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_regions_share_one_search_and_solve_on_their_own_samples():
    """Default: the hyperparameters of one search on all samples; each region solves only for its dual coefficients."""
    from conftest import brute_force_weights

    q, y = IDENT.q_deg, IDENT.errors_mm
    model = PartitionedErrorModel(partition=KMeansPartition(2), local=GaussianProcessErrorModel(inputs="joint"),
                                  random_state=0).fit(q, y)
    whole = GaussianProcessErrorModel(inputs="joint", random_state=0).fit(q, y)     # 85 < 500: the search sees all
    W = brute_force_weights(model.partition_, model._coordinates(q)[1])
    for region, gp in enumerate(model.models_):
        assert (gp.amplitude_, gp.noise_) == (whole.amplitude_, whole.noise_)
        np.testing.assert_array_equal(gp.length_scale_, whole.length_scale_)
        np.testing.assert_array_equal(gp.y_std_, whole.y_std_)
        rows = W[:, region] > 0
        assert 40 <= rows.sum() < len(q) and gp.n_train_ == rows.sum()
        Z = unit_scaled(q, q)                                    # the map of all samples, not the region's
        match = np.argmin(np.sum((gp.X_train_[:, None, :] - Z[None]) ** 2, axis=2), axis=1)   # the region's order
        assert sorted(match.tolist()) == np.flatnonzero(rows).tolist()
        np.testing.assert_allclose(gp.X_train_, Z[match], rtol=0, atol=1e-14)
        alpha = dual_coefficients(Z[match], (y[match] - whole.y_mean_) / whole.y_std_, whole.amplitude_,
                                  whole.length_scale_, whole.noise_)
        np.testing.assert_allclose(gp.dual_coef_, alpha, rtol=1e-8, atol=1e-8 * np.abs(alpha).max())
    own = PartitionedErrorModel(partition=KMeansPartition(2), local=GaussianProcessErrorModel(
        inputs="joint", hyperparameters="per_region"), random_state=0).fit(q, y)
    assert not np.array_equal(own.models_[0].length_scale_, own.models_[1].length_scale_)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_a_region_overlap_widens_what_every_region_trains_on():
    """region_overlap f: a region's GP takes every sample within f times its kernel's reach (3 widths)."""
    import dataclasses

    from conftest import brute_force_weights

    q, y = IDENT.q_deg, IDENT.errors_mm
    sizes = []
    for f in (1.0, 1.3):
        model = PartitionedErrorModel(partition=KMeansPartition(3), local=GaussianProcessErrorModel(
            inputs="joint", region_overlap=f, restarts=0), random_state=0).fit(q, y)
        S = model._coordinates(q)[1]
        wide = dataclasses.replace(model.partition_, sigmas=model.partition_.sigmas * f)
        W = brute_force_weights(wide, S)
        r = np.sqrt(np.sum(((S[:, None, :] - model.partition_.centres[None]) / model.partition_.sigmas[None]) ** 2, 2))
        inside = r.min(axis=1) <= 2.5 * f            # where the cutoff is not moved outward: reach is 3 f widths
        np.testing.assert_array_equal((W > 0)[inside], (r < 3 * f)[inside])
        sizes.append([gp.n_train_ for gp in model.models_])
        assert sizes[-1] == (W > 0).sum(axis=0).tolist()
    assert all(b > a for a, b in zip(*sizes)) and max(sizes[1]) <= len(q)
    hard = PartitionedErrorModel(partition=KMeansPartition(3), blend="hard", local=GaussianProcessErrorModel(
        inputs="joint", region_overlap=1.3, restarts=0), random_state=0).fit(q, y)
    assert [gp.n_train_ for gp in hard.models_] == sizes[1]       # hard switching, but the same wide training sets


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_hyper_samples_search_a_subset_and_solve_on_all():
    q, y = IDENT.q_deg, IDENT.errors_mm
    full = GaussianProcessErrorModel(inputs="joint", random_state=3).fit(q, y)
    same = GaussianProcessErrorModel(inputs="joint", hyper_samples=85, random_state=3).fit(q, y)
    assert np.array_equal(same.dual_coef_, full.dual_coef_)
    assert same.length_scale_.tolist() == full.length_scale_.tolist()
    part = GaussianProcessErrorModel(inputs="joint", hyper_samples=40, random_state=3).fit(q, y)
    assert part.n_train_ == 85 and not np.allclose(part.length_scale_, full.length_scale_, rtol=1e-3)
    reference = GaussianProcessRegressor(part.sklearn_kernel(), normalize_y=True, optimizer=None)
    reference.fit(unit_scaled(q, q), y)
    np.testing.assert_allclose(part.log_marginal_likelihood_, reference.log_marginal_likelihood_value_, rtol=1e-9)
    np.testing.assert_allclose(part.predict(RECTANGLE.q_deg), reference.predict(unit_scaled(RECTANGLE.q_deg, q)),
                               rtol=0, atol=1e-10)
    # a partition's shared search on 30 samples keeps every input's extremes: the map is that of all samples
    model = PartitionedErrorModel(partition=KMeansPartition(2), local=GaussianProcessErrorModel(
        inputs="joint", hyper_samples=30, restarts=0), random_state=0).fit(q, y)
    lo, hi = q.min(axis=0), q.max(axis=0)
    moving = hi > lo
    for gp in model.models_:
        assert gp.input_map_.active.tolist() == moving.tolist()
        np.testing.assert_array_equal(gp.input_map_.centre[moving], ((hi + lo) / 2)[moving])
        np.testing.assert_array_equal(gp.input_map_.scale[moving], ((hi - lo) / 2)[moving])


def test_regions_sharing_hyperparameters_count_their_one_mean_once():
    """Regions of a shared search take the shared output mean (not their own): the partition's effective
    parameters are the regions' kernel traces plus one mean per output; with per-region searches, one
    mean per region and output."""
    q, y = IDENT.q_deg, IDENT.errors_mm
    for hyper, means in (("shared", 3), ("per_region", 6)):
        model = PartitionedErrorModel(partition=KMeansPartition(2), local=GaussianProcessErrorModel(
            inputs="joint", restarts=0, hyperparameters=hyper), random_state=0).fit(q, y)
        traces = sum(m.effective_parameters() - 3 for m in model.models_)
        assert model.effective_parameters() == pytest.approx(traces + means, rel=1e-12)
        same = np.array_equal(model.models_[0].y_mean_, model.models_[1].y_mean_)
        assert same == (hyper == "shared")


def smooth_errors(seed: int):
    """30 to 120 points in a cube with smooth errors (a sine of a random direction per axis) and noise, and 400
    fresh points of the same function (noise-free)."""
    rng = np.random.default_rng(seed)
    n, d = int(rng.integers(30, 120)), int(rng.integers(1, 4))
    X = rng.uniform(-1, 1, (n, d))
    W = rng.normal(0, 1.5, (d, 3))
    y = np.sin(X @ W) + rng.normal(0, rng.choice([0.05, 0.2, 0.5]), (n, 3))
    fresh = rng.uniform(-1, 1, (400, d))
    return X, y, fresh, np.sin(fresh @ W)


@pytest.mark.parametrize("seed", [15, 31, 57])
def test_the_search_escapes_the_short_length_scale_optimum_of_the_default_start(seed):
    X, y, fresh, truth = smooth_errors(seed)
    gp = GaussianProcessErrorModel(inputs="cartesian", restarts=0).fit(X, y)
    Z = gp.input_map_.transform(X)
    reference = GaussianProcessRegressor(gp._kernel(Z.shape[1]), normalize_y=True, n_restarts_optimizer=0).fit(Z, y)
    assert reference.kernel_.k1.k2.length_scale.max() < 0.05          # scikit-learn: a white-noise fit
    assert gp.log_marginal_likelihood_ > reference.log_marginal_likelihood_value_ + 10       # a better optimum
    left = np.sqrt(np.mean(np.sum((truth - gp.predict(fresh)) ** 2, axis=1)))
    left_reference = np.sqrt(np.mean(np.sum((truth - reference.predict(gp.input_map_.transform(fresh))) ** 2, axis=1)))
    assert left < 0.8 * left_reference


def test_a_cv_fold_whose_gp_found_another_optimum_is_noted(caplog):
    from partcal.study.fitting import _note_other_optima

    X, y, _, _ = smooth_errors(31)
    final = GaussianProcessErrorModel(inputs="cartesian", restarts=0).fit(X, y)
    Z = final.input_map_.transform(X)
    poor = GaussianProcessRegressor(final._kernel(Z.shape[1]), normalize_y=True, n_restarts_optimizer=0).fit(Z, y)
    params = poor.kernel_.get_params()
    fold = GaussianProcessErrorModel(inputs="cartesian", fixed_kernel={
        "input_map": final.input_map_, "amplitude": params["k1__k1__constant_value"],
        "length_scale": params["k1__k2__length_scale"], "noise": params["k2__noise_level"]}).fit(X, y)
    assert final.optimum_gap(final) is None
    ratio = np.exp(np.mean(np.log(fold.length_scale_ / final.length_scale_)))
    assert fold.optimum_gap(final) == (f"noise variance {fold.noise_:.3g} against {final.noise_:.3g}, length scales "
                                       f"x{ratio:.3g} (geometric mean)")
    fold.set_params(fixed_kernel=None)              # as a fold's own search would have left it
    with caplog.at_level("WARNING", logger="partcal.study.fitting"):
        _note_other_optima([final, fold], final)
    assert "cross-validation fold 2 of 2: its Gaussian process found another optimum than the final fit's" in caplog.text
    assert "fold 1 of 2" not in caplog.text
