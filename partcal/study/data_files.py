"""Measurement CSVs written by the data commands: ``partcal import`` (a foreign file, or the data of a run
config) and ``partcal simulate`` (the data sets of a virtual robot).

:func:`import_file` converts one file (its format, a row subset, a tracker registration on its own
poses); :func:`import_run` converts every data set of a run config as the run would read it, and
writes the run's robot beside them; :func:`simulate_files` measures a virtual robot. Lines worth
showing before the files are written (a registration) go to ``show``::

    from partcal.study.importing import import_file

    done = import_file("export.csv", "identification.csv", fmt="tmac.yaml", robot="universal_robots_ur10",
                       frame="tracker", show=print)
    done.n, done.rms_3d_mm
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .. import __version__
from .._io import check_folder_writable, refuse_input_as_output
from ..data.formats import ROWS_EXPECTED, MeasurementFormat, RowSelection, load_format
from ..data.measurements import read_measurements, write_measurements
from ..data.registration import Registration, register_measurements, registered
from ..data.simulate import load_study, simulate, write_study
from ..errors import ConfigError, PartcalError
from ..metrics import pooled_rms
from .config import load_config, robot_named
from .outputs import (check_writable, registration_comment, replace_folder, write_datasets,
                      write_robot_yaml)
from .prepare import load_datasets
from .tables import registration_line, simulation_table


@dataclass(frozen=True)
class Imported:
    """A converted file: its ``n`` poses, the 3-D RMS of their errors (mm), the registration (tracker frame)."""

    output: str | Path
    n: int
    rms_3d_mm: float
    registration: Registration | None = None

    def lines(self) -> list[str]:
        """What ``partcal import`` prints once the file is written."""
        return [f"wrote {self.n} poses to {self.output} (errors: 3-D RMS {self.rms_3d_mm:.3f} mm)"]


def _quiet(text: str) -> None:
    """The default of ``show``: say nothing."""


def import_file(source: str | Path, output: str | Path, *, robot: str | Path | None = None,
                fmt: str | Path | MeasurementFormat | None = None, rows: str | None = None, every: int = 1,
                frame: str = "base", tool_mm=None, show: Callable[[str], None] = _quiet) -> Imported:
    """Convert the measurement file ``source`` into the contract CSV ``output``.

    Parameters
    ----------
    robot : str or Path, optional
        Built-in name, robot YAML or URDF: nominal positions by forward
        kinematics, and the robot of a tracker registration.
    fmt : MeasurementFormat or path of its YAML, optional
        The file's format (docs/data.md); default the contract.
    rows, every : the data rows to keep (``"1-600"``) and every k-th of them.
    frame : {"base", "tracker"}
        ``"tracker"``: register the file's tracker frame (and the tool offset,
        unless ``tool_mm`` (3,) mm in the flange frame is given) on its own poses.
    show : callable, optional
        Receives the registration's line before the file is written.
    """
    format_path = fmt if isinstance(fmt, (str, Path)) else None
    refuse_input_as_output(output, "import", [("input file", source), ("format file", format_path),
                                              ("robot file", robot)])
    if frame == "tracker" and not robot:
        raise PartcalError("import: --frame tracker needs --robot (a built-in name, a robot YAML or a URDF)")
    if tool_mm is not None and frame != "tracker":
        raise PartcalError("import: --tool-mm is the target offset of a tracker registration; it needs --frame "
                           "tracker (in the base frame the measured positions already include the tool)")
    try:
        selection = RowSelection.parse(rows, every) if (rows or every != 1) else None
    except ConfigError:              # the class's own words name its parameters; the command's name its options
        bad = (f"--every {every!r}: expected a whole number >= 1" if not (isinstance(every, int) and every >= 1)
               else f"--rows {rows!r}: expected {ROWS_EXPECTED}")
        raise ConfigError(f"import: {bad}") from None
    arm = robot_named(robot) if robot else None
    m = read_measurements(source, arm, fmt=load_format(format_path) if format_path else fmt, rows=selection,
                          frame=frame)
    lines = [f"imported from {source} by partcal {__version__}: degrees, mm"]
    reg = None
    if frame == "tracker":
        reg = register_measurements(arm, m, tool_mm=tool_mm, fit_tool=tool_mm is None, source=str(source))
        m = registered(m, arm, reg)
        lines.append(registration_comment(reg, shared=False))
        show(registration_line(reg))
    write_measurements(m, output, comment="\n".join(lines))
    return Imported(output, len(m), pooled_rms(m.errors_mm), reg)


def import_run(config: str | Path, output: str | Path, *, show: Callable[[str], None] = _quiet) -> list[str]:
    """Convert the data sets of the run config ``config`` (format, subsets, registration) into the folder
    ``output`` (``<data set>.csv``, and ``robot.yaml`` when the run names a robot), without fitting.

    ``show`` receives each registration's line before the files are written;
    the lines returned say what was written.
    """
    refuse_input_as_output(output, "import", [("run config", config)])
    run = load_config(config)
    refuse_input_as_output(output, "import", [("run's input", p) for p in run.inputs()])
    folder = Path(output)
    check_writable(folder, run.inputs(), option="-o")
    datasets, robot, registrations = load_datasets(run)
    for reg in {id(r): r for r in registrations.values()}.values():
        show(registration_line(reg, [n for n, r in registrations.items() if r is reg]))

    def fill(tmp: Path) -> list[Path]:
        written = write_datasets(run, datasets, registrations, tmp)
        if robot is None:
            return written
        tool = "the tool offset registered on the identification set" if registrations else "its tool offset"
        return written + [write_robot_yaml(robot, tmp / "robot.yaml", (
            f"robot of run {run.name!r} (partcal {__version__}, from {run.robot}) with {tool}: the robot of "
            "the data sets beside it (base frame)"))]

    paths = [folder / p.name for p in replace_folder(folder, fill)]
    data = [p for p in paths if p.name != "robot.yaml"]
    lines = [f"wrote {len(data)} data sets ({', '.join(f'{n}: {len(m)}' for n, m in datasets.items())}) to {output}"]
    if robot is not None:
        lines.append(f"robot (tool offset included): {folder / 'robot.yaml'}")
    return lines


def simulate_files(config: str | Path) -> list[str]:
    """``partcal simulate``: the data sets of the virtual-robot config ``config`` written (docs/virtual_robot.md);
    the lines returned are the table of the data sets and what was written."""
    start = time.perf_counter()
    study = load_study(config)
    check_folder_writable(study.output)          # before the simulation, not after
    data = simulate(study)
    paths = write_study(study, data)
    return simulation_table(study, data) + [
        f"wrote {len(paths)} files to {study.output} in {time.perf_counter() - start:.1f} s"]
