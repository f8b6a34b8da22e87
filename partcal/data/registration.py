"""Tracker registration: the rigid transform tracker -> robot base, and the tool (SMR) offset.

A laser tracker measures its target (an SMR, a T-Mac) in its own frame. With
a robot model, a measured point ``m`` (tracker frame) and the nominal target
position at joint angles ``q`` are related by::

    R @ m + t  =  p_flange(q) + R_flange(q) @ tool      (+ the robot's error)

with ``R, t`` the pose of the tracker frame in the base frame (6 parameters)
and ``tool`` the target's offset in the flange frame (the robot's last DH
frame; 3 parameters, or fixed when known). They are estimated by nonlinear
least squares (``scipy.optimize.least_squares``) from a closed-form Kabsch
start, on the identification set only; the same transform then carries every
test set measured from the same tracker position into the base frame.

Whatever the robot's rigid error is, the registration absorbs it: what
remains, ``measured - nominal`` after registration, is the error an error
model can learn. A registration whose poses do not determine the parameters
(too few poses, collinear points, a flange that never turns) is refused
rather than returned: the condition number of the scaled Jacobian must
stay below :data:`MAX_CONDITION`.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .._validation import check_array
from ..errors import DataError
from ..robot.kinematics import Robot
from .measurements import Measurements
from .plausibility import Plausibility, check_residuals

log = logging.getLogger(__name__)

MAX_CONDITION = 1000.0
WARN_CONDITION = 100.0
PARAMETERS = ("rotation x", "rotation y", "rotation z", "translation x", "translation y", "translation z",
              "tool x", "tool y", "tool z")


@dataclass(frozen=True, eq=False)
class Registration:
    """A fitted tracker registration.

    Attributes
    ----------
    rotation : ndarray, shape (3, 3)
        Rotation tracker -> base (``p_base = rotation @ p_tracker + translation_mm``).
    translation_mm : ndarray, shape (3,)
        The tracker frame's origin in the base frame, mm.
    tool_mm : ndarray, shape (3,)
        The target's offset in the flange (last DH) frame, mm.
    rms_3d, max_3d : float
        3-D RMS and largest norm of the residuals ``registered measured - nominal``, mm.
    condition : float
        Condition number of the scaled Jacobian at the solution (1 is ideal;
        rotations about the points' centroid, scaled by their spread, so it
        depends on the poses only, not on where the tracker stands).
    n_poses : int
        Poses the registration was fitted on.
    fit_tool : bool
        Whether ``tool_mm`` was fitted (else it was given).
    """

    rotation: NDArray[np.float64]
    translation_mm: NDArray[np.float64]
    tool_mm: NDArray[np.float64]
    rms_3d: float
    max_3d: float
    condition: float
    n_poses: int
    fit_tool: bool

    @property
    def rotation_deg(self) -> NDArray[np.float64]:
        """The rotation as a rotation vector (axis times angle), degrees, shape (3,)."""
        return Rotation.from_matrix(self.rotation).as_rotvec(degrees=True)

    def to_base(self, tracker_mm) -> NDArray[np.float64]:
        """Points in the tracker frame ``(n, 3)`` mm -> the base frame ``(n, 3)`` mm."""
        p = check_array(tracker_mm, "tracker_mm", columns=3)
        return p @ self.rotation.T + self.translation_mm

    def to_dict(self) -> dict:
        """Plain numbers for metrics.json: mm and degrees."""
        return {"rms_3d": float(self.rms_3d), "max_3d": float(self.max_3d),
                "rotation_deg": [float(v) for v in self.rotation_deg],
                "translation_mm": [float(v) for v in self.translation_mm],
                "tool_mm": [float(v) for v in self.tool_mm], "condition": float(self.condition),
                "n": int(self.n_poses), "fit_tool": bool(self.fit_tool)}


def kabsch(source, target) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The proper rotation ``R`` and translation ``t`` minimising ``sum |R @ s + t - p|^2``.

    Parameters
    ----------
    source, target : array-like, shape (n, 3)
        Corresponding points (n >= 3), e.g. mm.

    Returns
    -------
    R : ndarray, shape (3, 3)
        det(R) = +1 (a reflection is never returned).
    t : ndarray, shape (3,)

    Examples
    --------
    >>> s = np.array([[0., 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    >>> R, t = kabsch(s, s[:, [1, 0, 2]] * [-1, 1, 1] + 5)
    >>> (np.round(R, 12) + 0.0).tolist(), (np.round(t, 12) + 0.0).tolist()
    ([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [5.0, 5.0, 5.0])
    """
    s = check_array(source, "source", columns=3, min_rows=3)
    p = check_array(target, "target", columns=3, min_rows=3)
    s0, p0 = s.mean(axis=0), p.mean(axis=0)
    u, _, vt = np.linalg.svd((s - s0).T @ (p - p0))
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rot = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rot, p0 - rot @ s0


def register_tracker(robot: Robot, q_deg, measured_mm, *, tool_mm=None, fit_tool: bool = True,
                     source: str = "registration", max_condition: float = MAX_CONDITION,
                     plausibility: Plausibility | None = None) -> Registration:
    """Fit the tracker frame (and the tool offset) to measured poses.

    Parameters
    ----------
    robot : Robot
        The nominal kinematics; its own ``tool_mm`` is the default tool.
    q_deg : array-like, shape (n, N)
        Joint angles, degrees.
    measured_mm : array-like, shape (n, 3)
        The target measured in the tracker frame, mm.
    tool_mm : array-like, shape (3,), optional
        The target's offset in the flange frame, mm: fixed with
        ``fit_tool=False``, the starting value otherwise. Default the robot's.
    fit_tool : bool
        Estimate the tool offset too (9 parameters instead of 6).
    source : str
        Names the data in error messages (a file name).
    max_condition : float
        Refuse registrations whose condition number exceeds this.
    plausibility : Plausibility, optional
        Residuals beyond its ``max_error_of_reach`` of the robot's reach are
        refused, with the likely cause (metres, swapped columns, another robot).

    Returns
    -------
    Registration

    Raises
    ------
    DataError
        Too few poses, poses that do not determine the parameters, or
        residuals no calibrated robot has.
    """
    q = robot.check_joints(q_deg)
    meas = check_array(measured_mm, "measured_mm", columns=3)
    if meas.shape[0] != q.shape[0]:
        raise DataError(f"{source}: {meas.shape[0]} measured points but {q.shape[0]} poses")
    tool0 = robot.tool_mm if tool_mm is None else check_array(np.reshape(tool_mm, (1, -1)), "tool_mm", columns=3)[0]
    n_params = 9 if fit_tool else 6
    need = n_params // 3 + 1
    if q.shape[0] < need:
        raise DataError(f"{source}: a tracker registration {'with' if fit_tool else 'without'} the tool needs at "
                        f"least {need} poses ({n_params} parameters); got {q.shape[0]}")
    flange = robot.replace(tool_mm=np.zeros(3)).forward(q)
    p_fl, r_fl = flange[:, :3, 3], flange[:, :3, :3]
    rot0, t0 = kabsch(meas, p_fl + r_fl @ tool0)

    def residuals(x):
        rot = Rotation.from_rotvec(x[:3]).as_matrix() @ rot0
        tool = x[6:9] if fit_tool else tool0
        return (meas @ rot.T + x[3:6] - p_fl - r_fl @ tool).ravel()

    x0 = np.concatenate([np.zeros(3), t0, tool0 if fit_tool else []])
    sol = least_squares(residuals, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200 * n_params)
    rot = Rotation.from_rotvec(sol.x[:3]).as_matrix() @ rot0
    tool = sol.x[6:9].copy() if fit_tool else tool0.copy()
    registered = meas @ rot.T + sol.x[3:6]
    check_residuals(source, sol.fun.reshape(-1, 3), p_fl + r_fl @ tool0, meas, robot.reach_mm, robot.name,
                    plausibility or Plausibility())
    condition, weakest = _conditioning(registered, r_fl, fit_tool)
    if not condition <= max_condition:
        raise DataError(f"{source}: the tracker registration is ill-conditioned (condition number {condition:.3g} > "
                        f"{max_condition:g}): the {q.shape[0]} poses do not determine {weakest}; measure poses "
                        "spread in space with varied flange orientations, or give the tool offset "
                        "(registration: {tool_mm: [x, y, z], fit_tool: false})")
    if condition > WARN_CONDITION:
        log.warning("%s: the tracker registration is poorly conditioned (condition number %.0f): the poses "
                    "barely determine %s", source, condition, weakest)
    norms = np.linalg.norm(sol.fun.reshape(-1, 3), axis=1)
    reg = Registration(rotation=rot, translation_mm=sol.x[3:6].copy(), tool_mm=tool,
                       rms_3d=float(np.sqrt(np.mean(norms**2))), max_3d=float(norms.max()), condition=condition,
                       n_poses=q.shape[0], fit_tool=fit_tool)
    log.info("%s: registered %d poses, RMS %.4f mm, condition %.1f", source, q.shape[0], reg.rms_3d, condition)
    return reg


def _conditioning(points_mm: NDArray[np.float64], r_flange: NDArray[np.float64], fit_tool: bool) -> tuple[float, str]:
    """Condition number of the scaled Jacobian, and the weakest parameter combination in words.

    Rotations are taken about the centroid of the registered points and
    scaled by the points' RMS distance from it (a rotation counts as the
    displacement it causes there), so that neither a tracker standing far
    away nor the choice of units looks like a badly posed problem; translation
    and tool columns are in mm.
    """
    lever = points_mm - points_mm.mean(axis=0)
    size = float(np.sqrt(np.mean(np.einsum("ij,ij->i", lever, lever))))
    if size == 0.0:
        return float("inf"), "the rotation (all points coincide)"
    n = lever.shape[0]
    jac = np.zeros((n, 3, 9 if fit_tool else 6))
    for k in range(3):
        axis = np.zeros(3)
        axis[k] = 1.0
        jac[:, :, k] = np.cross(axis, lever / size)
        jac[:, k, 3 + k] = 1.0
    if fit_tool:
        jac[:, :, 6:9] = -r_flange
    _, sv, vt = np.linalg.svd(jac.reshape(3 * n, -1), full_matrices=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > sv[0] * 1e-15 else float("inf")
    weakest = vt[-1]
    big = [PARAMETERS[i] for i in np.argsort(-np.abs(weakest)) if abs(weakest[i]) >= 0.3][:3]
    return condition, "the combination of " + ", ".join(big) if len(big) > 1 else big[0]


def registered(m: Measurements, robot: Robot, reg: Registration) -> Measurements:
    """A data set in the tracker frame carried into the base frame.

    The measured points are transformed by ``reg``; the nominal positions are
    recomputed by forward kinematics with the registration's tool offset.
    """
    nominal = robot.replace(tool_mm=np.asarray(reg.tool_mm, dtype=float)).positions(m.q_deg)
    return dataclasses.replace(m, nominal_mm=nominal, measured_mm=reg.to_base(m.measured_mm))
