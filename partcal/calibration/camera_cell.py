"""The camera's cell: the cell description's cameras and boards (read and checked), a board's half-turn symmetry,
a virtual cell's true cameras and boards and the pixel rows its images give (``partcal simulate``), and what an
identified table gives out (a camera's ``camera_info`` YAML, the cameras' and boards' frames). Used by
:mod:`.camera`."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .._yamlio import Section
from ..errors import DataError, PartcalError
from ..robot.rotations import poses_from
from .camera_model import INTRINSICS, board_points, pose_matrix, project
from .cell import named_entry
from .measurement import MeasurementRows

BOARD_TYPES = ("chessboard", "charuco", "apriltag")

TAG_FAMILIES = {"36h11": 587, "36h10": 2320, "25h9": 35, "16h5": 30}
"""An AprilTag grid's ``family`` (default ``36h11``) and its count of tags: tag ``t`` of the grid, row by row, is the
family's tag ``t``."""
MOUNTS = ("cell", "flange")
POSE = ("x", "y", "z", "rx", "ry", "rz")
OBLIQUE_DEG = 60.0
"""A simulated image sees the board turned at most this far from the camera's line of sight."""
MARGIN_PX = 10.0
"""A simulated image keeps the points at least this far inside its edges."""


def _positive(value) -> str | None:
    return None if np.isfinite(value) and value > 0 else "a finite number > 0"


def read_camera(entry) -> dict:
    """One camera of the cell's ``cameras:``: its mount, image size, intrinsics and whether they are fitted."""
    out = {"mount": entry.get("mount", "str", check=lambda v: None if v in MOUNTS else "'cell' or 'flange'"),
           "fit_intrinsics": entry.get("fit_intrinsics", "bool", default=True)}
    size = entry.get("image_size", "list", check=lambda v: None if len(v) == 2 and all(
        isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in v) else "[width, height] in pixels")
    out["image_size"] = [int(v) for v in size]
    if entry.has("intrinsics"):
        sec = entry.section("intrinsics")
        values = {}
        for key in INTRINSICS:
            required = key in INTRINSICS[:4]
            values[key] = sec.get(key, "float", **({} if required else {"default": 0.0}),
                                  check=_positive if required else lambda v: None if np.isfinite(v) else "finite")
        sec.done()
        out["intrinsics"] = [values[k] for k in INTRINSICS]
    elif not out["fit_intrinsics"]:
        entry.fail(entry.path("intrinsics"), "is required with fit_intrinsics: false (known intrinsics: fx, fy, cx, "
                                             "cy in pixels, and k1, k2, p1, p2, k3); got none")
    if entry.has("pose"):           # the truth of a virtual cell (partcal simulate): x, y, z mm, rx, ry, rz degrees
        out["pose"] = [float(v) for v in entry.get("pose", "list", check=_six)]
    entry.done()
    return out


def read_board(entry) -> dict:
    """One board of the cell's ``boards:``: its type, size (squares or tags), and sizes in mm (required)."""
    out = {"type": entry.get("type", "str", check=lambda v: None if v in BOARD_TYPES else
                             f"one of {', '.join(BOARD_TYPES)}")}
    for key in ("rows", "cols"):
        out[key] = entry.get(key, "int", check=lambda v: None if v >= 2 else "an integer >= 2")
    out["square_mm"] = entry.get("square_mm", "float", check=_positive)
    if out["type"] != "chessboard":
        out["marker_mm"] = entry.get("marker_mm", "float", check=lambda v: _positive(v) or (
            None if v < out["square_mm"] else f"smaller than square_mm ({out['square_mm']:g})"))
    if out["type"] == "apriltag":
        family = entry.get("family", "str", "36h11", check=lambda v: _family(v, out["rows"], out["cols"]))
        if family != "36h11":
            out["family"] = family
    if entry.has("pose"):
        out["pose"] = [float(v) for v in entry.get("pose", "list", check=_six)]
    entry.done()
    return out


def _family(value: str, rows: int, cols: int) -> str | None:
    if value not in TAG_FAMILIES:
        return f"one of {', '.join(TAG_FAMILIES)}"
    if TAG_FAMILIES[value] < rows * cols:
        return f"a family of {rows * cols} tags or more (a grid of {rows} x {cols}; it has {TAG_FAMILIES[value]})"
    return None


def _six(value) -> str | None:
    ok = len(value) == 6 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    return None if ok else "[x, y, z, rx, ry, rz] (mm, a rotation vector in degrees)"


def half_turn_symmetric(board: dict) -> bool:
    """Whether the board's points look the same turned half a turn about its normal (its corners' ids then
    cannot tell its two orientations apart): a chessboard of an odd count of squares along one side and an even
    count along the other is not; one with both counts even or both odd is (its colours then repeat under the
    turn). A ChArUco board or a tag grid never is (its markers are read)."""
    return board["type"] == "chessboard" and (board["rows"] - board["cols"]) % 2 == 0



def simulated_rows(truth, spec, rng, noise) -> MeasurementRows:
    """Camera rows of a virtual robot (``partcal simulate``; :meth:`CameraPoints.simulate
    <partcal.calibration.camera.CameraPoints.simulate>`): ``spec`` ``{images: N, cameras: [names], min_points: k,
    render: bool}`` (default: 30 images of every camera of the true cell, each seeing at least half its board;
    ``render: true`` writes the images too, :func:`partcal.data.boards.image_files`). Poses are drawn within the
    config's ranges and kept when the board is in front of the camera, turned less than :data:`OBLIQUE_DEG` from
    it and ``min_points`` of its points fall inside the image; the true cell's cameras and boards give their
    ``pose`` (``[x, y, z, rx, ry, rz]``: mm, a rotation vector in degrees) and the cameras their ``intrinsics``."""
    unknown = set(spec) - {"images", "cameras", "min_points", "render"}
    if unknown:
        raise DataError(f"a camera data set reads images, cameras, min_points, render; got "
                        f"{', '.join(sorted(unknown))}")
    cameras, boards = true_cell(truth.cell)
    count = int(spec.get("images", 30))
    q_all, texts, numbers = [], {"image": [], "camera": [], "board": []}, {"point": [], "u_px": [], "v_px": []}
    for cam in spec.get("cameras") or list(cameras):
        if cam not in cameras:
            raise DataError(f"a camera data set names camera {cam!r}; the cell has {', '.join(cameras)}")
        board = next(iter(boards))
        local = board_points(boards[board])
        least = int(spec.get("min_points", (local.shape[0] + 1) // 2))
        taken = 0
        for _ in range(200):
            q = truth.sample(200, rng)
            seen, uv = seen_points(cameras[cam], boards[board], *truth.robot.true_flange(q), local)
            good = np.flatnonzero(seen.sum(axis=1) >= least)[:count - taken]
            for i in good:
                points = np.flatnonzero(seen[i])
                image = f"{cam}-{taken + 1:04d}"
                q_all.append(np.repeat(q[i][None], points.size, axis=0))
                texts["image"] += [image] * points.size
                texts["camera"] += [cam] * points.size
                texts["board"] += [board] * points.size
                numbers["point"].append(points.astype(float))
                noisy = uv[i, points] + rng.normal(0.0, noise, (points.size, 2))
                numbers["u_px"].append(noisy[:, 0])
                numbers["v_px"].append(noisy[:, 1])
                taken += 1
            if taken == count:
                break
        else:
            raise DataError(f"camera {cam!r} sees board {board!r} in {taken} of 40,000 poses drawn; {count} wanted "
                            "(the sampling ranges, the camera's pose or the board's)")
    q = np.vstack(q_all)
    n = len(q)
    size = {c: cameras[c]["image_size"] for c in cameras}
    u = np.concatenate(numbers["u_px"])
    v = np.concatenate(numbers["v_px"])
    width = np.array([size[c][0] for c in texts["camera"]], dtype=float)
    height = np.array([size[c][1] for c in texts["camera"]], dtype=float)
    return MeasurementRows(q, ("camera",) * n, tuple(str(i + 1) for i in range(n)), tuple(range(1, n + 1)),
                           "camera", {"point": np.concatenate(numbers["point"]), "u_px": np.clip(u, 0, width),
                                      "v_px": np.clip(v, 0, height)},
                           {k: tuple(t) for k, t in texts.items()})


PLAN_IMAGES = 300
"""At most this many candidate images for ``partcal plan --measurement camera`` (each is many rows)."""


def candidate_rows(robot, cell: dict, count: int, rng, poses: NDArray[np.float64] | None = None) -> MeasurementRows:
    """Candidate images for ``partcal plan --measurement camera``: for every camera and every board (the cameras all
    in the cell, seeing boards on the flange, or all on the flange, seeing boards in the cell), poses where
    the camera sees at least half of the board's points inside its image, the board turned less than
    :data:`OBLIQUE_DEG` from the line of sight (:func:`seen_points`, at the nominal robot and the camera's and
    board's approximate ``pose`` and the camera's ``intrinsics`` the cell gives); each image's rows carry the pixels
    predicted there. ``poses`` (n, N) deg: the poses to choose from (the cell's reachable, collision-free ones);
    default: drawn within the joint limits. At most ``min(count, PLAN_IMAGES)`` images, shared evenly among the
    pairs."""
    cameras, boards = cell.get("cameras") or {}, cell.get("boards") or {}
    if not cameras or not boards:
        raise PartcalError("plan --measurement camera: the cell needs cameras: and boards: (with their approximate "
                           "pose and the camera's intrinsics)")
    for section, entries, keys in (("cameras", cameras, ("pose", "intrinsics")), ("boards", boards, ("pose",))):
        for name, spec in entries.items():
            missing = [k for k in keys if k not in spec]
            if missing:
                raise PartcalError(f"plan --measurement camera: {section}.{name}: planning images needs its "
                                   f"approximate {' and '.join(missing)} (pose: [x, y, z, rx, ry, rz] mm and degrees, "
                                   "in the base frame or the flange's; intrinsics: fx, fy, cx, cy)")
    mounts = {spec["mount"] for spec in cameras.values()}
    if len(mounts) > 1:
        raise PartcalError("plan --measurement camera: the cell has cameras in the cell and on the flange, and which "
                           "board each sees is not known before the images are taken: plan each set-up on a cell of "
                           "its own (its cameras and the boards they see)")
    pairs = [(cam, board) for cam in cameras for board in boards]
    wanted = min(int(count), PLAN_IMAGES)
    each = [wanted // len(pairs) + (k < wanted % len(pairs)) for k in range(len(pairs))]
    q_all, points, uv_all, images, texts = [], [], [], [], {"camera": [], "board": []}
    count_images = 0
    for (cam, board), want in zip(pairs, each):
        local = board_points(boards[board])
        least, taken = (local.shape[0] + 1) // 2, 0
        batches = [poses] if poses is not None else (
            rng.uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], size=(2000, robot.n_joints)) for _ in range(50))
        for q in batches:
            flange = robot.flange(q)
            seen, uv = seen_points(cameras[cam], boards[board], flange[:, :3, 3], flange[:, :3, :3], local)
            for i in np.flatnonzero(seen.sum(axis=1) >= least)[:want - taken]:
                mine = np.flatnonzero(seen[i])
                taken, count_images = taken + 1, count_images + 1
                images += [f"{cam}-{count_images:04d}"] * mine.size
                texts["camera"] += [cam] * mine.size
                texts["board"] += [board] * mine.size
                q_all.append(np.repeat(q[i][None], mine.size, axis=0))
                points.append(mine.astype(float))
                uv_all.append(uv[i, mine])
            if taken == want:
                break
        if taken < 3:
            where = f"the {len(poses)} poses given" if poses is not None else "100,000 poses drawn"
            raise PartcalError(f"plan --measurement camera: camera {cam!r} sees board {board!r} in {taken} of {where} "
                               "at the nominal robot; check their poses in the cell")
    n = len(images)
    uv = np.vstack(uv_all)
    return MeasurementRows(np.vstack(q_all), ("camera",) * n, tuple(str(i + 1) for i in range(n)),
                           tuple(range(1, n + 1)), "plan", {"point": np.concatenate(points), "u_px": uv[:, 0],
                                                            "v_px": uv[:, 1]},
                           {"image": tuple(images), **{k: tuple(v) for k, v in texts.items()}})


def true_cell(sections: dict) -> tuple[dict, dict]:
    """The true cameras and boards of a virtual cell's ``cell:`` (each with its ``pose``; the cameras with their
    ``intrinsics``), read and checked as the cell's description is."""
    out = []
    for key, read in (("cameras", read_camera), ("boards", read_board)):
        sec = Section(sections.get(key), f"cell.{key}", {}, "the virtual robot's config")
        entries = {name: read(named_entry(sec, name)) for name in list(sec.data)}
        for name, spec in entries.items():
            if "pose" not in spec:
                sec.fail(sec.path(name), "a virtual cell's camera or board needs its true pose: [x, y, z, rx, ry, rz] "
                                         "(mm, a rotation vector in degrees)")
            if key == "cameras" and "intrinsics" not in spec:
                sec.fail(sec.path(name), "a virtual camera needs its true intrinsics (fx, fy, cx, cy, k1, ...)")
        if not entries:
            sec.fail(sec.where, f"a virtual cell's camera data set needs {key}; got none")
        out.append(entries)
    return out[0], out[1]


def camera_T_boards(camera: dict, board: dict, flange_mm, flange_rotations) -> NDArray[np.float64]:
    """The true board in the true camera's frame (n, 4, 4; mm) at flange poses (positions (n, 3) mm, rotations
    (n, 3, 3), base frame): the camera's and the board's ``pose`` on their mounts."""
    cam, brd = pose_matrix(camera["pose"]), pose_matrix(board["pose"])
    flange = poses_from(flange_mm, flange_rotations)
    if camera["mount"] == "cell":
        return np.linalg.inv(cam) @ flange @ brd
    return np.linalg.inv(flange @ cam) @ brd


def seen_points(camera: dict, board: dict, flange_mm, flange_rotations, local) -> tuple[NDArray, NDArray]:
    """Which of a board's points (``local``, (p, 3) mm in its frame) a camera sees at flange poses (positions
    (n, 3) mm, rotations (n, 3, 3), base frame), and their true pixels: masks (n, p) and pixels (n, p, 2)."""
    n = flange_mm.shape[0]
    cam_T_board = camera_T_boards(camera, board, flange_mm, flange_rotations)
    points = np.einsum("nij,pj->npi", cam_T_board[:, :3, :3], local) + cam_T_board[:, None, :3, 3]
    centre = cam_T_board[:, :3, 3] + cam_T_board[:, :3, :3] @ local.mean(axis=0)
    facing = np.einsum("ni,ni->n", cam_T_board[:, :3, 2], centre) / np.linalg.norm(centre, axis=1)
    front = points[..., 2] > 50.0
    safe = np.where(front[..., None], points, np.array([0.0, 0.0, 1.0]))
    uv = project(safe.reshape(-1, 3), np.asarray(camera["intrinsics"], dtype=float))[0].reshape(n, -1, 2)
    width, height = camera["image_size"]
    inside = ((uv[..., 0] >= MARGIN_PX) & (uv[..., 0] <= width - MARGIN_PX) & (uv[..., 1] >= MARGIN_PX)
              & (uv[..., 1] <= height - MARGIN_PX))
    ok = front & inside & (facing > np.cos(np.radians(OBLIQUE_DEG)))[:, None] & front.all(axis=1)[:, None]
    return ok, uv


def camera_info_text(name: str, image_size, intrinsics, how: str) -> str:
    """A camera's intrinsics as ROS's ``camera_info`` YAML (``plumb_bob``: OpenCV's k1, k2, p1, p2, k3), which
    ``cv2.FileStorage`` reads too (the ``%YAML 1.1`` line)."""
    fx, fy, cx, cy, *dist = (float(v) for v in intrinsics)

    def matrix(rows, cols, data):
        return f"  rows: {rows}\n  cols: {cols}\n  data: [{', '.join(repr(float(v)) for v in data)}]"
    return "\n".join([
        "%YAML 1.1", "---", f"# camera {name}: intrinsics {how} by partcal (OpenCV's pinhole camera with Brown-Conrady "
        "distortion; pixels)", f"image_width: {int(image_size[0])}", f"image_height: {int(image_size[1])}",
        f"camera_name: {name}", "camera_matrix:", matrix(3, 3, [fx, 0, cx, 0, fy, cy, 0, 0, 1]),
        "distortion_model: plumb_bob", "distortion_coefficients:", matrix(1, 5, dist),
        "rectification_matrix:", matrix(3, 3, np.eye(3).ravel()),
        "projection_matrix:", matrix(3, 4, [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0])]) + "\n"


def mounted_frames(names, values) -> list[tuple[str, str, NDArray[np.float64]]]:
    """The cameras' and boards' poses of an identified table: ``(link, mount, pose (4, 4) mm)`` each, ``link``
    ``NAME_optical_frame`` for a camera (x right, y down, z along the optical axis: ROS's optical frame) and
    ``NAME_board`` for a board, ``mount`` ``cell`` (the base frame the rows are in) or ``flange``."""
    value = dict(zip(names, np.asarray(values, dtype=float)))
    out = []
    for name in names:
        for what, suffix in (("camera", "optical_frame"), ("board", "board")):
            if name.startswith(f"{what} ") and "@" in name and name.endswith(".x"):
                entry, mount = name[len(what) + 1:-2].split("@")
                pose = pose_matrix([value[f"{what} {entry}@{mount}.{c}"] for c in POSE])
                out.append((f"{entry}_{suffix}", mount, pose))
    return out
