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

Several targets on the tool (``x_meas@B``..) each get their own offset in the
flange frame, fitted with the frame from all of them; a measured orientation
(a 6-D probe) adds the probe's constant rotation on the flange, and its
residual, the small turn from the model's flange to the measured one, counts
``orientation_mm_per_rad`` mm per radian beside the positions' mm. Residuals are
reported per target, and for the orientation in degrees.

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
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from .._validation import check_array, check_std
from ..errors import DataError
from ..metrics import ROBUST_LOSSES, loss_weights, pooled_rms
from ..robot.frames import kabsch
from ..robot.kinematics import ORIENTATION_MM_PER_RAD, Robot, flange_offset
from ..robot.rotations import (matrices_from_xyz_deg, matrix_from_rotation_vector, rotation_vector_from_matrix,
                               rotation_vectors_from_matrices, xyz_deg_from_matrices)
from .measurements import Measurements
from .pose_columns import PRIMARY
from .plausibility import Plausibility, check_orientation_residuals, check_residuals

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
    target_tools_mm : dict of str to ndarray (3,)
        The extra targets' offsets in the flange frame, mm (empty for one target).
    target_rms_3d : dict of str to float
        3-D RMS of each target's residuals, mm, the primary (:data:`PRIMARY`) first (empty for one target).
    probe_rotation : ndarray, shape (3, 3), optional
        The measured frame's rotation on the flange (``R_flange @ probe_rotation`` is what the probe
        reads, in the base frame), when an orientation was measured.
    orientation_rms_deg : float, optional
        RMS angle of the orientation residuals, degrees.
    robust : dict, optional
        With a robust loss: ``loss``, ``scale_mm`` and ``downweighted``, the rows (``row`` from 0,
        ``residual_mm``, ``weight``) the loss weighs below 0.5 (:func:`register_tracker`). None otherwise.
    """

    rotation: NDArray[np.float64]
    translation_mm: NDArray[np.float64]
    tool_mm: NDArray[np.float64]
    rms_3d: float
    max_3d: float
    condition: float
    n_poses: int
    fit_tool: bool
    target_tools_mm: dict = field(default_factory=dict)
    target_rms_3d: dict = field(default_factory=dict)
    probe_rotation: NDArray[np.float64] | None = None
    orientation_rms_deg: float | None = None
    robust: dict | None = None

    @property
    def rotation_deg(self) -> NDArray[np.float64]:
        """The rotation as a rotation vector (axis times angle), degrees, shape (3,)."""
        return np.degrees(rotation_vector_from_matrix(self.rotation))

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
                "n": int(self.n_poses), "fit_tool": bool(self.fit_tool), **self._more_dict()}

    def _more_dict(self) -> dict:
        """The extra targets' and the orientation's fields (none for one target without orientation)."""
        out = {}
        if self.target_rms_3d:
            out["targets"] = {name: {"rms_3d": float(rms), "tool_mm": [float(v) for v in self.tool_of(name)]}
                              for name, rms in self.target_rms_3d.items()}
        if self.probe_rotation is not None:
            out["probe_rotation_deg"] = [float(v) for v in np.degrees(rotation_vector_from_matrix(self.probe_rotation))]
            out["orientation_rms_deg"] = float(self.orientation_rms_deg)
        if self.robust is not None:
            out["robust"] = self.robust
        return out

    def tool_of(self, target: str) -> NDArray[np.float64]:
        """A target's offset in the flange frame, mm."""
        return self.tool_mm if target == PRIMARY else self.target_tools_mm[target]


def register_tracker(robot: Robot, q_deg, measured_mm, *, tool_mm=None, fit_tool: bool = True,
                     source: str = "registration", max_condition: float = MAX_CONDITION,
                     plausibility: Plausibility | None = None, targets: dict | None = None,
                     target_tools_mm: dict | None = None, orientation_deg=None,
                     orientation_mm_per_rad: float = ORIENTATION_MM_PER_RAD, probe_rotation=None,
                     std_mm=None, loss: str = "linear", loss_scale: float = 3.0) -> Registration:
    """Fit the tracker frame (and the tool offsets) to measured poses.

    Parameters
    ----------
    robot : Robot
        The nominal kinematics; its own ``tool_mm`` is the default tool.
    q_deg : array-like, shape (n, N)
        Joint angles, degrees.
    measured_mm : array-like, shape (n, 3)
        The (primary) target measured in the tracker frame, mm.
    tool_mm : array-like, shape (3,), optional
        The target's offset in the flange frame, mm: fixed with
        ``fit_tool=False``, the starting value otherwise. Default the robot's.
    fit_tool : bool
        Estimate the tool offsets too (3 parameters per target).
    source : str
        Names the data in error messages (a file name).
    max_condition : float
        Refuse registrations whose condition number exceeds this.
    plausibility : Plausibility, optional
        Residuals beyond its ``max_error_of_reach`` of the robot's reach are
        refused, with the likely cause (metres, swapped columns, another robot).
    targets : dict of str to array-like (n, 3), optional
        Further targets measured in the tracker frame, mm, by name.
    target_tools_mm : dict of str to array-like (3,), optional
        Their offsets in the flange frame, mm: required with ``fit_tool=False``;
        by default each starts from the mean offset the Kabsch frame gives it.
    orientation_deg : array-like, shape (n, 3), optional
        The probe's orientation in the tracker frame, intrinsic XYZ degrees:
        fits the probe's rotation on the flange too.
    orientation_mm_per_rad : float
        Weight of an orientation residual: one radian counts as this many mm.
    probe_rotation : array-like, shape (3, 3), optional
        The probe's rotation on the flange, given (another registration's, the
        probe not remounted): then only the frame is fitted to the orientation.
    std_mm : array-like, shape (n, 3), optional
        The measured points' standard deviations per coordinate (tracker frame), mm: each pose's residuals
        (every target's) are divided by the root mean square of its three and multiplied by the
        reference (their root mean square over the poses); the orientation's are not weighted. None: every
        pose alike (the fit is then the same as before weights existed).
    loss : {"linear", "huber", "soft_l1", "cauchy"}
        scipy's ``least_squares`` loss of each weighted residual coordinate (trust-region reflective);
        ``linear``: least squares by Levenberg-Marquardt.
    loss_scale : float
        The loss's ``f_scale`` in standard deviations of a coordinate: of the larger of the reference of
        ``std_mm`` and the robust spread (1.4826 median absolute residual) of the previous fit, taken again up
        to 4 times. The nominal robot's own errors (a millimetre) dwarf a tracker's noise: measured against
        the nominal model, a point's residual is mostly the robot's, so the noise alone would name every row.

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
    extra = {name: check_array(p, f"targets[{name!r}]", columns=3) for name, p in (targets or {}).items()}
    tool0 = robot.tool_mm if tool_mm is None else check_array(np.reshape(tool_mm, (1, -1)), "tool_mm", columns=3)[0]
    n_params = (6 + 3 * (1 + len(extra)) * fit_tool) + 3 * (orientation_deg is not None and probe_rotation is None)
    need = 4 if fit_tool else 3            # the primary target's frame and offset alone need these
    if q.shape[0] < need:
        raise DataError(f"{source}: a tracker registration {'with' if fit_tool else 'without'} the tool needs at "
                        f"least {need} poses ({9 if fit_tool else 6} parameters); got {q.shape[0]}")
    flange = robot.flange(q)
    p_fl, r_fl = flange[:, :3, 3], flange[:, :3, :3]
    rot0, t0 = kabsch(meas, p_fl + r_fl @ tool0)
    tools0 = np.vstack([tool0] + [_start_tool(name, extra[name], rot0, t0, flange, target_tools_mm, fit_tool, source)
                                  for name in extra])
    points = np.stack([meas, *extra.values()])                                     # (K, n, 3)
    probe = None if orientation_deg is None else _Probe(q.shape[0], orientation_deg, rot0, r_fl, orientation_mm_per_rad,
                                                        probe_rotation)
    k_tools = 3 * len(tools0) if fit_tool else 0

    def unpack(x):
        rot = matrix_from_rotation_vector(x[:3]) @ rot0
        tools = x[6:6 + k_tools].reshape(-1, 3) if fit_tool else tools0
        return rot, x[3:6], tools

    def position_residuals(x):
        rot, shift, tools = unpack(x)
        return points @ rot.T + shift - p_fl - np.einsum("nij,kj->kni", r_fl, tools)

    def residuals(x):
        out = position_residuals(x).ravel()
        return out if probe is None else np.concatenate([out, probe.residuals(unpack(x)[0], x[6 + k_tools:])])

    x0 = np.concatenate([np.zeros(3), t0, tools0.ravel() if fit_tool else [], np.zeros(probe.size if probe else 0)])
    weight, reference = _pose_weights(std_mm, q.shape[0], len(points), probe is not None, source)
    if weight is not None:
        plain = residuals

        def residuals(x):
            return plain(x) * weight
    sol = least_squares(residuals, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200 * n_params)
    robust = None
    if loss != "linear":
        sol, robust = _robust_fit(residuals, sol, loss, loss_scale, reference, q.shape[0], weight, n_params)
        for row in robust["downweighted"]:
            log.warning("%s: data row %d: down-weighted by the registration's %s loss (residual %.4g mm, weight "
                        "%.3g)", source, row["row"] + 1, loss, row["residual_mm"], row["weight"])
    rot, shift, tools = unpack(sol.x)
    resid = position_residuals(sol.x)
    check_residuals(source, resid[0], p_fl + r_fl @ tool0, meas, robot.reach_mm, robot.name,
                    plausibility or Plausibility())
    _check_mirror(source, meas, p_fl, r_fl, tools0[0], fit_tool, pooled_rms(resid[0]))
    if probe is not None:
        check_orientation_residuals(source, np.degrees(np.linalg.norm(probe.turns(rot, sol.x[6 + k_tools:]), axis=1)),
                                    r_fl, orientation_deg, rot, plausibility or Plausibility())
    condition, weakest = _conditioning(points @ rot.T + shift, r_fl, fit_tool, [PRIMARY, *extra])
    if not condition <= max_condition:
        raise DataError(f"{source}: the tracker registration is ill-conditioned (condition number {condition:.3g} > "
                        f"{max_condition:g}): the {q.shape[0]} poses do not determine {weakest}; measure poses "
                        "spread in space with varied flange orientations, or give the tool offset "
                        "(registration: {tool_mm: [x, y, z], fit_tool: false})")
    if condition > WARN_CONDITION:
        log.warning("%s: the tracker registration is poorly conditioned (condition number %.0f): the poses "
                    "barely determine %s", source, condition, weakest)
    rms = np.sqrt(np.mean(np.sum(resid**2, axis=2), axis=1))
    norms = np.linalg.norm(resid[0], axis=1)
    reg = Registration(rotation=rot, translation_mm=shift.copy(), tool_mm=tools[0].copy(),
                       rms_3d=float(rms[0]), max_3d=float(norms.max()), condition=condition,
                       n_poses=q.shape[0], fit_tool=fit_tool,
                       target_tools_mm={name: tools[k + 1].copy() for k, name in enumerate(extra)},
                       target_rms_3d=dict(zip([PRIMARY, *extra], map(float, rms))) if extra else {},
                       **(probe.result(rot, sol.x[6 + k_tools:]) if probe else {}), robust=robust)
    log.info("%s: registered %d poses, RMS %.4f mm, condition %.1f", source, q.shape[0], reg.rms_3d, condition)
    return reg


def _pose_weights(std_mm, n: int, k: int, orientation: bool, source: str):
    """The weight of every residual of :func:`register_tracker` from the points' standard deviations ``std_mm``
    (n, 3): ``reference / s`` per pose, ``s`` the root mean square of its three, for each of the ``k`` targets'
    coordinates (the orientation's 1); and the reference. ``(None, None)`` without them."""
    if std_mm is None:
        return None, None
    std = check_std(std_mm, n, source)
    per_pose = np.sqrt(np.mean(std**2, axis=1))
    reference = float(np.sqrt(np.mean(per_pose**2)))
    weight = np.tile(np.repeat(reference / per_pose, 3), k)
    return (np.concatenate([weight, np.ones(3 * n)]) if orientation else weight), reference


def _robust_fit(residuals, sol, loss: str, loss_scale: float, reference: float | None, n: int, weight, n_params: int):
    """The robust refit of a registration from the least-squares solution ``sol``, and its ``robust`` entry (the
    primary target's rows weighed below 0.5, each row's weight its worst coordinate's ``rho'``)."""
    if loss not in ROBUST_LOSSES:
        raise DataError(f"loss must be one of {', '.join(ROBUST_LOSSES)}; got {loss!r}")
    scale = None
    for _ in range(4):
        new = loss_scale * max(1.4826 * float(np.median(np.abs(residuals(sol.x)))), reference or 0.0, 1e-12)
        if scale is not None and abs(new - scale) < 0.05 * scale:
            break
        scale = new
        sol = least_squares(residuals, sol.x, method="trf", loss=loss, f_scale=scale, xtol=1e-15, ftol=1e-15,
                            gtol=1e-15, max_nfev=200 * n_params)
    r = residuals(sol.x)[:3 * n]
    row_weight = loss_weights(r / scale, loss).reshape(n, 3).min(axis=1)
    plain = (r if weight is None else r / weight[:3 * n]).reshape(n, 3)
    low = np.flatnonzero(row_weight < 0.5)
    return sol, {"loss": loss, "scale_mm": float(scale),
                 "downweighted": [{"row": int(i), "residual_mm": float(np.linalg.norm(plain[i])),
                                   "weight": float(row_weight[i])} for i in low]}


def register_measurements(robot: Robot, m: Measurements, **options) -> Registration:
    """:func:`register_tracker` on a data set: its primary target, its extra targets and its orientation.

    ``options`` are :func:`register_tracker`'s keywords (``tool_mm``, ``fit_tool``, ``source`` ...).
    """
    return register_tracker(robot, m.q_deg, m.measured_mm, targets=m.extra_measured_mm,
                            orientation_deg=m.measured_orientation_deg, std_mm=m.std_mm, **options)


MIRROR_RATIO = 0.5
"""A registration is refused as a mirror image when the measured points with one axis flipped register to
less than this fraction of their own residual: a rotation cannot undo a mirror, so swapped tracker columns
or a flipped sign fit worse than their mirror image. (Poses nearly in a plane register almost as well
mirrored: IPA UR10 series B rows 2-300 with x and y swapped left 3.0 mm against 0.56 mm flipped back.)"""


def _check_mirror(source: str, measured_mm, p_fl, r_fl, tool_mm, fit_tool: bool, rms_mm: float) -> None:
    """Refuse points that register better mirrored (one axis flipped) than as they are (:data:`MIRROR_RATIO`)."""
    mirrored = _position_rms(measured_mm * [-1.0, 1.0, 1.0], p_fl, r_fl, tool_mm, fit_tool)
    if mirrored < MIRROR_RATIO * rms_mm:
        raise DataError(f"{source}: the measured positions are a mirror image of the robot's: the tracker "
                        f"registration leaves {rms_mm:.4g} mm RMS, the same points with one axis flipped "
                        f"{mirrored:.4g} mm: two of the columns x_meas, y_meas, z_meas swapped, or one sign flipped")


def _position_rms(measured_mm, p_fl, r_fl, tool_mm, fit_tool: bool) -> float:
    """3-D RMS of the best registration (frame, and the tool with ``fit_tool``) of the points alone, mm."""
    rot0, t0 = kabsch(measured_mm, p_fl + r_fl @ tool_mm)

    def residuals(x):
        rot = matrix_from_rotation_vector(x[:3]) @ rot0
        tool = x[6:9] if fit_tool else tool_mm
        return (measured_mm @ rot.T + x[3:6] - p_fl - r_fl @ tool).ravel()

    x0 = np.concatenate([np.zeros(3), t0, tool_mm if fit_tool else []])
    sol = least_squares(residuals, x0, method="lm", xtol=1e-12, ftol=1e-12, max_nfev=200 * len(x0))
    return pooled_rms(sol.fun.reshape(-1, 3))


def _start_tool(name: str, points: NDArray[np.float64], rot0, t0, flange, given: dict | None, fit_tool: bool,
                source: str) -> NDArray[np.float64]:
    """An extra target's offset: given, or (to start the fit) the mean one the Kabsch frame puts it at."""
    if given is not None and name in given:
        return check_array(np.reshape(given[name], (1, -1)), f"target_tools_mm[{name!r}]", columns=3)[0]
    if not fit_tool:
        raise DataError(f"{source}: with the tool given (fit_tool: false) every target's offset must be given too; "
                        f"target {name} has none")
    return flange_offset(flange, points @ rot0.T + t0)


class _Probe:
    """The orientation part of a registration: the probe's rotation on the flange and its residuals.

    The residual is the small turn ``log(base_R_tracker @ tracker_R_probe @ probe_R_flange @ flange_R_base)``
    (a rotation vector in the base frame, radians; the identity when all agree) times ``mm_per_rad``.
    """

    def __init__(self, n: int, orientation_deg, base_R_tracker0, base_R_flange, mm_per_rad: float, given=None):
        angles = check_array(orientation_deg, "orientation_deg", columns=3)
        if angles.shape[0] != n:
            raise DataError(f"orientation_deg has {angles.shape[0]} rows but q_deg has {n}")
        self.tracker_R_probe, self.base_R_flange = matrices_from_xyz_deg(angles), base_R_flange
        self.weight = float(mm_per_rad)
        if given is not None:                  # fixed: no parameter of its own
            self.start, self.size = np.asarray(given, dtype=float).reshape(3, 3), 0
            return
        u, _, vt = np.linalg.svd(np.mean(base_R_flange.transpose(0, 2, 1) @ base_R_tracker0 @ self.tracker_R_probe,
                                         axis=0))
        self.start, self.size = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt, 3     # the mean rotation

    def flange_R_probe(self, x) -> NDArray[np.float64]:
        """The probe's rotation on the flange ``(3, 3)`` for the parameters ``x`` (a turn from the start)."""
        return (matrix_from_rotation_vector(x) if self.size else np.eye(3)) @ self.start

    def turns(self, base_R_tracker, x) -> NDArray[np.float64]:
        flange_R_probe = self.flange_R_probe(x)
        return rotation_vectors_from_matrices(base_R_tracker @ self.tracker_R_probe @ flange_R_probe.T
                                              @ self.base_R_flange.transpose(0, 2, 1))

    def residuals(self, base_R_tracker, x) -> NDArray[np.float64]:
        return (self.weight * self.turns(base_R_tracker, x)).ravel()

    def result(self, base_R_tracker, x) -> dict:
        angles = np.linalg.norm(self.turns(base_R_tracker, x), axis=1)
        return {"probe_rotation": self.flange_R_probe(x),
                "orientation_rms_deg": float(np.degrees(np.sqrt(np.mean(angles**2))))}


def _conditioning(points_mm: NDArray[np.float64], r_flange: NDArray[np.float64], fit_tool: bool,
                  names: list[str]) -> tuple[float, str]:
    """Condition number of the scaled Jacobian, and the weakest parameter combination in words.

    ``points_mm`` (K, n, 3) are the registered points of the K targets. Rotations are
    taken about their centroid and scaled by the points' RMS distance from it (a
    rotation counts as the displacement it causes there), so that neither a
    tracker standing far away nor the choice of units looks like a badly posed
    problem; translation and tool columns are in mm. The orientation's rows are
    left out: the number says what the positions determine.
    """
    k_targets, n = points_mm.shape[:2]
    lever = (points_mm - points_mm.reshape(-1, 3).mean(axis=0)).reshape(-1, 3)
    size = float(np.sqrt(np.mean(np.einsum("ij,ij->i", lever, lever))))
    if size == 0.0:
        return float("inf"), "the rotation (all points coincide)"
    labels = list(PARAMETERS[:6])
    jac = np.zeros((k_targets * n, 3, 6 + 3 * k_targets * fit_tool))
    for k in range(3):
        axis = np.zeros(3)
        axis[k] = 1.0
        jac[:, :, k] = np.cross(axis, lever / size)
        jac[:, k, 3 + k] = 1.0
    if fit_tool:
        for t, name in enumerate(names):
            jac[t * n:(t + 1) * n, :, 6 + 3 * t:9 + 3 * t] = -r_flange
            labels += [f"tool {c}" if name == PRIMARY else f"tool@{name} {c}" for c in "xyz"]
    _, sv, vt = np.linalg.svd(jac.reshape(3 * k_targets * n, -1), full_matrices=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > sv[0] * 1e-15 else float("inf")
    weakest = vt[-1]
    big = [labels[i] for i in np.argsort(-np.abs(weakest)) if abs(weakest[i]) >= 0.3][:3]
    return condition, "the combination of " + ", ".join(big) if len(big) > 1 else big[0]


def registered(m: Measurements, robot: Robot, reg: Registration) -> Measurements:
    """A data set in the tracker frame carried into the base frame.

    The measured points are transformed by ``reg``; the nominal positions are
    recomputed by forward kinematics with the registration's tool offsets.
    Extra targets come along when ``reg`` has their offsets; a measured
    orientation when ``reg`` fitted the probe's rotation: it becomes the
    measured flange's (``R @ R_meas @ probe^T``), beside the nominal flange's.
    """
    flange = robot.flange(m.q_deg)
    p_fl, r_fl = flange[:, :3, 3], flange[:, :3, :3]
    nominal = robot.replace(tool_mm=np.asarray(reg.tool_mm, dtype=float)).positions(m.q_deg)
    kept = [name for name in m.extra_measured_mm if name in reg.target_tools_mm]
    orientation = {}
    if m.has_orientation and reg.probe_rotation is not None:
        turned = reg.rotation @ matrices_from_xyz_deg(m.measured_orientation_deg) @ reg.probe_rotation.T
        orientation = {"measured_orientation_deg": xyz_deg_from_matrices(turned),
                       "nominal_orientation_deg": xyz_deg_from_matrices(r_fl)}
    std = {} if m.std_mm is None else {"std_mm": np.sqrt(m.std_mm**2 @ (reg.rotation**2).T)}   # diag(R S R^T)
    return dataclasses.replace(m, nominal_mm=nominal, measured_mm=reg.to_base(m.measured_mm), **std,
                               extra_measured_mm={name: reg.to_base(m.extra_measured_mm[name]) for name in kept},
                               extra_nominal_mm={name: p_fl + r_fl @ reg.target_tools_mm[name] for name in kept},
                               **orientation)
