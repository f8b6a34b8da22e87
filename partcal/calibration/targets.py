"""Kinematic identification from several targets on the tool and from the measured orientation.

One target per pose tells the identification where one point of the tool went. More targets
(reflectors on a plate) and a 6-D probe's orientation also say how the tool turned, which
separates parameters one point leaves equivalent (the last joints' offsets and twists against
the tool offset) and adds equations per pose.

The parameters follow the model's own (geometry, then joint errors): each extra target's offset
in the flange frame (``tool@B.x`` ..., mm, starting from its nominal offset) and, with an
orientation, the measured frame's small turn on the flange (``probe.rx``, ``probe.ry``,
``probe.rz``: a rotation vector in degrees, nominally zero, since data in the base frame carry the
measured flange's orientation: docs/data.md).

The residual vector stacks the primary target's position residuals (``n x 3``, mm), each extra
target's, then the orientation's: the turn from the measured orientation to the model's,
``log(R_model @ R_meas^T)`` as a rotation vector in the base frame, in radians times
``mm_per_rad`` (by default :data:`~partcal.robot.kinematics.ORIENTATION_MM_PER_RAD`, 200: one
mrad counts as 0.2 mm). All Jacobians are analytic.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import DataError
from ..robot.kinematics import ORIENTATION_MM_PER_RAD, Robot
from ..robot.rotations import matrices_from_rotation_vectors

PROBE_PARAMETERS = (("probe.rx", "deg"), ("probe.ry", "deg"), ("probe.rz", "deg"))


@dataclass(frozen=True, eq=False)
class Extra:
    """What the poses measured beyond the primary target.

    Attributes
    ----------
    tools_mm : dict of str to ndarray (3,)
        The extra targets' nominal offsets in the flange frame, mm (where their fit starts).
    measured_mm : dict of str to ndarray (n, 3)
        Their measured positions in the base frame, mm (same keys).
    rotations : ndarray, shape (n, 3, 3), optional
        The measured flange orientation in the base frame.
    mm_per_rad : float
        Weight of an orientation residual: one radian counts as this many mm.
    """

    tools_mm: dict
    measured_mm: dict
    rotations: NDArray[np.float64] | None = None
    mm_per_rad: float = ORIENTATION_MM_PER_RAD

    def names(self) -> list[tuple[str, str]]:
        """``(name, unit)`` of the added parameters (:func:`added_names`)."""
        return added_names(self.tools_mm, self.rotations is not None)

    def nominal(self) -> NDArray[np.float64]:
        """The added parameters' nominal values (:func:`added_nominal`)."""
        return added_nominal(self.tools_mm, self.rotations is not None)

    @property
    def size(self) -> int:
        return 3 * len(self.tools_mm) + 3 * (self.rotations is not None)


def added_names(tools_mm: dict, orientation: bool) -> list[tuple[str, str]]:
    """``(name, unit)`` of the added parameters: each target's offset, then the probe's turn.

    >>> [n for n, _ in added_names({"B": [0, 0, 1]}, True)]
    ['tool@B.x', 'tool@B.y', 'tool@B.z', 'probe.rx', 'probe.ry', 'probe.rz']
    """
    return [(f"tool@{name}.{c}", "mm") for name in tools_mm for c in "xyz"] + \
        (list(PROBE_PARAMETERS) if orientation else [])


def added_nominal(tools_mm: dict, orientation: bool) -> NDArray[np.float64]:
    """The added parameters' nominal values: the targets' offsets (mm), a zero turn (degrees)."""
    tools = [np.asarray(t, dtype=float) for t in tools_mm.values()]
    return np.concatenate(tools + [np.zeros(3 if orientation else 0)])


def extra_from(robot: Robot, q_deg: NDArray[np.float64], targets: dict | None, orientation_deg,
               mm_per_rad: float = ORIENTATION_MM_PER_RAD) -> Extra | None:
    """:class:`Extra` from errors, as :meth:`KinematicModel.fit` takes them (None when there is nothing more).

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    q_deg : ndarray, shape (n, N)
    targets : dict of str to (array-like (3,), array-like (n, 3)), optional
        Per extra target: its nominal offset in the flange frame (mm) and its errors
        ``measured - nominal`` (mm), the nominal being the robot with that offset.
    orientation_deg : array-like, shape (n, 3), optional
        Orientation errors: the turn from the nominal flange orientation to the measured
        one, a rotation vector in the base frame, degrees (``Measurements.orientation_errors_deg``).
    """
    if not targets and orientation_deg is None:
        return None
    n = q_deg.shape[0]
    tools, measured = {}, {}
    for name, (tool, errors) in (targets or {}).items():
        tools[name] = check_array(np.reshape(tool, (1, -1)), f"targets[{name!r}] offset", columns=3)[0]
        err = check_array(errors, f"targets[{name!r}] errors", columns=3)
        if err.shape[0] != n:
            raise DataError(f"targets[{name!r}] has {err.shape[0]} rows but X has {n}")
        measured[name] = robot.replace(tool_mm=tools[name]).positions(q_deg) + err
    rotations = None
    if orientation_deg is not None:
        turns = check_array(orientation_deg, "orientation_deg", columns=3)
        if turns.shape[0] != n:
            raise DataError(f"orientation_deg has {turns.shape[0]} rows but X has {n}")
        rotations = matrices_from_rotation_vectors(np.radians(turns)) @ robot.forward(q_deg)[:, :3, :3]
    return Extra(tools, measured, rotations, float(mm_per_rad))
