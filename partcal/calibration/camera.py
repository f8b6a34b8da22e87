"""Camera rows: one detected point of a board seen by one camera in one image (:class:`CameraPoints`).

Two set-ups, alone or together: a camera fixed in the cell seeing a board on the flange (eye-to-hand) and a camera
on the flange seeing a board fixed in the cell (eye-in-hand); several cameras. The type's unknowns are each
camera's pose (in the base frame, or on the flange: the hand-eye), each board's pose (on the flange, or in the
cell) and each camera's intrinsics (OpenCV's pinhole camera with Brown-Conrady distortion: ``fx, fy, cx, cy, k1,
k2, p1, p2, k3``), fitted with the robot's parameters, or given. Residuals are pixels, weighed by the stated pixel
noise (:attr:`CameraPoints.default_noise`).

Poses are a position (mm) and a rotation vector (degrees): ``camera C.x, y, z, rx, ry, rz`` maps the camera's
frame (x right, y down, z along the optical axis) into the base frame (mount ``cell``) or the flange's
(mount ``flange``); ``board B.x ... rz`` maps the board's frame (x along its columns, y along its rows, z into the
board; its points at z = 0, :func:`board_points`) likewise.

The cell's description::

    cameras:
      cam1: {mount: cell, image_size: [1920, 1200], intrinsics: {fx: 1400, fy: 1400, cx: 960, cy: 600}}
      cam2: {mount: flange, image_size: [1280, 1024], fit_intrinsics: false,
             intrinsics: {fx: 900, fy: 900, cx: 640, cy: 512, k1: -0.1}}
    boards:
      b1: {type: charuco, rows: 8, cols: 11, square_mm: 30, marker_mm: 22}

Intrinsics are the fit's start (``fit_intrinsics: true``, the default) or known (``false``); a camera without
them starts from its image's centre and a focal length read from the images (the board's homographies).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.rotations import (left_jacobian, log_derivative, matrix_from_rotation_vector, poses_from,
                               skew_matrices)
from .camera_cell import (POSE, camera_info_text, candidate_rows, half_turn_symmetric, read_board, read_camera,
                          simulated_rows)
from .camera_model import (INTRINSICS, board_points, focal_from_homographies, homography, pose_from_homography,
                           pose_values, project, solve_ax_yc, undistorted)
from .cell import named_entry
from .measurement import Column, MeasurementType, Residuals

_DEG = np.pi / 180.0
IMAGE_MISFIT = 10.0
"""An image whose points the fit leaves this many times the stated pixel noise from their prediction (RMS) is named:
its detection disagrees with its pose (an image paired with another's joints after a failed detection, a board that
slipped, a wrong corner order)."""
IMAGE_OUTLIER = 3.0
"""... and this many times the median image's RMS: a few such images bend the fit, so every image then leaves more
than the noise; those far beyond the others are the ones named."""
MIN_IMAGE_POINTS = 6
"""An image with fewer points of a board places nothing at the fit's start (its rows are fitted all the same)."""


# ---------------------------------------------------------------------- the measurement type
class CameraPoints(MeasurementType):
    """A point of a board seen by a camera in one image: its pixel ``u_px, v_px``. The camera and the board
    stand one in the cell and one on the flange (``mount`` in the cell's ``cameras:``; the board the other)."""

    name = "camera"
    unit = "px"
    default_noise = 0.2
    needs_orientation = True
    columns = {"image": Column(text=True, required=True), "camera": Column(text=True, required=True),
               "board": Column(text=True),
               "point": Column(required=True, check=lambda v: None if v >= 0 and v == int(v) else
                               "a board point's id (an integer >= 0)"),
               "u_px": Column("px", required=True), "v_px": Column("px", required=True)}
    summary = "a board point seen by camera `camera` in image `image`: its pixel u, v (2 residuals, px)"
    cell_section, feature_column = "cameras", "camera"
    extra_sections = ("boards",)

    @classmethod
    def read_section(cls, sec) -> dict:
        return {name: read_camera(named_entry(sec, name)) for name in list(sec.data)}

    @classmethod
    def read_extra_section(cls, name: str, sec) -> dict:
        return {board: read_board(named_entry(sec, board)) for board in list(sec.data)}

    @classmethod
    def given_section(cls, true: dict, rng) -> dict:
        """What a simulated cell knows of its cameras: mount and image size; intrinsics as written, when the
        true camera says ``fit_intrinsics: false`` (known), else none (fitted from the images)."""
        out = {}
        for name, spec in true.items():
            out[name] = {"mount": spec["mount"], "image_size": list(spec["image_size"])}
            if spec.get("fit_intrinsics", True) is False:
                out[name].update(fit_intrinsics=False, intrinsics=dict(spec["intrinsics"]))
        return out

    @classmethod
    def given_extra_section(cls, name: str, true: dict, rng) -> dict:
        """A simulated cell knows its boards' geometry, not their poses."""
        return {board: {k: v for k, v in spec.items() if k != "pose"} for board, spec in true.items()}

    def __init__(self, rows, index, cell, noise):
        super().__init__(rows, index, cell, noise)
        self.cameras_cell = dict(cell.get("cameras") or {})
        self.boards_cell = dict(cell.get("boards") or {})
        self.image = rows.text("image", index)
        self.camera = rows.text("camera", index)
        self.point = rows.number("point", index).astype(int)
        self.uv = np.column_stack([rows.number("u_px", index), rows.number("v_px", index)])
        named = rows.texts.get("board")
        self.board = [named[i] if named is not None and named[i] else "" for i in index]
        self._resolve()
        self.camera_names = list(dict.fromkeys(self.camera))
        self.board_names = list(dict.fromkeys(self.board))
        self.pairs = _grouped(zip(self.camera, self.board))                       # each camera's board
        self.groups = _grouped(zip(self.image, self.camera, self.board))         # each image
        self.local = np.empty((index.size, 3))
        for b in self.board_names:
            mine = np.array([x == b for x in self.board])
            self.local[mine] = board_points(self.boards_cell[b])[self.point[mine]]

    def _resolve(self) -> None:
        """Each row's camera in the cell, its board (named, or the one board the cell has), mounts opposite, point
        ids on the board, pixels within the image."""
        rows, index = self.rows, self.index
        counts: dict[str, int] = {}
        for i, (cam, row) in enumerate(zip(self.camera, index)):
            if cam not in self.cameras_cell:
                listed = ", ".join(self.cameras_cell) or "none: the cell has no cameras section"
                raise DataError(f"{rows.where(row)}: column 'camera': {cam!r} is not a camera of the cell ({listed})")
            if not self.board[i]:
                if len(self.boards_cell) != 1:
                    listed = ", ".join(self.boards_cell) or "none: the cell has no boards section"
                    raise DataError(f"{rows.where(row)}: column 'board': a camera row names its board when the cell "
                                    f"has other than one ({listed})")
                self.board[i] = next(iter(self.boards_cell))
            board = self.boards_cell.get(self.board[i])
            if board is None:
                raise DataError(f"{rows.where(row)}: column 'board': {self.board[i]!r} is not a board of the cell "
                                f"({', '.join(self.boards_cell) or 'none'})")
            count = counts.setdefault(self.board[i], board_points(board).shape[0])
            if self.point[i] >= count:
                raise DataError(f"{rows.where(row)}: column 'point': {self.point[i]} is not a point of board "
                                f"{self.board[i]!r} (a {board['type']} of {board['rows']} x {board['cols']}: ids 0 to "
                                f"{count - 1})")
            width, height = self.cameras_cell[cam]["image_size"]
            for k, (column, limit) in enumerate((("u_px", width), ("v_px", height))):
                if not 0.0 <= self.uv[i, k] <= limit:
                    raise DataError(f"{rows.where(row)}: column {column!r}: {self.uv[i, k]:g} lies outside camera "
                                    f"{cam!r}'s image; expected a pixel in [0, {limit}] (image_size {width} x "
                                    f"{height})")
        seen_by: dict[str, dict[str, int]] = {}
        for i, (cam, b) in enumerate(zip(self.camera, self.board)):
            seen_by.setdefault(b, {}).setdefault(self.cameras_cell[cam]["mount"], i)
        for b, mounts in seen_by.items():
            if len(mounts) > 1:
                raise DataError(f"{rows.where(index[max(mounts.values())])}: column 'camera': board {b!r} is seen by "
                                "a camera in the cell and by one on the flange; a board stands where the cameras "
                                "that see it do not (name a board per set-up, column 'board')")

    # -------------------------------------------------------------- unknowns
    def _layout(self) -> None:
        """Where each camera's and board's unknowns stand in ``u``: ``self.at[("camera", name)]`` -> first index."""
        self.names_units, self.at = [], {}
        for cam in self.camera_names:
            self.at[("camera", cam)] = len(self.names_units)
            mount = self.cameras_cell[cam]["mount"]
            self.names_units += [(f"camera {cam}@{mount}.{c}", "mm" if c in "xyz" else "deg") for c in POSE]
            if self.cameras_cell[cam]["fit_intrinsics"]:
                self.at[("intrinsics", cam)] = len(self.names_units)
                self.names_units += [(f"camera {cam}.{k}", "px" if k in INTRINSICS[:4] else "1") for k in INTRINSICS]
        for b in self.board_names:
            self.at[("board", b)] = len(self.names_units)
            self.names_units += [(f"board {b}@{self._board_mount(b)}.{c}", "mm" if c in "xyz" else "deg")
                                 for c in POSE]

    def unknowns(self, positions, rotations):
        self._layout()
        start = np.zeros(len(self.names_units))
        flanges = poses_from(positions[self.index] - rotations[self.index] @ self.tool_mm, rotations[self.index])
        placed: dict[str, NDArray[np.float64]] = {}
        for cam in sorted(self.camera_names, key=lambda c: -self.camera.count(c)):     # most rows first
            k = self._start_intrinsics(cam)
            if ("intrinsics", cam) in self.at:
                start[self.at[("intrinsics", cam)]:][:9] = k
            views = self._views(cam, k)
            if len(views) < 3:
                first = self.index[self.camera.index(cam)]
                raise DataError(f"{self.rows.where(first)}: column 'camera': camera {cam!r} sees a board with at least "
                                f"{MIN_IMAGE_POINTS} points in {len(views)} images; its pose needs at least three")
            board = views[0][0]
            a = np.array([flanges[rows[0]] for _, rows, _ in views])
            seen = np.array([pose for _, _, pose in views])          # camera_T_board per image
            if self.cameras_cell[cam]["mount"] == "cell":            # base_T_flange X = Y cam_T_board, X flange_T_board
                x, y = solve_ax_yc(a, seen)
                camera_pose, board_pose = y, x
            else:                                                    # base_T_flange X = Y board_T_cam, X flange_T_cam
                x, y = solve_ax_yc(a, np.linalg.inv(seen))
                camera_pose, board_pose = x, y
            start[self.at[("camera", cam)]:][:6] = pose_values(camera_pose)
            if board not in placed:
                placed[board] = board_pose
                start[self.at[("board", board)]:][:6] = pose_values(board_pose)
        return self.names_units, start

    def _start_intrinsics(self, cam: str) -> NDArray[np.float64]:
        spec = self.cameras_cell[cam]
        if "intrinsics" in spec:
            return np.asarray(spec["intrinsics"], dtype=float)
        width, height = spec["image_size"]
        centre = np.array([width / 2.0, height / 2.0])
        hs = []
        for (_, c, _), mine in self.groups.items():
            if c == cam and mine.size >= MIN_IMAGE_POINTS:
                hs.append(homography(self.local[mine, :2], self.uv[mine] - centre))
        f = focal_from_homographies(hs)
        if f is None:
            first = self.index[self.camera.index(cam)]
            raise DataError(f"{self.rows.where(first)}: column 'camera': camera {cam!r}'s images do not fix a focal "
                            "length (every view square on to the board?): give its intrinsics in the cell")
        return np.array([f, f, *centre, 0.0, 0.0, 0.0, 0.0, 0.0])

    def _views(self, cam: str, k: NDArray[np.float64]) -> list[tuple[str, NDArray[np.intp], NDArray[np.float64]]]:
        """Each image of camera ``cam`` with enough points of one board: the board, its rows (positions in
        ``self.index``) and the board's pose in the camera's frame, from its homography."""
        out = []
        for (_, c, board), mine in self.groups.items():
            if c != cam or mine.size < MIN_IMAGE_POINTS:
                continue
            h = homography(self.local[mine, :2], undistorted(self.uv[mine], k))
            out.append((board, mine, pose_from_homography(h)))
        main = max(dict.fromkeys(b for b, _, _ in out), key=lambda b: sum(v[0] == b for v in out), default=None)
        return [v for v in out if v[0] == main]

    # -------------------------------------------------------------- residuals
    def residuals(self, positions, rotations, u) -> Residuals:
        m = self.index.size
        values = np.empty((m, 2))
        grad = np.empty((m, 2, 3))
        turn = np.empty((m, 2, 3))
        tool = np.empty((m, 2, 3))
        du = np.zeros((m, 2, u.size))
        rot, pos = rotations[self.index], positions[self.index]
        for (cam, b), mine in self.pairs.items():
            self._block(mine, cam, b, pos[mine], rot[mine], u, values, grad, turn, tool, du)
        return Residuals(values.ravel(), np.repeat(self.index, 2), grad.reshape(-1, 3), du.reshape(2 * m, -1),
                         turn_grad=turn.reshape(-1, 3), scaled=np.zeros(2 * m, dtype=bool),
                         tool_grad=tool.reshape(-1, 3))

    def intrinsics(self, cam: str, u) -> NDArray[np.float64]:
        """Camera ``cam``'s intrinsics at the unknowns ``u`` (fitted, or known)."""
        at = self.at.get(("intrinsics", cam))
        return np.asarray(self.cameras_cell[cam]["intrinsics"], dtype=float) if at is None else u[at:at + 9]

    def _block(self, mine, cam, b, pos, rot, u, values, grad, turn, tool, du) -> None:
        """The residuals of rows ``mine`` (camera ``cam``, board ``b``) and their derivatives, written in place."""
        ci, bi = self.at[("camera", cam)], self.at[("board", b)]
        rc_vec, rb_vec = np.radians(u[ci + 3:ci + 6]), np.radians(u[bi + 3:bi + 6])
        rc, rb = matrix_from_rotation_vector(rc_vec), matrix_from_rotation_vector(rb_vec)
        tc, tb = u[ci:ci + 3], u[bi:bi + 3]
        jc, jb = left_jacobian(rc_vec) * _DEG, left_jacobian(rb_vec) * _DEG
        spun = self.local[mine] @ rb.T                        # R_b s, in the frame the board is mounted in
        eye = np.broadcast_to(np.eye(3), (mine.size, 3, 3))
        if self.cameras_cell[cam]["mount"] == "cell":
            lever = np.einsum("nij,nj->ni", rot, tb + spun - self.tool_mm)       # the point from the tool point
            p = pos + lever
            to_cam = np.broadcast_to(rc.T, (mine.size, 3, 3))                     # d X / d p
            by_turn = -skew_matrices(lever)                                        # d p / d turn of the tool
            by_tool = -rot
            by_camera = np.concatenate([-to_cam, rc.T @ skew_matrices(p - tc) @ jc], axis=2)
            by_board = np.concatenate([rot, -rot @ skew_matrices(spun) @ jb], axis=2)
            by_board = to_cam @ by_board
            points_cam = (p - tc) @ rc
            grad_p, turn_p, tool_p = to_cam, to_cam @ by_turn, to_cam @ by_tool
        else:
            p = tb + spun                                                          # the board's point, base frame
            centre = pos + rot @ (tc - self.tool_mm)
            to_cam = rc.T @ rot.transpose(0, 2, 1)                                # X = R_c^T R^T (p - C)
            points_cam = np.einsum("nij,nj->ni", to_cam, p - centre)
            grad_p = -to_cam
            turn_p = to_cam @ skew_matrices(p - pos)
            tool_p = np.broadcast_to(rc.T, (mine.size, 3, 3))
            local = np.einsum("nji,nj->ni", rot, p - centre)                        # R^T (p - C)
            by_camera = np.concatenate([-np.broadcast_to(rc.T, (mine.size, 3, 3)),
                                        rc.T @ skew_matrices(local) @ jc], axis=2)
            by_board = to_cam @ np.concatenate([eye, -skew_matrices(spun) @ jb], axis=2)
        if np.any(points_cam[:, 2] <= 0):
            points_cam = points_cam.copy()
            points_cam[:, 2] = np.maximum(points_cam[:, 2], 1e-6)          # behind the camera: a large residual
        k = self.intrinsics(cam, u)
        uv, by_point, by_k = project(points_cam, k)
        values[mine] = uv - self.uv[mine]
        grad[mine], turn[mine], tool[mine] = by_point @ grad_p, by_point @ turn_p, by_point @ tool_p
        du[mine, :, ci:ci + 6] += by_point @ by_camera
        du[mine, :, bi:bi + 6] += by_point @ by_board
        if ("intrinsics", cam) in self.at:
            at = self.at[("intrinsics", cam)]
            du[mine, :, at:at + 9] = by_k

    @classmethod
    def files(cls, cell: dict, names, values) -> dict[str, str]:
        """Each camera's intrinsics as an OpenCV / ROS ``camera_info`` YAML (``camera_NAME.yaml``): the fitted ones
        of an identified table (``names``, ``values``), or those the cell gives."""
        value = dict(zip(names, np.asarray(values, dtype=float)))
        out = {}
        for cam, spec in (cell.get("cameras") or {}).items():
            fitted = [value.get(f"camera {cam}.{k}") for k in INTRINSICS]
            if all(v is not None for v in fitted):
                out[f"camera_{cam}.yaml"] = camera_info_text(cam, spec["image_size"], np.array(fitted), "identified")
            elif "intrinsics" in spec and f"camera {cam}@{spec['mount']}.x" in value:
                out[f"camera_{cam}.yaml"] = camera_info_text(cam, spec["image_size"], spec["intrinsics"], "given")
        return out

    # -------------------------------------------------------------- a virtual robot's images
    @classmethod
    def simulate(cls, truth, spec, rng, noise):
        """Pixel rows of a virtual robot (``partcal simulate``): :func:`~partcal.calibration.camera_cell.simulated_rows`."""
        return simulated_rows(truth, spec, rng, noise)

    plans_by = "image"
    """``partcal plan --measurement camera`` chooses whole images (each many rows), not rows."""

    @staticmethod
    def candidates(robot, cell, count, rng, poses=None):
        """Candidate images for ``partcal plan`` (at ``poses``, the cell's safe poses, when given):
        :func:`~partcal.calibration.camera_cell.candidate_rows`."""
        return candidate_rows(robot, cell, count, rng, poses)

    # -------------------------------------------------------------- the cell's symmetries, words
    def moved(self, u, omega, shift):
        """What stands in the cell (a camera of mount ``cell``, a board on a camera of mount ``flange``) turns and
        shifts with it; what is on the flange and the intrinsics do not."""
        out = np.zeros_like(u)
        for (what, name), at in self.at.items():
            in_cell = (what == "camera" and self.cameras_cell[name]["mount"] == "cell") or (
                what == "board" and self._board_mount(name) == "cell")
            if what != "intrinsics" and in_cell:
                out[at:at + 3] = np.cross(omega, u[at:at + 3]) + shift
                out[at + 3:at + 6] = np.degrees(log_derivative(np.radians(u[at + 3:at + 6])[None])[0] @ omega)
        return out

    def scaled_lengths(self, start):
        """Under a uniform scale the poses' positions scale; their turns and the intrinsics do not."""
        return start

    def stands_for(self, names: list[str]) -> set[str]:
        """Pixels see the camera's pose relative to the board's: what stands in the cell carries the base frame
        (``base.*``, and joint 1's offset and length along its axis, ``theta[1]``, ``d[1]``) and what is on the
        flange carries the last row of the chain (every parameter of it: the flange's own frame)."""
        rows = [int(n[6:-1]) for n in names if n.startswith("theta[") and n.endswith("]")]
        last = f"[{max(rows)}]" if rows else None
        return {n for n in names if n.startswith("base.") or n in ("theta[1]", "d[1]")
                or (last is not None and n.endswith(last))}

    def _board_mount(self, board: str) -> str:
        cam = next(c for c, b in zip(self.camera, self.board) if b == board)
        return "flange" if self.cameras_cell[cam]["mount"] == "cell" else "cell"

    def notes(self) -> list[str]:
        out = []
        mounts = {self.cameras_cell[c]["mount"] for c in self.camera_names}
        if "cell" in mounts:
            out.append("camera: a camera in the cell is the images' only reference of the base frame: the base's pose "
                       "and the camera's are one unknown (joint 1's offset and the base height with them): with camera "
                       "rows alone the base is held nominal and the camera's pose identified in it (tracker points or "
                       "touches beside the images fix the base)")
        if "flange" in mounts:
            out.append("camera: a board in the cell is the images' only reference of the base frame: the base's pose "
                       "and the board's are one unknown (joint 1's offset and the base height with them): with camera "
                       "rows alone the base is held nominal and the board's pose identified in it")
        out.append("camera: the last joint's offset and the flange's own frame (the chain's last row) go with the "
                   "pose on the flange (the board's or the camera's: the hand-eye), held nominal with camera rows "
                   "alone; a camera does not see the tool offset")
        if any(half_turn_symmetric(self.boards_cell[b]) for b in self.board_names):
            out.append("camera: a chessboard with both square counts even or both odd looks the same turned half a "
                       "turn: its detections may flip between images (use one odd and one even count, or a ChArUco "
                       "board)")
        return out

    def image_rms(self, residuals: Residuals) -> dict[tuple[str, str, str], float]:
        """Each image's RMS pixel residual (over its points' u and v), keyed ``(image, camera, board)``."""
        values = residuals.values[:2 * self.index.size].reshape(-1, 2)
        return {key: float(np.sqrt(np.mean(values[mine] ** 2))) for key, mine in self.groups.items()}

    def fit_notes(self, residuals: Residuals) -> list[str]:
        """The images the fit leaves :data:`IMAGE_MISFIT` times the stated pixel noise or more (RMS) and
        :data:`IMAGE_OUTLIER` times the median image's or more, worst first, each named by its image id, camera and
        file lines. A few images paired with the wrong joints bend a least-squares fit, so the others leave more
        than the noise too: they are counted in one further note, not named as the culprits."""
        rms = self.image_rms(residuals)
        median = float(np.median(list(rms.values())))
        bound = max(IMAGE_MISFIT * self.noise, IMAGE_OUTLIER * median)
        far = sorted((key for key, value in rms.items() if value >= bound), key=lambda k: -rms[k])
        out = []
        for key in far:
            rows, value = self.index[self.groups[key]], rms[key]
            where = f"{self.rows.where(rows[0])}-{self.rows.lines[rows[-1]]}"
            out.append(f"camera: image {key[0]!r} (camera {key[1]}, board {key[2]}, {where}) leaves {value:.3g} px RMS, "
                       f"{value / self.noise:.0f} times the stated pixel noise {self.noise:g} px and "
                       f"{value / median:.1f} times the median image's: its detection disagrees with its pose's "
                       "prediction (paired with another image's joints after a failed detection? a board that "
                       "slipped?): check its joints row, or leave the image out")
        beyond = sum(value >= IMAGE_MISFIT * self.noise for key, value in rms.items() if key not in far)
        if far and beyond:
            out.append(f"camera: {beyond} further images leave more than {IMAGE_MISFIT:g} times the pixel noise "
                       f"(median image {median:.3g} px): the fit is bent by the images named above; leave them out "
                       "and run again")
        return out

    def describe(self) -> str:
        images = len(set(zip(self.image, self.camera)))
        return (f"{self.index.size} board points in {images} images of {len(self.camera_names)} cameras "
                f"({', '.join(c + ' on the ' + self.cameras_cell[c]['mount'] for c in self.camera_names)})")


def _grouped(keys) -> dict[tuple, NDArray[np.intp]]:
    """The positions of each key among ``keys``, in their order (first seen first)."""
    out: dict[tuple, list[int]] = {}
    for k, key in enumerate(keys):
        out.setdefault(key, []).append(k)
    return {key: np.array(rows, dtype=np.intp) for key, rows in out.items()}
