"""ISO 9283 performance figures of a manipulator from measured cycles: pose, distance and path.

Every function takes plain arrays (positions in mm, orientation deviations in
degrees) and the cycles the data were measured in (:class:`Cycles`: which
commanded pose each row is, and in which cycle). The figures and their
symbols are those of ISO 9283:1998 (see ``docs/iso9283.md``):

- pose accuracy ``AP = |barycentre of the attained positions - commanded|``
  with its parts ``APx, APy, APz``;
- pose repeatability ``RP = mean(l) + 3 S_l``, ``l`` the distances of the
  attained positions to their barycentre, ``S_l`` their sample standard
  deviation;
- orientation accuracy ``AP_a, AP_b, AP_c`` (mean deviation about x, y, z)
  and repeatability ``RP_a, RP_b, RP_c`` (3 sample standard deviations);
- distance accuracy ``AD = mean(D) - D_c`` and repeatability ``RD = 3 S_D``
  between two poses measured in the same cycles;
- path accuracy ``AT`` and repeatability ``RT``: the largest of the pose
  figures over the points of a path, measured in the plane normal to it.

Bad input (a pose measured once where a repeatability is asked, cycles that
command different poses) is refused with a :class:`~partcal.errors.DataError`
that names the file, its line and the field.

>>> cyc = cycles_from_joints(np.array([[0.0], [10.0], [0.0], [10.0]]))
>>> cyc.pose.tolist(), cyc.cycle.tolist()
([0, 1, 0, 1], [0, 0, 1, 1])
>>> f = pose_figures(np.zeros((4, 3)), np.array([[1.0, 0, 0], [0, 0, 0], [3.0, 0, 0], [0, 0, 0]]), cyc)
>>> f.ap_mm.tolist(), f.rp_mm.tolist()                 # barycentre (2, 0, 0); l = 1, 1: RP = 1 + 3 * 0
([2.0, 0.0], [1.0, 0.0])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError

DEFAULT_TOLERANCE_DEG = 0.01      # commanded joints this close are one pose (a tracker session's rounding)
REPEATABILITY_FACTOR = 3.0        # ISO 9283: mean distance + 3 standard deviations


# ---------------------------------------------------------------------- cycles
@dataclass(frozen=True)
class Cycles:
    """Which commanded pose each measured row is, and in which cycle.

    Attributes
    ----------
    pose : ndarray of int, shape (n,)
        Pose number of each row, from 0 in order of first appearance.
    cycle : ndarray of int, shape (n,)
        Cycle number of each row, from 0.
    """

    pose: NDArray[np.intp]
    cycle: NDArray[np.intp]

    @property
    def n_poses(self) -> int:
        return int(self.pose.max()) + 1 if self.pose.size else 0

    @property
    def counts(self) -> NDArray[np.intp]:
        """Cycles (rows) of each pose, shape (P,)."""
        return np.bincount(self.pose, minlength=self.n_poses)

    def first_rows(self) -> NDArray[np.intp]:
        """The first row of each pose, shape (P,)."""
        first = np.full(self.n_poses, len(self.pose), dtype=np.intp)
        np.minimum.at(first, self.pose, np.arange(len(self.pose)))
        return first


def where(source: str, lines, row: int) -> str:
    """``FILE:LINE`` of a data row (0-based ``row``) when the lines are known, else ``FILE: data row K``."""
    if lines is not None:
        return f"{source}:{int(lines[row])}"
    return f"{source}: data row {row + 1}"


def _first_appearance(labels: NDArray[np.intp]) -> NDArray[np.intp]:
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), dtype=np.intp)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[np.ravel(inverse)]


def cycles_from_joints(q_deg, tol_deg: float = DEFAULT_TOLERANCE_DEG) -> Cycles:
    """Cycles recognised from repeated commanded poses: rows whose joints agree within ``tol_deg`` are one pose.

    Rows are linked when every joint differs by at most ``tol_deg``; a pose is
    a connected set of linked rows, and its rows are its cycles in file order.

    Parameters
    ----------
    q_deg : array-like, shape (n, N)
        Commanded joint angles, degrees.
    tol_deg : float
        Largest difference of one joint between two visits of one pose, degrees.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    q = np.asarray(q_deg, dtype=float).reshape(len(q_deg), -1)
    pairs = cKDTree(q).query_pairs(tol_deg, p=np.inf, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(q), len(q)))
    pose = _first_appearance(connected_components(graph, directed=False)[1])
    return Cycles(pose, _occurrence(pose))


def _occurrence(pose: NDArray[np.intp]) -> NDArray[np.intp]:
    """How many earlier rows have the same pose: the cycle of each row."""
    order = np.argsort(pose, kind="stable")
    counts = np.bincount(pose)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = np.empty_like(pose)
    out[order] = np.arange(len(pose)) - np.repeat(starts, counts)
    return out


def cycles_from_column(cycle_labels, q_deg, tol_deg: float = DEFAULT_TOLERANCE_DEG, *, source: str = "data",
                       lines=None, columns=None) -> Cycles:
    """Cycles from a ``cycle`` column: the k-th row of every cycle is the same commanded pose.

    Parameters
    ----------
    cycle_labels : array-like, shape (n,)
        The cycle of each row (any labels; cycles are numbered in order of first appearance).
    q_deg : array-like, shape (n, N)
        Commanded joint angles, degrees: row k of every cycle must command the
        joints of row k of the first cycle, within ``tol_deg``.
    source, lines : str and sequence of int, optional
        The file and the line of each row, for the error messages.
    columns : sequence of str, optional
        Names of the joint columns (default ``q1..qN``).

    Raises
    ------
    DataError
        A cycle with another number of rows than the first, or commanding
        another pose than the first cycle at the same place.
    """
    q = np.asarray(q_deg, dtype=float).reshape(len(q_deg), -1)
    cycle_labels = np.asarray(cycle_labels)
    cycle = _first_appearance(np.unique(cycle_labels, return_inverse=True)[1].ravel()).astype(np.intp)
    counts = np.bincount(cycle)
    names = list(columns) if columns is not None else [f"q{j + 1}" for j in range(q.shape[1])]
    if np.any(counts != counts[0]):
        c = int(np.flatnonzero(counts != counts[0])[0])
        row = int(np.flatnonzero(cycle == c)[0])
        raise DataError(f"{where(source, lines, row)}: column 'cycle': cycle {str(cycle_labels[row])!r} has {counts[c]} "
                        f"rows, expected {counts[0]} like the first cycle (every cycle visits the same poses)")
    pose = _occurrence(cycle)
    first = np.flatnonzero(cycle == 0)           # row of pose k in the first cycle: first[k]
    off = np.abs(q - q[first[pose]])
    bad = np.argwhere(off > tol_deg)
    if bad.size:
        row, j = (int(v) for v in bad[0])
        raise DataError(f"{where(source, lines, row)}: column {names[j]!r}: pose {pose[row] + 1} of cycle "
                        f"{str(cycle_labels[row])!r} commands {q[row, j]:.6g} deg, expected {q[first[pose[row]], j]:.6g} "
                        f"(within {tol_deg:g} deg) as in the first cycle: commanded poses differ between cycles")
    return Cycles(pose, cycle)


def require_repeats(cycles: Cycles, *, source: str = "data", lines=None, what: str = "repeatability",
                    field: str = "column 'cycle'") -> None:
    """Refuse a pose measured in fewer than two cycles, naming its first line and ``field``, what its cycles
    came from (the ``cycle`` column, or the joint columns when poses are recognised from repeated joints):
    ``what`` needs repeats."""
    once = np.flatnonzero(cycles.counts < 2)
    if once.size:
        row = int(cycles.first_rows()[once[0]])
        raise DataError(f"{where(source, lines, row)}: {field}: pose {once[0] + 1} was measured in 1 cycle, "
                        f"but {what} needs at least 2 (ISO 9283 asks for 30); {once.size} of {cycles.n_poses} poses "
                        "have a single cycle")


# ---------------------------------------------------------------------- pose figures
@dataclass(frozen=True)
class PoseFigures:
    """ISO 9283 pose accuracy and repeatability of every commanded pose (P poses).

    Attributes
    ----------
    n_cycles : ndarray of int, shape (P,)
    commanded_mm, barycentre_mm : ndarray, shape (P, 3)
        The commanded position (mean over the cycles) and the barycentre of the attained ones.
    ap_xyz_mm : ndarray, shape (P, 3)
        ``APx, APy, APz``: barycentre minus commanded.
    ap_mm : ndarray, shape (P,)
        ``AP``: the distance of the barycentre from the commanded position.
    l_mean_mm, s_l_mm, rp_mm : ndarray, shape (P,)
        Mean distance to the barycentre, its sample standard deviation and
        ``RP = l_mean + 3 S_l``; NaN for a pose measured once.
    ap_abc_deg, rp_abc_deg : ndarray, shape (P, 3), or None
        ``AP_a, AP_b, AP_c`` (mean orientation deviation about x, y, z) and
        ``RP_a, RP_b, RP_c`` (3 sample standard deviations), degrees; None
        without measured orientation.
    """

    n_cycles: NDArray[np.intp]
    commanded_mm: NDArray[np.float64]
    barycentre_mm: NDArray[np.float64]
    ap_xyz_mm: NDArray[np.float64]
    ap_mm: NDArray[np.float64]
    l_mean_mm: NDArray[np.float64]
    s_l_mm: NDArray[np.float64]
    rp_mm: NDArray[np.float64]
    ap_abc_deg: NDArray[np.float64] | None = None
    rp_abc_deg: NDArray[np.float64] | None = None


def _means(values: NDArray[np.float64], pose: NDArray[np.intp], counts: NDArray[np.intp]) -> NDArray[np.float64]:
    """Mean of each column of ``values (n, k)`` over the rows of each pose, shape (P, k)."""
    return np.stack([np.bincount(pose, weights=values[:, j], minlength=len(counts)) for j in range(values.shape[1])],
                    axis=1) / counts[:, None]


def _sample_std(values: NDArray[np.float64], pose: NDArray[np.intp], counts: NDArray[np.intp],
                means: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sample standard deviation (``n - 1``) of each column per pose, shape (P, k); NaN for one cycle."""
    dev = (values - means[pose]) ** 2
    ss = np.stack([np.bincount(pose, weights=dev[:, j], minlength=len(counts)) for j in range(values.shape[1])],
                  axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts[:, None] > 1, np.sqrt(ss / np.maximum(counts - 1, 1)[:, None]), np.nan)


def pose_figures(commanded_mm, attained_mm, cycles: Cycles, orientation_deviation_deg=None) -> PoseFigures:
    """ISO 9283 pose accuracy (AP) and repeatability (RP) of every pose.

    Parameters
    ----------
    commanded_mm, attained_mm : array-like, shape (n, 3)
        Commanded (nominal) and attained (measured) positions of every row, mm.
    cycles : Cycles
        The pose and cycle of every row.
    orientation_deviation_deg : array-like, shape (n, 3), optional
        Attained orientation relative to the commanded one, as the rotation
        vector's components about x, y, z (degrees): the orientation figures
        ``AP_a..``, ``RP_a..`` come from it.
    """
    cmd = np.asarray(commanded_mm, dtype=float)
    att = np.asarray(attained_mm, dtype=float)
    pose, counts = cycles.pose, cycles.counts
    commanded, bary = _means(cmd, pose, counts), _means(att, pose, counts)
    ap_xyz = bary - commanded
    dist = np.linalg.norm(att - bary[pose], axis=1)[:, None]
    l_mean = _means(dist, pose, counts)
    s_l = _sample_std(dist, pose, counts, l_mean)[:, 0]
    l_mean = l_mean[:, 0]
    ap_abc = rp_abc = None
    if orientation_deviation_deg is not None:
        turn = np.asarray(orientation_deviation_deg, dtype=float)
        ap_abc = _means(turn, pose, counts)
        rp_abc = REPEATABILITY_FACTOR * _sample_std(turn, pose, counts, ap_abc)
    return PoseFigures(counts, commanded, bary, ap_xyz, np.linalg.norm(ap_xyz, axis=1), l_mean, s_l,
                       l_mean + REPEATABILITY_FACTOR * s_l, ap_abc, rp_abc)


# ---------------------------------------------------------------------- distance figures
@dataclass(frozen=True)
class DistanceFigures:
    """ISO 9283 distance accuracy and repeatability between two poses measured in the same cycles.

    Attributes
    ----------
    poses : tuple of int
        The two poses (0-based).
    n_cycles : int
    commanded_mm : float
        ``D_c``, the commanded distance.
    ad_mm, rd_mm : float
        ``AD = mean(D_j) - D_c`` and ``RD = 3 S_D`` (NaN for one cycle).
    ad_xyz_mm, rd_xyz_mm : ndarray, shape (3,)
        The same per axis, of ``D_x = |x_1 - x_2|`` and so on.
    """

    poses: tuple[int, int]
    n_cycles: int
    commanded_mm: float
    ad_mm: float
    rd_mm: float
    ad_xyz_mm: NDArray[np.float64]
    rd_xyz_mm: NDArray[np.float64]


def distance_figures(commanded_mm, attained_mm, cycles: Cycles, poses: tuple[int, int]) -> DistanceFigures:
    """Distance accuracy (AD) and repeatability (RD) between ``poses`` (0-based), over the cycles with both.

    ``D_j`` is the distance between the attained positions of the two poses in
    cycle ``j``; ``D_c`` that between their commanded positions (means over the cycles).
    """
    cmd = np.asarray(commanded_mm, dtype=float)
    att = np.asarray(attained_mm, dtype=float)
    a, b = poses
    rows_a = {int(c): k for k, c in zip(np.flatnonzero(cycles.pose == a), cycles.cycle[cycles.pose == a])}
    rows_b = {int(c): k for k, c in zip(np.flatnonzero(cycles.pose == b), cycles.cycle[cycles.pose == b])}
    both = sorted(set(rows_a) & set(rows_b))
    ia, ib = [rows_a[c] for c in both], [rows_b[c] for c in both]
    if not both:
        raise DataError(f"poses {a + 1} and {b + 1} share no cycle, so their distance was never measured")
    d_xyz = np.abs(att[ia] - att[ib])
    d = np.linalg.norm(att[ia] - att[ib], axis=1)
    c_xyz = np.abs(cmd[ia].mean(axis=0) - cmd[ib].mean(axis=0))
    n = len(both)
    rd = REPEATABILITY_FACTOR * d.std(ddof=1) if n > 1 else np.nan
    rd_xyz = REPEATABILITY_FACTOR * d_xyz.std(axis=0, ddof=1) if n > 1 else np.full(3, np.nan)
    return DistanceFigures((a, b), n, float(np.linalg.norm(c_xyz)), float(d.mean() - np.linalg.norm(c_xyz)),
                           float(rd), d_xyz.mean(axis=0) - c_xyz, rd_xyz)


# ---------------------------------------------------------------------- path figures
@dataclass(frozen=True)
class PathFigures:
    """ISO 9283 path accuracy and repeatability: the poses of one data set are the points of a path.

    Attributes
    ----------
    at_mm, rt_mm : float
        ``AT``: the largest distance, in the plane normal to the commanded
        path, from a point's barycentre to the commanded point; ``RT``: the
        largest ``mean(l) + 3 S_l`` with ``l`` measured in that plane.
    at_point, rt_point : int
        The point (pose, 0-based) where each is reached.
    deviation_mm, repeatability_mm : ndarray, shape (P,)
        Both along the path.
    """

    at_mm: float
    rt_mm: float
    at_point: int
    rt_point: int
    deviation_mm: NDArray[np.float64]
    repeatability_mm: NDArray[np.float64]


def path_tangents(points_mm: NDArray[np.float64]) -> NDArray[np.float64]:
    """Unit tangents of a polyline ``(P, 3)`` mm: central differences, one-sided at the ends, shape (P, 3).

    >>> path_tangents(np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 1, 0]])).round(3).tolist()
    [[1.0, 0.0, 0.0], [0.894, 0.447, 0.0], [0.707, 0.707, 0.0]]
    """
    step = np.gradient(np.asarray(points_mm, dtype=float), axis=0)
    norm = np.linalg.norm(step, axis=1, keepdims=True)
    return np.divide(step, norm, out=np.zeros_like(step), where=norm > 0)


def path_figures(commanded_mm, attained_mm, cycles: Cycles) -> PathFigures:
    """Path accuracy (AT) and repeatability (RT) of a path measured in cycles (each pose is a path point).

    The commanded points, in pose order, are the path; deviations are
    projected on the plane normal to it at each point (ISO 9283's normal
    planes), so a point reached a little early or late along the path is not
    counted as off the path.
    """
    cmd = np.asarray(commanded_mm, dtype=float)
    att = np.asarray(attained_mm, dtype=float)
    pose, counts = cycles.pose, cycles.counts
    commanded, bary = _means(cmd, pose, counts), _means(att, pose, counts)
    t = path_tangents(commanded)

    def normal(v, tangents):
        return v - np.sum(v * tangents, axis=1, keepdims=True) * tangents

    deviation = np.linalg.norm(normal(bary - commanded, t), axis=1)
    dist = np.linalg.norm(normal(att - bary[pose], t[pose]), axis=1)[:, None]
    l_mean = _means(dist, pose, counts)
    s_l = _sample_std(dist, pose, counts, l_mean)[:, 0]
    rep = l_mean[:, 0] + REPEATABILITY_FACTOR * s_l
    at_k = int(np.argmax(deviation))
    rt_k = int(np.nanargmax(rep)) if np.isfinite(rep).any() else 0
    return PathFigures(float(deviation[at_k]), float(rep[rt_k]), at_k, rt_k, deviation, rep)
