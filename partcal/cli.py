"""The ``partcal`` command line: argument parsing, progress output and exit codes.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback),
1 internal failure.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np

from . import __version__
from .errors import PartcalError

log = logging.getLogger("partcal")

# Table 2 of the paper: uncompensated RMS (mm) per data set, x / y / z.
PAPER_UNCOMPENSATED = {
    "identification": (8.0, 7.5, 17.9),
    "test_rectangle": (16.2, 19.1, 16.6),
    "test_spiral_xy": (54.3, 5.4, 60.9),
    "test_spiral_yz": (11.8, 19.4, 2.0),
}


def _cmd_simulate(args) -> int:
    from .data.simulate import load_study, simulate, write_study
    from .metrics import rms_per_axis

    start = time.perf_counter()
    study = load_study(args.config)
    data = simulate(study)
    paths = write_study(study, data)
    print(f"Virtual {study.robot.nominal.name}, seed {study.seed}: uncompensated RMS error (mm)")
    print(f"{'data set':<18}{'n':>6}{'x':>8}{'y':>8}{'z':>8}   paper Table 2 (x / y / z)")
    for name, m in data.items():
        x, y, z = rms_per_axis(m.errors_mm)
        paper = PAPER_UNCOMPENSATED.get(name)
        ref = " / ".join(f"{v:.1f}" for v in paper) if paper else "-"
        print(f"{name:<18}{len(m):>6}{x:>8.2f}{y:>8.2f}{z:>8.2f}   {ref}")
    print(f"wrote {len(paths)} files to {study.output} in {time.perf_counter() - start:.1f} s")
    return 0


class Progress:
    """Progress on stderr: a bar that rewrites itself on a terminal, plain lines otherwise."""

    def __init__(self, quiet: bool = False, banner: str = ""):
        self.quiet, self.tty, self.banner = quiet, sys.stderr.isatty(), banner

    def __call__(self, done: int, total: int, text: str) -> None:
        if self.quiet:
            return
        if self.banner:      # shown with the first result, so bad input still gets exactly one line
            sys.stderr.write(self.banner + "\n")
            self.banner = ""
        if self.tty:
            bar = "#" * round(20 * done / total)
            sys.stderr.write(f"\r[{bar:<20}] {done}/{total} {text[:60]:<60}")
            if done == total:
                sys.stderr.write("\n")
        else:
            sys.stderr.write(f"partcal: [{done}/{total}] {text}\n")
        sys.stderr.flush()


def _cmd_run(args) -> int:
    from .study.config import load_config
    from .study.outputs import check_writable, write_run
    from .study.registry import run

    config = load_config(args.config)
    check_writable(config.output)
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
    print(f"outputs: {out}")
    return 0


def results_table(result) -> str:
    """The paper's Table 2 layout: RMS x / y / z (mm) per model and data set."""
    names = list(result.datasets)
    width = 24
    head1 = f"{'RMS error (mm)':<{width}}" + "".join(f"{n[:22]:^24}" for n in names)
    head2 = f"{'model':<{width}}" + "".join(f"{'x':>8}{'y':>8}{'z':>8}" for _ in names)
    lines = [head1, head2, "-" * len(head2)]

    def row(label, stats):
        return f"{label[:width - 1]:<{width}}" + "".join("".join(f"{v:8.2f}" for v in stats[n]["rms"]) for n in names)

    lines.append(row("uncompensated", result.uncompensated))
    for r in result.models:
        lines.append(row(r.spec.name, r.metrics))
    best = next(r for r in result.models if r.spec.name == result.best)
    lines.append(f"best by {result.config.cv_folds}-fold CV on the identification set: {best.spec.name} "
                 f"(CV 3-D RMS {best.cv_rms_3d:.3f} mm)")
    comp = [r for r in result.models if r.compensation]
    if comp:
        lines.append("")
        lines.append("compensation on the virtual robot, 3-D RMS (mm): before / predicted residual / after")
        for r in comp:
            cells = "  ".join(f"{n}: {c['before']['rms_3d']:.2f} / {c['predicted_residual']['rms_3d']:.2f} / "
                              f"{c['after']['rms_3d']:.2f}" for n, c in r.compensation.items())
            lines.append(f"  {r.spec.name:<22}{cells}")
    return "\n".join(lines)


def _cmd_predict(args) -> int:
    from ._io import atomic_write
    from .data.measurements import read_columns
    from .robot.kinematics import joint_columns
    from .study.predictor import load_predictor

    predictor = load_predictor(args.model)
    if predictor.inputs == "cartesian":
        cols, X, _ = read_columns(args.input, [["x", "y", "z"], ["x_nom", "y_nom", "z_nom"]])
        errors = predictor.predict(positions=X)
    else:
        cols, X, _ = read_columns(args.input, [joint_columns(predictor.n_inputs)])
        errors = predictor.predict(joints=X)
    _write_table(args.output, cols + ["dx", "dy", "dz"], np.hstack([X, errors]), atomic_write)
    _warn_if_far(predictor, X)
    print(f"predicted errors for {len(X)} points: {args.output}")
    return 0


def _warn_if_far(predictor, X) -> None:
    """One stderr line if model inputs ``X`` lie far from the training data (predict and compensate)."""
    from .study.predictor import EXTRAPOLATION_LIMIT

    far = predictor.distance_to_data(**({"positions": X} if predictor.inputs == "cartesian" else {"joints": X}))
    if (far > EXTRAPOLATION_LIMIT).any():
        print(f"partcal: warning: {int((far > EXTRAPOLATION_LIMIT).sum())} of {len(far)} points lie more than "
              f"{EXTRAPOLATION_LIMIT:g} {'mm' if predictor.inputs == 'cartesian' else 'deg'} outside the data "
              "the model was fitted on", file=sys.stderr)


def _cmd_compensate(args) -> int:
    import warnings

    from ._io import atomic_write
    from .data.measurements import read_columns
    from .robot.compensation import CompensationWarning
    from .robot.kinematics import joint_columns
    from .study.predictor import load_predictor

    predictor = load_predictor(args.model)
    n_q = predictor.robot.n_joints if predictor.robot is not None else 0
    optional = joint_columns(n_q) if predictor.inputs == "joint" else []
    cols, targets, seeds = read_columns(args.targets, [["x", "y", "z"]], optional)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", CompensationWarning)
        result = predictor.compensate_full(targets, seeds)
    for w in caught:
        print(f"partcal: warning: {w.message}", file=sys.stderr)
    _warn_if_far(predictor, result.commanded_mm if predictor.inputs == "cartesian" else result.joints_deg)
    header, parts = list(cols), [targets]
    if seeds is not None:
        header += optional
        parts.append(seeds)
    header += ["x_cmd", "y_cmd", "z_cmd"]
    parts.append(result.commanded_mm)
    if result.joints_deg is not None:
        header += [f"{c}_cmd" for c in joint_columns(n_q)]
        parts.append(result.joints_deg)
    _write_table(args.output, header, np.hstack(parts), atomic_write)
    print(f"compensated {len(targets)} targets ({int(result.converged.sum())} converged): {args.output}")
    return 0


def _write_table(path, header, values, atomic_write) -> None:
    with atomic_write(path) as handle:
        handle.write(",".join(header) + "\n")
        for row in values:
            handle.write(",".join(f"{v:.6f}" for v in row) + "\n")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="partcal", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"partcal {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="show debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sim = sub.add_parser("simulate", help="generate measurement data from a virtual robot config")
    sim.add_argument("config", help="virtual-experiment YAML, e.g. configs/sk120_virtual.yaml")
    sim.set_defaults(func=_cmd_simulate)
    run = sub.add_parser("run", help="fit and compare the models of a batch-run YAML; write metrics, models, report")
    run.add_argument("config", help="batch-run YAML, e.g. configs/paper_sk120.yaml")
    run.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    run.add_argument("--screenshot", action="store_true",
                     help="also save a full-page screenshot of the report (needs chromium)")
    run.set_defaults(func=_cmd_run)
    pred = sub.add_parser("predict", help="predict errors with a model file")
    pred.add_argument("model", help="model file (models/<name>.json of a run)")
    pred.add_argument("input", help="CSV with x,y,z (mm) for Cartesian models or q1..qN (deg) for joint models")
    pred.add_argument("-o", "--output", required=True, help="CSV to write (inputs + dx,dy,dz)")
    pred.set_defaults(func=_cmd_predict)
    comp = sub.add_parser("compensate", help="false targets that make the robot reach the given targets")
    comp.add_argument("model", help="model file (models/<name>.json of a run)")
    comp.add_argument("targets", help="CSV with x,y,z (mm); joint models also read q1..qN as IK seeds")
    comp.add_argument("-o", "--output", required=True, help="CSV to write (targets + x_cmd,y_cmd,z_cmd[,qK_cmd])")
    comp.set_defaults(func=_cmd_compensate)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except PartcalError as exc:
        print(f"partcal: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("partcal: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # an internal failure: keep the traceback for a bug report
        log.exception("internal error")
        print(f"partcal: internal error: {type(exc).__name__}: {exc} (please report it)", file=sys.stderr)
        return 1
