"""The camera's geometry, in numpy: a board's points, OpenCV's pinhole camera with Brown-Conrady distortion and its
derivatives (:func:`project`), and the closed forms a camera fit starts from (a plane's homography, a focal length
from homographies, a plane's pose, the hand-eye ``A X = Y C``). Used by :mod:`.camera`."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..robot.rotations import matrix_from_rotation_vector, rotation_vector_from_matrix

INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
"""A camera's intrinsics in OpenCV's order (the camera matrix's four, then ``distCoeffs`` k1, k2, p1, p2, k3)."""


def board_points(board: dict) -> NDArray[np.float64]:
    """The points of a board (n, 3) mm in its own frame, row ``id`` the point of that id.

    A chessboard or ChArUco board of ``rows`` x ``cols`` squares has ``(rows - 1) (cols - 1)`` inner corners, id
    ``r (cols - 1) + c`` at ``((c + 1) s, (r + 1) s, 0)`` (``s`` = ``square_mm``: OpenCV's ChArUco ids). An
    AprilTag grid of ``rows`` x ``cols`` tags at pitch ``square_mm``, each ``marker_mm`` wide, has four corners
    per tag, id ``4 t + k`` (tag ``t = r cols + c``; ``k`` in OpenCV's order: top left, top right, bottom right,
    bottom left).

    >>> board_points({"type": "chessboard", "rows": 3, "cols": 4, "square_mm": 10.0})[[0, 1, 3]].tolist()
    [[10.0, 10.0, 0.0], [20.0, 10.0, 0.0], [10.0, 20.0, 0.0]]
    """
    rows, cols, s = int(board["rows"]), int(board["cols"]), float(board["square_mm"])
    if board["type"] in ("chessboard", "charuco"):
        r, c = np.divmod(np.arange((rows - 1) * (cols - 1)), cols - 1)
        return np.column_stack([(c + 1) * s, (r + 1) * s, np.zeros(r.size)])
    half = float(board["marker_mm"]) / 2.0
    r, c = np.divmod(np.arange(rows * cols), cols)
    centres = np.column_stack([(c + 0.5) * s, (r + 0.5) * s, np.zeros(r.size)])
    corners = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    return (centres[:, None, :] + corners[None]).reshape(-1, 3)


def project(points_cam: NDArray[np.float64], intrinsics: NDArray[np.float64]
            ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Pixels of points in the camera's frame, and their derivatives: OpenCV's pinhole camera with Brown-Conrady
    distortion (``cv2.projectPoints`` with ``distCoeffs = (k1, k2, p1, p2, k3)``).

    Parameters
    ----------
    points_cam : ndarray, shape (n, 3)
        Points in the camera's frame, mm (z > 0: in front of it).
    intrinsics : ndarray, shape (9,)
        ``fx, fy, cx, cy`` (px), ``k1, k2, p1, p2, k3``.

    Returns
    -------
    uv : ndarray, shape (n, 2)
        Pixels.
    by_point : ndarray, shape (n, 2, 3)
        ``d uv / d point``.
    by_intrinsics : ndarray, shape (n, 2, 9)
        ``d uv / d intrinsics``.
    """
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = (float(v) for v in intrinsics)
    X, Y, Z = points_cam[:, 0], points_cam[:, 1], points_cam[:, 2]
    x, y = X / Z, Y / Z
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    slope = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)            # d radial / d r2
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    uv = np.column_stack([fx * xd + cx, fy * yd + cy])
    n = points_cam.shape[0]
    dxy = np.empty((n, 2, 2))               # d (xd, yd) / d (x, y)
    dxy[:, 0, 0] = radial + 2.0 * x * x * slope + 2.0 * p1 * y + 6.0 * p2 * x
    dxy[:, 0, 1] = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y
    dxy[:, 1, 0] = 2.0 * x * y * slope + 2.0 * p1 * x + 2.0 * p2 * y
    dxy[:, 1, 1] = radial + 2.0 * y * y * slope + 6.0 * p1 * y + 2.0 * p2 * x
    dxy[:, 0] *= fx
    dxy[:, 1] *= fy
    dnorm = np.zeros((n, 2, 3))             # d (x, y) / d (X, Y, Z)
    dnorm[:, 0, 0] = dnorm[:, 1, 1] = 1.0 / Z
    dnorm[:, 0, 2], dnorm[:, 1, 2] = -x / Z, -y / Z
    by_point = dxy @ dnorm
    by_k = np.zeros((n, 2, 9))
    by_k[:, 0, 0], by_k[:, 1, 1], by_k[:, 0, 2], by_k[:, 1, 3] = xd, yd, 1.0, 1.0
    for j, power in ((4, r2), (5, r2 * r2), (8, r2 ** 3)):
        by_k[:, 0, j], by_k[:, 1, j] = fx * x * power, fy * y * power
    by_k[:, 0, 6], by_k[:, 1, 6] = fx * 2.0 * x * y, fy * (r2 + 2.0 * y * y)
    by_k[:, 0, 7], by_k[:, 1, 7] = fx * (r2 + 2.0 * x * x), fy * 2.0 * x * y
    return uv, by_point, by_k


def undistorted(uv: NDArray[np.float64], intrinsics: NDArray[np.float64], steps: int = 20) -> NDArray[np.float64]:
    """Normalised image coordinates ``(x, y)`` (n, 2) of pixels ``uv`` (n, 2): the distortion inverted by
    fixed-point steps (enough for a fit's start)."""
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = (float(v) for v in intrinsics)
    xd, yd = (uv[:, 0] - cx) / fx, (uv[:, 1] - cy) / fy
    x, y = xd.copy(), yd.copy()
    for _ in range(steps):
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        x = (xd - 2.0 * p1 * x * y - p2 * (r2 + 2.0 * x * x)) / radial
        y = (yd - p1 * (r2 + 2.0 * y * y) - 2.0 * p2 * x * y) / radial
    return np.column_stack([x, y])


def homography(plane: NDArray[np.float64], image: NDArray[np.float64]) -> NDArray[np.float64]:
    """The homography (3, 3) taking board-plane points ``plane`` (n, 2) to ``image`` points (n, 2) (the direct
    linear transform on centred, scaled coordinates)."""
    def normaliser(p):
        c, s = p.mean(axis=0), np.sqrt(2.0) / max(np.mean(np.linalg.norm(p - p.mean(axis=0), axis=1)), 1e-12)
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])
    ta, tb = normaliser(plane), normaliser(image)
    a = np.column_stack([plane, np.ones(len(plane))]) @ ta.T
    b = np.column_stack([image, np.ones(len(image))]) @ tb.T
    zero = np.zeros_like(a)
    rows = np.vstack([np.hstack([a, zero, -b[:, :1] * a]), np.hstack([zero, a, -b[:, 1:2] * a])])
    h = np.linalg.eigh(rows.T @ rows)[1][:, 0].reshape(3, 3)      # the smallest singular vector
    h = np.linalg.inv(tb) @ h @ ta
    return h / h[2, 2]


def focal_from_homographies(hs: list[NDArray[np.float64]]) -> float | None:
    """A focal length (px) shared by ``fx = fy`` from homographies of a plane to pixels centred on the principal
    point (Zhang's two constraints on ``[r1 r2]`` with a square pixel, by least squares); None when they say
    nothing (every view fronto-parallel)."""
    num, den = [], []
    for h in hs:
        (a1, a2), (b1, b2), (c1, c2) = h[0, :2], h[1, :2], h[2, :2]
        num += [-(a1 * a2 + b1 * b2), (a2 * a2 + b2 * b2) - (a1 * a1 + b1 * b1)]    # f^2 * den = num
        den += [c1 * c2, c1 * c1 - c2 * c2]
    num, den = np.array(num), np.array(den)
    f2 = float(num @ den / (den @ den)) if den @ den > 0 else -1.0
    return float(np.sqrt(f2)) if f2 > 0 else None


def pose_from_homography(h: NDArray[np.float64]) -> NDArray[np.float64]:
    """The plane's pose in the camera's frame (4, 4) from its homography to normalised image coordinates."""
    scale = 1.0 / np.linalg.norm(h[:, 0])
    if h[2, 2] * scale < 0:                    # the plane in front of the camera
        scale = -scale
    r1, r2, t = h[:, 0] * scale, h[:, 1] * scale, h[:, 2] * scale
    u, _, vt = np.linalg.svd(np.column_stack([r1, r2, np.cross(r1, r2)]))
    out = np.eye(4)
    out[:3, :3] = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    out[:3, 3] = t
    return out


def solve_ax_yc(a: NDArray[np.float64], c: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``X``, ``Y`` (4, 4) with ``A_i X = Y C_i`` for poses ``a``, ``c`` (n, 4, 4) in the least-squares sense
    (rotations from the null vector of the linear system on their entries, projected onto rotations, then the
    translations): a start for the fit, not its answer."""
    eye = np.eye(3)
    rows = np.vstack([np.hstack([np.kron(ai[:3, :3], eye), -np.kron(eye, ci[:3, :3].T)]) for ai, ci in zip(a, c)])
    v = np.linalg.eigh(rows.T @ rows)[1][:, 0]
    rx, ry = v[:9].reshape(3, 3), v[9:].reshape(3, 3)
    det = np.linalg.det(rx)
    scale = np.sign(det) / abs(det) ** (1.0 / 3.0)
    rotations = []
    for r in (rx * scale, ry * scale):
        u, _, vt = np.linalg.svd(r)
        rotations.append(u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt)
    lhs = np.vstack([np.hstack([ai[:3, :3], -eye]) for ai in a])
    rhs = np.concatenate([rotations[1] @ ci[:3, 3] - ai[:3, 3] for ai, ci in zip(a, c)])
    t = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    x, y = np.eye(4), np.eye(4)
    x[:3, :3], x[:3, 3], y[:3, :3], y[:3, 3] = rotations[0], t[:3], rotations[1], t[3:]
    return x, y


def pose_values(pose: NDArray[np.float64]) -> list[float]:
    """``x, y, z`` mm and the rotation vector ``rx, ry, rz`` degrees of a pose (4, 4)."""
    return [*pose[:3, 3], *np.degrees(rotation_vector_from_matrix(pose[:3, :3]))]


def pose_matrix(values) -> NDArray[np.float64]:
    """The pose (4, 4) of ``x, y, z`` mm and a rotation vector ``rx, ry, rz`` degrees."""
    out = np.eye(4)
    out[:3, :3] = matrix_from_rotation_vector(np.radians(np.asarray(values[3:6], dtype=float)))
    out[:3, 3] = values[:3]
    return out


