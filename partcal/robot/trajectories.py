"""The paper's test trajectories (section 7), as Cartesian target points in mm.

Trajectory I is a rectangle of four straight sides of 50 points each;
trajectories II and III are Archimedes spirals ``r = phi`` scaled by ``W``
(eqs. 21-22), with ``phi`` from 0 in steps of ``5 pi / 200`` (200 points),
drawn in the X-Y plane while z rises linearly, and in the Y-Z plane while x
rises linearly. The paper gives the start points; the rectangle's sides and
the spirals' rise are not given and are chosen here (see ``docs/virtual_robot.md``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import ConfigError

PATHS = ("rectangle", "spiral_xy", "spiral_yz")
DEFAULT_STARTS = {"rectangle": (1100.0, 800.0, 600.0), "spiral_xy": (1200.0, -600.0, 600.0),
                  "spiral_yz": (500.0, 500.0, 1400.0)}


def rectangle(start_mm=DEFAULT_STARTS["rectangle"], side1_mm=(0.0, -1200.0, 0.0),
              side2_mm=(-200.0, 0.0, 500.0), points_per_side: int = 50) -> NDArray[np.float64]:
    """Corners ``start, start+side1, start+side1+side2, start+side2``; shape (4 * points_per_side, 3).

    Each side starts at its corner and stops one step before the next one, so
    no point is repeated.

    >>> path = rectangle()
    >>> path.shape, path[0].tolist(), path[50].tolist()
    ((200, 3), [1100.0, 800.0, 600.0], [1100.0, -400.0, 600.0])
    """
    start, u, v = (check_array(np.reshape(x, (1, 3)), name, columns=3)[0]
                   for x, name in ((start_mm, "start_mm"), (side1_mm, "side1_mm"), (side2_mm, "side2_mm")))
    corners = np.array([start, start + u, start + u + v, start + v, start])
    t = np.arange(points_per_side)[:, None] / points_per_side
    return np.vstack([corners[i] + t * (corners[i + 1] - corners[i]) for i in range(4)])


def spiral(start_mm, plane: str = "xy", rise_mm: float = 400.0, scale_mm: float = 20.0,
           n_points: int = 200, turns_rad: float = 5 * np.pi) -> NDArray[np.float64]:
    """Archimedes spiral ``r = phi``, ``(u, v) = start + W r (cos phi, sin phi)``.

    Parameters
    ----------
    start_mm : array-like, shape (3,)
        The first point (at ``phi = 0``, where ``r = 0``).
    plane : {"xy", "yz"}
        The plane of the spiral; the remaining axis rises linearly by ``rise_mm``.
    scale_mm : float
        The enlargement factor ``W``.

    >>> path = spiral((1200, -600, 600), "xy")
    >>> path.shape, path[0].tolist()
    ((200, 3), [1200.0, -600.0, 600.0])
    """
    axes = {"xy": (0, 1, 2), "yz": (1, 2, 0)}
    if plane not in axes:
        raise ConfigError(f"spiral plane must be 'xy' or 'yz'; got {plane!r}")
    u, v, w = axes[plane]
    phi = np.arange(n_points) * (turns_rad / n_points)
    out = np.tile(np.asarray(start_mm, dtype=float), (n_points, 1))
    out[:, u] += scale_mm * phi * np.cos(phi)
    out[:, v] += scale_mm * phi * np.sin(phi)
    out[:, w] += np.linspace(0.0, rise_mm, n_points)
    return out


def paper_path(name: str, start_mm=None) -> NDArray[np.float64]:
    """One of the paper's three test paths by name (``rectangle``, ``spiral_xy``, ``spiral_yz``)."""
    if name not in PATHS:
        raise ConfigError(f"unknown path {name!r}; expected one of {', '.join(PATHS)}")
    start = DEFAULT_STARTS[name] if start_mm is None else start_mm
    if name == "rectangle":
        return rectangle(start)
    return spiral(start, name[-2:])
