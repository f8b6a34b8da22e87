"""Error statistics: RMS per axis, 3-D RMS, maximum and percentiles of the error norm (mm)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def rms_per_axis(errors_mm: NDArray[np.float64]) -> NDArray[np.float64]:
    """Root mean square of each column, shape (3,).

    >>> rms_per_axis(np.array([[3.0, 0, 1], [-3.0, 0, 1]])).tolist()
    [3.0, 0.0, 1.0]
    """
    return np.sqrt(np.mean(np.square(errors_mm), axis=0))


def summary(errors_mm: NDArray[np.float64]) -> dict:
    """``{"rms": [x, y, z], "rms_3d", "max_3d", "p95_3d"}`` of an ``(n, 3)`` error array, in mm.

    >>> summary(np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0]]))["rms_3d"]
    3.5355339059327378
    """
    norms = np.linalg.norm(errors_mm, axis=1)
    return {
        "rms": rms_per_axis(errors_mm).tolist(),
        "rms_3d": float(np.sqrt(np.mean(np.square(norms)))),
        "max_3d": float(norms.max()),
        "p95_3d": float(np.percentile(norms, 95)),
    }
