"""The plane contact type (partcal/calibration/plane_contacts.py) on touches put by hand, where a cosmic-ray run
showed no test held it: a plane's parameter names and start, the refusals (too few touches, one orientation, a touch
far from its plane, a given normal far from the touches, touches on a line), what a given plane starts from, the
offset a tied plane's scale moves, and flush residuals against values computed here."""

import re
import warnings

import numpy as np
import pytest
from conftest import own_string
from scipy.spatial.transform import Rotation

from partcal.calibration.measurement import MeasurementRows
from partcal.calibration.registry import MEASUREMENT_TYPES
from partcal.data.measurement_rows import read_cell
from partcal.errors import ConfigError, DataError

TURNS = [0.0, 10.0, 20.0, -10.0, -20.0, 5.0, 15.0, -5.0, -15.0]
"""The tool's turn about x at each touch (degrees): touches from several orientations."""


def _planes(features, cell=None, flush=None):
    """The plane type on rows touching ``features`` (one per row; lines from 2)."""
    n = len(features)
    numbers = {} if flush is None else {"flush": np.asarray(flush, dtype=float)}
    rows = MeasurementRows(np.zeros((n, 6)), ("plane",) * n, tuple(str(i + 1) for i in range(n)),
                           tuple(range(2, n + 2)), "test.csv", numbers, {"feature": tuple(features)})
    return MEASUREMENT_TYPES["plane"](rows, np.arange(n), cell or {}, 0.01)


def _pointing_down(turns_deg):
    """Tool rotations pointing down (z along -z of the base) and turned about x by each of ``turns_deg``."""
    return Rotation.from_euler("x", 180.0 + np.asarray(turns_deg, dtype=float)[:, None], degrees=True).as_matrix()


def _on_plane(normal, offset, count, centre=None, spread=200.0):
    """``count`` points on the plane ``normal . p = offset`` (a ring of them about its point nearest ``centre``)."""
    normal = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    foot = normal * offset if centre is None else centre + normal * (offset - normal @ centre)
    angles = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    return foot + spread * (np.cos(angles)[:, None] * a + np.sin(angles)[:, None] * b)


def _unknowns(planes, positions, turns=None):
    turns = TURNS * (len(positions) // len(TURNS) + 1) if turns is None else turns
    return planes.unknowns(positions, _pointing_down(turns[:len(positions)]))


def test_an_unknown_planes_normal_points_towards_the_base_origin_and_names_its_pole():
    """The plane z = 400 (above the base) gets the normal -z: unknowns ``top.x/-z``, ``top.y/-z`` (its tilts) and
    an offset of -400; the plane z = -300 (below) the normal +z, ``floor.x/+z``, offset -300."""
    positions = np.vstack([_on_plane([0, 0, 1], 400.0, 6, centre=[800, 0, 0]),
                           _on_plane([0, 0, 1], -300.0, 6, centre=[600, 0, 0])])
    names, start = _unknowns(_planes(["top"] * 6 + ["floor"] * 6), positions)
    assert names == [("plane top.x/-z", "1"), ("plane top.y/-z", "1"), ("plane top.offset", "mm"),
                     ("plane floor.x/+z", "1"), ("plane floor.y/+z", "1"), ("plane floor.offset", "mm")]
    np.testing.assert_allclose(start, [0.0, 0.0, -400.0, 0.0, 0.0, -300.0], atol=1e-9)


@pytest.mark.parametrize("few, many", [("aa", "bb"), ("bb", "aa")])
def test_a_plane_with_too_few_touches_is_refused_whatever_its_name_sorts_as(few, many):
    """One plane touched twice (lines 2 and 3), the other four times: the first is refused, not given the other's
    touches, whichever name sorts first."""
    with pytest.raises(DataError, match=rf"^test.csv:2: column 'feature': plane '{few}' has 2 touches; its 3 "):
        _planes([few, few, many, many, many, many])


@pytest.mark.parametrize("still, turned", [("aa", "bb"), ("bb", "aa")])
def test_the_one_orientation_check_reads_each_planes_own_touches(still, turned):
    """One plane touched four times from one orientation, the other from four: the first is refused naming its
    first line, the names read as separate strings (as a file's cells are) and whichever sorts first."""
    features = [own_string(still) for _ in range(4)] + [own_string(turned) for _ in range(4)]
    positions = np.vstack([_on_plane([0, 0, 1], 400.0, 4, [800, 0, 0]), _on_plane([1, 0, 0], 700.0, 4, [0, 0, 300])])
    with pytest.raises(DataError, match=rf"^test.csv:2: column 'feature': plane '{still}' is touched from one "):
        _unknowns(_planes(features), positions, [0.0] * 4 + [0.0, 10.0, 20.0, -10.0])


def test_touches_turned_a_degree_and_a_half_are_taken():
    positions = _on_plane([0, 0, 1], 400.0, 4, [800, 0, 0])
    assert _unknowns(_planes(["top"] * 4), positions, [0.0, 1.5, 0.0, 1.5])[0][2] == ("plane top.offset", "mm")


def test_a_tilted_planes_start_slopes_give_back_its_normal():
    """The plane z = 400 tilted 5 degrees about x (unknown): its start's slopes a, b rebuild the normal the touches
    put it at, pole + a t1 + b t2 normalised (pole -z, towards the base origin; t1 x, t2 y)."""
    tilt = np.radians(5.0)
    normal = np.array([0.0, -np.sin(tilt), -np.cos(tilt)])
    names, start = _unknowns(_planes(["top"] * 6), _on_plane(-normal, 400.0, 6, [800, 0, 0]))
    rebuilt = np.array([0.0, 0.0, -1.0]) + start[0] * np.array([1.0, 0, 0]) + start[1] * np.array([0, 1.0, 0])
    np.testing.assert_allclose(rebuilt / np.linalg.norm(rebuilt), normal, atol=1e-12)
    assert start[2] == pytest.approx(-400.0)


def test_a_given_normal_already_along_the_touches_is_not_turned_over():
    """The floor z = -300 (its normal towards the base origin is +z) given 5 degrees from +z: taken as it is."""
    floor = _on_plane([0, 0, 1], -300.0, 4, [700, 0, 0])
    given = [np.sin(np.radians(5.0)), 0.0, np.cos(np.radians(5.0))]
    cell = {"planes": {"floor": {"normal": given, "offset_mm": -300.0}}}
    names, start = _unknowns(_planes(["floor"] * 4, cell), floor)
    assert names[0] == ("plane floor.x/+z", "1") and start[2] == pytest.approx(-300.0)


TIED = {"planes": {"top": {}, "step": {"parallel_to": "top", "spacing_mm": -200.0}}}


@pytest.mark.parametrize("turns, refused", [([0.0], False), ([0.0, 0.0], True), ([0.0, 10.0], False)])
def test_a_tied_plane_touched_once_is_taken_and_twice_from_one_orientation_refused(turns, refused):
    """'top' (z = 400) four times from four orientations, then the tied 'step' (z = 200): once, twice from one
    orientation (refused, naming line 6) or twice turned 10 degrees."""
    k = len(turns)
    positions = np.vstack([_on_plane([0, 0, 1], 400.0, 4, [800, 0, 0]), _on_plane([0, 0, 1], 200.0, k, [700, 0, 0])])
    planes = _planes(["top"] * 4 + ["step"] * k, TIED)
    rotations = [0.0, 10.0, 20.0, -10.0] + turns
    if refused:
        with pytest.raises(DataError, match=r"^test.csv:6: column 'feature': plane 'step' is touched from one "):
            _unknowns(planes, positions, rotations)
    else:
        names, start = _unknowns(planes, positions, rotations)     # the spacing orients the normal: +z
        assert names[0] == ("plane top.x/+z", "1")
        np.testing.assert_allclose(start, [0.0, 0.0, 400.0], atol=1e-9)


def test_a_touch_far_from_its_plane_is_refused_saying_how_far():
    """Eight touches on a ring of the plane z = 400 and a ninth (line 10) at its centre 50 mm above: the plane through
    the nine sits 50 / 9 mm above the ring, so the ninth is 44.4 mm from it (beyond 20 mm); refused naming it."""
    positions = np.vstack([_on_plane([0, 0, 1], 400.0, 8, [800, 0, 0]), [[800.0, 0.0, 450.0]]])
    with pytest.raises(DataError, match=r"^test.csv:10: column 'feature': the nominal robot puts this touch 44.4 mm "
                                        r"from plane 'top' \(1 touches beyond 20 mm\)"):
        _unknowns(_planes(["top"] * 9), positions)


def _given_plane_rows(tilt_deg):
    """Planes 'wall' (x = 900) and 'side' (y = 500) touched first, then 'top' (z = 400); the cell gives top's
    normal tilted ``tilt_deg`` about y from the touches' one (given two units long: any length is a direction)."""
    normal = [np.sin(np.radians(tilt_deg)), 0.0, np.cos(np.radians(tilt_deg))]
    positions = np.vstack([_on_plane([1, 0, 0], 900.0, 4, [0, 0, 300]), _on_plane([0, 1, 0], 500.0, 4, [600, 0, 300]),
                           _on_plane([0, 0, 1], 400.0, 4, [800, 0, 0])])
    cell = {"planes": {"wall": {}, "side": {}, "top": {"normal": [2.0 * v for v in normal], "offset_mm": 400.0}}}
    return _planes(["wall"] * 4 + ["side"] * 4 + ["top"] * 4, cell), positions, normal


@pytest.mark.parametrize("tilt_deg", [9.5, 10.5])
def test_a_given_normal_more_than_ten_degrees_from_the_touches_is_refused_naming_the_planes_first_touch(tilt_deg):
    planes, positions, normal = _given_plane_rows(tilt_deg)
    if tilt_deg < 10.0:
        names, start = _unknowns(planes, positions, [0.0, 10.0, 20.0, -10.0] * 3)
        np.testing.assert_allclose(start[-3:], [0.0, 0.0, 400.0], atol=1e-9)   # the touches' plane, +z as given
        return
    shown = str([round(float(v), 4) for v in normal])
    with pytest.raises(DataError, match=rf"^test.csv:10: column 'feature': the nominal robot's touches of plane 'top' "
                                        rf"put its normal 10.5 degrees from the cell's planes.top.normal "
                                        rf"{re.escape(shown)} \(more than 10\)"):
        _unknowns(planes, positions, [0.0, 10.0, 20.0, -10.0] * 3)
    assert shown == "[0.1822, 0.0, 0.9833]"


def test_a_group_two_spacings_orient_is_refused_when_the_given_normal_points_the_other_way():
    """'top' (z = 400) and the tied 'step' (200 mm below it along the normal, z = 200) orient the normal +z by
    themselves; a given normal -z is 180 degrees from it."""
    positions = np.vstack([_on_plane([0, 0, 1], 400.0, 4, [800, 0, 0]), _on_plane([0, 0, 1], 200.0, 4, [700, 0, 0])])
    cell = {"planes": {"top": {"normal": [0.0, 0.0, -1.0], "offset_mm": -400.0},
                       "step": {"parallel_to": own_string("top"), "spacing_mm": -200.0}}}
    with pytest.raises(DataError, match=r"^test.csv:2: .* put its normal 180.0 degrees from the cell's planes.top"):
        _unknowns(_planes(["top"] * 4 + ["step"] * 4, cell), positions, [0.0, 10.0, 20.0, -10.0] * 2)


def test_touches_on_one_line_fix_no_unknown_plane_and_a_given_one_starts_where_the_cell_puts_it():
    """Four touches along a line of z = 400, or a micrometre off it (after those of two other planes): refused for an
    unknown plane, naming its first touch; with the plane given (normal +z, offset 410, 10 mm off) the start is the
    cell's, and each touch's residual is z - 410 (by hand)."""
    line = np.column_stack([np.linspace(600.0, 900.0, 4), np.zeros(4), np.full(4, 400.0)])
    side, wall = _on_plane([1, 0, 0], 700.0, 4, [0, 0, 300]), _on_plane([0, 1, 0], 500.0, 4, [600, 0, 300])
    nearly = line + [[0.0, 1e-6, 0.0], [0.0, -1e-6, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1e-6]]   # a micrometre off
    for touches in (line, nearly):        # 'side' and 'wall' (sorting before and after 'top') touched first
        with pytest.raises(DataError, match=r"^test.csv:10: column 'feature': the touches of plane 'top' lie on one "):
            _unknowns(_planes(["side"] * 4 + ["wall"] * 4 + ["top"] * 4), np.vstack([side, wall, touches]))
    planes = _planes(["top"] * 4, {"planes": {"top": {"normal": [0.0, 0.0, 1.0], "offset_mm": 410.0}}})
    names, start = _unknowns(planes, line)
    np.testing.assert_allclose(start, [0.0, 0.0, 410.0], atol=1e-12)
    residuals = planes.residuals(line, _pointing_down(TURNS[:4]), start)
    np.testing.assert_allclose(residuals.values, [-10.0] * 4, atol=1e-12)


def test_a_tied_plane_touched_alone_once_starts_from_its_given_root():
    """Only 'step' touched (once, at z = 200), tied 200 mm below a given 'top' (z = 400): one touch fixes no plane,
    the start is the cell's (normal +z, offset 400) and the touch's residual 200 - 400 + 200 = 0."""
    cell = {"planes": {"top": {"normal": [0.0, 0.0, 1.0], "offset_mm": 400.0},
                       "step": {"parallel_to": "top", "spacing_mm": -200.0}}}
    planes = _planes(["step"], cell)
    tip = np.array([[700.0, 0.0, 200.0]])
    names, start = _unknowns(planes, tip)
    np.testing.assert_allclose(start, [0.0, 0.0, 400.0], atol=1e-12)
    np.testing.assert_allclose(planes.residuals(tip, _pointing_down([0.0]), start).values, [0.0], atol=1e-12)


@pytest.mark.parametrize("entry, missing", [("{normal: [0, 0, 1]}", "offset_mm"), ("{offset_mm: 400}", "normal"),
                                            ("{parallel_to: side}", "spacing_mm")])
def test_half_a_planes_form_is_refused_naming_the_key_it_misses(tmp_path, entry, missing):
    path = tmp_path / "cell.yaml"
    path.write_text(f"planes:\n  side: {{}}\n  top: {entry}\n")
    with pytest.raises(ConfigError, match=rf"cell.yaml: planes.top \(line 3\): missing required key '{missing}'"):
        read_cell(path)


def test_a_scale_moves_the_offset_of_a_tied_plane_touched_alone_and_no_offset_of_two_spacings():
    """Root 'top' untouched: its tied 'step' (-200) touched alone scales as the plane it is, top's offset plus
    -200; with 'step2' (-100) touched too, the two spacings measure a length and no offset moves. A second group,
    'side' (unknown, x = 700) then its tied 'side2' (+50) touched alone: the second root's offset moves by +50.
    The tie names are strings of their own, as a file's are."""
    cell = {"planes": {"top": {}, "step": {"parallel_to": own_string("top"), "spacing_mm": -200.0},
                       "step2": {"parallel_to": own_string("top"), "spacing_mm": -100.0},
                       "side": {}, "side2": {"parallel_to": own_string("side"), "spacing_mm": 50.0}}}
    step = _on_plane([0, 0, 1], 200.0, 4, [800, 0, 0])
    alone = _planes(["step"] * 4, cell)
    start = _unknowns(alone, step)[1]
    np.testing.assert_allclose(alone.scaled_lengths(start), start + [0.0, 0.0, -200.0], atol=1e-12)
    both = _planes(["step"] * 4 + ["step2"] * 4 + ["side2"] * 4, cell)
    positions = np.vstack([step, _on_plane([0, 0, 1], 300.0, 4, [700, 0, 0]),
                           _on_plane([1, 0, 0], 750.0, 4, [0, 0, 300])])
    start = _unknowns(both, positions)[1]
    np.testing.assert_allclose(both.scaled_lengths(start), start + [0.0, 0.0, 0.0, 0.0, 0.0, 50.0], atol=1e-12)


def test_a_spacing_in_metres_is_refused_naming_the_tied_planes_first_touch_and_an_untouched_root_checks_nothing():
    """'top' (z = 400) and 'step' (z = 200, lines 3 and 5, interleaved) with a spacing of -0.2: refused naming line
    3. 'step' touched with its root untouched: nothing to check, and no numpy warning of an empty mean."""
    features = ["top", "step", "top", "step", "top", "top"]
    positions = np.array([[800.0, 0.0, 400.0], [700.0, 0.0, 200.0], [900.0, 100.0, 400.0], [750.0, 50.0, 200.0],
                          [700.0, -150.0, 400.0], [850.0, 150.0, 400.0]])
    cell = {"planes": {"top": {}, "step": {"parallel_to": "top", "spacing_mm": -0.2}}}
    with pytest.raises(DataError, match=r"^test.csv:3: planes.step.spacing_mm: -0.2 mm, but the nominal robot's "
                                        r"touches of 'step' and 'top' say about -200.0 mm"):
        _unknowns(_planes(features, cell), positions)
    cell["planes"]["step"]["spacing_mm"] = -200.0
    step = _on_plane([0, 0, 1], 200.0, 4, [700, 0, 0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        planes = _planes(["step"] * 4, cell)
        _unknowns(planes, step)
    assert planes.suspicions == []


def test_flush_residuals_on_a_tilted_plane_by_hand():
    """A plane tilted 5 degrees about y and a flush touch whose tool z axis is exactly against its normal: the two
    tilt residuals are zero; the tool turned 1 degree further about y: the rim of a 50 mm face rises by
    50 (sin 5 - sin 6 degrees) along the first tangent (x) and not along the second (y). The plane is the second of
    two: the flush residuals fill its own unknowns' columns."""
    tilt = np.radians(5.0)
    normal = np.array([-np.sin(tilt), 0.0, -np.cos(tilt)])          # the plane z = 400 tilted, towards the origin
    tips = _on_plane(-normal, 400.0, 4, [800, 0, 0])
    wall = _on_plane([1, 0, 0], 900.0, 4, [0, 0, 300])
    against = Rotation.from_rotvec([0.0, np.pi + tilt, 0.0]).as_matrix()   # z = (-sin 5, 0, -cos 5) = the normal...
    assert np.allclose(against[:, 2] @ normal, 1.0)                 # ...so the face lies on it from the normal's side
    planes = _planes(["wall"] * 4 + ["top"] * 4, flush=[0] * 4 + [1, 0, 0, 0])
    rotations = np.concatenate([_pointing_down([0.0, 10.0, 20.0, -10.0]), _pointing_down([0.0, 10.0, 20.0, -10.0])])
    rotations[4] = against
    positions = np.vstack([wall, tips])
    names, start = planes.unknowns(positions, rotations)
    assert names[3:] == [("plane top.x/-z", "1"), ("plane top.y/-z", "1"), ("plane top.offset", "mm")]
    res = planes.residuals(positions, rotations, start)
    np.testing.assert_allclose(res.values[8:], [0.0, 0.0], atol=1e-9)
    assert res.rows_a[8:].tolist() == [4, 4]
    assert res.du.shape == (10, 6) and np.all(res.du[8:, :3] == 0.0) and np.all(res.du[8:, 5] == 0.0)
    assert np.any(res.du[8:, 3:5] != 0.0)
    rotations[4] = Rotation.from_rotvec([0.0, np.pi + tilt + np.radians(1.0), 0.0]).as_matrix()  # z: 6 degrees
    res = planes.residuals(positions, rotations, start)
    np.testing.assert_allclose(res.values[8:], [50.0 * (np.sin(tilt) - np.sin(np.radians(6.0))), 0.0], atol=1e-9)


def test_a_group_is_fitted_from_its_plane_with_most_touches_whatever_the_names_sort_as_and_are_read():
    """'top' touched three times along a line (it fixes no plane by itself) and the tied 'step' (sorting before
    it, its tie named by a string of its own) five times over an area: the group's normal comes from step's
    touches, +z as the spacing says, and top's offset is 400."""
    cell = {"planes": {"top": {}, "step": {"parallel_to": own_string("top"), "spacing_mm": -200.0}}}
    line = np.column_stack([np.linspace(600.0, 900.0, 3), np.zeros(3), np.full(3, 400.0)])
    positions = np.vstack([line, _on_plane([0, 0, 1], 200.0, 5, [700, 0, 0])])
    features = [own_string("top") for _ in range(3)] + [own_string("step") for _ in range(5)]
    names, start = _unknowns(_planes(features, cell), positions, [0.0, 10.0, 20.0, 0.0, 10.0, 20.0, -10.0, 5.0])
    assert names[0] == ("plane top.x/+z", "1")
    np.testing.assert_allclose(start, [0.0, 0.0, 400.0], atol=1e-9)


@pytest.mark.parametrize("flush, taken", [("0", True), ("1", True), ("", True), ("2", False), ("-1", False)])
def test_a_touchs_flush_mark_is_0_1_or_empty(tmp_path, flush, taken):
    from partcal.data.measurement_rows import read_measurement_rows
    path = tmp_path / "m.csv"
    path.write_text(f"q1,q2,q3,q4,q5,q6,measurement,feature,flush\n0,0,0,0,0,0,plane,top,{flush}\n")
    if taken:
        assert np.nan_to_num(read_measurement_rows(path).numbers["flush"][0]) == float(flush or 0)
        return
    with pytest.raises(DataError, match=rf"m.csv:2: column 'flush': expected 0 or 1 .*, got '{flush}'"):
        read_measurement_rows(path)


def test_a_given_root_is_oriented_by_its_own_groups_spacings_alone():
    """'aa' given (normal +z, z = 400) touched alone; another group, 'zz' (x = 700) and its tied 'zz2' (50 mm on),
    sorts after it: aa's normal still turns to the given +z (zz's two spacings orient zz alone)."""
    cell = {"planes": {"aa": {"normal": [0.0, 0.0, 1.0], "offset_mm": 400.0}, "zz": {},
                       "zz2": {"parallel_to": "zz", "spacing_mm": 50.0}}}
    positions = np.vstack([_on_plane([0, 0, 1], 400.0, 4, [800, 0, 0]), _on_plane([1, 0, 0], 700.0, 4, [0, 0, 300]),
                           _on_plane([1, 0, 0], 750.0, 4, [0, 0, 300])])
    names, start = _unknowns(_planes(["aa"] * 4 + ["zz"] * 4 + ["zz2"] * 4, cell), positions)
    assert names[0] == ("plane aa.x/+z", "1") and start[2] == pytest.approx(400.0)


def test_three_spacings_touched_orient_their_group_against_a_given_normal():
    """'top' (z = 400), 'step' (-200: z = 200) and 'step2' (-100: z = 300) touched orient the normal +z by
    themselves; a given normal -z is 180 degrees from it."""
    cell = {"planes": {"top": {"normal": [0.0, 0.0, -1.0], "offset_mm": -400.0},
                       "step": {"parallel_to": "top", "spacing_mm": -200.0},
                       "step2": {"parallel_to": "top", "spacing_mm": -100.0}}}
    positions = np.vstack([_on_plane([0, 0, 1], z, 4, [800, 0, 0]) for z in (400.0, 200.0, 300.0)])
    with pytest.raises(DataError, match=r"^test.csv:2: .* put its normal 180.0 degrees from the cell's planes.top"):
        _unknowns(_planes(["top"] * 4 + ["step"] * 4 + ["step2"] * 4, cell), positions)


def test_each_planes_unknowns_move_with_the_cell_as_refitting_the_moved_touches_does():
    """Two planes (one tilted): the cell turned by a small w about the base origin and shifted by t moves each
    touch p to p + w x p + t; the planes fitted again on the moved touches start where ``moved`` says, to first
    order."""
    tilt = np.radians(5.0)
    positions = np.vstack([_on_plane([np.sin(tilt), 0.0, np.cos(tilt)], 400.0, 6, [800, 0, 0]),
                           _on_plane([1, 0.1, 0], 700.0, 6, [0, 0, 300])])
    planes = _planes(["top"] * 6 + ["side"] * 6)
    start = _unknowns(planes, positions)[1]
    omega, shift, eps = np.array([0.3, -0.2, 0.5]), np.array([2.0, -1.0, 3.0]), 1e-6
    moved = positions + eps * (np.cross(omega, positions) + shift)
    again = _unknowns(_planes(["top"] * 6 + ["side"] * 6), moved)[1]
    np.testing.assert_allclose(planes.moved(start, omega, shift), (again - start) / eps, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("entry, message", [
    ("{normal: [0, 0, 1, 0], offset_mm: 400}", r"planes.top.normal \(line 3\): must be a list of three finite numbers; got a list \["),
    ("{normal: [true, 0, 1], offset_mm: 400}", r"planes.top.normal \(line 3\): must be a list of three finite numbers; got a list \["),
    ("{normal: [0, 0, up], offset_mm: 400}", r"planes.top.normal \(line 3\): must be a list of three finite numbers; got a list \["),
    ("{normal: [0, 0, .nan], offset_mm: 400}", r"planes.top.normal \(line 3\): must be a list of three finite numbers; got a list \["),
    ("{colour: red}", r"planes.top.colour \(line 3\): unknown key \(known: normal, offset_mm, parallel_to, spacing_mm\)"),
    ("{normal: [0, 0, 1], offset_mm: 400, colour: red}",
     r"planes.top.colour \(line 3\): unknown key beside 'normal' \(that form has normal, offset_mm; one form per "
     r"feature\)$")])
def test_a_cells_vectors_and_keys_are_checked_naming_path_and_line(tmp_path, entry, message):
    """Four numbers, a boolean, a word or NaN in a normal; a key of no form (the keys of every form listed); a key
    beside a form's (that form's keys named, no list of every key)."""
    path = tmp_path / "cell.yaml"
    path.write_text(f"planes:\n  side: {{}}\n  top: {entry}\n")
    with pytest.raises(ConfigError, match=message):
        read_cell(path)


@pytest.mark.parametrize("noise, taken", [("0.05", True), ("0", False), ("-0.05", False)])
def test_a_stated_noise_is_a_number_above_zero(tmp_path, noise, taken):
    path = tmp_path / "cell.yaml"
    path.write_text(f"noise: {{plane: {noise}}}\n")
    if taken:
        assert read_cell(path)["noise"]["plane"] == 0.05
        return
    with pytest.raises(ConfigError, match=rf"noise.plane \(line 1\): must be a finite number > 0; got {float(noise)}"):
        read_cell(path)
