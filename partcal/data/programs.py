"""Robot programs: the table of dialects, reading a program, and telling a program from a targets CSV.

The dialects (one module each) find the targets of a program with the byte spans of their numbers and
write new numbers in their place; everything else in the file stays byte for byte (see
:mod:`partcal.data.program_text`).

========== ============================== ==========================================================
dialect    files                          targets
========== ============================== ==========================================================
urscript   ``.script``                    ``p[x, y, z, rx, ry, rz]`` (m, rad), joint lists (rad)
krl        ``.src``, ``.dat``             ``E6POS POS E3POS FRAME`` (mm, deg), ``E6AXIS AXIS`` (deg)
rapid      ``.mod``, ``.prg``             ``robtarget`` (mm, quaternion), ``jointtarget`` (deg)
joints     ``.csv`` with ``q1..qN``       one row per time step (deg)
========== ============================== ==========================================================
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import DataError
from . import program_joints, program_krl, program_rapid, program_urscript
from .program_text import BOM, Dialect, Program, ProgramSyntaxError, Target, UnknownFrameError

DIALECTS: dict[str, Dialect] = {d.name: d for d in (program_urscript.DIALECT, program_krl.DIALECT,
                                                     program_rapid.DIALECT, program_joints.DIALECT)}

__all__ = ["DIALECTS", "Program", "ProgramSyntaxError", "Target", "UnknownFrameError", "frame_option",
           "program_kind", "read_program"]
_NAMED = re.compile(r"\s*([$A-Za-z_][\w$]*(?:\[\s*\d+\s*\])?)\s*=(?!=)(.*)$", re.DOTALL)
_KRL_SYSTEM_FRAMES = ("BASE_DATA[", "TOOL_DATA[")     # KRL names are caseless; targets name these in capitals


def program_kind(path: str | Path) -> str | None:
    """The dialect a file's name (and, for CSV, its header) says it is in; None for a targets CSV.

    A ``.csv`` is a joint trajectory when its header has ``q1`` and no position columns (``x`` or
    ``x_nom``): a targets CSV (``x,y,z``, optionally ``q1..qN`` as seeds) is compensated as before.
    """
    suffix = Path(path).suffix.lower()
    for name, dialect in DIALECTS.items():
        if suffix in dialect.extensions and name != "joints":
            return name
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


def read_program(path: str | Path, dialect: str | None = None) -> Program:
    """Read a robot program: its bytes (kept exactly), dialect and targets.

    Parameters
    ----------
    path : str or Path
    dialect : {"urscript", "krl", "rapid", "joints"}, optional
        Default: from the file name (:func:`program_kind`).

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
    with open(path, "rb") as handle:
        raw = handle.read()
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or b"\x00" in raw:
        nul = raw.find(b"\x00")
        found = "a UTF-16 byte order mark" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else \
            f"a NUL byte at byte {nul} (UTF-16 or not text)"
        raise DataError(f"{path}: expected a text file in an 8-bit encoding (ASCII, UTF-8, cp1252), got {found}; "
                        "save the program as UTF-8 or cp1252")
    text = raw.decode("latin-1")          # one character per byte: offsets are byte offsets
    targets, frames = DIALECTS[name].parse(text, str(path))
    DIALECTS[name].fill(text, targets)
    return Program(str(path), text, DIALECTS[name], targets, frames)


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
