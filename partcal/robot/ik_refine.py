"""Full-pose IK near singularities: Levenberg-Marquardt on the whole (biased) pose equation, with restarts.

:func:`partcal.robot.ik.solve_pose` takes damped least-squares steps with a
fixed damping and, for false targets, neglects the slope of the error model.
Both fail near a singularity (the UR wrist at ``q5 = 0``, a stretched elbow,
the wrist over the base axis), where the Jacobian has a singular value far
below the others: :func:`refine_pose` finishes the poses it leaves.
:func:`conditioning` measures how close joints are to a singularity.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .ik import CHUNK, Settings, biased_pose, pose_jacobian, take_step, within_pose_tolerance
from .rotations import rotation_vectors_from_matrices

RESTARTS_DEG = (30.0, -30.0, 90.0, -90.0, 180.0, -180.0)   # along the weakest direction, from where the solve stuck


def refine_pose(robot, positions: NDArray[np.float64], rotations: NDArray[np.float64], q: NDArray[np.float64],
                free: NDArray[np.intp], settings: Settings, tol_deg: float, length_mm: float,
                bias: Callable | None = None, fd_deg: float = 1e-4) -> tuple:
    """Levenberg-Marquardt on :func:`~partcal.robot.ik.solve_pose`'s equation: the bias's slope, adaptive damping.

    For the poses :func:`~partcal.robot.ik.solve_pose` leaves unconverged: near a singularity
    (the UR wrist at ``q5 = 0``, a stretched elbow) the Jacobian has a small
    singular value, so a fixed damping creeps along it, and the bias's slope,
    neglected there, is no longer small beside it: the iteration stalls or
    wanders. Here the Jacobian is that of the whole equation (the forward
    kinematics' own, plus the bias's by forward differences of ``fd_deg``),
    and each pose's damping ``mu`` adapts: a step that lowers the pose's
    error is taken and ``mu`` shrinks, one that does not is refused and ``mu``
    grows. A pose stops when it meets the tolerances, or when ``mu`` has
    grown so far that no step lowers its error (a pose the robot cannot take
    there, or a local minimum).

    A pose still off is solved again from its stopping point moved along the
    Jacobian's weakest direction there (the self-motion of a singularity: the
    UR's wrist at ``q5 = 0`` turns ``q4`` against ``q6``) by each of
    :data:`RESTARTS_DEG` (the largest joint's change, nearest first): near a
    singularity the solution can lie a large turn of ``q4`` away, which
    small steps from the seed do not reach. The first restart that meets the
    tolerances within the robot's limits and constraints is kept; a pose that none brings there keeps the first
    solve's joints, near its seed. Returns joints (n, N) degrees and
    iterations (n,), all solves counted.
    """
    tol_rad = np.radians(tol_deg)

    def lm(rows, start):
        q_out, its = np.array(start, dtype=float), np.zeros(len(rows), dtype=np.int64)
        for k in range(0, len(rows), CHUNK):
            block, part = slice(k, k + CHUNK), rows[k:k + CHUNK]
            q_out[block], its[block] = _lm_block(robot, positions[part].T, rotations[part], q_out[block].T, free,
                                                 settings, tol_rad, length_mm, bias, fd_deg)
        return q_out, its

    def met(rows, q_rows):
        err = _pose_error(robot, positions[rows].T, rotations[rows], q_rows.T, free, length_mm, bias)
        return within_pose_tolerance(err, settings.tol_mm, length_mm * tol_rad)

    everyone = np.arange(len(q))
    out, iterations = lm(everyone, q)
    left = everyone[~met(everyone, out)]
    if left.size == 0:
        return out, iterations
    stuck = out[left]                 # restarts along the self-motion there, the nearest first
    jac = _pose_error(robot, positions[left].T, rotations[left], stuck.T, free, length_mm, bias, fd_deg)[1]
    weak = np.linalg.svd(jac)[2][:, -1, :]                              # (k, F): the pose's weakest direction
    weak /= np.abs(weak).max(axis=1, keepdims=True)
    todo = np.ones(left.size, dtype=bool)
    lo, hi = robot.limits_deg[free, 0], robot.limits_deg[free, 1]
    for turn_deg in RESTARTS_DEG:
        k = np.flatnonzero(todo)
        if k.size == 0:
            break
        seeds = stuck[k].copy()
        seeds[:, free] = np.clip(seeds[:, free] + turn_deg * weak[k], lo, hi)
        q_new, its = lm(left[k], seeds)
        iterations[left[k]] += its
        ok = met(left[k], q_new) & robot.within_limits(q_new)       # a constraint the box clip cannot keep
        out[left[k[ok]]] = q_new[ok]
        todo[k[ok]] = False
    return out, iterations


def conditioning(robot, q: NDArray[np.float64], free: NDArray[np.intp], length_mm: float) -> NDArray[np.float64]:
    """The ratio of the smallest to the largest singular value of the free joints' pose Jacobian at joints
    ``q`` (n, N) degrees (orientation rows times ``length_mm``), shape (n,): 0 at a singularity."""
    p, _, frames = robot.walk(robot.rotors(np.asarray(q, dtype=float).T), record=robot.moving_rows(free))
    s = np.linalg.svd(pose_jacobian(robot, p, frames, free, length_mm).transpose(2, 1, 0), compute_uv=False)
    return s[:, -1] / np.maximum(s[:, 0], 1e-300)


def _pose_error(robot, targets, rotations, qT, free, length: float, bias, fd_deg: float | None = None):
    """The pose error (6, m), mm and ``length`` x rad, of joints ``qT`` (N, m); with ``fd_deg`` also the
    Jacobian of the whole equation ``d error / d q`` (m, 6, F) per degree."""
    record = robot.moving_rows(free) if fd_deg is not None else ()
    p, axes, frames = robot.walk(robot.rotors(qT), record=record)
    reached = np.stack([np.broadcast_to(a, p.shape) for a in axes], axis=1).transpose(2, 0, 1)
    b = None if bias is None else bias(qT.T)
    at, turned = (p, reached) if b is None else biased_pose(p, reached, b)
    turn = rotation_vectors_from_matrices(rotations @ turned.transpose(0, 2, 1)).T                 # (3, m) rad
    err = np.concatenate([targets - at, length * turn])
    if fd_deg is None:
        return err
    jac = pose_jacobian(robot, p, frames, free, length)                              # (F, 6, m) per degree
    if b is not None:          # the bias moves the pose too: its slope by forward differences
        for f, j in enumerate(free):
            shifted = qT.copy()
            shifted[j] += fd_deg
            slope = (bias(shifted.T) - b).T / fd_deg                                    # (6, m)
            jac[f] += np.concatenate([slope[:3], length * slope[3:]])
    return err, -jac.transpose(2, 1, 0)


def _lm_block(robot, targets, rotations, qT, free, settings: Settings, tol_rad: float, length: float, bias,
              fd_deg: float):
    """:func:`refine_pose` on one block: ``targets`` (3, m), ``rotations`` (m, 3, 3), ``qT`` (N, m)."""
    qT = qT.copy()
    lo, hi = robot.limits_deg[free, 0][:, None], robot.limits_deg[free, 1][:, None]
    m = qT.shape[1]
    idx, done_q = np.arange(m), qT
    iterations = np.zeros(m, dtype=np.int64)
    err, jac = _pose_error(robot, targets, rotations, qT, free, length, bias, fd_deg)
    cost = np.sum(err * err, axis=0)
    scale = np.einsum("mkf,mkf->mf", jac, jac).max(axis=1)       # the largest diagonal of J^T J, per pose
    mu = 1e-6 * scale
    eye = np.eye(len(free))
    for _ in range(settings.max_iter):
        met = within_pose_tolerance(err, settings.tol_mm, length * tol_rad)
        stuck = mu > 1e8 * scale                                  # no step lowers the error: give up
        keep = ~(met | stuck)
        if not keep.any():
            break
        if not keep.all():
            done_q[:, idx[~keep]] = qT[:, ~keep]
            idx, qT, targets, rotations = idx[keep], qT[:, keep], targets[:, keep], rotations[keep]
            err, jac, cost, mu, scale = err[:, keep], jac[keep], cost[keep], mu[keep], scale[keep]
        JT = jac.transpose(0, 2, 1)                                                     # (m, F, 6)
        A = JT @ jac + mu[:, None, None] * eye
        step = -np.linalg.solve(A, (JT @ err.T[:, :, None]))[:, :, 0].T                 # (F, m)
        trial = qT.copy()
        take_step(trial, free, step, settings, lo, hi)
        new = _pose_error(robot, targets, rotations, trial, free, length, bias)
        new_cost = np.sum(new * new, axis=0)
        better = new_cost < cost
        mu = np.where(better, np.maximum(mu / 3.0, 1e-12 * scale), mu * 4.0)
        iterations[idx] += 1
        if better.any():
            qT[:, better] = trial[:, better]
            sub = np.flatnonzero(better)
            e2, j2 = _pose_error(robot, targets[:, sub], rotations[sub], qT[:, sub], free, length, bias, fd_deg)
            err[:, sub], jac[sub], cost[sub] = e2, j2, new_cost[sub]
    done_q[:, idx] = qT
    return done_q.T, iterations
