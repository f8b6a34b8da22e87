"""Distances: between two rows' tool tips, or between the tip and a pivot (a ballbar, a draw-wire) (:class:`Distances`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from .fixed_points import FixedPoints
from .measurement import Column, MeasurementType, Residuals, point_unknowns, points_moved, worst_of

UNIT_FACTOR = 30.0
"""A distance this many times shorter or longer than the nominal robot's, where that is at least :data:`LONG_MM`,
is refused: its unit is not mm."""

LONG_MM = 300.0
"""... (shorter nominal distances are not judged: a tool the nominal robot lacks changes them by any factor)."""


class Distances(MeasurementType):
    """The distance between this row's tool tip and another row's (or a pivot's)."""

    name = "distance"
    columns = {"distance_mm": Column("mm", required=True, check=lambda v: None if v > 0 else "a distance > 0 mm"),
               "to": Column(text=True, required=True, refers="points")}
    summary = "|tip - tip of row `to` (or pivot `to`)| - distance_mm (mm)"

    def __init__(self, rows, index, cell, noise):
        super().__init__(rows, index, cell, noise)
        self.measured = rows.number("distance_mm", index)
        targets = rows.text("to", index)
        where = {name: i for i, name in enumerate(rows.ids)}
        fixed = rows.of(FixedPoints.name)
        points = set(cell.get("points") or {}) | (set(rows.text("feature", fixed)) if fixed.size else set())
        self.other = np.full(index.size, -1, dtype=np.intp)
        self.pivot: list[str | None] = []
        for i, (row, to) in enumerate(zip(index, targets)):
            if to in where:
                self.other[i] = where[to]
                self.pivot.append(None)
            elif to in points:
                self.pivot.append(to)
            else:
                raise DataError(f"{rows.where(row)}: column 'to': {to!r} names no row (column 'id') and no point of "
                                "the cell")
            if to in where and where[to] == row:
                raise DataError(f"{rows.where(row)}: column 'to': the row refers to itself")
        bad = np.flatnonzero(~(self.measured > 0))
        if bad.size:
            raise DataError(f"{rows.where(index[bad[0]])}: column 'distance_mm': {self.measured[bad[0]]:g} is not a "
                            "distance; expected a length above 0 mm")
        self.specs = dict(cell.get("points") or {})
        self.pivots = [p for p in dict.fromkeys(x for x in self.pivot if x)
                       if "known_mm" not in self.specs.get(p, {})]

    def unknowns(self, positions, rotations):
        names, start = [], []
        for name in self.pivots:
            mine = np.array([p == name for p in self.pivot])
            names += point_unknowns(name)
            start += list(_sphere_centre(positions[self.index[mine]], self.measured[mine]))
        start = np.array(start)
        between = self.other >= 0         # a pivot's distance is checked by the fit: its place is unknown here
        nominal = np.linalg.norm(positions[self.index[between]] - positions[self.other[between]], axis=1)
        # an unknown tool moves short distances by tens of mm (the IPA UR10's 93 mm reflector against a zero
        # tool: 4.3 mm measured, 37.8 nominal), so only a factor that no tool makes on a long one is refused
        ratio = self.measured[between] / np.maximum(nominal, 1e-9)
        off = (nominal >= LONG_MM) & ((ratio < 1.0 / UNIT_FACTOR) | (ratio > UNIT_FACTOR))
        worst = worst_of(np.abs(np.log(ratio)), off)
        if worst is not None:
            i, count = worst
            row = self.index[between][i]
            raise DataError(f"{self.rows.where(row)}: column 'distance_mm': {self.measured[between][i]:g} mm, but the "
                            f"nominal robot puts the two tips {nominal[i]:.3f} mm apart ({count} distances off by "
                            f"a factor beyond {UNIT_FACTOR:g}): expected the distance in mm (metres?)")
        return names, start

    def residuals(self, positions, rotations, u) -> Residuals:
        m = self.index.size
        ends = positions[np.maximum(self.other, 0)]
        du = np.zeros((m, u.size))
        pivot_cols = np.full(m, -1)
        for i in np.flatnonzero(self.other < 0):                 # a pivot: a point of its own
            pivot = self.pivot[i]
            if pivot in self.pivots:
                pivot_cols[i] = 3 * self.pivots.index(pivot)
                ends[i] = u[pivot_cols[i]:pivot_cols[i] + 3]
            else:
                ends[i] = self.specs[pivot]["known_mm"]
        diff = positions[self.index] - ends
        length = np.linalg.norm(diff, axis=1)
        direction = diff / np.where(length > 0, length, 1.0)[:, None]
        for i in np.flatnonzero(pivot_cols >= 0):
            du[i, pivot_cols[i]:pivot_cols[i] + 3] = -direction[i]
        rows_b = np.where(self.other >= 0, self.other, -1)
        return Residuals(length - self.measured, self.index.copy(), direction, du, rows_b=rows_b,
                         grad_b=-direction)

    def moved(self, u, omega, shift):
        return points_moved(u, omega, shift)          # the pivots

    def notes(self) -> list[str]:
        return ["distance: distances do not fix where the robot stands: the base frame (its place and turn) is "
                "held nominal, and a model from distances alone is scored after a rigid fit"]

    def describe(self) -> str:
        pivots = sorted({p for p in self.pivot if p})
        return f"{self.index.size} distances" + (f" (pivots {', '.join(pivots)})" if pivots else "")


def _sphere_centre(points: NDArray[np.float64], radii: NDArray[np.float64]) -> NDArray[np.float64]:
    """The centre of the sphere through ``points`` at distances ``radii`` (linear least squares:
    ``2 p . c - |c|^2 = |p|^2 - r^2``); the points' mean where they do not fix it."""
    a = np.column_stack([2.0 * points, -np.ones(len(points))])
    b = np.sum(points**2, axis=1) - radii**2
    if len(points) < 4 or np.linalg.matrix_rank(a) < 4:
        return points.mean(axis=0)
    return np.linalg.lstsq(a, b, rcond=None)[0][:3]
