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
from scipy.spatial.transform import Rotation

from .._validation import check_array
from ..errors import DataError
from ..robot.kinematics import ORIENTATION_MM_PER_RAD, Robot
from .joint_errors import JointErrors

PROBE_PARAMETERS = (("probe.rx", "deg"), ("probe.ry", "deg"), ("probe.rz", "deg"))
_DEG = np.pi / 180.0


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
        rotations = Rotation.from_rotvec(turns, degrees=True).as_matrix() @ robot.forward(q_deg)[:, :3, :3]
    return Extra(tools, measured, rotations, float(mm_per_rad))


def stacked(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64], values: NDArray[np.float64],
            payload_kg: NDArray[np.float64], measured_mm: NDArray[np.float64], extra: Extra,
            jacobian: bool = True, parametrization: str = "dh") -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """The stacked residuals (model - measured) of every target and the orientation, and their Jacobian.

    Parameters
    ----------
    values : ndarray, shape (P + extra.size,)
        The model's parameters (geometry, joint errors), then the extra ones.
    measured_mm : ndarray, shape (n, 3)
        The primary target, base frame, mm.
    parametrization : {"dh", "complete"}
        The geometry's parameters (:mod:`partcal.models.identification`).

    Returns
    -------
    residuals : ndarray, shape (3 n (K + 1) [+ 3 n],)
        mm (the orientation's: radians times ``extra.mm_per_rad``).
    jacobian : ndarray, shape (len(residuals), len(values)), or None
    """
    # identification imports this module: its functions are imported where used
    from .identification import actual_joints, geometric_size, identification_jacobian, robot_with

    par = parametrization
    size = geometric_size(nominal, par)
    own = size + (errors.size if errors is not None else 0)
    tool_at, n = slice(size - 9, size - 6), q_deg.shape[0]
    q_actual, design, moves = actual_joints(nominal, errors, q_deg, values[:own], payload_kg, derivatives=jacobian,
                                            parametrization=par)
    tools = [values[tool_at]] + [values[own + 3 * k:own + 3 * k + 3] for k in range(len(extra.tools_mm))]
    residuals, blocks = [], []
    for k, (tool, meas) in enumerate(zip(tools, [measured_mm, *extra.measured_mm.values()])):
        v_k = values[:own].copy()
        v_k[tool_at] = tool
        if not jacobian:
            residuals.append((robot_with(nominal, v_k, par).positions(q_actual) - meas).ravel())
            continue
        p, jac = identification_jacobian(nominal, q_actual, v_k[:size], par)
        residuals.append((p - meas).ravel())
        block = np.zeros((3 * n, values.size))
        if k:
            block[:, own + 3 * (k - 1):own + 3 * k] = jac[:, tool_at]
            jac[:, tool_at] = 0.0
        if design is not None:
            joints = robot_with(nominal, v_k, par).jacobian(q_actual)
            if moves is not None:
                jac[:, :size - 6] += np.einsum("nij,njp->nip", joints, moves).reshape(-1, size - 6)
            block[:, size:own] = np.einsum("nij,njp->nip", joints, design).reshape(-1, design.shape[2])
        block[:, :size] = jac
        blocks.append(block)
    if extra.rotations is not None:
        r, j = _orientation(nominal, q_actual, design, moves, values, own, extra, jacobian, par)
        residuals.append(r)
        blocks.append(j)
    return np.concatenate(residuals), (np.vstack(blocks) if jacobian else None)


def _orientation(nominal: Robot, q_actual, design, moves, values, own: int, extra: Extra, jacobian: bool,
                 parametrization: str = "dh"):
    """The orientation's residuals ``mm_per_rad * log(R_model R_meas^T)`` and their Jacobian rows.

    A parameter's column is the angular velocity it gives the flange (base frame, per unit): a
    row's theta turns about the row's z axis, its alpha about the next frame's x axis (a complete
    row's turns about their axes), the base correction about its axes, a joint error through the
    joint's axes, the probe's turn about the model frame's axes. Lengths turn nothing.
    """
    from .identification import base_axes, complete_axes, geometric_size, robot_with      # (see stacked)

    size, rows, n = geometric_size(nominal, parametrization), nominal.alpha_deg.size, q_actual.shape[0]
    robot = robot_with(nominal, values[:own], parametrization)
    model = robot.forward(q_actual)[:, :3, :3] @ Rotation.from_rotvec(values[-3:], degrees=True).as_matrix()
    weight = extra.mm_per_rad
    turns = Rotation.from_matrix(model @ extra.rotations.transpose(0, 2, 1)).as_rotvec()
    residuals = weight * turns.ravel()
    if not jacobian:
        return residuals, None
    _, xs, zs = robot.frame_axes(q_actual)                                # (n, R + 1, 3)
    omega = np.zeros((n, 3, values.size))
    if parametrization == "complete":
        omega[:, :, 0:7 * rows:7] = zs[:, :rows].transpose(0, 2, 1) * _DEG     # theta of each row
        axes = complete_axes(robot, q_actual, values)[2]                      # (n, R, 3, 3)
        for r in range(rows):
            omega[:, :, 7 * r + 4:7 * r + 7] = axes[:, r] * _DEG
    else:
        omega[:, :, 0:4 * rows:4] = zs[:, :rows].transpose(0, 2, 1) * _DEG     # theta of each row
        omega[:, :, 3:4 * rows:4] = robot.dh_axes(q_actual)[1].transpose(0, 2, 1) * _DEG   # alpha of each row
    for k, axis in enumerate(base_axes(nominal, values, parametrization)):
        omega[:, :, size - 3 + k] = axis * _DEG
    if design is not None:
        per_joint = np.einsum("nri,rj->nij", zs[:, :rows], nominal.coupling) * _DEG      # (n, 3, N)
        if moves is not None:
            omega[:, :, :size - 6] += np.einsum("nij,njp->nip", per_joint, moves)
        omega[:, :, size:own] = np.einsum("nij,njp->nip", per_joint, design)
    omega[:, :, -3:] = model * _DEG                                        # columns: the model frame's axes
    return residuals, weight * np.einsum("nij,njp->nip", _log_derivative(turns), omega).reshape(-1, values.size)


def _log_derivative(turns: NDArray[np.float64]) -> NDArray[np.float64]:
    """How ``log(exp(w) exp(phi))`` moves with a small turn ``w`` at rotation vectors ``phi`` (n, 3): the
    inverse left Jacobian of SO(3), ``I - [phi]/2 + c [phi]^2`` with ``c = 1/t^2 - (1 + cos t)/(2 t sin t)``,
    ``t = |phi|`` (``c -> 1/12`` as ``t -> 0``), shape (n, 3, 3)."""
    t = np.linalg.norm(turns, axis=1)
    small = t < 1e-6
    safe = np.where(small, 1.0, t)
    c = np.where(small, 1.0 / 12.0, 1.0 / safe**2 - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)))
    skew = np.zeros((len(turns), 3, 3))
    skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -turns[:, 2], turns[:, 1], -turns[:, 0]
    skew -= skew.transpose(0, 2, 1)
    return np.eye(3) - 0.5 * skew + c[:, None, None] * skew @ skew
