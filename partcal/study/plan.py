"""Plan a measurement before the tracker is set up: which poses, how many, and how good a pose set is.

``plan_poses`` draws a candidate pool (joint-limit poses, poses whose tool is
inside a Cartesian box, or the user's own list of reachable and safe poses)
and keeps the ``n`` that make the kinematic model (a
:class:`~partcal.calibration.design.PlannedModel`: geometry, and the joint
compliance and harmonics of ``kind: kinematic``) best identifiable
(D-optimal, DETMAX; see :mod:`partcal.calibration.design`). ``evaluate_poses`` reports
the observability indices of any pose set, the parameters it cannot
identify, the predicted standard error of each parameter and the predicted
position uncertainty of the identified robot over the workspace, for a given
tracker noise. ``pose_curve`` does that for a range of ``n``, so the engineer
sees where more poses stop paying. ``write_plan`` writes the poses as a pose
list in the measurement-CSV layout.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write
from ..calibration.checks import check_joint_units
from ..errors import DataError, PartcalError
from ..calibration import design
from .._validation import seed_from
from ..robot.description import joint_columns
from ..robot.floor import Floor, above_floor, below_floor_text, robot_floor
from ..robot.kinematics import Robot

log = logging.getLogger(__name__)
DEFAULT_NOISE_MM = 0.03     # a laser tracker at 2-3 m: about 15 um + 6 um/m per coordinate
DEFAULT_POOL = 2000         # candidate poses drawn within the limits (or the box)
WORKSPACE_POSES = 1000      # joint-limit poses over which a pose set's uncertainty is predicted
_MAX_DRAWS = 400_000        # uniform joint-space draws before a candidate search gives up
ROBOT_FLOOR = "robot"       # the floor of the robot's description (floor_mm), the default of every drawn pool


# ---------------------------------------------------------------------- candidates
def candidates_within_limits(robot: Robot, n: int, rng: np.random.Generator, box_mm=None,
                             floor: Floor | None = None) -> NDArray[np.float64]:
    """``n`` uniform random poses within the joint limits and coupled constraints, shape ``(n, N)`` deg.

    With ``box_mm`` (``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, mm) only
    poses whose nominal tool position lies in the box count; with ``floor``
    (:class:`~partcal.robot.floor.Floor`) only poses whose links, flange and tool
    stay above it. Poses that fail are drawn again, so ``n`` come back or a
    one-line error says that the limits, box and floor leave too little room.
    """
    lo, hi = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    found, draws, batch = [], 0, max(4 * n, 1000)
    kept = 0
    while kept < n and draws < _MAX_DRAWS:
        q = rng.uniform(lo, hi, size=(batch, robot.n_joints))
        draws += batch
        q = q[robot.within_limits(q)]
        if box_mm is not None and len(q):
            p = robot.positions(q)
            q = q[np.all((p >= box_mm[0]) & (p <= box_mm[1]), axis=1)]
        if floor is not None and len(q):
            q = q[above_floor(robot, q, floor)]
        found.append(q)
        kept += len(q)
    if kept < n:
        where = "".join([f" with the tool inside the box {np.asarray(box_mm).tolist()} mm" if box_mm is not None
                         else "", f" with every link above the floor ({floor.describe()})" if floor is not None
                         else ""])
        raise DataError(f"only {kept} of {draws} random joint-limit poses of {robot.name} are admissible{where}; "
                        f"{n} candidates were asked for: "
                        + ("widen the box, " if box_mm is not None else "")
                        + ("lower the floor (--floor-mm, --clearance-mm), " if floor is not None else "")
                        + "or give a candidate CSV")
    return np.concatenate(found)[:n]


def floor_of(robot: Robot, floor) -> Floor | None:
    """The floor a plan keeps above: ``floor`` itself (a :class:`~partcal.robot.floor.Floor` or None for none),
    or the robot's own (``floor_mm`` of its description, default clearance) for :data:`ROBOT_FLOOR`."""
    if isinstance(floor, str) and floor == ROBOT_FLOOR:
        return robot_floor(robot)
    if floor is not None and not isinstance(floor, Floor):
        raise PartcalError(f"floor must be a Floor, None or {ROBOT_FLOOR!r}; got {floor!r}")
    return floor


def check_candidates(robot: Robot, q_deg: NDArray[np.float64], source: str,
                     floor: Floor | None = None) -> NDArray[np.float64]:
    """The user's poses ``(n, N)`` deg (candidates, or a set to evaluate), refused when they look like radians
    (:func:`~partcal.calibration.checks.check_joint_units`), one is outside the limits, or (with ``floor``) one
    puts a link, the flange or the tool below the floor."""
    q_deg = robot.check_joints(q_deg, source)
    check_joint_units(source, ["data row 1"], q_deg)
    bad = np.flatnonzero(~robot.within_limits(q_deg))
    if bad.size:
        k = int(bad[0])
        raise DataError(f"{source}: data row {k + 1} ({np.round(q_deg[k], 4).tolist()} deg) is outside the joint "
                        f"limits or coupled constraints of {robot.name}; expected admissible poses only "
                        f"({bad.size} of {len(q_deg)} are not)")
    if floor is not None:
        low = np.flatnonzero(~above_floor(robot, q_deg, floor))
        if low.size:
            k = int(low[0])
            raise DataError(f"{source}: data row {k + 1} ({np.round(q_deg[k], 4).tolist()} deg) "
                            f"{below_floor_text(robot, q_deg[k], floor)}, below the floor of {robot.name} "
                            f"({floor.describe()}; {low.size} of {len(q_deg)} poses are below): give poses above "
                            "it, or set the floor (--floor-mm, --clearance-mm) or turn it off (--no-floor)")
    return q_deg


# ---------------------------------------------------------------------- evaluation
@dataclass(frozen=True)
class Evaluation:
    """What a pose set promises for the kinematic identification.

    Attributes
    ----------
    indices : Indices
        Over the parameters the set identifies (scaled columns, see :mod:`partcal.calibration.design`).
    names, units : tuple of str, length P
        Every parameter of the model.
    identified : tuple of str
        The parameters the set identifies.
    missing : tuple of str
        Parameters joint-limit (workspace) poses identify but this set does not: its weakness.
    never : tuple of str
        Parameters no pose of the workspace identifies: positions cannot separate them from the others
        (equivalent parameters carry their effect), or the candidates never move what they need.
    std_error : ndarray, shape (P,)
        Predicted standard error of each identified parameter (mm, deg; NaN otherwise).
    noise_mm : float
        Tracker noise per coordinate the predictions assume.
    position_rms_mm, position_p95_mm, position_max_mm : float
        Predicted 3-D standard deviation of the identified robot's position over the
        workspace poses: RMS, 95th percentile and largest.
    note : str
        Why some of ``never`` cannot be identified, where the model says (a compliance without a payload).
    """

    indices: design.Indices
    names: tuple[str, ...]
    units: tuple[str, ...]
    identified: tuple[str, ...]
    missing: tuple[str, ...]
    never: tuple[str, ...]
    std_error: NDArray[np.float64]
    noise_mm: float
    position_rms_mm: float
    position_p95_mm: float
    position_max_mm: float
    note: str = ""

    def lines(self) -> list[str]:
        """The text ``partcal plan --evaluate`` prints."""
        ind = self.indices
        out = [f"observability ({ind.n_poses} poses, {ind.n_parameters} identified parameters): {ind.text()}",
               "not identifiable from this set (joint-limit poses would identify them): "
               + (", ".join(self.missing) if self.missing else "none"),
               "not identifiable from any pose of the workspace (kept nominal; where positions cannot separate "
               "them, equivalent parameters carry their effect): "
               + (", ".join(self.never) if self.never else "none")
               + (f"; {self.note}" if self.note else ""),
               f"predicted position uncertainty of the identified robot over the workspace, tracker noise "
               f"{self.noise_mm:g} mm per coordinate: RMS {self.position_rms_mm:.4f} mm, 95% "
               f"{self.position_p95_mm:.4f} mm, max {self.position_max_mm:.4f} mm"
               + (" (the missing parameters' own errors come on top)" if self.missing else ""),
               "predicted standard error of each identified parameter:"]
        for name, unit, std in zip(self.names, self.units, self.std_error):
            if np.isfinite(std):
                out.append(f"  {name:<12}{std:>12.4g} {unit}")
        return out

    def to_dict(self) -> dict:
        return {"indices": self.indices.to_dict(), "identified": list(self.identified), "missing": list(self.missing),
                "never": list(self.never), "noise_mm": self.noise_mm, "position_rms_mm": self.position_rms_mm,
                "position_p95_mm": self.position_p95_mm, "position_max_mm": self.position_max_mm,
                "std_error": {n: float(s) for n, s in zip(self.names, self.std_error) if np.isfinite(s)}}


@dataclass(frozen=True)
class Workspace:
    """Poses standing for the workspace, their scaled Jacobian blocks and the parameters they identify,
    for one planned model."""

    q_deg: NDArray[np.float64]
    blocks: NDArray[np.float64]         # (m, 3, P), scaled columns
    structural: NDArray[np.intp]        # parameters the workspace poses identify
    wanted: NDArray[np.bool_]
    scales: NDArray[np.float64]
    model: design.PlannedModel


def workspace(robot: Robot, q_deg=None, *, model: design.PlannedModel = design.DH, random_state=0,
              n_poses: int = WORKSPACE_POSES, box_mm=None, floor=ROBOT_FLOOR, rcond: float = 1e-6) -> Workspace:
    """The workspace a pose set is judged on: ``q_deg`` (candidates), else joint-limit poses (seeded).

    ``model`` is the kinematic model planned for (:class:`~partcal.calibration.design.PlannedModel`: base,
    tool, compliance, joint harmonics, payload). Drawn poses keep above ``floor`` (see :func:`floor_of`;
    default the robot's own floor); ``q_deg`` are taken as given (:func:`check_candidates` checks them).
    """
    model.check(robot)
    if q_deg is None:
        q_deg = candidates_within_limits(robot, n_poses, np.random.default_rng(random_state), box_mm,
                                         floor_of(robot, floor))
    jac, wanted = design.model_jacobian(robot, q_deg, model)
    scales = design.parameter_scales(robot, model)
    structural = design.identifiable(jac, wanted, rcond)
    return Workspace(q_deg, (jac * scales).reshape(len(q_deg), 3, -1), structural, wanted, scales, model)


def _model_of(space: Workspace | None, model: design.PlannedModel | None) -> design.PlannedModel:
    """The planned model: the workspace's, or ``model`` (default DH); refused when they differ."""
    if space is not None and model is not None and model != space.model:
        raise PartcalError(f"the planned model {model} differs from the workspace's {space.model}; build the "
                           "workspace for the model (plan.workspace(robot, model=...))")
    return space.model if space is not None else (model or design.DH)


def evaluate_poses(robot: Robot, q_deg, *, space: Workspace | None = None, noise_mm: float = DEFAULT_NOISE_MM,
                   model: design.PlannedModel | None = None, rcond: float = 1e-6) -> Evaluation:
    """The indices, identifiable parameters and predicted uncertainties of a pose set.

    Parameters
    ----------
    robot : Robot
    q_deg : array-like, shape (n, N)
        The poses, degrees.
    space : Workspace, optional
        Where the position uncertainty is predicted and which parameters count
        as identifiable at all (default: :func:`workspace` of the robot's limits).
    noise_mm : float
        Tracker noise, standard deviation per coordinate, mm.
    model : PlannedModel, optional
        The model the set is judged for: the workspace's (default DH with base and tool).
    rcond : float
        As for :class:`~partcal.models.kinematic.KinematicModel`.
    """
    q_deg = robot.check_joints(q_deg)
    if not (math.isfinite(noise_mm) and noise_mm > 0):
        raise PartcalError(f"the tracker noise must be a positive number of mm; got {noise_mm!r}")
    model = _model_of(space, model)
    space = space or workspace(robot, model=model)
    jac, wanted = design.model_jacobian(robot, q_deg, model)
    within = np.zeros_like(wanted)
    within[space.structural] = True
    own = design.identifiable(jac, within, rcond)      # a subset of what the workspace identifies
    names = design.model_parameters(robot, model)[0]
    label = [n for n, _ in names]
    scaled = jac[:, own] * space.scales[own]
    ind = design.indices(scaled, len(q_deg))
    std = np.full(len(names), np.nan)
    uncertainty = np.zeros(1)
    if own.size:
        cov = design.parameter_covariance(scaled, noise_mm)
        std[own] = np.sqrt(np.diag(cov)) * space.scales[own]   # back from scaled units
        uncertainty = design.position_std(space.blocks[:, :, own], cov)
    missing = tuple(label[i] for i in np.setdiff1d(space.structural, own))
    never = tuple(label[i] for i in np.setdiff1d(np.flatnonzero(wanted), space.structural))
    note = (f"a compliance is not identifiable from data at one payload ({model.payload_kg:g} kg): the sags carry "
            "the gravity; data at a second payload identify it" if model.compliance else "")
    return Evaluation(ind, tuple(label), tuple(u for _, u in names), tuple(label[i] for i in own), missing, never, std,
                      float(noise_mm), float(np.sqrt(np.mean(uncertainty**2))), float(np.percentile(uncertainty, 95)),
                      float(uncertainty.max()), note)


# ---------------------------------------------------------------------- planning
@dataclass(frozen=True)
class Plan:
    """A planned pose set.

    Attributes
    ----------
    q_deg : ndarray, shape (n, N)
        The chosen poses, degrees, in candidate order.
    chosen : ndarray of int, shape (n,)
        Their rows in the candidate pool.
    evaluation : Evaluation
    exchange : ExchangeResult
    n_candidates : int
    """

    q_deg: NDArray[np.float64]
    chosen: NDArray[np.intp]
    evaluation: Evaluation
    exchange: design.ExchangeResult
    n_candidates: int


def min_poses(n_parameters: int) -> int:
    """The fewest poses whose ``3 n`` coordinates can identify ``n_parameters`` parameters."""
    return max(1, math.ceil(n_parameters / 3))


def check_count(robot: Robot, n, space: Workspace) -> None:
    """Refuse a pose count below what the identifiable parameters need or above the candidates."""
    count, need = len(space.q_deg), min_poses(space.structural.size)
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < need or n > count:
        raise PartcalError(f"the number of poses must be a whole number in [{need}, {count}]: at least "
                           f"{need} poses for the {space.structural.size} identifiable parameters of {robot.name} "
                           f"(3 coordinates per pose), at most the {count} candidates; got {n!r}")


def plan_poses(robot: Robot, n: int, *, space: Workspace | None = None, noise_mm: float = DEFAULT_NOISE_MM,
               model: design.PlannedModel | None = None, random_state=0, callback=None, floor=ROBOT_FLOOR) -> Plan:
    """Choose ``n`` poses of the candidate pool that make the kinematic model best identifiable.

    Parameters
    ----------
    robot : Robot
    n : int
        Poses to measure.
    space : Workspace, optional
        The candidate pool (see :func:`workspace`; it takes joint-limit poses,
        a Cartesian box or the user's poses). Default: :data:`DEFAULT_POOL`
        joint-limit poses drawn with ``random_state``.
    noise_mm : float
        Tracker noise for the predicted uncertainties.
    model : PlannedModel, optional
        The kinematic model to make identifiable (geometry, compliance, harmonics): the workspace's,
        default DH with base and tool.
    random_state : int or Generator
        Seeds the pool (when drawn here) and the exchange's random start.
    callback : callable, optional
        ``callback(exchanges, logdet)`` after each accepted exchange.
    floor : Floor, None or "robot"
        The floor the pool drawn here keeps above (:func:`floor_of`; default the robot's own). A given
        ``space`` holds its poses already.
    """
    seeds = np.random.SeedSequence(seed_from(random_state)).spawn(2)
    model = _model_of(space, model)
    if space is None:
        space = workspace(robot, model=model, random_state=np.random.default_rng(seeds[0]), n_poses=DEFAULT_POOL,
                          floor=floor)
    check_count(robot, n, space)
    blocks = space.blocks[:, :, space.structural]
    result = design.detmax(blocks, int(n), random_state=np.random.default_rng(seeds[1]), callback=callback)
    q = space.q_deg[result.indices]
    return Plan(q, result.indices,
                evaluate_poses(robot, q, space=space, noise_mm=noise_mm),
                result, len(space.q_deg))


def pose_curve(robot: Robot, counts, *, space: Workspace, noise_mm: float = DEFAULT_NOISE_MM, random_state=0,
               callback=None) -> list[dict]:
    """Planned sets of each size in ``counts`` for the workspace's model: indices and predicted uncertainty.

    Each dict: ``n``, ``o1``, ``condition``, ``position_rms_mm``, ``position_p95_mm``,
    ``missing`` (parameters the set cannot identify), and ``random_position_rms_mm`` and
    ``random_missing`` (the same for a random set of the size, for scale).
    """
    rows = []
    rng = np.random.default_rng(seed_from(random_state))
    for k, n in enumerate(counts):
        plan = plan_poses(robot, int(n), space=space, noise_mm=noise_mm, random_state=rng)
        ev = plan.evaluation
        rand = evaluate_poses(robot, space.q_deg[rng.choice(len(space.q_deg), int(n), replace=False)],
                              space=space, noise_mm=noise_mm)
        rows.append({"n": int(n), "o1": ev.indices.o1, "condition": ev.indices.condition,
                     "position_rms_mm": ev.position_rms_mm, "position_p95_mm": ev.position_p95_mm,
                     "missing": len(ev.missing),
                     "random_position_rms_mm": rand.position_rms_mm, "random_missing": len(rand.missing)})
        if callback is not None:
            callback(k + 1, len(counts), rows[-1])
    return rows


def curve_counts(n_parameters: int, largest: int) -> list[int]:
    """Pose counts for :func:`pose_curve`: from the fewest that identify to ``largest``, about 8 steps."""
    low = max(min_poses(n_parameters), 1)
    high = max(largest, low)
    return sorted({int(round(v)) for v in np.geomspace(low, high, 8)})


def curve_lines(rows: list[dict], noise_mm: float) -> list[str]:
    """The table ``partcal plan --curve`` prints."""
    lines = [f"predicted 3-D position uncertainty of the identified robot over the workspace (mm), tracker noise "
             f"{noise_mm:g} mm per coordinate",
             f"{'poses':>6}{'O1':>10}{'condition':>11}{'RMS':>9}{'95%':>9}{'random RMS':>12}  missing (planned/random)"]
    for r in rows:
        lines.append(f"{r['n']:>6}{r['o1']:>10.4g}{r['condition']:>11.4g}{r['position_rms_mm']:>9.4f}"
                     f"{r['position_p95_mm']:>9.4f}{r['random_position_rms_mm']:>12.4f}  "
                     f"{r['missing']}/{r['random_missing']}")
    return lines


# ---------------------------------------------------------------------- output
def write_plan(robot: Robot, q_deg: NDArray[np.float64], path: str | Path, *, comment: str = "",
               labels=None, cycles=None) -> None:
    """Write poses as a pose list in the measurement-CSV layout.

    Columns ``q1..qN`` (deg), ``x_nom, y_nom, z_nom`` (mm, forward kinematics) and ``set`` (``plan``, or one
    of ``labels`` per pose), then ``cycle`` when ``cycles`` (one number per pose) are given.

    The measured columns ``x_meas, y_meas, z_meas`` are left out: they come
    from the tracker. Written atomically.
    """
    nominal = robot.positions(q_deg)
    labels = ["plan"] * len(q_deg) if labels is None else list(labels)
    header = joint_columns(robot.n_joints) + ["x_nom", "y_nom", "z_nom", "set"] + (["cycle"] if cycles is not None
                                                                                   else [])
    with atomic_write(path, newline="") as handle:
        for text in comment.splitlines():
            handle.write(f"# {text}\n")
        handle.write(",".join(header) + "\n")
        for k, row in enumerate(np.hstack([q_deg, nominal])):
            handle.write(",".join(f"{v:.6f}" for v in row) + f",{labels[k]}"
                         + (f",{int(cycles[k])}" if cycles is not None else "") + "\n")


def iso_cube_plan(robot: Robot, path: str | Path, *, cube=None, cycles: int = 30, random_state=0,
                  comment: str = "", floor=ROBOT_FLOOR):
    """Write the ISO 9283 test poses P1..P5 of a cube, ``cycles`` times, as a pose list; return the cube.

    ``cube`` is ``(cx, cy, cz, edge)`` in mm (the centre and the edge), or
    None for the largest cube found in the workspace
    (:func:`~partcal.robot.iso_cube.largest_cube`, seeded). Every cycle visits
    P1, P2, P3, P4, P5 in order; the ``set`` column names the point and
    ``cycle`` counts from 1. The cube and its test poses keep above ``floor`` (:func:`floor_of`; default the
    robot's own floor): a given cube that does not is refused naming its lowest corner or the pose.
    """
    from ..robot import iso_cube

    if not isinstance(cycles, (int, np.integer)) or isinstance(cycles, bool) or cycles < 1:
        raise PartcalError(f"the number of cycles must be a whole number >= 1; got {cycles!r}")
    floor = floor_of(robot, floor)
    solved = (iso_cube.largest_cube(robot, random_state=random_state, floor=floor) if cube is None
              else iso_cube.solve_cube(robot, cube[:3], float(cube[3]), floor=floor))
    corners = iso_cube.cube_corners(solved.centre_mm, solved.edge_mm)
    text = (comment + "\n" if comment else "") + (
        f"ISO 9283 test cube: centre {np.round(solved.centre_mm, 3).tolist()} mm, edge {solved.edge_mm:g} mm; "
        f"corners C1..C8 {np.round(corners, 3).tolist()}; plane C1-C2-C7-C8; P1 the centre, P2..P5 at "
        f"{iso_cube.POINT_FRACTION:g} of the diagonal from C1, C2, C7, C8; {cycles} cycles; "
        + ("the tool keeps P1's orientation at every point" if solved.held_orientation else
           f"{robot.name} cannot hold P1's tool orientation at every point: P2..P5 are solved for the position"))
    n = len(solved.q_deg)
    write_plan(robot, np.tile(solved.q_deg, (cycles, 1)), path, comment=text,
               labels=[f"P{k + 1}" for k in range(n)] * cycles, cycles=np.repeat(np.arange(1, cycles + 1), n))
    return solved


def run_indices(robot: Robot, q_deg) -> Evaluation:
    """The evaluation of a run's identification set (what ``partcal run`` prints and the report shows)."""
    return evaluate_poses(robot, q_deg)
