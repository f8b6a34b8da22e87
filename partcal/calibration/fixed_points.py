"""Fixed points: the tool tip brought to a point of the cell (a sphere's or cone's centre, a nest) from several
orientations (:class:`FixedPoints`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from .checks import known_length
from .cell import check_ties, entry_form, named_entry, positive_problem, vector3_problem
from .measurement import NEAR_MM, Column, MeasurementType, Residuals, counted, largest_turn_deg, point_unknowns, points_moved, unit_rows, worst_of

POINT_FORMS = (("distance_to", "distance_mm"), ("known_mm",))
"""The keys of each form of a fixed point (tied, known); an unknown point has none."""

BAR_NOISE_MM = 0.001
"""The stated uncertainty of a known length between two fixed points (a calibrated bar), mm."""



class FixedPoints(MeasurementType):
    """The tool tip brought to a fixed point (a sphere's or cone's centre, a nest)."""

    name = "fixed"
    columns = {"feature": Column(text=True, required=True)}
    summary = "the tool tip at fixed point `feature`: 3 residuals (mm)"
    cell_section, feature_column = "points", "feature"

    @classmethod
    def read_section(cls, sec) -> dict:
        """The cell's points: each ``{}`` (unknown), ``{known_mm: [x, y, z]}`` (known in the base frame) or
        ``{distance_to: NAME, distance_mm: d}`` (tied to another by a known distance)."""
        out = {}
        for name in list(sec.data):
            entry = named_entry(sec, name)
            entry_form(entry, POINT_FORMS)
            if entry.has("distance_to") or entry.has("distance_mm"):
                out[name] = {"distance_to": entry.get("distance_to", "str"),
                             "distance_mm": entry.get("distance_mm", "float", check=positive_problem)}
            elif entry.has("known_mm"):
                out[name] = {"known_mm": [float(v) for v in entry.get("known_mm", "list", check=vector3_problem)]}
            else:
                out[name] = {}
            entry.done()
        check_ties(sec, out, "distance_to")
        return out

    def __init__(self, rows, index, cell, noise):
        super().__init__(rows, index, cell, noise)
        self.point = rows.text("feature", index)
        self.specs = dict(cell.get("points") or {})
        self.names = list(dict.fromkeys(self.point))
        for name in self.names:
            mine = self.index[[p == name for p in self.point]]
            known = "known_mm" in self.specs.get(name, {})
            if mine.size < 2 and not known:
                raise DataError(f"{rows.where(mine[0])}: column 'feature': fixed point {name!r} is reached once; an "
                                "unknown point needs visits from at least two orientations (three for the robot "
                                "to learn from it)")

    def unknowns(self, positions, rotations):
        names, start = [], []
        self.unknown = [n for n in self.names if "known_mm" not in self.specs.get(n, {})]
        tied = [n for n, spec in self.specs.items() if "distance_to" in spec and n in self.names]
        for n in tied:
            other = self.specs[n]["distance_to"]
            if other not in self.names and "known_mm" not in self.specs.get(other, {}):
                first = self.index[self.point.index(n)]
                raise DataError(f"{self.rows.where(first)}: column 'feature': fixed point {n!r} is tied to {other!r} "
                                f"by distance_mm (points.{n}.distance_to of the cell), but no row visits "
                                f"{other!r}: visit it too, or list {n!r} as unknown ({n}: {{}})")
        for name in self.unknown:
            names += point_unknowns(name)
            start += list(np.median(positions[self.index[[p == name for p in self.point]]], axis=0))
        self.tied = tied
        start = np.array(start)
        self._check_rows(positions, rotations, start)
        self._check_bars(start)
        return names, start

    def _check_bars(self, u) -> None:
        """Each known distance between two points against the nominal robot's view of it (the medians of their
        visits, or a known point): refused when its unit is another, said when off by more than the nominal
        robot's own errors (:func:`~partcal.calibration.checks.known_length`)."""
        for name in self.tied:
            other = self.specs[name]["distance_to"]
            seen = float(np.linalg.norm(self.centre(name, u)[0] - self.centre(other, u)[0]))
            first = self.index[self.point.index(name)]
            note = known_length(f"points.{name}.distance_mm", self.rows.where(first),
                                float(self.specs[name]["distance_mm"]), seen,
                                f"the nominal robot's visits of {name!r} and {other!r}")
            if note:
                self.suspicions.append(note)

    def _check_rows(self, positions, rotations, u) -> None:
        """Every point reached from more than one orientation, every visit near its point at the nominal robot."""
        for name in self.names:
            mine = self.index[[p == name for p in self.point]]
            if mine.size > 1 and largest_turn_deg(rotations[mine]) < 1.0:
                raise DataError(f"{self.rows.where(mine[0])}: column 'feature': fixed point {name!r} is reached from "
                                f"one orientation of the tool only ({mine.size} visits within 1 degree): visits must "
                                "turn the tool about the point")
        distance = np.linalg.norm(self.residuals(positions, rotations, u).values[:3 * self.index.size]
                                  .reshape(-1, 3), axis=1)
        worst = worst_of(distance, distance > NEAR_MM)
        if worst is not None:
            i, count = worst
            raise DataError(f"{self.rows.where(self.index[i])}: column 'feature': the nominal robot puts this visit "
                            f"{distance[i]:.1f} mm from point {self.point[i]!r} (the median of its visits, or its "
                            f"known_mm; {count} visits beyond {NEAR_MM:g} mm): expected a visit of that point")

    def centre(self, name: str, u: NDArray[np.float64]) -> tuple[NDArray[np.float64], int | None]:
        """Point ``name``'s position and the first of its three unknowns (None when known)."""
        if name in self.unknown:
            k = 3 * self.unknown.index(name)
            return u[k:k + 3], k
        return np.asarray(self.specs[name]["known_mm"], dtype=float), None

    def residuals(self, positions, rotations, u) -> Residuals:
        m = self.index.size
        values, du = np.empty((m, 3)), np.zeros((3 * m, u.size))
        for i, (row, name) in enumerate(zip(self.index, self.point)):
            c, k = self.centre(name, u)
            values[i] = positions[row] - c
            if k is not None:
                du[3 * i:3 * i + 3, k:k + 3] = -np.eye(3)
        which, grad = unit_rows(m)
        out = Residuals(values.ravel(), self.index[which], grad, du, turning=np.ones(3 * m, dtype=bool))
        if not self.tied:
            return out
        bars, bar_du = [], []
        for name in self.tied:
            other = self.specs[name]["distance_to"]
            a, ka = self.centre(name, u)
            b, kb = self.centre(other, u)
            length = np.linalg.norm(a - b)
            direction = (a - b) / length
            scale = self.noise / BAR_NOISE_MM         # weighed as a length known to BAR_NOISE_MM
            bars.append(scale * (length - float(self.specs[name]["distance_mm"])))
            d = np.zeros(u.size)
            if ka is not None:
                d[ka:ka + 3] += scale * direction
            if kb is not None:
                d[kb:kb + 3] -= scale * direction
            bar_du.append(d)
        n = len(bars)
        return Residuals(np.concatenate([out.values, bars]), np.concatenate([out.rows_a, np.full(n, -1)]),
                         np.vstack([out.grad_a, np.zeros((n, 3))]), np.vstack([out.du, bar_du]),
                         turning=np.concatenate([out.turning, np.zeros(n, dtype=bool)]))     # a length does not turn

    def moved(self, u, omega, shift):
        return points_moved(u, omega, shift)

    def describe(self) -> str:
        return f"{self.index.size} visits of {len(self.names)} fixed points ({counted(self.point, self.names)})"
