"""Camera calibration: the robot, the hand-eye, the board and the intrinsics identified together from pixels
(camera rows), against OpenCV's five hand-eye methods on the nominal flange poses.

A virtual UR10 with DH errors (0.5 mm, 0.03 deg, 0.05 deg offsets), tilts between its parallel axes (q2 0.03 deg,
q3 -0.02 deg), a base error and a tool error; a 1920 x 1200 camera with distortion; a ChArUco board of 8 x 11
squares. Two set-ups: eye-to-hand (the camera in the cell, the board on the flange) and eye-in-hand (the camera
on the flange, the board on the table). 30, 60 and 120 images, the board's corners with 0.2 px of normal noise
(``partcal simulate``'s pixel rows: the true pixels plus noise, not rendered images; the detection's own error on
rendered images is tests/test_detect.py's, under 0.1 px RMS), at random poses with the board in view or, with
``--planned``, at the poses ``partcal plan --measurement camera`` chooses. Per row the median over the virtual robots
(seeds):

- partcal: the hand-eye (the board's pose on the flange, eye-to-hand; the camera's, eye-in-hand) against the truth
  in the gauge the images define (the cell's frame: the fitted pose in the cell against the true one; the
  flange's: the mean over the poses in view of the fitted flange's pose against the true one in that frame), in mm
  and degrees; the largest error of fx, fy, cx, cy (px); the board's centre in
  the camera's frame with no fit on up to 2,000 random poses with the board in view (mm); the identification's
  time (s);
- beside a tracker (0.02 mm per axis) measuring the point on the flange (the board's centre eye-to-hand, the
  camera's optical centre eye-in-hand) at the images' poses and identified with the same parametrization: that
  point through each fit's chain after a rigid fit onto the truth, on the 2,000 poses in view and on 2,000 random
  poses, and the ratio camera / tracker (the issue's target: no worse than 2); the no-fit figure on the random
  poses as well; the ratio each fit's covariance predicts on the poses in view (:func:`expected_rigid_rms`);
- OpenCV: ``cv2.solvePnP`` per image (with the true intrinsics: the most OpenCV can be given), then
  ``cv2.calibrateHandEye`` (Tsai, Park, Horaud, Andreff, Daniilidis) on the nominal robot's flange poses, the
  hand-eye scored in the same gauge; the best of the five and its method; the board's centre in the camera's
  frame through the nominal robot and the best method's hand-eye.

    .venv/bin/python benchmarks/bench_camera.py [--robots 3] [--parametrization dh|complete]
        [--setups eye-to-hand eye-in-hand] [--images 30 60 120] [--planned] [--redraws 12]   (a minute per robot)
"""

from __future__ import annotations

import argparse
import contextlib
import io
import logging
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

from partcal.calibration.camera_cell import seen_points, true_cell  # noqa: E402
from partcal.calibration.camera_model import board_points, pose_matrix  # noqa: E402
from partcal.calibration.measurement import MeasurementRows  # noqa: E402
from partcal.calibration.parameters import geometric_size, robot_with  # noqa: E402
from partcal.calibration.stacked import identify_measurements  # noqa: E402
from partcal.cli import main  # noqa: E402
from partcal.data.measurement_rows import read_cell, read_measurement_rows  # noqa: E402
from partcal.data.sampling import sample_configurations  # noqa: E402
from partcal.data.simulate import load_study  # noqa: E402
from partcal.robot.frames import kabsch  # noqa: E402
from partcal.robot.rotations import poses_from  # noqa: E402
from partcal.study.plan_measurements import plan_measurements  # noqa: E402

TRACKER_MM = 0.02
"""The tracker beside the camera: normal noise per axis (mm)."""

SETUPS = {
    "eye-to-hand": {"mount": "cell", "k": [1500.0, 1500.0, 960.0, 600.0, -0.1, 0.05, 0.0005, -0.0003, 0.0],
                    "camera": [1900.0, 300.0, 900.0, -73.4542, -96.1699, 68.1777],
                    "board": [-165.0, 120.0, 30.0, 178.0, 3.0, 2.0], "square": 30.0},
    "eye-in-hand": {"mount": "flange", "k": [1400.0, 1400.0, 950.0, 610.0, -0.12, 0.06, 0.0004, -0.0002, 0.0],
                    "camera": [0.0, 70.0, 40.0, 2.0, -3.0, 90.0],
                    "board": [580.0, 160.0, 20.0, 179.0, 2.0, 1.0], "square": 40.0},
}
PARAMETRIZATION = "complete"
"""The chain's parametrization (``--parametrization``): DH rows cannot hold tilts between parallel axes, the
complete one can."""
METHODS = {"Tsai": cv2.CALIB_HAND_EYE_TSAI, "Park": cv2.CALIB_HAND_EYE_PARK, "Horaud": cv2.CALIB_HAND_EYE_HORAUD,
           "Andreff": cv2.CALIB_HAND_EYE_ANDREFF, "Daniilidis": cv2.CALIB_HAND_EYE_DANIILIDIS}

VIRTUAL = """robot: universal_robots_ur10
seed: {seed}
output: data
errors:
  dh_sigma: {{length_mm: 0.5, twist_deg: 0.03, zero_offset_deg: 0.05}}
  tilt_deg: {{q2: 0.03, q3: -0.02}}
  tool_mm: [0.3, -0.2, 0.4]
  base: {{rotation_deg: [0.02, -0.03, 0.04], translation_mm: [1.0, -0.5, 0.8]}}
tracker: {{position_mm: [2500, 0, 0], accuracy_ppm: 0, repeatability_ppm: 10, readings: 1}}
sampling:
  ranges_deg: {{q1: [-40, 40], q2: [-150, -30], q3: [-140, 140], q4: [-180, 180], q5: [-150, 150], q6: [-180, 180]}}
cell:
  cameras:
    cam1: {{mount: {mount}, image_size: [1920, 1200], pose: {camera},
           intrinsics: {{fx: {k[0]}, fy: {k[1]}, cx: {k[2]}, cy: {k[3]}, k1: {k[4]}, k2: {k[5]}, p1: {k[6]}, p2: {k[7]}}}}}
  boards:
    b1: {{type: charuco, rows: 8, cols: 11, square_mm: {square}, marker_mm: {marker}, pose: {board}}}
datasets:
  images: {{camera: {{images: {images}}}, noise: 0.2}}
"""


def error(expected, got) -> tuple[float, float]:
    return (float(np.linalg.norm(expected[:3, 3] - got[:3, 3])),
            float(np.degrees(Rotation.from_matrix(expected[:3, :3].T @ got[:3, :3]).magnitude())))


def mean_pose(poses) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_matrix(poses[:, :3, :3]).mean().as_matrix()
    out[:3, 3] = poses[:, :3, 3].mean(axis=0)
    return out


def opencv(setup: dict, rows, nominal_flange) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Each method's (pose on the flange, pose in the cell) from solvePnP per image and calibrateHandEye."""
    k = setup["k"]
    matrix = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1.0]])
    local = board_points({"type": "charuco", "rows": 8, "cols": 11, "square_mm": setup["square"], "marker_mm": 1})
    images = list(dict.fromkeys(rows.texts["image"]))
    board_in_cam, flange = [], []
    for image in images:
        mine = np.flatnonzero(np.array(rows.texts["image"]) == image)
        uv = np.column_stack([rows.numbers["u_px"][mine], rows.numbers["v_px"][mine]])
        ok, rvec, tvec = cv2.solvePnP(local[rows.numbers["point"][mine].astype(int)], uv, matrix, np.array(k[4:]))
        b = np.eye(4)
        b[:3, :3], b[:3, 3] = cv2.Rodrigues(rvec)[0], tvec.ravel()
        board_in_cam.append(b)
        flange.append(nominal_flange[mine[0]])
    board_in_cam, flange = np.array(board_in_cam), np.array(flange)
    out = {}
    for name, method in METHODS.items():
        if setup["mount"] == "flange":          # camera on the flange: cam -> gripper
            r, t = cv2.calibrateHandEye(flange[:, :3, :3], flange[:, :3, 3], board_in_cam[:, :3, :3],
                                        board_in_cam[:, :3, 3], method=method)
            on_flange = np.eye(4)
            on_flange[:3, :3], on_flange[:3, 3] = r, t.ravel()
            in_cell = mean_pose(flange @ on_flange @ board_in_cam)
        else:                                   # camera in the cell: base -> gripper poses give cam -> base
            inverse = np.linalg.inv(flange)
            r, t = cv2.calibrateHandEye(inverse[:, :3, :3], inverse[:, :3, 3], board_in_cam[:, :3, :3],
                                        board_in_cam[:, :3, 3], method=method)
            in_cell = np.eye(4)
            in_cell[:3, :3], in_cell[:3, 3] = r, t.ravel()
            on_flange = mean_pose(inverse @ in_cell @ board_in_cam)
        out[name] = (on_flange, in_cell)
    return out


def board_centre_miss(setup, study, q, fitted_flange, on_flange, in_cell) -> float:
    """RMS (mm) of the board's centre in the camera's frame, fitted chain against the true one, poses ``q``."""
    centre = np.array([5.5 * setup["square"], 4.0 * setup["square"], 0.0, 1.0])
    true = poses_from(*study.robot.true_flange(q))
    if setup["mount"] == "cell":
        truth = np.linalg.inv(pose_matrix(setup["camera"])) @ true @ pose_matrix(setup["board"]) @ centre
        fitted = np.linalg.inv(in_cell) @ fitted_flange @ on_flange @ centre
    else:
        truth = np.linalg.inv(true @ pose_matrix(setup["camera"])) @ pose_matrix(setup["board"]) @ centre
        fitted = np.linalg.inv(fitted_flange @ on_flange) @ in_cell @ centre
    return float(np.sqrt(np.mean(np.sum((truth - fitted)[:, :3] ** 2, axis=1))))


def rigid_rms(predicted, truth) -> float:
    """RMS (mm) of ``predicted`` points against ``truth`` after the rigid fit (Kabsch) of one onto the other."""
    rot, shift = kabsch(predicted, truth)
    return float(np.sqrt(np.mean(np.sum((predicted @ rot.T + shift - truth) ** 2, axis=1))))


def flange_point(setup) -> np.ndarray:
    """The point on the flange both fits are scored by (flange frame, true): the board's centre (eye-to-hand) or
    the camera's optical centre (eye-in-hand)."""
    if setup["mount"] == "cell":
        return (pose_matrix(setup["board"]) @ np.array([5.5 * setup["square"], 4.0 * setup["square"], 0.0, 1.0]))[:3]
    return np.asarray(setup["camera"][:3], dtype=float)


def tracker_fit(setup, study, q_images, seed):
    """A tracker (``TRACKER_MM`` per axis) measuring the flange point (:func:`flange_point`) at the images' poses,
    identified with the same parametrization (the point's designed offset the nominal tool, its error fitted): the
    nominal robot with that tool and the identification (the fitted robot's positions are the point's)."""
    nominal = study.robot.nominal.replace(tool_mm=flange_point(setup))
    truth = true_points(setup, study, q_images)
    measured = truth + np.random.default_rng(seed + 200).normal(0.0, TRACKER_MM, truth.shape)
    n = len(q_images)
    rows = MeasurementRows(q_images, ("point",) * n, tuple(str(i + 1) for i in range(n)), tuple(range(1, n + 1)),
                           "tracker", {"x_meas": measured[:, 0], "y_meas": measured[:, 1], "z_meas": measured[:, 2]})
    table, _ = identify_measurements(nominal, rows, {"noise": {"point": TRACKER_MM}}, parametrization=PARAMETRIZATION)
    return nominal, table


def expected_rigid_rms(points_of, table, step: float = 1e-4) -> float:
    """The RMS (mm) of a fit's points after a rigid fit that its covariance predicts (``points_of(values)``: the
    points, (n, 3) mm, through the parameter values): the points' Jacobian in the identified parameters (finite
    differences), the six rigid motions of the points projected out, ``sqrt(trace(J C J^T) / n)``. For a least-squares
    fit of Gaussian noise this is the Cramer-Rao bound: no estimator from the same data does better on average."""
    identified = np.flatnonzero(np.array(table.status) == "identified")
    base = points_of(table.value)
    columns = []
    for k in identified:
        value = table.value.copy()
        value[k] += step
        columns.append(((points_of(value) - base) / step).ravel())
    jac = np.array(columns).T
    rigid = np.zeros((base.size, 6))
    for i, p in enumerate(base):        # a shift, then a small turn about the origin: w x p
        rigid[3 * i:3 * i + 3, :3] = np.eye(3)
        rigid[3 * i:3 * i + 3, 3:] = [[0.0, p[2], -p[1]], [-p[2], 0.0, p[0]], [p[1], -p[0], 0.0]]
    basis = np.linalg.qr(rigid)[0]
    jac -= basis @ (basis.T @ jac)
    return float(np.sqrt(np.trace(jac @ table.covariance @ jac.T) / len(base)))


def true_points(setup, study, q) -> np.ndarray:
    """The flange point (:func:`flange_point`) through the true chain at poses ``q``, (n, 3) mm."""
    positions, rotations = study.robot.true_flange(q)
    return positions + rotations @ flange_point(setup)


def point_scores(setup, study, q, camera_points, tracker_points) -> tuple[float, float]:
    """The flange point after a rigid fit over poses ``q``: through the camera's fit (its chain and its pose on the
    flange) and through the tracker's (``*_points(q)``), RMS mm."""
    truth = true_points(setup, study, q)
    return rigid_rms(camera_points(q), truth), rigid_rms(tracker_points(q), truth)


def planned_rows(study, cell: dict, images: int, seed: int) -> MeasurementRows:
    """Pixel rows (0.2 px) of the true robot at ``images`` poses chosen by ``partcal plan --measurement camera``
    (D-optimal among its candidate images, at the nominal robot, the camera's and board's true poses and the true
    intrinsics standing for the cell's approximate ones)."""
    cameras, boards = true_cell(study.cell.sections)
    planning = {**cell, "cameras": {c: {**cell["cameras"][c], "pose": cameras[c]["pose"],
                                        "intrinsics": cameras[c]["intrinsics"]} for c in cell["cameras"]},
                "boards": {b: {**cell["boards"][b], "pose": boards[b]["pose"]} for b in cell["boards"]}}
    plan = plan_measurements(study.robot.nominal, images, planning, "camera", random_state=seed, floor=None)
    image = list(plan.rows.texts["image"])
    q = plan.rows.q_deg[[image.index(name) for name in dict.fromkeys(image)]]
    return pixel_rows(study, q, np.random.default_rng(seed + 300))


def pixel_rows(study, q, rng) -> MeasurementRows:
    """Pixel rows of the true robot at poses ``q``: the board's corners in view, plus 0.2 px of normal noise."""
    cameras, boards = true_cell(study.cell.sections)
    seen, uv = seen_points(cameras["cam1"], boards["b1"], *study.robot.true_flange(q), board_points(boards["b1"]))
    k, point = np.nonzero(seen)
    pixels = uv[k, point] + rng.normal(0.0, 0.2, (k.size, 2))
    n = k.size
    return MeasurementRows(q[k], ("camera",) * n, tuple(str(i + 1) for i in range(n)), tuple(range(1, n + 1)),
                           "pixels", {"point": point.astype(float), "u_px": pixels[:, 0], "v_px": pixels[:, 1]},
                           {"image": tuple(f"image{i + 1}" for i in k), "camera": ("cam1",) * n,
                            "board": ("b1",) * n})


def one(name: str, images: int, seed: int, folder: Path, planned: bool = False, redraws: int = 0) -> dict:
    setup = SETUPS[name]
    mount = setup["mount"]
    text = VIRTUAL.format(seed=seed, mount=mount, camera=setup["camera"], k=setup["k"], square=setup["square"],
                          marker=0.75 * setup["square"], board=setup["board"], images=images)
    (folder / "virtual.yaml").write_text(text)
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", str(folder / "virtual.yaml")]) == 0
    study = load_study(folder / "virtual.yaml")
    nominal = study.robot.nominal
    cell = read_cell(folder / "data" / "cell.yaml")
    rows = planned_rows(study, cell, images, seed) if planned else read_measurement_rows(folder / "data" / "images.csv")
    start = time.perf_counter()
    table, _ = identify_measurements(nominal, rows, cell, parametrization=PARAMETRIZATION)
    seconds = time.perf_counter() - start
    value = dict(zip(table.names, table.value))
    other = "flange" if mount == "cell" else "cell"
    camera = pose_matrix([value[f"camera cam1@{mount}.{c}"] for c in ("x", "y", "z", "rx", "ry", "rz")])
    board = pose_matrix([value[f"board b1@{other}.{c}"] for c in ("x", "y", "z", "rx", "ry", "rz")])
    on_flange, in_cell = (board, camera) if mount == "cell" else (camera, board)
    fitted_robot = robot_with(nominal, table.value[:geometric_size(nominal, PARAMETRIZATION)], PARAMETRIZATION)
    # random poses with the board in view (the true chain's view)
    cameras, boards = true_cell(study.cell.sections)
    q = sample_configurations(nominal, 20000, study.ranges_deg, study.fixed_deg, np.random.default_rng(seed + 100))
    seen = seen_points(cameras["cam1"], boards["b1"], *study.robot.true_flange(q), board_points(boards["b1"]))[0]
    q_random = q[:2000]
    q = q[seen.sum(axis=1) >= seen.shape[1] // 2][:2000]
    true_on_flange = pose_matrix(setup["board"] if mount == "cell" else setup["camera"])
    true_in_cell = pose_matrix(setup["camera"] if mount == "cell" else setup["board"])
    true_flange = poses_from(*study.robot.true_flange(q))

    def hand_eye_error(flange_q, on, cell_pose):
        """The pose on the flange against the truth carried into the fitted chain's frames: the cell's gauge
        from the pose in the cell, the flange's as the mean of fitted^-1 gauge true over the poses."""
        gauge = cell_pose @ np.linalg.inv(true_in_cell)
        return error(mean_pose(np.linalg.inv(flange_q) @ gauge @ true_flange) @ true_on_flange, on)

    out = {"he": hand_eye_error(fitted_robot.flange(q), on_flange, in_cell),
           "k": float(np.max(np.abs(np.array([value[f"camera cam1.{c}"] for c in ("fx", "fy", "cx", "cy")])
                                     - setup["k"][:4]))),
           "view": board_centre_miss(setup, study, q, fitted_robot.flange(q), on_flange, in_cell),
           "seconds": seconds, "in_view": len(q),
           "random": board_centre_miss(setup, study, q_random, fitted_robot.flange(q_random), on_flange, in_cell)}
    q_images = np.unique(rows.q_deg, axis=0)
    tracker_nominal, tracker_table = tracker_fit(setup, study, q_images, seed)
    local = np.linalg.inv(true_on_flange) @ np.r_[flange_point(setup), 1.0]   # in the frame of the pose on the flange
    pose_keys = [table.names.index(f"{'board b1@flange' if mount == 'cell' else 'camera cam1@flange'}.{c}")
                 for c in ("x", "y", "z", "rx", "ry", "rz")]
    size = geometric_size(nominal, PARAMETRIZATION)

    def camera_points(poses, values=table.value):
        chain = robot_with(nominal, values[:size], PARAMETRIZATION)
        return (chain.flange(poses) @ pose_matrix(values[pose_keys]) @ local)[:, :3]

    def tracker_points(poses, values=tracker_table.value):
        return robot_with(tracker_nominal, values[:size], PARAMETRIZATION).positions(poses)

    out["rigid_view"] = point_scores(setup, study, q, camera_points, tracker_points)
    out["rigid_random"] = point_scores(setup, study, q_random, camera_points, tracker_points)
    out["expected_view"] = (expected_rigid_rms(lambda v: camera_points(q, v), table),
                            expected_rigid_rms(lambda v: tracker_points(q, v), tracker_table))
    truth = true_points(setup, study, q)
    again = []
    for k in range(redraws):           # the same poses, the noise drawn again: the spread the expected figure claims
        redrawn = identify_measurements(nominal, pixel_rows(study, q_images, np.random.default_rng(seed + 1000 + k)),
                                        cell, parametrization=PARAMETRIZATION)[0]
        again.append((rigid_rms(camera_points(q, redrawn.value), truth),
                      expected_rigid_rms(lambda v: camera_points(q, v), redrawn)))
    out["redraws"] = np.array(again).reshape(-1, 2)
    methods = opencv(setup, rows, nominal.flange(rows.q_deg))
    scores = {m: hand_eye_error(nominal.flange(q), x, y) for m, (x, y) in methods.items()}
    best = min(scores, key=lambda m: scores[m][0])
    out["cv"] = {m: s for m, s in scores.items()}
    out["cv_best"] = (best, scores[best])
    out["cv_view"] = board_centre_miss(setup, study, q, nominal.flange(q), *methods[best])
    return out


def run(robots: int, setups=tuple(SETUPS), counts=(30, 60, 120), planned: bool = False, redraws: int = 0) -> None:
    logging.getLogger("partcal").setLevel(logging.ERROR)
    table, beside = [], []
    for name in setups:
        for images in counts:
            results = []
            for seed in range(robots):
                with tempfile.TemporaryDirectory() as tmp:
                    results.append(one(name, images, seed, Path(tmp), planned, redraws))
                r = results[-1]
                print(f"  {name} {images} images, robot {seed}: hand-eye {r['he'][0]:.3f} mm {r['he'][1]:.4f} deg, "
                      f"no fit in view {r['view']:.3f} mm, rigid camera/tracker "
                      f"{r['rigid_view'][0] / r['rigid_view'][1]:.2f} (expected "
                      f"{r['expected_view'][0] / r['expected_view'][1]:.2f}), OpenCV best {r['cv_best'][1][0]:.3f} mm, "
                      f"{r['seconds']:.1f} s", file=sys.stderr, flush=True)
                if redraws:
                    d = r["redraws"]
                    print(f"    {redraws} draws of the noise at the same poses: the camera's point after a rigid fit "
                          f"{np.sqrt(np.mean(d[:, 0] ** 2)):.4f} mm RMS ({d[:, 0].min():.4f} to {d[:, 0].max():.4f}), "
                          f"expected {np.mean(d[:, 1]):.4f} mm", file=sys.stderr, flush=True)
            med = lambda f: float(np.median([f(r) for r in results]))  # noqa: E731
            best = max(set(r["cv_best"][0] for r in results), key=[r["cv_best"][0] for r in results].count)
            table.append([name, images, f"{med(lambda r: r['he'][0]):.3f}", f"{med(lambda r: r['he'][1]):.4f}",
                          f"{med(lambda r: r['k']):.2f}", f"{med(lambda r: r['view']):.3f}",
                          f"{med(lambda r: r['seconds']):.1f}",
                          f"{med(lambda r: r['cv_best'][1][0]):.3f}", f"{med(lambda r: r['cv_best'][1][1]):.4f}",
                          best, f"{med(lambda r: r['cv_view']):.3f}",
                          " ".join(f"{m[:4]} {med(lambda r: r['cv'][m][0]):.2f}" for m in METHODS)])
            beside.append([name, images, f"{med(lambda r: r['view']):.3f}", f"{med(lambda r: r['random']):.3f}",
                           f"{med(lambda r: r['rigid_view'][0]):.3f}", f"{med(lambda r: r['rigid_view'][1]):.3f}",
                           f"{med(lambda r: r['rigid_view'][0] / r['rigid_view'][1]):.2f}",
                           f"{med(lambda r: r['expected_view'][0] / r['expected_view'][1]):.2f}",
                           f"{med(lambda r: r['rigid_random'][0]):.3f}", f"{med(lambda r: r['rigid_random'][1]):.3f}",
                           f"{med(lambda r: r['rigid_random'][0] / r['rigid_random'][1]):.2f}"])
    print_table(f"Camera: partcal (robot ({PARAMETRIZATION}) + hand-eye + board + intrinsics from pixels) vs OpenCV "
                f"hand-eye on nominal poses; virtual UR10, 0.2 px, {'planned' if planned else 'random'} images, median of "
                f"{robots} robots",
                ["set-up", "images", "he mm", "he deg", "K px", "view mm", "s", "cv he mm", "cv he deg", "best",
                 "cv view mm", "OpenCV methods (he mm)"], table)
    print("he: the hand-eye against the truth (pose on the flange, in the gauge the images define); K: largest fx, fy, cx, cy "
          "error; view: the board's centre in the camera's frame, no fit, RMS over random poses with the board "
          "in view; s: one identification; cv: OpenCV (solvePnP with the true intrinsics, calibrateHandEye on the "
          "nominal flange poses), best of five by he mm")
    print_table(f"Camera beside a tracker ({TRACKER_MM} mm) on the same poses, both {PARAMETRIZATION}; median of "
                f"{robots} robots",
                ["set-up", "images", "no fit in view mm", "no fit random mm", "rigid in view: camera mm", "tracker mm",
                 "camera/tracker", "expected", "rigid random: camera mm", "tracker mm", "camera/tracker"], beside)
    print("no fit: the board's centre in the camera's frame (as above), on 2,000 poses with the board in view and on "
          "2,000 random poses; rigid: the point on the flange (the board's centre eye-to-hand, the camera's optical "
          "centre eye-in-hand) through each fit's chain after a rigid fit onto the truth; the tracker measures that "
          "point at the images' poses and is identified with the same parametrization; expected: the ratio each "
          "fit's covariance predicts in view (the Cramer-Rao bound of its data; the measured ratio scatters about "
          "it with the noise drawn)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, default=3, help="virtual robots (seeds) per row; median reported")
    parser.add_argument("--parametrization", choices=("dh", "complete"), default="complete")
    parser.add_argument("--setups", nargs="+", choices=tuple(SETUPS), default=tuple(SETUPS), help="default: both")
    parser.add_argument("--images", nargs="+", type=int, default=(30, 60, 120), help="default: 30 60 120")
    parser.add_argument("--redraws", type=int, default=0, help="per robot, identify again from the same poses with "
                        "the noise drawn anew this many times: the RMS the expected figure predicts (standard error)")
    parser.add_argument("--planned", action="store_true",
                        help="images at the poses partcal plan chooses (D-optimal), not at random poses in view")
    args = parser.parse_args()
    PARAMETRIZATION = args.parametrization
    run(args.robots, args.setups, args.images, args.planned, args.redraws)
