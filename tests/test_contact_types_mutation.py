"""Refusals and starts of the fixed-point and distance types (partcal/calibration/fixed_points.py, distances.py)
that a cosmic-ray run showed no test held: a point visited from one orientation only, or once, or a visit far from
its point's others, refused naming the point and its first row; a distance that is no length refused naming the
first bad row; the unit check's factor on long distances and its blindness to pivots; a pivot's start (the sphere
through its tips) against the centre the tips were put around."""

import numpy as np
import pytest
from conftest import own_string
from scipy.spatial.transform import Rotation

from partcal import load_robot
from partcal.calibration.measurement import MeasurementRows
from partcal.calibration.registry import MEASUREMENT_TYPES
from partcal.calibration.stacked import identify_measurements
from partcal.data.measurement_rows import read_measurement_rows
from partcal.errors import DataError

ROBOT = load_robot("universal_robots_ur10")


def _rows(q, types, numbers=None, texts=None):
    n = len(q)
    return MeasurementRows(np.asarray(q, dtype=float), tuple(types), tuple(str(i + 1) for i in range(n)),
                           tuple(range(2, n + 2)), "test.csv", numbers or {}, texts or {})


def _visits(place, turns_deg):
    """Joints putting the nominal UR10's tool tip at ``place`` (mm), pointing down and turned about x by each of
    ``turns_deg``."""
    poses = np.tile(np.eye(4), (len(turns_deg), 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("x", 180.0 + np.asarray(turns_deg, dtype=float)[:, None], degrees=True).as_matrix()
    poses[:, :3, 3] = place
    rng = np.random.default_rng(5)
    q = np.full((len(turns_deg), 6), np.nan)
    for _ in range(40):
        seed = rng.uniform([-90, -150, -140, -180, -150, -180], [90, -30, 140, 180, 150, 180])
        ik = ROBOT.inverse_pose(poses, np.tile(seed, (len(turns_deg), 1)))
        todo = np.isnan(q[:, 0]) & ik.success
        q[todo] = ik.q_deg[todo]
        if np.isfinite(q).all():
            return q
    raise AssertionError("no joints for the visits")


TURNS = [0.0, 10.0, 20.0, -10.0, -20.0, 5.0]


def test_a_point_visited_from_one_orientation_is_refused_naming_it_and_its_first_row():
    """Point a from six orientations, point b twice from one (rows 7 and 8, lines 8 and 9): refused naming b and
    line 8; the same with b's two visits turned 20 degrees apart is identified from."""
    a, b = _visits([800.0, 0.0, 400.0], TURNS), _visits([700.0, 200.0, 400.0], [0.0, 0.0])
    rows = _rows(np.vstack([a, b]), ["fixed"] * 8, texts={"feature": ("a",) * 6 + ("b",) * 2})
    with pytest.raises(DataError, match=r"^test.csv:8: column 'feature': fixed point 'b' is reached from one "
                                        r"orientation of the tool only \(2 visits within 1 degree\)"):
        identify_measurements(ROBOT, rows, {})
    turned = _rows(np.vstack([a, _visits([700.0, 200.0, 400.0], [0.0, 20.0])]), ["fixed"] * 8, texts=rows.texts)
    table, _ = identify_measurements(ROBOT, turned, {})
    assert table.target_rms_mm["fixed"] < 1e-6


def test_an_unknown_point_reached_once_is_refused_whatever_its_name_sorts_as():
    """a once (line 2), b from six orientations: a is refused (a point of the name sorting first, as the bug that
    counted every name >= 'a' as a's would not see)."""
    rows = _rows(np.vstack([_visits([800.0, 0.0, 400.0], [0.0]), _visits([700.0, 200.0, 400.0], TURNS)]),
                 ["fixed"] * 7, texts={"feature": ("a",) + ("b",) * 6})
    with pytest.raises(DataError, match=r"^test.csv:2: column 'feature': fixed point 'a' is reached once"):
        identify_measurements(ROBOT, rows, {})


def test_a_visit_far_from_its_points_other_visits_is_refused_naming_it():
    """The fourth visit commanded 50 mm away (line 5): refused, saying how far (the median of the visits is the
    point, so 50 mm is what the message reads)."""
    q = _visits([800.0, 0.0, 400.0], TURNS)
    q[3] = _visits([850.0, 0.0, 400.0], [TURNS[3]])[0]
    rows = _rows(q, ["fixed"] * 6, texts={"feature": ("a",) * 6})
    with pytest.raises(DataError, match=r"^test.csv:5: column 'feature': the nominal robot puts this visit 50.0 mm "
                                        r"from point 'a'"):
        identify_measurements(ROBOT, rows, {})


def _pivot_rows(measured, far_mm):
    """Distance rows to an unknown pivot ``p`` and, last, one pose row: the type built on them."""
    n = len(measured)
    rows = _rows(np.zeros((n + 1, 6)), ["distance"] * n + ["pose"],
                 {"distance_mm": np.r_[measured, np.nan]}, {"to": ("p",) * n + ("",)})
    return MEASUREMENT_TYPES["distance"](rows, np.arange(n), {"points": {"p": {}}}, 0.01)


def test_a_pivots_start_is_the_sphere_through_its_tips_and_the_unit_check_leaves_pivots_alone():
    """Tips at 120 to 180 mm around a centre (eight of them, not on one plane): the start is the centre to 1e-9 mm
    (the tips were put around it). A pose row 10 m away, last in the table: the unit check judges tip-to-tip
    distances only, so a pivot's 150 mm against it (a factor of 67) is no unit error."""
    rng = np.random.default_rng(8)
    centre = np.array([600.0, 100.0, 300.0])
    directions = rng.normal(size=(8, 3))
    radii = np.linspace(120.0, 180.0, 8)                      # a pivot's distances differ row by row
    tips = centre + radii[:, None] * directions / np.linalg.norm(directions, axis=1)[:, None]
    positions = np.vstack([tips, [10600.0, 100.0, 300.0]])
    names, start = _pivot_rows(radii, 10000.0).unknowns(positions, np.tile(np.eye(3), (9, 1, 1)))
    assert len(names) == 3 and np.allclose(start, centre, atol=1e-9)


def test_a_distance_that_is_no_length_is_refused_naming_the_first_such_row():
    """Distances -5 (row 3, line 4) and 0 (row 5, line 6): the first is named, with its value."""
    rows = _rows(np.zeros((6, 6)), ["pose"] + ["distance"] * 5,
                 {"distance_mm": np.array([np.nan, 100.0, -5.0, 120.0, 0.0, 90.0])}, {"to": ("",) + ("1",) * 5})
    with pytest.raises(DataError, match=r"^test.csv:4: column 'distance_mm': -5 is not a distance; expected a length "
                                        r"above 0 mm"):
        MEASUREMENT_TYPES["distance"](rows, np.arange(1, 6), {}, 0.01)


@pytest.mark.parametrize("nominal, factor, refused", [
    (1000.0, 1 / 20, False), (1000.0, 1 / 40, True), (1000.0, 20.0, False), (1000.0, 40.0, True),
    (1000.0, 29.5, False), (1000.0, 30.5, True), (1000.0, 1 / 29.5, False), (1000.0, 1 / 30.5, True),
    (300.5, 40.0, True), (299.5, 40.0, False)])
def test_a_long_distance_is_refused_only_beyond_thirty_times_its_nominal(nominal, factor, refused):
    """Two tips ``nominal`` mm apart at the nominal robot: 20 times shorter or longer is data (a tool can move a
    distance a lot; only a factor no tool makes is a unit), 40 times is refused naming the row; the edges, half a
    step either side: a factor of 30 (either way) on a nominal distance of 300 mm or more."""
    positions = np.array([[0.0, 0.0, 0.0], [nominal, 0.0, 0.0]])
    rows = _rows(np.zeros((2, 6)), ["pose", "distance"], {"distance_mm": np.array([np.nan, nominal * factor])},
                 {"to": ("", "1")})
    distances = MEASUREMENT_TYPES["distance"](rows, np.array([1]), {}, 0.01)
    if refused:
        with pytest.raises(DataError, match=r"^test.csv:3: column 'distance_mm': .* \(metres\?\)"):
            distances.unknowns(positions, np.tile(np.eye(3), (2, 1, 1)))
    else:
        names, start = distances.unknowns(positions, np.tile(np.eye(3), (2, 1, 1)))
        assert names == [] and len(start) == 0


def test_the_point_checks_read_each_points_own_visits_whatever_the_names_sort_as():
    """The same refusals with the names the other way round (a point's visits are its own, not those of every name
    sorting before or after it): a reached from one orientation twice (line 2) beside b from six; b reached once
    (line 8) beside a from six."""
    one = _rows(np.vstack([_visits([700.0, 200.0, 400.0], [0.0, 0.0]), _visits([800.0, 0.0, 400.0], TURNS)]),
                ["fixed"] * 8, texts={"feature": ("a",) * 2 + ("b",) * 6})
    with pytest.raises(DataError, match=r"^test.csv:2: column 'feature': fixed point 'a' is reached from one"):
        identify_measurements(ROBOT, one, {})
    once = _rows(np.vstack([_visits([800.0, 0.0, 400.0], TURNS), _visits([700.0, 200.0, 400.0], [0.0])]),
                 ["fixed"] * 7, texts={"feature": ("a",) * 6 + ("b",)})
    with pytest.raises(DataError, match=r"^test.csv:8: column 'feature': fixed point 'b' is reached once"):
        identify_measurements(ROBOT, once, {})


def test_a_known_point_visited_once_and_visits_turned_a_degree_and_a_half_are_taken():
    """A point known in the base frame needs one visit (its place is no unknown); two visits of an unknown point
    turned 1.5 degrees apart are more than the 1 degree the rule asks."""
    a, k = _visits([800.0, 0.0, 400.0], TURNS), _visits([700.0, 200.0, 400.0], [0.0])
    rows = _rows(np.vstack([a, k]), ["fixed"] * 7, texts={"feature": ("a",) * 6 + ("k",)})
    table, _ = identify_measurements(ROBOT, rows, {"points": {"k": {"known_mm": [700.0, 200.0, 400.0]}}})
    assert table.target_rms_mm["fixed"] < 1e-6
    rows = _rows(np.vstack([a, _visits([700.0, 200.0, 400.0], [0.0, 1.5])]), ["fixed"] * 8,
                 texts={"feature": ("a",) * 6 + ("b",) * 2})
    table, _ = identify_measurements(ROBOT, rows, {})
    assert table.target_rms_mm["fixed"] < 1e-6


def test_a_point_tied_by_distance_to_alone_is_refused_asking_for_its_distance(tmp_path):
    from partcal.data.measurement_rows import read_cell
    from partcal.errors import ConfigError
    path = tmp_path / "cell.yaml"
    path.write_text("points:\n  nest_a: {}\n  nest_b: {distance_to: nest_a}\n")
    with pytest.raises(ConfigError, match=r"points.nest_b \(line 3\): missing required key 'distance_mm'"):
        read_cell(path)


def _distance_table():
    """Rows 0-2 poses; rows 3-6 distances: 3 to row 0 (id 1), 4 to row 2 (id 3, a later row than its own would be
    for row 1), 5 to the known pivot k, 6 to the unknown pivot p."""
    return _rows(np.zeros((7, 6)), ["pose"] * 3 + ["distance"] * 4,
                 {"distance_mm": np.array([np.nan] * 3 + [500.0, 700.0, 300.0, 400.0])},
                 {"to": ("",) * 3 + ("1", "3", "k", "p")})


def test_distance_residuals_read_the_other_row_a_known_pivot_or_the_unknown_one_by_hand():
    """Tips put by hand; each residual is |tip - other end| - distance (the other end a row's tip, a known pivot
    from the cell, or the unknown pivot's three values in ``u``), its gradients the unit vector from that end to the
    tip (the unknown pivot's the opposite), and only the tip-to-tip rows name a second row."""
    cell = {"points": {"k": {"known_mm": [0.0, 0.0, 1000.0]}, "p": {}}}
    distances = MEASUREMENT_TYPES["distance"](_distance_table(), np.arange(3, 7), cell, 0.01)
    assert distances.describe() == "4 distances (pivots k, p)"
    tips = np.array([[0.0, 0.0, 0.0], [900.0, 0.0, 0.0], [0.0, 800.0, 0.0],
                     [300.0, 400.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 600.0], [100.0, 200.0, 300.0]])
    u = np.array([100.0, 200.0, 700.0])                        # p: 400 mm above row 6's tip
    res = distances.residuals(tips, np.tile(np.eye(3), (7, 1, 1)), u)
    # row 3 -> row 0: 500 apart (measured 500); row 4 -> row 2: 800 (700); row 5 -> k: 400 (300); row 6 -> p: 400
    np.testing.assert_allclose(res.values, [0.0, 100.0, 100.0, 0.0], atol=1e-12)
    assert res.rows_a.tolist() == [3, 4, 5, 6] and res.rows_b.tolist() == [0, 2, -1, -1]
    directions = np.array([[0.6, 0.8, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    np.testing.assert_allclose(res.grad_a, directions, atol=1e-12)
    np.testing.assert_allclose(res.grad_b, -directions, atol=1e-12)
    np.testing.assert_allclose(res.du, [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 1.0]], atol=1e-12)


def test_a_distance_to_a_later_row_is_taken_and_one_to_its_own_row_refused():
    """Row 2 (id 3) measured to row 3 (id 4, after it) and row 3 to row 0: taken; row 3 to itself is refused
    naming its line."""
    rows = _rows(np.zeros((4, 6)), ["pose", "pose", "distance", "distance"],
                 {"distance_mm": np.array([np.nan, np.nan, 500.0, 500.0])}, {"to": ("", "", "4", "1")})
    assert MEASUREMENT_TYPES["distance"](rows, np.array([2, 3]), {}, 0.01).other.tolist() == [3, 0]
    rows.texts["to"] = ("", "", "1", "4")
    with pytest.raises(DataError, match=r"^test.csv:5: column 'to': the row refers to itself"):
        MEASUREMENT_TYPES["distance"](rows, np.array([2, 3]), {}, 0.01)


def test_a_pivots_start_is_the_tips_mean_where_they_do_not_fix_a_sphere():
    """Three tips, or six on one plane, do not fix a sphere's centre: the start is their mean. Four tips off one plane
    fix it: the start is the centre they were put around."""
    centre = np.array([600.0, 100.0, 300.0])
    on_circle = centre + 150.0 * np.array([[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0, 5, 6)])
    for tips in (on_circle[:3], on_circle):
        positions = np.vstack([tips, [0.0, 0.0, 0.0]])
        _, start = _pivot_rows(np.full(len(tips), 150.0), 0.0).unknowns(positions, np.tile(np.eye(3), (len(tips) + 1, 1, 1)))
        np.testing.assert_allclose(start, tips.mean(axis=0), atol=1e-9)
    tetra = centre + 150.0 * np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [-0.6, -0.64, 0.48]])
    _, start = _pivot_rows(np.full(4, 150.0), 0.0).unknowns(np.vstack([tetra, [0.0, 0, 0]]), np.tile(np.eye(3), (5, 1, 1)))
    np.testing.assert_allclose(start, centre, atol=1e-9)


@pytest.mark.parametrize("value, taken", [(0.0, False), (-0.5, False), (0.5, True)])
def test_a_distance_of_zero_or_below_is_refused_by_the_reader_and_the_type(tmp_path, value, taken):
    """Half a millimetre is a distance; zero and -0.5 are not, refused when the file is read (naming its line) and,
    for rows built in Python, by the type."""
    path = tmp_path / "m.csv"
    path.write_text(f"q1,q2,q3,q4,q5,q6,measurement,distance_mm,to\n0,0,0,0,0,0,pose,,\n0,0,0,0,0,0,distance,{value},1\n")
    rows = _rows(np.zeros((2, 6)), ["pose", "distance"], {"distance_mm": np.array([np.nan, value])}, {"to": ("", "1")})
    if taken:
        assert read_measurement_rows(path).numbers["distance_mm"][1] == value
        assert MEASUREMENT_TYPES["distance"](rows, np.array([1]), {}, 0.01).measured.tolist() == [value]
        return
    with pytest.raises(DataError, match=rf"m.csv:3: column 'distance_mm': expected a distance > 0 mm, got '{value:g}'"):
        read_measurement_rows(path)
    with pytest.raises(DataError, match=rf"^test.csv:3: column 'distance_mm': {value:g} is not a distance"):
        MEASUREMENT_TYPES["distance"](rows, np.array([1]), {}, 0.01)


@pytest.mark.parametrize("distance, to, column", [("", "1", "distance_mm"), ("500", "", "to")])
def test_a_distance_row_without_its_length_or_its_other_end_is_refused_by_the_reader(tmp_path, distance, to, column):
    """Both of a distance's columns are required, whatever the type's declaration is read as: the reader names
    the empty one (not the type later, with a message about a nan length or an empty name)."""
    path = tmp_path / "m.csv"
    path.write_text(f"q1,q2,q3,q4,q5,q6,measurement,distance_mm,to\n0,0,0,0,0,0,pose,,\n"
                    f"0,0,0,0,0,0,distance,{distance},{to}\n")
    with pytest.raises(DataError, match=rf"m.csv:3: column '{column}': expected a value on a distance row"):
        read_measurement_rows(path)


def test_tips_at_one_place_give_no_direction_and_half_a_millimetre_apart_a_unit_one():
    """Row 1's tip on row 0's (a length of 0: the residual is minus the distance, the gradient zero, never NaN);
    row 2's 0.5 mm from row 0's along y: the gradient is the unit vector, not the 0.5 mm difference."""
    rows = _rows(np.zeros((3, 6)), ["pose", "distance", "distance"],
                 {"distance_mm": np.array([np.nan, 2.0, 0.75])}, {"to": ("", "1", "1")})
    tips = np.array([[500.0, 0.0, 300.0], [500.0, 0.0, 300.0], [500.0, 0.5, 300.0]])
    res = MEASUREMENT_TYPES["distance"](rows, np.array([1, 2]), {}, 0.01).residuals(tips, np.tile(np.eye(3), (3, 1, 1)),
                                                                                  np.zeros(0))
    np.testing.assert_allclose(res.values, [-2.0, -0.25], atol=1e-12)
    np.testing.assert_array_equal(res.grad_a, [[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def test_a_pivots_rows_are_found_by_its_name_not_by_one_text_object():
    """The pivot's name read as a separate string on each row (as a file's cells are): every row's tip still
    joins its sphere, and the start is the centre."""
    rng = np.random.default_rng(8)
    centre = np.array([600.0, 100.0, 300.0])
    directions = rng.normal(size=(8, 3))
    radii = np.linspace(120.0, 180.0, 8)
    tips = centre + radii[:, None] * directions / np.linalg.norm(directions, axis=1)[:, None]
    names = tuple(own_string("bar1") for _ in range(8)) + ("",)
    assert names[0] is not names[1]
    rows = _rows(np.zeros((9, 6)), ["distance"] * 8 + ["pose"], {"distance_mm": np.r_[radii, np.nan]}, {"to": names})
    distances = MEASUREMENT_TYPES["distance"](rows, np.arange(8), {"points": {"bar1": {}}}, 0.01)
    _, start = distances.unknowns(np.vstack([tips, [0.0, 0.0, 0.0]]), np.tile(np.eye(3), (9, 1, 1)))
    np.testing.assert_allclose(start, centre, atol=1e-9)
