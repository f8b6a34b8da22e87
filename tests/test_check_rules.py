"""The rules of partcal/calibration/checks.py one by one, on rows and numbers made by hand (no simulation): where each
threshold lies, which row and column a refusal names, which rows a misfit names. Every expected value is worked out
by hand from the rule's words in the module's docstrings (test_calibration_checks.py runs the same checks through
``partcal run`` on a simulated cell)."""

import re
from types import SimpleNamespace

import numpy as np
import pytest

from partcal.calibration.checks import check_freedom, check_joint_units, check_measured, check_rows, known_length, \
    misfit_notes
from partcal.calibration.measurement import MeasurementRows
from partcal.errors import DataError
from partcal.robot.description import load_robot


def _rows(q_deg, **numbers) -> MeasurementRows:
    n = len(q_deg)
    return MeasurementRows(q_deg=np.asarray(q_deg, dtype=float), types=("point",) * n,
                           ids=tuple(str(i + 1) for i in range(n)), lines=tuple(range(10, 10 + n)), source="m.csv",
                           numbers=numbers)


def _moving(n: int, largest: float) -> np.ndarray:
    """``n`` poses of 6 joints, every joint moving, the largest magnitude ``largest`` (on joint 1 of the last pose)."""
    q = np.linspace(-0.5, 0.5, n)[:, None] * np.arange(1, 7) / 6.0
    q[-1, 0] = largest
    return q


# ---------------------------------------------------------------- joints in radians


@pytest.mark.parametrize("largest", [6.0, -6.0, 2 * np.pi])
def test_five_moving_poses_within_a_full_turn_are_radians(largest):
    """Within ±2π (a full turn in radians, 2π itself included), either sign: refused, naming the first row given and
    the number of poses."""
    with pytest.raises(DataError, match=r"^m\.csv:row 7: every joint angle of the 5 poses lies within ±6(\.\d+)? degrees"):
        check_joint_units("m.csv", ["row 7", "row 8"], _moving(5, largest))


@pytest.mark.parametrize("largest", [7.0, 2 * np.pi + 1e-6])
def test_a_joint_beyond_a_full_turn_is_evidence_of_degrees(largest):
    check_joint_units("m.csv", ["row 7"], _moving(5, largest))


def test_four_poses_are_too_few_to_call_radians():
    check_joint_units("m.csv", ["row 7"], _moving(4, 6.0))


def test_poses_that_do_not_move_are_no_evidence_though_the_joints_differ():
    """Ten copies of one pose (its six joints 1 to 6 degrees): nothing moves between poses, nothing is said."""
    check_joint_units("m.csv", ["row 7"], np.tile(np.arange(1.0, 7.0), (10, 1)))


def test_one_joint_moving_is_enough_to_call_radians():
    q = np.zeros((6, 6))
    q[:, 2] = np.linspace(-1.0, 1.0, 6)
    with pytest.raises(DataError, match="of the 6 poses lies within ±1 degrees"):
        check_joint_units("m.csv", ["row 1"], q)


# ---------------------------------------------------------------- rows planned, not measured


@pytest.mark.parametrize("mark", [1.0, 2.0, 0.5])
def test_the_first_planned_row_is_named_by_its_line(mark):
    """partcal plan writes 1; any other mark but 0 (or an empty cell) is a row planned too."""
    rows = _rows(np.zeros((5, 6)), planned=[0.0, np.nan, mark, 0.0, 1.0])
    with pytest.raises(DataError, match=r"^m\.csv:12: column 'planned'"):
        check_measured(rows)


@pytest.mark.parametrize("planned", [[0.0, 0.0, 0.0], [np.nan, np.nan, np.nan], None])
def test_rows_not_planned_pass(planned):
    check_measured(_rows(np.zeros((3, 6)), **({} if planned is None else {"planned": planned})))


# ---------------------------------------------------------------- joint limits (motoman_sk120: every joint its own)

SK120 = load_robot("motoman_sk120")
INSIDE = np.array([0.0, -117.5, -180.0, 0.0, 0.0, 0.0])        # the middle of each joint's range
"""Limits: [-180, 180], [-175, -60], [-250, -110], [-180, 180], [-130, 130], [-360, 360]."""


def _sk120(edits) -> MeasurementRows:
    q = np.tile(INSIDE, (8, 1)) + np.linspace(0.0, 7.0, 8)[:, None]        # poses apart: they move
    for (i, j), value in edits.items():
        q[i, j] = value
    return _rows(q)


@pytest.mark.parametrize("value", [-175.9, -59.1, -176.0, -59.0])
def test_a_joint_a_degree_or_less_beyond_its_limit_passes(value):
    check_rows(SK120, _sk120({(3, 1): value}))


@pytest.mark.parametrize("value, limit", [(-176.5, "low"), (-58.5, "high")])
def test_a_joint_more_than_a_degree_beyond_either_limit_is_refused(value, limit):
    with pytest.raises(DataError, match=rf"^m\.csv:13: column 'q2': {value:g} degrees lies outside joint 2's limits "
                                        r"\[-175, -60\] of motoman_sk120 \(1 rows beyond a limit\)$"):
        check_rows(SK120, _sk120({(3, 1): value}))


def test_the_row_and_joint_farthest_beyond_are_named_and_the_rows_beyond_counted():
    """Row 2 is 5 degrees beyond joint 5's high limit (130) and 2 beyond joint 2's; row 5 is 20 beyond joint 3's low
    limit (-250); row 6 is 2 beyond joint 1's; row 1 is 0.5 beyond joint 5's and row 4 exactly 1 beyond joint 1's,
    within the slack: three rows, the farthest row 5's joint 3."""
    rows = _sk120({(2, 4): 135.0, (2, 1): -57.0, (5, 2): -270.0, (6, 0): 182.0, (1, 4): 130.5, (4, 0): 181.0})
    with pytest.raises(DataError, match=r"^m\.csv:15: column 'q3': -270 degrees lies outside joint 3's limits "
                                        r"\[-250, -110\] of motoman_sk120 \(3 rows beyond a limit\)$"):
        check_rows(SK120, rows)


def test_degrees_read_as_radians_are_named_as_the_likely_cause():
    """Joints that a format multiplied by 180/π: divided by 57.3 they lie within the limits (the cause is said); with
    one joint beyond its limit either way (joint 6 at 400 degrees before the scaling, or joint 3 at -300) no cause is
    said."""
    q = (np.tile(INSIDE, (8, 1)) + np.linspace(0.0, 7.0, 8)[:, None]) * np.degrees(1.0)
    with pytest.raises(DataError, match=r"rows beyond a limit\); every joint divided by 57\.3 lies within them"):
        check_rows(SK120, _rows(q))
    q[0, 5] = 400.0 * np.degrees(1.0)
    with pytest.raises(DataError, match=r"rows beyond a limit\)$"):
        check_rows(SK120, _rows(q))
    q[0, 5] = 0.0
    q[3, 2] = -300.0 * np.degrees(1.0)                     # joint 3 below its low limit either way
    with pytest.raises(DataError, match=r"rows beyond a limit\)$"):
        check_rows(SK120, _rows(q))


def test_joints_within_a_full_turn_are_refused_as_radians_before_the_limits():
    with pytest.raises(DataError, match=r"^m\.csv:10: every joint angle of the 8 poses"):
        check_rows(SK120, _rows(_moving(8, 3.0)))


# ---------------------------------------------------------------- the residual against the stated noise


def _misfit(residuals, noise, n=6):
    return misfit_notes(_rows(np.zeros((n, 6))), residuals, noise)


def test_an_rms_ten_times_the_stated_noise_is_not_calibrated_and_names_the_three_worst_rows():
    """Rows 0..3 with residuals (row 0 has two: 12 and 16, i.e. 20 in all), 5, 13, 11 and one residual of no row
    (-1, 14): squares 144+256+25+169+121+196 = 911, RMS sqrt(911/6) = 12.32, 12.3 times 1 mm."""
    values = np.array([12.0, 5.0, 13.0, 16.0, 11.0, 14.0])
    row_of = np.array([0, 1, 2, 0, 3, -1])
    notes, ratios = _misfit({"distance": (values, row_of)}, {"distance": (1.0, "mm", True)})
    assert ratios == {"distance": pytest.approx(np.sqrt(911 / 6))}
    assert notes == ["not calibrated: the distance rows' fit leaves 12.3 mm RMS, 12 times their stated noise 1 mm; "
                     "the worst rows: m.csv:10 (20 mm), m.csv:12 (13 mm), m.csv:13 (11 mm): a wrong known length or "
                     "unit in the cell, rows of another feature, or a noise stated too small"]


def test_exactly_ten_times_the_noise_is_not_calibrated_and_just_under_is():
    noise = {"plane": (0.5, "mm", True)}
    at, _ = _misfit({"plane": (np.full(4, 5.0), np.arange(4))}, noise)
    under, ratios = _misfit({"plane": (np.full(4, 4.99), np.arange(4))}, noise)
    assert len(at) == 1 and "5 mm RMS, 10 times their stated noise 0.5 mm" in at[0]
    assert under == [] and ratios == {"plane": pytest.approx(9.98)}


def test_a_noise_not_stated_is_not_judged_and_a_type_without_residuals_is_skipped():
    """Three types in order: one with no residuals (no ratio), one whose noise is the default (its ratio, no note), one
    stated and 20 times off: only the last is noted."""
    residuals = {"empty": (np.zeros(0), np.zeros(0, dtype=int)),
                 "point": (np.full(3, 100.0), np.arange(3)),
                 "plane": (np.array([0.0, 2.0, 0.0, 4.0]), np.array([0, 1, 4, 5]))}
    noise = {"empty": (1.0, "mm", True), "point": (1.0, "mm", False), "plane": (0.1, "mm", True)}
    notes, ratios = _misfit(residuals, noise)
    assert ratios == {"point": pytest.approx(100.0), "plane": pytest.approx(np.sqrt(5.0) / 0.1)}
    assert len(notes) == 1
    assert "the plane rows' fit leaves 2.24 mm RMS, 22 times their stated noise 0.1 mm; the worst rows: m.csv:15 " \
           "(4 mm), m.csv:11 (2 mm), m.csv:10 (0 mm): a wrong" in notes[0]


# ---------------------------------------------------------------- known lengths


@pytest.mark.parametrize("stated, seen", [(1.0, 3.0), (1000.0, -3.0), (1000.0, 0.0)])
def test_a_view_of_3_mm_or_less_judges_nothing(stated, seen):
    assert known_length("k", "f:1", stated, seen, "v") is None


@pytest.mark.parametrize("stated, seen", [(1250.0, 1000.0), (800.0, 1000.0), (-1250.0, -1000.0)])
def test_a_length_off_by_the_factor_itself_is_a_note_not_a_refusal(stated, seen):
    note = known_length("k", "f:1", stated, seen, "v")
    assert note is not None and note.startswith(f"not calibrated: k is {stated:g} mm, but v say {seen:.2f} mm (")


@pytest.mark.parametrize("stated, seen", [(1260.0, 1000.0), (790.0, 1000.0), (5.0, 3.1)])
def test_a_length_beyond_the_factor_is_refused(stated, seen):
    with pytest.raises(DataError, match=rf"^f:1: k: {stated:g} mm, but v say about {seen:.1f} mm: expected the length "
                                        r"in mm, or the right feature$"):
        known_length("k", "f:1", stated, seen, "v")


@pytest.mark.parametrize("stated, unit", [(1.0, "metres? 1 metres is 1000 mm"),
                                          (100.0, "centimetres? 100 centimetres is 1000 mm"),
                                          (39.37, "inches? 39.37 inches is 999.998 mm"),
                                          (1.19, "metres? 1.19 metres is 1190 mm"),
                                          (0.81, "metres? 0.81 metres is 810 mm")])
def test_a_length_in_another_unit_is_named_with_its_value_in_mm(stated, unit):
    with pytest.raises(DataError, match=rf"^f:1: k: {stated:g} mm, but v say about 1000\.0 mm: expected the length in "
                                        rf"mm \({re.escape(unit)}\), or the right feature$"):
        known_length("k", "f:1", stated, 1000.0, "v")


@pytest.mark.parametrize("stated", [1.21, 0.79, 300.0, 0.0])
def test_a_ratio_more_than_a_fifth_from_any_unit_names_none(stated):
    """Nor is a length of 0 asked about its sign."""
    with pytest.raises(DataError, match=r"expected the length in mm, or the right feature$"):
        known_length("k", "f:1", stated, 1000.0, "v")


def test_a_negative_length_is_asked_about_its_sign():
    with pytest.raises(DataError, match=r"expected the length in mm \(its sign\?\), or the right feature$"):
        known_length("k", "f:1", -1000.0, 1000.0, "v")
    with pytest.raises(DataError, match=r"in mm \(metres\? -1 metres is -1000 mm\) \(its sign\?\), or"):
        known_length("k", "f:1", -1.0, 1000.0, "v")


@pytest.mark.parametrize("stated, seen, said", [(1004.0, 1000.0, None), (1005.0, 1000.0, None),
                                                (1006.0, 1000.0, "6.0 mm off"), (994.0, 1000.0, "6.0 mm off"),
                                                (102.9, 100.0, None), (103.5, 100.0, "3.5 mm off"),
                                                (-1006.0, -1000.0, "6.0 mm off"), (-1004.0, -1000.0, None)])
def test_a_length_is_noted_when_off_by_more_than_3_mm_or_half_a_percent(stated, seen, said):
    """Off by more than max(3 mm, 0.5 % of the view): 5 mm at 1000 mm (exactly 5 is not more), 3 mm at 100 mm."""
    note = known_length("k", "f:1", stated, seen, "v")
    assert (note is None) if said is None else (said in note and note.endswith("measure it again or leave it out"))


# ---------------------------------------------------------------- residuals left to judge a fit


def test_a_fit_needs_more_residuals_than_parameters():
    """Seven residuals, one of no row (-1, not counted): six; six identified parameters (two fixed, not counted)
    leave none (eight: fewer than none), five leave one."""
    rows = _rows(np.zeros((3, 6)))
    row_of = np.array([0, 0, 1, 1, 2, 2, -1])
    six = SimpleNamespace(status=["identified"] * 6 + ["fixed"] * 2)
    with pytest.raises(DataError, match=r"^m\.csv: 3 rows give 6 residuals for the 6 parameters they identify"):
        check_freedom(rows, row_of, six)
    with pytest.raises(DataError, match=r"^m\.csv: 3 rows give 6 residuals for the 8 parameters they identify"):
        check_freedom(rows, row_of, SimpleNamespace(status=["identified"] * 8))
    check_freedom(rows, row_of, SimpleNamespace(status=["identified"] * 5 + ["fixed"] * 3))
