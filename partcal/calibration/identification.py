"""Kinematic identification from measured positions (tracker points): :func:`identify`.

``identify`` finds the parameters (:mod:`partcal.calibration.parameters`) that put the forward kinematics
through the measured positions. It is the one identification of :mod:`partcal.calibration.stacked` on rows
of tracker points (:func:`point_rows`): the primary target's, each further target's and the measured
orientation, weighed by their stated standard deviations, with a robust loss and a prior as asked. Its table
says what the tracker path always said: the primary target's 3-D RMS, each target's and the orientation's.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array, check_std
from ..errors import DataError
from ..metrics import pooled_rms
from ..robot.kinematics import ORIENTATION_MM_PER_RAD, Robot
from ..robot.rotations import matrices_from_rotation_vectors, xyz_deg_from_matrices
from .fit import held_still
from .identifiability import identifiable_parameters
from .joint_errors import JointErrors
from .measurement import MeasurementRows
from .parameters import PARAMETRIZATIONS, PRIMARY_TARGET, Identification
from .prior import Prior
from .stacked import StackedProblem, identify_measurements
from .tracker_points import ORIENTATION_WEIGHT, STD_COLUMNS, TARGETS, TrackerPoints

log = logging.getLogger(__name__)


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


def point_rows(q_deg: NDArray[np.float64], measured_mm: NDArray[np.float64], extra: Extra | None = None,
               std_mm: NDArray[np.float64] | None = None, payload_kg: NDArray[np.float64] | None = None,
               source: str = "positions") -> tuple[MeasurementRows, dict]:
    """Tracker points of ``n`` poses as rows of the point type, and the cell they need: the primary target's rows
    (row ``i``: pose ``i``, with the orientation when ``extra`` has one), then each further target's (column
    ``target``); every row of a pose takes its standard deviations ``std_mm`` (n, 3). The cell gives the further
    targets' nominal offsets (where their fit starts) and the orientation's weight."""
    n = len(q_deg)
    extra = extra or Extra({}, {})
    names = ["", *extra.tools_mm]
    x = np.vstack([measured_mm, *extra.measured_mm.values()])
    numbers = {"x_meas": x[:, 0], "y_meas": x[:, 1], "z_meas": x[:, 2]}
    if extra.rotations is not None:
        angles = np.vstack([xyz_deg_from_matrices(extra.rotations), np.full((n * (len(names) - 1), 3), np.nan)])
        numbers.update({c: angles[:, k] for k, c in enumerate(("rx_meas", "ry_meas", "rz_meas"))})
    if std_mm is not None:
        numbers.update({c: np.tile(std_mm[:, k], len(names)) for k, c in enumerate(STD_COLUMNS)})
    texts = {"target": tuple(t for t in names for _ in range(n))} if len(names) > 1 else {}
    ids = tuple(f"{i + 1}" + (f"@{t}" if t else "") for t in names for i in range(n))
    rows = MeasurementRows(np.tile(q_deg, (len(names), 1)), ("point",) * (n * len(names)), ids, tuple(range(1, n + 1)) *
                len(names), source, numbers, texts, None if payload_kg is None else np.tile(payload_kg, len(names)))
    cell = {TARGETS: {k: np.asarray(v, dtype=float) for k, v in extra.tools_mm.items()},
            ORIENTATION_WEIGHT: float(extra.mm_per_rad)}
    return rows, cell


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
        Further targets and the measured orientation: their residuals are stacked with the primary's, one
        offset per target (``tool@B.x`` ...) and the probe's turn (``probe.rx`` ...) are identified too
        (their parameters come last).
    parametrization : {"dh", "complete"}
        The geometric parameters: four DH parameters per row, or each row's
        theta offset and the six errors of its fixed transform.
    std_mm : ndarray, shape (n, 3), optional
        The standard deviation of each measured coordinate, mm: weighted least squares, each residual
        divided by its standard deviation and multiplied by their root mean square (the reference), so
        that the weighted residuals stay mm-like (further targets' rows take their pose's; the orientation's
        are not weighted). None: every row alike.
    loss : {"linear", "huber", "soft_l1", "cauchy"}
        scipy's ``least_squares`` loss, applied to each weighted residual coordinate.
    loss_scale : float
        The loss's ``f_scale`` in standard deviations of one coordinate: the reference of ``std_mm``, or
        without it the robust spread (1.4826 times the median absolute residual) of the least-squares fit.
    prior : Prior, optional
        A Gaussian prior on some parameters (:mod:`partcal.calibration.prior`, indices into the table's order):
        MAP (:func:`~partcal.calibration.stacked.identify_measurements`).

    Returns
    -------
    Identification
        ``rms_mm`` is the primary target's 3-D RMS; with further targets or an orientation,
        ``target_rms_mm`` holds each target's and ``orientation_rms_deg`` the orientation's.
    """
    q_deg = held_still(robot.check_joints(q_deg))
    measured_mm = check_array(measured_mm, "measured_mm", columns=3)
    n = len(q_deg)
    if len(measured_mm) != n:
        raise DataError(f"measured_mm has {len(measured_mm)} rows but q_deg has {n}")
    if parametrization not in PARAMETRIZATIONS:
        raise DataError(f"parametrization must be one of {', '.join(PARAMETRIZATIONS)}; got {parametrization!r}")
    std = None if std_mm is None else check_std(std_mm, n)
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (n,))
    rows, cell = point_rows(q_deg, measured_mm, extra, std, payload)
    table, _ = identify_measurements(robot, rows, cell, base=base, tool=tool, rcond=rcond, errors=errors,
                                 payload_kg=payload[np.arange(len(rows)) % n], parametrization=parametrization,
                                 prior=prior, loss=loss, loss_scale=loss_scale)
    return _tracker_figures(table, robot, rows, cell, errors, payload, parametrization, n, extra, base, tool, rcond)


def _tracker_figures(table: Identification, robot: Robot, rows: MeasurementRows, cell: dict, errors, payload, parametrization,
                     n: int, extra: Extra | None, base: bool, tool: bool, rcond: float) -> Identification:
    """``table`` with the figures of tracker points of ``n`` poses: the primary target's 3-D RMS (``rms_mm``), each
    target's and the orientation's (with further targets or an orientation), and the rows a robust loss
    down-weighed named by their pose."""
    tiled = payload[np.arange(len(rows)) % n]
    problem = StackedProblem(robot, errors, rows, [TrackerPoints.build(rows, cell)], tiled, parametrization)
    values = problem.raw(table.value)[0]
    positions = values[:3 * len(rows)].reshape(-1, n, 3)
    rms = [pooled_rms(block) for block in positions]
    robust = table.robust
    if robust is not None:
        worst: dict[int, dict] = {}
        for d in robust["downweighted"]:
            pose = d["row"] % n
            if pose not in worst or d["weight"] < worst[pose]["weight"]:
                worst[pose] = {"row": pose, "residual_mm": d["residual_mm"], "weight": d["weight"]}
        robust = {**robust, "downweighted": [worst[k] for k in sorted(worst)]}
    table = dataclasses.replace(table, rms_mm=rms[0], n_poses=n, robust=robust, target_rms_mm={}, misfit=None)
    if extra is None:
        return table
    angle = None
    if extra.rotations is not None:
        turns = values[3 * len(rows):].reshape(n, 3) / extra.mm_per_rad
        angle = float(np.degrees(pooled_rms(turns)))
    primary, primary_cell = point_rows(rows.q_deg[:n], rows_measured(rows, n))
    start = StackedProblem(robot, errors, primary, [TrackerPoints.build(primary, primary_cell)], payload, parametrization)
    own = start.own
    jac0 = start(start.start)[1][:, :own]
    wanted = np.ones(own, dtype=bool)
    size = own - (errors.size if errors is not None else 0)
    wanted[size - 9:size - 6], wanted[size - 6:size] = tool, base
    identifiable = identifiable_parameters(jac0, wanted, rcond, list(table.units[:own]))[1]
    return dataclasses.replace(table, target_rms_mm=dict(zip([PRIMARY_TARGET, *extra.tools_mm], rms)),
                               orientation_rms_deg=angle, primary_identifiable=identifiable)


def rows_measured(rows: MeasurementRows, n: int) -> NDArray[np.float64]:
    """The primary target's measured positions (n, 3) mm of point rows made by :func:`point_rows`."""
    return np.column_stack([rows.numbers[c][:n] for c in ("x_meas", "y_meas", "z_meas")])
