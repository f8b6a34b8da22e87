"""Full-pose compensation with pose models (6 outputs: mm, then a rotation vector in mrad): the Predictor and the
``predict`` / ``compensate`` commands."""

import csv
import warnings

import numpy as np
import pytest
from conftest import partcal_cli as run
from scipy.spatial.transform import Rotation

from partcal import DataError, ErrorModel, load_predictor, load_robot
from partcal.robot.compensation import CompensationWarning
from partcal.robot.kinematics import xyz_deg_from_matrices
from partcal.study.persist import model_to_dict, save_model
from partcal.study.predictor import Predictor

UR10 = load_robot("universal_robots_ur10")
NOMINAL = UR10.replace(tool_mm=np.array([30.0, -20.0, 150.0]))
CENTRE = np.array([20.0, -70.0, 90.0, -100.0, -80.0, 10.0])      # the UR10 joints the data lie around, degrees


def _true_robot():
    """The nominal UR10 with other DH lengths (1 mm) and angles (0.05 degrees): the arm the data come from."""
    rng = np.random.default_rng(5)
    rows = NOMINAL.alpha_deg.size
    return NOMINAL.replace(a_mm=NOMINAL.a_mm + rng.normal(0, 1.0, rows), d_mm=NOMINAL.d_mm + rng.normal(0, 1.0, rows),
                           alpha_deg=NOMINAL.alpha_deg + rng.normal(0, 0.05, rows),
                           theta_offset_deg=NOMINAL.theta_offset_deg + rng.normal(0, 0.05, rows))


TRUE = _true_robot()


def true_pose_errors(q):
    """The true arm's pose errors at joints ``q``: position (mm), then the rotation vector (mrad) of
    ``R_true R_nominal^T``, straight from both robots' forward kinematics."""
    T, N = TRUE.forward(q), NOMINAL.forward(q)
    turn = Rotation.from_matrix(T[:, :3, :3] @ N[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
    return np.hstack([T[:, :3, 3] - N[:, :3, 3], 1000.0 * turn])


def predictor_of(model, robot=NOMINAL, name="pose"):
    """A Predictor of an in-memory model, with the document its model file would hold."""
    return Predictor(model, model_to_dict(model, name=name, robot=robot), robot)


def euler_rotations(angles_deg):
    """Intrinsic XYZ angles (degrees) to rotations, by scipy ('XYZ' upper case: intrinsic)."""
    return Rotation.from_euler("XYZ", angles_deg, degrees=True).as_matrix()


@pytest.fixture(scope="module")
def joint_pose_model():
    q = CENTRE + np.random.default_rng(0).uniform(-20, 20, (400, 6))
    return ErrorModel(inputs="joint", degree=3, cross_terms=True, solver="lstsq").fit(q, true_pose_errors(q))


def linear_pose_field(p):
    """A Cartesian pose-error field: about a millimetre per metre, and turns of 5 to 10 mrad."""
    return np.hstack([1e-3 * p[:, [1, 2, 0]], 5.0 + 2e-3 * p])


@pytest.fixture(scope="module")
def cartesian_pose_model():
    q = CENTRE + np.random.default_rng(1).uniform(-40, 40, (300, 6))
    p = NOMINAL.positions(q)
    return ErrorModel(degree=1, solver="lstsq").fit(p, linear_pose_field(p))


def test_joint_pose_model_puts_the_true_robot_on_the_target_pose(joint_pose_model):
    """Commanding the compensated joints, the true arm reaches the target poses to the model's accuracy; commanding
    the targets themselves, it misses by millimetres and hundredths of a degree."""
    from partcal.robot.kinematics import pose_errors

    p = predictor_of(joint_pose_model)
    q = CENTRE + np.random.default_rng(2).uniform(-15, 15, (50, 6))
    wanted = NOMINAL.forward(q)
    result = p.compensate_pose(wanted[:, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3]), q, tol_mm=1e-6,
                               tol_deg=1e-6)
    assert result.converged.all()
    assert (result.residual_mm <= 1e-6).all() and (result.residual_deg <= 1e-6).all()
    np.testing.assert_allclose(NOMINAL.forward(result.joints_deg)[:, :3, 3], result.commanded_mm, atol=1e-9)
    miss_mm, miss_deg = pose_errors(TRUE.forward(result.joints_deg), wanted)
    before_mm, before_deg = pose_errors(TRUE.forward(q), wanted)
    assert miss_mm.max() < 0.02 and miss_deg.max() < 0.002                 # 0.0075 mm, 0.00045 degrees
    assert before_mm.min() > 2.0 and before_deg.min() > 0.02              # 2.9 to 3.3 mm, 0.029 to 0.093 degrees
    assert miss_mm.max() < before_mm.min() / 100 and miss_deg.max() < before_deg.min() / 20


def test_cartesian_pose_model_commands_the_turned_back_orientation(cartesian_pose_model):
    """The position is the fixed point p' + e(p') = p; the orientation is exp(-r(p')) R_target, r in mrad."""
    p = predictor_of(cartesian_pose_model)
    q = CENTRE + np.random.default_rng(3).uniform(-30, 30, (20, 6))
    targets = NOMINAL.positions(q)
    angles = xyz_deg_from_matrices(NOMINAL.forward(q)[:, :3, :3]) + [1.0, -2.0, 3.0]
    result = p.compensate_pose(targets, angles)
    assert result.converged.all() and result.joints_deg is None
    predicted = cartesian_pose_model.predict(result.commanded_mm)
    np.testing.assert_allclose(result.commanded_mm + predicted[:, :3], targets, atol=1e-4)
    expected = Rotation.from_rotvec(-1e-3 * predicted[:, 3:]).as_matrix() @ euler_rotations(angles)
    np.testing.assert_allclose(result.commanded_rotation, expected, atol=1e-12)
    turned = np.degrees(np.linalg.norm(Rotation.from_matrix(result.commanded_rotation @ euler_rotations(angles)
                                                            .transpose(0, 2, 1)).as_rotvec(), axis=1))
    np.testing.assert_allclose(turned, np.degrees(1e-3 * np.linalg.norm(predicted[:, 3:], axis=1)), rtol=1e-9)
    assert turned.min() > 0.4                                             # the command does turn: 7 to 15 mrad
    assert (result.residual_deg < 1e-9).all()


def test_a_pose_the_robot_cannot_take_is_not_converged_and_warns(cartesian_pose_model):
    p = predictor_of(cartesian_pose_model)
    reachable = NOMINAL.forward(CENTRE[None])
    positions = np.vstack([reachable[:, :3, 3], [[1480.0, 0.0, 0.0]]])             # the second is out of reach
    angles = np.repeat(xyz_deg_from_matrices(reachable[:, :3, :3]), 2, axis=0)
    with pytest.warns(CompensationWarning, match=r"^model 'pose': 1 of 2 targets did not converge to 0.0001 mm and "
                                                 r"1e-05 deg: #1 \(\S+ mm, \S+ deg: out of reach\)$"):
        result = p.compensate_pose(positions, angles)
    assert result.converged.tolist() == [True, False]
    no_robot = Predictor(cartesian_pose_model, model_to_dict(cartesian_pose_model, name="pose"))
    assert no_robot.compensate_pose(positions, angles).converged.all()    # without a robot, nothing says it is out


@pytest.fixture(scope="module")
def near_the_wrist_singularity():
    """A DH pose model of the true arm (identified from its exact pose errors on 400 poses with |q5| < 2 deg) and
    40 target poses of the nominal arm with |q5| < 1 deg (the UR wrist singularity is q5 = 0), |q3| >= 30."""
    from partcal.models.kinematic import KinematicModel

    q = np.random.default_rng(0).uniform([-90, -150, 30, -180, -2, -180], [90, -30, 140, 180, 2, 180], (400, 6))
    model = KinematicModel(robot=NOMINAL, use_orientation=True).fit(q, true_pose_errors(q))
    targets = np.random.default_rng(1).uniform([-90, -150, 30, -180, -1, -180], [90, -30, 140, 180, 1, 180], (40, 6))
    targets[:, 2] *= np.random.default_rng(2).choice([-1, 1], len(targets))
    return predictor_of(model, name="DH (pose)"), targets


def test_targets_near_the_wrist_singularity_converge_and_the_true_arm_reaches_them(near_the_wrist_singularity):
    """Near q5 = 0 the pose Jacobian has a singular value far below the others: fixed-damping steps that neglect
    the model's slope stall there (14 of these 40 targets did not converge). Now at least 34 do (37 here), and the true arm,
    commanded to the returned joints, reaches each converged target pose (its own forward kinematics, not the
    solver's residual); the targets left are refused as singular."""
    from partcal.robot.kinematics import pose_errors

    p, q = near_the_wrist_singularity
    wanted = NOMINAL.forward(q)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CompensationWarning)
        result = p.compensate_pose(wanted[:, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3]), q)
    assert result.converged.sum() >= 34
    ok = result.converged
    miss_mm, miss_deg = pose_errors(TRUE.forward(result.joints_deg[ok]), wanted[ok])
    assert miss_mm.max() < 2e-4 and miss_deg.max() < 2e-5              # the tolerances, 1e-4 mm and 1e-5 deg
    assert (result.residual_mm[ok] <= 1e-4).all() and (result.residual_deg[ok] <= 1e-5).all()
    before_mm, _ = pose_errors(TRUE.forward(q), wanted)                  # uncompensated, the true arm misses
    assert before_mm.min() > 0.3
    reasons = result.reasons(1e-4, 1e-5, NOMINAL, wanted[:, :3, 3])
    assert {reasons[i] for i in np.flatnonzero(~ok)} <= {"singular"}


def test_a_target_refused_at_a_singularity_says_so(near_the_wrist_singularity):
    """A target the solve leaves at a singularity is named in the warning with its miss and 'singular'."""
    p, q = near_the_wrist_singularity
    wanted = NOMINAL.forward(q)
    with pytest.warns(CompensationWarning, match=r"^model 'DH \(pose\)': [1-6] of 40 targets did not converge to "
                                                 r"0.0001 mm and 1e-05 deg: #\d+ \(\S+ mm, \S+ deg: singular\)"):
        p.compensate_pose(wanted[:, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3]), q)


def test_pose_models_predict_six_columns_and_position_models_three(joint_pose_model, cartesian_pose_model):
    q = CENTRE[None] + [[0.0] * 6, [5.0] * 6]
    pose = predictor_of(joint_pose_model)
    assert pose.predicts_pose
    np.testing.assert_array_equal(pose.predict(joints=q), joint_pose_model.predict(q))
    assert pose.predict(joints=np.zeros((0, 6))).shape == (0, 6)
    assert predictor_of(cartesian_pose_model).predict(positions=np.zeros((0, 3))).shape == (0, 6)
    train = CENTRE + np.random.default_rng(0).uniform(-20, 20, (30, 6))
    position = predictor_of(ErrorModel(inputs="joint", solver="lstsq").fit(train, true_pose_errors(train)[:, :3]))
    assert not position.predicts_pose and position.predict(joints=q).shape == (2, 3)
    assert position.predict(joints=np.zeros((0, 6))).shape == (0, 3)


def test_a_pose_model_without_orientations_compensates_positions_as_a_position_model(cartesian_pose_model):
    """compensate_full reads the position outputs: the same command as a model fitted on them alone."""
    q = CENTRE + np.random.default_rng(1).uniform(-40, 40, (300, 6))
    p = NOMINAL.positions(q)
    position = ErrorModel(degree=1, solver="lstsq").fit(p, linear_pose_field(p)[:, :3])
    targets = p[:10] + 5.0
    np.testing.assert_allclose(predictor_of(cartesian_pose_model).compensate_full(targets).commanded_mm,
                               predictor_of(position).compensate_full(targets).commanded_mm, atol=1e-9)


def test_compensate_pose_refuses_a_position_model_and_bad_inputs(cartesian_pose_model):
    position = predictor_of(ErrorModel(solver="lstsq").fit(np.random.default_rng(0).uniform(0, 900, (20, 3)),
                                                            np.zeros((20, 3))), name="FDP(CI)")
    with pytest.raises(DataError, match=r"model 'FDP\(CI\)' predicts position errors only \(3 outputs\), so it "
                                        r"cannot compensate an orientation: fit a pose model \(6 outputs"):
        position.compensate_pose([[900.0, 0.0, 500.0]], [[0.0, 0.0, 0.0]])
    p = predictor_of(cartesian_pose_model)
    cases = [(([[900.0, 0.0, 500.0]], [[0.0, 0.0]]), r"Expected orientations_deg with shape \(n, 3\), got array "
                                                     r"with shape \(1, 2\)"),
             (([[900.0, 0.0, 500.0]], [[0.0, np.nan, 0.0]]), r"orientations_deg holds a non-finite value \(nan\) at "
                                                             r"index \(0, 1\)"),
             (([[900.0, 0.0, 500.0]] * 2, [[0.0, 0.0, 0.0]]), "orientations_deg has 1 rows but positions_mm has 2")]
    for args, message in cases:
        with pytest.raises(DataError, match=message):
            p.compensate_pose(*args)
    with pytest.raises(DataError, match="tol_deg must be a finite number >= 0; got -1"):
        p.compensate_pose([[900.0, 0.0, 500.0]], [[0.0, 0.0, 0.0]], tol_deg=-1)
    empty = p.compensate_pose(np.zeros((0, 3)), np.zeros((0, 3)))
    assert empty.commanded_rotation.shape == (0, 3, 3) and empty.residual_deg.shape == (0,)


def test_a_predicted_turn_beyond_half_a_turn_is_refused_as_implausible(cartesian_pose_model):
    p = predictor_of(cartesian_pose_model)
    X = np.array([[900.0, 0.0, 500.0], [1e6, 0.0, 0.0]])
    p.refuse_implausible(X[:1], np.array([[1.0, 2.0, 3.0, 3000.0, 0.0, 0.0]]))          # 172 degrees: accepted
    with pytest.raises(DataError, match=r"in.csv: data row 2: the predicted error turns by 4000 mrad, more than "
                                        r"half a turn \(3142 mrad\) \(1 of 2 rows\); the input \[1e\+06, 0, 0\]"):
        p.refuse_implausible(X, np.array([[1.0, 2.0, 3.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0, 0.0, 4000.0, 0.0]]),
                             source="in.csv")


# ---------------------------------------------------------------------------------------------- command line
@pytest.fixture(scope="module")
def pose_files(tmp_path_factory, joint_pose_model, cartesian_pose_model):
    folder = tmp_path_factory.mktemp("pose")
    save_model(joint_pose_model, folder / "ai.json", name="pose AI", robot=NOMINAL)
    save_model(cartesian_pose_model, folder / "ci.json", name="pose CI", robot=NOMINAL)
    return folder / "ai.json", folder / "ci.json"


def write_csv(path, header, rows):
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(f"{v:.9f}" for v in r) for r in rows) + "\n")
    return path


def read_csv(path):
    with open(path) as handle:
        return list(csv.DictReader(handle))


def columns(rows, names):
    return np.array([[float(r[k]) for k in names] for r in rows])


def test_compensate_command_round_trip_with_orientation(pose_files, tmp_path):
    q = CENTRE + np.random.default_rng(4).uniform(-15, 15, (6, 6))
    wanted = NOMINAL.forward(q)
    angles = xyz_deg_from_matrices(wanted[:, :3, :3])
    targets = write_csv(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz", "q1", "q2", "q3", "q4", "q5", "q6"],
                        np.hstack([wanted[:, :3, 3], angles, q]))
    out = tmp_path / "c.csv"
    res = run("compensate", str(pose_files[0]), str(targets), "-o", str(out))
    assert res.returncode == 0 and res.stderr == "", res.stderr
    rows = read_csv(out)
    assert list(rows[0]) == ["x", "y", "z", "rx", "ry", "rz", "q1", "q2", "q3", "q4", "q5", "q6", "x_cmd", "y_cmd",
                             "z_cmd", "rx_cmd", "ry_cmd", "rz_cmd", "q1_cmd", "q2_cmd", "q3_cmd", "q4_cmd", "q5_cmd",
                             "q6_cmd", "miss_mm", "miss_deg", "converged", "reason"]
    assert [r["converged"] for r in rows] == ["true"] * 6 and [r["reason"] for r in rows] == [""] * 6
    assert columns(rows, ["miss_mm"]).max() <= 1e-4 and columns(rows, ["miss_deg"]).max() <= 1e-5
    q_cmd = columns(rows, [f"q{j}_cmd" for j in range(1, 7)])
    commanded = NOMINAL.forward(q_cmd)                      # the pose written is the nominal pose of the joints
    np.testing.assert_allclose(columns(rows, ["x_cmd", "y_cmd", "z_cmd"]), commanded[:, :3, 3], atol=1e-5)
    np.testing.assert_allclose(euler_rotations(columns(rows, ["rx_cmd", "ry_cmd", "rz_cmd"])), commanded[:, :3, :3],
                               atol=1e-7)
    reached = TRUE.forward(q_cmd)                           # and takes the true arm to the targets
    assert np.linalg.norm(reached[:, :3, 3] - wanted[:, :3, 3], axis=1).max() < 0.02
    np.testing.assert_allclose(reached[:, :3, :3], wanted[:, :3, :3], atol=4e-5)


def test_compensate_command_near_the_wrist_singularity_writes_the_joints_and_each_reason(
        near_the_wrist_singularity, tmp_path):
    """The 40 targets near q5 = 0 through the command, seeded with their joints: exit 3 for the few refused, each
    row's reason written (singular) and the first named on stderr; the converged rows' joints take the true arm
    to their targets."""
    p, q = near_the_wrist_singularity
    model = tmp_path / "dh.json"
    save_model(p.model, model, name="DH (pose)", robot=NOMINAL)
    wanted = NOMINAL.forward(q)
    targets = write_csv(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz", "q1", "q2", "q3", "q4", "q5", "q6"],
                        np.hstack([wanted[:, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3]), q]))
    res = run("compensate", str(model), str(targets), "-o", str(tmp_path / "c.csv"))
    rows = read_csv(tmp_path / "c.csv")
    bad = [k for k, r in enumerate(rows) if r["converged"] == "false"]
    assert res.returncode == 3 and 1 <= len(bad) <= 6
    assert {rows[k]["reason"] for k in bad} == {"singular"}
    assert f"targets did not converge or are unreachable (first: data row {bad[0] + 1} of" in res.stderr
    assert ": singular, predicted miss " in res.stderr
    good = [k for k in range(len(rows)) if k not in bad]
    reached = TRUE.forward(columns([rows[k] for k in good], [f"q{j}_cmd" for j in range(1, 7)]))
    assert np.linalg.norm(reached[:, :3, 3] - wanted[good, :3, 3], axis=1).max() < 1e-3


def test_compensate_command_reads_target_orientations_through_a_format(pose_files, tmp_path):
    """A format maps the target orientations (as rx_nom..: a file's own rx, ry, rz columns may hold a measured
    orientation) and converts them from radians: the commands equal those of the same targets in degrees."""
    q = CENTRE + np.random.default_rng(6).uniform(-10, 10, (3, 6))
    wanted = NOMINAL.forward(q)
    angles = xyz_deg_from_matrices(wanted[:, :3, :3])
    plain = write_csv(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz"], np.hstack([wanted[:, :3, 3], angles]))
    foreign = write_csv(tmp_path / "f.csv", ["X", "Y", "Z", "A", "B", "C"],
                        np.hstack([wanted[:, :3, 3], np.radians(angles)]))
    (tmp_path / "fmt.yaml").write_text("columns: {x: X, y: Y, z: Z, rx_nom: A, ry_nom: B, rz_nom: C}\norientation_unit: rad\n")
    assert run("compensate", str(pose_files[0]), str(plain), "-o", str(tmp_path / "a.csv")).returncode == 0
    res = run("compensate", str(pose_files[0]), str(foreign), "--format", str(tmp_path / "fmt.yaml"), "-o",
              str(tmp_path / "b.csv"))
    assert res.returncode == 0, res.stderr
    names = ["x_cmd", "y_cmd", "z_cmd", "rx_cmd", "ry_cmd", "rz_cmd"]
    np.testing.assert_allclose(columns(read_csv(tmp_path / "b.csv"), names),
                               columns(read_csv(tmp_path / "a.csv"), names), atol=1e-6)


def test_compensate_command_reads_the_nominal_orientation_and_exits_3_on_an_unreachable_pose(pose_files, tmp_path):
    wanted = NOMINAL.forward(CENTRE[None])
    rows = [np.hstack([wanted[0, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3])[0]]), [1480, 0, 0, 10, 20, 30]]
    targets = write_csv(tmp_path / "t.csv", ["x_nom", "y_nom", "z_nom", "rx_nom", "ry_nom", "rz_nom"], rows)
    out = tmp_path / "c.csv"
    res = run("compensate", str(pose_files[1]), str(targets), "-o", str(out))
    assert res.returncode == 3 and res.stderr.count("\n") == 1, res.stderr
    assert (f"1 of 2 targets did not converge or are unreachable (first: data row 2 of {targets}, target [1480.0, "
            "0.0, 0.0] mm, [10.0, 20.0, 30.0] deg: out of reach, predicted miss ") in res.stderr
    written = read_csv(out)
    assert [r["reason"] for r in written] == ["", "out of reach"] and float(written[0]["miss_deg"]) <= 1e-5
    assert list(written[0])[:9] == ["x_nom", "y_nom", "z_nom", "rx_nom", "ry_nom", "rz_nom", "x_cmd", "y_cmd", "z_cmd"]
    assert [r["converged"] for r in written] == ["true", "false"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CompensationWarning)
        result = load_predictor(pose_files[1]).compensate_pose(np.array(rows)[:, :3], np.array(rows)[:, 3:])
    np.testing.assert_allclose(columns(written, ["rx_cmd", "ry_cmd", "rz_cmd"]),
                               xyz_deg_from_matrices(result.commanded_rotation), atol=1e-6)


def test_compensate_command_refuses_an_incomplete_triple_or_a_bad_angle(pose_files, tmp_path):
    out = tmp_path / "c.csv"
    targets = write_csv(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry"], [[900, 0, 500, 0, 0]])
    res = run("compensate", str(pose_files[1]), str(targets), "-o", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert f"{targets}:1: column 'rz' is missing (give all of rx, ry, rz or none)" in res.stderr
    targets = write_csv(tmp_path / "t.csv", ["x", "y", "z", "rx", "ry", "rz"], [[900, 0, 500, 0, 0, 0],
                                                                               [900, 0, 500, 0, 95.5, 0]])
    res = run("compensate", str(pose_files[1]), str(targets), "-o", str(out))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert (f"{targets}: data row 2: column 'ry': expected an angle in [-90, 90] degrees (intrinsic XYZ angles), "
            "got 95.5") in res.stderr
    assert not out.exists()


def test_a_pose_model_without_orientation_columns_compensates_positions(pose_files, tmp_path):
    targets = write_csv(tmp_path / "t.csv", ["x", "y", "z"], NOMINAL.positions(CENTRE[None] + [[0.0] * 6, [9.0] * 6]))
    out = tmp_path / "c.csv"
    res = run("compensate", str(pose_files[1]), str(targets), "-o", str(out))
    assert res.returncode == 0, res.stderr
    rows = read_csv(out)
    assert list(rows[0]) == ["x", "y", "z", "x_cmd", "y_cmd", "z_cmd", "miss_mm", "converged", "reason"]
    expected = load_predictor(pose_files[1]).compensate_full(columns(rows, ["x", "y", "z"])).commanded_mm
    np.testing.assert_allclose(columns(rows, ["x_cmd", "y_cmd", "z_cmd"]), expected, atol=1e-6)


def test_predict_command_writes_the_rotation_vector_of_a_pose_model(pose_files, tmp_path):
    q = CENTRE[None] + [[0.0] * 6, [4.0, -3, 2, -1, 5, 6]]
    points = write_csv(tmp_path / "q.csv", [f"q{j}" for j in range(1, 7)], q)
    out = tmp_path / "p.csv"
    res = run("predict", str(pose_files[0]), str(points), "-o", str(out))
    assert res.returncode == 0 and res.stderr == "", res.stderr
    rows = read_csv(out)
    assert list(rows[0]) == ["q1", "q2", "q3", "q4", "q5", "q6", "dx", "dy", "dz", "drx", "dry", "drz"]
    np.testing.assert_allclose(columns(rows, ["dx", "dy", "dz", "drx", "dry", "drz"]), true_pose_errors(q),
                               atol=0.02)                                         # the true arm's, mm and mrad


def test_each_target_row_is_compensated_at_its_own_payload():
    """``compensate`` groups rows by their payload_kg: a row's command is that of compensate_pose at its payload."""
    class Sagging(ErrorModel):          # the joint pose model, sagging 0.01 mm per kg in z
        @property
        def reads_payload(self):
            return True

        def predict_validated(self, X, payload_kg=None):
            out = super().predict_validated(X)
            out[:, 2] -= 0.01 * (0.0 if payload_kg is None else payload_kg)
            return out

    train = CENTRE + np.random.default_rng(0).uniform(-20, 20, (400, 6))
    p = predictor_of(Sagging(inputs="joint", degree=3, cross_terms=True, solver="lstsq").fit(train,
                                                                                         true_pose_errors(train)))
    q = CENTRE + np.random.default_rng(6).uniform(-10, 10, (4, 6))
    wanted = NOMINAL.forward(q)
    targets, angles = wanted[:, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3])
    payload = np.array([0.0, 20.0, 0.0, 50.0])
    result = p.compensate_rows(targets, angles, q, payload_kg=payload)
    for k, kg in enumerate(payload):
        alone = p.compensate_pose(targets[k:k + 1], angles[k:k + 1], q[k:k + 1], payload_kg=kg)
        np.testing.assert_allclose(result.joints_deg[k], alone.joints_deg[0], atol=1e-9)
        np.testing.assert_allclose(result.commanded_rotation[k], alone.commanded_rotation[0], atol=1e-12)
    heavy = p.compensate_pose(targets[3:], angles[3:], q[3:], payload_kg=0.0).commanded_mm
    assert result.commanded_mm[3, 2] - heavy[0, 2] == pytest.approx(0.5, abs=0.01)     # 50 kg: 0.5 mm higher
