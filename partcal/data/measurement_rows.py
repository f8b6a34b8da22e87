"""Measurement types in one CSV: plane contacts, fixed points, distances, tracker points, poses.

A measurement CSV with a ``measurement`` column holds one row per observation (``docs/data.md``, "Measurement
types"): ``q1..qN`` (degrees) on every row, the row's ``measurement`` and the columns that type reads:

========== ===========================================================================================
type       reads
========== ===========================================================================================
point      ``x_meas, y_meas, z_meas``: a tracker point in the base frame, mm
plane      ``feature`` (the plane's name), ``flush`` (optional 0/1: a flat face of the tool on the plane)
fixed      ``feature`` (the fixed point's name)
distance   ``distance_mm`` (> 0) and ``to`` (another row's ``id``, or a point of the cell)
pose       nothing: joints only, a pose other rows' ``to`` name
========== ===========================================================================================

plus the optional ``id`` (a row's name; default its 1-based data-row number), ``set`` and ``payload_kg``.
Any other column is kept: as numbers when every filled cell is a number, as texts otherwise (a type added
outside partcal reads its own columns from there). A file without ``measurement`` is the usual point CSV
(:mod:`partcal.data.measurements`); :func:`has_measurement_column` tells them apart.

What each type reads is declared on its class (:attr:`MeasurementType.columns
<partcal.calibration.measurement.MeasurementType.columns>`), and the types are those of
:data:`partcal.calibration.registry.MEASUREMENT_TYPES`: a type added there is read here with nothing more. The cell
YAML (what the cell knows of its planes and points, and of any type's own section) is read by :func:`read_cell`.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Collection, Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write
from .._validation import MAX_PAYLOAD_KG
from .._yamlio import Section, load_yaml
from ..calibration.cell import positive_problem
from ..calibration.checks import PLANNED
from ..calibration.measurement import MeasurementRows
from ..calibration.registry import END_TYPE, MEASUREMENT_TYPES, measurement_names
from ..errors import DataError
from ..robot.description import joint_columns, load_robot
from ..robot.kinematics import Robot
from .formats import ID, MEASUREMENT, OLD_MEASUREMENT, MeasurementFormat
from .measurements import MEASURED, PAYLOAD, csv_rows, delimiter_hint, joint_count, parse_number, read_table

log = logging.getLogger(__name__)

_EXAMPLE = "q1,...,q6,measurement,feature,distance_mm,to"


def has_measurement_column(path: str | Path, fmt: MeasurementFormat | None = None) -> bool:
    """Whether the CSV's header has a ``measurement`` column, or the column ``fmt`` maps ``measurement`` to (a measurement-type
    file, read by :func:`read_measurement_rows`; without it the file is a point CSV for ``read_measurements``).

    Only the header line is read; a missing or unreadable file raises :class:`~partcal.errors.DataError`.
    """
    fmt = fmt or MeasurementFormat()
    for number, cells in csv_rows(Path(path), fmt.delimiter):
        names = {c.strip() for c in cells}
        found = fmt.file_column(MEASUREMENT) in names or fmt.file_column(OLD_MEASUREMENT) in names
        hint = delimiter_hint([c.strip() for c in cells], fmt)
        if not found and hint and any(c in cells[0] for c in (fmt.file_column(MEASUREMENT), OLD_MEASUREMENT)):
            raise DataError(f"{path}:{number}: {hint}")
        return found
    return False


def read_measurement_rows(path: str | Path, robot: str | Robot | None = None, fmt: MeasurementFormat | None = None,
                      cell: Mapping | None = None, *, measurements: Collection[str] | None = None,
                      name: str | None = None, ids_elsewhere: Collection[str] = ()) -> MeasurementRows:
    """Read a measurements CSV (module docstring; ``docs/data.md``).

    Parameters
    ----------
    path : str or Path
    robot : str or Robot, optional
        The file's joint columns must be its joints.
    fmt : MeasurementFormat, optional
        Delimiter, decimal mark, column mapping (the types columns' too) and units of a foreign file
        (``length_unit: m`` converts ``distance_mm`` too), and its ``types``: the file's type values ->
        type names.
    cell : dict, optional
        What :func:`read_cell` returns: a plane row's ``feature`` must then be one of its ``planes``, a
        fixed row's one of its ``points``, and a distance row's ``to`` must name a row's ``id`` or one of
        its ``points`` (without cell, a ``to`` naming no row is taken for a point defined elsewhere).
    types : collection of str
        The type names accepted (the study layer passes its table's names).
    name : str, optional
        The data set's name; default the file stem.
    ids_elsewhere : collection of str
        Ids of rows in other files read with this one (a ballbar's poses in one file, its distances in another): a
        reference may name them too.

    Raises
    ------
    DataError
        One message naming the file, line, column, the bad value and what was expected: an unknown type, a
        duplicate id, a ``to`` naming nothing, a plane or fixed row's ``feature`` that the cell (given)
        do not list, a non-numeric number, an empty joint cell, a plane or fixed
        row without ``feature``, a distance row without ``distance_mm`` or ``to`` or with a distance <= 0,
        a ``flush`` other than 0 or 1, a point row without ``x_meas, y_meas, z_meas``, a payload out of range.
    """
    path = Path(path)
    fmt = fmt or MeasurementFormat()
    table = read_table(path, _EXAMPLE, fmt, measurements_file=True)
    header, seen, data = table.header, table.seen, table.data
    where = f"{path}:{table.line}"
    if MEASUREMENT not in seen and OLD_MEASUREMENT in seen:        # the column's name before partcal 0.2
        log.warning("%s: column %r: the old name of %r, read as it for this release: rename it (the old name will "
                    "be refused in the next)", where, header[seen[OLD_MEASUREMENT]], MEASUREMENT)
        seen[MEASUREMENT] = seen.pop(OLD_MEASUREMENT)
    if MEASUREMENT not in seen:
        raise DataError(f"{where}: column 'measurement' is missing: expected a measurements file "
                        f"(columns such as {_EXAMPLE}); a file without it is a point CSV")
    if not data:
        raise DataError(f"{where}: the header is not followed by any data row")
    n_q = joint_count(where, seen)
    model = load_robot(robot) if robot is not None else None
    if model is not None and model.n_joints != n_q:
        raise DataError(f"{path}: the file has {n_q} joint columns (q1..q{n_q}) but robot {model.name!r} has "
                        f"{model.n_joints} joints")
    for number, cells in data:
        if len(cells) != len(header):
            raise DataError(f"{path}:{number}: expected {len(header)} cells as in the header, got {len(cells)}")
    grid = _Cells(path, header, seen, data, fmt)
    joints = joint_columns(n_q)
    q = fmt.to_contract(joints, np.column_stack([grid.numbers(c, required=True) for c in joints]))
    written = grid.texts(MEASUREMENT)
    measurement = tuple(fmt.measurements.get(k, k) for k in written)
    known = tuple(measurement_names() if measurements is None else measurements)
    for r, k in enumerate(measurement):
        if k not in known:
            named = f" (the format's types name it {k!r})" if k != written[r] else ""
            grid.fail(r, MEASUREMENT, written[r], f"one of the types {', '.join(known)}{named}")
    numbers, texts = _columns(grid, seen, fmt)
    ids = _ids(grid, cell)
    _check_rows(grid, measurement, numbers, texts, ids, cell, set(ids_elsewhere))
    payload = numbers.get(PAYLOAD)
    return MeasurementRows(q_deg=q, types=measurement, ids=ids, lines=tuple(number for number, _ in data),
                            source=str(path), numbers=numbers, texts=texts,
                            payload_kg=None if payload is None or np.isnan(payload).all() else np.nan_to_num(payload),
                            name=name if name is not None else path.stem)


class _Cells:
    """One parsed file's cells by contract column, with refusals that name file, line, column and value."""

    def __init__(self, path: Path, header: list[str], seen: dict[str, int], data: list, fmt: MeasurementFormat):
        self.path, self.header, self.seen, self.data, self.fmt = path, header, seen, data, fmt
        self.decimal = fmt.decimal

    def label(self, column: str) -> str:
        """How messages name a column: ``'Length' (distance_mm)`` when the format maps it, ``'to'`` otherwise."""
        return self.header[self.seen[column]] if column in self.seen else self.fmt.label(column)

    def fail(self, row: int, column: str, value: str, expected: str):
        label = self.label(column)
        shown = "an empty cell" if value == "" else repr(value)
        raise DataError(f"{self.path}:{self.data[row][0]}: column {label}: expected {expected}, got {shown}")

    def texts(self, column: str) -> tuple[str, ...]:
        at = self.seen.get(column)
        return tuple("" if at is None else cells[at].strip() for _, cells in self.data)

    def numbers(self, column: str, required: bool = False) -> NDArray[np.float64]:
        """The column as floats, NaN for empty cells (refused when ``required``)."""
        at = self.seen[column]
        out = np.full(len(self.data), np.nan)
        for r, (number, cells) in enumerate(self.data):
            text = cells[at].strip()
            if text:
                out[r] = parse_number(self.path, number, self.header[at], text, self.decimal)
            elif required:
                self.fail(r, column, text, "a number (it is required on every row)")
        return out

    def is_numeric(self, column: str) -> bool:
        """Whether every filled cell of a column is a plain number (and at least one is filled)."""
        at = self.seen[column]
        filled = [(number, cells[at].strip()) for number, cells in self.data if cells[at].strip()]
        try:
            for number, text in filled:
                parse_number(self.path, number, self.header[at], text, self.decimal)
        except DataError:
            return False
        return bool(filled)


def declared_columns() -> dict:
    """Every column the measurement types declare (:attr:`MeasurementType.columns
    <partcal.calibration.measurement.MeasurementType.columns>`), by name (the first type's declaration of one)."""
    out = {}
    for cls in MEASUREMENT_TYPES.values():
        for name, column in cls.columns.items():
            out.setdefault(name, column)
    return out


def _columns(grid: _Cells, seen: dict[str, int], fmt: MeasurementFormat) -> tuple[dict, dict]:
    """Every column but the joints, ``measurement`` and ``id``: numbers (contract units: a declared column in mm is
    converted from a format's metres) and texts. A mapped file column is kept under its contract name only
    (``seen`` holds it under both)."""
    numbers, texts = {}, {}
    declared = declared_columns()
    text = {name for name, column in declared.items() if column.text} | {"set"}
    numeric = {name for name, column in declared.items() if not column.text} | set(MEASURED) | {PAYLOAD}
    mapped = {seen[c] for c in fmt.columns if c in seen}
    for column in seen:
        if column in (MEASUREMENT, ID) or re.fullmatch(r"q\d+", column) or (seen[column] in mapped and
                                                                     column not in fmt.columns):
            continue
        if column in text or (column not in numeric and not grid.is_numeric(column)):
            texts[column] = grid.texts(column)
            continue
        values = fmt.to_contract([column], grid.numbers(column)[:, None])[:, 0]
        if column not in MEASURED and column in declared and declared[column].unit == "mm" and fmt.length_unit == "m":
            values = values * 1000.0
        numbers[column] = values
    return numbers, texts


def _ids(grid: _Cells, cell: Mapping | None) -> tuple[str, ...]:
    given = grid.texts(ID)
    ids = tuple(text or str(r + 1) for r, text in enumerate(given))
    first: dict[str, int] = {}
    referred = {c.refers for cls in MEASUREMENT_TYPES.values() for c in cls.columns.values() if c.refers}
    points = {name for section in referred for name in (cell or {}).get(section, {})}
    for r, name in enumerate(ids):
        if name in first:
            grid.fail(r, ID, name, f"an id of its own (line {grid.data[first[name]][0]} has it already; a row "
                                   "without an id is named by its data-row number)")
        if name in points:
            grid.fail(r, ID, name, "an id that is not also a point of the cell (a 'to' naming it would "
                                   "be ambiguous)")
        first[name] = r
    return ids


def _check_rows(grid: _Cells, types: tuple, numbers: dict, texts: dict, ids: tuple, cell: Mapping | None,
                elsewhere: set = frozenset()):
    """Each row's own columns, as its type declares them: present where required, of the values it allows, naming
    an entry of the cell's section it names (when a cell is given), another row or an entry it refers to."""
    known_ids = set(ids) | elsewhere
    for r, k in enumerate(types):
        cls = MEASUREMENT_TYPES.get(k)
        if cls is None:
            continue
        required = [c for c, column in cls.columns.items() if column.required]
        for column, spec in cls.columns.items():
            if column not in texts and column not in numbers:
                if spec.required:
                    grid.fail(r, column, "", f"a value on a {k} row, but the file has no column {grid.label(column)} "
                                             f"({k} rows read {', '.join(required)})")
                continue
            value = texts[column][r] if column in texts else numbers[column][r]
            if value == "" or (not spec.text and np.isnan(value)):
                if spec.required:
                    grid.fail(r, column, "", f"a value on a {k} row ({k} rows read {', '.join(required)})")
                continue
            problem = spec.check(value) if spec.check is not None and not spec.text else None
            if problem:
                grid.fail(r, column, f"{value:g}", problem)
            if spec.refers is not None:
                _check_reference(grid, r, column, value, ids, known_ids, cell, spec.refers)
        if cls.cell_section and cls.feature_column and cell is not None and cls.cell_section in cell:
            names, name = cell[cls.cell_section], texts[cls.feature_column][r]
            if name not in names:
                listed = ", ".join(names) or "none"
                grid.fail(r, cls.feature_column, name, f"one of the {cls.cell_section} of the cell ({listed}; an "
                                                      "unknown one is listed as NAME: {})")
    if PAYLOAD in numbers:
        values = numbers[PAYLOAD]
        bad = np.flatnonzero((values < 0) | (values > MAX_PAYLOAD_KG))
        if bad.size:
            grid.fail(int(bad[0]), PAYLOAD, f"{values[bad[0]]:g}", f"a payload mass in [0, {MAX_PAYLOAD_KG:g}] kg")


def _check_reference(grid: _Cells, r: int, column: str, to: str, ids: tuple, known_ids: set, cell: Mapping | None,
                     section: str) -> None:
    """Column ``column`` of row ``r`` names another row's id, or (with a cell) an entry of its ``section``."""
    if to == ids[r]:
        grid.fail(r, column, to, "another row's id (a distance from a row to itself)")
    entries = None if cell is None else set(cell.get(section, {}))
    if entries is not None and to not in known_ids and to not in entries:
        listed = ", ".join(sorted(entries)) or "none"
        grid.fail(r, column, to, f"the id of a row of the file or a {section[:-1]} of the cell ({listed})")


def write_measurement_rows(table: MeasurementRows, path: str | Path, comment: str | None = None) -> None:
    """Write a measurements CSV that :func:`read_measurement_rows` reads back (atomically).

    Columns: ``q1..qN``, ``measurement``, ``id``, then the contract's columns present (``feature``, ``flush``,
    ``distance_mm``, ``to``, ``x_meas``, ``y_meas``, ``z_meas``, ``set``, ``payload_kg``), then any others
    in the table's order. Numbers get 6 decimals (``flush`` is written 0/1), NaN and ``""`` an empty cell;
    ``comment`` becomes ``#`` lines above the header.
    """
    order = ("feature", "flush", "distance_mm", "to", *MEASURED, "set", PAYLOAD)
    present = [c for c in order if c in table.numbers or c in table.texts]
    present += [c for c in (*table.numbers, *table.texts) if c not in present]
    header = joint_columns(table.q_deg.shape[1]) + [MEASUREMENT, ID] + present
    with atomic_write(path, newline="") as handle:
        for text in (comment or "").splitlines():
            handle.write(f"# {text}\n")
        handle.write(",".join(header) + "\n")
        for r in range(len(table)):
            cells = [f"{v:.6f}" for v in table.q_deg[r]] + [_quote(table.types[r]), _quote(table.ids[r])]
            for column in present:
                if column in table.texts:
                    cells.append(_quote(table.texts[column][r]))
                    continue
                v = table.numbers[column][r]
                cells.append("" if np.isnan(v) else f"{v:g}" if column in ("flush", PLANNED) else f"{v:.6f}")
            handle.write(",".join(cells) + "\n")


def _quote(text: str) -> str:
    if any(ch in text for ch in ',"\n\r') or text != text.strip():
        return '"' + text.replace('"', '""') + '"'
    return text


# ---------------------------------------------------------------------------------------------- cell YAML
def read_cell(path: str | Path) -> dict:
    """Read and validate a cell YAML: each measurement type's section (the planes, the points, a section of a type
    added outside partcal: :attr:`MeasurementType.cell_section <partcal.calibration.measurement.MeasurementType.
    cell_section>`, read by the type) and each type's noise (in its unit).

    Returns ``{"planes": {name: {...}}, "points": {name: {...}}, ..., "noise": {type: noise}}``, every section of
    the table's types present (empty when the file has none). A plane is ``{}`` (unknown), ``{"normal": [nx, ny,
    nz] (unit), "offset_mm": d}`` (approximately known: the plane ``n . p = d`` in the base frame, the fit's start)
    or ``{"parallel_to": NAME, "spacing_mm": s}`` (tied: that plane's normal, its offset plus ``s``); a point is
    ``{}`` (unknown), ``{"known_mm": [x, y, z]}`` (known in the base frame) or ``{"distance_to": NAME,
    "distance_mm": d}`` (tied by a known distance).

    Raises
    ------
    ConfigError
        Naming the key's path and line: an unknown key (a section no type reads among them), a zero normal, a
        number that is not finite, a ``parallel_to`` or ``distance_to`` naming itself or no entry of its section, a
        cycle of them, a noise for an unknown type.
    """
    data, lines = load_yaml(path)
    top = Section(data, "", lines, str(path))
    out = cell_from_section(top)
    top.done()
    return out


def cell_from_section(top: Section) -> dict:
    """:func:`read_cell` of a mapping already loaded (each type's section and ``noise`` of ``top``; ``noise_mm``,
    its old name, read for one release)."""
    out = {}
    for cls in MEASUREMENT_TYPES.values():
        for section in (cls.cell_section, *cls.extra_sections):
            if section and section not in out:
                sec = top.section(section)
                out[section] = (cls.read_section(sec) if section == cls.cell_section else
                                cls.read_extra_section(section, sec))
                sec.done()
    top.renamed("noise_mm", "noise")
    noise, names = top.section("noise"), [n for n in measurement_names() if n != END_TYPE]
    out["noise"] = {}
    for name in list(noise.data):
        if name not in names:
            noise.fail(noise.path(str(name)), f"unknown type; expected one of {', '.join(names)}")
        out["noise"][name] = noise.get(name, "float", check=positive_problem)
    noise.done()
    return out
