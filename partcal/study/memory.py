"""Memory a run's fits will need, estimated before anything is fitted.

Series and kinematic models need a few arrays of ``n x terms``; a Gaussian
process needs ``n x n`` matrices, which on many samples outgrow any machine
(20,000 poses: a 3.2 GB kernel matrix, and the hyperparameter search holds
one per hyperparameter besides). ``run --check`` and every run estimate the
peak of each Gaussian process's fit here and refuse the config (exit 2) when
it exceeds the memory the machine has available, naming the entry, the
estimate and what to change.

The estimates, in 8-byte numbers, for ``n`` samples with ``d`` inputs:

- hyperparameter search on ``s`` samples (``hyper_samples``; a global GP
  searches on all of them by default): ``(d + 9) s^2`` (the kernel matrix,
  its gradient per hyperparameter, its Cholesky factor, its inverse and the
  per-output products of scikit-learn's likelihood gradient);
- the solve on all of a GP's samples: ``3 n^2`` (kernel, factor, a copy);
- with a partition of ``k`` regions (the smallest of a list; an octree of
  depth ``t`` counts as ``2^t``), each region is taken to hold
  ``min(n, 2 overlap n / k)`` samples: twice its share, for uneven regions.

The folds of cross-validation fit on fewer samples than the final fit, so
the final fit is the peak.
"""

from __future__ import annotations

import math

from .config import ModelSpec, RunConfig

_GB = 1024.0**3


def available_bytes() -> float | None:
    """The memory the machine has available now (Linux ``MemAvailable``), or None when unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        return None
    return None


def gp_peak_bytes(spec: ModelSpec, n: int, d: int) -> tuple[float, int, int]:
    """Peak bytes of a Gaussian-process entry's fit on ``n`` samples of ``d`` inputs, with the search and
    solve sizes it assumed: ``(bytes, search samples, solve samples)``."""
    gp = spec.gp
    solve = n
    if spec.partition is not None:
        size = min(spec.partition.sizes)
        regions = size if spec.partition.method == "kmeans" else 2**size
        solve = min(n, math.ceil(2 * gp.region_overlap * n / max(regions, 1)))
        if gp.hyperparameters == "shared":
            search = int(gp.hyper_samples or min(max(n // 10, 500), 2000))
        else:
            search = int(gp.hyper_samples or solve)
    else:
        search = int(gp.hyper_samples or n)
    search = min(search, n)
    return 8.0 * max((d + 9) * search**2, 3 * solve**2), search, solve


def check_memory(config: RunConfig, n: int, n_joints: int, available: float | None = None) -> None:
    """Refuse the config when a Gaussian process of it needs more memory than ``available`` bytes
    (default: what the machine has available now; unknown means no check)."""
    available = available_bytes() if available is None else available
    if available is None:
        return
    for i, entry in enumerate(config.models):
        spec, key = (entry.residual, f"models[{i}].residual") if entry.kind == "kinematic" else (entry, f"models[{i}]")
        if spec is None or spec.kind != "gaussian_process":
            continue
        d = 3 if spec.inputs == "cartesian" else n_joints
        peak, search, solve = gp_peak_bytes(spec, n, d)
        if peak > available:
            where = f"{key}.hyper_samples" if f"{key}.hyper_samples" in config.lines else key
            if where not in config.lines:
                where = f"models[{i}]"
            config.fail(where, f"{entry.name!r}: its Gaussian process would need about {peak / _GB:.1f} GB "
                               f"(hyperparameter search on {search} samples, solve on {solve}) but the machine has "
                               f"{available / _GB:.1f} GB available: set hyper_samples (e.g. 2000) for the search, "
                               "and a partition (method: kmeans, n_regions) so that each region solves on fewer "
                               "samples (docs/config.md, \"Memory\")")
