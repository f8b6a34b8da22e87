"""The measurement CSV contract: read, validate and write measured poses.

One row per pose, one header line, ``#`` comment lines allowed. Columns:
``q1..qN`` (joint angles, degrees), ``x_nom, y_nom, z_nom`` (nominal tool
position, mm; optional when a robot model is given), ``x_meas, y_meas,
z_meas`` (measured position, mm), an optional text column ``set`` and an
optional ``payload_kg`` (the payload at the tool point when the pose was
measured, kg) and optional ``std_x, std_y, std_z`` (the measured position's
standard deviation per coordinate, mm, all three or none: they weigh the
rows in registration and identification). Other columns are accepted and ignored. Errors are
``measured - nominal``.

A pose may carry more: further targets on the tool, each as wide columns with
the target's name after ``@`` (``x_meas@B, y_meas@B, z_meas@B`` and optionally
``x_nom@B, ...``; the unsuffixed columns are the primary target, named
:data:`PRIMARY`), and the tool's measured orientation ``rx_meas, ry_meas,
rz_meas`` (intrinsic XYZ angles, degrees: ``R = Rx Ry Rz``) with its nominal
``rx_nom, ry_nom, rz_nom`` (or a robot's forward kinematics).

Every problem is reported once, as ``FILE:LINE: column 'NAME': what was wrong``,
where LINE is the line number an editor shows.

Files from elsewhere (a tracker's export: semicolons, decimal commas, other
column names, radians, metres) are read by the same functions with a
:class:`~partcal.data.formats.MeasurementFormat`; values are converted once,
here, to degrees and millimetres.
"""

from __future__ import annotations

import csv
import itertools
import re
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write
from .._validation import MAX_PAYLOAD_KG, check_array, check_std
from ..errors import DataError
from ..metrics import MRAD_PER_DEG
from ..robot.description import MAX_JOINTS, joint_columns, load_robot
from ..robot.kinematics import Robot
from ..robot.rotations import matrices_from_xyz_deg, rotation_vectors_from_matrices, xyz_deg_from_matrices
from .formats import MEASUREMENT, OLD_MEASUREMENT, STDS, MeasurementFormat, RowSelection, file_must_have
from .pose_columns import (ORIENTATION_MEASURED, ORIENTATION_NOMINAL, PRIMARY, check_angles, checked_orientation,
                           checked_targets, orientation_columns, suffixed, target_columns)
from .plausibility import Plausibility, check_measured, check_orientation

NOMINAL = ("x_nom", "y_nom", "z_nom")
MEASURED = ("x_meas", "y_meas", "z_meas")
PAYLOAD = "payload_kg"
_JOINT = re.compile(r"^q(\d+)$")
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_PLAIN = frozenset("0123456789+-.eE \t")     # the characters of plain numbers (see _plain_numbers)
_CONTRACT = MeasurementFormat()


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measured poses of one data set.

    Attributes
    ----------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    nominal_mm, measured_mm : ndarray, shape (n, 3)
        Nominal (controller model) and measured tool positions, mm.
    name : str
        The data set's name (the file stem by default).
    labels : tuple of str, optional
        The ``set`` column, when present.
    groups : tuple of str, optional
        The pose each row measures, from a column the reader was told to read
        (``group_column``): rows of one pose are held out together by
        cross-validation. Without it, rows whose joint angles agree within 0.01
        degrees are one pose.
    payload_kg : ndarray, shape (n,), optional
        The payload at the tool point of each pose, kg (the ``payload_kg``
        column). Kinematic models with joint compliance read it; it is None
        when the file has no such column (the model's own ``payload_kg`` then
        applies).
    extra_measured_mm : dict of str to ndarray (n, 3), optional
        Further targets on the tool (not the primary one), by name: measured
        positions, mm. ``nominal_mm``, ``measured_mm`` and ``errors_mm`` are
        always the primary target's (named :data:`PRIMARY`).
    extra_nominal_mm : dict of str to ndarray (n, 3), optional
        Their nominal positions, mm: for every extra target or for none.
    measured_orientation_deg, nominal_orientation_deg : ndarray, shape (n, 3), optional
        The tool's orientation, intrinsic XYZ angles ``(rx, ry, rz)`` degrees
        (``R = Rx(rx) Ry(ry) Rz(rz)``, :func:`~partcal.robot.rotations.matrices_from_xyz_deg`),
        measured and nominal; both or neither. ``rx, rz`` lie in [-180, 180] and ``ry`` in [-90, 90].
    """

    q_deg: NDArray[np.float64]
    nominal_mm: NDArray[np.float64]
    measured_mm: NDArray[np.float64]
    name: str = "measurements"
    labels: tuple[str, ...] | None = field(default=None)
    groups: tuple[str, ...] | None = field(default=None)
    payload_kg: NDArray[np.float64] | None = field(default=None)
    extra_measured_mm: dict = field(default_factory=dict)
    extra_nominal_mm: dict = field(default_factory=dict)
    measured_orientation_deg: NDArray[np.float64] | None = None
    nominal_orientation_deg: NDArray[np.float64] | None = None
    std_mm: NDArray[np.float64] | None = None

    def __post_init__(self):
        q = check_array(self.q_deg, "q_deg", min_rows=1)
        n = q.shape[0]
        if not 1 <= q.shape[1] <= MAX_JOINTS:
            raise DataError(f"q_deg must have 1..{MAX_JOINTS} columns, got {q.shape[1]}")
        for attr in ("nominal_mm", "measured_mm"):
            arr = check_array(getattr(self, attr), attr, columns=3)
            if arr.shape[0] != n:
                raise DataError(f"{attr} has {arr.shape[0]} rows but q_deg has {n}")
            object.__setattr__(self, attr, arr)
        object.__setattr__(self, "q_deg", q)
        for name in ("labels", "groups"):
            given = getattr(self, name)
            if given is not None and len(given) != n:
                raise DataError(f"{name} has {len(given)} entries but q_deg has {n} rows")
        measured, nominal = checked_targets(self.extra_measured_mm, self.extra_nominal_mm, n)
        object.__setattr__(self, "extra_measured_mm", measured)
        object.__setattr__(self, "extra_nominal_mm", nominal)
        for attr, arr in zip(("measured_orientation_deg", "nominal_orientation_deg"),
                             checked_orientation(self.measured_orientation_deg, self.nominal_orientation_deg, n)):
            object.__setattr__(self, attr, arr)
        if self.payload_kg is not None:
            payload = check_array(self.payload_kg, "payload_kg", ndim=1)
            bad = first_bad_payload(payload)
            if payload.shape[0] != n or bad is not None:
                got = f"{payload[bad]:g} kg at row {bad + 1}" if bad is not None else f"{payload.shape[0]} values"
                raise DataError(f"Expected payload_kg as {n} masses in [0, {MAX_PAYLOAD_KG:g}] kg (one per pose), "
                                f"got {got}")
            object.__setattr__(self, "payload_kg", payload)
        if self.std_mm is not None:
            object.__setattr__(self, "std_mm", check_std(self.std_mm, n))

    def take(self, rows, name: str | None = None) -> "Measurements":
        """The rows ``rows`` (indices or a boolean mask) as a data set of their own, every column kept."""
        def some(v):
            return None if v is None else v[rows]

        def texts(v):
            return None if v is None else tuple(np.asarray(v, dtype=object)[rows].tolist())

        return dataclasses.replace(
            self, q_deg=self.q_deg[rows], nominal_mm=self.nominal_mm[rows], measured_mm=self.measured_mm[rows],
            name=self.name if name is None else name, labels=texts(self.labels), groups=texts(self.groups),
            payload_kg=some(self.payload_kg), extra_measured_mm={k: v[rows] for k, v in self.extra_measured_mm.items()},
            extra_nominal_mm={k: v[rows] for k, v in self.extra_nominal_mm.items()},
            measured_orientation_deg=some(self.measured_orientation_deg),
            nominal_orientation_deg=some(self.nominal_orientation_deg), std_mm=some(self.std_mm))

    def __len__(self) -> int:
        return self.q_deg.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q_deg.shape[1]

    @property
    def errors_mm(self) -> NDArray[np.float64]:
        """Position errors ``measured - nominal``, shape (n, 3), mm."""
        return self.measured_mm - self.nominal_mm

    @property
    def target_names(self) -> tuple[str, ...]:
        """The targets measured: :data:`PRIMARY` first, then the extra ones in file order."""
        return (PRIMARY, *self.extra_measured_mm)

    def measured_of(self, target: str) -> NDArray[np.float64]:
        """The measured positions of one target, shape (n, 3), mm."""
        return self.measured_mm if target == PRIMARY else self.extra_measured_mm[self._target(target)]

    def nominal_of(self, target: str) -> NDArray[np.float64] | None:
        """The nominal positions of one target, shape (n, 3), mm (None when an extra target has none)."""
        return self.nominal_mm if target == PRIMARY else self.extra_nominal_mm.get(self._target(target))

    def _target(self, target: str) -> str:
        if target not in self.extra_measured_mm:
            raise DataError(f"Expected a target of {self.name} ({', '.join(self.target_names)}), got {target!r}.")
        return target

    @property
    def has_orientation(self) -> bool:
        return self.measured_orientation_deg is not None

    @property
    def orientation_errors_deg(self) -> NDArray[np.float64]:
        """Orientation errors as rotation vectors (axis times angle) in the base frame, shape (n, 3), degrees.

        The turn that carries the nominal orientation to the measured one:
        ``R_meas = exp([e]) R_nom``.
        """
        if not self.has_orientation:
            raise DataError(f"{self.name} has no measured orientation (columns rx_meas, ry_meas, rz_meas)")
        turn = matrices_from_xyz_deg(self.measured_orientation_deg) @ \
            matrices_from_xyz_deg(self.nominal_orientation_deg).transpose(0, 2, 1)
        return np.degrees(rotation_vectors_from_matrices(turn))

    @property
    def pose_errors(self) -> NDArray[np.float64]:
        """The pose errors, shape (n, 6): the primary target's position error (mm), then the orientation error
        (:attr:`orientation_errors_deg`) in mrad: what a model predicting pose errors fits."""
        return np.hstack([self.errors_mm, self.orientation_errors_deg * MRAD_PER_DEG])


def read_measurements(path: str | Path, robot: str | Robot | None = None, *, name: str | None = None,
                      fmt: MeasurementFormat | None = None, rows: RowSelection | None = None,
                      frame: str = "base", plausibility: Plausibility | None = None,
                      group_column: str | None = None) -> Measurements:
    """Read a measurement CSV, or a foreign file described by ``fmt``.

    Parameters
    ----------
    path : str or Path
    robot : str or Robot, optional
        Used to compute the nominal positions by forward kinematics when the
        file has no ``x_nom, y_nom, z_nom`` columns.
    name : str, optional
        Data set name; default the file name without extension.
    fmt : MeasurementFormat, optional
        Delimiter, decimal mark, column names and units of the file; default
        the contract (comma, decimal point, degrees, mm).
    rows : RowSelection, optional
        Data rows to keep (the whole file is validated either way).
    frame : {"base", "tracker"}
        ``"tracker"``: the measured positions are in a tracker's frame, to be
        registered (:mod:`partcal.data.registration`); the nominal positions
        then always come from ``robot`` (required), and nominal columns in the
        file are refused rather than silently ignored.
    plausibility : Plausibility, optional
        The limits of physically plausible data (default
        :class:`~partcal.data.plausibility.Plausibility()`): nominal columns
        against the robot's forward kinematics, joint angles in radians,
        errors larger than a fraction of the reach.
    group_column : str, optional
        A column of the file (any text) naming the pose each row measures:
        kept as :attr:`Measurements.groups`.

    Returns
    -------
    Measurements
        Joint angles in degrees, positions in mm.

    Raises
    ------
    DataError
        For any malformed content, naming the file, line and column; for data
        no robot can have produced, naming the worst row and the likely cause.
    """
    if frame not in ("base", "tracker"):
        raise DataError(f"The 'frame' parameter of read_measurements must be 'base' or 'tracker'. "
                        f"Got {frame!r} instead.")
    path = Path(path)
    fmt = fmt or _CONTRACT
    line, header, seen, data = _table(path, "q1,...,x_meas,y_meas,z_meas", fmt)
    columns = _check_header(path, line, seen, fmt, has_robot=robot is not None)
    if frame == "tracker":
        if robot is None:
            raise DataError(f"{path}: measurements in a tracker frame need a robot model to register them")
        given = (columns["nom"] or []) + [c for t in columns["targets"].values() for c in t["nom"] or []] + \
            (columns["rot_nom"] or [])
        if given:
            raise DataError(f"{path}:{line}: column {header[given[0]]}: with frame: tracker the nominal "
                            "positions come from the robot and the registration; drop the nominal columns "
                            "(or their mapping), or use frame: base")
    names, cols = _numeric_columns(columns)
    values = fmt.to_contract(names, _numbers(path, line, header, data, cols, fmt.decimal))
    check_angles(path, header, data, names, cols, values)
    keep = (rows or RowSelection()).indices(len(data), path)
    values = values[keep]
    at = {contract: k for k, contract in enumerate(names)}

    def block(contract: tuple | list) -> NDArray[np.float64]:
        return values[:, [at[c] for c in contract]]

    n_q = len(columns["q"])
    q = block(joint_columns(n_q))
    meas = block(MEASURED)
    model = load_robot(robot) if robot is not None else None
    if model is not None and model.n_joints != n_q:     # even with nominal columns: joint models read q1..qN
        raise DataError(f"{path}: the file has {n_q} joint columns (q1..q{n_q}) but robot {model.name!r} has "
                        f"{model.n_joints} joints")
    nominal = block(NOMINAL) if columns["nom"] else model.positions(q)
    check_measured(str(path), [data[i][0] for i in keep], q, nominal, meas, model, nominal_given=bool(columns["nom"]),
                   frame=frame, limits=plausibility or Plausibility())
    extra = {t: block(suffixed("meas", t)) for t in columns["targets"]}
    extra_nominal = {t: block(suffixed("nom", t)) for t, c in columns["targets"].items() if c["nom"]}
    orientation = nominal_orientation = None
    if columns["rot_meas"]:
        orientation = block(ORIENTATION_MEASURED)
        nominal_orientation = (block(ORIENTATION_NOMINAL) if columns["rot_nom"]
                               else xyz_deg_from_matrices(model.forward(q)[:, :3, :3]))
        if frame == "base":
            check_orientation(str(path), [data[i][0] for i in keep], q, orientation, nominal_orientation, model,
                              nominal_given=bool(columns["rot_nom"]), limits=plausibility or Plausibility())
    labels = groups = None
    if columns["set"] is not None:
        labels = tuple(data[i][1][columns["set"]].strip() for i in keep)
    if group_column is not None:
        if group_column not in seen:
            raise DataError(f"{path}:{line}: column {group_column!r} is missing (data.groups names it as the "
                            f"column of each row's pose); the file has {', '.join(h.strip(chr(39)) for h in header)}")
        groups = tuple(data[i][1][seen[group_column]].strip() for i in keep)
    payload = _payloads(path, line, header, data, seen[PAYLOAD], fmt.decimal)[keep] if PAYLOAD in seen else None
    std = _stds(path, line, header, data, seen, fmt)
    return Measurements(q_deg=q, nominal_mm=nominal, measured_mm=meas,
                        name=name if name is not None else path.stem, labels=labels, groups=groups,
                        payload_kg=payload, extra_measured_mm=extra, extra_nominal_mm=extra_nominal,
                        measured_orientation_deg=orientation, nominal_orientation_deg=nominal_orientation,
                        std_mm=None if std is None else std[keep])


def _stds(path: Path, line: int, header: list[str], data: list, seen: dict[str, int], fmt: MeasurementFormat
          ) -> NDArray[np.float64] | None:
    """The ``std_x, std_y, std_z`` columns (all three or none), mm, each a positive number; None without them."""
    present = [c for c in STDS if c in seen]
    if not present:
        return None
    if len(present) < 3:
        missing = next(c for c in STDS if c not in seen)
        raise DataError(f"{path}:{line}: column {fmt.file_column(missing)!r} is missing (give all of "
                        f"{', '.join(fmt.file_column(c) for c in STDS)} or none)")
    cols = [seen[c] for c in STDS]
    values = fmt.to_contract(list(STDS), _numbers(path, line, header, data, cols, fmt.decimal))
    bad = np.argwhere(~(values > 0))
    if bad.size:
        r, c = bad[0]
        raise DataError(f"{path}:{data[r][0]}: column {header[cols[c]]}: expected a standard deviation > 0 (mm), "
                        f"got {values[r, c]:g}")
    return values


def first_bad_payload(values: NDArray[np.float64]) -> int | None:
    """Index of the first payload outside [0, MAX_PAYLOAD_KG] kg, or None."""
    bad = np.flatnonzero((values < 0) | (values > MAX_PAYLOAD_KG))
    return int(bad[0]) if bad.size else None


@dataclass(frozen=True)
class CsvTable:
    """A CSV parsed once (header checked, rows split), whose numeric columns are read on demand: what
    :func:`read_columns` reads, and the payload column, for a reader that takes several groups of one file."""

    path: Path
    line: int                    # the header's line
    header: list[str]            # column labels for messages
    seen: dict[str, int]         # contract name -> position
    data: list
    fmt: MeasurementFormat

    def has(self, columns) -> bool:
        """Whether every one of the contract ``columns`` is in the file."""
        return all(c in self.seen for c in columns)

    def columns(self, alternatives: list[list[str]], optional: list[str] = ()
                ) -> tuple[list[str], NDArray[np.float64], NDArray[np.float64] | None]:
        """See :func:`read_columns`."""
        fmt, path, line, seen = self.fmt, self.path, self.line, self.seen
        chosen = next((group for group in alternatives if all(c in seen for c in group)), None)
        if chosen is None:
            wanted = " or ".join(",".join(fmt.file_column(c) for c in g) for g in alternatives)
            missing = next(c for c in alternatives[0] if c not in seen)
            raise DataError(f"{path}:{line}: column {fmt.file_column(missing)!r} is missing (expected columns "
                            f"{wanted})")
        present = [c for c in optional if c in seen]
        if present and len(present) < len(optional):
            missing = next(c for c in optional if c not in seen)
            raise DataError(f"{path}:{line}: column {fmt.file_column(missing)!r} is missing (give all of "
                            f"{', '.join(fmt.file_column(c) for c in optional)} or none)")
        extra = list(optional) if present else []
        values = _numbers(path, line, self.header, self.data, [seen[c] for c in chosen + extra], fmt.decimal)
        values = fmt.to_contract(chosen + extra, values)
        k = len(chosen)
        return chosen, values[:, :k], (values[:, k:] if extra else None)

    def payloads(self) -> NDArray[np.float64] | None:
        """The ``payload_kg`` column, kg per data row, or None when the file has none (``partcal predict`` and
        ``compensate`` read it for models with compliant joints). Refusals name the file, line and column."""
        if PAYLOAD not in self.seen:
            return None
        return _payloads(self.path, self.line, self.header, self.data, self.seen[PAYLOAD], self.fmt.decimal)


def read_table(path: str | Path, expected: str, fmt: MeasurementFormat | None = None, *,
               measurements_file: bool = False) -> CsvTable:
    """Parse a CSV once (``expected``: a header to suggest when the file is empty); errors name file, line and
    column. ``measurements_file``: the file is a measurements file (which mapped columns it must have:
    :func:`~partcal.data.formats.file_must_have`)."""
    path, fmt = Path(path), fmt or _CONTRACT
    return CsvTable(path, *_table(path, expected, fmt, measurements_file), fmt)


def _payloads(path: Path, line: int, header: list[str], data: list, column: int, decimal: str
              ) -> NDArray[np.float64]:
    """The ``payload_kg`` column: a mass in [0, MAX_PAYLOAD_KG] kg on every row."""
    values = _numbers(path, line, header, data, [column], decimal)[:, 0]
    bad = first_bad_payload(values)
    if bad is not None:
        raise DataError(f"{path}:{data[bad][0]}: column {header[column]}: expected a payload mass in "
                        f"[0, {MAX_PAYLOAD_KG:g}] kg, got {values[bad]:g}")
    return values


def _numeric_columns(columns: dict) -> tuple[list[str], list[int]]:
    """The contract names and file positions of every numeric column the header check found."""
    n_q = len(columns["q"])
    names = joint_columns(n_q) + (list(NOMINAL) if columns["nom"] else []) + list(MEASURED)
    cols = columns["q"] + (columns["nom"] or []) + columns["meas"]
    for target, found in columns["targets"].items():
        names += suffixed("meas", target) + (suffixed("nom", target) if found["nom"] else [])
        cols += found["meas"] + (found["nom"] or [])
    for kind, contract in (("rot_meas", ORIENTATION_MEASURED), ("rot_nom", ORIENTATION_NOMINAL)):
        if columns[kind]:
            names += list(contract)
            cols += columns[kind]
    return names, cols


def csv_rows(path: Path, delimiter: str = ","):
    """Yield ``(line_number, cells)`` for the header and data lines, skipping comments and blanks.

    A UTF-8 byte-order mark (as Excel writes) is accepted and dropped.
    """
    try:
        handle = path.open(newline="", encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"{path}: no such file") from None
    except OSError as exc:
        raise DataError(f"{path}: cannot read: {exc.strerror or exc}") from None
    with handle:
        try:
            for number, text in enumerate(handle, start=1):
                stripped = text.strip()
                if not stripped or stripped.startswith("#"):
                    continue
                yield number, next(csv.reader([text], delimiter=delimiter))
        except UnicodeDecodeError as exc:
            raise DataError(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None


def _table(path: Path, expected: str, fmt: MeasurementFormat = _CONTRACT, measurements_file: bool = False
           ) -> tuple[int, list[str], dict[str, int], list]:
    """Header line number, column labels for messages, contract name -> position, and the data rows.

    Refuses empty files, duplicate columns and mapped columns that are missing
    (those the file must have: :func:`~partcal.data.formats.file_must_have`, as a
    run's one format may map both its point CSVs' and measurements files' columns;
    a mapped column that is absent is then not found). File columns that ``fmt`` maps are found
    under their contract names; an unmapped file column named like a mapped
    contract column is ignored.
    """
    rows = list(csv_rows(path, fmt.delimiter))
    if not rows:
        raise DataError(f"{path}: empty file: expected a header line such as '{expected}'")
    line, names = rows[0][0], [h.strip() for h in rows[0][1]]
    hint = delimiter_hint(names, fmt)
    if hint:        # no measurement file has a single column: the delimiter is wrong
        raise DataError(f"{path}:{line}: {hint}")
    position: dict[str, int] = {}
    for i, col in enumerate(names):
        if col in position:
            raise DataError(f"{path}:{line}: column {col!r} appears twice (columns {position[col] + 1} and {i + 1})")
        position[col] = i
    seen = {col: i for col, i in position.items() if col not in fmt.columns}
    labels = [repr(col) for col in names]
    for contract, column in fmt.columns.items():
        if column not in position:
            if not file_must_have(contract, measurements_file):
                continue
            raise DataError(f"{path}:{line}: column {column!r} is missing (the format maps {contract} to it)")
        seen[contract] = position[column]
        labels[position[column]] = fmt.label(contract)
    return line, labels, seen, rows[1:]


def delimiter_hint(names: list[str], fmt: MeasurementFormat) -> str:
    """A hint when a single-column header looks split by another delimiter than the format's."""
    if len(names) == 1:
        for other in (";", ",", "\t", "|"):
            if other != fmt.delimiter and other in names[0]:
                return (f"the header is one column containing {other!r}, but the delimiter is {fmt.delimiter!r}: "
                        f"is it {other!r}? (set the format's delimiter)")
    return ""


def _numbers(path: Path, line: int, header: list[str], data: list, columns: list[int], decimal: str = "."
             ) -> NDArray[np.float64]:
    """The given columns of every data row as floats, shape (rows, len(columns)); at least one row.

    ``header`` holds the columns' labels for messages (see :func:`_table`).
    """
    if not data:
        raise DataError(f"{path}:{line}: the header is not followed by any data row")
    if decimal == "." and all(len(cells) == len(header) for _, cells in data):
        values = _plain_numbers(data, columns)
        if values is not None:
            return values
    values = np.empty((len(data), len(columns)))
    for r, (number, cells) in enumerate(data):      # cell by cell: the first bad one is named
        if len(cells) != len(header):
            hint = (" (a decimal comma in a comma-separated file? set the format's delimiter)"
                    if len(cells) > len(header) and decimal == "." else "")
            raise DataError(f"{path}:{number}: expected {len(header)} cells as in the header, got {len(cells)}{hint}")
        for c, col in enumerate(columns):
            values[r, c] = parse_number(path, number, header[col], cells[col], decimal)
    return values


def joint_count(where: str, seen: dict[str, int]) -> int:
    """The number N of joint columns ``q1..qN`` among a header's contract names ``seen``; refused (``where``:
    ``FILE:LINE`` of the header) when there are none, when they have gaps or when N > MAX_JOINTS."""
    joints = sorted(int(m.group(1)) for col in seen if (m := _JOINT.match(col)))
    if not joints:
        raise DataError(f"{where}: no joint columns: expected q1..qN (degrees), N in 1..{MAX_JOINTS}")
    if joints != list(range(1, len(joints) + 1)) or len(joints) > MAX_JOINTS:
        expected = f"q1..q{min(len(joints), MAX_JOINTS)}"
        bad = next((f"q{j}" for j, k in zip(joints, range(1, len(joints) + 1)) if j != k), f"q{joints[-1]}")
        raise DataError(f"{where}: column {bad!r}: joint columns must run q1..qN without gaps, "
                        f"N <= {MAX_JOINTS}; expected {expected}")
    return len(joints)


def _check_header(path: Path, line: int, seen: dict[str, int], fmt: MeasurementFormat, *, has_robot: bool) -> dict:
    where = f"{path}:{line}"
    n_joints = joint_count(where, seen)
    for col in MEASURED:
        if col not in seen:
            named = fmt.file_column(MEASUREMENT if MEASUREMENT in seen else OLD_MEASUREMENT)
            other = (f"; column {named!r} makes it a measurements file, which partcal run and "
                     "partcal plan --evaluate read (docs/data.md, \"Measurement types\"), not this command"
                     if MEASUREMENT in seen or OLD_MEASUREMENT in seen else "")
            raise DataError(f"{where}: column {fmt.file_column(col)!r} is missing (required: "
                            f"{', '.join(fmt.file_column(c) for c in MEASURED)}){other}")
    present = [c for c in NOMINAL if c in seen]
    if 0 < len(present) < 3:
        missing = next(c for c in NOMINAL if c not in seen)
        raise DataError(f"{where}: column {missing!r} is missing (give all of {', '.join(NOMINAL)} or none)")
    if not present and not has_robot:
        raise DataError(f"{where}: columns {', '.join(NOMINAL)} are missing; give them, or a robot model "
                        "to compute nominal positions by forward kinematics")
    return {
        "q": [seen[c] for c in joint_columns(n_joints)],
        "nom": [seen[c] for c in NOMINAL] if present else None,
        "meas": [seen[c] for c in MEASURED],
        "set": seen.get("set"),
        "targets": target_columns(where, seen, fmt),
        **orientation_columns(where, seen, fmt, has_robot=has_robot),
    }


def _plain_numbers(data: list, columns: list[int]) -> NDArray[np.float64] | None:
    """Every given column at once, when all its cells are plain finite numbers with a decimal point; None
    otherwise, and :func:`_numbers` then reads cell by cell to name the first bad one.

    Cells of digits, signs, points, exponents and blanks that numpy converts are exactly those
    :func:`parse_number` reads (``1_000``, ``nan``, ``inf`` and ``0x1`` hold other characters; ``1e``, ``1..2``
    or an empty cell fail the conversion), with the same values. 100,000 rows of 12 columns: 1.1 s
    instead of 2.7 s.
    """
    texts = [[cells[col] for col in columns] for _, cells in data]
    if not set("".join(itertools.chain.from_iterable(texts))) <= _PLAIN:
        return None
    try:
        out = np.array(texts, dtype=float)
    except ValueError:
        return None
    return out if np.isfinite(out).all() else None


def parse_number(path: Path, line: int, label: str, cell: str, decimal: str = ".") -> float:
    """One cell as a float: plain decimal notation only (no ``1_000``, ``nan``, ``inf`` or thousands marks)."""
    text = cell.strip()
    other = "," if decimal == "." else "."
    if other in text and _NUMBER.fullmatch(text.replace(other, ".")):
        mark = "comma" if decimal == "," else "point"
        raise DataError(f"{path}:{line}: column {label}: expected a number with a decimal {mark} {decimal!r}, got "
                        f"{text!r} (is the decimal mark {other!r}? set the format's decimal)")
    value = float(text.replace(decimal, ".")) if _NUMBER.fullmatch(text.replace(decimal, ".")) else None
    if value is None or not np.isfinite(value):
        shown = "an empty cell" if not text else repr(text)
        raise DataError(f"{path}:{line}: column {label}: expected a finite number, got {shown}")
    return value


def write_measurements(m: Measurements, path: str | Path, *, comment: str | None = None) -> None:
    """Write measurements as a CSV that :func:`read_measurements` reads back.

    Extra targets (with their nominal columns when present) follow the
    primary one; the orientation, nominal then measured, follows them.
    Angles are written with 6 decimals (micro-degrees) and positions with 6
    decimals (nanometres), so files are identical whenever the data are.
    The file is written to a temporary name and renamed when complete.
    """
    header = joint_columns(m.n_joints) + list(NOMINAL) + list(MEASURED)
    blocks = [m.q_deg, m.nominal_mm, m.measured_mm]
    for target, measured in m.extra_measured_mm.items():
        if target in m.extra_nominal_mm:
            header += suffixed("nom", target)
            blocks.append(m.extra_nominal_mm[target])
        header += suffixed("meas", target)
        blocks.append(measured)
    if m.has_orientation:
        header += list(ORIENTATION_NOMINAL) + list(ORIENTATION_MEASURED)
        blocks += [m.nominal_orientation_deg, m.measured_orientation_deg]
    if m.payload_kg is not None:
        header.append(PAYLOAD)
        blocks.append(m.payload_kg[:, None])
    if m.std_mm is not None:
        header += list(STDS)
        blocks.append(m.std_mm)
    if m.labels is not None:
        header.append("set")
    with atomic_write(path, newline="") as handle:
        for text in (comment or "").splitlines():
            handle.write(f"# {text}\n")
        handle.write(",".join(header) + "\n")
        numbers = np.hstack(blocks)
        for i, row in enumerate(numbers):
            cells = [f"{v:.6f}" for v in row]
            if m.labels is not None:
                cells.append(_quote(m.labels[i]))
            handle.write(",".join(cells) + "\n")


def _quote(text: str) -> str:
    if any(ch in text for ch in ',"\n\r'):
        return '"' + text.replace('"', '""') + '"'
    return text


def read_columns(path: str | Path, alternatives: list[list[str]], optional: list[str] = (),
                 fmt: MeasurementFormat | None = None
                 ) -> tuple[list[str], NDArray[np.float64], NDArray[np.float64] | None]:
    """Read numeric columns from a CSV: the first group of ``alternatives`` present, plus ``optional``.

    Returns the chosen (contract) column names, their values ``(n, k)`` in
    degrees and mm, and the optional columns' values (or None when absent).
    ``fmt`` describes a foreign file as for :func:`read_measurements`. Errors
    name file, line and column.
    """
    return read_table(path, ",".join(alternatives[0]), fmt).columns(alternatives, optional)


def read_text_column(path: str | Path, column: str, fmt: MeasurementFormat | None = None
                     ) -> tuple[NDArray[np.intp], tuple[str, ...] | None]:
    """The line number (as an editor shows it) of every data row, and the cells of ``column`` (None when absent).

    For labels a reader keeps as text (a ``cycle`` column), and for messages
    that name a data row's line.
    """
    path = Path(path)
    fmt = fmt or _CONTRACT
    _, _, seen, data = _table(path, column, fmt)
    lines = np.array([number for number, _ in data], dtype=np.intp)
    if column not in seen:
        return lines, None
    return lines, tuple(cells[seen[column]].strip() for _, cells in data)
