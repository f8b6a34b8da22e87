"""Foreign measurement files: delimiter, decimal mark, column names, units, and row subsets.

A :class:`MeasurementFormat` says how a file differs from the measurement CSV
contract (``docs/data.md``): its delimiter and decimal mark, which of its
columns hold the contract's columns, and the units of its joint angles and
lengths. The reader in :mod:`partcal.data.measurements` applies it, so values
are converted once, at the boundary, to degrees and millimetres.

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
from typing import Mapping

import numpy as np
from numpy.typing import NDArray

from .._yamlio import Section, load_yaml, range_check
from ..errors import ConfigError, DataError
from ..robot.description import MAX_JOINTS

JOINTS = tuple(f"q{j}" for j in range(1, MAX_JOINTS + 1))
LENGTHS = ("x_nom", "y_nom", "z_nom", "x_meas", "y_meas", "z_meas", "x", "y", "z")
CONTRACT_COLUMNS = JOINTS + LENGTHS + ("set",)
JOINT_UNITS = ("deg", "rad")
LENGTH_UNITS = ("mm", "m")
_RANGE = re.compile(r"^\s*(\d+)\s*(?:-\s*(\d+)\s*)?$")


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
        Contract column (``q1``..``q12``, ``x_nom``.., ``x_meas``.., ``x, y, z``,
        ``set``) -> the file's column that holds it. Unmapped contract columns
        are looked up under their own name; unmapped file columns are ignored.
    joint_unit : {"deg", "rad"}
        Unit of the joint columns in the file.
    length_unit : {"mm", "m"}
        Unit of the position columns in the file.
    """

    delimiter: str = ","
    decimal: str = "."
    columns: Mapping[str, str] = field(default_factory=dict)
    joint_unit: str = "deg"
    length_unit: str = "mm"

    def __post_init__(self):
        problem = _format_problem(self)
        if problem:
            key, expected, got = problem
            raise ConfigError(f"The {key!r} parameter of MeasurementFormat must be {expected}. Got {got!r} instead.")
        object.__setattr__(self, "columns", dict(self.columns))

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
            elif name in LENGTHS and self.length_unit == "m":
                out[:, k] = out[:, k] * 1000.0
        return out

    @property
    def is_contract(self) -> bool:
        """True when the format changes nothing (the contract itself)."""
        return self == MeasurementFormat()

    def to_dict(self) -> dict:
        """Plain types, as in the YAML."""
        return {"delimiter": self.delimiter, "decimal": self.decimal, "columns": dict(self.columns),
                "joint_unit": self.joint_unit, "length_unit": self.length_unit}

    @classmethod
    def from_section(cls, sec: Section) -> "MeasurementFormat":
        """Read the format keys of a YAML mapping; errors name the key path and line."""
        delimiter = sec.get("delimiter", "str", default=",", check=_delimiter_check)
        decimal = sec.get("decimal", "str", default=".",
                          check=lambda v: None if v in (".", ",") else "'.' or ','")
        if decimal == delimiter:
            sec.fail(sec.path("decimal"), f"must differ from the delimiter {delimiter!r}; got {decimal!r}")
        joint_unit = sec.get("joint_unit", "str", default="deg", check=_one_of(JOINT_UNITS))
        length_unit = sec.get("length_unit", "str", default="mm", check=_one_of(LENGTH_UNITS))
        columns = _columns(sec.section("columns"))
        sec.done()
        return cls(delimiter=delimiter, decimal=decimal, columns=columns, joint_unit=joint_unit,
                   length_unit=length_unit)


def load_format(path: str | Path) -> MeasurementFormat:
    """Read a format YAML file: the keys of ``data.format`` at its top level (``partcal ... --format``)."""
    data, lines = load_yaml(path)
    return MeasurementFormat.from_section(Section(data, "", lines, str(path)))


def _columns(sec: Section) -> dict[str, str]:
    out: dict[str, str] = {}
    for key in list(sec.data):
        name = str(key)
        if name not in CONTRACT_COLUMNS:
            close = difflib.get_close_matches(name, CONTRACT_COLUMNS, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            sec.fail(sec.path(name), f"not a contract column (q1..q{MAX_JOINTS}, x_nom, y_nom, z_nom, x_meas, "
                                     f"y_meas, z_meas, x, y, z, set){hint}")
        value = sec.get(key, "str", check=lambda v: None if v.strip() else "a non-empty column name")
        out[name] = value.strip()
    problem = _mapping_problem(out)
    if problem:
        sec.fail(sec.path(problem[0]), problem[1])
    sec.done()
    return out


def _mapping_problem(columns: Mapping[str, str]) -> tuple[str, str] | None:
    """The first contract column whose file column also holds another contract column, and why.

    Two contract columns mapped to one file column, or mapped to the name of
    a contract column that is not mapped (and so is read under its own name:
    ``{x_meas: q1}`` would read q1 twice).
    """
    owner: dict[str, str] = {}
    for key, value in columns.items():
        if value in owner:
            return key, (f"column {value!r} is already mapped to {owner[value]}; each file column can hold one "
                         "contract column")
        owner[value] = key
    for key, value in columns.items():
        if value in CONTRACT_COLUMNS and value != key and value not in columns:
            return key, (f"column {value!r} is also read as {value} (a contract column not mapped is read under "
                         f"its own name); each file column can hold one contract column: map {value} too")
    return None


def _delimiter_check(value: str) -> str | None:
    if len(value) != 1 or value in "\"\r\n":
        return "one character other than a quote or a line break (e.g. ',', ';' or \"\\t\")"
    return None


def _one_of(allowed: tuple[str, ...]):
    def check(value):
        return None if value in allowed else "one of " + ", ".join(repr(a) for a in allowed)
    return check


def _format_problem(fmt: MeasurementFormat) -> tuple[str, str, object] | None:
    """The first bad parameter of a format built in Python, as ``(key, expected, got)``."""
    if not isinstance(fmt.delimiter, str) or _delimiter_check(fmt.delimiter):
        return "delimiter", "one character other than a quote or a line break", fmt.delimiter
    if fmt.decimal not in (".", ","):
        return "decimal", "'.' or ','", fmt.decimal
    if fmt.decimal == fmt.delimiter:
        return "decimal", f"different from the delimiter {fmt.delimiter!r}", fmt.decimal
    if fmt.joint_unit not in JOINT_UNITS:
        return "joint_unit", "'deg' or 'rad'", fmt.joint_unit
    if fmt.length_unit not in LENGTH_UNITS:
        return "length_unit", "'mm' or 'm'", fmt.length_unit
    if not isinstance(fmt.columns, Mapping):
        return "columns", "a mapping of contract column to file column", fmt.columns
    for key, value in fmt.columns.items():
        if key not in CONTRACT_COLUMNS:
            return "columns", "a mapping whose keys are contract columns", key
        if not isinstance(value, str) or not value.strip():
            return "columns", "a mapping to non-empty file column names", value
    problem = _mapping_problem(fmt.columns)
    if problem:
        return "columns", f"a mapping where each file column holds one contract column ({problem[1]})", fmt.columns
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
        if not isinstance(self.every, int) or isinstance(self.every, bool) or self.every < 1:
            raise ConfigError(f"The 'every' parameter of RowSelection must be an int >= 1. Got {self.every!r} instead.")
        last = 0
        for low, high in self.ranges:
            if not 1 <= low <= high or low <= last:
                raise ConfigError(f"The 'ranges' parameter of RowSelection must hold increasing, non-overlapping "
                                  f"1-based ranges. Got {self.text!r} instead.")
            last = high

    @classmethod
    def parse(cls, text: str | None, every: int = 1) -> "RowSelection":
        """From text such as ``"1-600"`` or ``"1-100, 201-300, 400"``."""
        if text is None:
            return cls((), every)
        ranges = []
        for part in text.split(","):
            m = _RANGE.match(part)
            if not m:
                raise ConfigError(f"cannot read {part.strip()!r}: expected N or N-M (1-based data rows)")
            low = int(m.group(1))
            ranges.append((low, int(m.group(2)) if m.group(2) else low))
        return cls(tuple(ranges), every)

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
        text = sec.get("rows", "str", default=None)
        every = sec.get("every", "int", default=1, check=range_check(1, integer=True))
        try:
            return cls.parse(text, every)
        except ConfigError:
            sec.fail(sec.path("rows"), f"must be data rows such as '1-600' or '1-100, 201-300' (1-based, "
                                       f"increasing, not overlapping); got {text!r}")
