"""Board images of a virtual robot: a board's printed pattern (a ChArUco board through ``cv2.aruco``, a chessboard
and an AprilTag grid drawn here) seen by a camera of OpenCV's model (:func:`partcal.calibration.camera_model.project`)
at a pose, each pixel the average of a few samples of the pattern (:func:`render_view`); a folder of such images with
the joints CSV that :func:`partcal.data.detect.detect_folder` reads (:func:`render_folder`). Tests, benchmarks and the
docs render their images with it: no image data is kept in the repository."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write
from ..calibration.camera_cell import camera_T_boards, true_cell
from ..calibration.camera_model import board_points, project
from ..robot.description import joint_columns

PIXELS_PER_MM = 8.0
"""The printed pattern's resolution, pixels per mm."""

SAMPLES = 3
"""Each rendered pixel averages ``SAMPLES x SAMPLES`` samples of the pattern (anti-aliasing)."""

BACKGROUND = 90
"""The grey of what the board does not cover."""

ARUCO_DICTIONARY = cv2.aruco.DICT_4X4_1000
"""The markers of a ChArUco board (and of the detection that reads it)."""

TAG_DICTIONARIES = {"16h5": cv2.aruco.DICT_APRILTAG_16h5, "25h9": cv2.aruco.DICT_APRILTAG_25h9,
                    "36h10": cv2.aruco.DICT_APRILTAG_36h10, "36h11": cv2.aruco.DICT_APRILTAG_36h11}
"""OpenCV's dictionary of each AprilTag family (:data:`partcal.calibration.camera_cell.TAG_FAMILIES`)."""


def tag_dictionary(board: dict):
    """OpenCV's dictionary of an AprilTag grid's tags (tag ``t`` of the grid is the family's tag ``t``)."""
    return cv2.aruco.getPredefinedDictionary(TAG_DICTIONARIES[board.get("family", "36h11")])


def tag_cells(board: dict) -> int:
    """The cells across one tag (its code's bits and the black border around them)."""
    return tag_dictionary(board).markerSize + 2


def charuco_board(board: dict):
    """OpenCV's ChArUco board of a board of the cell (``cols`` x ``rows`` squares, sizes in mm)."""
    return cv2.aruco.CharucoBoard((int(board["cols"]), int(board["rows"])), float(board["square_mm"]),
                                  float(board["marker_mm"]), cv2.aruco.getPredefinedDictionary(ARUCO_DICTIONARY))


def pattern(board: dict) -> tuple[NDArray[np.uint8], float]:
    """The printed pattern (grey image, :data:`PIXELS_PER_MM`) with a white margin of one square around the
    squares, and the margin (mm): board point ``(x, y)`` mm is at pixel ``((x + margin) ppm - 1/2, (y + margin)
    ppm - 1/2)``."""
    s, rows, cols = float(board["square_mm"]), int(board["rows"]), int(board["cols"])
    width, height = int(round(cols * s * PIXELS_PER_MM)), int(round(rows * s * PIXELS_PER_MM))
    if board["type"] == "charuco":
        squares = charuco_board(board).generateImage((width, height), marginSize=0, borderBits=1)
    elif board["type"] == "chessboard":
        y, x = np.mgrid[0:height, 0:width]
        r, c = ((y + 0.5) / PIXELS_PER_MM // s).astype(int), ((x + 0.5) / PIXELS_PER_MM // s).astype(int)
        squares = np.where((r + c) % 2 == 0, 0, 255).astype(np.uint8)
    else:
        squares = _tag_grid(board, width, height)
    margin = int(round(s * PIXELS_PER_MM))
    return cv2.copyMakeBorder(squares, margin, margin, margin, margin, cv2.BORDER_CONSTANT, value=255), s


def _tag_grid(board: dict, width: int, height: int) -> NDArray[np.uint8]:
    """An AprilTag grid's printed tags on white: tag ``r cols + c`` (its black border ``marker_mm`` wide) centred
    in the grid's square ``(r, c)``; each pixel takes the colour of the tag's cell its centre falls in."""
    s, half, cols = float(board["square_mm"]), float(board["marker_mm"]) / 2, int(board["cols"])
    dictionary, cells = tag_dictionary(board), tag_cells(board)
    count = int(board["rows"]) * cols
    bits = np.array([cv2.aruco.generateImageMarker(dictionary, t, cells, borderBits=1) for t in range(count)])

    def cell(pixels: int):
        at = (np.arange(pixels) + 0.5) / PIXELS_PER_MM
        square = (at // s).astype(int)
        k = np.floor((at - (square + 0.5) * s + half) / (2 * half) * cells).astype(int)
        inside = (k >= 0) & (k < cells)
        return square, np.clip(k, 0, cells - 1), inside

    r, v, inside_v = cell(height)
    c, u, inside_u = cell(width)
    tags = r[:, None] * cols + c[None, :]
    out = bits[tags, v[:, None], u[None, :]]
    return np.where(inside_v[:, None] & inside_u[None, :], out, 255).astype(np.uint8)


def camera_rays(camera: dict, step: int = 2) -> NDArray[np.float64]:
    """The normalised, undistorted image coordinates ``(x, y, 1)`` of every sample of a camera's image, shape
    (H S, W S, 3) (S = :data:`SAMPLES`): computed once per camera, used for every view. The distortion is inverted
    exactly on a grid of nodes ``step`` pixels apart and interpolated (bicubic, at OpenCV's 1/32 of a node) between them:
    it is smooth (thousandths of a pixel)."""
    width, height = camera["image_size"]
    k = np.asarray(camera["intrinsics"], dtype=float)
    matrix = np.array([[k[0], 0.0, k[2]], [0.0, k[1], k[3]], [0.0, 0.0, 1.0]])
    nodes_u = np.arange(-2 * step, width + 3 * step, step, dtype=float)
    nodes_v = np.arange(-2 * step, height + 3 * step, step, dtype=float)
    grid = np.stack(np.meshgrid(nodes_u, nodes_v), axis=-1).reshape(-1, 1, 2)
    exact = cv2.undistortPointsIter(grid, matrix, k[4:], None, None,
                                    (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-14))[:, 0]
    pinhole = (grid[:, 0] - k[2:4]) / k[:2]
    delta = (exact - pinhole).reshape(nodes_v.size, nodes_u.size, 2).astype(np.float32)
    offsets = (np.arange(SAMPLES) + 0.5) / SAMPLES - 0.5
    u = (np.arange(width)[:, None] + offsets).ravel()
    v = (np.arange(height)[:, None] + offsets).ravel()
    map_u = np.broadcast_to(((u - nodes_u[0]) / step).astype(np.float32), (v.size, u.size))
    map_v = np.broadcast_to(((v - nodes_v[0]) / step).astype(np.float32)[:, None], (v.size, u.size))
    out = np.empty((v.size, u.size, 3))
    out[..., 0] = (u[None, :] - k[2]) / k[0]
    out[..., 1] = (v[:, None] - k[3]) / k[1]
    out[..., 2] = 1.0
    for c in range(2):
        out[..., c] += cv2.remap(np.ascontiguousarray(delta[..., c]), np.ascontiguousarray(map_u),
                                 np.ascontiguousarray(map_v), cv2.INTER_CUBIC)
    return out


def render_view(rays: NDArray[np.float64], texture: tuple, cam_T_board: NDArray[np.float64],
                rng: np.random.Generator, noise: float = 2.0, blur: float = 0.6) -> NDArray[np.uint8]:
    """The grey image a camera (its :func:`camera_rays`) takes of a board's ``texture`` (:func:`pattern`) at
    ``cam_T_board`` (4, 4; mm): each sample's ray met with the board's plane, the pattern sampled there, the
    samples averaged per pixel, a slight blur (``blur`` px, the lens) and grey noise (``noise`` levels)."""
    image, margin = texture
    rotation, shift = cam_T_board[:3, :3], cam_T_board[:3, 3]
    normal = rotation[:, 2]
    depth = (normal @ shift) / (rays @ normal)                  # the ray's length to the board's plane
    points = rays * depth[..., None] - shift
    local = points @ rotation                                   # board frame (mm): x, y on the plane
    map_x = ((local[..., 0] + margin) * PIXELS_PER_MM - 0.5).astype(np.float32)
    map_y = ((local[..., 1] + margin) * PIXELS_PER_MM - 0.5).astype(np.float32)
    behind = depth <= 0
    map_x[behind] = -1e6
    sampled = cv2.remap(image, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                        borderValue=BACKGROUND).astype(np.float32)
    height, width = rays.shape[0] // SAMPLES, rays.shape[1] // SAMPLES
    pixels = sampled.reshape(height, SAMPLES, width, SAMPLES).mean(axis=(1, 3))
    if blur > 0:
        pixels = cv2.GaussianBlur(pixels, (0, 0), blur)
    pixels = pixels + rng.normal(0.0, noise, pixels.shape)
    return np.clip(np.rint(pixels), 0, 255).astype(np.uint8)


def render_folder(folder: str | Path, camera: dict, board: dict, cam_T_boards: NDArray[np.float64],
                  q_deg: NDArray[np.float64], rng: np.random.Generator, names: list[str] | None = None) -> list[Path]:
    """Write one PNG per view (``image_0001.png``, ...) and ``joints.csv`` (``image, q1..qN``, one row per
    image) into ``folder``; return the images' paths. ``cam_T_boards`` (n, 4, 4) the board in the camera's frame
    at each view, ``q_deg`` (n, N) the joints of each."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rays, texture = camera_rays(camera), pattern(board)
    names = names or [f"image_{k + 1:04d}.png" for k in range(len(q_deg))]
    paths = []
    for name, pose in zip(names, cam_T_boards):
        path = folder / name
        cv2.imwrite(str(path), render_view(rays, texture, pose, rng))
        paths.append(path)
    with atomic_write(folder / "joints.csv", newline="") as handle:
        handle.write(",".join(["image", *joint_columns(q_deg.shape[1])]) + "\n")
        for name, q in zip(names, q_deg):
            handle.write(",".join([name, *(f"{v:.6f}" for v in q)]) + "\n")
    return paths


def true_pixels(camera: dict, board: dict, cam_T_board: NDArray[np.float64]) -> NDArray[np.float64]:
    """Every board point's true pixel (p, 2) in a view (its id the row)."""
    local = board_points(board)
    points = local @ cam_T_board[:3, :3].T + cam_T_board[:3, 3]
    return project(points, np.asarray(camera["intrinsics"], dtype=float))[0]


def image_files(rows, sections: dict, true_flange, rng: np.random.Generator) -> dict[str, bytes]:
    """The images of a virtual robot's camera rows (``partcal simulate`` with ``render: true``): for each camera,
    ``<camera>/<image>.png`` of every image of ``rows`` (the board at the true robot's pose of that image) and
    ``<camera>/joints.csv`` (``image, q1..qN``: the folder ``partcal detect`` reads). ``sections``: the virtual
    cell's true ``cameras:`` and ``boards:`` (:func:`partcal.calibration.camera_cell.true_cell`);
    ``true_flange(q)``: the true flange's positions and rotations. Returns relative path -> the file's bytes."""
    cameras, boards = true_cell(sections)
    images, first = np.unique(np.asarray(rows.texts["image"]), return_index=True)
    order = np.argsort(first)
    files = {}
    for cam in dict.fromkeys(rows.texts["camera"]):
        mine = [k for k in order if rows.texts["camera"][first[k]] == cam]
        rays, textures = camera_rays(cameras[cam]), {}
        lines = [",".join(["image", *joint_columns(rows.q_deg.shape[1])])]
        for k in mine:
            row = first[k]
            q = rows.q_deg[row:row + 1]
            name = rows.texts["board"][row]
            texture = textures.setdefault(name, pattern(boards[name]))
            pose = camera_T_boards(cameras[cam], boards[name], *true_flange(q))[0]
            png = cv2.imencode(".png", render_view(rays, texture, pose, rng))[1]
            files[f"{cam}/{images[k]}.png"] = png.tobytes()
            lines.append(",".join([f"{images[k]}.png", *(f"{v:.6f}" for v in q[0])]))
        files[f"{cam}/joints.csv"] = ("\n".join(lines) + "\n").encode()
    return files
