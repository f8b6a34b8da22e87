"""What the one identification checks of every row before it fits, and of its fit after, whatever the rows'
measurement types: joints in degrees and within the robot's limits, rows planned but not yet measured, and each
type's residual against the noise it states (a fit many times its noise is not called calibrated, and its worst
rows are named)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.kinematics import Robot
from .measurement import MeasurementRows

MIN_POSES = 5
"""Fewer poses are no evidence of radians."""

LIMIT_SLACK_DEG = 1.0
"""A joint this far beyond the robot's limit is refused (less is a controller's rounding at a limit)."""

PLANNED = "planned"
"""The column ``partcal plan`` writes on rows it plans (1): their joints are where the nominal robot would touch,
not where the robot did; such rows are refused until measured."""

NOT_CALIBRATED = 10.0
"""A type whose fit leaves an RMS residual this many times the noise it states is not called calibrated."""

WORST_ROWS = 3
"""How many of the worst rows a misfit names."""

MISFIT_KEEPS = 0.1
"""With a robust loss, the fit is judged on the rows it weighs at least this much (those it weighs less it has set
aside, and names)."""


def check_joint_units(source: str, rows: list, q_deg: NDArray[np.float64]) -> None:
    """Refuse joint angles that all lie within ±2π: radians read as degrees (``rows[0]`` names the first row)."""
    q = np.asarray(q_deg, dtype=float)
    if len(q) < MIN_POSES or not np.ptp(q, axis=0).any():
        return                                  # a few poses, or nothing moves: no evidence either way
    largest = float(np.abs(q).max())
    if largest <= 2 * np.pi + 1e-9:
        raise DataError(f"{source}:{rows[0]}: every joint angle of the {len(q)} poses lies within ±{largest:.3g} "
                        f"degrees: they look like radians; the contract is degrees (a format with joint_unit: rad "
                        f"converts them)")


def check_measured(rows: MeasurementRows) -> None:
    """Refuse rows ``partcal plan`` planned (:data:`PLANNED` not 0 nor empty), naming the first: a fit needs the
    joints the robot reached. (Judging a plan, ``plan --evaluate``, reads them as they are.)"""
    planned = rows.numbers.get(PLANNED)
    marked = None if planned is None else np.nan_to_num(planned) != 0      # plan writes 1; any mark but 0 counts
    if marked is not None and marked.any():
        i = int(np.flatnonzero(marked)[0])
        raise DataError(f"{rows.where(i)}: column {PLANNED!r}: a row partcal plan planned, not yet measured (its "
                        "joints are where the nominal robot would touch): measure it, write the joints the robot "
                        "reached, and drop the column")


def check_rows(robot: Robot, rows: MeasurementRows) -> None:
    """Refuse, naming file, line, column and value: joints that all look like radians, and a joint beyond the
    robot's limits by more than :data:`LIMIT_SLACK_DEG` (with the likely cause when the file's joints are degrees
    that a format read as radians)."""
    q = rows.q_deg
    check_joint_units(rows.source, [rows.lines[0]], q)
    low, high = robot.limits_deg[:, 0] - LIMIT_SLACK_DEG, robot.limits_deg[:, 1] + LIMIT_SLACK_DEG
    beyond = np.maximum(low - q, q - high)
    if not np.any(beyond > 0):
        return
    i, j = np.unravel_index(int(np.argmax(beyond)), beyond.shape)
    count = int(np.sum(np.any(beyond > 0, axis=1)))
    as_read = q / np.degrees(1.0)               # the file's numbers, had a format not scaled them
    cause = ("; every joint divided by 57.3 lies within them: degrees read as radians (a format's joint_unit: rad "
             "converts radians; this file looks like degrees)?" if np.all((as_read >= low) & (as_read <= high))
             else "")
    raise DataError(f"{rows.where(i)}: column 'q{j + 1}': {q[i, j]:g} degrees lies outside joint {j + 1}'s limits "
                    f"[{robot.limits_deg[j, 0]:g}, {robot.limits_deg[j, 1]:g}] of {robot.name} ({count} rows beyond "
                    f"a limit){cause}")


def misfit_notes(rows: MeasurementRows, residuals: dict[str, tuple[NDArray[np.float64], NDArray[np.intp]]],
                 noise: dict[str, tuple[float, str, bool]]) -> tuple[list[str], dict]:
    """The fit's residual of each type against its stated noise: a note for each type whose RMS is
    :data:`NOT_CALIBRATED` times its noise or more (naming its worst rows), and the ratios.

    ``residuals``: type -> (its residuals, the row of each); ``noise``: type -> (noise, unit, stated). A type
    whose noise is not stated (its default) is not judged: a tracker's points of a real robot leave its
    unmodelled errors, which no noise states."""
    notes, ratios = [], {}
    for name, (values, row_of) in residuals.items():
        sigma, unit, stated = noise[name]
        if values.size == 0:
            continue
        rms = float(np.sqrt(np.mean(values**2)))
        ratios[name] = rms / sigma
        if not stated or rms < NOT_CALIBRATED * sigma:
            continue
        per_row: dict[int, float] = {}
        for r, v in zip(row_of, values):
            if r >= 0:
                per_row[int(r)] = per_row.get(int(r), 0.0) + float(v) ** 2
        worst = sorted(per_row, key=per_row.get, reverse=True)[:WORST_ROWS]
        named = ", ".join(f"{rows.where(r)} ({np.sqrt(per_row[r]):.3g} {unit})" for r in worst)
        notes.append(f"not calibrated: the {name} rows' fit leaves {rms:.3g} {unit} RMS, {rms / sigma:.0f} times "
                     f"their stated noise {sigma:g} {unit}; the worst rows: {named}: a wrong known length or unit in "
                     "the cell, rows of another feature, or a noise stated too small")
    return notes, ratios


LENGTH_FACTOR = 1.25
"""A known length of the cell more than this factor off the nominal robot's view of it (or less than its inverse) is
refused: a unit (metres, cm, inches) or another feature's."""

LENGTH_MM, LENGTH_SHARE = 3.0, 0.005
"""A known length farther than this (mm, or this share of it, whichever is larger) from the nominal robot's view of
it is more than the nominal robot's own errors make: the fit would bend the robot to meet it, so it is said and the
fit not called calibrated."""

UNITS = ((1e-3, "metres"), (0.1, "centimetres"), (1 / 25.4, "inches"))


def known_length(key: str, where: str, stated_mm: float, seen_mm: float, seen_by: str) -> str | None:
    """A length the cell states (``key``, its value ``stated_mm``) against the nominal robot's view of it
    (``seen_mm``, from ``seen_by``): refused (one :class:`DataError` naming ``where`` and the key, with the unit it
    looks like) when off by more than :data:`LENGTH_FACTOR`; a note when off by more than the nominal robot's own
    errors (:data:`LENGTH_MM`, :data:`LENGTH_SHARE`); None when it agrees."""
    if not abs(seen_mm) > LENGTH_MM:
        return None                              # too short a view to judge a unit by
    ratio = stated_mm / seen_mm
    if not 1 / LENGTH_FACTOR <= ratio <= LENGTH_FACTOR:
        unit = next((f" ({name}? {stated_mm:g} {name} is {stated_mm / f:g} mm)" for f, name in UNITS
                     if abs(abs(ratio) / f - 1) < 0.2), "")
        sign = " (its sign?)" if ratio < 0 else ""
        raise DataError(f"{where}: {key}: {stated_mm:g} mm, but {seen_by} say about {seen_mm:.1f} mm: expected the "
                        f"length in mm{unit}{sign}, or the right feature")
    off = abs(stated_mm - seen_mm)
    if off > max(LENGTH_MM, LENGTH_SHARE * abs(seen_mm)):
        return (f"not calibrated: {key} is {stated_mm:g} mm, but {seen_by} say {seen_mm:.2f} mm ({off:.1f} mm off, "
                "more than the nominal robot's own errors make): the fit bends the robot to meet it; measure it again "
                "or leave it out")
    return None


def check_freedom(rows: MeasurementRows, row_of: NDArray[np.intp], table) -> None:
    """Refuse a fit that identified as many parameters as its rows have residuals, or more: nothing is left to judge
    it by, its standard errors and spread are not defined, and a model file of it could not be used."""
    residuals = int(np.sum(row_of >= 0))
    identified = table.status.count("identified")
    if residuals <= identified:
        raise DataError(f"{rows.source}: {len(rows)} rows give {residuals} residuals for the {identified} parameters "
                        "they identify: no residual is left to judge the fit by or to give it a spread; measure more "
                        "rows (or fewer parameters: DH rows, no compliance)")
