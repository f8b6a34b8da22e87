"""Joint trajectories as CSV: one row per time step, the joint angles ``q1..qN`` in degrees.

The layout of the measurement CSV (docs/data.md): comma-separated, one header line, ``#`` comment lines;
columns other than ``q1..qN`` (a time, a speed) are kept as written. Each row is a joint target: it is
replaced by the joints at which the robot reaches the pose that the nominal robot has at the row's joints.
"""

from __future__ import annotations

import re

import numpy as np

from ..robot.description import joint_columns
from .program_text import BOM, LINE_BREAK, Dialect, Field, ProgramSyntaxError, Target, is_number, syntax_error

DEG_DECIMALS = 6
_JOINT = re.compile(r"q(\d+)")


def header_joints(header: list[str]) -> int:
    """How many joint columns ``q1..qN`` a header has (0: none)."""
    names = {h.strip() for h in header}
    n = 0
    while f"q{n + 1}" in names:
        n += 1
    return n


def parse(text: str, source: str) -> tuple[list[Target], dict]:
    """Every data row of a joint trajectory CSV as a joint target (``text``: its bytes decoded as latin-1)."""
    targets, header, columns, row = [], None, [], 0
    at = 0
    for number, line in enumerate(_lines(text), start=1):
        start, body = at, line.rstrip("\r\n")
        at += len(line)
        if number == 1 and body.startswith(BOM):
            start, body = start + len(BOM), body[len(BOM):]
        if not body.strip() or body.lstrip().startswith("#"):
            continue
        cells = body.split(",")
        if header is None:
            header = [c.strip() for c in cells]
            n = header_joints(header)
            if n == 0:
                raise ProgramSyntaxError(f"{source}: line {number}: a joint trajectory needs the columns q1..qN "
                                         f"(degrees); the header has {', '.join(header)}")
            if len(set(header)) != len(header):
                raise ProgramSyntaxError(f"{source}: line {number}: duplicate column names in the header")
            columns = [header.index(c) for c in joint_columns(n)]
            continue
        row += 1
        offsets = np.cumsum([0] + [len(c) + 1 for c in cells])
        if len(cells) != len(header):
            raise syntax_error(source, text, start, f"data row {row}: {len(cells)} cells",
                               f"{len(header)} cells, as the header")
        fields = []
        for k in columns:
            cell = cells[k]
            offset = start + int(offsets[k]) + len(cell) - len(cell.lstrip())
            value = cell.strip()
            if not is_number(value):
                raise syntax_error(source, text, offset, f"data row {row}, column {header[k]!r}",
                                   "a joint angle in degrees", value)
            fields.append(Field(offset, offset + len(value), value, float(value)))
        targets.append(Target(f"row {row}", number, fields[0].start - start + 1, "joints", tuple(fields),
                              line_end=start + len(body)))
    return targets, {}, []


def _lines(text: str) -> list[str]:
    """The lines of ``text`` with their endings (CR LF, LF or a lone CR; not the other breaks of
    ``str.splitlines``: a cp1252 ellipsis, byte 0x85, read as latin-1 is NEL and stays in its line)."""
    ends = [m.end() for m in LINE_BREAK.finditer(text)]
    bounds = [0] + ends + ([len(text)] if not ends or ends[-1] < len(text) else [])
    return [text[a:b] for a, b in zip(bounds, bounds[1:])]


def frame(value: str, source: str):
    raise ProgramSyntaxError(f"{source}: a joint trajectory has no frames or tools; got {value!r}")


DIALECT = Dialect("joints", (".csv",), parse, frame, "#", joint_decimals=DEG_DECIMALS, comment_line=True)
