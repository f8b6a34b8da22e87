"""How much can batching the swarms of many regions gain? A bare swarm loop, numpy and compiled.

Issue 13 asks for a partitioned PSO model's 64 regions to fit their swarms in
one batch at least 5x faster than one by one. bench_partition.py measures
partcal itself; this script measures the bound: a bare loop of the same
per-coordinate operations as partcal's swarm (16-bit uniforms from raw
64-bit words, constriction update, velocity clamp, absorbing walls, a
sum-of-squares fitness, personal and global bests), with no stopping tests,
no results and 200 iterations, for 64 regions x 3 axes = 192 swarms of 50
particles. The batch draws all its random words with one call per
iteration and one problem-sized call otherwise, which favours the batch, so
its speed-up is an upper bound for partcal's.

Four engines:
- numpy: one numpy call per array operation (partcal's own way);
- numpy, float32: the same in single precision (half the bytes per
  operation; partcal works in float64);
- compiled step: the update and the bests as two compiled loops (numba),
  the iterations, random draws and fitness in Python and numpy, as a
  compiled version of partcal's step would be (same random words as the
  numpy loop, so it must find bit for bit the same best: checked);
- compiled loop: the whole run in one compiled call (its random words from
  an inline xorshift64*, as fast as numpy's raw words).

The speed-up of batching is what Python's per-call overhead costs one by one
against the arithmetic per coordinate, which a batch cannot remove. Making
each call cheaper (compiled code) shrinks the first, so the ratio falls.

numba is not a dependency of partcal; `make bench` installs it (with pyswarms)
for the benchmarks only. Without it only the numpy rows are printed.
Run: make bench   or   .venv/bin/python benchmarks/bench_swarm_batch.py
"""

import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402
from _table import best_time, print_table  # noqa: E402

try:
    import numba
except ImportError:          # the numpy rows still run
    numba = None

REGIONS, AXES, PARTICLES, ITERATIONS = 64, 3, 50, 200
CHI, C = 0.7298437881283576, 2.05
PULL = CHI * C * 2.0**-16          # a 16-bit uniform times this is chi c r


def start(dims: int, n_prob: int, seed: int, dtype=np.float64):
    """Positions, velocities, personal bests, bounds and clamps of ``n_prob`` swarms, ``(b, dims, n)``."""
    rng = np.random.default_rng(seed)
    half = rng.uniform(0.5, 2.0, size=(n_prob, dims, 1)) * np.ones((1, 1, PARTICLES))
    lo, hi = -half - rng.uniform(-0.3, 0.3, size=half.shape), half
    lo, hi = lo.astype(dtype), hi.astype(dtype)
    x = rng.uniform(lo, hi).astype(dtype)
    p = x.copy()
    pf = np.einsum("bkp,bkp->bp", x, x)
    return x, np.zeros_like(x), p, pf, lo, hi, (hi - lo) * dtype(0.5)


def numpy_run(dims: int, n_prob: int, seed: int, dtype=np.float64) -> float:
    """The swarm loop as numpy calls; returns the best fitness found (to compare engines)."""
    x, v, p, pf, lo, hi, vmax = start(dims, n_prob, seed, dtype)
    pull, chi = dtype(PULL), dtype(CHI)
    bits = np.random.default_rng(seed + 1).bit_generator
    words = 2 * dims * PARTICLES * n_prob // 4 + 1
    t, r1, r2, mask = np.empty_like(x), np.empty_like(x), np.empty_like(x), np.empty(x.shape, bool)
    rows, vmin = np.arange(n_prob), -vmax
    g = pf.argmin(axis=1)
    for _ in range(ITERATIONS):
        u = bits.random_raw(words).view(np.uint16)[:2 * x.size].reshape((2,) + x.shape)
        np.multiply(u[0], pull, out=r1)
        np.multiply(u[1], pull, out=r2)
        v *= chi
        np.subtract(p, x, out=t)
        t *= r1
        v += t
        np.subtract(p[rows, :, g][:, :, None], x, out=t)
        t *= r2
        v += t
        np.minimum(v, vmax, out=v)
        np.maximum(v, vmin, out=v)
        x += v
        np.maximum(x, lo, out=t)
        np.minimum(t, hi, out=t)
        np.not_equal(t, x, out=mask)
        if np.count_nonzero(mask):
            v[mask] = 0.0
            x, t = t, x
        f = np.einsum("bkp,bkp->bp", x, x)
        better = f < pf
        np.copyto(mask, better[:, None, :])
        np.putmask(p, mask, x)
        np.fmin(pf, f, out=pf)
        g = pf.argmin(axis=1)
    return float(pf.min())


if numba is not None:
    @numba.njit(cache=True)
    def _move(x, v, p, u, g, lo, hi, vmax):
        """One velocity and position update of every swarm (absorbing walls), in place."""
        b, dims, n = x.shape
        size = b * dims * n
        for i in range(b):
            for d in range(dims):
                base = (i * dims + d) * n
                guide = p[i, d, g[i]]
                xr, vr, pr, lr, hr, mr = x[i, d], v[i, d], p[i, d], lo[i, d], hi[i, d], vmax[i, d]
                u1, u2 = u[base:base + n], u[size + base:size + base + n]
                for k in range(n):
                    xv = xr[k]
                    vv = vr[k] * CHI
                    vv += (pr[k] - xv) * (u1[k] * PULL)
                    vv += (guide - xv) * (u2[k] * PULL)
                    vv = max(min(vv, mr[k]), -mr[k])
                    xv += vv
                    xc = min(max(xv, lr[k]), hr[k])
                    vr[k] = vv if xc == xv else 0.0
                    xr[k] = xc

    @numba.njit(cache=True)
    def _bests(x, p, pf, f, g):
        """New personal bests, and every swarm's best particle into ``g``."""
        b, dims, n = x.shape
        for i in range(b):
            for k in range(n):
                if f[i, k] < pf[i, k]:
                    pf[i, k] = f[i, k]
                    for d in range(dims):
                        p[i, d, k] = x[i, d, k]
            best = 0
            for k in range(1, n):
                if pf[i, k] < pf[i, best]:
                    best = k
            g[i] = best

    @numba.njit(cache=True)
    def _whole_run(x, v, p, pf, lo, hi, vmax, seed, iterations):
        """The loop of ``numpy_run`` in one compiled call (raw words from an inline xorshift64*)."""
        b, dims, n = x.shape
        g = np.zeros(b, np.int64)
        f = np.empty((b, n))
        raw = np.empty((2 * b * dims * n) // 4 + 1, np.uint64)
        u = raw.view(np.uint16)
        state = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) | np.uint64(1)
        _bests(x, p, pf, pf.copy(), g)
        for _ in range(iterations):
            for j in range(raw.size):
                state ^= state >> np.uint64(12)
                state ^= state << np.uint64(25)
                state ^= state >> np.uint64(27)
                raw[j] = state * np.uint64(0x2545F4914F6CDD1D)
            _move(x, v, p, u, g, lo, hi, vmax)
            for i in range(b):
                for k in range(n):
                    s = 0.0
                    for d in range(dims):
                        s += x[i, d, k] * x[i, d, k]
                    f[i, k] = s
            _bests(x, p, pf, f, g)
        return pf.min()


def step_run(dims: int, n_prob: int, seed: int) -> float:
    """Compiled update and bests; iterations, random words and fitness in Python and numpy."""
    x, v, p, pf, lo, hi, vmax = start(dims, n_prob, seed)
    bits = np.random.default_rng(seed + 1).bit_generator
    words = 2 * dims * PARTICLES * n_prob // 4 + 1
    g = pf.argmin(axis=1)
    for _ in range(ITERATIONS):
        _move(x, v, p, bits.random_raw(words).view(np.uint16), g, lo, hi, vmax)
        _bests(x, p, pf, np.einsum("bkp,bkp->bp", x, x), g)
    return float(pf.min())


def loop_run(dims: int, n_prob: int, seed: int) -> float:
    x, v, p, pf, lo, hi, vmax = start(dims, n_prob, seed)
    return float(_whole_run(x, v, p, pf, lo, hi, vmax, seed + 1, ITERATIONS))


def main() -> None:
    engines = [("numpy", numpy_run), ("numpy, float32", lambda *a: numpy_run(*a, dtype=np.float32))]
    if numba is None:
        print("numba is not installed: numpy rows only (make bench installs it)")
    else:
        engines += [("compiled step", step_run), ("compiled loop", loop_run)]
        for _, run in engines[2:]:
            run(2, 2, 0)                      # compile (or load numba's cache) before timing
    rows = []
    for dims, label in ((4, "FDP(CI)"), (7, "SDP(CI)")):
        for name, run in engines:
            solo = best_time(lambda: [run(dims, AXES, r) for r in range(REGIONS)], repeat=3, clock=time.process_time)
            batch = best_time(lambda: run(dims, REGIONS * AXES, 0), repeat=3, clock=time.process_time)
            coords = REGIONS * AXES * dims * PARTICLES * ITERATIONS
            same = "-" if name != "compiled step" else ("yes" if run(dims, REGIONS * AXES, 0) == numpy_run(
                dims, REGIONS * AXES, 0) and run(dims, AXES, 5) == numpy_run(dims, AXES, 5) else "NO")
            rows.append([label, dims, name, f"{solo * 1e3:.1f}", f"{batch * 1e3:.1f}", f"{solo / batch:.1f}x",
                         f"{batch / coords * 1e9:.2f}", f"{solo / REGIONS / ITERATIONS * 1e6:.1f}", same])
    print_table(f"A bare swarm loop: {REGIONS} regions x {AXES} axes, {PARTICLES} particles, {ITERATIONS} "
                "iterations, one core (CPU time)",
                ["local model", "coords", "engine", "one by one ms", "batch ms", "batching gain",
                 "batch ns per coord-iteration", "one by one us per region-iteration", "same best as numpy"], rows)


if __name__ == "__main__":
    main()
