"""What every robot program dialect shares: targets with the byte spans of their numbers, and rewriting them.

A program is read as bytes and decoded as latin-1, one character per byte, so a character offset is a byte
offset and any encoding (UTF-8, cp1252, latin-1) comes back byte for byte: the dialects look only at ASCII
syntax, and only the numbers of targets are ever replaced.
"""

from __future__ import annotations

import ast
import math
import re
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError

NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
NUMBER_RE = re.compile(NUMBER)
BOM = "\xef\xbb\xbf"         # a UTF-8 byte order mark, read as latin-1: not part of the first line
LINE_BREAK = re.compile(r"\r\n|\r|\n")    # a line ends at CR LF, LF or a lone CR (old Mac editors)
_BREAK_CHAR = re.compile(r"[\r\n]")


def is_number(text: str) -> bool:
    """Whether ``text`` is a number as the vendors write it and finite as a float (``1e999`` is not)."""
    return bool(NUMBER_RE.fullmatch(text)) and np.isfinite(float(text))


CONSTANT_CALLS = {"d2r": math.radians, "r2d": math.degrees}
CONSTANT_NAMES = {"pi": math.pi}
_OPERATORS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
              ast.Div: lambda a, b: a / b, ast.USub: lambda a: -a, ast.UAdd: lambda a: a}


def constant_value(text: str) -> float | None:
    """The value of constant arithmetic as URScript writes it in a pose (``0.05 * 2``, ``-(0.1)``, ``d2r(180)``,
    ``pi / 2``): numbers, ``+ - * /``, parentheses, ``d2r``, ``r2d`` and ``pi``; None for anything else (a
    variable, another function) or a value that is not finite.

    >>> constant_value("0.05 * 2"), constant_value("-(0.1)"), constant_value("d2r(90)") == math.pi / 2
    (0.1, -0.1, True)
    >>> constant_value("z0 - 2*h") is None, constant_value("1/0") is None
    (True, True)
    """
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except (SyntaxError, ValueError):
        return None

    def value(node):
        if isinstance(node, ast.Constant) and type(node.value) in (int, float):
            return float(node.value)
        if isinstance(node, ast.Name) and node.id in CONSTANT_NAMES:
            return CONSTANT_NAMES[node.id]
        if isinstance(node, ast.UnaryOp) and type(node.op) in _OPERATORS:
            return _OPERATORS[type(node.op)](value(node.operand))
        if isinstance(node, ast.BinOp) and type(node.op) in _OPERATORS:
            return _OPERATORS[type(node.op)](value(node.left), value(node.right))
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in CONSTANT_CALLS \
                and len(node.args) == 1 and not node.keywords:
            return CONSTANT_CALLS[node.func.id](value(node.args[0]))
        raise ValueError(node)

    try:
        result = value(tree)
    except (ValueError, ZeroDivisionError, OverflowError):
        return None
    return result if math.isfinite(result) else None


class ProgramSyntaxError(DataError):
    """A target of a robot program cannot be read (names the file, line and column)."""


class UnknownFrameError(DataError):
    """A target is given relative to a frame (work object, base, feature, tool) that was not given."""


@dataclass(frozen=True)
class Field:
    """One number of a target in the file: its character span, its text and its value (file units)."""

    start: int
    end: int
    text: str
    value: float


@dataclass
class Target:
    """One target of a program.

    Attributes
    ----------
    name : str
        The variable's name (``p10``, ``XP1``), or ``movel`` / ``row 3`` for an inline target.
    line, column : int
        1-based position of the target's first number, as an editor shows it.
    kind : "pose" or "joints"
    fields : tuple of Field
        The numbers rewritten by compensation: a pose's position then rotation, or the joints.
    position_mm : ndarray, shape (3,)
        A pose's position, mm (None for joints).
    rotation : ndarray, shape (3, 3)
        A pose's orientation (None for joints).
    joints_deg : ndarray, shape (N,)
        A joint target's angles, degrees (None for poses).
    configuration : tuple of int or None
        The configuration written with a pose (KUKA ``(S, T)``, ABB ``(cf1, cf4, cf6, cfx)``), if any.
    frame, tool : str or None
        The names of the frame and the tool the target is given in, when the program names them (None: the
        dialect's default, the robot base and the flange unless options say otherwise).
    line_end : int
        Offset of the end of the target's line (before its line ending): where a comment goes.
    external : tuple of (str, float)
        The external axes written with a pose, as the program names them and in its units (KUKA ``E1 1500``,
        ABB ``eax_a``; a track's mm, a positioner's degrees); none when absent or unused (ABB's ``9E9``).
    """

    name: str
    line: int
    column: int
    kind: str
    fields: tuple
    position_mm: NDArray[np.float64] | None = None
    rotation: NDArray[np.float64] | None = None
    joints_deg: NDArray[np.float64] | None = None
    configuration: tuple | None = None
    frame: str | None = None
    tool: str | None = None
    line_end: int = 0
    external: tuple = ()

    def where(self, source: str) -> str:
        return f"{source}: line {self.line}, column {self.column}: target {self.name}"


@dataclass(frozen=True)
class Left:
    """A pose of a program that is not compensated and stays as written: where it is, and why.

    ``name`` is the variable (or the move) it belongs to; ``line`` and ``column`` (1-based) are where its text
    starts; ``reason`` says why it is no target partcal can compensate (computed at run time, in a frame set at
    run time, reached by no motion)."""

    name: str
    line: int
    column: int
    reason: str

    def where(self, source: str) -> str:
        return f"{source}: line {self.line}, column {self.column}: {self.name}"


def lf_view(code: str) -> str:
    """``code`` with each lone CR made a LF (same length, same offsets): ``^`` and ``$`` of a multi-line regular
    expression then find the lines of a CR-only file too."""
    return re.sub(r"\r(?!\n)", "\n", code)


@dataclass(frozen=True)
class Dialect:
    """A program language: how to find its targets, and its units and rotations.

    ``parse(text, source)`` -> the targets (list of Target, their fields only), the frames and tools the
    program defines itself (name -> pose (4, 4) mm) and the poses left as written (list of ``(offset, name,
    reason)``: computed at run time, in a frame set at run time, reached by no motion). A pose target's fields are its position, then its
    rotation: ``poses(values (n, k))`` -> positions (n, 3) mm and rotations (n, 3, 3), and
    ``pose_values(positions, rotations, old (n, k))`` -> the fields' values, the rotation written nearest the
    old one; ``pose_decimals``: the fewest decimals of each field. A joint target's fields are its joints,
    ``joint_unit_deg`` degrees each, written with at least ``joint_decimals`` decimals.
    ``frame(text, source)`` -> a pose (4, 4) mm from an option's value in the vendor's syntax.
    ``configuration(q_deg (n, N))`` -> the configuration each joint solution has (n, k) ints, compared
    with a target's written one at the indices ``compare``; ``seeds(configurations (n, k), reference (n, N)
    deg)`` -> IK seeds that have the written configurations (-1: not written), near the reference joints;
    ``ranges(configurations (n, k))`` -> the joint ranges they allow (low, high (n, N) degrees; -inf, inf where
    free), where a straight wrist's shared turn is split (:func:`partcal.robot.wrist.nearest_split`).
    ``comment``: the line-comment mark. ``edge_kept``: a target whose intended joint lies on the edge of two
    configurations (ABB's axis 4 at 0 degrees, tool down) has both, and its compensated joints may take either
    side (the ABB controller takes the nearest; a KUKA ``T`` bit decides the turn of a ``PTP``, so KRL keeps
    the written side).
    """

    name: str
    extensions: tuple[str, ...]
    parse: Callable
    frame: Callable
    comment: str
    poses: Callable | None = None
    pose_values: Callable | None = None
    pose_decimals: tuple[int, ...] = ()
    joint_unit_deg: float = 1.0
    joint_decimals: int = 6
    configuration: Callable | None = None
    compare: tuple[int, ...] = ()
    seeds: Callable | None = None
    ranges: Callable | None = None
    comment_line: bool = False          # a note goes on a line of its own before the target (CSV)
    statement_end: str = ""             # a note goes after the statement's end (RAPID's ";"), not mid-statement
    edge_kept: bool = False             # a target on a configuration's edge keeps it on either side (ABB)

    def fill(self, text: str, targets: list[Target]) -> None:
        """Lines, columns, poses and joints of parsed targets, computed for all of them at once."""
        if not targets:
            return
        starts = line_starts(text)
        offsets = np.array([t.fields[0].start for t in targets])
        lines = np.searchsorted(starts, offsets, side="right")      # lines started at or before each target
        for t, line, column in zip(targets, lines, offsets - starts[lines - 1] + 1):
            t.line, t.column = int(line), int(column)
        poses = [t for t in targets if t.kind == "pose"]
        if poses:
            positions, rotations = self.poses(np.array([[f.value for f in t.fields] for t in poses]))
            for t, p, r in zip(poses, positions, rotations):
                t.position_mm, t.rotation = p, r
        for t in targets:
            if t.kind == "joints":
                t.joints_deg = np.array([f.value for f in t.fields]) * self.joint_unit_deg

    def texts(self, targets: list[Target], positions=None, rotations=None, joints_deg=None,
              tol_deg: float = 0.0) -> list[list[str]]:
        """The new text of every field of ``targets`` (all poses, or all joints): positions (n, 3) mm and
        rotations (n, 3, 3), or joints (n, N) degrees. A number equal to the old one at the precision
        written keeps its text (:func:`number_text`); a rotation within ``tol_deg`` degrees of the old one
        keeps its numbers (a quaternion written a little off unit, a rotation vector of either sign)."""
        old = np.array([[f.value for f in t.fields] for t in targets])
        if joints_deg is not None:
            values, decimals = np.asarray(joints_deg) / self.joint_unit_deg, [self.joint_decimals] * old.shape[1]
        else:
            values, decimals = self.pose_values(positions, rotations, old), self.pose_decimals
            before = np.stack([t.rotation for t in targets])
            chord = np.linalg.norm(rotations - before, axis=(1, 2)) / (2.0 * np.sqrt(2.0))   # sin(angle / 2)
            same = np.degrees(2.0 * np.arcsin(np.minimum(chord, 1.0))) <= tol_deg
            values[same, 3:] = old[same, 3:]
        return [[number_text(v, f, d) for v, f, d in zip(row, t.fields, decimals)] for row, t in zip(values, targets)]

    def note(self, text: str, target: Target, message: str) -> tuple[int, int, str]:
        """Where and how a note about ``target`` goes: ``(offset, offset, text)`` to insert, a comment at the
        end of the target's line, or a comment line before it (with the file's line ending)."""
        if not self.comment_line:
            end = text.find(self.statement_end, target.fields[-1].end) if self.statement_end else -1
            at = line_end(text, end) if end >= 0 else target.line_end
            return at, at, f" {self.comment} {message}"
        start = line_start(text, target.fields[0].start)
        ending = LINE_BREAK.match(text, target.line_end) or LINE_BREAK.search(text)
        return start, start, f"{self.comment} {message}{ending.group() if ending else chr(10)}"


@dataclass
class Program:
    """A program read from a file: its text (latin-1 decoded bytes), dialect and targets."""

    path: str
    text: str
    dialect: Dialect
    targets: list[Target] = field(default_factory=list)
    frames: dict = field(default_factory=dict)      # frames and tools defined in the program: name -> (4, 4) mm
    left: list[Left] = field(default_factory=list)  # poses not compensated, kept as written, with the reason

    def rewritten(self, replacements: list[tuple[int, int, str]]) -> bytes:
        """The program's bytes with ``(start, end, new text)`` spans replaced (spans do not overlap)."""
        out, at = [], 0
        for start, end, new in sorted(replacements):
            out.append(self.text[at:start])
            out.append(new)
            at = end
        out.append(self.text[at:])
        return "".join(out).encode("latin-1")


def line_starts(text: str) -> np.ndarray:
    """Offsets at which the lines of ``text`` start (the first is 0; CR LF, LF and a lone CR end a line)."""
    return np.array([0] + [m.end() for m in LINE_BREAK.finditer(text)], dtype=np.int64)


def line_start(text: str, offset: int) -> int:
    """Offset of the start of the line holding ``offset``."""
    return max(text.rfind("\n", 0, offset), text.rfind("\r", 0, offset)) + 1


def line_and_column(text: str, offset: int) -> tuple[int, int]:
    r"""1-based line and column of a character offset (CR LF, LF or a lone CR ends a line).

    >>> line_and_column("a\rbc\r\nd", 6), line_and_column("one line", 4)
    ((3, 1), (1, 5))
    """
    return len(LINE_BREAK.findall(text, 0, offset)) + 1, offset - line_start(text, offset) + 1


def line_end(text: str, offset: int) -> int:
    """Offset of the end of the line holding ``offset``, before its line break (the end of the text if none)."""
    end = _BREAK_CHAR.search(text, offset)
    return len(text) if end is None else end.start()


def syntax_error(source: str, text: str, offset: int, what: str, expected: str,
                 found: str | None = None) -> ProgramSyntaxError:
    """One error naming the file, line and column, what was found (default: the text there) and what was
    expected; nothing is written."""
    line, column = line_and_column(text, offset)
    found = _BREAK_CHAR.split(text[offset:offset + 40])[0] if found is None else found
    return ProgramSyntaxError(f"{source}: line {line}, column {column}: {what}: expected {expected}, got "
                              f"{found!r}; nothing written")


def numbers(source: str, text: str, start: int, end: int, count: int | tuple, what: str,
            constants: bool = False) -> list[Field]:
    """The comma-separated numbers between ``start`` and ``end`` (a list body), exactly ``count`` of them; with
    ``constants``, an item may be constant arithmetic (:func:`constant_value`), read as its value."""
    out, at = [], start
    body = text[start:end]
    for k, part in enumerate(top_level(body) if constants and "(" in body else body.split(",")):
        stripped = part.strip()
        offset = at + (len(part) - len(part.lstrip()))
        value = float(stripped) if is_number(stripped) else constant_value(stripped) if constants else None
        if value is None:
            raise syntax_error(source, text, offset, f"{what}, item {k + 1}", "a number", stripped)
        out.append(Field(offset, offset + len(stripped), stripped, value))
        at += len(part) + 1
    counts = count if isinstance(count, tuple) else (count,)
    if len(out) not in counts:
        raise syntax_error(source, text, start, what, f"{' or '.join(map(str, counts))} numbers (got {len(out)})")
    return out


def top_level(body: str) -> list[str]:
    """The comma-separated items of a list body, commas inside brackets, braces and calls not counted.

    >>> top_level("p[0, 1], d2r(90), {X 1, Y 2}")
    ['p[0, 1]', ' d2r(90)', ' {X 1, Y 2}']
    """
    out, depth, at = [], 0, 0
    for k, c in enumerate(body):
        depth += 1 if c in "([{" else -1 if c in ")]}" else 0
        if c == "," and depth == 0:
            out.append(body[at:k])
            at = k + 1
    return out + [body[at:]]


_STYLE = re.compile(r"(?P<sign>[-+]?)(?P<whole>\d*)(?:\.(?P<frac>\d*))?(?:(?P<e>[eE])(?P<esign>[-+]?)(?P<exp>\d+))?")


def number_text(value: float, old: Field, min_decimals: int) -> str:
    """``value`` written as the number ``old`` was: its own text when equal at the precision written (at least
    ``min_decimals`` decimals), else in its style: as many decimals as it had and at least ``min_decimals``,
    without the leading zero where it had none (``.208``), a ``+`` where it had one, in exponent form where it
    was (``1.5e-01``, the exponent's case, sign and digits kept). Constant arithmetic (``0.05 * 2``) that
    changes becomes a number.

    >>> f = lambda text: Field(0, len(text), text, float(eval(text)))
    >>> number_text(0.2080000001, f(".208"), 8), number_text(0.2083, f(".208"), 8), number_text(-0.5, f("-.4"), 3)
    ('.208', '.20830000', '-.500')
    >>> number_text(0.1503, f("1.5e-01"), 4), number_text(1203.5, f("+1.2E+03"), 3), number_text(0.1, f("0.05 * 2"), 3)
    ('1.503e-01', '+1.203500E+03', '0.05 * 2')
    """
    m = _STYLE.fullmatch(old.text)               # None: constant arithmetic, read as its value
    if m is not None and m.group("e"):
        return _exponent_text(value, old, m, min_decimals)
    decimals = max(min_decimals, len(m.group("frac") or "") if m else 0)
    new = f"{value + 0.0:.{decimals}f}"
    if float(new) == 0.0:
        new = new.lstrip("-")                       # no "-0.000000"
    if float(f"{old.value + 0.0:.{decimals}f}") == float(new):
        return old.text
    if m is None:
        return new
    if m.group("sign") == "+" and not new.startswith("-"):
        new = "+" + new
    if not m.group("whole"):                        # written without the zero before the point
        new = re.sub(r"^([-+]?)0\.", r"\1.", new)
    return new


def _exponent_text(value: float, old: Field, m: re.Match, min_decimals: int) -> str:
    """``value`` in the exponent form of ``old`` (``m``: its parts), with at least ``min_decimals`` decimals of
    the value itself; ``old``'s text when equal at that precision."""
    exponent = int(m.group("esign") + m.group("exp"))
    places = max(min_decimals, len(m.group("frac") or "") - exponent)        # decimals of the value
    if round(value, places) == round(old.value, places):
        return old.text
    power = exponent if value == 0 else int(np.floor(np.log10(abs(value))))
    mantissa = f"{value / 10.0 ** power:.{max(places + power, 0)}f}"
    if abs(float(mantissa)) >= 10:                  # rounded up to the next power of ten
        power += 1
        mantissa = f"{value / 10.0 ** power:.{max(places + power, 0)}f}"
    sign = "-" if power < 0 else "+" if m.group("esign") == "+" else ""
    new = f"{mantissa}{m.group('e')}{sign}{str(abs(power)).zfill(len(m.group('exp')))}"
    return "+" + new if m.group("sign") == "+" and not new.startswith("-") else new


def frame_pose(positions_mm, rotations) -> NDArray[np.float64]:
    """One pose (4, 4) mm from a position (3,) mm and a rotation (3, 3)."""
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotations, positions_mm
    return out


def masked(text: str, comment: str) -> str:
    """``text`` with comments (from ``comment`` to the end of the line) and double-quoted strings blanked out
    (each character a space, line endings kept): offsets stay those of ``text``, and no number or bracket in a
    comment or a string is mistaken for a target."""
    pattern = re.compile('"[^"\\r\\n]*"|' + re.escape(comment) + "[^\\r\\n]*")
    return pattern.sub(lambda m: " " * len(m.group()), text)


def closing(text: str, start: int, open_: str, close: str) -> int:
    """Offset of the bracket that closes the one at ``start``; -1 if none."""
    depth = 0
    for k in range(start, len(text)):
        if text[k] == open_:
            depth += 1
        elif text[k] == close:
            depth -= 1
            if depth == 0:
                return k
    return -1
