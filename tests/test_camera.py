"""The camera measurement type: OpenCV's projection, the residuals' derivatives, the start's closed forms and the
refusals of bad input (partcal/calibration/camera.py, camera_model.py)."""

import cv2
import numpy as np
import pytest

from partcal.calibration.camera import CameraPoints
from partcal.calibration.camera_cell import half_turn_symmetric
from partcal.calibration.camera_model import (board_points, focal_from_homographies, homography, pose_from_homography,
                                              pose_matrix, pose_values, project, solve_ax_yc, undistorted)
from partcal.calibration.measurement import MeasurementRows
from partcal.calibration.registry import built_types
from partcal.data.measurement_rows import read_cell
from partcal.errors import ConfigError, DataError
from scipy.spatial.transform import Rotation

INTRINSICS = np.array([1450.0, 1420.0, 955.0, 610.0, -0.12, 0.07, 0.0006, -0.0004, -0.015])


def test_projection_matches_opencv_project_points():
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-400, 400, (200, 2)), rng.uniform(500, 1500, 200)])
    ours = project(points, INTRINSICS)[0]
    k = np.array([[INTRINSICS[0], 0, INTRINSICS[2]], [0, INTRINSICS[1], INTRINSICS[3]], [0, 0, 1.0]])
    theirs = cv2.projectPoints(points, np.zeros(3), np.zeros(3), k, INTRINSICS[4:])[0][:, 0]
    assert np.max(np.abs(ours - theirs)) < 1e-9


def test_projection_derivatives_match_central_differences():
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-300, 300, (20, 2)), rng.uniform(600, 1200, 20)])
    _, by_point, by_k = project(points, INTRINSICS)
    for j in range(3):
        step = np.zeros(3)
        step[j] = 1e-4
        numeric = (project(points + step, INTRINSICS)[0] - project(points - step, INTRINSICS)[0]) / 2e-4
        assert np.allclose(by_point[:, :, j], numeric, atol=1e-6)
    for j in range(9):
        step = np.zeros(9)
        step[j] = 1e-6 * max(abs(INTRINSICS[j]), 1.0)
        numeric = (project(points, INTRINSICS + step)[0] - project(points, INTRINSICS - step)[0]) / (2 * step[j])
        assert np.allclose(by_k[:, :, j], numeric, atol=1e-4)


def _cell(mount: str, fit: bool = True) -> dict:
    return {"cameras": {"c1": {"mount": mount, "fit_intrinsics": fit, "image_size": [1920, 1200],
                               "intrinsics": INTRINSICS.tolist()}},
            "boards": {"b1": {"type": "charuco", "rows": 5, "cols": 6, "square_mm": 40.0, "marker_mm": 30.0}}}


def _rows(n_images: int, points: np.ndarray, uv: np.ndarray) -> MeasurementRows:
    per = points.size
    m = n_images * per
    return MeasurementRows(np.zeros((m, 6)), ("camera",) * m, tuple(str(i) for i in range(m)),
                           tuple(range(2, m + 2)), "rows.csv",
                           {"point": np.tile(points, n_images).astype(float), "u_px": uv[:, 0], "v_px": uv[:, 1]},
                           {"image": tuple(f"i{i // per}" for i in range(m)), "camera": ("c1",) * m,
                            "board": ("b1",) * m})


@pytest.mark.parametrize("mount", ["cell", "flange"])
def test_residual_derivatives_match_central_differences(mount):
    rng = np.random.default_rng(3)
    points = np.arange(0, 20, 3)
    n = 4
    rows = _rows(n, points, rng.uniform(100, 1000, (n * points.size, 2)))
    camera = built_types(rows, _cell(mount))[0]
    camera._layout()
    u = np.zeros(len(camera.names_units))
    u[0:6] = [1500, 200, 800, -70, -95, 70] if mount == "cell" else [5, 60, 40, 3, -4, 88]
    u[6:15] = INTRINSICS
    u[15:21] = [-100, 90, 30, 178, 3, 2] if mount == "cell" else [600, 150, 10, 179, 2, 1]
    camera.tool_mm = np.array([1.0, -2.0, 150.0])
    positions = rng.uniform(-50, 50, (len(rows), 3)) + [800, 0, 600]
    rotations = Rotation.from_rotvec(rng.normal(0, 0.2, (len(rows), 3)) + [np.pi, 0, 0]).as_matrix()
    r = camera.residuals(positions, rotations, u)

    def values(p=positions, rot=rotations, uu=u, tool=None):
        camera.tool_mm = np.array([1.0, -2.0, 150.0]) if tool is None else tool
        return camera.residuals(p, rot, uu).values

    row = r.rows_a
    for j in range(3):
        step = np.zeros(3)
        step[j] = 1e-4
        numeric = (values(positions + step) - values(positions - step)) / 2e-4
        assert np.allclose(r.grad_a[:, j], numeric, atol=1e-5 * np.abs(numeric).max())
        turn = Rotation.from_rotvec(step * 10).as_matrix()
        numeric = (values(rot=turn @ rotations) - values(rot=turn.T @ rotations)) / 2e-3
        assert np.allclose(r.turn_grad[:, j], numeric, rtol=1e-4, atol=1e-4 * np.abs(numeric).max())
        numeric = (values(tool=[1.0, -2.0, 150.0] + step) - values(tool=[1.0, -2.0, 150.0] - step)) / 2e-4
        assert np.allclose(r.tool_grad[:, j], numeric, atol=1e-5 * np.abs(numeric).max())
    for j in range(u.size):
        step = np.zeros(u.size)
        step[j] = 1e-6 * max(abs(u[j]), 1.0)
        numeric = (values(uu=u + step) - values(uu=u - step)) / (2 * step[j])
        assert np.allclose(r.du[:, j], numeric, atol=1e-4 * max(np.abs(numeric).max(), 1e-3)), j
    assert np.array_equal(row, np.repeat(np.arange(len(rows)), 2))


def test_homography_pose_and_focal_recover_a_view():
    board = board_points({"type": "chessboard", "rows": 7, "cols": 10, "square_mm": 25.0})
    rng = np.random.default_rng(4)
    views, truth = [], []
    for _ in range(5):
        pose = pose_matrix([rng.uniform(-100, 100), rng.uniform(-100, 100), rng.uniform(700, 1000),
                            *rng.uniform(-30, 30, 3)])
        cam = board @ pose[:3, :3].T + pose[:3, 3]
        uv = cam[:, :2] / cam[:, 2:]
        views.append(homography(board[:, :2], uv * 1400.0))
        truth.append(pose)
        assert np.allclose(pose_from_homography(homography(board[:, :2], uv)), pose, atol=1e-6)
    assert focal_from_homographies(views) == pytest.approx(1400.0, rel=1e-6)


def test_a_negated_homography_gives_the_same_pose_in_front_of_the_camera_and_flat_views_no_focal():
    """A homography is known up to its sign: -H gives the pose with the board in front (z > 0). Views square to
    the optical axis say nothing of the focal length (Zhang's constraints vanish): None, not a guess."""
    board = board_points({"type": "chessboard", "rows": 5, "cols": 6, "square_mm": 30.0})
    pose = pose_matrix([40.0, -25.0, 800.0, 10.0, -20.0, 5.0])
    cam = board @ pose[:3, :3].T + pose[:3, 3]
    h = homography(board[:, :2], cam[:, :2] / cam[:, 2:])
    assert np.allclose(pose_from_homography(-h), pose, atol=1e-6)
    tiny = pose.copy()
    tiny[:3, 3] /= 2000.0                                     # the same view of a board 2000 times smaller: z 0.4
    cam = board / 2000.0 @ tiny[:3, :3].T + tiny[:3, 3]
    h = homography(board[:, :2] / 2000.0, cam[:, :2] / cam[:, 2:])
    assert np.allclose(pose_from_homography(h), tiny, atol=1e-9)
    assert np.allclose(pose_from_homography(-h), tiny, atol=1e-9)
    flat = [np.array([[1400.0, 0.0, 1400.0 * x], [0.0, 1400.0, 1400.0 * y], [0.0, 0.0, z]])   # K [r1 r2 t], R = I
            for x, y, z in ((0.0, 0.0, 900.0), (30.0, -20.0, 800.0))]
    assert focal_from_homographies(flat) is None


def test_pose_values_and_pose_matrix_are_each_others_inverse():
    """x, y, z mm and a rotation vector in degrees, to a pose and back (and the pose's parts read by hand: a turn
    of 90 degrees about z)."""
    values = [12.5, -40.0, 700.0, 20.0, -35.0, 50.0]
    assert np.allclose(pose_values(pose_matrix(values)), values, atol=1e-9)
    turn = pose_matrix([1.0, 2.0, 3.0, 0.0, 0.0, 90.0])
    assert np.allclose(turn, [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], atol=1e-12)
    assert np.allclose(pose_values(turn), [1.0, 2.0, 3.0, 0.0, 0.0, 90.0], atol=1e-9)


def test_undistorted_inverts_the_projection_as_opencv_does():
    """Pixels of a camera with distortion (k1 -0.25: a wide lens) back to normalised coordinates: the points' own
    x/Z, y/Z to 1e-9, and cv2.undistortPoints' answer (a second method)."""
    k = np.array([1200.0, 1180.0, 640.0, 500.0, -0.25, 0.08, 0.001, -0.0007, -0.01])
    rng = np.random.default_rng(2)
    points = np.column_stack([rng.uniform(-300, 300, 50), rng.uniform(-250, 250, 50), rng.uniform(700, 900, 50)])
    uv = project(points, k)[0]
    back = undistorted(uv, k, steps=60)
    assert np.allclose(back, points[:, :2] / points[:, 2:], atol=1e-9)
    matrix = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
    theirs = cv2.undistortPointsIter(uv.reshape(-1, 1, 2), matrix, k[4:], None, None,
                                     (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15))[:, 0]
    assert np.allclose(back, theirs, atol=1e-7)


def test_apriltag_grid_points_are_each_tags_corners_in_opencvs_order():
    """Tag t = r cols + c centred in square (r, c) of the grid, its black border marker_mm wide: ids 4 t + k at the
    top left, top right, bottom right, bottom left (worked by hand for a 2 x 3 grid at 50 mm, tags 40 mm)."""
    points = board_points({"type": "apriltag", "rows": 2, "cols": 3, "square_mm": 50.0, "marker_mm": 40.0})
    assert points.shape == (24, 3)
    assert points[4 * 0:4 * 0 + 4, :2].tolist() == [[5.0, 5.0], [45.0, 5.0], [45.0, 45.0], [5.0, 45.0]]
    assert points[4 * 5:4 * 5 + 4, :2].tolist() == [[105.0, 55.0], [145.0, 55.0], [145.0, 95.0], [105.0, 95.0]]
    assert points[4 * 1, :2].tolist() == [55.0, 5.0] and np.all(points[:, 2] == 0.0)


def test_ax_yc_recovers_both_poses():
    rng = np.random.default_rng(5)
    x = pose_matrix([10, -20, 30, 5, 170, -20])
    y = pose_matrix([1500, 200, 800, -70, -95, 70])
    a = np.array([pose_matrix([*rng.uniform(-500, 500, 3), *rng.uniform(-120, 120, 3)]) for _ in range(6)])
    c = np.linalg.inv(y) @ a @ x
    got_x, got_y = solve_ax_yc(a, c)
    assert np.allclose(got_x, x, atol=1e-6) and np.allclose(got_y, y, atol=1e-6)


def test_board_points_follow_opencv_charuco_ids():
    board = cv2.aruco.CharucoBoard((6, 5), 40.0, 30.0, cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50))
    theirs = np.asarray(board.getChessboardCorners())
    ours = board_points({"type": "charuco", "rows": 5, "cols": 6, "square_mm": 40.0, "marker_mm": 30.0})
    assert np.allclose(ours, theirs)


def test_half_turn_symmetry_of_chessboards():
    assert half_turn_symmetric({"type": "chessboard", "rows": 8, "cols": 10})
    assert half_turn_symmetric({"type": "chessboard", "rows": 7, "cols": 9})
    assert not half_turn_symmetric({"type": "chessboard", "rows": 7, "cols": 10})
    assert not half_turn_symmetric({"type": "charuco", "rows": 8, "cols": 10})


def test_a_board_without_sizes_is_refused_naming_file_and_field(tmp_path):
    path = tmp_path / "cell.yaml"
    path.write_text("cameras:\n  c1: {mount: cell, image_size: [640, 480]}\nboards:\n"
                    "  b1: {type: charuco, rows: 5, cols: 7}\n")
    with pytest.raises(ConfigError, match=rf"{path}: boards.b1 \(line 4\): missing required key 'square_mm'"):
        read_cell(path)
    path.write_text("cameras:\n  c1: {mount: cell, image_size: [640, 480]}\nboards:\n"
                    "  b1: {type: charuco, rows: 5, cols: 7, square_mm: 30}\n")
    with pytest.raises(ConfigError, match=r"boards.b1 \(line 4\): missing required key 'marker_mm'"):
        read_cell(path)


@pytest.mark.parametrize("family, message", [
    ("36h12", r"boards.b1.family \(line 4\): must be one of 36h11, 36h10, 25h9, 16h5; got '36h12'"),
    ("16h5", r"boards.b1.family \(line 4\): must be a family of 42 tags or more \(a grid of 6 x 7; it has 30\); "
             r"got '16h5'"),
])
def test_an_apriltag_family_that_cannot_hold_the_grid_is_refused(tmp_path, family, message):
    path = tmp_path / "cell.yaml"
    path.write_text("cameras:\n  c1: {mount: cell, image_size: [640, 480]}\nboards:\n"
                    f"  b1: {{type: apriltag, rows: 6, cols: 7, square_mm: 30, marker_mm: 24, family: '{family}'}}\n")
    with pytest.raises(ConfigError, match=message):
        read_cell(path)


def test_known_intrinsics_are_required_where_they_are_not_fitted(tmp_path):
    path = tmp_path / "cell.yaml"
    path.write_text("cameras:\n  c1: {mount: cell, image_size: [640, 480], fit_intrinsics: false}\n")
    with pytest.raises(ConfigError, match=r"cameras.c1.intrinsics: is required with fit_intrinsics: false"):
        read_cell(path)


def test_a_pixel_outside_the_image_is_refused_naming_file_line_and_column():
    uv = np.full((7, 2), 300.0)
    uv[4, 1] = 1250.0
    rows = _rows(1, np.arange(7), uv)
    with pytest.raises(DataError, match=r"rows.csv:6: column 'v_px': 1250 lies outside camera 'c1''s image; "
                                        r"expected a pixel in \[0, 1200\]"):
        built_types(rows, _cell("cell"))


def test_a_point_the_board_lacks_and_an_unknown_camera_are_refused():
    rows = _rows(1, np.array([0, 1, 20]), np.full((3, 2), 300.0))
    with pytest.raises(DataError, match=r"rows.csv:4: column 'point': 20 is not a point of board 'b1' .*ids 0 to 19"):
        built_types(rows, _cell("cell"))
    cell = _cell("cell")
    cell["cameras"] = {"other": cell["cameras"]["c1"]}
    with pytest.raises(DataError, match=r"rows.csv:2: column 'camera': 'c1' is not a camera of the cell \(other\)"):
        CameraPoints(_rows(1, np.arange(3), np.full((3, 2), 300.0)), np.arange(3), cell, 0.2)
