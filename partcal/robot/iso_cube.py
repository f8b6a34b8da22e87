"""The ISO 9283 test cube and its five test poses P1..P5, solved for a robot's joints.

The cube's corners are numbered ``C1..C4`` around the bottom face and
``C5..C8`` above them, so that ``C1-C2-C7-C8`` is a diagonal plane (it holds
the bottom edge ``C1-C2`` and the top edge ``C7-C8`` opposite it). ``P1`` is
the cube's centre; ``P2, P3, P4, P5`` lie on the plane's diagonals at a tenth
of the diagonal's length from ``C1, C2, C7, C8``.

>>> corners = cube_corners(np.zeros(3), 100.0)
>>> corners[[0, 1, 6, 7]].tolist()                 # C1, C2, C7, C8: the diagonal plane y = z
[[-50.0, -50.0, -50.0], [50.0, -50.0, -50.0], [50.0, 50.0, 50.0], [-50.0, 50.0, 50.0]]
>>> cube_points(np.zeros(3), 100.0)[:2].tolist()   # P1 the centre, P2 a tenth of C1-C7 from C1
[[0.0, 0.0, 0.0], [-40.0, -40.0, -40.0]]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from .floor import Floor, above_floor, below_floor_text
from .kinematics import Robot

POINT_FRACTION = 0.1            # P2..P5: this fraction of the diagonal from its corner
_UNIT = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                  [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float) / 2.0
_GRID = np.stack(np.meshgrid(*[np.linspace(-0.5, 0.5, 4)] * 3, indexing="ij"), -1).reshape(-1, 3)  # corners too
_PLANE = (0, 1, 6, 7)           # C1, C2, C7, C8
_OPPOSITE = {0: 6, 1: 7, 6: 0, 7: 1}     # the other end of each corner's diagonal in the plane
_IK_TOL_MM = 1e-6


def cube_corners(centre_mm, edge_mm: float) -> NDArray[np.float64]:
    """The corners ``C1..C8`` of an axis-aligned cube, shape (8, 3) mm."""
    return np.asarray(centre_mm, dtype=float) + edge_mm * _UNIT


def cube_points(centre_mm, edge_mm: float) -> NDArray[np.float64]:
    """``P1..P5`` of the cube, shape (5, 3) mm."""
    c = cube_corners(centre_mm, edge_mm)
    near = [c[k] + POINT_FRACTION * (c[_OPPOSITE[k]] - c[k]) for k in _PLANE]
    return np.vstack([np.asarray(centre_mm, dtype=float)[None], near])


@dataclass(frozen=True)
class Cube:
    """A test cube solved for a robot.

    Attributes
    ----------
    centre_mm : ndarray, shape (3,)
    edge_mm : float
    points_mm : ndarray, shape (5, 3)
        P1..P5, mm (the nominal positions of the tool).
    q_deg : ndarray, shape (5, N)
        Joint angles reaching them, degrees: P2..P5 solved from P1's joints.
    held_orientation : bool
        Whether the tool keeps P1's orientation at every point (as the standard
        asks); False when the robot cannot (its wrist limits), and P2..P5 are then
        solved for the position alone.
    """

    centre_mm: NDArray[np.float64]
    edge_mm: float
    points_mm: NDArray[np.float64]
    q_deg: NDArray[np.float64]
    held_orientation: bool = False


def _reach(robot: Robot, targets: NDArray[np.float64], seeds: NDArray[np.float64]):
    """IK of ``targets (n, 3)`` from ``seeds (n, N)``: joints, and which are reached within the limits."""
    result = robot.inverse(targets, seeds, tol_mm=_IK_TOL_MM, max_iter=200)
    return result.q_deg, result.success


def solve_cube(robot: Robot, centre_mm, edge_mm: float, seed_deg=None, floor: Floor | None = None) -> Cube:
    """The cube's test poses for ``robot``, refused (naming the corner) when a corner or point is out of reach.

    The centre is solved from ``seed_deg`` (default the home pose), every
    corner and P2..P5 from the centre's joints, so that all poses lie on one
    branch of the inverse kinematics; P2..P5 keep P1's tool orientation where
    the robot can hold it at all four (full-pose IK), else they are solved for
    the position alone (``held_orientation`` says which); a corner the robot cannot reach within
    its joint limits and constraints leaves the workspace, and so does a cube
    with a point of its 4 x 4 x 4 grid out of reach (a hole in the workspace,
    such as the column about a first joint's axis). With ``floor`` (:class:`~partcal.robot.floor.Floor`), a
    cube whose bottom corners lie below it is refused naming the lowest corner (C1: the bottom face is
    C1..C4), and so are test poses that put a link, the flange or the tool below it.
    """
    centre = np.asarray(centre_mm, dtype=float).reshape(3)
    if not np.all(np.isfinite(centre)):
        raise DataError(f"the cube's centre must be three finite numbers of mm; got {centre.tolist()}")
    if not (np.isfinite(edge_mm) and edge_mm > 0):
        raise DataError(f"the cube's edge must be a positive number of mm; got {edge_mm!r}")
    corners = cube_corners(centre, edge_mm)
    if floor is not None and np.any(corners[:, 2] < floor.lowest_mm):
        low = np.flatnonzero(corners[:, 2] < floor.lowest_mm)
        raise DataError(f"the cube (centre {np.round(centre, 3).tolist()} mm, edge {edge_mm:g} mm) reaches below "
                        f"the floor of {robot.name} ({floor.describe()}) at corner C{low[0] + 1} "
                        f"{np.round(corners[low[0]], 3).tolist()} mm ({low.size} of 8 corners below): raise the "
                        "centre or shrink the edge")
    seed = robot.check_joints(robot.home_deg if seed_deg is None else seed_deg)
    q0, ok = _reach(robot, centre[None], seed)
    if not ok[0]:
        raise DataError(f"the cube's centre P1 {np.round(centre, 3).tolist()} mm is out of reach of {robot.name} "
                        "within its joint limits")
    _, ok = _reach(robot, corners, np.repeat(q0, 8, axis=0))
    if not ok.all():
        k = int(np.flatnonzero(~ok)[0])
        raise DataError(f"the cube (centre {np.round(centre, 3).tolist()} mm, edge {edge_mm:g} mm) leaves the "
                        f"workspace or the joint limits of {robot.name} at corner C{k + 1} "
                        f"{np.round(corners[k], 3).tolist()} mm ({int((~ok).sum())} of 8 corners out of reach)")
    inside = centre + edge_mm * _GRID
    _, ok = _reach(robot, inside, np.repeat(q0, len(inside), axis=0))
    if not ok.all():
        k = int(np.flatnonzero(~ok)[0])
        raise DataError(f"the cube (centre {np.round(centre, 3).tolist()} mm, edge {edge_mm:g} mm) leaves the "
                        f"workspace of {robot.name} inside: the point {np.round(inside[k], 3).tolist()} mm of its "
                        "4 x 4 x 4 grid is out of reach within the joint limits")
    points = cube_points(centre, edge_mm)
    poses = np.repeat(robot.forward(q0), len(points), axis=0)       # P1's tool orientation at every point
    poses[:, :3, 3] = points
    held = robot.inverse_pose(poses, np.repeat(q0, len(points), axis=0), tol_mm=_IK_TOL_MM, tol_deg=1e-6,
                              max_iter=300)
    if held.success.all() and above_floor(robot, held.q_deg, floor).all():
        return Cube(centre, float(edge_mm), points, held.q_deg, True)
    q, ok = _reach(robot, points, np.repeat(q0, 5, axis=0))
    if not ok.all():
        k = int(np.flatnonzero(~ok)[0])
        raise DataError(f"the cube's test point P{k + 1} {np.round(points[k], 3).tolist()} mm is out of reach of "
                        f"{robot.name} within its joint limits")
    low = np.flatnonzero(~above_floor(robot, q, floor))
    if low.size:
        k = int(low[0])
        raise DataError(f"the cube's test pose P{k + 1} {np.round(points[k], 3).tolist()} mm "
                        f"{below_floor_text(robot, q[k], floor)}, below the floor of {robot.name} "
                        f"({floor.describe()}): raise the cube")
    return Cube(centre, float(edge_mm), points, q, False)


def largest_cube(robot: Robot, *, random_state=0, n_centres: int = 40, steps: int = 14,
                 floor: Floor | None = None) -> Cube:
    """The largest test cube found in the workspace, solved (see :func:`solve_cube`).

    Candidate centres are the tool positions of ``n_centres`` random poses
    within the joint limits (seeded); for each, the largest edge whose eight
    corners and interior points (a 4 x 4 x 4 grid) are all reachable from the
    centre's joints is found by bisection
    over ``steps`` halvings of the robot's reach, all centres at once. A cube
    may not hold the vertical line through the base (the first joint's axis
    on an upright robot: the arm's own column). With ``floor``, the centres' poses keep above it and
    the cube's bottom face (corners C1..C4) stays above it. The largest of them is returned.
    """
    rng = np.random.default_rng(random_state)
    lo, hi = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    q = rng.uniform(lo, hi, size=(50 * n_centres, robot.n_joints))
    q = q[robot.within_limits(q) & above_floor(robot, q, floor)][:n_centres]
    if len(q) == 0:
        raise DataError(f"no random pose within the joint limits of {robot.name}"
                        + (f" above its floor ({floor.describe()})" if floor is not None else "")
                        + ": give the cube (--cube)")
    centres = robot.positions(q)
    axis = robot.base_mm[:2]      # the first joint's axis (vertical through the base): no cube holds it
    low, high = np.zeros(len(q)), np.minimum(robot.reach_mm, 2.0 * np.abs(centres[:, :2] - axis).max(axis=1))
    if floor is not None:                 # the bottom face C1..C4 at centre - edge / 2 stays above the floor
        high = np.maximum(np.minimum(high, 2.0 * (centres[:, 2] - floor.lowest_mm)), 0.0)
    seeds = np.repeat(q, len(_GRID), axis=0)
    for _ in range(steps):
        mid = 0.5 * (low + high)
        targets = (centres[:, None, :] + mid[:, None, None] * _GRID[None]).reshape(-1, 3)
        ok = _reach(robot, targets, seeds)[1].reshape(len(q), len(_GRID)).all(axis=1)
        low, high = np.where(ok, mid, low), np.where(ok, high, mid)
    for k in np.argsort(-low):          # the largest that also solves P1..P5
        if low[k] <= 0:
            break
        try:
            return solve_cube(robot, centres[k], float(np.floor(low[k])), q[k], floor)
        except DataError:
            continue
    raise DataError(f"found no test cube within the workspace of {robot.name}: give the cube (--cube)")
