"""The downstream commands on files: ``predict`` and ``compensate`` on a points CSV, ``compensate`` on a robot
program.

Each is one call that reads the input, asks a :class:`~partcal.study.predictor.Predictor` and writes the
output (a CSV of the given columns and the new ones, or the rewritten program and its JSON summary), and
returns what the command line says about it::

    from partcal.study.downstream import compensate_points

    done = compensate_points("reports/run/models/sdp-ci.json", "targets.csv", "commands.csv")
    done.failure or f"{done.n} targets compensated"
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import atomic_write, refuse_input_as_output
from ..data.formats import MeasurementFormat, load_format
from ..data.point_tables import TURN_COLUMNS, read_point_table
from ..data.programs import DIALECTS, frame_option, program_kind, read_program
from ..errors import ModelFileError, PartcalError
from ..models.kinds import equations_of
from ..metrics import ExtrapolationWarning
from ..robot.compensation import CompensationWarning
from ..robot.description import joint_columns
from ..robot.rotations import xyz_deg_from_matrices
from .predictor import EXTRAPOLATION_LIMIT, Predictor, load_predictor
from .programs import ProgramFrames, ProgramResult, compensate_program


@dataclass(frozen=True)
class Outcome:
    """What a downstream command did, and what the command line says of it.

    ``n``: the rows (points, targets) or a program's targets; ``lines``: the
    lines on stdout; ``warnings``: ``partcal: warning:`` lines (inputs far from
    the model's data, a program without targets); ``notes``: other stderr lines
    (a program's summary); ``failure``: the line on targets not compensated
    (``""``: none; exit code 3). A robot program's :class:`ProgramResult` and
    its summary are kept in ``result`` and ``summary``.
    """

    output: str | Path | None
    n: int
    lines: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    failure: str = ""
    result: ProgramResult | None = None
    summary: dict | None = None


def _format(fmt: str | Path | MeasurementFormat | None) -> MeasurementFormat | None:
    return load_format(fmt) if isinstance(fmt, (str, Path)) else fmt


def predict_points(model: str | Path, points: str | Path, output: str | Path, *,
                   fmt: str | Path | MeasurementFormat | None = None, std: bool = False) -> Outcome:
    """``partcal predict``: the errors a model file predicts at the rows of ``points`` (its columns, then
    ``dx,dy,dz``, pose models' ``drx,dry,drz``, with ``std`` their standard deviations ``sd..``) into
    ``output``; a row whose prediction is not plausible is refused and nothing written."""
    refuse_input_as_output(output, "predict", [("model file", model), ("input file", points),
                                               ("format file", fmt if isinstance(fmt, (str, Path)) else None)])
    predictor = load_predictor(model)
    joints = predictor.n_inputs if predictor.inputs == "joint" else None
    # a model with compliant joints reads the payload of each row too, when the file has it
    table = read_point_table(points, _format(fmt), joints=joints, payload=predictor.model.reads_payload)
    X, payload = table.values, table.payload_kg
    if joints:
        errors = predictor.predict(joints=X, payload_kg=payload, return_std=std)
    else:
        errors = predictor.predict(positions=X, return_std=std)
        payload = None
    spread = None
    if std:
        errors, spread = errors
    predictor.refuse_implausible(X, errors, source=str(points), std=spread)     # nothing is written then
    given = [X] if payload is None else [X, payload[:, None]]
    header = table.columns + (["payload_kg"] if payload is not None else []) + ["dx", "dy", "dz"] + (
        TURN_COLUMNS if predictor.predicts_pose else [])
    if spread is not None:
        header += ["sdx", "sdy", "sdz"] + (["sd" + c[1:] for c in TURN_COLUMNS] if predictor.predicts_pose else [])
        given.append(errors)
        errors = spread
    write_table(output, header, np.hstack(given + [errors]))
    far = far_from_data(predictor, X)
    return Outcome(output, len(X), (f"predicted errors for {len(X)} points: {output}",), (far,) if far else ())


def far_from_data(predictor: Predictor, X: NDArray[np.float64]) -> str:
    """A warning text if model inputs ``X`` (mm or deg) lie far from the training data, else ``""``."""
    far = predictor.distance_to_data(**({"positions": X} if predictor.inputs == "cartesian" else {"joints": X}))
    if not (far > EXTRAPOLATION_LIMIT).any():
        return ""
    unit = "mm" if predictor.inputs == "cartesian" else "deg"
    return (f"{int((far > EXTRAPOLATION_LIMIT).sum())} of {len(far)} points lie more than {EXTRAPOLATION_LIMIT:g} "
            f"{unit} from the data the model was fitted on (the farthest, data row {int(np.argmax(far)) + 1}, "
            f"{far.max():.4g} {unit})")


def compensate_points(model: str | Path, targets: str | Path, output: str | Path, *,
                      fmt: str | Path | MeasurementFormat | None = None, std: bool = False, tol_mm: float = 1e-4,
                      tol_deg: float = 1e-5) -> Outcome:
    """``partcal compensate`` on a targets CSV: the commanded positions (and orientations, joints) that make
    the robot reach each target, at each row's payload, into ``output``.

    ``output`` repeats the given columns and adds ``x_cmd,y_cmd,z_cmd``
    (``rx_cmd..`` with orientations, ``qK_cmd`` for joint models), with
    ``std`` the position expected to be left and its spread, then
    ``miss_mm`` (``miss_deg``), ``converged`` and ``reason``. Targets that do
    not converge are written and marked; :attr:`Outcome.failure` names the first.
    """
    refuse_input_as_output(output, "compensate", [("model file", model), ("targets file", targets),
                                                  ("format file", fmt if isinstance(fmt, (str, Path)) else None)])
    predictor = load_predictor(model)
    n_q = predictor.robot.n_joints if predictor.robot is not None else 0
    table = read_point_table(targets, _format(fmt), seeds=n_q if predictor.inputs == "joint" else 0,
                             orientation=True, payload=predictor.model.reads_payload)
    cols, wanted, seeds, optional = table.columns, table.values, table.seeds, table.seed_columns
    turn_cols, angles, payload = table.orientation_columns, table.orientation_deg, table.payload_kg
    if angles is not None and not predictor.predicts_pose:
        raise PartcalError(f"compensate: {targets} has the orientation columns {', '.join(turn_cols)}, but "
                           f"{model} predicts position errors only ({predictor.model.n_outputs()} outputs): fit "
                           "a pose model ('predict: pose' in the run config) to compensate orientations, or drop "
                           "those columns to compensate the positions; nothing written")
    with warnings.catch_warnings():       # the failure line and the exit code say it instead
        warnings.simplefilter("ignore", CompensationWarning)
        warnings.simplefilter("ignore", ExtrapolationWarning)
        result = predictor.compensate_rows(wanted, angles, seeds, payload_kg=payload, tol_mm=tol_mm,
                                           tol_deg=tol_deg)
    far = far_from_data(predictor, result.commanded_mm if predictor.inputs == "cartesian" else result.joints_deg)
    header, parts = list(cols), [wanted]
    for names, values in ((turn_cols, angles), (optional, seeds),
                          (["payload_kg"], None if payload is None else payload[:, None])):
        if values is not None:
            header += names
            parts.append(values)
    header += ["x_cmd", "y_cmd", "z_cmd"]
    parts.append(result.commanded_mm)
    if angles is not None:
        header += ["rx_cmd", "ry_cmd", "rz_cmd"]
        parts.append(xyz_deg_from_matrices(result.commanded_rotation))
    if result.joints_deg is not None:
        header += [f"{c}_cmd" for c in joint_columns(n_q)]
        parts.append(result.joints_deg)
    if std:          # the position expected to be left at each target, and its spread
        header += ["dx_left", "dy_left", "dz_left", "sdx", "sdy", "sdz"]
        parts += list(predictor.residual_of(result, wanted, payload))
    header.append("miss_mm")            # the predicted miss of each target after compensation
    parts.append(result.residual_mm[:, None])
    if angles is not None:
        header.append("miss_deg")
        parts.append(result.residual_deg[:, None])
    reasons = result.reasons(tol_mm, tol_deg if angles is not None else None, predictor.robot, wanted)
    write_table(output, header + ["converged", "reason"], np.hstack(parts), flags=result.converged, texts=reasons,
                significant=1 if angles is None else 2)
    bad = np.flatnonzero(~result.converged)
    if not bad.size:
        return Outcome(output, len(wanted), (f"compensated {len(wanted)} targets (all converged): {output}",),
                       (far,) if far else ())
    first = int(bad[0])
    target = f"{wanted[first].round(3).tolist()} mm" + ("" if angles is None else
                                                       f", {angles[first].round(3).tolist()} deg")
    miss = f"{result.residual_mm[first]:.3g} mm" + ("" if angles is None else
                                                    f", {result.residual_deg[first]:.3g} deg")
    failure = (f"{bad.size} of {len(wanted)} targets did not converge or are unreachable (first: data "
               f"row {first + 1} of {targets}, target {target}: {reasons[first]}, predicted miss {miss}); "
               f"{output} marks them converged=false" + (f"; also, {far}" if far else ""))
    return Outcome(output, len(wanted), failure=failure)


def write_table(path: str | Path, header: list[str], values: NDArray[np.float64], flags=None, texts=None,
                significant: int = 0) -> None:
    """A CSV of ``header`` and ``values`` (n, k): numbers with 6 decimals (the last ``significant`` columns
    with 6 significant digits: misses of micrometres); ``flags`` (one bool per row) as a column of
    true/false after them, then ``texts`` (one string per row, no commas) as a last column."""
    with atomic_write(path) as handle:
        handle.write(",".join(header) + "\n")
        for k, row in enumerate(values):
            split = len(row) - significant
            cells = [f"{v:.6f}" for v in row[:split]] + [f"{v:.6g}" for v in row[split:]]
            cells += [("true" if flags[k] else "false")] if flags is not None else []
            cells += [texts[k]] if texts is not None else []
            handle.write(",".join(cells) + "\n")


def compensate_file(model: str | Path, targets: str | Path, output: str | Path, *, program: str | None = None,
                    fmt: str | Path | MeasurementFormat | None = None, std: bool = False, frames=(), tools=(),
                    keep_unconverged: bool = False, tol_mm: float = 1e-4, tol_deg: float = 1e-5) -> Outcome:
    """``partcal compensate``: :func:`compensate_points` for a targets CSV, :func:`compensate_program_file` for
    a robot program in the dialect ``program`` (default: told from the file, :func:`program_kind`); an option
    that does not apply to the file is refused."""
    kind = program or program_kind(targets)
    if kind is None:
        for flag, value in (("--frame", frames), ("--tool", tools), ("--keep-unconverged", keep_unconverged)):
            if value:
                raise PartcalError(f"compensate: {flag} is for robot programs (URScript, KRL, RAPID, joint "
                                   f"trajectories); {targets} is a targets CSV")
        return compensate_points(model, targets, output, fmt=fmt, std=std, tol_mm=tol_mm, tol_deg=tol_deg)
    if std:
        raise PartcalError(f"compensate: --std writes columns of a targets CSV; {targets} is a robot program")
    refuse_input_as_output(output, "compensate", [("model file", model), ("program", targets)])
    if fmt:
        raise PartcalError("compensate: --format is for targets CSVs, not robot programs")
    return compensate_program_file(model, targets, output, kind, frames=frames, tools=tools,
                                   keep_unconverged=keep_unconverged, tol_mm=tol_mm, tol_deg=tol_deg)


def compensate_program_file(model: str | Path, program: str | Path, output: str | Path, dialect: str, *,
                            frames=(), tools=(), keep_unconverged: bool = False, tol_mm: float = 1e-4,
                            tol_deg: float = 1e-5) -> Outcome:
    """``partcal compensate`` on a robot program: the program with its targets rewritten into ``output`` and
    a summary into ``output`` + ``.json``; nothing written when a target is not compensated, unless
    ``keep_unconverged`` (then it keeps its numbers, with a comment).

    ``frames`` and ``tools`` are the options' texts, ``NAME=VALUE`` or
    ``VALUE`` (the default), VALUE in the dialect's own syntax
    (:func:`partcal.data.programs.frame_option`).
    """
    refuse_input_as_output(output, "compensate", [("model file", model), ("program", program)])
    given = ProgramFrames(_named(frames, dialect, "--frame"), _named(tools, dialect, "--tool"))
    predictor = load_predictor(model)
    read = read_program(program, dialect)
    named = program_kind(program)
    if not read.targets and named not in (None, dialect):       # --program said one language, the file another
        raise PartcalError(f"{program}: holds no targets read as {dialect}, and its name or text says {named}: "
                           f"give --program {named} (or leave --program out); nothing written")
    with warnings.catch_warnings():       # the failure line and the exit code say it instead
        warnings.simplefilter("ignore", CompensationWarning)
        warnings.simplefilter("ignore", ExtrapolationWarning)
        result = compensate_program(predictor, read, given, keep_unconverged=keep_unconverged, tol_mm=tol_mm,
                                    tol_deg=tol_deg)
    summary = result.summary(predictor.name)
    empty = () if read.targets else (f"{program} holds no targets partcal reads ({dialect}); written as it was "
                                     "(docs/predictor.md, 'Robot programs', says which targets are read)",)
    empty += far_targets(result, str(program))
    failure = ""
    if result.failures:
        first, why = result.failures[0]
        more = len(result.failures) - 1
        failure = (f"{first.where(str(program))} {why}" + (f" (and {more} more)" if more else "") +
                   f"; {len(result.failures)} of {len(read.targets)} targets not compensated")
    if result.output is None:
        return Outcome(None, len(read.targets), warnings=empty, result=result, summary=summary, failure=(
            failure + "; nothing written (--keep-unconverged writes them as they were, with a comment)"))
    summary_path = Path(str(output) + ".json")
    with atomic_write(output, "wb") as handle:
        handle.write(result.output)
    with atomic_write(summary_path) as handle:
        json.dump(summary, handle, indent=2)
        handle.write("\n")
    return Outcome(output, len(read.targets), warnings=empty, notes=(program_line(summary, output, summary_path),),
                   failure=failure and f"{failure}; {output} keeps them as they were, with a comment",
                   result=result, summary=summary)


def far_targets(result: ProgramResult, source: str, shown: int = 10) -> tuple[str, ...]:
    """A warning per compensated target whose model input lies far from the model's data (the first ``shown``,
    then how many more: the summary lists them all), as ``compensate`` warns of a targets CSV's rows."""
    far = result.far()
    unit = result.input_unit
    lines = tuple(f"{t.where(source)}: lies {d:.4g} {unit} from the data the model was fitted on (more than "
                  f"{EXTRAPOLATION_LIMIT:g} {unit}): its correction is the model extrapolated" for t, d in far[:shown])
    more = (f"{source}: and {len(far) - shown} more targets more than {EXTRAPOLATION_LIMIT:g} {unit} from the data "
            "(the summary's far_from_data lists them)",) if len(far) > shown else ()
    return lines + more


def program_line(summary: dict, output, summary_path) -> str:
    """One line on a compensated program: how many targets, the largest correction, the predicted residual."""
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


def model_equations(model: str | Path, digits: int | None = None) -> list[str]:
    """``partcal equations``: a series model's fitted equations in mm and degrees, rounded to ``digits``
    significant digits (None: full precision, which reproduces the predictions); other kinds are refused."""
    predictor = load_predictor(model)
    lines = equations_of(predictor.model, precision=digits)
    if lines is None:
        raise ModelFileError(f"{model}: a {predictor.document['kind']} model has no single equation per "
                             "axis; equations are printed for global series models")
    return lines


def _named(values, dialect: str, option: str) -> dict:
    """``--frame``/``--tool`` values by name (None: the default), each a pose (4, 4) mm; a name given twice
    is refused."""
    out = {}
    for value in values or []:
        name, pose = frame_option(value, DIALECTS[dialect], option)
        if name in out:
            raise PartcalError(f"compensate: {option} {name or '(the default)'} is given twice")
        out[name] = pose
    return out
