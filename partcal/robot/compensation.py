"""False-target error correction: command p' such that the robot, erring by e, reaches p.

Cartesian models solve ``p' + e(p') = p`` by the fixed-point iteration
``p'_{k+1} = p - e(p'_k)``. It converges when the error field changes by less
than 1 mm per mm, which holds by orders of magnitude for robot errors (a few
mm over metres); points that do not reach the tolerance are reported, never
silently returned. Joint models solve ``FK(q') + e(q') = p`` for the joints
directly, by damped least squares on the whole equation (joints the model
never saw move kept fixed).

Full poses (a model of 6 outputs: the position error, then the rotation
vector that turns the nominal orientation into the real one) are compensated
the same ways: joint models solve the whole pose equation by damped least
squares (:func:`false_target_poses`); Cartesian models, which read the
position alone, take the position's fixed point and then the orientation
that the predicted turn carries onto the target
(:func:`false_target_cartesian_poses`).

Either way the answer must be one the robot can take: joint solutions that
break the robot's limits or coupled constraints (the SK120's ``q2 - q3`` in
[10, 120]) are not converged, and a Cartesian command is converged only
where the robot's inverse kinematics reaches it within those limits
(:func:`reachable`, :func:`reachable_poses` for full poses).
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from . import ik, ik_refine
from .kinematics import Robot, checked_poses, ik_settings
from .rotations import matrices_from_rotation_vectors, rotation_vectors_from_matrices


SINGULAR_CONDITIONING = 1e-3    # a pose Jacobian whose singular values span more than this is at a singularity


class CompensationWarning(UserWarning):
    """Some targets did not converge to the requested tolerance."""


@dataclass(frozen=True)
class CompensationResult:
    """Commanded positions (and joints for joint models), with per-target convergence.

    ``residual_mm`` is the predicted miss after compensation: ``|p' + e(p') - p|``.
    ``singular`` (a full-pose joint solve, else None) marks the unconverged
    targets whose solve stopped at a singularity (:meth:`reasons` says
    ``"singular"`` for them).
    """

    commanded_mm: NDArray[np.float64]
    joints_deg: NDArray[np.float64] | None
    iterations: NDArray[np.int64]
    residual_mm: NDArray[np.float64]
    converged: NDArray[np.bool_]
    commanded_rotation: NDArray[np.float64] | None = None    # full-pose compensation: (n, 3, 3)
    residual_deg: NDArray[np.float64] | None = None          # and its predicted orientation miss
    singular: NDArray[np.bool_] | None = None                # full-pose joint solve: stopped at a singularity

    def reasons(self, tol_mm: float, tol_deg: float | None = None, robot: Robot | None = None,
                targets_mm: NDArray[np.float64] | None = None) -> list[str]:
        """Why each target is not converged (``""`` where it is), from what the solve left.

        In this order: ``"diverged"``, no finite prediction at the command (the
        iteration ran away, as far outside the data); ``"out of reach"``, the
        predicted miss (``residual_mm``, and ``residual_deg`` with ``tol_deg``)
        is beyond the tolerance and the nominal ``robot`` does not reach the
        target position ``targets_mm`` (n, 3) mm within its limits either
        (:func:`reachable`); ``"joint limit"``, the joint solution
        (``joints_deg``) breaks the robot's limits or coupled constraints;
        ``"not converged"``, the miss is beyond the tolerance after the
        iterations, or ``"singular"`` where it is and the solve stopped at
        joints where the robot loses a direction of motion (``singular``, a
        full-pose joint solve: the compensated pose lies across a singularity
        from the seed's posture); ``"out of reach"`` too where the miss is
        within the tolerance but the robot's inverse kinematics does not reach
        the command within its limits (a Cartesian model's reachability check).
        """
        n = len(self.converged)
        missed = ~(self.residual_mm <= tol_mm)
        finite = np.isfinite(self.residual_mm)
        if tol_deg is not None and self.residual_deg is not None:
            missed |= ~(self.residual_deg <= tol_deg)
            finite &= np.isfinite(self.residual_deg)
        limited = np.zeros(n, dtype=bool)
        beyond = np.zeros(n, dtype=bool)
        if robot is not None:
            if self.joints_deg is not None:
                limited = ~robot.within_limits(self.joints_deg)
            if targets_mm is not None:
                check = np.flatnonzero(missed & finite & ~self.converged)
                beyond[check] = ~reachable(robot, np.asarray(targets_mm, dtype=float)[check])
        singular = missed & (self.singular if self.singular is not None else False)
        why = np.select([~finite, beyond, limited, singular, missed],
                        ["diverged", "out of reach", "joint limit", "singular", "not converged"], "out of reach")
        return ["" if ok else str(w) for ok, w in zip(self.converged, why)]

    def warn_unconverged(self, tol_mm: float, tol_deg: float | None = None, *, robot: Robot | None = None,
                         targets_mm: NDArray[np.float64] | None = None, source: str = "") -> None:
        """A :class:`CompensationWarning` naming the first unconverged targets (0-based), their misses and why.

        ``tol_deg`` (full-pose results) adds the orientation tolerance and
        misses; each listed target gives its reason (:meth:`reasons`, with
        ``robot`` and ``targets_mm`` as there), so a miss inside the tolerance
        is never listed without what failed (a joint limit, out of reach).
        ``source`` leads the message: the model, and the data set (``model
        'DH' on data set 'test'``).
        """
        bad = np.flatnonzero(~self.converged)
        if bad.size:
            pose = tol_deg is not None and self.residual_deg is not None
            why = self.reasons(tol_mm, tol_deg if pose else None, robot, targets_mm)
            listed = ", ".join(f"#{i} ({self.residual_mm[i]:.3g} mm" + (f", {self.residual_deg[i]:.3g} deg"
                                                                         if pose else "") + f": {why[i]})"
                               for i in bad[:5])
            more = f" and {bad.size - 5} more" if bad.size > 5 else ""
            tolerance = f"{tol_mm:g} mm" + (f" and {tol_deg:g} deg" if pose else "")
            lead = f"{source}: " if source else ""
            warnings.warn(f"{lead}{bad.size} of {len(self.converged)} targets did not converge to {tolerance}: "
                          f"{listed}{more}", CompensationWarning, stacklevel=3)


def merged(parts: list[tuple[NDArray[np.bool_], CompensationResult]]) -> CompensationResult:
    """One result from results of disjoint row sets: ``parts`` pairs a boolean row mask with its result."""
    n = len(parts[0][0])
    first = parts[0][1]

    def gather(field: str):
        if getattr(first, field) is None:
            return None
        out = np.empty((n,) + getattr(first, field).shape[1:], dtype=getattr(first, field).dtype)
        for rows, result in parts:
            out[rows] = getattr(result, field)
        return out

    return CompensationResult(*(gather(f.name) for f in dataclasses.fields(CompensationResult)))


def false_target(predict: Callable[[NDArray[np.float64]], NDArray[np.float64]], targets_mm: NDArray[np.float64],
                 *, tol_mm: float = 1e-4, max_iter: int = 50) -> CompensationResult:
    """Fixed-point false targets for a Cartesian error model ``predict(positions) -> errors``.

    Each step predicts only the targets still moving. A target whose next
    command would not be finite (the iteration diverges, as it can far outside
    the data, where a polynomial grows fast) stops and is reported not
    converged, with an infinite residual and the target itself as its command
    (never a command of 1e200 mm).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        cmd = targets_mm - predict(targets_mm)
        start = np.all(np.isfinite(cmd), axis=1)
        cmd[~start] = targets_mm[~start]              # nothing finite to command: the target itself
        iterations = np.ones(len(targets_mm), dtype=np.int64)
        miss = np.full(targets_mm.shape, np.inf)
        live = start.copy()
        for step in range(max_iter):
            idx = np.flatnonzero(live)
            if idx.size == 0:
                break
            miss[idx] = cmd[idx] + predict(cmd[idx]) - targets_mm[idx]
            norm = np.linalg.norm(miss[idx], axis=1)
            move = norm > tol_mm                      # NaN: not a step, and not converged
            live[idx[~move]] = False
            if step == max_iter - 1:
                break
            move = idx[move]
            new = cmd[move] - miss[move]              # = target - e(cmd)
            finite = np.all(np.isfinite(new), axis=1)
            cmd[move[finite]] = new[finite]
            iterations[move[finite]] += 1
            live[move[~finite]] = False
            miss[move[~finite]] = np.inf
        residual = np.linalg.norm(miss, axis=1)
    diverged = ~np.isfinite(residual)
    residual[diverged] = np.inf
    cmd[diverged] = targets_mm[diverged]
    return CompensationResult(cmd, None, iterations, residual, residual <= tol_mm)


def false_target_joints(predict: Callable[[NDArray[np.float64]], NDArray[np.float64]], robot: Robot,
                        targets_mm: NDArray[np.float64], seeds_deg: NDArray[np.float64], fixed: tuple[int, ...],
                        *, tol_mm: float = 1e-4, max_iter: int = 50) -> CompensationResult:
    """False targets for a joint-angle error model ``predict(q_deg) -> errors``, via the robot's IK.

    First the plain IK of every target from its seed (which picks the branch,
    as it always did), then damped least-squares steps on the whole equation
    ``p - FK(q) - e(q)``, with the Jacobian of ``FK`` alone: the error model
    changes by far less than a millimetre per degree, so neglecting its slope
    costs nothing in accuracy, only a factor ``|de/dq| / |J|`` in the
    convergence rate. Both are one batched loop for all targets, instead of a
    full IK per fixed-point iteration. ``iterations`` counts the second
    phase's steps (at most ``max_iter``).
    """
    free = robot.free_joints(fixed)
    q = ik.solve(robot, targets_mm, np.array(seeds_deg, dtype=float), free, ik.Settings())[0]
    q, iterations = ik.solve(robot, targets_mm, q, free, ik.Settings(max_iter=max_iter), bias=predict,
                             tol_mm=tol_mm)
    reached = robot.positions_validated(q)
    with np.errstate(over="ignore", invalid="ignore"):
        residual = np.linalg.norm(reached + predict(q) - targets_mm, axis=1)
    converged = (residual <= tol_mm) & robot.within_limits(q)      # a pose the robot cannot take is no answer
    return CompensationResult(reached, q, iterations, residual, converged)


def false_target_poses(predict: Callable[[NDArray[np.float64]], NDArray[np.float64]], robot: Robot,
                       poses: NDArray[np.float64], seeds_deg: NDArray[np.float64] | None = None,
                       fixed: tuple[int, ...] = (), *,
                       tol_mm: float = 1e-4, tol_deg: float = 1e-5, length_mm: float = 1000.0,
                       max_iter: int = 50) -> CompensationResult:
    """Full-pose false targets for a joint-angle model ``predict(q_deg) -> (n, 6)`` pose errors.

    The predicted error of a pose is its position error (mm) and the rotation
    vector (radians, base frame) that turns the nominal orientation into the
    real one: the robot commanded to ``q`` reaches ``p(q) + dp`` with the
    orientation ``exp(dr) R(q)``. As :func:`false_target_joints`: the plain
    full-pose IK of every pose from its seed, then damped least-squares steps
    on the whole equation with the model's slope neglected. Poses those
    leave off the tolerances (near a singularity, where the fixed damping
    creeps and the neglected slope matters) are finished by
    Levenberg-Marquardt on the whole equation, the model's slope included,
    with restarts along the self-motion (:func:`~partcal.robot.ik_refine.refine_pose`);
    ``iterations`` counts every step. The commanded
    pose is the nominal pose at the solution (``commanded_mm``,
    ``commanded_rotation``); ``residual_mm`` and ``residual_deg`` are the
    predicted misses; ``singular`` marks the unconverged poses whose solve
    stopped at a singularity (the pose Jacobian's singular values spanning
    more than ``1 / SINGULAR_CONDITIONING``): no joints near the seed's
    posture take the compensated pose.
    """
    poses = checked_poses(poses)
    free, settings = robot.free_joints(fixed), ik_settings(tol_mm, max_iter, 10.0, 0.05, tol_deg=tol_deg,
                                                            length_mm=length_mm)
    positions, rotations = poses[:, :3, 3], poses[:, :3, :3]

    def errors(q):          # the predicted pose errors; a non-finite one moves nothing (and never converges)
        e = np.asarray(predict(q), dtype=float)
        if e.shape != (len(q), 6):
            raise DataError(f"predict must give pose errors of shape ({len(q)}, 6) (mm, then a rotation vector in "
                            f"radians); got shape {e.shape}")
        return np.where(np.isfinite(e).all(axis=1, keepdims=True), e, 0.0)

    q = ik.solve_pose(robot, positions, rotations, robot.checked_seeds(seeds_deg, len(poses)), free, ik.Settings(),
                      1e-8, length_mm)[0]
    q, iterations = ik.solve_pose(robot, positions, rotations, q, free, settings, tol_deg, length_mm, bias=errors)
    left = np.flatnonzero(iterations >= max_iter)         # near a singularity: the whole equation's slope
    if left.size:
        q[left], more = ik_refine.refine_pose(robot, positions[left], rotations[left], q[left], free, settings,
                                              tol_deg, length_mm, bias=errors)
        iterations[left] += more
    nominal = robot.forward(q)
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(np.asarray(predict(q), dtype=float)).all(axis=1)
    at, turned = ik.biased_pose(nominal[:, :3, 3].T, nominal[:, :3, :3], errors(q))
    residual_mm = np.where(finite, np.linalg.norm(at.T - positions, axis=1), np.inf)
    miss_rotvec = rotation_vectors_from_matrices(rotations @ turned.transpose(0, 2, 1))
    residual_deg = np.where(finite, np.degrees(np.linalg.norm(miss_rotvec, axis=1)), np.inf)
    converged = (residual_mm <= tol_mm) & (residual_deg <= tol_deg) & robot.within_limits(q)
    singular = np.zeros(len(q), dtype=bool)
    off = np.flatnonzero(~converged)
    if off.size:
        singular[off] = ik_refine.conditioning(robot, q[off], free, length_mm) < SINGULAR_CONDITIONING
    return CompensationResult(nominal[:, :3, 3], q, iterations, residual_mm, converged,
                              commanded_rotation=nominal[:, :3, :3], residual_deg=residual_deg, singular=singular)


def false_target_cartesian_poses(predict: Callable[[NDArray[np.float64]], NDArray[np.float64]],
                                 poses: NDArray[np.float64], *, tol_mm: float = 1e-4, tol_deg: float = 1e-5,
                                 max_iter: int = 50) -> CompensationResult:
    """Full-pose false targets for a Cartesian model ``predict(positions_mm) -> (n, 6)`` pose errors.

    The pose error is that of :func:`false_target_poses` (position mm, then
    the rotation vector ``r`` in radians, base frame, with ``R_real =
    exp(r) R_commanded``), read at the commanded position alone. So the
    position is the fixed point of :func:`false_target` on the first three
    columns, and the commanded orientation is then exactly
    ``exp(-r(p')) R_target``: its predicted miss ``residual_deg`` is rounding.
    A target is converged when its position is; one without a finite
    prediction at its command keeps the target's orientation as its command,
    with an infinite residual.

    Examples
    --------
    A robot that errs by +1 mm in x and turns 0.01 rad about z everywhere is
    commanded 1 mm short, turned back by 0.01 rad:

    >>> pose = np.eye(4); pose[:3, 3] = [1000.0, 0.0, 500.0]
    >>> r = false_target_cartesian_poses(lambda p: np.tile([1.0, 0, 0, 0, 0, 0.01], (len(p), 1)), pose[None])
    >>> r.commanded_mm, bool(r.converged[0])
    (array([[999.,   0., 500.]]), True)
    >>> np.degrees(np.arctan2(r.commanded_rotation[0, 1, 0], r.commanded_rotation[0, 0, 0])).round(4)
    np.float64(-0.573)
    """
    poses = checked_poses(poses)
    rotations = poses[:, :3, :3]

    def errors(X):
        e = np.asarray(predict(X), dtype=float)
        if e.shape != (len(X), 6):
            raise DataError(f"predict must give pose errors of shape ({len(X)}, 6) (mm, then a rotation vector in "
                            f"radians); got shape {e.shape}")
        return e

    position = false_target(lambda X: errors(X)[:, :3], poses[:, :3, 3], tol_mm=tol_mm, max_iter=max_iter)
    with np.errstate(over="ignore", invalid="ignore"):
        turn = errors(position.commanded_mm)[:, 3:]
    ok = np.isfinite(turn).all(axis=1) & np.isfinite(position.residual_mm)
    turn[~ok] = 0.0
    commanded = matrices_from_rotation_vectors(-turn) @ rotations
    real = matrices_from_rotation_vectors(turn) @ commanded            # what the model says the robot reaches
    miss_rotvec = rotation_vectors_from_matrices(rotations @ real.transpose(0, 2, 1))
    residual_deg = np.where(ok, np.degrees(np.linalg.norm(miss_rotvec, axis=1)), np.inf)
    return dataclasses.replace(position, converged=position.converged & ok & (residual_deg <= tol_deg),
                               commanded_rotation=commanded, residual_deg=residual_deg)


def reachable(robot: Robot, points_mm: NDArray[np.float64], seeds_deg: NDArray[np.float64] | None = None, *,
              tol_mm: float = 1e-6, tries: int = 40) -> NDArray[np.bool_]:
    """Which points ``(n, 3)`` mm the robot's tool reaches with joints inside its limits and constraints.

    Position IK (all joints free) from ``seeds_deg`` (default the home
    pose); points it misses are tried again from up to ``tries - 1`` more
    seeds spread over the joint ranges inside the constraints (drawn once
    from a fixed seed: the same for every call), since damped least squares
    can stop at a limit, or cross a coupled constraint, from one seed and
    not from another.
    """
    points = np.asarray(points_mm, dtype=float)
    return _reached_from_seeds(robot, np.all(np.isfinite(points), axis=1), seeds_deg, tries,
                               lambda todo, start: robot.inverse(points[todo], start, tol_mm=tol_mm).success)


def reachable_poses(robot: Robot, poses: NDArray[np.float64], seeds_deg: NDArray[np.float64] | None = None, *,
                    tol_mm: float = 1e-6, tol_deg: float = 1e-6, tries: int = 40) -> NDArray[np.bool_]:
    """Which tool poses ``(n, 4, 4)`` (mm) the robot takes with joints inside its limits and constraints.

    :func:`reachable` for position and orientation: full-pose IK
    (:meth:`Robot.inverse_pose`, all joints free) from ``seeds_deg`` (default
    the home pose), then from the same further seeds. A robot with fewer than
    six joints takes only some orientations at a point.
    """
    poses = np.asarray(poses, dtype=float)
    return _reached_from_seeds(robot, np.all(np.isfinite(poses), axis=(1, 2)), seeds_deg, tries,
                               lambda todo, start: robot.inverse_pose(poses[todo], start, tol_mm=tol_mm,
                                                                      tol_deg=tol_deg).success)


def _reached_from_seeds(robot: Robot, finite: NDArray[np.bool_], seeds_deg, tries: int,
                        solve: Callable[[NDArray[np.intp], NDArray[np.float64]], NDArray[np.bool_]]
                        ) -> NDArray[np.bool_]:
    """``solve(rows, seeds)`` from the given seeds, then from fixed seeds spread inside the limits, for the
    finite rows it has not reached yet."""
    ok = np.zeros(len(finite), dtype=bool)
    low, high = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    spread = np.random.default_rng(0).uniform(low, high, (64 * tries, len(low)))    # fixed: the same every call
    seeds = [robot.home_deg if seeds_deg is None else seeds_deg, *spread[robot.within_limits(spread)][:tries - 1]]
    for seed in seeds:
        todo = np.flatnonzero(~ok & finite)
        if todo.size == 0:
            break
        ok[todo] = solve(todo, seed if np.ndim(seed) == 1 else np.asarray(seed)[todo])
    return ok
