"""Plane contacts: the probe tip on a plane of the cell, and a flat face of the tool lying on it (:class:`PlaneContacts`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from .checks import known_length
from .cell import check_ties, entry_form, finite_problem, named_entry, unit_vector
from .measurement import NEAR_MM, Column, MeasurementType, Residuals, counted, largest_turn_deg, worst_of

PLANE_FORMS = (("parallel_to", "spacing_mm"), ("normal", "offset_mm"))
"""The keys of each form of a plane (tied, approximately known); an unknown plane has none."""

GIVEN_NORMAL_DEG = 10.0
"""A plane whose nominal touches put its normal farther than this from the cell's approximate normal is refused."""

FACE_RADIUS_MM = 50.0
"""A flush contact's tilt residual: the rise of the rim of a face of this radius, mm per radian."""


class PlaneContacts(MeasurementType):
    """The probe tip on a plane (and, flush, a face of the tool lying on it)."""

    name = "plane"
    columns = {"feature": Column(text=True, required=True),
               "flush": Column(check=lambda v: None if v in (0, 1) else "0 or 1 (1: a flat face of the tool lies on "
                                                                       "the plane), or empty")}
    summary = "the tool tip touches plane `feature`: its distance to the plane (mm); flush adds two tilts"
    cell_section, feature_column = "planes", "feature"

    @classmethod
    def read_section(cls, sec) -> dict:
        """The cell's planes: each ``{}`` (unknown), ``{normal: [nx, ny, nz], offset_mm: d}`` (approximately
        known: ``n . p = d`` in the base frame, the fit's start) or ``{parallel_to: NAME, spacing_mm: s}`` (tied:
        that plane's normal, its offset plus ``s``)."""
        out = {}
        for name in list(sec.data):
            entry = named_entry(sec, name)
            entry_form(entry, PLANE_FORMS)
            if entry.has("parallel_to") or entry.has("spacing_mm"):
                out[name] = {"parallel_to": entry.get("parallel_to", "str"),
                             "spacing_mm": entry.get("spacing_mm", "float", check=finite_problem)}
            elif entry.has("normal") or entry.has("offset_mm"):
                out[name] = {"normal": unit_vector(entry, "normal"),
                             "offset_mm": entry.get("offset_mm", "float", check=finite_problem)}
            else:
                out[name] = {}
            entry.done()
        check_ties(sec, out, "parallel_to")
        return out

    def __init__(self, rows, index, cell, noise):
        super().__init__(rows, index, cell, noise)
        self.plane = rows.text("feature", index)
        flush = rows.numbers.get("flush")
        self.flush = np.zeros(index.size, dtype=bool) if flush is None else np.nan_to_num(
            np.asarray(flush, dtype=float)[index]) > 0.5
        self.needs_orientation = bool(self.flush.any())         # the tool's turn enters flush rows alone
        self.specs = dict((cell.get("planes") or {}))
        self.names = list(dict.fromkeys(self.plane))
        for name in self.names:
            spec = self.specs.setdefault(name, {})
            root = spec.get("parallel_to")
            if root is not None and root not in self.specs:
                raise DataError(f"plane {name!r}: parallel_to {root!r} is not a plane of the cell")
        self._check()

    def _check(self) -> None:
        """Enough touches from more than one orientation on every plane with unknowns."""
        for name in self.names:
            mine = self.index[[p == name for p in self.plane]]
            spec = self.specs[name]
            need = 0 if "parallel_to" in spec else 3
            if mine.size < max(need, 1):
                raise DataError(f"{self.rows.where(mine[0])}: column 'feature': plane {name!r} has {mine.size} "
                                f"touches; its {need} unknowns (two tilts and an offset) need at least {need}")

    def _root(self, name: str) -> tuple[str, float]:
        """The plane whose normal and offset ``name`` follows, and the spacing added to the offset."""
        spacing = 0.0
        seen = {name}
        while "parallel_to" in self.specs[name]:
            spacing += float(self.specs[name].get("spacing_mm", 0.0))
            name = self.specs[name]["parallel_to"]
            if name in seen:
                raise DataError(f"planes: parallel_to makes a cycle through {name!r}")
            seen.add(name)
        return name, spacing

    def unknowns(self, positions, rotations):
        roots = list(dict.fromkeys(self._root(n)[0] for n in self.names))
        self.frames, names, start = {}, [], []
        for root in roots:
            spec = self.specs.get(root, {})
            members = [n for n in self.names if self._root(n)[0] == root]
            if "normal" in spec:
                normal, offset = self._started(root, members, positions, spec)
            else:
                normal, offset = self._fitted_plane(root, members, positions)
            if not np.isfinite(offset):
                tips = positions[self.index[[self._root(p)[0] == root for p in self.plane]]]
                spacing = np.array([self._root(p)[1] for p in self.plane if self._root(p)[0] == root])
                offset = float(np.mean(tips @ normal - spacing))
            axis = int(np.argmax(np.abs(normal)))
            pole = np.sign(normal[axis]) * np.eye(3)[axis]
            t1, t2 = (np.eye(3)[i] for i in range(3) if i != axis)
            self.frames[root] = (pole, t1, t2)
            label = f"{'+' if pole[axis] > 0 else '-'}{'xyz'[axis]}"
            names += [(f"plane {root}.{'xyz'[i]}/{label}", "1") for i in range(3) if i != axis]
            names.append((f"plane {root}.offset", "mm"))
            start += [float(normal @ t1 / (normal @ pole)), float(normal @ t2 / (normal @ pole)), offset]
        self.roots = roots
        start = np.array(start)
        self._check_spacings(positions, start)     # first: a spacing in metres puts every touch far from its plane
        self._check_rows(positions, rotations, start)
        return names, start

    def _check_spacings(self, positions, u) -> None:
        """Each known spacing between two touched planes against the nominal robot's view of it (the mean distance
        of their touches along the normal): refused when its unit is another, said when off by more than the
        nominal robot's own errors (:func:`~partcal.calibration.checks.known_length`)."""
        for name in self.names:
            parent = self.specs[name].get("parallel_to")
            if parent is None or parent not in self.names:
                continue
            normal = self._plane(self._root(name)[0], u)[0]
            mine, theirs = ([self.index[[p == n for p in self.plane]]] for n in (name, parent))
            seen = float(np.mean(positions[mine[0]] @ normal) - np.mean(positions[theirs[0]] @ normal))
            note = known_length(f"planes.{name}.spacing_mm", self.rows.where(mine[0][0]),
                                float(self.specs[name].get("spacing_mm", 0.0)), seen,
                                f"the nominal robot's touches of {name!r} and {parent!r}")
            if note:
                self.suspicions.append(note)

    def moved(self, u, omega, shift):
        """A root plane's normal turns with the cell (its slopes change accordingly) and its offset shifts by the
        shift's part along the normal (a turn about the origin changes no offset)."""
        out = np.zeros_like(u)
        for k, root in enumerate(self.roots):
            normal = self._plane(root, u)[0]
            pole, t1, t2 = self.frames[root]
            turned, across = np.cross(omega, normal), normal @ pole
            for j, t in enumerate((t1, t2)):
                out[3 * k + j] = turned @ t / across - (normal @ t) * (turned @ pole) / across**2
            out[3 * k + 2] = normal @ shift
        return out

    def scaled_lengths(self, start):
        """A root plane's offset scales with the planes of its group that are touched: when they are all one plane
        (one spacing: the plane tied to it touched alone), that plane's offset ``offset + spacing`` scales and
        the spacing measures no length; touched planes of two spacings make the spacing a known length."""
        out = np.array(start, dtype=float)
        for k, root in enumerate(self.roots):
            spacings = {self._root(n)[1] for n in self.names if self._root(n)[0] == root}
            if len(spacings) == 1:
                out[3 * k + 2] += spacings.pop()
        return out

    def _check_rows(self, positions, rotations, u) -> None:
        """Every plane touched from more than one tool orientation, every touch near its plane at the nominal
        robot (:data:`~partcal.calibration.measurement.NEAR_MM`)."""
        for name in self.names:
            mine = self.index[[p == name for p in self.plane]]
            if mine.size > 1 and largest_turn_deg(rotations[mine]) < 1.0:
                raise DataError(f"{self.rows.where(mine[0])}: column 'feature': plane {name!r} is touched from one "
                                "orientation of the tool only (it turns less than 1 degree over the "
                                f"{mine.size} touches): such touches cannot tell the tool's offset from the plane's "
                                "place; touch it with the tool turned (flush: spun about its axis)")
        distance = np.abs(self.residuals(positions, rotations, u).values[:self.index.size])
        worst = worst_of(distance, distance > NEAR_MM)
        if worst is not None:
            i, count = worst
            raise DataError(f"{self.rows.where(self.index[i])}: column 'feature': the nominal robot puts this touch "
                            f"{distance[i]:.1f} mm from plane {self.plane[i]!r} ({count} touches beyond "
                            f"{NEAR_MM:g} mm): expected a touch of that plane (a wrong feature name, or the plane's "
                            "normal and offset in the cell?)")

    def _started(self, root: str, members: list[str], positions, spec: dict) -> tuple[NDArray[np.float64], float]:
        """Where an approximately known plane's fit starts: where the nominal robot's touches put it, when they fix a
        plane (what the touches then cannot identify of it is held there, consistent with the robot, not at the
        given values, which would bend the robot to meet them); the given normal only orients it. Touches that
        fix no plane (on one line) start from the given values. A plane the touches put far from the given one
        is refused: the feature or the normal is wrong."""
        given = np.asarray(spec["normal"], dtype=float)
        given = given / np.linalg.norm(given)
        try:
            normal, offset = self._fitted_plane(root, members, positions)
        except DataError:
            return given, float(spec.get("offset_mm", np.nan))
        spacings = {self._root(p)[1] for p in self.plane if self._root(p)[0] == root}
        if normal @ given < 0 and len(spacings) < 2:    # two spacings touched orient the group by themselves
            normal = -normal
        angle = float(np.degrees(np.arccos(np.clip(normal @ given, -1.0, 1.0))))
        if angle > GIVEN_NORMAL_DEG:
            where = self.index[[self._root(p)[0] == root for p in self.plane]][0]
            raise DataError(f"{self.rows.where(where)}: column 'feature': the nominal robot's touches of plane "
                            f"{root!r} put its normal {angle:.1f} degrees from the cell's planes.{root}.normal "
                            f"{[round(v, 4) for v in given.tolist()]} (more than {GIVEN_NORMAL_DEG:g}): a wrong "
                            "feature name, or a wrong normal (the base frame's, a unit vector)?")
        return normal, offset

    def _fitted_plane(self, root: str, members: list[str], positions) -> tuple[NDArray[np.float64], float]:
        """The plane through the nominal touches of ``root`` and the planes tied to it (their spacings taken
        off along the normal, which the fit itself finds: by the smallest principal axis of the touches of
        the plane with most of them, then the offset)."""
        counts = {m: sum(p == m for p in self.plane) for m in members}
        best = max(counts, key=counts.get)
        tips = positions[self.index[[p == best for p in self.plane]]]
        centred = tips - tips.mean(axis=0)
        _, sv, vt = np.linalg.svd(centred, full_matrices=False)
        where = self.index[[p == best for p in self.plane]][0]
        if sv.size < 3 or sv[1] < 1e-6 * max(sv[0], 1e-300):
            raise DataError(f"{self.rows.where(where)}: column 'feature': the touches of plane {best!r} lie on one "
                            "line or point: they do not fix a plane's normal (give its normal in the cell)")
        normal = vt[2]
        group = self.index[[self._root(p)[0] == root for p in self.plane]]
        spacing = np.array([self._root(p)[1] for p in self.plane if self._root(p)[0] == root])
        if np.any(spacing):             # the side the spacings count along: the one the touches agree with
            spread = [np.var(positions[group] @ (sign * normal) - spacing) for sign in (1.0, -1.0)]
            normal = normal if spread[0] <= spread[1] else -normal
        elif normal @ tips.mean(axis=0) > 0:        # else towards the robot's base origin
            normal = -normal
        return normal, np.nan

    def _plane(self, root: str, u: NDArray[np.float64]) -> tuple[NDArray[np.float64], float, tuple]:
        """Normal, offset and ``d normal / d tilt`` (two vectors) of root plane ``root`` at its unknowns.

        The normal is ``pole + a t1 + b t2`` normalised: ``pole`` the coordinate axis (with its sign) nearest the
        plane's start, ``t1, t2`` the other two axes, ``a, b`` its unknowns (named ``plane P.x/+z``, ...). The
        unknowns mean the same whatever rows the fit saw, so a fitted plane scores held-out touches."""
        k = self.roots.index(root)
        a, b, offset = u[3 * k:3 * k + 3]
        n0, t1, t2 = self.frames[root]
        raw = n0 + a * t1 + b * t2
        length = np.linalg.norm(raw)
        normal = raw / length
        project = np.eye(3) - np.outer(normal, normal)
        return normal, offset, (project @ t1 / length, project @ t2 / length)

    def residuals(self, positions, rotations, u) -> Residuals:
        m = self.index.size
        values, grad, du = np.empty(m), np.empty((m, 3)), np.zeros((m, u.size))
        extra = []
        for i, (row, name) in enumerate(zip(self.index, self.plane)):
            root, spacing = self._root(name)
            k = self.roots.index(root)
            normal, offset, tilts = self._plane(root, u)
            p = positions[row]
            values[i] = normal @ p - offset - spacing
            grad[i] = normal
            du[i, 3 * k:3 * k + 2] = [t @ p for t in tilts]
            du[i, 3 * k + 2] = -1.0
            if self.flush[i]:
                extra.append((row, k, normal, tilts))
        out = Residuals(values, self.index.copy(), grad, du,
                        turn_grad=np.zeros((m, 3)) if self.needs_orientation else None, scaled=np.ones(m, dtype=bool))
        if not extra:
            return out
        return _with_flush(out, extra, rotations, self.frames, self.roots, u.size)

    def notes(self) -> list[str]:
        return ["plane: a plane's offset trades against the tool's length along its normal, and touches never "
                "fix where along a plane the robot is: what the planes leave is held nominal"]

    def describe(self) -> str:
        flush = int(self.flush.sum())
        return (f"{self.index.size} touches on {len(self.names)} planes ({counted(self.plane, self.names)})"
                + (f", {flush} flush" if flush else ""))


def _with_flush(out: Residuals, flush: list, rotations, frames: dict, roots: list, k: int) -> Residuals:
    """``out`` with two tilt residuals per flush row: the tool z axis' components along the plane's start
    tangents, ``t . (z + s n)`` times :data:`FACE_RADIUS_MM`, ``s`` the side the face meets the plane from."""
    values, rows, turn, du = [], [], [], []
    for row, index, normal, tilts in flush:
        z = rotations[row][:, 2]
        side = -1.0 if z @ normal > 0 else 1.0         # z and the normal opposed: the face lies on the plane
        n0, t1, t2 = frames[roots[index]]
        for j, t in enumerate((t1, t2)):
            values.append(FACE_RADIUS_MM * t @ (z + side * normal))
            rows.append(row)
            turn.append(FACE_RADIUS_MM * np.cross(z, t))
            d = np.zeros(k)
            d[3 * index:3 * index + 2] = [FACE_RADIUS_MM * side * t @ tilt for tilt in tilts]
            du.append(d)
    m = len(values)
    return Residuals(np.concatenate([out.values, values]), np.concatenate([out.rows_a, rows]),
                     np.vstack([out.grad_a, np.zeros((m, 3))]), np.vstack([out.du, du]),
                     turn_grad=np.vstack([out.turn_grad, turn]),
                     scaled=np.concatenate([out.scaled, np.zeros(m, dtype=bool)]))    # a tilt does not scale
