"""Input maps: scaled coordinates for kernels and partitions, with joint angles wrapped.

Gaussian processes and joint-space partitions measure distances between
inputs, so the inputs must be comparable: each input is centred and scaled
to [-1, 1] over its training range (a wrist joint that turns through 300
degrees would otherwise outweigh a shoulder that moves through 60), and
inputs that never moved are left out.

A joint angle is periodic. When the training angles of a joint straddle the
±180 degree seam (say 170..180 and -180..-170), the raw numbers put
neighbours 350 degrees apart. ``InputMap`` then reads that joint in a
360-degree window that starts in the middle of the largest empty arc of the
data, so the data are contiguous in it (here 170..190); queries are mapped
into the same window. A joint whose data are contiguous already is left as
it is. A joint sampled all the way round keeps one seam, placed in its
largest gap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._validation import FieldReader
from .features import varying_inputs


def _window_start(x: NDArray[np.float64]) -> float:
    """Start of the 360-degree window in which angles ``x`` are contiguous, or NaN if raw values are."""
    a = np.sort(np.mod(x, 360.0))
    gaps = np.diff(np.append(a, a[0] + 360.0))            # the empty arc after each sorted angle
    k = int(np.argmax(gaps))
    if x.max() - x.min() <= 360.0 - gaps[k] + 1e-9:     # the raw values already span the shortest arc
        return float("nan")
    return float(np.mod(a[k] + gaps[k] / 2.0, 360.0))


@dataclass(frozen=True)
class InputMap:
    """Per-input wrapping (joint angles only), centring and scaling.

    Attributes
    ----------
    window : ndarray, shape (d,)
        Start of each input's 360-degree window (degrees), NaN where the
        input is used as it is.
    centre, scale : ndarray, shape (d,)
        ``u = (wrapped - centre) / scale`` lies in [-1, 1] on the training data.
    active : ndarray of bool, shape (d,)
        Inputs that vary in the training data; the others are left out.

    Examples
    --------
    >>> m = InputMap.fit(np.array([[175.0, 0.0], [-175.0, 10.0], [179.0, 20.0]]), angles=True)
    >>> m.wrap(np.array([[-179.0, 5.0]])).tolist()          # -179 is 181 in the data's window
    [[181.0, 5.0]]
    >>> m.transform(np.array([[180.0, 10.0]])).tolist()      # the middle of both ranges
    [[0.0, 0.0]]
    """

    window: NDArray[np.float64]
    centre: NDArray[np.float64]
    scale: NDArray[np.float64]
    active: NDArray[np.bool_]

    @classmethod
    def fit(cls, X: NDArray[np.float64], angles: bool) -> "InputMap":
        """Learn the map from training inputs ``X`` (n, d): degrees if ``angles``, else any unit."""
        d = X.shape[1]
        window = np.array([_window_start(X[:, j]) for j in range(d)]) if angles else np.full(d, np.nan)
        wrapped = _wrap(X, window)
        lo, hi = wrapped.min(axis=0), wrapped.max(axis=0)
        active = varying_inputs(wrapped)
        return cls(window, (hi + lo) / 2.0, np.where(active, (hi - lo) / 2.0, 1.0), active)

    @property
    def n_active(self) -> int:
        return int(self.active.sum())

    def wrap(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """``X`` (n, d) with wrapped joints read in their windows (same units); unchanged otherwise."""
        return _wrap(X, self.window)

    def scaled(self, wrapped: NDArray[np.float64]) -> NDArray[np.float64]:
        """Scaled active inputs ``(n, max(1, n_active))`` of already wrapped ``X`` (one zero column if none vary)."""
        if not self.active.any():
            return np.zeros((wrapped.shape[0], 1))
        return (wrapped[:, self.active] - self.centre[self.active]) / self.scale[self.active]

    def transform(self, X: NDArray[np.float64]) -> NDArray[np.float64]:
        """Wrap, then scale: the coordinates kernels and partitions work in."""
        return self.scaled(self.wrap(X))

    def to_dict(self) -> dict:
        return {"window": [None if np.isnan(w) else float(w) for w in self.window],
                "centre": self.centre.tolist(), "scale": self.scale.tolist(), "active": self.active.tolist()}

    @classmethod
    def from_file(cls, m: FieldReader, n_in: int) -> "InputMap":
        """The map a model file keeps (``m`` reads its section), every field checked."""
        window = m.get("window", list)
        if len(window) != n_in or not all(w is None or (isinstance(w, (int, float)) and not isinstance(w, bool)
                                                        and np.isfinite(w)) for w in window):
            m.fail("window", f"expected {n_in} numbers or nulls")
        active = m.get("active", list)
        if len(active) != n_in or not all(isinstance(a, bool) for a in active):
            m.fail("active", f"expected {n_in} true/false values")
        scale = m.array("scale", (n_in,))
        if np.any(scale[np.array(active, dtype=bool)] <= 0):
            m.fail("scale", "the scales of the varying inputs must be > 0")
        return cls(np.array([np.nan if w is None else w for w in window], dtype=float),
                   m.array("centre", (n_in,)), scale, np.array(active, dtype=bool))



def _wrap(X: NDArray[np.float64], window: NDArray[np.float64]) -> NDArray[np.float64]:
    wrapped = ~np.isnan(window)
    if not wrapped.any():
        return X
    out = X.copy()
    low = window[wrapped]
    out[:, wrapped] = low + np.mod(X[:, wrapped] - low, 360.0)
    return out
