"""Tracker points: the tool's position (of any target on it, and its orientation) in the robot's base frame or
in the tracker's own frame (:class:`TrackerPoints`)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.frames import kabsch
from ..robot.kinematics import ORIENTATION_MM_PER_RAD
from ..robot.rotations import (left_jacobian, log_derivative, matrices_from_xyz_deg, matrix_from_rotation_vector,
                               rotation_vector_from_matrix, rotation_vectors_from_matrices, skew_matrices)
from .measurement import Column, MeasurementType, Residuals, unit_rows, worst_of
from .parameters import PRIMARY_TARGET

PROBE_PARAMETERS = (("probe.rx", "deg"), ("probe.ry", "deg"), ("probe.rz", "deg"))
"""The measured frame's small turn on the flange (a rotation vector, degrees): an unknown of point rows with a measured
orientation (data in the base frame carry the measured flange's orientation: docs/data.md)."""

TARGETS = "targets"
"""The cell's key of the further targets' nominal offsets on the tool (flange frame, mm): where their fit starts
(without one, from the rows at the nominal robot)."""

ORIENTATION_WEIGHT = "orientation_mm_per_rad"
"""The cell's key of an orientation residual's weight: one radian counts as this many mm (default
:data:`~partcal.robot.kinematics.ORIENTATION_MM_PER_RAD`)."""

STD_COLUMNS = ("std_x", "std_y", "std_z")
"""Per-row standard deviations of the measured coordinates (mm): they weigh the point rows among themselves."""

TRACKER_FRAME = "tracker_frame"
"""The cell' key that says the point rows are in the instrument's frame (``True``): the point type then
has six unknowns of its own, the instrument's pose in the base frame (``tracker.x, y, z`` mm, ``tracker.rx,
ry, rz`` a rotation vector in degrees), fitted with the robot's: the registration is part of the fit."""

ORIENTATION_COLUMNS = ("rx_meas", "ry_meas", "rz_meas")

POINT_FAR_MM = 100.0
"""A tracker point in the base frame this far from where the nominal robot puts it is refused: metres, or a
point in another frame."""

TRACKER_PARAMETERS = (("tracker.x", "mm"), ("tracker.y", "mm"), ("tracker.z", "mm"), ("tracker.rx", "deg"),
                      ("tracker.ry", "deg"), ("tracker.rz", "deg"))


class TrackerPoints(MeasurementType):
    """A tracker point of the tool, in the robot's base frame (registered), or in the tracker's own frame
    (cell ``tracker_frame: true``: the tracker's pose is then the type's unknowns). A row may name a further
    target on the tool (column ``target``; empty or ``A``: the primary one, the robot's tool point) and carry
    the tool's measured orientation (``rx_meas, ry_meas, rz_meas``, intrinsic XYZ degrees, base frame)."""

    name = "point"
    columns = {**{c: Column("mm", required=True) for c in ("x_meas", "y_meas", "z_meas")},
               "target": Column(text=True), **{c: Column("deg") for c in ORIENTATION_COLUMNS},
               **{c: Column("mm") for c in STD_COLUMNS}}
    default_noise = 0.02
    summary = ("a tracker point of the tool (of target `target`): 3 residuals (mm); with rx_meas, ry_meas, "
               "rz_meas the tool's turn too, 3 more (radians times 200 mm)")

    def __init__(self, rows, index, cell, noise):
        super().__init__(rows, index, cell, noise)
        self.measured = np.column_stack([rows.number(c, index) for c in ("x_meas", "y_meas", "z_meas")])
        self.own_frame = bool(cell.get(TRACKER_FRAME))
        named = rows.texts.get("target", ("",) * len(rows))
        self.target = [named[i] if named[i] != PRIMARY_TARGET else "" for i in index]
        self.targets = [t for t in dict.fromkeys(self.target) if t]
        self.turned = self._orientation_rows(rows, index)
        if self.turned.size and self.own_frame:
            raise DataError(f"{rows.where(index[self.turned[0]])}: columns 'rx_meas, ry_meas, rz_meas': a measured "
                            "orientation is read in the robot's base frame only; with data.frame: tracker register "
                            "the file first (partcal import) or leave the orientation out")
        self.needs_orientation = bool(self.targets) or bool(self.turned.size)
        self.fixes_frame = not self.own_frame
        self.orientation_weight = float(cell.get(ORIENTATION_WEIGHT, ORIENTATION_MM_PER_RAD))
        self.std = self._std(rows, index)

    @staticmethod
    def _std(rows, index) -> NDArray[np.float64] | None:
        """The rows' stated standard deviations (n, 3) mm (every cell given and > 0), or None without the columns."""
        if not all(c in rows.numbers for c in STD_COLUMNS):
            return None
        std = np.column_stack([rows.number(c, index) for c in STD_COLUMNS])
        bad = np.flatnonzero(~np.all(std > 0, axis=1))
        if bad.size:
            row = bad[0]
            j = int(np.flatnonzero(~(std[row] > 0))[0])
            raise DataError(f"{rows.where(index[row])}: column {STD_COLUMNS[j]!r}: {std[row, j]:g} is not a standard "
                            "deviation; expected a number > 0 (mm)")
        return std

    def relative_weights(self, residuals: Residuals) -> NDArray[np.float64]:
        """The stated standard deviations' weights of the position residuals, ``reference / std`` with ``reference``
        their root mean square (so the type's noise keeps its level); an orientation's residuals weigh one."""
        out = np.ones(residuals.values.size)
        if self.std is not None:
            n = self.index.size
            out[:3 * n] = (np.sqrt(np.mean(self.std**2)) / self.std).ravel()
        return out

    def stated_spread(self) -> float | None:
        """The root mean square of the rows' stated standard deviations, mm (without them: the type's stated noise)."""
        return super().stated_spread() if self.std is None else float(np.sqrt(np.mean(self.std**2)))

    def follows_tool(self, name: str) -> bool:
        """A further target's offset on the flange is a tool parameter (held where the tool is)."""
        return name.startswith("tool@")

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
        given = self.cell.get(TARGETS) or {}
        for target in self.targets:     # its offset from the primary target, flange frame: given, or from the data
            names += [(f"tool@{target}.{c}", "mm") for c in "xyz"]
            if target in given:
                start += [float(v) for v in given[target]]
                continue
            mine = np.array([t == target for t in self.target])
            rows = self.index[mine]
            seen = self._seen(start[:6] if self.own_frame else None, self.measured[mine])
            local = np.einsum("nji,nj->ni", rotations[rows], seen - positions[rows]) + self.tool_mm
            start += list(np.median(local, axis=0))
        if self.turned.size:
            names += list(PROBE_PARAMETERS)
            start += [0.0, 0.0, 0.0]
        return names, np.array(start, dtype=float)

    def _check_near(self, positions, primary) -> None:
        off = np.linalg.norm(positions[self.index[primary]] - self.measured[primary], axis=1)
        worst = worst_of(off, off > POINT_FAR_MM)
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
        which, grad = unit_rows(n)
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
        tool_grad = np.zeros((n, 3, 3)) if self.targets else None
        for target in self.targets:         # p_B = p_A + R (d - t): its offset d on the flange turns with the tool
            mine = np.flatnonzero([t == target for t in self.target])
            rot = rotations[self.index[mine]]
            lever = rot @ (u[k:k + 3] - self.tool_mm)
            tips[mine] += lever
            du[mine, :, k:k + 3] = rot
            tool_grad[mine] = -rot
            turn_grad[mine] = -skew_matrices(lever)          # d(R d) = w x (R d)
            k += 3
        out = Residuals((tips - seen).ravel(), self.index[which], grad, du.reshape(3 * n, -1),
                        turn_grad=None if turn_grad is None else turn_grad.reshape(3 * n, 3),
                        turning=np.ones(3 * n, dtype=bool),
                        tool_grad=None if tool_grad is None else tool_grad.reshape(3 * n, 3))
        if not self.turned.size:
            return out
        return self._with_orientation(out, rotations, u[k:k + 3], k)

    def _with_orientation(self, out: Residuals, rotations, probe, k: int) -> Residuals:
        """``out`` with the orientation's residuals ``w log(R P R_meas^T)`` (three per row with one; ``w``
        :data:`~partcal.robot.kinematics.ORIENTATION_MM_PER_RAD`, ``P`` the probe's turn on the flange)."""
        rows = self.index[self.turned]
        model = rotations[rows] @ matrix_from_rotation_vector(np.radians(probe))
        turns = rotation_vectors_from_matrices(model @ self.rotations_measured.transpose(0, 2, 1))
        weight = self.orientation_weight
        slope = weight * log_derivative(turns)                                 # (m, 3, 3): by a turn w of the tool
        du = np.zeros((rows.size, 3, out.du.shape[1]))
        # P(p + dp) = P exp(J_r(p) dp): a turn of the tool by R P J_r(p) dp, J_r(p) = J_l(p)^T
        du[:, :, k:k + 3] = slope @ (model @ left_jacobian(np.radians(probe)).T) * (np.pi / 180.0)
        m = 3 * rows.size
        tool_grad = None if out.tool_grad is None else np.vstack([out.tool_grad, np.zeros((m, 3))])
        return Residuals(np.concatenate([out.values, weight * turns.ravel()]),
                         np.concatenate([out.rows_a, np.repeat(rows, 3)]), np.vstack([out.grad_a, np.zeros((m, 3))]),
                         np.vstack([out.du, du.reshape(m, -1)]),
                         turn_grad=np.vstack([out.turn_grad, slope.reshape(m, 3)]),
                         scaled=np.concatenate([np.ones(out.values.size, dtype=bool), np.zeros(m, dtype=bool)]),
                         turning=np.ones(out.values.size + m, dtype=bool),      # an angle turns, does not scale
                         tool_grad=tool_grad)

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


def target_parameters(tools_mm: dict, orientation: bool) -> list[tuple[str, str]]:
    """``(name, unit)`` of what point rows add to the robot's parameters in the base frame: each further target's
    offset, then the probe's turn.

    >>> [n for n, _ in target_parameters({"B": [0, 0, 1]}, True)]
    ['tool@B.x', 'tool@B.y', 'tool@B.z', 'probe.rx', 'probe.ry', 'probe.rz']
    """
    return [(f"tool@{name}.{c}", "mm") for name in tools_mm for c in "xyz"] + \
        (list(PROBE_PARAMETERS) if orientation else [])


def target_nominal(tools_mm: dict, orientation: bool) -> NDArray[np.float64]:
    """Their nominal values: the targets' offsets (mm), a zero turn (degrees)."""
    tools = [np.asarray(t, dtype=float) for t in tools_mm.values()]
    return np.concatenate(tools + [np.zeros(3 if orientation else 0)])
