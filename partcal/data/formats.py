"""Foreign measurement files: delimiter, decimal mark, column names, units, and row subsets.

A :class:`MeasurementFormat` says how a file differs from the measurement CSV
contract (``docs/data.md``): its delimiter and decimal mark, which of its
columns hold the contract's columns, and the units of its joint angles and
lengths. The readers in :mod:`partcal.data.measurements` and
:mod:`partcal.data.measurement_rows` apply it, so values are converted once, at
the boundary, to degrees and millimetres. For a measurements file it also
maps its columns (``measurement``, ``feature``, ``distance_mm``..) and the
file's type values (``measurements``).

A :class:`RowSelection` picks data rows of a file (``rows: "1-600"``,
``every: 5``), for instance a subset of a large series for identification.

Examples
--------
>>> fmt = MeasurementFormat(delimiter=";", decimal=",", columns={"q1": "axis_1"}, joint_unit="rad")
>>> fmt.file_column("q1"), fmt.file_column("q2")
('axis_1', 'q2')
>>> RowSelection.parse("1-3, 7").indices(10, "f.csv").tolist()
[0, 1, 2, 6]
>>> RowSelection.parse("1-3, 7", every=2).indices(10, "f.csv").tolist()
[0, 2]
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .._validation import one_of
from ..calibration.registry import MEASUREMENT_TYPES
from .._yamlio import Section, load_yaml
from ..errors import ConfigError, DataError
from ..robot.description import MAX_JOINTS

JOINTS = tuple(f"q{j}" for j in range(1, MAX_JOINTS + 1))
LENGTHS = ("x_nom", "y_nom", "z_nom", "x_meas", "y_meas", "z_meas", "x", "y", "z")
ORIENTATIONS = ("rx_meas", "ry_meas", "rz_meas", "rx_nom", "ry_nom", "rz_nom")
STDS = ("std_x", "std_y", "std_z")      # the measured position's standard deviation per coordinate (a length)
CONTRACT_COLUMNS = JOINTS + LENGTHS + ORIENTATIONS + STDS + ("set", "payload_kg")
MEASUREMENT, ID = "measurement", "id"
OLD_MEASUREMENT = "kind"
"""The measurements file's column of each row's type: ``measurement`` (``kind`` read for one release)."""


def measurement_columns() -> tuple[str, ...]:
    """A measurements file's columns beyond the point contract's: ``measurement``, ``id`` and those the measurement
    types declare (:data:`partcal.calibration.registry.MEASUREMENT_TYPES`, read when asked: a type added there is
    known here)."""
    declared = (c for cls in MEASUREMENT_TYPES.values() for c in cls.columns if not is_contract_column(c))
    return (MEASUREMENT, ID, *dict.fromkeys(declared))


TARGET_COLUMN = re.compile(r"^([xyz]_(?:meas|nom))@(.*)$")
TARGET_NAME = re.compile(r"^[A-Za-z0-9_]+$")
JOINT_UNITS = ("deg", "rad")
LENGTH_UNITS = ("mm", "m")
ORIENTATION_UNITS = ("deg", "rad")
_RANGE = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")
ROWS_EXPECTED = "data rows such as '1-600' or '1-100, 201-300' (1-based, increasing, not overlapping)"


@dataclass(frozen=True)
class MeasurementFormat:
    """How a measurement file differs from the contract (comma, decimal point, degrees, mm).

    Parameters
    ----------
    delimiter : str
        One character between cells (default ``","``); not a quote or a line break.
    decimal : str
        The decimal mark, ``"."`` (default) or ``","``; must differ from ``delimiter``.
    columns : mapping of str to str
        Contract column (``q1``..``q12``, ``x_nom``.., ``x_meas``.., a target's
        ``x_meas@B``.., ``rx_meas``.., ``rx_nom``.., ``x, y, z``, ``set``, and
        a measurements file's ``measurement, id, feature, to, target,
        distance_mm, flush``) -> the file's column that holds it. Unmapped contract columns
        are looked up under their own name; unmapped file columns are ignored.
        One format may serve a run's point CSVs and measurements files: which mapped
        columns a file must have is :func:`file_must_have`.
    joint_unit : {"deg", "rad"}
        Unit of the joint columns in the file.
    length_unit : {"mm", "m"}
        Unit of the position columns in the file.
    orientation_unit : {"deg", "rad"}
        Unit of the orientation columns (intrinsic XYZ angles) in the file.
    measurements : mapping of str to str
        A measurements file's ``measurement`` values -> partcal's type names
        (``{"Plane": "plane", "Sphere": "fixed"}``); an unmapped value is read
        as written. The reader checks the names against its types.
    """

    delimiter: str = ","
    decimal: str = "."
    columns: Mapping[str, str] = field(default_factory=dict)
    joint_unit: str = "deg"
    length_unit: str = "mm"
    orientation_unit: str = "deg"
    measurements: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self):
        problem = _format_problem(self.delimiter, self.decimal, self.columns, self.joint_unit, self.length_unit,
                                  self.orientation_unit, self.measurements)
        if problem:
            name = f"{problem.key!r} parameter" if problem.entry is None else f"{problem.key!r} entry {problem.entry!r}"
            raise ConfigError(f"The {name} of MeasurementFormat must be {problem.expected}. "
                              f"Got {problem.got!r}{problem.note} instead.")
        object.__setattr__(self, "columns", dict(self.columns))
        object.__setattr__(self, "measurements", dict(self.measurements))

    def file_column(self, contract: str) -> str:
        """The file's name of a contract column (itself when unmapped)."""
        return self.columns.get(contract, contract)

    def label(self, contract: str) -> str:
        """How messages name a column: ``'smr_x' (x_meas)`` when mapped, ``'x_meas'`` otherwise."""
        mapped = self.columns.get(contract)
        return f"{mapped!r} ({contract})" if mapped is not None and mapped != contract else repr(contract)

    def to_contract(self, names: list[str], values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Convert columns ``names`` of ``values`` (n, k) to degrees and millimetres (a new array)."""
        out = np.array(values, dtype=float)
        for k, name in enumerate(names):
            if name in JOINTS and self.joint_unit == "rad":
                out[:, k] = np.degrees(out[:, k])
            elif _is_length(name) and self.length_unit == "m":
                out[:, k] = out[:, k] * 1000.0
            elif name in ORIENTATIONS and self.orientation_unit == "rad":
                out[:, k] = np.degrees(out[:, k])
        return out

    @property
    def is_contract(self) -> bool:
        """True when the format changes nothing (the contract itself)."""
        return self == MeasurementFormat()

    def to_dict(self) -> dict:
        """Plain types, as in the YAML (``measurements`` only when given)."""
        return {"delimiter": self.delimiter, "decimal": self.decimal, "columns": dict(self.columns),
                "joint_unit": self.joint_unit, "length_unit": self.length_unit,
                "orientation_unit": self.orientation_unit,
                **({"measurements": dict(self.measurements)} if self.measurements else {})}

    @classmethod
    def from_section(cls, sec: Section) -> "MeasurementFormat":
        """Read the format keys of a YAML mapping; errors name the key path and line.

        The rules are those of the constructor (:func:`_format_problem`), framed
        as ``key (line N): must be ...; got ...``.
        """
        values = {key: sec.get(key, "str", default=default) for key, default in
                  (("delimiter", ","), ("decimal", "."), ("joint_unit", "deg"), ("length_unit", "mm"),
                   ("orientation_unit", "deg"))}
        cols = sec.section("columns")
        cols.renamed(OLD_MEASUREMENT, MEASUREMENT)
        values["columns"] = {str(key): _stripped(cols.get(key, "str")) for key in list(cols.data)}
        sec.renamed("kinds", "measurements")
        measurements = sec.section("measurements")
        values["measurements"] = {str(key): _stripped(measurements.get(key, "str")) for key in list(measurements.data)}
        problem = _format_problem(**values)
        if problem:
            where = problem.key if problem.entry is None else f"{problem.key}.{problem.entry}"
            sec.fail(sec.path(where), f"must be {problem.expected}; got {problem.got!r}{problem.note}")
        sec.done()
        return cls(**values)


def load_format(path: str | Path) -> MeasurementFormat:
    """Read a format YAML file: the keys of ``data.format`` at its top level (``partcal ... --format``)."""
    data, lines = load_yaml(path)
    return MeasurementFormat.from_section(Section(data, "", lines, str(path)))


def _stripped(name: str) -> str:
    """A file column name from YAML without surrounding blanks (a blank name stays as written, to be refused)."""
    return name.strip() or name


class _Problem(NamedTuple):
    """A broken format rule: ``key`` (and ``entry`` of ``columns``) must be ``expected``; got ``got`` (``note``)."""

    key: str
    entry: Any
    expected: str
    got: Any
    note: str = ""


def _format_problem(delimiter: Any, decimal: Any, columns: Any, joint_unit: Any, length_unit: Any,
                    orientation_unit: Any = "deg", measurements: Any = None) -> _Problem | None:
    """The first format rule the values break, or None: each rule is checked here and only here.

    Both ways of making a format use it: the constructor frames the problem
    scikit-learn style, :meth:`MeasurementFormat.from_section` with the YAML key
    path and line.
    """
    if not isinstance(delimiter, str) or len(delimiter) != 1 or delimiter in "\"\r\n":
        return _Problem("delimiter", None, "one character other than a quote or a line break (e.g. ',', ';' or "
                                           "\"\\t\")", delimiter)
    if one_of(".", ",").problem(decimal):
        return _Problem("decimal", None, one_of(".", ",").expected, decimal)
    if decimal == delimiter:
        return _Problem("decimal", None, f"different from the delimiter {delimiter!r}", decimal)
    for key, value, allowed in (("joint_unit", joint_unit, JOINT_UNITS), ("length_unit", length_unit, LENGTH_UNITS),
                                ("orientation_unit", orientation_unit, ORIENTATION_UNITS)):
        if one_of(*allowed).problem(value):
            return _Problem(key, None, one_of(*allowed).expected, value)
    if not isinstance(columns, Mapping):
        return _Problem("columns", None, "a mapping of contract column to file column", columns)
    for key, value in columns.items():
        if not is_contract_column(key) and key not in measurement_columns():
            close = _close(str(key))
            return _Problem("columns", key, f"a contract column (q1..q{MAX_JOINTS}, x_nom, y_nom, z_nom, x_meas, "
                                            "y_meas, z_meas, x_meas@NAME.., rx_meas, ry_meas, rz_meas, rx_nom, "
                                            "ry_nom, rz_nom, x, y, z, std_x, std_y, std_z, set, "
                                            f"payload_kg) or a measurement-type column ({', '.join(measurement_columns())})",
                            key, f" (did you mean {close[0]!r}?)" if close else "")
        if not isinstance(value, str) or not value.strip():
            return _Problem("columns", key, "a non-empty file column name", value)
    return _mapping_problem(columns) or _measurements_problem({} if measurements is None else measurements)


def _measurements_problem(measurements: Any) -> _Problem | None:
    """The first broken rule of ``measurements``: a mapping of the file's type value to a type name, both non-empty
    texts (whether the name is a type is the reader's to say: the data layer does not know the models' types)."""
    if not isinstance(measurements, Mapping):
        return _Problem("measurements", None, "a mapping of the file's type value to a type name", measurements)
    for key, value in measurements.items():
        if not isinstance(key, str) or not key.strip():
            return _Problem("measurements", key, "a non-empty type value of the file", key)
        if not isinstance(value, str) or not value.strip():
            return _Problem("measurements", key, "a non-empty type name (point, plane, fixed, distance, pose, ...)", value)
    return None


def _close(key: str) -> list[str]:
    """The mappable column a misspelt key most likely meant (``[]``: none): a point column as always, else a
    measurements file's columns at a stricter cutoff (so that ``temperature`` is not taken for ``feature``)."""
    return (difflib.get_close_matches(key, CONTRACT_COLUMNS, n=1, cutoff=0.6)
            or difflib.get_close_matches(key, measurement_columns(), n=1, cutoff=0.7))


def file_must_have(contract: str, measurements_file: bool) -> bool:
    """Whether a file must have the column that a format maps ``contract`` to (it is refused naming both when it
    has not): one format may serve a run's point CSVs and measurements files.

    A point CSV must have its contract's mapped columns, not a measurements file's (``measurement``, ``feature``..); a
    measurements file its joints and ``measurement``, while every other column (a type's, ``x_meas``.., ``set``,
    ``payload_kg``) is read when present: a row whose type requires it is refused naming the mapped column, so a
    ballbar's export need not carry a plane's ``feature``.

    >>> file_must_have("measurement", measurements_file=False), file_must_have("x_meas", measurements_file=True)
    (False, False)
    >>> file_must_have("x_meas", measurements_file=False), file_must_have("feature", measurements_file=True)
    (True, False)
    """
    if measurements_file:
        return contract in JOINTS or contract == MEASUREMENT
    return contract not in measurement_columns()


def is_contract_column(name: Any) -> bool:
    """Whether ``name`` is a contract column: a fixed one, or a target's coordinate such as ``x_meas@B``.

    >>> is_contract_column("y_nom@C"), is_contract_column("x_meas@"), is_contract_column("w_meas@B")
    (True, False, False)
    """
    if not isinstance(name, str):
        return False
    target = TARGET_COLUMN.match(name)
    return name in CONTRACT_COLUMNS or (target is not None and TARGET_NAME.match(target.group(2)) is not None)


def _is_length(name: str) -> bool:
    """A position column: ``x_meas``, ``x``, ``y_nom@B`` ..."""
    target = TARGET_COLUMN.match(name)
    return name in LENGTHS or name in STDS or target is not None


def _mapping_problem(columns: Mapping[str, str]) -> _Problem | None:
    """The first contract column whose file column also holds another contract column.

    Two contract columns mapped to one file column, or mapped to the name of
    a contract column that is not mapped (and so is read under its own name:
    ``{x_meas: q1}`` would read q1 twice). The measurements file's own columns
    (``measurement``, ``id``, ``feature``..) count as contract columns here only in a
    format that maps one of them (a format for measurements files), so that a point
    format mapping, say, ``set`` to a column ``id`` stays valid.
    """
    one = "a file column that holds no other contract column"
    measurements = any(key in measurement_columns() for key in columns)
    owner: dict[str, str] = {}
    for key, value in columns.items():
        if value in owner:
            return _Problem("columns", key, one, value, f" (already mapped to {owner[value]})")
        owner[value] = key
    for key, value in columns.items():
        if (is_contract_column(value) or (measurements and value in measurement_columns())) and value != key and value not in columns:
            return _Problem("columns", key, one, value, f" (the contract column {value} is not mapped, so it is "
                                                        f"read under its own name: map {value} too)")
    return None


@dataclass(frozen=True)
class RowSelection:
    """Data rows to keep: 1-based inclusive ranges (all rows when empty), then every ``every``-th.

    Rows count data lines only (the first line after the header is row 1;
    comments and blank lines do not count).
    """

    ranges: tuple[tuple[int, int], ...] = ()
    every: int = 1

    def __post_init__(self):
        problem = _every_problem(self.every)
        if problem:
            raise ConfigError(f"The 'every' parameter of RowSelection must be {problem}. Got {self.every!r} instead.")
        if not _increasing(self.ranges):
            raise _bad_rows(self.text)

    @classmethod
    def parse(cls, text: str | None, every: int = 1) -> "RowSelection":
        """From text such as ``"1-600"`` or ``"1-100, 201-300, 400"``."""
        if text is None:
            return cls((), every)
        ranges = _ranges(text)
        if ranges is None:
            raise _bad_rows(text)
        return cls(ranges, every)

    @property
    def text(self) -> str | None:
        """The ranges as text (``None`` for all rows)."""
        if not self.ranges:
            return None
        return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in self.ranges)

    @property
    def is_all(self) -> bool:
        return not self.ranges and self.every == 1

    def indices(self, n_rows: int, source: str | Path) -> NDArray[np.intp]:
        """0-based indices of the kept rows of a file with ``n_rows`` data rows."""
        if self.ranges:
            high = self.ranges[-1][1]
            if high > n_rows:
                raise DataError(f"{source}: rows {self.text!r} asks for data row {high}, but the file has "
                                f"{n_rows} data rows")
            chosen = np.concatenate([np.arange(a - 1, b) for a, b in self.ranges])
        else:
            chosen = np.arange(n_rows)
        return chosen[::self.every]

    def to_dict(self) -> dict:
        return {"rows": self.text, "every": self.every}

    @classmethod
    def from_section(cls, sec: Section) -> "RowSelection":
        """Read ``rows`` and ``every`` of a YAML mapping (other keys are the caller's)."""
        text = sec.get("rows", "str", default=None, check=lambda t: None if _ranges(t) is not None else ROWS_EXPECTED)
        every = sec.get("every", "int", default=1, check=_every_problem)
        return cls.parse(text, every)


def _every_problem(every: Any) -> str | None:
    """What ``every`` must be, or None when it is: an int >= 1 (bools are not ints here)."""
    ok = isinstance(every, int) and not isinstance(every, bool) and every >= 1
    return None if ok else "an int >= 1"


def _increasing(ranges: tuple[tuple[int, int], ...]) -> bool:
    """The rows rule: 1-based ``(first, last)`` ranges, each ``first <= last``, increasing, not overlapping."""
    last = 0
    for low, high in ranges:
        if not 1 <= low <= high or low <= last:
            return False
        last = high
    return True


def _ranges(text: str) -> tuple[tuple[int, int], ...] | None:
    """The ranges of ``"1-100, 201-300, 400"``, or None when the text does not follow the rows rule."""
    ranges = []
    for part in text.split(","):
        m = _RANGE.match(part)
        if not m:
            return None
        low = int(m.group(1))
        ranges.append((low, int(m.group(2)) if m.group(2) else low))
    return tuple(ranges) if _increasing(tuple(ranges)) else None


def _bad_rows(text: str | None) -> ConfigError:
    return ConfigError(f"The 'rows' parameter of RowSelection must be {ROWS_EXPECTED}. Got {text!r} instead.")
