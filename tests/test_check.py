"""``partcal check`` on a virtual UR10: unchanged data hold, a moved joint offset and a changed tool are found and
ranked first, the statistic and its p-value against an independent computation, bad inputs refused; a joint offset
under a drifting frame and a frame change told apart (forward selection where joint 1 moves little), the share of
an explanation the likeliest reproduces against an independent finite difference."""

import dataclasses

import numpy as np
import pytest
from conftest import partcal_cli, write_text
from scipy.stats import chi2

from partcal.data.measurements import Measurements, read_measurements, write_measurements
from partcal.data.sampling import sample_configurations
from partcal.data.simulate import load_study
from partcal.models.kinematic import KinematicModel
from partcal.models.series import ErrorModel
from partcal.study.check import check_arrays, check_file
from partcal.study.persist import load_model, save_model
from partcal.study.spread import calibrate_spread

STUDY = """robot: universal_robots_ur10
seed: 41
output: out
targets:
  A: [0, 0, 120]
errors:
  dh_sigma: {length_mm: 0.5, twist_deg: 0.03, zero_offset_deg: 0.05}
  tool_mm: [0.3, -0.2, 0.4]
  base: {rotation_deg: [0.02, -0.03, 0.04], translation_mm: [1.0, -0.5, 0.8]}
tracker: {position_mm: [2500, 0, 0], accuracy_ppm: 0, repeatability_ppm: 10, readings: 1}
sampling:
  ranges_deg: {q1: [-90, 90], q2: [-150, -30], q3: [-140, 140], q4: [-180, 180], q5: [-150, 150], q6: [-180, 180]}
datasets:
  identification: {sample: 10}
"""


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A virtual UR10, its DH model identified from 150 poses with a calibrated spread (a model file), and a
    function measuring new poses on it into a CSV."""
    folder = tmp_path_factory.mktemp("check")
    study = load_study(write_text(folder, STUDY, "virtual.yaml"))
    virtual, rng = study.robot, np.random.default_rng(41)
    q = sample_configurations(virtual.nominal, 190, study.ranges_deg, {}, rng)
    train, new = q[:150], q[150:]
    measured = virtual.measure(train, rng)
    model = KinematicModel(robot=virtual.nominal)
    calibrate_spread(model, train, measured - virtual.nominal.positions(train), folds=5)
    path = folder / "dh.json"
    save_model(model, path, name="DH", robot=virtual.nominal)

    def measure(name, robot=virtual, read_offset_deg=np.zeros(6)):
        """The 40 new poses measured on ``robot``, the joints written as read (true plus ``read_offset_deg``)."""
        data = Measurements(new + read_offset_deg, virtual.nominal.positions(new + read_offset_deg),
                            robot.measure(new, np.random.default_rng(7)))
        out = folder / f"{name}.csv"
        write_measurements(data, out)
        return out, data
    return path, measure, virtual, folder


def independent_statistic(model_path, csv):
    """The mean squared standardised residual and its p-value, from the model's own prediction and spread."""
    model, data = load_model(model_path)[0], read_measurements(csv)
    mean, std = model.predict_with_std(data.q_deg)
    z = (data.measured_mm - model.robot_.positions(data.q_deg) - mean) / std
    return float(np.mean(z ** 2)), float(chi2.sf(np.sum(z ** 2), z.size))


def test_unchanged_robot_holds_with_the_independent_statistic(cell):
    model_path, measure, _, _ = cell
    csv, data = measure("same")
    result = check_file(model_path, csv)
    mean_z2, p = independent_statistic(model_path, csv)
    assert result.dof == 3 * len(data)
    assert result.mean_z2 == pytest.approx(mean_z2, rel=1e-12)
    assert result.p_value == pytest.approx(p, rel=1e-9)
    assert p >= 0.01 and result.holds
    code, out = (lambda r: (r.returncode, r.stdout))(partcal_cli("check", str(model_path), str(csv)))
    assert code == 0
    assert out.startswith(f"holds: mean squared standardised residual {mean_z2:.3f} over {3 * len(data)} "
                          f"coordinates, p = {p:.3g}")


@pytest.mark.parametrize("shift", [0.05, -0.05])
def test_a_joint_offset_moved_by_five_hundredths_of_a_degree_is_found_and_ranked_first(cell, shift):
    model_path, measure, _, _ = cell
    csv, data = measure(f"q2{shift}", read_offset_deg=np.array([0, shift, 0, 0, 0, 0]))
    result = check_file(model_path, csv)
    mean_z2, p = independent_statistic(model_path, csv)
    assert result.mean_z2 == pytest.approx(mean_z2, rel=1e-12) and p < 1e-6
    assert not result.holds
    best = result.explanations[0]
    assert best.name == "joint 2's offset"
    assert best.change[0] == pytest.approx(-shift, abs=0.005)    # the true angle is the reading minus the shift
    assert best.mean_z2 < 2.0 and best.evidence > result.explanations[1].evidence


def test_a_tool_change_is_found_as_the_tool(cell):
    model_path, measure, virtual, _ = cell
    change = np.array([0.6, -0.4, 0.5])
    retooled = dataclasses.replace(virtual, true=virtual.true.replace(tool_mm=virtual.true.tool_mm + change))
    csv, _ = measure("tool", robot=retooled)
    result = check_file(model_path, csv)
    assert not result.holds
    assert result.explanations[0].name == "the tool offset"
    np.testing.assert_allclose(result.explanations[0].change, change, atol=0.05)
    run = partcal_cli("check", str(model_path), str(csv))
    assert run.returncode == 0 and run.stdout.startswith("moved:") and "most likely the tool offset" in run.stdout


def test_data_in_a_tracker_frame_are_registered_first_and_hold(cell):
    model_path, measure, _, folder = cell
    _, data = measure("base")
    angle = np.radians(30.0)
    turn = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    tracker = data.measured_mm @ turn.T + [2500.0, -300.0, 100.0]
    csv = folder / "tracker.csv"
    header = "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas"
    np.savetxt(csv, np.hstack([data.q_deg, tracker]), delimiter=",", header=header, comments="", fmt="%.9f")
    result = check_file(model_path, csv, frame="tracker")
    assert result.holds and result.dof == 3 * len(data) - 6
    assert all(e.name != "the base frame" for e in result.explanations)
    assert abs(result.registration[0][2]) == pytest.approx(30.0, abs=0.05)     # the turn about z undone
    run = partcal_cli("check", str(model_path), str(csv), "--frame", "tracker", "--rows", "1-20")
    assert run.returncode == 0 and "over 54 coordinates" in run.stdout
    assert "tracker frame was registered on these poses first" in run.stdout


def test_bad_inputs_are_refused_naming_file_and_field(cell, tmp_path):
    model_path, measure, _, _ = cell
    csv, _ = measure("ok")
    missing = partcal_cli("check", str(tmp_path / "none.json"), str(csv))
    assert missing.returncode == 2 and "none.json" in missing.stderr and "no such model file" in missing.stderr
    five = write_text(tmp_path, "q1,q2,q3,q4,q5,x_meas,y_meas,z_meas\n0,-90,90,0,0,1,2,3\n", "five.csv")
    wrong = partcal_cli("check", str(model_path), str(five))
    assert wrong.returncode == 2 and "five.csv" in wrong.stderr and "5 joint columns (q1..q5)" in wrong.stderr
    assert "has 6 joints" in wrong.stderr
    bare = write_text(tmp_path, "q1,q2,q3,q4,q5,q6\n0,-90,90,0,0,0\n", "bare.csv")
    unmeasured = partcal_cli("check", str(model_path), str(bare))
    assert unmeasured.returncode == 2 and "bare.csv" in unmeasured.stderr and "x_meas" in unmeasured.stderr
    for run in (missing, wrong, unmeasured):
        assert "Traceback" not in run.stderr and run.stdout == ""


def test_a_model_without_robot_parameters_is_judged_without_explanations(cell):
    """A Cartesian series model (the robot from its file) is judged by its calibrated spread at the nominal
    positions; there is nothing to explain with."""
    model_path, measure, virtual, folder = cell
    rng = np.random.default_rng(5)
    q = sample_configurations(virtual.nominal, 150, {1: (-90, 90), 2: (-150, -30), 3: (-140, 140)}, {}, rng)
    nominal = virtual.nominal.positions(q)
    series = calibrate_spread(ErrorModel(inputs="cartesian", degree=2, solver="lstsq"), nominal,
                              virtual.measure(q, rng) - nominal, folds=5)
    path = folder / "sdp.json"
    save_model(series, path, name="SDP(CI)", robot=virtual.nominal)
    csv, _ = measure("series", read_offset_deg=np.array([0, 0.05, 0, 0, 0, 0]))
    result, data = check_file(path, csv), read_measurements(csv)
    mean, std = series.predict_with_std(virtual.nominal.positions(data.q_deg))
    z = (data.measured_mm - virtual.nominal.positions(data.q_deg) - mean) / std
    assert result.mean_z2 == pytest.approx(np.mean(z ** 2), rel=1e-9) and result.explanations == ()
    assert "no explanations tried" in "\n".join(result.lines())


def _rigidly_moved(points_mm, rotvec_deg, shift_mm):
    """Points carried by a small rigid motion: turned by ``rotvec_deg`` about the base origin, then shifted."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_rotvec(np.radians(rotvec_deg)).apply(points_mm) + shift_mm


def _window(cell, q1_deg=None, q1_range=(-90, 90), n=50, seed=11):
    """``n`` new poses of the virtual cell (joint 1 within ``q1_range``, or held at ``q1_deg`` when given), measured
    on the true robot, and the loaded model."""
    model_path, _, virtual, _ = cell
    rng = np.random.default_rng(seed)
    q = sample_configurations(virtual.nominal, n, {1: q1_range, 2: (-150, -30), 3: (-140, 140)}, {}, rng)
    if q1_deg is not None:
        q[:, 0] = q1_deg
    return load_model(model_path)[0], q, virtual.measure(q, rng), virtual.nominal


def test_a_joint_offset_under_a_small_frame_drift_is_still_the_joint(cell):
    """Joint 2 read 0.05 degree off while the frame drifts by 0.1 mm and 0.01 degree (a tracker's drift), 50 poses
    spread over joint 1: the joint is ranked first, fitted near the injected change."""
    model, q, measured, nominal = _window(cell)
    read = q + [0, 0.05, 0, 0, 0, 0]
    drifted = _rigidly_moved(measured, [0.01, 0.0, 0.0], [0.1, 0.0, 0.0])
    result = check_arrays(model, read, drifted - nominal.positions(read))
    assert not result.holds
    assert result.explanations[0].name == "joint 2's offset"
    assert result.explanations[0].change[0] == pytest.approx(-0.05, abs=0.01)


def test_a_frame_change_of_the_same_size_is_the_frame(cell):
    """The frame turned by 0.05 degree and shifted by 0.3 mm (at the reach, as much as joint 2's 0.05 degree moves
    the tool): the base frame is ranked first, not joint 2."""
    model, q, measured, nominal = _window(cell)
    moved = _rigidly_moved(measured, [0.05, 0.0, 0.0], [0.0, -0.3, 0.0])
    result = check_arrays(model, q, moved - nominal.positions(q))
    assert not result.holds
    assert result.explanations[0].name == "the base frame"
    assert result.explanations[0].mean_z2 < 2.0
    assert [name for name, _ in result.together] == ["the base frame"]


@pytest.mark.parametrize("seed", [11, 12])
def test_forward_selection_takes_a_joint_offset_beside_a_drifting_frame(cell, seed):
    """50 poses with joint 1 within 20 degrees (as in a window of a real series): a joint 2 turn is mostly what a
    frame change does, and with the frame drifting by 0.1 mm and 0.01 degree besides, forward selection takes
    both (the injected change and the drift), each with positive evidence; the same poses with only the frame
    changed take the frame alone."""
    model, q, measured, nominal = _window(cell, q1_range=(30, 50), seed=seed)
    read = q + [0, 0.05, 0, 0, 0, 0]
    drifted = _rigidly_moved(measured, [0.01, 0.0, 0.0], [0.1, 0.0, 0.0])
    both = check_arrays(model, read, drifted - nominal.positions(read))
    taken = dict(both.together)
    assert set(taken) == {"joint 2's offset", "the base frame"} and min(taken.values()) > 2.0
    assert "beyond it" in both.verdict() and "taken together" in "\n".join(both.lines())
    moved = _rigidly_moved(measured, [0.05, 0.0, 0.0], [0.0, -0.3, 0.0])
    frame = check_arrays(model, q, moved - nominal.positions(q))
    assert [name for name, _ in frame.together] == ["the base frame"] and "beyond it" not in frame.verdict()


def _share_of_joint2_in_frame(model, q, std):
    """Independently of the check: the share of a joint 2 turn's standardised effect (a finite difference of the
    identified robot's positions) that a rigid motion of the frame (three shifts, three turns about the origin)
    reproduces."""
    robot = model.identified_robot_
    step = np.zeros_like(q)
    step[:, 1] = 1e-4
    a = ((robot.positions(q + step) - robot.positions(q - step)) / 2e-4 / std).reshape(-1)
    p = robot.positions(q)
    turns = [np.cross(axis, p) for axis in np.eye(3)]
    frame = np.column_stack([(np.broadcast_to(axis, p.shape) / std).reshape(-1) for axis in np.eye(3)]
                            + [(t / std).reshape(-1) for t in turns])
    fit = frame @ np.linalg.lstsq(frame, a, rcond=None)[0]
    return float(fit @ fit / (a @ a))


@pytest.mark.parametrize("q1_deg", [None, 30.0])
def test_the_share_of_an_explanation_the_likeliest_can_reproduce(cell, q1_deg):
    """A frame change: joint 2's offset's ``shared`` is the share of its effect a frame motion reproduces, computed
    independently; with joint 1 held still a joint 2 turn is a rigid turn about a fixed axis, all of it."""
    model, q, measured, nominal = _window(cell, q1_deg=q1_deg)
    moved = _rigidly_moved(measured, [0.05, 0.0, 0.0], [0.0, -0.3, 0.0])
    result = check_arrays(model, q, moved - nominal.positions(q))
    assert result.explanations[0].name == "the base frame" and result.explanations[0].shared == pytest.approx(1.0)
    joint2 = next(e for e in result.explanations if e.name == "joint 2's offset")
    _, std = model.predict_with_std(q)
    expected = _share_of_joint2_in_frame(model, q, std)
    assert joint2.shared == pytest.approx(expected, abs=1e-4)
    if q1_deg is not None:
        assert expected == pytest.approx(1.0, abs=1e-6)
    else:
        assert expected < 0.9
    assert f"shared {joint2.shared:4.2f}" in "\n".join(result.lines())


@pytest.mark.parametrize("p, verdict", [(0.003, "moved"), (0.03, "holds")])
def test_the_verdict_turns_at_a_p_value_of_one_hundredth(cell, p, verdict):
    """New poses whose standardised residuals are scaled so that their chi-square p-value (scipy's, with 3 n
    degrees of freedom) is 0.003 or 0.03: a tenth and ten times the default significance away from it, the first is
    'moved' and the second 'holds', on the command line too."""
    model_path, measure, _, folder = cell
    _, data = measure(f"p{p}")
    model = load_model(model_path)[0]
    mean, std = model.predict_with_std(data.q_deg)
    z = (data.measured_mm - model.robot_.positions(data.q_deg) - mean) / std
    z *= np.sqrt(chi2.isf(p, z.size) / np.sum(z ** 2))
    csv = folder / f"scaled{p}.csv"
    write_measurements(Measurements(data.q_deg, data.nominal_mm, model.robot_.positions(data.q_deg) + mean + z * std),
                       csv)
    result = check_file(model_path, csv)
    assert result.p_value == pytest.approx(p, rel=1e-3)           # the CSV rounds the positions
    assert result.alpha == 0.01 and result.holds == (verdict == "holds")
    run = partcal_cli("check", str(model_path), str(csv))
    assert run.returncode == 0 and run.stdout.startswith(f"{verdict}:")


def test_check_takes_a_significance_in_zero_one_and_needs_a_degree_of_freedom(cell):
    """A significance outside (0, 1) is refused; within it it sets the verdict (the same poses moved above their
    p-value, hold below it); two poses registered in a tracker frame leave 6 - 6 = 0 coordinates and are refused,
    three leave 3."""
    from partcal import ConfigError
    from partcal.errors import DataError
    model_path, measure, _, _ = cell
    _, data = measure("alpha")
    model = load_model(model_path)[0]
    errors = data.measured_mm - model.robot_.positions(data.q_deg)
    for alpha in (0.0, 1.0, -0.5, 1.5):
        with pytest.raises(ConfigError, match=r"check: alpha must lie in \(0, 1\); got"):
            check_arrays(model, data.q_deg, errors, alpha=alpha)
    p = check_arrays(model, data.q_deg, errors).p_value             # 0.995: the spread is conservative
    assert not check_arrays(model, data.q_deg, errors, alpha=(1.0 + p) / 2).holds
    assert check_arrays(model, data.q_deg, errors, alpha=p / 2).holds
    with pytest.raises(DataError, match=r"2 poses leave no degree of freedom to check once the tracker frame is "
                                        r"registered on them \(give at least 3\)"):
        check_arrays(model, data.q_deg[:2], errors[:2], registered=True)
    three = check_arrays(model, data.q_deg[:3], errors[:3], registered=True)
    assert three.dof == 3 and all(e.name != "the base frame" for e in three.explanations)
    assert check_arrays(model, data.q_deg[:3], errors[:3]).dof == 9


def test_each_explanations_evidence_is_its_marginal_likelihood_against_none(cell):
    """Each joint's offset and the tool offset, with their columns written out as central differences of the
    identified arm's positions: the evidence equals 2 ln of the Bayes factor computed from the two marginal
    likelihoods (z ~ N(0, I + B B^T) against z ~ N(0, I), B the standardised columns times the prior standard
    deviations), the fitted change the posterior mean, and what is left the chi-square of its residuals."""
    model_path, measure, _, _ = cell
    csv, _ = measure("q2-evidence", read_offset_deg=np.array([0, 0.03, 0, 0, 0, 0]))
    result, data = check_file(model_path, csv), read_measurements(csv)
    model = load_model(model_path)[0]
    q = data.q_deg
    mean, std = model.predict_with_std(q)
    zv = ((data.measured_mm - model.robot_.positions(q) - mean) / std).ravel()
    arm = model.identified_robot_
    h = 1e-4
    columns = {f"joint {j + 1}'s offset": (0.1, [(arm.positions(q + h * np.eye(6)[j]) -
                                                   arm.positions(q - h * np.eye(6)[j])).ravel() / (2 * h)])
               for j in range(6)}
    columns["the tool offset"] = (1.0, [(arm.replace(tool_mm=arm.tool_mm + h * e).positions(q) -
                                         arm.replace(tool_mm=arm.tool_mm - h * e).positions(q)).ravel() / (2 * h)
                                        for e in np.eye(3)])
    found = {e.name: e for e in result.explanations}
    assert result.explanations[0].name == "joint 2's offset"
    for name, (s, cols) in columns.items():
        B = np.column_stack(cols) / std.ravel()[:, None] * s
        cov = np.eye(zv.size) + B @ B.T
        evidence = zv @ zv - zv @ np.linalg.solve(cov, zv) - np.linalg.slogdet(cov)[1]
        change = s * B.T @ np.linalg.solve(cov, zv)                  # the posterior mean, mm or degrees
        left = zv - B @ (change / s)
        e = found[name]
        assert e.evidence == pytest.approx(evidence, rel=1e-6, abs=1e-6), name
        np.testing.assert_allclose(e.change, change, rtol=1e-5, atol=1e-9, err_msg=name)
        assert e.p_value == pytest.approx(chi2.sf(left @ left, zv.size - B.shape[1]), rel=1e-5), name


class _PayloadSag(ErrorModel):
    """A series model whose prediction is a sag of 0.1 mm per kg along -z and whose spread is 0.05 mm: what a
    model that reads the payload gives, written out so that the check's use of the payload can be computed by
    hand."""

    @property
    def reads_payload(self) -> bool:
        return True

    def spread_problem(self):
        return None

    def predict_with_std(self, X, payload_kg=None):
        sag = np.zeros((len(X), 3))
        sag[:, 2] = -0.1 * (np.zeros(len(X)) if payload_kg is None else np.asarray(payload_kg, dtype=float))
        return sag, np.full((len(X), 3), 0.05)


def test_check_judges_a_payload_reading_model_at_each_poses_payload(cell):
    """The payload of each pose goes to a model that reads one (a sag of 0.1 mm per kg here): the standardised
    residuals are (measured - 0.1 kg-sag) / 0.05, by hand; without a payload the model's default (none)."""
    model_path, measure, virtual, _ = cell
    _, data = measure("payload")
    q = data.q_deg
    payload = np.linspace(0.0, 10.0, len(q))
    model = _PayloadSag(inputs="joint", degree=1, solver="lstsq").fit(q, np.zeros((len(q), 3)))
    errors = np.zeros((len(q), 3))
    errors[:, 2] = -0.1 * payload + 0.01
    z = np.zeros((len(q), 3))
    z[:, 2] = 0.01 / 0.05
    np.testing.assert_allclose(check_arrays(model, q, errors, robot=virtual.nominal, payload_kg=payload).z, z,
                               atol=1e-12)
    np.testing.assert_allclose(check_arrays(model, q, errors, robot=virtual.nominal).z[:, 2],
                               (errors[:, 2]) / 0.05, atol=1e-12)


def test_a_model_of_pose_errors_is_judged_on_its_positions(cell):
    """A series model of six columns (the position error, then an orientation's three): check reads the first
    three of the data and of the model's mean and spread, as computed here by hand (3 n coordinates)."""
    _, _, virtual, _ = cell
    rng = np.random.default_rng(5)
    q = sample_configurations(virtual.nominal, 190, {1: (-90, 90), 2: (-150, -30), 3: (-140, 140)}, {}, rng)
    nominal = virtual.nominal.positions(q)
    errors = np.column_stack([virtual.measure(q, rng) - nominal, rng.normal(0.0, 0.1, (len(q), 3))])
    model = calibrate_spread(ErrorModel(inputs="cartesian", degree=2, solver="lstsq"), nominal[:150], errors[:150],
                             folds=5)
    result = check_arrays(model, q[150:], errors[150:], robot=virtual.nominal)
    mean, std = model.predict_with_std(nominal[150:])
    assert mean.shape == (40, 6)
    z = (errors[150:, :3] - mean[:, :3]) / std[:, :3]
    assert result.dof == 120 and result.mean_z2 == pytest.approx(np.mean(z ** 2), rel=1e-12)
