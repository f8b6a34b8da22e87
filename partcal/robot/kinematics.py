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
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import ConfigError, DataError, UnreachableError

MAX_JOINTS = 12
_CHUNK = 4096
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

    def within_limits(self, q_deg: NDArray[np.float64]) -> NDArray[np.bool_]:
        """Which poses respect the joint limits and the coupled constraints, shape (n,)."""
        ok = np.all((q_deg >= self.limits_deg[:, 0]) & (q_deg <= self.limits_deg[:, 1]), axis=1)
        for coeffs, low, high in self.constraints:
            v = q_deg @ coeffs
            ok &= (v >= low) & (v <= high)
        return ok

    # ------------------------------------------------------------------ kinematics
    def _chain(self, q_deg: NDArray[np.float64], keep_axes: bool = False):
        """Walk the chain; return tool positions, orientations and optionally the frames.

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
        origins, _, axes = self._chain(self.check_joints(q_deg), keep_axes=True)[2]
        return np.stack(origins, axis=1), np.stack(axes, axis=1)

    def positions(self, q_deg) -> NDArray[np.float64]:
        """Tool positions, shape ``(n, 3)`` mm, for joint angles ``(n, N)`` degrees.

        Examples
        --------
        >>> robot = load_robot("motoman_sk120")
        >>> robot.positions([[0, -90, -180, 0, 0, 0]]).round(2).tolist()
        [[1857.65, 0.0, 1555.32]]
        """
        q = self.check_joints(q_deg)
        out = np.empty((q.shape[0], 3))
        for start in range(0, q.shape[0], _CHUNK):  # cache-sized blocks: ~2x faster on big batches
            out[start:start + _CHUNK] = self._chain(q[start:start + _CHUNK])[0]
        return out

    def forward(self, q_deg) -> NDArray[np.float64]:
        """Tool poses as homogeneous transforms, shape ``(n, 4, 4)`` (mm)."""
        p, rot, _ = self._chain(self.check_joints(q_deg))
        out = np.zeros((p.shape[0], 4, 4))
        out[:, :3, :3] = rot
        out[:, :3, 3] = p
        out[:, 3, 3] = 1.0
        return out

    def jacobian(self, q_deg) -> NDArray[np.float64]:
        """Position Jacobian ``d p / d q``, shape ``(n, 3, N)``, in mm per degree.

        Each DH row contributes ``z x (p - o)`` for its rotation axis ``z`` and
        origin ``o``; rows coupled to several joints add up through the
        coupling matrix.
        """
        return self._position_and_jacobian(self.check_joints(q_deg))[1]

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

    def _position_and_jacobian(self, q_deg: NDArray[np.float64]):
        p, _, (origins, _, axes) = self._chain(q_deg, keep_axes=True)
        moving = np.flatnonzero(self.coupling.any(axis=1))
        z = np.stack([axes[r] for r in moving], axis=-1)                # (n, 3, M)
        lever = p[:, :, None] - np.stack([origins[r] for r in moving], axis=-1)
        cross = z[:, [1, 2, 0]] * lever[:, [2, 0, 1]] - z[:, [2, 0, 1]] * lever[:, [1, 2, 0]]
        return p, cross @ self.coupling[moving] * (np.pi / 180.0)

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
            warm start keeps a path on one branch.
        """
        targets = check_array(targets_mm, "targets_mm", columns=3)
        n = targets.shape[0]
        seeds = self.home_deg if seeds_deg is None else seeds_deg
        q = np.array(np.broadcast_to(np.asarray(seeds, dtype=float), (n, self.n_joints)))
        q = self.check_joints(q, "seeds_deg")
        free = self._free_joints(fixed)
        q = self._solve(targets, q, free, tol_mm, max_iter, max_step_deg, damping)
        dist = np.linalg.norm(targets - self._chain(q)[0], axis=1)
        return IKResult(q_deg=q, error_mm=dist, success=(dist <= tol_mm) & self.within_limits(q))

    def _free_joints(self, fixed) -> NDArray[np.intp]:
        bad = [j for j in fixed if not (isinstance(j, (int, np.integer)) and 1 <= j <= self.n_joints)]
        if bad:
            raise DataError(f"fixed joints must be in 1..{self.n_joints}; got {bad[0]!r}")
        return np.array([j for j in range(self.n_joints) if j + 1 not in set(fixed)], dtype=np.intp)

    def _solve(self, targets, q, free, tol_mm, max_iter, max_step_deg, damping):
        """Damped least-squares iterations on validated arrays (the hot loop)."""
        lo, hi = self.limits_deg[free, 0], self.limits_deg[free, 1]
        active = np.arange(targets.shape[0])
        for _ in range(max_iter):
            p, jac = self._position_and_jacobian(q[active])
            err = targets[active] - p
            keep = np.einsum("ij,ij->i", err, err) > tol_mm**2
            if not keep.any():
                break
            active, err, jac = active[keep], err[keep], jac[keep][:, :, free]
            jjt = jac @ jac.transpose(0, 2, 1) + damping**2 * np.eye(3)
            step = (jac.transpose(0, 2, 1) @ np.linalg.solve(jjt, err[:, :, None]))[:, :, 0]
            biggest = np.abs(step).max(axis=1, keepdims=True)
            step *= np.minimum(1.0, max_step_deg / np.maximum(biggest, 1e-300))
            q_act = q[active]
            q_act[:, free] = np.clip(q_act[:, free] + step, lo, hi)
            q[active] = q_act
        return q

    def inverse_path(self, targets_mm, seed_deg=None, *, fixed=(), tol_mm: float = 1e-8) -> NDArray[np.float64]:
        """Joint angles along a path, each point warm-started from the previous one.

        Raises
        ------
        UnreachableError
            Naming every target that could not be reached, with its distance.
        """
        targets = check_array(targets_mm, "targets_mm", columns=3, min_rows=1)
        q = np.empty((targets.shape[0], self.n_joints))
        seed = self.check_joints(self.home_deg if seed_deg is None else seed_deg, "seed_deg")[0]
        free = self._free_joints(fixed)
        for i in range(targets.shape[0]):
            seed = q[i] = self._solve(targets[i:i + 1], seed[None].copy(), free, tol_mm, 100, 10.0, 0.05)[0]
        errors = np.linalg.norm(targets - self._chain(q)[0], axis=1)
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
    try:
        spec = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML: {exc}") from None
    return robot_from_dict(spec, source=str(path))


def robot_reference(name: str, base: Path) -> str:
    """A robot named in a config: a ``.yaml`` path relative to the config's folder, or a built-in name."""
    candidate = base / name
    return str(candidate) if candidate.suffix in (".yaml", ".yml") else name


_ROBOT_KEYS = {"name", "description", "joints", "links", "tool_mm", "limits_deg", "home_deg",
               "constraints_deg"}


def robot_from_dict(spec: dict, source: str = "robot") -> Robot:
    """Build a :class:`Robot` from its YAML mapping (see ``docs/robots.md``)."""
    def fail(where: str, msg: str):
        raise ConfigError(f"{source}: {where}: {msg}")

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
    rows = []
    for i, link in enumerate(spec["links"] or []):
        if not isinstance(link, dict) or set(link) != {"theta", "d", "a", "alpha"}:
            fail(f"links[{i}]", f"expected a mapping with theta, d, a, alpha; got {link!r}")
        try:
            off, coeffs = parse_theta(link["theta"], n)
        except ConfigError as exc:
            fail(f"links[{i}].theta", str(exc))
        rows.append((float(link["alpha"]), float(link["d"]), float(link["a"]), off, coeffs))
    if not rows:
        fail("links", "needs at least one DH row")
    coupling = np.array([r[4] for r in rows])
    unused = [f"q{j + 1}" for j in range(n) if not coupling[:, j].any()]
    if unused:
        fail("links", f"joint(s) {', '.join(unused)} appear in no theta expression")
    limits = np.asarray(spec["limits_deg"], dtype=float)
    if limits.shape != (n, 2) or np.any(limits[:, 0] >= limits[:, 1]):
        fail("limits_deg", f"expected {n} pairs [low, high] with low < high; got {spec['limits_deg']!r}")
    home = np.asarray(spec.get("home_deg", limits.mean(axis=1)), dtype=float)
    if home.shape != (n,):
        fail("home_deg", f"expected {n} angles; got {spec.get('home_deg')!r}")
    tool = np.asarray(spec.get("tool_mm", [0, 0, 0]), dtype=float)
    if tool.shape != (3,):
        fail("tool_mm", f"expected [x, y, z]; got {spec.get('tool_mm')!r}")
    constraints = []
    for i, c in enumerate(spec.get("constraints_deg") or []):
        try:
            _, coeffs = parse_theta(c["expr"], n)
            low, high = (float(v) for v in c["range"])
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
