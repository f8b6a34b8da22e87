"""Camera rows of a virtual robot through the command line: ``partcal simulate`` writes pixel rows of a board seen by
a camera (eye-to-hand: the camera in the cell, the board on the flange; eye-in-hand: the other way round),
``partcal run`` identifies the robot, the camera, the board and the intrinsics together, and the model file is
scored against the simulation's truth (0.2 px noise)."""

import json

import cv2
import numpy as np
import pytest
import yourdfpy
from scipy.spatial.transform import Rotation

from partcal.calibration.parameters import geometric_size, robot_with
from partcal.cli import main
from partcal.data.simulate import load_study
from partcal.robot.description import load_robot

INTRINSICS = {"cell": [1500.0, 1500.0, 960.0, 600.0, -0.1, 0.05, 0.0005, -0.0003, 0.0],
              "flange": [1400.0, 1400.0, 950.0, 610.0, -0.12, 0.06, 0.0004, -0.0002, 0.0]}
CAMERA = {"cell": [1900.0, 300.0, 900.0, -73.4542, -96.1699, 68.1777],      # looking at (800, 0, 500) from the side
          "flange": [0.0, 70.0, 40.0, 2.0, -3.0, 90.0]}                      # along the flange's z
BOARD = {"cell": [-165.0, 120.0, 30.0, 178.0, 3.0, 2.0],                     # on the flange, facing out
         "flange": [580.0, 160.0, 20.0, 179.0, 2.0, 1.0]}                    # on the table, facing up
SQUARE = {"cell": 30.0, "flange": 40.0}
OTHER = {"cell": "flange", "flange": "cell"}

VIRTUAL = """robot: universal_robots_ur10
seed: 3
output: data
errors:
  dh_sigma: {{length_mm: 0.5, twist_deg: 0.03, zero_offset_deg: 0.05}}
  tool_mm: [0.3, -0.2, 0.4]
  base: {{rotation_deg: [0.02, -0.03, 0.04], translation_mm: [1.0, -0.5, 0.8]}}
tracker: {{position_mm: [2500, 0, 0], accuracy_ppm: 0, repeatability_ppm: 10, readings: 1}}
sampling:
  ranges_deg: {{q1: [-40, 40], q2: [-150, -30], q3: [-140, 140], q4: [-180, 180], q5: [-150, 150], q6: [-180, 180]}}
cell:
  cameras:
    cam1:
      mount: {mount}
      image_size: [1920, 1200]
      intrinsics: {{fx: {k[0]}, fy: {k[1]}, cx: {k[2]}, cy: {k[3]}, k1: {k[4]}, k2: {k[5]}, p1: {k[6]}, p2: {k[7]}}}
      pose: {camera}
  boards:
    b1: {{type: charuco, rows: 8, cols: 11, square_mm: {square}, marker_mm: {marker}, pose: {board}}}
datasets:
  images: {{camera: {{images: 25}}, noise: 0.2}}
"""

RUN = """name: camera
robot: universal_robots_ur10
seed: 0
cv_folds: 2
data:
  identification: [data/images.csv]
  cell: data/cell.yaml
models:
  - {name: DH, kind: kinematic}
output: out
"""


def _pose(values) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(values[3:], degrees=True).as_matrix()
    out[:3, 3] = values[:3]
    return out


def _poses(flange_mm, flange_rot) -> np.ndarray:
    out = np.tile(np.eye(4), (len(flange_mm), 1, 1))
    out[:, :3, :3], out[:, :3, 3] = flange_rot, flange_mm
    return out


@pytest.mark.parametrize("mount", ["cell", "flange"])
def test_simulated_images_identify_the_hand_eye_the_robot_and_the_intrinsics(mount, tmp_path, capsys):
    (tmp_path / "virtual.yaml").write_text(VIRTUAL.format(
        mount=mount, k=INTRINSICS[mount], camera=CAMERA[mount], board=BOARD[mount], square=SQUARE[mount],
        marker=0.75 * SQUARE[mount]))
    assert main(["simulate", str(tmp_path / "virtual.yaml")]) == 0, capsys.readouterr().err
    truth = (tmp_path / "data" / "images.truth.yaml").read_text()
    assert "cameras:" in truth and "true_robot:" in truth
    assert "pose" not in (tmp_path / "data" / "cell.yaml").read_text()      # the cell knows no pose, no intrinsics
    (tmp_path / "run.yaml").write_text(RUN)
    assert main(["run", "-q", str(tmp_path / "run.yaml")]) == 0, capsys.readouterr().err
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert 0.15 < metrics["models"]["DH"]["cv_rms_by_type"]["camera"] < 0.25        # held out: the 0.2 px noise
    table = json.loads((tmp_path / "out" / "models" / "dh.json").read_text())["model"]["identification"]
    value = dict(zip(table["names"], table["value"]))

    nominal = load_robot("universal_robots_ur10")
    robot = robot_with(nominal, np.asarray(table["value"])[:geometric_size(nominal, "dh")])
    camera, board = ([value[f"{what}.{c}"] for c in ("x", "y", "z", "rx", "ry", "rz")]
                     for what in (f"camera cam1@{mount}", f"board b1@{OTHER[mount]}"))
    study = load_study(tmp_path / "virtual.yaml")
    q = np.unique(np.loadtxt(tmp_path / "data" / "images.csv", delimiter=",", comments="#", skiprows=3,
                             usecols=range(6)), axis=0)
    true_flange, fitted_flange = _poses(*study.robot.true_flange(q)), robot.flange(q)
    if mount == "cell":     # the board in the camera's frame, at the images' poses
        true_cam = np.linalg.inv(_pose(CAMERA[mount])) @ true_flange @ _pose(BOARD[mount])
        fitted_cam = np.linalg.inv(_pose(camera)) @ fitted_flange @ _pose(board)
        hand_eye, true_hand_eye = _pose(board), _pose(BOARD[mount])
    else:
        true_cam = np.linalg.inv(true_flange @ _pose(CAMERA[mount])) @ _pose(BOARD[mount])
        fitted_cam = np.linalg.inv(fitted_flange @ _pose(camera)) @ _pose(board)
        hand_eye, true_hand_eye = _pose(camera), _pose(CAMERA[mount])
    # the board's centre in the camera's frame: the whole chain, no fit
    centre = np.array([5.5 * SQUARE[mount], 4.0 * SQUARE[mount], 0.0, 1.0])
    miss = np.linalg.norm((true_cam @ centre - fitted_cam @ centre)[:, :3], axis=1)
    assert np.sqrt(np.mean(miss**2)) < 1.0
    # the hand-eye in the gauge the images define: the chain's last row held nominal, so the pose on the flange
    # carries the true last row's error: expected = (nominal last row)^-1 (true last row) (true pose on the flange)
    true = study.robot.true
    last = {k: np.r_[getattr(true, k)[:-1], getattr(nominal, k)[-1]]
            for k in ("alpha_deg", "d_mm", "a_mm", "theta_offset_deg")}
    q0 = q[:1]
    row_error = np.linalg.inv(true.replace(**last).flange(q0)[0]) @ true.flange(q0)[0]
    expected = row_error @ true_hand_eye
    assert np.linalg.norm(expected[:3, 3] - hand_eye[:3, 3]) < 0.15          # 0.08 and 0.05 mm seen
    assert Rotation.from_matrix(expected[:3, :3].T @ hand_eye[:3, :3]).magnitude() < np.radians(0.03)  # 0.015, 0.010 deg
    fitted_k = [value[f"camera cam1.{k}"] for k in ("fx", "fy", "cx", "cy")]
    assert np.allclose(fitted_k, INTRINSICS[mount][:4], atol=1.0)
    notes = " ".join(metrics.get("notes", [])) + json.dumps(metrics)
    assert "held nominal" in notes

    # out: the intrinsics as a camera_info YAML OpenCV reads, the camera a link of the exported URDF
    info = cv2.FileStorage(str(tmp_path / "out" / "models" / "dh_camera_cam1.yaml"), cv2.FILE_STORAGE_READ)
    data = info.getNode("camera_matrix").getNode("data")
    assert [data.at(i).real() for i in range(9)] == pytest.approx(
        [fitted_k[0], 0, fitted_k[2], 0, fitted_k[1], fitted_k[3], 0, 0, 1], abs=1e-9)
    assert info.getNode("image_width").real() == 1920
    distortion = info.getNode("distortion_coefficients").getNode("data")
    assert [distortion.at(i).real() for i in range(5)] == pytest.approx(
        [value[f"camera cam1.{k}"] for k in ("k1", "k2", "p1", "p2", "k3")], abs=1e-12)
    assert main(["export", str(tmp_path / "out" / "models" / "dh.json"), "-o", str(tmp_path / "export")]) == 0
    urdf = yourdfpy.URDF.load(str(tmp_path / "export" / "dh.urdf"))
    pose = q[3]
    urdf.update_cfg({f"joint{k + 1}": np.radians(pose[k]) for k in range(6)})
    seen = urdf.get_transform("cam1_optical_frame", "world")
    expected = fitted_flange[3] @ _pose(camera) if mount == "flange" else _pose(camera)
    assert np.allclose(seen[:3, :3], expected[:3, :3], atol=1e-12)
    assert np.allclose(seen[:3, 3] * 1000.0, expected[:3, 3], atol=1e-9)
    capsys.readouterr()
    assert main(["plan", "universal_robots_ur10", "--evaluate", str(tmp_path / "data" / "images.csv"),
                 "--cell", str(tmp_path / "data" / "cell.yaml")]) == 0
    said = capsys.readouterr().out
    assert "(held nominal): theta[1], d[1], theta[6], d[6], a[6], alpha[6], base.x" in said
    pose_in_cell = "camera's" if mount == "cell" else "board's"
    assert f"with camera rows alone the base is held nominal and the {pose_in_cell}" in said
