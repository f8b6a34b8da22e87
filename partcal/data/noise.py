"""A noise model of the measuring instrument: each measured coordinate's standard deviation.

A tracker's noise is a constant part plus one growing with the distance from the instrument (its
repeatability in ppm). ``data.noise: {constant_mm: 0.01, ppm: 10, instrument_mm: [x, y, z]}`` of a run
config gives every point of a data set without its own ``std_x, std_y, std_z`` columns the standard
deviation ``constant_mm + ppm * 1e-6 * |p - instrument|`` on each coordinate; registration and kinematic
identification then weigh the rows by it (docs/models.md, "Weights and robust fitting").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array


@dataclass(frozen=True)
class NoiseModel:
    """``std = constant_mm + ppm * 1e-6 * distance`` per coordinate, the distance from ``instrument_mm``.

    Parameters
    ----------
    constant_mm : float >= 0
    ppm : float >= 0
        The part growing with the distance, parts per million (at least one of the two > 0).
    instrument_mm : tuple of 3 floats
        The instrument's position in the frame of the measured points (the file's: the tracker's own frame,
        its origin, with ``frame: tracker``), mm.

    Examples
    --------
    >>> NoiseModel(0.01, 10.0, (0.0, 0.0, 0.0)).std_of(np.array([[3000.0, 0.0, 4000.0]])).tolist()
    [[0.06, 0.06, 0.06]]
    """

    constant_mm: float
    ppm: float
    instrument_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def std_of(self, measured_mm: NDArray[np.float64]) -> NDArray[np.float64]:
        """The standard deviation of each coordinate of points ``measured_mm`` (n, 3) mm: shape (n, 3), mm."""
        p = check_array(measured_mm, "measured_mm", columns=3)
        distance = np.linalg.norm(p - np.asarray(self.instrument_mm, dtype=float), axis=1)
        return np.repeat((self.constant_mm + self.ppm * 1e-6 * distance)[:, None], 3, axis=1)

    def to_dict(self) -> dict:
        return {"constant_mm": self.constant_mm, "ppm": self.ppm, "instrument_mm": list(self.instrument_mm)}
