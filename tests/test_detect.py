"""Images in: boards rendered for a virtual robot (partcal/data/boards.py) and detected in a folder of images with a
joints CSV (partcal/data/detect.py), scored against the true pixels (cv2.projectPoints of the true poses)."""

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from partcal.data.boards import camera_rays, pattern, render_folder, render_view
from partcal.data.detect import detect_board, detect_folder, write_pixel_rows
from partcal.data.measurement_rows import read_measurement_rows
from partcal.errors import DataError
from partcal.robot.description import load_robot

CAMERA = {"image_size": [800, 600], "intrinsics": [700.0, 700.0, 400.0, 300.0, -0.08, 0.03, 0.0004, -0.0003, 0.0]}
BOARDS = {"charuco": {"type": "charuco", "rows": 6, "cols": 8, "square_mm": 40.0, "marker_mm": 30.0},
          "chessboard": {"type": "chessboard", "rows": 6, "cols": 9, "square_mm": 25.0},
          "apriltag": {"type": "apriltag", "rows": 4, "cols": 6, "square_mm": 40.0, "marker_mm": 30.0}}


def _views(board: dict, count: int, seed: int = 0):
    """Board poses in the camera's frame (the board ~700 mm away, turned up to 35 degrees) and joints for them."""
    rng = np.random.default_rng(seed)
    centre = np.array([board["cols"], board["rows"], 0.0]) * board["square_mm"] / 2
    poses = []
    for _ in range(count):
        rotation = Rotation.from_rotvec(rng.uniform(-0.6, 0.6, 3) * [1, 1, 0.5]).as_matrix()
        pose = np.eye(4)
        pose[:3, :3] = rotation
        pose[:3, 3] = [rng.uniform(-40, 40), rng.uniform(-30, 30), rng.uniform(650, 800)] - rotation @ centre
        poses.append(pose)
    q = rng.uniform(-90, 90, (count, 6))
    return np.array(poses), q


def _truth(board: dict, pose: np.ndarray) -> np.ndarray:
    s, rows, cols = board["square_mm"], board["rows"], board["cols"]
    if board["type"] == "apriltag":              # tag t = r cols + c centred in its square; TL, TR, BR, BL
        h = board["marker_mm"] / 2
        local = np.array([[(c + 0.5) * s + dx * h, (r + 0.5) * s + dy * h, 0.0] for r in range(rows)
                          for c in range(cols) for dx, dy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    else:
        r, c = np.divmod(np.arange((rows - 1) * (cols - 1)), cols - 1)
        local = np.column_stack([(c + 1) * s, (r + 1) * s, np.zeros(r.size)])
    k = CAMERA["intrinsics"]
    matrix = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
    rvec = Rotation.from_matrix(pose[:3, :3]).as_rotvec()
    return cv2.projectPoints(local, rvec, pose[:3, 3], matrix, np.array(k[4:]))[0][:, 0]


@pytest.mark.parametrize("kind", ["charuco", "chessboard", "apriltag"])
def test_rendered_boards_are_detected_within_a_tenth_of_a_pixel(kind, tmp_path):
    board = BOARDS[kind]
    poses, q = _views(board, 4 if kind != "apriltag" else 6)      # the tags' sixth view: tags 22 px wide
    render_folder(tmp_path, CAMERA, board, poses, q, np.random.default_rng(1))
    found = detect_folder(tmp_path, tmp_path / "joints.csv", load_robot("universal_robots_ur10"), board, "cam1",
                          "b1", image_size=(800, 600))
    assert found.not_found == [] and found.warnings == []
    rows = found.rows
    errors = []
    for k, pose in enumerate(poses):
        mine = np.flatnonzero(np.array(rows.texts["image"]) == f"image_{k + 1:04d}.png")
        assert np.allclose(rows.q_deg[mine], q[k])
        truth = _truth(board, pose)
        ids = rows.numbers["point"][mine].astype(int)
        assert ids.size == truth.shape[0]                          # every corner in view found
        errors.append(np.column_stack([rows.numbers["u_px"][mine], rows.numbers["v_px"][mine]]) - truth[ids])
    rms = np.sqrt(np.mean(np.sum(np.vstack(errors) ** 2, axis=1)))
    assert rms < (0.1 if kind != "apriltag" else 0.05), rms      # tags: 0.041 px


def test_an_image_without_the_board_is_named_and_shifts_no_pairing(tmp_path):
    board = BOARDS["charuco"]
    poses, q = _views(board, 3, seed=2)
    poses[1][:3, 3] += [5000.0, 0.0, 0.0]                        # the board out of view
    render_folder(tmp_path, CAMERA, board, poses, q, np.random.default_rng(3))
    found = detect_folder(tmp_path, tmp_path / "joints.csv", load_robot("universal_robots_ur10"), board, "cam1")
    assert found.not_found == ["image_0002.png"]
    assert any("image_0002.png: no board found" in w for w in found.warnings)
    for k in (0, 2):
        mine = np.array(found.rows.texts["image"]) == f"image_{k + 1:04d}.png"
        assert mine.any() and np.allclose(found.rows.q_deg[mine], q[k])
    write_pixel_rows(found, tmp_path / "pixels.csv")
    back = read_measurement_rows(tmp_path / "pixels.csv")
    assert back.types[0] == "camera" and len(back) == len(found.rows)


def test_a_blurred_tag_grid_is_named_and_a_tag_of_the_family_outside_the_grid_is_no_point(tmp_path):
    """A tag grid rendered blurred over half a cell: its tags are read but their corners cannot be fitted, and the
    image is named (warned, and left out) instead of giving corners a pixel off. A 2 x 3 grid's detector reading an
    image of the 4 x 6 grid (the same family's tags 0-23): only tags 0-5 are its points (ids 0-23)."""
    board = BOARDS["apriltag"]
    poses, q = _views(board, 1, seed=6)
    rays, texture = camera_rays(CAMERA), pattern(board)
    cv2.imwrite(str(tmp_path / "sharp.png"), render_view(rays, texture, poses[0], np.random.default_rng(7)))
    cv2.imwrite(str(tmp_path / "blurred.png"), render_view(rays, texture, poses[0], np.random.default_rng(7),
                                                           blur=1.6))
    (tmp_path / "joints.csv").write_text("image,q1,q2,q3,q4,q5,q6\nsharp.png,0,0,0,0,0,0\nblurred.png,1,0,0,0,0,0\n")
    found = detect_folder(tmp_path, tmp_path / "joints.csv", load_robot("universal_robots_ur10"), board, "cam1")
    assert found.not_found == ["blurred.png"]
    assert any("blurred.png: tags" in w and "not fitted" in w for w in found.warnings)
    assert set(found.rows.texts["image"]) == {"sharp.png"} and len(found.rows) == 96
    small = {**board, "rows": 2, "cols": 3}
    ids, uv = detect_board(cv2.imread(str(tmp_path / "sharp.png"), cv2.IMREAD_GRAYSCALE), small)
    assert ids.tolist() == list(range(24))
    assert np.allclose(uv, _truth(board, poses[0])[:24], atol=0.3)      # tags 0-5 of the big grid: rows 0, cols 0-2


def test_a_half_turn_symmetric_chessboard_is_warned(tmp_path):
    board = {"type": "chessboard", "rows": 6, "cols": 8, "square_mm": 25.0}
    poses, q = _views(board, 1, seed=4)
    render_folder(tmp_path, CAMERA, board, poses, q, np.random.default_rng(5))
    found = detect_folder(tmp_path, tmp_path / "joints.csv", load_robot("universal_robots_ur10"), board, "cam1")
    assert any("looks the same turned half a turn" in w for w in found.warnings)


def _folder(tmp_path, joints: str, images=("a.png", "b.png")):
    for name in images:
        cv2.imwrite(str(tmp_path / name), np.full((60, 80), 128, np.uint8))
    (tmp_path / "joints.csv").write_text(joints)
    return tmp_path / "joints.csv"


@pytest.mark.parametrize("joints, images, message", [
    ("image,q1,q2,q3,q4,q5,q6\na.png,0,0,0,0,0,0\nb.png,0,0,0,0,0,0\nc.png,0,0,0,0,0,0\n", ("a.png", "b.png"),
     r"joints.csv:4: column 'image': 'c.png' is not an image of "),
    ("image,q1,q2,q3,q4,q5,q6\na.png,0,0,0,0,0,0\n", ("a.png", "b.png"),
     r"b.png: no row of .*joints.csv names this image"),
    ("image,q1,q2,q3,q4,q5\na.png,0,0,0,0,0\n", ("a.png",),
     r"joints.csv:1: columns q1, q2, q3, q4, q5: expected the 6 joints of universal_robots_ur10"),
    ("image,q1,q2,q3,q4,q5,q6\na.png,0,0,x,0,0,0\n", ("a.png",), r"joints.csv:2: column 'q3': expected a joint angle"),
])
def test_bad_joints_or_images_are_refused_naming_file_line_and_field(tmp_path, joints, images, message):
    path = _folder(tmp_path, joints, images)
    with pytest.raises(DataError, match=message):
        detect_folder(tmp_path, path, load_robot("universal_robots_ur10"), BOARDS["charuco"], "cam1")


def test_an_image_of_another_size_than_the_cameras_is_refused(tmp_path):
    path = _folder(tmp_path, "image,q1,q2,q3,q4,q5,q6\na.png,0,0,0,0,0,0\n", ("a.png",))
    with pytest.raises(DataError, match=r"a.png: 80 x 60 pixels; camera 'cam1''s image_size is 800 x 600"):
        detect_folder(tmp_path, path, load_robot("universal_robots_ur10"), BOARDS["charuco"], "cam1",
                      image_size=(800, 600))


CELL = """cameras:
  cam1: {mount: cell, image_size: [800, 600]}
boards:
  b1: {type: charuco, rows: 6, cols: 8, square_mm: 40, marker_mm: 30}
"""


def test_partcal_detect_writes_the_camera_rows_of_a_folder_and_names_an_image_without_the_board(tmp_path, capsys):
    """The command reads the board and the image size from the cell: the rows it writes are the true pixels
    (cv2.projectPoints of the true poses) within 0.1 px, each image with its own joints, the empty one named."""
    from partcal.cli import main
    board = BOARDS["charuco"]
    poses, q = _views(board, 3, seed=6)
    poses[0][:3, 3] += [5000.0, 0.0, 0.0]                        # the first image sees no board
    render_folder(tmp_path / "images", CAMERA, board, poses, q, np.random.default_rng(7))
    (tmp_path / "cell.yaml").write_text(CELL)
    args = ["detect", str(tmp_path / "images"), "--joints", str(tmp_path / "images" / "joints.csv"), "--cell",
            str(tmp_path / "cell.yaml"), "--robot", "universal_robots_ur10", "-o", str(tmp_path / "pixels.csv")]
    assert main(args) == 0
    out = capsys.readouterr()
    assert "no board found in 1 images (left out): image_0001.png" in out.out
    rows = read_measurement_rows(tmp_path / "pixels.csv")
    assert set(rows.texts["camera"]) == {"cam1"} and set(rows.texts["board"]) == {"b1"}
    assert set(rows.texts["image"]) == {"image_0002.png", "image_0003.png"}
    errors = []
    for k in (1, 2):
        mine = np.flatnonzero(np.array(rows.texts["image"]) == f"image_{k + 1:04d}.png")
        np.testing.assert_allclose(rows.q_deg[mine], np.repeat(q[k][None], mine.size, axis=0), atol=1e-9)
        uv = np.column_stack([rows.numbers["u_px"][mine], rows.numbers["v_px"][mine]])
        errors.append(uv - _truth(board, poses[k])[rows.numbers["point"][mine].astype(int)])
    assert np.sqrt(np.mean(np.sum(np.vstack(errors) ** 2, axis=1))) < 0.1


@pytest.mark.parametrize("cell, extra, message", [
    (CELL.replace("boards:", "  cam2: {mount: flange, image_size: [800, 600]}\nboards:"), [],
     r"cell.yaml: cameras: 2 entries \(cam1, cam2\); expected one, or name it with --camera"),
    (CELL, ["--board", "b9"], r"--board b9: not among .*cell.yaml's boards: \(b1\)"),
    (CELL.replace(", square_mm: 40", ""), [], r"cell.yaml.*square_mm"),
])
def test_partcal_detect_refuses_a_camera_or_board_it_cannot_choose(tmp_path, capsys, cell, extra, message):
    from partcal.cli import main
    path = _folder(tmp_path, "image,q1,q2,q3,q4,q5,q6\na.png,0,0,0,0,0,0\n", ("a.png",))
    (tmp_path / "cell.yaml").write_text(cell)
    code = main(["detect", str(tmp_path), "--joints", str(path), "--cell", str(tmp_path / "cell.yaml"), "--robot",
                 "universal_robots_ur10", "-o", str(tmp_path / "pixels.csv"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    import re
    assert re.search(message, err), err
    assert not (tmp_path / "pixels.csv").exists()
