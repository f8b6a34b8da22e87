"""ISO 9283 figures of a measured data set, as measured and after a model's correction (``partcal iso9283``).

The figures' summaries, JSON and text table are here too. A data set's rows are grouped into
poses and cycles (:mod:`partcal.data.iso9283`):
by a ``cycle`` column when the file has one, else by repeated commanded
joints. The commanded position of a row is its nominal position, the attained
one the measured position; after a model, the attained position is what the
model leaves: the measured position minus the predicted error (what a
compensated robot reaches, to first order), scored as a run scores the set
(a set registered in its own tracker frame up to a rigid transform).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from .. import __version__
from .._io import atomic_write, refuse_input_as_output
from ..data import iso9283
from ..data.formats import load_format
from ..data.measurements import Measurements, read_measurements, read_text_column
from ..errors import DataError
from ..robot.description import joint_columns
from .config import robot_named
from .predictor import load_predictor
from .scoring import errors_left

CYCLE_COLUMN = "cycle"


@dataclass(frozen=True)
class IsoData:
    """A data set with its cycles, and the line of every row (for messages).

    Attributes
    ----------
    measurements : Measurements
    cycles : Cycles
    lines : ndarray of int, shape (n,)
        The line (as an editor shows it) of each data row.
    source : str
    by_column : bool
        Whether the cycles came from a ``cycle`` column (else from repeated commanded joints).
    tol_deg : float
        Commanded joints this close are one pose.
    """

    measurements: Measurements
    cycles: iso9283.Cycles
    lines: NDArray[np.intp]
    source: str
    by_column: bool
    tol_deg: float = iso9283.DEFAULT_TOLERANCE_DEG


def read_iso_data(path, robot=None, *, fmt=None, tol_deg: float = iso9283.DEFAULT_TOLERANCE_DEG) -> IsoData:
    """Read a measurement CSV (or a foreign file with ``fmt``) and recognise its poses and cycles."""
    if not (np.isfinite(tol_deg) and tol_deg >= 0):
        raise DataError(f"the pose tolerance must be a non-negative number of degrees; got {tol_deg!r}")
    m = read_measurements(path, robot, fmt=fmt)
    lines, labels = read_text_column(path, CYCLE_COLUMN, fmt)
    if labels is None:
        cycles = iso9283.cycles_from_joints(m.q_deg, tol_deg)
    else:
        cycles = iso9283.cycles_from_column(labels, m.q_deg, tol_deg, source=str(path), lines=lines,
                                            columns=[fmt.file_column(c) if fmt else c
                                                     for c in joint_columns(m.n_joints)])
    return IsoData(m, cycles, lines, str(path), labels is not None, tol_deg)


@dataclass(frozen=True)
class IsoFigures:
    """The figures of one data set: pose, and optionally distance and path."""

    pose: iso9283.PoseFigures
    distance: iso9283.DistanceFigures | None
    path: iso9283.PathFigures | None

    def to_dict(self, lines=None) -> dict:
        return to_dict(self.pose, self.distance, self.path, lines)

    def lines(self) -> list[str]:
        return table_lines(self.pose, self.distance, self.path)


def iso_figures(data: IsoData, predicted: NDArray[np.float64] | None = None, *, own_frame: bool = False,
                distance: tuple[int, int] | None = None, path: bool = False,
                repeatability: bool = False) -> IsoFigures:
    """The ISO 9283 figures of ``data``, as measured or after a model predicting ``predicted`` (n, 3) mm.

    Parameters
    ----------
    predicted : ndarray, shape (n, 3) or (n, 6), optional
        A model's predicted errors at the rows (mm; a pose model's rotation
        vectors in mrad): the figures of what it leaves.
    own_frame : bool
        The set was registered in its own tracker frame: score up to a rigid transform.
    distance : (int, int), optional
        Two poses (1-based) for the distance figures AD, RD.
    path : bool
        The poses, in order, are the points of a path: also AT, RT.
    repeatability : bool
        Refuse a pose measured in a single cycle.
    """
    m, cycles = data.measurements, data.cycles
    if repeatability or path:
        field = ("column 'cycle'" if data.by_column else
                 f"columns q1..q{m.n_joints} (no other row commands the same joints within {data.tol_deg:g} deg; "
                 "a 'cycle' column names the cycles)")
        iso9283.require_repeats(cycles, source=data.source, lines=data.lines, field=field,
                                what="path repeatability" if path else "repeatability")
    zeros = np.zeros((len(m), 3 if predicted is None else predicted.shape[1]))
    left, _ = errors_left(m, zeros if predicted is None else predicted, own_frame)
    attained = m.nominal_mm + left
    turn = None
    if m.has_orientation:
        turn = m.orientation_errors_deg
        if predicted is not None and predicted.shape[1] == 6:
            turn = np.degrees(errors_left(m, predicted, own_frame)[1] / 1000.0)
    dist = None
    if distance is not None:
        bad = [p for p in distance if not 1 <= p <= cycles.n_poses]
        if bad:
            raise DataError(f"{data.source}: --distance names pose {bad[0]}, but the data have poses 1..{cycles.n_poses}")
        dist = iso9283.distance_figures(m.nominal_mm, attained, cycles, (distance[0] - 1, distance[1] - 1))
    trace = iso9283.path_figures(m.nominal_mm, attained, cycles) if path else None
    return IsoFigures(iso9283.pose_figures(m.nominal_mm, attained, cycles, turn), dist, trace)


def pose_lines(data: IsoData) -> NDArray[np.intp]:
    """The line of each pose's first row, shape (P,)."""
    return data.lines[data.cycles.first_rows()]


def describe(data: IsoData) -> str:
    """One line: rows, poses, cycles and where they came from."""
    counts = data.cycles.counts
    how = "a 'cycle' column" if data.by_column else "repeated commanded joints"
    return (f"{Path(data.source).name}: {len(data.measurements)} rows, {data.cycles.n_poses} poses, "
            f"{counts.min()} to {counts.max()} cycles per pose (from {how})")


def of_measurements(m: Measurements, tol_deg: float = iso9283.DEFAULT_TOLERANCE_DEG) -> IsoData:
    """A data set already read (a run's), its poses recognised from repeated commanded joints; no lines."""
    return IsoData(m, iso9283.cycles_from_joints(m.q_deg, tol_deg), np.arange(1, len(m) + 1), m.name, False, tol_deg)


def run_figures(datasets: dict[str, Measurements], predictions: dict[str, dict[str, NDArray[np.float64]]],
                own_frame: dict[str, bool] | None = None,
                attained: dict[str, dict[str, tuple[NDArray[np.float64], NDArray[np.bool_]]]] | None = None
                ) -> dict[str, dict]:
    """The ISO 9283 figures of every test set of a run, uncompensated and after each model.

    Parameters
    ----------
    datasets : dict of str to Measurements
        The run's data sets by name (the identification set is left out).
    predictions : dict of str to dict of str to ndarray
        Each model's predicted errors on each data set, ``{model: {data set: (n, 3 or 6)}}``.
    own_frame : dict of str to bool, optional
        The data sets registered in their own tracker frame (scored up to a rigid transform).
    attained : dict, optional
        With a virtual robot, ``{model: {data set: (positions (n, 3) mm, converged (n,) bool, turn (n, 3)
        deg or None)}}``: what its tracker read when the compensated targets were commanded
        (:func:`~partcal.study.scoring.verify_compensation`).

    Returns
    -------
    dict
        ``{data set: {"poses", "cycles_max", "uncompensated": summary, "models": {model: summary},
        "measured": {model: summary}}}`` with the summaries of :func:`summary` (``AP_mean_mm``,
        ``AP_max_mm``, ``RP_mean_mm``, ``RP_max_mm``; RP None without repeated poses). ``models`` holds
        the figures predicted (the measured position minus the predicted error); ``measured`` those
        the virtual robot reached with the compensated targets, over the converged ones
        (``converged`` of ``n`` in the summary), and is there only with a virtual robot.
    """
    own_frame, attained = own_frame or {}, attained or {}
    out = {}
    for name, m in datasets.items():
        if name == "identification":
            continue
        data = of_measurements(m)
        entry = {"poses": data.cycles.n_poses, "cycles_max": int(data.cycles.counts.max()),
                 "uncompensated": summary(iso_figures(data, own_frame=own_frame.get(name, False)).pose),
                 "models": {}}
        for model, by_set in predictions.items():
            if name in by_set:
                figures = iso_figures(data, by_set[name], own_frame=own_frame.get(name, False))
                entry["models"][model] = summary(figures.pose)
        measured = {model: measured_after(m, *by_set[name]) for model, by_set in attained.items() if name in by_set}
        if measured:
            entry["measured"] = measured
        out[name] = entry
    return out


def measured_after(m: Measurements, reached_mm: NDArray[np.float64], converged: NDArray[np.bool_],
                   turned_deg: NDArray[np.float64] | None = None,
                   tol_deg: float = iso9283.DEFAULT_TOLERANCE_DEG) -> dict | None:
    """The pose figures of what a robot reached when given the compensated targets of ``m``.

    The commanded position of a row is its nominal position (the target), the
    attained one ``reached_mm``; only the ``converged`` targets count (the
    others were never sent), their poses recognised from repeated commanded
    joints as in :func:`of_measurements`. ``turned_deg`` (n, 3), the turn from
    each target orientation to the one reached (rotation vectors, degrees),
    gives the orientation figures too. None when no target converged.

    >>> from partcal.data.measurements import Measurements
    >>> m = Measurements(np.zeros((3, 6)), np.zeros((3, 3)), np.zeros((3, 3)))
    >>> s = measured_after(m, np.array([[0.3, 0, 0], [0.1, 0, 0], [9.0, 9, 9]]), np.array([True, True, False]))
    >>> s["poses"], round(s["AP_max_mm"], 6), s["converged"], s["n"]
    (1, 0.2, 2, 3)
    """
    converged = np.asarray(converged, dtype=bool)
    if not converged.any():
        return None
    cycles = iso9283.cycles_from_joints(m.q_deg[converged], tol_deg)
    turn = None if turned_deg is None else np.asarray(turned_deg, dtype=float)[converged]
    figures = iso9283.pose_figures(m.nominal_mm[converged], np.asarray(reached_mm)[converged], cycles, turn)
    return {**summary(figures), "converged": int(converged.sum()), "n": len(converged)}


def run_lines(figures: dict[str, dict]) -> list[str]:
    """The printed table of :func:`run_figures`: AP mean / max (mm) per model and test set, and each set's RP;
    with a virtual robot, the same measured on it after compensation.

    >>> print("\\n".join(run_lines({"cubes": {"poses": 2, "cycles_max": 3, "uncompensated": {
    ...     "AP_mean_mm": 1.0, "AP_max_mm": 2.0, "RP_max_mm": 0.1}, "models": {"DH": {
    ...     "AP_mean_mm": 0.5, "AP_max_mm": 0.75, "RP_max_mm": 0.1}}, "measured": {"DH": {
    ...     "AP_mean_mm": 0.55, "AP_max_mm": 0.8, "RP_max_mm": 0.1}}}})))
    ISO 9283 pose accuracy AP (mm), mean / max over the poses of each test set
    model                                     cubes
    uncompensated                     1.000 / 2.000
    DH                                0.500 / 0.750
    DH, measured (virtual robot)      0.550 / 0.800
    poses (cycles, RP max)             2 (3, 0.100)
    """
    names = list(figures)
    models = list(dict.fromkeys(m for entry in figures.values() for m in entry["models"]))
    measured = list(dict.fromkeys(m for entry in figures.values() for m in entry.get("measured", {})))
    rows = [("uncompensated", [figures[n]["uncompensated"] for n in names])]
    rows += [(model, [figures[n]["models"].get(model) for n in names]) for model in models]
    rows += [(f"{model}, measured (virtual robot)", [figures[n].get("measured", {}).get(model) for n in names])
             for model in measured]
    width = max(len("poses (cycles, RP max)"), *(len(label) for label, _ in rows)) + 1
    columns = [max(16, len(n)) + 2 for n in names]

    def cell(stats: dict | None, size: int) -> str:
        return "-".rjust(size) if stats is None else f"{stats['AP_mean_mm']:.3f} / {stats['AP_max_mm']:.3f}".rjust(size)

    lines = ["ISO 9283 pose accuracy AP (mm), mean / max over the poses of each test set",
             f"{'model':<{width}}" + "".join(n.rjust(c) for n, c in zip(names, columns))]
    lines += [f"{label:<{width}}" + "".join(cell(s, c) for s, c in zip(stats, columns)) for label, stats in rows]
    tail = []
    for n in names:
        rp = figures[n]["uncompensated"]["RP_max_mm"]
        tail.append(f"{figures[n]['poses']} ({figures[n]['cycles_max']}" + (f", {rp:.3f})" if rp is not None else ")"))
    lines.append(f"{'poses (cycles, RP max)':<{width}}" + "".join(t.rjust(c) for t, c in zip(tail, columns)))
    short = [f"{model} on {n}: {s['converged']} of {s['n']}" for model in measured for n in names
             if (s := figures[n].get("measured", {}).get(model)) is not None and s.get("converged", 0) < s.get("n", 0)]
    if short:
        lines.append("measured over the targets whose compensation converged: " + "; ".join(short))
    return lines


# ---------------------------------------------------------------------- summaries
def _floats(values) -> list:
    return [None if not np.isfinite(v) else float(v) for v in np.ravel(values)]


def summary(figures: iso9283.PoseFigures) -> dict:
    """The figures over all poses: ``AP_mean_mm``, ``AP_max_mm`` and, with repeats, ``RP_max_mm``, ``RP_mean_mm``
    (over the poses measured more than once); with orientation ``AP_abc_max_deg``, ``RP_abc_max_deg``.

    >>> cyc = iso9283.Cycles(np.array([0, 1]), np.array([0, 0]))
    >>> summary(iso9283.pose_figures(np.zeros((2, 3)), np.array([[3.0, 4, 0], [1.0, 0, 0]]), cyc))
    {'poses': 2, 'AP_mean_mm': 3.0, 'AP_max_mm': 5.0, 'RP_mean_mm': None, 'RP_max_mm': None}
    """
    rp = figures.rp_mm[np.isfinite(figures.rp_mm)]
    out = {"poses": int(len(figures.ap_mm)), "AP_mean_mm": float(figures.ap_mm.mean()),
           "AP_max_mm": float(figures.ap_mm.max()),
           "RP_mean_mm": float(rp.mean()) if rp.size else None, "RP_max_mm": float(rp.max()) if rp.size else None}
    if figures.ap_abc_deg is not None:
        out["AP_abc_max_deg"] = _floats(np.abs(figures.ap_abc_deg).max(axis=0))
        rp_abc = figures.rp_abc_deg[np.isfinite(figures.rp_abc_deg[:, 0])]
        out["RP_abc_max_deg"] = _floats(rp_abc.max(axis=0)) if len(rp_abc) else None
    return out


def to_dict(figures: iso9283.PoseFigures, distance: iso9283.DistanceFigures | None = None,
            path: iso9283.PathFigures | None = None,
            lines=None) -> dict:
    """Plain JSON values of the figures: ``summary``, one entry per pose, and the distance and path figures."""
    poses = []
    for k in range(len(figures.ap_mm)):
        entry = {"pose": k + 1, "cycles": int(figures.n_cycles[k]),
                 "commanded_mm": _floats(figures.commanded_mm[k]), "AP_mm": float(figures.ap_mm[k]),
                 "APx_mm": float(figures.ap_xyz_mm[k, 0]), "APy_mm": float(figures.ap_xyz_mm[k, 1]),
                 "APz_mm": float(figures.ap_xyz_mm[k, 2]), "RP_mm": _floats([figures.rp_mm[k]])[0]}
        if lines is not None:
            entry["line"] = int(lines[k])
        if figures.ap_abc_deg is not None:
            entry.update({f"AP_{a}_deg": float(v) for a, v in zip("abc", figures.ap_abc_deg[k])})
            entry.update({f"RP_{a}_deg": f for a, f in zip("abc", _floats(figures.rp_abc_deg[k]))})
        poses.append(entry)
    out = {"summary": summary(figures), "poses": poses}
    if distance is not None:
        out["distance"] = {"poses": [distance.poses[0] + 1, distance.poses[1] + 1], "cycles": distance.n_cycles,
                           "Dc_mm": distance.commanded_mm, "AD_mm": distance.ad_mm,
                           "RD_mm": _floats([distance.rd_mm])[0], "AD_xyz_mm": _floats(distance.ad_xyz_mm),
                           "RD_xyz_mm": _floats(distance.rd_xyz_mm)}
    if path is not None:
        out["path"] = {"AT_mm": path.at_mm, "AT_point": path.at_point + 1,
                       "RT_mm": _floats([path.rt_mm])[0], "RT_point": path.rt_point + 1}
    return out


def _cell(value, width: int = 9, digits: int = 4) -> str:
    return f"{'-':>{width}}" if value is None or not np.isfinite(value) else f"{value:>{width}.{digits}f}"


def table_lines(figures: iso9283.PoseFigures, distance: iso9283.DistanceFigures | None = None,
                path: iso9283.PathFigures | None = None,
                max_rows: int = 40) -> list[str]:
    """The text table ``partcal iso9283`` prints: one row per pose (the first ``max_rows``), then the summary."""
    orient = figures.ap_abc_deg is not None
    head = f"{'pose':>5}{'cycles':>7}{'AP':>9}{'APx':>9}{'APy':>9}{'APz':>9}{'RP':>9}"
    head += f"{'AP_a':>9}{'AP_b':>9}{'AP_c':>9}{'RP_a':>9}{'RP_b':>9}{'RP_c':>9}" if orient else ""
    out = ["ISO 9283 pose figures (mm" + (", degrees" if orient else "") + ")", head]
    for k in range(min(len(figures.ap_mm), max_rows)):
        row = (f"{k + 1:>5}{int(figures.n_cycles[k]):>7}{_cell(figures.ap_mm[k])}"
               + "".join(_cell(v) for v in figures.ap_xyz_mm[k]) + _cell(figures.rp_mm[k]))
        if orient:
            row += "".join(_cell(v) for v in figures.ap_abc_deg[k]) + "".join(_cell(v) for v in figures.rp_abc_deg[k])
        out.append(row)
    if len(figures.ap_mm) > max_rows:
        out.append(f"  ... {len(figures.ap_mm) - max_rows} more poses (all of them with -o report.json)")
    s = summary(figures)
    out.append(f"{s['poses']} poses: AP mean {s['AP_mean_mm']:.4f} mm, max {s['AP_max_mm']:.4f} mm; "
               + (f"RP mean {s['RP_mean_mm']:.4f} mm, max {s['RP_max_mm']:.4f} mm" if s["RP_max_mm"] is not None
                  else "RP: no pose measured in more than one cycle"))
    if distance is not None:
        out.append(f"distance P{distance.poses[0] + 1}-P{distance.poses[1] + 1} over {distance.n_cycles} cycles: "
                   f"Dc {distance.commanded_mm:.3f} mm, AD {distance.ad_mm:.4f} mm, RD"
                   f" {_cell(distance.rd_mm, 0)} mm")
    if path is not None:
        out.append(f"path: AT {path.at_mm:.4f} mm (point {path.at_point + 1}), RT {_cell(path.rt_mm, 0)} mm "
                   f"(point {path.rt_point + 1})")
    return out


def _quiet(text: str) -> None:
    """The default of ``show``: nothing."""


def iso_report(data: str | Path, *, robot: str | Path | None = None, model: str | Path | None = None,
               fmt: str | Path | None = None, tol_deg: float = iso9283.DEFAULT_TOLERANCE_DEG,
               own_frame: bool = False, distance: tuple[int, int] | None = None, path: bool = False,
               repeatability: bool = False, output: str | Path | None = None,
               show: Callable[[str], None] = _quiet) -> IsoFigures:
    """``partcal iso9283 DATA``: the figures of a measurement file (after ``model``'s correction when given),
    their lines to ``show``, and with ``output`` the figures of every pose as JSON.

    ``robot`` (default: the model's) gives nominal positions and orientations
    by forward kinematics; the other parameters are :func:`iso_figures`' and
    :func:`read_iso_data`'s (``fmt``: the file's format YAML).
    """
    refuse_input_as_output(output, "iso9283", [("data file", data), ("format file", fmt), ("model file", model)])
    arm = robot_named(robot) if robot else None
    predictor = None
    if model:
        predictor = load_predictor(model)
        arm = arm or predictor.robot        # the data are checked against the robot the model corrects
    read = read_iso_data(data, arm, fmt=load_format(fmt) if fmt else None, tol_deg=tol_deg)
    predicted, name = None, None
    if predictor is not None:
        m = read.measurements
        predicted = (predictor.predict(joints=m.q_deg) if predictor.inputs == "joint"
                     else predictor.predict(positions=m.nominal_mm))
        name = predictor.name or Path(model).stem
    figures = iso_figures(read, predicted, own_frame=own_frame, distance=distance, path=path,
                          repeatability=repeatability)
    show(describe(read) + (f"; after model {name!r}" if name else ""))
    show("\n".join(figures.lines()))
    if output:
        doc = {"partcal_version": __version__, "data": str(data), "model": None if model is None else str(model),
               "tolerance_deg": tol_deg, "cycles_from": "column" if read.by_column else "joints",
               **figures.to_dict(pose_lines(read))}
        with atomic_write(output) as handle:
            json.dump(doc, handle, indent=1)
            handle.write("\n")
        show(f"wrote {output}")
    return figures
