"""Kinematic identification and hybrid models: exact recovery, identifiability, standard errors."""

import numpy as np
import pytest
from conftest import ROOT, tilted_dh_chain
from sklearn.base import clone

from partcal import ErrorModel, GaussianProcessErrorModel, KinematicModel, PartcalError, read_measurements
from partcal.calibration.identification import identify
from partcal.calibration.parameters import nominal_values, parameter_names, robot_with
from partcal.robot.description import robot_from_dict

# A planar arm: two parallel joint axes (alpha = 0) and a tool on the last x axis. Worked out by hand,
# positions alone cannot tell apart: d[1], d[2], tool.z and base.z (all slide along z), a[2] and tool.x
# (both along the last x axis), theta[2] and tool.y (to first order both move the tool across that axis),
# theta[1] and base.rz (both turn the whole arm about z0); alpha[2] turns about the axis the tool lies on,
# so it moves nothing. Everything else (a[1], alpha[1], base.x, base.y, base.rx, base.ry) stands alone:
# ten identifiable directions of seventeen.
PLANAR = {"name": "planar2", "joints": 2, "tool_mm": [100, 0, 0], "limits_deg": [[-170, 170], [-150, 150]],
          "links": [{"theta": "q1", "d": 0, "a": 500, "alpha": 0}, {"theta": "q2", "d": 0, "a": 400, "alpha": 0}]}
GROUPS = [{"d[1]", "d[2]", "tool.z", "base.z"}, {"a[2]", "tool.x"}, {"theta[2]", "tool.y"}, {"theta[1]", "base.rz"}]
ALONE = {"a[1]", "alpha[1]", "base.x", "base.y", "base.rx", "base.ry"}


def test_planar_arm_identifiability_matches_the_hand_derivation():
    robot = robot_from_dict(PLANAR)
    q = np.random.default_rng(0).uniform([-170, -150], [170, 150], (40, 2))
    table = identify(robot, q, robot.positions(q))
    status = dict(zip(table.names, table.status))
    assert table.rank == 10
    for group in GROUPS:
        assert sorted(status[n] for n in group) == ["identified"] + ["unidentifiable"] * (len(group) - 1), group
    assert {n for n in ALONE if status[n] == "identified"} == ALONE
    assert status["alpha[2]"] == "unidentifiable"


def sk120_poses(sk120, n, seed, wrist=True):
    rng = np.random.default_rng(seed)
    ranges = np.array([[-60, 60], [-160, -100], [-205, -145], [-150, 150], [-100, 100], [-90, 90]], dtype=float)
    q = rng.uniform(ranges[:, 0], ranges[:, 1], (2 * n, 6))
    if not wrist:
        q[:, 3:5] = 0.0
    return q[sk120.within_limits(q)][:n]


def deviations(robot, seed):
    """A random error of every parameter: 1 mm for lengths, 0.1 degree for angles."""
    units = np.array([u for _, u in parameter_names(robot)])
    return np.random.default_rng(seed).normal(size=units.size) * np.where(units == "mm", 1.0, 0.1)


@pytest.mark.parametrize("wrist", [True, False])
def test_noise_free_identification_recovers_the_identifiable_parameters_exactly(sk120, wrist):
    q = sk120_poses(sk120, 200, 1, wrist)
    probe = identify(sk120, q, sk120.positions(q))        # which parameters positions identify here
    free = np.array([s == "identified" for s in probe.status])
    true = nominal_values(sk120) + deviations(sk120, 2) * free
    measured = robot_with(sk120, true).positions(q)
    model = KinematicModel(robot=sk120).fit(q, measured - sk120.positions(q))
    table = model.identification_
    np.testing.assert_allclose(table.value[free], true[free], rtol=0, atol=1e-8)
    np.testing.assert_array_equal(table.value[~free], nominal_values(sk120)[~free])     # never moved
    assert table.unidentifiable() == [n for n, f in zip(table.names, free) if not f]
    assert table.rms_mm < 1e-9
    assert np.all(np.isnan(table.std_error[~free])) and np.all(table.std_error[free] >= 0)
    other = sk120_poses(sk120, 50, 3, wrist)
    np.testing.assert_allclose(model.predict(other), robot_with(sk120, true).positions(other)
                               - sk120.positions(other), atol=1e-8)
    if not wrist:     # q4 = q5 = 0 hide more: the wrist rows' offsets and twists cannot all be told apart
        moving = sk120_poses(sk120, 200, 1, wrist=True)
        assert table.rank < identify(sk120, moving, sk120.positions(moving)).rank


def test_errors_in_unidentifiable_parameters_are_absorbed_by_the_others(sk120):
    """Every parameter off: the identified set still reproduces the positions (up to second-order terms)."""
    q = sk120_poses(sk120, 200, 4)
    true = robot_with(sk120, nominal_values(sk120) + deviations(sk120, 5))
    model = KinematicModel(robot=sk120).fit(q, true.positions(q) - sk120.positions(q))
    assert model.identification_.rms_mm < 1e-3           # against errors of several mm before
    assert np.sqrt(np.mean(np.sum((true.positions(q) - sk120.positions(q)) ** 2, axis=1))) > 3


def test_standard_errors_match_the_scatter_over_noise_draws(sk120):
    q = sk120_poses(sk120, 120, 6)
    true = robot_with(sk120, nominal_values(sk120) + deviations(sk120, 7))
    exact = true.positions(q)
    rng = np.random.default_rng(8)
    values, errors = [], []
    for _ in range(40):
        table = identify(sk120, q, exact + rng.normal(0, 0.05, exact.shape))
        values.append(table.value)
        errors.append(table.std_error)
    free = np.array([s == "identified" for s in table.status])
    scatter = np.std(values, axis=0)[free]
    reported = np.mean(errors, axis=0)[free]
    ratio = scatter / reported
    assert 0.7 < np.median(ratio) < 1.3 and ratio.min() > 0.5 and ratio.max() < 1.6, ratio
    assert table.condition > 1 and np.isfinite(table.condition)


@pytest.fixture(scope="module")
def paper_data():
    return read_measurements(ROOT / "data" / "sk120" / "identification.csv")


@pytest.mark.parametrize("residual", [
    ErrorModel(inputs="joint", degree=2, solver="lstsq"),
    ErrorModel(inputs="cartesian", degree=1, solver="lstsq"),
    GaussianProcessErrorModel(inputs="joint", restarts=0),
])
def test_hybrid_is_the_kinematic_model_plus_the_residual_fitted_on_what_it_leaves(sk120, paper_data, residual):
    q, y = paper_data.q_deg, paper_data.errors_mm
    hybrid = KinematicModel(robot=sk120, residual=residual, random_state=0).fit(q, y)
    kinematic = KinematicModel(robot=sk120).fit(q, y)
    leftover = y - kinematic.predict(q)
    X = q if residual.inputs == "joint" else sk120.positions(q)
    part = clone(residual).set_params(random_state=hybrid.residual_.random_state).fit(X, leftover)
    test = read_measurements(ROOT / "data" / "sk120" / "test_rectangle.csv")
    Xt = test.q_deg if residual.inputs == "joint" else sk120.positions(test.q_deg)     # FK, not the CSV columns
    np.testing.assert_allclose(hybrid.predict(test.q_deg), kinematic.predict(test.q_deg) + part.predict(Xt),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(hybrid.predict_kinematic(test.q_deg), kinematic.predict(test.q_deg), rtol=0, atol=0)


def test_bad_parameters_and_inputs_are_refused(sk120, paper_data):
    q, y = paper_data.q_deg, paper_data.errors_mm
    with pytest.raises(PartcalError, match=r"The 'robot' parameter of KinematicModel must be a Robot, a built-in "
                                           r"robot name or a robot YAML path\. Got None instead\."):
        KinematicModel().fit(q, y)
    with pytest.raises(PartcalError, match=r"The 'rcond' parameter of KinematicModel must be a real number in "
                                           r"\(0\.0, 1\.0\]\. Got 0 instead\."):
        KinematicModel(robot=sk120, rcond=0).fit(q, y)
    with pytest.raises(PartcalError, match=r"The 'residual' parameter of KinematicModel must be None or a model "
                                           r"of a kind that may be a residual \(series, .*Got KinematicModel"):
        KinematicModel(robot=sk120, residual=KinematicModel(robot=sk120)).fit(q, y)
    with pytest.raises(PartcalError, match=r"KinematicModel for motoman_sk120 takes 6 joint angles \(degrees\) "
                                           r"per sample; got X with 5 columns"):
        KinematicModel(robot="motoman_sk120").fit(q[:, :5], y)
    with pytest.raises(PartcalError, match=r"Expected y with shape \(n, 3\) \(position errors, mm\) or \(n, 6\) "
                                           r"\(pose errors: .*\), got array with shape \(85, 2\)"):
        KinematicModel(robot=sk120).fit(q, y[:, :2])


def test_model_files_round_trip_bit_for_bit(tmp_path, sk120, paper_data):
    from partcal import KMeansPartition, PartitionedErrorModel
    from partcal.study.persist import load_model, model_to_dict, save_model

    residual = PartitionedErrorModel(partition=KMeansPartition(2, min_samples=20),
                                     local=GaussianProcessErrorModel(inputs="joint", restarts=0))
    model = KinematicModel(robot=sk120, residual=residual, random_state=0).fit(paper_data.q_deg, paper_data.errors_mm)
    save_model(model, tmp_path / "hybrid.json", name="DH + GP k-means", robot=sk120)
    loaded, doc = load_model(tmp_path / "hybrid.json")
    assert doc["kind"] == "kinematic" and doc["model"]["residual"]["kind"] == "partitioned"
    test = read_measurements(ROOT / "data" / "sk120" / "test_spiral_yz.csv")
    assert np.array_equal(loaded.predict(test.q_deg), model.predict(test.q_deg))
    assert np.array_equal(loaded.predict_kinematic(test.q_deg), model.predict_kinematic(test.q_deg))
    assert model_to_dict(loaded) | {"partcal_version": 0} == model_to_dict(model) | {"partcal_version": 0}


def _tilted_ur10(seed):
    """A UR10 with DH errors, a 120 mm tool and tilts about y between the parallel axes 2-3 (0.03 deg) and
    3-4 (-0.02 deg), written as 4 x 4 matrices from the published DH table (not from partcal's walk)."""
    rng = np.random.default_rng(seed)
    d = np.array([118.0, 0, 0, 163.9, 115.7, 92.2]) + rng.normal(0, 0.5, 6)
    a = np.array([0.0, -612.7, -571.6, 0, 0, 0]) + rng.normal(0, 0.5, 6)
    alpha = np.radians([90.0, 0, 0, 90, -90, 0])
    offset = rng.normal(0, 0.05, 6)

    def positions(q):
        out = tilted_dh_chain(q, d, a, alpha, offset, {1: 0.03, 2: -0.02})
        return (out @ [0.3, -0.2, 120.4, 1.0])[:, :3]
    return positions


def test_complete_parametrization_represents_tilts_between_parallel_axes():
    """Noise-free: the complete model predicts a robot with tilts between parallel axes to 1e-3 mm on new
    poses; DH rows cannot hold the tilts and leave more than 0.05 mm. (Not to rounding: the rank rule
    prunes at the nominal robot, whose axes are parallel, and what it drops there is redundant only to
    first order once the axes tilt; about 1e-4 mm here, far below a tracker's noise.)"""
    from partcal import load_robot

    truth = _tilted_ur10(3)
    nominal = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    rng = np.random.default_rng(4)
    q, other = rng.uniform(-180, 180, (200, 6)), rng.uniform(-180, 180, (200, 6))
    left, identified = {}, {}
    for par in ("dh", "complete"):
        model = KinematicModel(robot=nominal, parametrization=par).fit(q, truth(q) - nominal.positions(q))
        miss = model.predict(other) - (truth(other) - nominal.positions(other))
        left[par] = float(np.sqrt(np.mean(np.sum(miss**2, axis=1))))
        identified[par] = model.identification_.status.count("identified")
    assert left["complete"] < 1e-3 and left["dh"] > 0.05, left
    table = model.identification_
    assert table.names[:7] == ("theta[1]", "x[1]", "y[1]", "z[1]", "rx[1]", "ry[1]", "rz[1]")
    # two pairs of parallel axes (2-3, 3-4), each with one tilt DH cannot hold; the rest pruned by rank
    assert identified["complete"] == identified["dh"] + 2 and identified["complete"] < len(table.names)


def test_complete_parameter_jacobian_matches_finite_differences():
    """The complete rows' columns (theta, shifts, turns at non-zero values), tool and base, against central
    differences of the forward kinematics of the corrected robot."""
    from partcal import load_robot
    from partcal.calibration.chain import identification_jacobian
    from partcal.calibration.parameters import geometric_size

    ur10 = load_robot("universal_robots_ur10")
    robot = ur10.replace(origins=np.tile([1.0, -2.0, 3.0, 0.5, -1.0, 2.0], (6, 1)))
    rng = np.random.default_rng(5)
    q = rng.uniform(-180, 180, (5, 6))
    values = nominal_values(robot, parametrization="complete") + rng.normal(0, 0.1, geometric_size(robot, "complete"))
    p, jac = identification_jacobian(robot, q, values, "complete")
    h = 1e-6
    for k in range(values.size):
        up, down = values.copy(), values.copy()
        up[k] += h
        down[k] -= h
        numeric = (robot_with(robot, up, "complete").positions(q) - robot_with(robot, down, "complete").positions(q))
        np.testing.assert_allclose(jac[:, k], numeric.ravel() / (2 * h), atol=2e-6, err_msg=f"column {k}")


def test_complete_model_files_round_trip_and_refuse_what_it_cannot_fit(tmp_path):
    from partcal import load_robot
    from partcal.study.persist import load_model, save_model

    truth = _tilted_ur10(6)
    nominal = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    q = np.random.default_rng(7).uniform(-180, 180, (80, 6))
    model = KinematicModel(robot=nominal, parametrization="complete").fit(q, truth(q) - nominal.positions(q))
    save_model(model, tmp_path / "complete.json", name="complete", robot=nominal)
    loaded, doc = load_model(tmp_path / "complete.json")
    assert doc["model"]["parametrization"] == "complete" and loaded.parametrization == "complete"
    assert np.array_equal(loaded.predict(q), model.predict(q))
    with pytest.raises(PartcalError, match="parametrization.*one of"):
        KinematicModel(robot=nominal, parametrization="hayati").fit(q, truth(q))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_joints_held_still_but_read_back_with_jitter_identify_as_held_ones(sk120, paper_data, seed, caplog):
    """q4, q5 never move (the paper's poses) but read back with 0.001 degrees of noise: the identification is
    that of the same data with q4 = q5 = 0 exactly (rank, fit), and nothing is identified from the jitter."""
    rng = np.random.default_rng(seed)
    rows = np.r_[np.arange(85), rng.choice(85, 20, replace=False)]
    exact = paper_data.q_deg[rows]
    jittered = exact.copy()
    jittered[:, 3:5] += rng.normal(0.0, 0.001, (len(rows), 2))
    measured = paper_data.measured_mm[rows] + rng.normal(0.0, 0.02, (len(rows), 3))
    held = KinematicModel(robot=sk120).fit(exact, measured - sk120.positions(exact))
    with caplog.at_level("WARNING", logger="partcal.calibration.identification"):
        model = KinematicModel(robot=sk120).fit(jittered, measured - sk120.positions(jittered))
    assert model.identification_.rank == held.identification_.rank == 19
    assert "kept nominal" not in caplog.text                  # no wild value from the jitter had to be pruned
    left = measured - sk120.positions(jittered) - model.predict(jittered)
    left_held = measured - sk120.positions(exact) - held.predict(exact)
    assert np.sqrt(np.mean(np.sum(left**2, axis=1))) == pytest.approx(np.sqrt(np.mean(np.sum(left_held**2, axis=1))),
                                                                      abs=0.005)


def test_column_pivoting_without_ties_picks_the_columns_pivoted_qr_picks():
    """Away from ties the greedy choice is QR's column pivoting (scipy's LAPACK geqp3), order included."""
    import scipy.linalg

    from partcal.calibration.identifiability import _most_independent

    columns = np.random.default_rng(3).normal(size=(40, 9)) * np.geomspace(1, 20, 9)
    pivots = scipy.linalg.qr(columns, mode="r", pivoting=True)[1]
    assert _most_independent(columns, 9).tolist() == pivots.tolist()


@pytest.mark.parametrize("seed", range(5))
def test_which_of_exactly_dependent_parameters_is_identified_does_not_depend_on_rounding(seed):
    """The UR10's identification Jacobian from positions (base frame included) has exactly dependent columns
    (joint 1's offset and the base's turn about z, among others). Rounding at the level different BLAS kernels
    leave (1e-14 of a column) must not change which of them is kept: the first in the table is, always."""
    from partcal import load_robot
    from partcal.calibration.chain import identification_jacobian
    from partcal.calibration.identifiability import identifiable_parameters

    robot = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    q = np.random.default_rng(11).uniform(-180, 180, (60, 6))
    full = identification_jacobian(robot, q, nominal_values(robot), "dh")[1]
    wanted = np.ones(full.shape[1], dtype=bool)
    units = ["mm"] * full.shape[1]
    reference, rank = identifiable_parameters(full, wanted, 1e-10, units)
    rng = np.random.default_rng(seed)
    shaken = full * (1 + 1e-14 * rng.standard_normal(full.shape))
    assert identifiable_parameters(shaken, wanted, 1e-10, units)[0].tolist() == reference.tolist()
    assert rank < np.count_nonzero(np.linalg.norm(full, axis=0) > 0)       # there are dependent columns to choose from
