"""Physical plausibility at the boundary: data no robot can have produced are refused before any fit."""

import dataclasses

import numpy as np
import pytest
from conftest import ROOT, SHARED, partcal_cli
from scipy.spatial.transform import Rotation

from partcal import load_robot, read_measurements
from partcal.data.formats import MeasurementFormat, RowSelection
from partcal.data.plausibility import Plausibility
from partcal.data.registration import register_measurements, register_tracker
from partcal.errors import DataError, PartcalError

DATA = ROOT / "data" / "sk120"
UR10 = SHARED / "datasets" / "ipa_ur10" / "Series_B" / "measurements_joint_configurations.csv"


def write_csv(path, q, nominal, measured):
    rows = np.hstack([q, nominal, measured])
    path.write_text("q1,q2,q3,q4,q5,q6,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n"
                    + "".join(",".join(f"{v:.6f}" for v in r) + "\n" for r in rows))
    return path


@pytest.fixture(scope="module")
def ident():
    return read_measurements(DATA / "identification.csv")


def test_the_shipped_nominal_columns_are_the_robots_forward_kinematics(ident, sk120):
    gap = np.linalg.norm(sk120.positions(ident.q_deg) - ident.nominal_mm, axis=1).max()
    assert gap < 3e-5                                    # what the default tolerance (0.01 mm) must let through
    assert len(read_measurements(DATA / "identification.csv", sk120)) == 85


def test_another_robots_nominal_columns_are_refused_with_the_worst_row(ident, tmp_path):
    ur10 = load_robot("universal_robots_ur10")
    gap = np.linalg.norm(ur10.positions(ident.q_deg) - ident.nominal_mm, axis=1)
    lines = (DATA / "identification.csv").read_text().splitlines()
    header = next(i for i, text in enumerate(lines) if not text.startswith("#")) + 1
    line = header + 1 + int(np.argmax(gap))
    with pytest.raises(DataError, match=rf"identification.csv:{line}: x_nom, y_nom, z_nom lie {gap.max():.4g} mm "
                                        r"from robot universal_robots_ur10's forward kinematics .*85 of 85 poses.*"
                                        r"is it robot 'universal_robots_ur10'\?"):
        read_measurements(DATA / "identification.csv", ur10)
    loose = Plausibility(nominal_tolerance_mm=float(gap.max()) + 1, max_error_of_reach=1.0)
    assert len(read_measurements(DATA / "identification.csv", ur10, plausibility=loose)) == 85


def test_the_run_config_with_another_robot_is_refused_by_check(tmp_path):
    text = (ROOT / "configs" / "paper_sk120.yaml").read_text().replace("robot: motoman_sk120",
                                                                       "robot: universal_robots_ur10")
    text = "\n".join(line for line in text.splitlines() if "virtual_robot" not in line and not line.startswith("verify:"))
    config = tmp_path / "c.yaml"
    config.write_text(text.replace("../data/sk120/", f"{DATA}/"))
    res = partcal_cli("run", "--check", str(config))
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "identification.csv:68: x_nom, y_nom, z_nom lie 2423 mm from robot universal_robots_ur10's" in res.stderr


def test_joint_angles_in_radians_are_refused(ident, tmp_path):
    path = write_csv(tmp_path / "rad.csv", np.radians(ident.q_deg), ident.nominal_mm, ident.measured_mm)
    largest = np.abs(np.radians(ident.q_deg)).max()
    with pytest.raises(DataError, match=rf"rad.csv:2: every joint angle of the 85 poses lies within ±{largest:.3g} "
                                        "degrees: they look like radians"):
        read_measurements(path)
    one = write_csv(tmp_path / "one.csv", np.radians(ident.q_deg[:1]), ident.nominal_mm[:1], ident.measured_mm[:1])
    assert len(read_measurements(one)) == 1             # one pose is no evidence


@pytest.mark.parametrize("robot", [None, "motoman_sk120"])
def test_measured_positions_in_metres_are_refused(ident, tmp_path, robot):
    path = write_csv(tmp_path / "m.csv", ident.q_deg, ident.nominal_mm, ident.measured_mm / 1000)
    errors = np.linalg.norm(ident.measured_mm / 1000 - ident.nominal_mm, axis=1)
    reach = load_robot(robot).reach_mm if robot else np.linalg.norm(ident.nominal_mm, axis=1).max()
    with pytest.raises(DataError, match=rf"m.csv:{int(np.argmax(errors)) + 2}: the error measured - nominal is "
                                        rf"{errors.max():.4g} mm \(85 of 85 poses beyond {0.05 * reach:.4g} mm.*"
                                        r"are they in metres\?"):
        read_measurements(path, robot)


def test_swapped_measured_columns_are_named(ident, tmp_path):
    path = write_csv(tmp_path / "s.csv", ident.q_deg, ident.nominal_mm, ident.measured_mm[:, [0, 2, 1]])
    with pytest.raises(DataError, match=r"columns y_meas and z_meas look swapped \(swapping them leaves "
                                        rf"{np.sqrt(np.mean(np.sum(ident.errors_mm**2, axis=1))):.3g} mm RMS"):
        read_measurements(path)


def test_an_error_limit_is_configurable(ident, tmp_path):
    path = write_csv(tmp_path / "m.csv", ident.q_deg, ident.nominal_mm, ident.nominal_mm + [0, 0, 150.0])
    assert len(read_measurements(path, "motoman_sk120")) == 85          # 150 mm < 5% of the 4413 mm reach
    with pytest.raises(DataError, match=r"is 150 mm \(85 of 85 poses beyond 132.4 mm, 0.03 of robot"):
        read_measurements(path, "motoman_sk120", plausibility=Plausibility(max_error_of_reach=0.03))
    with pytest.raises(PartcalError, match=r"The 'max_error_of_reach' parameter of Plausibility must be a real "
                                           r"number in \(0\.0, 1\.0\]\. Got 0 instead\."):
        Plausibility(max_error_of_reach=0)


def test_a_registration_residual_no_robot_has_is_refused(sk120, ident):
    measured_m = ident.measured_mm / 1000                     # a tracker export in metres read as mm
    with pytest.raises(DataError, match=r"src: pose \d+: the tracker registration leaves .* mm \(3-D RMS .*"
                                        r"are they in metres\?"):
        register_tracker(sk120, ident.q_deg, measured_m, source="src")
    mirrored = ident.measured_mm * [1, -1, 1]                  # one sign flipped: a mirror image
    with pytest.raises(DataError, match="a mirror image of the robot's"):
        register_tracker(sk120, ident.q_deg, mirrored, source="src")
    assert register_tracker(sk120, ident.q_deg, ident.measured_mm, source="src").rms_3d < 30


def ur10_config(tmp_path, **replace):
    text = (ROOT / "configs" / "ur10_ipa.yaml").read_text()
    for old, new in replace.items():
        text = text.replace(old, new)
    config = tmp_path / "ur10.yaml"
    config.write_text(text.replace("../../shared/datasets/", f"{SHARED}/datasets/"))
    return config


@pytest.mark.parametrize("change, message", [
    ({"length_unit: mm": "length_unit: m"}, r"pose \d+: the tracker registration leaves .* mm \(3-D RMS 3.215e\+05 mm"
                                            r".*are they in mm but read as metres\?"),
    ({"x_meas: measurement_x,": "x_meas: measurement_y,", "y_meas: measurement_y,": "y_meas: measurement_x,"},
     r"pose \d+: the tracker registration leaves 998.3 mm \(3-D RMS 200.1 mm; 1000 of 1000 poses beyond 83.71 mm.*"
     "a mirror image"),
])
def test_the_ur10_config_with_a_unit_or_a_column_wrong_is_refused_by_check(tmp_path, change, message):
    if not UR10.is_file():
        pytest.skip("the IPA UR10 data set is not beside the repository")
    res = partcal_cli("run", "--check", str(ur10_config(tmp_path, **change)))
    assert res.returncode == 2 and res.stderr.count("partcal: error:") == 1 and "Traceback" not in res.stderr, res.stderr
    assert __import__("re").search(message, res.stderr), res.stderr


# ---------------------------------------------------------------------- the measured orientation

ORIENTATION_HEADER = "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas"


def pose_data(seed, n=30):
    """A UR10 measured in its base frame: joint angles, positions (mm) and the flange's true rotations, each
    turned by ~0.05 degrees and moved by ~0.05 mm."""
    rng = np.random.default_rng(seed)
    ur10 = load_robot("universal_robots_ur10")
    q = rng.uniform(-150, 150, (n, 6))
    frames = ur10.forward(q)
    turned = Rotation.from_rotvec(rng.normal(0, np.radians(0.05), (n, 3))) * Rotation.from_matrix(frames[:, :3, :3])
    return q, ur10.positions(q) + rng.normal(0, 0.05, (n, 3)), turned


def write_pose_csv(path, q, measured_mm, rx_meas, rx_nom=None):
    blocks, header = [q, measured_mm, rx_meas], ORIENTATION_HEADER + ",rx_meas,ry_meas,rz_meas"
    if rx_nom is not None:
        blocks.append(rx_nom)
        header += ",rx_nom,ry_nom,rz_nom"
    path.write_text(header + "\n" + "".join(",".join(f"{v:.6f}" for v in r) + "\n" for r in np.hstack(blocks)))
    return path


def turn_from_fk_deg(q, angles_deg):
    """Independent of partcal: the angle from the UR10's flange to the rotations the contract reads, degrees."""
    fk = Rotation.from_matrix(load_robot("universal_robots_ur10").forward(q)[:, :3, :3])
    return np.degrees((fk.inv() * Rotation.from_euler("XYZ", angles_deg, degrees=True)).magnitude())


MISTAKES = {       # a wrong way to write the true rotations, and the words that must name it
    "radians": (lambda r: r.as_euler("XYZ"), "the angles look like radians"),
    "rx and rz swapped": (lambda r: r.as_euler("XYZ", degrees=True)[:, ::-1], "columns rx_meas and rz_meas look swapped"),
    "extrinsic xyz": (lambda r: r.as_euler("xyz", degrees=True), "extrinsic \\(fixed axes\\) xyz Euler angles"),
    "intrinsic ZYX": (lambda r: r.as_euler("ZYX", degrees=True), "intrinsic ZYX Euler angles"),
    "intrinsic ZXY": (lambda r: r.as_euler("ZXY", degrees=True), "intrinsic ZXY Euler angles"),
}


@pytest.mark.parametrize("mistake", list(MISTAKES))
def test_a_measured_orientation_written_another_way_is_refused_with_its_cause(tmp_path, mistake):
    q, p_mm, turned = pose_data(0)
    write, words = MISTAKES[mistake]
    right = write_pose_csv(tmp_path / "right.csv", q, p_mm, turned.as_euler("XYZ", degrees=True))
    assert np.abs(read_measurements(right, "universal_robots_ur10").orientation_errors_deg).max() < 0.5
    wrong = write(turned)
    turn = turn_from_fk_deg(q, wrong)
    path = write_pose_csv(tmp_path / "wrong.csv", q, p_mm, wrong)
    with pytest.raises(DataError, match=rf"wrong.csv:{int(np.argmax(turn)) + 2}: the orientation error measured - "
                                        rf"nominal is {turn.max():.4g} degrees .*"
                                        rf"{np.count_nonzero(turn > 5)} of 30 poses beyond 5 degrees.*{words}"):
        read_measurements(path, "universal_robots_ur10")


def test_nominal_orientation_columns_are_compared_with_forward_kinematics(tmp_path):
    q, p_mm, turned = pose_data(1)
    fk = Rotation.from_matrix(load_robot("universal_robots_ur10").forward(q)[:, :3, :3]).as_euler("XYZ", degrees=True)
    measured = turned.as_euler("XYZ", degrees=True)
    assert len(read_measurements(write_pose_csv(tmp_path / "ok.csv", q, p_mm, measured, fk), "universal_robots_ur10"))
    gap = turn_from_fk_deg(q, fk[:, ::-1])
    path = write_pose_csv(tmp_path / "nom.csv", q, p_mm, measured, fk[:, ::-1])
    with pytest.raises(DataError, match=rf"nom.csv:{int(np.argmax(gap)) + 2}: rx_nom, ry_nom, rz_nom lie "
                                        rf"{gap.max():.4g} degrees from robot universal_robots_ur10's forward "
                                        r"kinematics.*columns rx_nom and rz_nom look swapped"):
        read_measurements(path, "universal_robots_ur10")


def test_fuzz_orientation_units_and_orders_are_refused_whenever_they_matter(tmp_path):
    for seed in range(25):
        rng = np.random.default_rng(100 + seed)
        n = int(rng.integers(5, 40))
        q, p_mm, turned = pose_data(seed + 100, n)
        mistake = list(MISTAKES)[seed % len(MISTAKES)]
        write, words = MISTAKES[mistake]
        wrong = write(turned)
        path = write_pose_csv(tmp_path / f"f{seed}.csv", q, p_mm, wrong)
        if turn_from_fk_deg(q, wrong).max() <= 5:            # no evidence: the mistake does not matter here
            continue
        with pytest.raises(DataError, match=words):
            read_measurements(path, "universal_robots_ur10")


UR10_POSE = ROOT / "configs" / "ur10_ipa_pose.yaml"


@pytest.mark.parametrize("change, message", [
    ({"rx_meas: measurement_rx, ry_meas: measurement_ry, rz_meas: measurement_rz":
      "rx_meas: measurement_rz, ry_meas: measurement_ry, rz_meas: measurement_rx"},
     r"the tracker registration's orientation residual is .* degrees .*columns rx_meas and rz_meas look swapped"),
])
def test_the_ur10_tmac_angles_read_wrong_are_refused_by_check(tmp_path, change, message):
    if not UR10.is_file():
        pytest.skip("the IPA UR10 data set is not beside the repository")
    text = UR10_POSE.read_text().replace('rows: "1-1000"', 'rows: "1-150"')
    for old, new in change.items():
        assert old in text
        text = text.replace(old, new)
    config = tmp_path / "pose.yaml"
    config.write_text(text.replace("../../shared/datasets/", f"{SHARED}/datasets/"))
    res = partcal_cli("run", "--check", str(config))
    assert res.returncode == 2 and res.stderr.count("partcal: error:") == 1 and "Traceback" not in res.stderr, res.stderr
    assert __import__("re").search(message, res.stderr), res.stderr


def test_the_ur10_tmac_angles_in_radians_are_refused_by_the_registration():
    if not UR10.is_file():
        pytest.skip("the IPA UR10 data set is not beside the repository")
    names = dict(q1="shoulder_pan_joint", q2="shoulder_lift_joint", q3="elbow_joint", q4="wrist_1_joint",
                 q5="wrist_2_joint", q6="wrist_3_joint", x_meas="measurement_x", y_meas="measurement_y",
                 z_meas="measurement_z", rx_meas="measurement_rx", ry_meas="measurement_ry", rz_meas="measurement_rz")
    fmt = MeasurementFormat(delimiter=";", decimal=",", columns=names, joint_unit="rad")
    ur10 = load_robot("universal_robots_ur10")
    m = read_measurements(UR10, ur10, fmt=fmt, frame="tracker", rows=RowSelection.parse("1-150"))
    assert register_measurements(ur10, m, source="B").orientation_rms_deg < 0.2
    in_radians = dataclasses.replace(m, measured_orientation_deg=np.radians(m.measured_orientation_deg))
    with pytest.raises(DataError, match=r"B: pose \d+: the tracker registration's orientation residual is .* degrees "
                                        r"\(RMS .*the angles look like radians .*reading them so leaves 0\.1\d* degrees"):
        register_measurements(ur10, in_radians, source="B")


# ---------------------------------------------------------------------- a mirror image at any size

@pytest.mark.parametrize("n", [6, 12, 40, 85])
@pytest.mark.parametrize("swap", [[1, 0, 2], [0, 2, 1], [2, 1, 0]])
def test_a_mirror_image_is_refused_at_any_size(sk120, ident, n, swap):
    rng = np.random.default_rng(n)
    turn = Rotation.from_rotvec(rng.normal(0, 1.0, 3)).as_matrix()               # where the tracker stands
    tracker = (ident.measured_mm[:n] - [3000.0, 500.0, 0.0]) @ turn               # base -> tracker frame
    assert register_tracker(sk120, ident.q_deg[:n], tracker, source="src").rms_3d < 30
    with pytest.raises(DataError, match=r"src: .*mirror image of the robot's"):
        register_tracker(sk120, ident.q_deg[:n], tracker[:, swap], source="src")


@pytest.mark.parametrize("rows", ["1-12", "1-30", "200-260", "2-300"])
def test_the_ur10_with_x_and_y_swapped_is_refused_on_any_rows(rows):
    """Series B's poses lie nearly in a plane: mirrored, they still register to 1.1 to 3.0 mm."""
    if not UR10.is_file():
        pytest.skip("the IPA UR10 data set is not beside the repository")
    names = dict(q1="shoulder_pan_joint", q2="shoulder_lift_joint", q3="elbow_joint", q4="wrist_1_joint",
                 q5="wrist_2_joint", q6="wrist_3_joint", x_meas="measurement_x", y_meas="measurement_y",
                 z_meas="measurement_z")
    ur10 = load_robot("universal_robots_ur10")
    m = read_measurements(UR10, ur10, fmt=MeasurementFormat(delimiter=";", decimal=",", columns=names,
                                                            joint_unit="rad"),
                          frame="tracker", rows=RowSelection.parse(rows))
    right = register_tracker(ur10, m.q_deg, m.measured_mm, source="B").rms_3d
    with pytest.raises(DataError, match=rf"B: the measured positions are a mirror image of the robot's: the tracker "
                                        rf"registration leaves .* mm RMS, the same points with one axis flipped "
                                        rf"{right:.4g} mm"):
        register_tracker(ur10, m.q_deg, m.measured_mm[:, [1, 0, 2]], source="B")


def test_the_ur10_config_with_x_and_y_swapped_is_refused_by_check_on_299_rows(tmp_path):
    if not UR10.is_file():
        pytest.skip("the IPA UR10 data set is not beside the repository")
    config = ur10_config(tmp_path, **{'rows: "1-1000"': 'rows: "2-300"', "x_meas: measurement_x,": "x_meas: measurement_y,",
                                      "y_meas: measurement_y,": "y_meas: measurement_x,",
                                      "    iso_cubes:": "    no_iso_cubes:", "      registration: own\n": ""})
    text = config.read_text()
    config.write_text(text[:text.index("    no_iso_cubes:")] + text[text.index("models:"):])
    res = partcal_cli("run", "--check", str(config))
    assert res.returncode == 2 and res.stderr.count("partcal: error:") == 1 and "Traceback" not in res.stderr
    assert "the tracker registration leaves 3.036 mm RMS, the same points with one axis flipped 0.5567 mm" in res.stderr
