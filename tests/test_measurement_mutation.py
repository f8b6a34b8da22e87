"""The road every measurement type shares (partcal/calibration/measurement.py), where a cosmic-ray run showed no test
held it: the rows' own checks (shapes, lengths, a missing column or value named), and what a type gets from the base
class when it declares nothing (its noise, whether the cell stated it, the spread it states, its cell section)."""

import numpy as np
import pytest

from partcal.calibration.measurement import Column, MeasurementRows, MeasurementType, Residuals, largest_turn_deg
from partcal.errors import ConfigError, DataError


def _rows(q, types=None, numbers=None, texts=None, ids=None, lines=None):
    q = np.asarray(q, dtype=float)
    n = len(q) if q.ndim else 0
    return MeasurementRows(q, types if types is not None else ["probe"] * n,
                           ids if ids is not None else [str(i + 1) for i in range(n)],
                           lines if lines is not None else list(range(2, n + 2)), "m.csv", numbers or {}, texts or {})


@pytest.mark.parametrize("q", [np.zeros(6), np.zeros((0, 6)), np.zeros((2, 3, 6)), [[0.0, np.nan]]])
def test_joints_that_are_not_a_finite_table_of_rows_are_refused(q):
    """One pose as a flat list, no pose, a 3-D array, a NaN: each refused, naming the shape expected."""
    with pytest.raises(DataError, match=r"^Expected q_deg with shape \(n, N\), n >= 1, finite degrees, got shape"):
        _rows(q, types=["probe"], ids=["1"], lines=[2])


@pytest.mark.parametrize("field", ["types", "ids", "lines", "feature"])
def test_every_per_row_field_must_have_one_entry_per_row(field):
    """Three rows of joints and a field of two entries: refused naming the field and both counts."""
    given = {"types": ["probe"] * 3, "ids": ["1", "2", "3"], "lines": [2, 3, 4], "texts": {"feature": ("a", "b", "c")}}
    if field == "feature":
        given["texts"] = {"feature": ("a", "b")}
    else:
        given[field] = given[field][:2]
    with pytest.raises(DataError, match=rf"^Expected {field} with 3 entries \(one per row of q_deg\), got 2$"):
        _rows(np.zeros((3, 6)), given["types"], None, given["texts"], given["ids"], given["lines"])


def test_rows_given_as_lists_are_kept_as_tuples():
    """Lists for the types, ids, lines and a text column come back as tuples (the rows are frozen and compare as
    the tuples a file gives)."""
    rows = _rows(np.zeros((2, 6)), ["probe", "probe"], texts={"feature": ["a", "b"]}, ids=["x", "y"], lines=[5, 6])
    assert rows.types == ("probe", "probe") and rows.ids == ("x", "y") and rows.lines == (5, 6)
    assert rows.texts == {"feature": ("a", "b")}


def test_a_missing_column_or_value_is_named_with_the_first_row_that_lacks_it():
    """A column the file lacks: named with the rows' type (one row asked for); a value missing on rows 2 and 3
    (lines 3 and 4): the first is named."""
    rows = _rows(np.zeros((3, 6)), ["probe", "gauge", "gauge"], numbers={"h": np.array([1.0, np.nan, np.nan])},
                 texts={"name": ("a", "", "")})
    with pytest.raises(DataError, match=r"^m.csv: the gauge rows need a column 'reading'; the file has none"):
        rows.number("reading", np.array([1]))
    with pytest.raises(DataError, match=r"^m.csv: the gauge rows need a column 'gauge'; the file has none"):
        rows.text("gauge", np.array([1]))
    with pytest.raises(DataError, match=r"^m.csv:3: column 'h': a gauge row needs a number here, got none"):
        rows.number("h", np.array([0, 1, 2]))
    with pytest.raises(DataError, match=r"^m.csv:4: column 'h': a gauge row needs a number here, got none"):
        rows.number("h", np.array([0, 2]))
    with pytest.raises(DataError, match=r"^m.csv:3: column 'name': a gauge row needs a name here, got none"):
        rows.text("name", np.array([0, 1, 2]))


class Bare(MeasurementType):
    """A type that declares its name and columns alone."""

    name = "bare"
    columns = {"h": Column("mm", required=True)}

    def residuals(self, positions, rotations, u):
        return Residuals(positions[self.index, 2] - self.rows.number("h", self.index), self.index.copy(),
                         np.tile([0.0, 0.0, 1.0], (self.index.size, 1)), np.zeros((self.index.size, u.size)))


class Named(MeasurementType):
    """A type that names the columns it reads and declares none."""

    name = "named"
    reads = ("a", "b")


class Both(MeasurementType):
    """A type that declares columns and reads a subset of them."""

    name = "both"
    columns = {"a": Column(), "b": Column()}
    reads = ("a",)


def test_what_a_type_that_declares_nothing_else_gets_from_the_road():
    """Its noise 0.01 unless the cell states one (then stated, and the spread its rows state); it reads its columns;
    it needs no orientation, fixes no frame, holds nothing with the tool, stands for nothing, moves nothing with the
    cell and describes itself by its row count."""
    rows = _rows(np.zeros((3, 6)), ["bare", "probe", "bare"], numbers={"h": np.array([1.0, 2.0, 3.0])})
    plain = Bare.build(rows, {})
    assert plain.noise == 0.01 and not plain.noise_stated and plain.stated_spread() is None
    stated = Bare.build(rows, {"noise": {"bare": 0.05}})
    assert stated.noise == 0.05 and stated.noise_stated and stated.stated_spread() == 0.05
    assert Bare.build(_rows(np.zeros((1, 6)), ["probe"]), {}) is None
    assert Bare.reads == ("h",) and Named.columns == {"a": Column(), "b": Column()} and Both.reads == ("a",)
    assert not Bare.needs_orientation and not Bare.fixes_frame and not plain.needs_orientation
    assert not plain.follows_tool("tool.x") and plain.stands_for(["base.x", "tool.x"]) == set()
    assert plain.unknowns(np.zeros((3, 3)), np.tile(np.eye(3), (3, 1, 1)))[0] == []
    assert list(plain.moved(np.array([1.0, 2.0]), np.ones(3), np.ones(3))) == [0.0, 0.0]
    assert plain.describe() == "2 bare rows" and plain.notes() == [] and Bare.files({}, [], []) == {}
    np.testing.assert_array_equal(plain.relative_weights(plain.residuals(np.zeros((3, 3)), None, np.zeros(0))), [1, 1])


def test_a_types_default_cell_section_reads_names_with_nothing_known(tmp_path):
    """A section of names, each ``{}``: read as such; a key inside one is refused; a simulated cell knows nothing of
    the true entries; a further section reads the same way."""
    from partcal._yamlio import Section, load_yaml

    def load_yaml_section(file):
        data, lines = load_yaml(file)
        return Section(data, "", lines, str(file))
    path = tmp_path / "cell.yaml"
    path.write_text("g1: {}\ng2: {}\n")
    sec = load_yaml_section(path)
    assert Bare.read_section(sec) == {"g1": {}, "g2": {}}
    assert Bare.read_extra_section("more", load_yaml_section(path)) == {"g1": {}, "g2": {}}
    assert Bare.given_section({"g1": {"zero": 1.0}}, None) == {"g1": {}}
    assert Bare.given_extra_section("more", {"g2": {"zero": 1.0}}, None) == {"g2": {}}
    path.write_text("g1: {zero: 2}\n")
    with pytest.raises(ConfigError, match=r"cell.yaml: g1.zero \(line 1\): unknown key"):
        Bare.read_section(load_yaml_section(path))


def test_the_largest_turn_is_read_against_the_first_rotation_and_its_rounding_is_clipped():
    """Rotations 0, 30 and 10 degrees about z: 30 (the first against itself is no turn); rotations whose trace
    rounds beyond its range (above 3, below -1) read 0 and 180 degrees, not NaN."""
    def about_z(deg):
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert largest_turn_deg(np.array([about_z(0), about_z(30), about_z(10)])) == pytest.approx(30.0)
    assert largest_turn_deg(np.array([np.eye(3), np.eye(3) * (1 + 1e-15)])) == 0.0
    assert largest_turn_deg(np.array([about_z(0)])) == 0.0
    assert largest_turn_deg(np.array([np.eye(3), about_z(180) * (1 + 1e-15)])) == pytest.approx(180.0)


@pytest.mark.parametrize("count", [2, 4])
def test_a_field_or_number_column_of_another_length_than_the_rows_is_refused(count):
    """Three rows of joints, a text column or a number column of two or four entries: refused with both counts."""
    with pytest.raises(DataError, match=rf"^Expected feature with 3 entries \(one per row of q_deg\), got {count}$"):
        _rows(np.zeros((3, 6)), texts={"feature": ("a",) * count})
    with pytest.raises(DataError, match=rf"^Expected numbers\['h'\] with shape \(3,\), got \({count},\)$"):
        _rows(np.zeros((3, 6)), numbers={"h": np.zeros(count)})


def test_rows_residuals_and_columns_are_frozen_and_rows_compare_by_identity():
    """Rows, residuals and column declarations cannot be changed once made; rows (holding arrays) compare and hash
    by identity, a column declaration by its fields."""
    import dataclasses
    rows = _rows(np.zeros((2, 6)))
    residuals = Residuals(np.zeros(2), np.arange(2), np.zeros((2, 3)), np.zeros((2, 0)))
    for value, field in ((rows, "types"), (residuals, "values"), (Column(), "unit")):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(value, field, None)
    assert rows != rows.take([0, 1]) and len({rows, rows.take([0, 1])}) == 2 and {residuals: 1}[residuals] == 1
    assert Column("mm") == Column("mm") and len({Column("mm"), Column("mm")}) == 1


def test_a_type_with_no_unknowns_starts_none():
    plain = Bare.build(_rows(np.zeros((2, 6)), ["bare"] * 2, numbers={"h": np.ones(2)}), {})
    names, start = plain.unknowns(np.zeros((2, 3)), np.tile(np.eye(3), (2, 1, 1)))
    assert names == [] and start.shape == (0,)


def test_a_type_built_on_another_keeps_its_columns():
    """A subclass that declares neither columns nor reads reads its parent's columns, units and checks kept."""
    class Deeper(Bare):
        name = "deeper"
    assert Deeper.columns is Bare.columns and Deeper.columns["h"] == Column("mm", required=True)
    assert Deeper.reads == ("h",)


@pytest.mark.parametrize("name, taken", [("", True), ("".join(["po", "se"]), True), ("point", True), ("zzz", False)])
def test_a_type_is_added_only_under_a_name_of_its_own(name, taken):
    """An empty name, the rows' end type 'pose' (a string of its own) and a built-in type's name are refused; a new
    name (sorting after 'pose') is added, then taken away again."""
    from partcal.calibration.registry import MEASUREMENT_TYPES, add_measurement_type
    kind = type("Added", (Bare,), {"name": name})
    if taken:
        with pytest.raises(ValueError, match="a measurement type needs a name of its own"):
            add_measurement_type(kind)
        return
    try:
        assert add_measurement_type(kind) is kind and MEASUREMENT_TYPES["zzz"] is kind
    finally:
        MEASUREMENT_TYPES.pop("zzz", None)


def test_the_rows_folds_draw_from_measure_and_keep_the_ends_their_distances_name():
    """Of rows pose, a type named after 'pose' ('zzz'), a distance to the pose and a point, the three that measure
    are drawn into folds; a subset of the distance alone brings its end along as a pose row; no residual scores
    nothing."""
    from partcal.calibration.cv import cv_score, measuring, subset
    rows = _rows(np.zeros((4, 6)), ["pose", "zzz", "distance", "point"], texts={"to": ("", "", "1", "")})
    assert measuring(rows).tolist() == [1, 2, 3]
    part = subset(rows, np.array([2]))
    assert part.ids == ("1", "3") and part.types == ("pose", "distance")
    chained = _rows(np.zeros((4, 6)), ["pose", "zzz", "distance", "distance"], texts={"to": ("", "", "1", "3")})
    both = subset(chained, np.array([2, 3]))          # row 3 names row 2, which measures: it stays a distance
    assert both.ids == ("1", "3", "4") and both.types == ("pose", "distance", "distance")
    assert subset(rows, np.array([3])).ids == ("4",)
    assert all(np.isnan(cv_score({}, {}, {})))


def test_rows_that_measure_no_length_leave_the_scale_free():
    """Touches of two unknown planes: the scale is free (the first note says so, before the plane type's own); a
    tracker's points in the base frame fix it."""
    from test_measurement_types import ROBOT, _rows as rows_of, _touches, _true_robot

    from partcal.calibration.cv import scale_free
    from partcal.calibration.stacked import observability
    rng = np.random.default_rng(11)
    q, names = _touches(_true_robot(rng), rng, {"top": ([0, 0, 1], 300.0), "side": ([1, 0, 0], 700.0)}, 20, 0.01)
    rows = rows_of(q, ["plane"] * len(q), texts={"feature": tuple(names)})
    notes = observability(ROBOT, rows, {})[0]
    assert len(notes) > 1 and scale_free(ROBOT, rows, {})
    tips = ROBOT.positions(q)
    points = rows_of(q, ["point"] * len(q), {"x_meas": tips[:, 0], "y_meas": tips[:, 1], "z_meas": tips[:, 2]})
    assert not scale_free(ROBOT, points, {})
