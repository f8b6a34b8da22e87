"""Shared fixtures and paths."""

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
# Shared reference data sets live in ../shared beside the repository (never copied into it); a git
# worktree one level deeper finds them by looking further up.
SHARED = next((p / "shared" for p in ROOT.parents if (p / "shared" / "datasets").is_dir()), ROOT.parent / "shared")


@pytest.fixture(scope="session")
def sk120():
    from partcal import load_robot

    return load_robot("motoman_sk120")


def smoothstep(r):
    """The blend cutoff written out: 1 below 2, 0 above 3, 10 t^3 - 15 t^4 + 6 t^5 between (t = 3 - r)."""
    import numpy as np

    t = np.clip(3.0 - r, 0.0, 1.0)
    return 10 * t**3 - 15 * t**4 + 6 * t**5


def brute_force_weights(partition, X):
    """Blend weights over ALL kernels, (n, M), straight from the definition in ``blending``'s docstring."""
    import numpy as np

    axes = partition.active
    z = (X[:, None, axes] - partition.centres[None][..., axes]) / partition.sigmas[None][..., axes]
    r2 = np.sum(z * z, axis=2)
    r = np.sqrt(r2)
    r_min = r.min(axis=1, keepdims=True)
    shift = np.maximum(0.0, r_min - 2.5)
    raw = np.exp(-(r2 - r_min**2) / 2) * smoothstep(r - shift)
    return raw / raw.sum(axis=1, keepdims=True)


def brute_force_blend(model, X):
    """A blended model's prediction as the weighted sum of every region model's own ``predict``."""
    import numpy as np

    local, coordinates = model._coordinates(X)      # joint inputs: wrapped for the models, scaled for the kernels
    W = brute_force_weights(model.partition_, coordinates)
    out = 0.0
    for k, region in enumerate(model.partition_.kernel_region):
        if W[:, k].any():
            out = out + W[:, k, None] * np.asarray(model.models_[region].predict(local)).reshape(len(X), -1)
    return out


def partcal_cli(*args, cwd=None):
    """``python -m partcal ARGS`` in a child process: its exit code, stdout and stderr."""
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "partcal", *args], capture_output=True, text=True, cwd=cwd)


def write_text(tmp_path, text, name):
    """Write ``text`` to ``tmp_path / name``; return the path."""
    path = tmp_path / name
    path.write_text(text)
    return path


def small_contact_cell(folder, *, touches: int, side: int, visits: int = 50, poses: int = 30):
    """The shipped virtual contact cell's config (configs/ur10_contacts_virtual.yaml) made smaller and written to
    ``folder / "virtual.yaml"``: ``touches`` on the top and step planes each, ``side`` on the side plane,
    ``visits`` to each fixed point, a ballbar of ``poses`` poses; its data go to ``folder / "data"``."""
    text = (ROOT / "configs" / "ur10_contacts_virtual.yaml").read_text()
    for old, new in (("output: ../data/ur10_contacts", "output: data"),
                     ("plane: {top: 300, step: 300, side: 200}",
                      f"plane: {{top: {touches}, step: {touches}, side: {side}}}"),
                     ("fixed: {nest_a: 50, nest_b: 50, sphere: 50, cone: 50}",
                      f"fixed: {{nest_a: {visits}, nest_b: {visits}, sphere: {visits}, cone: {visits}}}"),
                     ("pairs: all, poses: 100", f"pairs: all, poses: {poses}")):
        assert old in text, old
        text = text.replace(old, new)
    path = folder / "virtual.yaml"
    path.write_text(text)
    return path


DH_FIELDS = ("theta_offset_deg", "d_mm", "a_mm", "alpha_deg")


def tilted_dh_chain(q_deg, d_mm, a_mm, alpha_rad, offset_deg, tilts_deg, start=None):
    """Poses (n, 4, 4) of a chain of standard DH rows written out as 4 x 4 matrices (independently of
    partcal's walk), ``start @ row_1 @ ... @ row_R``, with a turn about y of ``tilts_deg[r]`` degrees ending
    row ``r`` (0-based) where given: tilts between parallel axes, which DH rows cannot hold."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    out = np.tile(np.eye(4) if start is None else start, (len(q_deg), 1, 1))
    for r in range(len(d_mm)):
        t = np.radians(q_deg[:, r] + offset_deg[r])
        row = np.zeros((len(q_deg), 4, 4))
        ct, st, ca, sa = np.cos(t), np.sin(t), np.cos(alpha_rad[r]), np.sin(alpha_rad[r])
        row[:, 0] = np.column_stack([ct, -st * ca, st * sa, a_mm[r] * ct])
        row[:, 1] = np.column_stack([st, ct * ca, -ct * sa, a_mm[r] * st])
        row[:, 2, 1:] = [sa, ca, d_mm[r]]
        row[:, 3, 3] = 1.0
        out = out @ row
        if r in tilts_deg:
            out[:, :3, :3] = out[:, :3, :3] @ Rotation.from_euler("y", tilts_deg[r], degrees=True).as_matrix()
    return out


def assert_jacobian_is_the_central_difference(robot, q_deg, h):
    """``robot.jacobian(q_deg)`` (n, 3, N) equals the central differences of ``robot.positions`` with each
    joint moved by ``+-h`` degrees, to 1e-6 mm/deg."""
    import numpy as np

    for j in range(robot.n_joints):
        step = np.zeros(robot.n_joints)
        step[j] = h
        numeric = (robot.positions(q_deg + step) - robot.positions(q_deg - step)) / (2 * h)
        np.testing.assert_allclose(robot.jacobian(q_deg)[:, :, j], numeric, atol=1e-6, err_msg=f"joint {j + 1}")


def moved_positions(robot, q_deg, k, step):
    """Forward kinematics with geometric parameter ``k`` moved by ``step``, written out from the robot's
    fields (for central differences): four DH fields per row, then the tool's x, y, z (mm), then the
    base's x, y, z (mm) and small base turns about x, y, z (degrees)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    rows = robot.alpha_deg.size
    if k < 4 * rows:
        row, field = divmod(k, 4)
        values = getattr(robot, DH_FIELDS[field]).copy()
        values[row] += step
        return robot.replace(**{DH_FIELDS[field]: values}).positions(q_deg)
    if k < 4 * rows + 3:
        tool = robot.tool_mm.copy()
        tool[k - 4 * rows] += step
        return robot.replace(tool_mm=tool).positions(q_deg)
    shift = np.zeros(3)
    shift[(k - 4 * rows - 3) % 3] = step
    p = robot.positions(q_deg)
    return p + shift if k < 4 * rows + 6 else p @ Rotation.from_rotvec(np.radians(shift)).as_matrix().T


def random_row_prior(v0, seed: int = 4):
    """``(index, mean, cov)`` of a Gaussian prior on the 24 DH rows' parameters of a 6-joint robot (nominal values
    ``v0``): a random full covariance (lengths looser than angles) and a mean off nominal, for MAP tests."""
    index = np.arange(24)
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(24, 24)) * 0.05
    cov = a @ a.T + np.diag(np.where(np.isin(np.arange(24) % 4, (1, 2)), 0.3, 0.03) ** 2)
    return index, v0[index] + rng.normal(size=24) * 0.1, cov


def own_string(text: str) -> str:
    """``text`` (two characters or more: CPython keeps one object per single character) as a string object of its
    own, as each cell of a file is, never the interned literal: what a test of ``==`` against ``is`` needs."""
    assert len(text) > 1
    return "".join(list(text))
