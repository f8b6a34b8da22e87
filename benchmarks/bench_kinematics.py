"""Forward kinematics throughput, path IK and joint-model compensation for the Motoman SK120 (one core).

Targets: FK >= 1,000,000 poses/s (issue 2), >= 3,000,000 (issue 13); IK of a
200-point path at least 20x faster than before issue 13, with the same joints;
false targets of a joint-input model at >= 100,000 targets/s (issue 13).
"Before" is partcal 0.1.0's code, kept verbatim in _reference_kinematics.py;
every reference is measured in the same run.
Times are CPU time of this process (time.process_time), robust to other jobs
on a shared machine. Run: .venv/bin/python benchmarks/bench_kinematics.py
"""

import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import _reference_kinematics as before  # noqa: E402
import numpy as np  # noqa: E402
from _table import best_time, print_table  # noqa: E402

from partcal import load_robot, read_measurements  # noqa: E402
from partcal.models.series import ErrorModel  # noqa: E402
from partcal.robot.compensation import false_target_joints  # noqa: E402
from partcal.robot.trajectories import PATHS, paper_path  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def sequential_path(robot, targets):
    """The straightforward path IK: each point from the previous solution, one after the other."""
    q, seed = np.empty((len(targets), robot.n_joints)), robot.home_deg.copy()
    for i in range(len(targets)):
        seed = q[i] = robot.inverse(targets[i:i + 1], seed, fixed=(4, 5)).q_deg[0]
    return q


def nested_false_targets(predict, robot, targets, seeds, fixed, tol_mm=1e-4, max_iter=50):
    """partcal 0.1.0's joint false targets: q <- IK(p - e(q)), a full IK (its old solver) per iteration."""
    free = robot.free_joints(fixed)

    def ik(p, q):
        return before._solve(robot, p, q.copy(), free, 1e-8, 100, 10.0, 0.05)

    q = ik(targets, seeds)
    for _ in range(max_iter):
        active = np.linalg.norm(before.positions(robot, q) + predict(q) - targets, axis=1) > tol_mm
        if not active.any():
            break
        q[active] = ik(targets[active] - predict(q[active]), q[active])
    return q


def main() -> None:
    robot = load_robot("motoman_sk120")
    rng = np.random.default_rng(0)
    rows = []
    for n in (10**3, 10**4, 10**5, 10**6):
        q = rng.uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], size=(n, robot.n_joints))
        repeat = 5 if n < 10**6 else 3
        t_before = best_time(lambda: before.positions(robot, q), repeat=repeat, clock=time.process_time)
        t = best_time(lambda: robot.positions(q), repeat=repeat, clock=time.process_time)
        diff = np.abs(robot.positions(q) - before.positions(robot, q)).max()
        rows.append([f"{n:,}", f"{n / t_before:,.0f}", f"{t * 1e3:.2f}", f"{n / t:,.0f}",
                     "yes" if n / t >= 3e6 else "NO", f"{diff:.0e}"])
    print_table("Forward kinematics, positions (n, 3), one core",
                ["poses", "before poses/s", "ms", "poses/s", ">= 3,000,000/s", "max |diff| mm"], rows)

    rows = []
    free = robot.free_joints((4, 5))
    for name in PATHS:
        targets = paper_path(name)
        t_before = best_time(lambda: before.inverse_path(robot, targets, robot.home_deg.copy(), free), repeat=2,
                             clock=time.process_time)
        t_seq = best_time(lambda: sequential_path(robot, targets), repeat=2, clock=time.process_time)
        t = best_time(lambda: robot.inverse_path(targets, fixed=(4, 5)), repeat=5, clock=time.process_time)
        q = robot.inverse_path(targets, fixed=(4, 5))
        diff = np.abs(q - before.inverse_path(robot, targets, robot.home_deg.copy(), free)).max()
        err = np.abs(robot.positions(q) - targets).max()
        rows.append([name, len(targets), f"{t_before * 1e3:.0f}", f"{t_seq * 1e3:.0f}", f"{t * 1e3:.1f}",
                     f"{t_before / t:.1f}x", "yes" if t_before >= 20 * t else "NO", f"{t_seq / t:.1f}x",
                     f"{diff:.0e}", f"{err:.0e}"])
    print_table("Path IK (q4 = q5 = 0 fixed), one core: before (one point after the other), the same "
                "loop on today's solver, inverse_path",
                ["path", "points", "before ms", "sequential ms", "inverse_path ms", "vs before", ">= 20x",
                 "vs sequential", "max |q - before| deg", "max |FK(q) - p| mm"], rows)

    m = read_measurements(os.path.join(ROOT, "data", "sk120", "identification.csv"))
    model = ErrorModel(inputs="joint", degree=2, solver="lstsq").fit(m.q_deg, m.errors_mm)
    q = m.q_deg[rng.integers(0, len(m.q_deg), 300_000)] + rng.normal(0, 3, (300_000, 6))
    q[:, 3:5] = 0.0
    q = q[robot.within_limits(q)][:100_000]
    targets = robot.positions(q)
    home = np.tile(robot.home_deg, (len(q), 1))
    rows = []
    for n in (10**3, 10**4, 10**5):
        for label, seeds in (("home pose", home), ("measured joints", q)):
            t = best_time(lambda: false_target_joints(model._predict_trusted, robot, targets[:n], seeds[:n], (4, 5)),
                          repeat=3 if n < 10**5 else 1, clock=time.process_time)
            if n == 10**4:
                t_ref = best_time(lambda: nested_false_targets(model._predict_trusted, robot, targets[:n],
                                                               seeds[:n].copy(), (4, 5)), repeat=1,
                                  clock=time.process_time)
                ref = f"{n / t_ref:,.0f}"
            else:
                ref = "-"
            rows.append([f"{n:,}", label, ref, f"{t * 1e3:.1f}", f"{n / t:,.0f}", "yes" if n / t >= 1e5 else "NO"])
    print_table("False targets of SDP(AI), one core (before: a full IK per fixed-point iteration)",
                ["targets", "IK seeds", "before targets/s", "ms", "targets/s", ">= 100,000/s"], rows)


if __name__ == "__main__":
    main()
