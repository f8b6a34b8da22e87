"""KUKA KRL: what the motions of a ``.src`` reach, and in which base and tool.

A point is in the base and with the tool in force at the motions that reach it, followed in file order:
``$BASE =`` and ``$TOOL =``, ``BAS(#BASE, n)`` and ``BAS(#TOOL, n)``, an inline form's ``FDAT_ACT = FP1`` (its
``BASE_NO``, ``TOOL_NO`` and ``IPO_FRAME``), ``$IPO_MODE = #TCP`` (a fixed tool, the workpiece on the robot), and
the call of a subroutine of the module that sets any of these. A point whose value the module changes before
a motion (``XC1.Z = XC1.Z + 20``, a partial aggregate ``XM1 = {X .., Y ..}``) is not what its declaration says.
:class:`Reach` gathers all of it for :mod:`partcal.data.program_krl`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Callable

from .program_text import ProgramSyntaxError, line_and_column, top_level

NULLFRAME = "$NULLFRAME"
POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")
JOINT_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")
_EVENT = re.compile(                      # in file order: what sets the base and tool, and the motions
    r"^[ \t]*(?P<sys>\$BASE|\$TOOL)[ \t]*=(?!=)[ \t]*(?P<value>[^\r\n]*?)[ \t]*(?=[\r\n]|\Z)"
    r"|\bBAS[ \t]*\([ \t]*#(?P<bas>BASE|TOOL)[ \t]*,(?P<number>[^)\r\n]*)\)"
    r"|\bFDAT_ACT[ \t]*=[ \t]*(?P<fdat>[A-Za-z_]\w*)"
    r"|^[ \t]*\$IPO_MODE[ \t]*=[ \t]*#(?P<ipo>\w+)"
    r"|^[ \t]*(?P<motion>PTP|LIN|CIRC|SPTP|SLIN|SCIRC)[ \t]+(?P<args>[^\r\n]*?)[ \t]*(?=[\r\n]|\Z)",
    re.IGNORECASE | re.MULTILINE)
_SUB = re.compile(r"^[ \t]*(?:GLOBAL[ \t]+)?DEF[ \t]+(?P<name>[A-Za-z_]\w*)[ \t]*\((?P<body>.*?)^[ \t]*END\b",
                  re.IGNORECASE | re.MULTILINE | re.DOTALL)
_SETS_FRAME = re.compile(r"^[ \t]*(?:\$BASE|\$TOOL|\$IPO_MODE|FDAT_ACT)[ \t]*=(?!=)|\bBAS[ \t]*\([ \t]*#(?:BASE|TOOL)\b",
                         re.IGNORECASE | re.MULTILINE)
_CHANGED = re.compile(r"^[ \t]*(?P<name>[A-Za-z_]\w*(?:[ \t]*\[[^\]\r\n]*\])?)(?:[ \t]*\.[ \t]*(?P<part>[A-Za-z]\w*))?"
                      r"[ \t]*=(?!=)[ \t]*(?P<value>[^\r\n;]*)", re.MULTILINE)


class Computed(str):
    """A base or tool set at run time (its statement and line): targets moved to in it are left as written."""


class FixedTool(str):
    """A fixed tool (an ``FDAT`` with ``IPO_FRAME #TCP``, ``$IPO_MODE = #TCP``): the robot carries the workpiece
    past it, its points are in the tool's frame; they are left as written (the robot's own tool point is not on
    them)."""


class Undefined(str):
    """The base and tool of an ``FDAT`` that neither the module nor a ``$config.dat`` found beside it defines
    (``FDAT_ACT = FHOME``, the standard home motion's, lives in ``$config.dat``)."""


def unusable(states: set) -> str | None:
    """Why points moved to with these (base, tool) pairs cannot be compensated, if they cannot."""
    for kind, text in ((FixedTool, "moved to with a fixed tool ({}: the robot carries the workpiece)"),
                       (Computed, "moved to in a base or tool set at run time ({})"),
                       (Undefined, "moved to in the base and tool of {}")):
        found = sorted(str(x) for state in states for x in state if isinstance(x, kind))
        if found:
            return text.format(found[0]) + ": not compensated, kept as written"
    return None


def fdat_frames(data: dict, line: int | None = None) -> tuple:
    """The base and tool an FDAT sets (``BASE_NO``, ``TOOL_NO``; 0: the robot base, the flange)."""
    if data.get("IPO_FRAME", "#BASE").upper() != "#BASE":
        return FixedTool(f"IPO_FRAME {data['IPO_FRAME']}"), None
    base, tool = data.get("BASE_NO", "0").strip(), data.get("TOOL_NO", "0").strip()
    if not re.fullmatch(r"\d+", base) or not re.fullmatch(r"\d+", tool):
        return Computed(f"FDAT BASE_NO {base}, TOOL_NO {tool}"), None
    return (NULLFRAME if int(base) == 0 else f"BASE_DATA[{int(base)}]",
            NULLFRAME if int(tool) == 0 else f"TOOL_DATA[{int(tool)}]")


def key(name: str) -> str:
    """A name as KRL compares it: upper case, no spaces (``xp1`` is ``XP1``; ``P[ 3 ]`` is ``P[3]``)."""
    return re.sub(r"\s+", "", name).upper()


class Reach:
    """What the motions of a ``.src`` reach, and in which base and tool: the events of the module docstring
    before each motion, in file order (from the program's start: the default frames, those of ``--frame`` and
    ``--tool``). ``fdat``: the FDATs of the module and its ``$config.dat``; ``frames`` gets the literal frames
    of ``$BASE = {..}`` assignments; ``frame(text, source)`` reads one."""

    def __init__(self, text: str, code: str, source: str, fdat: dict, frames: dict, frame: Callable):
        self.source_name = Path(source).name
        self.named: dict = {}          # NAME or NAME[3] -> {(base, tool)}; NAME[] (any element) for NAME[i]
        self.through: dict = {}        # NAME -> the expression a motion reaches it through
        self.inline: dict = {}         # offset of an inline aggregate -> {(base, tool)}
        self.changed = _changed(text, code)     # NAME -> how the module changes it before its motions
        base = tool = None
        ipo = None
        events = [(m.start(), m) for m in _EVENT.finditer(code)] + _calls(code)
        for at, m in sorted(events, key=lambda e: e[0]):
            line = line_and_column(text, at)[0]
            if isinstance(m, str):                    # a subroutine of the module that sets the base or tool
                base = tool = Computed(f"set by the subroutine {m}() called at line {line}")
            elif m.group("sys"):
                which = m.group("sys").upper()
                value = _state_value(which, m.group("value"), line, frames, source, frame)
                base, tool = (value, tool) if which == "$BASE" else (base, value)
            elif m.group("bas"):
                number = m.group("number").strip()
                which = m.group("bas").upper()
                value = (NULLFRAME if int(number) == 0 else f"{which}_DATA[{int(number)}]") if \
                    re.fullmatch(r"\d+", number) else Computed(f"BAS(#{which}, {number}) at line {line}")
                base, tool = (value, tool) if which == "BASE" else (base, value)
            elif m.group("fdat"):
                data, ipo = fdat.get(m.group("fdat").upper()), None
                base, tool = fdat_frames(data) if data is not None else (Undefined(
                    f"FDAT_ACT = {m.group('fdat')} at line {line}, which neither the module nor a $config.dat beside "
                    "it (or in System/ of a folder above it) defines: put the cell's $config.dat there"),) * 2
            elif m.group("ipo"):
                ipo = FixedTool(f"$IPO_MODE = #{m.group('ipo')} at line {line}") if \
                    m.group("ipo").upper() == "TCP" else None
            else:
                self._motion(m, (ipo, tool) if ipo is not None else (base, tool))

    def _motion(self, m, state: tuple) -> None:
        args = m.group("args")
        parts = [args] if m.group("motion").upper() not in ("CIRC", "SCIRC") else top_level(args)[:2]
        for part in parts:
            offset = m.start("args") + args.find(part) + len(part) - len(part.lstrip())
            part = part.strip()
            if part.startswith("{"):
                self.inline.setdefault(offset, set()).add(state)
                continue
            name = re.match(r"([$A-Za-z_][\w$]*)\s*(\[[^\]]*\])?", part)
            if name is None:
                continue
            rest = part[name.end():].lstrip()
            index = re.sub(r"\s+", "", name.group(2) or "")
            found = name.group(1).upper() + (index if re.fullmatch(r"\[\d+\]", index) else "[]" if index else "")
            if rest.startswith(":") or (rest[:1] in "+-*/" and rest):
                self.through.setdefault(found.replace("[]", ""), part.split(" C_")[0].strip())
            else:
                self.named.setdefault(found, set()).add(state)

    def states(self, name: str) -> set:
        """The (base, tool) pairs a named point is moved to with (an element: also those of ``NAME[i]``)."""
        found = set(self.named.get(name, set()))
        if "[" in name:
            found |= self.named.get(name.split("[")[0] + "[]", set())
        return found

    def change(self, name: str) -> str | None:
        """How the module changes the point ``name`` (or its array) before its motions, if it does."""
        return self.changed.get(name) or self.changed.get(name.split("[")[0])


def _calls(code: str) -> list[tuple[int, str]]:
    """Calls of the module's own subroutines that set the base, the tool or the interpolation mode: (offset,
    name), outside the subroutine itself."""
    subs = {m.group("name").upper(): m.span() for m in _SUB.finditer(code) if _SETS_FRAME.search(m.group("body"))}
    if not subs:
        return []
    pattern = re.compile(r"^[ \t]*(" + "|".join(map(re.escape, subs)) + r")[ \t]*\(", re.IGNORECASE | re.MULTILINE)
    return [(m.start(), m.group(1)) for m in pattern.finditer(code)
            if not subs[m.group(1).upper()][0] <= m.start() < subs[m.group(1).upper()][1]]


def _changed(text: str, code: str) -> dict:
    """Points a statement of the module changes in part: a component (``XC1.Z = XC1.Z + 20``) or a partial
    aggregate (``XM1 = {X 500, Y 0}``, the rest kept): NAME -> the statement and its line."""
    out: dict = {}
    for m in _CHANGED.finditer(code):
        value = m.group("value").strip()
        if m.group("part") is None:
            items = {i.split()[0].upper() for i in value.strip("{} ").split(",") if i.strip()} \
                if value.startswith("{") and value.endswith("}") else set()
            if not items or not items <= set(POSE_KEYS + JOINT_KEYS) or set(POSE_KEYS) <= items or \
                    set(JOINT_KEYS) <= items:
                continue                                  # not a point's aggregate, or a whole one
        statement = " ".join(code[m.start("name"):m.end("value")].split())
        out.setdefault(key(m.group("name")), f"{statement} at line {line_and_column(text, m.start('name'))[0]}")
    return out


def _state_value(which: str, value: str, line: int, frames: dict, source: str, frame: Callable):
    """The base or tool a ``$BASE = ..``/``$TOOL = ..`` assignment sets: a name, a literal frame (defined here
    as ``$BASE at line N``), or Computed."""
    upper = re.sub(r"\s+", "", value).upper()
    data = "BASE_DATA" if which == "$BASE" else "TOOL_DATA"
    if upper == NULLFRAME:
        return NULLFRAME
    if re.fullmatch(data + r"\[\d+\]", upper):
        return upper
    if upper.startswith("{") and upper.endswith("}"):
        try:
            pose = frame(value, source)
        except ProgramSyntaxError:
            pose = None
        if pose is not None:
            name = f"{which} at line {line}"
            frames[name] = pose
            return name
    return Computed(f"{which} = {value.strip()} at line {line}")

