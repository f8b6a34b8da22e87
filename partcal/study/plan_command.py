"""``partcal plan`` in one call: the options checked, the floor, the candidate pool, then a pose set planned,
evaluated, or the pose-count curve; or the ISO 9283 cube's test poses.

The options are the command line's (:class:`PlanOptions`, one field per option); progress lines go to
``say`` and the lines the command prints to ``show``::

    from partcal.study.plan_command import PlanOptions, run_plan

    run_plan("universal_robots_ur10", PlanOptions(n=40, output="poses.csv"), show=print)
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Callable

import numpy as np

from .. import __version__
from .._io import atomic_write, refuse_input_as_output
from ..data.formats import load_format
from ..data.measurements import read_columns
from ..errors import PartcalError
from ..calibration import design
from ..robot.description import joint_columns
from ..robot.floor import Floor, robot_floor
from ..robot.kinematics import Robot
from ..data.measurement_rows import has_measurement_column, read_cell, read_measurement_rows, write_measurement_rows
from ..calibration.measurement import SCALE
from ..calibration.registry import MEASUREMENT_TYPES, measurement_names
from . import plan, plan_measurements
from .config import robot_named


@dataclass(frozen=True)
class PlanOptions:
    """The options of ``partcal plan`` (docs/plan.md), each with the command line's default.

    ``n`` poses into ``output``, ``evaluate`` a pose set, ``curve`` up to ``curve_max`` poses; the pool from
    ``candidates`` (a CSV, in the ``format`` of a YAML), a ``box`` (xmin, ymin, zmin, xmax, ymax, zmax mm) or
    ``pool`` poses within the limits; the planned model (``no_base``, ``no_tool``, ``compliance`` joints,
    ``joint_harmonics`` (one K, or one per joint), ``payload_kg``, ``parametrization``); ``iso9283`` with
    ``cube`` (cx, cy, cz, edge mm) and ``cycles``; the floor (``floor_mm``, ``clearance_mm``, ``no_floor``);
    measurement types: ``measurement`` rows to plan on the cell's description ``cell`` (a cell YAML), which an evaluated
    measurements file is read with too.
    """

    n: int | None = None
    output: str | Path | None = None
    evaluate: str | Path | None = None
    curve: bool = False
    curve_max: int | None = None
    candidates: str | Path | None = None
    box: tuple[float, ...] | None = None
    format: str | Path | None = None
    pool: int = plan.DEFAULT_POOL
    noise_mm: float = plan.DEFAULT_NOISE_MM
    seed: int = 0
    no_base: bool = False
    no_tool: bool = False
    compliance: tuple[int, ...] | None = None
    joint_harmonics: tuple[int, ...] | None = None
    payload_kg: float = 0.0
    parametrization: str = "auto"
    iso9283: bool = False
    cube: tuple[float, float, float, float] | None = None
    cycles: int | None = None
    floor_mm: float | None = None
    clearance_mm: float | None = None
    no_floor: bool = False
    cell: str | Path | None = None
    measurement: str | None = None

    @classmethod
    def from_args(cls, args) -> "PlanOptions":
        """The options from an object with one attribute per field (the command line's parsed arguments)."""
        return cls(**{f.name: getattr(args, f.name) for f in fields(cls)})


def _quiet(text: str) -> None:
    """The default of ``say`` and ``show``: nothing."""


def run_plan(robot: str | Path, options: PlanOptions, *, say: Callable[[str], None] = _quiet,
             show: Callable[[str], None] = _quiet) -> None:
    """``partcal plan ROBOT``: what ``options`` ask, for the robot ``robot`` (built-in name, YAML or URDF)."""
    o = options
    if o.iso9283:
        return _iso9283(robot, o, show)
    fmt = load_format(o.format) if o.format else None
    if o.measurement is not None or (o.evaluate and has_measurement_column(o.evaluate, fmt)):
        return _measurements(robot, o, say, show)
    if o.cell is not None:
        raise PartcalError("plan: --cell goes with --measurement plane|fixed (plan touches or visits) or --evaluate of a "
                           "measurements file (one with a measurement column)")
    planning = o.n is not None
    if o.cube is not None or o.cycles is not None:
        raise PartcalError("plan: --cube and --cycles go with --iso9283")
    if not (planning or o.evaluate or o.curve):
        raise PartcalError("plan: give -n N -o POSES.csv (plan poses), --evaluate DATA.csv (judge a pose set) or "
                           "--curve (predicted uncertainty against the number of poses)")
    if planning != (o.output is not None):
        raise PartcalError("plan: -n N and -o POSES.csv go together (how many poses, and the CSV to write)")
    if planning and o.evaluate:
        raise PartcalError("plan: give either -n N -o POSES.csv or --evaluate DATA.csv, not both")
    if o.candidates and o.box:
        raise PartcalError("plan: give either --candidates FILE.csv or --box, not both")
    if not (o.noise_mm > 0 and np.isfinite(o.noise_mm)):
        raise PartcalError(f"plan: --noise-mm must be a positive number of mm; got {o.noise_mm!r}")
    refuse_input_as_output(o.output, "plan", [("candidate file", o.candidates), ("format file", o.format),
                                              ("evaluated file", o.evaluate), ("robot file", robot)])
    arm = robot_named(robot)
    floor = plan_floor(arm, o)
    start = time.perf_counter()
    model = _planned_model(arm, o)
    evaluated = plan.check_candidates(arm, _joints(arm, o.evaluate, o), str(o.evaluate)) if o.evaluate else None
    if o.candidates:
        stated = o.floor_mm is not None or o.clearance_mm is not None    # a cell's own poses: the cell's to vouch for
        q = plan.check_candidates(arm, _joints(arm, o.candidates, o), str(o.candidates), floor if stated else None)
        space, where = plan.workspace(arm, q, model=model), f"the {len(q)} poses of {o.candidates}"
    else:
        box = None if o.box is None else np.array(o.box, dtype=float).reshape(2, 3)
        if box is not None and np.any(box[0] >= box[1]):
            raise PartcalError(f"plan: --box takes XMIN YMIN ZMIN XMAX YMAX ZMAX (mm) with each min below its max; "
                               f"got {o.box}")
        space = plan.workspace(arm, random_state=o.seed, n_poses=o.pool, box_mm=box, floor=floor, model=model)
        where = (f"{o.pool} random poses within the joint limits" + (" and the box" if box is not None else "")
                 + (f", every link above the floor ({floor.describe()})" if floor is not None else ", no floor"))
    if planning or o.curve:                             # bad input gets its one line before any progress
        plan.check_count(arm, o.n if planning else plan.min_poses(space.structural.size), space)
    say(f"{arm.name}, {model.describe(arm)}: {space.structural.size} identifiable parameters over {where} "
        f"({time.perf_counter() - start:.1f} s)")
    if o.evaluate:
        show(f"{o.evaluate}: {len(evaluated)} poses of {arm.name}")
        show("\n".join(plan.evaluate_poses(arm, evaluated, space=space, noise_mm=o.noise_mm).lines()))
    if planning:
        _planned(arm, o, space, model, where, start, say, show)
    if o.curve:
        largest = o.curve_max or max(3 * space.structural.size, o.n or 0)
        counts = plan.curve_counts(space.structural.size, min(largest, len(space.q_deg)))
        rows = plan.pose_curve(arm, counts, space=space, noise_mm=o.noise_mm, random_state=o.seed,
                               callback=lambda k, total, row: say(f"curve [{k}/{total}] {row['n']} poses"))
        show("\n".join(plan.curve_lines(rows, o.noise_mm)))


def _planned_model(robot: Robot, o: PlanOptions) -> design.PlannedModel:
    """The model the options plan for (checked against the robot)."""
    harmonics = o.joint_harmonics or (0,)
    return design.PlannedModel(base=not o.no_base, tool=not o.no_tool, compliance=o.compliance or (),
                               joint_harmonics=harmonics[0] if len(harmonics) == 1 else harmonics,
                               payload_kg=o.payload_kg, parametrization=o.parametrization).check(robot)


def _joints(robot: Robot, path, o: PlanOptions) -> np.ndarray:
    """The joint columns of a pose file (candidates or a set to evaluate), deg."""
    return read_columns(path, [joint_columns(robot.n_joints)], fmt=load_format(o.format) if o.format else None)[1]


def _planned(robot: Robot, o: PlanOptions, space, model, where: str, start: float, say, show) -> None:
    """``-n N -o POSES.csv``: the D-optimal pose set written, its evaluation shown."""
    def progress(k: int, logdet: float) -> None:
        if k % 10 == 0:
            say(f"DETMAX exchange {k}: log det {logdet:.4f}")

    result = plan.plan_poses(robot, o.n, space=space, noise_mm=o.noise_mm, random_state=o.seed, callback=progress)
    plan.write_plan(robot, result.q_deg, o.output, comment=(
        f"Pose list planned by partcal {__version__} for {robot.name} ({model.describe(robot)}): {o.n} of "
        f"{where}, D-optimal (DETMAX), seed {o.seed}.\nJoint angles in degrees, nominal tool positions in "
        f"mm. Measure these poses; the tracker's positions become x_meas,y_meas,z_meas (mm).\n"
        f"{result.evaluation.indices.text()}"))
    show("\n".join(result.evaluation.lines()))
    show(f"wrote {o.n} poses to {o.output} ({result.exchange.exchanges} exchanges, log det "
         f"{result.exchange.start_logdet:.3f} -> {result.exchange.logdet:.3f}, "
         f"{time.perf_counter() - start:.1f} s)")


def _measurements(robot: str | Path, o: PlanOptions, say, show) -> None:
    """``--measurement plane|fixed -n N -o ROWS.csv --cell CELL.yaml`` (rows planned on the cell's planes and points), or
    ``--evaluate KINDS.csv [--cell CELL.yaml]`` (a measurements file judged): docs/plan.md, "Measurement types"."""
    planning = o.measurement is not None
    images = getattr(MEASUREMENT_TYPES.get(o.measurement), "plans_by", None) == "image"
    others = [flag for flag, on in (("--curve", o.curve), ("--candidates", o.candidates and not images),
                                    ("--box", o.box), ("--cube", o.cube), ("--cycles", o.cycles)) if on]
    if planning and o.evaluate:
        raise PartcalError("plan: give either --measurement with -n N -o ROWS.csv or --evaluate DATA.csv, not both")
    if planning and (o.n is None or o.output is None or o.cell is None):
        raise PartcalError(f"plan --measurement {o.measurement}: give -n N -o ROWS.csv --cell CELL.yaml (how many rows, the "
                           "measurements CSV to write, and the cell's planes and points)")
    if not planning and (o.n is not None or o.output is not None):
        raise PartcalError(f"plan: {o.evaluate} holds measurement types (a measurement column): give --evaluate alone, or "
                           "--measurement plane|fixed with -n N -o ROWS.csv to plan rows")
    if others:
        verb = "goes" if len(others) == 1 else "go"
        raise PartcalError(f"plan: {', '.join(others)} {verb} with tracker poses, not with measurement types "
                           f"({'--measurement' if planning else 'a measurements file'}); the candidates of --measurement are drawn "
                           "on the cell's planes and points (--pool of them); --candidates also goes with "
                           "--measurement camera (the poses its images are chosen among)")
    refuse_input_as_output(o.output, "plan", [("cell file", o.cell), ("candidate file", o.candidates),
                                              ("robot file", robot)])
    arm = robot_named(robot)
    model = _planned_model(arm, o)
    cell = read_cell(o.cell) if o.cell is not None else {}
    if not planning:
        table = read_measurement_rows(o.evaluate, arm, load_format(o.format) if o.format else None, cell or None,
                                  measurements=measurement_names())
        show(f"{o.evaluate}: {len(table)} rows of {arm.name} ({model.describe(arm)})")
        show("\n".join(plan_measurements.evaluate_measurements(arm, table, cell, model=model,
                                                  random_state=o.seed).lines()))
        return
    _measurements_planned(arm, o, model, cell, say, show)


def _measurements_planned(arm: Robot, o: PlanOptions, model, cell: dict, say, show) -> None:
    """``--measurement plane|fixed -n N -o ROWS.csv``: the rows planned, written as a measurements CSV, their evaluation shown."""
    start = time.perf_counter()
    floor, poses = plan_floor(arm, o), None
    if o.candidates:                                  # a cell's own poses: the cell's to vouch for, unless a floor is stated
        floor = floor if o.floor_mm is not None or o.clearance_mm is not None else None
        poses = plan.check_candidates(arm, _joints(arm, o.candidates, o), str(o.candidates), floor)
    result = plan_measurements.plan_measurements(arm, o.n, cell, o.measurement, model=model, pool=o.pool, random_state=o.seed,
                                   source=str(o.cell), floor=floor, poses=poses,
                                   callback=lambda k, logdet: say(f"DETMAX exchange {k}: log det {logdet:.4f}")
                                   if k % 10 == 0 else None)
    if getattr(MEASUREMENT_TYPES.get(o.measurement), "plans_by", None) == "image":
        _images_written(arm, o, model, result, start, show)
        return
    names = result.rows.texts["feature"]
    spread = ", ".join(f"{name} {names.count(name)}" for name in dict.fromkeys(names))
    ev = result.evaluation
    write_measurement_rows(plan_measurements.planned_table(result.rows, Path(o.output).stem), o.output, comment=(
        f"{o.measurement} rows planned by partcal {__version__} for {arm.name} ({model.describe(arm)}) on the features of "
        f"{o.cell}: {o.n} of {len(result.candidates)} candidates (the nominal tool tip on the feature, random "
        f"orientations), D-optimal (DETMAX), seed {o.seed}.\nJoint angles in degrees. Run each row and touch "
        f"(or visit) its feature; the rows are the measurements CSV partcal run reads.\n"
        f"Not identifiable from these rows (held nominal): {', '.join(ev.held) or 'none'}"))
    show("\n".join(ev.lines()))
    scale = any(note.startswith(SCALE) for note in ev.notes)
    show(f"the plan leaves unidentifiable (held nominal): {', '.join(ev.held) or 'nothing'}"
         + ("; and the robot's uniform scale: nothing in these rows measures a length (give a plane's spacing_mm or "
            "a point's known_mm)" if scale else ""))
    show(f"wrote {o.n} {o.measurement} rows ({spread}) to {o.output} ({result.exchange.exchanges} exchanges, log det "
         f"{result.exchange.start_logdet:.3f} -> {result.exchange.logdet:.3f}, {time.perf_counter() - start:.1f} s)")


def _images_written(arm: Robot, o: PlanOptions, model, result, start: float, show) -> None:
    """``--measurement camera -n N -o JOINTS.csv``: the planned images' joints (``image, q1..qN``, one row each: the
    joints CSV an image folder is detected with), their evaluation shown. With several cameras, one such file per
    camera (``JOINTS_<camera>.csv``): each camera's folder is detected with its own."""
    names, q = plan_measurements.planned_images(result.rows)
    camera = dict(zip(result.rows.texts["image"], result.rows.texts["camera"]))
    cameras = list(dict.fromkeys(camera[name] for name in names))
    ev = result.evaluation
    output = Path(o.output)
    written = []
    for cam in cameras:
        path = output if len(cameras) == 1 else output.with_name(f"{output.stem}_{cam}{output.suffix}")
        mine = [k for k, name in enumerate(names) if camera[name] == cam]
        lines = [f"# camera images planned by partcal {__version__} for {arm.name} ({model.describe(arm)}) on the "
                 f"cell {o.cell}: {len(names)} of {len(set(result.candidates.texts['image']))} candidate images (the "
                 f"board in view, not too oblique, at the nominal robot), D-optimal (DETMAX), seed {o.seed}"
                 + (f"; camera {cam}'s {len(mine)} of them." if len(cameras) > 1 else "."),
                 "# Joint angles in degrees. Take one image at each pose, named as its row; partcal.data.detect reads "
                 "the folder with this file.",
                 "image," + ",".join(f"q{j + 1}" for j in range(arm.n_joints))]
        lines += [names[k] + "," + ",".join(f"{v:.6f}" for v in q[k]) for k in mine]
        with atomic_write(path) as handle:
            handle.write("\n".join(lines) + "\n")
        written.append(f"{path} ({len(mine)})" if len(cameras) > 1 else str(path))
    show("\n".join(ev.lines()))
    show(f"wrote {len(names)} images' joints to {', '.join(written)} ({result.exchange.exchanges} exchanges, log det "
         f"{result.exchange.start_logdet:.3f} -> {result.exchange.logdet:.3f}, {time.perf_counter() - start:.1f} s)")


def plan_floor(robot: Robot, options: PlanOptions) -> Floor | None:
    """The floor a plan keeps every pose above (None: none), from the options ``floor_mm``, ``clearance_mm``
    and ``no_floor`` (default: the robot's own)."""
    floor_mm, clearance_mm = options.floor_mm, options.clearance_mm
    if floor_mm is not None and not np.isfinite(floor_mm):
        raise PartcalError(f"plan: --floor-mm must be a finite number of mm (the floor's height in the base frame); "
                           f"got {floor_mm!r}")
    if clearance_mm is not None and not (np.isfinite(clearance_mm) and clearance_mm >= 0):
        raise PartcalError(f"plan: --clearance-mm must be a number of mm >= 0; got {clearance_mm!r}")
    if options.no_floor and (floor_mm is not None or clearance_mm is not None):
        raise PartcalError("plan: --no-floor goes without --floor-mm and --clearance-mm")
    if clearance_mm is not None and floor_mm is None and robot.floor_mm is None:
        raise PartcalError(f"plan: --clearance-mm needs a floor, and {robot.name} is described without one "
                           "(floor_mm: null): give --floor-mm too")
    return robot_floor(robot, floor_mm, clearance_mm, off=options.no_floor)


def _iso9283(robot: str | Path, o: PlanOptions, show) -> None:
    """``--iso9283 -o POSES.csv``: the test poses P1..P5 of a cube, in cycles."""
    if o.output is None or o.n is not None or o.evaluate or o.curve:
        raise PartcalError("plan --iso9283: give -o POSES.csv (and optionally --cube CX CY CZ EDGE, --cycles N), "
                           "without -n, --evaluate or --curve")
    refuse_input_as_output(o.output, "plan", [("robot file", robot)])
    arm = robot_named(robot)
    floor = plan_floor(arm, o)
    cycles = 30 if o.cycles is None else o.cycles
    cube = plan.iso_cube_plan(arm, o.output, cube=o.cube, cycles=cycles, random_state=o.seed, floor=floor,
                              comment=f"ISO 9283 test poses planned by partcal {__version__} for {arm.name}. "
                                      "Joint angles in degrees, nominal tool positions in mm.")
    for k, (p, q) in enumerate(zip(cube.points_mm, cube.q_deg)):
        show(f"P{k + 1}: {np.round(p, 3).tolist()} mm, joints {np.round(q, 3).tolist()} deg")
    show(f"wrote {len(cube.q_deg) * cycles} poses ({cycles} cycles of P1..P5; cube centre "
         f"{np.round(cube.centre_mm, 3).tolist()} mm, edge {cube.edge_mm:g} mm) to {o.output}")
