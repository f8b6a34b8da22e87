"""Global series models: prediction time against one matmul of the same feature matrix.

Target (issue 13), one core: 10^6 predictions of a global series model within
3x of the time numpy takes for ``Phi @ coef`` alone, with ``Phi`` (10^6, terms)
already built (the straightforward prediction also has to build it); 10^7
points in bounded memory, without a 10^7 x terms matrix.
Models are fitted by least squares on the virtual-SK120 identification data;
the query points fill the training box (the timings do not depend on the values).
Times are CPU time of this process (time.process_time), least disturbed of several runs.
Run: .venv/bin/python benchmarks/bench_predict.py
"""

import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402
from _table import best_time, print_table  # noqa: E402

from partcal import read_measurements  # noqa: E402
from partcal.models.series import ErrorModel  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MODELS = [("FDP(CI)", dict(inputs="cartesian", degree=1)), ("SDP(CI)", dict(inputs="cartesian", degree=2)),
          ("SDP(AI)", dict(inputs="joint", degree=2)),
          ("cubic CI, cross terms", dict(inputs="cartesian", degree=3, cross_terms=True)),
          ("Fourier r=2 (AI)", dict(inputs="joint", basis="fourier", harmonics=2))]


def main() -> None:
    m = read_measurements(os.path.join(ROOT, "data", "sk120", "identification.csv"))
    rng = np.random.default_rng(0)
    rows = []
    for name, kw in MODELS:
        train = m.nominal_mm if kw["inputs"] == "cartesian" else m.q_deg
        model = ErrorModel(**kw, solver="lstsq").fit(train, m.errors_mm)
        X = rng.uniform(train.min(axis=0), train.max(axis=0), size=(10**6, train.shape[1]))
        phi = model.basis_.transform(X, model.scaling_, model.terms_)
        t_ref = best_time(lambda: phi @ model.coef_, repeat=7, clock=time.process_time)
        t_old = best_time(lambda: model.basis_.transform(X, model.scaling_, model.terms_) @ model.coef_, repeat=3,
                          clock=time.process_time)
        t_new = best_time(lambda: model.predict(X), repeat=7, clock=time.process_time)
        err = np.abs(model.predict(X) - phi @ model.coef_).max()
        rows.append([name, phi.shape[1], f"{t_ref * 1e3:.1f}", f"{t_old * 1e3:.1f}", f"{t_new * 1e3:.1f}",
                     f"{t_new / t_ref:.2f}x", "yes" if t_new <= 3 * t_ref else "NO", f"{err:.0e}"])
    print_table("10^6 predictions, one core: predict() against Phi @ coef with Phi already built",
                ["model", "terms", "Phi @ coef ms", "build Phi + product ms", "predict ms", "predict / matmul",
                 "within 3x", "max |diff| mm"], rows)

    model = ErrorModel(degree=2, solver="lstsq").fit(m.nominal_mm, m.errors_mm)
    X = rng.uniform(m.nominal_mm.min(axis=0), m.nominal_mm.max(axis=0), size=(10**7, 3))
    t = best_time(lambda: model.predict(X), repeat=3, clock=time.process_time)
    tracemalloc.start()
    out = model.predict(X)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    phi_mb = X.shape[0] * len(model.terms_) * 8 / 2**20
    print_table("10^7 predictions, SDP(CI): memory beyond the output",
                ["points", "predict s", "predictions/s", "output MB", "peak allocated MB", "a Phi would be MB"],
                [[f"{X.shape[0]:,}", f"{t:.3f}", f"{X.shape[0] / t:,.0f}", f"{out.nbytes / 2**20:.0f}",
                  f"{peak / 2**20:.0f}", f"{phi_mb:.0f}"]])


if __name__ == "__main__":
    main()
