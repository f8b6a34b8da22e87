"""``partcal plan --measurement camera``: images chosen D-optimally among poses that keep the board in view and not
too oblique (partcal/calibration/camera_cell.py's candidates, partcal/study/plan_measurements.py's exchange over
images), written as the joints CSV an image folder is detected with. Checked independently: each planned pose puts
the board in front of the camera, turned less than 60 degrees from its line of sight, at least half its corners
inside the image (a pinhole of the cell's intrinsics); the planned images identify the robot better (smaller
predicted position uncertainty) than as many candidate images taken at random."""

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from partcal.calibration.registry import MEASUREMENT_TYPES
from partcal.cli import main
from partcal.data.measurement_rows import read_cell
from partcal.robot.description import load_robot
from partcal.study.plan_measurements import evaluate_measurements, plan_measurements

CAMERA = [1900.0, 300.0, 900.0, -73.4542, -96.1699, 68.1777]
BOARD = [-165.0, 120.0, 30.0, 178.0, 3.0, 2.0]
CELL = {"cameras": {"cam1": {"mount": "cell", "image_size": [1920, 1200], "pose": CAMERA,
                             "intrinsics": {"fx": 1500, "fy": 1500, "cx": 960, "cy": 600}}},
        "boards": {"b1": {"type": "charuco", "rows": 8, "cols": 11, "square_mm": 30.0, "marker_mm": 22.5,
                          "pose": BOARD}},
        "noise": {"camera": 0.2}}


def _pose(values):
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(values[3:], degrees=True).as_matrix()
    out[:3, 3] = values[:3]
    return out


def test_planned_images_keep_the_board_in_view_and_beat_random_ones(tmp_path, capsys):
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump(CELL))
    assert main(["plan", "universal_robots_ur10", "--measurement", "camera", "-n", "10", "-o",
                 str(tmp_path / "joints.csv"), "--cell", str(tmp_path / "cell.yaml"), "--pool", "60", "-q"]) == 0
    said = capsys.readouterr().out
    assert "wrote 10 images' joints" in said
    lines = [line for line in (tmp_path / "joints.csv").read_text().splitlines() if not line.startswith("#")]
    assert lines[0] == "image,q1,q2,q3,q4,q5,q6" and len(lines) == 11
    q = np.array([[float(v) for v in line.split(",")[1:]] for line in lines[1:]])
    robot = load_robot("universal_robots_ur10")
    cam_T_board = np.linalg.inv(_pose(CAMERA)) @ robot.flange(q) @ _pose(BOARD)
    s = 30.0
    grid = np.array([[(c + 1) * s, (r + 1) * s, 0.0] for r in range(7) for c in range(10)])
    for pose in cam_T_board:
        points = grid @ pose[:3, :3].T + pose[:3, 3]
        assert np.all(points[:, 2] > 0)                                    # in front of the camera
        u = 1500 * points[:, 0] / points[:, 2] + 960
        v = 1500 * points[:, 1] / points[:, 2] + 600
        assert np.mean((u > 0) & (u < 1920) & (v > 0) & (v < 1200)) >= 0.5
        centre = points.mean(axis=0)
        facing = np.degrees(np.arccos(pose[:3, 2] @ centre / np.linalg.norm(centre)))
        assert facing < 60.0
    # D-optimal: better than as many candidate images at random (same candidates, seeded)
    cell = read_cell(tmp_path / "cell.yaml")
    planned = plan_measurements(robot, 10, cell, "camera", pool=60, random_state=0)
    image = np.array(planned.candidates.texts["image"])
    names = list(dict.fromkeys(image))
    rng = np.random.default_rng(1)
    for _ in range(2):
        pick = rng.choice(len(names), 10, replace=False)
        rows = planned.candidates.take(np.flatnonzero(np.isin(image, [names[k] for k in pick])))
        random = evaluate_measurements(robot, rows, cell, random_state=0)
        assert planned.evaluation.position_rms_mm < random.position_rms_mm


def test_planned_images_keep_above_the_floor(tmp_path):
    """Candidate images below a floor are dropped: with a floor at the base (0 mm, 100 mm clearance) every planned
    pose keeps the flange more than 100 mm above it (independently: the nominal flange's height)."""
    from partcal.robot.floor import Floor
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump(CELL))
    robot = load_robot("universal_robots_ur10")
    planned = plan_measurements(robot, 8, read_cell(tmp_path / "cell.yaml"), "camera", pool=40, random_state=2,
                                floor=Floor(0.0, 100.0))
    assert np.all(robot.flange(planned.rows.q_deg)[:, 2, 3] > 100.0)
    assert np.all(robot.flange(planned.candidates.q_deg)[:, 2, 3] > 100.0)
    drawn = MEASUREMENT_TYPES["camera"].candidates(robot, read_cell(tmp_path / "cell.yaml"), 40,
                                                   np.random.default_rng(0))
    assert np.any(robot.flange(drawn.q_deg)[:, 2, 3] <= 100.0)          # without the floor some are below it
