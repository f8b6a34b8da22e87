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
  by millimetres, rarely a few centimetres; 5% of a 1.3 m reach is 65 mm.

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
from ..errors import DataError
from ..robot.frames import kabsch

_AXES = ("x", "y", "z")
MIN_POSES = 5                 # fewer poses are no evidence of radians, nor (without a robot) of a workspace
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
    """

    max_error_of_reach: float = 0.05
    nominal_tolerance_mm: float = 0.01

    rules = {"max_error_of_reach": real(0.0, 1.0, default=0.05, low_open=True),     # read by the config too
             "nominal_tolerance_mm": real(0.0, default=0.01, low_open=True)}

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


def check_joint_units(source: str, rows: list[int], q_deg: NDArray[np.float64]) -> None:
    """Refuse joint angles that all lie within ±2π: radians read as degrees."""
    q = np.asarray(q_deg, dtype=float)
    if len(q) < MIN_POSES or not np.ptp(q, axis=0).any():
        return                                  # a few poses, or nothing moves: no evidence either way
    largest = float(np.abs(q).max())
    if largest <= 2 * np.pi + 1e-9:
        raise DataError(f"{source}:{rows[0]}: every joint angle of the {len(q)} poses lies within ±{largest:.3g} "
                        f"degrees: they look like radians; the contract is degrees (a format with joint_unit: rad "
                        f"converts them)")


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


def _spread(p: NDArray[np.float64]) -> float:
    """RMS distance of points from their centroid."""
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))))


def _mismatch(expected: NDArray[np.float64], got: NDArray[np.float64], rigid: bool) -> float:
    """3-D RMS of ``got - expected``, after the best rigid motion of ``got`` with ``rigid``."""
    if rigid and len(got) >= 3:
        rot, shift = kabsch(got, expected)
        got = got @ rot.T + shift
    return float(np.sqrt(np.mean(np.sum((got - expected) ** 2, axis=1))))


def _reach_of(nominal_mm) -> float:
    """Without a robot: the largest distance of a nominal position from the base origin, mm (at least 1)."""
    return max(float(np.linalg.norm(nominal_mm, axis=1).max()), 1.0)
