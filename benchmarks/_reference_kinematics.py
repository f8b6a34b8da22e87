"""partcal 0.1.0's forward kinematics and path IK, kept verbatim as the "before" of the benchmarks.

The walk with ``np.cos``/``np.sin`` of every row and the Newton solve with
``np.linalg.solve``, one path point after the other, exactly as they were
before issue 13 (commit 7b1737d), so that speed-ups are measured against
them in the same run. Only the benchmarks import this module.
"""

import numpy as np


def _cos_sin_deg(angle_deg):
    rad = np.radians(angle_deg)
    c, s = np.cos(rad), np.sin(rad)
    right = np.isclose(np.mod(angle_deg, 90.0), 0.0) | np.isclose(np.mod(angle_deg, 90.0), 90.0)
    c[right], s[right] = np.round(c[right]), np.round(s[right])
    return c, s


def chain(robot, q_deg, keep_axes=False):
    n = q_deg.shape[0]
    theta = np.radians(robot.theta_offset_deg[:, None] + robot.coupling @ q_deg.T)  # (R, n)
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    ca, sa = _cos_sin_deg(robot.alpha_deg)
    r0, r1, r2 = (np.repeat(robot.base_rotation[:, k, None], n, axis=1) for k in range(3))
    p = np.repeat(robot.base_mm[:, None], n, axis=1)
    axes, origins = [], []
    for row in range(theta.shape[0]):
        if keep_axes:
            axes.append(r2.T)
            origins.append(p.T.copy())
        c, s = cos_t[row], sin_t[row]
        x_new = c * r0 + s * r1
        y_rot = c * r1 - s * r0
        p += robot.a_mm[row] * x_new
        if robot.d_mm[row]:
            p += robot.d_mm[row] * r2
        if sa[row] == 0.0:
            r0, r1, r2 = x_new, ca[row] * y_rot, ca[row] * r2
        elif ca[row] == 0.0:
            r0, r1, r2 = x_new, sa[row] * r2, -sa[row] * y_rot
        else:
            r0, r1, r2 = x_new, ca[row] * y_rot + sa[row] * r2, ca[row] * r2 - sa[row] * y_rot
    if keep_axes:
        axes.append(r2.T)
        origins.append(p.T.copy())
    p += robot.tool_mm[0] * r0 + robot.tool_mm[1] * r1 + robot.tool_mm[2] * r2
    return p.T, np.stack([r0.T, r1.T, r2.T], axis=-1), axes, origins


def positions(robot, q, chunk=4096):
    out = np.empty((q.shape[0], 3))
    for start in range(0, q.shape[0], chunk):
        out[start:start + chunk] = chain(robot, q[start:start + chunk])[0]
    return out


def _position_and_jacobian(robot, q_deg):
    p, _, axes, origins = chain(robot, q_deg, keep_axes=True)
    moving = np.flatnonzero(robot.coupling.any(axis=1))
    z = np.stack([axes[r] for r in moving], axis=-1)
    lever = p[:, :, None] - np.stack([origins[r] for r in moving], axis=-1)
    cross = z[:, [1, 2, 0]] * lever[:, [2, 0, 1]] - z[:, [2, 0, 1]] * lever[:, [1, 2, 0]]
    return p, cross @ robot.coupling[moving] * (np.pi / 180.0)


def _solve(robot, targets, q, free, tol_mm, max_iter, max_step_deg, damping):
    lo, hi = robot.limits_deg[free, 0], robot.limits_deg[free, 1]
    active = np.arange(targets.shape[0])
    for _ in range(max_iter):
        p, jac = _position_and_jacobian(robot, q[active])
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


def inverse_path(robot, targets, seed, free, tol_mm=1e-8):
    """partcal 0.1.0's ``Robot.inverse_path``: each point from the previous solution, one after the other."""
    q = np.empty((targets.shape[0], robot.n_joints))
    for i in range(targets.shape[0]):
        seed = q[i] = _solve(robot, targets[i:i + 1], seed[None].copy(), free, tol_mm, 100, 10.0, 0.05)[0]
    return q
