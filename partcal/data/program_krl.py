"""KUKA KRL (``.dat`` and ``.src``): the aggregates ``{X .., Y .., Z .., A .., B .., C .., S .., T ..}``.

Units of the language: ``X Y Z`` in mm, ``A B C`` Z-Y-X Euler angles in degrees (``R = Rz(A) Ry(B) Rx(C)``),
``S`` (status) and ``T`` (turn: bit ``k`` set when axis ``k + 1`` is negative) integers, which may be written
in binary (``'B010'``); joint targets ``A1 .. A6`` in degrees. Targets are

- declarations of ``E6POS``, ``POS``, ``E3POS``, ``FRAME`` (poses) and ``E6AXIS``, ``AXIS``, ``E3AXIS``
  (joints) with an initial value, and assignments of a whole aggregate (``XP1 = {X ..}``, ``P[3] = {..}``),
  that a motion of the module reaches by name (a ``.dat`` is read with its module's ``.src`` beside it; a
  ``.dat`` without one takes every point it declares), or that an inline form's ``FDAT`` names;
- inline aggregates of a motion (``PTP {A1 0, ..}``, ``LIN {X .., ..}``).

A point no motion reaches (numbers for arithmetic), reached only through an expression, or moved to in a
base or tool computed at run time is kept as written and reported (``left``); so are the controller's
system variables (``TOOL_CORR``, ``BASE_CORR``, ``REF_TOOL``, ``REF_PT[]`` of ``$config.dat``). An aggregate
lacking some of ``X Y Z A B C`` (or ``A1 .. A6``) after a ``:``, of ``PTP_REL`` or ``LIN_REL``, or assigned to
no declared target is an offset and stays as written; a partial aggregate as the target of ``PTP``, ``LIN`` or
``CIRC`` (the other coordinates: wherever the robot is) is refused. ``BASE_DATA[n]`` and ``TOOL_DATA[n]``
aggregates are frames. A point is in the base and with the tool in force at its motions (``$BASE =``,
``$TOOL =``, ``BAS(#BASE, n)``, ``BAS(#TOOL, n)``, ``FDAT_ACT``, in file order; before them, the frames of the
options ``--frame`` and ``--tool``, default the robot base and the flange); a point ``XP1`` (or ``P1``) with
an ``FDAT`` ``FP1`` in ``BASE_DATA[BASE_NO]`` with ``TOOL_DATA[TOOL_NO]`` (number 0: the robot base, the
flange).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..robot.rotations import kuka_abc_from_matrices, matrices_from_kuka_abc
from .program_krl_reach import JOINT_KEYS, NULLFRAME, POSE_KEYS, Reach, fdat_frames, key, unusable
from .program_text import (Dialect, Field, ProgramSyntaxError, Target, UnknownFrameError, closing, frame_pose,
                           is_number, lf_view, line_and_column, line_end, masked, syntax_error)

POSE_TYPES = {"E6POS", "POS", "E3POS", "FRAME"}
JOINT_TYPES = {"E6AXIS", "AXIS", "E3AXIS"}
MM_DECIMALS, DEG_DECIMALS = 6, 6
_DECL = re.compile(r"(?:\bDECL\s+(?:GLOBAL\s+)?|^[ \t]*(?:GLOBAL[ \t]+)?(?=(?:E6POS|POS|E3POS|FRAME|E6AXIS|AXIS|E3AXIS|"
                   r"FDAT)[ \t]))([A-Za-z_]\w*)\s+([$A-Za-z_][\w\[\],]*)\s*=\s*$", re.IGNORECASE | re.MULTILINE)
_ASSIGN = re.compile(r"([$A-Za-z_][\w$]*(?:\[[\d, ]*\])?)\s*=\s*$")
_MOTION = re.compile(r"\b(PTP|LIN|CIRC|SPTP|SLIN|SCIRC|PTP_REL|LIN_REL)\s+$", re.IGNORECASE)
_ABSOLUTE_MOTIONS = {"PTP", "LIN", "CIRC", "SPTP", "SLIN", "SCIRC"}
_ITEM = re.compile(r"\s*([A-Za-z_]\w*)\s+(\S(?:.*\S)?)\s*$", re.DOTALL)
_INT = re.compile(r"[-+]?\d+|'[Bb][01]+'|'[Hh][0-9A-Fa-f]+'")
SYSTEM_FRAMES = {"TOOL_CORR", "TOOL_CORR_W", "BASE_CORR", "M_BASE_CORR", "REF_TOOL", "REF_PT", "MACHINE_DEF",
                 "MACHINE_TOOL_DAT", "MACHINE_FRAME_DAT", "LOAD_DATA", "TOOL_DATA", "BASE_DATA"}  # $config.dat's: no targets
EXTERNAL_KEYS = ("E1", "E2", "E3", "E4", "E5", "E6")
log = logging.getLogger(__name__)


def parse(text: str, source: str) -> tuple[list[Target], dict, list]:
    """The targets of a KRL file (``text``: its bytes decoded as latin-1), the frames it defines and the points
    left as written. A ``.dat`` is read with its module's ``.src`` beside it (same name), whose motions say which
    of its points are targets and in which base and tool; a ``.src`` with its ``.dat`` (its ``FDAT``s)."""
    code = lf_view(masked(text, ";"))
    frames, fdat = {NULLFRAME: np.eye(4)}, {}
    records = _aggregates(text, code, source)
    partner, config = _partner(source), config_dat(source)
    for rec in (_aggregates(*config) if config else []) + records + (_aggregates(*partner) if partner else []):
        _definitions(rec, frames, fdat)
    suffix = Path(source).suffix.lower()
    is_dat = suffix == ".dat" or (suffix != ".src" and re.search(r"^[ \t]*DEFDAT\b", code, re.I | re.M) is not None)
    motions = (partner if partner and partner[2].lower().endswith(".src") else None) if is_dat else (text, code, source)
    reach = Reach(*motions, fdat, frames, frame) if motions else None
    targets, left = [], []
    for rec in records:
        target = _record_target(text, source, rec, reach, fdat, left)
        if target is not None:
            targets.append(target)
    if is_dat and reach is None and targets:
        log.warning("%s: no module .src beside it: every point it declares is taken as a target, in the base and "
                    "tool of its FDAT or of --frame and --tool (put its .src beside it to take only what motions "
                    "reach, in the base and tool set before them)", source)
    return targets, frames, left


@dataclass
class _Record:
    """One aggregate ``{..}`` that may be a point: its span, how it is named (``decl``, ``assign``, ``motion``),
    its name, the declared kind (``pose``, ``joints``, another type's name, or None) and its items."""

    start: int
    end: int
    via: str
    name: str
    kind: str | None
    items: dict


def _aggregates(text: str, code: str, source: str) -> list[_Record]:
    """Every aggregate of a file that is declared, assigned or a motion's inline target."""
    out, at = [], 0
    while (start := code.find("{", at)) >= 0:
        end = closing(code, start, "{", "}")
        if end < 0:
            raise syntax_error(source, text, start, "aggregate", "a closing '}'")
        at = end + 1
        before = code[max(0, start - 200):start]
        decl, assign, motion = _DECL.search(before), _ASSIGN.search(before), _MOTION.search(before)
        if decl:
            typ, name, via = decl.group(1).upper(), decl.group(2), "decl"
            kind = "pose" if typ in POSE_TYPES else "joints" if typ in JOINT_TYPES else typ
        elif assign:
            name, kind, via = assign.group(1), None, "assign"
        elif motion:
            name, kind, via = motion.group(1).upper(), None, "motion"
        else:
            continue                                                 # an offset (after ':') or an argument
        out.append(_Record(start, end, via, name, kind, _items(text, code, source, start, end)))
    return out


def _definitions(rec: _Record, frames: dict, fdat: dict) -> None:
    """``FDAT``s, and ``BASE_DATA[n]`` and ``TOOL_DATA[n]`` frames written as numbers."""
    upper = key(rec.name)
    if rec.kind == "FDAT":
        fdat[upper] = {k: v[1] for k, v in rec.items.items() if k is not None}
    elif upper.startswith(("BASE_DATA[", "TOOL_DATA[")) and all(k in rec.items and rec.items[k][0] is not None
                                                                for k in POSE_KEYS):
        v = np.array([rec.items[k][0].value for k in POSE_KEYS])
        frames[upper] = frame_pose(v[:3], matrices_from_kuka_abc(v[3:])[0])


def _record_target(text, source, rec: _Record, reach, fdat, left) -> Target | None:
    """The target an aggregate is (None: not a target; a point not compensated goes into ``left``)."""
    upper = key(rec.name)
    if rec.kind == "FDAT" or upper.startswith(("$", "BASE_DATA[", "TOOL_DATA[")) or \
            rec.kind not in (None, "pose", "joints") or (rec.via == "motion" and upper.endswith("_REL")):
        return None                                   # frames, other data, and relative motions' offsets
    kind = rec.kind or ("pose" if all(k in rec.items for k in POSE_KEYS) else
                        "joints" if all(k in rec.items for k in JOINT_KEYS) else None)
    if kind is None:
        if rec.via == "motion" and upper in _ABSOLUTE_MOTIONS:      # the other coordinates: whatever the robot has
            raise syntax_error(source, text, rec.start, f"{upper} to a partial aggregate", "a whole target: all of "
                               f"{' '.join(POSE_KEYS)} or of {' '.join(JOINT_KEYS)} (a partial one cannot be "
                               "compensated)")
    why = _not_as_declared(rec, kind, upper, reach)
    if why:
        left.append((_first_value(rec), rec.name, why))
    if kind is None or why:
        return None
    first = _first_value(rec)
    target = _target(text, source, rec.name, kind, rec.items, rec.start)
    states = None if reach is None else reach.inline.get(rec.start) if rec.via == "motion" else reach.states(upper)
    if kind == "pose" and _fdat_of(upper, fdat) is not None and rec.via != "motion":
        _frames_of(target, fdat)         # an inline form's point: its FDAT's frames, where its motions set none
        states = {(b or target.frame, t or target.tool) for b, t in states or [(None, None)]}
    elif reach is None:
        return target                          # a data list without its .src: every point, as declared
    if not states:
        why = reach.through.get(upper) or reach.through.get(upper.split("[")[0])
        left.append((first, rec.name, f"reached only through the expression {why}, not compensated" if why else
                     f"no motion of {reach.source_name} reaches it: not a target, kept as written"))
        return None
    why = unusable(states) if kind == "pose" else None
    if why:
        left.append((first, rec.name, why))
        return None
    if len(states) > 1:
        named = " and ".join(f"$BASE {b or 'default'}, $TOOL {t or 'default'}" for b, t in sorted(
            states, key=lambda s: (str(s[0]), str(s[1]))))
        line, column = line_and_column(text, first)
        raise UnknownFrameError(f"{source}: line {line}, column {column}: target {rec.name}: it is moved to with "
                                f"{named}: one point cannot be compensated for two frames or tools; nothing written")
    if kind == "pose":
        target.frame, target.tool = next(iter(states))
    return target


def _not_as_declared(rec: _Record, kind: str | None, upper: str, reach: Reach | None) -> str | None:
    """Why an aggregate that is no motion's own is not what a motion moves to, if it is not: a partial one
    assigned at run time (the rest keeps the point's old values), a point the module changes at run time
    (``XC1.Z = XC1.Z + 20``), a system variable of the controller."""
    if rec.via == "motion":
        return None
    if kind is None:
        if rec.via != "assign" or reach is None or not reach.states(upper):
            return None
        keys = POSE_KEYS if set(rec.items) & set(POSE_KEYS) else JOINT_KEYS
        kept = ", ".join(k for k in keys if k not in rec.items)
        return (f"a partial aggregate assigned at run time: its {kept} keep the value {rec.name} had before, so the "
                "point moved to is not all written here: not compensated, kept as written")
    changed = reach.change(upper) if reach is not None else None
    if changed:
        return (f"changed at run time ({changed} of {reach.source_name}): its declared value is not what the robot "
                "moves to, kept as written")
    if upper.split("[")[0] in SYSTEM_FRAMES:
        return f"a system variable of the controller ({upper.split('[')[0]}), not a motion target: kept as written"
    return None


def _first_value(rec: _Record) -> int:
    """Offset of the first value of an aggregate (where a note about it points)."""
    offsets = [v[2] for k, v in rec.items.items() if k is not None]
    return min(offsets) if offsets else rec.start


def config_dat(source: str) -> tuple[str, str, str] | None:
    """The ``$config.dat`` of a module, where the controller keeps it: beside it, or in ``System`` of a folder up
    to three above it (a KRC backup's ``KRC/R1/System/$config.dat`` for ``KRC/R1/Program/weld/weld.src``). Its
    text, masked code and path; None when there is none (or ``source`` is it)."""
    path = Path(source)
    if path.name.lower() == "$config.dat":
        return None
    try:
        folders = [path.parent] + [d for a in path.parents[1:4] if a.is_dir() for d in a.iterdir()
                                   if d.is_dir() and d.name.lower() == "system"]
        match = next((f for folder in folders for f in folder.iterdir() if f.name.lower() == "$config.dat"), None)
        if match is None:
            return None
        text = match.read_bytes().decode("latin-1")
    except OSError:
        return None
    return text, lf_view(masked(text, ";")), str(match)


def _partner(source: str) -> tuple[str, str, str] | None:
    """The other file of the module (``.src`` for a ``.dat`` and back, same name, any case): its text, masked
    code and path; None when there is none."""
    path = Path(source)
    want = {".dat": ".src", ".src": ".dat"}.get(path.suffix.lower())
    if want is None:
        return None
    try:
        match = next((p for p in path.parent.iterdir() if p.name.lower() == (path.stem + want).lower()), None)
        if match is None:
            return None
        raw = match.read_bytes()
    except OSError:
        return None
    text = raw.decode("latin-1")
    return text, lf_view(masked(text, ";")), str(match)


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
    external = tuple((k, items[k][0].value) for k in EXTERNAL_KEYS if k in items and items[k][0] is not None)
    return Target(name, 0, 0, "pose", tuple(fields), configuration=None if config == (None, None) else config,
                  line_end=line_end(text, start), external=external)


def _status(item, text, source, name, key) -> int | None:
    if item is None:
        return None
    _, value, offset = item
    if not _INT.fullmatch(value):
        raise syntax_error(source, text, offset, f"{name}, {key}", "an integer (or 'B0101' binary)")
    if value.startswith("'"):
        return int(value[2:-1], 2 if value[1] in "Bb" else 16)
    return int(value)


def _fdat_of(name: str, fdat: dict) -> dict | None:
    """The FDAT of an inline form's point (``FP1`` for ``XP1`` or ``P1``), if any."""
    return fdat.get("F" + name) or (fdat.get("F" + name[1:]) if name.startswith("X") else None)


def _frames_of(target: Target, fdat: dict) -> None:
    """The base and tool an FDAT names for ``target`` (``FP1`` for ``XP1`` or ``P1``)."""
    data = _fdat_of(key(target.name), fdat)
    if data is not None and target.kind == "pose":
        target.frame, target.tool = fdat_frames(data)


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


def ranges(configurations) -> tuple[np.ndarray, np.ndarray]:
    """The joint ranges (n, 6) degrees, low and high, that configurations ``(S, T)`` (n, 2) allow: each axis on
    the side of 0 its bit of ``T`` names (0 itself on both); rows without ``T`` (-1) free."""
    turn = np.asarray(configurations)[:, 1]
    negative = (turn[:, None] >> np.arange(6)) & 1 == 1
    written = (turn >= 0)[:, None]
    low = np.where(written & ~negative, 0.0, -np.inf)
    high = np.where(written & negative, 0.0, np.inf)
    return low, high


DIALECT = Dialect("krl", (".src", ".dat"), parse, frame, ";", poses=poses, pose_values=pose_values,
                  pose_decimals=(MM_DECIMALS,) * 3 + (DEG_DECIMALS,) * 3, joint_decimals=DEG_DECIMALS,
                  configuration=configuration, compare=(1,), seeds=seeds, ranges=ranges)
