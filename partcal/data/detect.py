"""Images in: the points of a board detected in a folder of images with OpenCV, paired with their joints by the
image's name, as camera rows (:func:`detect_folder`, :func:`write_pixel_rows`).

The joints CSV has one row per image: ``image`` (the file's name in the folder) and ``q1..qN`` (degrees). An image is
paired with the row that names it, never by order, so an image where nothing is found is reported by name and
shifts no other. A ChArUco board is read through ``cv2.aruco`` (each corner's id from the markers around it); a
chessboard through ``cv2.findChessboardCornersSB`` refined by ``cv2.cornerSubPix``, its corners ordered by the board's own frame: seen from the
front (the board's x along its columns, y along its rows) and its square (0, 0) black. A chessboard that looks the
same turned half a turn (both square counts even or both odd) cannot be ordered so: it is warned of. An AprilTag
grid's tags are read by ``cv2.aruco`` and each corner is where two lines fitted to the tag's border edges meet
(:func:`detect_tags`).
"""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from ..calibration.camera_cell import half_turn_symmetric
from ..calibration.measurement import MeasurementRows
from ..errors import DataError
from ..robot.kinematics import Robot
from .boards import charuco_board, tag_cells, tag_dictionary
from .measurement_rows import write_measurement_rows

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
"""The files of a folder read as images."""

SUBPIXEL = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
"""The chessboard corners' refinement (``cv2.cornerSubPix`` in a 11 x 11 window): halves the sector-based
detector's error on rendered boards (0.13 -> 0.07 px RMS)."""

MIN_POINTS = 6
"""An image with fewer points of the board found counts as one where nothing was found."""


BLUR_CELLS = 1 / 3
"""A tag's edge blurred wider (the step's sigma) than this share of its cells is not fitted: the pixels across it
then hold too little of the step."""


@dataclass
class Detections:
    """What :func:`detect_folder` found: the camera rows, the images where nothing (or too little) was found, and
    warnings in words."""

    rows: MeasurementRows | None
    not_found: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def read_joints(path: str | Path, robot: Robot) -> dict[str, tuple[NDArray[np.float64], int]]:
    """The joints CSV: image name -> (joints (N,) degrees, line). Refused, naming file, line and column: no
    ``image`` column, a joint count that is not the robot's, an empty or non-numeric cell, an image named twice."""
    path = Path(path)
    with open(path, newline="") as handle:
        lines = [(k + 1, row) for k, row in enumerate(csv.reader(handle)) if row and not row[0].startswith("#")]
    if not lines:
        raise DataError(f"{path}: empty file; expected a header 'image,q1,...,q{robot.n_joints}' and a row per image")
    header_line, header = lines[0]
    header = [h.strip() for h in header]
    if "image" not in header:
        raise DataError(f"{path}:{header_line}: no column 'image' (the image's file name in the folder); got "
                        f"{', '.join(header)}")
    joints = [h for h in header if h.startswith("q") and h[1:].isdigit()]
    expected = [f"q{k + 1}" for k in range(robot.n_joints)]
    if joints != expected:
        raise DataError(f"{path}:{header_line}: columns {', '.join(joints) or 'none'}: expected the {robot.n_joints} "
                        f"joints of {robot.name} ({', '.join(expected)}), degrees")
    at = {h: header.index(h) for h in ("image", *joints)}
    out: dict[str, tuple[NDArray[np.float64], int]] = {}
    for line, row in lines[1:]:
        name = row[at["image"]].strip() if len(row) > at["image"] else ""
        if not name:
            raise DataError(f"{path}:{line}: column 'image': expected an image's file name, got none")
        if name in out:
            raise DataError(f"{path}:{line}: column 'image': {name!r} is named on line {out[name][1]} already")
        q = []
        for column in joints:
            text = row[at[column]].strip() if len(row) > at[column] else ""
            try:
                value = float(text)
            except ValueError:
                value = float("nan")
            if not np.isfinite(value):
                raise DataError(f"{path}:{line}: column {column!r}: expected a joint angle in degrees, got {text!r}")
            q.append(value)
        out[name] = (np.array(q), line)
    return out


def detect_board(image: NDArray[np.uint8], board: dict, unfitted: list[int] | None = None
                 ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """The board points found in a grey image: their ids (k,) and pixels (k, 2) (empty when none). ``unfitted``
    collects the tags of an AprilTag grid that were read but whose corners could not be fitted
    (:func:`detect_tags`)."""
    if board["type"] == "charuco":
        corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco_board(board)).detectBoard(image)
        if ids is None or len(ids) == 0:
            return np.zeros(0, dtype=np.intp), np.zeros((0, 2))
        return ids.ravel().astype(np.intp), corners[:, 0].astype(float)
    if board["type"] == "chessboard":
        size = (int(board["cols"]) - 1, int(board["rows"]) - 1)
        found, corners = cv2.findChessboardCornersSB(image, size, flags=cv2.CALIB_CB_ACCURACY)
        if not found:
            return np.zeros(0, dtype=np.intp), np.zeros((0, 2))
        corners = cv2.cornerSubPix(image, corners, (5, 5), (-1, -1), SUBPIXEL)      # SB's own: ~0.13 px
        grid = chessboard_order(image, corners[:, 0].astype(float).reshape(size[1], size[0], 2))
        return np.arange(grid.shape[0] * grid.shape[1]), grid.reshape(-1, 2)
    if board["type"] == "apriltag":
        return detect_tags(image, board, unfitted)
    raise DataError(f"detecting a {board['type']} board is not built; expected chessboard, charuco or apriltag")


def detect_tags(image: NDArray[np.uint8], board: dict, unfitted: list[int] | None = None
                ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """An AprilTag grid's tag corners found in a grey image: ids ``4 t + k`` (k: top left, top right, bottom
    right, bottom left) and pixels. ``cv2.aruco`` finds and reads the tags; each corner is then the meeting of
    two of the tag's border lines, each fitted to the pixels across its edge (:func:`edge_line`). OpenCV's own
    corner refinements leave 0.6-0.7 px on rendered tags (a tag's corner is no saddle point, and its contour is
    traced on whole pixels); the edges' lines about a tenth of that. A tag whose edges cannot be fitted (too small,
    blurred over more than a third of its cells, cut by the image's border) is left out and its id appended to
    ``unfitted``."""
    count = int(board["rows"]) * int(board["cols"])
    corners, ids, _ = cv2.aruco.ArucoDetector(tag_dictionary(board)).detectMarkers(image)
    if ids is None:
        return np.zeros(0, dtype=np.intp), np.zeros((0, 2))
    grey = image.astype(float)
    gap = (float(board["square_mm"]) - float(board["marker_mm"])) / float(board["marker_mm"])
    out_ids, out_uv, cells = [], [], tag_cells(board)
    for tag, quad in zip(ids.ravel(), corners):
        if tag >= count:
            continue                                       # a tag of the family that is not the grid's
        refined = tag_corners(grey, quad[0].astype(float), cells, gap)
        if refined is None:
            if unfitted is not None:
                unfitted.append(int(tag))
            continue
        out_ids.append(4 * int(tag) + np.arange(4))
        out_uv.append(refined)
    if not out_ids:
        return np.zeros(0, dtype=np.intp), np.zeros((0, 2))
    order = np.argsort(np.concatenate(out_ids))
    return np.concatenate(out_ids)[order].astype(np.intp), np.vstack(out_uv)[order]


def tag_corners(grey: NDArray[np.float64], quad: NDArray[np.float64], cells: int, gap: float
                ) -> NDArray[np.float64] | None:
    """A tag's four corners (4, 2) where its border lines meet (:func:`edge_line`), from OpenCV's ``quad``; None
    when an edge is too short to fit (under 8 pixels) or its fit fails. ``cells``: the cells across the tag;
    ``gap``: the white between two tags, in tag widths."""
    centre = quad.mean(axis=0)
    lines = [edge_line(grey, quad[k], quad[(k + 1) % 4], centre, cells, gap) for k in range(4)]
    if any(line is None for line in lines):
        return None
    corners = np.array([_meet(lines[k - 1], lines[k]) for k in range(4)])        # corner k: edges k - 1 and k
    return corners if np.all(np.abs(corners - quad) < 3.0) else None             # (NaN where two are parallel)


def _meet(first, second) -> NDArray[np.float64]:
    """Where two lines (a point and a direction each) meet; NaN where they are parallel."""
    (p, d), (q, e) = first, second
    det = d[1] * e[0] - d[0] * e[1]
    if abs(det) < 1e-9:
        return np.full(2, np.nan)
    t = ((q - p)[1] * e[0] - (q - p)[0] * e[1]) / det
    return p + t * d


def edge_line(grey: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64],
              centre: NDArray[np.float64], cells: int, gap: float
              ) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The line of a tag's border edge from ``a`` to ``b`` (a point and a unit direction): the pixels across the
    edge (0.6 of a cell inside, within the black border; up to a cell outside, within 0.6 of the white gap) away
    from its ends, fitted by least squares (Levenberg-Marquardt, :func:`_step_fit`) with a blurred step,
    ``dark + (light - dark) Phi(d / sigma)`` of the distance ``d`` to the line (offset and turn about the edge's
    middle): every pixel's grey counts, none is interpolated, and a blur symmetric about the edge moves it nowhere."""
    length = float(np.linalg.norm(b - a))
    if length < 8.0:
        return None
    t = (b - a) / length
    n = np.array([t[1], -t[0]])
    if n @ ((a + b) / 2 - centre) < 0:
        n = -n                                             # outwards: dark inside, light outside
    cell = length / cells
    inner, outer = 0.6 * cell, cell * min(1.0, 0.6 * gap * cells)
    ends = max(0.6 * cell, 2.5)
    lo = np.floor(np.minimum(a, b) - max(inner, outer) - 1).astype(int)
    hi = np.ceil(np.maximum(a, b) + max(inner, outer) + 1).astype(int)
    lo, hi = np.maximum(lo, 0), np.minimum(hi, np.array(grey.shape[::-1]) - 1)
    if np.any(hi - lo < 2):
        return None
    v, u = np.mgrid[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1]
    rel = np.column_stack([u.ravel(), v.ravel()]) - a
    d, s = rel @ n, rel @ t
    keep = (d > -inner) & (d < outer) & (s > ends) & (s < length - ends)
    if keep.sum() < 12:
        return None
    d, s = d[keep], s[keep] - length / 2
    value = grey[v.ravel()[keep], u.ravel()[keep]]
    dark, light = np.percentile(value, 5), np.percentile(value, 95)
    start = np.clip((light - value.mean()) / max(light - dark, 1.0) * (inner + outer) - inner, -inner, outer)
    x = np.array([start, 0.0, dark, light, 0.8])          # offset, turn, dark, light, sigma
    x = _step_fit(x, d, s, value)
    if not (np.isfinite(x).all() and abs(x[0]) < 3.0 and x[3] - x[2] > 10 and x[4] < BLUR_CELLS * cell):
        return None
    direction = t + x[1] * n
    return a + (length / 2) * t + x[0] * n, direction / np.linalg.norm(direction)


def _step_fit(x: NDArray[np.float64], d: NDArray[np.float64], s: NDArray[np.float64], value: NDArray[np.float64]
              ) -> NDArray[np.float64]:
    """A blurred step's five (:func:`edge_line`: offset, turn, dark, light, sigma) fitted from ``x`` by
    Levenberg-Marquardt to the greys ``value`` at distances ``d`` across the edge and ``s`` along it."""

    def model(x):
        z = (d - x[0] - x[1] * s) / x[4]
        cdf = ndtr(z)
        return x[2] + (x[3] - x[2]) * cdf - value, z, cdf

    residual, z, cdf = model(x)
    cost, damping = float(residual @ residual), 1e-3
    for _ in range(50):
        pdf, span = np.exp(-0.5 * z * z) / np.sqrt(2 * np.pi), x[3] - x[2]
        jac = np.column_stack([-span * pdf / x[4], -span * pdf * s / x[4], 1 - cdf, cdf, -span * pdf * z / x[4]])
        normal, gradient = jac.T @ jac, jac.T @ residual
        step = np.linalg.solve(normal + damping * np.diag(np.diag(normal) + 1e-12), -gradient)
        trial = x + step
        trial[4] = max(trial[4], 0.2)
        r2, z2, cdf2 = model(trial)
        if r2 @ r2 < cost:
            x, residual, z, cdf, cost = trial, r2, z2, cdf2, float(r2 @ r2)
            damping /= 3
            if abs(step[0]) < 1e-5 and abs(step[1]) < 1e-7:
                break
        else:
            damping *= 4
            if damping > 1e8:
                break
    return x


def chessboard_order(image: NDArray[np.uint8], grid: NDArray[np.float64]) -> NDArray[np.float64]:
    """A chessboard's inner corners (rows, cols, 2) reordered into the board's frame: of the four orders OpenCV may
    return (as is, half a turn, mirrored either way), those seen from the front (the board's x and y turning as
    the image's u and v), then the one whose first square, between its first four corners, is black."""
    candidates = [grid, grid[::-1, ::-1], grid[::-1, :], grid[:, ::-1]]
    front = [g for g in candidates if _turn(g) > 0]
    return min(front, key=lambda g: _grey(image, g[:2, :2].reshape(-1, 2).mean(axis=0)))


def _turn(grid: NDArray[np.float64]) -> float:
    x, y = grid[0, 1] - grid[0, 0], grid[1, 0] - grid[0, 0]
    return float(x[0] * y[1] - x[1] * y[0])


def _grey(image: NDArray[np.uint8], at: NDArray[np.float64]) -> float:
    u, v = (int(round(c)) for c in at)
    return float(image[max(v - 1, 0):v + 2, max(u - 1, 0):u + 2].mean())


def detect_folder(folder: str | Path, joints: str | Path, robot: Robot, board: dict, camera: str,
                  board_name: str = "", image_size: tuple[int, int] | None = None) -> Detections:
    """Detect a board in every image of ``folder`` and pair each with its joints (``joints``: the CSV of
    :func:`read_joints`, by the image's name).

    Parameters
    ----------
    folder : path
        The images (:data:`IMAGE_SUFFIXES`).
    joints : path
        One row per image: ``image, q1..qN``.
    robot : Robot
        Its joint count is the CSV's.
    board : dict
        The board as the cell's ``boards:`` gives it (``type, rows, cols, square_mm, marker_mm``).
    camera, board_name : str
        The rows' ``camera`` and ``board`` columns.
    image_size : (width, height), optional
        The camera's; an image of another size is refused.

    Returns
    -------
    Detections
        The rows (None when nothing was found anywhere), the images where nothing was found (by name), warnings.

    Raises
    ------
    DataError
        Naming the file and line or the image: an image with no row of joints, a row naming no image of the folder,
        an image that cannot be read or is of another size than the camera's.
    """
    folder, joints = Path(folder), Path(joints)
    rows = read_joints(joints, robot)
    images = sorted(p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    for name in images:
        if name not in rows:
            raise DataError(f"{folder / name}: no row of {joints} names this image (column 'image'); every image "
                            "needs the joints it was taken at")
    for name, (_, line) in rows.items():
        if name not in images:
            raise DataError(f"{joints}:{line}: column 'image': {name!r} is not an image of {folder}")
    out = Detections(None)
    if half_turn_symmetric(board):
        out.warnings.append(f"board {board_name or board['type']}: a chessboard of {board['rows']} x {board['cols']} "
                            "squares looks the same turned half a turn: its corners' order may flip between images "
                            "(use one odd and one even count, or a ChArUco board)")
    q, texts, numbers = [], {"image": [], "camera": [], "board": []}, {"point": [], "u_px": [], "v_px": []}
    for name in images:
        image = cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise DataError(f"{folder / name}: cannot be read as an image")
        if image_size is not None and tuple(image.shape[::-1]) != tuple(image_size):
            raise DataError(f"{folder / name}: {image.shape[1]} x {image.shape[0]} pixels; camera {camera!r}'s "
                            f"image_size is {image_size[0]} x {image_size[1]}")
        unfitted: list[int] = []
        ids, uv = detect_board(image, board, unfitted)
        if unfitted:
            out.warnings.append(f"{folder / name}: tags {', '.join(map(str, unfitted))} read but their corners not "
                                "fitted (blurred, too small or cut by the image's border): left out")
        if ids.size < MIN_POINTS:
            out.not_found.append(name)
            continue
        q.append(np.repeat(rows[name][0][None], ids.size, axis=0))
        texts["image"] += [name] * ids.size
        texts["camera"] += [camera] * ids.size
        texts["board"] += [board_name] * ids.size
        numbers["point"].append(ids.astype(float))
        numbers["u_px"].append(uv[:, 0])
        numbers["v_px"].append(uv[:, 1])
    for name in out.not_found:
        out.warnings.append(f"{folder / name}: no board found (fewer than {MIN_POINTS} points); the image is left "
                            "out, the others keep their own joints")
    for text in out.warnings:
        log.warning("%s", text)
    if q:
        q = np.vstack(q)
        n = len(q)
        out.rows = MeasurementRows(q, ("camera",) * n, tuple(f"{i}:{int(p)}" for i, p in zip(
            texts["image"], np.concatenate(numbers["point"]))), tuple(range(2, n + 2)), str(folder),
            {k: np.concatenate(v) for k, v in numbers.items()}, {k: tuple(v) for k, v in texts.items()})
    return out


def write_pixel_rows(detections: Detections, path: str | Path) -> None:
    """Write the camera rows as a measurements CSV (``partcal run`` reads it with a cell's ``cameras:`` and
    ``boards:``)."""
    if detections.rows is None:
        raise DataError(f"no board was found in any image ({', '.join(detections.not_found)}): nothing to write")
    write_measurement_rows(detections.rows, path, comment="camera rows detected by partcal (partcal.data.detect)")
