"""Measurement kinds in one CSV: plane contacts, fixed points, distances, tracker points, poses.

A measurement CSV with a ``kind`` column holds one row per observation (``docs/data.md``, "Measurement
kinds"): ``q1..qN`` (degrees) on every row, the row's ``kind`` and the columns that kind reads:

========== ===========================================================================================
kind       reads
========== ===========================================================================================
point      ``x_meas, y_meas, z_meas``: a tracker point in the base frame, mm
plane      ``feature`` (the plane's name), ``flush`` (optional 0/1: a flat face of the tool on the plane)
fixed      ``feature`` (the fixed point's name)
distance   ``distance_mm`` (> 0) and ``to`` (another row's ``id``, or a point of the features)
pose       nothing: joints only, a pose other rows' ``to`` name
========== ===========================================================================================

plus the optional ``id`` (a row's name; default its 1-based data-row number), ``set`` and ``payload_kg``.
Any other column is kept: as numbers when every filled cell is a number, as texts otherwise (a kind added
outside partcal reads its own columns from there). A file without ``kind`` is the usual point CSV
(:mod:`partcal.data.measurements`); :func:`has_kind_column` tells them apart.

The data layer does not know the models' table of kinds: the kind names a reader accepts are a parameter
(``kinds``; default :data:`BUILTIN_KINDS`), the study layer passes the table's names.

The features YAML (what the cell knows of its planes and points) is read by :func:`read_features`.
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write
from .._validation import MAX_PAYLOAD_KG
from .._yamlio import Section, load_yaml
from ..errors import DataError
from ..robot.description import joint_columns, load_robot
from ..robot.kinematics import Robot
from .formats import ID, KIND, KINDS_NUMBERS, KINDS_TEXTS, MeasurementFormat
from .measurements import MEASURED, PAYLOAD, csv_rows, joint_count, parse_number, read_table

BUILTIN_KINDS = ("point", "plane", "fixed", "distance", "pose")
"""The kinds partcal itself defines (``partcal.calibration.registry`` implements them)."""
NUMERIC = (*KINDS_NUMBERS, *MEASURED, PAYLOAD)
"""The contract's numeric columns (each present one is in :attr:`ObservationTable.numbers`)."""
TEXT = (*KINDS_TEXTS, "set")
"""The contract's text columns (each present one is in :attr:`ObservationTable.texts`)."""
READS = {"point": MEASURED, "plane": ("feature",), "fixed": ("feature",), "distance": ("distance_mm", "to"),
         "pose": ()}
"""The columns each built-in kind requires on its rows."""
FEATURE_OF = {"plane": "planes", "fixed": "points"}
"""The section of the features YAML that a row's ``feature`` names, by kind."""
FEATURE_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")
_EXAMPLE = "q1,...,q6,kind,feature,distance_mm,to"


@dataclass(frozen=True, eq=False)
class ObservationTable:
    """The rows of a measurement-kinds CSV, as plain arrays (the study layer turns them into kinds).

    Attributes
    ----------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    kind : tuple of str, (n,)
        Each row's kind.
    ids : tuple of str, (n,)
        Each row's name (the ``id`` column, or its 1-based data-row number as text).
    lines : tuple of int, (n,)
        The line of each row as an editor shows it (for messages).
    source : str
        The file as given (for messages).
    numbers : dict of str to ndarray (n,)
        Every numeric column present (``distance_mm``, ``flush``, ``x_meas``, ..., ``payload_kg`` and
        numeric columns of other names), in mm and degrees; NaN where a cell is empty.
    texts : dict of str to tuple of str (n,)
        Every text column present (``feature``, ``to``, ``set`` and text columns of other names); ``""``
        where a cell is empty.
    name : str
        The data set's name (the file stem by default).
    """

    q_deg: NDArray[np.float64]
    kind: tuple[str, ...]
    ids: tuple[str, ...]
    lines: tuple[int, ...]
    source: str
    numbers: dict = field(default_factory=dict)
    texts: dict = field(default_factory=dict)
    name: str = "observations"

    def __post_init__(self):
        q = np.asarray(self.q_deg, dtype=float)
        n = q.shape[0] if q.ndim == 2 else -1
        if n < 1 or not np.isfinite(q).all():
            raise DataError(f"Expected q_deg with shape (n, N), n >= 1, finite degrees, got shape {q.shape}")
        for what, values in (("kind", self.kind), ("ids", self.ids), ("lines", self.lines),
                             *self.texts.items()):
            if len(values) != n:
                raise DataError(f"Expected {what} with {n} entries (one per row of q_deg), got {len(values)}")
        numbers = {k: np.asarray(v, dtype=float) for k, v in self.numbers.items()}
        bad = next((k for k, v in numbers.items() if v.shape != (n,)), None)
        if bad is not None:
            raise DataError(f"Expected numbers[{bad!r}] with shape ({n},), got {numbers[bad].shape}")
        object.__setattr__(self, "q_deg", q)
        object.__setattr__(self, "numbers", numbers)
        object.__setattr__(self, "texts", {k: tuple(v) for k, v in self.texts.items()})
        for attr in ("kind", "ids", "lines"):
            object.__setattr__(self, attr, tuple(getattr(self, attr)))

    def __len__(self) -> int:
        return self.q_deg.shape[0]

    def rows_of(self, kind: str) -> NDArray[np.intp]:
        """0-based indices of the rows of one kind."""
        return np.flatnonzero(np.asarray(self.kind, dtype=object) == kind)


def has_kind_column(path: str | Path, fmt: MeasurementFormat | None = None) -> bool:
    """Whether the CSV's header has a ``kind`` column, or the column ``fmt`` maps ``kind`` to (a measurement-kinds
    file, read by :func:`read_observations`; without it the file is a point CSV for ``read_measurements``).

    Only the header line is read; a missing or unreadable file raises :class:`~partcal.errors.DataError`.
    """
    fmt = fmt or MeasurementFormat()
    for _, cells in csv_rows(Path(path), fmt.delimiter):
        return fmt.file_column(KIND) in (c.strip() for c in cells)
    return False


def read_observations(path: str | Path, robot: str | Robot | None = None, fmt: MeasurementFormat | None = None,
                      features: Mapping | None = None, *, kinds: Collection[str] = BUILTIN_KINDS,
                      name: str | None = None) -> ObservationTable:
    """Read a measurement-kinds CSV (module docstring; ``docs/data.md``).

    Parameters
    ----------
    path : str or Path
    robot : str or Robot, optional
        The file's joint columns must be its joints.
    fmt : MeasurementFormat, optional
        Delimiter, decimal mark, column mapping (the kinds columns' too) and units of a foreign file
        (``length_unit: m`` converts ``distance_mm`` too), and its ``kinds``: the file's kind values ->
        kind names.
    features : dict, optional
        What :func:`read_features` returns: a plane row's ``feature`` must then be one of its ``planes``, a
        fixed row's one of its ``points``, and a distance row's ``to`` must name a row's ``id`` or one of
        its ``points`` (without features, a ``to`` naming no row is taken for a point defined elsewhere).
    kinds : collection of str
        The kind names accepted (the study layer passes its table's names).
    name : str, optional
        The data set's name; default the file stem.

    Raises
    ------
    DataError
        One message naming the file, line, column, the bad value and what was expected: an unknown kind, a
        duplicate id, a ``to`` naming nothing, a plane or fixed row's ``feature`` that the features (given)
        do not list, a non-numeric number, an empty joint cell, a plane or fixed
        row without ``feature``, a distance row without ``distance_mm`` or ``to`` or with a distance <= 0,
        a ``flush`` other than 0 or 1, a point row without ``x_meas, y_meas, z_meas``, a payload out of range.
    """
    path = Path(path)
    fmt = fmt or MeasurementFormat()
    table = read_table(path, _EXAMPLE, fmt, kinds_file=True)
    header, seen, data = table.header, table.seen, table.data
    where = f"{path}:{table.line}"
    if KIND not in seen:
        raise DataError(f"{where}: column 'kind' is missing: expected a measurement-kinds file "
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
    cell = _Cells(path, header, seen, data, fmt)
    joints = joint_columns(n_q)
    q = fmt.to_contract(joints, np.column_stack([cell.numbers(c, required=True) for c in joints]))
    written = cell.texts(KIND)
    kind = tuple(fmt.kinds.get(k, k) for k in written)
    known = tuple(kinds)
    for r, k in enumerate(kind):
        if k not in known:
            named = f" (the format's kinds name it {k!r})" if k != written[r] else ""
            cell.fail(r, KIND, written[r], f"one of the kinds {', '.join(known)}{named}")
    numbers, texts = _columns(cell, seen, fmt)
    ids = _ids(cell, features)
    _check_rows(cell, kind, numbers, texts, ids, features)
    return ObservationTable(q_deg=q, kind=kind, ids=ids, lines=tuple(number for number, _ in data),
                            source=str(path), numbers=numbers, texts=texts,
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


def _columns(cell: _Cells, seen: dict[str, int], fmt: MeasurementFormat) -> tuple[dict, dict]:
    """Every column but the joints, ``kind`` and ``id``: numbers (contract units) and texts. A mapped file column
    is kept under its contract name only (``seen`` holds it under both)."""
    numbers, texts = {}, {}
    mapped = {seen[c] for c in fmt.columns if c in seen}
    for column in seen:
        if column in (KIND, ID) or re.fullmatch(r"q\d+", column) or (seen[column] in mapped and
                                                                     column not in fmt.columns):
            continue
        if column in TEXT or (column not in NUMERIC and not cell.is_numeric(column)):
            texts[column] = cell.texts(column)
            continue
        values = fmt.to_contract([column], cell.numbers(column)[:, None])[:, 0]
        if column == "distance_mm" and fmt.length_unit == "m":
            values = values * 1000.0
        numbers[column] = values
    return numbers, texts


def _ids(cell: _Cells, features: Mapping | None) -> tuple[str, ...]:
    given = cell.texts(ID)
    ids = tuple(text or str(r + 1) for r, text in enumerate(given))
    first: dict[str, int] = {}
    points = (features or {}).get("points", {})
    for r, name in enumerate(ids):
        if name in first:
            cell.fail(r, ID, name, f"an id of its own (line {cell.data[first[name]][0]} has it already; a row "
                                   "without an id is named by its data-row number)")
        if name in points:
            cell.fail(r, ID, name, "an id that is not also a point of the features (a 'to' naming it would "
                                   "be ambiguous)")
        first[name] = r
    return ids


def _check_rows(cell: _Cells, kind: tuple, numbers: dict, texts: dict, ids: tuple, features: Mapping | None):
    """Each row's own columns: present, and of the values its kind allows."""
    known_ids = set(ids)
    points = None if features is None else set(features.get("points", {}))
    for r, k in enumerate(kind):
        for column in READS.get(k, ()):
            if column not in texts and column not in numbers:
                cell.fail(r, column, "", f"a value on a {k} row, but the file has no column {cell.label(column)} "
                                         f"({k} rows read {', '.join(READS[k])})")
            empty = texts[column][r] == "" if column in texts else np.isnan(numbers[column][r])
            if empty:
                cell.fail(r, column, "", f"a value on a {k} row ({k} rows read {', '.join(READS[k])})")
        section = FEATURE_OF.get(k)
        if section is not None and features is not None and section in features:
            names = features[section]
            if texts["feature"][r] not in names:
                listed = ", ".join(names) or "none"
                cell.fail(r, "feature", texts["feature"][r], f"one of the {section} of the features ({listed}; an "
                                                             "unknown one is listed as NAME: {})")
        if k == "plane" and "flush" in numbers and not np.isnan(flush := numbers["flush"][r]) and flush not in (0, 1):
            cell.fail(r, "flush", f"{flush:g}", "0 or 1 (1: a flat face of the tool lies on the plane), or empty")
        if k == "distance":
            if not numbers["distance_mm"][r] > 0:
                cell.fail(r, "distance_mm", f"{numbers['distance_mm'][r]:g}", "a distance > 0 mm")
            to = texts["to"][r]
            if to == ids[r]:
                cell.fail(r, "to", to, "another row's id (a distance from a row to itself)")
            if points is not None and to not in known_ids and to not in points:
                listed = ", ".join(sorted(points)) or "none"
                cell.fail(r, "to", to, f"the id of a row of the file or a point of the features ({listed})")
    if PAYLOAD in numbers:
        values = numbers[PAYLOAD]
        bad = np.flatnonzero((values < 0) | (values > MAX_PAYLOAD_KG))
        if bad.size:
            cell.fail(int(bad[0]), PAYLOAD, f"{values[bad[0]]:g}", f"a payload mass in [0, {MAX_PAYLOAD_KG:g}] kg")


def write_observations(table: ObservationTable, path: str | Path, comment: str | None = None) -> None:
    """Write a measurement-kinds CSV that :func:`read_observations` reads back (atomically).

    Columns: ``q1..qN``, ``kind``, ``id``, then the contract's columns present (``feature``, ``flush``,
    ``distance_mm``, ``to``, ``x_meas``, ``y_meas``, ``z_meas``, ``set``, ``payload_kg``), then any others
    in the table's order. Numbers get 6 decimals (``flush`` is written 0/1), NaN and ``""`` an empty cell;
    ``comment`` becomes ``#`` lines above the header.
    """
    order = ("feature", "flush", "distance_mm", "to", *MEASURED, "set", PAYLOAD)
    present = [c for c in order if c in table.numbers or c in table.texts]
    present += [c for c in (*table.numbers, *table.texts) if c not in present]
    header = joint_columns(table.q_deg.shape[1]) + [KIND, ID] + present
    with atomic_write(path, newline="") as handle:
        for text in (comment or "").splitlines():
            handle.write(f"# {text}\n")
        handle.write(",".join(header) + "\n")
        for r in range(len(table)):
            cells = [f"{v:.6f}" for v in table.q_deg[r]] + [_quote(table.kind[r]), _quote(table.ids[r])]
            for column in present:
                if column in table.texts:
                    cells.append(_quote(table.texts[column][r]))
                    continue
                v = table.numbers[column][r]
                cells.append("" if np.isnan(v) else f"{v:g}" if column == "flush" else f"{v:.6f}")
            handle.write(",".join(cells) + "\n")


def _quote(text: str) -> str:
    if any(ch in text for ch in ',"\n\r') or text != text.strip():
        return '"' + text.replace('"', '""') + '"'
    return text


# ---------------------------------------------------------------------------------------------- features YAML
def read_features(path: str | Path, *, kinds: Collection[str] = BUILTIN_KINDS) -> dict:
    """Read and validate a features YAML: the cell's planes and fixed points, and each kind's noise.

    Returns ``{"planes": {name: {...}}, "points": {name: {...}}, "noise_mm": {kind: mm}}``. A plane is
    ``{}`` (unknown), ``{"normal": [nx, ny, nz] (unit), "offset_mm": d}`` (approximately known: the plane
    ``n . p = d`` in the base frame, still fitted) or ``{"parallel_to": NAME, "spacing_mm": s}`` (tied:
    that plane's normal, its offset plus ``s``); a point is ``{}`` (unknown), ``{"known_mm": [x, y, z]}``
    (known in the base frame) or ``{"distance_to": NAME, "distance_mm": d}`` (tied by a known distance).

    Raises
    ------
    ConfigError
        Naming the key's path and line: an unknown key, a zero normal, a number that is not finite, a
        ``parallel_to`` or ``distance_to`` naming itself or no feature of its section, a cycle of them, a
        noise for an unknown kind.
    """
    data, lines = load_yaml(path)
    top = Section(data, "", lines, str(path))
    out = features_from_section(top, kinds=kinds)
    top.done()
    return out


def features_from_section(top: Section, *, kinds: Collection[str] = BUILTIN_KINDS) -> dict:
    """:func:`read_features` of a mapping already loaded (``planes``, ``points``, ``noise_mm`` of ``top``)."""
    planes, points = top.section("planes"), top.section("points")
    out = {"planes": {}, "points": {}, "noise_mm": {}}
    for name in list(planes.data):
        out["planes"][name] = _plane(planes, name)
    planes.done()
    for name in list(points.data):
        out["points"][name] = _point(points, name)
    points.done()
    noise = top.section("noise_mm")
    for kind in list(noise.data):
        if kind not in kinds:
            noise.fail(noise.path(str(kind)), f"unknown kind; expected one of {', '.join(kinds)}")
        out["noise_mm"][kind] = noise.get(kind, "float", check=_positive)
    noise.done()
    check_ties(planes, out["planes"], "parallel_to")
    check_ties(points, out["points"], "distance_to")
    return out


PLANE_FORMS = (("parallel_to", "spacing_mm"), ("normal", "offset_mm"))
"""The keys of each form of a plane (tied, approximately known); an unknown plane has none."""
POINT_FORMS = (("distance_to", "distance_mm"), ("known_mm",))
"""The keys of each form of a fixed point (tied, known); an unknown point has none."""


def _form(sec: Section, forms: tuple) -> tuple[str, ...]:
    """The form whose keys ``sec`` uses (``()``: none); a key outside it is refused as unknown before a key of
    the form is missed, so that a typo is named (``offset`` for ``offset_mm``) and two forms do not mix."""
    form = next((keys for keys in forms if any(sec.has(k) for k in keys)), ())
    known = sorted(form or {k for keys in forms for k in keys})
    for key in sec.data:
        if key not in form:
            close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = f"; did you mean {close[0]!r}?" if close else "" if form else f" (known: {', '.join(known)})"
            of = f" beside {form[0]!r} (that form has {', '.join(form)}; one form per feature)" if form else ""
            sec.fail(sec.path(str(key)), f"unknown key{of}{hint}")
    return form


def _plane(planes: Section, name) -> dict:
    sec = _named(planes, name)
    _form(sec, PLANE_FORMS)
    if sec.has("parallel_to") or sec.has("spacing_mm"):
        out = {"parallel_to": sec.get("parallel_to", "str"), "spacing_mm": sec.get("spacing_mm", "float",
                                                                                   check=_finite)}
    elif sec.has("normal") or sec.has("offset_mm"):
        out = {"normal": unit_vector(sec, "normal"), "offset_mm": sec.get("offset_mm", "float", check=_finite)}
    else:
        out = {}
    sec.done()
    return out


def _point(points: Section, name) -> dict:
    sec = _named(points, name)
    _form(sec, POINT_FORMS)
    if sec.has("distance_to") or sec.has("distance_mm"):
        out = {"distance_to": sec.get("distance_to", "str"), "distance_mm": sec.get("distance_mm", "float",
                                                                                     check=_positive)}
    elif sec.has("known_mm"):
        out = {"known_mm": [float(v) for v in sec.get("known_mm", "list", check=vector3_problem)]}
    else:
        out = {}
    sec.done()
    return out


def _named(parent: Section, name) -> Section:
    """The section of a feature, its name checked (letters, digits, ``_ . -``)."""
    if not isinstance(name, str) or not FEATURE_NAME.match(name):
        parent.fail(parent.path(str(name)), f"a feature's name is letters, digits, '_', '.' or '-'; got {name!r}")
    return parent.section(name)


def check_ties(section: Section, features: dict, key: str) -> None:
    """Refuse a ``key`` (``parallel_to``, ``distance_to``) naming itself, no feature of ``section``, or closing
    a cycle."""
    for name, spec in features.items():
        other = spec.get(key)
        if other is None:
            continue
        where = f"{section.path(name)}.{key}"
        if other == name:
            section.fail(where, f"must name another feature than {name!r} itself")
        if other not in features:
            section.fail(where, f"must name a feature of {section.where} ({', '.join(features)}); got {other!r}")
        seen, at = [name], other
        while at is not None:
            if at in seen:
                section.fail(where, f"closes a cycle: {' -> '.join([*seen, at])}")
            seen.append(at)
            at = features[at].get(key)


def unit_vector(sec: Section, key: str) -> list[float]:
    """A 3-vector of ``sec`` (finite, not zero) made unit length."""
    v = np.asarray(sec.get(key, "list", check=vector3_problem), dtype=float)
    norm = float(np.linalg.norm(v))
    if not norm > 1e-12:
        sec.fail(sec.path(key), f"must be a direction (a non-zero vector); got {v.tolist()}")
    return (v / norm).tolist()


def vector3_problem(value) -> str | None:
    """A ``check`` for :meth:`Section.get`: three finite numbers."""
    ok = len(value) == 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v)
                                 for v in value)
    return None if ok else "a list of three finite numbers"


def _finite(value: float) -> str | None:
    return None if np.isfinite(value) else "a finite number"


def _positive(value: float) -> str | None:
    return None if np.isfinite(value) and value > 0 else "a finite number > 0"
