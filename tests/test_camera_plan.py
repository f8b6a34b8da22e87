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
    numbers = [int(name.removeprefix("cam1-")) for name in names]          # images numbered one by one (60 drawn,
    assert numbers == sorted(numbers) and numbers[-1] <= 60                 # some dropped below the floor)
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


def test_planned_images_are_chosen_among_the_cells_own_poses(tmp_path, capsys):
    """``--candidates FILE.csv`` (the cell's reachable, collision-free poses, e.g. within narrow joint ranges): every
    planned image is one of those poses, to the file's digits; a touch plan refuses them (its candidates are put on
    the planes), naming the option."""
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump(CELL))
    rng = np.random.default_rng(3)
    q = rng.uniform([-40, -150, -140, -180, -150, -180], [40, -30, 140, 180, 150, 180], (3000, 6))
    q = np.round(q, 3)
    np.savetxt(tmp_path / "safe.csv", q, delimiter=",", header="q1,q2,q3,q4,q5,q6", comments="", fmt="%.3f")
    assert main(["plan", "universal_robots_ur10", "--measurement", "camera", "-n", "6", "-o",
                 str(tmp_path / "joints.csv"), "--cell", str(tmp_path / "cell.yaml"), "--candidates",
                 str(tmp_path / "safe.csv"), "--pool", "40", "-q"]) == 0
    lines = [line for line in (tmp_path / "joints.csv").read_text().splitlines() if not line.startswith("#")]
    planned = np.array([[float(v) for v in line.split(",")[1:]] for line in lines[1:]])
    assert planned.shape == (6, 6)
    assert all(np.min(np.max(np.abs(q - row), axis=1)) < 1e-9 for row in planned)
    assert np.all((planned[:, 0] >= -40) & (planned[:, 0] <= 40))            # within the file's ranges
    plane_cell = tmp_path / "planes.yaml"
    plane_cell.write_text("planes:\n  top: {point_mm: [700, 0, 0], normal: [0, 0, 1]}\n")
    assert main(["plan", "universal_robots_ur10", "--measurement", "plane", "-n", "6", "-o", str(tmp_path / "t.csv"),
                 "--cell", str(plane_cell), "--candidates", str(tmp_path / "safe.csv"), "-q"]) == 2
    assert "--candidates goes with tracker poses" in capsys.readouterr().err


def test_two_cameras_in_the_cell_get_a_joints_file_each_with_the_board_in_their_view(tmp_path, capsys):
    """A second camera in the cell, across from the first: the plan shares the images between them and writes one
    joints CSV per camera (each camera's folder is detected with its own), each pose putting the board in that
    camera's view (a pinhole of its intrinsics, independently). Cameras in the cell and on the flange in one cell
    are refused: which board each sees is not known."""
    second = [1900.0, -300.0, 900.0, -91.45, -69.8492, 49.5181]     # the first mirrored across the base's x-z plane
    cell = {**CELL, "cameras": {**CELL["cameras"], "cam2": {**CELL["cameras"]["cam1"], "pose": second}}}
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump(cell))
    assert main(["plan", "universal_robots_ur10", "--measurement", "camera", "-n", "10", "-o",
                 str(tmp_path / "joints.csv"), "--cell", str(tmp_path / "cell.yaml"), "--pool", "60", "-q"]) == 0
    robot = load_robot("universal_robots_ur10")
    counts = {}
    for cam, pose in (("cam1", CAMERA), ("cam2", second)):
        lines = [line for line in (tmp_path / f"joints_{cam}.csv").read_text().splitlines()
                 if not line.startswith("#")]
        assert lines[0] == "image,q1,q2,q3,q4,q5,q6" and all(line.startswith(f"{cam}-") for line in lines[1:])
        q = np.array([[float(v) for v in line.split(",")[1:]] for line in lines[1:]])
        counts[cam] = len(q)
        cam_T_board = np.linalg.inv(_pose(pose)) @ robot.flange(q) @ _pose(BOARD)
        centre = cam_T_board[:, :3, :3] @ [165.0, 120.0, 0.0] + cam_T_board[:, :3, 3]
        assert np.all(centre[:, 2] > 0)
        u, v = 1500 * centre[:, 0] / centre[:, 2] + 960, 1500 * centre[:, 1] / centre[:, 2] + 600
        assert np.all((u > 0) & (u < 1920) & (v > 0) & (v < 1200))
    assert not (tmp_path / "joints.csv").exists() and sum(counts.values()) == 10 and min(counts.values()) >= 1
    mixed = {**cell, "cameras": {**cell["cameras"], "cam2": {**cell["cameras"]["cam2"], "mount": "flange",
                                                              "pose": [0.0, 70.0, 40.0, 2.0, -3.0, 90.0]}}}
    (tmp_path / "mixed.yaml").write_text(yaml.safe_dump(mixed))
    assert main(["plan", "universal_robots_ur10", "--measurement", "camera", "-n", "10", "-o",
                 str(tmp_path / "m.csv"), "--cell", str(tmp_path / "mixed.yaml"), "-q"]) == 2
    assert "plan each set-up on a cell of its own" in capsys.readouterr().err
