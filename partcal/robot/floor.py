"""The floor a floor-mounted arm must stay above: which poses put a link, the flange or the tool below it.

The floor is the horizontal plane ``z = height_mm`` of the robot's base frame,
where the robot's description states one (``floor_mm``: the built-in UR10's is
its base plane, ``z = 0``) or a command sets one; a description without
``floor_mm`` (a pedestal, a ceiling or a wall, a URDF) has none. A pose is
*above the floor* when every point of the arm that the joints can move stays
at least ``clearance_mm`` above it. The points are the origins of the
kinematic frames 1..R (the joints' frames, the last one the flange) and the
tool point. Frame origins lie on the links' centre lines, so the clearance
stands for the links' own radius plus a margin (default
:data:`DEFAULT_CLEARANCE_MM`: a UR10's wrist housings are about 90 mm across).
Points that no joint can move (the base's own frames, such as a UR10's
shoulder at 118 mm) are not checked: no pose changes them.

>>> from partcal.robot import load_robot
>>> robot = load_robot("universal_robots_ur10")
>>> floor = Floor()                                     # z = 0 of the base frame, 100 mm clearance
>>> above_floor(robot, [[0, -90, 0, -90, 0, 0], [0, 0, 0, 0, 0, 0]], floor).tolist()
[True, False]
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import PartcalError
from .kinematics import Robot

DEFAULT_CLEARANCE_MM = 100.0    # the links' radius about their frame origins, and a margin
_FIXED_TOL_MM = 1e-6            # a point whose height moves less than this with the joints is the base's own


@dataclass(frozen=True)
class Floor:
    """The plane ``z = height_mm`` (base frame, mm) that the arm's moving points keep ``clearance_mm`` above."""

    height_mm: float = 0.0
    clearance_mm: float = DEFAULT_CLEARANCE_MM

    def __post_init__(self):
        if not (_is_number(self.height_mm) and math.isfinite(self.height_mm)):
            raise PartcalError(f"the floor's height must be a finite number of mm; got {self.height_mm!r}")
        if not (_is_number(self.clearance_mm) and math.isfinite(self.clearance_mm) and self.clearance_mm >= 0):
            raise PartcalError(f"the floor clearance must be a number of mm >= 0; got {self.clearance_mm!r}")
        object.__setattr__(self, "height_mm", float(self.height_mm))        # numpy scalars: plain floats
        object.__setattr__(self, "clearance_mm", float(self.clearance_mm))

    @property
    def lowest_mm(self) -> float:
        """The lowest height a moving point may take, mm."""
        return float(self.height_mm + self.clearance_mm)

    def describe(self) -> str:
        """``z >= 100 mm: floor 0 mm + clearance 100 mm``."""
        return f"z >= {self.lowest_mm:g} mm: floor {self.height_mm:g} mm + clearance {self.clearance_mm:g} mm"


def _is_number(value) -> bool:
    """A real number (Python's or numpy's), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def robot_floor(robot: Robot, height_mm: float | None = None, clearance_mm: float | None = None,
                off: bool = False) -> Floor | None:
    """The floor of ``robot``: its description's ``floor_mm`` unless ``height_mm`` is given; None when off
    (``off``, or a robot described without a floor and no height given)."""
    if off:
        return None
    height = robot.floor_mm if height_mm is None else height_mm
    if height is None:
        return None
    return Floor(float(height), DEFAULT_CLEARANCE_MM if clearance_mm is None else float(clearance_mm))


def point_names(robot: Robot) -> list[str]:
    """Names of the checked points' candidates, in the order of :func:`point_heights`: frames 1..R, the tool."""
    rows = robot.alpha_deg.size
    return [f"frame {k}" if k < rows else f"frame {k} (flange)" for k in range(1, rows + 1)] + ["the tool"]


def point_heights(robot: Robot, q_deg) -> NDArray[np.float64]:
    """Heights (z, mm, base frame) of the frame origins 1..R and the tool, shape ``(n, R + 1)``."""
    origins, _ = robot.frames(q_deg)
    return np.concatenate([origins[:, 1:, 2], robot.positions(q_deg)[:, 2:3]], axis=1)


def moving_points(robot: Robot) -> NDArray[np.bool_]:
    """Which of :func:`point_names` the joints move up or down, shape ``(R + 1,)`` (seeded, deterministic)."""
    rng = np.random.default_rng(0)
    q = np.vstack([robot.home_deg, rng.uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1],
                                               size=(16, robot.n_joints))])
    return np.ptp(point_heights(robot, q), axis=0) > _FIXED_TOL_MM


def lowest_point(robot: Robot, q_deg) -> tuple[NDArray[np.float64], NDArray[np.intp]]:
    """The lowest moving point of each pose: its height (mm) and its index in :func:`point_names`."""
    heights = point_heights(robot, q_deg)
    moving = moving_points(robot)
    heights = np.where(moving, heights, np.inf)
    k = np.argmin(heights, axis=1)
    return heights[np.arange(len(k)), k], k


def above_floor(robot: Robot, q_deg, floor: Floor | None) -> NDArray[np.bool_]:
    """Which poses ``(n, N)`` deg keep every moving point ``floor.clearance_mm`` above the floor, shape ``(n,)``
    (all, when ``floor`` is None)."""
    q = robot.check_joints(q_deg)
    if floor is None:
        return np.ones(len(q), dtype=bool)
    return lowest_point(robot, q)[0] >= floor.lowest_mm


def below_floor_text(robot: Robot, q_deg, floor: Floor) -> str:
    """``puts frame 3 at z = -12.5 mm`` for the first pose of ``q_deg`` below the floor ("" when none is)."""
    q = robot.check_joints(q_deg)
    z, k = lowest_point(robot, q)
    bad = np.flatnonzero(z < floor.lowest_mm)
    if not bad.size:
        return ""
    i = int(bad[0])
    return f"puts {point_names(robot)[int(k[i])]} at z = {z[i]:.1f} mm"
