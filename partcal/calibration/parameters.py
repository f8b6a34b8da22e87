"""The parameter table of kinematic identification: parametrizations, names, nominal values, the robot
they describe, and an identified table (:class:`Identification`).

Every DH row has four parameters (its theta offset, d, a and alpha); the tool offset adds three and the
pose of the robot base in the measurement frame six (a shift and three small rotations). Two
parametrizations of the geometry: ``dh``, the four DH parameters of every row, and ``complete``, every
row's theta offset and the six errors of its fixed transform (a shift along and a turn about each axis of
the frame the row ends in), which holds what DH rows cannot, such as a tilt between parallel axes. Joint
errors (:mod:`partcal.calibration.joint_errors`) follow the geometric parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..robot.kinematics import Robot
from ..robot.rotations import matrix_from_rpy_deg, rpy_deg_from_matrix
from .joint_errors import JointErrors

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



PLAUSIBLE_ERROR = {"mm": 1.0, "deg": 0.1}
"""A plausible error of a geometric parameter of each unit, about a manufacturing tolerance (mm, degrees)."""


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


def own_geometry(nominal: Robot, values: NDArray[np.float64], parametrization: str = "dh") -> Robot:
    """The robot with ``values`` in its own base frame (the base correction left out): where gravity acts
    along ``-z``, and the joint errors' lever arms are taken."""
    own = values[:geometric_size(nominal, parametrization)].copy()
    own[-6:] = 0.0
    return robot_with(nominal, own, parametrization)



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
    misfit : dict, optional
        Fitted on measurement types: ``noise_ratio`` (each type's RMS residual over its noise) and ``calibrated``
        (False when a type with a stated noise leaves :data:`~partcal.calibration.checks.NOT_CALIBRATED` times it
        or more). None otherwise.
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
    misfit: dict | None = None

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
                **({"robust": self.robust} if self.robust is not None else {}),
                **({"misfit": self.misfit} if self.misfit is not None else {})}

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
                       d["prior_absorbed"], sum(s == "identified" for s in d["status"])), d.get("robust"), d.get("misfit"))

    def prior_indices(self) -> NDArray[np.intp]:
        """Indices of the parameters with a prior standard deviation (:attr:`prior_std`), in table order."""
        return np.zeros(0, dtype=np.intp) if self.prior_std is None else np.flatnonzero(np.isfinite(self.prior_std))


def _matrix(rows: list, n_rows: int) -> NDArray[np.float64]:
    """A JSON matrix (a list of rows) as an array of ``n_rows`` rows (an empty one keeps its shape)."""
    arr = np.asarray(rows, dtype=float)
    return arr.reshape(n_rows, -1) if arr.size else np.zeros((n_rows, 0))


def nominal_identification(robot: Robot, errors: JointErrors | None = None, parametrization: str = "dh"
                           ) -> Identification:
    """The nominal robot as an identified table that identified nothing: what "no calibration" predicts (its
    held-out residuals are the reference a calibration must beat)."""
    names = parameter_names(robot, errors, parametrization)
    value = nominal_values(robot, errors, parametrization)
    return Identification(tuple(n for n, _ in names), tuple(u for _, u in names), value, value.copy(),
                          np.full(value.size, np.nan), ("fixed",) * value.size, 0, 1.0, float("nan"), 0, 0)
