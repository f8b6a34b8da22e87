"""The ``partcal`` command line: argument parsing, progress output and exit codes.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback),
1 internal failure.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

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
    from .metrics import rms_per_axis
    from .simulate import load_study, simulate, write_study

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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="partcal", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"partcal {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="show debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sim = sub.add_parser("simulate", help="generate measurement data from a virtual robot config")
    sim.add_argument("config", help="virtual-experiment YAML, e.g. configs/sk120_virtual.yaml")
    sim.set_defaults(func=_cmd_simulate)
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
