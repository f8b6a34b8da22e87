"""Physical plausibility at the boundary: data no robot can have produced are refused before any fit."""

import numpy as np
import pytest
from conftest import ROOT, SHARED, partcal_cli

from partcal import load_robot, read_measurements
from partcal.data.plausibility import Plausibility
from partcal.data.registration import register_tracker
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
    text = "\n".join(line for line in text.splitlines() if "virtual_robot" not in line and line != "verify:")
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
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert __import__("re").search(message, res.stderr), res.stderr
