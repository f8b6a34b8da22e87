"""Joint errors the geometry cannot carry: gravity compliance and cyclic transmission errors.

A joint does not take the angle it is commanded. Its reducer adds a cyclic
error, a few harmonics of the joint angle (``sin(k q)`` and ``cos(k q)``,
``k = 1..K``), and gravity bends it: the torque of the masses beyond the
joint, over the joint's stiffness. The actual joint angles are

    q_actual = q + sum_k (s_k sin(k q) + c_k cos(k q)) + deflection(q_h)

with ``q_h`` the angles after the transmission errors, and the kinematic
model's forward kinematics runs on ``q_actual``.

The gravity torque about a joint's axis (the z axis of the first DH row it
turns, through that frame's origin ``o``) depends on where the masses are.
partcal lumps them at the origins of the DH frames beyond the joint (every
later frame that a row moves away from the previous one: a row with
``a = d = 0`` adds no new place) and identifies one *sag* parameter per joint
and frame: the deflection per metre of lever arm, ``compliance x weight``
(deg/m), with the lever ``phi(p) = (z_y r_x - z_x r_y) / 1000`` m of a point
``p`` (``r = p - o``, mm, robot base frame, gravity along its ``-z``). A known
payload (kg) at the tool point adds ``compliance x g x payload x
phi(tool)``, so with data at two payloads the compliance itself
(deg/(N m)) is identified. Every column is linear in its
parameter; which of them positions can tell apart (lumped masses on frames
that share an origin, a sag that is a first harmonic of its own joint, a
harmonic of a joint that never moves) is the identifiability analysis's job
(see :mod:`partcal.models.kinematic`).
"""

from __future__ import annotations

from dataclasses import dataclass
from numbers import Integral

import numpy as np
from numpy.typing import NDArray

from ..robot.kinematics import Robot

GRAVITY_M_S2 = 9.80665
MAX_HARMONICS = 8


def compliance_problem(value, n_joints: int) -> str | None:
    """None if ``value`` is a list of distinct joint numbers in ``1..n_joints``, else what is expected."""
    expected = f"a list of distinct joint numbers in [1, {n_joints}]"
    if not isinstance(value, (list, tuple)):
        return expected
    ok = all(isinstance(j, Integral) and not isinstance(j, bool) and 1 <= j <= n_joints for j in value)
    return None if ok and len(set(value)) == len(value) else expected


def harmonics_problem(value, n_joints: int) -> str | None:
    """None if ``value`` is an int in ``[0, 8]`` or a list of ``n_joints`` of them, else what is expected."""
    expected = f"an int in [0, {MAX_HARMONICS}] or a list of {n_joints} such ints"

    def one(v):
        return isinstance(v, Integral) and not isinstance(v, bool) and 0 <= v <= MAX_HARMONICS

    if isinstance(value, (list, tuple)):
        return None if len(value) == n_joints and all(one(v) for v in value) else expected
    return None if one(value) else expected


def harmonics_per_joint(value, n_joints: int) -> tuple[int, ...]:
    """``joint_harmonics`` (an int for every joint, or one per joint) as one int per joint."""
    return tuple(int(v) for v in value) if isinstance(value, (list, tuple)) else (int(value),) * n_joints


@dataclass(frozen=True)
class JointErrors:
    """Which joint errors a kinematic model identifies, for one robot.

    Attributes
    ----------
    compliance : tuple of int
        1-based joints that yield under gravity.
    harmonics : tuple of int, length N
        Harmonics of each joint's transmission error.
    pivots : tuple of int
        Per compliant joint, the DH frame whose z axis it turns about (its first row).
    signs : tuple of float
        Per compliant joint, the sign of the joint in that row (``+1``: it turns about ``+z``).
    frames : tuple of tuple of int
        Per compliant joint, the frames that may carry a lumped mass: every frame after the pivot whose
        row moves its origin (a row with ``a = d = 0`` puts its frame where the previous one is, so
        that frame would only repeat it).
    """

    compliance: tuple[int, ...]
    harmonics: tuple[int, ...]
    pivots: tuple[int, ...]
    signs: tuple[float, ...]
    frames: tuple[tuple[int, ...], ...]

    @classmethod
    def for_robot(cls, robot: Robot, compliance=(), harmonics=0) -> "JointErrors":
        """The joint errors of ``robot``: ``compliance`` joints (1-based), ``harmonics`` (an int or one per joint).

        >>> from partcal.robot import load_robot
        >>> errors = JointErrors.for_robot(load_robot("motoman_sk120"), [3], [0, 0, 1, 0, 0, 0])
        >>> [name for name, _ in errors.names()]        # row 7 (q5) has a = d = 0: no frame 7
        ['sin1[3]', 'cos1[3]', 'sag[3,f2]', 'sag[3,f3]', 'sag[3,f4]', 'sag[3,f5]', 'sag[3,f6]', 'sag[3,f8]', 'compliance[3]']
        """
        pivots, signs, frames = [], [], []
        moves = (robot.a_mm != 0) | (robot.d_mm != 0)          # row r moves frame r + 1 away from frame r
        if robot.origins is not None:
            moves |= np.any(robot.origins[:, :3] != 0, axis=1)
        for j in compliance:
            row = int(np.flatnonzero(robot.coupling[:, j - 1])[0])
            pivots.append(row)
            signs.append(float(np.sign(robot.coupling[row, j - 1])))
            frames.append(tuple(f for f in range(row + 1, robot.alpha_deg.size + 1) if moves[f - 1]))
        return cls(tuple(int(j) for j in compliance), harmonics_per_joint(harmonics, robot.n_joints),
                   tuple(pivots), tuple(signs), tuple(frames))

    @property
    def empty(self) -> bool:
        return not self.compliance and not any(self.harmonics)

    def names(self) -> list[tuple[str, str]]:
        """``(name, unit)`` of every parameter: harmonics (``sin1[2]``, ``cos1[2]``, ... deg), then per
        compliant joint its sags (``sag[2,f3]``, deg/m, frame 3) and its compliance (``compliance[2]``)."""
        out = [(f"{t}{k}[{j + 1}]", "deg") for j, count in enumerate(self.harmonics)
               for k in range(1, count + 1) for t in ("sin", "cos")]
        for j, frames in zip(self.compliance, self.frames):
            out += [(f"sag[{j},f{f}]", "deg/m") for f in frames]
            out.append((f"compliance[{j}]", "deg/(N m)"))
        return out

    @property
    def size(self) -> int:
        return 2 * sum(self.harmonics) + sum(len(f) + 1 for f in self.frames)

    def design(self, geometry: Robot, q_deg: NDArray[np.float64], values: NDArray[np.float64],
               payload_kg: NDArray[np.float64], derivatives: bool = False, motions=None):
        """The actual joint angles and ``d q_actual / d values``.

        Parameters
        ----------
        geometry : Robot
            The robot's geometry in its own base frame (gravity along its ``-z``).
        q_deg : ndarray, shape (n, N)
            Commanded joint angles, degrees.
        values : ndarray, shape (P,)
            The parameters, in the order of :meth:`names`.
        payload_kg : ndarray, shape (n,)
            Payload at the tool point per pose, kg.
        derivatives : bool
            Also the lever arms' dependence on the geometry and on the
            transmission errors (see Returns).
        motions : callable, optional
            ``motions(geometry, q_deg)``: how each geometric row parameter moves
            the frames (:func:`dh_motions`, the default, for DH rows; the
            complete parametrization gives its own).

        Returns
        -------
        q_actual : ndarray, shape (n, N)
            degrees.
        design : ndarray, shape (n, N, P)
            ``d q_actual / d values``. Without ``derivatives`` a harmonic's
            column leaves out how its turn moves the lever arms (the
            deflection is still linear in the other parameters).
        moves : ndarray, shape (n, N, K R + 3), or None
            With ``derivatives``: ``d q_actual / d`` every row parameter (the
            ``K`` of each row in the order of ``motions``: theta, d, a, alpha
            for DH rows) and the tool's x, y, z, through the lever arms.
        """
        out = np.zeros((*q_deg.shape, values.size))
        turned = self._harmonic_columns(q_deg, out)
        col = len(turned)
        q_h = q_deg + out[:, :, :col] @ values[:col]
        moves = self._sag_columns(geometry, q_h, values, payload_kg, out, col, derivatives, motions or dh_motions) \
            if self.compliance else None
        q_actual = q_deg + out @ values
        if moves is not None and turned:    # a harmonic turns its joint, and so the rows it drives (per degree)
            stride = (moves.shape[2] - 3) // geometry.alpha_deg.size           # each row's theta comes first
            per_joint = moves[:, :, 0:moves.shape[2] - 3:stride] @ geometry.coupling      # (n, N, N)
            for c, j in enumerate(turned):
                out[:, :, c] += per_joint[:, :, j] * out[:, j, c, None]
        return q_actual, out, moves

    def _harmonic_columns(self, q_deg: NDArray[np.float64], out: NDArray[np.float64]) -> list[int]:
        """Write ``sin(k q_j)``, ``cos(k q_j)`` into the first columns of ``out`` (n, N, P); return the joint
        (0-based) of each."""
        col, turned = 0, []
        for j, count in enumerate(self.harmonics):
            rad = np.radians(q_deg[:, j])
            for k in range(1, count + 1):
                out[:, j, col], out[:, j, col + 1] = np.sin(k * rad), np.cos(k * rad)
                turned += [j, j]
                col += 2
        return turned

    def _sag_columns(self, geometry: Robot, q_h, values, payload_kg, out, col: int, derivatives: bool, motions):
        """Write the lever arms of every compliant joint (sags, then the payload's) into ``out`` from column
        ``col`` on, for the joint angles ``q_h``; with ``derivatives`` return how the row parameters
        (``motions``) and the tool move them, ``(n, N, K R + 3)`` (None otherwise)."""
        origins, xs, zs = geometry.frame_axes(q_h)
        ys = np.cross(zs[:, -1], xs[:, -1])
        tool_mm = geometry.tool_mm
        tool = origins[:, -1] + tool_mm[0] * xs[:, -1] + tool_mm[1] * ys + tool_mm[2] * zs[:, -1]
        weight = GRAVITY_M_S2 * payload_kg
        frames_of = _Frames(origins, xs, zs, ys, tool, motions(geometry, q_h) if derivatives else [])
        moves = np.zeros((*q_h.shape, len(frames_of.motions) + 3)) if derivatives else None
        for j, pivot, sign, frames in zip(self.compliance, self.pivots, self.signs, self.frames):
            z = sign * zs[:, pivot]
            arm = np.concatenate([origins[:, list(frames)], tool[:, None]], axis=1) - origins[:, pivot, None]
            lever = _cross_z(arm, z[:, None]) / 1000.0
            out[:, j - 1, col:col + len(frames)] = lever[:, :-1]
            out[:, j - 1, col + len(frames)] = weight * lever[:, -1]
            if derivatives:
                w = np.empty((len(q_h), len(frames) + 1))
                w[:, :-1] = values[col:col + len(frames)]
                w[:, -1] = values[col + len(frames)] * weight
                moves[:, j - 1] = frames_of.lever_moves(pivot, z, arm, (*frames, origins.shape[1]), w)
            col += len(frames) + 1
        return moves


def _cross_z(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """The z component of ``a x b`` (last axis 3). The torque of a weight of 1 N at ``r`` (m) from a point
    of the axis ``z`` about it is ``z . (r x (0, 0, -1)) = (r x z)_z``: ``_cross_z(r, z)``."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


@dataclass(frozen=True)
class _Frames:
    """The DH frames of a batch of poses, for the lever arms' derivatives: origins, x and z axes
    ``(n, R + 1, 3)``, the last frame's y axis and the tool point ``(n, 3)``, and how each row parameter
    moves the frames after its row (``motions``: ``(kind, vector, centre, row)``, see :func:`dh_motions`)."""

    origins: NDArray[np.float64]
    xs: NDArray[np.float64]
    zs: NDArray[np.float64]
    y_last: NDArray[np.float64]
    tool: NDArray[np.float64]
    motions: list

    def lever_moves(self, pivot: int, z, arm, index: tuple, w) -> NDArray[np.float64]:
        """``d (sum_k w_k lever_k) / d`` every row parameter and the tool, shape (n, K R + 3).

        ``arm`` (n, K, 3) mm runs from the pivot to the points, ``index`` (K,) is each point's frame
        (the tool's is ``R + 1``), ``w`` (n, K) their weights (deg/m). A row before the pivot turns the
        pivot, its axis and every point together: the lever changes only by a rotation (a tilt against
        gravity), never by a shift. A row after it moves the points beyond it, the axis staying put.

        The weighted lever is linear in the points, so each motion acts on one weighted sum of them
        (``sum_k w_k u x r_k = u x sum_k w_k r_k``), never on every point: one cross product of
        ``(n, 3)`` per motion.
        """
        n = arm.shape[0]
        size = len(self.motions)
        out = np.zeros((n, size + 3))
        index = np.asarray(index)
        rad = np.pi / 180.0

        def torque(v):                     # the lever's change when the points move by v (weights summed)
            return (v[:, 0] * z[:, 1] - v[:, 1] * z[:, 0]) / 1000.0

        whole = np.einsum("nk,nki->ni", w, arm)             # sum_k w_k arm_k
        beyond: dict[int, tuple] = {}                       # per row: sum of w_k, sum of w_k (point_k - pivot)

        def sums(r: int) -> tuple:
            if r not in beyond:
                mask = index >= r + 1
                beyond[r] = (w[:, mask].sum(axis=1), np.einsum("nk,nki->ni", w[:, mask], arm[:, mask]))
            return beyond[r]

        pivot_at = self.origins[:, pivot]
        for c, (kind, u, centre, r) in enumerate(self.motions):
            if pivot >= r + 1:                                  # the whole lever turns (shifts change nothing)
                if kind == "turn":
                    dz = np.cross(u, z)
                    out[:, c] = (torque(np.cross(u, whole)) + (whole[:, 0] * dz[:, 1] - whole[:, 1] * dz[:, 0])
                                 / 1000.0) * rad
                continue
            weight, moment = sums(r)
            if kind == "turn":              # sum_k w_k u x (point_k - centre)
                out[:, c] = torque(np.cross(u, moment + weight[:, None] * (pivot_at - centre))) * rad
            else:
                out[:, c] = torque(u) * weight
        for k, axis in enumerate((self.xs[:, -1], self.y_last, self.zs[:, -1])):
            out[:, size + k] = torque(axis) * w[:, -1]
        return out


def dh_motions(geometry: Robot, q_deg: NDArray[np.float64]) -> list:
    """How each DH row parameter moves the frames after its row, ``(kind, vector (n, 3), centre (n, 3), row)``
    in the order theta, d, a, alpha of every row: theta turns about the row's z axis at its origin, d
    shifts along it, a shifts along the x axis after the row's DH part and alpha turns about it there (the
    next frame's, for a row without a further origin)."""
    origins, _, zs = geometry.frame_axes(q_deg)
    mid_origins, mid_xs = geometry.dh_axes(q_deg)
    out = []
    for r in range(origins.shape[1] - 1):
        out += [("turn", zs[:, r], origins[:, r], r), ("shift", zs[:, r], None, r),
                ("shift", mid_xs[:, r], None, r), ("turn", mid_xs[:, r], mid_origins[:, r], r)]
    return out
