"""Partitioned models: fit time and prediction throughput against samples and regions.

Targets (issue 4), one core: 10^6 predictions in under 2 s for 64 blended SDP
regions; fitting 10^5 samples into 64 regions in under 10 s.
Data: a smooth synthetic error field over a 2 x 2 x 2 m workspace (the
timings do not depend on the values). Local models: SDP(CI) by least squares.
Run: .venv/bin/python benchmarks/bench_partition.py
"""

import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402
from _table import best_time, print_table  # noqa: E402

from partcal.models.partition import KMeansPartition, Octree  # noqa: E402
from partcal.models.partitioned import PartitionedErrorModel  # noqa: E402
from partcal.models.series import ErrorModel  # noqa: E402

LOW, HIGH = np.array([-1000.0, -1000, -500]), np.array([1000.0, 1000, 1500])


def field(n, seed=0):
    X = np.random.default_rng(seed).uniform(LOW, HIGH, size=(n, 3))
    return X, np.c_[np.sin(X[:, 0] / 300), np.cos(X[:, 1] / 400), X[:, 2] / 1000 * np.sin(X[:, 0] / 500)]


def model(spec, blend="gaussian"):
    return PartitionedErrorModel(partition=spec, local=ErrorModel(degree=2, solver="lstsq"), blend=blend,
                                 random_state=0)


def main() -> None:
    X, y = field(100_000)
    rows = []
    for label, spec in [("octree depth 0", Octree(max_depth=0)), ("octree depth 1", Octree(max_depth=1)),
                        ("octree depth 2", Octree(max_depth=2)), ("octree depth 3", Octree(max_depth=3)),
                        ("k-means 8", KMeansPartition(8)), ("k-means 64", KMeansPartition(64))]:
        for blend in ("gaussian", "hard"):
            m = model(spec, blend)
            t_fit = best_time(lambda: m.fit(X, y), repeat=1)
            Xq, _ = field(10**6, seed=1)
            t_pred = best_time(lambda: m.predict(Xq), repeat=2)
            rows.append([label, blend, m.partition_.n_regions, f"{t_fit:.2f}", f"{t_pred:.2f}",
                         f"{1e6 / t_pred:,.0f}"])
    print_table("Regions: fit 10^5 samples, predict 10^6 points (SDP local models)",
                ["partition", "blend", "regions", "fit s", "predict s", "predictions/s"], rows)
    rows = []
    for n in (10**3, 10**4, 10**5, 10**6):
        Xn, yn = field(n)
        m = model(Octree(max_depth=2))
        t_fit = best_time(lambda: m.fit(Xn, yn), repeat=1)
        t_pred = best_time(lambda: m.predict(Xn), repeat=2)
        rows.append([f"{n:,}", m.partition_.n_regions, f"{t_fit:.3f}", f"{t_pred:.3f}", f"{n / t_pred:,.0f}"])
    print_table("Samples: octree depth 2, blended (fit n samples, predict the same n)",
                ["samples", "regions", "fit s", "predict s", "predictions/s"], rows)


if __name__ == "__main__":
    main()
