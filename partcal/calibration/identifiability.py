"""What the data can identify: the rank rule and its answers to the symmetries of a cell.

Positions alone cannot tell every parameter apart: two parallel joint axes share one ``d``, the first
joint's offset is a turn of the base about its z axis, and a wrist that never moves hides its own offsets.
Those directions are found before the fit from the rank of the identification Jacobian (its columns scaled
to unit length; the rank from the singular values, the choice of which parameters to keep by column
pivoting, ties going to the first in the table, so that the choice is the same on every processor). They
stay at their nominal values and are reported as unidentifiable.

On rows of measurement types the rank rule reads the Jacobian on consistent data
(:func:`consistent_jacobian`), so that noise or a misfit cannot make a null direction (a uniform scale, a
turn of the whole cell) look merely weak.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from .chain import chain_at
from .parameters import PLAUSIBLE_ERROR, geometric_size, parameter_names

WEAK_LEVER = 0.01
"""A geometric parameter whose plausible error moves the tool by less than this fraction of what the median
geometric parameter's does is not identified (see :func:`identifiable_parameters`)."""


def identifiable_parameters(jac0: NDArray[np.float64], wanted: NDArray[np.bool_], rcond: float, units: list[str],
                            data_rows: int | None = None) -> tuple[NDArray[np.intp], int]:
    """Indices of the parameters to identify, and the rank, from the Jacobian ``jac0`` at nominal.

    The columns are scaled to unit length; the rank counts singular values
    above ``rcond`` times the largest; column pivoting picks that many
    columns (the most independent first, :func:`_most_independent`). Columns
    that do not move the tool at all never count, and neither does a
    geometric parameter (mm, degrees) whose plausible error
    (:data:`PLAUSIBLE_ERROR`) moves the tool by less than :data:`WEAK_LEVER`
    of the median one's: a joint offset whose lever is a millimetre (a target
    on the last joint's axis) would mimic a tool offset, which unit columns
    cannot tell apart from it, and would then need a turn of degrees for a
    tenth of a millimetre, far outside the range where the fit converges.

    ``data_rows``: the first rows of ``jac0`` are the measurements' and the rest a prior's (which move no
    tool): the median lever is read on those rows alone. (Read on the prior's rows too, a strong prior's
    columns raised it ten thousandfold and dropped every parameter it does not hold, the base frame of an
    update among them.)
    """
    norms = np.linalg.norm(jac0, axis=0)
    moving = wanted & (norms > 1e-12 * max(norms.max(), 1e-300))
    per_unit = np.array([PLAUSIBLE_ERROR.get(unit, np.nan) for unit in units])
    plausible = per_unit * norms
    lever = plausible if data_rows is None else per_unit * np.linalg.norm(jac0[:data_rows], axis=0)
    geometric = moving & np.isfinite(plausible)
    if geometric.any():
        moving &= ~geometric | (plausible >= WEAK_LEVER * np.median(lever[geometric]))
    candidates = np.flatnonzero(moving)
    if candidates.size == 0:
        return candidates, 0
    scaled = jac0[:, candidates] / norms[candidates]
    singular = np.linalg.svd(scaled, compute_uv=False)
    rank = int(np.sum(singular > rcond * singular[0]))
    return np.sort(candidates[_most_independent(scaled, rank)]), rank


PIVOT_TIE = 1e-6
"""Columns whose parts left after the columns already chosen differ in length by less than this fraction of
the longest count as equally independent, and the first of them is chosen (see :func:`_most_independent`)."""


def _most_independent(columns: NDArray[np.float64], count: int) -> NDArray[np.intp]:
    """The positions of ``count`` columns of ``columns``, the most independent first: at each step the column
    with the longest part left after projecting out those already chosen (QR's column pivoting).

    Parameters whose columns are exactly dependent (a joint offset and the base's turn about the same axis,
    as positions see them) leave parts of equal length, which rounding orders at random: pivoted QR picked
    one with one processor's BLAS kernels and the other with another's, and the model's orientation changed
    with the choice. Here parts within :data:`PIVOT_TIE` of the longest count as equal and the first such
    column of the parameter table is chosen, so the choice is the same wherever it runs.

    Examples
    --------
    >>> columns = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1e-15]])
    >>> _most_independent(columns, 2).tolist()
    [0, 1]
    """
    left = np.array(columns, dtype=float)
    chosen: list[int] = []
    for _ in range(count):
        lengths = np.linalg.norm(left, axis=0)
        lengths[chosen] = -1.0
        best = int(np.flatnonzero(lengths >= (1.0 - PIVOT_TIE) * lengths.max())[0])
        chosen.append(best)
        direction = left[:, best] / lengths[best]
        for _ in range(2):                                      # twice: Gram-Schmidt keeps its orthogonality
            left -= np.outer(direction, direction @ left)
    return np.array(chosen, dtype=np.intp)



def scale_direction(problem) -> NDArray[np.float64]:
    """The parameter change of a uniform scale of the whole cell by one: the robot's lengths (found as the
    length parameters' change that moves every row's target ``p`` by ``p``, the base's place included), and
    every length among the types' unknowns by its own value. Zero when the robot's lengths cannot do it."""
    chain = chain_at(problem.nominal, problem.errors, problem.poses, problem.start[:problem.own],
                     problem.pose_payload, problem.par, False, True)
    units = [u for _, u in parameter_names(problem.nominal, problem.errors, problem.par)]
    size = geometric_size(problem.nominal, problem.par)
    lengths = np.flatnonzero(np.array(units[:size]) == "mm")
    jac = chain.jac[:, :, lengths].reshape(-1, lengths.size)
    x = np.linalg.lstsq(jac, chain.positions.ravel(), rcond=None)[0]
    s = np.zeros(problem.start.size)
    if np.linalg.norm(jac @ x - chain.positions.ravel()) > 1e-6 * np.linalg.norm(chain.positions):
        return s
    s[lengths] = x
    mine = np.array([u == "mm" for _, u in problem.names], dtype=bool)
    scaled = problem.start[problem.own:].copy()
    for measurement, cols in zip(problem.measurements, problem.columns):
        scaled[cols - problem.own] = measurement.scaled_lengths(scaled[cols - problem.own])
    s[problem.own:][mine] = scaled[mine]
    return s


def rigid_directions(problem) -> NDArray[np.float64]:
    """The parameter changes of the six rigid motions of the whole cell (shifts along, then turns about the base
    frame's axes, through its origin), as columns ``(P, 6)``: the base correction (its shift, its turn) and the
    types' unknowns as each type moves them (:meth:`MeasurementType.moved`)."""
    size = geometric_size(problem.nominal, problem.par)
    out = np.zeros((problem.start.size, 6))
    for k in range(3):
        out[size - 6 + k, k] = 1.0                           # base.x, y, z: mm
        out[size - 3 + k, 3 + k] = np.degrees(1.0)           # base.rx, ry, rz: degrees per radian
    seen: set[int] = set()
    for measurement, cols in zip(problem.measurements, problem.columns):
        u = problem.start[cols]
        new = np.array([c not in seen for c in cols], dtype=bool)      # a shared unknown moves once
        for k in range(6):
            motion = np.eye(6)[k]
            out[cols[new], k] = measurement.moved(u, motion[3:], motion[:3])[new]
        seen.update(cols.tolist())
    return out


def misfit_parts(problem, values: NDArray[np.float64]) -> NDArray[np.float64]:
    """What the residuals' misfit adds to the Jacobian's answer to a scale and to the three turns of the cell,
    columns ``(m, 4)`` (weighted as the stacked residuals): the residuals are homogeneous in the cell's lengths
    (``J s = r + L``, ``L`` the known lengths, for the residuals that are lengths) and a vector residual turns
    with the cell (``J s_k = e_k x r + ...``), so on consistent data (``r = 0``) these parts are nil."""
    parts = []
    for index, r in enumerate(problem.each(values)):
        w = problem.weight_of(index, r)[:, None]
        m = np.zeros((r.values.size, 4))
        m[:, 0] = r.values if r.scaled is None else np.where(r.scaled, r.values, 0.0)
        if r.turning is not None and r.turning.any():
            at = np.flatnonzero(r.turning)
            triples = r.values[at].reshape(-1, 3)
            for k in range(3):
                m[at, 1 + k] = np.cross(np.eye(3)[k], triples).ravel()
        parts.append(w * m)
    return np.vstack(parts)


def consistent_jacobian(jac0: NDArray[np.float64], misfit: NDArray[np.float64], directions: NDArray[np.float64],
                        rcond: float) -> NDArray[np.float64]:
    """The Jacobian the rank rule reads: ``jac0`` with its answers to the cell's symmetries made what they would
    be on consistent data.

    ``directions`` (P, k) are parameter changes of a uniform scale and of turns of the whole cell; ``misfit``
    (m, k) what the residuals' misfit adds to ``jac0``'s answer to each (:func:`misfit_parts`). At the nominal
    robot the residuals are its misfit (millimetres), which made a scale or a turn about a known point that
    nothing fixes look merely weak. ``jac0`` is changed along those directions alone, with the directions it
    already cannot see (a shift of the whole cell) taken out of them, so that those stay as they are; in
    unit-column coordinates, as the rank rule reads them. Directions ``jac0`` already cannot see are left.
    """
    norms = np.linalg.norm(jac0, axis=0)
    live = norms > 0
    unit = jac0[:, live] / norms[live]
    r = scipy.linalg.qr(unit, mode="r")[0][:unit.shape[1]] if unit.shape[0] > unit.shape[1] else unit
    _, singular, vt = np.linalg.svd(r, full_matrices=False)
    null = vt[singular < rcond * singular[0]]
    whole = directions[live] * norms[live][:, None]
    t = whole - null.T @ (null @ whole)
    keep = np.linalg.norm(t, axis=0) > 1e-9 * np.maximum(np.linalg.norm(whole, axis=0), 1e-300)
    if not keep.any():
        return jac0         # each is a null direction already: the data are consistent along it (planned rows)
    t, misfit = t[:, keep], misfit[:, keep]
    out = jac0.copy()
    out[:, live] = (unit - misfit @ np.linalg.pinv(t)) * norms[live]
    return out


def null_direction(jac: NDArray[np.float64], direction: NDArray[np.float64], wanted, rcond: float) -> bool:
    """Whether ``direction`` over the ``wanted`` parameters changes no residual, as the rank rule counts zero:
    ``|J s|`` below ``rcond`` times the largest singular value, in unit-column coordinates."""
    norms = np.linalg.norm(jac, axis=0)
    live = wanted & (norms > 0)
    scaled = direction[live] * norms[live]
    if not np.any(scaled):
        return False
    t = scaled / np.linalg.norm(scaled)
    unit = jac[:, live] / norms[live]
    largest = np.linalg.svd(unit, compute_uv=False)[0]
    return bool(np.linalg.norm(unit @ t) < np.sqrt(rcond) * largest)
