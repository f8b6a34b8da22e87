"""Weighted and robust kinematic identification (issue 41): each against values computed independently."""

import json

import numpy as np
import pytest
from conftest import ROOT
from scipy.optimize import least_squares

from partcal import KinematicModel, PartcalError, read_measurements
from partcal.data.formats import MeasurementFormat, RowSelection
from partcal.robot.rotations import matrix_from_rpy_deg
from partcal.study.config import load_config
from partcal.report import render_report
from partcal.study.outputs import write_run
from partcal.study.runner import run
from partcal.data.simulate import load_study
from partcal.study.persist import load_model, save_model
from partcal.metrics import loss_weights
from partcal.calibration.identification import identify
from partcal.calibration.parameters import robot_with


@pytest.fixture(scope="module")
def ur10():
    """The virtual UR10 with tilted axes, 120 random poses and their true positions."""
    study = load_study(ROOT / "configs" / "ur10_tilts_virtual.yaml")
    rng = np.random.default_rng(4)
    limits = study.robot.nominal.limits_deg.copy()
    for joint, (lo, hi) in study.ranges_deg.items():
        limits[joint - 1] = lo, hi
    q = rng.uniform(limits[:, 0], limits[:, 1], (120, 6))
    return study.robot, q, study.robot.true_positions(q), rng


def test_weighted_fit_minimises_the_residuals_divided_by_their_std(ur10):
    vr, q, true, rng = ur10
    std = np.repeat(rng.uniform(0.005, 0.05, (len(q), 1)), 3, axis=1)
    std[:, 2] *= 2.0                                  # per coordinate too
    measured = true + rng.standard_normal(true.shape) * std
    table = identify(vr.nominal, q, measured, std_mm=std)         # DH: the tilts stay unmodelled, as may happen
    free = np.flatnonzero(np.array(table.status) == "identified")

    def scaled(x):                                    # the rows divided by their std by hand, plain least squares
        v = table.nominal.copy()
        v[free] = x
        return ((robot_with(vr.nominal, v).positions(q) - measured) / std).ravel()
    by_hand = least_squares(scaled, table.nominal[free], method="lm", x_scale="jac", xtol=1e-15, ftol=1e-15,
                            gtol=1e-15).x
    np.testing.assert_allclose(table.value[free], by_hand, atol=1e-5)     # by_hand: finite-difference Jacobian
    assert np.sum(scaled(table.value[free]) ** 2) <= np.sum(scaled(by_hand) ** 2) * (1 + 1e-9)
    plain = identify(vr.nominal, q, measured)
    assert np.max(np.abs(plain.value[free] - by_hand)) > 1e-4          # the weights change the answer
    ref = np.sqrt(np.mean(std**2))
    assert table.sigma_mm == pytest.approx(ref * np.sqrt(np.sum(scaled(table.value[free]) ** 2) /
                                                         (scaled(by_hand).size - free.size)), rel=1e-6)
    assert table.rms_mm == pytest.approx(np.sqrt(np.mean(np.sum((robot_with(vr.nominal, table.value).positions(q)
                                                                 - measured) ** 2, axis=1))), rel=1e-9)


def test_equal_std_gives_the_unweighted_fit(ur10):
    vr, q, true, rng = ur10
    measured = true + rng.normal(0.0, 0.02, true.shape)
    weighted = identify(vr.nominal, q, measured, std_mm=np.full(true.shape, 0.02))
    plain = identify(vr.nominal, q, measured)
    np.testing.assert_allclose(weighted.value, plain.value, atol=1e-9)
    np.testing.assert_allclose(weighted.covariance, plain.covariance, rtol=1e-6, atol=1e-15)


@pytest.mark.parametrize("std", [np.zeros((120, 3)), np.full((120, 2), 0.01), np.full((119, 3), 0.01)])
def test_bad_std_is_refused(ur10, std):
    vr, q, true, _ = ur10
    with pytest.raises(PartcalError, match="std_mm"):
        identify(vr.nominal, q, true, std_mm=std)


def test_robust_loss_names_the_corrupted_rows_and_ignores_them(ur10):
    vr, q, true, rng = ur10
    clean = true + rng.normal(0.0, 0.01, true.shape)
    bad = np.array([7, 50, 93])
    shifted = clean.copy()
    shifted[bad] += [[2.0, 0.0, 0.0], [0.0, -1.5, 0.0], [1.0, 1.0, 3.0]]
    nominal = vr.nominal.positions(q)
    q_test = q + rng.normal(0.0, 20.0, q.shape)
    truth = vr.true_positions(q_test) - vr.nominal.positions(q_test)

    def error(model):
        return np.sqrt(np.mean(np.sum((model.predict(q_test) - truth) ** 2, axis=1)))
    clean_fit = KinematicModel(robot=vr.nominal, parametrization="complete").fit(q, clean - nominal)
    robust = KinematicModel(robot=vr.nominal, parametrization="complete", loss="cauchy", loss_scale=5.0).fit(
        q, shifted - nominal)
    plain = KinematicModel(robot=vr.nominal, parametrization="complete").fit(q, shifted - nominal)
    named = robust.identification_.robust["downweighted"]
    assert [d["row"] for d in named] == bad.tolist()
    np.testing.assert_allclose([d["residual_mm"] for d in named], np.linalg.norm(shifted[bad] - clean[bad], axis=1),
                               rtol=0.05)
    assert error(robust) < 1.1 * error(clean_fit) < 0.2 * error(plain)
    assert robust.identification_.robust["scale_mm"] == pytest.approx(5 * 0.01, rel=0.3)


def test_robust_model_file_keeps_the_loss_and_the_named_rows(ur10, tmp_path):
    vr, q, true, rng = ur10
    measured = true + rng.normal(0.0, 0.01, true.shape)
    measured[3] += 4.0
    model = KinematicModel(robot=vr.nominal, parametrization="complete", loss="huber").fit(q, measured - vr.nominal.positions(q))
    path = tmp_path / "m.json"
    save_model(model, path)
    back = load_model(path)[0]
    assert back.loss == "huber" and back.loss_scale == 3.0
    assert back.identification_.robust == model.identification_.robust
    assert [d["row"] for d in model.identification_.robust["downweighted"]] == [3]


def test_loss_weights_are_the_derivative_of_scipys_losses():
    z = np.array([0.1, 0.9, 1.5, 4.0])
    from scipy.optimize._lsq.least_squares import IMPLEMENTED_LOSSES
    for loss in ("huber", "soft_l1", "cauchy"):
        rho = np.empty((3, z.size))
        IMPLEMENTED_LOSSES[loss](z**2, rho, cost_only=False)
        np.testing.assert_allclose(loss_weights(z, loss), rho[1], rtol=1e-12)


@pytest.mark.parametrize("loss", ["huber", "cauchy"])
def test_a_far_rows_down_weight_and_the_covariance_are_the_losses_own(ur10, loss):
    """A row pushed 0.4 mm off among rows of stated standard deviations: its weight is scipy's rho' of its worst
    weighted coordinate over the loss's scale (loss_scale times the standard deviations' root mean square), and
    the covariance is iteratively reweighted least squares' at the solution, sigma^2 (J^T W J)^-1 with W those
    weights and sigma^2 = sum(W r^2) / dof, J written here as central differences."""
    from scipy.optimize._lsq.least_squares import IMPLEMENTED_LOSSES
    vr, q, true, _ = ur10
    rng = np.random.default_rng(81)
    std = np.repeat(rng.uniform(0.01, 0.03, (len(q), 1)), 3, axis=1)
    measured = true + rng.standard_normal(true.shape) * std
    measured[17] += [0.3, -0.2, 0.25]
    table = identify(vr.nominal, q, measured, std_mm=std, loss=loss, loss_scale=2.0, parametrization="complete")
    reference = np.sqrt(np.mean(std**2))
    scale = 2.0 * reference
    assert table.robust["scale_mm"] == pytest.approx(scale, rel=1e-12)

    def weighted(v):
        return ((robot_with(vr.nominal, v, "complete").positions(q) - measured) / std * reference).ravel()
    r = weighted(table.value)
    rho = np.empty((3, r.size))
    IMPLEMENTED_LOSSES[loss]((r / scale) ** 2, rho, cost_only=False)
    per_row = rho[1].reshape(-1, 3).min(axis=1)
    named = {d["row"]: d["weight"] for d in table.robust["downweighted"]}
    assert 17 in named and named[17] < 0.2
    assert sorted(named) == np.flatnonzero(per_row < 0.5).tolist()
    np.testing.assert_allclose(list(named.values()), per_row[sorted(named)], rtol=1e-6)
    free = np.flatnonzero(np.array(table.status) == "identified")
    jac = np.empty((r.size, free.size))
    for j, k in enumerate(free):
        step = np.zeros(table.value.size)
        step[k] = 1e-6
        jac[:, j] = (weighted(table.value + step) - weighted(table.value - step)) / 2e-6
    sigma2 = np.sum(rho[1] * r**2) / (r.size - free.size)
    expected = sigma2 * np.linalg.inv(jac.T @ (rho[1][:, None] * jac))
    np.testing.assert_allclose(table.covariance, expected, rtol=1e-5, atol=1e-7 * np.abs(expected).max())
    assert table.sigma_mm == pytest.approx(np.sqrt(sigma2), rel=1e-6)


def _tracker_files(tmp_path, vr, rng, *, std_columns: bool):
    """An identification and a test CSV of the virtual UR10 in a tracker frame 2.5 m away, noise growing with
    the distance (0.005 mm + 5 ppm per axis); row 11 of the identification set pushed 3 mm off."""
    rot, shift = matrix_from_rpy_deg([0.5, -1.0, 170.0]), np.array([2500.0, 100.0, -300.0])
    header = "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas" + (",std_x,std_y,std_z" if std_columns else "")
    limits = vr.nominal.limits_deg
    for name, n in (("ident", 150), ("test", 60)):
        q = rng.uniform(np.maximum(limits[:, 0], -170), np.minimum(limits[:, 1], 170), (n, 6))
        in_tracker = (vr.true_positions(q) - shift) @ rot       # p_base = rot p_tracker + shift
        std = np.repeat((0.005 + 5e-6 * np.linalg.norm(in_tracker, axis=1))[:, None], 3, axis=1)
        measured = in_tracker + rng.standard_normal(in_tracker.shape) * std
        if name == "ident":
            measured[10] += [0.0, 3.0, 0.0]
        cells = [q, measured] + ([std] if std_columns else [])
        np.savetxt(tmp_path / f"{name}.csv", np.column_stack(cells), delimiter=",", header=header, comments="",
                   fmt="%.9f")


def _run(tmp_path, data_extra: str = "", models: str = "{name: DH, kind: kinematic}", registration: str = ""):
    (tmp_path / "run.yaml").write_text(
        "name: w\nrobot: universal_robots_ur10\ncv_folds: 3\ndata:\n  frame: tracker\n  identification: ident.csv\n"
        f"  tests: {{test: test.csv}}\n{data_extra}models:\n  - {models}\n{registration}output: out\n")
    return run(load_config(tmp_path / "run.yaml"))


def test_noise_model_weighs_as_the_std_columns_do(ur10, tmp_path):
    vr, _, _, _ = ur10
    (tmp_path / "cols").mkdir()
    (tmp_path / "model").mkdir()
    _tracker_files(tmp_path / "cols", vr, np.random.default_rng(8), std_columns=True)
    _tracker_files(tmp_path / "model", vr, np.random.default_rng(8), std_columns=False)
    by_columns = _run(tmp_path / "cols")
    by_model = _run(tmp_path / "model", "  noise: {constant_mm: 0.005, ppm: 5}\n")     # the tracker at its origin
    plain = _run(tmp_path / "model")
    a, b, c = (r.models[0].predictions["test"] for r in (by_columns, by_model, plain))
    np.testing.assert_allclose(a, b, atol=2e-4)       # the columns: of the true points, 9 decimals
    assert np.max(np.abs(a - c)) > 5e-3
    m = read_measurements(tmp_path / "cols" / "ident.csv", "universal_robots_ur10", frame="tracker")
    distance = np.linalg.norm(m.measured_mm, axis=1)
    np.testing.assert_allclose(m.std_mm[:, 1], 0.005 + 5e-6 * distance, atol=2e-5)     # of the true points


def test_robust_run_names_the_bad_row_in_the_warnings_metrics_and_report(ur10, tmp_path, caplog):
    vr, _, _, _ = ur10
    _tracker_files(tmp_path, vr, np.random.default_rng(9), std_columns=True)
    with caplog.at_level("WARNING"):
        result = _run(tmp_path, models="{name: DH, kind: kinematic, parametrization: complete, loss: cauchy, "
                                       "loss_scale: 5}", registration="registration: {loss: cauchy, loss_scale: 5}\n")
    reg = result.registrations["identification"].robust     # against the nominal robot: its errors set the scale
    assert reg["scale_mm"] > 0.3 and len(reg["downweighted"]) <= 1
    table = result.models[0].model.identification_.robust
    assert [d["row"] for d in table["downweighted"]] == [10]
    assert table["downweighted"][0]["residual_mm"] == pytest.approx(3.0, abs=0.1)
    assert any(r.getMessage().startswith("DH: identification set, data row 11: down-weighted by the cauchy loss")
               for r in caplog.records)
    out = write_run(result, render_report)
    metrics = json.loads((out / "metrics.json").read_text())
    assert [d["row"] for d in metrics["models"]["DH"]["robust"]["downweighted"]] == [10]
    html = (out / "index.html").read_text()
    assert 'class="downweighted"' in html and "<td>11</td>" in html


def test_data_noise_with_a_prior_keeps_its_weights_in_a_run(ur10, tmp_path):
    """data.noise and prior: plausible together in a run (base frame): the model is the weighted MAP that
    identify gives with each point's standard deviation from the noise model (itself checked against a written-out
    MAP in test_prior), not the unweighted one."""
    from partcal.calibration.parameters import geometric_size, nominal_values, parameter_names, PLAUSIBLE_ERROR
    from partcal.calibration.prior import plausible_prior
    vr, q, true, rng = ur10
    std = np.repeat((0.005 + 50e-6 * np.linalg.norm(true, axis=1))[:, None], 3, axis=1)
    measured = true + np.random.default_rng(91).standard_normal(true.shape) * std
    header = "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas"
    for name, rows in (("ident", slice(0, 90)), ("test", slice(90, 120))):
        np.savetxt(tmp_path / f"{name}.csv", np.column_stack([q[rows], measured[rows]]), delimiter=",",
                   header=header, comments="", fmt="%.9f")
    import yaml
    from partcal.robot.description import robot_to_dict
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(robot_to_dict(vr.nominal)))     # the virtual cell's tool
    (tmp_path / "run.yaml").write_text(
        "name: w\nrobot: robot.yaml\ncv_folds: 3\ndata:\n  identification: ident.csv\n"
        "  tests: {test: test.csv}\n  noise: {constant_mm: 0.005, ppm: 50}\n"
        "models:\n  - {name: DH, kind: kinematic, prior: plausible, prior_strength: 0.1}\noutput: out\n")
    fitted = run(load_config(tmp_path / "run.yaml")).models[0].model.identification_
    robot = vr.nominal
    read = read_measurements(tmp_path / "ident.csv", robot)
    units = [u for _, u in parameter_names(robot)]
    prior = plausible_prior(units, geometric_size(robot) - 9, nominal_values(robot), 0.1, PLAUSIBLE_ERROR)
    by_hand = np.repeat((0.005 + 50e-6 * np.linalg.norm(read.measured_mm, axis=1))[:, None], 3, axis=1)
    weighted = identify(robot, read.q_deg, read.measured_mm, std_mm=by_hand, prior=prior)
    unweighted = identify(robot, read.q_deg, read.measured_mm, prior=prior)
    np.testing.assert_allclose(fitted.value, weighted.value, atol=1e-6)
    assert np.max(np.abs(unweighted.value - weighted.value)) > 1e-3


def test_ipa_std_columns_read_through_a_format(tmp_path):
    path = ROOT.parent / "shared" / "datasets" / "ipa_ur10" / "Series_B" / "measurements_joint_configurations.csv"
    if not path.is_file():
        pytest.skip("needs ../shared/datasets/ipa_ur10")
    names = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
             "wrist_3_joint"]
    columns = {f"q{k + 1}": n for k, n in enumerate(names)} | {
        f"{a}_meas": f"measurement_{a}" for a in "xyz"} | {f"std_{a}": f"measurement_std_{a}" for a in "xyz"}
    fmt = MeasurementFormat(delimiter=";", decimal=",", columns=columns, joint_unit="rad")
    m = read_measurements(path, "universal_robots_ur10", fmt=fmt, frame="tracker", rows=RowSelection.parse("1-20"))
    lines = path.read_text(encoding="utf-8").splitlines()
    header = lines[0].split(";")
    expected = [[float(line.split(";")[header.index(f"measurement_std_{a}")].replace(",", ".")) for a in "xyz"]
                for line in lines[1:21]]
    np.testing.assert_array_equal(m.std_mm, expected)
    bad = tmp_path / "bad.csv"
    bad.write_text("q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas,std_x,std_y,std_z\n0,-90,0,-90,0,0,1,2,3,0.1,0,0.1\n")
    with pytest.raises(PartcalError, match=r"bad.csv:2: column 'std_y': expected a standard deviation > 0 \(mm\), got 0"):
        read_measurements(bad, "universal_robots_ur10", frame="tracker")


@pytest.mark.parametrize("noise, message", [
    ("{constant_mm: 0, ppm: 0}", "constant_mm or ppm must be > 0"),
    ("{constant_mm: -1}", "constant_mm"),
    ("{ppm: 5, instrument_mm: [1, 2]}", "a list of 3 numbers"),
    ("{ppm: 5, where: 1}", "where")])
def test_bad_noise_model_is_refused(tmp_path, noise, message):
    (tmp_path / "a.csv").write_text("q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas\n0,-90,0,-90,0,0,1,2,3\n")
    (tmp_path / "run.yaml").write_text(f"name: n\nrobot: universal_robots_ur10\ndata:\n  identification: a.csv\n"
                                       f"  noise: {noise}\nmodels:\n  - {{name: DH, kind: kinematic}}\noutput: o\n")
    with pytest.raises(PartcalError, match=message):
        load_config(tmp_path / "run.yaml")


def test_noise_model_gives_each_point_its_distance_std():
    from partcal.data.noise import NoiseModel
    p = np.array([[2500.0, 0.0, 0.0], [0.0, 0.0, 0.0], [1000.0, 1000.0, 500.0]])
    expected = 0.005 + 5e-6 * np.array([0.0, 2500.0, np.sqrt(1500.0**2 + 1000.0**2 + 500.0**2)])
    np.testing.assert_allclose(NoiseModel(0.005, 5.0, (2500.0, 0.0, 0.0)).std_of(p), np.repeat(expected[:, None], 3, 1))

