"""One identification over every measurement type present: the types' residuals stacked and weighted by
their stated noise (:class:`StackedProblem`), the robot's parameters and the types' unknowns fitted together
(:func:`identify_measurements`), what the rows cannot identify (:func:`observability`), held-out residuals
(:func:`type_residuals`)."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ..robot.kinematics import Robot
from .chain import Chain, chain_at
from .checks import MISFIT_KEEPS, check_freedom, check_measured, check_rows, misfit_notes
from .fit import fit_parameters, held_still
from .identifiability import consistent_jacobian, identifiable_parameters, misfit_parts, null_direction, rigid_directions, scale_direction
from .joint_errors import JointErrors
from .measurement import REFERENCE_NOISE_MM, SCALE, MeasurementType, Residuals, MeasurementRows
from .parameters import Identification, geometric_size, nominal_values, parameter_names
from .prior import Prior
from .registry import built_types

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------- the stacked problem
class StackedProblem:
    """The types' residuals stacked and weighted, and their Jacobian by the model's and the types' unknowns."""

    def __init__(self, nominal: Robot, errors, rows: MeasurementRows, measurements: list[MeasurementType], payload, parametrization):
        self.nominal, self.errors, self.rows, self.measurements = nominal, errors, rows, measurements
        self.payload, self.par = payload, parametrization
        self.own = nominal_values(nominal, errors, parametrization).size
        size = geometric_size(nominal, parametrization)
        self.tool = slice(size - 9, size - 6)
        self.orientation = any(k.needs_orientation for k in measurements)
        # the chain once per distinct pose (all pairs of 1,000 poses are 500,000 rows of 1,000 poses)
        poses, inverse = np.unique(np.column_stack([rows.q_deg, payload]), axis=0, return_inverse=True)
        self.poses, self.pose_payload, self.inverse = poses[:, :-1], poses[:, -1], inverse.ravel()
        v0 = nominal_values(nominal, errors, parametrization)
        start = self.chain(v0, False, orientation=True)          # the types check their rows' orientations
        self.at_tool(v0)
        self.names: list[tuple[str, str]] = []
        starts: list[float] = []
        self.columns: list[NDArray[np.intp]] = []
        for measurement in measurements:
            names, values = measurement.unknowns(start.positions, start.rotations)
            cols = []
            for name, value in zip(names, values):
                if name not in self.names:
                    self.names.append(name)
                    starts.append(float(value))
                cols.append(self.own + self.names.index(name))
            self.columns.append(np.array(cols, dtype=np.intp))
        self.start = np.concatenate([v0, np.array(starts)])
        self.weights = [REFERENCE_NOISE_MM / measurement.noise for measurement in measurements]
        residuals = self.each(self.start)
        self.residual_weights = np.concatenate([self.weight_of(k, r) for k, r in enumerate(residuals)])
        self.row_of = np.concatenate([r.rows_a for r in residuals])

    def weight_of(self, k: int, r: Residuals) -> NDArray[np.float64]:
        """The weight of each residual ``r`` of type ``k``: reference noise over the type's, times its weight
        among the type's own (:meth:`MeasurementType.relative_weights`)."""
        return self.weights[k] * self.measurements[k].relative_weights(r)

    def each(self, values: NDArray[np.float64]) -> list[Residuals]:
        """Each type's residuals at ``values`` (unweighted, with their derivatives by the targets)."""
        chain = self.chain(values, False)
        self.at_tool(values)
        return [measurement.residuals(chain.positions, chain.rotations, u) for measurement, u in zip(self.measurements, self.split(values))]

    def at_tool(self, values: NDArray[np.float64]) -> None:
        """Tell every type the model's tool offset at ``values`` (:attr:`MeasurementType.tool_mm`)."""
        for measurement in self.measurements:
            measurement.tool_mm = values[self.tool].copy()

    def reference_mm(self) -> float | None:
        """The stated standard deviation of one weighted residual (root mean square over the residuals), when
        every type states its spread (:meth:`MeasurementType.stated_spread`); else None."""
        spreads = [measurement.stated_spread() for measurement in self.measurements]
        if any(s is None for s in spreads):
            return None
        counts = np.bincount(np.repeat(np.arange(len(self.measurements)), [r.values.size for r in self.each(self.start)]),
                             minlength=len(self.measurements))
        levels = np.array([w * s for w, s in zip(self.weights, spreads)])
        return float(np.sqrt(np.sum(counts * levels**2) / max(counts.sum(), 1)))

    def split(self, values: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        return [values[cols] for cols in self.columns]

    def chain(self, values: NDArray[np.float64], jacobian: bool, orientation: bool | None = None) -> Chain:
        """:class:`Chain` at every row (its derivatives at every distinct pose: index them by ``inverse``); the
        tool's rotations when a type reads them (or ``orientation``)."""
        chain = chain_at(self.nominal, self.errors, self.poses, values[:self.own], self.pose_payload, self.par,
                         self.orientation if orientation is None else orientation, jacobian)
        return Chain(chain.positions[self.inverse], None if chain.rotations is None else
                     chain.rotations[self.inverse], chain.jac, chain.omega)

    def raw(self, values: NDArray[np.float64], measured_only: bool = False) -> list[NDArray[np.float64]]:
        """Each type's residuals (mm, unweighted); ``measured_only``: those of rows alone (not a known length
        between two of a type's unknowns)."""
        return [r.values[r.rows_a >= 0] if measured_only else r.values for r in self.each(values)]

    def __call__(self, values: NDArray[np.float64], jacobian: bool = True):
        """The weighted residuals and (with ``jacobian``) their Jacobian, as ``identify``'s ``jac_at``."""
        chain = self.chain(values, jacobian)
        self.at_tool(values)
        out, blocks = [], []
        for k, (measurement, u, cols) in enumerate(zip(self.measurements, self.split(values), self.columns)):
            r = measurement.residuals(chain.positions, chain.rotations, u)
            w = self.weight_of(k, r)
            out.append(w * r.values)
            if jacobian:
                block = np.zeros((r.values.size, values.size))
                block[:, :self.own] = _through_chain(r, chain, self.inverse)
                np.add.at(block.T, cols, r.du.T)
                if r.tool_grad is not None:
                    block[:, self.tool] += r.tool_grad
                blocks.append(w[:, None] * block)
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



def identify_measurements(robot: Robot, rows: MeasurementRows, cell: dict | None = None, *, base: bool = True,
                      tool: bool = True, rcond: float = 1e-6, errors: JointErrors | None = None,
                      payload_kg=0.0, parametrization: str = "dh", prior: Prior | None = None,
                      loss: str = "linear", loss_scale: float = 3.0, residual_left: bool = False
                      ) -> tuple[Identification, list[str]]:
    """Identify the robot's parameters and the types' unknowns from rows of any measurement types.

    Parameters
    ----------
    robot : Robot
        The nominal robot.
    rows : MeasurementRows
        Every row (all types).
    cell : dict, optional
        The cell's planes and points and the types' noise (:func:`partcal.data.measurement_rows.read_cell`).
    base, tool, rcond, errors, payload_kg, parametrization
        As :func:`~partcal.calibration.identification.identify`.
    prior : Prior, optional
        A Gaussian prior on the robot's own parameters (indices into the table's first entries, never the
        types' unknowns): MAP as in :func:`~partcal.calibration.identification.identify`, by the same means (its
        rows appended to the weighted residuals, which read as millimetres of a 0.02 mm tracker, and to the
        Jacobian the rank rule reads; the parameters it holds never pruned as implausible; the covariance
        the posterior's). The types' RMS figures are those of the rows alone.
    loss, loss_scale
        A robust loss (:data:`~partcal.calibration.fit.LOSSES`) on every weighted residual, its scale
        ``loss_scale`` times the residuals' stated standard deviation (when every type states one: its rows'
        ``std`` columns or the cell's noise) or the robust spread of the least-squares fit's; the rows it
        down-weighs are named in ``robust`` (``row``: an index into ``rows``, ``where``: file and line).
    residual_left : bool
        Refuse a fit that leaves no residual (as many identified parameters as residuals): a model to be written
        needs one for its standard errors and spread (:func:`~partcal.calibration.checks.check_freedom`).

    Returns
    -------
    identification : Identification
        The robot's parameters, then the types' unknowns. ``target_rms_mm`` holds each type's RMS residual
        (mm) under its name; ``rms_mm`` is the RMS of every residual (mm).
    notes : list of str
        What the data cannot identify, in words (a uniform scale, each type's own blind spots).
    """
    cell = cell or {}
    check_measured(rows)
    rows = dataclasses.replace(rows, q_deg=held_still(robot.check_joints(rows.q_deg)))
    problem, names, wanted, jac0, notes = _prepared(robot, rows, cell, base, tool, rcond, errors, payload_kg,
                                                    parametrization, prior)
    size, measurements = geometric_size(robot, parametrization), problem.measurements
    table = fit_parameters(problem if prior is None else prior.augmented(problem), problem.start, jac0, wanted,
                           names, rcond, size, len(rows), loss=loss, loss_scale=loss_scale,
                           reference_mm=problem.reference_mm(), held=None if prior is None else
                           prior.held(problem.start.size), row_of=problem.row_of,
                           weighted_by=problem.residual_weights, prior_rows=0 if prior is None else prior.size)[0]
    each = problem.each(table.value)
    raw = [r.values[r.rows_a >= 0] for r in each]
    per_type = {m.name: float(np.sqrt(np.mean(r**2))) if r.size else 0.0 for m, r in zip(measurements, raw)}
    everything = np.concatenate(raw)
    if residual_left:
        check_freedom(rows, problem.row_of, table)
    kept = np.ones(len(rows), dtype=bool)          # a robust loss's fit is judged on the rows it keeps
    if table.robust is not None:
        kept[[d["row"] for d in table.robust["downweighted"] if d["weight"] < MISFIT_KEEPS]] = False
    misfit, ratios = misfit_notes(rows, {m.name: (r.values[(r.rows_a < 0) | kept[r.rows_a]],
                                                  r.rows_a[(r.rows_a < 0) | kept[r.rows_a]])
                                         for m, r in zip(measurements, each)},
                                  {m.name: (m.noise, m.unit, m.noise_stated) for m in measurements})
    misfit += [note for m in measurements for note in m.suspicions]
    misfit += [note for m, r in zip(measurements, each) for note in m.fit_notes(r)]
    for note in notes:                  # what the rows cannot identify: said once (the same in every fold's fit)
        log.warning("%s", note)
    notes = misfit + notes
    robust = None if table.robust is None else {**table.robust, "downweighted": [
        {**d, "where": rows.where(d["row"]), "id": rows.ids[d["row"]], "type": rows.types[d["row"]]}
        for d in table.robust["downweighted"]]}
    table = dataclasses.replace(table, target_rms_mm=per_type, rms_mm=float(np.sqrt(np.mean(everything**2))),
                                robust=robust, misfit={"noise_ratio": ratios, "calibrated": not misfit})
    return table, notes


def stand_ins(measurements: list[MeasurementType], names: list[str]) -> set[str]:
    """The robot's parameters (of ``names``) every type present says its own unknowns stand for
    (:meth:`MeasurementType.stands_for`): held nominal, the types' unknowns carrying them."""
    return set.intersection(*(measurement.stands_for(names) for measurement in measurements)) if measurements else set()


def rank_jacobian(problem: StackedProblem, wanted: NDArray[np.bool_], rcond: float
                  ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The Jacobian the rank rule reads, at the problem's start on consistent data (:func:`consistent_jacobian`
    along a uniform scale and the three turns of the cell, the turns when the base is asked for), and the
    scale's direction."""
    jac0 = problem(problem.start)[1]
    direction = scale_direction(problem)
    if any(measurement.fixes_frame for measurement in problem.measurements):   # measured in the base frame: the frame and the scale fixed
        return jac0, direction
    rigid = rigid_directions(problem)
    turns = rigid[:, 3:] if not np.any(rigid[~wanted, 3:]) else np.zeros((rigid.shape[0], 0))   # base held: none
    directions = np.column_stack([direction, turns])
    misfit = misfit_parts(problem, problem.start)[:, :directions.shape[1]]
    return consistent_jacobian(jac0, misfit, directions, rcond), direction


def _prepared(robot: Robot, rows: MeasurementRows, cell: dict, base: bool, tool: bool, rcond: float, errors, payload_kg,
              parametrization: str, prior: Prior | None = None):
    """The stacked problem at its start, every parameter's name, those asked for, the Jacobian the rank rule
    reads (on consistent data: :func:`consistent_jacobian`; a ``prior``'s rows appended) and what the data
    cannot identify, in words. The rows are checked first (:func:`~partcal.calibration.checks.check_rows`)."""
    check_rows(robot, rows)
    measurements = built_types(rows, cell)
    q_deg = robot.check_joints(rows.q_deg)
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(q_deg),))
    problem = StackedProblem(robot, errors, rows, measurements, payload, parametrization)
    names = parameter_names(robot, errors, parametrization) + problem.names
    size = geometric_size(robot, parametrization)
    wanted = np.ones(problem.start.size, dtype=bool)
    wanted[size - 9:size - 6] = tool
    wanted[size - 6:size] = base
    for measurement, cols in zip(measurements, problem.columns):       # a type's unknowns of the tool (a further target's offset)
        wanted[cols] = [tool or not measurement.follows_tool(problem.names[c - problem.own][0]) for c in cols]
    own = [n for n, _ in parameter_names(robot, errors, parametrization)]
    carried = stand_ins(measurements, own)
    wanted[[i for i, n in enumerate(own) if n in carried]] = False   # carried by the types' own unknowns
    notes = [note for measurement in measurements for note in measurement.notes()]
    jac0, direction = rank_jacobian(problem, wanted, rcond)
    if prior is not None:
        own = parameter_names(robot, errors, parametrization)
        if prior.index.size and int(prior.index.max()) >= len(own):
            raise DataError(f"the prior holds parameter {int(prior.index.max())}; the robot has {len(own)} (a "
                            "prior is on the robot's parameters, never on the types' unknowns)")
        robot_names = [n for n, _ in own]   # a prior model fitted on types lists its own types' unknowns after these
        dataclasses.replace(prior, names=None if prior.names is None else prior.names[:len(own)]
                            ).check_names(robot_names)
    if np.any(direction) and null_direction(jac0, direction, wanted, rcond):
        held = prior is not None and not null_direction(np.vstack([jac0, prior.jacobian(jac0.shape[1])]), direction, wanted,
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


def observability(robot: Robot, rows: MeasurementRows, cell: dict | None = None, *, base: bool = True, tool: bool = True,
                  rcond: float = 1e-6, errors: JointErrors | None = None, payload_kg=0.0,
                  parametrization: str = "dh", prior: Prior | None = None) -> tuple[list[str], list[str]]:
    """What rows of measurement types cannot identify, without fitting: the notes of :func:`identify_measurements`
    and the parameters its rank rule would hold nominal (judged at the nominal robot, on consistent data; with
    a ``prior``, its rows read too)."""
    problem, names, wanted, jac0, notes = _prepared(robot, rows, cell or {}, base, tool, rcond, errors, payload_kg,
                                                    parametrization, prior)
    free = identifiable_parameters(jac0, wanted, rcond, [u for _, u in names],
                                   jac0.shape[0] - (prior.size if prior is not None else 0))[0]
    held = [names[i][0] for i in np.flatnonzero(wanted) if i not in set(free.tolist())]
    carried = stand_ins(problem.measurements, [n for n, _ in names])
    return notes, [n for n, _ in names if n in carried] + held


def freedom(robot: Robot, rows: MeasurementRows, cell: dict | None = None, *, base: bool = True, tool: bool = True,
            rcond: float = 1e-6, errors: JointErrors | None = None, payload_kg=0.0, parametrization: str = "dh",
            prior: Prior | None = None) -> tuple[int, int]:
    """How many residuals the rows give and how many parameters they identify (the rank rule at the nominal
    robot, as :func:`observability`), without fitting: a fit needs more of the first."""
    problem, names, wanted, jac0, _ = _prepared(robot, rows, cell or {}, base, tool, rcond, errors, payload_kg,
                                                parametrization, prior)
    free = identifiable_parameters(jac0, wanted, rcond, [u for _, u in names],
                                   jac0.shape[0] - (prior.size if prior is not None else 0))[0]
    return int(np.sum(problem.row_of >= 0)), int(free.size)


def type_residuals(robot: Robot, rows: MeasurementRows, cell: dict, table: Identification, *,
                   errors: JointErrors | None = None, payload_kg=0.0, parametrization: str = "dh",
                   only: NDArray[np.intp] | None = None, fitted_here: list | None = None,
                   row_of: dict | None = None) -> dict[str, NDArray[np.float64]]:
    """Each type's residuals (mm) on ``rows`` for an identified ``table``: what held-out rows of the same type
    leave. The types' unknowns are the table's; an unknown the table lacks (a plane or point the fit never saw)
    is fitted on these rows with everything else held, and its name appended to ``fitted_here`` (a list, when
    given). ``only`` (indices into ``rows``): the residuals of those rows alone, the types built on every row
    (held-out rows need not satisfy what an identification needs of its rows, such as three touches per
    plane); a type none of them reads is left out. ``row_of`` (a dict, when given, with ``only``) receives the
    row (an index into ``rows``) of each residual, per type."""
    measurements = built_types(rows, cell)
    payload = np.broadcast_to(np.asarray(payload_kg, dtype=float), (len(rows),))
    problem = StackedProblem(robot, errors, rows, measurements, payload, parametrization)
    values = problem.start.copy()
    values[:problem.own] = table.value[:problem.own]
    fitted = dict(zip(table.names[problem.own:], table.value[problem.own:]))
    missing = np.zeros(values.size, dtype=bool)
    for k, (name, _) in enumerate(problem.names):
        if name in fitted:
            values[problem.own + k] = fitted[name]
        else:
            missing[problem.own + k] = True
    if missing.any():                  # cell the fit never saw: placed on these rows, the robot held
        names = parameter_names(robot, errors, parametrization) + problem.names
        size = geometric_size(robot, parametrization)
        values = fit_parameters(problem, values, problem(values)[1], missing, names, 1e-6, size, len(rows))[0].value
        if fitted_here is not None:
            fitted_here += [n for (n, _), m in zip(names, missing) if m]
    if only is None:
        return {measurement.name: r for measurement, r in zip(measurements, problem.raw(values, measured_only=True))}
    out = {}
    for measurement, r in zip(measurements, problem.each(values)):
        keep = np.isin(r.rows_a, only) & (r.rows_a >= 0)
        if keep.any():
            out[measurement.name] = r.values[keep]
            if row_of is not None:
                row_of[measurement.name] = r.rows_a[keep]
    return out
