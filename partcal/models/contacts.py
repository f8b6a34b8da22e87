"""The built-in measurement kinds: tracker points, plane contacts, fixed points and distances.

Each is one class registered in :data:`~partcal.models.measures.MEASUREMENT_KINDS` (see
:mod:`partcal.models.measures` for what a kind answers). Lengths are mm; a plane's normal slopes
are plain numbers; residuals are mm.

- ``point``: a tracker point of the tool in the base frame, residual ``p - measured`` (three per row); or
  in the tracker's own frame (features ``tracker_frame: true``), the tracker's pose then six unknowns
  of the kind, fitted with the robot's (:data:`TRACKER_FRAME`).
- ``plane``: the tool tip touches plane ``feature``: ``n . p - offset`` (one per row); a ``flush``
  row (a flat face of the tool lies on the plane) adds the tool z axis' two tilts against the
  normal, as millimetres of the face's rim (:data:`FACE_RADIUS_MM`). Planes are unknown (three
  unknowns: the normal's two slopes against the coordinate axis nearest it, the offset), started
  from the given normal and offset or from the nominal robot's touches, or tied to another plane
  (``parallel_to``: its normal, and its offset plus a known ``spacing_mm``: no unknowns of its own).
- ``fixed``: the tool tip at fixed point ``feature``: ``p - c`` (three per row); the point unknown
  (three unknowns, started at the nominal touches' mean), known (``known_mm``), or tied to another
  by a known distance (``distance_to``, ``distance_mm``: one more residual, the bar's length, of
  noise :data:`BAR_NOISE_MM`).
- ``distance``: ``|p - p_to| - distance_mm`` between this row's tip and row ``to``'s, or the
  point ``to`` of the features (a ballbar's pivot: a fixed point of its own, sharing its unknowns).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.frames import kabsch
from ..robot.kinematics import ORIENTATION_MM_PER_RAD
from ..robot.rotations import (left_jacobian, log_derivative, matrices_from_xyz_deg, matrix_from_rotation_vector,
                               rotation_vector_from_matrix, rotation_vectors_from_matrices, skew_matrices)
from .identification import PRIMARY_TARGET
from .targets import PROBE_PARAMETERS
from .measures import END_KIND, NEAR_MM, MeasurementKind, Residuals, Rows, add_measurement_kind

FACE_RADIUS_MM = 50.0
"""A flush contact's tilt residual: the rise of the rim of a face of this radius, mm per radian."""

BAR_NOISE_MM = 0.001
"""The stated uncertainty of a known length between two fixed points (a calibrated bar), mm."""


def _unit_rows(n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Three residuals per row: their rows' repeat pattern and the unit gradients."""
    return np.repeat(np.arange(n), 3), np.tile(np.eye(3), (n, 1))


TRACKER_FRAME = "tracker_frame"
"""The features' key that says the point rows are in the instrument's frame (``True``): the point kind then
has six unknowns of its own, the instrument's pose in the base frame (``tracker.x, y, z`` mm, ``tracker.rx,
ry, rz`` a rotation vector in degrees), fitted with the robot's: the registration is part of the fit."""

ORIENTATION_COLUMNS = ("rx_meas", "ry_meas", "rz_meas")

UNIT_FACTOR = 30.0
"""A distance this many times shorter or longer than the nominal robot's, where that is at least :data:`LONG_MM`,
is refused: its unit is not mm."""

LONG_MM = 300.0
"""... (shorter nominal distances are not judged: a tool the nominal robot lacks changes them by any factor)."""

POINT_FAR_MM = 100.0
"""A tracker point in the base frame this far from where the nominal robot puts it is refused: metres, or a
point in another frame."""

TRACKER_PARAMETERS = (("tracker.x", "mm"), ("tracker.y", "mm"), ("tracker.z", "mm"), ("tracker.rx", "deg"),
                      ("tracker.ry", "deg"), ("tracker.rz", "deg"))


@add_measurement_kind
class PointKind(MeasurementKind):
    """A tracker point of the tool, in the robot's base frame (registered), or in the tracker's own frame
    (features ``tracker_frame: true``: the tracker's pose is then the kind's unknowns). A row may name a further
    target on the tool (column ``target``; empty or ``A``: the primary one, the robot's tool point) and carry
    the tool's measured orientation (``rx_meas, ry_meas, rz_meas``, intrinsic XYZ degrees, base frame)."""

    name = "point"
    reads = ("x_meas", "y_meas", "z_meas", "target", "rx_meas", "ry_meas", "rz_meas")
    default_noise_mm = 0.02
    summary = ("a tracker point of the tool (of target `target`): 3 residuals (mm); with rx_meas, ry_meas, "
               "rz_meas the tool's turn too, 3 more (radians times 200 mm)")

    def __init__(self, rows, index, features, noise_mm):
        super().__init__(rows, index, features, noise_mm)
        self.measured = np.column_stack([rows.number(c, index) for c in ("x_meas", "y_meas", "z_meas")])
        self.own_frame = bool(features.get(TRACKER_FRAME))
        named = rows.texts.get("target", ("",) * len(rows))
        self.target = [named[i] if named[i] != PRIMARY_TARGET else "" for i in index]
        self.targets = [t for t in dict.fromkeys(self.target) if t]
        self.turned = self._orientation_rows(rows, index)
        if self.turned.size and self.own_frame:
            raise DataError(f"{rows.where(index[self.turned[0]])}: columns 'rx_meas, ry_meas, rz_meas': a measured "
                            "orientation is read in the robot's base frame only; with data.frame: tracker register "
                            "the file first (partcal import) or leave the orientation out")
        self.needs_orientation = bool(self.targets) or bool(self.turned.size)

    def _orientation_rows(self, rows, index) -> NDArray[np.intp]:
        """Positions in ``index`` of the rows with a measured orientation (all three angles, else refused)."""
        angles = [rows.numbers.get(c) for c in ORIENTATION_COLUMNS]
        if all(a is None for a in angles):
            self.rotations_measured = np.zeros((0, 3, 3))
            return np.zeros(0, dtype=np.intp)
        given = np.column_stack([np.full(len(rows), np.nan) if a is None else a for a in angles])[index]
        some, every = np.isfinite(given).any(axis=1), np.isfinite(given).all(axis=1)
        bad = np.flatnonzero(some & ~every)
        if bad.size:
            column = ORIENTATION_COLUMNS[int(np.flatnonzero(~np.isfinite(given[bad[0]]))[0])]
            raise DataError(f"{rows.where(index[bad[0]])}: column {column!r}: a point row's orientation needs all of "
                            f"{', '.join(ORIENTATION_COLUMNS)}; this one is empty")
        turned = np.flatnonzero(every)
        self.rotations_measured = matrices_from_xyz_deg(given[turned])
        return turned

    def unknowns(self, positions, rotations):
        names, start = [], []
        primary = np.array([not t for t in self.target], dtype=bool)
        if self.own_frame:
            names += list(TRACKER_PARAMETERS)
            if primary.sum() < 3:       # too few to place it: the rank rule holds what they do not fix
                start += [0.0] * 6
            else:                       # tracker -> base at the nominal robot
                rotation, shift = kabsch(self.measured[primary], positions[self.index[primary]])
                start += [*shift, *np.degrees(rotation_vector_from_matrix(rotation))]
        else:
            self._check_near(positions, primary)
        for target in self.targets:     # its offset from the primary target, flange frame, from the data
            mine = np.array([t == target for t in self.target])
            rows = self.index[mine]
            seen = self._seen(start[:6] if self.own_frame else None, self.measured[mine])
            local = np.einsum("nji,nj->ni", rotations[rows], seen - positions[rows])
            names += [(f"target {target}.{c}", "mm") for c in "xyz"]
            start += list(np.median(local, axis=0))
        if self.turned.size:
            names += list(PROBE_PARAMETERS)
            start += [0.0, 0.0, 0.0]
        return names, np.array(start, dtype=float)

    def _check_near(self, positions, primary) -> None:
        off = np.linalg.norm(positions[self.index[primary]] - self.measured[primary], axis=1)
        worst = _worst_of(off, off > POINT_FAR_MM)
        if worst is not None:
            i, count = worst
            raise DataError(f"{self.rows.where(self.index[primary][i])}: columns 'x_meas, y_meas, z_meas': the "
                            f"nominal robot puts this point {off[i]:.1f} mm away ({count} points beyond "
                            f"{POINT_FAR_MM:g} mm): expected tracker points in the robot's base frame, in mm (points "
                            "in the tracker's own frame: data.frame: tracker)")

    @staticmethod
    def _seen(frame, measured: NDArray[np.float64]) -> NDArray[np.float64]:
        """The measured points in the base frame: as they are, or through the tracker's pose ``frame``."""
        if frame is None:
            return measured
        return measured @ matrix_from_rotation_vector(np.radians(frame[3:6])).T + np.asarray(frame[:3])

    def residuals(self, positions, rotations, u) -> Residuals:
        n = self.index.size
        which, grad = _unit_rows(n)
        du = np.zeros((n, 3, u.size))
        k = 0
        if self.own_frame:
            turn = np.radians(u[3:6])
            seen = self.measured @ matrix_from_rotation_vector(turn).T          # R x, base frame axes
            du[:, :, :3] = -np.eye(3)
            # d(R x) = (J_l dr) x (R x): a turn of the rotation vector by dr (radians)
            du[:, :, 3:6] = skew_matrices(seen) @ left_jacobian(turn) * (np.pi / 180.0)
            seen, k = seen + u[:3], 6
        else:
            seen = self.measured
        tips = positions[self.index].copy()
        turn_grad = np.zeros((n, 3, 3)) if self.needs_orientation else None
        for target in self.targets:         # p_B = p_A + R d: its offset d turns with the tool
            mine = np.flatnonzero([t == target for t in self.target])
            rot = rotations[self.index[mine]]
            lever = rot @ u[k:k + 3]
            tips[mine] += lever
            du[mine, :, k:k + 3] = rot
            turn_grad[mine] = -skew_matrices(lever)          # d(R d) = w x (R d)
            k += 3
        out = Residuals((tips - seen).ravel(), self.index[which], grad, du.reshape(3 * n, -1),
                        turn_grad=None if turn_grad is None else turn_grad.reshape(3 * n, 3),
                        turning=np.ones(3 * n, dtype=bool))
        if not self.turned.size:
            return out
        return self._with_orientation(out, rotations, u[k:k + 3], k)

    def _with_orientation(self, out: Residuals, rotations, probe, k: int) -> Residuals:
        """``out`` with the orientation's residuals ``w log(R P R_meas^T)`` (three per row with one; ``w``
        :data:`~partcal.robot.kinematics.ORIENTATION_MM_PER_RAD`, ``P`` the probe's turn on the flange)."""
        rows = self.index[self.turned]
        model = rotations[rows] @ matrix_from_rotation_vector(np.radians(probe))
        turns = rotation_vectors_from_matrices(model @ self.rotations_measured.transpose(0, 2, 1))
        weight = ORIENTATION_MM_PER_RAD
        slope = weight * log_derivative(turns)                                 # (m, 3, 3): by a turn w of the tool
        du = np.zeros((rows.size, 3, out.du.shape[1]))
        # P(p + dp) = P exp(J_r(p) dp): a turn of the tool by R P J_r(p) dp, J_r(p) = J_l(p)^T
        du[:, :, k:k + 3] = slope @ (model @ left_jacobian(np.radians(probe)).T) * (np.pi / 180.0)
        m = 3 * rows.size
        return Residuals(np.concatenate([out.values, weight * turns.ravel()]),
                         np.concatenate([out.rows_a, np.repeat(rows, 3)]), np.vstack([out.grad_a, np.zeros((m, 3))]),
                         np.vstack([out.du, du.reshape(m, -1)]),
                         turn_grad=np.vstack([out.turn_grad, slope.reshape(m, 3)]),
                         scaled=np.concatenate([np.ones(out.values.size, dtype=bool), np.zeros(m, dtype=bool)]),
                         turning=np.ones(out.values.size + m, dtype=bool))      # an angle turns, does not scale

    def moved(self, u, omega, shift):
        out = np.zeros_like(u)
        if self.own_frame:              # the tracker turns and shifts with the cell: exp(w) R, w x T + t
            out[:3] = np.cross(omega, u[:3]) + shift
            out[3:6] = np.degrees(log_derivative(np.radians(u[3:6])[None])[0] @ omega)
        return out

    def notes(self) -> list[str]:
        return ["point: the tracker's frame and the robot's base frame are one unknown: the tracker's pose is "
                "held where the nominal robot puts it and the base identified"] if self.own_frame else []

    def describe(self) -> str:
        where = "in the tracker's frame" if self.own_frame else "in the base frame"
        more = (f", targets {', '.join(self.targets)} beside the primary" if self.targets else "") + (
            f", {self.turned.size} with the tool's orientation" if self.turned.size else "")
        return f"{self.index.size} tracker points {where}{more}"


def _worst_of(values: NDArray[np.float64], beyond: NDArray[np.bool_]) -> tuple[int, int] | None:
    """The index of the largest of ``values`` where ``beyond`` holds, and how many hold (what a refusal names:
    the worst row and the count); None where none does."""
    far = np.flatnonzero(beyond)
    return (int(far[np.argmax(values[far])]), int(far.size)) if far.size else None


def _largest_turn_deg(rotations: NDArray[np.float64]) -> float:
    """The largest angle (degrees) between the first of ``rotations`` (n, 3, 3) and the others."""
    cos = (np.einsum("ij,nij->n", rotations[0], rotations[1:]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max(initial=0.0))


@add_measurement_kind
class PlaneKind(MeasurementKind):
    """The probe tip on a plane (and, flush, a face of the tool lying on it)."""

    name = "plane"
    reads = ("feature", "flush")
    summary = "the tool tip touches plane `feature`: its distance to the plane (mm); flush adds two tilts"

    def __init__(self, rows, index, features, noise_mm):
        super().__init__(rows, index, features, noise_mm)
        self.plane = rows.text("feature", index)
        flush = rows.numbers.get("flush")
        self.flush = np.zeros(index.size, dtype=bool) if flush is None else np.nan_to_num(
            np.asarray(flush, dtype=float)[index]) > 0.5
        self.needs_orientation = bool(self.flush.any())         # the tool's turn enters flush rows alone
        self.specs = dict((features.get("planes") or {}))
        self.names = list(dict.fromkeys(self.plane))
        for name in self.names:
            spec = self.specs.setdefault(name, {})
            root = spec.get("parallel_to")
            if root is not None and root not in self.specs:
                raise DataError(f"plane {name!r}: parallel_to {root!r} is not a plane of the features")
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
                normal = np.asarray(spec["normal"], dtype=float)
                normal = normal / np.linalg.norm(normal)
                offset = float(spec.get("offset_mm", np.nan))
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
        self._check_rows(positions, rotations, start)
        return names, start

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
        robot (:data:`~partcal.models.measures.NEAR_MM`)."""
        for name in self.names:
            mine = self.index[[p == name for p in self.plane]]
            if mine.size > 1 and _largest_turn_deg(rotations[mine]) < 1.0:
                raise DataError(f"{self.rows.where(mine[0])}: column 'feature': plane {name!r} is touched from one "
                                "orientation of the tool only (it turns less than 1 degree over the "
                                f"{mine.size} touches): such touches cannot tell the tool's offset from the plane's "
                                "place; touch it with the tool turned (flush: spun about its axis)")
        distance = np.abs(self.residuals(positions, rotations, u).values[:self.index.size])
        worst = _worst_of(distance, distance > NEAR_MM)
        if worst is not None:
            i, count = worst
            raise DataError(f"{self.rows.where(self.index[i])}: column 'feature': the nominal robot puts this touch "
                            f"{distance[i]:.1f} mm from plane {self.plane[i]!r} ({count} touches beyond "
                            f"{NEAR_MM:g} mm): expected a touch of that plane (a wrong feature name, or the plane's "
                            "normal and offset in the features?)")

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
                            "line or point: they do not fix a plane's normal (give its normal in the features)")
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
        return (f"{self.index.size} touches on {len(self.names)} planes ({_counted(self.plane, self.names)})"
                + (f", {flush} flush" if flush else ""))


def _counted(features, names) -> str:
    """``top 300, step 300, side 200``: each name and how many rows name it."""
    features = list(features)
    return ", ".join(f"{name} {features.count(name)}" for name in names)


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


def _points_moved(u: NDArray[np.float64], omega, shift) -> NDArray[np.float64]:
    """How points (x, y, z after x, y, z) move with a small turn ``omega`` and a shift of the cell."""
    return (np.cross(omega, u.reshape(-1, 3)) + shift).ravel()


def _point_unknowns(name: str) -> list[tuple[str, str]]:
    return [(f"point {name}.{c}", "mm") for c in "xyz"]


@add_measurement_kind
class FixedPointKind(MeasurementKind):
    """The tool tip brought to a fixed point (a sphere's or cone's centre, a nest)."""

    name = "fixed"
    reads = ("feature",)
    summary = "the tool tip at fixed point `feature`: 3 residuals (mm)"

    def __init__(self, rows, index, features, noise_mm):
        super().__init__(rows, index, features, noise_mm)
        self.point = rows.text("feature", index)
        self.specs = dict(features.get("points") or {})
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
                                f"by distance_mm (points.{n}.distance_to of the features), but no row visits "
                                f"{other!r}: visit it too, or list {n!r} as unknown ({n}: {{}})")
        for name in self.unknown:
            names += _point_unknowns(name)
            start += list(np.median(positions[self.index[[p == name for p in self.point]]], axis=0))
        self.tied = tied
        start = np.array(start)
        self._check_rows(positions, rotations, start)
        return names, start

    def _check_rows(self, positions, rotations, u) -> None:
        """Every point reached from more than one orientation, every visit near its point at the nominal robot."""
        for name in self.names:
            mine = self.index[[p == name for p in self.point]]
            if mine.size > 1 and _largest_turn_deg(rotations[mine]) < 1.0:
                raise DataError(f"{self.rows.where(mine[0])}: column 'feature': fixed point {name!r} is reached from "
                                f"one orientation of the tool only ({mine.size} visits within 1 degree): visits must "
                                "turn the tool about the point")
        distance = np.linalg.norm(self.residuals(positions, rotations, u).values[:3 * self.index.size]
                                  .reshape(-1, 3), axis=1)
        worst = _worst_of(distance, distance > NEAR_MM)
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
        which, grad = _unit_rows(m)
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
            scale = self.noise_mm / BAR_NOISE_MM         # weighed as a length known to BAR_NOISE_MM
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
        return _points_moved(u, omega, shift)

    def describe(self) -> str:
        return f"{self.index.size} visits of {len(self.names)} fixed points ({_counted(self.point, self.names)})"


@add_measurement_kind
class DistanceKind(MeasurementKind):
    """The distance between this row's tool tip and another row's (or a pivot's)."""

    name = "distance"
    reads = ("distance_mm", "to")
    summary = "|tip - tip of row `to` (or pivot `to`)| - distance_mm (mm)"

    def __init__(self, rows, index, features, noise_mm):
        super().__init__(rows, index, features, noise_mm)
        self.measured = rows.number("distance_mm", index)
        targets = rows.text("to", index)
        where = {name: i for i, name in enumerate(rows.ids)}
        fixed = rows.of(FixedPointKind.name)
        points = set(features.get("points") or {}) | (set(rows.text("feature", fixed)) if fixed.size else set())
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
                                "the features")
            if to in where and where[to] == row:
                raise DataError(f"{rows.where(row)}: column 'to': the row refers to itself")
        bad = np.flatnonzero(~(self.measured > 0))
        if bad.size:
            raise DataError(f"{rows.where(index[bad[0]])}: column 'distance_mm': {self.measured[bad[0]]:g} is not a "
                            "distance; expected a length above 0 mm")
        self.specs = dict(features.get("points") or {})
        self.pivots = [p for p in dict.fromkeys(x for x in self.pivot if x)
                       if "known_mm" not in self.specs.get(p, {})]

    def unknowns(self, positions, rotations):
        names, start = [], []
        for name in self.pivots:
            mine = np.array([p == name for p in self.pivot])
            names += _point_unknowns(name)
            start += list(_sphere_centre(positions[self.index[mine]], self.measured[mine]))
        start = np.array(start)
        between = self.other >= 0         # a pivot's distance is checked by the fit: its place is unknown here
        nominal = np.linalg.norm(positions[self.index[between]] - positions[self.other[between]], axis=1)
        # an unknown tool moves short distances by tens of mm (the IPA UR10's 93 mm reflector against a zero
        # tool: 4.3 mm measured, 37.8 nominal), so only a factor that no tool makes on a long one is refused
        ratio = self.measured[between] / np.maximum(nominal, 1e-9)
        off = (nominal >= LONG_MM) & ((ratio < 1.0 / UNIT_FACTOR) | (ratio > UNIT_FACTOR))
        worst = _worst_of(np.abs(np.log(ratio)), off)
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
        return _points_moved(u, omega, shift)          # the pivots

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


__all__ = ["PointKind", "PlaneKind", "FixedPointKind", "DistanceKind", "END_KIND", "Rows"]
