"""Robot kinematics: one generic chain of joint motions and fixed transforms, with coupled joints.

A robot is a chain of rows, each a joint's turn about its frame's ``z`` axis
followed by a fixed transform to the next joint's frame:
``T = Rz(theta) F``, ``F = Tz(d) Tx(a) Rx(alpha) E``. ``d, a, alpha`` are the
standard DH part of the fixed transform (exact shortcuts for right angles,
and the rows of partcal's robot YAML); ``E`` is any further rigid transform
(``origins``: translation and roll-pitch-yaw, as a URDF joint's origin), the
identity for a DH robot. A URDF chain is a chain of rows with ``d = a = alpha = 0``
and ``E`` its joints' origins, turned so that each joint axis is ``z``
(:mod:`partcal.robot.urdf`). The tool offset follows the last row. Each row's
``theta`` is a *linear expression* of the joint angles, such as ``q1`` or
``180 - q2 + q3``; that is enough to describe closed-chain mechanisms whose
passive angles follow the actuated ones, like the parallelogram (five-bar) of
the Motoman SK120 in the paper's Table 1, and a URDF's mimic joints.

Everything is batched: joint angles come in as ``(n, N)`` arrays in degrees,
positions go out as ``(n, 3)`` arrays in mm. Radians live only inside.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import DataError, UnreachableError
from . import ik
from .rotations import matrices_from_xyz_deg, rpy_deg_from_matrix, xyz_deg_from_matrices  # noqa: F401 - as before
from .rotations import matrix_from_rpy_deg, rotation_vectors_from_matrices

#: :func:`~partcal.robot.rotations.matrix_from_rpy_deg` by its name before rotations.py held every convention.
matrix_from_euler_deg = matrix_from_rpy_deg

_CHUNK = 8192
_I1, _I2 = [1, 2, 0], [2, 0, 1]          # cross product: (a x b)_k = a_{k+1} b_{k+2} - a_{k+2} b_{k+1}


def _cos_sin_deg(angle_deg: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """cos and sin of angles in degrees, exact (0 or +-1) at multiples of 90 degrees."""
    rad = np.radians(angle_deg)
    c, s = np.cos(rad), np.sin(rad)
    rest = np.mod(angle_deg, 90.0)      # exact multiples only: a twist of -90.0005 is not -90
    right = (np.abs(rest) <= 1e-12) | (np.abs(rest - 90.0) <= 1e-12)
    c[right], s[right] = np.round(c[right]), np.round(s[right])
    return c, s


ORIENTATION_MM_PER_RAD = 200.0
"""How many mm an orientation residual of one radian counts as beside position residuals (registration,
identification): the displacement a turn causes 200 mm from its axis, about a tool plate's size. For a
tracker's 0.02-0.03 mm and a 6-D probe's 0.005-0.01 degrees, this weighs each roughly by its noise."""


@dataclass(frozen=True, eq=False)
class Robot:
    """A serial chain of joint turns and fixed transforms (DH rows, possibly with a general origin), possibly
    with coupled joints.

    Attributes
    ----------
    name : str
    n_joints : int
        Number of actuated joints ``N`` (the columns ``q1..qN``).
    alpha_deg, d_mm, a_mm, theta_offset_deg : ndarray, shape (R,)
        DH parameters of the ``R`` rows.
    coupling : ndarray, shape (R, N)
        ``theta_row = theta_offset_deg + coupling @ q_deg``.
    tool_mm : ndarray, shape (3,)
        The measured point in the last frame.
    base_rotation, base_mm : ndarray, shape (3, 3) and (3,)
        Pose of the first DH frame in the base (world) frame.
    limits_deg : ndarray, shape (N, 2)
        Lower and upper joint limits.
    home_deg : ndarray, shape (N,)
        A reference pose, the default seed of inverse kinematics.
    constraints : tuple of (coefficients, low, high)
        Extra limits on linear joint combinations (e.g. the parallelogram's
        inner angle ``q2 - q3``), as ``low <= coefficients @ q <= high``.
    prismatic : ndarray of bool, shape (R,), or None
        Rows that slide instead of turning: their ``theta`` is the constant
        ``theta_offset_deg`` and ``d = d_mm + coupling @ q`` (mm; a prismatic
        joint's column holds millimetres). None: every row turns.
    origins : ndarray, shape (R, 6), or None
        A rigid transform ``E`` ending each row after its DH part:
        ``x, y, z`` (mm) then ``roll, pitch, yaw`` (degrees, the rotation
        ``Rz(yaw) Ry(pitch) Rx(roll)``, a URDF origin's convention). None: the
        identity for every row (a plain DH chain).
    floor_mm : float or None
        Height of the floor in the base frame, mm (0: the base frame stands on
        it); None (the default: a floor not stated is not assumed) for an arm not
        standing on a floor (ceiling, wall, pedestal) or one whose mounting
        height is not known. ``partcal plan`` keeps every pose above it
        (:mod:`partcal.robot.floor`).
    plausible_error : dict or None
        The robot's own plausible error of a geometric parameter per unit (``{"mm": ..., "deg": ...}``, the
        datasheet's tolerances) for the identification's plausible prior; None: partcal's defaults
        (:data:`partcal.calibration.parameters.PLAUSIBLE_ERROR`).
    """

    name: str
    n_joints: int
    alpha_deg: NDArray[np.float64]
    d_mm: NDArray[np.float64]
    a_mm: NDArray[np.float64]
    theta_offset_deg: NDArray[np.float64]
    coupling: NDArray[np.float64]
    tool_mm: NDArray[np.float64]
    limits_deg: NDArray[np.float64]
    home_deg: NDArray[np.float64]
    base_rotation: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.eye(3))
    base_mm: NDArray[np.float64] = dataclasses.field(default_factory=lambda: np.zeros(3))
    constraints: tuple = ()
    origins: NDArray[np.float64] | None = None
    prismatic: NDArray[np.bool_] | None = None
    floor_mm: float | None = None
    plausible_error: dict | None = None

    def replace(self, **changes) -> "Robot":
        """Return a copy with some fields changed (used to build perturbed robots)."""
        return dataclasses.replace(self, **changes)

    def check_joints(self, q_deg, name: str = "q_deg") -> NDArray[np.float64]:
        """Validate joint angles: ``(n, N)`` finite degrees (a single pose is promoted)."""
        arr = np.asarray(q_deg, dtype=float)
        if arr.ndim == 1:
            arr = arr[None, :]
        return check_array(arr, name, columns=self.n_joints)

    @property
    def reach_mm(self) -> float:
        """An upper bound on the distance from the base origin to the tool, mm (every link stretched out).

        >>> from partcal.robot import load_robot
        >>> round(load_robot("motoman_sk120").reach_mm, 2)
        4413.19
        """
        extra = 0.0 if self.origins is None else float(np.linalg.norm(self.origins[:, :3], axis=1).sum())
        if self.prismatic is not None:        # a slide adds its longest travel
            travel = np.abs(self.coupling[self.prismatic]) @ np.abs(self.limits_deg).max(axis=1)
            extra += float(travel.sum())
        return float(np.hypot(self.a_mm, self.d_mm).sum() + extra + np.linalg.norm(self.tool_mm))

    def within_limits(self, q_deg: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which poses respect the joint limits and the coupled constraints, shape (n,)."""
        ok = np.all((q_deg >= self.limits_deg[:, 0]) & (q_deg <= self.limits_deg[:, 1]), axis=1)
        for coeffs, low, high in self.constraints:
            v = q_deg @ coeffs
            ok &= (v >= low) & (v <= high)
        return ok

    # ------------------------------------------------------------------ kinematics
    # The walk is the robot layer's own geometry, public so that solvers (IK, identification) can walk the chain
    # once per iteration: ``p, axes, frames = robot.walk(robot.rotors(qT), record=robot.moving_rows(free))``,
    # then ``robot.walk_jacobian(p, frames, free)``. Joints enter transposed, ``qT`` (N, n) degrees, and
    # vectors leave as (3, n): every operation then runs over contiguous runs of the n poses.
    @property
    def n_rows(self) -> int:
        """The number of rows ``R`` of the chain (joint turns or slides, each with its fixed transform)."""
        return len(self.alpha_deg)

    @functools.cached_property
    def _rows(self) -> tuple["_Row", ...]:
        """The DH rows compiled for the walk (built once per robot)."""
        ca, sa = _cos_sin_deg(self.alpha_deg)
        return tuple(_Row(float(off), tuple((int(j), float(c)) for j, c in enumerate(coef) if c),
                          float(ca[r]), float(sa[r]), float(self.a_mm[r]), float(self.d_mm[r]), self._origin(r),
                          bool(self.prismatic is not None and self.prismatic[r]))
                     for r, (off, coef) in enumerate(zip(self.theta_offset_deg, self.coupling)))

    def _origin(self, row: int) -> tuple | None:
        """Row ``row``'s transform ``E`` as ``(rotation (3, 3), translation (3,) mm)`` of floats, None if identity."""
        if self.origins is None or not np.any(self.origins[row]):
            return None
        rot = matrix_from_rpy_deg(self.origins[row, 3:])
        return tuple(tuple(float(v) for v in line) for line in rot), tuple(float(v) for v in self.origins[row, :3])

    def rotors(self, qT: NDArray[np.float64], rows=None) -> list:
        """The rotor ``exp(-i theta)`` of each row, the input of :meth:`walk`.

        Parameters
        ----------
        qT : ndarray, shape (N, n)
            Joint angles in degrees (mm for a slide), one column per pose: the transpose of ``q_deg``.
        rows : collection of int, optional
            Only these rows (0-based); the others are ``None`` (a solver fills them from an earlier call).

        Returns
        -------
        list of length R
            Per row a complex array ``(n,)`` (its turn ``theta`` varies with the joints), a Python complex
            (constant), ``None`` (not asked for), or for a sliding row the pair ``(rotor, slide (n,) mm)``.
            Every operation is elementwise in the poses, so a pose gets the same bits alone or in any batch.
        """
        out: list = [None] * len(self._rows)
        varying = []
        for r, row in enumerate(self._rows):
            if rows is not None and r not in rows:
                continue
            if row.terms and not row.slide:
                varying.append(r)
            else:
                rad = np.radians(row.offset)
                out[r] = complex(np.cos(rad), -np.sin(rad))
                if row.slide:
                    out[r] = (out[r], _linear(row.terms, 0.0, qT, np.empty(qT.shape[1])))
        if varying:
            theta = np.empty((len(varying), qT.shape[1]))
            for k, r in enumerate(varying):
                _theta(self._rows[r], qT, out=theta[k])
            rotors = _rotors(theta)                    # one call for all rows
            for k, r in enumerate(varying):
                out[r] = rotors[k]
        return out

    def walk(self, trig: list, record=()) -> tuple:
        """Walk the chain from the base to the tool for the rows' rotors (:meth:`rotors`).

        A frame is kept as ``w = x + i y`` (3, n) complex and ``z`` (3, n): the
        turn by ``theta`` about ``z`` is one complex product, ``w exp(-i theta)``.

        Parameters
        ----------
        trig : list of length R
            The rotors of every row, as :meth:`rotors` gives them.
        record : collection of int
            Rows (0-based; ``R`` for the frame after the last row) whose axis and origin to keep.

        Returns
        -------
        p : ndarray, shape (3, n)
            Tool positions in the base frame, mm.
        axes : tuple of three ndarrays, shape (3, n) or (3, 1)
            The tool frame's ``x, y, z`` axes in the base frame (unit vectors; an axis no joint turns
            comes back as one column).
        frames : dict
            ``{row: (z (3, n), o (3, n) mm)}`` for each row in ``record``: the axis the row turns about
            and its origin, in the base frame.
        """
        n = next((e.shape[-1] for e in (t[1] if isinstance(t, tuple) else t for t in trig)
                  if isinstance(e, np.ndarray)), 1)
        base = self.base_rotation
        w = (base[:, 0] + 1j * base[:, 1])[:, None]                      # (3, 1): broadcast at first
        z = base[:, 2][:, None]
        p = np.repeat(self.base_mm[:, None], n, axis=1)
        frames = {}
        for r, (row, e) in enumerate(zip(self._rows, trig)):
            if r in record:
                frames[r] = (z if z.shape == p.shape else np.repeat(z, n, axis=1), p.copy())
            slide = None
            if isinstance(e, tuple):
                e, slide = e
            w = w * e                                  # x' = c x + s y, y' = c y - s x
            if row.a:
                p += row.a * w.real
            if row.d:
                p += row.d * z
            if slide is not None:
                p += slide * z
            # then alpha about x': (y, z) -> (ca y + sa z, ca z - sa y); exact shortcuts for 0, 180, +-90
            if row.sa == 0.0:
                if row.ca != 1.0:
                    w, z = np.conjugate(w), np.negative(z)
            else:
                y, turned = w.imag, np.empty(w.shape, dtype=complex)
                turned.real = w.real
                if row.ca == 0.0:
                    turned.imag = z if row.sa == 1.0 else np.negative(z)
                    z = np.negative(y) if row.sa == 1.0 else y.copy()
                else:
                    turned.imag = row.ca * y + row.sa * z
                    z = row.ca * z - row.sa * y
                w = turned
            if row.origin is not None:
                w, z = _apply_origin(row.origin, w, z, p)
        if len(self._rows) in record:
            frames[len(self._rows)] = (z if z.shape == p.shape else np.repeat(z, n, axis=1), p.copy())
        p += self.tool_mm[0] * w.real + self.tool_mm[1] * w.imag + self.tool_mm[2] * z
        return p, (w.real, w.imag, z), frames

    def _chain(self, q_deg: NDArray[np.float64], keep_axes: bool = False):
        """The straightforward walk (x, y, z axes of every frame), for :meth:`parameter_jacobian`.

        Returns tool positions, orientations and optionally the frames.

        With ``keep_axes`` the third value is ``(origins, x_axes, z_axes, mids)``:
        three lists of ``R + 1`` arrays ``(n, 3)`` (frame 0 is the base; frame
        ``r + 1`` ends row ``r``), and per row the origin and x axis after its
        DH part, before its transform ``E`` (the frame itself for a row without
        one); otherwise None. Internally vectors are ``(3, n)`` so every
        operation runs over contiguous runs of ``n`` values (about twice as
        fast as ``(n, 3)``).
        """
        n = q_deg.shape[0]
        moved = self.coupling @ q_deg.T                                                  # (R, n): deg, or mm
        slides = np.zeros(moved.shape[0], dtype=bool) if self.prismatic is None else self.prismatic
        theta = np.radians(self.theta_offset_deg[:, None] + np.where(slides[:, None], 0.0, moved))  # (R, n)
        cos_t, sin_t = np.cos(theta), np.sin(theta)
        ca, sa = _cos_sin_deg(self.alpha_deg)
        r0, r1, r2 = (np.repeat(self.base_rotation[:, k, None], n, axis=1) for k in range(3))
        p = np.repeat(self.base_mm[:, None], n, axis=1)
        origins, xs, zs, mids = [], [], [], []
        for row in range(theta.shape[0]):
            if keep_axes:
                origins.append(p.T.copy())
                xs.append(r0.T)
                zs.append(r2.T)
            c, s = cos_t[row], sin_t[row]
            x_new = c * r0 + s * r1
            y_rot = c * r1 - s * r0
            p += self.a_mm[row] * x_new
            if self.d_mm[row]:
                p += self.d_mm[row] * r2
            if slides[row]:
                p += moved[row] * r2
            if sa[row] == 0.0:  # alpha = 0 or 180: exact, and saves half the work of this row
                r0, r1, r2 = x_new, ca[row] * y_rot, ca[row] * r2
            elif ca[row] == 0.0:  # alpha = +-90
                r0, r1, r2 = x_new, sa[row] * r2, -sa[row] * y_rot
            else:
                r0, r1, r2 = x_new, ca[row] * y_rot + sa[row] * r2, ca[row] * r2 - sa[row] * y_rot
            origin = self._rows[row].origin
            if keep_axes:
                mids.append((p.T.copy(), r0.T))
            if origin is not None:
                (e0, e1, e2), t = origin
                p += t[0] * r0 + t[1] * r1 + t[2] * r2
                r0, r1, r2 = [e0[k] * r0 + e1[k] * r1 + e2[k] * r2 for k in range(3)]
        if keep_axes:
            origins.append(p.T.copy())
            xs.append(r0.T)
            zs.append(r2.T)
        p += self.tool_mm[0] * r0 + self.tool_mm[1] * r1 + self.tool_mm[2] * r2
        frames = (origins, xs, zs, mids) if keep_axes else None
        return p.T, np.stack([r0.T, r1.T, r2.T], axis=-1), frames

    def frames(self, q_deg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Origins and z axes of the DH frames 0..R, each of shape ``(n, R + 1, 3)``.

        Frame 0 is the first DH frame (the base); frame ``k`` follows row ``k``.
        """
        qT = self.check_joints(q_deg).T
        _, _, frames = self.walk(self.rotors(qT), record=range(len(self._rows) + 1))
        keys = sorted(frames)
        return (np.stack([frames[k][1].T for k in keys], axis=1), np.stack([frames[k][0].T for k in keys], axis=1))

    def frame_axes(self, q_deg) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Origins, x axes and z axes of the DH frames 0..R, each of shape ``(n, R + 1, 3)``.

        Frame 0 is the first DH frame (the base); frame ``k`` follows row ``k``.
        """
        _, _, (origins, xs, zs, _) = self._chain(self.check_joints(q_deg), keep_axes=True)
        return np.stack(origins, axis=1), np.stack(xs, axis=1), np.stack(zs, axis=1)

    def dh_axes(self, q_deg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Origins and x axes after each row's DH part (before its origin ``E``), each ``(n, R, 3)``: where a
        row's ``alpha`` turns and along which its ``a`` shifts (frame ``r + 1`` for a row without ``E``)."""
        _, _, (_, _, _, mids) = self._chain(self.check_joints(q_deg), keep_axes=True)
        return np.stack([m[0] for m in mids], axis=1), np.stack([m[1] for m in mids], axis=1)

    def positions(self, q_deg) -> NDArray[np.float64]:
        """Tool positions, shape ``(n, 3)`` mm, for joint angles ``(n, N)`` degrees.

        Examples
        --------
        >>> from partcal.robot import load_robot
        >>> robot = load_robot("motoman_sk120")
        >>> robot.positions([[0, -90, -180, 0, 0, 0]]).round(2).tolist()
        [[1857.65, 0.0, 1555.32]]
        """
        return self.positions_validated(self.check_joints(q_deg))

    def positions_validated(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`positions` of joint angles already checked as a float ``(n, N)`` array in degrees (as
        :meth:`check_joints` returns them; nothing is checked here), shape ``(n, 3)`` mm, in cache-sized blocks."""
        out = np.empty((q.shape[0], 3))
        for start in range(0, q.shape[0], _CHUNK):  # cache-sized blocks: ~2x faster on big batches
            qT = q[start:start + _CHUNK].T
            out[start:start + _CHUNK] = self.walk(self.rotors(qT))[0].T
        return out

    def forward(self, q_deg) -> NDArray[np.float64]:
        """Tool poses as homogeneous transforms, shape ``(n, 4, 4)`` (mm)."""
        q = self.check_joints(q_deg)
        p, axes, _ = self.walk(self.rotors(q.T))
        out = np.zeros((q.shape[0], 4, 4))
        n = q.shape[0]      # an axis that no joint turns (a planar arm's z) comes back as one column
        out[:, :3, :3] = np.stack([np.broadcast_to(a, (3, n)).T for a in axes], axis=-1)
        out[:, :3, 3] = p.T
        out[:, 3, 3] = 1.0
        return out

    def flange(self, q_deg) -> NDArray[np.float64]:
        """Flange poses, shape ``(n, 4, 4)`` (mm): the tool poses without the tool offset."""
        return self.replace(tool_mm=np.zeros(3)).forward(q_deg)

    def jacobian(self, q_deg) -> NDArray[np.float64]:
        """Position Jacobian ``d p / d q``, shape ``(n, 3, N)``, in mm per degree.

        Each DH row contributes ``z x (p - o)`` for its rotation axis ``z`` and
        origin ``o``; rows coupled to several joints add up through the
        coupling matrix.
        """
        qT = self.check_joints(q_deg).T
        _, jac = self._position_jacobian(self.rotors(qT), np.arange(self.n_joints))
        return jac.transpose(2, 1, 0)

    def _position_jacobian(self, trig: list, free: NDArray[np.intp]):
        """Tool position (3, n) mm and Jacobian ``(F, 3, n)`` mm/deg for the joints ``free``."""
        moving = self.moving_rows(free)
        p, _, frames = self.walk(trig, record=moving)
        return p, self.walk_jacobian(p, frames, free)

    def moving_rows(self, free) -> list[int]:
        """The rows (0-based, ascending) that some joint in ``free`` (0-based joint indices) turns or slides:
        the ``record`` a :meth:`walk` needs for :meth:`walk_jacobian`."""
        free = {int(j) for j in free}
        return [r for r, row in enumerate(self._rows) if any(j in free for j, _ in row.terms)]

    def walk_jacobian(self, p: NDArray[np.float64], frames: dict, free, angular: bool = False) -> NDArray[np.float64]:
        """The Jacobian of the walked tool position (or orientation) by the joints ``free``.

        Parameters
        ----------
        p : ndarray, shape (3, n)
            Tool positions (mm) from :meth:`walk`.
        frames : dict
            The ``frames`` of that walk, which recorded at least the rows :meth:`moving_rows` gives for ``free``.
        free : sequence of int, length F
            0-based joints, in the order of the Jacobian's columns.
        angular : bool
            The orientation's Jacobian instead: the axes the joints turn the tool about, rad per degree
            (zero for a slide).

        Returns
        -------
        ndarray, shape (F, 3, n)
            ``d p / d q`` in mm per degree (mm per mm for a slide), base frame. Sums run in a fixed order,
            elementwise in the poses: a pose gets the same bits alone or in any batch (batched path IK
            relies on it).
        """
        moving, plan = self._jacobian_plan(tuple(int(j) for j in free))
        jac = np.zeros((len(free), 3, p.shape[1]))
        if not moving:
            return jac
        z = np.stack([frames[r][0] for r in moving])               # (M, 3, n) axes
        if angular:
            cross = z * (np.pi / 180.0)
        else:
            lever = p[None] - np.stack([frames[r][1] for r in moving])  # (M, 3, n) origin -> tool
            cross = z[:, _I1] * lever[:, _I2]
            cross -= z[:, _I2] * lever[:, _I1]
            cross *= np.pi / 180.0
        for k, r in enumerate(moving):              # a sliding row moves the tool along its axis (mm per mm)
            if self._rows[r].slide:
                cross[k] = 0.0 if angular else z[k]
        for k, f, c in plan:                                       # column f += c * (row k's contribution)
            if c == 1.0:
                jac[f] += cross[k]
            elif c == -1.0:
                jac[f] -= cross[k]
            else:
                jac[f] += c * cross[k]
        return jac

    def _jacobian_plan(self, free: tuple) -> tuple[list[int], list[tuple[int, int, float]]]:
        """The moving rows for the joints ``free`` and ``(row, column, coefficient)`` of each sum (cached)."""
        plan = self._plans.get(free)
        if plan is None:
            where = {j: f for f, j in enumerate(free)}
            moving = self.moving_rows(free)
            plan = self._plans[free] = (moving, [(k, where[j], c) for k, r in enumerate(moving)
                                                 for j, c in self._rows[r].terms if j in where])
        return plan

    @functools.cached_property
    def _plans(self) -> dict:
        return {}

    def parameter_jacobian(self, q_deg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Tool positions and their derivatives by the geometric parameters.

        Returns
        -------
        positions : ndarray, shape (n, 3)
            mm.
        jacobian : ndarray, shape (n, 3, 4 R + 3)
            ``d p / d (theta_offset, d, a, alpha)`` of every DH row (four
            columns per row, in that order; mm per degree for the angles, mm
            per mm for the lengths), then ``d p / d tool_mm`` (three columns).
            A row's theta offset turns everything after it about the row's z
            axis; its alpha turns about the row's new x axis at the end of its
            DH part (before its transform ``E``, if any).
        """
        p, rot, (origins, xs, zs, mids) = self._chain(self.check_joints(q_deg), keep_axes=True)
        rows = self.alpha_deg.size
        out = np.empty((p.shape[0], 3, 4 * rows + 3))
        to_rad = np.pi / 180.0
        for r in range(rows):
            mid_origin, mid_x = mids[r]
            out[:, :, 4 * r] = np.cross(zs[r], p - origins[r]) * to_rad
            out[:, :, 4 * r + 1] = zs[r]
            out[:, :, 4 * r + 2] = mid_x
            out[:, :, 4 * r + 3] = np.cross(mid_x, p - mid_origin) * to_rad
        out[:, :, 4 * rows:] = rot
        return p, out


    # ------------------------------------------------------------------ inverse
    def inverse(
        self, targets_mm, seeds_deg=None, *, fixed=(), tol_mm: float = 1e-8, max_iter: int = 100,
        max_step_deg: float = 10.0, damping: float = 0.05,
    ) -> "IKResult":
        """Position inverse kinematics by damped least squares, all targets at once.

        Parameters
        ----------
        targets_mm : array-like, shape (n, 3)
        seeds_deg : array-like, shape (n, N) or (N,), optional
            Starting joint angles; default the robot's home pose. Fixed joints
            keep their seed value.
        fixed : sequence of int
            1-based joints that must not move (e.g. ``(4, 5)``).
        tol_mm : float
            A target counts as reached when the position error is below this.

        Returns
        -------
        IKResult
            With ``q_deg`` (n, N), ``error_mm`` (n,) and ``success`` (n,).
            Redundant joints move by minimum-norm steps from the seed, so a
            warm start keeps a path on one branch. Each target's result does
            not depend on the others in the batch.
        """
        targets = check_array(targets_mm, "targets_mm", columns=3)
        n = targets.shape[0]
        seeds = self.home_deg if seeds_deg is None else seeds_deg
        q = np.array(np.broadcast_to(np.asarray(seeds, dtype=float), (n, self.n_joints)))
        q = self.check_joints(q, "seeds_deg")
        free = self.free_joints(fixed)
        q = ik.solve(self, targets, q, free, ik.Settings(tol_mm, max_iter, max_step_deg, damping))[0]
        dist = np.linalg.norm(targets - self.positions_validated(q), axis=1)
        return IKResult(q_deg=q, error_mm=dist, success=(dist <= tol_mm) & self.within_limits(q))

    def inverse_pose(
        self, poses, seeds_deg=None, *, fixed=(), tol_mm: float = 1e-8, tol_deg: float = 1e-8,
        length_mm: float = 1000.0, max_iter: int = 100, max_step_deg: float = 10.0, damping: float = 0.05,
    ) -> "IKResult":
        """Full-pose (position and orientation) inverse kinematics by damped least squares, all at once.

        Parameters
        ----------
        poses : array-like, shape (n, 4, 4)
            Tool poses as homogeneous transforms (mm), as :meth:`forward` gives.
        seeds_deg, fixed, max_iter, max_step_deg, damping
            As for :meth:`inverse`.
        tol_mm, tol_deg : float
            A pose counts as reached when its position error is below
            ``tol_mm`` and its orientation error (the angle of the rotation
            between the reached and the wanted orientation) below ``tol_deg``.
        length_mm : float
            How a step weighs orientation against position: one radian of
            orientation error counts as ``length_mm`` mm (about the arm's reach).

        Returns
        -------
        IKResult
            With ``q_deg``, ``error_mm``, ``error_deg`` and ``success``. A
            robot with fewer than six free joints reaches only some poses; the
            others end at the least-squares compromise and are not a success.
        """
        poses = checked_poses(poses)
        q, free = self.checked_seeds(seeds_deg, len(poses)), self.free_joints(fixed)
        settings = ik_settings(tol_mm, max_iter, max_step_deg, damping, tol_deg=tol_deg, length_mm=length_mm)
        q = ik.solve_pose(self, poses[:, :3, 3], poses[:, :3, :3], q, free, settings, tol_deg, length_mm)[0]
        error_mm, error_deg = pose_errors(self.forward(q), poses)
        return IKResult(q_deg=q, error_mm=error_mm, error_deg=error_deg,
                        success=(error_mm <= tol_mm) & (error_deg <= tol_deg) & self.within_limits(q))

    def free_joints(self, fixed) -> NDArray[np.intp]:
        """The 0-based joints that move, ``(F,)`` ascending, when the 1-based joints ``fixed`` are held.

        Raises
        ------
        DataError
            A ``fixed`` entry that is not a joint number, or ``fixed`` holding every joint.
        """
        bad = [j for j in fixed if not (isinstance(j, (int, np.integer)) and 1 <= j <= self.n_joints)]
        if bad:
            raise DataError(f"fixed joints must be in 1..{self.n_joints}; got {bad[0]!r}")
        free = np.array([j for j in range(self.n_joints) if j + 1 not in set(fixed)], dtype=np.intp)
        if free.size == 0:
            raise DataError(f"fixed holds every joint of {self.name} (1..{self.n_joints}): nothing is left to move")
        return free

    def checked_seeds(self, seeds_deg, n: int) -> NDArray[np.float64]:
        """IK seeds ``(n, N)`` degrees for ``n`` targets from ``seeds_deg``: one seed ``(N,)`` or ``(1, N)``
        for all, one per target ``(n, N)``, or None (the home pose); checked finite, a bad shape refused."""
        seeds = np.asarray(self.home_deg if seeds_deg is None else seeds_deg, dtype=float)
        if seeds.shape not in ((self.n_joints,), (1, self.n_joints), (n, self.n_joints)):
            raise DataError(f"Expected seeds_deg with shape ({self.n_joints},) or ({n}, {self.n_joints}) (degrees), "
                            f"got array with shape {seeds.shape}")
        return self.check_joints(np.array(np.broadcast_to(seeds, (n, self.n_joints))), "seeds_deg")

    def inverse_path(self, targets_mm, seed_deg=None, *, fixed=(), tol_mm: float = 1e-8) -> NDArray[np.float64]:
        """Joint angles along a path, each point warm-started from the previous one.

        The result is the sequential one (solve point ``i`` from the solution of
        point ``i - 1``), computed for all points at once: batched damped least
        squares, corrected along the redundant joints' self-motion until the
        chain is consistent, then sequential steps only where it is not (see
        :func:`partcal.robot.ik.solve_path`).

        Raises
        ------
        UnreachableError
            Naming every target that could not be reached, with its distance.
        """
        targets = check_array(targets_mm, "targets_mm", columns=3, min_rows=1)
        seed = self.check_joints(self.home_deg if seed_deg is None else seed_deg, "seed_deg")[0]
        free = self.free_joints(fixed)
        q = ik.solve_path(self, targets, seed, free, ik.Settings(tol_mm))
        errors = np.linalg.norm(targets - self.positions_validated(q), axis=1)
        ok = (errors <= tol_mm) & self.within_limits(q)
        if not ok.all():
            bad = np.flatnonzero(~ok)
            listed = ", ".join(f"#{i} ({errors[i]:.3g} mm)" for i in bad[:5])
            more = f" and {bad.size - 5} more" if bad.size > 5 else ""
            raise UnreachableError(
                f"{self.name}: {bad.size} of {targets.shape[0]} targets unreachable within the joint "
                f"limits: {listed}{more}", bad.tolist(), errors[bad].tolist())
        return q


@dataclass(frozen=True)
class _Row:
    """One DH row compiled for the walk: ``theta = offset + sum(c * q[j])`` degrees."""

    offset: float
    terms: tuple
    ca: float
    sa: float
    a: float
    d: float
    origin: tuple | None = None       # E: (rotation rows, translation mm), None for the identity
    slide: bool = False               # a prismatic row: d = d + sum(c * q[j]) mm, theta = offset


def _apply_origin(origin: tuple, w, z, p):
    """A row's transform ``E`` on a frame kept as ``w = x + i y`` and ``z`` (3, n or 1): shifts ``p`` (3, n) in
    place by ``E``'s translation along the frame's axes and returns the turned ``(w, z)``."""
    (r0, r1, r2), t = origin
    x, y = w.real, w.imag
    if any(t):
        p += t[0] * x + t[1] * y + t[2] * z
    out = np.empty(np.broadcast_shapes(x.shape, np.shape(z)), dtype=complex)
    out.real = r0[0] * x + r1[0] * y + r2[0] * z         # the new axis k is sum_j R[j, k] * axis_j
    out.imag = r0[1] * x + r1[1] * y + r2[1] * z
    return out, r0[2] * x + r1[2] * y + r2[2] * z


def _theta(row: _Row, qT: NDArray[np.float64], out: NDArray[np.float64]) -> NDArray[np.float64]:
    """The row's joint angle in degrees for joints ``qT`` (N, n), into ``out`` (n,), summed in a fixed order."""
    return _linear(row.terms, row.offset, qT, out)


def _linear(terms: tuple, constant: float, qT: NDArray[np.float64], out: NDArray[np.float64]) -> NDArray[np.float64]:
    """``constant + sum(c * q[j])`` over ``terms`` for joints ``qT`` (N, n), into ``out`` (n,), in a fixed order."""
    j, c = terms[0]
    np.multiply(qT[j], c, out=out)
    for j, c in terms[1:]:
        if c == 1.0:
            out += qT[j]
        elif c == -1.0:
            out -= qT[j]
        else:
            out += c * qT[j]
    if constant:
        out += constant
    return out


def _rotors(theta_deg: NDArray[np.float64]) -> NDArray[np.complex128]:
    """``exp(-i theta)`` for angles in degrees, from ``t = tan(theta / 2)``.

    ``cos = (1 - t^2) / (1 + t^2)``, ``sin = 2 t / (1 + t^2)``: numpy vectorises
    ``tan`` for float64 but not ``sin`` and ``cos``, so this is about 4 times
    faster, to a few units in the last place.
    """
    t = np.multiply(theta_deg, np.pi / 360.0)
    np.tan(t, out=t)
    inv = t * t
    out = np.empty(t.shape, dtype=complex)
    np.subtract(1.0, inv, out=out.real)
    inv += 1.0
    np.divide(1.0, inv, out=inv)
    out.real *= inv
    inv *= -2.0
    np.multiply(t, inv, out=out.imag)
    return out


@dataclass(frozen=True)
class IKResult:
    """Outcome of :meth:`Robot.inverse` (and :meth:`Robot.inverse_pose`, which also gives the orientation
    error ``error_deg``): angles, remaining error and success per target."""

    q_deg: NDArray[np.float64]
    error_mm: NDArray[np.float64]
    success: NDArray[np.bool_]
    error_deg: NDArray[np.float64] | None = None


def checked_poses(poses) -> NDArray[np.float64]:
    """Tool poses ``(n, 4, 4)`` as homogeneous transforms (mm), their rotations made exactly orthonormal.

    A rotation block may be off orthonormal by 1e-4 (the rounding of a file
    with six decimals); it is replaced by the nearest rotation. Anything else
    is refused, naming the first bad pose and what was wrong with it.
    """
    poses = np.array(poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4) or len(poses) == 0:
        raise DataError(f"Expected poses with shape (n, 4, 4), n >= 1 (homogeneous transforms, mm), got array with "
                        f"shape {poses.shape}")
    rotations = poses[:, :3, :3]
    with np.errstate(invalid="ignore"):
        off = np.abs(rotations @ rotations.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(np.nan_to_num(rotations))
    problems = [(~np.isfinite(poses).all(axis=(1, 2)), "has a non-finite entry"),
                (np.abs(poses[:, 3] - [0.0, 0.0, 0.0, 1.0]).max(axis=1) > 0, "has a last row other than [0, 0, 0, 1]"),
                (~(off <= 1e-4), "has a rotation block that is not orthonormal"), (det <= 0, "has a rotation block "
                                                                                          "that mirrors (det < 0)")]
    for bad, what in problems:
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise DataError(f"poses[{k}] {what}: expected a rotation (orthonormal to 1e-4, determinant +1) and a "
                            f"position; got {np.round(poses[k], 6).tolist()} (largest deviation of R R^T from I: "
                            f"{off[k]:.3g})")
    u, _, vt = np.linalg.svd(rotations)
    poses[:, :3, :3] = u @ vt
    return poses


def ik_settings(tol_mm, max_iter, max_step_deg, damping, *, tol_deg=0.0, length_mm=1.0) -> "ik.Settings":
    """IK settings, each checked: tolerances >= 0, ``max_iter`` an int >= 1, steps, damping and the orientation
    length > 0 (all finite)."""
    rules = [("tol_mm", tol_mm, 0.0, True), ("tol_deg", tol_deg, 0.0, True), ("max_step_deg", max_step_deg, 0.0, False),
             ("damping", damping, 0.0, False), ("length_mm", length_mm, 0.0, False)]
    for name, value, low, inclusive in rules:
        ok = isinstance(value, (int, float, np.integer, np.floating)) and np.isfinite(value) and \
            (value >= low if inclusive else value > low)
        if not ok:
            raise DataError(f"{name} must be a finite number {'>=' if inclusive else '>'} {low:g}; got {value!r}")
    if not isinstance(max_iter, (int, np.integer)) or isinstance(max_iter, bool) or max_iter < 1:
        raise DataError(f"max_iter must be an int >= 1; got {max_iter!r}")
    return ik.Settings(float(tol_mm), int(max_iter), float(max_step_deg), float(damping))


def flange_offset(base_T_flange: NDArray[np.float64], points_mm: NDArray[np.float64]) -> NDArray[np.float64]:
    """The offset in the flange frame (3,) mm that best puts the tool on ``points_mm`` (n, 3, base frame) from
    flange poses ``base_T_flange`` ``(n, 4, 4)``: the mean over the poses of ``R^T (p - o)``."""
    return np.einsum("nji,nj->i", base_T_flange[:, :3, :3], points_mm - base_T_flange[:, :3, 3]) / len(points_mm)


def pose_errors(reached: NDArray[np.float64], wanted: NDArray[np.float64]
                ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position error (mm) and orientation error (deg: the angle of ``R_wanted R_reached^T``) of poses
    ``(n, 4, 4)``, each shape (n,)."""
    dist = np.linalg.norm(wanted[:, :3, 3] - reached[:, :3, 3], axis=1)
    return dist, np.degrees(np.linalg.norm(rotation_vectors_from_matrices(wanted[:, :3, :3] @ reached[:, :3, :3]
                                                               .transpose(0, 2, 1)), axis=1))
