"""Physical plausibility of measured data: refused before anything is fitted, with the likely cause.

A measurement file can be perfectly well formed and still physically wrong:
positions in metres read as millimetres, two columns swapped, joint angles
in radians, the data of another robot. Nothing downstream notices (a
registration absorbs what it can, a model fits whatever errors it is given),
so the data are checked here, where they enter:

- **nominal columns against the robot**: when a file gives ``x_nom, y_nom,
  z_nom`` and the run has a robot, its forward kinematics of ``q1..qN`` must
  give them to ``nominal_tolerance_mm`` (default 0.01 mm; the shipped data
  agree to 2e-5 mm);
- **joint angles that look like radians**: every angle of at least five
  poses within ±2π "degrees" (no robot's data move that little);
- **errors no calibrated robot has**: the errors ``measured - nominal`` (and
  a tracker registration's residuals) must stay below ``max_error_of_reach``
  (default 0.05) times the robot's reach (without a robot, the largest
  distance of a nominal position from the base origin, when at least five
  poses spread over 100 mm or more give one). Industrial robots err
  by millimetres, rarely a few centimetres; 5% of a 1.3 m reach is 65 mm;
- **the measured orientation** (``rx_meas..``): a file's nominal orientation
  (``rx_nom..``) must be the robot's forward kinematics to
  ``nominal_orientation_tolerance_deg`` (default 0.01 degrees), and the turn
  from nominal to measured (in a tracker's frame: the registration's
  orientation residual, :func:`check_orientation_residuals`) must stay below
  ``max_orientation_error_deg`` (default 5 degrees; robots err by tenths of
  a degree: the IPA UR10 leaves 0.16 at most). The likely cause is found by
  reading the angles each other way: radians, another order of Euler angles
  (intrinsic or extrinsic), two of the columns swapped.

Each refusal names the file, the worst row, the size of the mismatch and the
likely cause (units, swapped columns, radians, a different robot), found by
trying each of them on the data.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np
from numpy.typing import NDArray


from .._validation import check_params, real
from ..calibration.checks import MIN_POSES, check_joint_units
from ..errors import DataError
from ..metrics import pooled_rms
from ..robot.frames import kabsch
from ..robot.rotations import matrices_from_euler_deg, matrices_from_xyz_deg

_AXES = ("x", "y", "z")
MIN_WORKSPACE_MM = 100.0      # without a robot: nominal positions spread less than this give no reach


@dataclass(frozen=True)
class Plausibility:
    """The limits of plausible data (``data.checks`` in a run config).

    Attributes
    ----------
    max_error_of_reach : float
        The largest error (and registration residual) accepted, as a fraction
        of the robot's reach; in (0, 1].
    nominal_tolerance_mm : float
        How far the file's nominal positions may lie from the robot's forward
        kinematics, mm.
    max_orientation_error_deg : float
        The largest orientation error (and registration orientation residual)
        accepted, degrees; in (0, 180].
    nominal_orientation_tolerance_deg : float
        How far the file's nominal orientation may lie from the robot's
        forward kinematics, degrees.
    """

    max_error_of_reach: float = 0.05
    nominal_tolerance_mm: float = 0.01
    max_orientation_error_deg: float = 5.0
    nominal_orientation_tolerance_deg: float = 0.01

    rules = {"max_error_of_reach": real(0.0, 1.0, default=0.05, low_open=True),     # read by the config too
             "nominal_tolerance_mm": real(0.0, default=0.01, low_open=True),
             "max_orientation_error_deg": real(0.0, 180.0, default=5.0, low_open=True),
             "nominal_orientation_tolerance_deg": real(0.0, default=0.01, low_open=True)}

    def __post_init__(self):
        check_params("Plausibility", self.rules, (), {name: getattr(self, name) for name in self.rules})


def check_measured(source: str, rows: list[int], q_deg: NDArray[np.float64], nominal_mm, measured_mm,
                   robot=None, *, nominal_given: bool, frame: str = "base",
                   limits: Plausibility = Plausibility()) -> None:
    """Refuse measurements no robot can have produced (see the module docstring).

    Parameters
    ----------
    source : str
        The file, for messages.
    rows : list of int
        The file line of each pose (as an editor shows it), for messages.
    q_deg : ndarray, shape (n, N)
        Joint angles, degrees.
    nominal_mm, measured_mm : ndarray, shape (n, 3)
        Nominal and measured positions, mm (measured in a tracker's frame with
        ``frame="tracker"``: then only the joint angles are checked here, the
        rest by :func:`check_residuals` after the registration).
    robot : Robot, optional
    nominal_given : bool
        The nominal positions came from the file (not from ``robot``).
    """
    check_joint_units(source, rows, q_deg)
    if frame == "tracker":
        return
    if robot is not None and nominal_given:
        fk = robot.positions(q_deg)
        gap = np.linalg.norm(nominal_mm - fk, axis=1)
        worst = int(np.argmax(gap))
        if gap[worst] > limits.nominal_tolerance_mm:
            raise DataError(
                f"{source}:{rows[worst]}: x_nom, y_nom, z_nom lie {gap[worst]:.4g} mm from robot {robot.name}'s "
                f"forward kinematics of the joint angles ({np.count_nonzero(gap > limits.nominal_tolerance_mm)} of "
                f"{len(gap)} poses beyond {limits.nominal_tolerance_mm:g} mm, data.checks.nominal_tolerance_mm): "
                f"{likely_cause(fk, nominal_mm, q_deg, 'nominal', robot=robot.name)}")
    if robot is None and (len(nominal_mm) < MIN_POSES or _spread(nominal_mm) < MIN_WORKSPACE_MM):
        return                                  # without a robot, a few poses close together give no reach
    reach = robot.reach_mm if robot is not None else _reach_of(nominal_mm)
    check_errors([f"{source}:{r}" for r in rows], nominal_mm, measured_mm, reach, limits,
                 robot=robot.name if robot is not None else None)


def check_errors(where: list[str], nominal_mm, measured_mm, reach_mm: float,
                 limits: Plausibility = Plausibility(), *, robot: str | None = None) -> None:
    """Refuse errors larger than ``limits.max_error_of_reach`` of the reach; ``where[i]`` names pose ``i``."""
    errors = np.linalg.norm(np.asarray(measured_mm) - np.asarray(nominal_mm), axis=1)
    limit = limits.max_error_of_reach * reach_mm
    worst = int(np.argmax(errors))
    if errors[worst] > limit:
        reach_of = f"robot {robot}'s reach" if robot else "the largest nominal distance from the base"
        raise DataError(
            f"{where[worst]}: the error measured - nominal is {errors[worst]:.4g} mm ({np.count_nonzero(errors > limit)} of {len(errors)} "
            f"poses beyond {limit:.4g} mm, {limits.max_error_of_reach:g} of {reach_of}, {reach_mm:.0f} mm; "
            f"data.checks.max_error_of_reach): no calibrated robot errs that much: "
            f"{likely_cause(nominal_mm, measured_mm, None, 'measured', robot=robot)}")


def check_residuals(source: str, residual_mm: NDArray[np.float64], nominal_mm, measured_mm, reach_mm: float,
                    robot: str, limits: Plausibility = Plausibility()) -> None:
    """Refuse a tracker registration whose residuals no calibrated robot has.

    ``residual_mm`` (n, 3) are registered measured - nominal, mm; ``nominal_mm``
    and ``measured_mm`` (tracker frame) are tried for the likely cause.
    """
    norms = np.linalg.norm(residual_mm, axis=1)
    worst = int(np.argmax(norms))
    limit = limits.max_error_of_reach * reach_mm
    if norms[worst] <= limit:
        return
    raise DataError(
        f"{source}: pose {worst + 1}: the tracker registration leaves {norms[worst]:.4g} mm (3-D RMS "
        f"{np.sqrt(np.mean(norms**2)):.4g} mm; {np.count_nonzero(norms > limit)} of {len(norms)} poses beyond "
        f"{limit:.4g} mm, {limits.max_error_of_reach:g} of robot {robot}'s reach, {reach_mm:.0f} mm; "
        f"data.checks.max_error_of_reach): no calibrated robot errs that much: "
        f"{likely_cause(nominal_mm, measured_mm, None, 'measured', robot=robot, rigid=True)}")


def likely_cause(expected_mm, got_mm, q_deg=None, which: str = "measured", *, robot: str | None = None,
                 rigid: bool = False) -> str:
    """The likeliest reason why positions ``got_mm`` do not match ``expected_mm``, in words.

    Tries, in turn: lengths in another unit (the spreads differ by ~1000),
    joint angles in radians, two swapped columns (one of the other five
    orders matches far better; up to a rigid motion with ``rigid=True``,
    as in a tracker's frame), and names a different robot otherwise.
    """
    expected, got = np.asarray(expected_mm, float), np.asarray(got_mm, float)
    spread = _spread(expected)
    ratio = _spread(got) / spread if spread > 1.0 else 1.0          # one pose, or none apart: no evidence
    if ratio < 0.05:
        return (f"the {which} positions span {ratio:.3g} times what they should: are they in metres? (the "
                f"format's length_unit: m converts them)")
    if ratio > 20:
        return (f"the {which} positions span {ratio:.3g} times what they should: are they in mm but read as "
                f"metres? (check the format's length_unit)")
    if q_deg is not None and np.abs(q_deg).max() <= 2 * np.pi + 1e-9:
        return "the joint angles look like radians (the format's joint_unit: rad converts them)"
    base = _mismatch(expected, got, rigid)
    best = min(((_mismatch(expected, got[:, list(order)], rigid), order)
                for order in permutations(range(3)) if order != (0, 1, 2)), key=lambda t: t[0])
    if best[0] < 0.2 * base and rigid:      # in a tracker's frame any one swap undoes a mirror image
        return (f"the {which} positions are a mirror image of the robot's: two of the columns "
                f"x_meas, y_meas, z_meas swapped, or one sign flipped (swapping two leaves {best[0]:.3g} mm RMS "
                f"instead of {base:.3g})")
    if best[0] < 0.2 * base:
        swapped = [_AXES[i] for i in range(3) if best[1][i] != i]
        suffix = "nom" if which == "nominal" else "meas"
        return (f"columns {' and '.join(f'{a}_{suffix}' for a in swapped)} "
                f"look swapped (swapping them leaves {best[0]:.3g} mm RMS instead of {base:.3g})")
    if robot:
        return f"is it robot {robot!r}? (the data of another robot, or another tool, look like this)"
    return "are the nominal and measured positions of the same poses, in the same frame (data.frame: tracker)?"


def check_orientation(source: str, rows: list[int], q_deg: NDArray[np.float64], measured_deg, nominal_deg,
                      robot=None, *, nominal_given: bool, limits: Plausibility = Plausibility()) -> None:
    """Refuse a measured orientation (base frame) no robot can have, and nominal columns the robot does not give.

    Parameters
    ----------
    source : str
        The file, for messages.
    rows : list of int
        The file line of each pose, for messages.
    q_deg : ndarray, shape (n, N)
        Joint angles, degrees.
    measured_deg, nominal_deg : ndarray, shape (n, 3)
        Measured and nominal orientation, intrinsic XYZ angles, degrees.
    robot : Robot, optional
    nominal_given : bool
        The nominal orientation came from the file (not from ``robot``).
    """
    nominal = matrices_from_xyz_deg(nominal_deg)
    if robot is not None and nominal_given:
        fk = robot.forward(q_deg)[:, :3, :3]
        gap = _turn_deg(fk, nominal)
        worst = int(np.argmax(gap))
        tolerance = limits.nominal_orientation_tolerance_deg
        if gap[worst] > tolerance:
            raise DataError(
                f"{source}:{rows[worst]}: rx_nom, ry_nom, rz_nom lie {gap[worst]:.4g} degrees from robot "
                f"{robot.name}'s forward kinematics of the joint angles ({np.count_nonzero(gap > tolerance)} of "
                f"{len(gap)} poses beyond {tolerance:g} degrees, data.checks.nominal_orientation_tolerance_deg): "
                f"{orientation_cause(fk, nominal_deg, 'nom', robot=robot.name)}")
    turn = _turn_deg(nominal, matrices_from_xyz_deg(measured_deg))
    _refuse_turns([f"{source}:{r}" for r in rows], turn, "the orientation error measured - nominal", limits,
                  lambda: orientation_cause(nominal, measured_deg, "meas"))


def check_orientation_residuals(source: str, turn_deg: NDArray[np.float64], flange_rotations, measured_deg,
                                frame_rotation, limits: Plausibility = Plausibility()) -> None:
    """Refuse a tracker registration whose orientation residuals no robot has.

    ``turn_deg`` (n,) are the residual angles, degrees; ``flange_rotations``
    (n, 3, 3) the nominal flange's, ``measured_deg`` (n, 3) the probe's
    angles in the tracker frame and ``frame_rotation`` (3, 3) the fitted
    rotation tracker -> base, tried for the likely cause (the probe's turn
    on the flange refitted for each reading of the angles).
    """
    _refuse_turns([f"{source}: pose {i + 1}" for i in range(len(turn_deg))], np.asarray(turn_deg, float),
                  "the tracker registration's orientation residual", limits,
                  lambda: orientation_cause(flange_rotations, measured_deg, "meas", frame_rotation=frame_rotation))


def _refuse_turns(where: list[str], turn_deg: NDArray[np.float64], what: str, limits: Plausibility, cause) -> None:
    """Refuse turns beyond ``limits.max_orientation_error_deg``; ``cause()`` gives the likely cause in words."""
    limit = limits.max_orientation_error_deg
    worst = int(np.argmax(turn_deg))
    if turn_deg[worst] > limit:
        raise DataError(
            f"{where[worst]}: {what} is {turn_deg[worst]:.4g} degrees (RMS {np.sqrt(np.mean(turn_deg**2)):.4g}; "
            f"{np.count_nonzero(turn_deg > limit)} of {len(turn_deg)} poses beyond {limit:g} degrees, "
            f"data.checks.max_orientation_error_deg): no calibrated robot errs that much: {cause()}")


_ORDERS = ("XZY", "YXZ", "YZX", "ZXY", "ZYX", "xyz", "xzy", "yxz", "yzx", "zxy")
"""Euler orders tried as causes (scipy's names: upper case intrinsic, lower case extrinsic); the contract is
intrinsic XYZ, and extrinsic zyx is the same as rx and rz swapped (tried first)."""


def orientation_readings(angles_deg, which: str = "meas") -> list[tuple[str, NDArray[np.float64]]]:
    """The rotations ``(n, 3, 3)`` that the angles ``(n, 3)`` would be under each likely mistake, in words.

    Two of the columns swapped, radians read as degrees, and each other
    order of Euler angles.
    """
    a = np.asarray(angles_deg, dtype=float)
    out = []
    for order in permutations(range(3)):
        if order != (0, 1, 2) and sum(order[i] != i for i in range(3)) == 2:
            swapped = [f"r{'xyz'[i]}_{which}" for i in range(3) if order[i] != i]
            out.append((f"columns {' and '.join(swapped)} look swapped", matrices_from_xyz_deg(a[:, list(order)])))
    out.append(("the angles look like radians (the format's orientation_unit: rad converts them)",
                matrices_from_xyz_deg(np.degrees(a))))
    for order in _ORDERS:
        kind = "intrinsic" if order.isupper() else "extrinsic (fixed axes)"
        out.append((f"the angles look like {kind} {order} Euler angles; the contract is intrinsic XYZ (R = Rx Ry Rz)",
                    matrices_from_euler_deg(order, a)))
    return out


def orientation_cause(expected, got_deg, which: str = "meas", *, robot: str | None = None,
                      frame_rotation=None) -> str:
    """The likeliest reason why angles ``got_deg`` (n, 3) do not give rotations ``expected`` (n, 3, 3), in words.

    With ``frame_rotation`` (a tracker's frame), ``got_deg`` are turned by it
    and the probe's constant turn on the flange is refitted for each reading.
    """
    expected = np.asarray(expected, dtype=float)
    rigid = frame_rotation is not None
    left = np.eye(3) if frame_rotation is None else np.asarray(frame_rotation, dtype=float)
    base = _turn_rms(expected, left @ matrices_from_xyz_deg(got_deg), rigid)
    tried = [(_turn_rms(expected, left @ rot, rigid), words) for words, rot in orientation_readings(got_deg, which)]
    best = min(rms for rms, _ in tried)
    if best < 0.2 * base:
        words = next(w for rms, w in tried if rms <= best * 1.001 + 1e-12)
        return f"{words} (reading them so leaves {best:.3g} degrees RMS instead of {base:.3g})"
    if not rigid and _turn_rms(expected, matrices_from_xyz_deg(got_deg), True) < 0.2 * base:
        return ("the orientations differ by one constant turn: is it a probe's or tool's own frame? (the "
                "orientation columns are the last frame's; frame: tracker fits a probe's turn on the flange)")
    if robot:
        return f"is it robot {robot!r}? (the data of another robot, or another tool, look like this)"
    return "are the nominal and measured orientations of the same poses, in the same frame and convention?"


def _turn_deg(expected: NDArray[np.float64], got: NDArray[np.float64]) -> NDArray[np.float64]:
    """The angle of the turn from each ``expected`` rotation to ``got`` (n, 3, 3), degrees, shape (n,)."""
    cos = (np.einsum("nij,nij->n", expected, got) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _turn_rms(expected: NDArray[np.float64], got: NDArray[np.float64], rigid: bool) -> float:
    """RMS angle of the turns ``expected -> got``, degrees; with ``rigid`` after the best constant turn ``P`` on
    the right (``got @ P.T``: a probe's turn on the flange)."""
    if rigid:
        u, _, vt = np.linalg.svd(np.mean(got.transpose(0, 2, 1) @ expected, axis=0))
        got = got @ (u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt)
    return float(np.sqrt(np.mean(_turn_deg(expected, got) ** 2)))


def _spread(p: NDArray[np.float64]) -> float:
    """RMS distance of points from their centroid."""
    return pooled_rms(p - p.mean(axis=0))


def _mismatch(expected: NDArray[np.float64], got: NDArray[np.float64], rigid: bool) -> float:
    """3-D RMS of ``got - expected``, after the best rigid motion of ``got`` with ``rigid``."""
    if rigid and len(got) >= 3:
        rot, shift = kabsch(got, expected)
        got = got @ rot.T + shift
    return pooled_rms(got - expected)


def _reach_of(nominal_mm) -> float:
    """Without a robot: the largest distance of a nominal position from the base origin, mm (at least 1)."""
    return max(float(np.linalg.norm(nominal_mm, axis=1).max()), 1.0)
