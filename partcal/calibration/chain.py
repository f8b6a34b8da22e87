"""The chain as identification sees it: positions of the model with given parameter values, and their
analytic derivatives by every parameter (geometry, the base correction, joint errors), the flange's angular
velocity per parameter, and the joint angles the arm takes under its joint errors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..robot.kinematics import Robot
from ..robot.rotations import matrix_from_rpy_deg
from .joint_errors import JointErrors
from .parameters import PARAMETRIZATIONS, geometric_size, own_geometry, robot_with

_DEG = np.pi / 180.0


def identification_jacobian(nominal: Robot, q_deg: NDArray[np.float64], values: NDArray[np.float64],
                            parametrization: str = "dh") -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions ``(n, 3)`` mm of the robot with ``values``, and ``d p / d values``, shape ``(3 n, G)``.

    Rows of the Jacobian run over poses then x, y, z (``positions.ravel()``).
    """
    robot = robot_with(nominal, values, parametrization)
    p, chain = robot.parameter_jacobian(q_deg)
    size = geometric_size(nominal, parametrization)
    if PARAMETRIZATIONS[parametrization].origins:
        chain = _complete_columns(robot, q_deg, p, chain, values)
    lever = p - values[size - 6:size - 3]                # about the shifted base origin
    base = np.empty((p.shape[0], 3, 6))
    base[:, :, :3] = np.eye(3)
    for k, axis in enumerate(base_axes(nominal, values, parametrization)):
        base[:, :, 3 + k] = np.cross(axis, lever) * (np.pi / 180.0)
    return p, np.concatenate([chain, base], axis=2).reshape(-1, size)


def complete_axes(robot: Robot, q_deg: NDArray[np.float64], values: NDArray[np.float64]
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """For the complete parametrization at ``values``: the frame origins ``(n, R + 1, 3)`` and, per row, the
    directions its shifts ``x, y, z`` move along and the axes its turns ``rx, ry, rz`` turn about (about the
    origin of the frame the row ends in), each ``(n, R, 3, 3)`` (last axis: the parameter).

    The errors follow the row's transform, ``E Tr(x, y, z) Rz Ry Rx``: the shifts move along the axes of
    ``F``, the frame before the turn; ``rz`` turns about ``F``'s z, ``ry`` about ``F Rz`` y, ``rx`` about
    ``F Rz Ry`` x.
    """
    rows = robot.alpha_deg.size
    origins, xs, zs = robot.frame_axes(q_deg)
    frames = np.stack([xs[:, 1:], np.cross(zs[:, 1:], xs[:, 1:]), zs[:, 1:]], axis=-1)     # (n, R, 3, 3)
    turns = values[:7 * rows].reshape(rows, 7)[:, 4:]
    shifts, axes = np.empty_like(frames), np.empty_like(frames)
    for r in range(rows):
        rx, ry, rz = turns[r]
        f = frames[:, r] @ matrix_from_rpy_deg(turns[r]).T
        local = np.column_stack([matrix_from_rpy_deg([0.0, 0.0, rz]) @ matrix_from_rpy_deg([0.0, ry, 0.0])
                                 @ [1.0, 0, 0], matrix_from_rpy_deg([0.0, 0.0, rz]) @ [0, 1.0, 0], [0, 0, 1.0]])
        shifts[:, r], axes[:, r] = f, f @ local
    return origins, shifts, axes


def _complete_columns(robot: Robot, q_deg, p, chain, values) -> NDArray[np.float64]:
    """``d p / d`` the complete rows' parameters and the tool ``(n, 3, 7 R + 3)``, from the DH columns
    ``chain`` of :meth:`Robot.parameter_jacobian` (their theta columns are the same)."""
    rows = robot.alpha_deg.size
    origins, shifts, axes = complete_axes(robot, q_deg, values)
    out = np.empty((p.shape[0], 3, 7 * rows + 3))
    out[:, :, 0:7 * rows:7] = chain[:, :, 0:4 * rows:4]
    for r in range(rows):
        out[:, :, 7 * r + 1:7 * r + 4] = shifts[:, r]
        lever = p - origins[:, r + 1]
        out[:, :, 7 * r + 4:7 * r + 7] = np.cross(axes[:, r], lever[:, :, None], axis=1) * (np.pi / 180.0)
    out[:, :, 7 * rows:] = chain[:, :, 4 * rows:]
    return out


def base_axes(nominal: Robot, values: NDArray[np.float64], parametrization: str = "dh"
              ) -> list[NDArray[np.float64]]:
    """The axes ``(3,)`` the base correction's ``rx, ry, rz`` turn about (``Rz Ry Rx``), in the measurement frame."""
    size = geometric_size(nominal, parametrization)
    _, ry, rz = values[size - 3:size]
    turn_z = matrix_from_rpy_deg(np.array([0.0, 0.0, rz]))
    return [turn_z @ matrix_from_rpy_deg(np.array([0.0, ry, 0.0])) @ [1.0, 0, 0], turn_z @ [0, 1.0, 0],
            np.array([0, 0, 1.0])]


def actual_joints(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64],
                  values: NDArray[np.float64], payload_kg: NDArray[np.float64], derivatives: bool = False,
                  parametrization: str = "dh"):
    """The joint angles the arm takes, ``(n, N)`` deg, their design and the lever arms' moves (see
    :meth:`JointErrors.design`; None without joint errors). Gravity acts in the robot's own base frame:
    the base correction is left out."""
    if errors is None or errors.empty:
        return q_deg, None, None
    size = geometric_size(nominal, parametrization)
    motions = complete_motions(values) if PARAMETRIZATIONS[parametrization].origins else None
    return errors.design(own_geometry(nominal, values, parametrization), q_deg, values[size:size + errors.size],
                         payload_kg, derivatives, motions)


def complete_motions(values: NDArray[np.float64]):
    """For the lever arms of compliant joints: how each complete row parameter at ``values`` moves the frames
    after its row (as :func:`partcal.calibration.joint_errors.dh_motions`): theta turns about the row's z axis,
    the shifts and turns of :func:`complete_axes` (turns about the origin of the frame the row ends in)."""
    def motions(geometry: Robot, q_deg: NDArray[np.float64]) -> list:
        origins, shifts, axes = complete_axes(geometry, q_deg, values)
        zs = geometry.frame_axes(q_deg)[2]
        out = []
        for r in range(geometry.alpha_deg.size):
            out.append(("turn", zs[:, r], origins[:, r], r))
            out += [("shift", shifts[:, r, :, k], None, r) for k in range(3)]
            out += [("turn", axes[:, r, :, k], origins[:, r + 1], r) for k in range(3)]
        return out
    return motions


def model_positions(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64],
                    values: NDArray[np.float64], payload_kg: NDArray[np.float64], parametrization: str = "dh"
                    ) -> NDArray[np.float64]:
    """Tool positions ``(n, 3)`` mm of the model with ``values`` (geometry and joint errors)."""
    q_actual = actual_joints(nominal, errors, q_deg, values, payload_kg, parametrization=parametrization)[0]
    return robot_with(nominal, values, parametrization).positions(q_actual)


def model_jacobian(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64],
                   values: NDArray[np.float64], payload_kg: NDArray[np.float64], parametrization: str = "dh"
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions ``(n, 3)`` mm and ``d p / d values``, shape ``(3 n, P)``, geometry and joint errors.

    The geometric columns are those of :func:`identification_jacobian` at the actual joint angles, plus,
    with compliant joints, how the DH rows and the tool move the lever arms; a joint error's column is
    the joint's position Jacobian times its design column. All analytic.
    """
    q_actual, design, moves = actual_joints(nominal, errors, q_deg, values, payload_kg, derivatives=True,
                                            parametrization=parametrization)
    size = geometric_size(nominal, parametrization)
    p, jac = identification_jacobian(nominal, q_actual, values[:size], parametrization)
    if design is None:
        return p, jac
    joints = robot_with(nominal, values, parametrization).jacobian(q_actual)      # (n, 3, N) mm/deg
    if moves is not None:
        jac[:, :size - 6] += (joints @ moves).reshape(-1, size - 6)      # batched matmul: about 2x faster than einsum
    extra = (joints @ design).reshape(-1, design.shape[2])
    return p, np.hstack([jac, extra])


def turn_columns(nominal: Robot, robot: Robot, q_actual: NDArray[np.float64], design, moves,
                 values: NDArray[np.float64], parametrization: str = "dh") -> NDArray[np.float64]:
    """How each of the model's own parameters ``values`` (geometry, joint errors) turns the flange: its angular
    velocity in the base frame per unit (radians per degree; lengths turn nothing), shape ``(n, 3, P)``.

    A row's theta turns about the row's z axis, its alpha about the next frame's x axis (a complete row's
    turns about their axes), the base correction about its axes, a joint error through the joint's axes.
    ``robot`` is the nominal robot with ``values``; ``q_actual``, ``design``, ``moves`` as
    :func:`actual_joints` gives them.
    """
    size, rows, n = geometric_size(nominal, parametrization), nominal.alpha_deg.size, q_actual.shape[0]
    _, xs, zs = robot.frame_axes(q_actual)                                # (n, R + 1, 3)
    omega = np.zeros((n, 3, values.size))
    if PARAMETRIZATIONS[parametrization].origins:
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
        omega[:, :, size:] = np.einsum("nij,njp->nip", per_joint, design)
    return omega


@dataclass(frozen=True, eq=False)
class Chain:
    """The model's targets at every row: positions (n, 3) mm, tool rotations (n, 3, 3) when a type needs
    them, and their derivatives by the model's own parameters: ``jac`` (n, 3, P), ``omega`` (n, 3, P) the
    tool's angular velocity (radians per unit)."""

    positions: NDArray[np.float64]
    rotations: NDArray[np.float64] | None
    jac: NDArray[np.float64] | None
    omega: NDArray[np.float64] | None


def chain_at(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64], values: NDArray[np.float64],
             payload_kg: NDArray[np.float64], parametrization: str, orientation: bool, jacobian: bool) -> Chain:
    """:class:`Chain` of the model with its own parameters ``values``."""
    robot = robot_with(nominal, values, parametrization)
    q_actual, design, moves = actual_joints(nominal, errors, q_deg, values, payload_kg, derivatives=jacobian,
                                            parametrization=parametrization)
    rotations = robot.forward(q_actual)[:, :3, :3] if orientation else None
    if not jacobian:
        return Chain(model_positions(nominal, errors, q_deg, values, payload_kg, parametrization), rotations,
                     None, None)
    p, jac = model_jacobian(nominal, errors, q_deg, values, payload_kg, parametrization)
    omega = turn_columns(nominal, robot, q_actual, design, moves, values, parametrization) if orientation else None
    return Chain(p, rotations, jac.reshape(p.shape[0], 3, -1), omega)
