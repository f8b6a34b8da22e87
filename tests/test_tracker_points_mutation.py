"""The tracker point type (partcal/calibration/tracker_points.py) on points put by hand, where a cosmic-ray run
showed no test held it: the refusals of stated deviations and orientations (the first bad row and column named), a
point far from the nominal robot, the starts of the tracker's pose and of a further target (in the base frame and
in the tracker's), the weights and spread the deviations give, the shapes orientation rows add, and the words and
nominal values the type gives the rest of partcal."""

import numpy as np
import pytest
from conftest import own_string
from scipy.spatial.transform import Rotation

from partcal.calibration.measurement import MeasurementRows
from partcal.calibration.registry import MEASUREMENT_TYPES
from partcal.calibration.tracker_points import TRACKER_FRAME, target_nominal
from partcal.errors import DataError


def _points(measured, numbers=None, texts=None, cell=None):
    """The point type on rows measuring ``measured`` (n, 3) mm; lines from 2."""
    measured = np.asarray(measured, dtype=float)
    n = len(measured)
    columns = {"x_meas": measured[:, 0], "y_meas": measured[:, 1], "z_meas": measured[:, 2], **(numbers or {})}
    rows = MeasurementRows(np.zeros((n, 6)), ("point",) * n, tuple(str(i + 1) for i in range(n)),
                           tuple(range(2, n + 2)), "test.csv", columns, texts or {})
    return MEASUREMENT_TYPES["point"](rows, np.arange(n), cell or {}, 0.02)


PLACES = np.array([[800.0, 0.0, 400.0], [700.0, 300.0, 500.0], [600.0, -200.0, 300.0], [900.0, 100.0, 600.0],
                   [750.0, -300.0, 450.0], [650.0, 250.0, 350.0]])
TURNS = Rotation.from_rotvec([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.4, 0.0], [0.0, 0.0, 0.5], [0.2, -0.3, 0.1],
                              [-0.4, 0.1, 0.2]]).as_matrix()


def _std(rows_std):
    std = np.asarray(rows_std, dtype=float)
    return {"std_x": std[:, 0], "std_y": std[:, 1], "std_z": std[:, 2]}


@pytest.mark.parametrize("values, line, column, shown", [
    ([[0.02, 0.02, 0.02], [0.02, 0.0, 0.02], [-0.5, 0.02, 0.02], [0.02, 0.02, 0.02]], 3, "std_y", "0"),
    ([[0.02, 0.02, 0.02], [0.02, 0.02, 0.02], [0.02, 0.02, -0.5], [0.02, -0.3, 0.02]], 4, "std_z", "-0.5"),
    ([[0.02, 0.02, 0.02], [-0.1, 0.02, -0.2], [0.02, 0.02, 0.02], [0.02, 0.02, 0.02]], 3, "std_x", "-0.1")])
def test_the_first_row_with_a_deviation_of_zero_or_below_is_refused_naming_its_first_bad_column(values, line,
                                                                                                 column, shown):
    """A zero is no standard deviation; the first bad row (line), its first bad column and that column's value."""
    with pytest.raises(DataError, match=rf"^test.csv:{line}: column '{column}': {shown} is not a standard deviation"):
        _points(PLACES[:4], _std(values))


def test_stated_deviations_weigh_the_positions_by_their_root_mean_square_and_orientations_by_one():
    """Deviations 0.01, 0.02, 0.04 on x, y, z of two rows with the tool's orientation measured: the positions
    weigh rms / std (rms = sqrt(0.0007)), the six orientation residuals one; the spread stated is that rms."""
    angles = np.array([[10.0, 20.0, 30.0], [-5.0, 15.0, 0.0]])
    numbers = {**_std([[0.01, 0.02, 0.04]] * 2),
               "rx_meas": angles[:, 0], "ry_meas": angles[:, 1], "rz_meas": angles[:, 2]}
    points = _points(PLACES[:2], numbers)
    rms = np.sqrt(np.mean(np.array([0.01, 0.02, 0.04]) ** 2))
    residuals = points.residuals(PLACES[:2], TURNS[:2], np.zeros(3))
    assert residuals.values.size == 12 and residuals.turning.size == 12 and residuals.du.shape == (12, 3)
    weights = points.relative_weights(residuals)
    np.testing.assert_allclose(weights, np.r_[np.tile(rms / np.array([0.01, 0.02, 0.04]), 2), np.ones(6)], rtol=1e-12)
    assert points.stated_spread() == pytest.approx(rms, rel=1e-12)
    assert points.describe() == "2 tracker points in the base frame, 2 with the tool's orientation"


def test_an_orientation_with_an_angle_missing_is_refused_naming_the_missing_column():
    numbers = {"rx_meas": np.array([10.0, np.nan]), "ry_meas": np.array([20.0, 5.0]), "rz_meas": np.array([30.0, 7.0])}
    with pytest.raises(DataError, match=r"^test.csv:3: column 'rx_meas': a point row's orientation needs all of"):
        _points(PLACES[:2], numbers)
    numbers["rx_meas"][1], numbers["rz_meas"][1] = 1.0, np.nan
    with pytest.raises(DataError, match=r"^test.csv:3: column 'rz_meas': a point row's orientation needs all of"):
        _points(PLACES[:2], numbers)
    three = {"rx_meas": np.array([10.0, np.nan, 1.0, 4.0]), "ry_meas": np.array([20.0, 5.0, 2.0, 3.0]),
             "rz_meas": np.array([10.0, np.nan, 1.0, np.nan])}          # row 2 misses two angles, row 4 one
    with pytest.raises(DataError, match=r"^test.csv:3: column 'rx_meas': a point row's orientation needs all of"):
        _points(PLACES[:4], three)


def test_orientations_in_the_trackers_frame_are_refused_naming_the_first_row_with_one():
    angles = np.array([np.nan, 10.0, np.nan, 20.0])
    numbers = {"rx_meas": angles, "ry_meas": angles, "rz_meas": angles}
    with pytest.raises(DataError, match=r"^test.csv:3: columns 'rx_meas, ry_meas, rz_meas': a measured orientation is "
                                        r"read in the robot's base frame only"):
        _points(PLACES[:4], numbers, cell={TRACKER_FRAME: True})


def test_a_point_far_from_where_the_nominal_robot_puts_it_is_refused_saying_how_far():
    """Six points, the fourth (line 5) 150 mm off along y, the others 2 mm off: refused naming line 5 and 150 mm."""
    measured = PLACES + [0.0, 0.0, 2.0]
    measured[3, 1] += 150.0
    with pytest.raises(DataError, match=r"^test.csv:5: columns 'x_meas, y_meas, z_meas': the nominal robot puts this "
                                        r"point 150.0 mm away \(1 points beyond 100 mm\)"):
        _points(measured).unknowns(PLACES, TURNS)
    assert _points(PLACES + [0.0, 0.0, 2.0]).unknowns(PLACES, TURNS) == ([], pytest.approx(np.zeros(0)))


def _tracker_frame(points_in_base, turn_deg, shift_mm):
    """The same points as a tracker turned by ``turn_deg`` (a rotation vector) and shifted by ``shift_mm`` sees
    them: ``x = R^T (p - t)``."""
    rotation = Rotation.from_rotvec(np.radians(turn_deg)).as_matrix()
    return (points_in_base - shift_mm) @ rotation


@pytest.mark.parametrize("count", [2, 3])
def test_the_trackers_pose_starts_where_three_points_put_it_and_at_zero_below_three(count):
    """In the tracker's frame: three points fix its pose (the start is the pose they were put through); two leave
    it at zero, six values either way."""
    turn, shift = np.array([2.0, -3.0, 10.0]), np.array([2500.0, 100.0, -50.0])
    points = _points(_tracker_frame(PLACES[:count], turn, shift), cell={TRACKER_FRAME: True})
    names, start = points.unknowns(PLACES[:count], TURNS[:count])
    assert [n for n, _ in names] == ["tracker.x", "tracker.y", "tracker.z", "tracker.rx", "tracker.ry", "tracker.rz"]
    np.testing.assert_allclose(start, np.r_[shift, turn] if count == 3 else np.zeros(6), atol=1e-9)


@pytest.mark.parametrize("frame", ["base", "tracker"])
def test_a_further_targets_start_is_its_offset_on_the_flange_from_its_own_rows(frame):
    """Primary rows (four, the tool 100 mm along the flange's z), rows of target 'B1' (three, each name its own
    string) 41, 40 and 39 mm along the flange's y from the primary, and of target '1B' (a name sorting before the
    primary's 'A'; two rows, 30 mm along x): B1 starts at the median of its rows (0, 40, 100), 1B at (30, 0, 100), in
    the base frame or through the tracker's started pose; the probe's turn (two rows with the tool's orientation)
    starts at zero; each further row's residual is what its median leaves, turned with the tool."""
    tool = np.array([0.0, 0.0, 100.0])
    seen = np.array([[0.0, 41.0, 0.0], [0.0, 40.0, 0.0], [0.0, 39.0, 0.0], [30.0, 0.0, 0.0], [30.0, 0.0, 0.0]])
    q_turns = np.concatenate([TURNS[:4], TURNS[3:6], TURNS[1:3]])
    positions = np.vstack([PLACES[:4], PLACES[3:6], PLACES[1:3]])
    base = positions + np.vstack([np.zeros((4, 3)), np.einsum("nij,nj->ni", q_turns[4:], seen)])
    angles = np.full((9, 3), np.nan)
    angles[:2] = [[10.0, 20.0, 30.0], [-5.0, 15.0, 0.0]]
    numbers = {"rx_meas": angles[:, 0], "ry_meas": angles[:, 1], "rz_meas": angles[:, 2]}
    texts = {"target": ("", "A", "", "") + tuple(own_string("B1") for _ in range(3)) + tuple(own_string("1B") for _ in range(2))}
    turn, shift = np.array([2.0, -3.0, 10.0]), np.array([2500.0, 100.0, -50.0])
    if frame == "tracker":
        measured, cell, numbers = _tracker_frame(base, turn, shift), {TRACKER_FRAME: True}, {}
    else:
        measured, cell = base, {}
    points = _points(measured, numbers, texts, cell)
    points.tool_mm = tool
    names, start = points.unknowns(positions, q_turns)
    names = [n for n, _ in names]
    b = names.index("tool@B1.x")
    assert names[b:b + 6] == ["tool@B1.x", "tool@B1.y", "tool@B1.z", "tool@1B.x", "tool@1B.y", "tool@1B.z"]
    np.testing.assert_allclose(start[b:b + 6], [0.0, 40.0, 100.0, 30.0, 0.0, 100.0], atol=1e-9)
    if frame == "base":
        assert names[b + 6:] == ["probe.rx", "probe.ry", "probe.rz"] and list(start[b + 6:]) == [0.0, 0.0, 0.0]
        assert points.describe() == ("9 tracker points in the base frame, targets B1, 1B beside the primary, 2 with "
                                     "the tool's orientation")
        residuals = points.residuals(positions, q_turns, start)
        assert residuals.turn_grad.shape == (33, 3) and residuals.du.shape == (33, 9)
        miss = [[0.0, -1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        left = np.einsum("nij,nj->ni", q_turns[4:], miss)
        np.testing.assert_allclose(residuals.values[:27], np.r_[np.zeros(12), left.ravel()], atol=1e-9)


def test_the_trackers_pose_moves_with_the_cell_and_the_targets_stay_on_the_flange():
    """In the tracker's frame with a further target: a small turn w of the cell about the base origin and a shift t
    move the tracker's place by w x p + t and its rotation vector as composing exp(w) before it does (a finite
    difference of scipy's rotations); the target's offset on the flange does not move."""
    points = _points(_tracker_frame(PLACES[:4], [2.0, -3.0, 10.0], [2500.0, 100.0, -50.0]),
                     texts={"target": ("", "", "B1", "B1")}, cell={TRACKER_FRAME: True})
    u = np.array([2500.0, 100.0, -50.0, 2.0, -3.0, 10.0, 150.0, 40.0, 0.0])      # B1 150 mm out
    omega, shift = np.array([1e-7, -2e-7, 3e-7]), np.array([0.5, -0.25, 1.0])
    moved = points.moved(u, omega, shift)
    np.testing.assert_allclose(moved[:3], np.cross(omega, u[:3]) + shift, rtol=1e-12)
    turned = (Rotation.from_rotvec(omega) * Rotation.from_rotvec(np.radians(u[3:6]))).as_rotvec()
    np.testing.assert_allclose(moved[3:6], np.degrees(turned) - u[3:6], rtol=1e-5)
    assert list(moved[6:]) == [0.0, 0.0, 0.0]


def test_target_names_are_read_as_text_and_the_parameters_targets_add_are_named_in_order(tmp_path):
    """A file's target column keeps its names as text ('B', '12'); what the targets add to the robot's parameters:
    each target's three offsets, then the probe's turn only with an orientation."""
    from partcal.calibration.tracker_points import target_parameters
    from partcal.data.measurement_rows import read_measurement_rows
    path = tmp_path / "m.csv"
    path.write_text("q1,q2,q3,q4,q5,q6,measurement,x_meas,y_meas,z_meas,target\n0,0,0,0,0,0,point,1,2,3,B\n"
                    "0,0,0,0,0,0,point,1,2,3,12\n")
    assert read_measurement_rows(path).texts["target"] == ("B", "12")
    tools = {"B": [0.0, 40.0, 0.0], "C": [10.0, 0.0, 5.0]}
    assert [n for n, _ in target_parameters(tools, False)] == ["tool@B.x", "tool@B.y", "tool@B.z", "tool@C.x",
                                                               "tool@C.y", "tool@C.z"]
    assert [n for n, _ in target_parameters(tools, True)][6:] == ["probe.rx", "probe.ry", "probe.rz"]


def test_two_rows_with_a_further_target_give_their_residuals_every_gradient():
    """Two rows only (a turn gradient of six rows, not of 3 - n): target B's rows' turn gradients are -[R d]x."""
    offset = np.array([0.0, 40.0, 0.0])
    measured = PLACES[:2] + np.einsum("nij,j->ni", TURNS[:2], offset)
    points = _points(measured, texts={"target": ("B", "B")})
    residuals = points.residuals(PLACES[:2], TURNS[:2], offset)
    np.testing.assert_allclose(residuals.values, 0.0, atol=1e-9)
    lever = TURNS[0] @ offset
    np.testing.assert_allclose(residuals.turn_grad[:3], -np.array([[0, -lever[2], lever[1]], [lever[2], 0, -lever[0]],
                                                                   [-lever[1], lever[0], 0]]), atol=1e-12)


def test_the_nominal_values_of_targets_and_the_probe():
    """The targets' offsets as given, then three zeros for the probe's turn when an orientation is measured."""
    tools = {"B": [0.0, 40.0, 0.0], "C": [10.0, 0.0, 5.0]}
    np.testing.assert_array_equal(target_nominal(tools, True), [0.0, 40.0, 0.0, 10.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(target_nominal(tools, False), [0.0, 40.0, 0.0, 10.0, 0.0, 5.0])


def test_points_in_the_base_frame_fix_the_frame_for_a_residual_model_and_points_in_the_trackers_frame_do_not():
    """A kinematic model with a residual model: fitted on tracker points in the base frame (they fix it: no frame
    note); refused on the same points in the tracker's frame, which fix no frame (the residual would learn the
    registration)."""
    from partcal import load_robot
    from partcal.models.kinematic import KinematicModel
    from partcal.models.series import ErrorModel
    robot = load_robot("universal_robots_ur10")
    rng = np.random.default_rng(21)
    q = np.array([-90, -150, -140, -180, -150, -180.0]) + [180, 120, 280, 360, 300, 360.0] * rng.random((40, 6))
    seen = robot.positions(q) + rng.normal(0.0, 0.02, (40, 3))
    n = len(q)

    def rows(measured):
        columns = {"x_meas": measured[:, 0], "y_meas": measured[:, 1], "z_meas": measured[:, 2]}
        return MeasurementRows(q, ("point",) * n, tuple(str(i + 1) for i in range(n)), tuple(range(2, n + 2)),
                               "test.csv", columns)

    model = KinematicModel(robot=robot, parametrization="dh", residual=ErrorModel(solver="lstsq"))
    model.fit(q, None, rows=rows(seen), cell={})
    assert model.frame_fixed_ and not any("fix no frame" in note for note in model.fit_notes())
    with pytest.raises(DataError, match=r"their points are in the tracker's frame"):
        in_tracker = rows(_tracker_frame(seen, [2.0, -3.0, 10.0], [2500.0, 100.0, -50.0]))
        KinematicModel(robot=robot, parametrization="dh", residual=ErrorModel(solver="lstsq")).fit(
            q, None, rows=in_tracker, cell={TRACKER_FRAME: True})
