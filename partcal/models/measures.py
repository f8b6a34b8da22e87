"""Kinds of measurement: one identification over whatever a cell measured.

A laser tracker gives 3-D points of the tool in its own frame. Most cells own other instruments: a
touch probe and a flat plate (the tip's distance to a plane is zero), a reference sphere or a nest
reached from many orientations (the tip is at one point each time), a ballbar or draw-wire (the
distance between two tips, or between the tip and a pivot). Each is a **measurement kind**: one
class that reads its rows, declares its own unknowns (a plane's normal and offset, a point's
position), and gives its residuals and their derivatives from the chain's positions (and, where it
needs it, the tool's orientation). :data:`MEASUREMENT_KINDS` lists them; :func:`add_measurement_kind`
adds one.

:func:`identify_measures` stacks the residuals of every kind present, each divided by its kind's
stated noise (and multiplied by :data:`REFERENCE_NOISE_MM`, so that they read as millimetres of a
tracker), and fits the robot's parameters and the kinds' unknowns together with the rank rule and
Levenberg-Marquardt of :func:`~partcal.models.identification.identify`. The result is the same
:class:`~partcal.models.identification.Identification`, the kinds' unknowns listed after the robot's.

What the data cannot identify is judged on consistent data: the Jacobian at the nominal robot with
the kinds' unknowns started from the nominal robot's own positions at the measured poses, so noise
or a misfit cannot make a null direction look merely weak. A uniform scale of the robot is such a
direction whenever nothing measures a length (planes and points whose positions are all unknown):
it is named (:data:`SCALE`), and the rank rule holds one length nominal.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.kinematics import Robot
from .identification import (Identification, actual_joints, fit_parameters, geometric_size, identifiable_parameters,
                             model_jacobian, model_positions, nominal_values, parameter_names, robot_with, turn_columns)
from .joint_errors import JointErrors
from .prior import Prior

log = logging.getLogger(__name__)

REFERENCE_NOISE_MM = 0.02
"""Residuals are weighted by this over their kind's noise: a tracker point of 0.02 mm per axis weighs one."""

NEAR_MM = 20.0
"""A row whose target the nominal robot puts farther than this from what the row says (a touch from its plane,
a visit from its point's other visits) is refused as bad input: a robot's geometric errors are millimetres, so
the row names the wrong feature. (A distance is refused only by a factor, :data:`~partcal.models.contacts.UNIT_FACTOR`:
an unknown tool changes short distances by more than this.)"""

SCALE = "scale"
"""The name under which a uniform scale of the robot is reported when nothing in the data measures a length."""


@dataclass(frozen=True, eq=False)
class Rows:
    """Every row of an identification's data, all kinds together, as the study layer hands them over.

    Attributes
    ----------
    q_deg : ndarray, shape (n, N)
        Commanded joint angles, degrees.
    kind : tuple of str
        Each row's kind (a name of :data:`MEASUREMENT_KINDS`, or ``pose``: an end other rows refer to).
    ids : tuple of str
        Each row's name (the ``id`` column, or its 1-based data-row number).
    lines : tuple of int
        The line of each row in its file (for messages).
    source : str
        The file (or files) the rows came from.
    numbers : dict of str to ndarray (n,)
        Numeric columns (NaN where a row has none): ``x_meas``, ``distance_mm``, ``flush``, ...
    texts : dict of str to tuple of str
        Text columns ("" where empty): ``feature``, ``to``, ...
    payload_kg : ndarray, shape (n,), optional
    sources : tuple of str, optional
        Each row's file, when the rows come from several (``source`` names them all).
    """

    q_deg: NDArray[np.float64]
    kind: tuple[str, ...]
    ids: tuple[str, ...]
    lines: tuple[int, ...]
    source: str
    numbers: dict = field(default_factory=dict)
    texts: dict = field(default_factory=dict)
    payload_kg: NDArray[np.float64] | None = None
    sources: tuple[str, ...] | None = None

    def __len__(self) -> int:
        return self.q_deg.shape[0]

    def of(self, kind: str) -> NDArray[np.intp]:
        """The indices of the rows of ``kind``."""
        return np.flatnonzero(np.asarray(self.kind, dtype=object) == kind)

    def where(self, row: int) -> str:
        """``FILE:LINE`` of row ``row``, for messages."""
        return f"{self.source if self.sources is None else self.sources[row]}:{self.lines[row]}"

    def number(self, column: str, rows: NDArray[np.intp]) -> NDArray[np.float64]:
        """Column ``column`` at ``rows``, every value present and finite, else one :class:`DataError`."""
        values = self.numbers.get(column)
        if values is None:
            raise DataError(f"{self.source}: the {self.kind[rows[0]]} rows need a column {column!r}; the file has "
                            "none")
        out = np.asarray(values, dtype=float)[rows]
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            raise DataError(f"{self.where(rows[bad[0]])}: column {column!r}: a {self.kind[rows[bad[0]]]} row needs a "
                            f"number here, got none")
        return out

    def text(self, column: str, rows: NDArray[np.intp]) -> list[str]:
        """Column ``column`` at ``rows``, every value given, else one :class:`DataError`."""
        values = self.texts.get(column)
        if values is None:
            raise DataError(f"{self.source}: the {self.kind[rows[0]]} rows need a column {column!r}; the file has "
                            "none")
        out = [values[i] for i in rows]
        for i, v in zip(rows, out):
            if not v:
                raise DataError(f"{self.where(i)}: column {column!r}: a {self.kind[i]} row needs a name here, got "
                                "none")
        return out

    def take(self, rows) -> "Rows":
        """The rows ``rows`` (indices) as rows of their own; ``ids`` kept, so references resolve while both
        ends are among them."""
        rows = np.asarray(rows, dtype=np.intp)
        return Rows(self.q_deg[rows], tuple(self.kind[i] for i in rows), tuple(self.ids[i] for i in rows),
                    tuple(self.lines[i] for i in rows), self.source,
                    {k: np.asarray(v)[rows] for k, v in self.numbers.items()},
                    {k: tuple(v[i] for i in rows) for k, v in self.texts.items()},
                    None if self.payload_kg is None else self.payload_kg[rows],
                    None if self.sources is None else tuple(self.sources[i] for i in rows))


@dataclass(frozen=True, eq=False)
class Residuals:
    """A kind's residuals (mm, before weighting) and what they depend on.

    Attributes
    ----------
    values : ndarray, shape (m,)
    rows_a : ndarray of int, shape (m,)
        The row whose target each residual reads (an index into the identification's rows); -1: none.
    grad_a : ndarray, shape (m, 3)
        ``d value / d position`` of that row's target.
    rows_b, grad_b : the same for a second row (distances), or None.
    turn_grad : ndarray, shape (m, 3), optional
        ``d value / d turn`` of row ``rows_a``'s tool (a small rotation vector in the base frame, radians).
    scaled : ndarray of bool, shape (m,), optional
        The residuals that are lengths (they scale with the cell; None: all). An angle is not.
    turning : ndarray of bool, shape (m,), optional
        The residuals that come as x, y, z triples of a vector that turns with the cell (a point's miss, an
        orientation's; None: none). A distance to a plane or between two points does not turn.
    du : ndarray, shape (m, k)
        ``d value / d`` the kind's unknowns (:meth:`MeasurementKind.unknowns`, in their order).
    """

    values: NDArray[np.float64]
    rows_a: NDArray[np.intp]
    grad_a: NDArray[np.float64]
    du: NDArray[np.float64]
    rows_b: NDArray[np.intp] | None = None
    grad_b: NDArray[np.float64] | None = None
    turn_grad: NDArray[np.float64] | None = None
    scaled: NDArray[np.bool_] | None = None
    turning: NDArray[np.bool_] | None = None


class MeasurementKind:
    """What every measurement kind answers. A kind is built from all rows and reads those of its own ``name``.

    Class attributes: ``name`` (the CSV's ``kind`` value), ``reads`` (the columns its rows read beside the
    joints), ``needs_orientation`` (whether its residuals read the tool's orientation; an instance may say
    so for its rows alone), ``default_noise_mm`` (its stated noise when the cell states none), ``summary``
    (one line for the report: what one row says).
    """

    name: ClassVar[str] = ""
    reads: ClassVar[tuple[str, ...]] = ()
    needs_orientation: ClassVar[bool] = False
    default_noise_mm: ClassVar[float] = 0.01
    summary: ClassVar[str] = ""

    def __init__(self, rows: Rows, index: NDArray[np.intp], features: dict, noise_mm: float):
        self.rows, self.index, self.features, self.noise_mm = rows, index, features, float(noise_mm)

    @classmethod
    def build(cls, rows: Rows, features: dict) -> "MeasurementKind | None":
        """The kind over ``rows`` (None when no row is of it), its rows checked; ``features`` as
        :func:`partcal.data.observations.read_features` gives them."""
        index = rows.of(cls.name)
        if index.size == 0:
            return None
        noise = (features.get("noise_mm") or {}).get(cls.name, cls.default_noise_mm)
        return cls(rows, index, features, noise)

    def unknowns(self, positions: NDArray[np.float64], rotations: NDArray[np.float64]
                 ) -> tuple[list[tuple[str, str]], NDArray[np.float64]]:
        """The kind's own unknowns ``(name, unit)`` and where their fit starts, from the targets' ``positions``
        (n, 3) mm and tool ``rotations`` (n, 3, 3) of every row at the nominal robot (consistent data). Two
        kinds declaring an unknown of one name share it (a pivot that is also a fixed point). Rows the nominal
        robot puts far from what they say (:data:`NEAR_MM`: a touch near no plane; a distance in metres) are
        refused here."""
        return [], np.zeros(0)

    def residuals(self, positions: NDArray[np.float64], rotations: NDArray[np.float64] | None,
                  u: NDArray[np.float64]) -> Residuals:
        """The residuals at the targets' ``positions`` (n, 3) and ``rotations`` of every row, and the
        unknowns ``u``."""
        raise NotImplementedError

    def scaled_lengths(self, start: NDArray[np.float64]) -> NDArray[np.float64]:
        """How the kind's unknowns (at ``start``, in :meth:`unknowns`' order) change per unit of a uniform scale
        of the whole cell that leaves its rows' residuals as they are: a length by its own value (the default);
        the entries of unknowns that are not lengths are not read."""
        return start

    def moved(self, u: NDArray[np.float64], omega: NDArray[np.float64], shift: NDArray[np.float64]
              ) -> NDArray[np.float64]:
        """How the kind's unknowns ``u`` change, to first order, when the whole cell turns by the small rotation
        vector ``omega`` (radians) about the base frame's origin and shifts by ``shift`` (mm): a point turns and
        shifts with it, a plane's normal turns and its offset shifts. Default: unknowns that do not move."""
        return np.zeros_like(u)

    def notes(self) -> list[str]:
        """What this kind can never identify, in words (for the run and the report)."""
        return []

    def describe(self) -> str:
        """One line: the rows and what they touch."""
        return f"{self.index.size} {self.name} rows"


MEASUREMENT_KINDS: dict[str, type[MeasurementKind]] = {}
"""The table of measurement kinds: the CSV's ``kind`` value -> its class (:func:`add_measurement_kind`). The
built-in rows are those of :mod:`partcal.models.contacts`, registered when it is imported (as
:mod:`partcal.models.kinematic` does)."""

END_KIND = "pose"
"""A row of joints alone: an end other rows' distances refer to; it has no residual of its own."""


def add_measurement_kind(kind: type[MeasurementKind]) -> type[MeasurementKind]:
    """Register ``kind`` under its ``name`` (usable as a class decorator); a name taken is refused."""
    if not kind.name or kind.name == END_KIND or kind.name in MEASUREMENT_KINDS:
        raise ValueError(f"a measurement kind needs a name of its own; {kind.name!r} is empty or taken")
    MEASUREMENT_KINDS[kind.name] = kind
    return kind


def kind_names() -> tuple[str, ...]:
    """Every name a ``kind`` column may hold: the table's, and :data:`END_KIND`."""
    return (*MEASUREMENT_KINDS, END_KIND)


def built_kinds(rows: Rows, features: dict) -> list[MeasurementKind]:
    """The kinds present in ``rows``, in the table's order; a row of a kind the table does not list is refused."""
    known = set(kind_names())
    for i, k in enumerate(rows.kind):
        if k not in known:
            raise DataError(f"{rows.where(i)}: column 'kind': {k!r} is not a measurement kind; expected one of "
                            f"{', '.join(sorted(known))}")
    kinds = [k for k in (cls.build(rows, features) for cls in MEASUREMENT_KINDS.values()) if k is not None]
    if not kinds:
        raise DataError(f"{rows.source}: no row measures anything (every row is a {END_KIND!r} row)")
    return kinds


# ---------------------------------------------------------------------- the chain, as the kinds see it
@dataclass(frozen=True, eq=False)
class Chain:
    """The model's targets at every row: positions (n, 3) mm, tool rotations (n, 3, 3) when a kind needs
    them, and their derivatives by the model's own parameters: ``jac`` (n, 3, P), ``omega`` (n, 3, P) the
    tool's angular velocity (radians per unit)."""

    positions: NDArray[np.float64]
    rotations: NDArray[np.float64] | None
    jac: NDArray[np.float64] | None
    omega: NDArray[np.float64] | None


def chain_at(nominal: Robot, errors: JointErrors | None, q_deg: NDArray[np.float64], values: NDArray[np.float64],
             payload_kg: NDArray[np.float64], parametrization: str, orientation: bool, jacobian: bool) -> Chain:
    """:class:`Chain` of the model with its own parameters ``values``."""
    robot = robot_with(nominal, values, parametrization)
    q_actual, design, moves = actual_joints(nominal, errors, q_deg, values, payload_kg, derivatives=jacobian,
                                            parametrization=parametrization)
    rotations = robot.forward(q_actual)[:, :3, :3] if orientation else None
    if not jacobian:
        return Chain(model_positions(nominal, errors, q_deg, values, payload_kg, parametrization), rotations,
                     None, None)
    p, jac = model_jacobian(nominal, errors, q_deg, values, payload_kg, parametrization)
    omega = turn_columns(nominal, robot, q_actual, design, moves, values, parametrization) if orientation else None
    return Chain(p, rotations, jac.reshape(p.shape[0], 3, -1), omega)


# ---------------------------------------------------------------------- the stacked problem
class StackedProblem:
    """The kinds' residuals stacked and weighted, and their Jacobian by the model's and the kinds' unknowns."""

    def __init__(self, nominal: Robot, errors, rows: Rows, kinds: list[MeasurementKind], payload, parametrization):
        self.nominal, self.errors, self.rows, self.kinds = nominal, errors, rows, kinds
        self.payload, self.par = payload, parametrization
        self.own = nominal_values(nominal, errors, parametrization).size
        self.orientation = any(k.needs_orientation for k in kinds)
        # the chain once per distinct pose (all pairs of 1,000 poses are 500,000 rows of 1,000 poses)
        poses, inverse = np.unique(np.column_stack([rows.q_deg, payload]), axis=0, return_inverse=True)
        self.poses, self.pose_payload, self.inverse = poses[:, :-1], poses[:, -1], inverse.ravel()
        v0 = nominal_values(nominal, errors, parametrization)
        start = self.chain(v0, False, orientation=True)          # the kinds check their rows' orientations
        self.names: list[tuple[str, str]] = []
        starts: list[float] = []
        self.columns: list[NDArray[np.intp]] = []
        for kind in kinds:
            names, values = kind.unknowns(start.positions, start.rotations)
            cols = []
            for name, value in zip(names, values):
                if name not in self.names:
                    self.names.append(name)
                    starts.append(float(value))
                cols.append(self.own + self.names.index(name))
            self.columns.append(np.array(cols, dtype=np.intp))
        self.start = np.concatenate([v0, np.array(starts)])
        self.weights = [REFERENCE_NOISE_MM / kind.noise_mm for kind in kinds]

    def split(self, values: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        return [values[cols] for cols in self.columns]

    def chain(self, values: NDArray[np.float64], jacobian: bool, orientation: bool | None = None) -> Chain:
        """:class:`Chain` at every row (its derivatives at every distinct pose: index them by ``inverse``); the
        tool's rotations when a kind reads them (or ``orientation``)."""
        chain = chain_at(self.nominal, self.errors, self.poses, values[:self.own], self.pose_payload, self.par,
                         self.orientation if orientation is None else orientation, jacobian)
        return Chain(chain.positions[self.inverse], None if chain.rotations is None else
                     chain.rotations[self.inverse], chain.jac, chain.omega)

    def raw(self, values: NDArray[np.float64], measured_only: bool = False) -> list[NDArray[np.float64]]:
        """Each kind's residuals (mm, unweighted); ``measured_only``: those of rows alone (not a known length
        between two of a kind's unknowns)."""
        chain = self.chain(values, False)
        out = []
        for kind, u in zip(self.kinds, self.split(values)):
            r = kind.residuals(chain.positions, chain.rotations, u)
            out.append(r.values[r.rows_a >= 0] if measured_only else r.values)
        return out

    def __call__(self, values: NDArray[np.float64], jacobian: bool = True):
        """The weighted residuals and (with ``jacobian``) their Jacobian, as ``identify``'s ``jac_at``."""
        chain = self.chain(values, jacobian)
        out, blocks = [], []
        for kind, u, cols, w in zip(self.kinds, self.split(values), self.columns, self.weights):
            r = kind.residuals(chain.positions, chain.rotations, u)
            out.append(w * r.values)
            if jacobian:
                block = np.zeros((r.values.size, values.size))
                block[:, :self.own] = _through_chain(r, chain, self.inverse)
                np.add.at(block.T, cols, r.du.T)
                blocks.append(w * block)
        return np.concatenate(out), (np.vstack(blocks) if jacobian else None)


def _through_chain(r: Residuals, chain: Chain, pose_of: NDArray[np.intp], chunk: int = 20000
                   ) -> NDArray[np.float64]:
    """``d residual / d`` the model's own parameters: each residual's gradients through its rows' targets
    (row ``i``'s derivatives are those of pose ``pose_of[i]``)."""
    m, p = r.values.size, chain.jac.shape[2]
    out = np.zeros((m, p))
    for lo in range(0, m, chunk):
        part = slice(lo, lo + chunk)
        for rows, grad in ((r.rows_a, r.grad_a), (r.rows_b, r.grad_b)):
            if rows is None:
                continue
            rows, grad = rows[part], grad[part]
            live = rows >= 0
            out[part][live] += np.einsum("mi,mip->mp", grad[live], chain.jac[pose_of[rows[live]]])
        if r.turn_grad is not None:
            rows, grad = r.rows_a[part], r.turn_grad[part]
            live = rows >= 0
            out[part][live] += np.einsum("mi,mip->mp", grad[live], chain.omega[pose_of[rows[live]]])
    return out


def scale_direction(problem: "StackedProblem") -> NDArray[np.float64]:
    """The parameter change of a uniform scale of the whole cell by one: the robot's lengths (found as the
    length parameters' change that moves every row's target ``p`` by ``p``, the base's place included), and
    every length among the kinds' unknowns by its own value. Zero when the robot's lengths cannot do it."""
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
    for kind, cols in zip(problem.kinds, problem.columns):
        scaled[cols - problem.own] = kind.scaled_lengths(scaled[cols - problem.own])
    s[problem.own:][mine] = scaled[mine]
    return s


def rigid_directions(problem: "StackedProblem") -> NDArray[np.float64]:
    """The parameter changes of the six rigid motions of the whole cell (shifts along, then turns about the base
    frame's axes, through its origin), as columns ``(P, 6)``: the base correction (its shift, its turn) and the
    kinds' unknowns as each kind moves them (:meth:`MeasurementKind.moved`)."""
    size = geometric_size(problem.nominal, problem.par)
    out = np.zeros((problem.start.size, 6))
    for k in range(3):
        out[size - 6 + k, k] = 1.0                           # base.x, y, z: mm
        out[size - 3 + k, 3 + k] = np.degrees(1.0)           # base.rx, ry, rz: degrees per radian
    seen: set[int] = set()
    for kind, cols in zip(problem.kinds, problem.columns):
        u = problem.start[cols]
        new = np.array([c not in seen for c in cols], dtype=bool)      # a shared unknown moves once
        for k in range(6):
            motion = np.eye(6)[k]
            out[cols[new], k] = kind.moved(u, motion[3:], motion[:3])[new]
        seen.update(cols.tolist())
    return out


def misfit_parts(problem: "StackedProblem", values: NDArray[np.float64]) -> NDArray[np.float64]:
    """What the residuals' misfit adds to the Jacobian's answer to a scale and to the three turns of the cell,
    columns ``(m, 4)`` (weighted as the stacked residuals): the residuals are homogeneous in the cell's lengths
    (``J s = r + L``, ``L`` the known lengths, for the residuals that are lengths) and a vector residual turns
    with the cell (``J s_k = e_k x r + ...``), so on consistent data (``r = 0``) these parts are nil."""
    chain = problem.chain(values, False)
    parts = []
    for kind, u, w in zip(problem.kinds, problem.split(values), problem.weights):
        r = kind.residuals(chain.positions, chain.rotations, u)
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


def identify_measures(robot: Robot, rows: Rows, features: dict | None = None, *, base: bool = True,
                      tool: bool = True, rcond: float = 1e-6, errors: JointErrors | None = None,
                      payload_kg=0.0, parametrization: str = "dh", prior: Prior | None = None
                      ) -> tuple[Identification, list[str]]:
    """Identify the robot's parameters and the kinds' unknowns from rows of any measurement kinds.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    rows : Rows
        Every row (all kinds).
    features : dict, optional
        The cell's planes and points and the kinds' noise (:func:`partcal.data.observations.read_features`).
    base, tool, rcond, errors, payload_kg, parametrization
        As :func:`~partcal.models.identification.identify`.
    prior : Prior, optional
        A Gaussian prior on the robot's own parameters (indices into the table's first entries, never the
        kinds' unknowns): MAP as in :func:`~partcal.models.identification.identify`, by the same means (its
        rows appended to the weighted residuals, which read as millimetres of a 0.02 mm tracker, and to the
        Jacobian the rank rule reads; the parameters it holds never pruned as implausible; the covariance
        the posterior's). The kinds' RMS figures are those of the rows alone.

    Returns
    -------
    identification : Identification
        The robot's parameters, then the kinds' unknowns. ``target_rms_mm`` holds each kind's RMS residual
        (mm) under its name; ``rms_mm`` is the RMS of every residual (mm).
    notes : list of str
        What the data cannot identify, in words (a uniform scale, each kind's own blind spots).
    """
    features = features or {}
    problem, names, wanted, jac0, notes = _prepared(robot, rows, features, base, tool, rcond, errors, payload_kg,
                                                    parametrization, prior)
    size, kinds, q_deg = geometric_size(robot, parametrization), problem.kinds, rows.q_deg
    if prior is None:
        table = fit_parameters(problem, problem.start, jac0, wanted, names, rcond, size, len(q_deg))[0]
    else:
        table = fit_parameters(prior.augmented(problem), problem.start, jac0, wanted, names, rcond, size,
                               len(q_deg), held=prior.held(problem.start.size))[0]
    raw = problem.raw(table.value, measured_only=True)
    per_kind = {kind.name: float(np.sqrt(np.mean(r**2))) if r.size else 0.0 for kind, r in zip(kinds, raw)}
    everything = np.concatenate(raw)
    table = dataclasses.replace(table, target_rms_mm=per_kind, rms_mm=float(np.sqrt(np.mean(everything**2))))
    for note in notes:
        log.warning("%s", note)
    return table, notes


def rank_jacobian(problem: StackedProblem, wanted: NDArray[np.bool_], rcond: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The Jacobian the rank rule reads, at the problem's start on consistent data (:func:`consistent_jacobian`
    along a uniform scale and the three turns of the cell, the turns when the base is asked for), and the
    scale's direction."""
    jac0 = problem(problem.start)[1]
    direction = scale_direction(problem)
    rigid = rigid_directions(problem)
    turns = rigid[:, 3:] if not np.any(rigid[~wanted, 3:]) else np.zeros((rigid.shape[0], 0))   # base held: none
    directions = np.column_stack([direction, turns])
    misfit = misfit_parts(problem, problem.start)[:, :directions.shape[1]]
    return consistent_jacobian(jac0, misfit, directions, rcond), direction


def _prepared(robot: Robot, rows: Rows, features: dict, base: bool, tool: bool, rcond: float, errors, payload_kg,
              parametrization: str, prior: Prior | None = None):
    """The stacked problem at its start, every parameter's name, those asked for, the Jacobian the rank rule
    reads (on consistent data: :func:`consistent_jacobian`; a ``prior``'s rows appended) and what the data
    cannot identify, in words."""
    kinds = built_kinds(rows, features)
    q_deg = robot.check_joints(rows.q_deg)
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(q_deg),))
    problem = StackedProblem(robot, errors, rows, kinds, payload, parametrization)
    names = parameter_names(robot, errors, parametrization) + problem.names
    size = geometric_size(robot, parametrization)
    wanted = np.ones(problem.start.size, dtype=bool)
    wanted[size - 9:size - 6] = tool
    wanted[size - 6:size] = base
    notes = [note for kind in kinds for note in kind.notes()]
    jac0, direction = rank_jacobian(problem, wanted, rcond)
    if prior is not None:
        own = parameter_names(robot, errors, parametrization)
        if prior.index.size and int(prior.index.max()) >= len(own):
            raise DataError(f"the prior holds parameter {int(prior.index.max())}; the robot has {len(own)} (a "
                            "prior is on the robot's parameters, never on the kinds' unknowns)")
        robot_names = [n for n, _ in own]   # a prior model fitted on kinds lists its own kinds' unknowns after these
        dataclasses.replace(prior, names=None if prior.names is None else prior.names[:len(own)]
                            ).check_names(robot_names)
    if np.any(direction) and _null(jac0, direction, wanted, rcond):
        held = prior is not None and not _null(np.vstack([jac0, prior.jacobian(jac0.shape[1])]), direction, wanted,
                                               rcond)
        notes.insert(0, f"{SCALE}: nothing here measures a length (every plane and point is unknown), so a uniform "
                        "scale of the robot cannot be identified: " + (
                            "the prior holds it (the lengths about their prior means, against the residuals' pull "
                            "towards a smaller robot: what it leaves depends on the strength and the number of rows)"
                            if held else
                            "one length is held nominal") + ". Give one: a plane's spacing_mm, a point's distance_mm "
                        "or known_mm, a distance, or tracker points")
    if prior is not None:
        jac0 = np.vstack([jac0, prior.jacobian(jac0.shape[1])])
    return problem, names, wanted, jac0, notes


def observability(robot: Robot, rows: Rows, features: dict | None = None, *, base: bool = True, tool: bool = True,
                  rcond: float = 1e-6, errors: JointErrors | None = None, payload_kg=0.0,
                  parametrization: str = "dh", prior: Prior | None = None) -> tuple[list[str], list[str]]:
    """What rows of measurement kinds cannot identify, without fitting: the notes of :func:`identify_measures`
    and the parameters its rank rule would hold nominal (judged at the nominal robot, on consistent data; with
    a ``prior``, its rows read too)."""
    _, names, wanted, jac0, notes = _prepared(robot, rows, features or {}, base, tool, rcond, errors, payload_kg,
                                              parametrization, prior)
    free = identifiable_parameters(jac0, wanted, rcond, [u for _, u in names])[0]
    held = [names[i][0] for i in np.flatnonzero(wanted) if i not in set(free.tolist())]
    return notes, held


def _null(jac: NDArray[np.float64], direction: NDArray[np.float64], wanted, rcond: float) -> bool:
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


@dataclass(frozen=True, eq=False)
class Measured:
    """What :meth:`KinematicModel.fit <partcal.models.kinematic.KinematicModel.fit>` identifies from instead
    of position errors: rows of any kinds and the cell's features."""

    rows: Rows
    features: dict = field(default_factory=dict)


def kind_residuals(robot: Robot, rows: Rows, features: dict, table: Identification, *,
                   errors: JointErrors | None = None, payload_kg=0.0, parametrization: str = "dh",
                   only: NDArray[np.intp] | None = None, fitted_here: list | None = None,
                   row_of: dict | None = None) -> dict[str, NDArray[np.float64]]:
    """Each kind's residuals (mm) on ``rows`` for an identified ``table``: what held-out rows of the same kind
    leave. The kinds' unknowns are the table's; an unknown the table lacks (a plane or point the fit never saw)
    is fitted on these rows with everything else held, and its name appended to ``fitted_here`` (a list, when
    given). ``only`` (indices into ``rows``): the residuals of those rows alone, the kinds built on every row
    (held-out rows need not satisfy what an identification needs of its rows, such as three touches per
    plane); a kind none of them reads is left out. ``row_of`` (a dict, when given, with ``only``) receives the
    row (an index into ``rows``) of each residual, per kind."""
    kinds = built_kinds(rows, features)
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(rows),))
    problem = StackedProblem(robot, errors, rows, kinds, payload, parametrization)
    values = problem.start.copy()
    values[:problem.own] = table.value[:problem.own]
    fitted = dict(zip(table.names[problem.own:], table.value[problem.own:]))
    missing = np.zeros(values.size, dtype=bool)
    for k, (name, _) in enumerate(problem.names):
        if name in fitted:
            values[problem.own + k] = fitted[name]
        else:
            missing[problem.own + k] = True
    if missing.any():                  # features the fit never saw: placed on these rows, the robot held
        names = parameter_names(robot, errors, parametrization) + problem.names
        size = geometric_size(robot, parametrization)
        values = fit_parameters(problem, values, problem(values)[1], missing, names, 1e-6, size, len(rows))[0].value
        if fitted_here is not None:
            fitted_here += [n for (n, _), m in zip(names, missing) if m]
    if only is None:
        return {kind.name: r for kind, r in zip(kinds, problem.raw(values, measured_only=True))}
    chain = problem.chain(values, False)
    out = {}
    for kind, u in zip(kinds, problem.split(values)):
        r = kind.residuals(chain.positions, chain.rotations, u)
        keep = np.isin(r.rows_a, only) & (r.rows_a >= 0)
        if keep.any():
            out[kind.name] = r.values[keep]
            if row_of is not None:
                row_of[kind.name] = r.rows_a[keep]
    return out
