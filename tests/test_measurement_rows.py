"""The measurements CSV and the cell YAML (partcal/data/measurement_rows.py, docs/data.md)."""

import re

import numpy as np
import pytest
from conftest import write_text

from partcal.data.formats import MeasurementFormat
from partcal.data.measurements import read_measurements
from partcal.data.measurement_rows import (MeasurementRows, has_measurement_column, read_cell, read_measurement_rows,
                                       write_measurement_rows)
from partcal.errors import ConfigError, DataError

HEADER = "q1,q2,measurement,id,feature,flush,distance_mm,to,x_meas,y_meas,z_meas,set"
ROWS = """\
# one row of every type
1,2,point,,,,,,100,200,300,id
3,4,plane,,top,1,,,,,,id
5,6,plane,,top,,,,,,,id
7,8,fixed,,nest_a,,,,,,,id
9,10,pose,end,,,,,,,,id
11,12,distance,,,,812.5,end,,,,id
13,14,distance,,,,900.25,nest_a,,,,id
"""


def write(tmp_path, text, name="obs.csv"):
    return write_text(tmp_path, text, name)


def refused(path, line, column, pattern, **kwargs):
    """Reading ``path`` fails naming the file, the line and the column, then ``pattern``."""
    with pytest.raises(DataError) as info:
        read_measurement_rows(path, **kwargs)
    message = str(info.value)
    head = f"{path}:{line}: column '{column}': "
    assert message.startswith(head), message
    assert re.search(pattern, message[len(head):]), message


def test_every_measurement_type_is_read_into_plain_arrays(tmp_path):
    path = write(tmp_path, HEADER + "\n" + ROWS)
    t = read_measurement_rows(path, None)
    assert t.types == ("point", "plane", "plane", "fixed", "pose", "distance", "distance")
    assert t.ids == ("1", "2", "3", "4", "end", "6", "7")          # default: the 1-based data-row number
    assert t.lines == (3, 4, 5, 6, 7, 8, 9)                          # the comment and header lines counted
    assert t.q_deg.tolist() == [[1, 2], [3, 4], [5, 6], [7, 8], [9, 10], [11, 12], [13, 14]]
    assert t.texts["feature"] == ("", "top", "top", "nest_a", "", "", "")
    assert t.texts["to"][5:] == ("end", "nest_a")
    np.testing.assert_array_equal(t.numbers["flush"], [np.nan, 1, np.nan, np.nan, np.nan, np.nan, np.nan])
    np.testing.assert_array_equal(t.numbers["distance_mm"][5:], [812.5, 900.25])
    assert np.isnan(t.numbers["distance_mm"][:5]).all()
    assert [t.numbers[c][0] for c in ("x_meas", "y_meas", "z_meas")] == [100, 200, 300]
    assert t.texts["set"] == ("id",) * 7 and t.name == "obs" and t.source == str(path)
    assert t.of("plane").tolist() == [1, 2] and len(t) == 7


def test_a_file_with_measurement_type_is_told_from_a_point_file(tmp_path):
    measurements = write(tmp_path, HEADER + "\n" + ROWS)
    points = write(tmp_path, "q1,q2,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas\n1,2,3,4,5,6,7,8\n", "p.csv")
    assert has_measurement_column(measurements) and not has_measurement_column(points)
    assert has_measurement_column(write(tmp_path, "q1;measurement\n1;pose\n", "semi.csv"), MeasurementFormat(delimiter=";"))
    assert read_measurements(points).errors_mm.tolist() == [[3, 3, 3]]      # a point file reads as before
    with pytest.raises(DataError, match=r"p\.csv:1: column 'measurement' is missing"):
        read_measurement_rows(points)


def test_other_columns_are_kept_as_numbers_or_texts(tmp_path):
    path = write(tmp_path, "q1,measurement,gauge_mm,note,flag\n1,pose,2.5,a,nan\n2,pose,,3,1\n")
    t = read_measurement_rows(path)
    np.testing.assert_array_equal(t.numbers["gauge_mm"], [2.5, np.nan])
    assert t.texts["note"] == ("a", "3") and t.texts["flag"] == ("nan", "1")


def test_measurement_types_are_a_parameter(tmp_path):
    path = write(tmp_path, "q1,measurement,angle\n1,inclinometer,0.5\n2,pose,\n")
    refused(path, 2, "measurement", r"one of the types point, plane, fixed, distance, camera, pose, got 'inclinometer'")
    t = read_measurement_rows(path, measurements=("pose", "inclinometer"))
    assert t.types == ("inclinometer", "pose") and t.numbers["angle"][0] == 0.5


@pytest.mark.parametrize("row, line, column, pattern", [
    ("1,2,laser,,,,,,,,,", 3, "measurement", r"one of the types point, plane, fixed, distance, camera, pose, got 'laser'"),
    ("1,2,,,,,,,,,,", 3, "measurement", r"one of the types .*, got an empty cell"),
    ("1,2,plane,,,,,,,,,", 3, "feature", r"a value on a plane row \(plane rows read feature\), got an empty cell"),
    ("1,2,fixed,,,,,,,,,", 3, "feature", r"a value on a fixed row"),
    ("1,2,distance,,,,,x,,,,", 3, "distance_mm", r"a value on a distance row \(distance rows read distance_mm, to\)"),
    ("1,2,distance,,,,5,,,,,", 3, "to", r"a value on a distance row"),
    ("1,2,distance,,,,0,x,,,,", 3, "distance_mm", r"a distance > 0 mm, got '0'"),
    ("1,2,distance,,,,-3.5,x,,,,", 3, "distance_mm", r"a distance > 0 mm, got '-3.5'"),
    ("1,2,point,,,,,,1,2,,", 3, "z_meas", r"a value on a point row \(point rows read x_meas, y_meas, z_meas\)"),
    ("1,2,point,,,,,,1,2,abc,", 3, "z_meas", r"expected a finite number, got 'abc'"),
    ("1,2,plane,,top,2,,,,,,", 3, "flush", r"0 or 1 .*, got '2'"),
    ("1,,pose,,,,,,,,,", 3, "q2", r"a number \(it is required on every row\), got an empty cell"),
    ("1,2,pose,,,,abc,,,,,", 3, "distance_mm", r"expected a finite number, got 'abc'"),
    ("1,2.5.1,pose,,,,,,,,,", 3, "q2", r"expected a finite number, got '2.5.1'"),
])
def test_each_refusal_names_file_line_and_column(tmp_path, row, line, column, pattern):
    path = write(tmp_path, HEADER + "\n1,2,pose,,,,,,,,,\n" + row + "\n")
    refused(path, line, column, pattern)


def test_duplicate_ids_and_dangling_references(tmp_path):
    dup = write(tmp_path, "q1,measurement,id\n1,pose,a\n2,pose,b\n3,pose,a\n")
    refused(dup, 4, "id", r"an id of its own \(line 2 has it already.*got 'a'")
    numbered = write(tmp_path, "q1,measurement,id\n1,pose,2\n2,pose,\n", "n.csv")      # row 2's default id is "2"
    refused(numbered, 3, "id", r"an id of its own \(line 2 has it already.*got '2'")
    cell = {"planes": {}, "points": {"pivot": {}}, "noise": {}}
    dangling = write(tmp_path, "q1,measurement,id,distance_mm,to\n1,pose,a,,\n2,distance,,10,b\n3,distance,,10,pivot\n",
                     "d.csv")
    refused(dangling, 3, "to", r"the id of a row of the file or a point of the cell \(pivot\), got 'b'",
            cell=cell)
    assert read_measurement_rows(dangling).texts["to"] == ("", "b", "pivot")       # without cell: not checked
    own = write(tmp_path, "q1,measurement,id,distance_mm,to\n1,distance,a,10,a\n", "own.csv")
    refused(own, 2, "to", r"another row's id \(a distance from a row to itself\), got 'a'")
    clash = write(tmp_path, "q1,measurement,id\n1,pose,pivot\n", "clash.csv")
    refused(clash, 2, "id", r"not also a point of the cell", cell=cell)


def test_missing_column_for_a_row_and_bad_header(tmp_path):
    with pytest.raises(DataError, match=r"h\.csv:2: the header is not followed by any data row"):
        read_measurement_rows(write(tmp_path, "# nothing yet\nq1,measurement\n", "h.csv"))
    with pytest.raises(DataError, match=r"e\.csv: empty file: expected a header line such as"):
        read_measurement_rows(write(tmp_path, "# nothing\n", "e.csv"))
    path = write(tmp_path, "q1,measurement\n1,plane\n")
    refused(path, 2, "feature", r"the file has no column 'feature'")
    with pytest.raises(DataError, match=r"g\.csv:1: column 'q3': joint columns must run q1\.\.qN without gaps"):
        read_measurement_rows(write(tmp_path, "q1,q3,measurement\n1,2,pose\n", "g.csv"))
    with pytest.raises(DataError, match=r"s\.csv:2: expected 3 cells as in the header, got 2"):
        read_measurement_rows(write(tmp_path, "q1,q2,measurement\n1,pose\n", "s.csv"))
    with pytest.raises(DataError, match=r"r\.csv: the file has 2 joint columns \(q1\.\.q2\) but robot "
                                        r"'universal_robots_ur10' has 6 joints"):
        read_measurement_rows(write(tmp_path, "q1,q2,measurement\n1,2,pose\n", "r.csv"), "universal_robots_ur10")
    with pytest.raises(DataError, match=r"p\.csv:3: column 'payload_kg': expected a payload mass in \[0, 100000\] "
                                        r"kg, got '-1'"):
        read_measurement_rows(write(tmp_path, "q1,measurement,payload_kg\n1,pose,2\n1,pose,-1\n", "p.csv"))


def test_foreign_units_are_converted(tmp_path):
    path = write(tmp_path, "q1;measurement;distance_mm;to;id\n0,5;pose;;;a\n1,0;distance;0,25;a;\n")
    fmt = MeasurementFormat(delimiter=";", decimal=",", joint_unit="rad", length_unit="m")
    t = read_measurement_rows(path, fmt=fmt)
    np.testing.assert_allclose(t.q_deg[:, 0], np.degrees([0.5, 1.0]))
    assert t.numbers["distance_mm"][1] == 250.0


def test_write_then_read_gives_the_same_table(tmp_path):
    table = MeasurementRows(
        q_deg=np.array([[10.5, -20.25], [0.125, 1.0], [3.0, 4.0]]), types=("plane", "pose", "distance"),
        ids=("t1", "p,1", "d"), lines=(0, 0, 0), source="mem",
        numbers={"flush": np.array([1.0, np.nan, np.nan]), "distance_mm": np.array([np.nan, np.nan, 812.123456])},
        texts={"feature": ("top", "", ""), "to": ("", "", "p,1")}, name="x")
    path = tmp_path / "x.csv"
    write_measurement_rows(table, path, comment="two\nlines")
    text = path.read_text()
    assert text.startswith("# two\n# lines\nq1,q2,measurement,id,feature,flush,distance_mm,to\n")
    back = read_measurement_rows(path)
    np.testing.assert_array_equal(back.q_deg, table.q_deg)
    assert back.types == table.types and back.ids == table.ids and back.texts == table.texts
    np.testing.assert_array_equal(back.numbers["flush"], table.numbers["flush"])
    np.testing.assert_array_equal(back.numbers["distance_mm"], table.numbers["distance_mm"])
    assert back.lines == (4, 5, 6)
    write_measurement_rows(back, tmp_path / "again.csv", comment="two\nlines")
    assert (tmp_path / "again.csv").read_text() == text


FEATURES = """\
planes:
  top:  {normal: [0, 0, 2], offset_mm: 800}
  step: {parallel_to: top, spacing_mm: -200}
  side: {}
points:
  nest_a: {}
  nest_b: {distance_to: nest_a, distance_mm: 1000}
  sphere: {known_mm: [900, 0, 300]}
noise: {plane: 0.01, fixed: 0.02}
"""


def test_features_are_read_with_unit_normals(tmp_path):
    f = read_cell(write(tmp_path, FEATURES, "cell.yaml"))
    assert f == {"planes": {"top": {"normal": [0.0, 0.0, 1.0], "offset_mm": 800.0},
                            "step": {"parallel_to": "top", "spacing_mm": -200.0}, "side": {}},
                 "points": {"nest_a": {}, "nest_b": {"distance_to": "nest_a", "distance_mm": 1000.0},
                            "sphere": {"known_mm": [900.0, 0.0, 300.0]}},
                 "cameras": {}, "boards": {}, "noise": {"plane": 0.01, "fixed": 0.02}}
    assert read_cell(write(tmp_path, "", "empty.yaml")) == {"planes": {}, "points": {}, "cameras": {}, "boards": {},
                                                            "noise": {}}


@pytest.mark.parametrize("old, new, pattern", [
    ("side: {}", "side: {colour: red}", r"planes\.side\.colour \(line 4\): unknown key"),
    ("[0, 0, 2]", "[0, 0, 0]", r"planes\.top\.normal \(line 2\): must be a direction \(a non-zero vector\); got "
                               r"\[0\.0, 0\.0, 0\.0\]"),
    ("[0, 0, 2]", "[0, 0]", r"planes\.top\.normal \(line 2\): must be a list of three finite numbers"),
    ("offset_mm: 800", "offset_mm: .nan", r"planes\.top\.offset_mm \(line 2\): must be a finite number; got nan"),
    ("parallel_to: top", "parallel_to: step", r"planes\.step\.parallel_to \(line 3\): must name another feature "
                                              r"than 'step' itself"),
    ("parallel_to: top", "parallel_to: floor", r"planes\.step\.parallel_to \(line 3\): must name a feature of "
                                               r"planes \(top, step, side\); got 'floor'"),
    ("nest_a: {}", "nest_a: {distance_to: nest_b, distance_mm: 5}",
     r"points\.nest_a\.distance_to \(line 6\): closes a cycle: nest_a -> nest_b -> nest_a"),
    ("distance_mm: 1000", "distance_mm: 0", r"points\.nest_b\.distance_mm \(line 7\): must be a finite number > 0"),
    ("fixed: 0.02", "laser: 0.02", r"noise\.laser \(line 9\): unknown type; expected one of point, plane"),
    ("noise:", "noise_level:", r"noise_level \(line 9\): unknown key; did you mean 'noise'"),
    ("side: {}", "'a b': {}", r"planes\.a b \(line 4\): a feature's name is letters"),
])
def test_feature_refusals_name_path_and_line(tmp_path, old, new, pattern):
    path = write(tmp_path, FEATURES.replace(old, new), "cell.yaml")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: .*{pattern}"):
        read_cell(path)


def test_the_old_name_noise_mm_is_read_for_one_release_with_a_warning(tmp_path, caplog):
    f = read_cell(write(tmp_path, FEATURES.replace("noise:", "noise_mm:"), "cell.yaml"))
    assert f["noise"] == {"plane": 0.01, "fixed": 0.02}
    assert any("noise_mm (line 9): the old name of 'noise'" in r.getMessage() for r in caplog.records)


def test_the_documented_example_reads(tmp_path):
    from conftest import ROOT

    text = (ROOT / "docs" / "data.md").read_text()
    block = text[text.index("q1,q2,q3,q4,q5,q6,measurement,id"):]
    path = write(tmp_path, block[:block.index("```")], "example.csv")
    cell = {"planes": {"top": {}}, "points": {"nest_a": {}}, "noise": {}}
    t = read_measurement_rows(path, "universal_robots_ur10", cell=cell)
    assert t.types == ("point", "plane", "plane", "fixed", "pose", "pose", "distance", "distance")
    assert t.numbers["flush"][2] == 1 and t.texts["to"][-2:] == ("a", "nest_a")


@pytest.mark.parametrize("old, new, pattern", [
    ("offset_mm: 800", "offset: 800", r"planes\.top\.offset \(line 2\): unknown key beside 'normal' .*did you mean "
                                      r"'offset_mm'\?"),
    ("spacing_mm: -200", "spacing_mm: -200, normal: [0, 0, 1]",
     r"planes\.step\.normal \(line 3\): unknown key beside 'parallel_to' \(that form has parallel_to, spacing_mm; "
     r"one form per feature\)"),
    ("known_mm: [900, 0, 300]", "known: [900, 0, 300]", r"points\.sphere\.known \(line 8\): unknown key; did you "
                                                        r"mean 'known_mm'\?"),
    ("distance_mm: 1000", "distance_mm: 1000, known_mm: [1, 2, 3]",
     r"points\.nest_b\.known_mm \(line 7\): unknown key beside 'distance_to'"),
])
def test_a_key_outside_a_features_form_is_named_before_a_missing_one(tmp_path, old, new, pattern):
    path = write(tmp_path, FEATURES.replace(old, new), "cell.yaml")
    with pytest.raises(ConfigError, match=rf"^{re.escape(str(path))}: {pattern}"):
        read_cell(path)


def test_with_features_a_row_names_a_plane_or_point_of_them(tmp_path):
    path = write(tmp_path, HEADER + "\n" + ROWS)
    refused(path, 4, "feature", r"one of the planes of the cell \(side; an unknown one is listed as NAME: "
                                r"\{\}\), got 'top'", cell={"planes": {"side": {}}, "points": {"nest_a": {}}})
    refused(path, 6, "feature", r"one of the points of the cell \(nest_b; .*got 'nest_a'",
            cell={"planes": {"top": {}}, "points": {"nest_b": {}}})
    t = read_measurement_rows(path, cell={"planes": {"top": {}}, "points": {"nest_a": {}}})
    assert t.texts["feature"][1:4] == ("top", "top", "nest_a")
    assert read_measurement_rows(path).texts["feature"][1] == "top"              # without cell: any name


# ------------------------------------------------------------------ a format maps the types columns too
FOREIGN = {"q1": "Axis 1", "q2": "Axis 2", "measurement": "Type", "id": "Name", "feature": "Feature", "flush": "Flat",
           "distance_mm": "Length", "to": "Ref", "x_meas": "X", "y_meas": "Y", "z_meas": "Z", "set": "Group"}


def _foreign_copy(text: str) -> str:
    """The contract file ``text`` as a touch-probe export would write it: the columns renamed by FOREIGN,
    semicolons, decimal commas, joints in radians and lengths in metres (computed here from the degrees and
    millimetres, not by partcal)."""
    lines = [line for line in text.splitlines() if line and not line.startswith("#")]
    header = lines[0].split(",")
    out = [";".join(FOREIGN[c] for c in header)]
    for line in lines[1:]:
        cells = []
        for column, cell in zip(header, line.split(",")):
            if cell and column in ("q1", "q2"):
                cell = repr(float(cell) * np.pi / 180.0)
            elif cell and column in ("distance_mm", "x_meas", "y_meas", "z_meas"):
                cell = repr(float(cell) / 1000.0)
            cells.append(cell.replace(".", ","))
        out.append(";".join(cells))
    return "\n".join(out) + "\n"


def test_a_foreign_measurements_file_reads_through_a_format_as_the_contract(tmp_path):
    contract = read_measurement_rows(write(tmp_path, HEADER + "\n" + ROWS))
    foreign = write(tmp_path, _foreign_copy(HEADER + "\n" + ROWS), "probe.csv")
    fmt = MeasurementFormat(delimiter=";", decimal=",", columns=FOREIGN, joint_unit="rad", length_unit="m")
    assert has_measurement_column(foreign, fmt) and not has_measurement_column(foreign, MeasurementFormat(delimiter=";"))
    t = read_measurement_rows(foreign, fmt=fmt)
    np.testing.assert_allclose(t.q_deg, contract.q_deg, rtol=1e-12)
    assert t.types == contract.types and t.ids == contract.ids and t.texts == contract.texts
    assert t.numbers.keys() == contract.numbers.keys()
    for column, values in contract.numbers.items():
        np.testing.assert_allclose(t.numbers[column], values, rtol=1e-12, err_msg=column)
    np.testing.assert_allclose(t.numbers["distance_mm"][5:], [812.5, 900.25], rtol=1e-12)   # metres -> mm


def test_messages_about_a_mapped_measurement_types_column_name_it_as_the_file_does(tmp_path):
    fmt = MeasurementFormat(columns={"measurement": "Type", "distance_mm": "Length"})
    path = write(tmp_path, "q1,Type,Length,to\n1,pose,,\n2,lazer,,\n")
    with pytest.raises(DataError, match=r"obs\.csv:3: column 'Type' \(measurement\): expected one of the types point, "):
        read_measurement_rows(path, fmt=fmt)
    path = write(tmp_path, "q1,Type,Length,to,id\n1,pose,,,a\n2,distance,-3,a,\n")
    with pytest.raises(DataError, match=r"obs\.csv:3: column 'Length' \(distance_mm\): expected a distance > 0 mm, "
                                        r"got '-3'"):
        read_measurement_rows(path, fmt=fmt)


def test_a_mapped_column_a_row_needs_missing_from_the_file_is_named_as_both(tmp_path):
    fmt = MeasurementFormat(columns={"measurement": "Type", "feature": "Feature"})
    path = write(tmp_path, "q1,Type,feature\n1,plane,top\n")       # the contract's name does not stand in
    with pytest.raises(DataError, match=r"obs\.csv:2: column 'Feature' \(feature\): expected a value on a plane row, "
                                        r"but the file has no column 'Feature' \(feature\)"):
        read_measurement_rows(path, fmt=fmt)


def test_a_format_serves_a_ballbar_export_without_the_columns_of_other_types(tmp_path):
    """One format maps every column of a probe's exports: a ballbar's file has no Feature column, and needs none."""
    fmt = MeasurementFormat(columns={"measurement": "Type", "feature": "Feature", "distance_mm": "Length", "to": "Ref",
                                     "id": "Name"})
    path = write(tmp_path, "q1,Type,Name,Length,Ref\n1,pose,a,,\n2,distance,,10.5,a\n")
    t = read_measurement_rows(path, fmt=fmt)
    assert t.types == ("pose", "distance") and t.numbers["distance_mm"][1] == 10.5 and t.texts["to"][1] == "a"


def test_one_format_serves_a_runs_point_csvs_and_measurements_files(tmp_path):
    """Each reader looks for the mapped columns it reads: the point CSV has no ``Type``, the measurements file no
    nominal columns."""
    fmt = MeasurementFormat(columns={"measurement": "Type", "feature": "Feature", "x_nom": "Xn", "x_meas": "X"})
    points = write(tmp_path, "q1,Xn,y_nom,z_nom,X,y_meas,z_meas\n1,10,20,30,11,22,33\n", "points.csv")
    measurements = write(tmp_path, "q1,Type,Feature,X,y_meas,z_meas\n1,plane,top,,,\n2,point,,4,5,6\n", "types.csv")
    assert not has_measurement_column(points, fmt) and has_measurement_column(measurements, fmt)
    m = read_measurements(points, fmt=fmt)
    assert m.nominal_mm.tolist() == [[10, 20, 30]] and m.measured_mm.tolist() == [[11, 22, 33]]
    t = read_measurement_rows(measurements, fmt=fmt)
    assert t.types == ("plane", "point") and t.texts["feature"] == ("top", "")
    assert t.numbers["x_meas"][1] == 4 and "x_nom" not in t.numbers


@pytest.mark.parametrize("columns, match", [
    ({"featur": "Feature"}, r"The 'columns' entry 'featur' of MeasurementFormat must be a contract column .* or "
                            r"a measurement-type column \(measurement, id, target, feature, flush, distance_mm, to, image, camera, board, "
                            r"point, u_px, v_px\)\. Got "
                            r"'featur' \(did you mean 'feature'\?\) instead"),
    ({"distance": "Length"}, r"Got 'distance' \(did you mean 'distance_mm'\?\) instead"),
    ({"Measurement": "Type"}, r"Got 'Measurement' \(did you mean 'measurement'\?\) instead"),
    ({"feature": "to"}, r"The 'columns' entry 'feature' of MeasurementFormat must be a file column that holds no "
                        r"other contract column\. Got 'to' \(the contract column to is not mapped, so it is read "
                        r"under its own name: map to too\) instead"),
])
def test_a_bad_measurement_types_key_of_a_format_is_refused_with_a_hint(columns, match):
    with pytest.raises(ConfigError, match=match):
        MeasurementFormat(columns=columns)


def test_a_point_format_may_map_a_column_named_like_a_measurement_types_column(tmp_path):
    """A format that maps no types column is a point format: a file column ``id`` holding ``set`` is fine."""
    fmt = MeasurementFormat(columns={"set": "id"})
    m = read_measurements(write(tmp_path, "q1,x_nom,y_nom,z_nom,x_meas,y_meas,z_meas,id\n1,1,2,3,1,2,3,run7\n",
                                "p.csv"), fmt=fmt)
    assert m.labels == ("run7",)


def test_a_format_names_the_files_measurement_type_values(tmp_path):
    fmt = MeasurementFormat(columns={"measurement": "Type"}, measurements={"Plane": "plane", "Sphere": "fixed", "Lazer": "lazer"})
    path = write(tmp_path, "q1,Type,feature\n1,Plane,top\n2,Sphere,nest\n3,pose,\n")
    t = read_measurement_rows(path, fmt=fmt)
    assert t.types == ("plane", "fixed", "pose")          # an unmapped value is read as written
    assert t.of("fixed").tolist() == [1]
    with pytest.raises(DataError, match=r"obs\.csv:2: column 'Type' \(measurement\): expected one of the types point, plane, "
                                        r"fixed, distance, camera, pose \(the format's types name it 'lazer'\), got 'Lazer'$"):
        read_measurement_rows(write(tmp_path, "q1,Type\n1,Lazer\n"), fmt=fmt)


def test_a_point_row_without_the_mapped_measured_columns_names_them(tmp_path):
    """A measurements file need not have the run's mapped ``x_meas``.. (a ballbar file has no point rows), but a point row
    then is refused naming the mapped column."""
    fmt = MeasurementFormat(columns={"x_meas": "X", "y_meas": "Y", "z_meas": "Z", "set": "Group"})
    assert read_measurement_rows(write(tmp_path, "q1,measurement\n1,pose\n"), fmt=fmt).types == ("pose",)
    with pytest.raises(DataError, match=r"obs\.csv:3: column 'X' \(x_meas\): expected a value on a point row, but "
                                        r"the file has no column 'X' \(x_meas\) \(point rows read x_meas, "):
        read_measurement_rows(write(tmp_path, "q1,measurement\n1,pose\n2,point\n"), fmt=fmt)


def test_a_mapped_target_column_is_read_as_text_even_when_its_names_are_digits(tmp_path):
    fmt = MeasurementFormat(columns={"target": "Reflector"})
    t = read_measurement_rows(write(tmp_path, "q1,measurement,x_meas,y_meas,z_meas,Reflector\n1,point,1,2,3,2\n"
                                          "2,point,4,5,6,\n"), fmt=fmt)
    assert t.texts["target"] == ("2", "") and "Reflector" not in t.texts and "target" not in t.numbers
