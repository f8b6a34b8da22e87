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

Two parametrizations of the geometry: ``dh``, the four DH parameters of
every row (its theta offset, d, a and alpha), and ``complete``, every row's
theta offset and the six errors of its fixed transform (a shift along and a
turn about each axis of the frame the row ends in). The complete one holds
what DH rows cannot, such as a tilt between parallel axes; the rank rule
below keeps of it what the data identify.

Positions alone cannot tell every parameter apart: two parallel joint axes
share one ``d``, the first joint's offset is a turn of the base about its z
axis, and a wrist that never moves hides its own offsets. Those directions
are found before the fit from the rank of the identification Jacobian (its
columns scaled to unit length; the rank from the singular values, the choice
of which parameters to keep by column pivoting, ties going to the first in the
table, so that the choice is the same on every processor).
They stay at their nominal values and are reported as unidentifiable.

Joint errors the geometry cannot carry, gravity compliance and cyclic
transmission errors (:mod:`partcal.models.joint_errors`), are identified with
the geometry: their parameters follow the geometric ones in the same vector,
the same rank analysis and the same fit; the forward kinematics then runs on
the joint angles the arm actually takes.

:class:`~partcal.models.kinematic.KinematicModel` wraps this as an error model.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
from numpy.typing import NDArray
from scipy.optimize import least_squares

from .._validation import check_array, check_std
from ..errors import DataError
from ..metrics import ROBUST_LOSSES, held_joints, loss_weights, pooled_rms
from ..robot.kinematics import Robot
from ..robot.rotations import (log_derivative, matrix_from_rotation_vector, matrix_from_rpy_deg,
                               rotation_vectors_from_matrices, rpy_deg_from_matrix)
from .joint_errors import JointErrors
from .prior import Prior
from .targets import Extra

log = logging.getLogger(__name__)

_DEG = np.pi / 180.0
ROW_PARAMETERS = (("theta", "deg"), ("d", "mm"), ("a", "mm"), ("alpha", "deg"))
COMPLETE_ROW_PARAMETERS = (("theta", "deg"), ("x", "mm"), ("y", "mm"), ("z", "mm"), ("rx", "deg"), ("ry", "deg"),
                           ("rz", "deg"))


@dataclass(frozen=True)
class Parametrization:
    """One way of writing a chain's rows as parameters (a row of :data:`PARAMETRIZATIONS`).

    Attributes
    ----------
    name : str
        Its name in run configs and model files (``parametrization:``).
    row_parameters : tuple of (name, unit)
        Each row's parameters, in the table's order.
    origins : bool
        A row's errors follow its general fixed transform (``complete``: a joint offset, then three shifts and
        three turns) rather than its four DH parameters.
    """

    name: str
    row_parameters: tuple[tuple[str, str], ...]
    origins: bool


PARAMETRIZATIONS = {p.name: p for p in (Parametrization("dh", ROW_PARAMETERS, origins=False),
                                        Parametrization("complete", COMPLETE_ROW_PARAMETERS, origins=True))}
TOOL_PARAMETERS = (("tool.x", "mm"), ("tool.y", "mm"), ("tool.z", "mm"))
BASE_PARAMETERS = (("base.x", "mm"), ("base.y", "mm"), ("base.z", "mm"),
                   ("base.rx", "deg"), ("base.ry", "deg"), ("base.rz", "deg"))
STATUSES = ("identified", "unidentifiable", "fixed")
PRIMARY_TARGET = "A"        # the data's unsuffixed target (partcal.data.measurements.PRIMARY)


# ---------------------------------------------------------------------- the parameter vector
def resolved_parametrization(parametrization: str, robot: Robot) -> str:
    """``parametrization`` with ``auto`` resolved: ``complete`` for a chain with general origins (a URDF's),
    ``dh`` for a robot of DH rows (docs/models.md says why)."""
    if parametrization != "auto":
        return parametrization
    general = robot.origins is not None and bool(np.any(robot.origins))
    return "complete" if general else "dh"


def parameter_names(robot: Robot, errors: JointErrors | None = None, parametrization: str = "dh"
                    ) -> list[tuple[str, str]]:
    """``(name, unit)`` of every parameter: ``theta[1], d[1], a[1], alpha[1], ..., tool.*, base.*`` (``dh``) or
    ``theta[1], x[1], y[1], z[1], rx[1], ry[1], rz[1], ...`` (``complete``), then the joint errors'
    (:meth:`JointErrors.names`).

    >>> from partcal import load_robot
    >>> [n for n, _ in parameter_names(load_robot("motoman_sk120"))][:5]
    ['theta[1]', 'd[1]', 'a[1]', 'alpha[1]', 'theta[2]']
    >>> [n for n, _ in parameter_names(load_robot("motoman_sk120"), parametrization="complete")][:8]
    ['theta[1]', 'x[1]', 'y[1]', 'z[1]', 'rx[1]', 'ry[1]', 'rz[1]', 'theta[2]']
    """
    rows = [(f"{p}[{r + 1}]", unit) for r in range(robot.alpha_deg.size)
            for p, unit in PARAMETRIZATIONS[parametrization].row_parameters]
    return rows + list(TOOL_PARAMETERS) + list(BASE_PARAMETERS) + (errors.names() if errors is not None else [])


def nominal_values(robot: Robot, errors: JointErrors | None = None, parametrization: str = "dh"
                   ) -> NDArray[np.float64]:
    """The robot's own parameter values, shape ``(G [+ P],)`` (:func:`geometric_size`): rows, tool, a zero base
    correction, and zero joint errors. A complete row's six errors are nominally zero."""
    if PARAMETRIZATIONS[parametrization].origins:
        zeros = np.zeros((robot.alpha_deg.size, 6))
        rows = np.column_stack([robot.theta_offset_deg, zeros]).ravel()
    else:
        rows = np.column_stack([robot.theta_offset_deg, robot.d_mm, robot.a_mm, robot.alpha_deg]).ravel()
    return np.concatenate([rows, robot.tool_mm, np.zeros(6 + (errors.size if errors is not None else 0))])


def geometric_size(robot: Robot, parametrization: str = "dh") -> int:
    """Number of geometric parameters ``G``: ``4 R + 9`` (``dh``) or ``7 R + 9`` (``complete``); the joint
    errors' follow them. The tool's three and the base's six are the last nine."""
    return len(PARAMETRIZATIONS[parametrization].row_parameters) * robot.alpha_deg.size + 9


def robot_with(nominal: Robot, values: NDArray[np.float64], parametrization: str = "dh") -> Robot:
    """The robot with parameter ``values`` (``(G,)``, as :func:`nominal_values`; joint errors ignored).

    The base correction turns the nominal base by ``Rz Ry Rx`` about the
    measurement frame's axes and then shifts it. A complete row's errors
    follow its fixed transform: ``E' = E Tr(x, y, z) Rz(rz) Ry(ry) Rx(rx)``.
    """
    rows, size = nominal.alpha_deg.size, geometric_size(nominal, parametrization)
    turn = matrix_from_rpy_deg(values[size - 3:size])
    moved = dict(tool_mm=values[size - 9:size - 6].copy(), base_rotation=turn @ nominal.base_rotation,
                 base_mm=turn @ nominal.base_mm + values[size - 6:size - 3])
    if PARAMETRIZATIONS[parametrization].origins:
        table = values[:7 * rows].reshape(rows, 7)
        return nominal.replace(theta_offset_deg=table[:, 0].copy(), origins=_corrected_origins(nominal, table[:, 1:]),
                               **moved)
    dh = values[:4 * rows].reshape(rows, 4)
    return nominal.replace(theta_offset_deg=dh[:, 0].copy(), d_mm=dh[:, 1].copy(), a_mm=dh[:, 2].copy(),
                           alpha_deg=dh[:, 3].copy(), **moved)


def _corrected_origins(nominal: Robot, errors: NDArray[np.float64]) -> NDArray[np.float64]:
    """Every row's transform ``E`` followed by its errors ``(R, 6)`` (x, y, z mm, rx, ry, rz deg), as origins
    ``(R, 6)`` (xyz mm, rpy deg)."""
    out = np.zeros((errors.shape[0], 6)) if nominal.origins is None else nominal.origins.copy()
    for r in np.flatnonzero(np.any(errors != 0, axis=1)):
        rot = matrix_from_rpy_deg(out[r, 3:])
        out[r, :3] = out[r, :3] + rot @ errors[r, :3]
        out[r, 3:] = rpy_deg_from_matrix(rot @ matrix_from_rpy_deg(errors[r, 3:]))
    return out


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
    after its row (as :func:`partcal.models.joint_errors.dh_motions`): theta turns about the row's z axis,
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


def own_geometry(nominal: Robot, values: NDArray[np.float64], parametrization: str = "dh") -> Robot:
    """The robot with ``values`` in its own base frame (the base correction left out): where gravity acts
    along ``-z``, and the joint errors' lever arms are taken."""
    own = values[:geometric_size(nominal, parametrization)].copy()
    own[-6:] = 0.0
    return robot_with(nominal, own, parametrization)


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
    covariance : ndarray, shape (K, K), optional
        The covariance ``sigma^2 (J^T J)^-1`` of the ``K`` identified parameters (in table order; mm and
        degrees): what a prediction's standard deviation needs. None in tables written before it was kept.
    sigma_mm : float, optional
        ``sigma``: the residual standard deviation per coordinate of the fit (mm).
    prior_std : ndarray, shape (P,), optional
        The prior standard deviation of every geometric parameter the data do not identify (status
        ``unidentifiable``: rank-deficient, too weak a lever, or kept nominal as implausible), its plausible
        manufacturing error (:data:`PLAUSIBLE_ERROR`); NaN for the others. None in tables written before it.
    prior_absorbed : ndarray, shape (K, U), optional
        How the ``K`` identified parameters absorb the ``U`` prior ones on the identification data:
        ``A = (J_i^T J_i)^-1 J_i^T J_u`` (the least-squares fit's answer to an error ``u`` of those
        parameters is ``-A u``). A prediction's error from them is ``(J_u(q) - J_i(q) A) u``: nil where
        the identified parameters stand in for them (a base turn for the first joint's offset), growing
        where the data did not go (:func:`prior_variance`).
    robust : dict, optional
        With a robust loss (:data:`LOSSES`, not ``linear``): ``loss``, ``scale_mm`` (its ``f_scale``, mm of the
        weighted residuals) and ``downweighted``, the measurement rows the loss weighs below
        :data:`DOWNWEIGHTED` (``row`` from 0, ``residual_mm`` its 3-D residual, ``weight``). None otherwise.
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
    covariance: NDArray[np.float64] | None = None
    sigma_mm: float | None = None
    prior_std: NDArray[np.float64] | None = None
    prior_absorbed: NDArray[np.float64] | None = None
    robust: dict | None = None

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
                    "primary_identifiable": self.primary_identifiable} if self.target_rms_mm else {}),
                **({"covariance": self.covariance.tolist(), "sigma_mm": float(self.sigma_mm)}
                   if self.covariance is not None else {}),
                **({"prior_std": [None if np.isnan(v) else float(v) for v in self.prior_std],
                    "prior_absorbed": self.prior_absorbed.tolist()} if self.prior_std is not None else {}),
                **({"robust": self.robust} if self.robust is not None else {})}

    @classmethod
    def from_dict(cls, d: dict) -> "Identification":
        return cls(tuple(d["names"]), tuple(d["units"]), np.asarray(d["nominal"], dtype=float),
                   np.asarray(d["value"], dtype=float),
                   np.array([np.nan if v is None else v for v in d["std_error"]], dtype=float),
                   tuple(d["status"]), int(d["rank"]), float(d["condition"]), float(d["rms_mm"]),
                   int(d["n_poses"]), int(d["evaluations"]), dict(d.get("target_rms_mm", {})),
                   d.get("orientation_rms_deg"), d.get("primary_identifiable"),
                   None if d.get("covariance") is None else np.asarray(d["covariance"], dtype=float).reshape(
                       len(d["covariance"]), -1),
                   None if d.get("sigma_mm") is None else float(d["sigma_mm"]),
                   None if d.get("prior_std") is None else np.array(
                       [np.nan if v is None else v for v in d["prior_std"]], dtype=float),
                   None if d.get("prior_absorbed") is None else _matrix(
                       d["prior_absorbed"], sum(s == "identified" for s in d["status"])), d.get("robust"))

    def prior_indices(self) -> NDArray[np.intp]:
        """Indices of the parameters with a prior standard deviation (:attr:`prior_std`), in table order."""
        return np.zeros(0, dtype=np.intp) if self.prior_std is None else np.flatnonzero(np.isfinite(self.prior_std))


def _matrix(rows: list, n_rows: int) -> NDArray[np.float64]:
    """A JSON matrix (a list of rows) as an array of ``n_rows`` rows (an empty one keeps its shape)."""
    arr = np.asarray(rows, dtype=float)
    return arr.reshape(n_rows, -1) if arr.size else np.zeros((n_rows, 0))


def identify(robot: Robot, q_deg: NDArray[np.float64], measured_mm: NDArray[np.float64], *, base: bool = True,
             tool: bool = True, rcond: float = 1e-6, errors: JointErrors | None = None,
             payload_kg=0.0, extra: Extra | None = None, parametrization: str = "dh",
             std_mm: NDArray[np.float64] | None = None, loss: str = "linear", loss_scale: float = 3.0,
             prior: Prior | None = None) -> Identification:
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
    parametrization : {"dh", "complete"}
        The geometric parameters: four DH parameters per row, or each row's
        theta offset and the six errors of its fixed transform (see the module
        notes).
    std_mm : ndarray, shape (n, 3), optional
        The standard deviation of each measured coordinate, mm: weighted least squares, each residual
        divided by its standard deviation and multiplied by their root mean square (the reference), so
        that the weighted residuals stay mm-like (further targets' rows take their pose's; the orientation's
        are not weighted). None: every row alike (the same fit as before weights existed).
    loss : {"linear", "huber", "soft_l1", "cauchy"}
        scipy's ``least_squares`` loss, applied to each weighted residual coordinate (:func:`fit_parameters`).
    loss_scale : float
        The loss's ``f_scale`` in standard deviations of one coordinate: the reference of ``std_mm``, or
        without it the robust spread (1.4826 times the median absolute residual) of the least-squares fit.
    prior : Prior, optional
        A Gaussian prior on some parameters (:mod:`partcal.models.prior`, indices into the table's order):
        its rows are appended to the residuals, so the fit is MAP. A parameter it holds is identifiable
        through it (the rank rule reads its row) and is never pruned as implausible (the prior prices its
        distance from the mean); the standard errors and covariance are the posterior's. Default none:
        plain least squares.

    Returns
    -------
    Identification
    """
    q_deg = held_still(robot.check_joints(q_deg))
    measured_mm = check_array(measured_mm, "measured_mm", columns=3)
    if len(measured_mm) != len(q_deg):
        raise DataError(f"measured_mm has {len(measured_mm)} rows but q_deg has {len(q_deg)}")
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(q_deg),))
    if parametrization not in PARAMETRIZATIONS:
        raise DataError(f"parametrization must be one of {', '.join(PARAMETRIZATIONS)}; got {parametrization!r}")
    v0 = nominal_values(robot, errors, parametrization)
    size, own = geometric_size(robot, parametrization), v0.size
    wanted = np.ones(v0.size + (extra.size if extra is not None else 0), dtype=bool)
    wanted[size - 9:size - 6] = tool
    wanted[size - 6:size] = base
    if extra is None:
        def jac_at(v, jacobian=True):
            if not jacobian:
                return (model_positions(robot, errors, q_deg, v, payload, parametrization) - measured_mm).ravel(), None
            p, jac = model_jacobian(robot, errors, q_deg, v, payload, parametrization)
            return (p - measured_mm).ravel(), jac
    else:
        v0 = np.concatenate([v0, extra.nominal()])
        wanted[own:own + 3 * len(extra.tools_mm)] = tool
        jac_at = functools.partial(stacked, robot, errors, q_deg, payload_kg=payload, measured_mm=measured_mm,
                                   extra=extra, parametrization=parametrization)
    data_at = jac_at
    if prior is not None:
        jac_at = prior.augmented(jac_at)
    jac0 = jac_at(v0)[1]
    names = parameter_names(robot, errors, parametrization) + (extra.names() if extra is not None else [])
    units = [unit for _, unit in names]
    weight, reference = row_weights(std_mm, len(q_deg), extra)
    if prior is None:
        result, resid = fit_parameters(jac_at, v0, jac0, wanted, names, rcond, size, q_deg.shape[0],
                                       row_weight=weight, loss=loss, loss_scale=loss_scale, reference_mm=reference)
    else:
        if weight is not None:          # the prior's rows are weighed as they are
            weight = np.concatenate([weight, np.ones(jac0.shape[0] - weight.size)])
        result, resid = fit_parameters(jac_at, v0, jac0, wanted, names, rcond, size, q_deg.shape[0],
                                       row_weight=weight, loss=loss, loss_scale=loss_scale, reference_mm=reference,
                                       held=prior.held(v0.size))
        resid = data_at(result.value, jacobian=False)[0]
    rms, angle = _target_rms(resid, len(q_deg), extra)
    more = {} if extra is None else {
        "target_rms_mm": dict(zip([PRIMARY_TARGET, *extra.tools_mm], rms)), "orientation_rms_deg": angle,
        "primary_identifiable": identifiable_parameters(jac0[:3 * len(q_deg), :own], wanted[:own], rcond,
                                                        units[:own])[1]}
    result = dataclasses.replace(result, rms_mm=rms[0], **more)
    log.info("identified %d of %d parameters (condition %.3g): RMS %.4f mm", result.status.count("identified"),
             result.value.size, result.condition, result.rms_mm)
    return result


def row_weights(std_mm: NDArray[np.float64] | None, n: int, extra: Extra | None = None
                ) -> tuple[NDArray[np.float64] | None, float | None]:
    """The weight of every stacked residual of :func:`identify` from the standard deviations ``std_mm`` (n, 3) mm
    of the primary target's coordinates: ``reference / std`` with ``reference`` their root mean square
    (returned too), each further target's rows taking their pose's, the orientation's rows 1. ``(None, None)``
    without standard deviations.

    Examples
    --------
    >>> w, ref = row_weights(np.array([[1.0, 1.0, 2.0], [1.0, 1.0, 2.0]]), 2)
    >>> round(ref, 6), w.round(6).tolist()
    (1.414214, [1.414214, 1.414214, 0.707107, 1.414214, 1.414214, 0.707107])
    """
    if std_mm is None:
        return None, None
    std = check_std(std_mm, n)
    reference = float(np.sqrt(np.mean(std**2)))
    weight = (reference / std).ravel()
    if extra is None:
        return weight, reference
    parts = [weight] * (1 + len(extra.tools_mm)) + ([np.ones(3 * n)] if extra.rotations is not None else [])
    return np.concatenate(parts), reference


LOSSES = ROBUST_LOSSES
"""The losses of robust identification: scipy ``least_squares``' (``linear`` is least squares)."""

DOWNWEIGHTED = 0.5
"""A measurement row whose worst coordinate the robust loss weighs below this (its ``rho'``) is named as
down-weighted (:attr:`Identification.robust`)."""


def fit_parameters(jac_at, v0: NDArray[np.float64], jac0: NDArray[np.float64], wanted: NDArray[np.bool_],
                   names: list[tuple[str, str]], rcond: float, size: int, n_poses: int, *,
                   row_weight: NDArray[np.float64] | None = None, loss: str = "linear", loss_scale: float = 3.0,
                   reference_mm: float | None = None, held: NDArray[np.bool_] | None = None
                   ) -> tuple[Identification, NDArray[np.float64]]:
    """The rank-checked fit of :func:`identify` over any stacked residuals, and the residuals it leaves.

    ``jac_at(values, jacobian=True)`` gives the residuals and their Jacobian; ``v0`` is the start (the
    nominal values); ``jac0`` the Jacobian the rank rule reads (at ``v0``, on consistent data);
    ``wanted`` the parameters asked for; ``names`` every parameter's ``(name, unit)``; ``size`` the number
    of geometric parameters (the rows', tool and base: the first ``size``). The table's ``rms_mm`` is the
    3-D RMS of the residuals read as points; callers replace it with their own figure.

    ``row_weight`` (one per residual, :func:`row_weights`) weighs the residuals (weighted least squares: the
    covariance and ``sigma`` are the weighted residuals'; the residuals returned are not weighted). ``loss``
    (:data:`LOSSES`) fits by scipy's trust-region reflective method with that loss, its ``f_scale``
    ``loss_scale`` times ``reference_mm`` (the weighted residuals' stated standard deviation) or, without it,
    times the robust spread of the least-squares fit's residuals; the covariance then weighs each residual by
    the loss's weight (:func:`loss_weights`), and the rows it weighs below :data:`DOWNWEIGHTED` are named in
    the table's ``robust`` (the first ``3 n_poses`` residuals are the measurement rows' coordinates).
    ``held``: the parameters a prior holds (its rows are in ``jac_at``), never pruned as implausible.
    """
    if loss not in LOSSES:
        raise DataError(f"loss must be one of {', '.join(LOSSES)}; got {loss!r}")
    if row_weight is not None:
        jac_at, jac0 = _weighted(jac_at, row_weight), jac0 * row_weight[:, None]
    units = [unit for _, unit in names]
    free, rank = identifiable_parameters(jac0, wanted, rcond, units)

    limits = np.full(v0.size, np.nan)
    limits[:size - 9] = [PLAUSIBLE_ERROR[unit] * IMPLAUSIBLE for unit in units[:size - 9]]     # the rows' parameters
    if held is not None:
        limits[held] = np.nan                                   # the prior prices their distance instead
    v, evaluations = v0.copy(), 0
    resid0 = jac_at(v0, jacobian=False)[0]
    while free.size:
        v = v0.copy()
        v[free] += np.linalg.lstsq(jac0[:, free], -resid0, rcond=None)[0]     # Gauss-Newton from nominal: cheap
        worst = _implausible(jac_at, v, v0, free, limits)
        if worst is None:
            v, nfev = _solve(jac_at, v0, free)
            evaluations += nfev
            if loss != "linear":
                v, nfev = _robust_solve(jac_at, v0, v, free, loss, loss_scale, reference_mm)
                evaluations += nfev
            worst = _implausible(jac_at, v, v0, free, limits)
            if worst is None:
                break
        k = free[worst]
        log.info("%s comes out %+.4g %s from nominal", names[k][0], v[k] - v0[k], units[k])
        log.warning("%s comes out beyond %g %s from nominal (%g times a plausible manufacturing error), and the "
                    "data do not fix it (nominal is within %g standard errors): kept nominal and the rest refitted",
                    names[k][0], limits[k], units[k], IMPLAUSIBLE, UNFIXED)
        free = np.delete(free, worst)
    if free.size == 0:
        v = v0.copy()
    resid, jac = jac_at(v)
    robust, counted = None, None
    if loss != "linear":
        scale = loss_scale * (reference_mm if reference_mm is not None else _robust_spread(jac_at, v))
        counted = loss_weights(resid / scale, loss)
        robust = _downweighted(resid, counted, row_weight, n_poses, loss, scale)
    std, condition, covariance, sigma = _uncertainty(jac[:, free], resid, counted)
    std_full = np.full(v.size, np.nan)
    std_full[free] = std
    status = np.where(wanted, "unidentifiable", "fixed").astype(object)
    status[free] = "identified"
    prior_std, absorbed = _prior(jac, free, status, units, size)
    result = Identification(tuple(n for n, _ in names), tuple(u for _, u in names), v0, v, std_full,
                            tuple(str(s) for s in status), rank, condition, pooled_rms(resid[:resid.size // 3 * 3]
                                                                                       .reshape(-1, 3)),
                            n_poses, evaluations, covariance=covariance, sigma_mm=sigma, prior_std=prior_std,
                            prior_absorbed=absorbed, robust=robust)
    return result, (resid if row_weight is None else resid / row_weight)


def _weighted(jac_at, row_weight: NDArray[np.float64]):
    """``jac_at`` with its residuals and Jacobian rows multiplied by ``row_weight``."""
    def weighted(v, jacobian=True):
        resid, jac = jac_at(v, jacobian)
        return resid * row_weight, (None if jac is None else jac * row_weight[:, None])
    return weighted


SCALE_PASSES = 4
"""Without a stated noise, the robust fit re-estimates its scale from its own residuals at most this many times
(the least-squares fit's residuals, which the outliers spread, start it), until it changes by less than 5 %."""


def _robust_solve(jac_at, v0: NDArray[np.float64], v: NDArray[np.float64], free: NDArray[np.intp], loss: str,
                  loss_scale: float, reference_mm: float | None) -> tuple[NDArray[np.float64], int]:
    """The robust fit from the least-squares values ``v``: ``f_scale`` is ``loss_scale`` times the stated
    standard deviation ``reference_mm``, or, without one, times the robust spread of the residuals, taken
    again after each fit (:data:`SCALE_PASSES`)."""
    evaluations, scale = 0, None
    for _ in range(1 if reference_mm is not None else SCALE_PASSES):
        new = loss_scale * (reference_mm if reference_mm is not None else _robust_spread(jac_at, v))
        if scale is not None and abs(new - scale) < 0.05 * scale:
            break
        scale = new
        v, nfev = _solve(jac_at, v0, free, loss=loss, f_scale=scale, start=v)
        evaluations += nfev
    return v, evaluations


def _robust_spread(jac_at, v: NDArray[np.float64]) -> float:
    """The robust standard deviation of one residual at ``v``: 1.4826 times the median absolute residual."""
    spread = 1.4826 * float(np.median(np.abs(jac_at(v, jacobian=False)[0])))
    return spread if spread > 0 else 1e-12


def _downweighted(resid, counted, row_weight, n_poses: int, loss: str, scale: float) -> dict:
    """The ``robust`` entry of a table: the loss, its scale and the rows it weighs below :data:`DOWNWEIGHTED`
    (each row's weight its worst coordinate's; its residual the 3-D one, mm, unweighted)."""
    rows = slice(0, 3 * n_poses)
    plain = resid[rows] if row_weight is None else resid[rows] / row_weight[rows]
    weight = counted[rows].reshape(n_poses, 3).min(axis=1)
    norm = np.linalg.norm(plain.reshape(n_poses, 3), axis=1)
    low = np.flatnonzero(weight < DOWNWEIGHTED)
    return {"loss": loss, "scale_mm": float(scale),
            "downweighted": [{"row": int(i), "residual_mm": float(norm[i]), "weight": float(weight[i])} for i in low]}


def _prior(jac: NDArray[np.float64], free: NDArray[np.intp], status, units: list[str], size: int
           ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The prior standard deviations of the geometric parameters the data do not identify (their plausible
    error, :data:`PLAUSIBLE_ERROR`; NaN for the rest), shape (P,), and how the identified parameters absorb
    them on the identification data, ``A = (J_i^T J_i)^-1 J_i^T J_u``, shape (K, U), from the stacked Jacobian
    ``jac`` at the solution (see :attr:`Identification.prior_absorbed`)."""
    prior = np.full(len(units), np.nan)
    unknown = [k for k in range(size) if status[k] == "unidentifiable" and units[k] in PLAUSIBLE_ERROR]
    prior[unknown] = [PLAUSIBLE_ERROR[units[k]] for k in unknown]
    if free.size == 0 or not unknown:
        return prior, np.zeros((free.size, len(unknown)))
    return prior, np.linalg.lstsq(jac[:, free], jac[:, unknown], rcond=None)[0]


def prior_variance(jac_identified: NDArray[np.float64], jac_prior: NDArray[np.float64],
                   absorbed: NDArray[np.float64], prior_std: NDArray[np.float64]) -> NDArray[np.float64]:
    """The variance a prediction gets from the parameters the data do not identify, shape (m,).

    ``diag(J P J^T)`` with ``J = J_u - J_i A``: ``J_u`` (m, U) the prediction's Jacobian over those
    parameters, ``J_i`` (m, K) over the identified ones, ``A`` (K, U) ``absorbed`` (how the fit made up for
    them on its data) and ``P = diag(prior_std**2)``. Where the identified parameters stand in for an
    unidentified one everywhere, ``J`` is nil; where the data left it unseen, it grows.

    >>> float(prior_variance(np.zeros((1, 0)), np.array([[2.0]]), np.zeros((0, 1)), np.array([0.5]))[0])
    1.0
    """
    effective = jac_prior - jac_identified @ absorbed
    return np.sum(effective**2 * prior_std**2, axis=1)


def held_still(q_deg: NDArray[np.float64]) -> NDArray[np.float64]:
    """The joint angles with every held joint (:func:`partcal.metrics.held_joints`: readings within
    :data:`~partcal.metrics.HELD_TOLERANCE_DEG`) set to its median: a joint that never moves fixes none of its
    own parameters, and its encoder's jitter must not pretend to (on 105 SK120 poses with q4, q5 read back
    with 0.001 degrees of noise, a[4] came out 32,140 mm). Exactly held joints are returned unchanged."""
    held = held_joints(q_deg)
    if not held.any() or len(q_deg) < 2:
        return q_deg
    out = q_deg.copy()
    out[:, held] = np.median(q_deg[:, held], axis=0)
    return out


def _target_rms(resid: NDArray[np.float64], n: int, extra: Extra | None) -> tuple[list[float], float | None]:
    """3-D RMS of each target's position residuals (mm, the primary first) and the orientation's RMS angle
    (degrees, None without one), from the stacked residuals of :func:`identify`."""
    k = 1 + (len(extra.tools_mm) if extra is not None else 0)
    blocks = resid[:3 * n * k].reshape(k, n, 3)
    rms = [pooled_rms(b) for b in blocks]
    if extra is None or extra.rotations is None:
        return rms, None
    turns = resid[3 * n * k:].reshape(n, 3) / extra.mm_per_rad
    return rms, float(np.degrees(pooled_rms(turns)))


PLAUSIBLE_ERROR = {"mm": 1.0, "deg": 0.1}
"""A plausible error of a geometric parameter of each unit, about a manufacturing tolerance (mm, degrees)."""

IMPLAUSIBLE = 10.0
"""A DH parameter identified more than this many plausible errors (:data:`PLAUSIBLE_ERROR`: 10 mm, 1 degree)
from nominal, and not fixed by the data (:data:`UNFIXED`), is a trade-off of nearly equivalent parameters under
unmodelled errors: :func:`identify` keeps it nominal and refits the rest. A large value the data do fix is kept:
a DH model absorbs unmodelled errors that way (on the virtual SK120, a[5] at -21 mm, 46 standard errors out,
stands for part of the unmodelled compliance)."""

UNFIXED = 3.0
"""... and within this many standard errors of nominal (the data do not fix it: on the real UR10, the second wrist's
offset and twist wandered 4 to 60 degrees at 0.05 to 0.3 of their standard errors)."""

WEAK_LEVER = 0.01
"""A geometric parameter whose plausible error moves the tool by less than this fraction of what the median
geometric parameter's does is not identified (see :func:`identifiable_parameters`)."""


def identifiable_parameters(jac0: NDArray[np.float64], wanted: NDArray[np.bool_], rcond: float, units: list[str]
                  ) -> tuple[NDArray[np.intp], int]:
    """Indices of the parameters to identify, and the rank, from the Jacobian ``jac0`` at nominal.

    The columns are scaled to unit length; the rank counts singular values
    above ``rcond`` times the largest; column pivoting picks that many
    columns (the most independent first, :func:`_most_independent`). Columns
    that do not move the tool at all never count, and neither does a
    geometric parameter (mm, degrees) whose plausible error
    (:data:`PLAUSIBLE_ERROR`) moves the tool by less than :data:`WEAK_LEVER`
    of the median one's: a joint offset whose lever is a millimetre (a target
    on the last joint's axis) would mimic a tool offset, which unit columns
    cannot tell apart from it, and would then need a turn of degrees for a
    tenth of a millimetre, far outside the range where the fit converges.
    """
    norms = np.linalg.norm(jac0, axis=0)
    moving = wanted & (norms > 1e-12 * max(norms.max(), 1e-300))
    plausible = np.array([PLAUSIBLE_ERROR.get(unit, np.nan) for unit in units]) * norms
    geometric = moving & np.isfinite(plausible)
    if geometric.any():
        moving &= ~geometric | (plausible >= WEAK_LEVER * np.median(plausible[geometric]))
    candidates = np.flatnonzero(moving)
    if candidates.size == 0:
        return candidates, 0
    scaled = jac0[:, candidates] / norms[candidates]
    singular = np.linalg.svd(scaled, compute_uv=False)
    rank = int(np.sum(singular > rcond * singular[0]))
    return np.sort(candidates[_most_independent(scaled, rank)]), rank


PIVOT_TIE = 1e-6
"""Columns whose parts left after the columns already chosen differ in length by less than this fraction of
the longest count as equally independent, and the first of them is chosen (see :func:`_most_independent`)."""


def _most_independent(columns: NDArray[np.float64], count: int) -> NDArray[np.intp]:
    """The positions of ``count`` columns of ``columns``, the most independent first: at each step the column
    with the longest part left after projecting out those already chosen (QR's column pivoting).

    Parameters whose columns are exactly dependent (a joint offset and the base's turn about the same axis,
    as positions see them) leave parts of equal length, which rounding orders at random: pivoted QR picked
    one with one processor's BLAS kernels and the other with another's, and the model's orientation changed
    with the choice. Here parts within :data:`PIVOT_TIE` of the longest count as equal and the first such
    column of the parameter table is chosen, so the choice is the same wherever it runs.

    Examples
    --------
    >>> columns = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1e-15]])
    >>> _most_independent(columns, 2).tolist()
    [0, 1]
    """
    left = np.array(columns, dtype=float)
    chosen: list[int] = []
    for _ in range(count):
        lengths = np.linalg.norm(left, axis=0)
        lengths[chosen] = -1.0
        best = int(np.flatnonzero(lengths >= (1.0 - PIVOT_TIE) * lengths.max())[0])
        chosen.append(best)
        direction = left[:, best] / lengths[best]
        for _ in range(2):                                      # twice: Gram-Schmidt keeps its orthogonality
            left -= np.outer(direction, direction @ left)
    return np.array(chosen, dtype=np.intp)


def _implausible(jac_at, v: NDArray[np.float64], v0: NDArray[np.float64], free: NDArray[np.intp],
                 limits: NDArray[np.float64]) -> int | None:
    """The position in ``free`` of the parameter farthest beyond its plausible range (``limits``, NaN: none)
    among those the data do not fix (nominal within :data:`UNFIXED` standard errors of ``v``); None if none."""
    beyond = np.abs(v - v0)[free] / limits[free]
    if not np.nanmax(beyond, initial=0.0) > 1.0:
        return None
    resid, jac = jac_at(v)
    std = _uncertainty(jac[:, free], resid)[0]
    loose = (beyond > 1.0) & ~(np.abs(v - v0)[free] >= UNFIXED * std)     # no standard error (NaN): not fixed
    return int(np.flatnonzero(loose)[np.argmax(beyond[loose])]) if loose.any() else None


def _solve(jac_at, v0: NDArray[np.float64], free: NDArray[np.intp], *, loss: str = "linear", f_scale: float = 1.0,
           start: NDArray[np.float64] | None = None) -> tuple[NDArray[np.float64], int]:
    """The values that minimise the residuals of ``jac_at`` over the parameters ``free`` (the others kept at
    ``v0``), by Levenberg-Marquardt from ``v0`` (with a ``loss`` other than ``linear``: scipy's
    trust-region reflective method with that loss and ``f_scale``, from ``start``); and the number of
    evaluations."""
    def values_of(x):
        v = v0.copy()
        v[free] = x
        return v

    robust = {} if loss == "linear" else {"method": "trf", "loss": loss, "f_scale": f_scale}
    x0 = v0[free] if start is None else start[free]
    sol = least_squares(lambda x: jac_at(values_of(x), jacobian=False)[0], x0,
                        jac=lambda x: jac_at(values_of(x))[1][:, free], **{"method": "lm", **robust},
                        x_scale="jac", ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=200 * (free.size + 1))
    log.debug("least squares: %s (%d evaluations)", sol.message, sol.nfev)
    return values_of(sol.x), int(sol.nfev)


def _uncertainty(jac: NDArray[np.float64], resid: NDArray[np.float64], counted: NDArray[np.float64] | None = None
                 ) -> tuple[NDArray[np.float64], float, NDArray[np.float64], float]:
    """Standard errors ``sqrt(diag(sigma^2 (J^T J)^-1))``, the condition number of the unit-column ``J``, the
    covariance ``sigma^2 (J^T J)^-1`` itself and ``sigma`` (the residual standard deviation per coordinate).
    ``counted`` (a robust loss's weight of each residual, :func:`loss_weights`) multiplies the rows of ``J`` and
    the residuals by its square root first (iteratively reweighted least squares' covariance)."""
    if counted is not None and not np.all(counted == 1.0):
        root = np.sqrt(counted)
        jac, resid = jac * root[:, None], resid * root
    dof = resid.size - jac.shape[1]
    sigma2 = float(np.sum(resid**2)) / dof if dof > 0 else np.nan
    if jac.shape[1] == 0:
        return np.zeros(0), 1.0, np.zeros((0, 0)), float(np.sqrt(sigma2))
    r = scipy.linalg.qr(jac, mode="r")[0][:jac.shape[1]]         # J = Q R: R has J's singular values, and J D's R D
    _, s, vt = np.linalg.svd(r, full_matrices=False)
    scaled = vt.T / s
    covariance = sigma2 * scaled @ scaled.T
    std = np.sqrt(np.diagonal(covariance))
    s_unit = np.linalg.svd(r / np.linalg.norm(jac, axis=0), compute_uv=False)
    return std, float(s_unit[0] / s_unit[-1]) if s_unit[-1] > 0 else np.inf, covariance, float(np.sqrt(sigma2))


# ---------------------------------------------------------------------- the estimator


# ---------------------------------------------------------------------- several targets and the orientation
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
                jac[:, :size - 6] += (joints @ moves).reshape(-1, size - 6)
            block[:, size:own] = (joints @ design).reshape(-1, design.shape[2])
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
    n = q_actual.shape[0]
    robot = robot_with(nominal, values[:own], parametrization)
    model = robot.forward(q_actual)[:, :3, :3] @ matrix_from_rotation_vector(np.radians(values[-3:]))
    weight = extra.mm_per_rad
    turns = rotation_vectors_from_matrices(model @ extra.rotations.transpose(0, 2, 1))
    residuals = weight * turns.ravel()
    if not jacobian:
        return residuals, None
    omega = np.zeros((n, 3, values.size))
    omega[:, :, :own] = turn_columns(nominal, robot, q_actual, design, moves, values[:own], parametrization)
    omega[:, :, -3:] = model * _DEG                                        # columns: the model frame's axes
    return residuals, weight * np.einsum("nij,njp->nip", log_derivative(turns), omega).reshape(-1, values.size)


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
