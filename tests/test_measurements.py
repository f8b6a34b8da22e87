"""The measurement CSV contract (CONTRACTS.md section 1)."""

import numpy as np
import pytest
from conftest import write_text

from partcal import DataError, Measurements, read_measurements, write_measurements
from partcal.data.measurements import read_columns

HEADER = "q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas"


def write(tmp_path, text, name="m.csv"):
    return write_text(tmp_path, text, name)


def test_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(0)
    nominal = rng.uniform(-1e3, 1e3, (7, 3))
    m = Measurements(rng.uniform(-90, 90, (7, 6)), nominal, nominal + rng.uniform(-20, 20, (7, 3)), name="demo",
                     labels=("a,b",) * 7)
    path = tmp_path / "demo.csv"
    write_measurements(m, path, comment="two\nlines")
    back = read_measurements(path)
    np.testing.assert_allclose(back.q_deg, m.q_deg, atol=5e-7)
    np.testing.assert_allclose(back.errors_mm, m.measured_mm - m.nominal_mm, atol=2e-6)
    assert back.labels == m.labels and back.name == "demo" and len(back) == 7
    write_measurements(back, tmp_path / "again.csv", comment="two\nlines")
    assert (tmp_path / "again.csv").read_bytes() == path.read_bytes()


def test_payload_per_pose_round_trip(tmp_path):
    m = Measurements(np.zeros((3, 2)), np.zeros((3, 3)), np.ones((3, 3)), payload_kg=np.array([0.0, 12.5, 100.0]))
    write_measurements(m, tmp_path / "p.csv")
    assert (tmp_path / "p.csv").read_text().splitlines()[0].endswith(",payload_kg")
    back = read_measurements(tmp_path / "p.csv")
    assert back.payload_kg.tolist() == [0.0, 12.5, 100.0]
    assert back.take([2, 0]).payload_kg.tolist() == [100.0, 0.0]
    assert read_measurements(write(tmp_path, HEADER + "\n1,2,3,4,5,6,7,8\n")).payload_kg is None
    with pytest.raises(DataError, match=r"Expected payload_kg as 3 masses in \[0, 100000\] kg \(one per pose\), got 2"):
        Measurements(np.zeros((3, 2)), np.zeros((3, 3)), np.ones((3, 3)), payload_kg=np.array([1.0, 2.0]))
    with pytest.raises(DataError, match=r"got -1 kg at row 2"):
        Measurements(np.zeros((3, 2)), np.zeros((3, 3)), np.ones((3, 3)), payload_kg=np.array([1.0, -1.0, 2.0]))


def test_comments_blank_lines_and_extra_columns(tmp_path):
    path = write(tmp_path, "# a comment\n\nq1,note,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n"
                           "# inside\n10,hello,1,2,3,1.5,2,2\n")
    m = read_measurements(path)
    assert m.q_deg.tolist() == [[10.0]]
    assert m.errors_mm.tolist() == [[0.5, 0.0, -1.0]]


def test_utf8_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "excel.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (HEADER + "\n1,2,3,4,5,6,7,8\n").encode())
    m = read_measurements(path)
    assert m.q_deg.tolist() == [[1.0, 2.0]] and m.errors_mm.tolist() == [[3.0, 3.0, 3.0]]


def test_plain_decimal_notation_is_read_exactly(tmp_path):
    m = read_measurements(write(tmp_path, HEADER + "\n+1.,-.5,1e3,2E-2,-0,3,4,5\n"))
    assert m.q_deg.tolist() == [[1.0, -0.5]] and m.nominal_mm.tolist() == [[1000.0, 0.02, 0.0]]


def test_nominal_from_forward_kinematics(tmp_path, sk120):
    path = write(tmp_path, "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas\n0,-90,-180,0,0,0,1858.65,0,1555.32\n")
    m = read_measurements(path, robot="motoman_sk120")
    np.testing.assert_allclose(m.nominal_mm, [[1857.65, 0.0, 1555.32]], atol=1e-9)
    np.testing.assert_allclose(m.errors_mm, [[1.0, 0.0, 0.0]], atol=1e-9)


@pytest.mark.parametrize("text, match", [
    ("", r"m.csv: empty file"),
    ("# only a comment\n", r"m.csv: empty file"),
    (HEADER + "\n", r"m.csv:1: the header is not followed by any data row"),
    ("q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas\n1,2,3,4,5,6,7\n", r"m.csv:1: column 'z_meas' is missing"),
    ("q1,q2,x_nom,z_nom,x_meas,y_meas,z_meas\n1,2,3,4,5,6,7\n", r"m.csv:1: column 'y_nom' is missing"),
    ("q1,q2,x_meas,y_meas,z_meas\n1,2,3,4,5\n", r"m.csv:1: columns x_nom, y_nom, z_nom are missing"),
    ("q1,q2,q1,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n", r"m.csv:1: column 'q1' appears twice \(columns 1 and 3\)"),
    ("q1,q2,q4,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n", r"m.csv:1: column 'q4': joint columns must run q1..qN"),
    ("x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n1,2,3,4,5,6\n", r"m.csv:1: no joint columns"),
    (HEADER + "\n1,2,3,4,5,6,7,8\n1,2,3,nan,5,6,7,8\n", r"m.csv:3: column 'y_nom': expected a finite number, got 'nan'"),
    (HEADER + "\n1,2,3,4,5,6,7,8\n1,abc,3,4,5,6,7,8\n", r"m.csv:3: column 'q2': expected a finite number, got 'abc'"),
    ("# c\n" + HEADER + "\n1,2,3,4,5,,7,8\n", r"m.csv:3: column 'x_meas': expected a finite number, got an empty cell"),
    (HEADER + "\n1,2,3,4,5,6,7,8\n1,2,3,4,5,6,7\n", r"m.csv:3: expected 8 cells as in the header, got 7"),
    (HEADER + "\n1,2,3,4,5,6,7,inf\n", r"m.csv:2: column 'z_meas': expected a finite number, got 'inf'"),
    (HEADER + "\n1,2,3,4,5,6,1_100,8\n", r"m.csv:2: column 'y_meas': expected a finite number, got '1_100'"),
    (HEADER + "\n1,2,3,4,5,6,7,\u0661\n", r"m.csv:2: column 'z_meas': expected a finite number, got '\u0661'"),
    (HEADER + "\n1,2,3,4,5,6,0x1f,8\n", r"m.csv:2: column 'y_meas': expected a finite number, got '0x1f'"),
    (HEADER + '\n1,2,3,4,5,6,"7,5",8\n', r"m.csv:2: column 'y_meas': expected a number with a decimal point '\.', "
                                          r"got '7,5' \(is the decimal mark ','\? set the format's decimal\)"),
    (HEADER + "\n1,2,3,4,5,6,7,5,8\n", r"m.csv:2: expected 8 cells as in the header, got 9 \(a decimal comma"),
    (HEADER + ",payload_kg\n1,2,3,4,5,6,7,8,5\n1,2,3,4,5,6,7,8,-2.5\n",
     r"m.csv:3: column 'payload_kg': expected a payload mass in \[0, 100000\] kg, got -2.5"),
    (HEADER + ",payload_kg\n1,2,3,4,5,6,7,8,heavy\n", r"m.csv:2: column 'payload_kg': expected a finite number, got 'heavy'"),
    (HEADER + ",payload_kg\n1,2,3,4,5,6,7,8,\n", r"m.csv:2: column 'payload_kg': expected a finite number, got an empty"),
])
def test_bad_files_get_one_clear_error(tmp_path, text, match):
    with pytest.raises(DataError, match=match):
        read_measurements(write(tmp_path, text))


def test_missing_file_and_joint_mismatch_with_robot(tmp_path):
    with pytest.raises(DataError, match=r"nope.csv: no such file"):
        read_measurements(tmp_path / "nope.csv")
    path = write(tmp_path, "q1,q2,x_meas,y_meas,z_meas\n1,2,3,4,5\n")
    with pytest.raises(DataError, match=r"2 joint columns \(q1..q2\) but robot 'motoman_sk120' has 6 joints"):
        read_measurements(path, robot="motoman_sk120")
    # with nominal columns too (a joint model fitted on 5 of 6 joints used to be written and then refused)
    path = write(tmp_path, "q1,q2,q3,q4,q5,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n" + "1," * 10 + "1\n")
    with pytest.raises(DataError, match=r"5 joint columns \(q1..q5\) but robot 'motoman_sk120' has 6 joints"):
        read_measurements(path, robot="motoman_sk120")
    assert read_measurements(path).n_joints == 5          # without a robot, any number of joints


def test_measurements_record_checks_shapes():
    with pytest.raises(DataError, match=r"nominal_mm has 2 rows but q_deg has 1"):
        Measurements(np.zeros((1, 6)), np.zeros((2, 3)), np.zeros((1, 3)))
    with pytest.raises(DataError, match=r"Expected measured_mm with shape \(n, 3\)"):
        Measurements(np.zeros((1, 6)), np.zeros((1, 3)), np.zeros((1, 2)))


def test_read_columns_alternatives_and_partial_optional_columns(tmp_path):
    path = write(tmp_path, "# c\nx_nom,y_nom,z_nom,q1,q2\n1,2,3,4,5\n")
    cols, values, extra = read_columns(path, [["x", "y", "z"], ["x_nom", "y_nom", "z_nom"]], ["q1", "q2"])
    assert cols == ["x_nom", "y_nom", "z_nom"] and values.tolist() == [[1, 2, 3]] and extra.tolist() == [[4, 5]]
    assert read_columns(path, [["x_nom", "y_nom", "z_nom"]])[2] is None
    with pytest.raises(DataError, match=r"m.csv:2: column 'q3' is missing \(give all of q1, q2, q3 or none\)"):
        read_columns(path, [["x_nom", "y_nom", "z_nom"]], ["q1", "q2", "q3"])
    with pytest.raises(DataError, match=r"m.csv:2: column 'x' is missing \(expected columns x,y,z\)"):
        read_columns(path, [["x", "y", "z"]])


# ---------------------------------------------------------------------- several targets and orientation
TARGETS = "q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas"


def _rotation(axis, angle_deg):
    """A rotation about a coordinate axis, written out by hand."""
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    return {"x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def test_targets_and_orientation_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    n = 6
    nominal = rng.uniform(-1e3, 1e3, (n, 3))
    extra = {"B": nominal + [100, 0, 0], "tip_2": nominal + [0, 50, 0]}
    angles = np.column_stack([rng.uniform(-180, 180, n), rng.uniform(-90, 90, n), rng.uniform(-180, 180, n)])
    m = Measurements(rng.uniform(-90, 90, (n, 6)), nominal, nominal + 0.5, name="multi",
                     extra_measured_mm={k: v + 0.25 for k, v in extra.items()}, extra_nominal_mm=extra,
                     measured_orientation_deg=angles + 0.01, nominal_orientation_deg=angles)
    path = tmp_path / "multi.csv"
    write_measurements(m, path)
    assert path.read_text().splitlines()[0] == (
        "q1,q2,q3,q4,q5,q6,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas,x_nom@B,y_nom@B,z_nom@B,x_meas@B,y_meas@B,"
        "z_meas@B,x_nom@tip_2,y_nom@tip_2,z_nom@tip_2,x_meas@tip_2,y_meas@tip_2,z_meas@tip_2,rx_nom,ry_nom,rz_nom,"
        "rx_meas,ry_meas,rz_meas")
    back = read_measurements(path)
    assert back.target_names == ("A", "B", "tip_2")
    np.testing.assert_allclose(back.errors_mm, 0.5, atol=2e-6)        # the primary target, as before
    np.testing.assert_allclose(back.measured_of("B") - back.nominal_of("B"), 0.25, atol=2e-6)
    np.testing.assert_allclose(back.nominal_of("tip_2"), extra["tip_2"], atol=1e-6)
    np.testing.assert_allclose(back.measured_orientation_deg, angles + 0.01, atol=1e-6)
    write_measurements(back, tmp_path / "again.csv")
    assert (tmp_path / "again.csv").read_bytes() == path.read_bytes()
    with pytest.raises(DataError, match=r"Expected a target of multi \(A, B, tip_2\), got 'C'"):
        back.measured_of("C")


def test_orientation_convention_is_intrinsic_xyz(tmp_path):
    from partcal.robot.kinematics import matrices_from_xyz_deg, xyz_deg_from_matrices

    by_hand = _rotation("x", 30) @ _rotation("y", -50) @ _rotation("z", 120)
    np.testing.assert_allclose(matrices_from_xyz_deg([[30, -50, 120]])[0], by_hand, atol=1e-15)
    np.testing.assert_allclose(xyz_deg_from_matrices(by_hand[None]), [[30, -50, 120]], atol=1e-12)
    # an orientation error: the measured tool turned by 0.5 degrees about the base's z axis
    turned = xyz_deg_from_matrices((_rotation("z", 0.5) @ by_hand)[None])
    m = Measurements(np.zeros((1, 2)), np.zeros((1, 3)), np.zeros((1, 3)), measured_orientation_deg=turned,
                     nominal_orientation_deg=[[30, -50, 120]])
    np.testing.assert_allclose(m.orientation_errors_deg, [[0, 0, 0.5]], atol=1e-12)


def test_nominal_orientation_and_extra_targets_with_a_robot(tmp_path, sk120):
    q = np.array([[0, -90, -180, 0, 0, 0], [10, -80, -170, 20, -30, 40]], dtype=float)
    p = sk120.positions(q)
    from scipy.spatial.transform import Rotation

    # measured as the flange's (a plausible orientation: a far one is refused, tests/test_plausibility.py)
    with __import__("warnings").catch_warnings():
        __import__("warnings").simplefilter("ignore")           # the first pose is at ry = 90: any rx, rz pair
        angles = Rotation.from_matrix(sk120.forward(q)[:, :3, :3]).as_euler("XYZ", degrees=True)
    rows = "\n".join(",".join(f"{v:.9f}" for v in (*qi, *pi, *(pi + 1), *ai)) for qi, pi, ai in zip(q, p, angles))
    path = write(tmp_path, "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas,x_meas@B,y_meas@B,z_meas@B,rx_meas,ry_meas,"
                           "rz_meas\n" + rows + "\n")
    m = read_measurements(path, robot=sk120)
    assert m.nominal_of("B") is None and m.extra_nominal_mm == {}
    np.testing.assert_allclose(m.measured_of("B"), p + 1, atol=1e-8)
    # the nominal orientation is the last frame's: check it against the flange axes by an independent reading
    axes = Rotation.from_euler("XYZ", m.nominal_orientation_deg, degrees=True).as_matrix()
    np.testing.assert_allclose(axes, sk120.forward(q)[:, :3, :3], atol=1e-12)


BAD_TARGETS = "q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas,"


@pytest.mark.parametrize("extra, cells, match", [
    ("x_meas@B,y_meas@B", "1,2", r"m.csv:1: column 'z_meas@B' is missing \(target B needs all of x_meas@B, "
                                 r"y_meas@B, z_meas@B\)"),
    ("x_nom@B,y_nom@B,z_nom@B", "1,2,3", r"m.csv:1: column 'x_meas@B' is missing"),
    ("x_meas@B,y_meas@B,z_meas@B,x_nom@B", "1,2,3,4", r"m.csv:1: column 'y_nom@B' is missing \(target B needs "
                                                      r"all of x_nom@B, y_nom@B, z_nom@B when it has nominal"),
    ("x_meas@B,y_meas@B,z_meas@B,x_nom@B,y_nom@B,z_nom@B,x_meas@C,y_meas@C,z_meas@C", "1,2,3,4,5,6,7,8,9",
     r"m.csv:1: column 'x_nom@C' is missing: target B has nominal columns, so every extra target needs them"),
    ("x_meas@,y_meas@,z_meas@", "1,2,3", r"m.csv:1: column 'x_meas@': a target name is letters, digits and '_'"),
    ("x_meas@A,y_meas@A,z_meas@A", "1,2,3", r"m.csv:1: column 'x_meas@A': 'A' names the unsuffixed columns"),
    ("rx_meas@B", "1", r"m.csv:1: column 'rx_meas@B': the orientation is one per pose"),
    ("rx_meas,ry_meas", "1,2", r"m.csv:1: column 'rz_meas' is missing \(give all of rx_meas, ry_meas, rz_meas"),
    ("rx_nom,ry_nom,rz_nom", "1,2,3", r"m.csv:1: column 'rx_meas' is missing: the nominal orientation"),
    ("rx_meas,ry_meas,rz_meas", "1,2,3", r"m.csv:1: columns rx_nom, ry_nom, rz_nom are missing; give them, or a "
                                         r"robot"),
    ("rx_meas,ry_meas,rz_meas,rx_nom,ry_nom,rz_nom", "1,95.5,3,1,2,3",
     r"m.csv:2: column 'ry_meas': expected an angle in \[-90, 90\] degrees \(intrinsic XYZ angles\), got '95.5'"),
    ("rx_meas,ry_meas,rz_meas,rx_nom,ry_nom,rz_nom", "1,2,3,1,2,-181",
     r"m.csv:2: column 'rz_nom': expected an angle in \[-180, 180\] degrees \(intrinsic XYZ angles\), got '-181'"),
    ("rx_meas,ry_meas,rz_meas,rx_nom,ry_nom,rz_nom", "1,nan,3,1,2,3",
     r"m.csv:2: column 'ry_meas': expected a finite number, got 'nan'"),
])
def test_bad_target_and_orientation_columns_get_one_clear_error(tmp_path, extra, cells, match):
    with pytest.raises(DataError, match=match):
        read_measurements(write(tmp_path, BAD_TARGETS + extra + "\n1,2,3,4,5,6,7,8," + cells + "\n"))


def test_a_tracker_frame_refuses_extra_nominal_columns(tmp_path):
    path = write(tmp_path, "q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas,x_meas@B,y_meas@B,z_meas@B,x_nom@B,y_nom@B,"
                           "z_nom@B\n" + "1," * 14 + "1\n")
    with pytest.raises(DataError, match=r"m.csv:1: column 'x_nom@B': with frame: tracker the nominal positions"):
        read_measurements(path, "motoman_sk120", frame="tracker")


def test_measurements_record_checks_targets_and_orientation():
    z = np.zeros((1, 3))
    with pytest.raises(DataError, match=r"Expected target names of letters, digits and '_' other than 'A'"):
        Measurements(np.zeros((1, 2)), z, z, extra_measured_mm={"A": z})
    with pytest.raises(DataError, match=r"extra_nominal_mm must name the targets of extra_measured_mm"):
        Measurements(np.zeros((1, 2)), z, z, extra_measured_mm={"B": z}, extra_nominal_mm={"C": z})
    with pytest.raises(DataError, match=r"Expected measured_orientation_deg and nominal_orientation_deg both"):
        Measurements(np.zeros((1, 2)), z, z, measured_orientation_deg=z)
    with pytest.raises(DataError, match=r"Expected nominal_orientation_deg within \[-90, 90\] degrees"):
        Measurements(np.zeros((1, 2)), z, z, measured_orientation_deg=z, nominal_orientation_deg=[[0, 91, 0]])


def test_a_measurements_file_read_as_points_is_named_as_one(tmp_path):
    from partcal.data.formats import MeasurementFormat
    path = tmp_path / "probe.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,kind,feature\n0,-90,90,0,90,0,plane,top\n")
    with pytest.raises(DataError, match=r"probe\.csv:1: column 'x_meas' is missing .*; column 'kind' makes it a "
                                        r"measurements file, which partcal run"):
        read_measurements(path, robot="universal_robots_ur10")
    foreign = tmp_path / "foreign.csv"
    foreign.write_text("q1,q2,q3,q4,q5,q6,Type,Feature\n0,-90,90,0,90,0,plane,top\n")
    with pytest.raises(DataError, match=r"column 'Type' makes it a measurements file"):
        read_measurements(foreign, robot="universal_robots_ur10", fmt=MeasurementFormat(columns={"measurement": "Type"}))
    plain = tmp_path / "plain.csv"
    plain.write_text("q1,q2,q3,q4,q5,q6,x_meas\n0,-90,90,0,90,0,1\n")
    with pytest.raises(DataError) as refused:
        read_measurements(plain, robot="universal_robots_ur10")
    assert "measurement-type" not in str(refused.value)
