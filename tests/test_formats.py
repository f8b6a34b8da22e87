"""Foreign measurement files: every format key, row subsets, and one clear error per problem."""

import math
import re

import numpy as np
import pytest
import yaml
from conftest import write_text

from partcal import ConfigError, DataError, read_measurements
from partcal._yamlio import Section, load_yaml
from partcal.data.formats import MeasurementFormat, RowSelection, load_format
from partcal.data.measurements import read_columns

CONTRACT = "q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n"


def write(tmp_path, text, name="f.csv"):
    return write_text(tmp_path, text, name)


def test_a_tracker_export_reads_as_the_contract(tmp_path):
    # semicolons, decimal commas, foreign names, unmapped columns (one in Excel's exponent notation), rad and m
    row = f"2,02011E+13;{-math.pi / 4:.12f};{math.pi / 2:.12f};1.5;-0.25;0.001;21.5;1;2;3".replace(".", ",")
    path = write(tmp_path, "stamp;axis_2;axis_1;smr_x;smr_y;smr_z;temp;x0;y0;z0\n" + row + "\n")
    columns = {"q1": "axis_1", "q2": "axis_2", "x_meas": "smr_x", "y_meas": "smr_y", "z_meas": "smr_z"}
    fmt = MeasurementFormat(delimiter=";", decimal=",", joint_unit="rad", length_unit="m", columns=columns)
    with pytest.raises(DataError, match=r"f.csv:1: columns x_nom, y_nom, z_nom are missing"):
        read_measurements(path, fmt=fmt)
    full = MeasurementFormat(**{**fmt.to_dict(), "columns": {**columns, "x_nom": "x0", "y_nom": "y0", "z_nom": "z0"}})
    m = read_measurements(path, fmt=full)
    np.testing.assert_allclose(m.q_deg, [[90.0, -45.0]], rtol=1e-12)
    np.testing.assert_allclose(m.measured_mm, [[1500.0, -250.0, 1.0]], rtol=1e-12)
    np.testing.assert_allclose(m.nominal_mm, [[1000.0, 2000.0, 3000.0]], rtol=1e-12)


@pytest.mark.parametrize("kwargs, text, q, meas", [
    ({"delimiter": "\t"}, CONTRACT.replace(",", "\t") + "1\t2\t0\t0\t0\t3\t4\t5\n", [1, 2], [3, 4, 5]),
    ({"delimiter": ";"}, CONTRACT.replace(",", ";") + "1;2;0;0;0;3;4;5\n", [1, 2], [3, 4, 5]),
    ({"delimiter": ";", "decimal": ","}, CONTRACT.replace(",", ";") + "1,5;2;0;0;0;3;4;-0,25\n", [1.5, 2], [3, 4, -0.25]),
    ({"columns": {"q1": "A1", "x_meas": "X"}}, CONTRACT.replace("q1", "A1").replace("x_meas", "X") + "1,2,0,0,0,3,4,5\n",
     [1, 2], [3, 4, 5]),
    ({"joint_unit": "rad"}, CONTRACT + f"{math.pi:.15f},{-math.pi / 6:.15f},0,0,0,3,4,5\n", [180, -30], [3, 4, 5]),
    ({"length_unit": "m"}, CONTRACT + "1,2,0,0,0,0.003,-4,5e-3\n", [1, 2], [3, -4000, 5]),
])
def test_each_format_key(tmp_path, kwargs, text, q, meas):
    m = read_measurements(write(tmp_path, text), fmt=MeasurementFormat(**kwargs))
    np.testing.assert_allclose(m.q_deg, [q], rtol=1e-13)
    np.testing.assert_allclose(m.measured_mm, [meas], rtol=1e-13)


def test_a_mapped_column_wins_over_an_unmapped_one_of_the_contract_name(tmp_path):
    path = write(tmp_path, "q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas,laser_x\n1,2,0,0,0,99,4,5,3\n")
    m = read_measurements(path, fmt=MeasurementFormat(columns={"x_meas": "laser_x"}))
    assert m.measured_mm.tolist() == [[3.0, 4.0, 5.0]]


@pytest.mark.parametrize("kwargs, text, match", [
    ({"columns": {"x_meas": "smr_x"}}, CONTRACT + "1,2,0,0,0,3,4,5\n",
     r"f.csv:1: column 'smr_x' is missing \(the format maps x_meas to it\)"),
    ({"columns": {"x_meas": "smr_x"}}, "# exported\n" + CONTRACT.replace("x_meas", "smr_x") + "1,2,0,0,0,3.5.1,4,5\n",
     r"f.csv:3: column 'smr_x' \(x_meas\): expected a finite number, got '3.5.1'"),
    ({"decimal": ",", "delimiter": ";"}, CONTRACT.replace(",", ";") + "1;2;0;0;0;3.5;4;5\n",
     r"f.csv:2: column 'x_meas': expected a number with a decimal comma ',', got '3.5' \(is the decimal mark '\.'\?"),
    ({"decimal": ",", "delimiter": ";"}, CONTRACT.replace(",", ";") + "1;2;0;0;0;1.234,5;4;5\n",
     r"f.csv:2: column 'x_meas': expected a finite number, got '1.234,5'"),
    ({"decimal": ",", "delimiter": ";"}, CONTRACT.replace(",", ";") + "1;2;0;0;0;1_0;4;5\n",
     r"f.csv:2: column 'x_meas': expected a finite number, got '1_0'"),
    ({"columns": {"q1": "axis_1"}}, "axis_1;q2;x_nom;y_nom;z_nom;x_meas;y_meas;z_meas\n1;2;0;0;0;3;4;5\n",
     r"f.csv:1: the header is one column containing ';', but the delimiter is ',': is it ';'\? \(set the format's "
     r"delimiter\)"),
    ({"delimiter": ";"}, CONTRACT + "1,2,0,0,0,3,4,5\n", r"f.csv:1: the header is one column containing ',', but the "
                                                         r"delimiter is ';'"),
    ({"delimiter": "|"}, "q1;q2\n1;2\n", r"f.csv:1: the header is one column containing ';'"),
    ({"delimiter": ";"}, "q1 q2 x_meas\n1 2 3\n", r"f.csv:1: no joint columns"),
    ({"columns": {"z_meas": "Z"}}, CONTRACT.replace("z_meas", "Z").replace("y_meas", "Y") + "1,2,0,0,0,3,4,5\n",
     r"f.csv:1: column 'y_meas' is missing \(required: x_meas, y_meas, Z\)"),
])
def test_bad_foreign_files_name_file_line_and_column(tmp_path, kwargs, text, match):
    with pytest.raises(DataError, match=match):
        read_measurements(write(tmp_path, text), fmt=MeasurementFormat(**kwargs))


@pytest.mark.parametrize("kwargs, match", [
    ({"delimiter": ";;"}, r"The 'delimiter' parameter of MeasurementFormat must be one character .* Got ';;' instead"),
    ({"delimiter": '"'}, r"The 'delimiter' parameter"),
    ({"decimal": ";"}, r"The 'decimal' parameter of MeasurementFormat must be one of '\.', ','\. Got ';' instead"),
    ({"decimal": ","}, r"The 'decimal' parameter of MeasurementFormat must be different from the delimiter ','\. "
                       r"Got ',' instead"),
    ({"joint_unit": "grad"}, r"The 'joint_unit' parameter of MeasurementFormat must be one of 'deg', 'rad'\. "
                             r"Got 'grad' instead"),
    ({"length_unit": "cm"}, r"The 'length_unit' parameter of MeasurementFormat must be one of 'mm', 'm'"),
    ({"orientation_unit": "grad"}, r"The 'orientation_unit' parameter of MeasurementFormat must be one of 'deg', "
                                   r"'rad'\. Got 'grad' instead"),
    ({"columns": {"x_meas@": "a"}}, r"The 'columns' entry 'x_meas@' of MeasurementFormat must be a contract column"),
    ({"columns": [("q1", "a")]}, r"The 'columns' parameter of MeasurementFormat must be a mapping of contract "
                                 r"column to file column"),
    ({"columns": {"q13": "a"}}, r"The 'columns' entry 'q13' of MeasurementFormat must be a contract column "
                                r"\(q1\.\.q12, .*, set, payload_kg\) or a measurement-type column \(measurement, id, "
                                r"target, feature, flush, distance_mm, to, image, camera, board, point, u_px, "
                                r"v_px\)\. Got 'q13'"),
    ({"columns": {"temperature": "a"}}, r"Got 'temperature' instead"),
    ({"columns": {"xmeas": "a"}}, r"Got 'xmeas' \(did you mean 'x_meas'\?\) instead"),
    ({"measurements": ["Plane"]}, r"The 'measurements' parameter of MeasurementFormat must be a mapping of the file's type "
                           r"value to a type name\. Got \['Plane'\] instead"),
    ({"measurements": {"Plane": ""}}, r"The 'measurements' entry 'Plane' of MeasurementFormat must be a non-empty type name"),
    ({"columns": {"q1": " "}}, r"The 'columns' entry 'q1' of MeasurementFormat must be a non-empty file column "
                               r"name\. Got ' ' instead"),
    ({"columns": {"q1": "a", "q2": "a"}}, r"The 'columns' entry 'q2' of MeasurementFormat must be a file column "
                                          r"that holds no other contract column\. Got 'a' \(already mapped to q1\)"),
    ({"columns": {"x_meas": "q1"}}, r"Got 'q1' \(the contract column q1 is not mapped, so it is read under its own "
                                    r"name: map q1 too\) instead"),
])
def test_bad_format_parameters(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        MeasurementFormat(**kwargs)


YAML = """delimiter: ";"
decimal: ","
columns: {q1: axis_1, x_meas: smr_x}
joint_unit: rad
length_unit: m
"""


def test_format_yaml_round_trip(tmp_path):
    fmt = load_format(write(tmp_path, YAML, "fmt.yaml"))
    assert fmt == MeasurementFormat(delimiter=";", decimal=",", columns={"q1": "axis_1", "x_meas": "smr_x"},
                                    joint_unit="rad", length_unit="m")
    assert MeasurementFormat(**fmt.to_dict()) == fmt and not fmt.is_contract and MeasurementFormat().is_contract


def test_a_format_for_measurements_files_round_trips_through_yaml(tmp_path):
    text = YAML.replace("x_meas: smr_x}", "x_meas: smr_x, measurement: Type, distance_mm: Length}")
    fmt = load_format(write(tmp_path, text + "measurements: {Sphere: fixed, Plane: plane}\n", "fmt.yaml"))
    assert fmt.columns == {"q1": "axis_1", "x_meas": "smr_x", "measurement": "Type", "distance_mm": "Length"}
    assert fmt.measurements == {"Sphere": "fixed", "Plane": "plane"}
    assert MeasurementFormat(**fmt.to_dict()) == fmt and fmt.to_dict()["measurements"] == fmt.measurements
    assert "measurements" not in MeasurementFormat().to_dict()        # a format without it is written as before


def test_a_format_of_the_old_names_kind_and_kinds_is_read_for_one_release_with_a_warning(tmp_path, caplog):
    text = YAML.replace("x_meas: smr_x}", "x_meas: smr_x, kind: Type}")
    fmt = load_format(write(tmp_path, text + "kinds: {Plane: plane}\n", "fmt.yaml"))
    assert fmt.columns["measurement"] == "Type" and fmt.measurements == {"Plane": "plane"}
    said = [r.getMessage() for r in caplog.records]
    assert any("columns.kind (line 3): the old name of 'measurement'" in m for m in said)
    assert any("kinds (line 6): the old name of 'measurements'" in m for m in said)
    with pytest.raises(ConfigError, match=r"kinds \(line 6\): is the old name of 'measurements', which is given too"):
        load_format(write(tmp_path, text + "kinds: {Plane: plane}\nmeasurements: {}\n", "both.yaml"))


@pytest.mark.parametrize("old, new, match", [
    ('delimiter: ";"', 'delimiter: ","', r"fmt.yaml: decimal \(line 2\): must be different from the delimiter ','; "
                                         r"got ','"),
    ('decimal: ","', 'decimal: "/"', r"fmt.yaml: decimal \(line 2\): must be one of '\.', ','; got '/'"),
    ("q1: axis_1", "q_1: axis_1", r"fmt.yaml: columns.q_1 \(line 3\): must be a contract column "
                                  r"\(q1\.\.q12, .*, set, payload_kg\) or a measurement-type column \(measurement, .*\); "
                                  r"got 'q_1' \(did you mean 'q1'\?\)"),
    ("q1: axis_1", "q1: ' '", r"fmt.yaml: columns.q1 \(line 3\): must be a non-empty file column name; got ' '"),
    ("x_meas: smr_x", "x_meas: axis_1", r"columns.x_meas \(line 3\): must be a file column that holds no other "
                                        r"contract column; got 'axis_1' \(already mapped to q1\)"),
    ("x_meas: smr_x", "x_meas: ' axis_1 '", r"columns.x_meas \(line 3\): .*; got 'axis_1' \(already mapped to q1\)"),
    ("x_meas: smr_x", "x_meas: q2", r"columns.x_meas \(line 3\): .*; got 'q2' \(the contract column q2 is not mapped, "
                                    r"so it is read under its own name: map q2 too\)"),
    ("joint_unit: rad", "joint_unit: radians", r"joint_unit \(line 4\): must be one of 'deg', 'rad'; got 'radians'"),
    ("length_unit: m", "length_units: m", r"length_units \(line 5\): unknown key; did you mean 'length_unit'\?"),
    ('delimiter: ";"', 'delimiter: ";,"', r"delimiter \(line 1\): must be one character other than a quote"),
    ('delimiter: ";"', 'delimiter: 1', r"delimiter \(line 1\): must be a text; got 1"),
])
def test_format_yaml_errors_name_key_and_line(tmp_path, old, new, match):
    with pytest.raises(ConfigError, match=match):
        load_format(write(tmp_path, YAML.replace(old, new), "fmt.yaml"))


@pytest.mark.parametrize("kwargs", [
    {"delimiter": ";;"}, {"delimiter": '"'}, {"decimal": ";"}, {"decimal": ","}, {"joint_unit": "grad"},
    {"length_unit": "cm"}, {"columns": {"q13": "a"}}, {"columns": {"xmeas": "a"}}, {"columns": {"q1": " "}},
    {"columns": {"q1": "a", "q2": "a"}}, {"columns": {"x_meas": "q1"}}, {"columns": {"featur": "a"}},
    {"columns": {"measurement": "a", "feature": "to"}}, {"measurements": {"Plane": " "}},
])
def test_each_format_rule_has_one_wording_from_python_and_from_yaml(tmp_path, kwargs):
    with pytest.raises(ConfigError) as built:
        MeasurementFormat(**kwargs)
    with pytest.raises(ConfigError) as read:
        load_format(write(tmp_path, yaml.safe_dump(kwargs), "fmt.yaml"))
    python = re.fullmatch(r"The '(\w+)' (?:parameter|entry '(\w+)') of MeasurementFormat must be (.+)\. "
                          r"Got (.+) instead\.", str(built.value))
    from_yaml = re.fullmatch(r".*fmt\.yaml: ([\w.]+) \(line \d+\): must be (.+); got (.+)", str(read.value))
    assert python and from_yaml, (str(built.value), str(read.value))
    key, entry, expected, got = python.groups()
    assert from_yaml.groups() == (key if entry is None else f"{key}.{entry}", expected, got)


@pytest.mark.parametrize("python, text", [
    (lambda: RowSelection(every=0), "every: 0"), (lambda: RowSelection.parse("4-2"), "rows: 4-2"),
    (lambda: RowSelection.parse("1-3, 3-4"), "rows: 1-3, 3-4"), (lambda: RowSelection.parse("1-"), "rows: 1-"),
    (lambda: RowSelection(((5, 6), (1, 2))), "rows: 5-6, 1-2"),
])
def test_each_row_rule_has_one_wording_from_python_and_from_yaml(tmp_path, python, text):
    with pytest.raises(ConfigError) as built:
        python()
    path = write(tmp_path, text + "\n", "sel.yaml")
    data, lines = load_yaml(path)
    with pytest.raises(ConfigError) as read:
        RowSelection.from_section(Section(data, "", lines, str(path)))
    key, expected, got = re.fullmatch(r"The '(\w+)' parameter of RowSelection must be (.+)\. Got (.+) instead\.",
                                      str(built.value)).groups()
    assert str(read.value) == f"{path}: {key} (line 1): must be {expected}; got {got}"


def test_row_selection(tmp_path):
    assert RowSelection.parse("2-4").indices(5, "f").tolist() == [1, 2, 3]
    assert RowSelection.parse(None, every=3).indices(7, "f").tolist() == [0, 3, 6]
    assert RowSelection.parse("1-2, 5, 7-9", every=2).indices(9, "f").tolist() == [0, 4, 7]
    assert RowSelection.parse(" 3 - 4 ").text == "3-4" and RowSelection().is_all
    with pytest.raises(DataError, match=r"f.csv: rows '1-600' asks for data row 600, but the file has 599 data rows"):
        RowSelection.parse("1-600").indices(599, "f.csv")
    for bad in ("0-3", "4-2", "1-3, 3-5", "5, 2", "1-", "a", ""):
        with pytest.raises(ConfigError):
            RowSelection.parse(bad)
    with pytest.raises(ConfigError, match=r"'every' parameter of RowSelection must be an int >= 1\. Got 0"):
        RowSelection(every=0)
    path = write(tmp_path, "rows: 1-3, 3-4\n", "sel.yaml")
    data, lines = load_yaml(path)
    with pytest.raises(ConfigError, match=r"sel.yaml: rows \(line 1\): must be data rows such as '1-600'.*got '1-3, 3-4'"):
        RowSelection.from_section(Section(data, "", lines, str(path)))


def test_rows_pick_data_lines_not_file_lines(tmp_path):
    path = write(tmp_path, "# exported\n" + CONTRACT + "".join(f"{i},0,0,0,0,0,0,0\n# note\n" for i in range(1, 7)))
    m = read_measurements(path, rows=RowSelection.parse("2-6", every=2))
    assert m.q_deg[:, 0].tolist() == [2.0, 4.0, 6.0]
    labelled = write(tmp_path, "q1,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas,set\n" +
                     "".join(f"{i},0,0,0,0,0,0,s{i}\n" for i in range(1, 5)), "l.csv")
    assert read_measurements(labelled, rows=RowSelection.parse("3-4")).labels == ("s3", "s4")


def test_read_columns_with_a_format(tmp_path):
    path = write(tmp_path, "A;B;C;J1\n0,1;0,2;0,3;3,14159265358979\n")
    fmt = MeasurementFormat(delimiter=";", decimal=",", length_unit="m", joint_unit="rad",
                            columns={"x": "A", "y": "B", "z": "C", "q1": "J1"})
    cols, xyz, q = read_columns(path, [["x", "y", "z"]], ["q1"], fmt=fmt)
    assert cols == ["x", "y", "z"]
    np.testing.assert_allclose(xyz, [[100.0, 200.0, 300.0]], rtol=1e-13)
    np.testing.assert_allclose(q, [[180.0]], rtol=1e-13)
    with pytest.raises(DataError, match=r"f.csv:1: column 'x' is missing \(expected columns x,B,C\)"):
        read_columns(path, [["x", "y", "z"]], fmt=MeasurementFormat(delimiter=";", columns={"y": "B", "z": "C"}))


def test_tracker_frame_needs_a_robot_and_refuses_nominal_columns(tmp_path):
    path = write(tmp_path, CONTRACT + "1,2,0,0,0,3,4,5\n")
    with pytest.raises(DataError, match=r"f.csv: measurements in a tracker frame need a robot model"):
        read_measurements(path, frame="tracker")
    six = write(tmp_path, "q1,q2,q3,q4,q5,q6,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n" + "0," * 11 + "0\n", "six.csv")
    with pytest.raises(DataError, match=r"six.csv:1: column 'x_nom': with frame: tracker the nominal positions"):
        read_measurements(six, "motoman_sk120", frame="tracker")
    with pytest.raises(DataError, match=r"The 'frame' parameter of read_measurements must be 'base' or 'tracker'\. "
                                        r"Got 'Tracker' instead"):
        read_measurements(six, "motoman_sk120", frame="Tracker")


def test_the_ipa_orientation_columns_read_through_a_format(tmp_path):
    # the T-Mac's export: orientation in intrinsic XYZ degrees beside the position, each with a std column
    header = "a1;a2;a3;a4;a5;a6;measurement_x;measurement_std_x;measurement_y;measurement_z;measurement_rx;measurement_ry;" \
             "measurement_rz;mx;my;mz\n"
    path = write(tmp_path, header + "0,5;-0,25;1;1;1;1;383,97;0,04;-3240,75;201,72;-90,179563;-20,112975;-90,157388;0;0;0\n")
    columns = {**{f"q{j}": f"a{j}" for j in range(1, 7)}, "x_meas": "measurement_x", "y_meas": "measurement_y", "z_meas": "measurement_z",
               "rx_meas": "measurement_rx", "ry_meas": "measurement_ry", "rz_meas": "measurement_rz",
               "x_nom": "mx", "y_nom": "my", "z_nom": "mz", "rx_nom": "mx", "ry_nom": "my", "rz_nom": "mz"}
    with pytest.raises(ConfigError, match=r"'columns' entry 'rx_nom' .* Got 'mx' \(already mapped to x_nom\)"):
        MeasurementFormat(delimiter=";", decimal=",", columns=columns)
    del columns["rx_nom"], columns["ry_nom"], columns["rz_nom"]
    fmt = MeasurementFormat(delimiter=";", decimal=",", joint_unit="rad", columns=columns)
    with pytest.raises(DataError, match=r"f.csv:1: columns rx_nom, ry_nom, rz_nom are missing"):
        read_measurements(path, fmt=fmt)
    m = read_measurements(path, "universal_robots_ur10", fmt=MeasurementFormat(
        **{**fmt.to_dict(), "columns": {k: v for k, v in columns.items() if "nom" not in k}}), frame="tracker")
    np.testing.assert_allclose(m.measured_orientation_deg, [[-90.179563, -20.112975, -90.157388]], rtol=1e-12)
    assert m.nominal_orientation_deg.shape == (1, 3)


def test_orientation_in_radians_and_target_columns_in_metres(tmp_path):
    path = write(tmp_path, "q1,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas,tx,ty,tz,rx_nom,ry_nom,rz_nom,rx,ry,rz\n"
                           f"1,0,0,0,0.001,0,0,0.1,0.2,0.3,{math.pi / 2},{-math.pi / 4},0.1,{math.pi / 2},{-math.pi / 4},0.1\n")
    fmt = MeasurementFormat(length_unit="m", orientation_unit="rad", columns={
        "x_meas@B": "tx", "y_meas@B": "ty", "z_meas@B": "tz", "rx_meas": "rx", "ry_meas": "ry", "rz_meas": "rz"})
    m = read_measurements(path, fmt=fmt)
    np.testing.assert_allclose(m.measured_of("B"), [[100, 200, 300]], rtol=1e-12)
    np.testing.assert_allclose(m.measured_orientation_deg, [[90, -45, math.degrees(0.1)]], rtol=1e-12)
    assert load_format(write(tmp_path, "orientation_unit: rad\n", "o.yaml")).orientation_unit == "rad"
