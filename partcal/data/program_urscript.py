"""URScript (Universal Robots, ``.script``): pose literals ``p[x, y, z, rx, ry, rz]`` and joint lists.

Units of the language: positions in metres, orientations as rotation vectors (axis times angle) in radians,
joints in radians. Targets are

- a pose literal ``p[...]`` as the first argument of ``movel``, ``movej``, ``movep``, ``movec`` (both its
  poses), ``servoj`` or ``get_inverse_kin``, or assigned to a variable (``wp1 = p[...]``) that a move
  takes (``movel(wp1, ..)``; ``movel(pose_trans(Plane_1, wp1), ..)``: in the feature ``Plane_1``): in the
  default frame (the robot base, or the feature given as ``--frame``);
- ``pose_trans(NAME, p[...])``: the pose is relative to the feature ``NAME``, which must be given
  (``--frame NAME=p[...]``);
- a list of six numbers as the first argument of a move (joints), or assigned to a variable that some
  move takes as its first argument.

``set_tcp(p[...])`` sets the tool of the moves after it (in file order): a pose variable has the tool of the
moves that take it, wherever it is assigned (PolyScope declares every waypoint at the top); ``set_tcp`` of
anything else names a tool that must be given (``--tool``). Relative motions (``pose_add``, ``pose_trans`` of a
variable) are no targets and stay as written; a move to a pose a function computes is reported.
"""

from __future__ import annotations

import re

import numpy as np

from ..robot.rotations import matrices_from_rotation_vectors, rotation_vectors_from_matrices
from .program_text import (CONSTANT_CALLS, CONSTANT_NAMES, Dialect, ProgramSyntaxError, Target, UnknownFrameError,
                           closing, frame_pose, line_and_column, line_end, masked, numbers, syntax_error, top_level)

MOVES = ("movel", "movej", "movep", "movec", "servoj")
_POSE = re.compile(r"\bp\s*\[")
_MOVE = re.compile(r"\b(" + "|".join(MOVES) + r")\s*\(\s*")
_ASSIGN = re.compile(r"(?:^|[\r\n;])[ \t]*(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*=[ \t]*$")
_POSE_TRANS = re.compile(r"\bpose_trans\s*\(\s*([A-Za-z_]\w*)\s*,\s*$")
_SET_TCP = re.compile(r"\bset_tcp\s*\(\s*")
M_DECIMALS, RAD_DECIMALS = 8, 9        # 1e-8 m = 1e-5 mm; 1e-9 rad


def parse(text: str, source: str) -> tuple[list[Target], dict, list]:
    """The targets of a URScript program (``text``: the file decoded as latin-1), the tools it sets (name ->
    pose (4, 4) mm), and the poses computed at run time, left as written."""
    code = masked(text, "#")
    tools: dict = {}
    tcps = _tcps(text, code, source, tools)
    uses, values = _pose_uses(code, tcps), _assignments(text, code)
    targets, left = [], []
    for m in _POSE.finditer(code):
        start = m.end() - 1
        if closing(code, start, "[", "]") < 0:          # a broken program, whether or not a move takes this pose
            raise syntax_error(source, text, start, "pose literal", "a closing ']'")
        before = code[max(0, m.start() - 200):m.start()]
        frame, tool, variable = None, _tool_at(tcps, start), None
        if re.search(r"\bset_tcp\s*\(\s*$", before):
            continue                                                    # a tool, not a target
        assigned = _ASSIGN.search(before)
        if re.search(r"\b(" + "|".join(MOVES) + r"|get_inverse_kin)\s*\(\s*$", before) or \
                re.search(r"\bmovec\s*\([^()]*,\s*$", before):
            pass
        elif (trans := _POSE_TRANS.search(before)) is not None:
            if not _MOVED_TRANS.search(before):
                continue                        # pose_trans(A, p[..]) computed into a variable: an offset of A
            frame = trans.group(1)
        elif assigned and assigned.group(1) in uses:                    # a pose variable that a move takes
            variable = assigned.group(1)
            frame, tool = _one_use(text, code, source, start, variable, uses[variable])
        else:
            continue                                        # an offset, an argument, a variable no move takes
        name = _name_before(code, start) or "p[...]"
        why = _computed(code, start, "pose") or _computed_frame(frame, values) or _reassigned(variable, values) or \
            (f"moved to with a TCP computed at run time ({tool})" if tool and tool.endswith(_COMPUTED_TCP) else None)
        if why:
            left.append((_first_item(code, start), name, why + ": kept as written"))
        else:
            targets.append(_pose_target(text, code, source, start, frame, tool, name))
    targets += _joint_targets(text, code, source, left) + _list_targets(text, code, source, tcps, values, left)
    left += _relative_moves(code) + _computed_moves(code, values)
    return sorted(targets, key=lambda t: t.fields[0].start), tools, left


_MOVED_TRANS = re.compile(r"\b(?:" + "|".join(MOVES) + r"|get_inverse_kin)\s*\(\s*pose_trans\s*\(\s*[A-Za-z_]\w*\s*,\s*$")
_ASSIGNMENT = re.compile(r"(?:^|(?<=[\r\n;]))[ \t]*(?:global[ \t]+|local[ \t]+)?([A-Za-z_]\w*)[ \t]*(?::=|=(?!=))[ \t]*",
                         re.MULTILINE)


def _assignments(text: str, code: str) -> dict:
    """Every assignment of a variable: name -> [(its line, the value as written, whether it is a literal: a pose
    or a list of numbers and constant arithmetic, no value of the run)]."""
    out: dict = {}
    for m in _ASSIGNMENT.finditer(code):
        end = m.end()
        depth = 0
        while end < len(code) and (depth > 0 or code[end] not in "\r\n;"):
            depth += 1 if code[end] in "([" else -1 if code[end] in ")]" else 0
            end += 1
        value = " ".join(code[m.end():end].split())
        out.setdefault(m.group(1), []).append((line_and_column(text, m.start(1))[0], value, _is_literal(value)))
    return out


def _is_literal(value: str) -> bool:
    """Whether an assigned value is written out, no value of the run: ``p[..]`` or ``[..]`` (lists of them too)
    naming no variable or function but constant arithmetic's (a number written wrong is the reader's to refuse)."""
    return value.strip()[:1] in ("p", "[") and not set(_IDENTIFIER.findall(re.sub(r"\bp\s*\[", "[", value))) - _CONSTANT


def _first_computed(name: str | None, values: dict) -> tuple | None:
    """The first assignment of ``name`` that is no literal: (line, value), or None."""
    return next(((line, value) for line, value, literal in values.get(name, ()) if not literal), None)


def _computed_frame(frame: str | None, values: dict) -> str | None:
    """Why a pose relative to ``frame`` (``pose_trans(frame, p[..])``) is no target: ``frame`` is computed at
    run time (``here = get_actual_tcp_pose()``), not a feature to give."""
    found = _first_computed(frame, values)
    return None if found is None else (f"relative to {frame}, a pose computed at run time ({frame} = {found[1]} at "
                                       f"line {found[0]})")


def _reassigned(variable: str | None, values: dict) -> str | None:
    """Why a pose literal assigned to ``variable`` is no target: the variable is assigned a computed pose too
    (PolyScope's ``global Place_p=p[0,0,0,0,0,0]``, set by an Assignment node before its move)."""
    found = _first_computed(variable, values)
    return None if found is None else (f"{variable} is also assigned {found[1]} at line {found[0]}: the pose its "
                                       "moves take is computed at run time, not this one")


def _computed_moves(code: str, values: dict) -> list[tuple[int, str, str]]:
    """Moves to a variable only ever assigned a computed pose (``here = get_actual_tcp_pose()``, then
    ``movel(here)``): no target, reported as ``left`` entries (offset, name, why)."""
    out = []
    for m in re.finditer(r"\b(?P<move>" + "|".join(MOVES) + r"|get_inverse_kin)\s*\(\s*(?P<name>[A-Za-z_]\w*)\s*[,)]",
                         code):
        assigned = values.get(m.group("name"), ())
        if assigned and not any(literal for _, _, literal in assigned):
            line, value = _first_computed(m.group("name"), values)
            out.append((m.start("name"), m.group("move"), f"moved to {m.group('name')}, a pose computed at run time "
                        f"({m.group('name')} = {value} at line {line}): not compensated, kept as written"))
    return out


_RELATIVE = re.compile(r"\b(?P<move>" + "|".join(MOVES) + r")\s*\(\s*(?P<call>(?!pose_trans\b|get_inverse_kin\s*\(\s*"
                       r"(?:p\s*\[|[A-Za-z_]\w*\s*[,)]))[A-Za-z_]\w*)\s*\(")


def _relative_moves(code: str) -> list[tuple[int, str, str]]:
    """Moves to a pose a function computes at run time (``movel(pose_add(approach, p[0, 0, 0.1, 0, 0, 0]))``):
    no target, reported with the function, as ``left`` entries (offset, name, why)."""
    return [(m.start("call"), m.group("move"), f"a relative motion computed at run time ({m.group('call')}(..)): "
             "not compensated, kept as written") for m in _RELATIVE.finditer(code)]


_IDENTIFIER = re.compile(r"(?<![\w.])[A-Za-z_]\w*")
_EXPRESSION = re.compile(r"[\w\s.+\-*/%()\[\],]+")
_COMPUTED_TCP = "(computed at run time)"
_CONSTANT = set(CONSTANT_CALLS) | set(CONSTANT_NAMES)        # d2r(180), pi / 2: constant arithmetic, read


def _computed(code: str, start: int, what: str) -> str | None:
    """Why the list at ``start`` is no target: some item is an expression of run-time values (``p[home[0] + r,
    ..]``); None when every item is a number, or when an item is neither (then the caller refuses it)."""
    end = _end_of(code, start)
    items = top_level(code[start + 1:end])
    if any(set(_IDENTIFIER.findall(item)) - _CONSTANT and _EXPRESSION.fullmatch(item.strip()) for item in items):
        body = " ".join(code[start + 1:end].split())
        shown = body if len(body) <= 60 else body[:57] + "..."
        return f"a {what} computed at run time ({'p' if what == 'pose' else ''}[{shown}])"
    return None


def _first_item(code: str, start: int) -> int:
    """Offset of the first character of the first item of the list at ``start``."""
    return start + 1 + len(code[start + 1:]) - len(code[start + 1:].lstrip())


def _one_use(text, code, source, start, name, used) -> tuple:
    """The frame and the tool of a pose variable: those of the moves that take it (PolyScope declares every
    waypoint at the top and sets the TCP before the moves); refused when they differ."""
    if len(used) > 1:
        first = start + 1 + len(code[start + 1:_end_of(code, start)]) - \
            len(code[start + 1:_end_of(code, start)].lstrip())                # the first number
        line, column = line_and_column(text, first)
        frames = {f for f, _ in used}
        if len(frames) > 1:
            named = " and ".join("the base" if f is None else f"pose_trans({f}, ..)" for f in sorted(frames, key=str))
            raise UnknownFrameError(f"{source}: line {line}, column {column}: target {name}: it is used in {named}: "
                                    "one pose cannot be compensated for two frames; nothing written")
        named = " and ".join("the flange" if t is None else t for t in sorted({t for _, t in used}, key=str))
        raise UnknownFrameError(f"{source}: line {line}, column {column}: target {name}: it is moved to with the "
                                f"tools {named}: one pose cannot be compensated for two tools; nothing written")
    return next(iter(used))


def _tool_at(tcps: list, offset: int) -> str | None:
    """The tool in force at ``offset``: the last ``set_tcp`` before it (None: none, the default)."""
    return next((t for at, t in reversed(tcps) if at < offset), None)


def _pose_target(text, code, source, start, frame, tool, name) -> Target:
    end = closing(code, start, "[", "]")
    if end < 0:
        raise syntax_error(source, text, start, "pose literal", "a closing ']'")
    fields = numbers(source, text, start + 1, end, 6, "pose p[x, y, z, rx, ry, rz] (m, rad)", constants=True)
    return Target(name, 0, 0, "pose", tuple(fields), frame=frame, tool=tool, line_end=line_end(text, start))


def _end_of(code: str, start: int) -> int:
    """The offset of the ``]`` closing the ``[`` at ``start`` (the end of the text if none)."""
    end = closing(code, start, "[", "]")
    return len(code) if end < 0 else end


def _name_before(code: str, start: int) -> str | None:
    """The variable a pose literal at ``start`` is assigned to, or the move that takes it."""
    head = code[max(0, start - 200):start]
    m = re.search(r"([A-Za-z_]\w*)[ \t]*=[ \t]*p\s*$", head)
    if m:
        return m.group(1)
    move = re.search(r"\b(" + "|".join(MOVES) + r")\s*\((?:\s*pose_trans\s*\()?[^()]*$", head)
    return move.group(1) if move else None


def _tcps(text: str, code: str, source: str, tools: dict) -> list[tuple[int, str]]:
    """Each ``set_tcp`` (its offset, and the tool's name: ``set_tcp, line N`` for a pose literal, whose pose
    goes into ``tools``, or the argument named)."""
    out = []
    for m in _SET_TCP.finditer(code):
        end = closing(code, code.rfind("(", 0, m.end()), "(", ")")
        arg = code[m.end():end].strip() if end > 0 else ""
        if re.match(r"p\s*\[", arg) and _computed(code, code.index("[", m.end()), "pose"):
            out.append((m.start(), f"set_tcp at line {line_and_column(text, m.start())[0]} {_COMPUTED_TCP}"))
        elif re.match(r"p\s*\[", arg):
            inner = code.index("[", m.end())
            fields = numbers(source, text, inner + 1, closing(code, inner, "[", "]"), 6, "set_tcp pose", constants=True)
            v = np.array([f.value for f in fields])
            name = f"set_tcp at line {line_and_column(text, m.start())[0]}"
            tools[name] = frame_pose(v[:3] * 1000.0, matrices_from_rotation_vectors(v[3:])[0])
            out.append((m.start(), name))
        else:
            out.append((m.start(), arg or "set_tcp(...)"))
    return out


def _pose_uses(code: str, tcps: list) -> dict:
    """The variables that moves take as a pose (``movel(wp1, ..)``, ``movel(pose_trans(Plane_1, wp1), ..)``,
    both poses of ``movec``), each with the (frame, tool) pairs it is moved to with (None: the default frame;
    the tool: the last ``set_tcp`` before the move, not before the variable's assignment)."""
    uses: dict = {}
    moves = "|".join(MOVES) + "|get_inverse_kin"
    for m in re.finditer(r"\b(?:" + moves + r")\s*\(\s*(?:pose_trans\s*\(\s*([A-Za-z_]\w*)\s*,\s*)?"
                         r"([A-Za-z_]\w*)\s*[,)]", code):
        uses.setdefault(m.group(2), set()).add((m.group(1), _tool_at(tcps, m.start())))
    for m in re.finditer(r"\bmovec\s*\([^(),]*,\s*([A-Za-z_]\w*)\s*[,)]", code):
        uses.setdefault(m.group(1), set()).add((None, _tool_at(tcps, m.start())))
    return uses


def _joint_targets(text: str, code: str, source: str, left: list) -> list[Target]:
    """Lists of six numbers taken by a move: inline, or through a variable (computed ones go to ``left``)."""
    out, moved, found = [], set(), []
    for m in _MOVE.finditer(code):
        at = m.end()
        if code.startswith("[", at):
            found.append((at, m.group(1)))
        elif (name := re.match(r"([A-Za-z_]\w*)\s*(\[?)", code[at:])) is not None and not name.group(2):
            moved.add(name.group(1))                          # an element of a list: _list_targets
    for name in moved:
        for m in re.finditer(r"(?:^|[\r\n;])[ \t]*(?:global[ \t]+|local[ \t]+)?" + re.escape(name) +
                             r"[ \t]*=[ \t]*\[", code):
            found.append((m.end() - 1, name))
    for at, name in found:
        why = _computed(code, at, "joint list")
        if why:
            left.append((_first_item(code, at), name, why + ": kept as written"))
        else:
            out.append(_joints(text, code, source, at, name))
    return out


def _list_targets(text: str, code: str, source: str, tcps: list, values: dict, left: list) -> list[Target]:
    """The poses and joint lists of a list that moves take element by element (``path = [p[..], p[..]]``, then
    ``movel(path[i])`` in a loop): targets ``path[0]``, ``path[1]``.., with the tool of those moves (computed
    ones go to ``left``; a list moved to with two tools is refused, as a pose variable)."""
    uses: dict = {}
    for m in re.finditer(r"\b(?:" + "|".join(MOVES) + r"|get_inverse_kin)\s*\(\s*([A-Za-z_]\w*)\s*\[", code):
        uses.setdefault(m.group(1), set()).add((None, _tool_at(tcps, m.start())))
    out = []
    for name, used in uses.items():
        for m in re.finditer(r"(?:^|(?<=[\r\n;]))[ \t]*(?:global[ \t]+|local[ \t]+)?" + re.escape(name) +
                             r"[ \t]*=(?!=)[ \t]*\[", code, re.MULTILINE):
            at, end = m.end() - 1, _end_of(code, m.end() - 1)
            offset = at + 1
            for k, item in enumerate(top_level(code[at + 1:end])):
                start = offset + len(item) - len(item.lstrip())
                offset += len(item) + 1
                pose = re.match(r"p\s*\[", code[start:])
                if not pose and not code.startswith("[", start):
                    continue                                        # an element computed some other way
                start += pose.end() - 1 if pose else 0
                what, element = "pose" if pose else "joint list", f"{name}[{k}]"
                why = _computed(code, start, what)
                if why:
                    left.append((_first_item(code, start), element, why + ": kept as written"))
                elif pose:
                    frame, tool = _one_use(text, code, source, start, element, used)
                    out.append(_pose_target(text, code, source, start, frame, tool, element))
                else:
                    out.append(_joints(text, code, source, start, element))
    return out


def _joints(text, code, source, start, name) -> Target:
    end = closing(code, start, "[", "]")
    if end < 0:
        raise syntax_error(source, text, start, "joint list", "a closing ']'")
    fields = numbers(source, text, start + 1, end, 6, "joint list [q1, ..., q6] (rad)", constants=True)
    return Target(name, 0, 0, "joints", tuple(fields), line_end=line_end(text, start))


def poses(values):
    """Positions (n, 3) mm and rotations (n, 3, 3) of pose fields (n, 6): metres, then a rotation vector."""
    return values[:, :3] * 1000.0, matrices_from_rotation_vectors(values[:, 3:])


def pose_values(positions_mm, rotations, old):
    """Pose fields (n, 6): metres, then the rotation vector (radians) nearest the one written."""
    return np.hstack([np.asarray(positions_mm) / 1000.0, rotation_vectors_from_matrices(rotations, near=old[:, 3:])])


def frame(value: str, source: str) -> np.ndarray:
    """A feature or a TCP given as ``p[x, y, z, rx, ry, rz]`` (m, rad): the pose (4, 4) in mm."""
    m = re.fullmatch(r"\s*p\s*\[(.*)\]\s*", value)
    if not m:
        raise ProgramSyntaxError(f"{source}: expected a URScript pose p[x, y, z, rx, ry, rz] (m, rad), got {value!r}")
    fields = numbers(source, value, m.start(1), m.end(1), 6, "pose p[x, y, z, rx, ry, rz] (m, rad)")
    v = np.array([f.value for f in fields])
    return frame_pose(v[:3] * 1000.0, matrices_from_rotation_vectors(v[3:])[0])


DIALECT = Dialect("urscript", (".script", ".urscript"), parse, frame, "#", poses=poses, pose_values=pose_values,
                  pose_decimals=(M_DECIMALS,) * 3 + (RAD_DECIMALS,) * 3, joint_unit_deg=180.0 / np.pi,
                  joint_decimals=RAD_DECIMALS)
