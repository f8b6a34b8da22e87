"""The ``partcal`` command line: argument parsing, progress output and exit codes.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback),
3 compensation left targets unconverged or unreachable (the output marks
them), 1 internal failure.
"""

from __future__ import annotations

import argparse
import logging
import os
import re
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from . import __version__
from .errors import PartcalError

log = logging.getLogger("partcal")


def _cmd_simulate(args) -> int:
    from ._io import check_folder_writable
    from .data.simulate import load_study, simulate, write_study
    from .study.tables import simulation_table

    start = time.perf_counter()
    study = load_study(args.config)
    check_folder_writable(study.output)          # before the simulation, not after
    data = simulate(study)
    paths = write_study(study, data)
    print("\n".join(simulation_table(study, data)))
    print(f"wrote {len(paths)} files to {study.output} in {time.perf_counter() - start:.1f} s")
    return 0


class Progress:
    """Progress on stderr, one line per finished model (on a terminal too: a warning never lands inside
    a half-drawn bar)."""

    def __init__(self, quiet: bool = False, banner: str = ""):
        self.quiet, self.banner = quiet, banner

    def __call__(self, done: int, total: int, text: str) -> None:
        if self.quiet:
            return
        if self.banner:      # shown with the first line, so bad input still gets exactly one line
            sys.stderr.write(self.banner + "\n")
            self.banner = ""
        sys.stderr.write(f"partcal: [{done}/{total}] {text}\n" if done else f"partcal: {text}\n")
        sys.stderr.flush()


def _cmd_run(args) -> int:
    from .study.config import load_config
    from .study.outputs import check_writable, write_run
    from .study.runner import run
    from .study.tables import results_table

    config = load_config(args.config)
    if args.check:
        from .study.prepare import prepare

        prepared = prepare(config)
        data, plan = prepared.datasets, prepared.plan
        check_writable(config.output, config.inputs(), create=False)
        sizes = ", ".join(f"{name} {len(m)}" for name, m in data.items())
        print(f"{args.config}: OK: {len(plan.models)} models; data sets (rows): {sizes}; cross-validation: "
              f"{plan.cv.describe()}; nothing fitted")
        return 0
    if args.screenshot:
        _check_browser()                       # before the fits, not after them
    check_writable(config.output, config.inputs())
    progress = Progress(args.quiet, f"partcal {__version__}: run {config.name!r}, {len(config.models)} models, "
                                    f"{1 + len(config.tests)} data sets, seed {config.seed}")
    result = run(config, progress)
    render = None
    try:
        from .report import render_report
        render = lambda res, folder: render_report(res, folder, screenshot=args.screenshot)  # noqa: E731
    except ImportError as exc:      # the report needs matplotlib and jinja2
        log.warning("no report: %s", exc)
    out = write_run(result, render)
    print(results_table(result))
    ev = result.design
    if ev is not None:
        print(f"identification set: {ev.indices.text()}; not identifiable from it: {', '.join(ev.missing) or 'none'}")
    print(f"outputs: {out}")
    return 0


def _check_browser() -> None:
    """``run --screenshot`` needs Chromium and Playwright: refuse before fitting when either is missing."""
    from .report.browser import chromium_path

    chromium_path()
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        raise PartcalError("--screenshot needs the Python package 'playwright' (pip install 'partcal[browser]'; it "
                           "uses the system's chromium)") from None


def _cmd_predict(args) -> int:
    from ._io import atomic_write
    from .data.point_tables import TURN_COLUMNS, read_point_table
    from .study.predictor import load_predictor

    _refuse_input_as_output(args.output, "predict", [("model file", args.model), ("input file", args.input),
                                                     ("format file", args.format)])
    predictor = load_predictor(args.model)
    joints = predictor.n_inputs if predictor.inputs == "joint" else None
    # a model with compliant joints reads the payload of each row too, when the file has it
    table = read_point_table(args.input, _format(args), joints=joints, payload=predictor.model.reads_payload)
    X, payload = table.values, table.payload_kg
    if joints:
        errors = predictor.predict(joints=X, payload_kg=payload, return_std=args.std)
    else:
        errors = predictor.predict(positions=X, return_std=args.std)
        payload = None
    std = None
    if args.std:
        errors, std = errors
    predictor.refuse_implausible(X, errors, source=args.input, std=std)     # nothing is written then
    given = [X] if payload is None else [X, payload[:, None]]
    header = table.columns + (["payload_kg"] if payload is not None else []) + ["dx", "dy", "dz"] + (
        TURN_COLUMNS if predictor.predicts_pose else [])
    if std is not None:
        header += ["sdx", "sdy", "sdz"] + (["sd" + c[1:] for c in TURN_COLUMNS] if predictor.predicts_pose else [])
        given.append(errors)
        errors = std
    _write_table(args.output, header, np.hstack(given + [errors]), atomic_write)
    _warn_if_far(predictor, X)
    print(f"predicted errors for {len(X)} points: {args.output}")
    return 0


def _far_from_data(predictor, X) -> str:
    """A warning text if model inputs ``X`` lie far from the training data, else ``""``."""
    from .study.predictor import EXTRAPOLATION_LIMIT

    far = predictor.distance_to_data(**({"positions": X} if predictor.inputs == "cartesian" else {"joints": X}))
    if not (far > EXTRAPOLATION_LIMIT).any():
        return ""
    unit = "mm" if predictor.inputs == "cartesian" else "deg"
    return (f"{int((far > EXTRAPOLATION_LIMIT).sum())} of {len(far)} points lie more than {EXTRAPOLATION_LIMIT:g} "
            f"{unit} from the data the model was fitted on (the farthest, data row {int(np.argmax(far)) + 1}, "
            f"{far.max():.4g} {unit})")


def _warn_if_far(predictor, X) -> None:
    """One stderr line if model inputs ``X`` lie far from the training data (predict and compensate)."""
    text = _far_from_data(predictor, X)
    if text:
        print(f"partcal: warning: {text}", file=sys.stderr)


def _cmd_compensate(args) -> int:
    from ._io import atomic_write
    from .data.programs import program_kind

    kind = args.program or program_kind(args.targets)
    if kind is not None:
        if args.std:
            raise PartcalError(f"compensate: --std writes columns of a targets CSV; {args.targets} is a robot program")
        return _compensate_program(args, kind)
    for flag, value in (("--frame", args.frame), ("--tool", args.tool), ("--keep-unconverged", args.keep_unconverged)):
        if value:
            raise PartcalError(f"compensate: {flag} is for robot programs (URScript, KRL, RAPID, joint "
                               f"trajectories); {args.targets} is a targets CSV")
    from .data.point_tables import read_point_table
    from .metrics import ExtrapolationWarning
    from .robot.compensation import CompensationWarning
    from .robot.description import joint_columns
    from .robot.kinematics import xyz_deg_from_matrices
    from .study.predictor import load_predictor

    _refuse_input_as_output(args.output, "compensate", [("model file", args.model), ("targets file", args.targets),
                                                        ("format file", args.format)])
    predictor = load_predictor(args.model)
    n_q = predictor.robot.n_joints if predictor.robot is not None else 0
    table = read_point_table(args.targets, _format(args), seeds=n_q if predictor.inputs == "joint" else 0,
                             orientation=True, payload=predictor.model.reads_payload)
    cols, targets, seeds, optional = table.columns, table.values, table.seeds, table.seed_columns
    turn_cols, angles, payload = table.orientation_columns, table.orientation_deg, table.payload_kg
    if angles is not None and not predictor.predicts_pose:
        raise PartcalError(f"compensate: {args.targets} has the orientation columns {', '.join(turn_cols)}, but "
                           f"{args.model} predicts position errors only ({predictor.model.n_outputs()} outputs): fit "
                           "a pose model ('predict: pose' in the run config) to compensate orientations, or drop "
                           "those columns to compensate the positions; nothing written")
    with warnings.catch_warnings():       # exit code 3 and one stderr line below say it instead
        warnings.simplefilter("ignore", CompensationWarning)
        warnings.simplefilter("ignore", ExtrapolationWarning)
        result = _compensated(predictor, targets, seeds, payload, angles, args.tol_mm, args.tol_deg)
    far = _far_from_data(predictor, result.commanded_mm if predictor.inputs == "cartesian" else result.joints_deg)
    header, parts = list(cols), [targets]
    if angles is not None:
        header += turn_cols
        parts.append(angles)
    if seeds is not None:
        header += optional
        parts.append(seeds)
    if payload is not None:
        header.append("payload_kg")
        parts.append(payload[:, None])
    header += ["x_cmd", "y_cmd", "z_cmd"]
    parts.append(result.commanded_mm)
    if angles is not None:
        header += ["rx_cmd", "ry_cmd", "rz_cmd"]
        parts.append(xyz_deg_from_matrices(result.commanded_rotation))
    if result.joints_deg is not None:
        header += [f"{c}_cmd" for c in joint_columns(n_q)]
        parts.append(result.joints_deg)
    if args.std:          # the position expected to be left at each target, and its spread
        header += ["dx_left", "dy_left", "dz_left", "sdx", "sdy", "sdz"]
        parts += list(predictor.residual_of(result, targets, payload))
    header.append("miss_mm")            # the predicted miss of each target after compensation
    parts.append(result.residual_mm[:, None])
    if angles is not None:
        header.append("miss_deg")
        parts.append(result.residual_deg[:, None])
    reasons = result.reasons(args.tol_mm, args.tol_deg if angles is not None else None, predictor.robot,
                             targets)
    _write_table(args.output, header + ["converged", "reason"], np.hstack(parts), atomic_write,
                 flags=result.converged, texts=reasons, significant=1 if angles is None else 2)
    bad = np.flatnonzero(~result.converged)
    if bad.size:
        first = int(bad[0])
        target = f"{targets[first].round(3).tolist()} mm" + ("" if angles is None else
                                                               f", {angles[first].round(3).tolist()} deg")
        miss = f"{result.residual_mm[first]:.3g} mm" + ("" if angles is None else
                                                        f", {result.residual_deg[first]:.3g} deg")
        print(f"partcal: {bad.size} of {len(targets)} targets did not converge or are unreachable (first: data "
              f"row {first + 1} of {args.targets}, target {target}: {reasons[first]}, predicted miss {miss}); "
              f"{args.output} marks "
              f"them converged=false" + (f"; also, {far}" if far else ""), file=sys.stderr)
        return 3
    if far:
        print(f"partcal: warning: {far}", file=sys.stderr)
    print(f"compensated {len(targets)} targets (all converged): {args.output}")
    return 0


def _compensate_program(args, kind: str) -> int:
    """``partcal compensate MODEL PROGRAM -o OUT``: the program with its targets rewritten; exit 3 (nothing
    written) when a target is not compensated, unless ``--keep-unconverged``."""
    import json

    from ._io import atomic_write
    from .data.programs import DIALECTS, read_program
    from .metrics import ExtrapolationWarning
    from .robot.compensation import CompensationWarning
    from .study.predictor import load_predictor
    from .study.programs import ProgramFrames, compensate_program

    _refuse_input_as_output(args.output, "compensate", [("model file", args.model), ("program", args.targets)])
    if args.format:
        raise PartcalError("compensate: --format is for targets CSVs, not robot programs")
    dialect = DIALECTS[kind]
    frames = ProgramFrames(_named_frames(args.frame, dialect, "--frame"), _named_frames(args.tool, dialect, "--tool"))
    predictor = load_predictor(args.model)
    program = read_program(args.targets, kind)
    with warnings.catch_warnings():       # exit code 3 and one stderr line below say it instead
        warnings.simplefilter("ignore", CompensationWarning)
        warnings.simplefilter("ignore", ExtrapolationWarning)
        result = compensate_program(predictor, program, frames, keep_unconverged=args.keep_unconverged,
                                    tol_mm=args.tol_mm, tol_deg=args.tol_deg)
    summary = result.summary(predictor.name)
    if not program.targets:
        print(f"partcal: warning: {args.targets} holds no targets partcal reads ({dialect.name}); written as it "
              "was (docs/predictor.md, 'Robot programs', says which targets are read)", file=sys.stderr)
    if result.failures:
        first, why = result.failures[0]
        more = len(result.failures) - 1
        line = (f"partcal: {first.where(args.targets)} {why}" + (f" (and {more} more)" if more else "") +
                f"; {len(result.failures)} of {len(program.targets)} targets not compensated")
        if result.output is None:
            print(line + f"; nothing written (--keep-unconverged writes them as they were, with a comment)",
                  file=sys.stderr)
            return 3
    summary_path = Path(str(args.output) + ".json")
    with atomic_write(args.output, "wb") as handle:
        handle.write(result.output)
    with atomic_write(summary_path) as handle:
        json.dump(summary, handle, indent=2)
        handle.write("\n")
    print(_program_summary(summary, args.output, summary_path), file=sys.stderr)
    if result.failures:
        print(line + f"; {args.output} keeps them as they were, with a comment", file=sys.stderr)
        return 3
    return 0


def _named_frames(values, dialect, option: str) -> dict:
    """``--frame``/``--tool`` values, ``NAME=VALUE`` or ``VALUE`` (the default), VALUE in the dialect's syntax."""
    import re

    out = {}
    for value in values or []:
        m = re.match(r"\s*([$A-Za-z_][\w$]*(?:\[\s*\d+\s*\])?)\s*=(?!=)(.*)$", value, re.DOTALL)
        name, text = (m.group(1).replace(" ", ""), m.group(2)) if m else (None, value)
        if name is not None and name.upper().startswith(("BASE_DATA[", "TOOL_DATA[")):
            name = name.upper()
        if name in out:
            raise PartcalError(f"compensate: {option} {name or '(the default)'} is given twice")
        out[name] = dialect.frame(text, f"{option} {value!r}")
    return out


def _program_summary(summary: dict, output, summary_path) -> str:
    """The stderr summary of a compensated program."""
    big, turn, res = summary["largest_correction"], summary["largest_turn"], summary["predicted_residual"]
    text = f"compensated {summary['compensated']} of {summary['targets']} targets ({summary['dialect']})"
    if big:
        text += (f"; largest correction {big['mm']:.4g} mm (target {big['target']}, line {big['line']}) and "
                 f"{turn['deg']:.4g} deg (target {turn['target']}, line {turn['line']})")
    if res:
        text += f"; predicted residual at most {res['max_mm']:.3g} mm, {res['max_deg']:.3g} deg"
    if summary["orientation"] == "kept":
        text += " (a position model: orientations kept)"
    return text + f": {output} (summary: {summary_path})"


def _compensated(predictor, targets, seeds, payload, angles=None, tol_mm: float = 1e-4, tol_deg: float = 1e-5):
    """``compensate_full`` of every target (``compensate_pose`` with ``angles``, (n, 3) degrees), each at its
    own payload when ``payload`` (kg per row) is given, to the tolerances ``tol_mm`` and ``tol_deg``."""
    from .robot.compensation import merged

    def solve(rows, kg):
        def some(v):
            return v if rows is None or v is None else v[rows]

        if angles is None:
            return predictor.compensate_full(some(targets), some(seeds), payload_kg=kg, tol_mm=tol_mm)
        return predictor.compensate_pose(some(targets), some(angles), some(seeds), payload_kg=kg, tol_mm=tol_mm,
                                         tol_deg=tol_deg)

    if payload is None:
        return solve(None, None)
    groups = [payload == kg for kg in np.unique(payload)]
    return merged([(rows, solve(rows, float(payload[rows][0]))) for rows in groups])


def _refuse_input_as_output(output, command: str, inputs) -> None:
    """Refuse ``-o`` naming one of the command's input files (``inputs``: pairs of what it is and its path).

    Writing there would replace the input (a raw export, the model file) with
    the output; the same file under another name (a link) counts too.
    """
    if output is None or not Path(output).exists():
        return
    for what, path in inputs:
        if path is not None and Path(path).exists() and os.path.samefile(output, path):
            raise PartcalError(f"{command}: -o {output} is the {what} ({path}); writing there would replace an "
                               "input, so name another file")


def _format(args):
    """The ``--format FILE.yaml`` of a command, or None for the contract."""
    if not getattr(args, "format", None):
        return None
    from .data.formats import load_format

    return load_format(args.format)


def _cmd_import(args) -> int:
    if (args.input is None) == (args.config is None):
        raise PartcalError("import: give either an input file or --config RUN.yaml (not both)")
    if args.config is not None:
        return _import_run(args)
    import numpy as np

    from .data.formats import RowSelection
    from .data.measurements import read_measurements, write_measurements
    from .data.registration import register_measurements, registered
    from .robot.description import load_robot

    if args.output is None:
        raise PartcalError("import: give the CSV to write with -o OUT.csv")
    _refuse_input_as_output(args.output, "import", [("input file", args.input), ("format file", args.format),
                                                    ("robot file", args.robot)])
    if args.frame == "tracker" and not args.robot:
        raise PartcalError("import: --frame tracker needs --robot (a built-in name, a robot YAML or a URDF)")
    if args.tool_mm is not None and args.frame != "tracker":
        raise PartcalError("import: --tool-mm is the target offset of a tracker registration; it needs --frame "
                           "tracker (in the base frame the measured positions already include the tool)")
    rows = RowSelection.parse(args.rows, args.every) if (args.rows or args.every != 1) else None
    robot = load_robot(args.robot) if args.robot else None
    m = read_measurements(args.input, robot, fmt=_format(args), rows=rows, frame=args.frame)
    lines = [f"imported from {args.input} by partcal {__version__}: degrees, mm"]
    if args.frame == "tracker":
        reg = register_measurements(robot, m, tool_mm=args.tool_mm, fit_tool=args.tool_mm is None,
                                    source=str(args.input))
        m = registered(m, robot, reg)
        from .study.outputs import registration_comment
        from .study.tables import registration_line

        lines.append(registration_comment(reg, shared=False))
        print(registration_line(reg))
    write_measurements(m, args.output, comment="\n".join(lines))
    rms = float(np.sqrt(np.mean(np.sum(m.errors_mm**2, axis=1))))
    print(f"wrote {len(m)} poses to {args.output} (errors: 3-D RMS {rms:.3f} mm)")
    return 0


def _import_run(args) -> int:
    from .study.config import load_config
    from .study.outputs import check_writable, replace_folder, write_datasets, write_robot_yaml
    from .study.prepare import load_datasets
    from .study.tables import registration_line

    if args.output is None:
        raise PartcalError("import --config: give the output folder with -o FOLDER")
    _refuse_input_as_output(args.output, "import", [("run config", args.config)])
    config = load_config(args.config)
    _refuse_input_as_output(args.output, "import", [("run's input", p) for p in config.inputs()])
    output = Path(args.output)
    check_writable(output, config.inputs(), option="-o")
    datasets, robot, registrations = load_datasets(config)
    for reg in {id(r): r for r in registrations.values()}.values():
        print(registration_line(reg, [n for n, r in registrations.items() if r is reg]))

    def fill(tmp: Path) -> list[Path]:
        written = write_datasets(config, datasets, registrations, tmp)
        if robot is None:
            return written
        tool = "the tool offset registered on the identification set" if registrations else "its tool offset"
        return written + [write_robot_yaml(robot, tmp / "robot.yaml", (
            f"robot of run {config.name!r} (partcal {__version__}, from {config.robot}) with {tool}: the robot of "
            "the data sets beside it (base frame)"))]

    paths = [output / p.name for p in replace_folder(output, fill)]
    data = [p for p in paths if p.name != "robot.yaml"]
    print(f"wrote {len(data)} data sets ({', '.join(f'{n}: {len(m)}' for n, m in datasets.items())}) to {args.output}")
    if robot is not None:
        print(f"robot (tool offset included): {output / 'robot.yaml'}")
    return 0


def _write_table(path, header, values, atomic_write, flags=None, texts=None, significant: int = 0) -> None:
    """Numbers with 6 decimals (the last ``significant`` columns with 6 significant digits: misses of
    micrometres); ``flags`` (one bool per row) as a column of true/false after them, then ``texts`` (one
    string per row, no commas) as a last column."""
    with atomic_write(path) as handle:
        handle.write(",".join(header) + "\n")
        for k, row in enumerate(values):
            split = len(row) - significant
            cells = [f"{v:.6f}" for v in row[:split]] + [f"{v:.6g}" for v in row[split:]]
            cells += [("true" if flags[k] else "false")] if flags is not None else []
            cells += [texts[k]] if texts is not None else []
            handle.write(",".join(cells) + "\n")


def _cmd_equations(args) -> int:
    from .errors import ModelFileError
    from .models.kinds import equations_of
    from .study.predictor import load_predictor

    predictor = load_predictor(args.model)
    lines = equations_of(predictor.model, precision=args.digits)
    if lines is None:
        raise ModelFileError(f"{args.model}: a {predictor.document['kind']} model has no single equation per "
                             "axis; equations are printed for global series models")
    print("\n".join(lines))
    return 0


def _cmd_plan(args) -> int:
    from .data.measurements import read_columns
    from .robot.description import joint_columns, load_robot
    from .models import design
    from .study import plan

    planning = args.n is not None
    if args.iso9283:
        return _plan_iso9283(args)
    if args.cube is not None or args.cycles is not None:
        raise PartcalError("plan: --cube and --cycles go with --iso9283")
    if not (planning or args.evaluate or args.curve):
        raise PartcalError("plan: give -n N -o POSES.csv (plan poses), --evaluate DATA.csv (judge a pose set) or "
                           "--curve (predicted uncertainty against the number of poses)")
    if planning != (args.output is not None):
        raise PartcalError("plan: -n N and -o POSES.csv go together (how many poses, and the CSV to write)")
    if planning and args.evaluate:
        raise PartcalError("plan: give either -n N -o POSES.csv or --evaluate DATA.csv, not both")
    if args.candidates and args.box:
        raise PartcalError("plan: give either --candidates FILE.csv or --box, not both")
    if not (args.noise_mm > 0 and np.isfinite(args.noise_mm)):
        raise PartcalError(f"plan: --noise-mm must be a positive number of mm; got {args.noise_mm!r}")
    _refuse_input_as_output(args.output, "plan", [("candidate file", args.candidates), ("format file", args.format),
                                                 ("evaluated file", args.evaluate), ("robot file", args.robot)])
    robot = load_robot(args.robot)
    floor = _plan_floor(args, robot)
    say = (lambda text: None) if args.quiet else (lambda text: print(f"partcal: plan: {text}", file=sys.stderr))
    start = time.perf_counter()
    model = design.PlannedModel(base=not args.no_base, tool=not args.no_tool, compliance=args.compliance or (),
                                joint_harmonics=_one_or_many(args.joint_harmonics or (0,)),
                                payload_kg=args.payload_kg, parametrization=args.parametrization).check(robot)
    options = {"model": model}
    evaluated = plan.check_candidates(robot, read_columns(args.evaluate, [joint_columns(robot.n_joints)],
                                                          fmt=_format(args))[1], str(args.evaluate)) \
        if args.evaluate else None
    if args.candidates:
        stated = args.floor_mm is not None or args.clearance_mm is not None    # a cell's own poses: the cell's
        q = plan.check_candidates(robot, read_columns(args.candidates, [joint_columns(robot.n_joints)],
                                                      fmt=_format(args))[1], str(args.candidates),
                                  floor if stated else None)
        space, where = plan.workspace(robot, q, **options), f"the {len(q)} poses of {args.candidates}"
    else:
        box = None if args.box is None else np.array(args.box, dtype=float).reshape(2, 3)
        if box is not None and np.any(box[0] >= box[1]):
            raise PartcalError(f"plan: --box takes XMIN YMIN ZMIN XMAX YMAX ZMAX (mm) with each min below its max; "
                               f"got {args.box}")
        space = plan.workspace(robot, random_state=args.seed, n_poses=args.pool, box_mm=box, floor=floor, **options)
        where = (f"{args.pool} random poses within the joint limits" + (" and the box" if box is not None else "")
                 + (f", every link above the floor ({floor.describe()})" if floor is not None else ", no floor"))
    if planning or args.curve:                             # bad input gets its one line before any progress
        plan.check_count(robot, args.n if planning else plan.min_poses(space.structural.size), space)
    say(f"{robot.name}, {model.describe(robot)}: {space.structural.size} identifiable parameters over {where} "
        f"({time.perf_counter() - start:.1f} s)")
    if args.evaluate:
        q = evaluated
        print(f"{args.evaluate}: {len(q)} poses of {robot.name}")
        print("\n".join(plan.evaluate_poses(robot, q, space=space, noise_mm=args.noise_mm).lines()))
    if planning:
        def progress(k: int, logdet: float) -> None:
            if k % 10 == 0:
                say(f"DETMAX exchange {k}: log det {logdet:.4f}")
        result = plan.plan_poses(robot, args.n, space=space, noise_mm=args.noise_mm, random_state=args.seed,
                                 callback=progress)
        plan.write_plan(robot, result.q_deg, args.output, comment=(
            f"Pose list planned by partcal {__version__} for {robot.name} ({model.describe(robot)}): {args.n} of "
            f"{where}, D-optimal (DETMAX), seed {args.seed}.\nJoint angles in degrees, nominal tool positions in "
            f"mm. Measure these poses; the tracker's positions become x_meas,y_meas,z_meas (mm).\n"
            f"{result.evaluation.indices.text()}"))
        print("\n".join(result.evaluation.lines()))
        print(f"wrote {args.n} poses to {args.output} ({result.exchange.exchanges} exchanges, log det "
              f"{result.exchange.start_logdet:.3f} -> {result.exchange.logdet:.3f}, "
              f"{time.perf_counter() - start:.1f} s)")
    if args.curve:
        largest = args.curve_max or max(3 * space.structural.size, args.n or 0)
        counts = plan.curve_counts(space.structural.size, min(largest, len(space.q_deg)))
        rows = plan.pose_curve(robot, counts, space=space, noise_mm=args.noise_mm, random_state=args.seed,
                               callback=lambda k, total, row: say(f"curve [{k}/{total}] {row['n']} poses"))
        print("\n".join(plan.curve_lines(rows, args.noise_mm)))
    return 0


def _cmd_export(args) -> int:
    from .data.measurements import read_measurements
    from .study.export import FORMATS, export_model
    from .study.persist import load_model

    formats = tuple(args.formats.split(",")) if args.formats else FORMATS
    q = errors = None
    if args.data:
        robot = load_model(args.model)[0].robot_
        data = read_measurements(args.data, robot, fmt=_format(args))
        q, errors = data.q_deg, data.errors_mm
    result = export_model(args.model, Path(args.output), formats, q, errors)
    for fmt, path in result.files.items():
        print(f"{fmt}: {path}")
    for fmt, why in result.skipped.items():
        print(f"{fmt}: not written: {why}")
    if result.tcp_text:
        print(f"ur: the kinematics file has no tool; set the tool centre point in tool0 on the controller: "
              f"{result.tcp_text}")
    if result.not_carried:
        print(result.not_carried)
    return 0


def _cmd_iso9283(args) -> int:
    import json

    from ._io import atomic_write
    from .robot.description import load_robot
    from .study.iso_figures import describe, iso_figures, pose_lines, read_iso_data

    _refuse_input_as_output(args.output, "iso9283", [("data file", args.data), ("format file", args.format),
                                                    ("model file", args.model)])
    robot = load_robot(args.robot) if args.robot else None
    predictor = None
    if args.model:
        from .study.predictor import load_predictor

        predictor = load_predictor(args.model)
        robot = robot or predictor.robot        # the data are checked against the robot the model corrects
    data = read_iso_data(args.data, robot, fmt=_format(args), tol_deg=args.tol_deg)
    predicted, name = None, None
    if predictor is not None:
        q = data.measurements.q_deg
        predicted = (predictor.predict(joints=q) if predictor.inputs == "joint"
                     else predictor.predict(positions=data.measurements.nominal_mm))
        name = predictor.name or Path(args.model).stem
    figures = iso_figures(data, predicted, own_frame=args.own_frame, distance=args.distance, path=args.path,
                          repeatability=args.repeatability)
    print(describe(data) + (f"; after model {name!r}" if name else ""))
    print("\n".join(figures.lines()))
    if args.output:
        doc = {"partcal_version": __version__, "data": str(args.data), "model": args.model,
               "tolerance_deg": args.tol_deg, "cycles_from": "column" if data.by_column else "joints",
               **figures.to_dict(pose_lines(data))}
        with atomic_write(args.output) as handle:
            json.dump(doc, handle, indent=1)
            handle.write("\n")
        print(f"wrote {args.output}")
    return 0


def _plan_floor(args, robot):
    """The floor ``plan`` keeps every pose above (None: none), from --floor-mm, --clearance-mm, --no-floor."""
    from .robot.floor import robot_floor

    if args.floor_mm is not None and not np.isfinite(args.floor_mm):
        raise PartcalError(f"plan: --floor-mm must be a finite number of mm (the floor's height in the base frame); "
                           f"got {args.floor_mm!r}")
    if args.clearance_mm is not None and not (np.isfinite(args.clearance_mm) and args.clearance_mm >= 0):
        raise PartcalError(f"plan: --clearance-mm must be a number of mm >= 0; got {args.clearance_mm!r}")
    if args.no_floor and (args.floor_mm is not None or args.clearance_mm is not None):
        raise PartcalError("plan: --no-floor goes without --floor-mm and --clearance-mm")
    if args.clearance_mm is not None and args.floor_mm is None and robot.floor_mm is None:
        raise PartcalError(f"plan: --clearance-mm needs a floor, and {robot.name} is described without one "
                           "(floor_mm: null): give --floor-mm too")
    return robot_floor(robot, args.floor_mm, args.clearance_mm, off=args.no_floor)


def _plan_iso9283(args) -> int:
    from .robot.description import load_robot
    from .study import plan

    if args.output is None or args.n is not None or args.evaluate or args.curve:
        raise PartcalError("plan --iso9283: give -o POSES.csv (and optionally --cube CX CY CZ EDGE, --cycles N), "
                           "without -n, --evaluate or --curve")
    _refuse_input_as_output(args.output, "plan", [("robot file", args.robot)])
    robot = load_robot(args.robot)
    floor = _plan_floor(args, robot)
    cycles = 30 if args.cycles is None else args.cycles
    cube = plan.iso_cube_plan(robot, args.output, cube=args.cube, cycles=cycles, random_state=args.seed, floor=floor,
                              comment=f"ISO 9283 test poses planned by partcal {__version__} for {robot.name}. "
                                      "Joint angles in degrees, nominal tool positions in mm.")
    for k, (p, q) in enumerate(zip(cube.points_mm, cube.q_deg)):
        print(f"P{k + 1}: {np.round(p, 3).tolist()} mm, joints {np.round(q, 3).tolist()} deg")
    print(f"wrote {len(cube.q_deg) * cycles} poses ({cycles} cycles of P1..P5; cube centre "
          f"{np.round(cube.centre_mm, 3).tolist()} mm, edge {cube.edge_mm:g} mm) to {args.output}")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with the project's rule for bad input: one line on stderr, exit 2 (no usage block); a negative
    number in any notation (``-650``, ``-0.5``, ``-1e3``) is a value, not an option (argparse's own rule
    knows no exponent, so ``--floor-mm -1e3`` read ``-1e3`` as an option)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str):
        self.exit(2, f"partcal: error: {self.prog}: {message} (see '{self.prog} --help')\n")


_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


def _int_list(text: str) -> tuple[int, ...]:
    """``2,3`` -> ``(2, 3)``: whole numbers separated by commas."""
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected whole numbers separated by commas (2,3); got {text!r}") \
            from None


def _one_or_many(values: tuple[int, ...]):
    """One number for every joint, or the list as given."""
    return values[0] if len(values) == 1 else values


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number; got {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1; got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="partcal", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"partcal {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="show debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sim = sub.add_parser("simulate", help="generate measurement data from a virtual robot config")
    sim.add_argument("config", help="virtual-experiment YAML, e.g. configs/sk120_virtual.yaml")
    sim.set_defaults(func=_cmd_simulate)
    run = sub.add_parser("run", help="fit and compare the models of a batch-run YAML; write metrics, models, report")
    run.add_argument("config", help="batch-run YAML, e.g. configs/paper_sk120.yaml")
    run.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    run.add_argument("--check", action="store_true",
                     help="only check the config and its data (every problem a fit would meet); fit nothing")
    run.add_argument("--screenshot", action="store_true",
                     help="also save a full-page screenshot of the report (needs chromium)")
    run.set_defaults(func=_cmd_run)
    pred = sub.add_parser("predict", help="predict errors with a model file")
    pred.add_argument("model", help="model file (models/<name>.json of a run)")
    pred.add_argument("input", help="CSV with x,y,z (mm) for Cartesian models or q1..qN (deg) for joint models")
    pred.add_argument("-o", "--output", required=True,
                      help="CSV to write (inputs + dx,dy,dz in mm; pose models also drx,dry,drz in mrad)")
    pred.add_argument("--format", metavar="FILE.yaml", help="the input's format (delimiter, decimal, columns, "
                                                            "units), see docs/data.md")
    pred.add_argument("--std", action="store_true", help="also the standard deviation of each predicted error: "
                                                         "sdx,sdy,sdz (mm; pose models also sdrx,sdry,sdrz, mrad)")
    pred.set_defaults(func=_cmd_predict)
    comp = sub.add_parser("compensate", help="false targets that make the robot reach the given targets")
    comp.add_argument("model", help="model file (models/<name>.json of a run)")
    comp.add_argument("targets", help="CSV with x,y,z (or x_nom,y_nom,z_nom) in mm; joint models also read q1..qN "
                                      "as IK seeds; pose models also rx,ry,rz (or rx_nom,ry_nom,rz_nom), intrinsic "
                                      "XYZ degrees; or a robot program (URScript, KRL, RAPID, joint trajectory "
                                      "CSV), see --program")
    comp.add_argument("-o", "--output", required=True,
                      help="CSV to write (targets + x_cmd,y_cmd,z_cmd[,rx_cmd,ry_cmd,rz_cmd][,qK_cmd][,std columns],miss_mm"
                           "[,miss_deg],converged,reason); "
                           "exit code 3 when any target did not converge")
    comp.add_argument("--format", metavar="FILE.yaml", help="the targets' format (delimiter, decimal, columns, "
                                                            "units), see docs/data.md")
    comp.add_argument("--std", action="store_true",
                      help="also the position expected to be left at each target (dx_left,dy_left,dz_left: target "
                           "minus where the model says the command lands) and its standard deviation sdx,sdy,sdz (mm)")
    comp.add_argument("--tol-mm", type=_positive_float, default=1e-4,
                      help="a target is converged when its predicted miss is within this (default 1e-4 mm)")
    comp.add_argument("--tol-deg", type=_positive_float, default=1e-5,
                      help="pose models: and its predicted orientation miss within this (default 1e-5 deg)")
    comp.add_argument("--program", choices=("urscript", "krl", "rapid", "joints"),
                      help="TARGETS is a robot program in this language (default: from its name: .script, "
                           ".src/.dat, .mod/.prg; a .csv with q1..qN and no x,y,z is a joint trajectory)")
    comp.add_argument("--frame", action="append", metavar="[NAME=]FRAME",
                      help="a program's frame in its own syntax (UR feature p[...], KUKA base {X ..}, ABB work "
                           "object [[x,y,z],[q1,..]]); without NAME, the frame of targets that name none")
    comp.add_argument("--tool", action="append", metavar="[NAME=]TOOL",
                      help="a program's tool (TCP) in its own syntax, as --frame")
    comp.add_argument("--keep-unconverged", action="store_true",
                      help="write the program even when targets are not compensated: they keep their numbers, "
                           "with a comment (exit code 3 all the same)")
    comp.set_defaults(func=_cmd_compensate)
    eqs = sub.add_parser("equations", help="print a series model's fitted equations in mm and degrees")
    eqs.add_argument("model", help="model file (models/<name>.json of a run)")
    eqs.add_argument("--digits", type=_positive_int, default=None,
                     help="round to this many significant digits (default: full precision, which reproduces "
                          "the model's predictions)")
    eqs.set_defaults(func=_cmd_equations)
    imp = sub.add_parser("import", help="convert a foreign measurement file (or a run's data) into contract CSVs")
    imp.add_argument("input", nargs="?", help="the file to convert (or use --config)")
    imp.add_argument("-o", "--output", help="CSV to write; with --config, the folder for <data set>.csv")
    imp.add_argument("--format", metavar="FILE.yaml", help="the input's format, see docs/data.md")
    imp.add_argument("--robot", help="robot (built-in name, robot YAML, or a URDF as FILE.urdf#base=LINK&tip=LINK) "
                                     "for nominal positions by forward kinematics")
    imp.add_argument("--frame", choices=("base", "tracker"), default="base",
                     help="tracker: register the file's tracker frame (and tool offset) on its own poses")
    imp.add_argument("--tool-mm", nargs=3, type=float, metavar=("X", "Y", "Z"),
                     help="with --frame tracker: the known target offset in the flange frame (not fitted then)")
    imp.add_argument("--rows", help="data rows to keep, e.g. '1-600' or '1-100, 201-300'")
    imp.add_argument("--every", type=_positive_int, default=1, help="keep every k-th of the rows")
    imp.add_argument("--config", metavar="RUN.yaml",
                     help="convert the data of a run config (format, subsets, registration) without fitting")
    imp.set_defaults(func=_cmd_import)
    exp = sub.add_parser("export", help="write the calibrated robot of a kinematic model: URDF, UR kinematics YAML, "
                                        "DH table, robot YAML")
    exp.add_argument("model", help="model file of kind kinematic (models/<name>.json of a run)")
    exp.add_argument("-o", "--output", required=True, help="folder to write into")
    exp.add_argument("--formats", metavar="F,F", help="some of urdf,ur,dh,yaml (default: all the chain allows)")
    exp.add_argument("--data", metavar="DATA.csv", help="a measurement CSV (base frame): the RMS the exported "
                                                        "geometry and the full model leave on it")
    exp.add_argument("--format", metavar="FILE.yaml", help="the data's format, see docs/data.md")
    exp.set_defaults(func=_cmd_export)
    iso = sub.add_parser("iso9283", help="ISO 9283 figures of measured cycles: pose accuracy and repeatability (AP, "
                                         "RP), distance (AD, RD), path (AT, RT)")
    iso.add_argument("data", help="measurement CSV (commanded joints, nominal and measured positions; optional "
                                  "'cycle' column)")
    iso.add_argument("--format", metavar="FILE.yaml", help="the file's format, see docs/data.md")
    iso.add_argument("--robot", help="robot (built-in name or YAML) for nominal positions and orientations by "
                                     "forward kinematics")
    iso.add_argument("--model", metavar="MODEL.json", help="the figures after this model's correction (measured "
                                                           "minus predicted error)")
    iso.add_argument("--own-frame", action="store_true",
                     help="the data were registered in their own tracker frame: score up to a rigid transform")
    iso.add_argument("--tol-deg", type=float, default=0.01,
                     help="commanded joints this close are one pose (default 0.01 deg)")
    iso.add_argument("--distance", nargs=2, type=_positive_int, metavar=("A", "B"),
                     help="distance accuracy and repeatability between poses A and B (1-based, e.g. 2 4)")
    iso.add_argument("--path", action="store_true", help="the poses, in order, are the points of a path: AT, RT")
    iso.add_argument("--repeatability", action="store_true",
                     help="refuse a pose measured in a single cycle (its RP is otherwise left out)")
    iso.add_argument("-o", "--output", metavar="REPORT.json", help="write the figures of every pose as JSON")
    iso.set_defaults(func=_cmd_iso9283)
    pln = sub.add_parser("plan", help="choose the poses to measure (D-optimal), or judge a pose set's observability")
    pln.add_argument("robot", help="built-in robot name, robot YAML, or a URDF as FILE.urdf#base=LINK&tip=LINK")
    pln.add_argument("-n", type=_positive_int, help="number of poses to plan")
    pln.add_argument("-o", "--output", help="pose list to write (q1..qN deg, x_nom,y_nom,z_nom mm)")
    pln.add_argument("--evaluate", metavar="DATA.csv", help="print the observability indices, unidentifiable "
                                                            "parameters and predicted uncertainty of a pose set")
    pln.add_argument("--curve", action="store_true", help="print the predicted uncertainty against the number of poses")
    pln.add_argument("--curve-max", type=_positive_int, help="largest pose count of --curve (default 3 x parameters)")
    pln.add_argument("--candidates", metavar="FILE.csv", help="the reachable, safe poses to choose from (q1..qN)")
    pln.add_argument("--box", nargs=6, type=float, metavar=("XMIN", "YMIN", "ZMIN", "XMAX", "YMAX", "ZMAX"),
                     help="candidates with the nominal tool position inside this box (mm, base frame)")
    pln.add_argument("--format", metavar="FILE.yaml",
                     help="format of --candidates / --evaluate files, see docs/data.md")
    pln.add_argument("--pool", type=_positive_int, default=2000,
                     help="candidates drawn within the limits (default 2000)")
    pln.add_argument("--noise-mm", type=float, default=0.03,
                     help="tracker noise per coordinate for the predictions (default 0.03 mm)")
    pln.add_argument("--seed", type=int, default=0, help="seed of the candidates and the exchange (default 0)")
    pln.add_argument("--no-base", action="store_true", help="the base pose is known (not identified)")
    pln.add_argument("--no-tool", action="store_true", help="the tool offset is known (not identified)")
    pln.add_argument("--compliance", type=_int_list, metavar="J,J",
                     help="plan for the gravity compliance of these joints too (as kind: kinematic's compliance)")
    pln.add_argument("--joint-harmonics", type=_int_list, metavar="K[,K...]",
                     help="plan for K transmission harmonics of every joint, or one K per joint")
    pln.add_argument("--payload-kg", type=float, default=0.0,
                     help="the payload the measurement carries at the tool (kg, default 0; with --compliance)")
    pln.add_argument("--parametrization", choices=("auto", "dh", "complete"), default="auto",
                     help="the geometric parameters planned for (auto: dh for DH rows, complete for a URDF's chain)")
    pln.add_argument("--iso9283", action="store_true",
                     help="write the ISO 9283 test poses P1..P5 of a cube, in cycles (with -o POSES.csv)")
    pln.add_argument("--cube", nargs=4, type=float, metavar=("CX", "CY", "CZ", "EDGE"),
                     help="with --iso9283: the cube's centre and edge (mm, base frame; default the largest cube "
                          "found in the workspace)")
    pln.add_argument("--cycles", type=_positive_int, help="with --iso9283: cycles of P1..P5 (default 30)")
    pln.add_argument("--floor-mm", type=float, metavar="Z",
                     help="height of the floor in the base frame (mm); every planned pose keeps its links, flange "
                          "and tool above it (default: the robot's floor_mm, none when its description states "
                          "none); --candidates are checked against a floor only when this or --clearance-mm is given")
    pln.add_argument("--clearance-mm", type=float, metavar="C",
                     help="how far above the floor the joint origins, flange and tool stay (default 100 mm)")
    pln.add_argument("--no-floor", action="store_true",
                     help="no floor (a ceiling- or wall-mounted robot): poses anywhere within the limits")
    pln.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    pln.set_defaults(func=_cmd_plan)
    return parser


class _Once(logging.Filter):
    """Lets each message through once: a warning repeated by every fold or data set is said one time."""

    def __init__(self):
        super().__init__()
        self.seen: set[str] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        text = record.getMessage()
        if text in self.seen:
            return False
        self.seen.add(text)
        return True


class _Format(logging.Formatter):
    """``partcal: warning: ...``: the one format of every message partcal prints on stderr."""

    def format(self, record: logging.LogRecord) -> str:
        where = f" {record.name}" if record.levelno < logging.WARNING else ""
        return f"partcal: {record.levelname.lower()}{where}: {record.getMessage()}"


_HANDLER = logging.StreamHandler()
_HANDLER.setFormatter(_Format())
_HANDLER.addFilter(_Once())


def _log_to_stderr(level: int) -> None:
    """partcal's log records at ``level`` and above on stderr, each message once."""
    _HANDLER.stream = sys.stderr
    _HANDLER.filters[0].seen.clear()
    root = logging.getLogger()
    if _HANDLER not in root.handlers:
        root.addHandler(_HANDLER)
    root.setLevel(level)
    for name in ("matplotlib", "PIL", "asyncio", "urllib3"):        # other libraries' debug chatter
        logging.getLogger(name).setLevel(max(level, logging.INFO))


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Python warnings (a library's, or partcal's own) in the same one-line format, each once."""
    log.warning("%s", message)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    _log_to_stderr(logging.DEBUG if args.verbose else logging.WARNING)
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():      # numbers are checked, never warned about
            warnings.simplefilter("ignore", RuntimeWarning)
            warnings.showwarning = _show_warning
            return args.func(args)
    except PartcalError as exc:
        print(f"partcal: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print("partcal: error: out of memory: the machine could not hold what this command needs (a Gaussian "
              "process on many samples? see 'partcal run --check'); nothing was replaced", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("partcal: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:          # the machine, not partcal: a full disk, a folder gone; earlier outputs stay
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"partcal: error: {where}{exc.strerror or exc}; nothing was replaced", file=sys.stderr)
        return 1
    except Exception as exc:  # an internal failure: keep the traceback for a bug report
        log.exception("internal error")
        print(f"partcal: internal error: {type(exc).__name__}: {exc} (please report it)", file=sys.stderr)
        return 1
