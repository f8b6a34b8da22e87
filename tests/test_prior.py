"""Priors in kinematic identification (MAP) and `partcal update`: a model file as the prior of a new fit."""

import numpy as np
import pytest
from conftest import random_row_prior
from scipy.optimize import least_squares

from partcal import load_robot
from partcal.metrics import pooled_rms
from partcal.calibration.chain import model_positions
from partcal.calibration.identification import identify
from partcal.calibration.parameters import nominal_values, parameter_names
from partcal.calibration.prior import plausible_prior, Prior
from partcal.study.update import DEFAULT_INFLATE, IDENTIFY_LITTLE


@pytest.fixture(scope="module")
def ur10():
    return load_robot("universal_robots_ur10")


def poses(robot, n, seed, spread=1.0):
    rng = np.random.default_rng(seed)
    lo, hi = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    mid = (lo + hi) / 2
    return mid + spread * rng.uniform(-1, 1, (n, robot.n_joints)) * np.minimum((hi - lo) / 2, 120.0)


def moved(robot, seed):
    """Measured positions of a robot whose rows' parameters are off by about 0.5 mm / 0.05 deg, with noise."""
    units = np.array([u for _, u in parameter_names(robot)])
    rng = np.random.default_rng(seed)
    true = nominal_values(robot) + rng.normal(size=units.size) * np.where(units == "mm", 0.5, 0.05)
    true[-15:] = nominal_values(robot)[-15:]                  # tool, base: nominal
    return true


def test_map_equals_an_independent_augmented_least_squares(ur10):
    q = poses(ur10, 25, 1)
    true = moved(ur10, 2)
    measured = model_positions(ur10, None, q, true, np.zeros(len(q))) + \
        np.random.default_rng(3).normal(scale=0.05, size=(len(q), 3))
    v0 = nominal_values(ur10)
    index, mean, cov = random_row_prior(v0)                   # on the DH rows' parameters
    noise = 0.05
    table = identify(ur10, q, measured, prior=Prior.from_covariance(index, mean, cov, noise))
    free = np.flatnonzero(np.array(table.status) == "identified")
    plain = identify(ur10, q, measured)
    assert np.sum(np.array(plain.status)[:24] == "identified") < 20
    # the prior makes every row parameter identifiable but the two whose column is nil (the flange's turn
    # and twist do not move a tool on its axis: the lever rule drops them, with or without a prior)
    assert set(index) - set(free) == {20, 23}
    chol = np.linalg.cholesky(cov)

    def resid(x):                                             # written out: |r|^2 + sigma^2 (v-m)^T C^-1 (v-m)
        v = v0.copy()
        v[free] = x
        p = model_positions(ur10, None, q, v, np.zeros(len(q)))
        return np.concatenate([(p - measured).ravel(), noise * np.linalg.solve(chol, v[index] - mean)])

    x = least_squares(resid, v0[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(np.sum(resid(table.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-9)
    np.testing.assert_allclose(table.value[free], x, atol=1e-5)     # the valley is flat to 1e-13 mm^2 there


def test_a_strong_prior_returns_its_mean_and_a_zero_one_the_plain_fit(ur10):
    q = poses(ur10, 40, 5)
    true = moved(ur10, 6)
    measured = model_positions(ur10, None, q, true, np.zeros(len(q)))
    v0 = nominal_values(ur10)
    units = [u for _, u in parameter_names(ur10)]
    mean = v0.copy()
    mean[:24] += np.random.default_rng(7).normal(size=24) * 0.2
    strong = identify(ur10, q, measured, prior=Prior.from_std(np.arange(24), mean[:24], np.full(24, 1e-3), 1e4))
    np.testing.assert_allclose(strong.value[:24], mean[:24], atol=1e-6)
    plain = identify(ur10, q, measured)
    none = identify(ur10, q, measured, prior=Prior.from_std(np.arange(24), mean[:24], np.ones(24), 0.0))
    identified = np.array(plain.status) == "identified"
    assert none.status == plain.status
    np.testing.assert_allclose(none.value[identified], plain.value[identified], atol=1e-8)
    assert plausible_prior(units, 24, v0, 0.0, {"mm": 1.0, "deg": 0.1}) is None


def test_a_prior_holds_a_fit_on_the_measured_orientation_too(ur10):
    """The orientation (and further targets) stack more residuals; the prior's rows go below them all."""
    from partcal.models.kinematic import KinematicModel
    q = poses(ur10, 30, 31)
    rng = np.random.default_rng(32)
    y = np.column_stack([rng.normal(scale=0.5, size=(30, 3)), rng.normal(scale=1.0, size=(30, 3))])   # mm, mrad
    strong = KinematicModel(robot=ur10, use_orientation=True, prior="plausible", prior_strength=1e5).fit(q, y)
    np.testing.assert_allclose(strong.identification_.value[:24], nominal_values(ur10)[:24], atol=1e-3)
    free = KinematicModel(robot=ur10, use_orientation=True).fit(q, y)
    assert np.abs(free.identification_.value[:24] - nominal_values(ur10)[:24]).max() > 0.1


def test_without_a_prior_the_fit_is_unchanged_bit_for_bit(ur10):
    """No prior, and a plausible prior of strength 0 (which is none), give one fit bit for bit: the plain least
    squares of the positions, as an independently written one finds it."""
    from partcal.models.kinematic import KinematicModel
    q = poses(ur10, 30, 8)
    measured = model_positions(ur10, None, q, moved(ur10, 9), np.zeros(len(q))) + \
        np.random.default_rng(10).normal(scale=0.02, size=(len(q), 3))
    y = measured - ur10.positions(q)
    plain = KinematicModel(robot=ur10).fit(q, y).identification_
    zero = KinematicModel(robot=ur10, prior="plausible", prior_strength=0.0).fit(q, y).identification_
    assert zero.status == plain.status
    for field in ("value", "std_error", "covariance"):
        np.testing.assert_array_equal(getattr(zero, field), getattr(plain, field))
    free = np.flatnonzero(np.array(plain.status) == "identified")
    v0 = nominal_values(ur10)

    def resid(x):                                             # written out: the positions' residuals alone
        v = v0.copy()
        v[free] = x
        return (model_positions(ur10, None, q, v, np.zeros(len(q))) - measured).ravel()

    x = least_squares(resid, v0[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(plain.value[free], x, atol=1e-5)
    np.testing.assert_allclose(np.sum(resid(plain.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-9)
    # and a prior would have changed it: the comparison can tell
    weak = KinematicModel(robot=ur10, prior="plausible", prior_strength=0.3).fit(q, y).identification_
    assert np.max(np.abs(weak.value[free] - plain.value[free])) > 1e-3


def test_a_prior_keeps_the_per_row_weights(ur10):
    """Standard deviations per row and a prior together: the MAP of the rows divided by their standard deviations
    (times their root mean square, as identify states them) and the prior's rows, written out here."""
    q = poses(ur10, 30, 51)
    rng = np.random.default_rng(52)
    std = np.repeat(rng.uniform(0.01, 0.2, (30, 1)), 3, axis=1)
    std[:, 2] *= 3.0
    measured = model_positions(ur10, None, q, moved(ur10, 53), np.zeros(len(q))) + rng.standard_normal((30, 3)) * std
    v0 = nominal_values(ur10)
    units = np.array([u for _, u in parameter_names(ur10)])[:24]
    prior = Prior.from_std(np.arange(24), v0[:24], np.where(units == "mm", 1.0, 0.1), 0.05)
    table = identify(ur10, q, measured, std_mm=std, prior=prior)
    free = np.flatnonzero(np.array(table.status) == "identified")
    reference = np.sqrt(np.mean(std**2))

    def resid(x):
        v = v0.copy()
        v[free] = x
        p = model_positions(ur10, None, q, v, np.zeros(len(q)))
        return np.concatenate([((p - measured) / std * reference).ravel(), 0.05 * (v[:24] - v0[:24]) /
                               np.where(units == "mm", 1.0, 0.1)])

    x = least_squares(resid, v0[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(table.value[free], x, atol=2e-5)
    np.testing.assert_allclose(np.sum(resid(table.value[free]) ** 2), np.sum(resid(x) ** 2), rtol=1e-9)
    unweighted = identify(ur10, q, measured, prior=prior)     # the weights matter here
    assert np.max(np.abs(unweighted.value[free] - x)) > 1e-2


def test_a_parameter_the_prior_holds_is_never_pruned_as_implausible(ur10):
    """d[1] trades exactly with the base's height: the data fix their sum alone. A prior puts d[1] 15 mm off nominal
    (beyond the 10 mm a row's length may plausibly be, and within three of its standard errors of nominal, where an
    unheld parameter is kept nominal): the prior prices that distance, so the MAP keeps it, as a written-out MAP
    finds, and the base's height makes up for it."""
    q = poses(ur10, 30, 61)
    measured = ur10.positions(q) + np.random.default_rng(62).normal(scale=0.01, size=(30, 3))
    v0 = nominal_values(ur10)
    base_z = [n for n, _ in parameter_names(ur10)].index("base.z")
    prior = Prior.from_std([1], [v0[1] + 15.0], [20.0], 0.01)
    table = identify(ur10, q, measured, prior=prior)
    assert table.status[1] == table.status[base_z] == "identified"
    free = np.flatnonzero(np.array(table.status) == "identified")

    def resid(x):
        v = v0.copy()
        v[free] = x
        return np.concatenate([(model_positions(ur10, None, q, v, np.zeros(len(q))) - measured).ravel(),
                               [0.01 * (v[1] - v0[1] - 15.0) / 20.0]])

    x = least_squares(resid, v0[free], jac="3-point", x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(table.value[free], x, atol=1e-3)
    assert table.value[1] - v0[1] == pytest.approx(15.0, abs=1e-3)
    assert table.value[base_z] == pytest.approx(-15.0, abs=0.01)


def test_the_plausible_prior_holds_every_row_parameter_the_last_one_too(ur10):
    """The plausible prior has a row per row parameter (the last row's twist included), each its plausible error
    under the strength; a strong one holds them all at nominal where the data alone would move the last one."""
    from partcal.calibration.parameters import geometric_size, PLAUSIBLE_ERROR
    from partcal.models.kinematic import KinematicModel
    units = [u for _, u in parameter_names(ur10)]
    prior = plausible_prior(units, geometric_size(ur10) - 9, nominal_values(ur10), 2.0, PLAUSIBLE_ERROR)
    assert prior.index.tolist() == list(range(24))
    np.testing.assert_allclose(prior.root, np.diag([2.0 / (1.0 if k % 4 in (1, 2) else 0.1) for k in range(24)]))
    robot = ur10.replace(tool_mm=np.array([80.0, 60.0, 150.0]))      # off the flange's axis: its twist moves it
    q = poses(robot, 40, 71)
    true = nominal_values(robot)
    true[23] += 0.5                                           # alpha[6], the last row parameter
    y = model_positions(robot, None, q, true, np.zeros(len(q))) - robot.positions(q)
    alone = KinematicModel(robot=robot, tool=False).fit(q, y).identification_
    assert alone.value[23] - true[23] == pytest.approx(0.0, abs=1e-6)
    held = KinematicModel(robot=robot, tool=False, prior="plausible", prior_strength=1e3).fit(q, y).identification_
    np.testing.assert_allclose(held.value[:24], nominal_values(robot)[:24], atol=1e-3)


def test_a_bad_prior_covariance_is_refused():
    with pytest.raises(ValueError, match=r"\(2, 2\) matrix"):
        Prior.from_covariance([0, 1], [0.0, 0.0], np.eye(3), 1.0)
    with pytest.raises(ValueError, match="positive definite"):
        Prior.from_covariance([0, 1], [0.0, 0.0], -np.eye(2), 1.0)
    with pytest.raises(ValueError, match="standard deviations > 0"):
        Prior.from_std([0], [0.0], [0.0], 1.0)


# ---------------------------------------------------------------------- partcal update
def measured_set(robot, truth_values, q, seed, noise=0.01):
    from partcal.data.measurements import Measurements
    p = model_positions(robot, None, q, truth_values, np.zeros(len(q)))
    p = p + np.random.default_rng(seed).normal(scale=noise, size=p.shape)
    return Measurements(q, robot.positions(q), p)


@pytest.fixture(scope="module")
def calibrated(ur10, tmp_path_factory):
    """A model file of a virtual UR10 (rows off by 0.5 mm / 0.05 deg), and the robot's true parameters."""
    from partcal.models.kinematic import KinematicModel
    from partcal.study.persist import save_model
    truth = moved(ur10, 11)
    m = measured_set(ur10, truth, poses(ur10, 150, 12), 13)
    path = tmp_path_factory.mktemp("update") / "a.json"
    save_model(KinematicModel(robot=ur10).fit(m.q_deg, m.errors_mm), path, name="robot a", robot=ur10)
    return path, truth


def test_update_moves_the_model_toward_a_shifted_joint_offset_and_records_its_provenance(ur10, calibrated, tmp_path):
    from partcal.cli import main
    from partcal.data.measurements import write_measurements
    from partcal.study.persist import load_model
    path, truth = calibrated
    shifted = truth.copy()
    shifted[4] += 0.05                                        # joint 2's offset moved by 0.05 degrees
    new = measured_set(ur10, shifted, poses(ur10, 30, 14), 15)
    write_measurements(new, tmp_path / "new.csv")
    assert main(["update", str(path), str(tmp_path / "new.csv"), "-o", str(tmp_path / "b.json")]) == 0
    old, old_doc = load_model(path)
    updated, doc = load_model(tmp_path / "b.json")
    info = doc["fit"]["update"]
    assert info["data"] == str(tmp_path / "new.csv") and info["rows"] == 30 and info["inflate"] == DEFAULT_INFLATE
    assert info["prior_checksum"] == old_doc["checksum"] and info["prior_name"] == "robot a"
    assert doc["name"] == "robot a updated"
    assert info["kept_prior"] is False and info["determined"] > IDENTIFY_LITTLE
    q = poses(ur10, 200, 16)
    true_errors = model_positions(ur10, None, q, shifted, np.zeros(len(q))) - ur10.positions(q)
    before = np.sqrt(np.mean(np.sum((old.predict(q) - true_errors) ** 2, axis=1)))
    after = np.sqrt(np.mean(np.sum((updated.predict(q) - true_errors) ** 2, axis=1)))
    table, table_old = updated.identification_, old.identification_
    assert before > 0.5 and after < 0.5 * before
    assert 0.025 < table.value[4] - table_old.value[4] < 0.06


def test_update_from_a_compact_patch_keeps_the_prior_and_says_so(ur10, calibrated, tmp_path):
    from partcal.data.measurements import write_measurements
    from partcal.study.persist import load_model
    from partcal.study.update import update_file
    path, truth = calibrated
    q = np.array([30.0, -60.0, 80.0, -100.0, 60.0, 10.0]) + np.random.default_rng(17).uniform(-1.5, 1.5, (20, 6))
    q[:, 5] = 10.0                                            # a compact patch, joint 6 still
    new = measured_set(ur10, truth, q, 18)
    write_measurements(new, tmp_path / "patch.csv")
    done = update_file(path, tmp_path / "patch.csv", tmp_path / "c.json")
    assert done.kept_prior and "identify little" in "\n".join(done.lines())
    old = load_model(path)[0].identification_
    table = done.model.identification_
    rows = np.flatnonzero(np.array(old.status[:24]) == "identified")
    np.testing.assert_allclose(table.value[rows], old.value[rows], atol=1e-3)


FRAME_TURN_DEG, FRAME_SHIFT_MM = np.array([0.2, -0.1, 0.3]), np.array([5.0, -3.0, 2.0])


def in_moved_frame(robot, values, q, seed, noise=0.01):
    """Positions of the robot with parameter ``values`` at ``q`` measured in a frame turned by FRAME_TURN_DEG
    (roll, pitch, yaw about fixed axes) and shifted by FRAME_SHIFT_MM from its base frame: new data after the
    tracker or the cell moved."""
    from partcal.data.measurements import Measurements
    from scipy.spatial.transform import Rotation
    turn = Rotation.from_euler("xyz", FRAME_TURN_DEG, degrees=True).as_matrix()
    p = model_positions(robot, None, q, values, np.zeros(len(q))) @ turn.T + FRAME_SHIFT_MM
    return Measurements(q, robot.positions(q), p + np.random.default_rng(seed).normal(scale=noise, size=p.shape))


def test_update_identifies_a_moved_base_afresh(ur10, calibrated):
    """New poses measured in a frame moved by 5 mm and 0.3 degree: the base frame is not part of the prior (a
    model's base is known to hundredths of a mm), so the update finds the new frame and predicts the new
    measurements to their noise."""
    from partcal.study.persist import load_model
    from partcal.study.update import update_model
    from scipy.spatial.transform import Rotation
    path, truth = calibrated
    done = update_model(load_model(path)[0], in_moved_frame(ur10, truth, poses(ur10, 30, 14), 15))
    assert not done.kept_prior
    assert done.rms_after_mm < 0.02 and done.rms_before_mm < 0.03           # 0.01 mm of noise per coordinate
    table = done.model.identification_
    base = table.value[[table.names.index(f"base.{c}") for c in ("x", "y", "z", "rx", "ry", "rz")]]
    np.testing.assert_allclose(base[:3], FRAME_SHIFT_MM, atol=0.05)
    turn = Rotation.from_euler("xyz", FRAME_TURN_DEG, degrees=True).as_matrix()
    np.testing.assert_allclose(Rotation.from_euler("ZYX", base[[5, 4, 3]], degrees=True).as_matrix(), turn,
                               atol=2e-5)
    q = poses(ur10, 200, 16)
    truth_there = in_moved_frame(ur10, truth, q, 0, noise=0.0).measured_mm
    assert pooled_rms(ur10.positions(q) + done.model.predict(q) - truth_there) < 0.02


def test_update_that_keeps_the_prior_holds_it_firmly_and_identifies_the_frame(ur10, calibrated):
    """A compact patch (joint 6 still) of a robot whose joint 2 moved 0.05 degree, in a moved frame: the poses
    identify little, so the prior model's parameters are kept, each to 1e-4 of its prior standard deviation (the
    identified ones' inflated covariance, the others' plausible error), and the frame alone is identified again:
    the positions on the patch are predicted to a few hundredths of a mm."""
    from partcal.study.persist import load_model
    from partcal.study.update import DEFAULT_INFLATE, update_model
    path, truth = calibrated
    q = np.array([30.0, -60.0, 80.0, -100.0, 60.0, 10.0]) + np.random.default_rng(17).uniform(-1.5, 1.5, (20, 6))
    q[:, 5] = 10.0
    shifted = truth.copy()
    shifted[4] += 0.05
    model = load_model(path)[0]
    done = update_model(model, in_moved_frame(ur10, shifted, q, 18))
    assert done.kept_prior
    old, new = model.identification_, done.model.identification_
    identified = [k for k, (n, s) in enumerate(zip(old.names, old.status)) if s == "identified"
                  and not n.startswith("base.")]
    std = np.full(len(old.names), np.nan)
    std[identified] = np.sqrt(np.diag(old.covariance)[[list(np.flatnonzero(np.array(old.status) == "identified"))
                                                       .index(k) for k in identified]] * DEFAULT_INFLATE)
    others = [k for k in old.prior_indices() if not old.names[k].startswith("base.")]
    std[others] = old.prior_std[others]
    held = np.flatnonzero(np.isfinite(std))
    assert held.size == 27
    assert np.max(np.abs(new.value[held] - old.value[held]) / std[held]) < 1e-4
    assert all(new.status[new.names.index(f"base.{c}")] == "identified" for c in ("x", "y", "z", "rx", "ry", "rz"))
    assert done.rms_after_mm == done.rms_before_mm < 0.05


@pytest.mark.parametrize("spread_deg", [1.5, 60.0])
def test_update_judges_the_new_poses_with_the_frame_profiled_out(ur10, calibrated, spread_deg):
    """What the new poses determine of each direction of the prior, against the posterior of the prior's
    parameters and the frame together (the frame free, no prior on it) inverted as one matrix, from central
    differences of the positions: with the frame profiled out, the poses' frame-like directions count for
    nothing (counted, a compact patch would seem to determine several); poses spread 60 degrees determine a
    quarter of one direction and more."""
    from partcal.study.persist import load_model
    from partcal.study.update import determined_shares, model_prior
    path, truth = calibrated
    model = load_model(path)[0]
    q = np.array([30.0, -60.0, 80.0, -100.0, 60.0, 10.0]) + \
        np.random.default_rng(17).uniform(-spread_deg, spread_deg, (20, 6))
    data = in_moved_frame(ur10, truth, q, 18)
    prior = model_prior(model, 1.0, unidentified=False)
    shares = determined_shares(model, data, prior)
    table = model.identification_
    frame = [table.names.index(f"base.{c}") for c in ("x", "y", "z", "rx", "ry", "rz")]
    columns = np.concatenate([prior.index, frame])
    jac = np.empty((3 * len(q), columns.size))
    for j, k in enumerate(columns):
        step = np.zeros(table.value.size)
        step[k] = 1e-4
        jac[:, j] = ((model_positions(ur10, None, q, table.value + step, np.zeros(len(q))) -
                      model_positions(ur10, None, q, table.value - step, np.zeros(len(q)))) / 2e-4).ravel()
    sigma = table.sigma_mm
    k = prior.index.size
    prior_cov = sigma**2 * np.linalg.inv(prior.root.T @ prior.root)
    information = jac.T @ jac / sigma**2
    information[:k, :k] += np.linalg.inv(prior_cov)
    posterior = np.linalg.inv(information)[:k, :k]            # the prior's parameters, the frame's marginalised
    root = np.linalg.cholesky(prior_cov)
    remaining = np.linalg.eigvalsh(np.linalg.solve(root, np.linalg.solve(root, posterior).T))
    expected = np.sort(1.0 - remaining)[::-1]                 # the share of each direction's variance removed
    np.testing.assert_allclose(shares, expected, rtol=1e-5, atol=1e-9)
    assert shares.sum() < 1.5 and (shares.max() > 0.2) == (spread_deg > 10)


def test_a_models_prior_is_its_inflated_covariance_and_its_unidentified_parameters_plausible_errors(ur10,
                                                                                                     calibrated):
    """model_prior's rows W, by hand: W^T W = sigma^2 C^-1 with C the covariance of the identified parameters (the
    base frame's left out unless asked) times the inflation, beside the unidentified ones' plausible errors
    squared; type_prior: each row parameter at the model's value, its plausible error under 1 mm."""
    from partcal.calibration.parameters import PLAUSIBLE_ERROR
    from partcal.study.persist import load_model
    from partcal.study.update import model_prior, type_prior
    model = load_model(calibrated[0])[0]
    table = model.identification_
    identified = np.flatnonzero(np.array(table.status) == "identified")
    unknown = table.prior_indices()
    for frame, unidentified in ((False, True), (True, True), (False, False)):
        keep = [j for j, k in enumerate(identified) if frame or not table.names[k].startswith("base.")]
        plausible = [k for k in unknown if unidentified and (frame or not table.names[k].startswith("base."))]
        cov = np.zeros((len(keep) + len(plausible),) * 2)
        cov[:len(keep), :len(keep)] = 7.0 * table.covariance[np.ix_(keep, keep)]
        cov[len(keep):, len(keep):] = np.diag(table.prior_std[plausible] ** 2)
        prior = model_prior(model, 7.0, frame=frame, unidentified=unidentified)
        assert prior.index.tolist() == identified[keep].tolist() + plausible
        np.testing.assert_array_equal(prior.mean, table.value[prior.index])
        expected = table.sigma_mm**2 * np.linalg.inv(cov)
        np.testing.assert_allclose(prior.root.T @ prior.root, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    assert any(table.names[k].startswith("base.") for k in unknown) and len(plausible) == 0
    other = type_prior(model, PLAUSIBLE_ERROR)
    assert other.index.tolist() == list(range(24))
    np.testing.assert_array_equal(other.mean, table.value[:24])
    np.testing.assert_allclose(other.root, np.diag([1.0 / (1.0 if k % 4 in (1, 2) else 0.1) for k in range(24)]))


def test_update_keeps_the_prior_below_one_and_a_half_directions_determined(ur10, calibrated):
    """Twenty poses spread 60 degrees about one pose determine about one direction of the prior model's
    covariance (between 0.5 and 1.5): too little, so the prior's values are kept. Its default inflation is 30."""
    from partcal.study.persist import load_model
    from partcal.study.update import update_model
    path, truth = calibrated
    model = load_model(path)[0]
    q = np.array([30.0, -60.0, 80.0, -100.0, 60.0, 10.0]) + np.random.default_rng(17).uniform(-60, 60, (20, 6))
    done = update_model(model, measured_set(ur10, truth, q, 18))
    assert 0.5 < done.shares.sum() < 1.5 and done.kept_prior
    done = update_model(model, measured_set(ur10, truth, poses(ur10, 20, 19), 18))   # 20 random poses: 1.8
    assert 1.5 < done.shares.sum() < 2.5 and not done.kept_prior
    wide = measured_set(ur10, truth, poses(ur10, 30, 14), 15)
    np.testing.assert_array_equal(update_model(model, wide).model.identification_.value,
                                  update_model(model, wide, 30.0).model.identification_.value)


def test_update_refuses_what_it_cannot_update(ur10, calibrated, tmp_path):
    """An inflation that is not a positive number (a small one is fine), a model without the covariance of its
    parameters, and a model fitted on the orientation (positions of one target only) are refused."""
    import dataclasses
    from partcal import PartcalError
    from partcal.errors import ModelFileError
    from partcal.models.kinematic import KinematicModel
    from partcal.study.persist import load_model, save_model
    from partcal.study.update import update_file, update_model
    path, truth = calibrated
    model = load_model(path)[0]
    data = measured_set(ur10, truth, poses(ur10, 30, 14), 15)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(PartcalError, match="--inflate must be a number > 0"):
            update_model(model, data, bad)
    assert not update_model(model, data, 0.5).kept_prior
    for field, value in (("covariance", None), ("sigma_mm", float("nan"))):
        bare = load_model(path)[0]
        bare.identification_ = dataclasses.replace(bare.identification_, **{field: value})
        with pytest.raises(ModelFileError, match="the model has no covariance of its parameters"):
            update_model(bare, data)
    q = poses(ur10, 30, 31)
    y = np.column_stack([np.random.default_rng(32).normal(scale=0.5, size=(30, 3)), np.zeros((30, 3))])
    save_model(KinematicModel(robot=ur10, use_orientation=True).fit(q, y), tmp_path / "pose.json", robot=ur10)
    from partcal.data.measurements import write_measurements
    write_measurements(data, tmp_path / "new.csv")
    with pytest.raises(ModelFileError, match="update reads positions of one target; this model was fitted on "
                                             "further targets or an orientation"):
        update_file(tmp_path / "pose.json", tmp_path / "new.csv", tmp_path / "out.json")


def test_update_of_a_model_without_its_tool_or_written_before_checksums(ur10, calibrated, tmp_path):
    """A model identified with its tool fixed (tool: false) updates (its fixed parameters are no part of the
    prior); a file written before model files carried a checksum gets the one computed from it in the
    provenance, and one written before the covariance was kept is refused naming it."""
    import json
    from partcal.data.measurements import write_measurements
    from partcal.errors import ModelFileError
    from partcal.models.kinematic import KinematicModel
    from partcal.study.persist import checksum, save_model
    from partcal.study.update import model_prior, update_file, update_model
    _, truth = calibrated
    m = measured_set(ur10, truth, poses(ur10, 60, 41), 42)
    fixed_tool = KinematicModel(robot=ur10, tool=False).fit(m.q_deg, m.errors_mm)
    assert fixed_tool.identification_.status[24:27] == ("fixed",) * 3
    assert not set(model_prior(fixed_tool, 1.0).index) & {24, 25, 26}
    new = measured_set(ur10, truth, poses(ur10, 30, 43), 44)
    assert update_model(fixed_tool, new).rms_after_mm < 0.05
    write_measurements(new, tmp_path / "new.csv")
    save_model(fixed_tool, tmp_path / "a.json", name="a", robot=ur10)
    doc = json.loads((tmp_path / "a.json").read_text())
    del doc["checksum"]
    (tmp_path / "old.json").write_text(json.dumps(doc))
    done = update_file(tmp_path / "old.json", tmp_path / "new.csv", tmp_path / "b.json")
    assert done.provenance["prior_checksum"] == checksum(doc)
    del doc["model"]["identification"]["covariance"]
    (tmp_path / "older.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError, match=r"older.json: the model has no covariance of its parameters"):
        update_file(tmp_path / "older.json", tmp_path / "new.csv", tmp_path / "c.json")


@pytest.mark.parametrize("case, message", [
    ("missing", "no such model file"), ("series", "field 'kind': update needs a model of kind 'kinematic'"),
    ("inflate", "--inflate: expected a positive number"), ("data", "new.csv")])
def test_update_refuses_bad_input_with_exit_2(ur10, calibrated, tmp_path, capsys, case, message):
    from partcal import ErrorModel
    from partcal.cli import main
    from partcal.study.persist import save_model
    path, _ = calibrated
    data = tmp_path / "new.csv"
    data.write_text("q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas\n0,0,0,0,0,0,1,2\n" if case == "data" else
                    "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas\n" + "0,-90,0,-90,0,0,0,0,0\n")
    args = [str(path), str(data), "-o", str(tmp_path / "out.json")]
    if case == "missing":
        args[0] = str(tmp_path / "nothing.json")
    if case == "series":
        q = poses(ur10, 40, 1)
        save_model(ErrorModel(inputs="joint", degree=1, solver="lstsq").fit(q, np.ones((40, 3))), tmp_path / "s.json",
                   robot=ur10)
        args[0] = str(tmp_path / "s.json")
    if case == "inflate":
        args += ["--inflate", "-1"]
    try:
        code = main(["update", *args])
    except SystemExit as exc:                                 # argparse refuses a bad option value itself
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "out.json").exists()


# ---------------------------------------------------------------------- priors in a run config
def run_config(tmp_path, entry, robot="universal_robots_ur10"):
    from conftest import ROOT
    data = ROOT / "data" / "sk120"
    path = tmp_path / "configs" / "run.yaml"
    path.parent.mkdir(exist_ok=True)
    path.write_text(f"name: demo\nrobot: {robot}\ndata:\n  identification: {data / 'identification.csv'}\n"
                    f"models:\n  - {{name: DH, kind: kinematic, {entry}}}\n")
    return path


def test_a_plausible_prior_with_a_list_of_strengths_takes_the_strongest_within_one_se_of_block_cv(ur10):
    from partcal.calibration.parameters import geometric_size, PLAUSIBLE_ERROR
    from partcal.models.kinematic import KinematicModel
    q = poses(ur10, 60, 21)
    measured = model_positions(ur10, None, q, moved(ur10, 22), np.zeros(len(q))) + \
        np.random.default_rng(23).normal(scale=0.3, size=(len(q), 3))
    y = measured - ur10.positions(q)
    strengths = (0.1, 0.3, 1.0, 3.0, 30.0)
    model = KinematicModel(robot=ur10, prior="plausible", prior_strength=strengths).fit(q, y)
    units = [u for _, u in parameter_names(ur10)]
    expected, errors = [], []                                 # the block CV written out
    for s in strengths:
        prior = plausible_prior(units, geometric_size(ur10) - 9, nominal_values(ur10), s, PLAUSIBLE_ERROR)
        left = []
        for test in np.array_split(np.arange(60), 5):
            train = np.setdiff1d(np.arange(60), test)
            fit = KinematicModel(robot=ur10).fit(q[train], y[train], prior=prior)
            left.append(y[test] - fit.predict(q[test]))
        sq = np.sum(np.vstack(left) ** 2, axis=1)
        expected.append(np.sqrt(sq.mean()))
        errors.append(np.std(sq, ddof=1) / np.sqrt(len(sq)) / (2 * np.sqrt(sq.mean())))   # delta method, per row
    table = model.prior_strength_table_
    assert [row["prior_strength"] for row in table] == list(strengths)
    np.testing.assert_allclose([row["cv_rms_3d"] for row in table], expected, rtol=1e-9)
    np.testing.assert_allclose([row["cv_se"] for row in table], errors, rtol=1e-9)
    best = int(np.argmin(expected))
    assert model.prior_strength_ == max(s for s, e in zip(strengths, expected) if e <= expected[best] + errors[best])
    assert model.prior_strength_ > strengths[best]            # not the lowest score: the simplest near it
    assert any(note.startswith(f"prior strength {model.prior_strength_:g} chosen by 5-block CV")
               for note in model.fit_notes())
    plain = KinematicModel(robot=ur10, prior="plausible", prior_strength=model.prior_strength_).fit(q, y)
    np.testing.assert_array_equal(plain.identification_.value, model.identification_.value)


def test_run_config_prior_keys(tmp_path, calibrated):
    import yaml
    from partcal import ConfigError
    from partcal.study.config import load_config
    from partcal.study.persist import load_model
    cfg = load_config(run_config(tmp_path, "prior: plausible, prior_strength: [0.3, 1, 3]"))
    assert cfg.models[0].params["prior"] == "plausible" and cfg.models[0].params["prior_strength"] == (0.3, 1.0, 3.0)
    assert yaml.safe_load(yaml.safe_dump(cfg.resolved()))["models"][0]["params"]["prior_strength"] == [0.3, 1, 3]
    path, _ = calibrated
    cfg = load_config(run_config(tmp_path, f"prior: {path}, prior_strength: 2"))
    prior = cfg.models[0].params["prior"]
    table = load_model(path)[0].identification_
    assert prior.source == str(path) and np.array_equal(prior.mean, table.value[prior.index])
    assert prior.index.tolist() == list(range(24))             # the rows' parameters; tool and frame afresh
    assert yaml.safe_load(yaml.safe_dump(cfg.resolved()))["models"][0]["params"]["prior"] == str(path)
    with pytest.raises(ConfigError, match=r"models\[0\]\.prior \(line 6\): '.*' was identified with 33 parameters, "
                                          r"this entry identifies 51 \(parameter 2: d\[1\] there, x\[1\] here\)"):
        load_config(run_config(tmp_path, f"prior: {path}, parametrization: complete"))
    with pytest.raises(ConfigError, match=r"models\[0\]\.prior \(line 6\): .*with 33 parameters, this entry "
                                          r"identifies 39 \(parameter 34: nothing there, sag\[2,f2\] here\)"):
        load_config(run_config(tmp_path, f"prior: {path}, compliance: [2]"))
    with pytest.raises(ConfigError, match=r"models\[0\]\.prior_strength \(line 6\): applies with a prior only"):
        load_config(run_config(tmp_path, "prior_strength: 2"))
    with pytest.raises(ConfigError, match=r"models\[0\]\.prior_strength \(line 6\): must be a number >= 0"):
        load_config(run_config(tmp_path, "prior: plausible, prior_strength: -1"))
    with pytest.raises(ConfigError, match=r"models\[0\]\.prior \(line 6\): 'plausible' or a kinematic model file; "
                                          r"'nothing.json': .*no such model file"):
        load_config(run_config(tmp_path, "prior: nothing.json"))
    with pytest.raises(ConfigError, match=r"its robot is 'universal_robots_ur10', the run's 'motoman_sk120'"):
        load_config(run_config(tmp_path, f"prior: {path}", robot="motoman_sk120"))


def test_another_robots_model_as_the_prior_helps_a_few_poses(ur10, calibrated):
    """Robot B of the same type as A (its rows 0.1 mm / 0.01 deg from A's): 10 poses of B with A's model as the
    prior (its values, their plausible errors) land nearer B's truth than 10 poses alone, A's model, or the plausible
    prior about nominal."""
    from partcal.calibration.parameters import PLAUSIBLE_ERROR
    from partcal.models.kinematic import KinematicModel
    from partcal.study.persist import load_model
    from partcal.study.update import type_prior
    path, truth_a = calibrated
    units = np.array([u for _, u in parameter_names(ur10)])
    truth_b = truth_a + np.random.default_rng(31).normal(size=units.size) * np.where(units == "mm", 0.1, 0.01) \
        * (np.arange(units.size) < 24)
    m = measured_set(ur10, truth_b, poses(ur10, 10, 32), 33, noise=0.1)
    model_a = load_model(path)[0]
    prior = type_prior(model_a, PLAUSIBLE_ERROR)
    with_prior = KinematicModel(robot=ur10, prior=prior, prior_strength=1.0).fit(m.q_deg, m.errors_mm)
    at_nominal = KinematicModel(robot=ur10, prior="plausible", prior_strength=1.0).fit(m.q_deg, m.errors_mm)
    alone = KinematicModel(robot=ur10).fit(m.q_deg, m.errors_mm)
    q = poses(ur10, 300, 34)
    truth = model_positions(ur10, None, q, truth_b, np.zeros(len(q))) - ur10.positions(q)

    def rms(model):
        return np.sqrt(np.mean(np.sum((model.predict(q) - truth) ** 2, axis=1)))
    assert rms(with_prior) < 0.75 * rms(alone)                # 0.20 mm against 0.30
    assert rms(with_prior) < 0.6 * rms(model_a)               # A's model alone: 0.39
    assert rms(with_prior) < 0.5 * rms(at_nominal)            # the datasheet prior about nominal: 0.48


def test_a_robot_files_plausible_error_sets_the_plausible_prior(ur10):
    from partcal import ConfigError
    from partcal.calibration.parameters import geometric_size
    from partcal.models.kinematic import KinematicModel
    from partcal.robot.description import robot_from_dict, robot_to_dict
    spec = robot_to_dict(ur10)
    own = robot_from_dict({**spec, "plausible_error": {"mm": 0.2}})
    assert own.plausible_error == {"mm": 0.2} and robot_to_dict(own)["plausible_error"] == {"mm": 0.2}
    q = poses(ur10, 30, 41)
    y = model_positions(ur10, None, q, moved(ur10, 42), np.zeros(len(q))) - ur10.positions(q)
    fitted = KinematicModel(robot=own, prior="plausible", prior_strength=2.0).fit(q, y).identification_
    units = [u for _, u in parameter_names(ur10)]
    expected = identify(ur10, q, ur10.positions(q) + y, prior=plausible_prior(
        units, geometric_size(ur10) - 9, nominal_values(ur10), 2.0, {"mm": 0.2, "deg": 0.1}))
    np.testing.assert_allclose(fitted.value, expected.value, atol=1e-9)
    with pytest.raises(ConfigError, match=r"plausible_error: expected numbers > 0"):
        robot_from_dict({**spec, "plausible_error": {"mm": 0}})
    with pytest.raises(ConfigError, match=r"plausible_error: expected \{mm: LENGTH, deg: ANGLE\}"):
        robot_from_dict({**spec, "plausible_error": {"m": 1}})


def test_a_run_chooses_the_prior_strength_on_its_own_folds_by_the_one_se_rule(tmp_path):
    """A list of strengths in a run: each scored on the run's folds (a pose's rows together), the strongest
    within one standard error of the lowest chosen; the folds and the rule written out here."""
    from partcal.models.kinematic import KinematicModel
    from partcal.study.config import load_config
    from partcal.study.runner import run
    from partcal.study.selection import grouped_splits, measured_poses
    strengths = (0.03, 0.1, 0.3, 0.5, 1.0, 10.0)
    cfg = load_config(run_config(tmp_path, f"prior: plausible, prior_strength: {list(strengths)}", "motoman_sk120"))
    result = run(cfg)
    r = result.models[0]
    ident = result.datasets["identification"]
    groups = measured_poses(ident)
    folds = grouped_splits(groups, 5, cfg.seed)
    scores, errors = [], []
    for s in strengths:
        left = np.empty_like(ident.errors_mm)
        for train, test in folds:
            fit = KinematicModel(robot=r.model.robot, prior="plausible", prior_strength=s)
            left[test] = ident.errors_mm[test] - fit.fit(ident.q_deg[train], ident.errors_mm[train]).predict(
                ident.q_deg[test])
        per_pose = np.bincount(groups, weights=np.sum(left ** 2, axis=1))
        rows = np.bincount(groups).astype(float)
        mse = per_pose.sum() / rows.sum()
        scores.append(np.sqrt(mse))
        se_mse = np.sqrt(np.sum((per_pose - mse * rows) ** 2) / (len(rows) * (len(rows) - 1))) / rows.mean()
        errors.append(se_mse / (2 * np.sqrt(mse)))
    best = int(np.argmin(scores))
    chosen = max(s for s, v in zip(strengths, scores) if v <= scores[best] + errors[best])
    assert chosen != strengths[best]                          # the rule, not the lowest score, decides here
    assert [row["prior_strength"] for row in r.prior_strength] == list(strengths)
    np.testing.assert_allclose([row["cv_rms_3d"] for row in r.prior_strength], scores, rtol=1e-9)
    np.testing.assert_allclose([row["cv_se"] for row in r.prior_strength], errors, rtol=1e-9)
    assert [row["chosen"] for row in r.prior_strength] == [s == chosen for s in strengths]
    assert r.model.prior_strength == chosen and r.nested
    assert any(note.startswith(f"prior strength {chosen:g} chosen by the run's cross-validation") for note in r.notes)
    plain = KinematicModel(robot=r.model.robot, prior="plausible", prior_strength=chosen).fit(ident.q_deg,
                                                                                              ident.errors_mm)
    np.testing.assert_allclose(r.model.identification_.value, plain.identification_.value, rtol=0, atol=1e-12)


def test_a_run_refuses_lists_of_both_granularities_and_prior_strengths(tmp_path):
    from partcal import ConfigError
    from partcal.study.config import load_config
    entry = ("prior: plausible, prior_strength: auto, residual: {inputs: joint, degree: 1, solver: {method: lstsq}, "
             "partition: {method: kmeans, n_regions: [2, 3]}}")
    with pytest.raises(ConfigError, match=r"models\[0\]\.prior_strength \(line 6\): the run's cross-validation "
                                          r"chooses one list per entry"):
        load_config(run_config(tmp_path, entry, "motoman_sk120"))
    cfg = load_config(run_config(tmp_path, "prior: plausible, prior_strength: auto", "motoman_sk120"))
    assert cfg.models[0].strengths == (0.1, 0.178, 0.316, 0.562, 1.0, 1.778, 3.162, 5.623, 10.0, 17.783, 31.623)


# ---------------------------------------------------------------------- a prior's pieces, against values worked out by hand
def rotation_z(deg):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_a_prior_from_standard_deviations_weighs_each_row_by_the_noise_over_its_deviation():
    prior = Prior.from_std([2, 0], [1.0, -3.0], [0.5, 4.0], 0.2)
    np.testing.assert_allclose(prior.root, [[0.4, 0.0], [0.0, 0.05]])          # 0.2 / 0.5, 0.2 / 4
    values = np.array([5.0, 7.0, 3.5])
    np.testing.assert_allclose(prior.rows(values), [0.4 * (3.5 - 1.0), 0.05 * (5.0 + 3.0)])
    assert prior.size == 2
    assert Prior.from_std([0], [0.0], [0.5], 0.0).root.tolist() == [[0.0]]     # no noise: a prior of zero weight
    for std, noise in (([0.0], 1.0), ([-1.0], 1.0), ([np.inf], 1.0), ([np.nan], 1.0), ([1.0], -0.5)):
        with pytest.raises(ValueError, match="standard deviations > 0 and a noise >= 0"):
            Prior.from_std([0], [0.0], std, noise)


def test_a_prior_covariances_root_squares_to_the_noise_squared_over_the_covariance():
    """``W^T W = sigma^2 C^-1`` for a covariance built from a known turn and known variances (4, 1, 0.25)."""
    turn = rotation_z(30.0)
    cov = turn @ np.diag([4.0, 1.0, 0.25]) @ turn.T
    prior = Prior.from_covariance([0, 1, 2], [0.0, 0.0, 0.0], cov, 0.3)
    expected = 0.09 * turn @ np.diag([0.25, 1.0, 4.0]) @ turn.T
    np.testing.assert_allclose(prior.root.T @ prior.root, expected, atol=1e-12)
    # one standard deviation along each principal axis costs a row of length sigma
    for axis, std in zip(turn.T, [2.0, 1.0, 0.5]):
        assert np.linalg.norm(prior.rows(std * axis)) == pytest.approx(0.3)
    # only the symmetric part counts: an antisymmetric addition changes nothing
    skew = np.array([[0.0, 0.7, -0.2], [-0.7, 0.0, 0.4], [0.2, -0.4, 0.0]])
    skewed = Prior.from_covariance([0, 1, 2], [0.0, 0.0, 0.0], cov + skew, 0.3)
    np.testing.assert_allclose(skewed.root.T @ skewed.root, expected, atol=1e-12)


def test_a_singular_prior_covariance_holds_its_null_direction_at_the_eigenvalue_floor():
    """A covariance singular to rounding (variances 4, 1 and 0 or -1e-20) is accepted; the null direction gets the
    variance EIGEN_FLOOR times the largest (4e-12), so one unit along it costs sigma / 2e-6."""
    from partcal.calibration.prior import EIGEN_FLOOR
    assert EIGEN_FLOOR == 1e-12
    turn = rotation_z(40.0)
    for smallest in (0.0, -1e-20):
        cov = turn @ np.diag([4.0, 1.0, smallest]) @ turn.T
        prior = Prior.from_covariance([0, 1, 2], [0.0, 0.0, 0.0], cov, 0.5)
        assert np.linalg.norm(prior.rows(np.array([0.0, 0.0, 1.0]))) == pytest.approx(0.5 / 2e-6, rel=1e-6)
        assert np.linalg.norm(prior.rows(turn[:, 0])) == pytest.approx(0.5 / 2.0, rel=1e-9)
    small = Prior.from_covariance([1], [0.0], [[0.5]], 1.0)                    # a largest variance below 1
    assert small.root.tolist() == [[pytest.approx(np.sqrt(2.0))]]
    empty = Prior.from_covariance([], [], np.zeros((0, 0)), 1.0)               # nothing held
    assert empty.size == 0 and empty.rows(np.array([1.0, 2.0])).size == 0
    for bad in (np.zeros((2, 2)), -0.5 * np.eye(2), -np.eye(1)):
        with pytest.raises(ValueError, match="positive definite"):
            Prior.from_covariance(list(range(len(bad))), np.zeros(len(bad)), bad, 1.0)
    with pytest.raises(ValueError, match="finite"):
        Prior.from_covariance([0, 1], [0.0, 0.0], [[1.0, 0.0], [0.0, np.nan]], 1.0)
    for shape in ((1, 1), (2, 1), (2, 3), (3, 3)):                            # smaller or larger than (2, 2)
        with pytest.raises(ValueError, match=r"\(2, 2\) matrix"):
            Prior.from_covariance([0, 1], [0.0, 0.0], np.eye(*shape), 1.0)


def test_a_priors_jacobian_is_its_rows_finite_differences_and_augmented_appends_both():
    prior = Prior.from_covariance([3, 1], [0.5, -1.0], [[2.0, 0.3], [0.3, 0.5]], 0.1)
    values = np.array([0.2, 0.7, -0.4, 1.9, 3.0])
    step = 1e-6
    numeric = np.column_stack([(prior.rows(values + step * e) - prior.rows(values - step * e)) / (2 * step)
                               for e in np.eye(values.size)])
    np.testing.assert_allclose(prior.jacobian(values.size), numeric, atol=1e-9)
    assert prior.held(5).tolist() == [False, True, False, True, False]

    def model(v, jacobian=True):                                 # two residuals: v0 + v4, 2 v2
        return np.array([v[0] + v[4], 2 * v[2]]), (np.array([[1.0, 0, 0, 0, 1], [0, 0, 2, 0, 0]]) if jacobian else None)
    resid, jac = prior.augmented(model)(values)
    np.testing.assert_allclose(resid, np.concatenate([[3.2, -0.8], prior.rows(values)]))
    np.testing.assert_allclose(jac, np.vstack([[[1.0, 0, 0, 0, 1], [0, 0, 2, 0, 0]], numeric]), atol=1e-9)
    resid, jac = prior.augmented(model)(values, jacobian=False)
    assert jac is None and resid.size == 4


def test_a_prior_refuses_a_fit_of_other_parameters_or_fewer_than_it_holds():
    prior = Prior.from_std([2], [0.0], [1.0], 1.0)
    prior.check_names(["a", "b", "c"])                           # names unknown: not compared
    named = Prior(prior.index, prior.mean, prior.root, names=("a", "b", "c"))
    named.check_names(["a", "b", "c"])
    for other in (["a", "b", "x"], ["a", "b", "b"], ["a", "b"]):
        with pytest.raises(ValueError, match="made for the parameters a, b, c"):
            named.check_names(other)
    with pytest.raises(ValueError, match="holds parameter 2; this fit has 2"):
        prior.check_names(["a", "b"])                            # index 2 == len: one beyond the last
    with pytest.raises(ValueError, match="holds parameter 2; this fit has 1"):
        prior.check_names(["a"])


def test_the_auto_strength_grid_is_four_to_a_decade_from_a_tenth():
    from partcal.calibration.prior import STRENGTH_GRID, strengths_of
    assert STRENGTH_GRID == (0.1, 0.178, 0.316, 0.562, 1.0, 1.778, 3.162, 5.623, 10.0, 17.783, 31.623)
    assert strengths_of("auto") == STRENGTH_GRID
    assert strengths_of((2, 1.5, 2)) == (1.5, 2.0) and strengths_of(0) == (0.0,)


def test_a_prior_strength_is_a_number_at_least_zero_auto_or_a_list_of_different_ones():
    from partcal.calibration.prior import strength_problem
    for good in (0, 0.5, 2, "auto", [0, 0.5], (1, 3)):
        assert strength_problem(good) is None, good
    for bad in (-0.5, -1, True, float("inf"), float("nan"), "automatic", "", [], None):
        assert strength_problem(bad) == "a number >= 0, auto, or a non-empty list of numbers >= 0", bad
    assert strength_problem([1, 1]) == "a list of different numbers (item 2 repeats 1)"
    assert strength_problem([0.5, -0.5]) == "a non-empty list of numbers >= 0 (item 2 is -0.5)"
    assert strength_problem([False]) == "a non-empty list of numbers >= 0 (item 1 is False)"


def test_the_strongest_prior_within_one_standard_error_and_what_no_finite_score_chooses():
    from partcal.calibration.prior import strongest_within
    nan = float("nan")
    assert strongest_within([1, 3, 10], [0.40, 0.405, 0.50], [0.01, 0.01, 0.01]) == 1    # 0.405 <= 0.41 < 0.50
    assert strongest_within([10, 3, 1], [0.50, 0.405, 0.40], [0.01, 0.01, 0.01]) == 1    # order of the list aside
    assert strongest_within([1, 3], [nan, nan], [nan, nan]) == 0                          # nothing to compare: the first
    assert strongest_within([1, 1], [0.4, 0.4], [0.0, 0.0]) == 0                          # a tie: the first listed


def test_the_strength_note_warns_only_when_the_lowest_score_is_at_a_weakest_strength_above_zero():
    from partcal.calibration.prior import strength_note, strength_rows
    warning = "the lowest is at the weakest strength tried: weaker ones, not tried, may do better"
    best, table = strength_rows([3, 1], [0.415, 0.41], [0.001, 0.001])
    assert best == 1 and [row["chosen"] for row in table] == [False, True]
    assert strength_note(table, "CV").endswith(warning)                       # lowest at 1, the weakest
    alone = strength_rows([3], [0.415], [0.001])[1]
    assert not strength_note(alone, "CV").endswith(warning)                   # one strength: nothing weaker to try
    zero = strength_rows([0, 1], [0.41, 0.415], [0.001, 0.001])[1]
    assert not strength_note(zero, "CV").endswith(warning)                    # the weakest is no prior at all
    for strengths, scores in (([0.5, 1], [0.415, 0.41]), ([1, 0.5], [0.41, 0.415])):
        above = strength_rows(strengths, scores, [0.001, 0.001])[1]
        assert not strength_note(above, "CV").endswith(warning)               # the lowest is not the weakest


def test_the_plausible_prior_holds_the_first_rows_parameters_of_a_unit_it_knows():
    units = ["mm", "deg", "count", "mm", "mm"]
    nominal = np.array([10.0, 20.0, 30.0, 40.0, 50.0])
    prior = plausible_prior(units, 4, nominal, 0.5, {"mm": 0.25, "deg": 0.1})
    assert prior.index.tolist() == [0, 1, 3] and prior.mean.tolist() == [10.0, 20.0, 40.0]
    np.testing.assert_allclose(np.diag(prior.root), [2.0, 5.0, 2.0])             # 0.5 / 0.25, 0.5 / 0.1
    assert plausible_prior(units, 4, nominal, 0, {"mm": 0.25}) is None
    assert plausible_prior(units, 4, nominal, 1, {"mm": 0.25}).index.tolist() == [0, 3]
    with pytest.raises(ValueError, match="a noise >= 0"):
        plausible_prior(units, 4, nominal, -1.0, {"mm": 0.25})                 # a negative strength is no prior
