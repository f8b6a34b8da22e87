"""Kinematic identification from measured positions (tracker points): :func:`identify`.

``identify`` finds the parameters (:mod:`partcal.calibration.parameters`) that put the forward kinematics
through the measured positions, by the rank-checked Levenberg-Marquardt fit of
:mod:`partcal.calibration.fit` with the analytic Jacobian of the chain (:mod:`partcal.calibration.chain`);
further targets and the measured orientation are stacked with the primary target's positions.
"""

from __future__ import annotations

import dataclasses
import functools
import logging

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array, check_std
from ..errors import DataError
from ..metrics import pooled_rms
from ..robot.kinematics import Robot
from ..robot.rotations import log_derivative, matrix_from_rotation_vector, rotation_vectors_from_matrices
from .chain import actual_joints, identification_jacobian, model_jacobian, model_positions, turn_columns
from .fit import fit_parameters, held_still
from .identifiability import identifiable_parameters
from .joint_errors import JointErrors
from .parameters import PARAMETRIZATIONS, PRIMARY_TARGET, Identification, geometric_size, nominal_values, parameter_names, robot_with
from .prior import Prior
from .targets import Extra

log = logging.getLogger(__name__)

_DEG = np.pi / 180.0


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
        Further targets and the measured orientation (:mod:`partcal.calibration.targets`):
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
        A Gaussian prior on some parameters (:mod:`partcal.calibration.prior`, indices into the table's order):
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
        The geometry's parameters (:mod:`partcal.calibration.identification`).

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
