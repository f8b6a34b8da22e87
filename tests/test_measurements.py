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
