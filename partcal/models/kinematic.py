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

``KinematicModel`` wraps this as an error model: its predicted error is
``FK(identified, q) - FK(nominal, q)``. With ``residual=`` another error
model is fitted to what the identified kinematics leave, and the two
predictions add up (a hybrid model).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import PurePath

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy.optimize import least_squares
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import check_array, check_real, param_error
from ..errors import DataError
from ..metrics import distance_outside_boxes
from ..robot.description import load_robot
from ..robot.kinematics import Robot
from .base import ErrorModelBase, seed_from
from .bases import varying_inputs
from .gp import GaussianProcessErrorModel
from .partitioned import PartitionedErrorModel
from .series import ErrorModel

log = logging.getLogger(__name__)
ROW_PARAMETERS = (("theta", "deg"), ("d", "mm"), ("a", "mm"), ("alpha", "deg"))
TOOL_PARAMETERS = (("tool.x", "mm"), ("tool.y", "mm"), ("tool.z", "mm"))
BASE_PARAMETERS = (("base.x", "mm"), ("base.y", "mm"), ("base.z", "mm"),
                   ("base.rx", "deg"), ("base.ry", "deg"), ("base.rz", "deg"))
STATUSES = ("identified", "unidentifiable", "fixed")


# ---------------------------------------------------------------------- the parameter vector
def parameter_names(robot: Robot) -> list[tuple[str, str]]:
    """``(name, unit)`` of every geometric parameter: ``theta[1], d[1], a[1], alpha[1], ..., tool.*, base.*``.

    >>> [n for n, _ in parameter_names(load_robot("motoman_sk120"))][:5]
    ['theta[1]', 'd[1]', 'a[1]', 'alpha[1]', 'theta[2]']
    """
    rows = [(f"{p}[{r + 1}]", unit) for r in range(robot.alpha_deg.size) for p, unit in ROW_PARAMETERS]
    return rows + list(TOOL_PARAMETERS) + list(BASE_PARAMETERS)


def nominal_values(robot: Robot) -> NDArray[np.float64]:
    """The robot's own parameter values, shape ``(4 R + 9,)``: rows, tool, then a zero base correction."""
    rows = np.column_stack([robot.theta_offset_deg, robot.d_mm, robot.a_mm, robot.alpha_deg]).ravel()
    return np.concatenate([rows, robot.tool_mm, np.zeros(6)])


def _rotation_deg(angles_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """``Rz(rz) Ry(ry) Rx(rx)`` for ``(rx, ry, rz)`` in degrees (the virtual robot's base convention)."""
    cx, cy, cz = np.cos(np.radians(angles_deg))
    sx, sy, sz = np.sin(np.radians(angles_deg))
    rot_x = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    rot_y = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rot_z = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rot_z @ rot_y @ rot_x


def robot_with(nominal: Robot, values: NDArray[np.float64]) -> Robot:
    """The robot with parameter ``values`` (``(4 R + 9,)``, as :func:`nominal_values`).

    The base correction turns the nominal base by ``Rz Ry Rx`` about the
    measurement frame's axes and then shifts it.
    """
    rows = nominal.alpha_deg.size
    dh = values[:4 * rows].reshape(rows, 4)
    turn = _rotation_deg(values[4 * rows + 6:])
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
    _, ry, rz = values[4 * rows + 6:]
    lever = p - values[4 * rows + 3:4 * rows + 6]                # about the shifted base origin
    turn_z = _rotation_deg(np.array([0.0, 0.0, rz]))
    axes = [turn_z @ _rotation_deg(np.array([0.0, ry, 0.0])) @ [1.0, 0, 0], turn_z @ [0, 1.0, 0],
            np.array([0, 0, 1.0])]                               # d/drx, d/dry, d/drz of Rz Ry Rx
    base = np.empty((p.shape[0], 3, 6))
    base[:, :, :3] = np.eye(3)
    for k, axis in enumerate(axes):
        base[:, :, 3 + k] = np.cross(axis, lever) * (np.pi / 180.0)
    return p, np.concatenate([chain, base], axis=2).reshape(-1, 4 * rows + 9)


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
        3-D RMS of the remaining position error on the identification data.
    n_poses, evaluations : int
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
                "rms_mm": float(self.rms_mm), "n_poses": int(self.n_poses), "evaluations": int(self.evaluations)}

    @classmethod
    def from_dict(cls, d: dict) -> "Identification":
        return cls(tuple(d["names"]), tuple(d["units"]), np.asarray(d["nominal"], dtype=float),
                   np.asarray(d["value"], dtype=float),
                   np.array([np.nan if v is None else v for v in d["std_error"]], dtype=float),
                   tuple(d["status"]), int(d["rank"]), float(d["condition"]), float(d["rms_mm"]),
                   int(d["n_poses"]), int(d["evaluations"]))


def identify(robot: Robot, q_deg: NDArray[np.float64], measured_mm: NDArray[np.float64], *, base: bool = True,
             tool: bool = True, rcond: float = 1e-6) -> Identification:
    """Identify the geometric parameters that bring FK through measured positions.

    Parameters
    ----------
    robot : Robot
        The nominal robot (the starting point, and the values kept for what
        cannot be identified).
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    measured_mm : ndarray, shape (n, 3)
        Measured tool positions in the base (measurement) frame, mm.
    base, tool : bool
        Whether the base pose and the tool offset are identified too.
    rcond : float
        Singular values of the unit-column Jacobian below ``rcond`` times the
        largest count as zero: those directions are unidentifiable.

    Returns
    -------
    Identification
    """
    q_deg = robot.check_joints(q_deg)
    measured_mm = check_array(measured_mm, "measured_mm", columns=3)
    if len(measured_mm) != len(q_deg):
        raise DataError(f"measured_mm has {len(measured_mm)} rows but q_deg has {len(q_deg)}")
    v0 = nominal_values(robot)
    rows = robot.alpha_deg.size
    wanted = np.ones(v0.size, dtype=bool)
    wanted[4 * rows:4 * rows + 3] = tool
    wanted[4 * rows + 3:] = base
    free, rank = _identifiable(robot, q_deg, wanted, rcond)

    def values_of(x):
        v = v0.copy()
        v[free] = x
        return v

    def residuals(x):
        return (robot_with(robot, values_of(x)).positions(q_deg) - measured_mm).ravel()

    def jacobian(x):
        return identification_jacobian(robot, q_deg, values_of(x))[1][:, free]

    v, evaluations = v0.copy(), 0
    if free.size:
        sol = least_squares(residuals, v0[free], jac=jacobian, method="lm", x_scale="jac",
                            ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=200 * (free.size + 1))
        v, evaluations = values_of(sol.x), int(sol.nfev)
    p, jac = identification_jacobian(robot, q_deg, v)
    resid = p - measured_mm
    std, condition = _uncertainty(jac[:, free], resid)
    std_full = np.full(v.size, np.nan)
    std_full[free] = std
    status = np.where(wanted, "unidentifiable", "fixed").astype(object)
    status[free] = "identified"
    names = parameter_names(robot)
    result = Identification(tuple(n for n, _ in names), tuple(u for _, u in names), v0, v, std_full,
                            tuple(str(s) for s in status), rank, condition,
                            float(np.sqrt(np.mean(np.sum(resid**2, axis=1)))), q_deg.shape[0], evaluations)
    log.info("identified %d of %d parameters (condition %.3g): RMS %.4f mm", free.size, v.size, condition,
             result.rms_mm)
    return result


def _identifiable(robot: Robot, q_deg, wanted: NDArray[np.bool_], rcond: float) -> tuple[NDArray[np.intp], int]:
    """Indices of the parameters to identify, and the rank, from the unit-column Jacobian at nominal.

    The rank counts singular values above ``rcond`` times the largest; a QR
    factorisation with column pivoting picks that many columns (the most
    independent first). Columns that do not move the tool at all never count.
    """
    _, jac0 = identification_jacobian(robot, q_deg, nominal_values(robot))
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
RESIDUAL_MODELS = (ErrorModel, PartitionedErrorModel, GaussianProcessErrorModel)


def inputs_of(model) -> str:
    """What a model reads: ``cartesian`` (positions, mm) or ``joint`` (angles, degrees)."""
    if isinstance(model, PartitionedErrorModel):
        return (model.local if model.local is not None else ErrorModel()).inputs
    return model.inputs


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

    def __init__(self, *, robot=None, base=True, tool=True, rcond=1e-6, residual=None, random_state=None):
        self.robot = robot
        self.base = base
        self.tool = tool
        self.rcond = rcond
        self.residual = residual
        self.random_state = random_state

    def _check_params(self) -> Robot:
        own = type(self).__name__
        if not isinstance(self.robot, (Robot, str, PurePath)):
            raise param_error(own, "robot", "a Robot, a built-in robot name or a robot YAML path", self.robot)
        robot = load_robot(self.robot)
        for name in ("base", "tool"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise param_error(own, name, "a bool", getattr(self, name))
        check_real(own, "rcond", self.rcond, 0.0, 1.0, low_open=True)
        if self.residual is not None and not isinstance(self.residual, RESIDUAL_MODELS):
            raise param_error(own, "residual", "None, an ErrorModel, a PartitionedErrorModel or a "
                              "GaussianProcessErrorModel", self.residual)
        return robot

    def fit(self, X, y):
        """Identify the parameters from joint angles ``X`` (n, N) deg and errors ``y`` (n, 3) mm. Returns self."""
        robot = self._check_params()
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        if X.shape[1] != robot.n_joints:
            raise DataError(f"{type(self).__name__} for {robot.name} takes {robot.n_joints} joint angles "
                            f"(degrees) per sample; got X with {X.shape[1]} columns")
        if y.ndim != 2 or y.shape[1] != 3:
            raise DataError(f"Expected y (position errors) with shape (n, 3), got array with shape {y.shape}.")
        self._y_1d = False
        nominal = robot.positions(X)
        self.identification_ = identify(robot, X, nominal + y, base=bool(self.base), tool=bool(self.tool),
                                        rcond=float(self.rcond))
        self.robot_ = robot
        self.identified_robot_ = robot_with(robot, self.identification_.value)
        self.active_ = varying_inputs(X)
        self.data_bounds_ = np.stack([X.min(axis=0), X.max(axis=0)])
        self.residual_ = None
        if self.residual is not None:
            seed = int(np.random.SeedSequence(seed_from(self.random_state)).spawn(1)[0].generate_state(1)[0])
            leftover = y - (self.identified_robot_.positions(X) - nominal)
            self.residual_ = clone(self.residual).set_params(random_state=seed)
            self.residual_.fit(self._residual_inputs(X, nominal), leftover)
        return self._prepare()

    def _prepare(self) -> "KinematicModel":
        """Build what a prediction reads (after fitting or loading); returns self.

        A :class:`Robot` compiles its DH rows on its first forward kinematics:
        one pose through both robots does it here, not in ``predict``. The
        residual model prepares its own (see :meth:`ErrorModelBase._prepare`).
        """
        for robot in (self.robot_, self.identified_robot_):
            robot.positions(self.data_bounds_[:1])
        if self.residual_ is not None:
            self.residual_._prepare()
        return super()._prepare()

    def _residual_inputs(self, X: NDArray[np.float64], nominal: NDArray[np.float64]) -> NDArray[np.float64]:
        """What the residual model reads: the nominal positions ``nominal`` (mm) or the joints ``X`` (deg)."""
        return nominal if inputs_of(self.residual_) == "cartesian" else X

    # ------------------------------------------------------------------ prediction
    def predict(self, X) -> NDArray[np.float64]:
        """Predicted errors ``FK(identified) - FK(nominal)`` (+ the residual model), shape (n, 3) mm."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._predict_trusted(X)

    def predict_kinematic(self, X) -> NDArray[np.float64]:
        """The kinematic part alone, ``FK(identified) - FK(nominal)``, shape (n, 3) mm."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self.identified_robot_.positions(X) - self.robot_.positions(X)

    def _predict_trusted(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        nominal = self.robot_.positions(X)
        out = self.identified_robot_.positions(X) - nominal
        if self.residual_ is not None:
            out += self.residual_.predict(self._residual_inputs(X, nominal))
        return out

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance (degrees) of each pose outside the box of the training joint angles, shape (n,)."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return distance_outside_boxes(X, self.data_bounds_[:1], self.data_bounds_[1:])

