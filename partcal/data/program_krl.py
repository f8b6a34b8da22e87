"""KUKA KRL (``.dat`` and ``.src``): the aggregates ``{X .., Y .., Z .., A .., B .., C .., S .., T ..}``.

Units of the language: ``X Y Z`` in mm, ``A B C`` Z-Y-X Euler angles in degrees (``R = Rz(A) Ry(B) Rx(C)``),
``S`` (status) and ``T`` (turn: bit ``k`` set when axis ``k + 1`` is negative) integers, which may be written
in binary (``'B010'``); joint targets ``A1 .. A6`` in degrees. Targets are

- declarations of ``E6POS``, ``POS``, ``E3POS``, ``FRAME`` (poses) and ``E6AXIS``, ``AXIS``, ``E3AXIS``
  (joints), with an initial value;
- assignments of a whole aggregate to a variable (``XP1 = {X ..}``, in ``.src`` files too), and inline
  aggregates of a motion (``PTP {A1 0, ..}``, ``LIN {X .., ..}``).

An aggregate lacking some of ``X Y Z A B C`` (or ``A1 .. A6``) after a ``:``, of ``PTP_REL`` or
``LIN_REL``, or assigned to no declared target is an offset and stays as written; a partial aggregate as
the target of ``PTP``, ``LIN`` or ``CIRC`` (the other coordinates: wherever the robot is) is refused.
``$BASE``, ``$TOOL``, ``BASE_DATA[n]`` and ``TOOL_DATA[n]`` aggregates are frames, not targets:
``BASE_DATA[n]`` and ``TOOL_DATA[n]`` defined in the file are used for the targets that name them.
A target ``XP1`` (or ``P1``) with an ``FDAT`` named ``FP1`` is in the frame ``BASE_DATA[BASE_NO]`` with
the tool ``TOOL_DATA[TOOL_NO]`` (number 0: the robot base, the flange); without one, in the frames of
the options ``--frame`` and ``--tool`` (default: the robot base, the flange).
"""

from __future__ import annotations

import re

import numpy as np

from ..robot.rotations import kuka_abc_from_matrices, matrices_from_kuka_abc
from .program_text import (Dialect, Field, ProgramSyntaxError, Target, closing, frame_pose, is_number, line_end,
                           masked, syntax_error)

POSE_TYPES = {"E6POS", "POS", "E3POS", "FRAME"}
JOINT_TYPES = {"E6AXIS", "AXIS", "E3AXIS"}
POSE_KEYS = ("X", "Y", "Z", "A", "B", "C")
JOINT_KEYS = ("A1", "A2", "A3", "A4", "A5", "A6")
NULLFRAME = "$NULLFRAME"
MM_DECIMALS, DEG_DECIMALS = 6, 6
_DECL = re.compile(r"\bDECL\s+(?:GLOBAL\s+)?([A-Za-z_]\w*)\s+([$A-Za-z_][\w\[\],]*)\s*=\s*$", re.IGNORECASE)
_ASSIGN = re.compile(r"([$A-Za-z_][\w$]*(?:\[[\d, ]*\])?)\s*=\s*$")
_MOTION = re.compile(r"\b(PTP|LIN|CIRC|SPTP|SLIN|SCIRC|PTP_REL|LIN_REL)\s+$", re.IGNORECASE)
_ABSOLUTE_MOTIONS = {"PTP", "LIN", "CIRC", "SPTP", "SLIN", "SCIRC"}
_ITEM = re.compile(r"\s*([A-Za-z_]\w*)\s+(\S(?:.*\S)?)\s*$", re.DOTALL)
_INT = re.compile(r"[-+]?\d+|'[BbHh][0-9A-Fa-f]+'")


def parse(text: str, source: str) -> tuple[list[Target], dict]:
    """The targets of a KRL file (``text``: its bytes decoded as latin-1) and the frames it defines."""
    code = masked(text, ";")
    targets, frames, fdat = [], {NULLFRAME: np.eye(4)}, {}
    at = 0
    while (start := code.find("{", at)) >= 0:
        end = closing(code, start, "{", "}")
        if end < 0:
            raise syntax_error(source, text, start, "aggregate", "a closing '}'")
        at = end + 1
        before = code[max(0, start - 200):start]
        decl, assign = _DECL.search(before), _ASSIGN.search(before)
        kind = name = None
        if decl:
            typ, name = decl.group(1).upper(), decl.group(2)
            kind = "pose" if typ in POSE_TYPES else "joints" if typ in JOINT_TYPES else typ
        elif assign:
            name = assign.group(1)
        elif _MOTION.search(before):
            name = _MOTION.search(before).group(1).upper()
        else:
            continue                                                 # an offset (after ':') or an argument
        items = _items(text, code, source, start, end)
        if kind == "FDAT":
            fdat[name.upper()] = {k: v[1] for k, v in items.items() if k is not None}
            continue
        upper = name.upper()
        if upper.startswith(("BASE_DATA[", "TOOL_DATA[")) and all(k in items for k in POSE_KEYS):
            frames[upper.replace(" ", "")] = _pose_of(items, text, source)[0]
            continue
        if upper.startswith("$") or kind not in (None, "pose", "joints"):
            continue
        if kind is None:
            kind = "pose" if all(k in items for k in POSE_KEYS) else \
                "joints" if all(k in items for k in JOINT_KEYS) else None
            if kind is None and upper in _ABSOLUTE_MOTIONS:     # the other coordinates: whatever the robot has
                raise syntax_error(source, text, start, f"{upper} to a partial aggregate", "a whole target: all "
                                   f"of {' '.join(POSE_KEYS)} or of {' '.join(JOINT_KEYS)} (a partial one cannot "
                                   "be compensated)")
            if kind is None:
                continue
        targets.append(_target(text, source, name, kind, items, start))
    for t in targets:
        _frames_of(t, fdat)
    return targets, frames


def _items(text, code, source, start, end) -> dict:
    """``KEY value`` items of an aggregate: key -> (Field or None, value text, offset); a part that is no
    ``KEY value`` item is kept under ``None`` (its offset), refused only where a target needs its items."""
    out, at = {}, start + 1
    for part in code[start + 1:end].split(","):
        if part.strip():
            m = _ITEM.match(part)
            if not m:
                out.setdefault(None, at + len(part) - len(part.lstrip()))
            else:
                key, value = m.group(1).upper(), m.group(2)
                offset = at + m.start(2)
                field = Field(offset, offset + len(value), value, float(value)) if is_number(value) \
                    else None
                out[key] = (field, value, offset)
        at += len(part) + 1
    return out


def _number(items, key, text, source, what) -> Field:
    field, value, offset = items[key]
    if field is None:
        raise syntax_error(source, text, offset, f"{what}, {key}", "a number", value)
    return field


def _pose_of(items, text, source) -> tuple[np.ndarray, list]:
    fields = [_number(items, k, text, source, "KRL pose") for k in POSE_KEYS]
    v = np.array([f.value for f in fields])
    return frame_pose(v[:3], matrices_from_kuka_abc(v[3:])[0]), fields


def _target(text, source, name, kind, items, start) -> Target:
    keys = POSE_KEYS if kind == "pose" else JOINT_KEYS
    if None in items:
        raise syntax_error(source, text, items[None], f"{name}: aggregate item", "'KEY value'")
    missing = [k for k in keys if k not in items]
    if missing:
        raise syntax_error(source, text, start, f"{name}: a {'pose' if kind == 'pose' else 'joint'} aggregate "
                           f"without {', '.join(missing)}", f"all of {' '.join(keys)}")
    fields = [_number(items, k, text, source, name) for k in keys]
    if kind == "joints":
        return Target(name, 0, 0, "joints", tuple(fields), line_end=line_end(text, start))
    config = tuple(_status(items.get(k), text, source, name, k) for k in ("S", "T"))
    return Target(name, 0, 0, "pose", tuple(fields), configuration=None if config == (None, None) else config,
                  line_end=line_end(text, start))


def _status(item, text, source, name, key) -> int | None:
    if item is None:
        return None
    _, value, offset = item
    if not _INT.fullmatch(value):
        raise syntax_error(source, text, offset, f"{name}, {key}", "an integer (or 'B0101' binary)")
    if value.startswith("'"):
        return int(value[2:-1], 2 if value[1] in "Bb" else 16)
    return int(value)


def _frames_of(target: Target, fdat: dict) -> None:
    """The base and tool an FDAT names for ``target`` (``FP1`` for ``XP1`` or ``P1``)."""
    name = target.name.upper()
    data = fdat.get("F" + name) or (fdat.get("F" + name[1:]) if name.startswith("X") else None)
    if data is None or target.kind != "pose":
        return
    if data.get("IPO_FRAME", "#BASE").upper() != "#BASE":
        target.frame = f"IPO_FRAME {data['IPO_FRAME']} (a fixed tool)"
        return
    base, tool = data.get("BASE_NO", "0").strip(), data.get("TOOL_NO", "0").strip()
    target.frame = NULLFRAME if base == "0" else f"BASE_DATA[{base}]"
    target.tool = NULLFRAME if tool == "0" else f"TOOL_DATA[{tool}]"


def poses(values):
    """Positions (n, 3) mm and rotations (n, 3, 3) of pose fields (n, 6): ``X Y Z`` mm, ``A B C`` degrees."""
    return values[:, :3], matrices_from_kuka_abc(values[:, 3:])


def pose_values(positions_mm, rotations, old):
    """Pose fields (n, 6): ``X Y Z`` mm and ``A B C`` degrees, A and C within 180 degrees of the ones written."""
    return np.hstack([positions_mm, kuka_abc_from_matrices(rotations, near=old[:, 3:])])


def frame(value: str, source: str) -> np.ndarray:
    """A base or tool given as a KRL frame ``{X .., Y .., Z .., A .., B .., C ..}`` (mm, degrees)."""
    text = value.strip()
    if not (text.startswith("{") and text.endswith("}")):
        raise ProgramSyntaxError(f"{source}: expected a KRL frame {{X .., Y .., Z .., A .., B .., C ..}} (mm, "
                                 f"degrees), got {value!r}")
    items = _items(text, text, source, 0, len(text) - 1)
    missing = [k for k in POSE_KEYS if k not in items]
    if missing:
        raise ProgramSyntaxError(f"{source}: the frame {value!r} lacks {', '.join(missing)}")
    return _pose_of(items, text, source)[0]


def configuration(q_deg) -> np.ndarray:
    """``(S, T)`` of joint solutions (n, 6) degrees: ``T`` from the axes' signs; ``S`` is not computed (-1)."""
    q = np.asarray(q_deg, dtype=float)
    turn = ((q[:, :6] < 0) * (1 << np.arange(6))).sum(axis=1)
    return np.stack([np.full(len(q), -1), turn], axis=1)


def seeds(configurations, reference_deg) -> np.ndarray:
    """IK seeds (n, 6) degrees with the signs the turns ``T`` give (a reference joint of the wrong sign is
    mirrored; one at 0 becomes +-45 degrees); rows without ``T`` (-1) keep the reference."""
    q = np.array(reference_deg, dtype=float)
    turn = np.asarray(configurations)[:, 1]
    negative = (turn[:, None] >> np.arange(6)) & 1 == 1
    magnitude = np.where(np.abs(q[:, :6]) < 1.0, 45.0, np.abs(q[:, :6]))
    signed = np.where(negative, -magnitude, magnitude)
    q[:, :6] = np.where((turn >= 0)[:, None], signed, q[:, :6])
    return q


DIALECT = Dialect("krl", (".src", ".dat"), parse, frame, ";", poses=poses, pose_values=pose_values,
                  pose_decimals=(MM_DECIMALS,) * 3 + (DEG_DECIMALS,) * 3, joint_decimals=DEG_DECIMALS,
                  configuration=configuration, compare=(1,), seeds=seeds)
