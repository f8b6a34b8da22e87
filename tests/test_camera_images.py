"""From images to the hand-eye: board images of a virtual robot rendered (partcal/data/boards.py), the board
detected in them with the joints CSV (partcal/data/detect.py), and the robot, the camera, the board and the
intrinsics identified from the detected pixels (eye-to-hand), scored against the simulation's truth."""

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from partcal.calibration.camera_cell import MARGIN_PX, seen_points, true_cell
from partcal.calibration.camera_model import board_points
from partcal.calibration.stacked import identify_measurements
from partcal.data.boards import render_folder
from partcal.data.detect import detect_folder
from partcal.data.sampling import sample_configurations
from partcal.data.simulate import load_study

VIRTUAL = """robot: universal_robots_ur10
seed: 5
output: data
errors:
  dh_sigma: {length_mm: 0.5, twist_deg: 0.03, zero_offset_deg: 0.05}
  tool_mm: [0.3, -0.2, 0.4]
  base: {rotation_deg: [0.02, -0.03, 0.04], translation_mm: [1.0, -0.5, 0.8]}
tracker: {position_mm: [2500, 0, 0], accuracy_ppm: 0, repeatability_ppm: 10, readings: 1}
sampling:
  ranges_deg: {q1: [-40, 40], q2: [-150, -30], q3: [-140, 140], q4: [-180, 180], q5: [-150, 150], q6: [-180, 180]}
cell:
  cameras:
    cam1: {mount: cell, image_size: [960, 600], pose: [1900.0, 300.0, 900.0, -73.4542, -96.1699, 68.1777],
           intrinsics: {fx: 750, fy: 750, cx: 480, cy: 300, k1: -0.1, k2: 0.05, p1: 0.0005, p2: -0.0003}}
  boards:
    b1: {type: charuco, rows: 8, cols: 11, square_mm: 50, marker_mm: 38, pose: [-275, 200, 30, 178, 3, 2]}
datasets:
  test: {sample: 10}
"""


def _pose(values) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(values[3:], degrees=True).as_matrix()
    out[:3, 3] = values[:3]
    return out


def test_rendered_images_of_a_virtual_robot_give_its_hand_eye(tmp_path):
    (tmp_path / "virtual.yaml").write_text(VIRTUAL)
    study = load_study(tmp_path / "virtual.yaml")
    cameras, boards = true_cell(study.cell.sections)
    camera, board = cameras["cam1"], boards["b1"]
    q = sample_configurations(study.robot.nominal, 3000, study.ranges_deg, study.fixed_deg,
                              np.random.default_rng(6))
    flange_mm, flange_rot = study.robot.true_flange(q)
    seen, uv = seen_points(camera, board, flange_mm, flange_rot, board_points(board))
    span = np.ptp(uv[..., 0], axis=1)
    keep = np.flatnonzero(seen.all(axis=1) & (span > 300))[:12]     # the whole board in view, 300 px wide or more
    flanges = np.tile(np.eye(4), (keep.size, 1, 1))
    flanges[:, :3, :3], flanges[:, :3, 3] = flange_rot[keep], flange_mm[keep]
    in_camera = np.linalg.inv(_pose(camera["pose"])) @ flanges @ _pose(board["pose"])
    render_folder(tmp_path / "images", camera, board, in_camera, q[keep], np.random.default_rng(7))

    found = detect_folder(tmp_path / "images", tmp_path / "images" / "joints.csv", study.robot.nominal, board, "cam1",
                          "b1", image_size=(960, 600))
    assert found.not_found == []
    cell = {"cameras": {"cam1": {"mount": "cell", "image_size": [960, 600], "fit_intrinsics": True}},
            "boards": {"b1": {k: v for k, v in board.items() if k != "pose"}}, "noise": {"camera": 0.1}}
    table, _ = identify_measurements(study.robot.nominal, found.rows, cell)
    value = dict(zip(table.names, table.value))
    assert table.target_rms_mm["camera"] < 0.15                         # the detection's own error, px
    fitted = _pose([value[f"board b1@flange.{c}"] for c in ("x", "y", "z", "rx", "ry", "rz")])
    true, nominal = study.robot.true, study.robot.nominal
    last = {k: np.r_[getattr(true, k)[:-1], getattr(nominal, k)[-1]]
            for k in ("alpha_deg", "d_mm", "a_mm", "theta_offset_deg")}
    expected = np.linalg.inv(true.replace(**last).flange(q[:1])[0]) @ true.flange(q[:1])[0] @ _pose(board["pose"])
    assert np.linalg.norm(expected[:3, 3] - fitted[:3, 3]) < 0.3        # 0.03 mm seen with 16 images
    assert Rotation.from_matrix(expected[:3, :3].T @ fitted[:3, :3]).magnitude() < np.radians(0.05)
    k = [value[f"camera cam1.{c}"] for c in ("fx", "fy", "cx", "cy")]
    assert np.allclose(k, [750, 750, 480, 300], atol=1.5)


APRILTAG = "b1: {type: apriltag, rows: 5, cols: 7, square_mm: 80, marker_mm: 64, pose: [-280, 200, 30, 178, 3, 2]}"
"""The ChArUco board's place taken by an AprilTag grid of about its size (tags about 26 px wide in the images)."""


@pytest.mark.parametrize("board", ["charuco", "apriltag"])
def test_partcal_simulate_renders_the_images_that_partcal_detect_reads_back_to_the_simulated_pixels(tmp_path, board):
    """``render: true`` writes each image of the simulated rows with its joints CSV; ``partcal detect`` on that
    folder finds most points the rows hold and no other, without offset and within 0.25 px RMS of the simulated
    pixels (0.01 px of noise there; the board's squares about 20 px wide): the images show the board where the rows
    put it, at the joints the rows give."""
    from partcal.cli import main
    from partcal.data.measurement_rows import read_measurement_rows
    config = VIRTUAL.replace("  test: {sample: 10}", "  images: {camera: {images: 4, render: true}, noise: 0.01}")
    if board == "apriltag":
        config = re.sub(r"b1: \{type: charuco.*\}", APRILTAG, config)
    (tmp_path / "virtual.yaml").write_text(config)
    assert main(["simulate", str(tmp_path / "virtual.yaml")]) == 0
    folder = tmp_path / "data" / "images_images" / "cam1"
    assert sorted(p.name for p in folder.iterdir()) == [*(f"cam1-{k:04d}.png" for k in range(1, 5)), "joints.csv"]
    assert not list((tmp_path / "data").rglob("*.partial"))
    assert main(["detect", str(folder), "--joints", str(folder / "joints.csv"), "--cell",
                 str(tmp_path / "data" / "cell.yaml"), "--robot", "universal_robots_ur10", "-o",
                 str(tmp_path / "pixels.csv")]) == 0
    simulated, found = (read_measurement_rows(p) for p in (tmp_path / "data" / "images.csv", tmp_path / "pixels.csv"))

    def keyed(rows, suffix):
        return {(image.removesuffix(suffix), int(p)): (q, np.array([u, v])) for image, p, q, u, v in zip(
            rows.texts["image"], rows.numbers["point"], rows.q_deg, rows.numbers["u_px"], rows.numbers["v_px"])}

    want, got = keyed(simulated, ""), keyed(found, ".png")
    near_border = [k for k in set(got) - set(want) if not (MARGIN_PX < got[k][1][0] < 960 - MARGIN_PX and
                                                           MARGIN_PX < got[k][1][1] < 600 - MARGIN_PX)]
    assert set(got) - set(want) == set(near_border)         # no point the rows lack but in the border they leave out
    got = {k: got[k] for k in got if k in want}
    assert len(got) > 0.8 * len(want)                         # most of theirs
    miss = np.array([got[k][1] - want[k][1] for k in got])
    assert np.all(np.abs(miss.mean(axis=0)) < 0.02)          # no offset: a half-pixel convention would show 0.5
    assert np.sqrt(np.mean(np.sum(miss**2, axis=1))) < 0.25    # squares of 20 px seen obliquely: 0.18 px seen
    assert max(np.max(np.abs(got[k][0] - want[k][0])) for k in got) < 1e-5
