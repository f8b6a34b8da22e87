"""Inverse kinematics: batched damped least squares, and whole paths solved at once.

:func:`solve` runs damped least-squares iterations for many targets at once.
Every operation is elementwise in the targets and sums run in a fixed order,
so a target gets the same bits alone or in any batch.

:func:`solve_path` gives the *sequential* path solution, point ``i`` solved
from the solution of point ``i - 1``, without solving the points one after
another. Write ``F(p, s)`` for the solution of target ``p`` from seed ``s``.
The path is the fixed point of ``Q_i = F(p_i, Q_{i-1})`` and is found by
Newton's method on the whole chain (multiple shooting):

1. ``Q_i``: every point roughly (to 0.5 mm) from the path's seed, one batch;
2. ``G_i = F(p_i, Q_{i-1})`` for all points, one batch. Where the chain is
   consistent, ``G = Q``. With redundant joints, an error in the seed of
   point ``i`` survives in its solution along the self-motion (the null space
   of the Jacobian), so point ``i + 1`` inherits it, and so on: a plain
   repetition would take as many passes as there are points. Instead the
   corrections are carried down the chain along the self-motion: with one
   redundant direction ``n_i``, ``Q_i <- G_i + tau_i n_i`` with
   ``tau_i = a_i (n.(G - Q)_{i-1} + tau_{i-1})``, where the gain ``a_i`` (how
   much of a seed's self-motion reaches the solution) is 1 at first, then
   the secant of the last two passes; with several, the accumulated
   defects projected onto each point's null space;
3. repeat 2 until ``G = Q`` to 1e-10 degrees: ``G`` is then the sequential
   solution to about that.

Five passes settle the paper's 200-point paths. Points before the first one
that has not settled are exact in any case, so the path is processed in
segments, and a segment that does not settle restarts from its last exact
point: sequential steps only where needed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .rotations import matrices_from_rotation_vectors, rotation_vectors_from_matrices

CHUNK = 4096           # targets per block: the working arrays stay in cache
_SEGMENT = 256         # path points per chain: keeps the correction accurate on long paths
_PASSES = 12
_I1, _I2 = [1, 2, 0], [2, 0, 1]
_I11, _I22, _I12, _I21 = np.ix_([1, 2, 0], [1, 2, 0]), np.ix_([2, 0, 1], [2, 0, 1]), \
    np.ix_([1, 2, 0], [2, 0, 1]), np.ix_([2, 0, 1], [1, 2, 0])      # (i+1, j+1), (i+2, j+2), ... mod 3


@dataclass(frozen=True)
class Settings:
    """Damped least squares: stop at ``tol_mm``; steps capped at ``max_step_deg`` per joint."""

    tol_mm: float = 1e-8
    max_iter: int = 100
    max_step_deg: float = 10.0
    damping: float = 0.05


def solve(robot, targets: NDArray[np.float64], q: NDArray[np.float64], free: NDArray[np.intp],
          settings: Settings, bias: Callable | None = None, tol_mm: float | None = None,
          seed_jacobian: bool = False) -> tuple:
    """Damped least-squares IK for every target; returns joints (n, N) degrees and iterations (n,).

    Parameters
    ----------
    robot : Robot
    targets : ndarray, shape (n, 3)
        Positions in mm.
    q : ndarray, shape (n, N)
        Seeds in degrees; joints not in ``free`` keep their value.
    free : ndarray of int
        0-based joints that move.
    bias : callable, optional
        ``bias(q (m, N) deg) -> (m, 3) mm`` added to the forward kinematics:
        solves ``FK(q) + bias(q) = target`` (false targets of joint models).
        Its Jacobian is neglected, so it must change slowly with ``q``.
    tol_mm : float, optional
        Convergence tolerance for the biased equation (default ``settings.tol_mm``).
    seed_jacobian : bool
        Also return the free joints' Jacobian at the seeds, (F, 3, n) mm/deg
        (computed anyway in the first iteration).
    """
    out = np.array(q, dtype=float)
    iterations = np.zeros(len(out), dtype=np.int64)
    jac = np.empty((len(free), 3, len(out))) if seed_jacobian else None
    for start in range(0, len(out), CHUNK):
        block = slice(start, start + CHUNK)
        qT, its = _solve_block(robot, targets[block].T, out[block].T, free, settings, bias,
                               settings.tol_mm if tol_mm is None else tol_mm,
                               None if jac is None else jac[:, :, block])
        out[block], iterations[block] = qT.T, its
    return (out, iterations, jac) if seed_jacobian else (out, iterations)


def _solve_block(robot, targets, qT, free, settings: Settings, bias, tol, seed_jac=None):
    """:func:`solve` on one block: ``targets`` (3, m), joints ``qT`` (N, m); returns (qT, iterations).

    ``seed_jac`` (F, 3, m), if given, receives the Jacobian at the seeds.
    """
    qT, targets = qT.copy(), np.ascontiguousarray(targets)
    m = qT.shape[1]
    record = robot.moving_rows(free)
    moving = set(record)
    still = {r for r in range(robot.n_rows) if r not in moving}
    fixed_trig = robot.rotors(qT, rows=still)          # rows that no free joint turns: once per block
    lo, hi = robot.limits_deg[free, 0][:, None], robot.limits_deg[free, 1][:, None]
    done_q, iterations = qT, np.zeros(m, dtype=np.int64)
    idx = np.arange(m)
    for _ in range(settings.max_iter):
        moved = robot.rotors(qT, rows=moving)
        trig = [fixed_trig[r] if r in still else moved[r] for r in range(robot.n_rows)]
        p, _, frames = robot.walk(trig, record=record)
        err = targets - p
        if bias is not None:
            err -= bias(qT.T).T
        keep = (err[0] * err[0] + err[1] * err[1] + err[2] * err[2]) > tol * tol
        going = np.count_nonzero(keep)
        if seed_jac is not None:
            jac = seed_jac[...] = robot.walk_jacobian(p, frames, free)
        if not going:
            break
        if seed_jac is None:
            jac = robot.walk_jacobian(p, frames, free)
        seed_jac = None
        if going < keep.size:                          # drop the converged targets
            done_q[:, idx[~keep]] = qT[:, ~keep]
            idx, qT, targets, err, jac = idx[keep], qT[:, keep], targets[:, keep], err[:, keep], jac[:, :, keep]
            fixed_trig = [t[keep] if isinstance(t, np.ndarray) else (t[0], t[1][keep]) if isinstance(t, tuple) else t
                          for t in fixed_trig]
        take_step(qT, free, _dls_step(jac, err, settings.damping), settings, lo, hi)
        iterations[idx] += 1
    done_q[:, idx] = qT
    return done_q, iterations


def within_pose_tolerance(err: NDArray[np.float64], tol_mm: float, tol_length: float) -> NDArray[np.bool_]:
    """Which poses of a pose error (6, m) (mm, and ``length`` x rad) meet both tolerances, shape (m,)."""
    return (np.sum(err[:3] ** 2, axis=0) <= tol_mm ** 2) & (np.sum(err[3:] ** 2, axis=0) <= tol_length ** 2)


def pose_jacobian(robot, p, frames, free: NDArray[np.intp], length: float) -> NDArray[np.float64]:
    """The forward kinematics' pose Jacobian (F, 6, m) per degree of the walked chain: the position's rows, then
    the turn's times ``length``."""
    return np.concatenate([robot.walk_jacobian(p, frames, free), length * robot.walk_jacobian(p, frames, free, True)],
                          axis=1)


def take_step(qT, free, step, settings: Settings, lo, hi) -> None:
    """Move the free joints of ``qT`` (N, m) degrees in place by ``step`` (F, m) degrees (changed too), each
    target's step capped at ``settings.max_step_deg`` for its largest joint, and clipped to the joint limits
    ``lo, hi`` (F, 1) degrees of the joints ``free`` (0-based)."""
    biggest = np.abs(step).max(axis=0)
    np.maximum(biggest, 1e-300, out=biggest)
    step *= np.minimum(1.0, settings.max_step_deg / biggest)
    step += qT[free]
    np.minimum(step, hi, out=step)
    np.maximum(step, lo, out=step)
    qT[free] = step


def _dls_step(jac: NDArray[np.float64], err: NDArray[np.float64], damping: float) -> NDArray[np.float64]:
    """``J^T (J J^T + damping^2 I)^-1 err`` for every target: ``jac`` (F, 3, m), ``err`` (3, m) -> (F, m).

    The 3 x 3 system is solved by its adjugate, elementwise, in a fixed order.
    """
    A = jac[0][:, None] * jac[0][None, :]              # (3, 3, m)
    for f in range(1, jac.shape[0]):
        A += jac[f][:, None] * jac[f][None, :]
    for k in range(3):
        A[k, k] += damping * damping
    adj = A[_I11] * A[_I22]                            # cofactors; A is symmetric, so adj = cofactors
    adj -= A[_I12] * A[_I21]
    det = A[0, 0] * adj[0, 0] + A[0, 1] * adj[0, 1] + A[0, 2] * adj[0, 2]
    weighted = adj * err[None, :, :]
    y = weighted[:, 0] + weighted[:, 1] + weighted[:, 2]
    y /= det
    step = jac[:, 0] * y[0]
    step += jac[:, 1] * y[1]
    step += jac[:, 2] * y[2]
    return step


# ---------------------------------------------------------------------- full poses
def solve_pose(robot, positions: NDArray[np.float64], rotations: NDArray[np.float64], q: NDArray[np.float64],
               free: NDArray[np.intp], settings: Settings, tol_deg: float, length_mm: float,
               bias: Callable | None = None) -> tuple:
    """Damped least squares on position and orientation; returns joints (n, N) degrees and iterations (n,).

    ``positions`` (n, 3) mm and ``rotations`` (n, 3, 3) are the wanted tool
    poses. The error of a pose is the position difference and the rotation
    vector of ``R_wanted R^T`` (radians, in the base frame) times
    ``length_mm``; the step solves the 6 x 6 damped system of every pose.
    ``bias(q (m, N) deg) -> (m, 6)``, if given, is a pose error added to the
    forward kinematics (position mm, then a rotation vector in radians that
    turns the tool's orientation in the base frame): the solution then
    satisfies ``FK(q) + bias(q) = pose`` (false targets of joint models; the
    bias's Jacobian is neglected, as for :func:`solve`).
    """
    out = np.array(q, dtype=float)
    iterations = np.zeros(len(out), dtype=np.int64)
    tol_rad = np.radians(tol_deg)
    for start in range(0, len(out), CHUNK):
        block = slice(start, start + CHUNK)
        out[block], iterations[block] = _pose_block(robot, positions[block].T, rotations[block], out[block].T,
                                                    free, settings, tol_rad, length_mm, bias)
    return out, iterations


def biased_pose(p: NDArray[np.float64], reached: NDArray[np.float64], error: NDArray[np.float64]) -> tuple:
    """The pose ``(p (3, m), R (m, 3, 3))`` moved by a pose error ``(m, 6)``: position mm, rotation vector rad."""
    return p + error[:, :3].T, matrices_from_rotation_vectors(error[:, 3:]) @ reached


def _pose_block(robot, targets, rotations, qT, free, settings: Settings, tol_rad: float, length: float, bias=None):
    """:func:`solve_pose` on one block: ``targets`` (3, m), ``rotations`` (m, 3, 3), ``qT`` (N, m)."""
    qT = qT.copy()
    record = robot.moving_rows(free)
    lo, hi = robot.limits_deg[free, 0][:, None], robot.limits_deg[free, 1][:, None]
    idx, done_q = np.arange(qT.shape[1]), qT
    iterations = np.zeros(qT.shape[1], dtype=np.int64)
    for _ in range(settings.max_iter):
        p, axes, frames = robot.walk(robot.rotors(qT), record=record)
        reached = np.stack([np.broadcast_to(a, p.shape) for a in axes], axis=1).transpose(2, 0, 1)   # (m, 3, 3)
        at, turned = (p, reached) if bias is None else biased_pose(p, reached, bias(qT.T))
        turn = rotation_vectors_from_matrices(rotations @ turned.transpose(0, 2, 1)).T          # (3, m) rad
        err = np.concatenate([targets - at, length * turn])
        keep = ~within_pose_tolerance(err, settings.tol_mm, length * tol_rad)
        if not keep.any():
            break
        if not keep.all():                              # drop the converged poses
            done_q[:, idx[~keep]] = qT[:, ~keep]
            idx, qT, targets, rotations, err = idx[keep], qT[:, keep], targets[:, keep], rotations[keep], err[:, keep]
            p, frames = p[:, keep], {r: (z[:, keep], o[:, keep]) for r, (z, o) in frames.items()}
        jac = pose_jacobian(robot, p, frames, free, length)                                     # (F, 6, m)
        J = jac.transpose(2, 1, 0)                                                              # (m, 6, F)
        A = J @ J.transpose(0, 2, 1) + settings.damping ** 2 * np.eye(6)
        step = (J.transpose(0, 2, 1) @ np.linalg.solve(A, err.T[:, :, None]))[:, :, 0].T        # (F, m)
        take_step(qT, free, step, settings, lo, hi)
        iterations[idx] += 1
    done_q[:, idx] = qT
    return done_q.T, iterations


# ---------------------------------------------------------------------- paths
def solve_path(robot, targets: NDArray[np.float64], seed: NDArray[np.float64], free: NDArray[np.intp],
               settings: Settings) -> NDArray[np.float64]:
    """The sequential path solution for ``targets`` (n, 3) mm from ``seed`` (N,) degrees, shape (n, N)."""
    out = np.empty((len(targets), robot.n_joints))
    start = 0
    while start < len(targets):
        part = targets[start:start + _SEGMENT]
        q, good = _chain(robot, part, seed, free, settings)
        out[start:start + good] = q[:good]
        seed, start = q[good - 1], start + good
    return out


def _chain(robot, targets, seed, free, settings: Settings) -> tuple[NDArray[np.float64], int]:
    """Chain Newton on one segment; returns the joints (m, N) and how many leading points are exact."""
    m = len(targets)
    if m == 1:
        return solve(robot, targets, seed[None], free, settings)[0], 1
    # pass 0: every point roughly (to 0.5 mm), from the seed; only a start for the passes that follow
    rough = Settings(0.5, settings.max_iter, settings.max_step_deg, settings.damping)
    Q = solve(robot, targets, np.repeat(seed[None], m, axis=0), free, rough)[0]
    last, G, before = np.inf, np.empty_like(Q), None
    for k in range(_PASSES):
        if k == 0:                                              # G_0 = F(p_0, seed) once: final from then on
            G, _, jac = solve(robot, targets, np.vstack([seed, Q[:-1]]), free, settings, seed_jacobian=True)
            jac = jac[:, :, 1:]
        else:
            G[1:], _, jac = solve(robot, targets[1:], Q[:-1], free, settings, seed_jacobian=True)
        D = G - Q
        D[0] = 0.0 if k == 0 else D[0]
        gap = np.abs(D).max(axis=1)
        worst = gap.max()
        if worst <= 1e-10 or (worst <= 1e-9 and worst > 0.5 * last):
            return G, m                                         # consistent to rounding
        last = worst
        # the Jacobian at Q_i (the seed of point i + 1) stands in for the one at G_i
        jac = np.concatenate([jac, jac[:, :, -1:]], axis=2)
        if len(free) == 4:                                      # one redundant direction: secant gains
            step, before = _secant(jac, G, Q, before, free)
        else:
            step = _carried(jac, D, free)
        Q = G + step
    good = int(np.argmax(gap > 1e-9))                           # the first point whose seed still moves
    return G, max(good, 1)


def _secant(jac, G, Q, before, free):
    """Corrections along the one self-motion direction ``n_i``: ``Q_i <- G_i + tau_i n_i``.

    ``tau_i = a_i (rho_{i-1} + tau_{i-1})`` with ``rho = n . (G - Q)`` and the
    gain ``a_i`` of the self-motion from the seed of point ``i`` to its
    solution: 1 at first, then the secant of the last two passes (as the
    seed of point ``i`` changed, so did its solution). Solved in closed form:
    ``tau_i = A_i sum_{j<i} rho_j / A_j`` with ``A = cumprod(a)``.
    Returns the corrections (m, N) and what the next pass needs.
    """
    n = _null_direction(jac)                                     # (4, m)
    Gf, Qf = G[:, free].T, Q[:, free].T
    rho = (n * (Gf - Qf)).sum(axis=0)
    a = np.ones(len(G))
    if before is not None:
        G_old, Q_old = before
        num = (n[:, 1:] * (Gf[:, 1:] - G_old[:, 1:])).sum(axis=0)
        den = (n[:, :-1] * (Qf[:, :-1] - Q_old[:, :-1])).sum(axis=0)
        ok = np.abs(den) > 1e-10
        a[1:][ok] = np.clip(num[ok] / den[ok], 0.5, 2.0)
    A = np.cumprod(a)
    tau = np.zeros(len(G))
    np.cumsum(rho[:-1] / A[:-1], out=tau[1:])
    tau *= A
    step = np.zeros_like(G)
    step[:, free] = (tau * n).T
    return step, (Gf, Qf)


def _null_direction(jac: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit null vector of each 3 x 4 Jacobian ``jac`` (4, 3, m), shape (4, m).

    Its components are the signed 3 x 3 minors, ``(+|c1 c2 c3|, -|c0 c2 c3|,
    +|c0 c1 c3|, -|c0 c1 c2|)`` of the columns ``c`` (a cross product in four
    dimensions), so it turns smoothly along a path, without sign flips.
    """
    c = jac
    c23 = c[2][_I1] * c[3][_I2] - c[2][_I2] * c[3][_I1]          # c2 x c3, (3, m)
    c01 = c[0][_I1] * c[1][_I2] - c[0][_I2] * c[1][_I1]          # c0 x c1
    n = np.stack([(c[1] * c23).sum(axis=0), -(c[0] * c23).sum(axis=0),
                  (c[3] * c01).sum(axis=0), -(c[2] * c01).sum(axis=0)])
    n /= np.sqrt((n * n).sum(axis=0))
    return n


def _carried(jac: NDArray[np.float64], D: NDArray[np.float64], free) -> NDArray[np.float64]:
    """Corrections ``c_i = P_i (D_0 + ... + D_{i-1})``, ``c_0 = 0``, as joint changes (m, N).

    ``P_i`` projects onto the self-motion at point ``i`` (the null space of the
    free joints' Jacobian ``jac[:, :, i]``, (F, 3, m)): ``P v = v - J^T (J
    J^T)^-1 J v``. Carrying a correction from point to point, ``c_i = P_i
    (c_{i-1} + D_{i-1})``, is this to first order, since the self-motion
    turns slowly along a path. Without redundancy ``P = 0``: a plain repetition.
    """
    v = np.zeros((len(free), len(D)))
    np.cumsum(D[:-1, free].T, axis=1, out=v[:, 1:])
    Jv = np.stack([(jac[:, k] * v).sum(axis=0) for k in range(3)])   # J v, (3, m)
    v -= _dls_step(jac, Jv, 0.0)
    out = np.zeros_like(D)
    out[:, free] = v.T
    return out
