"""``partcal run`` as calls: a config checked (``--check``), or run and written, with the lines the command
prints.

The report is a layer above the study: :func:`run_and_write` takes the function that renders it
(``partcal.report.render_report``) from its caller::

    from partcal.report import render_report
    from partcal.study.config import load_config
    from partcal.study.run_command import run_and_write

    print("\n".join(run_and_write(load_config("configs/paper_sk120.yaml"), report=lambda: render_report)))
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

from .. import __version__
from .config import RunConfig
from .measurement_run import check_measurement_run, measurement_run_table, run_measurements, uses_measurement_types, write_measurement_run
from .outputs import check_writable, write_run
from .prepare import prepare
from .results import RunResult
from .runner import run
from .tables import results_table

Render = Callable[[RunResult, Path], None]


class Progress:
    """A run's progress as lines on stderr, one per finished model (on a terminal too: a warning never lands
    inside a half-drawn bar), ``banner`` with the first (so bad input still gets exactly one line); none when
    ``quiet``. Pass it to :func:`run_and_write` as ``progress``."""

    def __init__(self, quiet: bool = False, banner: str = ""):
        self.quiet, self.banner = quiet, banner

    @classmethod
    def of_run(cls, config: RunConfig, quiet: bool = False) -> "Progress":
        """The progress of a run of ``config``, its banner naming the run, its models, data sets and seed."""
        return cls(quiet, f"partcal {__version__}: run {config.name!r}, {len(config.models)} models, "
                          f"{1 + len(config.tests)} data sets, seed {config.seed}")

    def __bool__(self) -> bool:
        """False when quiet: stages that print their own progress (a slow model's folds) ask this."""
        return not self.quiet

    def __call__(self, done: int, total: int, text: str) -> None:
        if self.quiet:
            return
        if self.banner:
            sys.stderr.write(self.banner + "\n")
            self.banner = ""
        sys.stderr.write(f"partcal: [{done}/{total}] {text}\n" if done else f"partcal: {text}\n")
        sys.stderr.flush()


def check_run(config: RunConfig, source: str | Path) -> str:
    """``partcal run --check``: every problem a fit would meet refused, else one line on what would run
    (``source``: how to name the config); nothing fitted."""
    if uses_measurement_types(config):
        return check_measurement_run(config, source)
    prepared = prepare(config)
    data, plan = prepared.datasets, prepared.plan
    check_writable(config.output, config.inputs(), create=False)
    sizes = ", ".join(f"{name} {len(m)}" for name, m in data.items())
    return (f"{source}: OK: {len(plan.models)} models; data sets (rows): {sizes}; cross-validation: "
            f"{plan.cv.describe()}; nothing fitted")


def run_and_write(config: RunConfig, progress: Callable[[int, int, str], None] | None = None,
                  report: Callable[[], Render | None] = lambda: None) -> list[str]:
    """Run ``config`` (:func:`~partcal.study.runner.run`, ``progress`` hearing of each model), write its
    outputs with the report that ``report()`` returns (asked after the fits; None: no report), and return
    the lines the command prints: the results table, the identification set's observability, the folder."""
    check_writable(config.output, config.inputs())
    if uses_measurement_types(config):
        kinds = run_measurements(config, progress)
        return [measurement_run_table(kinds), f"outputs: {write_measurement_run(kinds, report())}"]
    result = run(config, progress)
    out = write_run(result, report())
    lines = [results_table(result)]
    ev = result.design
    if ev is not None:
        lines.append(f"identification set: {ev.indices.text()}; not identifiable from it: "
                     f"{', '.join(ev.missing) or 'none'}")
    return lines + [f"outputs: {out}"]
