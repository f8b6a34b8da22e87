"""The virtual robot's contact measurements: plane touches, fixed-point visits and distances.

Each is generated on the TRUE robot (``VirtualRobot.true`` with its base error, tool and the joints'
compliance and gear errors): the joints returned are what the robot was commanded, and the true tool
tip lies on the true plane or point up to the stated noise. Plain functions on a
:class:`~partcal.data.simulate.VirtualRobot` (passed in, not imported: the simulation imports this
module), for ``partcal simulate`` (:mod:`partcal.data.contact_sets`) and benchmarks. See
``docs/virtual_robot.md``, "Contact data".
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError, UnreachableError
from ..robot.kinematics import Robot
from ..robot.rotations import matrices_from_rotation_vectors
from .sampling import uniform_configurations

ON_FEATURE_MM = 1e-6
"""How close (besides the stated noise) the true tip lands on its plane or point: rows missing it are dropped."""
NEAR_PLANE_MM, NEAR_POINT_MM = 150.0, 300.0
"""Candidate configurations whose true tip lies this close to the feature are moved onto it."""
ROUNDS = 12
"""Batches of candidates drawn before a feature is declared out of reach."""


def true_robot_in_base(vr) -> Robot:
    """The true robot with the virtual robot's base error folded into its base frame: its positions of the
    ACTUAL joints are the true tool tips in the base frame (``vr.true_positions`` of the commanded ones)."""
    t = vr.true
    return t.replace(base_rotation=vr.base_rotation @ t.base_rotation,
                     base_mm=vr.base_rotation @ t.base_mm + vr.base_mm)


def commanded_joints(vr, q_actual: NDArray[np.float64], q_start: NDArray[np.float64]) -> NDArray[np.float64]:
    """The commanded joints whose actual joints (compliance, gear errors) are ``q_actual`` ``(n, N)`` degrees,
    by fixed-point iteration from ``q_start`` (the errors change slowly with the joints)."""
    q = np.array(q_start, dtype=float)
    for _ in range(50):
        step = q_actual - vr.actual_joints(q)
        q += step
        if np.abs(step).max(initial=0.0) < 1e-12:
            break
    return q


def _newton(vr, tib: Robot, q: NDArray[np.float64], residual, steps: int = 4) -> NDArray[np.float64]:
    """A few minimum-norm Newton steps on the commanded joints: ``residual(tips) -> (values (n, k), rows (n, k, 3))``
    with ``d value / d tip = rows``; the true robot's Jacobian stands for the commanded joints' (the joint
    errors' own slope is small)."""
    q = q.copy()
    for _ in range(steps):
        values, rows = residual(vr.true_positions(q))
        jac = rows @ tib.jacobian(vr.actual_joints(q))               # (n, k, N)
        q -= np.einsum("nik,nk->ni", np.linalg.pinv(jac), values)
    return q


def _solved(vr, tib: Robot, seeds_cmd, targets, rotations=None):
    """Commanded joints putting the true tip on ``targets`` (and the tool z axis as in ``rotations``), and which
    rows the IK reached within the joint limits."""
    qa = vr.actual_joints(seeds_cmd)
    if rotations is None:
        res = tib.inverse(targets, qa, tol_mm=1e-7)
    else:
        poses = np.tile(np.eye(4), (len(targets), 1, 1))
        poses[:, :3, :3], poses[:, :3, 3] = rotations, targets
        res = tib.inverse_pose(poses, qa, tol_mm=1e-7, tol_deg=1e-6)
    q = commanded_joints(vr, res.q_deg, seeds_cmd)
    return q, res.success & vr.nominal.within_limits(q)


def _plane_args(plane) -> tuple[NDArray[np.float64], float]:
    if isinstance(plane, dict):
        normal = np.asarray(plane["normal"], dtype=float)
        return normal / np.linalg.norm(normal), float(plane["offset_mm"])
    normal, offset = plane
    normal = np.asarray(normal, dtype=float)
    return normal / np.linalg.norm(normal), float(offset)


def plane_touches(vr, planes: dict, counts: dict, rng: np.random.Generator, noise_mm: float, *, flush: bool = False,
                  ranges_deg: dict | None = None, fixed_deg: dict | None = None
                  ) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Commanded joints whose TRUE tool tip touches each TRUE plane, ``counts[name]`` times.

    Parameters
    ----------
    vr : VirtualRobot
    planes : dict
        name -> ``(normal (3,), offset_mm)`` or ``{"normal": ..., "offset_mm": ...}``: the plane
        ``n . p = offset`` (base frame, mm; the normal is normalised).
    counts : dict
        name -> number of touches.
    rng : numpy.random.Generator
    noise_mm : float
        Standard deviation of the miss along the normal: the true tip lies ``N(0, noise_mm)`` off the plane.
    flush : bool
        The tool's z axis along the plane's normal (a flat face of the tool on the plane; the sign nearest
        the sampled orientation), else the sampled orientations (changed a little by the move).
    ranges_deg, fixed_deg : dict, optional
        Joint ranges ``{joint: (lo, hi)}`` and held joints ``{joint: deg}`` (1-based) of the samples.

    Returns
    -------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees, within the joint limits; the touches of each plane in turn.
    names : tuple of str, (n,)
        The plane each row touches.

    Raises
    ------
    UnreachableError
        A plane the arm cannot touch ``counts[name]`` times within its ranges (naming the plane).
    """
    _checked(planes, counts, noise_mm, "plane")
    tib, out_q, out_names = true_robot_in_base(vr), [], []
    for name, count in counts.items():
        normal, offset = _plane_args(planes[name])

        def near(tips, qa):
            ok = np.abs(tips @ normal - offset) < NEAR_PLANE_MM
            if flush:               # the tool's face comes down onto the plane: its z axis against the normal
                ok &= tib.forward(qa)[:, :3, 2] @ normal < -np.cos(np.radians(45.0))
            return ok

        def targets(tips, qa, k):
            miss = rng.normal(0.0, noise_mm, k) if noise_mm > 0 else np.zeros(k)
            goal = tips - (tips @ normal - offset - miss)[:, None] * normal
            rot = _flush_rotations(tib.forward(qa)[:, :3, :3], normal) if flush else None
            return goal, rot, miss

        def residual(miss):
            return lambda tips: ((tips @ normal - offset - miss)[:, None], np.broadcast_to(normal, (len(tips), 1, 3)))

        q = _visits(vr, tib, count, near, targets, residual, rng, ranges_deg or {}, fixed_deg or {},
                    f"plane {name!r}")
        out_q.append(q)
        out_names += [name] * count
    return np.concatenate(out_q), tuple(out_names)


def fixed_point_visits(vr, points: dict, counts: dict, rng: np.random.Generator, noise_mm: float, *,
                       ranges_deg: dict | None = None, fixed_deg: dict | None = None
                       ) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Commanded joints bringing the TRUE tool tip to each TRUE point from different orientations.

    ``points``: name -> position (3,) mm (base frame); ``counts``: name -> visits; the true tip lands
    ``N(0, noise_mm)`` off the point per axis. The orientations are those of random configurations near
    the point, each moved onto it. Returns the commanded joints ``(n, N)`` degrees and each row's point;
    an unreachable point raises :class:`~partcal.errors.UnreachableError` naming it. Other parameters as
    :func:`plane_touches`.
    """
    _checked(points, counts, noise_mm, "point")
    tib, out_q, out_names = true_robot_in_base(vr), [], []
    for name, count in counts.items():
        point = np.asarray(points[name], dtype=float)

        def near(tips, qa):
            return np.linalg.norm(tips - point, axis=1) < NEAR_POINT_MM

        def targets(tips, qa, k):
            miss = rng.normal(0.0, noise_mm, (k, 3)) if noise_mm > 0 else np.zeros((k, 3))
            return point + miss, None, miss

        def residual(miss):
            return lambda tips: (tips - point - miss, np.broadcast_to(np.eye(3), (len(tips), 3, 3)))

        q = _visits(vr, tib, count, near, targets, residual, rng, ranges_deg or {}, fixed_deg or {},
                    f"point {name!r}")
        out_q.append(q)
        out_names += [name] * count
    return np.concatenate(out_q), tuple(out_names)


def _checked(cell: dict, counts: dict, noise_mm: float, what: str) -> None:
    """Refuse counts naming no feature or not a count >= 1, and a noise that is not a finite number >= 0."""
    for name, count in counts.items():
        if name not in cell:
            raise DataError(f"counts names the {what} {name!r}, which the {what}s given do not hold "
                            f"({', '.join(map(str, cell)) or 'none'})")
        if not isinstance(count, (int, np.integer)) or isinstance(count, bool) or count < 1:
            raise DataError(f"counts[{name!r}] must be a number of rows >= 1; got {count!r}")
    if not (isinstance(noise_mm, (int, float, np.integer, np.floating)) and np.isfinite(noise_mm) and noise_mm >= 0):
        raise DataError(f"noise_mm must be a finite number >= 0 (mm); got {noise_mm!r}")


def _visits(vr, tib, count, near, targets, residual, rng, ranges, fixed, what) -> NDArray[np.float64]:
    """``count`` commanded configurations: random candidates near a feature, moved onto it (IK on the true
    robot, the joint errors inverted, Newton steps), kept when within the limits and on the feature."""
    kept, tried = [], 0
    for _ in range(ROUNDS):
        cand = uniform_configurations(vr.nominal, max(4000, 100 * count), ranges, fixed, rng)
        tried += len(cand)
        qa = vr.actual_joints(cand) if len(cand) else cand
        close = np.flatnonzero(near(tib.positions(qa), qa)) if len(cand) else np.zeros(0, dtype=int)
        need = count - sum(len(k) for k in kept)
        pick = close[:2 * need]
        if pick.size == 0:
            continue
        goal, rot, miss = targets(tib.positions(qa[pick]), qa[pick], pick.size)
        q, ok = _solved(vr, tib, cand[pick], goal, rot)
        q = _newton(vr, tib, q, residual(miss))
        values, _ = residual(miss)(vr.true_positions(q))
        ok &= (np.abs(values).max(axis=1) < ON_FEATURE_MM) & vr.nominal.within_limits(q)
        kept.append(q[ok][:need])
        if sum(len(k) for k in kept) >= count:
            return np.concatenate(kept)[:count]
    found = sum(len(k) for k in kept)
    raise UnreachableError(f"{what}: the arm reached it {found} times of {count} asked from {tried} sampled "
                           f"configurations: out of reach within the joint ranges, or too near their edge")


def _flush_rotations(rotations: NDArray[np.float64], normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """Each orientation turned by the smallest rotation that lays its z axis along ``-normal``: the tool's face
    down on the plane, whose normal points out of the material."""
    z = rotations[:, :, 2]
    want = np.broadcast_to(-normal, z.shape)
    axis = np.cross(z, want)
    sin = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(sin, np.einsum("ij,ij->i", z, want))
    vec = np.where(sin[:, None] > 1e-15, axis / np.maximum(sin, 1e-300)[:, None] * angle[:, None], 0.0)
    return matrices_from_rotation_vectors(vec) @ rotations


def pair_distances(vr, q_deg: NDArray[np.float64], pairs: NDArray[np.intp], rng: np.random.Generator,
                   noise_mm: float) -> NDArray[np.float64]:
    """Measured distances between the TRUE tool tips of pose pairs, mm, ``(m,)``: ``|tip_a - tip_b|`` plus
    ``N(0, noise_mm)``. ``pairs`` ``(m, 2)`` holds 0-based rows of ``q_deg`` ``(n, N)`` (commanded, degrees)."""
    _checked({}, {}, noise_mm, "")
    tips = vr.true_positions(q_deg)
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer) or \
            (pairs.size and (pairs.min() < 0 or pairs.max() >= len(tips))):
        raise DataError(f"Expected pairs with shape (m, 2) of row indices in [0, {len(tips)}), got array with "
                        f"shape {pairs.shape} and dtype {pairs.dtype}")
    d = np.linalg.norm(tips[pairs[:, 0]] - tips[pairs[:, 1]], axis=1)
    return d + (rng.normal(0.0, noise_mm, len(d)) if noise_mm > 0 else 0.0)


def all_pairs(n: int) -> NDArray[np.intp]:
    """Every pair ``(i, j)``, ``i < j < n``, shape ``(n (n - 1) / 2, 2)``, in row order.

    >>> all_pairs(3).tolist()
    [[0, 1], [0, 2], [1, 2]]
    """
    return np.column_stack(np.triu_indices(n, 1)).astype(np.intp)


def random_pairs(n: int, m: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """``m`` distinct random pairs ``(i, j)``, ``i < j < n``, shape ``(m, 2)``, in row order."""
    return all_pairs(n)[np.sort(rng.choice(n * (n - 1) // 2, size=m, replace=False))]
