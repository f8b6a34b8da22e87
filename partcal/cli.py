"""The ``partcal`` command line: argument parsing, progress output and exit codes.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback), 3 compensation left targets
unconverged or unreachable (the output marks them), 1 internal failure.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import math
import re
import sys
import warnings
from collections.abc import Sequence

from . import __version__
from ._io import exit_cleanly_on_sigterm
from .errors import PartcalError, log_to_stderr

log = logging.getLogger("partcal")


def _cmd_run(args) -> int:
    from .study.config import load_config
    from .study.run_command import Progress, check_run, run_and_write
    config = load_config(args.config)
    if args.check:
        print(check_run(config, args.config))
        return 0
    if args.screenshot:
        from .report.browser import check_screenshot_tools
        check_screenshot_tools()               # before the fits, not after them
    progress = Progress.of_run(config, args.quiet)

    def report():           # the renderer, asked after the fits; None without matplotlib and jinja2
        try:
            from .report import render_report
        except ImportError as exc:
            log.warning("no report: %s", exc)
            return None
        return lambda result, folder: render_report(result, folder, screenshot=args.screenshot)

    print("\n".join(run_and_write(config, progress, report)))
    return 0


def _printed(module: str, call):
    """A command that prints the lines of ``call(study module, args)`` (``partcal.study.<module>``, imported then)."""
    def command(args) -> int:
        done = call(importlib.import_module(f"partcal.study.{module}"), args)
        print("\n".join(done.lines() if hasattr(done, "lines") else done))
        return 0
    return command


def _said(done) -> int:
    """A downstream command's outcome: warnings and notes on stderr, then its failure (exit 3) or its lines."""
    for text in done.warnings:
        print(f"partcal: warning: {text}", file=sys.stderr)
    for text in done.notes:
        print(text, file=sys.stderr)
    if done.failure:
        print(f"partcal: {done.failure}", file=sys.stderr)
        return 3
    if done.lines:
        print("\n".join(done.lines))
    return 0


def _cmd_import(args) -> int:
    if (args.input is None) == (args.config is None):
        raise PartcalError("import: give either an input file or --config RUN.yaml (not both)")
    if args.output is None:
        raise PartcalError("import --config: give the output folder with -o FOLDER" if args.config else
                           "import: give the CSV to write with -o OUT.csv")
    from .study.data_files import import_file, import_run
    print("\n".join(import_run(args.config, args.output, show=print) if args.config else import_file(
        args.input, args.output, robot=args.robot, fmt=args.format, rows=args.rows, every=args.every,
        frame=args.frame, tool_mm=args.tool_mm, show=print).lines()))
    return 0


def _cmd_plan(args) -> int:
    from .study.plan_command import PlanOptions, run_plan
    say = (lambda text: None) if args.quiet else (lambda text: print(f"partcal: plan: {text}", file=sys.stderr))
    run_plan(args.robot, PlanOptions.from_args(args), say=say, show=print)
    return 0


def _cmd_iso9283(args) -> int:
    from .study.iso_figures import iso_report
    iso_report(args.data, robot=args.robot, model=args.model, fmt=args.format, tol_deg=args.tol_deg,
               own_frame=args.own_frame, distance=args.distance, path=args.path, repeatability=args.repeatability,
               output=args.output, show=print)
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with the project's rule for bad input: one line on stderr, exit 2 (no usage block); a negative
    number in any notation (``-650``, ``-0.5``, ``-1e3``) is a value, not an option (argparse's own rule
    knows no exponent, so ``--floor-mm -1e3`` read ``-1e3`` as an option)."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def parse_known_args(self, args=None, namespace=None):
        namespace, extra = super().parse_known_args(args, namespace)
        if extra and self.prog != "partcal":        # a command's own: refused naming the command, not partcal
            self.error(f"unrecognized arguments: {' '.join(extra)}")
        return namespace, extra

    def error(self, message: str):
        where = "" if self.prog == "partcal" else f"{self.prog}: "     # 'partcal: error: partcal:' said it twice
        self.exit(2, f"partcal: error: {where}{message} (see '{self.prog} --help')\n")


_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


class _Names(Sequence):
    """An option's choices, the names of ``module.table`` after ``first``, read when argparse first needs them (the
    command line starts without the table's module). Give the option a ``metavar``: argparse reads them for one."""

    def __init__(self, module: str, table: str, first: tuple[str, ...] = ()):
        self.module, self.table, self.first = module, table, first

    def __getitem__(self, k):
        return (*self.first, *getattr(importlib.import_module(self.module), self.table))[k]

    def __len__(self) -> int:
        return len(self.first) + len(getattr(importlib.import_module(self.module), self.table))


def _checked(convert, ok, expected: str):
    """An argparse ``type``: ``convert(text)``, refused naming what was ``expected`` unless it is ``ok``."""
    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            value = None
        if value is None or not ok(value):
            raise argparse.ArgumentTypeError(f"expected {expected}; got {text!r}")
        return value
    return parse


_positive_float = _checked(float, lambda v: math.isfinite(v) and v > 0, "a positive number")
_positive_int = _checked(int, lambda v: v >= 1, "a whole number >= 1")
_int_list = _checked(lambda text: tuple(int(v) for v in text.split(",")), lambda v: True,   # 2,3 -> (2, 3)
                     "whole numbers separated by commas (2,3)")


def _format_option(p, whose: str) -> None:
    p.add_argument("--format", metavar="FILE.yaml",
                   help=f"{whose} format (delimiter, decimal, columns, units), see docs/data.md")


def _add_run_commands(sub) -> None:
    sim = sub.add_parser("simulate", help="generate measurement data from a virtual robot config")
    sim.add_argument("config", help="virtual-experiment YAML, e.g. configs/sk120_virtual.yaml")
    sim.set_defaults(func=_printed("data_files", lambda m, a: m.simulate_files(a.config)))
    det = sub.add_parser("detect", help="detect the cell's board in a folder of images: the camera rows of a run")
    det.add_argument("images", help="folder of images (.png, .jpg, .bmp, .tif), one per row of --joints")
    det.add_argument("--joints", required=True, metavar="JOINTS.csv", help="image,q1..qN (deg): each image's pose")
    det.add_argument("--cell", required=True, metavar="CELL.yaml", help="the cell's cameras: and boards: (sizes)")
    det.add_argument("--robot", required=True, help="robot (built-in name, robot YAML or URDF): its joint count")
    det.add_argument("--camera", help="the cell's camera that took the images (default: its only one)")
    det.add_argument("--board", help="the cell's board in the images (default: its only one)")
    det.add_argument("-o", "--output", required=True, help="measurements CSV to write (camera rows)")
    det.set_defaults(func=_printed("detect_command", lambda m, a: m.detect_images(
        a.images, a.joints, a.cell, a.robot, a.output, camera=a.camera, board=a.board)))
    run = sub.add_parser("run", help="fit and compare the models of a batch-run YAML; write metrics, models, report")
    run.add_argument("config", help="batch-run YAML, e.g. configs/paper_sk120.yaml")
    run.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    run.add_argument("--check", action="store_true",
                     help="only check the config and its data (every problem a fit would meet); fit nothing")
    run.add_argument("--screenshot", action="store_true",
                     help="also save a full-page screenshot of the report (needs chromium)")
    run.set_defaults(func=_cmd_run)


def _add_downstream(sub) -> None:
    pred = sub.add_parser("predict", help="predict errors with a model file")
    pred.add_argument("model", help="model file (models/<name>.json of a run)")
    pred.add_argument("input", help="CSV with x,y,z (mm) for Cartesian models or q1..qN (deg) for joint models")
    pred.add_argument("-o", "--output", required=True,
                      help="CSV to write (inputs + dx,dy,dz in mm; pose models also drx,dry,drz in mrad)")
    _format_option(pred, "the input's")
    pred.add_argument("--std", action="store_true", help="also the standard deviation of each predicted error: "
                                                         "sdx,sdy,sdz (mm; pose models also sdrx,sdry,sdrz, mrad)")
    pred.set_defaults(func=lambda a: _said(importlib.import_module("partcal.study.downstream").predict_points(
        a.model, a.input, a.output, fmt=a.format, std=a.std)))
    comp = sub.add_parser("compensate", help="false targets that make the robot reach the given targets")
    comp.add_argument("model", help="model file (models/<name>.json of a run)")
    comp.add_argument("targets", help="CSV with x,y,z (or x_nom,y_nom,z_nom) in mm; joint models also read q1..qN "
                                      "as IK seeds; pose models also rx,ry,rz (or rx_nom,ry_nom,rz_nom), intrinsic "
                                      "XYZ degrees; or a robot program (URScript, KRL, RAPID, joint trajectory "
                                      "CSV), see --program")
    comp.add_argument("-o", "--output", required=True,
                      help="CSV to write (targets + x_cmd,y_cmd,z_cmd[,rx_cmd,ry_cmd,rz_cmd][,qK_cmd][,std "
                           "columns],miss_mm[,miss_deg],converged,reason); exit code 3 when any target did not "
                           "converge")
    _format_option(comp, "the targets'")
    comp.add_argument("--std", action="store_true",
                      help="also the position expected to be left at each target (dx_left,dy_left,dz_left: target "
                           "minus where the model says the command lands) and its standard deviation sdx,sdy,sdz (mm)")
    comp.add_argument("--tol-mm", type=_positive_float, default=1e-4,
                      help="a target is converged when its predicted miss is within this (default 1e-4 mm)")
    comp.add_argument("--tol-deg", type=_positive_float, default=1e-5,
                      help="pose models: and its predicted orientation miss within this (default 1e-5 deg)")
    comp.add_argument("--program", choices=_Names("partcal.data.programs", "DIALECTS"), metavar="LANGUAGE",
                      help="TARGETS is a robot program in this language, one of %(choices)s (default: from its "
                           "name: .script, .src/.dat, .mod/.prg; a .csv with q1..qN and no x,y,z is a joint "
                           "trajectory)")
    comp.add_argument("--frame", action="append", metavar="[NAME=]FRAME",
                      help="a program's frame in its own syntax (UR feature p[...], KUKA base {X ..}, ABB work "
                           "object [[x,y,z],[q1,..]]); without NAME, the frame of targets that name none")
    comp.add_argument("--tool", action="append", metavar="[NAME=]TOOL",
                      help="a program's tool (TCP) in its own syntax, as --frame")
    comp.add_argument("--keep-unconverged", action="store_true",
                      help="write the program even when targets are not compensated: they keep their numbers, "
                           "with a comment (exit code 3 all the same)")
    comp.set_defaults(func=lambda a: _said(importlib.import_module("partcal.study.downstream").compensate_file(
        a.model, a.targets, a.output, program=a.program, fmt=a.format, std=a.std, frames=a.frame, tools=a.tool,
        tol_mm=a.tol_mm, tol_deg=a.tol_deg, keep_unconverged=a.keep_unconverged)))


def _add_file_commands(sub) -> None:
    eqs = sub.add_parser("equations", help="print a series model's fitted equations in mm and degrees")
    eqs.add_argument("model", help="model file (models/<name>.json of a run)")
    eqs.add_argument("--digits", type=_positive_int, default=None,
                     help="round to this many significant digits (default: full precision, which reproduces "
                          "the model's predictions)")
    eqs.set_defaults(func=_printed("downstream", lambda m, a: m.model_equations(a.model, a.digits)))
    imp = sub.add_parser("import", help="convert a foreign measurement file (or a run's data) into contract CSVs")
    imp.add_argument("input", nargs="?", help="the file to convert (or use --config)")
    imp.add_argument("-o", "--output", help="CSV to write; with --config, the folder for <data set>.csv")
    _format_option(imp, "the input's")
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
    _format_option(exp, "the data's")
    exp.set_defaults(func=_printed("export", lambda m, a: m.export_files(
        a.model, a.output, tuple(a.formats.split(",")) if a.formats else None, data=a.data, fmt=a.format)))
    upd = sub.add_parser("update", help="re-identify a kinematic model from new measurements, the model and its "
                                        "covariance the prior (docs/models.md, \"Updating a calibration\")")
    upd.add_argument("model", help="model file of kind kinematic (models/<name>.json of a run)")
    upd.add_argument("data", help="measurement CSV of the new poses (base frame, or near it: the frame is refitted)")
    upd.add_argument("-o", "--output", required=True, help="model file to write (its provenance in fit.update)")
    _format_option(upd, "the data's")
    upd.add_argument("--inflate", type=_positive_float, help="the model's covariance times this (default 30: real "
                                                             "residuals are correlated, docs/models.md)")
    upd.set_defaults(func=_printed("update", lambda m, a: m.update_file(a.model, a.data, a.output, fmt=a.format,
                                                                         inflate=a.inflate)))
    chk = sub.add_parser("check", help="do new measurements agree with a model's calibrated spread? if not, what moved")
    chk.add_argument("model", help="model file (models/<name>.json of a run)")
    chk.add_argument("data", help="measurement CSV of the new poses (q1..qN deg; x_meas,y_meas,z_meas mm)")
    _format_option(chk, "the data's")
    chk.add_argument("--frame", choices=("base", "tracker"), default="base",
                     help="tracker: the data are in a tracker's frame, registered on them first")
    chk.add_argument("--rows", help="data rows to check, e.g. '1-50' or '1-20, 41-70'")
    chk.set_defaults(func=_printed("check", lambda m, a: m.check_file(a.model, a.data, fmt=a.format, frame=a.frame,
                                                                       rows=a.rows)))


def _add_plan(sub) -> None:
    iso = sub.add_parser("iso9283", help="ISO 9283 figures of measured cycles: pose accuracy and repeatability (AP, "
                                         "RP), distance (AD, RD), path (AT, RT)")
    iso.add_argument("data", help="measurement CSV (commanded joints, nominal and measured positions; optional "
                                  "'cycle' column)")
    _format_option(iso, "the file's")
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
    _format_option(pln, "the --candidates and --evaluate files'")
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
    pln.add_argument("--parametrization", default="auto", metavar="NAME",
                     choices=_Names("partcal.calibration.parameters", "PARAMETRIZATIONS", first=("auto",)),
                     help="the geometric parameters planned for, one of %(choices)s (auto: dh for DH rows, complete "
                          "for a URDF's chain)")
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
    pln.add_argument("--measurement", "--kind", metavar="TYPE", choices=_Names("partcal.calibration.registry",
                     "MEASUREMENT_TYPES"), help="plan rows of this measurement type on --cell instead of poses (plane: "
                     "touches of its planes, fixed: visits of its points), a measurements CSV (-n -o; --kind: old name)")
    pln.add_argument("--cell", "--features", metavar="CELL.yaml", help="the cell's planes and points, for "
                     "--measurement and an --evaluate of a measurements file (--features: its old name)")
    pln.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    pln.set_defaults(func=_cmd_plan)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="partcal", description="Predict and correct the positioning errors of robot manipulators.")
    parser.add_argument("--version", action="version", version=f"partcal {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="show debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for add in (_add_run_commands, _add_downstream, _add_file_commands, _add_plan):
        add(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    log_to_stderr(logging.DEBUG if args.verbose else logging.WARNING)
    exit_cleanly_on_sigterm()           # a terminated command removes what it half wrote (exit 143)
    try:
        from ._validation import numbers_checked
        with numbers_checked():             # numbers are checked, never warned about; other warnings: one line, once
            warnings.showwarning = lambda message, *where, **more: log.warning("%s", message)
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
