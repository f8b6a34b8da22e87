"""Kinematic identification: the robot's geometric parameters from measured positions.

The classic calibration the paper's introduction describes. Every DH row has
four parameters (its theta offset, d, a and alpha); the tool offset adds three
and the pose of the robot base in the measurement frame six (a shift and
three small rotations). Rows whose theta follows several joints (the SK120's
parallelogram) get their own offsets like any other row, so a joint zero
offset that moves several coupled rows at once is one direction of this
parameter space. ``identify`` finds the parameters that put the forward
kinematics through the measured positions, by Levenberg-Marquardt with the
analytic Jacobian of the chain.

Positions alone cannot tell every parameter apart: two parallel joint axes
share one ``d``, the first joint's offset is a turn of the base about its z
axis, and a wrist that never moves hides its own offsets. Those directions
are found before the fit from the rank of the identification Jacobian (its
columns scaled to unit length; the rank from the singular values, the choice
of which parameters to keep from a QR factorisation with column pivoting).
They stay at their nominal values and are reported as unidentifiable.

Joint errors the geometry cannot carry, gravity compliance and cyclic
transmission errors (:mod:`partcal.models.joint_errors`), are identified with
the geometry: their parameters follow the geometric ones in the same vector,
the same rank analysis and the same fit; the forward kinematics then runs on
the joint angles the arm actually takes.

``KinematicModel`` wraps this as an error model: its predicted error is
``FK(identified, q_actual) - FK(nominal, q)``. With ``residual=`` another error
model is fitted to what the identified kinematics leave, and the two
predictions add up (a hybrid model).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass, field
from pathlib import PurePath

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import MAX_PAYLOAD_KG, FieldReader, Requirement, boolean, check_array, param_error, real
from ..errors import DataError, ModelFileError
from ..metrics import MRAD_PER_DEG, MRAD_PER_RAD, ORIENTATION, POSITION, distance_outside_boxes
from ..robot.description import load_robot, robot_from_dict, robot_to_dict
from ..robot.kinematics import ORIENTATION_MM_PER_RAD, Robot, matrix_from_euler_deg
from .base import ErrorModelBase, box_points, seed_from
from .bases import varying_inputs
from .gp import GaussianProcessErrorModel
from .joint_errors import JointErrors, compliance_problem, harmonics_problem
from .partitioned import PartitionedErrorModel
from .pose import PoseErrorModel
from .series import ErrorModel
from .targets import Extra, added_names, added_nominal, extra_from, stacked

log = logging.getLogger(__name__)
ROW_PARAMETERS = (("theta", "deg"), ("d", "mm"), ("a", "mm"), ("alpha", "deg"))
TOOL_PARAMETERS = (("tool.x", "mm"), ("tool.y", "mm"), ("tool.z", "mm"))
BASE_PARAMETERS = (("base.x", "mm"), ("base.y", "mm"), ("base.z", "mm"),
                   ("base.rx", "deg"), ("base.ry", "deg"), ("base.rz", "deg"))
STATUSES = ("identified", "unidentifiable", "fixed")
PRIMARY_TARGET = "A"        # the data's unsuffixed target (partcal.data.measurements.PRIMARY)


# ---------------------------------------------------------------------- the parameter vector
def parameter_names(robot: Robot, errors: JointErrors | None = None) -> list[tuple[str, str]]:
    """``(name, unit)`` of every parameter: ``theta[1], d[1], a[1], alpha[1], ..., tool.*, base.*``, then the
    joint errors' (:meth:`JointErrors.names`).

    >>> [n for n, _ in parameter_names(load_robot("motoman_sk120"))][:5]
    ['theta[1]', 'd[1]', 'a[1]', 'alpha[1]', 'theta[2]']
    """
    rows = [(f"{p}[{r + 1}]", unit) for r in range(robot.alpha_deg.size) for p, unit in ROW_PARAMETERS]
    return rows + list(TOOL_PARAMETERS) + list(BASE_PARAMETERS) + (errors.names() if errors is not None else [])


def nominal_values(robot: Robot, errors: JointErrors | None = None) -> NDArray[np.float64]:
    """The robot's own parameter values, shape ``(4 R + 9 [+ P],)``: rows, tool, a zero base correction, and
    zero joint errors."""
    rows = np.column_stack([robot.theta_offset_deg, robot.d_mm, robot.a_mm, robot.alpha_deg]).ravel()
    return np.concatenate([rows, robot.tool_mm, np.zeros(6 + (errors.size if errors is not None else 0))])


def geometric_size(robot: Robot) -> int:
    """Number of geometric parameters, ``4 R + 9`` (the joint errors' follow them)."""
    return 4 * robot.alpha_deg.size + 9


def robot_with(nominal: Robot, values: NDArray[np.float64]) -> Robot:
    """The robot with parameter ``values`` (``(4 R + 9,)``, as :func:`nominal_values`; joint errors ignored).

    The base correction turns the nominal base by ``Rz Ry Rx`` about the
    measurement frame's axes and then shifts it.
    """
    rows = nominal.alpha_deg.size
    dh = values[:4 * rows].reshape(rows, 4)
    turn = matrix_from_euler_deg(values[4 * rows + 6:4 * rows + 9])
    return nominal.replace(theta_offset_deg=dh[:, 0].copy(), d_mm=dh[:, 1].copy(), a_mm=dh[:, 2].copy(),
                           alpha_deg=dh[:, 3].copy(), tool_mm=values[4 * rows:4 * rows + 3].copy(),
                           base_rotation=turn @ nominal.base_rotation,
                           base_mm=turn @ nominal.base_mm + values[4 * rows + 3:4 * rows + 6])


def identification_jacobian(nominal: Robot, q_deg: NDArray[np.float64], values: NDArray[np.float64]
                            ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions ``(n, 3)`` mm of the robot with ``values``, and ``d p / d values``, shape ``(3 n, 4 R + 9)``.

    Rows of the Jacobian run over poses then x, y, z (``positions.ravel()``).
    """
    robot = robot_with(nominal, values)
    p, chain = robot.parameter_jacobian(q_deg)
    rows = nominal.alpha_deg.size
    lever = p - values[4 * rows + 3:4 * rows + 6]                # about the shifted base origin
    base = np.empty((p.shape[0], 3, 6))
    base[:, :, :3] = np.eye(3)
    for k, axis in enumerate(base_axes(nominal, values)):
        base[:, :, 3 + k] = np.cross(axis, lever) * (np.pi / 180.0)
    return p, np.concatenate([chain, base], axis=2).reshape(-1, 4 * rows + 9)


def base_axes(nominal: Robot, values: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """The axes ``(3,)`` the base correction's ``rx, ry, rz`` turn about (``Rz Ry Rx``), in the measurement frame."""
    rows = nominal.alpha_deg.size
    _, ry, rz = values[4 * rows + 6:4 * rows + 9]
    turn_z = matrix_from_euler_deg(np.array([0.0, 0.0, rz]))
    return [turn_z @ matrix_from_euler_deg(np.array([0.0, ry, 0.0])) @ [1.0, 0, 0], turn_z @ [0, 1.0, 0],
            np.array([0, 0, 1.0])]


def actual_joints(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64],
                  values: NDArray[np.float64], payload_kg: NDArray[np.float64], derivatives: bool = False):
    """The joint angles the arm takes, ``(n, N)`` deg, their design and the lever arms' moves (see
    :meth:`JointErrors.design`; None without joint errors). Gravity acts in the robot's own base frame:
    the base correction is left out."""
    if errors is None or errors.empty:
        return q_deg, None, None
    size = geometric_size(nominal)
    return errors.design(own_geometry(nominal, values), q_deg, values[size:size + errors.size], payload_kg,
                         derivatives)


def own_geometry(nominal: Robot, values: NDArray[np.float64]) -> Robot:
    """The robot with ``values`` in its own base frame (the base correction left out): where gravity acts
    along ``-z``, and the joint errors' lever arms are taken."""
    own = values[:geometric_size(nominal)].copy()
    own[-6:] = 0.0
    return robot_with(nominal, own)


def model_positions(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64],
                    values: NDArray[np.float64], payload_kg: NDArray[np.float64]) -> NDArray[np.float64]:
    """Tool positions ``(n, 3)`` mm of the model with ``values`` (geometry and joint errors)."""
    q_actual = actual_joints(nominal, errors, q_deg, values, payload_kg)[0]
    return robot_with(nominal, values).positions(q_actual)


def model_jacobian(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64],
                   values: NDArray[np.float64], payload_kg: NDArray[np.float64]
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions ``(n, 3)`` mm and ``d p / d values``, shape ``(3 n, P)``, geometry and joint errors.

    The geometric columns are those of :func:`identification_jacobian` at the actual joint angles, plus,
    with compliant joints, how the DH rows and the tool move the lever arms; a joint error's column is
    the joint's position Jacobian times its design column. All analytic.
    """
    q_actual, design, moves = actual_joints(nominal, errors, q_deg, values, payload_kg, derivatives=True)
    size = geometric_size(nominal)
    p, jac = identification_jacobian(nominal, q_actual, values[:size])
    if design is None:
        return p, jac
    joints = robot_with(nominal, values).jacobian(q_actual)                       # (n, 3, N) mm/deg
    if moves is not None:
        jac[:, :size - 6] += np.einsum("nij,njp->nip", joints, moves).reshape(-1, size - 6)
    extra = np.einsum("nij,njp->nip", joints, design).reshape(-1, design.shape[2])
    return p, np.hstack([jac, extra])


# ---------------------------------------------------------------------- identification
@dataclass(frozen=True)
class Identification:
    """An identified parameter table.

    Attributes
    ----------
    names, units : tuple of str, length P
    nominal, value : ndarray, shape (P,)
        The nominal and identified values (mm, degrees). Base entries are
        corrections of the nominal base, nominally zero.
    std_error : ndarray, shape (P,)
        Standard errors of the identified values (NaN where not identified):
        ``sigma^2 (J^T J)^-1`` with ``sigma^2`` the residual variance per
        coordinate.
    status : tuple of str
        ``identified``, ``unidentifiable`` (positions cannot separate it from
        the others; kept nominal) or ``fixed`` (not asked for).
    rank, condition : int, float
        Rank of the scaled identification Jacobian, and the condition number
        of its identified columns (at the solution).
    rms_mm : float
        3-D RMS of the remaining position error on the identification data (the primary target's).
    n_poses, evaluations : int
    target_rms_mm : dict of str to float
        With several targets or an orientation: each target's 3-D RMS, mm, the primary first.
    orientation_rms_deg : float, optional
        With an orientation: the RMS angle of the remaining orientation error, degrees.
    primary_identifiable : int, optional
        With several targets or an orientation: how many of the model's own parameters (those of a
        one-target table) the primary target's positions alone would identify, to compare with
        the count identified here.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    nominal: NDArray[np.float64]
    value: NDArray[np.float64]
    std_error: NDArray[np.float64]
    status: tuple[str, ...]
    rank: int
    condition: float
    rms_mm: float
    n_poses: int
    evaluations: int
    target_rms_mm: dict = field(default_factory=dict)
    orientation_rms_deg: float | None = None
    primary_identifiable: int | None = None

    @property
    def correction(self) -> NDArray[np.float64]:
        """Identified minus nominal, shape (P,)."""
        return self.value - self.nominal

    def rows(self) -> list[dict]:
        """One dict per parameter: ``name, unit, nominal, value, correction, std_error, status``."""
        return [{"name": n, "unit": u, "nominal": float(a), "value": float(b), "correction": float(b - a),
                 "std_error": None if np.isnan(s) else float(s), "status": st}
                for n, u, a, b, s, st in zip(self.names, self.units, self.nominal, self.value, self.std_error,
                                             self.status)]

    def unidentifiable(self) -> list[str]:
        """Names of the parameters positions cannot identify."""
        return [n for n, s in zip(self.names, self.status) if s == "unidentifiable"]

    def to_dict(self) -> dict:
        return {"names": list(self.names), "units": list(self.units), "nominal": self.nominal.tolist(),
                "value": self.value.tolist(),
                "std_error": [None if np.isnan(v) else float(v) for v in self.std_error],
                "status": list(self.status), "rank": int(self.rank), "condition": float(self.condition),
                "rms_mm": float(self.rms_mm), "n_poses": int(self.n_poses), "evaluations": int(self.evaluations),
                **({"target_rms_mm": dict(self.target_rms_mm), "orientation_rms_deg": self.orientation_rms_deg,
                    "primary_identifiable": self.primary_identifiable} if self.target_rms_mm else {})}

    @classmethod
    def from_dict(cls, d: dict) -> "Identification":
        return cls(tuple(d["names"]), tuple(d["units"]), np.asarray(d["nominal"], dtype=float),
                   np.asarray(d["value"], dtype=float),
                   np.array([np.nan if v is None else v for v in d["std_error"]], dtype=float),
                   tuple(d["status"]), int(d["rank"]), float(d["condition"]), float(d["rms_mm"]),
                   int(d["n_poses"]), int(d["evaluations"]), dict(d.get("target_rms_mm", {})),
                   d.get("orientation_rms_deg"), d.get("primary_identifiable"))


def identify(robot: Robot, q_deg: NDArray[np.float64], measured_mm: NDArray[np.float64], *, base: bool = True,
             tool: bool = True, rcond: float = 1e-6, errors: JointErrors | None = None,
             payload_kg=0.0, extra: Extra | None = None) -> Identification:
    """Identify the parameters that bring the model's forward kinematics through measured positions.

    Parameters
    ----------
    robot : Robot
        The nominal robot (the starting point, and the values kept for what
        cannot be identified).
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    measured_mm : ndarray, shape (n, 3)
        Measured (primary) tool positions in the base (measurement) frame, mm.
    base, tool : bool
        Whether the base pose and the tool offsets are identified too.
    rcond : float
        Singular values of the unit-column Jacobian below ``rcond`` times the
        largest count as zero: those directions are unidentifiable.
    errors : JointErrors, optional
        Joint compliance and transmission errors identified with the geometry
        (their parameters follow the geometric ones).
    payload_kg : float or ndarray, shape (n,)
        Payload at the tool point, kg (only read by compliant joints).
    extra : Extra, optional
        Further targets and the measured orientation (:mod:`partcal.models.targets`):
        their residuals are stacked with the primary's, one offset per target
        and the probe's turn are identified too (their parameters come last).

    Returns
    -------
    Identification
    """
    q_deg = robot.check_joints(q_deg)
    measured_mm = check_array(measured_mm, "measured_mm", columns=3)
    if len(measured_mm) != len(q_deg):
        raise DataError(f"measured_mm has {len(measured_mm)} rows but q_deg has {len(q_deg)}")
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(q_deg),))
    v0 = nominal_values(robot, errors)
    rows, own = robot.alpha_deg.size, v0.size
    wanted = np.ones(v0.size + (extra.size if extra is not None else 0), dtype=bool)
    wanted[4 * rows:4 * rows + 3] = tool
    wanted[4 * rows + 3:4 * rows + 9] = base
    if extra is None:
        def jac_at(v, jacobian=True):
            if not jacobian:
                return (model_positions(robot, errors, q_deg, v, payload) - measured_mm).ravel(), None
            p, jac = model_jacobian(robot, errors, q_deg, v, payload)
            return (p - measured_mm).ravel(), jac
    else:
        v0 = np.concatenate([v0, extra.nominal()])
        wanted[own:own + 3 * len(extra.tools_mm)] = tool
        jac_at = functools.partial(stacked, robot, errors, q_deg, payload_kg=payload, measured_mm=measured_mm,
                                   extra=extra)
    jac0 = jac_at(v0)[1]
    free, rank = _identifiable(jac0, wanted, rcond)

    def values_of(x):
        v = v0.copy()
        v[free] = x
        return v

    v, evaluations = v0.copy(), 0
    if free.size:
        sol = least_squares(lambda x: jac_at(values_of(x), jacobian=False)[0], v0[free],
                            jac=lambda x: jac_at(values_of(x))[1][:, free], method="lm",
                            x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=200 * (free.size + 1))
        v, evaluations = values_of(sol.x), int(sol.nfev)
        log.debug("least squares: %s (%d evaluations)", sol.message, sol.nfev)
    resid, jac = jac_at(v)
    std, condition = _uncertainty(jac[:, free], resid)
    std_full = np.full(v.size, np.nan)
    std_full[free] = std
    status = np.where(wanted, "unidentifiable", "fixed").astype(object)
    status[free] = "identified"
    names = parameter_names(robot, errors) + (extra.names() if extra is not None else [])
    rms, angle = _target_rms(resid, len(q_deg), extra)
    more = {} if extra is None else {
        "target_rms_mm": dict(zip([PRIMARY_TARGET, *extra.tools_mm], rms)), "orientation_rms_deg": angle,
        "primary_identifiable": _identifiable(jac0[:3 * len(q_deg), :own], wanted[:own], rcond)[1]}
    result = Identification(tuple(n for n, _ in names), tuple(u for _, u in names), v0, v, std_full,
                            tuple(str(s) for s in status), rank, condition, rms[0], q_deg.shape[0], evaluations,
                            **more)
    log.info("identified %d of %d parameters (condition %.3g): RMS %.4f mm", free.size, v.size, condition,
             result.rms_mm)
    return result


def _target_rms(resid: NDArray[np.float64], n: int, extra: Extra | None) -> tuple[list[float], float | None]:
    """3-D RMS of each target's position residuals (mm, the primary first) and the orientation's RMS angle
    (degrees, None without one), from the stacked residuals of :func:`identify`."""
    k = 1 + (len(extra.tools_mm) if extra is not None else 0)
    blocks = resid[:3 * n * k].reshape(k, n, 3)
    rms = [float(np.sqrt(np.mean(np.sum(b**2, axis=1)))) for b in blocks]
    if extra is None or extra.rotations is None:
        return rms, None
    turns = resid[3 * n * k:].reshape(n, 3) / extra.mm_per_rad
    return rms, float(np.degrees(np.sqrt(np.mean(np.sum(turns**2, axis=1)))))


def _identifiable(jac0: NDArray[np.float64], wanted: NDArray[np.bool_], rcond: float
                  ) -> tuple[NDArray[np.intp], int]:
    """Indices of the parameters to identify, and the rank, from the Jacobian ``jac0`` at nominal.

    The columns are scaled to unit length; the rank counts singular values
    above ``rcond`` times the largest; a QR factorisation with column
    pivoting picks that many columns (the most independent first). Columns
    that do not move the tool at all never count.
    """
    norms = np.linalg.norm(jac0, axis=0)
    candidates = np.flatnonzero(wanted & (norms > 1e-12 * max(norms.max(), 1e-300)))
    if candidates.size == 0:
        return candidates, 0
    scaled = jac0[:, candidates] / norms[candidates]
    singular = np.linalg.svd(scaled, compute_uv=False)
    rank = int(np.sum(singular > rcond * singular[0]))
    pivots = scipy.linalg.qr(scaled, mode="r", pivoting=True)[1]
    return np.sort(candidates[pivots[:rank]]), rank


def _uncertainty(jac: NDArray[np.float64], resid: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Standard errors ``sqrt(diag(sigma^2 (J^T J)^-1))`` and the condition number of the unit-column ``J``."""
    if jac.shape[1] == 0:
        return np.zeros(0), 1.0
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    dof = resid.size - jac.shape[1]
    sigma2 = float(np.sum(resid**2)) / dof if dof > 0 else np.nan
    std = np.sqrt(sigma2 * np.sum((vt.T / s) ** 2, axis=1))
    s_unit = np.linalg.svd(jac / np.linalg.norm(jac, axis=0), compute_uv=False)
    return std, float(s_unit[0] / s_unit[-1]) if s_unit[-1] > 0 else np.inf


# ---------------------------------------------------------------------- the estimator
RESIDUAL_MODELS = (ErrorModel, PartitionedErrorModel, GaussianProcessErrorModel, PoseErrorModel)


class KinematicModel(ErrorModelBase):
    """Kinematic calibration as an error model, optionally with a model of what it leaves.

    Parameters
    ----------
    robot : Robot or str
        The nominal robot (or a built-in name / robot YAML path).
    base : bool
        Identify the pose of the robot base in the measurement frame.
    tool : bool
        Identify the tool offset.
    rcond : float in (0, 1)
        Relative singular-value threshold below which a parameter direction
        counts as unidentifiable (see :func:`identify`).
    compliance : sequence of int
        1-based joints that yield under gravity (see :mod:`partcal.models.joint_errors`).
    joint_harmonics : int or sequence of int
        Harmonics of the cyclic transmission error of every joint (an int),
        or of each joint (one int per joint); 0: none.
    payload_kg : float >= 0
        The payload at the tool point, kg, of data given without one per
        pose (``fit``, ``predict``: ``payload_kg=`` per pose overrides it).
    residual : ErrorModel, PartitionedErrorModel or GaussianProcessErrorModel, optional
        Fitted to the errors the identified kinematics leave; its prediction
        is added (a hybrid model). A Cartesian residual reads the nominal
        positions ``FK(nominal, q)``.
    random_state : None, int, RandomState or Generator
        Seed of the residual model (a child stream).

    Attributes
    ----------
    robot_, identified_robot_ : Robot
    identification_ : Identification
        The identified table with standard errors and the condition number.
    residual_ : estimator or None
        Fitted on what the kinematics leave of the position errors.
        On pose errors a :class:`~partcal.models.pose.PoseErrorModel`: two residuals of the
        given settings, one on what is left of the position and one of the orientation (a
        Gaussian process then learns its own hyperparameters for each).
    joint_errors_ : JointErrors
        The joint errors identified (their values are the identified table's last entries).
    active_ : ndarray of bool, shape (N,)
        Joints that moved in the training data.

    Examples
    --------
    >>> robot = load_robot("motoman_sk120")
    >>> q = np.random.default_rng(0).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (60, 6))
    >>> longer = robot.replace(a_mm=robot.a_mm + [0, 0, 0.5, 0, 0, 0, 0, 0])
    >>> model = KinematicModel(robot=robot).fit(q, longer.positions(q) - robot.positions(q))
    >>> round(float(model.identification_.correction[10]), 9)        # a[3]: the upper arm, 0.5 mm longer
    0.5
    """

    inputs = "joint"

    def __init__(self, *, robot=None, base=True, tool=True, rcond=1e-6, compliance=(), joint_harmonics=0,
                 payload_kg=0.0, all_targets=False, use_orientation=False,
                 orientation_mm_per_rad=ORIENTATION_MM_PER_RAD, residual=None, random_state=None):
        self.robot = robot
        self.all_targets = all_targets
        self.use_orientation = use_orientation
        self.orientation_mm_per_rad = orientation_mm_per_rad
        self.base = base
        self.tool = tool
        self.rcond = rcond
        self.compliance = compliance
        self.joint_harmonics = joint_harmonics
        self.payload_kg = payload_kg
        self.residual = residual
        self.random_state = random_state

    kind = "kinematic"
    file_kind = "kinematic"
    takes_residual = True
    fits_pose_errors = True
    _parameter_rules = {"base": boolean(True), "tool": boolean(True),
                        "rcond": real(0.0, 1.0, default=1e-6, low_open=True),
                        "payload_kg": real(0.0, MAX_PAYLOAD_KG, default=0.0),
                        "all_targets": boolean(False), "use_orientation": boolean(False),
                        "orientation_mm_per_rad": real(0.0, 1e6, default=ORIENTATION_MM_PER_RAD, low_open=True)}
    _requirements = (Requirement("orientation_mm_per_rad", f"{ORIENTATION_MM_PER_RAD:g} (its default) unless "
                                 "use_orientation is true: it weighs the orientation in the identification",
                                 lambda p: p["use_orientation"] or p["orientation_mm_per_rad"] == ORIENTATION_MM_PER_RAD),)
    _from_fitted = ("all_targets", "use_orientation")     # a model file keeps what was fitted on instead
    _OPTIONAL_IN_FILES = ("payload_kg", "orientation_mm_per_rad")   # files written before them: the default
    _joint_rules = {"compliance": ((), compliance_problem), "joint_harmonics": (0, harmonics_problem)}

    def _check_params(self) -> Robot:
        own = type(self).__name__
        if not isinstance(self.robot, (Robot, str, PurePath)):
            raise param_error(own, "robot", "a Robot, a built-in robot name or a robot YAML path", self.robot)
        robot = load_robot(self.robot)
        self._check_rules()
        for name, (_, problem) in self._joint_rules.items():
            expected = problem(getattr(self, name), robot.n_joints)
            if expected is not None:
                raise param_error(own, name, expected, getattr(self, name))
        if self.residual is not None and not isinstance(self.residual, RESIDUAL_MODELS):
            raise param_error(own, "residual", "None, an ErrorModel, a PartitionedErrorModel or a "
                              "GaussianProcessErrorModel", self.residual)
        return robot

    def fit(self, X, y, payload_kg=None, *, targets=None, orientation_deg=None, orientation_mm_per_rad=None):
        """Identify the parameters from joint angles ``X`` (n, N) deg and errors ``y`` (n, 3) mm. Returns self.

        ``payload_kg`` (n,) kg per pose, or a number; default the parameter ``payload_kg``.

        ``y`` are the primary target's errors, or the pose errors (n, 6): those, then the
        orientation errors as rotation vectors in mrad (``Measurements.pose_errors``). A model
        fitted on pose errors predicts them: the orientation error of the identified robot (its
        probe's turn too) against the nominal one; with ``use_orientation`` and no
        ``orientation_deg``, the identification reads the orientation from ``y``; without
        ``use_orientation`` it identifies from the positions alone and predicts the orientation
        all the same (a residual model then fits all six). Further targets on the tool and the measured
        orientation, when given, are identified from too (:mod:`partcal.models.targets`):
        ``targets`` maps a target's name to ``(offset, errors)``, its nominal offset in the
        flange frame (3,) mm and its errors (n, 3) mm; ``orientation_deg`` (n, 3) are the
        orientation errors, rotation vectors from the nominal flange orientation to the
        measured one in the base frame, degrees, their residuals weighted by
        ``orientation_mm_per_rad`` (one radian counts as that many mm; default the parameter of
        that name, 200: one mrad weighs as 0.2 mm). The prediction stays the
        primary target's (:meth:`predict_target` gives another's).
        """
        robot = self._check_params()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        if X.shape[1] != robot.n_joints:
            raise DataError(f"{type(self).__name__} for {robot.name} takes {robot.n_joints} joint angles "
                            f"(degrees) per sample; got X with {X.shape[1]} columns")
        if y.ndim != 2 or y.shape[1] not in (3, 6):
            raise DataError(f"Expected y with shape (n, 3) (position errors, mm) or (n, 6) (pose errors: then the "
                            f"orientation's, a rotation vector in mrad), got array with shape {y.shape}.")
        self._y_1d, self.n_outputs_ = False, y.shape[1]
        if self.n_outputs_ == 6 and self.use_orientation and orientation_deg is None:
            orientation_deg = y[:, ORIENTATION] / MRAD_PER_DEG
        nominal = robot.positions(X)
        self.joint_errors_ = JointErrors.for_robot(robot, list(self.compliance), self.joint_harmonics)
        payload = self._payload(payload_kg, len(X))
        weight = self.orientation_mm_per_rad if orientation_mm_per_rad is None else orientation_mm_per_rad
        extra = extra_from(robot, X, targets, orientation_deg, weight)
        self.identification_ = identify(robot, X, nominal + y[:, POSITION], base=bool(self.base), tool=bool(self.tool),
                                        rcond=float(self.rcond), errors=self.joint_errors_, payload_kg=payload,
                                        extra=extra)
        self.targets_ = dict(extra.tools_mm) if extra is not None else {}
        self.orientation_ = extra is not None and extra.rotations is not None
        self.robot_ = robot
        self._build_robots()
        self.active_ = varying_inputs(X)
        self.data_bounds_ = np.stack([X.min(axis=0), X.max(axis=0)])
        self.residual_ = None
        if self.residual is not None:
            seed = self._residual_seed()
            leftover = y - self._kinematic_errors(X, payload)
            residual = clone(self.residual)
            if isinstance(residual, PoseErrorModel):      # frozen on pose errors (nested CV): its parts keep their seed
                self.residual_ = residual
            else:
                residual.set_params(random_state=seed)
                self.residual_ = PoseErrorModel(residual) if self.n_outputs_ == 6 else residual   # one per part
            self.residual_.fit(self._residual_inputs(X, nominal), leftover)
        return self._prepare()

    def _prepare(self) -> "KinematicModel":
        """Build what a prediction reads (after fitting or loading); returns self.

        A :class:`Robot` compiles its DH rows on its first forward kinematics:
        one pose through both robots does it here, not in ``predict``. The
        residual model prepares its own (see :meth:`ErrorModelBase._prepare`).
        """
        for robot in (self.robot_, self.identified_robot_, self._geometry):
            robot.positions(self.data_bounds_[:1])
        if self.residual_ is not None:
            self.residual_._prepare()
        return super()._prepare()

    def _residual_inputs(self, X: NDArray[np.float64], nominal: NDArray[np.float64]) -> NDArray[np.float64]:
        """What the residual model reads: the nominal positions ``nominal`` (mm) or the joints ``X`` (deg)."""
        return nominal if self.residual_.inputs == "cartesian" else X

    # ------------------------------------------------------------------ prediction
    def _payload(self, payload_kg, n: int) -> NDArray[np.float64]:
        """The payload per pose (n,) kg: ``payload_kg`` (a number or n values in [0, MAX_PAYLOAD_KG]), default
        the parameter."""
        value = self.payload_kg if payload_kg is None else payload_kg
        arr = check_array(np.atleast_1d(np.asarray(value, dtype=float)), "payload_kg", ndim=1)
        if arr.size not in (1, n) or np.any(arr < 0) or np.any(arr > MAX_PAYLOAD_KG):
            raise DataError(f"Expected payload_kg as one number in [0, {MAX_PAYLOAD_KG:g}] or {n} of them (kg, one "
                            f"per pose), got {arr.size} values from {arr.min() if arr.size else 'none'} to "
                            f"{arr.max() if arr.size else 'none'}.")
        return np.broadcast_to(arr, (n,)).copy()

    def _build_robots(self) -> None:
        """The identified robot, and its geometry in its own base frame (where the joint errors' lever arms
        are taken), from ``robot_`` and the identified table (after fitting or loading)."""
        self.identified_robot_ = robot_with(self.robot_, self.identification_.value)
        self._geometry = own_geometry(self.robot_, self.identification_.value)

    def _actual(self, X: NDArray[np.float64], payload: NDArray[np.float64]) -> NDArray[np.float64]:
        """The joint angles the identified arm takes (its joint errors), (n, N) deg."""
        errors = self.joint_errors_
        if errors.empty:
            return X
        size = geometric_size(self.robot_)
        return errors.design(self._geometry, X, self.identification_.value[size:size + errors.size], payload)[0]

    def _kinematic(self, X: NDArray[np.float64], payload: NDArray[np.float64]) -> NDArray[np.float64]:
        """Tool positions of the identified model (geometry and joint errors), (n, 3) mm."""
        return self.identified_robot_.positions(self._actual(X, payload))

    def _kinematic_errors(self, X: NDArray[np.float64], payload: NDArray[np.float64]) -> NDArray[np.float64]:
        """The identified model's errors against the nominal one, (n, outputs): the tool position's (mm) and, for
        a model of pose errors, the turn ``log(R_identified P R_nominal^T)`` (mrad; ``P`` the identified probe
        turn, identity without one)."""
        actual = self._actual(X, payload)
        if self.n_outputs() == 3:
            return self.identified_robot_.positions(actual) - self.robot_.positions(X)
        model, nominal = self.identified_robot_.forward(actual), self.robot_.forward(X)
        if self.orientation_:
            model[:, :3, :3] = model[:, :3, :3] @ Rotation.from_rotvec(self.identification_.value[-3:],
                                                                      degrees=True).as_matrix()
        turns = Rotation.from_matrix(model[:, :3, :3] @ nominal[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
        return np.hstack([model[:, :3, 3] - nominal[:, :3, 3], turns * MRAD_PER_RAD])

    def predict_target(self, X, target: str, payload_kg=None) -> NDArray[np.float64]:
        """The kinematic error of a target the model was fitted on, shape (n, 3) mm: ``FK(identified, its
        identified offset) - FK(nominal, its nominal offset)`` (the primary's: :meth:`predict_kinematic`)."""
        check_is_fitted(self, "identification_")
        if target == PRIMARY_TARGET:
            return self.predict_kinematic(X, payload_kg)[:, POSITION]
        if target not in self.targets_:
            raise DataError(f"Expected a target the model was fitted on "
                            f"({', '.join([PRIMARY_TARGET, *self.targets_])}), got {target!r}.")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        names = self.identification_.names
        tool = self.identification_.value[[names.index(f"tool@{target}.{c}") for c in "xyz"]]
        actual = self._actual(X, self._payload(payload_kg, len(X)))
        moved = self.identified_robot_.replace(tool_mm=tool).positions(actual)
        return moved - self.robot_.replace(tool_mm=self.targets_[target]).positions(X)

    def predict(self, X, payload_kg=None) -> NDArray[np.float64]:
        """Predicted errors ``FK(identified) - FK(nominal)`` (+ the residual model), shape (n, 3) mm; for a model
        fitted on pose errors (n, 6), the orientation's in mrad after (see :meth:`fit`).

        ``payload_kg`` (n,) kg per pose, or a number; default the parameter ``payload_kg``.
        """
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._predict_trusted(X, payload_kg)

    def predict_kinematic(self, X, payload_kg=None) -> NDArray[np.float64]:
        """The kinematic part alone, ``FK(identified) - FK(nominal)``, shape (n, 3) mm (a pose model's: (n, 6))."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._kinematic_errors(X, self._payload(payload_kg, len(X)))

    def _predict_trusted(self, X: NDArray[np.float64], payload_kg=None) -> NDArray[np.float64]:
        out = self._kinematic_errors(X, self._payload(payload_kg, len(X)))
        if self.residual_ is not None:
            nominal = self.robot_.positions(X) if self.residual_.inputs == "cartesian" else None
            out += self.residual_.predict(self._residual_inputs(X, nominal))
        return out

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance (degrees) of each pose outside the box of the training joint angles, shape (n,)."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return distance_outside_boxes(X, self.data_bounds_[:1], self.data_bounds_[1:])

    # ------------------------------------------------------------------ the kind: config, files, run, report
    @classmethod
    def params_from_config(cls, sec, context: dict) -> dict:
        """``base``, ``tool``, ``rcond``, ``payload_kg``, ``compliance`` and ``joint_harmonics``; the robot is the
        run's (top-level key ``robot``)."""
        if context.get("robot") is None:
            sec.fail(sec.path("kind"), "kind: kinematic needs the run's robot (top-level key 'robot')")
        n_joints = load_robot(context["robot"]).n_joints
        joint = {name: sec.get(name, "any", default=default, check=lambda v, p=problem: p(v, n_joints))
                 for name, (default, problem) in cls._joint_rules.items()}
        return {"robot": context["robot"], **super().params_from_config(sec, context), **joint}

    @classmethod
    def config_keys(cls) -> set[str]:
        return super().config_keys() | set(cls._joint_rules)

    @classmethod
    def from_params(cls, params: dict, random_state=None) -> "KinematicModel":
        return cls(**{**params, "robot": load_robot(params["robot"])}, random_state=random_state)

    @classmethod
    def input_space(cls, params: dict) -> str:
        return "joint"

    def file_section(self) -> dict:
        from .kinds import body_of      # the table of kinds knows this module

        errors = self.joint_errors_
        return {"robot": robot_to_dict(self.robot_), "base": bool(self.base), "tool": bool(self.tool),
                "rcond": float(self.rcond), "payload_kg": float(self.payload_kg),
                **({"orientation_mm_per_rad": float(self.orientation_mm_per_rad)} if self.orientation_ else {}),
                "compliance": list(errors.compliance), "joint_harmonics": list(errors.harmonics),
                "identification": self.identification_.to_dict(),
                **({"targets": {k: [float(v) for v in t] for k, t in self.targets_.items()},
                    "orientation": bool(self.orientation_)} if self.targets_ or self.orientation_ else {}),
                "data_bounds": self.data_bounds_.tolist(), "active": self.active_.tolist(),
                "residual": body_of(self.residual_) if self.residual_ is not None else None}

    @classmethod
    def from_file_section(cls, r: FieldReader, inputs: str, n_in: int, n_out: int) -> "KinematicModel":
        """A kinematic model from its section: the identified table must agree with the file's robot
        (nominal values, unidentified parameters kept nominal, standard errors >= 0)."""
        try:
            robot = robot_from_dict(r.get("robot", dict), source=f"{r.source}: field {r.path('robot')!r}")
        except Exception as exc:  # noqa: BLE001 - any damage in the robot section is a file error
            raise ModelFileError(str(exc)) from None
        if robot.n_joints != n_in:
            r.fail("robot", f"a robot with the file's {n_in} joints (n_inputs); got {robot.n_joints}")
        if n_out not in (3, 6):
            r.fail("", f"a kinematic model has 3 outputs (n_outputs; position errors) or 6 (pose errors); the file "
                       f"says {n_out}")
        joint = {}
        for name, (default, problem) in cls._joint_rules.items():       # files before the joint errors: none
            joint[name] = r.doc.get(name, default)
            if problem(joint[name], robot.n_joints) is not None:
                r.fail(name, f"expected {problem(joint[name], robot.n_joints)}; got {joint[name]!r}"[:200])
        rules = {key: rule for key, rule in cls._parameter_rules.items()
                 if key not in cls._from_fitted and (key in r.doc or key not in cls._OPTIONAL_IN_FILES)}
        tools, orientation = _targets_from(r)
        model = cls(robot=robot, **{key: r.rule(key, rule) for key, rule in rules.items()}, **joint,
                    all_targets=bool(tools), use_orientation=orientation)
        errors = JointErrors.for_robot(robot, joint["compliance"], joint["joint_harmonics"])
        table = _identification_from(r.sub("identification"), robot, errors, tools, orientation)
        model.robot_, model.identification_, model.joint_errors_ = robot, table, errors
        model.targets_, model.orientation_ = tools, orientation
        model._build_robots()
        model.data_bounds_ = r.array("data_bounds", (2, n_in))
        if np.any(model.data_bounds_[0] > model.data_bounds_[1]):
            r.fail("data_bounds", "a low bound exceeds its high bound")
        model.active_ = r.array("active", (n_in,), bool)
        model.n_features_in_, model.n_outputs_, model._y_1d = n_in, n_out, False
        model.residual_ = None
        if r.doc.get("residual") is not None:
            from .kinds import model_from_body      # the table of kinds knows this module

            model.residual_ = model_from_body(r.sub("residual"))
            if model.residual_.n_outputs() != n_out or isinstance(model.residual_, PoseErrorModel) != (n_out == 6):
                r.sub("residual").fail("kind", f"a residual of {n_out} outputs" + (" of kind 'pose' (one model on the "
                                       "position, one on the orientation)" if n_out == 6 else "") + f"; got kind "
                                       f"{r.sub('residual').doc.get('kind')!r} of {model.residual_.n_outputs()} outputs")
            model.residual = model.residual_ if n_out == 3 else model.residual_.model
        return model

    def check_file(self, r: FieldReader) -> None:
        """The identified robot moves the tool by less than the robot's reach from where the nominal robot
        puts it, at the corners and centre of the joint box of the data; a residual model is checked too."""
        poses = box_points(*self.data_bounds_)
        with np.errstate(all="ignore"):
            moved = self._kinematic(poses, self._payload(None, len(poses)))
            shift = np.linalg.norm(moved - self.robot_.positions(poses), axis=1)
        reach = self.robot_.reach_mm
        if not np.all(np.isfinite(shift)) or shift.max() > reach:
            worst = f"{shift.max():.4g} mm" if np.all(np.isfinite(shift)) else "a non-finite distance"
            r.sub("model").sub("identification").fail(
                "value", f"the identified robot moves the tool by {worst} within the joint box of its data, more "
                         f"than the robot's reach ({reach:.0f} mm): the identified values are damaged")
        if self.residual_ is not None:
            self.residual_.check_file(r.sub("model").sub("residual"))

    def n_outputs(self) -> int:
        return int(getattr(self, "n_outputs_", 3))

    def peak_fit_bytes(self, n: int, n_joints: int) -> tuple[float, str]:
        """The residual model's fit (the identification holds arrays of ``n x parameters``)."""
        return self.residual.peak_fit_bytes(n, n_joints) if self.residual is not None else (0.0, "")

    def describe(self) -> str:
        text = f"the kinematic parameters of {self.robot_.name}"
        errors = self.joint_errors_
        if errors.compliance:
            text += f", the gravity compliance of joint{'s' if len(errors.compliance) > 1 else ''} " + \
                ", ".join(str(j) for j in errors.compliance)
        if any(errors.harmonics):
            text += f", transmission errors (up to {max(errors.harmonics)} harmonics per joint)"
        return text + (f", plus a residual {self.residual_.describe()}" if self.residual_ is not None else "")

    @property
    def solver_name(self) -> str:
        return "levenberg-marquardt"

    def family(self) -> str:
        return "Kinematic models" if self.residual is None else "Hybrid models (kinematic + residual)"

    def effective_parameters(self) -> float:
        """The identified parameters, plus the residual model's."""
        own = sum(status == "identified" for status in self.identification_.status)
        return float(own + (self.residual_.effective_parameters() if self.residual_ is not None else 0.0))

    def fit_notes(self) -> list[str]:
        """A compliance the data could not identify (one payload: only its products with the masses, the
        sags, are seen), so that a payload changes nothing the model predicts; then the residual's notes."""
        held = [n for n in self.identification_.unidentifiable() if n.startswith("compliance[")]
        notes = [f"{', '.join(held)} not identifiable (data at one payload show only the sags): the predictions do "
                 "not change with the payload"] if held else []
        if self.n_outputs() == 6 and not self.orientation_:
            notes.append("identified from the positions alone, it predicts the orientation its parameters imply, "
                         "which the positions do not determine (use_orientation: true identifies from it)")
        return notes + (self.residual_.fit_notes() if self.residual_ is not None else [])

    def is_physical(self) -> bool:
        return self.residual is None

    def _residual_seed(self) -> int:
        """The residual model's seed: a child of this model's."""
        return int(np.random.SeedSequence(seed_from(self.random_state)).spawn(1)[0].generate_state(1)[0])

    def frozen(self, X, y, payload_kg=None, **measured) -> "KinematicModel":
        """With a residual model: the residual frozen on what the kinematics identified on ``X, y`` (and the
        further targets and orientation of :meth:`fit`, ``measured``) leave; on pose errors each part of the
        residual frozen on its own columns (a :class:`PoseErrorModel`)."""
        if self.residual is None:
            return self
        fitted = clone(self).set_params(residual=None).fit(X, y, payload_kg=payload_kg, **measured)
        X = np.asarray(X, dtype=float)
        nominal = fitted.robot_.positions(X)
        leftover = np.asarray(y, dtype=float) - fitted.predict(X, payload_kg=payload_kg)
        inputs = nominal if self.residual.inputs == "cartesian" else X
        residual = clone(self.residual).set_params(random_state=self._residual_seed())
        if leftover.shape[1] == 6:
            residual = PoseErrorModel(residual)
        return clone(self).set_params(residual=residual.frozen(inputs, leftover))

    def regions_model(self):
        return self.residual_.regions_model() if getattr(self, "residual_", None) is not None else None

    def identification(self) -> Identification:
        return self.identification_

    def run_summary(self) -> dict:
        table = self.identification_
        return {"kinematic": {"identified": table.status.count("identified"), "parameters": len(table.names),
                              "unidentifiable": table.unidentifiable(), "condition": table.condition,
                              "rms_3d": table.rms_mm, **_targets_summary(table)}}

    def predict_validated(self, X: NDArray[np.float64], payload_kg=None) -> NDArray[np.float64]:
        return self._predict_trusted(X, payload_kg)

    @property
    def reads_payload(self) -> bool:
        """Whether a payload changes the prediction (some joint yields under gravity)."""
        return bool(self.compliance)

    @property
    def reads_targets(self) -> bool:
        """Whether ``fit`` takes every measured target and the orientation (``all_targets``,
        ``use_orientation``): the run then gives them, pose by pose (``targets=``, ``orientation_deg=``)."""
        return bool(self.all_targets or self.use_orientation)


def _targets_summary(table: Identification) -> dict:
    """metrics.json fields of a fit on several targets or an orientation (none for one target)."""
    if not table.target_rms_mm:
        return {}
    return {"targets_rms_3d": dict(table.target_rms_mm), "orientation_rms_deg": table.orientation_rms_deg,
            "identifiable_from_primary": table.primary_identifiable}


def _targets_from(r: FieldReader) -> tuple[dict, bool]:
    """A model file's extra targets (name -> nominal offset, mm) and whether it read an orientation (files of
    one target have neither)."""
    tools = r.doc.get("targets", {})
    if not isinstance(tools, dict) or not all(
            isinstance(k, str) and isinstance(v, list) and len(v) == 3 and
            all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)
            for k, v in tools.items()):
        r.fail("targets", "a mapping of target name to its offset [x, y, z] (mm)")
    orientation = r.doc.get("orientation", False)
    if not isinstance(orientation, bool):
        r.fail("orientation", "true or false")
    return {k: np.asarray(v, dtype=float) for k, v in tools.items()}, orientation


def _identification_from(ident: FieldReader, robot: Robot, errors: JointErrors | None = None, tools=None,
                         orientation: bool = False) -> Identification:
    """A model file's identified table, which must agree with its robot: the robot's parameter names and
    nominal values, unidentified parameters kept nominal, standard errors finite and >= 0 (or null)."""
    names = [n for n, _ in parameter_names(robot, errors) + added_names(tools or {}, orientation)]
    if ident.get("names", list) != names:
        ident.fail("names", f"expected the {len(names)} parameters of {robot.name} ({names[0]} ... {names[-1]})")
    status = ident.get("status", list)
    if len(status) != len(names) or any(s not in STATUSES for s in status):
        ident.fail("status", f"expected {len(names)} of {', '.join(STATUSES)}")
    std = ident.get("std_error", list)
    if len(std) != len(names) or not all(v is None or isinstance(v, (int, float)) for v in std):
        ident.fail("std_error", f"expected {len(names)} numbers or nulls")
    nominal, value = ident.array("nominal", (len(names),)), ident.array("value", (len(names),))
    expected = np.concatenate([nominal_values(robot, errors), added_nominal(tools or {}, orientation)])
    off = np.flatnonzero(~np.isclose(nominal, expected, rtol=1e-12, atol=1e-9))
    if off.size:
        k = off[0]
        ident.fail("nominal", f"entry {k} ({names[k]}) is {float(nominal[k])!r}, but the file's robot gives "
                              f"{float(expected[k])!r}: "
                              "the nominal values must be those of field 'model.robot'")
    kept = np.flatnonzero((np.array(status) != "identified") & (value != nominal))
    if kept.size:
        k = kept[0]
        ident.fail("value", f"entry {k} ({names[k]}) is {status[k]!r}, so it keeps its nominal value "
                            f"{float(nominal[k])!r}; got {float(value[k])!r}")
    if any(v is not None and not (math.isfinite(v) and v >= 0) for v in std):
        ident.fail("std_error", "standard errors must be finite and >= 0 (or null)")
    return Identification.from_dict(ident.doc)
