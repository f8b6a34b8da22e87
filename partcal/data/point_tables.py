"""The input files of ``partcal predict`` and ``partcal compensate``: their column rules, read in one pass.

A point table lists where a model is asked about: Cartesian positions
(``x, y, z``, or else a measurement file's ``x_nom, y_nom, z_nom``; mm) or
joint angles (``q1..qN``, degrees); for ``compensate`` optionally the joints
to seed inverse kinematics with (``q1..qN`` beside positions), the wanted
orientations (``rx, ry, rz``, or else ``rx_nom, ry_nom, rz_nom``; intrinsic
XYZ degrees) and a payload per row (``payload_kg``). A format file maps a
foreign file's columns and units as for measurements (docs/data.md). The
file is parsed once, whatever is read from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.description import joint_columns
from .formats import MeasurementFormat
from .measurements import read_table
from .pose_columns import ORIENTATION_NOMINAL, orientation_problem

POSITION_COLUMNS = [["x", "y", "z"], ["x_nom", "y_nom", "z_nom"]]       # x,y,z or else x_nom..
ORIENTATION_COLUMNS = [["rx", "ry", "rz"], list(ORIENTATION_NOMINAL)]    # rx,ry,rz or else rx_nom..
TURN_COLUMNS = ["drx", "dry", "drz"]          # predict's output: a pose model's predicted rotation vector, mrad


@dataclass(frozen=True)
class PointTable:
    """What a point table holds, in contract units.

    Attributes
    ----------
    path : Path
    columns : list of str
        The columns of ``values`` as found (``x, y, z``, ``x_nom..`` or ``q1..qN``).
    values : ndarray, shape (n, k)
        Positions (mm) or joint angles (degrees).
    seed_columns : list of str
        ``q1..qN`` when the file gives IK seeds beside positions, else empty.
    seeds : ndarray, shape (n, N), or None
    orientation_columns : list of str
        ``rx, ry, rz`` or ``rx_nom..`` when the file gives orientations, else empty.
    orientation_deg : ndarray, shape (n, 3), or None
        Intrinsic XYZ angles, degrees.
    payload_kg : ndarray, shape (n,), or None
    """

    path: Path
    columns: list[str]
    values: NDArray[np.float64]
    seed_columns: list[str]
    seeds: NDArray[np.float64] | None
    orientation_columns: list[str]
    orientation_deg: NDArray[np.float64] | None
    payload_kg: NDArray[np.float64] | None

    def __len__(self) -> int:
        return len(self.values)


def read_point_table(path: str | Path, fmt: MeasurementFormat | None = None, *, joints: int | None = None,
                     seeds: int = 0, orientation: bool = False, payload: bool = False) -> PointTable:
    """Read a point table in one pass.

    Parameters
    ----------
    path : str or Path
    fmt : MeasurementFormat, optional
        A foreign file's columns and units.
    joints : int, optional
        Read ``q1..q{joints}`` (a joint-input model) instead of positions.
    seeds : int
        With positions, read ``q1..q{seeds}`` too when the file has them all (IK seeds); 0: never.
    orientation : bool
        Read the wanted orientations when the file has them (an incomplete triple or an angle out of range is
        refused).
    payload : bool
        Read the ``payload_kg`` column when the file has it.
    """
    fmt = fmt or MeasurementFormat()
    groups = [joint_columns(joints)] if joints else POSITION_COLUMNS
    table = read_table(path, ",".join(groups[0]), fmt)
    optional = joint_columns(seeds) if seeds and not joints else []
    columns, values, seed_values = table.columns(groups, optional)
    turn_columns, turns = ([], None)
    if orientation:
        turn_columns, turns = _orientations(table, groups, fmt)
    return PointTable(table.path, columns, values, optional if seed_values is not None else [], seed_values,
                      turn_columns, turns, table.payloads() if payload else None)


def _orientations(table, groups, fmt: MeasurementFormat) -> tuple[list[str], NDArray[np.float64] | None]:
    """The first orientation triple the file has, in contract degrees, and its columns; ``([], None)`` if none."""
    for names in ORIENTATION_COLUMNS:
        angles = table.columns(groups, names)[2]
        if angles is not None:
            break
    else:
        return [], None
    if names[0] == "rx":        # read under their own names: the format's orientation unit applies as to rx_nom..
        angles = fmt.to_contract(list(ORIENTATION_NOMINAL), angles)
    problem = orientation_problem(angles)
    if problem is not None:
        row, k, expected = problem
        raise DataError(f"{table.path}: data row {row + 1}: column {names[k]!r}: expected an angle in {expected}, "
                        f"got {angles[row, k]:g}")
    return list(names), angles
