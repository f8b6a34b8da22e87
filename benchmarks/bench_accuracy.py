"""Global against partitioned models on the virtual SK120: RMS on the three test trajectories.

For each training set (the paper's 85 configurations, and a dense set of 2,000)
and each local basis (FDP and SDP of the Cartesian position, least squares),
the partition granularity is chosen by 5-fold cross-validation on the training
set only; the table gives the 3-D RMS (mm) on the test trajectories, which no
fit has seen. Run: .venv/bin/python benchmarks/bench_accuracy.py
"""

import dataclasses
import os
import sys

sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402
from _table import print_table  # noqa: E402

from partcal.data.simulate import load_study, simulate  # noqa: E402
from partcal.metrics import cross_validated_rms  # noqa: E402
from partcal.models.partition import KMeansPartition, Octree  # noqa: E402
from partcal.models.partitioned import PartitionedErrorModel, select_granularity  # noqa: E402
from partcal.models.series import ErrorModel  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TESTS = ["test_rectangle", "test_spiral_xy", "test_spiral_yz"]


def rms_3d(model, m):
    return float(np.sqrt(np.mean(np.sum((m.errors_mm - model.predict(m.nominal_mm)) ** 2, axis=1))))


def main() -> None:
    study = load_study(os.path.join(ROOT, "configs", "sk120_virtual.yaml"))
    sets = dict(study.datasets) | {"dense": {"sample": 2000}}
    data = simulate(dataclasses.replace(study, datasets=sets))
    rows = [["-", "uncompensated", "-", "-"] + [f"{np.sqrt(np.mean(np.sum(data[t].errors_mm**2, 1))):.2f}"
                                               for t in TESTS]]
    for train_name in ("identification", "dense"):
        train = data[train_name]
        X, y = train.nominal_mm, train.errors_mm
        for degree, label in ((1, "FDP(CI)"), (2, "SDP(CI)")):
            local = ErrorModel(degree=degree, solver="lstsq")
            glob = local.fit(X, y)
            rows.append([f"{train_name} ({len(train)})", f"{label} global", "-",
                         f"{cross_validated_rms(local, X, y):.2f}"] + [f"{rms_3d(glob, data[t]):.2f}" for t in TESTS])
            for spec, grid in ((Octree(), [1, 2, 3]), (KMeansPartition(), [2, 4, 8, 16, 32])):
                template = PartitionedErrorModel(partition=spec, local=local, random_state=0)
                try:
                    best, table = select_granularity(template, X, y, grid)
                except Exception as exc:   # too few samples for any split: report, do not hide
                    rows.append([f"{train_name} ({len(train)})", f"{label} {type(spec).__name__}", "-",
                                 f"({exc})"] + ["-"] * 3)
                    continue
                cv = min(r["cv_rms_3d"] for r in table)
                rows.append([f"{train_name} ({len(train)})", f"{label} {type(spec).__name__}",
                             f"{best.partition_.n_regions} regions", f"{cv:.2f}"]
                            + [f"{rms_3d(best, data[t]):.2f}" for t in TESTS])
    print_table("3-D RMS (mm): global vs partitioned (granularity chosen by 5-fold CV on the training set)",
                ["training set", "model", "partition", "CV RMS"] + TESTS, rows)


if __name__ == "__main__":
    main()
