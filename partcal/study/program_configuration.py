"""Whether the joints of a compensated robot program keep the configuration its targets were written with.

Three things, as a controller sees them: the vendor's configuration written with a target (KUKA ``T``: the
axes' signs; ABB ``cf1 cf4 cf6``: quarter revolutions; a joint within :data:`BOUNDARY_DEG` of an edge is on
both sides), no flip of the arm (the sign of the Jacobian's determinant, where it is not ~0), and, where the
intended wrist is straight (axes 4 and 6 turning about one line, :mod:`partcal.robot.wrist`), the turn the two
share instead of their split, which the pose does not fix.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..data.program_text import Program, Target
from ..robot.wrist import shared_turns

BOUNDARY_DEG = 1e-6       # a joint this close to a configuration's boundary is in both
SINGULAR_DET = 1e-6
"""The determinant of the reach-scaled Jacobian below which a pose counts as on a singularity, whose sign
means nothing. On the SK120's rectangle the determinant is about 2e-4 times axis 5 in degrees: a wrist written
at axis 5 = 0 to micrometres lies 1e-4 degrees off it (2e-8), where the sign is the rounding's (1e-9 counted
three of ten such targets as flips); 1e-6 holds axis 5 within 0.005 degrees as on the singularity."""

def written_ranges(program: Program, targets: list[Target], n_joints: int) -> tuple:
    """The joint ranges (low, high (n, N) degrees) the configurations written with ``targets`` allow (-inf, inf
    where none is written or the dialect has none): where a straight wrist's shared turn is split."""
    low, high = np.full((len(targets), n_joints), -np.inf), np.full((len(targets), n_joints), np.inf)
    rows = [k for k, t in enumerate(targets) if t.configuration is not None]
    if program.dialect.ranges is not None and rows:
        config = np.array([[-1 if c is None else c for c in targets[k].configuration] for k in rows])
        lo, hi = program.dialect.ranges(config)
        low[rows, :lo.shape[1]], high[rows, :hi.shape[1]] = lo, hi
    return low, high


def _matches(program: Program, targets: list[Target], q: NDArray[np.float64], q0=None) -> NDArray[np.bool_]:
    """Whether joint solutions have the configuration their targets name (the parts the dialect compares).
    With the intended joints ``q0`` and a dialect whose edges are kept (``Dialect.edge_kept``): a target whose
    intended joint lies on an edge (ABB axis 4 at 0, tool down) has both sides' configuration, so ``q`` may be
    on either."""
    dialect = program.dialect
    ok = np.ones(len(q), dtype=bool)
    if dialect.configuration is None or not dialect.compare:
        return ok
    low, high = _configuration_bounds(dialect, q)
    edge = _configuration_bounds(dialect, q0) if q0 is not None and dialect.edge_kept else None
    for j, t in enumerate(targets):
        if t.configuration is not None:
            ok[j] = all(t.configuration[i] is None or t.configuration[i] in (low[j, i], high[j, i]) or
                        (edge is not None and edge[0][j, i] != edge[1][j, i] and t.configuration[i] in
                         (edge[0][j, i], edge[1][j, i]) and {low[j, i], high[j, i]} & {edge[0][j, i], edge[1][j, i]})
                        for i in dialect.compare)
    return ok


def _configuration_bounds(dialect, q) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The configuration of joints ``q`` (n, N) moved by -/+ 1e-6 degrees: a joint on a boundary (a KUKA
    axis at 0, an ABB axis at 90) is in both configurations."""
    return dialect.configuration(q - BOUNDARY_DEG), dialect.configuration(q + BOUNDARY_DEG)


def configuration_kept(robot, program: Program, targets: list[Target], q0, q1) -> NDArray[np.bool_]:
    """No flip (the Jacobian's determinant keeps its sign, where not ~0), and the configuration written with a
    target (KUKA ``T``, ABB ``cf1 cf4 cf6``) still that of the compensated joints. A target written without
    one is the controller's to solve near where the robot is: only a flip changes it. Where the intended wrist
    is straight (:func:`configuration_of`), its bend's sign is no branch: the compensated pose's wrist bends
    the way its tilt needs, or its twin half a turn round the other way."""
    straight = shared_turns(robot, q0)[0] >= 0
    before = np.where(straight, 0.0, _branch(robot, q0))
    return (before * _branch(robot, q1) >= 0) & configuration_of(robot, program, targets, q1, q0)


def configuration_of(robot, program: Program, targets: list[Target], q, q0) -> NDArray[np.bool_]:
    """Whether joints ``q`` (n, N) have the configuration written with their targets (:func:`_matches`, with the
    intended joints ``q0`` for the edges). Where ``q0``'s wrist is straight (two joints share one turn,
    :func:`~partcal.robot.wrist.shared_turns`), the written configuration is checked on the shared turn
    (:func:`_shared_turn_kept`)."""
    kept = _matches(program, targets, q, q0)
    j, k, c = shared_turns(robot, q0)
    straight = np.flatnonzero((j >= 0) & np.array([t.configuration is not None for t in targets], dtype=bool))
    if straight.size and program.dialect.ranges is not None:
        kept[straight] = _shared_turn_kept(program, [targets[i] for i in straight], q[straight], j[straight],
                                           k[straight], c[straight])
    return kept


def _shared_turn_kept(program: Program, targets: list[Target], q1, j, k, c) -> NDArray[np.bool_]:
    """The written configuration of targets whose intended wrist is straight (joints ``j`` and ``k`` turning
    about one line, the bend between them at 0): it names one split of the turn the two share, which the
    compensated pose, a fraction of a degree off straight, splits its own way (or, the bend's sign flipped,
    its twin half a turn round: the same pose). Kept when the other joints stay in their written ranges and
    the shared turn ``c q_j + q_k`` in the range the written ranges of ``j`` and ``k`` give it."""
    low, high = written_ranges(program, targets, q1.shape[1])
    low, high = low - BOUNDARY_DEG, high + BOUNDARY_DEG
    rows = np.arange(len(q1))
    columns = np.arange(q1.shape[1])[None, :]
    wrist = (columns >= j[:, None]) & (columns <= k[:, None])
    others = np.all(wrist | ((q1 >= low) & (q1 <= high)), axis=1)
    ends = np.sort(np.stack([c * low[rows, j], c * high[rows, j]]), axis=0)
    turn = c * q1[rows, j] + q1[rows, k]
    with np.errstate(invalid="ignore"):          # inf - inf: a range free at both ends
        shared = (turn >= ends[0] + low[rows, k]) & (turn <= ends[1] + high[rows, k])
    return others & shared


def configurations_text(program: Program, q0, q1) -> str:
    dialect = program.dialect
    if dialect.configuration is not None and dialect.compare:
        a, b = dialect.configuration(q0[None])[0], dialect.configuration(q1[None])[0]
        if not np.array_equal(a[list(dialect.compare)], b[list(dialect.compare)]):
            return f"{a.tolist()} -> {b.tolist()} in {dialect.name}'s terms"
    return "the arm flips: the Jacobian's determinant changes sign"


def _branch(robot, q: NDArray[np.float64], step_deg: float = 1e-4) -> NDArray[np.float64]:
    """Sign of the 6 x 6 Jacobian's determinant (position mm, rotation vector rad; by central differences),
    0 within :data:`SINGULAR_DET` of a singularity (relative to the arm's reach)."""
    n, N = q.shape
    if n == 0 or N != 6:
        return np.zeros(n)
    shifted = np.repeat(q[:, None], 2 * N, axis=1)
    for k in range(N):
        shifted[:, 2 * k, k] += step_deg
        shifted[:, 2 * k + 1, k] -= step_deg
    T = robot.forward(shifted.reshape(-1, N)).reshape(n, 2 * N, 4, 4)
    dp = (T[:, 0::2, :3, 3] - T[:, 1::2, :3, 3]) / robot.reach_mm
    dR = np.einsum("nkij,nklj->nkil", T[:, 0::2, :3, :3], T[:, 1::2, :3, :3])
    dr = np.stack([dR[..., 2, 1] - dR[..., 1, 2], dR[..., 0, 2] - dR[..., 2, 0], dR[..., 1, 0] - dR[..., 0, 1]],
                  axis=-1) / 2.0
    J = np.concatenate([dp, dr], axis=2) / (2 * np.radians(step_deg))       # (n, 6 joints, 6)
    det = np.linalg.det(J)
    return np.where(np.abs(det) > SINGULAR_DET, np.sign(det), 0.0)
