"""ABB RAPID (``.mod``, ``.prg``): ``robtarget`` and ``jointtarget`` data.

Units of the language: ``robtarget`` ``[[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [eax_a, ..]]``
with the position in mm, the orientation a unit quaternion scalar first, and ``confdata`` the quarter
revolutions of axes 1, 4 and 6 (``cf = floor(angle / 90)``; ``cfx`` depends on the robot type and is kept
as written); ``jointtarget`` ``[[j1, .., j6], [eax_a, ..]]`` in degrees. Targets are declarations
(``CONST``, ``PERS``, ``VAR``) with an initial value, each element of a declared array (``p{3}``), and
inline values as a move's target.

A robtarget is in the work object and with the tool of the moves that use it (``MoveL p10, v100, z10,
tool1 \\WObj:=wobj1;``, ``TriggL p10, v100, trigg1, z10, tool1;``, also through ``Offs(p10, ..)`` and
``RelTool(p10, ..)``); ``wobj0`` (the world, taken as the robot base) and ``tool0`` (the flange) when no
move names others. ``tooldata`` (held by the robot) and ``wobjdata`` (a fixed user frame: ``uframe`` then
``oframe``) declared in the module are used; others must be given as options. A robtarget used with two
different tools or work objects is refused. Names are case-insensitive (``WObj0`` is ``wobj0``).
``ConfJ \\Off`` and ``ConfL \\Off`` drop the written configuration of the targets of the moves they govern
(the controller does not monitor it). A robtarget assigned at run time, or moved to with a tool or work
object assigned at run time or under ``PDispOn``, is left as written and reported.
"""

from __future__ import annotations

import re

import numpy as np

from ..robot.rotations import matrices_from_quaternions, quaternions_from_matrices
from .program_text import (Dialect, ProgramSyntaxError, Target, UnknownFrameError, closing, frame_pose,
                           line_and_column, line_end, masked, numbers, syntax_error)

MM_DECIMALS, QUATERNION_DECIMALS, DEG_DECIMALS = 6, 9, 6
UNIT_TOLERANCE = 1e-3      # a quaternion's norm may differ from 1 by this much (numbers rounded when written)
UNUSED_AXIS = 8.9e9        # an external axis written 9E9 (9E+09) is not used
_DECL = re.compile(r"\b(?:CONST|PERS|VAR)\s+(robtarget|jointtarget|tooldata|wobjdata)\s+([A-Za-z_]\w*)"
                   r"\s*(\{\s*\d+\s*\})?\s*:=\s*\[", re.IGNORECASE)
_WOBJ = re.compile(r"\\WObj\s*:=\s*([A-Za-z_]\w*)", re.IGNORECASE)


def parse(text: str, source: str) -> tuple[list[Target], dict, list]:
    """The targets of a RAPID module (``text``: its bytes decoded as latin-1), the tools and work objects it
    declares (name -> pose (4, 4) mm; ``tool0`` and ``wobj0`` the identity) and the poses left as written.

    RAPID names are case-insensitive: ``WObj0`` is ``wobj0``, ``TGRIPPER`` the ``tGripper`` declared."""
    code = masked(text, "!")
    frames = {"tool0": np.eye(4), "wobj0": np.eye(4)}
    names = {"tool0": "tool0", "wobj0": "wobj0"}           # lower case -> the name as declared
    targets = []
    for m in _DECL.finditer(code):
        kind, name, start = m.group(1).lower(), m.group(2), m.end() - 1
        read = {"robtarget": _robtarget, "jointtarget": _jointtarget}.get(kind)
        if read is not None and m.group(3):             # an array: one target per element, name{k}
            elements = _elements(text, code, source, start, f"{kind} array {name}")
            targets += [read(text, code, source, at, f"{name}{{{k}}}") for k, (at, end) in
                        enumerate(elements, start=1) if end > 0]
            if len(elements) != int(m.group(3).strip("{} ")) or any(end < 0 for _, end in elements):
                raise syntax_error(source, text, start, f"{kind} array {name}{m.group(3)}",
                                   f"{m.group(3).strip('{} ')} bracketed {kind}s")
        elif read is not None:
            targets.append(read(text, code, source, start, name))
        else:
            names.setdefault(name.lower(), name)
            pose = _frame_data(text, code, source, start, name, kind)
            if pose is not None:
                frames[name] = pose
    changed = _changed_at_run_time(text, code)
    uses: dict = {}
    left: list = []
    for move, state in _moves(code):
        _use(text, code, source, move, state, names, changed, targets, uses, left)
    return _framed(text, source, targets, uses, changed, left), frames, left


_EVENT = re.compile(r"\bConf(?P<conf>[LJ])\s*\\(?P<on>On|Off)\b|\b(?P<pdisp>PDispOn|PDispSet|PDispOff)\b"
                    r"|(?P<move>\b(?:Move\w*|Trigg[JLC]))\s+(?P<args>[^;]*);", re.IGNORECASE)
_ASSIGNED = re.compile(r"(?:^|;|\bTHEN\b|\bELSE\b|\bDO\b)[ \t]*(?P<name>[A-Za-z_]\w*)"
                       r"(?P<part>(?:[ \t]*\.[ \t]*\w+|[ \t]*\{[^}\r\n]*\})*)[ \t]*:=", re.IGNORECASE | re.MULTILINE)


def _moves(code: str):
    """Each ``Move*`` and ``TriggJ``/``TriggL``/``TriggC`` instruction in file order, with the state before it:
    whether its configuration is monitored (``ConfJ`` for ``MoveJ*`` and ``TriggJ``, ``ConfL`` for the linear and
    circular ones; on until ``\\Off``) and the program displacement (``PDispOn``/``PDispSet`` until
    ``PDispOff``) in force."""
    conf = {"L": True, "J": True}
    displaced = None
    for m in _EVENT.finditer(code):
        if m.group("conf"):
            conf[m.group("conf").upper()] = m.group("on").lower() == "on"
        elif m.group("pdisp"):
            displaced = None if m.group("pdisp").lower() == "pdispoff" else m.group("pdisp")
        else:
            kind = m.group("move").upper()
            monitored = conf["J"] if kind.startswith(("MOVEJ", "TRIGGJ")) else \
                conf["L"] if kind.startswith(("MOVEL", "MOVEC", "TRIGGL", "TRIGGC")) else True
            yield m, (monitored, displaced)


def _changed_at_run_time(text: str, code: str) -> dict:
    """Data assigned by an instruction (``wobj1.oframe.trans.x := ..``, ``p10 := CRobT()``): lower-case name ->
    the statement and its line. Declarations (``PERS wobjdata wobj1 := ..``) are no assignments."""
    out: dict = {}
    for m in _ASSIGNED.finditer(code):
        name = m.group("name")
        if name.upper() in ("CONST", "PERS", "VAR", "TASK", "LOCAL"):
            continue
        stop = code.find(";", m.end())
        statement = " ".join(code[m.start("name"):stop if stop > 0 else m.end()].split())
        out.setdefault(name.lower(), f"{statement} at line {line_and_column(text, m.start('name'))[0]}")
    return out


def _use(text, code, source, m, state, names, changed, targets, uses, left) -> None:
    """A move's targets: inline ones become targets (or are left), named ones record the use."""
    monitored, displaced = state
    args = _arguments(code, m.start("args"), m.end("args"))
    plain = [(a, s) for a, s in args if not a.startswith("\\")]
    move = m.group("move").upper()
    n_targets = 2 if move in ("MOVEC", "TRIGGC") or move.startswith("MOVEC") else 1
    at = n_targets + (3 if move.startswith("TRIGG") else 2)       # speed, zone (a Trigg: speed, trigger, zone)
    if len(plain) <= at:
        return
    tool = re.match(r"[A-Za-z_]\w*", plain[at][0])
    wobj = _WOBJ.search(m.group("args"))
    tool_name = tool.group() if tool else plain[at][0]
    wobj_name = wobj.group(1) if wobj else "wobj0"
    where = (names.setdefault(tool_name.lower(), tool_name), names.setdefault(wobj_name.lower(), wobj_name))
    for arg, start in plain[:n_targets]:
        if arg.startswith("["):
            pose = arg.startswith("[[") and arg.count("[") >= 5
            literal = _robtarget(text, code, source, start, m.group("move")) if pose else \
                _jointtarget(text, code, source, start, m.group("move"))
            why = _why_left(where, displaced, changed) if pose else None
            if why:
                left.append((literal.fields[0].start, literal.name, why))
                continue
            literal.tool, literal.frame = where
            if not monitored:
                literal.configuration = None
            targets.append(literal)
        else:
            used = re.match(r"(?:(?:Offs|RelTool)\s*\(\s*)?([A-Za-z_]\w*)", arg, re.IGNORECASE)
            if used:
                uses.setdefault(used.group(1).lower(), set()).add((where, monitored, displaced))


def _why_left(where: tuple, displaced, changed: dict) -> str | None:
    """Why a robtarget moved to with ``where`` (tool, work object) cannot be compensated, if it cannot."""
    if displaced:
        return f"moved to under a program displacement ({displaced}), set at run time: not compensated, kept as written"
    for what, name in zip(("tool", "work object"), where):
        if name.lower() in changed:
            return (f"its {what} {name} is changed at run time ({changed[name.lower()]}): not compensated in its "
                    "declared value, kept as written")
    return None


def _framed(text, source, targets, uses, changed, left) -> list[Target]:
    """Named targets with the tool and work object of their moves (several: refused), the configuration
    dropped where every move that takes it leaves it unmonitored; those that cannot be compensated go to
    ``left``."""
    out = []
    for t in targets:
        base = t.name.split("{")[0].lower()
        seen = uses.get(base)
        if t.kind == "pose" and t.tool is None and base in changed:
            left.append((t.fields[0].start, t.name, f"assigned at run time ({changed[base]}): its declared value "
                                                   "is not what the robot moves to, kept as written"))
            continue
        if t.kind == "pose" and seen and t.tool is None:
            wheres = {w for w, _, _ in seen}
            if len(wheres) > 1:
                uses_text = " and ".join(f"{a}\\WObj:={b}" for a, b in sorted(wheres))
                t.line, t.column = line_and_column(text, t.fields[0].start)
                raise UnknownFrameError(f"{t.where(source)}: it is used with {uses_text}: one robtarget cannot be "
                                        "compensated for two tools or work objects (declare one per use); nothing "
                                        "written")
            why = next((w for w in (_why_left(where, d, changed) for where, _, d in seen) if w), None)
            if why:
                left.append((t.fields[0].start, t.name, why))
                continue
            t.tool, t.frame = next(iter(wheres))
            if not any(monitored for _, monitored, _ in seen):
                t.configuration = None
        out.append(t)
    return sorted(out, key=lambda t: t.fields[0].start)


def _arguments(code: str, start: int, end: int) -> list[tuple[str, int]]:
    """Top-level comma-separated arguments of an instruction (text, offset)."""
    out, depth, at = [], 0, start
    for k in range(start, end + 1):
        c = code[k] if k < end else ","
        if c in "[(":
            depth += 1
        elif c in "])":
            depth -= 1
        if c == "," and depth == 0:
            part = code[at:k]
            out.append((part.strip(), at + len(part) - len(part.lstrip())))
            at = k + 1
    return out


def _elements(text, code, source, start, what) -> list[tuple[int, int]]:
    """The bracketed elements ``[..]`` of the list at ``start``: their (start, end) offsets."""
    end = closing(code, start, "[", "]")
    if end < 0:
        raise syntax_error(source, text, start, what, "a closing ']'")
    out, at = [], start + 1
    while at < end:
        while at < end and code[at] in " \t\r\n,":
            at += 1
        if at >= end:
            break
        if code[at] != "[":
            stop = min([i for i in (code.find(",", at, end), end) if i >= 0])
            out.append((at, -stop))                                 # not a list: a plain value
            at = stop
            continue
        close = closing(code, at, "[", "]")
        out.append((at, close))
        at = close + 1
    return out


def _robtarget(text, code, source, start, name) -> Target:
    what = f"robtarget {name} [[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [eax]]"
    parts = _elements(text, code, source, start, what)
    if len(parts) != 4 or any(e < 0 for _, e in parts):
        raise syntax_error(source, text, start, what, "four bracketed lists")
    trans = numbers(source, text, parts[0][0] + 1, parts[0][1], 3, f"{name}: position [x, y, z] (mm)")
    rot = numbers(source, text, parts[1][0] + 1, parts[1][1], 4, f"{name}: quaternion [q1, q2, q3, q4]")
    conf = numbers(source, text, parts[2][0] + 1, parts[2][1], 4, f"{name}: confdata [cf1, cf4, cf6, cfx]")
    extax = numbers(source, text, parts[3][0] + 1, parts[3][1], 6, f"{name}: extjoint [eax_a, .., eax_f]")
    _check_unit(text, source, rot, f"{name}: quaternion")
    used = tuple((f"eax_{'abcdef'[k]}", f.value) for k, f in enumerate(extax) if f.value < UNUSED_AXIS)
    return Target(name, 0, 0, "pose", tuple(trans + rot), configuration=tuple(int(f.value) for f in conf),
                  line_end=line_end(text, start), external=used)


def _check_unit(text, source, fields, what) -> None:
    """A quaternion of a robtarget, a tool or a work object: of norm 1 within 1e-3 (the controller's own
    check), else refused naming where it is; never normalised silently (a zero one has no rotation)."""
    norm = float(np.linalg.norm([f.value for f in fields]))
    if abs(norm - 1.0) > UNIT_TOLERANCE:
        raise syntax_error(source, text, fields[0].start, f"{what} of norm {norm:.6g}",
                           f"a unit quaternion (norm 1 to {UNIT_TOLERANCE:g})",
                           "[" + ", ".join(f.text for f in fields) + "]")


def _jointtarget(text, code, source, start, name) -> Target:
    what = f"jointtarget {name} [[j1, .., j6], [eax]]"
    parts = _elements(text, code, source, start, what)
    if len(parts) != 2 or any(e < 0 for _, e in parts):
        raise syntax_error(source, text, start, what, "two bracketed lists")
    fields = numbers(source, text, parts[0][0] + 1, parts[0][1], 6, f"{name}: robax [j1, .., j6] (degrees)")
    return Target(name, 0, 0, "joints", tuple(fields), line_end=line_end(text, start))


def _pose(text, code, source, start, what) -> np.ndarray:
    """A ``pose`` ``[[x, y, z], [q1, q2, q3, q4]]`` at ``start``: (4, 4) mm."""
    parts = _elements(text, code, source, start, what)
    if len(parts) != 2 or any(e < 0 for _, e in parts):
        raise syntax_error(source, text, start, what, "[[x, y, z], [q1, q2, q3, q4]]")
    trans = numbers(source, text, parts[0][0] + 1, parts[0][1], 3, f"{what}: [x, y, z]")
    rot = numbers(source, text, parts[1][0] + 1, parts[1][1], 4, f"{what}: [q1, q2, q3, q4]")
    _check_unit(text, source, rot, f"{what}: quaternion")
    return frame_pose([f.value for f in trans], matrices_from_quaternions([f.value for f in rot])[0])


def _frame_data(text, code, source, start, name, kind) -> np.ndarray | None:
    """A tool's ``tframe`` (held by the robot) or a work object's ``uframe oframe`` (fixed); None for others
    (a stationary tool, a moving work object): targets that use them are refused as unknown frames."""
    parts = _elements(text, code, source, start, f"{kind} {name}")
    flag = code[parts[0][0]:-parts[0][1]].strip().upper() if parts and parts[0][1] < 0 else ""
    if kind == "tooldata":
        return _pose(text, code, source, parts[1][0], f"tooldata {name} tframe") if flag == "TRUE" and \
            len(parts) >= 2 and parts[1][1] > 0 else None
    # [robhold, ufprog, ufmec, uframe, oframe]: the string ufmec is blanked out, so the frames are the last two
    fixed = len(parts) >= 4 and flag == "FALSE" and parts[-2][1] > 0 and parts[-1][1] > 0 and parts[1][1] < 0 \
        and code[parts[1][0]:-parts[1][1]].strip().upper() == "TRUE"
    if not fixed:
        return None
    return _pose(text, code, source, parts[-2][0], f"wobjdata {name} uframe") @ \
        _pose(text, code, source, parts[-1][0], f"wobjdata {name} oframe")


def poses(values):
    """Positions (n, 3) mm and rotations (n, 3, 3) of pose fields (n, 7): ``x y z`` mm, the quaternion."""
    return values[:, :3], matrices_from_quaternions(values[:, 3:])


def pose_values(positions_mm, rotations, old):
    """Pose fields (n, 7): ``x y z`` mm and the unit quaternion on the side of the one written (``q`` and
    ``-q`` are one rotation)."""
    return np.hstack([positions_mm, quaternions_from_matrices(rotations, near=old[:, 3:])])


def frame(value: str, source: str) -> np.ndarray:
    """A work object or tool frame given as a RAPID pose ``[[x, y, z], [q1, q2, q3, q4]]`` (mm, quaternion)."""
    text = value.strip()
    if not text.startswith("["):
        raise ProgramSyntaxError(f"{source}: expected a RAPID pose [[x, y, z], [q1, q2, q3, q4]] (mm), got {value!r}")
    return _pose(text, text, source, 0, f"pose {value!r}")


def configuration(q_deg) -> np.ndarray:
    """``(cf1, cf4, cf6, cfx)`` of joint solutions (n, 6) degrees: quarter revolutions; ``cfx`` not computed."""
    q = np.asarray(q_deg, dtype=float)
    quarters = np.floor(q[:, [0, 3, 5]] / 90.0).astype(int)
    return np.hstack([quarters, np.full((len(q), 1), -1)])


def seeds(configurations, reference_deg) -> np.ndarray:
    """IK seeds (n, 6) degrees: axes 1, 4 and 6 in the middle of the quarter revolution ``cf1, cf4, cf6``
    name, the others those of the reference."""
    q = np.array(reference_deg, dtype=float)
    cf = np.asarray(configurations)[:, :3]
    q[:, [0, 3, 5]] = cf * 90.0 + 45.0
    return q


def ranges(configurations) -> tuple[np.ndarray, np.ndarray]:
    """The joint ranges (n, 6) degrees, low and high, that configurations ``(cf1, cf4, cf6, cfx)`` (n, 4) allow:
    axes 1, 4 and 6 in their quarter revolution (edges included), the others free."""
    cf = np.asarray(configurations)[:, :3]
    low, high = np.full((len(cf), 6), -np.inf), np.full((len(cf), 6), np.inf)
    low[:, [0, 3, 5]], high[:, [0, 3, 5]] = cf * 90.0, cf * 90.0 + 90.0
    return low, high


DIALECT = Dialect("rapid", (".mod", ".modx", ".prg", ".sys"), parse, frame, "!", poses=poses, pose_values=pose_values,
                  pose_decimals=(MM_DECIMALS,) * 3 + (QUATERNION_DECIMALS,) * 4, joint_decimals=DEG_DECIMALS,
                  configuration=configuration, compare=(0, 1, 2), seeds=seeds, ranges=ranges, statement_end=";",
                  edge_kept=True)
