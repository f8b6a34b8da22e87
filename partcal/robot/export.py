"""The calibrated robot out: a chain written as a URDF, as the UR drivers' kinematics YAML, as a DH table.

Everything here reads a :class:`~partcal.robot.kinematics.Robot`, whose rows
are ``Rz(theta) G`` with ``theta = offset + coupling @ q`` and ``G`` the
row's fixed transform (``Tz(d) Tx(a) Rx(alpha) E``), after the base pose
``B`` and before the tool point. Units change at this boundary: mm and
degrees inside, metres and radians in URDF and UR files.

- :func:`urdf_from_robot`: one URDF joint per row, its origin ``G`` of the
  row before (``B`` for the first) times ``Rz(offset)``: the joint offsets
  fold into the origins, as drivers ignore ``<calibration>``. Base and tool
  are fixed joints (``world -> base_link`` for a given base pose, ``flange ->
  tcp`` for the tool point, turned by the identified turn of the tool or
  reflector when one is given: ``flange_T_tool``'s rotation).
- :func:`ur_kinematics_from_robot`: the ``kinematics:`` mapping of
  ur_description's ``default_kinematics.yaml``. ur_description builds
  ``base_link_inertia -> shoulder -> upper_arm -> forearm -> wrist_1 ->
  wrist_2 -> wrist_3``, each joint an origin ``Tr(x, y, z) Rz(yaw) Ry(pitch)
  Rx(roll)`` (metres, radians) then a turn about its z axis; ``tool0`` is the
  wrist_3 frame (its flange and tool0 turns cancel). Each row's ``G`` is split
  into ``Tz(h) Rz(gamma)``, which commutes with the joint's turn and moves in
  front of it, and the rest ``N``, which goes into the next joint's origin;
  the last row's ``N`` cannot follow ``q6`` in that file, so it goes into the
  tool centre point (TCP) reported beside it, with the tool's own turn. The
  file has no tool (ur_description's ``tool0`` hangs at a fixed turn from
  ``flange``): the TCP, position and rotation, is for the controller
  (``set_tcp(p[x, y, z, rx, ry, rz])``, metres and a rotation vector in
  radians, as the Installation's TCP takes it), written in the file's header.
- :func:`dh_rows`: the standard DH table, for a chain that is one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import PartcalError
from .kinematics import Robot
from .rotations import matrix_from_rpy_deg, rotation_vectors_from_matrices, rpy_deg_from_matrix

UR_JOINTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
_MM_TO_M = 1e-3


class ExportError(PartcalError):
    """A robot cannot be written in the form asked for (one line: which form, what it needs, what it has)."""


def fixed_transforms(robot: Robot) -> NDArray[np.float64]:
    """Every row's fixed transform ``G = Tz(d) Tx(a) Rx(alpha) E``, shape ``(R, 4, 4)`` (mm); a sliding row's
    constant ``d`` is left out (it slides with the joint: the URDF's joint origin holds it)."""
    rows = robot.alpha_deg.size
    out = np.tile(np.eye(4), (rows, 1, 1))
    for r in range(rows):
        out[r, :3, :3] = matrix_from_rpy_deg([robot.alpha_deg[r], 0.0, 0.0])
        slide = robot.prismatic is not None and robot.prismatic[r]
        out[r, :3, 3] = [robot.a_mm[r], 0.0, 0.0 if slide else robot.d_mm[r]]
        if robot.origins is not None:
            extra = np.eye(4)
            extra[:3, :3] = matrix_from_rpy_deg(robot.origins[r, 3:])
            extra[:3, 3] = robot.origins[r, :3]
            out[r] = out[r] @ extra
    return out


def transform(rotation=None, translation=None) -> NDArray[np.float64]:
    """A homogeneous transform ``(4, 4)`` from a rotation ``(3, 3)`` and a translation ``(3,)``."""
    out = np.eye(4)
    if rotation is not None:
        out[:3, :3] = rotation
    if translation is not None:
        out[:3, 3] = translation
    return out


def rz(angle_deg: float) -> NDArray[np.float64]:
    return transform(matrix_from_rpy_deg([0.0, 0.0, angle_deg]))


def _row_joints(robot: Robot) -> list[tuple[int, float] | None]:
    """Each row's joint (0-based) and coefficient, or None for a row no joint turns; several joints refused."""
    out = []
    for r, coef in enumerate(robot.coupling):
        joints = np.flatnonzero(coef)
        if joints.size > 1:
            raise ExportError(f"{robot.name}: row {r + 1} turns with {joints.size} joints "
                              f"({' '.join(f'q{j + 1}' for j in joints)}); a URDF joint follows one (a parallelogram "
                              "needs partcal's own robot YAML or the DH table)")
        out.append((int(joints[0]), float(coef[joints[0]])) if joints.size else None)
    return out


@dataclass(frozen=True)
class UrdfJoint:
    """One joint of an exported URDF: its name, type, parent and child links, origin ``(4, 4)`` (mm), the
    joint it mimics and the multiplier, and its limits (deg)."""

    name: str
    kind: str
    parent: str
    child: str
    origin: NDArray[np.float64]
    mimic: tuple[str, float] | None = None
    limits_deg: tuple[float, float] | None = None      # mm for a prismatic joint


def urdf_joints(robot: Robot, base_pose: NDArray[np.float64] | None = None,
                tool_rotation: NDArray[np.float64] | None = None) -> list[UrdfJoint]:
    """The joints of :func:`urdf_from_robot` (see the module notes)."""
    rows = _row_joints(robot)
    fixed = fixed_transforms(robot)
    joints = [] if base_pose is None else [UrdfJoint("world_joint", "fixed", "world", "base_link", base_pose)]
    first = {}
    previous = transform(robot.base_rotation, robot.base_mm)
    parent = "base_link"
    slides = robot.prismatic if robot.prismatic is not None else np.zeros(len(rows), dtype=bool)
    for r, row in enumerate(rows):
        origin = previous @ rz(robot.theta_offset_deg[r])
        if slides[r]:                       # the slide's constant part: into the origin, before the joint
            origin = origin @ transform(None, [0.0, 0.0, robot.d_mm[r]])
        kind = "prismatic" if slides[r] else "revolute"
        child = f"link{r + 1}"
        if row is None:
            joints.append(UrdfJoint(f"row{r + 1}_fixed", "fixed", parent, child, origin))
        else:
            j, c = row
            if j not in first and c == 1.0:
                first[j] = f"joint{j + 1}"
                joints.append(UrdfJoint(first[j], kind, parent, child, origin,
                                        limits_deg=tuple(float(v) for v in robot.limits_deg[j])))
            else:
                master = first.get(j)
                if master is None:
                    raise ExportError(f"{robot.name}: row {r + 1} turns by {c:g} q{j + 1} before any row turns by "
                                      f"q{j + 1} itself; a URDF mimic joint needs that one first")
                joints.append(UrdfJoint(f"row{r + 1}_mimic", kind, parent, child, origin, mimic=(master, c),
                                        limits_deg=(-360.0 * abs(c) - 360.0, 360.0 * abs(c) + 360.0)))
        previous, parent = fixed[r], child
    joints.append(UrdfJoint("flange_joint", "fixed", parent, "flange", previous))
    joints.append(UrdfJoint("tcp_joint", "fixed", "flange", "tcp", transform(tool_rotation, robot.tool_mm)))
    return joints


def urdf_from_robot(robot: Robot, base_pose: NDArray[np.float64] | None = None, comment: str = "",
                    tool_rotation: NDArray[np.float64] | None = None, fixed_links=()) -> str:
    """The chain as URDF text: links ``[world], base_link, link1..linkR, flange, tcp`` (metres, radians).

    Parameters
    ----------
    robot : Robot
    base_pose : ndarray, shape (4, 4), optional
        The robot's base in a world (measurement) frame, mm: a fixed joint
        ``world -> base_link``. None: the file starts at ``base_link``.
    comment : str
        Put at the top of the file.
    tool_rotation : ndarray, shape (3, 3), optional
        The tool's (or reflector's) turn in the flange frame, ``flange_T_tool``'s
        rotation (an identified probe turn): the fixed joint ``flange -> tcp``
        carries it. None: the tool frame is the flange's, moved to the tool point.
    fixed_links : sequence of (child, parent, origin)
        Further links fixed to one of the chain's (``world``, ``base_link``, ``flange``, ...) at ``origin`` (4, 4;
        mm): a camera's optical frame, a board.
    """
    from xml.sax.saxutils import quoteattr

    lines = ['<?xml version="1.0"?>', *(f"<!-- {c} -->" for c in comment.splitlines() if c),
             f"<robot name={quoteattr(robot.name + '_calibrated')}>"]
    joints = urdf_joints(robot, base_pose, tool_rotation)
    joints += [UrdfJoint(f"{child}_joint", "fixed", parent, child, np.asarray(origin, dtype=float))
               for child, parent, origin in fixed_links]
    links = [joints[0].parent] + [j.child for j in joints]
    lines += [f'  <link name="{name}"/>' for name in links]
    for j in joints:
        xyz = " ".join(repr(float(v) * _MM_TO_M) for v in j.origin[:3, 3])
        rpy = " ".join(repr(math.radians(float(v))) for v in rpy_deg_from_matrix(j.origin[:3, :3]))
        lines.append(f'  <joint name="{j.name}" type="{j.kind}">')
        lines.append(f'    <parent link="{j.parent}"/>\n    <child link="{j.child}"/>')
        lines.append(f'    <origin xyz="{xyz}" rpy="{rpy}"/>')
        if j.kind in ("revolute", "prismatic"):
            low, high = (v * _MM_TO_M if j.kind == "prismatic" else math.radians(v) for v in j.limits_deg)
            lines.append('    <axis xyz="0 0 1"/>')
            lines.append(f'    <limit lower="{low!r}" upper="{high!r}" effort="0" velocity="0"/>')
        if j.mimic is not None:
            lines.append(f'    <mimic joint="{j.mimic[0]}" multiplier="{j.mimic[1]!r}" offset="0"/>')
        lines.append("  </joint>")
    lines.append("</robot>")
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class UrKinematics:
    """The UR drivers' kinematics (``kinematics`` of ``default_kinematics.yaml``: per joint x, y, z in metres,
    roll, pitch, yaw in radians), and the tool centre point in ``tool0``: ``tcp_mm`` (3,) and ``tcp_rotation``
    (3, 3), what the last row leaves after ``q6`` and the measured point."""

    joints: dict
    tcp_mm: NDArray[np.float64]
    tcp_rotation: NDArray[np.float64]

    @property
    def tcp_rotvec_rad(self) -> NDArray[np.float64]:
        """The TCP's turn as a rotation vector ``(3,)``, radians (``rx, ry, rz`` of UR's TCP)."""
        return rotation_vectors_from_matrices(self.tcp_rotation)[0]

    def tcp_text(self) -> str:
        """The TCP as the controller takes it, one line: position (mm) and rotation vector (radians, and the
        angle in degrees), and ``set_tcp``'s form (metres, radians)."""
        x, y, z = (float(v) for v in self.tcp_mm)
        rx, ry, rz = (float(v) for v in self.tcp_rotvec_rad)
        angle = math.degrees(math.sqrt(rx * rx + ry * ry + rz * rz))
        pose = ", ".join(repr(v) for v in (x * _MM_TO_M, y * _MM_TO_M, z * _MM_TO_M, rx, ry, rz))
        return (f"x {x:.6f} y {y:.6f} z {z:.6f} mm, rx {rx:.9f} ry {ry:.9f} rz {rz:.9f} rad (rotation vector, a "
                f"turn of {angle:.6f} deg); set_tcp(p[{pose}])")

    def yaml_text(self, hash_text: str, comment: str = "") -> str:
        """The file, in ur_description's layout."""
        lines = [f"# {c}" if c else "#" for c in comment.splitlines()]
        lines.append("kinematics:")
        for name, values in self.joints.items():
            lines.append(f"  {name}:")
            lines += [f"    {key}: {value!r}" for key, value in values.items()]
        lines.append(f"  hash: {hash_text}")
        return "\n".join(lines) + "\n"


def ur_kinematics_from_robot(robot: Robot, tool_rotation: NDArray[np.float64] | None = None) -> UrKinematics:
    """The UR kinematics of a six-joint chain whose row ``k`` turns with ``q_k`` alone (see the module notes);
    ``tool_rotation`` (3, 3), the tool's turn in the flange frame, goes into the TCP with the last row's rest.

    Raises
    ------
    ExportError
        For any other chain.
    """
    rows = robot.alpha_deg.size
    if robot.n_joints != 6 or rows != 6 or not np.array_equal(robot.coupling, np.eye(6)) or \
            (robot.prismatic is not None and robot.prismatic.any()):
        raise ExportError(f"{robot.name}: the UR kinematics file needs six rows turned by q1..q6 in order; the robot "
                          f"has {robot.n_joints} joints in {rows} rows")
    _check_ur_shape(robot)
    fixed = fixed_transforms(robot)
    rest = transform(robot.base_rotation, robot.base_mm)
    out = {}
    for r, name in enumerate(UR_JOINTS):
        rotation = fixed[r, :3, :3]
        gamma = float(rpy_deg_from_matrix(rotation)[2])
        ahead = transform(matrix_from_rpy_deg([0.0, 0.0, gamma]), [0.0, 0.0, fixed[r, 2, 3]])   # Tz(h) Rz(gamma)
        origin = rest @ rz(robot.theta_offset_deg[r]) @ ahead
        rest = np.linalg.inv(ahead) @ fixed[r]
        roll, pitch, yaw = (math.radians(float(v)) for v in rpy_deg_from_matrix(origin[:3, :3]))
        x, y, z = (float(v) * _MM_TO_M for v in origin[:3, 3])
        out[name] = {"x": x, "y": y, "z": z, "roll": roll, "pitch": pitch, "yaw": yaw}
    tcp = rest @ transform(tool_rotation, robot.tool_mm)
    return UrKinematics(out, tcp[:3, 3].copy(), tcp[:3, :3].copy())


UR_PARALLEL_TOL_DEG = 1.0       # how far from parallel UR-shaped axes 2, 3, 4 may be (identified tilts: ~0.05 deg)


def _check_ur_shape(robot: Robot) -> None:
    """Refuse a six-joint chain that is not a UR arm's: ur_description builds shoulder, elbow and wrist 1 about
    parallel axes (joints 2, 3 and 4), and wrist 2 across them; a KUKA or ABB arm (joint 4 along the forearm)
    has no UR kinematics file."""
    axes = robot.frames(robot.home_deg[None])[1][0]           # z of frames 0..R: joint k turns about z of k - 1
    angle = [math.degrees(math.acos(min(1.0, abs(float(axes[k] @ axes[k + 1]))))) for k in range(5)]
    bad = [(k + 1, k + 2) for k in (1, 2) if angle[k] > UR_PARALLEL_TOL_DEG]
    if bad or angle[3] < 90.0 - UR_PARALLEL_TOL_DEG:
        j, k = bad[0] if bad else (4, 5)
        raise ExportError(f"{robot.name}: the UR kinematics file is for UR-shaped chains (joints 2, 3 and 4 about "
                          f"parallel axes, joint 5 across them, as ur_description builds its arms); here joints {j} "
                          f"and {k} turn about axes {angle[j - 1]:.1f} degrees apart")


def dh_rows(robot: Robot) -> list[dict]:
    """The standard DH table (``theta`` expression, ``d_mm``, ``a_mm``, ``alpha_deg`` per row), for a chain
    without general origins and with its base at the first frame.

    Raises
    ------
    ExportError
        When the chain is not one (rows with origins, as identified by the complete parametrization).
    """
    from .description import robot_to_dict

    if robot.origins is not None and np.any(robot.origins):
        rows = [r + 1 for r in range(robot.alpha_deg.size) if np.any(robot.origins[r])]
        raise ExportError(f"{robot.name}: rows {', '.join(map(str, rows))} have transforms beyond DH (d, a, alpha): "
                          "the chain has no DH table (the complete parametrization's tilts need a URDF or the UR file)")
    spec = robot_to_dict(robot)
    return [{"row": k + 1, "theta": link["theta"], "d_mm": link["d"], "a_mm": link["a"], "alpha_deg": link["alpha"]}
            for k, link in enumerate(spec["links"])]
