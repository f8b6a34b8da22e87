"""Robot programs: the table of dialects, reading a program, and telling a program from a targets CSV.

The dialects (one module each) find the targets of a program with the byte spans of their numbers and
write new numbers in their place; everything else in the file stays byte for byte (see
:mod:`partcal.data.program_text`).

========== ============================== ==========================================================
dialect    files                          targets
========== ============================== ==========================================================
urscript   ``.script``, ``.urscript``     ``p[x, y, z, rx, ry, rz]`` (m, rad), joint lists (rad)
krl        ``.src``, ``.dat``             ``E6POS POS E3POS FRAME`` (mm, deg), ``E6AXIS AXIS`` (deg)
rapid      ``.mod``, ``.modx``, ``.prg``, ``robtarget`` (mm, quaternion), ``jointtarget`` (deg)
           ``.sys``
joints     ``.csv`` with ``q1..qN``       one row per time step (deg)
========== ============================== ==========================================================

A file with another name, or none, is read as the program its text shows (:func:`program_kind`).
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

from ..errors import DataError
from . import program_joints, program_krl, program_rapid, program_urscript
from .program_text import (BOM, Dialect, Left, Program, ProgramSyntaxError, Target, UnknownFrameError, lf_view,
                           line_and_column, masked)

log = logging.getLogger(__name__)

DIALECTS: dict[str, Dialect] = {d.name: d for d in (program_urscript.DIALECT, program_krl.DIALECT,
                                                     program_rapid.DIALECT, program_joints.DIALECT)}

__all__ = ["DIALECTS", "Left", "Program", "ProgramSyntaxError", "Target", "UnknownFrameError", "frame_option",
           "program_kind", "read_program"]
_NAMED = re.compile(r"\s*([$A-Za-z_][\w$]*(?:\[\s*\d+\s*\])?)\s*=(?!=)(.*)$", re.DOTALL)
_KRL_SYSTEM_FRAMES = ("BASE_DATA[", "TOOL_DATA[")     # KRL names are caseless; targets name these in capitals


_SNIFF = (("rapid", re.compile(r"^[ \t]*MODULE[ \t]+\w+", re.IGNORECASE | re.MULTILINE)),
          ("krl", re.compile(r"^[ \t]*(?:&ACCESS\b|&REL\b|DEFDAT[ \t]|DEF(?:FCT)?[ \t]+[$\w]+[ \t]*\([^)\r\n]*\)"
                             r"[ \t]*(?:;[^\r\n]*)?$)", re.IGNORECASE | re.MULTILINE)),
          ("urscript", re.compile(r"^[ \t]*def[ \t]+\w+[ \t]*\([^)\r\n]*\)[ \t]*:|\b(?:movel|movej|movep)[ \t]*\("
                                  r"[ \t]*(?:p[ \t]*\[|\[)", re.MULTILINE)))


def program_kind(path: str | Path) -> str | None:
    """The dialect a file's name (and, for CSV, its header) says it is in; None for a targets CSV.

    A ``.csv`` is a joint trajectory when its header has ``q1`` and no position columns (``x`` or
    ``x_nom``): a targets CSV (``x,y,z``, optionally ``q1..qN`` as seeds) is compensated as before. A file
    with another name (or none) is a program when its text says which: a RAPID ``MODULE``, a KRL ``DEF``,
    ``DEFDAT`` or ``&ACCESS`` line, a URScript ``def name():`` or a move to a literal.
    """
    suffix = Path(path).suffix.lower()
    for name, dialect in DIALECTS.items():
        if suffix in dialect.extensions and name != "joints":
            return name
    if suffix != ".csv":
        return _sniffed(path)
    if suffix == ".csv":
        try:
            with open(path, encoding="latin-1") as handle:
                lines = (line.removeprefix(BOM) if k == 0 else line for k, line in enumerate(handle))
                header = next((line for line in lines if line.strip() and not line.lstrip().startswith("#")), "")
        except OSError:
            return None
        names = {c.strip() for c in header.rstrip("\r\n").split(",")}
        if "q1" in names and not names & {"x", "x_nom"}:
            return "joints"
    return None


def _sniffed(path: str | Path) -> str | None:
    """The dialect the start of a file's text is in (comments and strings not read); None if none says."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(16384).decode("latin-1")
    except OSError:
        return None
    for name, pattern in _SNIFF:
        if pattern.search(lf_view(masked(head, DIALECTS[name].comment))):
            return name
    return None


def read_program(path: str | Path, dialect: str | None = None) -> Program:
    """Read a robot program: its bytes (kept exactly), dialect and targets.

    Parameters
    ----------
    path : str or Path
    dialect : {"urscript", "krl", "rapid", "joints"}, optional
        Default: from the file name (:func:`program_kind`).

    Poses that are no targets partcal can compensate (computed at run time, in a frame set at run time,
    reached by no motion) are kept as written, listed in ``Program.left`` and logged as warnings, one each.

    Raises
    ------
    ProgramSyntaxError
        A target that cannot be read, naming the file, line and column.
    """
    name = dialect or program_kind(path)
    if name not in DIALECTS:
        raise DataError(f"{path}: cannot tell which robot program language this is (expected a file ending in "
                        f"{', '.join(e for d in DIALECTS.values() for e in d.extensions)}, or a dialect in "
                        f"{', '.join(DIALECTS)}); got {name if dialect else Path(path).suffix or 'no extension'!r}")
    try:
        with open(path, "rb") as handle:
            raw = handle.read()
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError) as exc:
        raise DataError(f"{path}: no such program file ({exc.strerror.lower()}); nothing written") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw:
        nul = raw.find(b"\x00")
        found = "a UTF-16 byte order mark" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else \
            f"a NUL byte at byte {nul} (UTF-16 or not text)"
        raise DataError(f"{path}: expected a text file in an 8-bit encoding (ASCII, UTF-8, cp1252), got {found}; "
                        "save the program as UTF-8 or cp1252")
    text = raw.decode("latin-1")          # one character per byte: offsets are byte offsets
    targets, frames, left = DIALECTS[name].parse(text, str(path))
    DIALECTS[name].fill(text, targets)
    kept = [Left(what, *line_and_column(text, at), why) for at, what, why in sorted(left)]
    for item in kept:
        log.warning("%s: left as written: %s", item.where(str(path)), item.reason)
    return Program(str(path), text, DIALECTS[name], targets, frames, kept)


def frame_option(value: str, dialect: Dialect, option: str = "--frame") -> tuple[str | None, object]:
    """A frame or tool given on the command line, ``NAME=VALUE`` or ``VALUE`` (the default: targets that name
    none), VALUE in ``dialect``'s own syntax: its name (None for the default) and pose (4, 4) mm.

    KUKA's ``base_data[1]`` and ``tool_data[1]`` are named in capitals, as the targets of a program name
    them (``BASE_DATA[1]``).
    """
    m = _NAMED.match(value)
    name, text = (m.group(1).replace(" ", ""), m.group(2)) if m else (None, value)
    if name is not None and name.upper().startswith(_KRL_SYSTEM_FRAMES):
        name = name.upper()
    return name, dialect.frame(text, f"{option} {value!r}")
