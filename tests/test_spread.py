"""The standard deviation of every prediction: against textbook formulas and scikit-learn, known noise, growth
where a model extrapolates, calibration, model files old and new, the command line."""

import copy
import dataclasses
import json

import numpy as np
import pytest
from conftest import ROOT, partcal_cli

from partcal.errors import DataError, PartcalError
from partcal.models.gp import GaussianProcessErrorModel
from partcal.models.kinematic import KinematicModel
from partcal.models.partition import KMeansPartition
from partcal.models.partitioned import PartitionedErrorModel
from partcal.models.series import ErrorModel
from partcal.study.spread import calibrate_spread, contiguous_folds
from partcal.study.persist import save_model
from partcal.study.predictor import load_predictor

Z95 = 1.959963984540054


@pytest.fixture(scope="module")
def linear_data():
    rng = np.random.default_rng(3)
    X = rng.uniform(-500, 500, size=(40, 3))
    y = X @ np.array([[0.01, 0, 0.002], [0, -0.02, 0], [0.003, 0, 0.01]]) + rng.normal(0, 0.1, size=(40, 3))
    return X, y


def test_series_spread_is_the_least_squares_prediction_interval(linear_data):
    X, y = linear_data
    model = ErrorModel(inputs="cartesian", degree=1, solver="lstsq").fit(X, y)
    at = np.array([[0.0, 0, 0], [400.0, -300, 100], [3000.0, 0, 0]])
    mean, std = model.predict_with_std(at)
    A = np.hstack([np.ones((len(X), 1)), X])                      # the textbook: raw design, no scaling
    coef, sse, *_ = np.linalg.lstsq(A, y, rcond=None)
    sigma2 = sse / (len(X) - 4)
    a = np.hstack([np.ones((len(at), 1)), at])
    leverage = np.einsum("ij,jk,ik->i", a, np.linalg.inv(A.T @ A), a)
    np.testing.assert_allclose(mean, a @ coef, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(std, np.sqrt(np.outer(1 + leverage, sigma2)), rtol=1e-9)
    assert np.all(std[2] > 2 * std[0])                            # far outside the data: much wider


def test_gp_spread_is_scikit_learns_posterior(linear_data):
    from sklearn.gaussian_process import GaussianProcessRegressor

    X, y = linear_data
    model = GaussianProcessErrorModel(inputs="cartesian", restarts=0, random_state=0).fit(X, y)
    at = np.array([[0.0, 0, 0], [450.0, 450, -450], [1e8, 1e8, 1e8]])
    mean, std = model.predict_with_std(at)
    Z = model.input_map_.transform(X)
    reference = GaussianProcessRegressor(model.sklearn_kernel(), optimizer=None, alpha=1e-14).fit(Z, y[:, 0])
    _, sd = reference.predict(model.input_map_.transform(at), return_std=True)     # sd does not depend on y
    np.testing.assert_allclose(std, np.outer(sd, model.y_std_), rtol=1e-6)
    np.testing.assert_allclose(mean, model.predict(at))
    prior = np.sqrt(model.amplitude_ + model.noise_) * model.y_std_
    np.testing.assert_allclose(std[2], prior, rtol=1e-6)            # far away: the prior's spread


def test_one_region_blends_to_its_local_models_spread(linear_data):
    X, y = linear_data
    local = ErrorModel(inputs="cartesian", degree=1, solver="lstsq")
    one = PartitionedErrorModel(partition=KMeansPartition(n_regions=1, min_samples=5), local=local).fit(X, y)
    at = np.array([[10.0, 20, 30], [600.0, 0, 0]])
    np.testing.assert_allclose(one.predict_with_std(at)[1], local.fit(X, y).predict_with_std(at)[1], rtol=1e-9)
    two = PartitionedErrorModel(partition=KMeansPartition(n_regions=2, min_samples=5), local=local,
                                random_state=0).fit(X, y)
    mean, std = two.predict_with_std(at)
    np.testing.assert_allclose(mean, two.predict(at), rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(std)) and np.all(std > 0)


@pytest.fixture(scope="module")
def noisy_sk120():
    """The virtual SK120's geometry (no compliance, gears or tracker scale), its arm scattering 0.05 mm per axis."""
    from partcal.data.simulate import load_study, sample_configurations

    study = load_study(ROOT / "configs" / "sk120_virtual.yaml")
    virtual = dataclasses.replace(study.robot, compliance=(), gear=(), tracker_scale=0.0, repeatability_mm=0.05)
    rng = np.random.default_rng(0)

    def draw(n, ranges):
        q = sample_configurations(virtual.nominal, n, ranges, study.fixed_deg, rng)
        return q, virtual.measure(q, rng) - virtual.nominal.positions(q)

    return virtual, draw, study.ranges_deg


def test_kinematic_spread_covers_95_percent_of_new_noisy_poses(noisy_sk120):
    virtual, draw, ranges = noisy_sk120
    q, e = draw(150, ranges)
    model = KinematicModel(robot=virtual.nominal).fit(q, e)
    q_new, e_new = draw(1000, ranges)
    mean, std = model.predict_with_std(q_new)
    share = np.mean(np.abs(e_new - mean) <= Z95 * std)
    assert 0.93 <= share <= 0.97, share
    assert np.median(std) == pytest.approx(0.05, rel=0.1)          # mostly the known scatter
    narrow = {1: (-20, 20), 2: (-140, -120), 3: (-185, -165), 6: (-30, 30)}
    model = KinematicModel(robot=virtual.nominal).fit(*draw(60, narrow))
    inside = model.predict_with_std(draw(50, narrow)[0])[1]
    outside = model.predict_with_std(draw(50, {1: (50, 60), 2: (-160, -150), 3: (-205, -195)})[0])[1]
    assert np.median(outside) > 1.5 * np.median(inside)            # beyond the joint ranges of the data


def test_prior_variance_is_the_unabsorbed_part_of_j_p_jt():
    from partcal.calibration.fit import prior_variance

    J_i = np.array([[1.0, 0.0], [0.0, 2.0], [1.0, 1.0]])        # 3 outputs, 2 identified parameters
    J_u = np.array([[1.0, 3.0], [0.5, 0.0], [2.0, 1.0]])        # 2 parameters the data do not identify
    A = np.array([[1.0, 0.0], [0.0, 0.5]])                      # how the fit absorbed them
    p = np.array([0.5, 0.2])
    # by hand: J = J_u - J_i A = [[0, 3], [0.5, -1], [1, 0.5]]; diag(J diag(p^2) J^T)
    expected = [0 * 0.25 + 9 * 0.04, 0.25 * 0.25 + 1 * 0.04, 1 * 0.25 + 0.25 * 0.04]
    np.testing.assert_allclose(prior_variance(J_i, J_u, A, p), expected, rtol=1e-12)
    np.testing.assert_allclose(prior_variance(np.zeros((3, 0)), J_u, np.zeros((0, 2)), p),
                               np.diag(J_u @ np.diag(p**2) @ J_u.T), rtol=1e-12)   # nothing absorbs: J_u P J_u^T


def _fd_jacobian(nominal, values, q, h=1e-5):
    """d positions / d values by central differences, (3 n, P): the forward kinematics alone."""
    from partcal.calibration.parameters import robot_with

    cols = []
    for k in range(values.size):
        step = np.zeros_like(values)
        step[k] = h
        cols.append((robot_with(nominal, values + step).positions(q) - robot_with(nominal, values - step).positions(q)
                     ).ravel() / (2 * h))
    return np.column_stack(cols)


def test_unidentified_parameters_add_their_plausible_error_where_the_data_did_not_go(noisy_sk120):
    from partcal.calibration.parameters import PLAUSIBLE_ERROR
    from partcal.data.simulate import sample_configurations

    virtual, draw, ranges = noisy_sk120
    q, e = draw(150, ranges)                                   # the paper's poses: wrist held at q4 = q5 = 0
    model = KinematicModel(robot=virtual.nominal).fit(q, e)
    table = model.identification_
    free = np.flatnonzero(np.array(table.status) == "identified")
    prior = np.flatnonzero([s == "unidentifiable" for s in table.status])
    assert {"theta[4]", "theta[5]"} <= {table.names[k] for k in prior}      # the held wrist's joint offsets
    np.testing.assert_array_equal(table.prior_std[prior], [PLAUSIBLE_ERROR[table.units[k]] for k in prior])
    assert np.isnan(np.delete(table.prior_std, prior)).all()
    turned = {**ranges, 4: (-90, 90), 5: (-60, 60)}
    rng = np.random.default_rng(7)
    q_new = sample_configurations(virtual.nominal, 20, turned, {}, rng)
    # by hand: J = J_u - J_i A at the new poses, A from the Jacobian on the data (finite differences)
    train, new = _fd_jacobian(virtual.nominal, table.value, q), _fd_jacobian(virtual.nominal, table.value, q_new)
    A = np.linalg.lstsq(train[:, free], train[:, prior], rcond=None)[0]
    J = new[:, prior] - new[:, free] @ A
    by_hand = np.einsum("ij,j,ij->i", J, table.prior_std[prior] ** 2, J).reshape(-1, 3)
    std = model.predict_with_std(q_new)[1]
    model.identification_ = dataclasses.replace(table, prior_std=None, prior_absorbed=None)   # as an older file
    without = model.predict_with_std(q_new)[1]
    np.testing.assert_allclose(std**2 - without**2, by_hand, rtol=1e-4, atol=1e-8)
    model.identification_ = table
    q_held, e_held = draw(300, ranges)
    q_turned = sample_configurations(virtual.nominal, 300, turned, {}, rng)
    e_turned = virtual.measure(q_turned, rng) - virtual.nominal.positions(q_turned)
    for q_at, e_at in ((q_held, e_held), (q_turned, e_turned)):    # the interval holds on both
        mean, std = model.predict_with_std(q_at)
        assert 0.92 <= np.mean(np.abs(e_at - mean) <= Z95 * std) <= 0.99
    assert np.median(model.predict_with_std(q_turned)[1]) > 10 * np.median(model.predict_with_std(q_held)[1])


def test_calibration_scales_the_spread_to_held_out_blocks(linear_data):
    X, y = linear_data
    assert [t.tolist() for _, t in contiguous_folds(5, 2)] == [[0, 1, 2], [3, 4]]
    stationary = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y, folds=4, depth=False)
    assert np.all((stationary.spread_scale_ > 0.6) & (stationary.spread_scale_ < 1.6))
    drift = y + np.linspace(0, 1.0, len(y))[:, None]                # a session that drifts by 1 mm
    drifting = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, drift, folds=4, depth=False)
    assert np.all(drifting.spread_scale_ > 1.2 * stationary.spread_scale_)   # wider than its own fit says
    from partcal.study.config import SpreadOptions
    from partcal.study.spread import forward_folds, run_spread

    assert [(a.tolist(), b.tolist()) for a, b in forward_folds(5, 2)] == [([0, 1, 2], [3, 4])]
    later = run_spread(SpreadOptions("forward", folds=4, depth=False),
                       ErrorModel(inputs="cartesian", solver="lstsq").fit(X, drift), X, drift, cv_folds=[]).scale
    assert np.all(later > drifting.spread_scale_)          # predicted only from the past, the drift shows more
    own = ErrorModel(inputs="cartesian", solver="lstsq").fit(X, drift).predict_with_std(X)[1]
    np.testing.assert_allclose(drifting.predict_with_std(X)[1], own * drifting.spread_scale_)


def test_scale_from_scores_is_the_quantile_over_the_normal_one():
    from scipy.stats import norm

    from partcal.study.spread import scale_from_scores

    rng = np.random.default_rng(11)
    scores = np.abs(rng.normal(0, 1, (200_000, 2))) * [1.0, 2.5]      # a spread right, and one 2.5 times too narrow
    np.testing.assert_allclose(scale_from_scores(scores, 0.95), [1.0, 2.5], rtol=0.02)
    few = np.array([[0.1, np.nan], [0.2, np.nan], [0.3, np.nan], [0.4, np.nan], [0.5, np.inf]])
    np.testing.assert_allclose(scale_from_scores(few, 0.9), [np.quantile([0.1, 0.2, 0.3, 0.4, 0.5], 0.9)
                                                             / norm.ppf(0.95), 1.0])   # no finite score: 1


def test_folds_calibration_reads_the_cross_validation_fits_as_a_refit_would(linear_data):
    from partcal.study.config import SpreadOptions
    from partcal.study.selection import held_out_residuals
    from partcal.study.spread import run_spread

    X, y = linear_data
    model = ErrorModel(inputs="cartesian", solver="lstsq")
    folds = contiguous_folds(len(X), 4)[::-1]                             # any folds: the run's
    fits: list = []
    held_out_residuals(model, X, y, folds, fitted=fits)
    fitted = run_spread(SpreadOptions(calibration="folds"), model.fit(X, y), X, y, cv_folds=folds, fold_fits=fits)
    refit = run_spread(SpreadOptions(calibration="folds"), model, X, y, cv_folds=folds)
    np.testing.assert_allclose(fitted.scale, refit.scale, rtol=1e-12)
    assert (fitted.depth is None) == (refit.depth is None)
    contiguous = run_spread(SpreadOptions("contiguous", folds=4), model, X, y, cv_folds=folds)
    alone = calibrate_spread(clone_of(model), X, y, folds=4)
    np.testing.assert_allclose(contiguous.scale, alone.spread_scale_, rtol=1e-12)
    assert run_spread(SpreadOptions(calibration="none"), model, X, y, cv_folds=folds) is None


def clone_of(model):
    from sklearn.base import clone

    return clone(model)


def test_spread_key_of_a_run_config(tmp_path):
    from partcal.errors import ConfigError
    from partcal.study.config import SpreadOptions, load_config

    data = ROOT / "data" / "sk120"
    base = (f"name: s\ndata:\n  identification: {data / 'identification.csv'}\n"
            "models:\n  - {name: a, degree: 1, solver: {method: lstsq}}\n")
    path = tmp_path / "run.yaml"
    path.write_text(base)
    assert load_config(path).spread == SpreadOptions("forward", 0.95, 5)
    path.write_text(base + "spread: {calibration: folds, coverage: 0.9}\n")
    assert load_config(path).spread == SpreadOptions("folds", 0.9, 5)
    path.write_text(base + "spread: {depth: false}\n")
    assert load_config(path).spread == SpreadOptions("forward", 0.95, 5, depth=False)
    for bad, match in (("{calibration: blocks}", r"spread.calibration \(line 6\): must be one of .*got 'blocks'"),
                       ("{coverage: 1.0}", r"spread.coverage \(line 6\): must be a number in \[0.5, 1\)"),
                       ("{folds: 1}", r"spread.folds \(line 6\): must be .*got 1"),
                       ("{fold: 3}", r"spread.fold .*did you mean 'folds'"),
                       ("{calibration: none, folds: 7}",
                        r"spread.folds \(line 6\): applies to calibration: forward or contiguous only"),
                       ("{depth: 1}", r"spread.depth \(line 6\): must be true or false"),
                       ("{calibration: none, depth: false}",
                        r"spread.depth \(line 6\): applies to a calibrated spread only")):
        path.write_text(base + f"spread: {bad}\n")
        with pytest.raises(ConfigError, match=match):
            load_config(path)


def test_model_files_carry_the_spread_and_old_ones_say_they_have_none(tmp_path, linear_data, noisy_sk120):
    X, y = linear_data
    virtual, draw, ranges = noisy_sk120
    series = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y, folds=4)
    q, e = draw(60, ranges)
    kinematic = KinematicModel(robot=virtual.nominal).fit(q, e)
    for model, X_in, key, name in ((series, X, "positions", "series"), (kinematic, q, "joints", "dh")):
        path = tmp_path / f"{name}.json"
        save_model(model, path, name=name)
        mean, std = load_predictor(path).predict(**{key: X_in}, return_std=True)
        expected = model.predict_with_std(X_in)
        np.testing.assert_allclose(mean, expected[0], rtol=1e-12)
        np.testing.assert_allclose(std, expected[1], rtol=1e-9)
        doc = json.loads(path.read_text())                    # as written before partcal kept the spread
        del doc["checksum"]
        doc.pop("spread_scale", None)
        for section in (doc["model"], doc["model"].get("identification", {})):
            for field in ("coef_covariance", "noise_var", "covariance", "sigma_mm"):
                section.pop(field, None)
        path.write_text(json.dumps(doc))
        old = load_predictor(path)
        np.testing.assert_allclose(old.predict(**{key: X_in}), expected[0], rtol=1e-12)
        with pytest.raises(DataError, match=rf"^model '{name}': this .* file was written before partcal kept .*: "
                                            r"fit it again"):
            old.predict(**{key: X_in}, return_std=True)


def test_kinematic_files_before_the_prior_load_with_the_identified_parameters_spread(tmp_path, noisy_sk120):
    virtual, draw, ranges = noisy_sk120
    q, e = draw(60, ranges)
    model = KinematicModel(robot=virtual.nominal).fit(q, e)
    path = tmp_path / "dh.json"
    save_model(model, path, name="dh")
    doc = json.loads(path.read_text())
    assert doc["model"]["identification"]["prior_std"].count(None) < len(doc["model"]["identification"]["names"])
    del doc["checksum"], doc["model"]["identification"]["prior_std"], doc["model"]["identification"]["prior_absorbed"]
    path.write_text(json.dumps(doc))
    q_turned = q.copy()
    q_turned[:, 3:5] = [40.0, 30.0]
    std = load_predictor(path).predict(joints=q_turned, return_std=True)[1]
    model.identification_ = dataclasses.replace(model.identification_, prior_std=None, prior_absorbed=None)
    np.testing.assert_allclose(std, model.predict_with_std(q_turned)[1], rtol=1e-9)


def test_predict_std_adds_sd_columns_and_compensate_std_the_expected_residual(tmp_path, linear_data):
    X, y = linear_data
    model = ErrorModel(inputs="cartesian", degree=1, solver="lstsq").fit(X, y)
    path = tmp_path / "m.json"
    save_model(model, path, name="m")
    points = tmp_path / "p.csv"
    points.write_text("x,y,z\n0,0,0\n400,-300,100\n")
    res = partcal_cli("predict", str(path), str(points), "-o", str(tmp_path / "out.csv"), "--std")
    assert res.returncode == 0, res.stderr
    rows = (tmp_path / "out.csv").read_text().splitlines()
    assert rows[0] == "x,y,z,dx,dy,dz,sdx,sdy,sdz"
    values = np.array([[float(v) for v in r.split(",")] for r in rows[1:]])
    np.testing.assert_allclose(values[:, 6:], model.predict_with_std(values[:, :3])[1], atol=2e-6)
    res = partcal_cli("compensate", str(path), str(points), "-o", str(tmp_path / "cmd.csv"), "--std")
    assert res.returncode == 0, res.stderr
    rows = (tmp_path / "cmd.csv").read_text().splitlines()
    assert rows[0] == "x,y,z,x_cmd,y_cmd,z_cmd,dx_left,dy_left,dz_left,sdx,sdy,sdz,miss_mm,converged,reason"
    values = np.array([[float(v) for v in r.split(",")[:-2]] for r in rows[1:]])
    assert np.abs(values[:, 6:9]).max() < 1e-3                               # converged: nothing left expected
    np.testing.assert_allclose(values[:, 9:12], model.predict_with_std(values[:, 3:6])[1], atol=2e-6)


def test_forward_calibration_leaves_out_the_blocks_a_model_cannot_be_fitted_before(linear_data):
    from partcal.study.config import SpreadOptions
    from partcal.study.spread import forward_folds, held_out_scores, run_spread, scale_from_scores

    X, y = linear_data
    model = PartitionedErrorModel(partition=KMeansPartition(n_regions=1, min_samples=15),
                                  local=ErrorModel(inputs="cartesian", degree=1, solver="lstsq")).fit(X, y)
    folds = forward_folds(len(X), 4)                # trained on 10, 20 and 30 rows: the first is refused
    with pytest.raises(PartcalError, match="a region needs at least 15 samples .*; got 10 samples in all"):
        clone_of(model).fit(X[folds[0][0]], y[folds[0][0]])
    scale = run_spread(SpreadOptions("forward", folds=4, depth=False), model, X, y, cv_folds=[]).scale
    np.testing.assert_allclose(scale, scale_from_scores(held_out_scores(model, X, y, folds[1:]), 0.95), rtol=1e-12)


class _WarnsOnFewRows:
    """The mean and scatter of the training errors; a partcal warning when fitted on fewer than ``below`` rows."""

    def __init__(self, below=25):
        self.below = below

    def get_params(self, deep=True):
        return {"below": self.below}

    def set_params(self, **params):
        self.below = params.get("below", self.below)
        return self

    def fit(self, X, y):
        import logging
        if len(X) < self.below:
            logging.getLogger("partcal.models.fake").warning("fitted on %d rows", len(X))
        self.mean_, self.std_ = y.mean(axis=0), y.std(axis=0)
        return self

    def predict_with_std(self, X):
        return np.tile(self.mean_, (len(X), 1)), np.tile(self.std_, (len(X), 1))


def test_the_spread_calibrations_fits_on_part_of_the_rows_warn_once_naming_the_calibration(caplog):
    from partcal.study.spread import forward_folds, held_out_scores

    rng = np.random.default_rng(3)
    X, y = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    folds = forward_folds(40, 4)                  # fitted on 10, 20 and 30 rows: the first two warn
    with caplog.at_level("WARNING", logger="partcal"):
        scores = held_out_scores(_WarnsOnFewRows(below=25), X, y, folds)
    said = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert said == ["spread calibration: its 3 fits on part of the identification rows gave 2 warnings (theirs, "
                    "not those of the model fitted on all the rows), the first: fitted on 10 rows"]
    expected = np.full_like(y, np.nan)
    for n in (10, 20, 30):                        # each block of 10 held out from the mean of the rows before it
        expected[n:n + 10] = np.abs(y[n:n + 10] - y[:n].mean(axis=0)) / y[:n].std(axis=0)
    np.testing.assert_allclose(scores, expected, rtol=1e-12)


def test_metrics_name_the_blocks_cut_when_folds_exceed_the_rows(tmp_path):
    from partcal.study.config import load_config
    from partcal.study.outputs import metrics_document
    from partcal.study.runner import run

    rows = (ROOT / "data" / "sk120" / "identification.csv").read_text().splitlines()
    data = [r for r in rows if not r.startswith("#")]
    (tmp_path / "ident.csv").write_text("\n".join(data[:13]) + "\n")       # header and 12 poses
    (tmp_path / "run.yaml").write_text(
        "name: s\ncv_folds: 3\ndata:\n  identification: ident.csv\nspread: {folds: 50}\n"
        "models:\n  - {name: a, degree: 1, solver: {method: lstsq}}\n")
    result = run(load_config(tmp_path / "run.yaml"))
    calibration = metrics_document(result)["models"]["a"]["spread_calibration"]
    assert (calibration["method"], calibration["folds"]) == ("forward", 12)     # one row a block, not 50
    from partcal.report import spread_rows
    assert "later blocks (12 contiguous blocks" in spread_rows(result)["calibration"]


def test_forward_calibration_leaves_out_a_fit_on_as_many_rows_as_terms():
    from scipy.stats import norm

    from partcal.study.config import SpreadOptions
    from partcal.study.spread import run_spread

    rng = np.random.default_rng(5)
    X = rng.uniform(-500.0, 500.0, (6, 3))
    y = X @ rng.normal(size=(3, 3)) * 1e-3 + rng.normal(0.0, 0.1, (6, 3))
    model = ErrorModel(inputs="cartesian", degree=1, solver="lstsq")
    saturated = clone_of(model).fit(X[:4], y[:4])              # 4 rows, 4 terms: residuals of rounding alone
    assert "no more samples than its 4 terms" in saturated.spread_problem()
    # blocks [0 1] [2] [3] [4] [5]: the fits on 2 and 3 rows are refused, the one on 4 has no spread; the
    # fit on rows 0..4 predicts row 5: its score by hand, least squares on [1, x, y, z]
    phi = np.column_stack([np.ones(6), X])
    coef, rss, *_ = np.linalg.lstsq(phi[:5], y[:5], rcond=None)
    leverage = phi[5] @ np.linalg.inv(phi[:5].T @ phi[:5]) @ phi[5]
    std = np.sqrt((1.0 + leverage) * rss / (5 - 4))
    expected = np.abs(y[5] - phi[5] @ coef) / std / norm.ppf(0.975)
    scale = run_spread(SpreadOptions("forward", folds=5, depth=False), model.fit(X, y), X, y, cv_folds=[]).scale
    np.testing.assert_allclose(scale, expected, rtol=1e-8)


# ---------------------------------------------------------------- the spread's growth with the inputs' depth
def test_depth_is_the_mahalanobis_distance_with_held_inputs_at_the_smallest_moved_scatter():
    from partcal.models.depth import DepthSpread

    rng = np.random.default_rng(8)
    X = np.column_stack([rng.normal(10, 3, 200), rng.normal(-5, 1, 200), np.full(200, 7.0)])
    X[:, 1] += 0.5 * X[:, 0]                                   # correlated inputs; the third held at 7
    at = np.array([[10.0, 0.0, 7.0], [16.0, 0.0, 7.0], [10.0, 0.0, 9.0]])
    cov = np.cov(X, rowvar=False, bias=True)
    cov[2, 2] = min(X[:, 0].std(), X[:, 1].std()) ** 2          # the held input: the smallest moved scatter
    expected = np.sqrt(np.einsum("ij,jk,ik->i", at - X.mean(0), np.linalg.inv(cov), at - X.mean(0)))
    depth = DepthSpread.of_inputs(X, beta=0.5)
    np.testing.assert_allclose(depth.depth(at), expected, rtol=1e-9)
    np.testing.assert_allclose(depth.factor(at), np.sqrt(1 + 0.5 * expected ** 2), rtol=1e-9)
    assert DepthSpread.of_inputs(X[:1]) is None


def _heteroscedastic(n, rng, growth=1.0):
    """Inputs in a box and errors of a plane plus noise whose scatter grows with the distance from the middle."""
    X = rng.uniform(-300.0, 300.0, (n, 3))
    r = np.linalg.norm(X / 173.2, axis=1)                        # about the depth: the box's sd is 173.2
    noise = rng.normal(size=(n, 3)) * (0.05 * np.sqrt(1 + growth * r ** 2))[:, None]
    return X, X @ np.array([[0.01, 0, 0.002], [0, -0.02, 0], [0.003, 0, 0.01]]) + noise


def test_depth_grows_the_spread_where_held_out_residuals_grow_and_covers_middle_and_edge():
    from partcal.study.spread import depth_from_scores, held_out_depths

    rng = np.random.default_rng(21)
    X, y = _heteroscedastic(600, rng)
    flat = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y, folds=5, depth=False)
    grown = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y, folds=5)
    assert flat.spread_depth_ is None and 0.3 < grown.spread_depth_.beta <= 4.0
    truth = 1.0                                    # the noise's own growth, in the box's standard deviations
    assert grown.spread_depth_.beta == pytest.approx(truth, rel=0.3)
    X_new, y_new = _heteroscedastic(20_000, rng)
    depth = np.linalg.norm(X_new / 173.2, axis=1)
    middle, edge = depth < 0.7, depth > 1.6
    cover = {}
    for name, model in (("flat", flat), ("grown", grown)):
        mean, std = model.predict_with_std(X_new)
        inside = np.abs(y_new - mean) <= Z95 * std
        cover[name] = (inside[middle].mean(), inside[edge].mean())
    assert cover["flat"][0] > 0.99 and cover["flat"][1] < 0.935        # a spread the same everywhere: both wrong
    assert 0.93 <= cover["grown"][0] <= 0.97 and 0.93 <= cover["grown"][1] <= 0.97
    # homoscedastic residuals: no growth
    X0 = rng.uniform(-300.0, 300.0, (600, 3))
    scores = np.abs(rng.normal(size=(600, 3)))
    assert depth_from_scores(scores, held_out_depths(X0, contiguous_folds(600, 5)), 0.95)[0] == 0.0


def test_a_model_file_carries_the_depth_and_refuses_a_bad_one(tmp_path):
    from partcal.errors import ModelFileError

    rng = np.random.default_rng(22)
    X, y = _heteroscedastic(300, rng)
    model = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y, folds=5)
    assert model.spread_depth_ is not None
    path = tmp_path / "m.json"
    save_model(model, path, name="m")
    at = np.array([[0.0, 0, 0], [300.0, -300, 300], [2000.0, 0, 0]])
    mean, std = load_predictor(path).predict(positions=at, return_std=True)
    np.testing.assert_allclose(std, model.predict_with_std(at)[1], rtol=1e-12)
    assert std[2, 0] > 5 * std[0, 0]                                   # far out: far wider
    doc = json.loads(path.read_text())
    del doc["checksum"]
    for field, value, match in (
            ("beta", -1.0, r"field 'spread_depth.beta': expected a finite number in \[0.0, 4.0\]; got -1.0"),
            ("whiten", [[1.0]], r"field 'spread_depth.whiten': expected shape \(3, 3\); got shape \(1, 1\)")):
        bad = json.loads(json.dumps(doc))
        bad["spread_depth"][field] = value
        path.write_text(json.dumps(bad))
        with pytest.raises(ModelFileError, match=match):
            load_predictor(path)


def test_a_hybrids_kinematic_part_counts_as_noise_only_what_its_residual_model_leaves(tmp_path):
    from partcal.data.simulate import load_study, sample_configurations

    study = load_study(ROOT / "configs" / "sk120_virtual.yaml")          # compliance and gears: DH leaves 0.5 mm
    virtual, rng = study.robot, np.random.default_rng(0)

    def draw(n):
        q = sample_configurations(virtual.nominal, n, study.ranges_deg, study.fixed_deg, rng)
        return q, virtual.measure(q, rng) - virtual.nominal.positions(q)

    q, e = draw(85)
    q_new, e_new = draw(1000)                                           # new poses like the data
    alone = KinematicModel(robot=virtual.nominal).fit(q, e)
    left = e - alone.predict(q)                                         # the DH fit's residuals, by hand
    dh_variance = np.sum(left ** 2) / (left.size - alone.identification_.status.count("identified"))
    hybrid = KinematicModel(robot=virtual.nominal, residual=ErrorModel(inputs="joint", degree=2, solver="lstsq"),
                            random_state=0).fit(q, e)
    resid_variance = np.mean(hybrid.residual_.predict_with_std(q)[1] ** 2)
    assert hybrid.covariance_scale_ == pytest.approx(resid_variance / dh_variance, rel=1e-6)
    assert alone.covariance_scale_ == 1.0 and hybrid.covariance_scale_ < 0.3
    mean, std = hybrid.predict_with_std(q_new)
    counted_twice = copy.copy(hybrid)
    counted_twice.covariance_scale_ = 1.0
    assert 0.93 <= np.mean(np.abs(e_new - mean) <= Z95 * std) <= 0.985
    assert np.mean(np.abs(e_new - mean) <= Z95 * counted_twice.predict_with_std(q_new)[1]) > 0.985
    path = tmp_path / "hybrid.json"
    save_model(hybrid, path, name="hybrid")
    assert json.loads(path.read_text())["model"]["covariance_scale"] == pytest.approx(hybrid.covariance_scale_)
    np.testing.assert_allclose(load_predictor(path).predict(joints=q_new, return_std=True)[1], std, rtol=1e-9)


def test_a_data_model_widens_where_a_joint_its_data_held_still_turns():
    from partcal.data.simulate import load_study, sample_configurations

    study = load_study(ROOT / "configs" / "sk120_virtual.yaml")
    virtual, rng = study.robot, np.random.default_rng(4)

    def draw(n, ranges, fixed):
        q = sample_configurations(virtual.nominal, n, ranges, fixed, rng)
        return q, virtual.measure(q, rng) - virtual.nominal.positions(q)

    q, e = draw(85, study.ranges_deg, study.fixed_deg)                  # the wrist held at q4 = q5 = 0
    q_turned, e_turned = draw(300, {**study.ranges_deg, 4: (-90, 90), 5: (-60, 60)}, {})
    gp = GaussianProcessErrorModel(inputs="joint", restarts=0, random_state=0)
    own = clone_of(gp).fit(q, e)
    model = calibrate_spread(gp, q, e, folds=5)
    # by hand: the training errors' variance, reached as the held joints move a few of the least moved joint's sd
    length = q[:, [0, 1, 2, 5]].std(axis=0).min()
    moved = np.sum((q_turned[:, 3:5] / length) ** 2, axis=1)
    prior = (1.0 - np.exp(-0.5 * moved))[:, None] * e.var(axis=0)
    np.testing.assert_allclose(model.spread_depth_.held_prior(q_turned), prior, rtol=1e-9)
    mean, std = model.predict_with_std(q_turned)
    growth = model.spread_depth_.factor(q_turned)[:, None]
    calibrated_alone = model.std_validated(q_turned)[1] * model.spread_scale_ * growth
    np.testing.assert_allclose(std, np.sqrt(calibrated_alone ** 2 + prior), rtol=1e-9)
    assert np.mean(np.abs(e_turned - own.predict(q_turned)) <= Z95 * own.predict_with_std(q_turned)[1]) < 0.1
    assert np.mean(np.abs(e_turned - mean) <= Z95 * std) > 0.9
    held = model.predict_with_std(q[:5])[1]                            # where the data held them: no prior
    np.testing.assert_allclose(held, model.std_validated(q[:5])[1] * model.spread_scale_
                               * model.spread_depth_.factor(q[:5])[:, None], rtol=1e-12)
    kinematic = calibrate_spread(KinematicModel(robot=virtual.nominal), q, e, folds=5)   # has its own prior
    assert kinematic.spread_depth_ is None or kinematic.spread_depth_.held_variance is None


def test_a_joint_that_jitters_in_the_data_is_held_for_the_depth_and_its_prior():
    from partcal.models.depth import DepthSpread

    rng = np.random.default_rng(9)
    X = np.column_stack([rng.uniform(-60, 60, 100), rng.uniform(-160, -100, 100), np.zeros(100)])
    y = rng.normal(0, 2.0, (100, 3))
    jitter = X.copy()
    jitter[:, 2] = rng.uniform(-0.004, 0.004, 100)                  # within the data layer's 0.01 degree
    at = np.array([[0.0, -130.0, 0.0], [0.0, -130.0, 30.0]])
    exact, jittered = DepthSpread.of_inputs(X, 0.5, y), DepthSpread.of_inputs(jitter, 0.5, y)
    assert jittered.held.tolist() == [False, False, True]
    np.testing.assert_allclose(jittered.depth(at), exact.depth(at), rtol=1e-3, atol=1e-3)
    np.testing.assert_allclose(jittered.held_prior(at), exact.held_prior(at), rtol=1e-3, atol=1e-6)
    assert jittered.depth(at)[1] < 10                    # 30 degrees in the smallest moved sd (17), not in 0.002


def test_inputs_the_data_moved_together_count_as_held_not_as_a_direction_of_no_scatter():
    from partcal.models.depth import DepthSpread

    rng = np.random.default_rng(12)
    q = rng.uniform(-60, 60, (85, 3))
    coupled = np.column_stack([q, q[:, 0]])                  # q4 follows q1 in every pose
    depth = DepthSpread.of_inputs(coupled)
    step = coupled[:1].copy()
    step[0, 3] += 1.0                                         # one degree off the coupling
    assert depth.depth(step)[0] - depth.depth(coupled[:1])[0] < 1.0 / q.std(axis=0).min() + 1e-9
    plane = rng.uniform(0, 1000, (100, 2))
    xyz = np.column_stack([plane, 1000.0 - plane[:, 0]])     # a tilted plane: x + z constant
    off = np.array([[500.0, 500.0, 510.0]])                  # 10 mm off it, in its middle
    assert DepthSpread.of_inputs(xyz).depth(off)[0] < 0.1
    nearly = xyz + rng.normal(0, 0.5, xyz.shape) * [1, 0, 1]  # x + z scatters by 0.7 mm only: at least l / 10
    assert DepthSpread.of_inputs(nearly).depth(off)[0] < 10 / (0.1 * xyz.std(axis=0).min()) + 1.0


def test_a_one_output_model_calibrates_as_a_column_does(linear_data):
    X, y = linear_data
    flat = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y[:, 0], folds=4)
    column = calibrate_spread(ErrorModel(inputs="cartesian", solver="lstsq"), X, y[:, :1], folds=4)
    np.testing.assert_allclose(flat.spread_scale_, column.spread_scale_, rtol=1e-12)


def test_bad_spread_fields_of_a_model_file_are_refused_naming_the_field(tmp_path, noisy_sk120):
    from partcal.errors import ModelFileError

    virtual, draw, ranges = noisy_sk120
    q, e = draw(60, ranges)
    for model, name, edit, match in (
            (KinematicModel(robot=virtual.nominal).fit(q, e), "dh", lambda d: d["model"].update(covariance_scale=0.5),
             r"field 'model.covariance_scale': a model without a residual model .*got 0.5"),
            (calibrate_spread(KinematicModel(robot=virtual.nominal), q, e, folds=4), "dh2",
             lambda d: d.update(spread_depth={"centre": [0.0] * 6, "whiten": np.eye(6).tolist(), "beta": 0.0,
                                              "held": [False] * 6, "length": 1.0, "held_variance": [1.0] * 3}),
             r"field 'spread_depth.held_variance': a kinematic model has its own prior"),
            (calibrate_spread(ErrorModel(inputs="joint", solver="lstsq"), q, e, folds=4), "sdp",
             lambda d: d.update(spread_depth={"centre": [0.0] * 6, "whiten": np.eye(6).tolist(), "beta": 0.0,
                                              "held": None, "length": 1.0, "held_variance": [1.0] * 3}),
             r"field 'spread_depth.held': the held inputs' prior .*needs")):
        path = tmp_path / f"{name}.json"
        save_model(model, path, name=name)
        doc = json.loads(path.read_text())
        del doc["checksum"]
        edit(doc)
        path.write_text(json.dumps(doc))
        with pytest.raises(ModelFileError, match=match):
            load_predictor(path)


def test_predict_refuses_a_spread_beyond_meaning_and_writes_nothing(tmp_path, noisy_sk120):
    virtual, draw, ranges = noisy_sk120
    q, e = draw(60, ranges)
    model = calibrate_spread(ErrorModel(inputs="joint", solver="lstsq"), q, e, folds=4)
    path = tmp_path / "m.json"
    save_model(model, path, name="m", robot=virtual.nominal)
    doc = json.loads(path.read_text())
    del doc["checksum"]
    doc["spread_depth"] = {"centre": q.mean(axis=0).tolist(), "whiten": (np.eye(6) * 1e200).tolist(), "beta": 4.0}
    path.write_text(json.dumps(doc))
    points = tmp_path / "q.csv"
    points.write_text("q1,q2,q3,q4,q5,q6\n" + ",".join(f"{v:.6f}" for v in q[0] + 1.0) + "\n")
    out = tmp_path / "out.csv"
    assert partcal_cli("predict", str(path), str(points), "-o", str(out)).returncode == 0   # the mean is fine
    out.unlink()
    res = partcal_cli("predict", str(path), str(points), "-o", str(out), "--std")
    assert res.returncode == 2 and res.stderr.count("\n") == 1 and not out.exists()
    assert "data row 1: the standard deviation of the predicted error is not finite" in res.stderr
