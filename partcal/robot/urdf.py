"""URDF in: a robot's chain from a URDF file, between a base link and a tip link.

The file is parsed by yourdfpy; the chain from ``base`` to ``tip`` becomes a
:class:`~partcal.robot.kinematics.Robot` of generic rows. A URDF joint is its
origin ``F`` (a fixed transform from the parent link) then its motion about
its axis ``a``; fixed joints fold into the transforms around them. With ``A``
a rotation that takes ``z`` to ``a``, the motion is ``A Rz(q) A^T``, so

``T = F1 A1 Rz(q1) (A1^T F2 A2) Rz(q2) ... Rz(qN) (AN^T F_tip)``:

the robot's base pose is ``F1 A1``, row ``k`` turns by ``qk`` about ``z`` and
ends in the origin ``Ak^T F(k+1) A(k+1)`` (the last one in ``AN^T F_tip``, the
fixed joints up to the tip). Rows have no DH part. Units change at this
boundary: metres to mm, radians to degrees. Limits come from the URDF
(continuous joints: +-360 degrees); a prismatic joint is a row that slides
along its axis (``Tz(q)`` between ``A`` and ``A^T``; its column is in mm); a
mimic joint is a row whose angle (or slide) is ``multiplier * q_master +
offset``, a coupled row like the SK120's parallelogram.

A malformed file, or a chain that is not there, is refused with one line
naming the file, the line and element, and what was expected.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import parse_qs

import numpy as np
from numpy.typing import NDArray

from ..errors import RobotFileError
from .kinematics import Robot
from .rotations import rpy_deg_from_matrix

MOVING = ("revolute", "continuous", "prismatic")
JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")
CONTINUOUS_LIMIT_DEG = 360.0
_M_TO_MM = 1000.0


@dataclass(frozen=True)
class UrdfReference:
    """A URDF robot as a run config names it: the file and the chain's ``base`` and ``tip`` links (None: the
    file's root link, and its only leaf)."""

    path: Path
    base: str | None = None
    tip: str | None = None

    def text(self) -> str:
        """The reference as one string, ``path.urdf#base=LINK&tip=LINK`` (what :func:`load_robot` reads)."""
        query = "&".join(f"{k}={v}" for k, v in (("base", self.base), ("tip", self.tip)) if v)
        return f"{self.path}#{query}" if query else str(self.path)

    @classmethod
    def parse(cls, text: str) -> "UrdfReference":
        """Read :meth:`text`'s form back."""
        path, _, query = str(text).partition("#")
        fields = {k: v[-1] for k, v in parse_qs(query, keep_blank_values=True).items()}
        unknown = set(fields) - {"base", "tip"}
        if unknown:
            raise RobotFileError(f"robot {text!r}: unknown field {sorted(unknown)[0]!r} after '#' (expected "
                                 "'path.urdf#base=LINK&tip=LINK')")
        return cls(Path(path), fields.get("base") or None, fields.get("tip") or None)


def is_urdf(text) -> bool:
    """Whether a robot reference names a URDF file (``.urdf``, optionally with ``#base=..&tip=..``)."""
    return str(text).partition("#")[0].lower().endswith(".urdf")


def robot_from_urdf(path, base: str | None = None, tip: str | None = None, name: str | None = None) -> Robot:
    """The chain of a URDF file from link ``base`` to link ``tip`` as a :class:`Robot` (mm, degrees).

    Parameters
    ----------
    path : str or Path
        The URDF file.
    base, tip : str, optional
        Link names; default the file's root link and its only leaf link.
    name : str, optional
        The robot's name; default the URDF's ``<robot name>``.

    Returns
    -------
    Robot
        One row per revolute or continuous joint between ``base`` and ``tip``
        (mimic joints too: coupled rows), joints ``q1..qN`` in chain order.

    Raises
    ------
    RobotFileError
        Naming the file, the element (and its line) and what was expected.
    """
    path = Path(path)
    if not path.is_file():
        raise RobotFileError(f"{path}: no such URDF file")
    _check_elements(path)
    import yourdfpy        # heavy (trimesh); only URDF users pay for it

    try:
        urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False,
                                  build_collision_scene_graph=False, load_collision_meshes=False)
    except Exception as exc:  # noqa: BLE001 - the parser's own complaint, in one line
        raise RobotFileError(f"{path}: cannot read the URDF: {exc}") from None
    joints = _chain(path, urdf, base, tip)
    return _robot(path, urdf, joints, name or urdf.robot.name)


def _chain(path: Path, urdf, base: str | None, tip: str | None) -> list:
    """The joints from ``base`` to ``tip``, in order."""
    links = [link.name for link in urdf.robot.links]
    by_child = {j.child: j for j in urdf.robot.joints}
    parents = {j.parent for j in urdf.robot.joints}
    roots = [link for link in links if link not in by_child]
    leaves = [link for link in links if link not in parents]
    base = base or (roots[0] if len(roots) == 1 else None)
    if base is None:
        raise RobotFileError(f"{path}: <robot>: expected one root link or a base link named; roots: {roots}")
    if tip is None:
        if len(leaves) != 1:
            raise RobotFileError(f"{path}: <robot>: the tip link must be named (tip: LINK); leaf links: "
                                 f"{', '.join(leaves)}")
        tip = leaves[0]
    for role, link in (("base", base), ("tip", tip)):
        if link not in links:
            raise RobotFileError(f"{path}: {role} link {link!r}: no <link> of that name (links: "
                                 f"{', '.join(links)})"[:400])
    chain, link = [], tip
    while link != base:
        if link not in by_child:
            raise RobotFileError(f"{path}: tip link {tip!r} does not hang below base link {base!r} (its chain ends "
                                 f"at {link!r})")
        chain.append(by_child[link])
        link = by_child[link].parent
    return chain[::-1]


def _robot(path: Path, urdf, joints: list, name: str) -> Robot:
    """The rows of the chain ``joints`` (see the module notes)."""
    by_name = {j.name: j for j in urdf.robot.joints}
    moving = [j for j in joints if j.type != "fixed"]
    for j in moving:
        if j.type not in MOVING:
            raise RobotFileError(f"{path}: <joint name={j.name!r} type={j.type!r}>: expected revolute, continuous, "
                                 "prismatic or fixed joints between base and tip (planar and floating joints are not "
                                 "supported)")
    if not moving:
        raise RobotFileError(f"{path}: no revolute or continuous joint between the base and the tip link")
    actuated = [j.name for j in moving if j.mimic is None]
    for j in moving:                       # a mimic joint's master outside the chain still drives it
        master = _master(path, j, by_name)[0]
        if master not in actuated:
            actuated.append(master)
    n = len(actuated)
    offsets, coupling = np.zeros(len(moving)), np.zeros((len(moving), n))
    slides, slide_mm = np.array([j.type == "prismatic" for j in moving]), np.zeros(len(moving))
    fixed, axes, before = np.eye(4), [], []
    for r, j in enumerate(moving):
        while joints[0] is not j:          # fixed joints before this one fold into its origin
            fixed = fixed @ _origin(joints.pop(0))
        joints.pop(0)
        before.append(fixed @ _origin(j))
        fixed = np.eye(4)
        axes.append(_turn_to(path, j))
        master, multiplier, offset = _master(path, j, by_name)
        if slides[r] != (by_name[master].type == "prismatic"):
            raise RobotFileError(f"{path}: <joint name={j.name!r}> <mimic joint={master!r}>: expected a master of the "
                                 "same kind (a slide follows a slide, a turn a turn)")
        coupling[r, actuated.index(master)] = multiplier
        if slides[r]:
            slide_mm[r] = offset * _M_TO_MM
        else:
            offsets[r] = math.degrees(offset)
    for j in joints:                       # fixed joints after the last one: the tip
        fixed = fixed @ _origin(j)
    after = before[1:] + [fixed]
    origins = np.zeros((len(moving), 6))
    for r in range(len(moving)):
        e = axes[r].T @ after[r][:3, :3] @ (axes[r + 1] if r + 1 < len(moving) else np.eye(3))
        origins[r, :3] = axes[r].T @ after[r][:3, 3] * _M_TO_MM
        origins[r, 3:] = rpy_deg_from_matrix(e)
    limits = np.array([_limits(path, by_name[a]) for a in actuated])
    home = np.clip(np.zeros(n), limits[:, 0], limits[:, 1])
    zeros = np.zeros(len(moving))
    return Robot(name=name, n_joints=n, alpha_deg=zeros, d_mm=slide_mm, a_mm=zeros.copy(),
                 theta_offset_deg=offsets, coupling=coupling, tool_mm=np.zeros(3), limits_deg=limits, home_deg=home,
                 base_rotation=before[0][:3, :3] @ axes[0], base_mm=before[0][:3, 3] * _M_TO_MM, origins=origins,
                 prismatic=slides if slides.any() else None, floor_mm=None)    # a URDF states no floor


def _origin(joint) -> NDArray[np.float64]:
    return np.eye(4) if joint.origin is None else np.asarray(joint.origin, dtype=float)


def _master(path: Path, joint, by_name: dict) -> tuple[str, float, float]:
    """The actuated joint that drives ``joint``, the multiplier and the offset (radians), through mimic chains."""
    name, multiplier, offset, seen = joint.name, 1.0, 0.0, set()
    while by_name[name].mimic is not None:
        mimic = by_name[name].mimic
        if mimic.joint not in by_name or mimic.joint in seen:
            raise RobotFileError(f"{path}: <joint name={name!r}> <mimic joint={mimic.joint!r}>: expected an "
                                 "existing joint (and no mimic loop)")
        seen.add(name)
        m = 1.0 if mimic.multiplier is None else float(mimic.multiplier)
        o = 0.0 if mimic.offset is None else float(mimic.offset)
        # q_joint = multiplier q_name + offset, and q_name = m q_master + o
        multiplier, offset, name = multiplier * m, offset + multiplier * o, mimic.joint
    return name, multiplier, offset


def _turn_to(path: Path, joint) -> NDArray[np.float64]:
    """A rotation ``A`` (3, 3) that takes ``z`` to the joint's unit axis (the identity for ``z`` itself)."""
    axis = np.asarray(joint.axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    z = np.array([0.0, 0.0, 1.0])
    if np.allclose(axis, z, rtol=0, atol=1e-15):
        return np.eye(3)
    if np.allclose(axis, -z, rtol=0, atol=1e-15):
        return np.diag([1.0, -1.0, -1.0])               # half a turn about x
    v, c = np.cross(z, axis), float(axis @ z)
    skew = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + skew + skew @ skew / (1.0 + c)   # Rodrigues: the shortest turn from z to the axis


def _limits(path: Path, joint) -> tuple[float, float]:
    """The joint's ``[low, high]``, degrees (continuous: +-360), or mm for a prismatic joint."""
    if joint.type == "continuous":
        return -CONTINUOUS_LIMIT_DEG, CONTINUOUS_LIMIT_DEG
    limit = joint.limit
    unit = "metres" if joint.type == "prismatic" else "radians"
    if limit is None or limit.lower is None or limit.upper is None or not limit.lower < limit.upper:
        raise RobotFileError(f"{path}: <joint name={joint.name!r}> <limit>: expected lower < upper ({unit}) for a "
                             f"{joint.type} joint; got {None if limit is None else (limit.lower, limit.upper)}")
    if joint.type == "prismatic":
        return limit.lower * _M_TO_MM, limit.upper * _M_TO_MM
    return math.degrees(limit.lower), math.degrees(limit.upper)


def _check_elements(path: Path) -> None:
    """The elements the chain reads, checked with their lines before yourdfpy parses the file: a ``<robot>``
    root; every ``<joint>`` with a name, a known type, ``<parent link>`` and ``<child link>``; numbers of
    the right count in ``<origin>``, ``<axis>`` (not zero, but for a fixed joint) and ``<limit>``; and the
    links and joints a tree (:func:`_check_tree`)."""
    from lxml import etree     # yourdfpy's own XML parser

    try:
        root = etree.parse(str(path)).getroot()
    except etree.XMLSyntaxError as exc:
        raise RobotFileError(f"{path}: line {exc.lineno}: not well-formed XML: {exc.msg}") from None
    if root.tag != "robot":
        raise RobotFileError(f"{path}: line {root.sourceline}: expected a <robot> root element; got <{root.tag}>")
    for joint in root.iter("joint"):
        if joint.getparent() is not root:
            continue                       # <transmission> holds <joint> elements of its own
        where = f"{path}: line {joint.sourceline}: <joint name={joint.get('name')!r}>"
        if not joint.get("name"):
            raise RobotFileError(f"{path}: line {joint.sourceline}: <joint>: expected a name attribute")
        if joint.get("type") not in JOINT_TYPES:
            raise RobotFileError(f"{where}: expected type one of {', '.join(JOINT_TYPES)}; got "
                                 f"{joint.get('type')!r}")
        for tag in ("parent", "child"):
            element = joint.find(tag)
            if element is None or not element.get("link"):
                raise RobotFileError(f"{where}: expected <{tag} link=\"...\"/>")
        checks = (("origin", "xyz", 3), ("origin", "rpy", 3), ("axis", "xyz", 3), ("limit", "lower", 1),
                  ("limit", "upper", 1), ("mimic", "multiplier", 1), ("mimic", "offset", 1))
        for tag, attribute, count in checks:
            element = joint.find(tag)
            if element is None or element.get(attribute) is None:
                continue
            text = element.get(attribute)
            try:
                values = [float(v) for v in text.split()]
            except ValueError:
                values = []
            if len(values) != count or not all(math.isfinite(v) for v in values):
                raise RobotFileError(f"{where} <{tag} {attribute}=\"{text}\">: expected {count} finite "
                                     f"number{'s' if count > 1 else ''} (metres, radians)")
            if tag == "axis" and not any(values) and joint.get("type") != "fixed":    # a fixed one means nothing
                raise RobotFileError(f"{where} <axis xyz=\"{text}\">: expected a non-zero axis")
    _check_tree(path, root)


def _check_tree(path: Path, root) -> None:
    """The links and joints of ``root`` form a tree: each ``<link>`` and ``<joint>`` name once, each joint
    between two declared links, each link the child of at most one joint, and no cycle. A link with two
    parents would otherwise keep one of them silently (and build another robot)."""
    links, joints, parent_of = {}, {}, {}
    for link in root.findall("link"):
        name = link.get("name")
        if not name:
            raise RobotFileError(f"{path}: line {link.sourceline}: <link>: expected a name attribute")
        if name in links:
            raise RobotFileError(f"{path}: line {link.sourceline}: <link name={name!r}>: expected each link name "
                                 f"once; already declared at line {links[name]}")
        links[name] = link.sourceline
    for joint in root.findall("joint"):
        name, line = joint.get("name"), joint.sourceline
        where = f"{path}: line {line}: <joint name={name!r}>"
        if name in joints:
            raise RobotFileError(f"{where}: expected each joint name once; already declared at line {joints[name]}")
        joints[name] = line
        parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
        for tag, link in (("parent", parent), ("child", child)):
            if link not in links:
                raise RobotFileError(f"{where} <{tag} link={link!r}>: expected a declared <link>; no link of that "
                                     "name")
        if child in parent_of:
            other, other_line, _ = parent_of[child]
            raise RobotFileError(f"{where} <child link={child!r}>: expected one parent joint per link (a URDF is a "
                                 f"tree); {child!r} is already the child of joint {other!r} at line {other_line}")
        parent_of[child] = (name, line, parent)
    done: set[str] = set()
    for start in links:                    # follow each link's parents up to a root; a link met twice: a cycle
        path_links, link = [], start
        while link in parent_of and link not in done:
            if link in path_links:
                loop = path_links[path_links.index(link):]
                child = max(loop, key=lambda k: parent_of[k][1])      # the joint read last closes it
                name, line, _ = parent_of[child]
                down = loop[::-1]                                     # parent -> child, from that joint's child
                down = down[down.index(child):] + down[:down.index(child)]
                chain = " -> ".join(down + [child])
                raise RobotFileError(f"{path}: line {line}: <joint name={name!r}>: closes a cycle of links ({chain}); "
                                     "expected a tree")
            path_links.append(link)
            link = parent_of[link][2]
        done.update(path_links)
