"""``partcal check`` and ``partcal update`` with pixel rows (partcal/study/check_types.py), on a model identified from camera rows of a virtual
eye-to-hand cell (``partcal simulate`` then ``partcal run``, as tests/test_camera_identification.py): new rows of
the same virtual robot hold, rows of the robot with joint 2's zero moved by 0.05 degree say moved and name it,
an update from new rows moves the hand-eye toward the simulation's truth, and tracker points against the camera
model are refused in one line."""

import dataclasses
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from partcal.calibration.registry import MEASUREMENT_TYPES
from partcal.cli import main
from partcal.data.contact_sets import Truth
from partcal.data.measurement_rows import write_measurement_rows
from partcal.data.simulate import load_study
from partcal.errors import ConfigError, DataError
from partcal.robot.description import load_robot
from partcal.study.check import check_file
from partcal.study.update import update_file
from test_camera_identification import BOARD, CAMERA, INTRINSICS, RUN, SQUARE, VIRTUAL, _pose

MOUNT = "cell"


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """A model of 20 images of a virtual eye-to-hand cell (0.2 px), and what the simulation knows of its truth."""
    folder = tmp_path_factory.mktemp("camera_check")
    (folder / "virtual.yaml").write_text(VIRTUAL.format(
        mount=MOUNT, k=INTRINSICS[MOUNT], camera=CAMERA[MOUNT], board=BOARD[MOUNT], square=SQUARE[MOUNT],
        marker=0.75 * SQUARE[MOUNT]).replace("images: 25", "images: 20") + "  points: {sample: 20}\n")
    cwd = __import__("os").getcwd()
    try:
        __import__("os").chdir(folder)
        assert main(["simulate", "virtual.yaml"]) == 0
        (folder / "run.yaml").write_text(RUN)
        assert main(["run", "-q", "run.yaml"]) == 0
    finally:
        __import__("os").chdir(cwd)
    return folder, load_study(folder / "virtual.yaml")


def _rows(study, path, images, seed, joint_moved_deg=0.0):
    """Camera rows of the virtual robot (joint 2's zero moved by ``joint_moved_deg``), written to ``path``."""
    vr = study.robot
    if joint_moved_deg:
        offset = vr.true.theta_offset_deg.copy()
        offset[1] += joint_moved_deg
        vr = dataclasses.replace(vr, true=vr.true.replace(theta_offset_deg=offset))
    truth = Truth(vr, study.ranges_deg, study.fixed_deg, dict(study.cell.sections))
    rows = MEASUREMENT_TYPES["camera"].simulate(truth, {"images": images}, np.random.default_rng(seed), 0.2)
    write_measurement_rows(rows, path)
    return path


def _hand_eye_miss(study, model_file):
    """The board's pose on the flange in the model file against the truth in the gauge the images define (the
    chain's last row held nominal: the pose on the flange carries the true last row's error): mm, degrees."""
    table = json.loads(model_file.read_text())["model"]["identification"]
    value = dict(zip(table["names"], table["value"]))
    fitted = _pose([value[f"board b1@flange.{c}"] for c in ("x", "y", "z", "rx", "ry", "rz")])
    nominal, true = load_robot("universal_robots_ur10"), study.robot.true
    last = {k: np.r_[getattr(true, k)[:-1], getattr(nominal, k)[-1]]
            for k in ("alpha_deg", "d_mm", "a_mm", "theta_offset_deg")}
    q0 = np.zeros((1, 6))
    expected = np.linalg.inv(true.replace(**last).flange(q0)[0]) @ true.flange(q0)[0] @ _pose(BOARD[MOUNT])
    return (float(np.linalg.norm(expected[:3, 3] - fitted[:3, 3])),
            float(np.degrees(Rotation.from_matrix(expected[:3, :3].T @ fitted[:3, :3]).magnitude())))


def test_check_pixel_rows_holds_for_the_same_robot_and_names_a_moved_joint(cell, tmp_path):
    folder, study = cell
    model = folder / "out" / "models" / "dh.json"
    same = check_file(model, _rows(study, tmp_path / "same.csv", 12, 11))
    assert same.holds and 0.9 < same.mean_z2 < 1.1, same.lines()
    moved = check_file(model, _rows(study, tmp_path / "moved.csv", 12, 11, joint_moved_deg=0.05))
    assert not moved.holds
    first = moved.explanations[0]
    assert first.name == "joint 2's offset"
    assert first.change[0] == pytest.approx(0.05, abs=0.01)          # the truth: +0.05 degree
    said = "\n".join(moved.lines())
    assert said.startswith("moved:") and "moved.csv:" in said         # the worst rows named by file and line
    with pytest.raises(ConfigError, match="--frame tracker"):
        check_file(model, tmp_path / "same.csv", frame="tracker")
    with pytest.raises(ConfigError, match="--rows"):
        check_file(model, tmp_path / "same.csv", rows="1-20")


def test_update_from_new_pixel_rows_moves_the_hand_eye_toward_the_truth(cell, tmp_path):
    folder, study = cell
    model = folder / "out" / "models" / "dh.json"
    before = _hand_eye_miss(study, model)
    done = update_file(model, _rows(study, tmp_path / "more.csv", 30, 12), tmp_path / "updated.json")
    after = _hand_eye_miss(study, tmp_path / "updated.json")
    assert after[0] < before[0] and after[1] < before[1], (before, after)
    assert 0.15 < done.rms_after["camera"] < 0.25                        # the 0.2 px noise
    updated = json.loads((tmp_path / "updated.json").read_text())
    assert updated["fit"]["update"]["rows"] > 0 and "cameras" in updated["fit"]["cell"]


def test_tracker_points_against_a_camera_model_are_refused_in_one_line(cell, tmp_path):
    folder, _ = cell
    model, points = folder / "out" / "models" / "dh.json", folder / "data" / "points.csv"
    with pytest.raises(DataError, match="see neither the tool offset nor the base frame") as refused:
        check_file(model, points)
    assert "\n" not in str(refused.value)
    with pytest.raises(DataError, match="without its cameras and boards"):
        update_file(model, points, tmp_path / "u.json")
