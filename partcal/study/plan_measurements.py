"""``partcal plan`` for measurement types: judge a measurements file, or plan plane touches and fixed-point visits.

A measurements file (a ``measurement`` column, docs/data.md "Measurement types") is judged as a tracker's pose set is
(:func:`evaluate_measurements`): at the nominal robot, on consistent data (the types' unknowns started from
the nominal robot's own positions at the measured poses), from the stacked Jacobian of every type,
each row weighted by its type's stated noise (:class:`~partcal.calibration.stacked.StackedProblem`). It
names what the data cannot identify (:func:`~partcal.calibration.stacked.observability`: a uniform scale
where nothing measures a length, each type's blind spots, the parameters held nominal) and gives the
indices, each identified parameter's predicted standard error and the predicted position uncertainty
of the identified robot over the workspace.

:func:`plan_measurements` plans ``n`` touches of the cell's planes (``type="plane"``) or visits of its fixed
points (``type="fixed"``): candidates from many tool orientations, each put on its feature by the
nominal robot (the contact simulator's generators run on the nominal robot: uniform joint samples
near the feature, inverse kinematics and Newton steps onto it, within the joint limits), then the
``n`` of them that maximise the determinant of the stacked, noise-weighted information of the robot's
and the types' unknowns (the points planner's DETMAX, :func:`~partcal.calibration.design.detmax`). A plane
is planned for when its geometry is given (``normal`` and ``offset_mm``, or ``parallel_to`` a plane
that has them, offset plus ``spacing_mm``); a fixed point when its position is (``known_mm``): an
unknown nest is planned for at its approximate position given as ``known_mm`` in the cell read
by ``plan``, and the measured file judged with the cell's own cell (``--evaluate``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..data.simulate import Tracker, VirtualRobot
from ..data.simulate_contacts import fixed_point_visits, plane_touches
from ..errors import PartcalError, UnreachableError
from ..calibration import design
from .._validation import seed_from
from ..calibration.identifiability import identifiable_parameters
from ..calibration.parameters import parameter_names
from ..calibration.measurement import REFERENCE_NOISE_MM, MeasurementRows
from ..calibration.checks import PLANNED
from ..calibration.registry import MEASUREMENT_TYPES, built_types
from ..calibration.stacked import observability, rank_jacobian, stand_ins, StackedProblem
from ..robot.floor import above_floor
from ..robot.kinematics import Robot
from . import plan

PLANNED_TYPES = ("plane", "fixed")
"""The built-in types ``partcal plan --measurement`` plans for (others: a type's ``candidates`` hook)."""


# ---------------------------------------------------------------------- the stacked design
@dataclass(frozen=True, eq=False)
class StackedDesign:
    """The stacked problem of some rows at the nominal robot, on consistent data.

    Attributes
    ----------
    names : list of (name, unit)
        The robot's parameters, then the types' unknowns.
    jac : ndarray, shape (m, P)
        The weighted residuals' Jacobian (each type's rows times ``REFERENCE_NOISE_MM / noise``), its answer
        to a uniform scale and the cell's turns made that of consistent data
        (:func:`~partcal.calibration.stacked.rank_jacobian`).
    row_of : ndarray of int, shape (m,)
        The row each residual reads (-1: none, a known length between two unknowns).
    wanted, free : which parameters are asked for, and which the rows identify (the fit's rank rule).
    notes : list of str
        What the rows cannot identify, in words.
    held : list of str
        The parameters asked for that the rank rule holds nominal.
    own : int
        How many of the columns are the robot's (the rest: the types' unknowns).
    """

    names: list
    jac: NDArray[np.float64]
    row_of: NDArray[np.intp]
    wanted: NDArray[np.bool_]
    free: NDArray[np.intp]
    notes: list
    held: list
    own: int


def stacked_design(robot: Robot, rows: MeasurementRows, cell: dict, model: design.PlannedModel = design.DH,
                   rcond: float = 1e-6) -> StackedDesign:
    """:class:`StackedDesign` of ``rows`` for the planned ``model`` (base, tool, joint errors; the rows' own
    payloads where they carry a ``payload_kg`` column, else the model's)."""
    errors, par = model.joint_errors(robot), model.parametrization_for(robot)
    measurements = built_types(rows, cell)
    payload = np.full(len(rows), float(model.payload_kg)) if rows.payload_kg is None else rows.payload_kg
    problem = StackedProblem(robot, errors, rows, measurements, payload, par)
    chain = problem.chain(problem.start, False)
    row_of = np.concatenate([k.residuals(chain.positions, chain.rotations, u).rows_a
                             for k, u in zip(measurements, problem.split(problem.start))])
    names = parameter_names(robot, errors, par) + problem.names
    carried = stand_ins(measurements, [n for n, _ in names])
    wanted = np.array([(model.tool or not n.startswith("tool.")) and (model.base or not n.startswith("base."))
                       and n not in carried for n, _ in names])
    jac = rank_jacobian(problem, wanted, rcond)[0]
    notes, held = observability(robot, rows, cell, base=model.base, tool=model.tool, rcond=rcond,
                                errors=errors, payload_kg=payload, parametrization=par)
    free = identifiable_parameters(jac, wanted, rcond, [u for _, u in names])[0]
    return StackedDesign(names, jac, row_of, wanted, free, notes, held, problem.own)


def column_scales(robot: Robot, names: list) -> NDArray[np.float64]:
    """Scales that make every column a length at the robot's reach (as :func:`design.parameter_scales`): an
    angle in degrees and a plane's slope (unit ``1``, radians) count as the arc they sweep at the reach."""
    reach = robot.reach_mm
    per_unit = {"deg": 180.0 / (np.pi * reach), "1": 1.0 / reach}
    return np.array([per_unit.get(unit, 1.0) for _, unit in names])


# ---------------------------------------------------------------------- evaluation
@dataclass(frozen=True)
class MeasurementEvaluation:
    """What ``plan --evaluate`` says of a measurements file (:func:`evaluate_measurements`)."""

    described: tuple[str, ...]
    notes: tuple[str, ...]
    held: tuple[str, ...]
    indices: design.Indices
    names: tuple[str, ...]
    units: tuple[str, ...]
    std_error: NDArray[np.float64]
    position_rms_mm: float
    position_p95_mm: float
    position_max_mm: float

    def lines(self) -> list[str]:
        out = [f"  {d}" for d in self.described]
        out.append("observability at the nominal robot, on consistent data (each type weighted by its stated "
                   f"noise; {REFERENCE_NOISE_MM:g} mm of a tracker point weighs one):")
        out.append(f"  {self.indices.text()}")
        out.append("not identifiable from these rows (held nominal): " + (", ".join(self.held) or "none"))
        out += [f"  {note}" for note in self.notes]
        out.append(f"predicted 3-D position uncertainty of the identified robot over the workspace (held parameters "
                   f"not counted): RMS {self.position_rms_mm:.4f} mm, 95% {self.position_p95_mm:.4f} mm, max "
                   f"{self.position_max_mm:.4f} mm")
        out.append("predicted standard error of each identified parameter:")
        out += [f"  {n:<24}{s:>12.4g} {u}" for n, u, s in zip(self.names, self.units, self.std_error)
                if np.isfinite(s)]
        return out


def evaluate_measurements(robot: Robot, rows: MeasurementRows, cell: dict, *, model: design.PlannedModel = design.DH,
                   workspace_q_deg: NDArray[np.float64] | None = None, random_state=0,
                   rcond: float = 1e-6) -> MeasurementEvaluation:
    """Judge rows of measurement types at the nominal robot (module docstring).

    Parameters
    ----------
    robot : Robot
    rows : MeasurementRows
        The rows of a measurements file (every type).
    cell : dict
        The cell's planes, points and noise (:func:`partcal.data.measurement_rows.read_cell`).
    model : PlannedModel
        The fit judged for (base, tool, joint errors, parametrization).
    workspace_q_deg : ndarray, shape (m, N), optional
        Where the position uncertainty is predicted (default :data:`plan.WORKSPACE_POSES` joint-limit poses
        above the robot's floor, seeded by ``random_state``).
    """
    model.check(robot)
    d = stacked_design(robot, rows, cell, model, rcond)
    scales = column_scales(robot, d.names)
    scaled = d.jac[:, d.free] * scales[d.free]
    ind = design.indices(scaled, len(rows))
    std = np.full(len(d.names), np.nan)
    position = np.zeros(1)
    if d.free.size:
        cov = design.parameter_covariance(scaled, REFERENCE_NOISE_MM)
        std[d.free] = np.sqrt(np.diag(cov)) * scales[d.free]
        if workspace_q_deg is None:
            workspace_q_deg = plan.candidates_within_limits(robot, plan.WORKSPACE_POSES,
                                                            np.random.default_rng(random_state),
                                                            floor=plan.floor_of(robot, plan.ROBOT_FLOOR))
        mine = np.flatnonzero(d.free < d.own)
        jac_ws = design.model_jacobian(robot, workspace_q_deg, model)[0]
        blocks = (jac_ws[:, d.free[mine]] * scales[d.free[mine]]).reshape(len(workspace_q_deg), 3, -1)
        position = design.position_std(blocks, cov[np.ix_(mine, mine)])
    described = tuple(k.describe() for k in built_types(rows, cell))
    return MeasurementEvaluation(described, tuple(d.notes), tuple(d.held), ind, tuple(n for n, _ in d.names),
                           tuple(u for _, u in d.names), std, float(np.sqrt(np.mean(position**2))),
                           float(np.percentile(position, 95)), float(position.max()))


# ---------------------------------------------------------------------- candidates
def nominal_cell(robot: Robot) -> VirtualRobot:
    """The nominal robot as a virtual robot without errors: the contact generators run on it put the NOMINAL
    tool tip on a feature."""
    return VirtualRobot(nominal=robot, true=robot, base_rotation=np.eye(3), base_mm=np.zeros(3), compliance=(),
                        gear=(), tracker=Tracker(np.zeros(3), 0.0, 0.0, 1), tracker_scale=1.0)


def plane_geometry(cell: dict, name: str, source: str) -> tuple[NDArray[np.float64], float]:
    """Plane ``name``'s unit normal and offset (mm) from the cell: its own, or its ``parallel_to`` plane's
    with the spacings added. A plane without them cannot be planned for (one :class:`PartcalError`)."""
    planes = cell.get("planes") or {}
    spacing, at = 0.0, name
    while "parallel_to" in planes[at]:
        spacing += float(planes[at].get("spacing_mm", 0.0))
        at = planes[at]["parallel_to"]
    spec = planes[at]
    if "normal" not in spec or "offset_mm" not in spec:
        tied = "" if at == name else f" (it is parallel_to {at!r}, which has none)"
        raise PartcalError(f"{source}: planes.{name}: a plane without normal and offset_mm cannot be planned for"
                           f"{tied}; give its approximate normal: [nx, ny, nz] and offset_mm: d (base frame)")
    normal = np.asarray(spec["normal"], dtype=float)
    return normal / np.linalg.norm(normal), float(spec["offset_mm"]) + spacing


def feature_targets(cell: dict, measurement: str, source: str) -> dict:
    """The cell of ``type`` to plan for: plane name -> (normal, offset_mm), or point name -> position (mm)."""
    if measurement not in PLANNED_TYPES:
        hooked = [k for k, cls in MEASUREMENT_TYPES.items() if cls.candidates is not None]
        raise PartcalError(f"plan: --measurement must be one of {', '.join([*PLANNED_TYPES, *hooked])} (a type "
                           f"without candidate poses cannot be planned); got {measurement!r}")
    section = "planes" if measurement == "plane" else "points"
    specs = cell.get(section) or {}
    if not specs:
        raise PartcalError(f"{source}: {section}: no {section} to plan {measurement} rows for; the cell define none")
    if measurement == "plane":
        return {name: plane_geometry(cell, name, source) for name in specs}
    out = {}
    for name, spec in specs.items():
        if "known_mm" not in spec:
            raise PartcalError(f"{source}: points.{name}: a fixed point without known_mm cannot be planned for; give "
                               "its position (approximate for an unknown nest) as known_mm: [x, y, z] (base frame)")
        out[name] = np.asarray(spec["known_mm"], dtype=float)
    return out


def touch_candidates(robot: Robot, cell: dict, measurement: str, count: int, rng: np.random.Generator, *,
                     source: str = "cell", floor=plan.ROBOT_FLOOR, ranges_deg: dict | None = None) -> MeasurementRows:
    """About ``count`` candidate rows of ``type``, shared evenly among the cell: the nominal tool tip on
    each plane (or at each point) from random orientations (joints sampled within the limits, or the
    ``ranges_deg`` ``{joint: (lo, hi)}``, 1-based), kept above ``floor``."""
    targets = feature_targets(cell, measurement, source)
    each = max(3, math.ceil(count / len(targets)))
    cell, floor = nominal_cell(robot), plan.floor_of(robot, floor)
    qs, names = [], []
    for name, target in targets.items():
        try:
            if measurement == "plane":
                q, _ = plane_touches(cell, {name: target}, {name: each}, rng, 0.0, ranges_deg=ranges_deg)
            else:
                q, _ = fixed_point_visits(cell, {name: target}, {name: each}, rng, 0.0,
                                          ranges_deg=ranges_deg)
        except UnreachableError as exc:
            raise UnreachableError(f"{source}: {'planes' if measurement == 'plane' else 'points'}.{name}: out of reach of "
                                   f"{robot.name}: {exc}") from None
        if floor is not None:
            q = q[above_floor(robot, q, floor)]
        if len(q) < 3:
            raise UnreachableError(f"{source}: {'planes' if measurement == 'plane' else 'points'}.{name}: {len(q)} of "
                                   f"{each} candidates keep above the floor ({floor.describe()}); lower the floor "
                                   "or move the feature")
        qs.append(q)
        names += [name] * len(q)
    return measurement_rows_of(np.vstack(qs), measurement, names)


def measurement_rows_of(q_deg: NDArray[np.float64], measurement: str, names, source: str = "plan") -> MeasurementRows:
    """Rows of one ``type`` at ``q_deg`` (n, N) deg, each naming its feature."""
    n = len(q_deg)
    return MeasurementRows(np.asarray(q_deg, dtype=float), (measurement,) * n, tuple(str(i + 1) for i in range(n)),
                tuple(range(1, n + 1)), source, {}, {"feature": tuple(names)})


# ---------------------------------------------------------------------- planning
@dataclass(frozen=True)
class MeasurementPlan:
    """Planned rows of one type: ``rows`` (in candidate order), their ``chosen`` rows of the ``candidates``, the
    ``evaluation`` of the set, the ``exchange``, and the candidates' scaled Jacobian ``blocks`` (C, r, L) the
    exchange chose from (:func:`candidate_blocks`; ``design.information_logdet(blocks, rows)`` judges any
    other choice of the same candidates alike)."""

    rows: MeasurementRows
    chosen: NDArray[np.intp]
    evaluation: MeasurementEvaluation
    exchange: design.ExchangeResult
    candidates: MeasurementRows
    blocks: NDArray[np.float64]


def candidate_blocks(robot: Robot, candidates: MeasurementRows, cell: dict, model: design.PlannedModel,
                     rcond: float = 1e-6) -> tuple[NDArray[np.float64], StackedDesign]:
    """Each candidate's weighted Jacobian rows over the parameters the whole pool identifies, columns scaled as
    :func:`column_scales`: shape ``(C, r, L)`` (``r`` residuals per row: 1 a touch, 3 a visit)."""
    d = stacked_design(robot, candidates, cell, model, rcond)
    live = d.row_of >= 0                      # a known length between two unknowns reads no row: no choice
    order = np.argsort(d.row_of[live], kind="stable")
    rows = d.jac[live][order][:, d.free] * column_scales(robot, d.names)[d.free]
    per = rows.shape[0] // len(candidates)
    return rows.reshape(len(candidates), per, -1), d


def plan_measurements(robot: Robot, n: int, cell: dict, measurement: str, *, model: design.PlannedModel = design.DH,
               pool: int = plan.DEFAULT_POOL, random_state=0, source: str = "cell", floor=plan.ROBOT_FLOOR,
               ranges_deg: dict | None = None, candidates: MeasurementRows | None = None, callback=None,
               poses: NDArray[np.float64] | None = None) -> MeasurementPlan:
    """Plan ``n`` rows of ``type`` (``plane``: touches; ``fixed``: visits) on the cell's cell (module
    docstring): ``pool`` candidates (:func:`touch_candidates`), the D-optimal ``n`` of them for the stacked
    problem. Given ``candidates`` (rows of ``type``) are chosen from instead. ``poses`` (n, N) deg: the cell's
    safe poses a type with its own candidates (a camera's images) draws them from, instead of the joint limits."""
    seeds = np.random.SeedSequence(seed_from(random_state)).spawn(3)
    model.check(robot)
    hook = getattr(MEASUREMENT_TYPES.get(measurement), "candidates", None)
    if poses is not None and (hook is None or measurement in PLANNED_TYPES):
        raise PartcalError(f"plan --measurement {measurement}: its candidates are put on the cell's planes and points, "
                           "not chosen among given poses (--candidates goes with tracker poses and camera images)")
    if candidates is None and hook is not None and measurement not in PLANNED_TYPES:
        rng = np.random.default_rng(seeds[0])                                       # the type's own candidates
        candidates = hook(robot, cell, pool, rng) if poses is None else hook(robot, cell, pool, rng, poses=poses)
        below = ~above_floor(robot, candidates.q_deg, plan.floor_of(robot, floor))   # an image's rows share its pose
        if below.any():
            candidates = candidates.take(np.flatnonzero(~below))
    elif candidates is None:
        candidates = touch_candidates(robot, cell, measurement, pool, np.random.default_rng(seeds[0]), source=source,
                                      floor=floor, ranges_deg=ranges_deg)
    if any(k != measurement for k in candidates.types):
        raise PartcalError(f"plan: the candidates must all be {measurement} rows; got {sorted(set(candidates.types))}")
    blocks, d = candidate_blocks(robot, candidates, cell, model)
    if getattr(MEASUREMENT_TYPES.get(measurement), "plans_by", None) == "image":     # a camera: whole images
        return _plan_images(robot, n, cell, measurement, model, candidates, blocks, d, seeds, callback)
    need = max(1, math.ceil(d.free.size / blocks.shape[1]))
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or not need <= n <= len(candidates):
        raise PartcalError(f"plan: the number of {measurement} rows must be a whole number in [{need}, {len(candidates)}]: "
                           f"at least {need} for the {d.free.size} identifiable unknowns, at most the "
                           f"{len(candidates)} candidates (--pool); got {n!r}")
    result = design.detmax(blocks, int(n), random_state=np.random.default_rng(seeds[1]), callback=callback)
    chosen = candidates.take(result.indices)
    chosen = dataclasses.replace(chosen, ids=tuple(str(i + 1) for i in range(len(chosen))),
                                 lines=tuple(range(1, len(chosen) + 1)))
    evaluation = evaluate_measurements(robot, chosen, cell, model=model, random_state=np.random.default_rng(seeds[2]))
    return MeasurementPlan(chosen, result.indices, evaluation, result, candidates, blocks)


def _plan_images(robot, n, cell, measurement, model, candidates, blocks, d, seeds, callback) -> MeasurementPlan:
    """``n`` whole images of a camera's candidates (``candidates.texts["image"]``), D-optimal: each image's rows'
    blocks as one block (the triangle of their QR: the same information), DETMAX over the images; the plan's rows
    are every row of the chosen images."""
    image = np.asarray(candidates.texts["image"], dtype=object)
    names = list(dict.fromkeys(image))
    rows_of = [np.flatnonzero(image == name) for name in names]
    width = blocks.shape[2]
    stacked = np.zeros((len(names), width, width))        # each image's rows as the triangle R of their QR
    for k, rows in enumerate(rows_of):                    # (R^T R = J^T J: the same information, fewer rows)
        triangle = np.linalg.qr(blocks[rows].reshape(-1, width), mode="r")
        stacked[k, :triangle.shape[0]] = triangle
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or not 3 <= n <= len(names):
        raise PartcalError(f"plan: the number of images must be a whole number in [3, {len(names)}]: at least 3 for "
                           f"the camera's pose, at most the {len(names)} candidate images; got {n!r}")
    result = design.detmax(stacked, int(n), random_state=np.random.default_rng(seeds[1]), callback=callback)
    taken = np.sort(np.concatenate([rows_of[k] for k in result.indices]))
    chosen = candidates.take(taken)
    chosen = dataclasses.replace(chosen, ids=tuple(str(i + 1) for i in range(len(chosen))),
                                 lines=tuple(range(1, len(chosen) + 1)))
    evaluation = evaluate_measurements(robot, chosen, cell, model=model, random_state=np.random.default_rng(seeds[2]))
    return MeasurementPlan(chosen, taken, evaluation, result, candidates, blocks)


def planned_images(rows: MeasurementRows) -> tuple[list[str], NDArray[np.float64]]:
    """The planned images' names and joints (one row each, in plan order): the joints CSV an image folder is taken
    with (:func:`partcal.data.detect.detect_folder`)."""
    image = list(rows.texts["image"])
    first = [image.index(name) for name in dict.fromkeys(image)]
    return [image[i] for i in first], rows.q_deg[first]


def planned_table(rows: MeasurementRows, name: str = "plan") -> MeasurementRows:
    """The planned rows as a measurements CSV's table (``measurement``, ``id``, what names their feature, joints, and
    ``planned`` 1: no measured value, they are to be measured; the identification refuses them until they are,
    :data:`~partcal.calibration.checks.PLANNED`) for ``write_measurement_rows``."""
    return MeasurementRows(q_deg=rows.q_deg, types=rows.types, ids=rows.ids, lines=rows.lines, source=rows.source,
                           numbers={PLANNED: np.ones(len(rows))}, texts=dict(rows.texts), name=name)
