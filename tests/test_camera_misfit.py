"""An image whose detection disagrees with its pose's prediction is named (issue 47: images paired with the wrong
poses after a failed detection): the joints of two images of simulated camera rows swapped, the fit's notes name both
images by id and file lines, and no other."""

import dataclasses

import numpy as np

from partcal.calibration.camera import IMAGE_MISFIT
from partcal.calibration.camera_cell import true_cell, seen_points
from partcal.calibration.camera_model import board_points
from partcal.calibration.stacked import identify_measurements
from partcal.data.contact_sets import Truth
from partcal.data.simulate import load_study
from partcal.calibration.registry import MEASUREMENT_TYPES
from test_camera_identification import BOARD, CAMERA, INTRINSICS, SQUARE, VIRTUAL

CELL = {"cameras": {"cam1": {"mount": "cell", "image_size": [1920, 1200], "fit_intrinsics": True}},
        "boards": {"b1": {"type": "charuco", "rows": 8, "cols": 11, "square_mm": 30.0, "marker_mm": 22.5}},
        "noise": {"camera": 0.2}}


def _rows(tmp_path):
    (tmp_path / "virtual.yaml").write_text(VIRTUAL.format(
        mount="cell", k=INTRINSICS["cell"], camera=CAMERA["cell"], board=BOARD["cell"], square=SQUARE["cell"],
        marker=0.75 * SQUARE["cell"]))
    study = load_study(tmp_path / "virtual.yaml")
    truth = Truth(study.robot, study.ranges_deg, study.fixed_deg, dict(study.cell.sections))
    rows = MEASUREMENT_TYPES["camera"].simulate(truth, {"images": 20}, np.random.default_rng(7), 0.2)
    return study, dataclasses.replace(rows, source="images.csv", lines=tuple(range(4, len(rows) + 4)))


def test_two_images_with_swapped_joints_are_named(tmp_path):
    study, rows = _rows(tmp_path)
    image = np.array(rows.texts["image"])
    q = rows.q_deg.copy()
    a, b = image == "cam1-0004", image == "cam1-0011"
    q[a], q[b] = rows.q_deg[b][0], rows.q_deg[a][0]            # each image given the other's joints
    swapped = dataclasses.replace(rows, q_deg=q)
    cell = _read_cell(tmp_path)
    _, notes = identify_measurements(study.robot.nominal, swapped, cell)
    named = [n for n in notes if n.startswith("camera: image")]     # the culprits (the rest counted, bent by them)
    assert len(named) == 2, notes
    first = np.flatnonzero(a)[0] + 4                              # its first row's line
    assert any("'cam1-0004'" in n and f"images.csv:{first}-" in n for n in named)
    assert any("'cam1-0011'" in n for n in named)
    assert any(n.startswith("camera: 18 further images") for n in notes)        # bent by the two, counted
    _, clean = identify_measurements(study.robot.nominal, rows, cell)
    assert not [n for n in clean if n.startswith("camera: image")]
    # independently of the fit: the true cell's pixels of each swapped image at the joints now paired with it are
    # far from its detections (hundreds of pixels), those of a clean image within the noise
    cameras, boards = true_cell(study.cell.sections)
    local = board_points(boards["b1"])
    for mask, expect_far in ((a, True), (b, True), (image == "cam1-0001", False)):
        seen, uv = seen_points(cameras["cam1"], boards["b1"], *study.robot.true_flange(q[mask][:1]), local)
        miss = uv[0, swapped.numbers["point"][mask].astype(int)] - np.column_stack(
            [swapped.numbers["u_px"][mask], swapped.numbers["v_px"][mask]])
        rms = np.sqrt(np.mean(miss**2))
        assert (rms > 10 * IMAGE_MISFIT * 0.2) if expect_far else (rms < 1.0), rms


def _read_cell(tmp_path):
    from partcal.data.measurement_rows import read_cell
    import yaml
    (tmp_path / "cell.yaml").write_text(yaml.safe_dump({k: v for k, v in CELL.items()}))
    return read_cell(tmp_path / "cell.yaml")
