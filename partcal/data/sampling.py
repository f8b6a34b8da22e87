"""Joint configurations for simulated data: well spread within ranges, joint limits and fixed joints.

:func:`sample_configurations` picks poses evenly over the joints' ranges (farthest-point selection, or a
scrambled Sobol sequence for large sets); :func:`uniform_configurations` draws admissible ones at random
(candidates for the contact generators, which keep those near a plane or a point).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import ConfigError
from ..robot.kinematics import Robot


def joint_bounds(robot: Robot, ranges_deg: dict) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Lower and upper joint bounds ``(N,)`` degrees: the limits narrowed by ``ranges_deg`` ({joint: (lo, hi)},
    1-based joints)."""
    lo = robot.limits_deg[:, 0].copy()
    hi = robot.limits_deg[:, 1].copy()
    for j, (a, b) in ranges_deg.items():
        lo[j - 1], hi[j - 1] = max(a, lo[j - 1]), min(b, hi[j - 1])
    return lo, hi


def uniform_configurations(robot: Robot, n: int, ranges_deg: dict, fixed_deg: dict, rng: np.random.Generator
                           ) -> NDArray[np.float64]:
    """``n`` uniform random candidates within the bounds, ``fixed_deg`` set; those breaking a limit or a
    constraint dropped (so up to ``n`` rows), shape ``(m, N)`` degrees."""
    lo, hi = joint_bounds(robot, ranges_deg)
    cand = rng.uniform(lo, hi, size=(n, robot.n_joints))
    for j, value in fixed_deg.items():
        cand[:, j - 1] = value
    return cand[robot.within_limits(cand)]


FARTHEST_POINT_UP_TO = 2000
"""Sampled data sets of up to this many poses are picked by farthest-point selection (its cost grows as the
square of the poses: 20,000 took 400 s); larger ones take the first admissible points of a scrambled Sobol
sequence, as evenly spread and linear in cost (20,000 in under a second)."""


def _low_discrepancy(robot: Robot, n: int, lo, hi, fixed_deg: dict, rng: np.random.Generator
                     ) -> NDArray[np.float64]:
    """The first ``n`` admissible points of a scrambled Sobol sequence over the ranges (seeded by ``rng``)."""
    from scipy.stats import qmc

    sobol = qmc.Sobol(robot.n_joints, scramble=True, seed=rng)
    kept, drawn = [], 0
    while sum(len(k) for k in kept) < n:
        batch = 1 << max(10, int(np.ceil(np.log2(n))))
        if drawn > 64 * n:
            raise ConfigError(f"fewer than {n} admissible configurations among {drawn} drawn; widen "
                              "sampling.ranges_deg")
        q = lo + sobol.random(batch) * (hi - lo)
        for j, value in fixed_deg.items():
            q[:, j - 1] = value
        kept.append(q[robot.within_limits(q)])
        drawn += batch
    return np.concatenate(kept)[:n]


def sample_configurations(robot: Robot, n: int, ranges_deg: dict, fixed_deg: dict,
                          rng: np.random.Generator, oversample: int = 20) -> NDArray[np.float64]:
    """``n`` well-spread joint configurations within ranges, limits and constraints.

    Draws ``oversample * n`` uniform candidates, keeps the admissible ones and
    picks ``n`` of them by farthest-point selection in range-normalised joint
    space, so the set covers every active joint's range evenly; above
    :data:`FARTHEST_POINT_UP_TO` poses, a scrambled Sobol sequence instead.
    """
    lo, hi = joint_bounds(robot, ranges_deg)
    if n > FARTHEST_POINT_UP_TO:
        return _low_discrepancy(robot, n, lo, hi, fixed_deg, rng)
    cand = rng.uniform(lo, hi, size=(oversample * n, robot.n_joints))
    for j, value in fixed_deg.items():
        cand[:, j - 1] = value
    cand = cand[robot.within_limits(cand)]
    if cand.shape[0] < n:
        raise ConfigError(f"only {cand.shape[0]} admissible configurations among {oversample * n} candidates; "
                         "widen sampling.ranges_deg")
    span = np.where(hi > lo, hi - lo, 1.0)
    unit = (cand - lo) / span
    chosen = [int(np.argmin(np.linalg.norm(unit - 0.5, axis=1)))]
    dist = np.linalg.norm(unit - unit[chosen[0]], axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(unit - unit[k], axis=1))
    return cand[chosen]
