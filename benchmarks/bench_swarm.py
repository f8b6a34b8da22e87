"""partcal's particle swarm against pyswarms' GlobalBestPSO on the same model fits.

Targets: for 12, 21 and 75 coefficients, partcal's PSO at least 3x (issue 3),
then 10x (issue 13) faster than pyswarms at equal or better RMS ratio to least
squares, at 85 and at 2,000 samples.

The problem: fit an error model to virtual-SK120 errors at 85 configurations
(all six joints moving, so the 2-harmonic Fourier series has 75 coefficients),
one swarm per output axis as ErrorModel does, in the same orthonormal
coefficient coordinates and the same search box. pyswarms gets settings chosen
for its best chance: constriction-equivalent w = 0.7298, c1 = c2 = 1.49618,
50 particles, up to 1000 iterations, early stop with ftol = 1e-10 over 100
iterations (its best feature for speed). It runs twice: with the residual
objective a user would write (cost grows with the samples) and with partcal's
Gram objective (cost independent of the samples), so the table shows both the
optimiser's own speed and the algebraic win.

Run: make bench   (installs pyswarms into .venv for this script only)
"""

import logging
import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402
from _table import print_table  # noqa: E402

from partcal.data.simulate import load_study, sample_configurations  # noqa: E402
from partcal.models.series import ErrorModel  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SEEDS = range(7)
MODELS = [("FDP(CI)", dict(inputs="cartesian", degree=1)),
          ("SDP(CI)", dict(inputs="cartesian", degree=2)),
          ("Fourier r=2 (AI)", dict(inputs="joint", basis="fourier", harmonics=2))]


def virtual_data(n=85, seed=11):
    study = load_study(os.path.join(ROOT, "configs", "sk120_virtual.yaml"))
    vr = study.robot
    rng = np.random.default_rng(seed)
    ranges = {**study.ranges_deg, 4: (-90, 90), 5: (-60, 60)}
    q = sample_configurations(vr.nominal, n, ranges, {}, rng)
    return q, vr.nominal.positions(q), vr.measure(q, rng) - vr.nominal.positions(q)


def pyswarms_fit(model, X, Y, seed, gram):
    """Fit ``model``'s coefficients with pyswarms, axis by axis, as ErrorModel does with partcal."""
    import pyswarms as ps

    ls = ErrorModel(**{**model.get_params(), "solver": "lstsq"}).fit(X, Y)
    phi = ls.basis_.transform(X, ls.scaling_, ls.terms_)
    U, s, Vt = np.linalg.svd(phi, full_matrices=False)
    coef = np.empty_like(ls.coef_)
    np.random.seed(seed)   # pyswarms draws from numpy's global generator
    for a in range(Y.shape[1]):
        y = Y[:, a]
        b, yy, n = U.T @ y, float(y @ y), len(y)
        if gram:
            def fun(Z):
                return np.sqrt(np.maximum(np.einsum("pk,pk->p", Z, Z) - 2 * Z @ b + yy, 0) / n)
        else:
            def fun(Z):
                return np.sqrt(np.mean((y[:, None] - U @ Z.T) ** 2, axis=0))
        half = np.sqrt(yy)
        opt = ps.single.GlobalBestPSO(n_particles=50, dimensions=b.size,
                                      options={"c1": 1.49618, "c2": 1.49618, "w": 0.7298},
                                      bounds=(np.full(b.size, -half), np.full(b.size, half)),
                                      ftol=1e-10, ftol_iter=100)
        _, z = opt.optimize(fun, iters=1000, verbose=False)
        coef[:, a] = (Vt.T / s) @ z
    rms = np.sqrt(np.mean((Y - phi @ coef) ** 2, axis=0))
    return float(np.sqrt((rms**2).sum() / (ls.lstsq_rms_**2).sum()))


def timed(fn):
    start = time.process_time()
    value = fn()
    return time.process_time() - start, value


def main() -> None:
    logging.getLogger("pyswarms").setLevel(logging.ERROR)
    workdir = tempfile.mkdtemp(prefix="bench_swarm_")
    os.chdir(workdir)       # pyswarms writes report.log into the working directory
    rows = []
    for n in (85, 2000):
        q, p, e = virtual_data(n)
        for name, kw in MODELS:
            X = q if kw["inputs"] == "joint" else p
            fits = {
                "partcal": lambda s: ErrorModel(**kw, random_state=s).fit(X, e).rms_ratio_,
                "pyswarms (residuals)": lambda s: pyswarms_fit(ErrorModel(**kw), X, e, s, gram=False),
                "pyswarms (Gram)": lambda s: pyswarms_fit(ErrorModel(**kw), X, e, s, gram=True),
            }
            runs = {label: [] for label in fits}
            for s in SEEDS:          # interleaved, so a slow spell of the machine hits all three alike
                for label, fit in fits.items():
                    runs[label].append(timed(lambda: fit(s)))
            results = {label: (statistics.median(t for t, _ in r), statistics.median(q for _, q in r),
                               max(q for _, q in r)) for label, r in runs.items()}
            n_coef = ErrorModel(**kw, solver="lstsq").fit(X, e).coef_.size
            base, base_ratio, base_worst = results["partcal"]
            for label, (t, ratio, worst) in results.items():
                met = "" if label == "partcal" else (
                    "yes" if t >= 10 * base and base_ratio <= ratio + 1e-12 and base_worst <= worst + 1e-12 else "NO")
                rows.append([n, name, n_coef, label, f"{t * 1e3:.1f}", f"{t / base:.1f}x",
                             f"{ratio:.6f}", f"{worst:.6f}", met])
    print_table("PSO fit of an error model (3 axes, median of 7 seeds, one core)",
                ["samples", "model", "coefs", "optimiser", "ms", "time vs partcal", "RMS ratio", "worst",
                 ">= 10x, ratio as good"], rows)


if __name__ == "__main__":
    main()
