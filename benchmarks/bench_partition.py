"""Partitioned models: fit time and prediction throughput against samples and regions.

Targets (issue 4), one core: 10^6 predictions in under 2 s for 64 blended SDP
regions; fitting 10^5 samples into 64 regions in under 10 s. Issue 13: the
swarms of a PSO model's 64 regions run as one vectorised batch, at least 5x
faster than fitting the regions one by one (same seeds, identical results).
Data: a smooth synthetic error field over a 2 x 2 x 2 m workspace (the
timings do not depend on the values). Local models: SDP(CI) by least squares.
Run: .venv/bin/python benchmarks/bench_partition.py
"""

import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402
from _table import best_time, print_table  # noqa: E402
from sklearn.base import clone  # noqa: E402

from partcal.models.partition import KMeansPartition, Octree  # noqa: E402
from partcal.models.partitioned import PartitionedErrorModel, _fit_regions  # noqa: E402
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
    regional_swarms()


def regional_swarms() -> None:
    """PSO local models: every region's swarms in one batch against the regions fitted one by one."""
    rows = []
    for n, depth in ((100_000, 2), (20_000, 2)):
        X, y = field(n)
        for label, degree in (("FDP(CI)", 1), ("SDP(CI)", 2)):
            local = ErrorModel(degree=degree)
            m = PartitionedErrorModel(partition=Octree(max_depth=depth), local=local, random_state=0)
            t_model = best_time(lambda: m.fit(X, y), repeat=1)
            groups = m._training_groups(m.partition_, X)
            seeds = [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(0).spawn(len(groups))]
            data = [(X[idx], y[idx], w) for idx, w in groups]

            def one_by_one():
                return [clone(local).set_params(random_state=s)._fit(*d) for s, d in zip(seeds, data)]

            def batched():
                return _fit_regions([clone(local).set_params(random_state=s) for s in seeds], data, None)

            t_solo = best_time(one_by_one, repeat=2)
            t_batch = best_time(batched, repeat=2)
            same = all(np.array_equal(a.coef_, b.coef_) for a, b in zip(one_by_one(), batched()))
            rows.append([f"{n:,}", label, len(groups), f"{t_solo:.3f}", f"{t_batch:.3f}", f"{t_solo / t_batch:.1f}x",
                         "yes" if same else "NO", f"{t_model:.2f}"])
    print_table("PSO regions (octree depth 2, gaussian blend): swarms one by one vs one batch, one core",
                ["samples", "local", "regions", "one by one s", "batched s", "speed-up", "identical coef",
                 "whole fit s"], rows)


if __name__ == "__main__":
    main()
