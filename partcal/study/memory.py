"""Memory a run's fits will need, estimated before anything is fitted.

Series and kinematic models need a few arrays of ``n x terms``; a Gaussian
process needs ``n x n`` matrices, which on many samples outgrow any machine
(20,000 poses: a 3.2 GB kernel matrix, and the hyperparameter search holds
one per hyperparameter besides). ``run --check`` and every run ask each
entry's model for the peak of its fit (``peak_fit_bytes`` of its kind: the
formulas are in ``GaussianProcessErrorModel.peak_fit_bytes``) and refuse the
config (exit 2) when it exceeds the memory the machine has available, naming
the entry, the estimate and what to change. A granularity list is estimated
at its coarsest candidate (the largest regions). The folds of
cross-validation fit on fewer samples than the final fit, so the final fit is
the peak.
"""

from __future__ import annotations

import dataclasses

from .config import RunConfig

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


def check_memory(config: RunConfig, n: int, n_joints: int, available: float | None = None) -> None:
    """Refuse the config when an entry's fit needs more memory than ``available`` bytes
    (default: what the machine has available now; unknown means no check)."""
    available = available_bytes() if available is None else available
    if available is None:
        return
    for i, entry in enumerate(config.models):
        for spec, key in ((entry, f"models[{i}]"), (entry.residual, f"models[{i}].residual")):
            if spec is None:
                continue
            coarsest = min(spec.partition.sizes) if spec.partition is not None else None
            model = dataclasses.replace(spec, residual=None).build(None, coarsest)
            peak, assumed = model.peak_fit_bytes(n, n_joints)
            if peak <= available:
                continue
            where = f"{key}.hyper_samples" if f"{key}.hyper_samples" in config.lines else key
            if where not in config.lines:
                where = f"models[{i}]"
            config.fail(where, f"{entry.name!r}: its fit would need about {peak / _GB:.1f} GB "
                               f"({assumed}) but the machine has {available / _GB:.1f} GB available: set "
                               "hyper_samples (e.g. 2000) for the search, and a partition (method: kmeans, "
                               "n_regions) so that each region solves on fewer samples (docs/config.md, \"Memory\")")
