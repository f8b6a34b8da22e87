"""FK throughput and path IK time for the Motoman SK120 (one core, numpy).

Targets (issue 2): FK >= 1,000,000 poses/s; IK of a 200-point path well under 1 s.
Run: .venv/bin/python benchmarks/bench_kinematics.py
"""

import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402
from _table import best_time, print_table  # noqa: E402

from partcal import load_robot  # noqa: E402
from partcal.robot.trajectories import PATHS, paper_path  # noqa: E402


def main() -> None:
    robot = load_robot("motoman_sk120")
    rng = np.random.default_rng(0)
    rows = []
    for n in (10**3, 10**4, 10**5, 10**6):
        q = rng.uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], size=(n, robot.n_joints))
        t = best_time(lambda: robot.positions(q), repeat=5 if n < 10**6 else 3)
        rows.append([f"{n:,}", f"{t * 1e3:.2f}", f"{n / t:,.0f}"])
    print_table("Forward kinematics, positions (n, 3)", ["poses", "ms", "poses/s"], rows)
    rows = []
    for name in PATHS:
        targets = paper_path(name)
        t = best_time(lambda: robot.inverse_path(targets, fixed=(4, 5)), repeat=3)
        q = robot.inverse_path(targets, fixed=(4, 5))
        err = np.abs(robot.positions(q) - targets).max()
        rows.append([name, len(targets), f"{t * 1e3:.0f}", f"{err:.1e}"])
    print_table("Path inverse kinematics (q4 = q5 = 0 fixed, warm starts)",
                ["path", "points", "ms", "max |FK(IK(p)) - p| mm"], rows)


if __name__ == "__main__":
    main()
