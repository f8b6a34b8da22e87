"""Full-pose compensation near singularities (issue 31): failures, their reasons, time and misses.

The virtual UR10 of configs/ur10_targets_virtual.yaml (DH deviations of 0.5 mm, 0.03 deg twists and
0.05 deg zero offsets, a tool-plate and a base error, a tracker with orientation), 200 identification
poses, and the DH model identified from the positions and the orientation (``use_orientation``). The
targets are nominal tool poses at random joints within the config's sampling ranges, each seeded with
its own joints (as ``partcal compensate`` with ``q1..q6`` columns): "random" draws q5 uniformly in
[-150, 150] degrees; "near wrist" in [-5, 5] (the wrist singularity is q5 = 0). Each is compensated
twice: by the fixed-damping solve alone (what ``Predictor.compensate_pose`` did before, the model's
slope neglected), and by the current solve, which finishes what that leaves with Levenberg-Marquardt on
the whole equation and restarts along the self-motion (partcal.robot.ik_refine).

Columns: targets, failures (and of them |q5| < 5 deg), the reasons of the failures
(``CompensationResult.reasons``), wall time per 1,000 targets (one run; a shared machine disturbs
it), and the largest predicted miss of the converged targets (mm, deg; the tolerances are 1e-4 mm and
1e-5 deg).

Run: .venv/bin/python benchmarks/bench_compensation.py [N]   (N random targets, default 100,000: about
a minute)
"""

import collections
import contextlib
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

import partcal.robot.ik_refine as ik_refine  # noqa: E402
from partcal.data.simulate import load_study, simulate  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.robot.compensation import CompensationWarning  # noqa: E402
from partcal.robot.kinematics import xyz_deg_from_matrices  # noqa: E402
from partcal.study.persist import model_to_dict  # noqa: E402
from partcal.study.predictor import Predictor  # noqa: E402

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "ur10_targets_virtual.yaml"
LOW = np.array([-90.0, -150.0, -140.0, -180.0, -150.0, -180.0])      # the config's sampling ranges, degrees
HIGH = np.array([90.0, -30.0, 140.0, 180.0, 150.0, 180.0])


def predictor() -> Predictor:
    """The DH (pose) model of the virtual UR10, identified from 200 poses."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "ur10.yaml"
        path.write_text(CONFIG.read_text().replace("identification: {sample: 16}", "identification: {sample: 200}")
                        .replace("test: {sample: 400}", "test: {sample: 4}"))
        study = load_study(path)
        ident = simulate(study)["identification"]
    robot = study.robot.nominal
    model = KinematicModel(robot=robot, use_orientation=True).fit(ident.q_deg, ident.pose_errors)
    return Predictor(model, model_to_dict(model, name="DH (pose)", robot=robot), robot)


@contextlib.contextmanager
def fixed_damping_only():
    """The solve as it was: the fixed-damping steps alone, nothing finishes what they leave."""
    kept = ik_refine.refine_pose
    ik_refine.refine_pose = lambda robot, positions, rotations, q, *args, **kwargs: (q, np.zeros(len(q), np.int64))
    try:
        yield
    finally:
        ik_refine.refine_pose = kept


def one_row(p: Predictor, name: str, q: np.ndarray, solver: str) -> list:
    wanted = p.robot.forward(q)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CompensationWarning)
        r = p.compensate_pose(wanted[:, :3, 3], xyz_deg_from_matrices(wanted[:, :3, :3]), q)
    seconds = time.perf_counter() - start
    bad = ~r.converged
    reasons = collections.Counter(w for w in r.reasons(1e-4, 1e-5, p.robot, wanted[:, :3, 3]) if w)
    ok = r.converged
    return [name, solver, len(q), f"{bad.sum()} ({(bad & (np.abs(q[:, 4]) < 5)).sum()})",
            ", ".join(f"{k} {v}" for k, v in sorted(reasons.items())) or "-", f"{1000 * seconds / len(q):.3f}",
            f"{r.residual_mm[ok].max():.2e}", f"{r.residual_deg[ok].max():.2e}"]


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    p = predictor()
    rng = np.random.default_rng(31)
    random = rng.uniform(LOW, HIGH, (n, 6))
    near = rng.uniform(LOW, HIGH, (max(n // 5, 1000), 6))
    near[:, 4] = rng.uniform(-5.0, 5.0, len(near))
    rows = []
    for name, q in (("random", random), ("near wrist", near)):
        with fixed_damping_only():
            rows.append(one_row(p, name, q, "fixed damping (before)"))
        rows.append(one_row(p, name, q, "+ LM and restarts"))
    print_table("Full-pose compensation of a DH (pose) model of the virtual UR10, each target seeded with its joints",
                ["targets", "solve", "n", "failed (|q5|<5)", "reasons", "s / 1000", "max miss mm", "max miss deg"],
                rows)


if __name__ == "__main__":
    main()
