"""Robot descriptions: the mapping a robot YAML file holds, the built-in robots, joint columns.

A description lists standard DH rows whose ``theta`` is a linear expression
of the joint angles (``q2``, ``180 - q2 + q3``), the joint limits, a home
pose, the tool offset and optional constraints between joints; see
``docs/robots.md``. :func:`robot_from_dict` checks it and builds a
:class:`~partcal.robot.kinematics.Robot`; :func:`robot_to_dict` writes it back
(exact round trip, as model files store it).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import NoReturn

import numpy as np
from numpy.typing import NDArray

from .._yamlio import load_yaml
from ..errors import ConfigError, DataError
from .kinematics import Robot
from .rotations import matrix_from_rpy_deg, rpy_deg_from_matrix
from .urdf import UrdfReference, is_urdf, robot_from_urdf

MAX_JOINTS = 12
_BUILTIN_DIR = Path(__file__).parent / "builtin"
_TERM = re.compile(r"\s*([+-]?)\s*(?:(\d+(?:\.\d*)?|\.\d+)\s*\*?\s*)?(q(\d+))?\s*")


def parse_theta(expr: str | float, n_joints: int) -> tuple[float, NDArray[np.float64]]:
    """Parse a joint-angle expression into ``(offset_deg, coefficients)``.

    Parameters
    ----------
    expr : str or float
        A sum of terms, each a number, ``qK`` or ``c*qK`` (degrees).
    n_joints : int
        Number of joints ``N``; ``K`` must be in ``1..N``.

    Returns
    -------
    offset_deg : float
    coefficients : ndarray, shape (N,)

    Examples
    --------
    >>> off, c = parse_theta("180 - q2 + q3", 6)
    >>> off, c.tolist()
    (180.0, [0.0, -1.0, 1.0, 0.0, 0.0, 0.0])
    """
    coeffs = np.zeros(n_joints)
    if isinstance(expr, (int, float)) and not isinstance(expr, bool):
        return float(expr), coeffs
    if not isinstance(expr, str) or not expr.strip():
        raise ConfigError(f"expected a number or an expression like '180 - q2 + q3', got {expr!r}")
    offset, pos = 0.0, 0
    text = expr.strip()
    while pos < len(text):
        m = _TERM.match(text, pos)
        if not m or m.end() == pos or (m.group(2) is None and m.group(3) is None):
            raise ConfigError(f"cannot read {expr!r} at character {pos + 1}: expected a number or qK")
        if pos > 0 and not m.group(1):
            raise ConfigError(f"cannot read {expr!r} at character {pos + 1}: expected '+' or '-'")
        sign = -1.0 if m.group(1) == "-" else 1.0
        value = float(m.group(2)) if m.group(2) is not None else 1.0
        if m.group(3):
            k = int(m.group(4))
            if not 1 <= k <= n_joints:
                raise ConfigError(f"{expr!r} names q{k}, but the robot has joints q1..q{n_joints}")
            coeffs[k - 1] += sign * value
        else:
            offset += sign * value
        pos = m.end()
    return offset, coeffs


def available_robots() -> list[str]:
    """Names of the built-in robots."""
    return sorted(p.stem for p in _BUILTIN_DIR.glob("*.yaml"))


def load_robot(name_or_path: str | Path | Robot | dict) -> Robot:
    """Load a built-in robot by name, a robot YAML file by path, or a URDF's chain.

    A URDF is a mapping ``{urdf: PATH, base: LINK, tip: LINK}`` or the text
    ``PATH.urdf#base=LINK&tip=LINK`` (``base``, ``tip`` optional: the root
    link and the only leaf); see :func:`partcal.robot.urdf.robot_from_urdf`.

    >>> load_robot("motoman_sk120").n_joints
    6
    """
    if isinstance(name_or_path, Robot):
        return name_or_path
    if isinstance(name_or_path, dict):
        name_or_path = urdf_reference(name_or_path, Path("."), "robot")
    if is_urdf(name_or_path):
        ref = UrdfReference.parse(str(name_or_path))
        return robot_from_urdf(ref.path, ref.base, ref.tip)
    text = str(name_or_path)
    path = Path(text)
    if not path.suffix and (_BUILTIN_DIR / f"{text}.yaml").exists():
        path = _BUILTIN_DIR / f"{text}.yaml"
    if not path.is_file():
        raise ConfigError(f"robot {text!r}: no such file, and not a built-in robot "
                          f"(built-ins: {', '.join(available_robots())})")
    spec, lines = load_yaml(path)
    return robot_from_dict(spec, source=str(path), lines=lines)


def robot_reference(name: str | dict, base: Path, where: str = "robot") -> str:
    """A robot named in a config: a ``.yaml`` or ``.urdf`` path relative to the config's folder, a built-in
    name, or a URDF mapping ``{urdf: PATH, base: LINK, tip: LINK}`` (returned as the text :func:`load_robot`
    reads, ``PATH.urdf#base=LINK&tip=LINK``, the path made relative to ``base``)."""
    if isinstance(name, dict):
        return urdf_reference(name, base, where)
    if is_urdf(name):
        ref = UrdfReference.parse(name)
        return UrdfReference(base / ref.path, ref.base, ref.tip).text()
    candidate = base / name
    return str(candidate) if candidate.suffix in (".yaml", ".yml") else name


def urdf_reference(spec: dict, base: Path, where: str = "robot") -> str:
    """The text form of a URDF mapping ``{urdf: PATH, base: LINK, tip: LINK}`` (``base``, ``tip`` optional),
    its path relative to the folder ``base``."""
    keys = {"urdf", "base", "tip"}
    if "urdf" not in spec or not set(spec) <= keys or not all(isinstance(v, str) and v for v in spec.values()):
        raise ConfigError(f"{where}: expected a built-in name, a robot file, or {{urdf: FILE.urdf, base: LINK, "
                          f"tip: LINK}} (texts); got {spec!r}"[:300])
    if not is_urdf(spec["urdf"]):
        raise ConfigError(f"{where}: urdf: expected a file ending in .urdf, got {spec['urdf']!r}")
    return UrdfReference(base / spec["urdf"], spec.get("base"), spec.get("tip")).text()


_ROBOT_KEYS = {"name", "description", "joints", "links", "tool_mm", "limits_deg", "home_deg",
               "constraints_deg", "base", "floor_mm", "plausible_error"}


def robot_from_dict(spec: dict, source: str = "robot", lines: dict[str, int] | None = None) -> Robot:
    """Build a :class:`Robot` from its YAML mapping (see ``docs/robots.md``).

    ``lines`` (key path -> line, from :func:`partcal._yamlio.load_yaml`) puts
    the line of the bad key into every message.
    """
    r = _Reader(source, lines or {})
    n = _joint_count(spec, r)
    alpha, d, a, off, coupling, origins, prismatic = _links(spec["links"], n, r)
    limits = r.numbers("limits_deg", spec["limits_deg"], (n, 2), f"{n} pairs [low, high] with low < high")
    if np.any(limits[:, 0] >= limits[:, 1]):
        r.fail("limits_deg", f"expected {n} pairs [low, high] with low < high; got {spec['limits_deg']!r}")
    home = r.numbers("home_deg", spec["home_deg"], (n,), f"{n} angles") if "home_deg" in spec else limits.mean(axis=1)
    tool = r.numbers("tool_mm", spec.get("tool_mm", [0, 0, 0]), (3,), "[x, y, z]")
    constraints = _constraints(spec.get("constraints_deg") or [], n, r)
    base = _origin(spec.get("base"), "base", r)
    floor = spec.get("floor_mm")                 # a floor the description does not state is not assumed
    floor = None if floor is None else r.number("floor_mm", floor)
    plausible = _plausible_error(spec.get("plausible_error"), r)
    return Robot(name=str(spec["name"]), n_joints=n, alpha_deg=alpha, d_mm=d, a_mm=a,
                 theta_offset_deg=off, coupling=coupling, tool_mm=tool, limits_deg=limits,
                 home_deg=home, constraints=constraints, origins=origins, prismatic=prismatic,
                 base_rotation=matrix_from_rpy_deg(base[3:]), base_mm=base[:3], floor_mm=floor,
                 plausible_error=plausible)


def _plausible_error(spec, r) -> dict | None:
    """``plausible_error``: ``{mm: ..., deg: ...}`` (either or both, numbers > 0), or None when absent."""
    if spec is None:
        return None
    if not (isinstance(spec, dict) and spec and set(spec) <= {"mm", "deg"}):
        r.fail("plausible_error", f"expected {{mm: LENGTH, deg: ANGLE}} (either or both); got {spec!r}"[:200])
    out = {unit: r.number(f"plausible_error.{unit}", value) for unit, value in spec.items()}
    if any(not value > 0 for value in out.values()):
        r.fail("plausible_error", f"expected numbers > 0; got {spec!r}"[:200])
    return out


class _Reader:
    """The messages of one robot mapping: ``source: where (line N): message``, and its number checks."""

    def __init__(self, source: str, lines: dict[str, int]):
        self.source, self.lines = source, lines

    def fail(self, where: str, msg: str) -> NoReturn:
        line = self.lines.get(where)
        raise ConfigError(f"{self.source}: {where}{f' (line {line})' if line else ''}: {msg}")

    def number(self, where: str, value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or abs(value) > 1e300:
            self.fail(where, f"must be a finite number; got {value!r}")
        return float(value)

    def numbers(self, where: str, value, shape: tuple[int, ...], what: str) -> NDArray[np.float64]:
        arr = np.asarray(value if isinstance(value, list) else [value], dtype=object)
        if arr.shape != shape:
            self.fail(where, f"expected {what}; got {value!r}")
        for index in np.ndindex(arr.shape):
            at = where + "".join(f"[{k}]" for k in index)
            self.number(at if at in self.lines else where, arr[index])
        return arr.astype(float)


def _joint_count(spec, r: _Reader) -> int:
    """The number of joints, once the top-level keys are known, present and of the right kind."""
    if not isinstance(spec, dict):
        r.fail("top level", f"expected a mapping, got {type(spec).__name__}")
    unknown = set(spec) - _ROBOT_KEYS
    if unknown:
        r.fail(sorted(unknown)[0], f"unknown key (allowed: {', '.join(sorted(_ROBOT_KEYS))})")
    for key in ("name", "joints", "links", "limits_deg"):
        if key not in spec:
            r.fail(key, "missing")
    n = spec["joints"]
    if not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
        r.fail("joints", f"must be an int in [1, {MAX_JOINTS}]; got {n!r}")
    for key, kind in (("links", list), ("constraints_deg", (list, type(None)))):
        if not isinstance(spec.get(key), kind):
            r.fail(key, f"expected a list; got {spec.get(key)!r}"[:200])
    return n


def _links(links: list, n: int, r: _Reader) -> tuple:
    """``alpha, d, a, theta offset`` (each ``(R,)``), the coupling ``(R, N)`` of the rows, their further
    transforms ``(R, 6)`` (``origin:``; None when no row has one) and which rows slide (``d`` an expression of
    the joints, mm; None when none does)."""
    rows, origins, slides = [], [], []
    for i, link in enumerate(links):
        if not isinstance(link, dict) or not {"theta", "d", "a", "alpha"} <= set(link) <= _LINK_KEYS:
            r.fail(f"links[{i}]", f"expected a mapping with theta, d, a, alpha (and optionally origin); got {link!r}")
        try:
            off, coeffs = parse_theta(link["theta"], n)
        except ConfigError as exc:
            r.fail(f"links[{i}].theta", str(exc))
        slide = False
        if isinstance(link["d"], str):         # a prismatic row: d = offset + sum(c qK) mm
            try:
                d_mm, d_coeffs = parse_theta(link["d"], n)
            except ConfigError as exc:
                r.fail(f"links[{i}].d", f"must be a finite number; got {link['d']!r} (or, for a row that slides, "
                                        f"an expression of the joints such as 'q1 + 100', mm: {exc})")
            slide = bool(d_coeffs.any())
            if slide and coeffs.any():
                r.fail(f"links[{i}]", f"a row turns (theta names a joint) or slides (d names one), not both; got "
                                      f"theta {link['theta']!r}, d {link['d']!r}")
            coeffs = d_coeffs if slide else coeffs
        else:
            d_mm = r.number(f"links[{i}].d", link["d"])
        rows.append((r.number(f"links[{i}].alpha", link["alpha"]), d_mm, r.number(f"links[{i}].a", link["a"]), off,
                     coeffs))
        origins.append(_origin(link.get("origin"), f"links[{i}].origin", r))
        slides.append(slide)
    if not rows:
        r.fail("links", "needs at least one DH row")
    coupling = np.array([row[4] for row in rows])
    unused = [f"q{j + 1}" for j in range(n) if not coupling[:, j].any()]
    if unused:
        r.fail("links", f"joint(s) {', '.join(unused)} appear in no theta or d expression")
    alpha, d, a, off = (np.array([row[k] for row in rows]) for k in range(4))
    return (alpha, d, a, off, coupling, (np.array(origins) if np.any(origins) else None),
            np.array(slides) if any(slides) else None)


_LINK_KEYS = {"theta", "d", "a", "alpha", "origin"}


def _origin(value, where: str, r: _Reader) -> NDArray[np.float64]:
    """A row's further transform ``{xyz_mm: [x, y, z], rpy_deg: [roll, pitch, yaw]}`` as ``(6,)`` (zeros if absent)."""
    if value is None:
        return np.zeros(6)
    if not isinstance(value, dict) or not set(value) <= {"xyz_mm", "rpy_deg"}:
        r.fail(where, f"expected {{xyz_mm: [x, y, z], rpy_deg: [roll, pitch, yaw]}}; got {value!r}"[:200])
    return np.concatenate([r.numbers(f"{where}.{key}", value.get(key, [0, 0, 0]), (3,), "three numbers")
                           for key in ("xyz_mm", "rpy_deg")])


def _constraints(items: list, n: int, r: _Reader) -> tuple:
    """``(coefficients (N,), low, high)`` of each entry of ``constraints_deg``."""
    constraints = []
    for i, c in enumerate(items):
        if not isinstance(c, dict) or not isinstance(c.get("range"), list) or len(c["range"]) != 2:
            r.fail(f"constraints_deg[{i}]", f"expected {{expr: 'q2 - q3', range: [low, high]}}; got {c!r}"[:200])
        try:
            _, coeffs = parse_theta(c["expr"], n)
            low, high = (r.number(f"constraints_deg[{i}].range", v) for v in c["range"])
        except (KeyError, TypeError, ValueError, ConfigError) as exc:
            r.fail(f"constraints_deg[{i}]", f"expected {{expr: 'q2 - q3', range: [low, high]}}: {exc}")
        constraints.append((coeffs, low, high))
    return tuple(constraints)


def joint_columns(n_joints: int) -> list[str]:
    """Column names ``q1..qN``."""
    if not 1 <= n_joints <= MAX_JOINTS:
        raise DataError(f"a robot has 1..{MAX_JOINTS} joints, got {n_joints}")
    return [f"q{j}" for j in range(1, n_joints + 1)]


def _expression(offset: float, coeffs: NDArray[np.float64]) -> str | float:
    """Inverse of :func:`parse_theta`: ``(180, [0, -1, 1])`` -> ``'180.0 - q2 + q3'``."""
    parts = [repr(float(offset))] if offset else []
    for j, c in enumerate(coeffs, start=1):
        if c:
            mag = "" if abs(c) == 1 else f"{abs(float(c))!r}*"
            sign = "-" if c < 0 else "+"
            parts.append(f"{sign} {mag}q{j}" if parts else f"{'-' if c < 0 else ''}{mag}q{j}")
    return " ".join(parts) if parts else 0.0


def robot_to_dict(robot: Robot) -> dict:
    """The robot as the mapping :func:`robot_from_dict` reads (exact round trip)."""
    origins = robot.origins if robot.origins is not None else np.zeros((robot.alpha_deg.size, 6))
    slides = robot.prismatic if robot.prismatic is not None else np.zeros(robot.alpha_deg.size, dtype=bool)
    return {
        "name": robot.name, "joints": robot.n_joints,
        "links": [{"theta": float(off) if slide else _expression(off, c),
                   "d": _expression(d, c) if slide else float(d), "a": float(a), "alpha": float(al),
                   **({"origin": {"xyz_mm": o[:3].tolist(), "rpy_deg": o[3:].tolist()}} if np.any(o) else {})}
                  for off, c, d, a, al, o, slide in zip(robot.theta_offset_deg, robot.coupling, robot.d_mm,
                                                        robot.a_mm, robot.alpha_deg, origins, slides)],
        "tool_mm": robot.tool_mm.tolist(), "limits_deg": robot.limits_deg.tolist(),
        "home_deg": robot.home_deg.tolist(),
        "constraints_deg": [{"expr": _expression(0.0, c), "range": [lo, hi]} for c, lo, hi in robot.constraints],
        **_base_entry(robot),
        **({} if robot.floor_mm is None else {"floor_mm": robot.floor_mm}),
        **({} if robot.plausible_error is None else {"plausible_error": dict(robot.plausible_error)}),
    }


def _base_entry(robot: Robot) -> dict:
    """``{"base": {xyz_mm, rpy_deg}}`` for a robot whose first frame is not the base frame (none otherwise)."""
    if np.array_equal(robot.base_rotation, np.eye(3)) and not np.any(robot.base_mm):
        return {}
    return {"base": {"xyz_mm": robot.base_mm.tolist(), "rpy_deg": rpy_deg_from_matrix(robot.base_rotation).tolist()}}
