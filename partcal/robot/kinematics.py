"""Robot kinematics: Denavit-Hartenberg chains with coupled (parallelogram) joints.

A robot is a chain of standard DH rows, ``T = Rz(theta) Tz(d) Tx(a) Rx(alpha)``,
followed by a tool offset. Each row's ``theta`` is a *linear expression* of the
joint angles, such as ``q1`` or ``180 - q2 + q3``; that is enough to describe
closed-chain mechanisms whose passive angles follow the actuated ones, like the
parallelogram (five-bar) of the Motoman SK120 in the paper's Table 1.

Everything is batched: joint angles come in as ``(n, N)`` arrays in degrees,
positions go out as ``(n, 3)`` arrays in mm. Radians live only inside.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from .._yamlio import load_yaml
from ..errors import ConfigError, DataError, UnreachableError
from . import ik

MAX_JOINTS = 12
_CHUNK = 8192
_I1, _I2 = [1, 2, 0], [2, 0, 1]          # cross product: (a x b)_k = a_{k+1} b_{k+2} - a_{k+2} b_{k+1}
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


def _cos_sin_deg(angle_deg: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """cos and sin of angles in degrees, exact (0 or +-1) at multiples of 90 degrees."""
    rad = np.radians(angle_deg)
    c, s = np.cos(rad), np.sin(rad)
    rest = np.mod(angle_deg, 90.0)      # exact multiples only: a twist of -90.0005 is not -90
    right = (np.abs(rest) <= 1e-12) | (np.abs(rest - 90.0) <= 1e-12)
    c[right], s[right] = np.round(c[right]), np.round(s[right])
    return c, s


@dataclass(frozen=True, eq=False)
class Robot:
    """A serial chain of standard DH rows, possibly with coupled joints.

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

        >>> round(load_robot("motoman_sk120").reach_mm, 2)
        4413.19
        """
        return float(np.hypot(self.a_mm, self.d_mm).sum() + np.linalg.norm(self.tool_mm))

    def within_limits(self, q_deg: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which poses respect the joint limits and the coupled constraints, shape (n,)."""
        ok = np.all((q_deg >= self.limits_deg[:, 0]) & (q_deg <= self.limits_deg[:, 1]), axis=1)
        for coeffs, low, high in self.constraints:
            v = q_deg @ coeffs
            ok &= (v >= low) & (v <= high)
        return ok

    # ------------------------------------------------------------------ kinematics
    @functools.cached_property
    def _rows(self) -> tuple["_Row", ...]:
        """The DH rows compiled for the walk (built once per robot)."""
        ca, sa = _cos_sin_deg(self.alpha_deg)
        return tuple(_Row(float(off), tuple((int(j), float(c)) for j, c in enumerate(coef) if c),
                          float(ca[r]), float(sa[r]), float(self.a_mm[r]), float(self.d_mm[r]))
                     for r, (off, coef) in enumerate(zip(self.theta_offset_deg, self.coupling)))

    def _trig(self, qT: NDArray[np.float64], rows=None) -> list:
        """The rotor ``exp(-i theta)`` of each DH row (all, or those in ``rows``), for joints ``qT`` (N, n).

        Constant rows give a Python complex, rows not asked for ``None``. Every
        operation is elementwise in the poses, so a pose gets the same bits
        alone or in any batch.
        """
        out: list = [None] * len(self._rows)
        varying = []
        for r, row in enumerate(self._rows):
            if rows is not None and r not in rows:
                continue
            if row.terms:
                varying.append(r)
            else:
                rad = np.radians(row.offset)
                out[r] = complex(np.cos(rad), -np.sin(rad))
        if varying:
            theta = np.empty((len(varying), qT.shape[1]))
            for k, r in enumerate(varying):
                _theta(self._rows[r], qT, out=theta[k])
            rotors = _rotors(theta)                    # one call for all rows
            for k, r in enumerate(varying):
                out[r] = rotors[k]
        return out

    def _walk(self, trig: list, record=()) -> tuple:
        """Walk the chain for the rows' rotors; return the tool position and frames.

        A frame is kept as ``w = x + i y`` (3, n) complex and ``z`` (3, n): the
        turn by ``theta`` about ``z`` is one complex product, ``w exp(-i theta)``.
        Vectors are ``(3, n)``, so every operation runs over contiguous runs of
        ``n`` values. Returns ``p`` (3, n), the last frame's axes ``(x, y, z)``
        and, for each row in ``record``, the axis ``z`` and origin ``o`` (3, n)
        it turns about.
        """
        n = next((e.shape[-1] for e in trig if isinstance(e, np.ndarray)), 1)
        base = self.base_rotation
        w = (base[:, 0] + 1j * base[:, 1])[:, None]                      # (3, 1): broadcast at first
        z = base[:, 2][:, None]
        p = np.repeat(self.base_mm[:, None], n, axis=1)
        frames = {}
        for r, (row, e) in enumerate(zip(self._rows, trig)):
            if r in record:
                frames[r] = (z if z.shape == p.shape else np.repeat(z, n, axis=1), p.copy())
            w = w * e                                  # x' = c x + s y, y' = c y - s x
            if row.a:
                p += row.a * w.real
            if row.d:
                p += row.d * z
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
        if len(self._rows) in record:
            frames[len(self._rows)] = (z if z.shape == p.shape else np.repeat(z, n, axis=1), p.copy())
        p += self.tool_mm[0] * w.real + self.tool_mm[1] * w.imag + self.tool_mm[2] * z
        return p, (w.real, w.imag, z), frames

    def _chain(self, q_deg: NDArray[np.float64], keep_axes: bool = False):
        """The straightforward walk (x, y, z axes of every frame), for :meth:`parameter_jacobian`.

        Returns tool positions, orientations and optionally the frames.

        With ``keep_axes`` the third value is ``(origins, x_axes, z_axes)``,
        three lists of ``R + 1`` arrays ``(n, 3)`` (frame 0 is the base);
        otherwise None. Internally vectors are ``(3, n)`` so every operation
        runs over contiguous runs of ``n`` values (about twice as fast as ``(n, 3)``).
        """
        n = q_deg.shape[0]
        theta = np.radians(self.theta_offset_deg[:, None] + self.coupling @ q_deg.T)  # (R, n)
        cos_t, sin_t = np.cos(theta), np.sin(theta)
        ca, sa = _cos_sin_deg(self.alpha_deg)
        r0, r1, r2 = (np.repeat(self.base_rotation[:, k, None], n, axis=1) for k in range(3))
        p = np.repeat(self.base_mm[:, None], n, axis=1)
        origins, xs, zs = [], [], []
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
            if sa[row] == 0.0:  # alpha = 0 or 180: exact, and saves half the work of this row
                r0, r1, r2 = x_new, ca[row] * y_rot, ca[row] * r2
            elif ca[row] == 0.0:  # alpha = +-90
                r0, r1, r2 = x_new, sa[row] * r2, -sa[row] * y_rot
            else:
                r0, r1, r2 = x_new, ca[row] * y_rot + sa[row] * r2, ca[row] * r2 - sa[row] * y_rot
        if keep_axes:
            origins.append(p.T.copy())
            xs.append(r0.T)
            zs.append(r2.T)
        p += self.tool_mm[0] * r0 + self.tool_mm[1] * r1 + self.tool_mm[2] * r2
        frames = (origins, xs, zs) if keep_axes else None
        return p.T, np.stack([r0.T, r1.T, r2.T], axis=-1), frames

    def frames(self, q_deg) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Origins and z axes of the DH frames 0..R, each of shape ``(n, R + 1, 3)``.

        Frame 0 is the first DH frame (the base); frame ``k`` follows row ``k``.
        """
        qT = self.check_joints(q_deg).T
        _, _, frames = self._walk(self._trig(qT), record=range(len(self._rows) + 1))
        keys = sorted(frames)
        return (np.stack([frames[k][1].T for k in keys], axis=1), np.stack([frames[k][0].T for k in keys], axis=1))

    def positions(self, q_deg) -> NDArray[np.float64]:
        """Tool positions, shape ``(n, 3)`` mm, for joint angles ``(n, N)`` degrees.

        Examples
        --------
        >>> robot = load_robot("motoman_sk120")
        >>> robot.positions([[0, -90, -180, 0, 0, 0]]).round(2).tolist()
        [[1857.65, 0.0, 1555.32]]
        """
        return self._positions(self.check_joints(q_deg))

    def _positions(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """:meth:`positions` on validated joints (n, N), in cache-sized blocks."""
        out = np.empty((q.shape[0], 3))
        for start in range(0, q.shape[0], _CHUNK):  # cache-sized blocks: ~2x faster on big batches
            qT = q[start:start + _CHUNK].T
            out[start:start + _CHUNK] = self._walk(self._trig(qT))[0].T
        return out

    def forward(self, q_deg) -> NDArray[np.float64]:
        """Tool poses as homogeneous transforms, shape ``(n, 4, 4)`` (mm)."""
        q = self.check_joints(q_deg)
        p, axes, _ = self._walk(self._trig(q.T))
        out = np.zeros((q.shape[0], 4, 4))
        n = q.shape[0]      # an axis that no joint turns (a planar arm's z) comes back as one column
        out[:, :3, :3] = np.stack([np.broadcast_to(a, (3, n)).T for a in axes], axis=-1)
        out[:, :3, 3] = p.T
        out[:, 3, 3] = 1.0
        return out

    def jacobian(self, q_deg) -> NDArray[np.float64]:
        """Position Jacobian ``d p / d q``, shape ``(n, 3, N)``, in mm per degree.

        Each DH row contributes ``z x (p - o)`` for its rotation axis ``z`` and
        origin ``o``; rows coupled to several joints add up through the
        coupling matrix.
        """
        qT = self.check_joints(q_deg).T
        _, jac = self._position_jacobian(self._trig(qT), np.arange(self.n_joints))
        return jac.transpose(2, 1, 0)

    def _position_jacobian(self, trig: list, free: NDArray[np.intp]):
        """Tool position (3, n) mm and Jacobian ``(F, 3, n)`` mm/deg for the joints ``free``."""
        moving = self._moving(free)
        p, _, frames = self._walk(trig, record=moving)
        return p, self._jacobian(p, frames, free)

    def _moving(self, free) -> list[int]:
        """The DH rows that some joint in ``free`` turns."""
        free = {int(j) for j in free}
        return [r for r, row in enumerate(self._rows) if any(j in free for j, _ in row.terms)]

    def _jacobian(self, p: NDArray[np.float64], frames: dict, free) -> NDArray[np.float64]:
        """The Jacobian ``(F, 3, n)`` mm/deg from a walk that recorded the rows :meth:`_moving` gives.

        Sums run in a fixed order, elementwise in the poses: a pose gets the
        same bits alone or in any batch (batched path IK relies on it).
        """
        moving, plan = self._jacobian_plan(tuple(int(j) for j in free))
        jac = np.zeros((len(free), 3, p.shape[1]))
        if not moving:
            return jac
        z = np.stack([frames[r][0] for r in moving])               # (M, 3, n) axes
        lever = p[None] - np.stack([frames[r][1] for r in moving])  # (M, 3, n) origin -> tool
        cross = z[:, _I1] * lever[:, _I2]
        cross -= z[:, _I2] * lever[:, _I1]
        cross *= np.pi / 180.0
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
            moving = self._moving(free)
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
            axis; its alpha turns about the row's new x axis at the row's end.
        """
        p, rot, (origins, xs, zs) = self._chain(self.check_joints(q_deg), keep_axes=True)
        rows = self.alpha_deg.size
        out = np.empty((p.shape[0], 3, 4 * rows + 3))
        to_rad = np.pi / 180.0
        for r in range(rows):
            out[:, :, 4 * r] = np.cross(zs[r], p - origins[r]) * to_rad
            out[:, :, 4 * r + 1] = zs[r]
            out[:, :, 4 * r + 2] = xs[r + 1]
            out[:, :, 4 * r + 3] = np.cross(xs[r + 1], p - origins[r + 1]) * to_rad
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
        free = self._free_joints(fixed)
        q = ik.solve(self, targets, q, free, ik.Settings(tol_mm, max_iter, max_step_deg, damping))[0]
        dist = np.linalg.norm(targets - self._positions(q), axis=1)
        return IKResult(q_deg=q, error_mm=dist, success=(dist <= tol_mm) & self.within_limits(q))

    def _free_joints(self, fixed) -> NDArray[np.intp]:
        bad = [j for j in fixed if not (isinstance(j, (int, np.integer)) and 1 <= j <= self.n_joints)]
        if bad:
            raise DataError(f"fixed joints must be in 1..{self.n_joints}; got {bad[0]!r}")
        return np.array([j for j in range(self.n_joints) if j + 1 not in set(fixed)], dtype=np.intp)

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
        free = self._free_joints(fixed)
        q = ik.solve_path(self, targets, seed, free, ik.Settings(tol_mm))
        errors = np.linalg.norm(targets - self._positions(q), axis=1)
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


def _theta(row: _Row, qT: NDArray[np.float64], out: NDArray[np.float64]) -> NDArray[np.float64]:
    """The row's joint angle in degrees for joints ``qT`` (N, n), into ``out`` (n,), summed in a fixed order."""
    j, c = row.terms[0]
    np.multiply(qT[j], c, out=out)
    for j, c in row.terms[1:]:
        if c == 1.0:
            out += qT[j]
        elif c == -1.0:
            out -= qT[j]
        else:
            out += c * qT[j]
    if row.offset:
        out += row.offset
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
    """Outcome of :meth:`Robot.inverse`: angles, remaining error and success per target."""

    q_deg: NDArray[np.float64]
    error_mm: NDArray[np.float64]
    success: NDArray[np.bool_]


# ---------------------------------------------------------------------- YAML
def available_robots() -> list[str]:
    """Names of the built-in robots."""
    return sorted(p.stem for p in _BUILTIN_DIR.glob("*.yaml"))


def load_robot(name_or_path: str | Path | Robot) -> Robot:
    """Load a built-in robot by name, or a robot YAML file by path.

    >>> load_robot("motoman_sk120").n_joints
    6
    """
    if isinstance(name_or_path, Robot):
        return name_or_path
    text = str(name_or_path)
    path = Path(text)
    if not path.suffix and (_BUILTIN_DIR / f"{text}.yaml").exists():
        path = _BUILTIN_DIR / f"{text}.yaml"
    if not path.is_file():
        raise ConfigError(f"robot {text!r}: no such file, and not a built-in robot "
                          f"(built-ins: {', '.join(available_robots())})")
    spec, lines = load_yaml(path)
    return robot_from_dict(spec, source=str(path), lines=lines)


def robot_reference(name: str, base: Path) -> str:
    """A robot named in a config: a ``.yaml`` path relative to the config's folder, or a built-in name."""
    candidate = base / name
    return str(candidate) if candidate.suffix in (".yaml", ".yml") else name


_ROBOT_KEYS = {"name", "description", "joints", "links", "tool_mm", "limits_deg", "home_deg",
               "constraints_deg"}


def robot_from_dict(spec: dict, source: str = "robot", lines: dict[str, int] | None = None) -> Robot:
    """Build a :class:`Robot` from its YAML mapping (see ``docs/robots.md``).

    ``lines`` (key path -> line, from :func:`partcal._yamlio.load_yaml`) puts
    the line of the bad key into every message.
    """
    lines = lines or {}

    def fail(where: str, msg: str):
        line = lines.get(where)
        raise ConfigError(f"{source}: {where}{f' (line {line})' if line else ''}: {msg}")

    def number(where: str, value) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or abs(value) > 1e300:
            fail(where, f"must be a finite number; got {value!r}")
        return float(value)

    def numbers(where: str, value, shape: tuple[int, ...], what: str) -> NDArray[np.float64]:
        arr = np.asarray(value if isinstance(value, list) else [value], dtype=object)
        if arr.shape != shape:
            fail(where, f"expected {what}; got {value!r}")
        for index in np.ndindex(arr.shape):
            at = where + "".join(f"[{k}]" for k in index)
            number(at if at in lines else where, arr[index])
        return arr.astype(float)

    if not isinstance(spec, dict):
        fail("top level", f"expected a mapping, got {type(spec).__name__}")
    unknown = set(spec) - _ROBOT_KEYS
    if unknown:
        fail(sorted(unknown)[0], f"unknown key (allowed: {', '.join(sorted(_ROBOT_KEYS))})")
    for key in ("name", "joints", "links", "limits_deg"):
        if key not in spec:
            fail(key, "missing")
    n = spec["joints"]
    if not isinstance(n, int) or not 1 <= n <= MAX_JOINTS:
        fail("joints", f"must be an int in [1, {MAX_JOINTS}]; got {n!r}")
    for key, kind in (("links", list), ("constraints_deg", (list, type(None)))):
        if not isinstance(spec.get(key), kind):
            fail(key, f"expected a list; got {spec.get(key)!r}"[:200])
    rows = []
    for i, link in enumerate(spec["links"]):
        if not isinstance(link, dict) or set(link) != {"theta", "d", "a", "alpha"}:
            fail(f"links[{i}]", f"expected a mapping with theta, d, a, alpha; got {link!r}")
        try:
            off, coeffs = parse_theta(link["theta"], n)
        except ConfigError as exc:
            fail(f"links[{i}].theta", str(exc))
        rows.append((*(number(f"links[{i}].{key}", link[key]) for key in ("alpha", "d", "a")), off, coeffs))
    if not rows:
        fail("links", "needs at least one DH row")
    coupling = np.array([r[4] for r in rows])
    unused = [f"q{j + 1}" for j in range(n) if not coupling[:, j].any()]
    if unused:
        fail("links", f"joint(s) {', '.join(unused)} appear in no theta expression")
    limits = numbers("limits_deg", spec["limits_deg"], (n, 2), f"{n} pairs [low, high] with low < high")
    if np.any(limits[:, 0] >= limits[:, 1]):
        fail("limits_deg", f"expected {n} pairs [low, high] with low < high; got {spec['limits_deg']!r}")
    home = numbers("home_deg", spec["home_deg"], (n,), f"{n} angles") if "home_deg" in spec else limits.mean(axis=1)
    tool = numbers("tool_mm", spec.get("tool_mm", [0, 0, 0]), (3,), "[x, y, z]")
    constraints = []
    for i, c in enumerate(spec.get("constraints_deg") or []):
        if not isinstance(c, dict) or not isinstance(c.get("range"), list) or len(c["range"]) != 2:
            fail(f"constraints_deg[{i}]", f"expected {{expr: 'q2 - q3', range: [low, high]}}; got {c!r}"[:200])
        try:
            _, coeffs = parse_theta(c["expr"], n)
            low, high = (number(f"constraints_deg[{i}].range", v) for v in c["range"])
        except (KeyError, TypeError, ValueError, ConfigError) as exc:
            fail(f"constraints_deg[{i}]", f"expected {{expr: 'q2 - q3', range: [low, high]}}: {exc}")
        constraints.append((coeffs, low, high))
    alpha, d, a, off = (np.array([r[k] for r in rows]) for k in range(4))
    return Robot(name=str(spec["name"]), n_joints=n, alpha_deg=alpha, d_mm=d, a_mm=a,
                 theta_offset_deg=off, coupling=coupling, tool_mm=tool, limits_deg=limits,
                 home_deg=home, constraints=tuple(constraints))


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
    return {
        "name": robot.name, "joints": robot.n_joints,
        "links": [{"theta": _expression(off, c), "d": float(d), "a": float(a), "alpha": float(al)}
                  for off, c, d, a, al in zip(robot.theta_offset_deg, robot.coupling, robot.d_mm, robot.a_mm,
                                              robot.alpha_deg)],
        "tool_mm": robot.tool_mm.tolist(), "limits_deg": robot.limits_deg.tolist(),
        "home_deg": robot.home_deg.tolist(),
        "constraints_deg": [{"expr": _expression(0.0, c), "range": [lo, hi]} for c, lo, hi in robot.constraints],
    }
