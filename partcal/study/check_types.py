"""What ``partcal check`` and ``partcal update`` share on rows of measurement types (camera pixels, touches, visits,
distances): the cell a model of a run on them keeps (``fit.cell``: its cameras, boards, planes and points, the types'
noise), the new rows' stacked problem at the model's values, a refit on rows, and the refusal of tracker points
against a model identified from camera rows. The check itself is :func:`partcal.study.check.check_type_rows`
(each new row's weighted residual judged by the model's fit sigma and, through the rows' Jacobian, its covariance:
``r^T (s^2 I + J C J^T)^-1 r`` against chi-square; each joint's offset and each camera's and board's pose as
explanations); the update :func:`partcal.study.update.update_type_rows` (the model's robot parameters the prior,
the cell's unknowns identified afresh from the new rows, as the base frame is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._yamlio import Section
from ..calibration.measurement import MeasurementRows
from ..calibration.prior import Prior
from ..calibration.registry import built_types
from ..calibration.stacked import StackedProblem
from ..data.measurement_rows import cell_from_section
from ..errors import ConfigError, DataError, ModelFileError

CELL_FIELD = "cell"
"""The model file's field (under ``fit``) that holds the cell a run on measurement types read."""


def model_cell(doc: dict, model_path) -> dict:
    """The cell a run on measurement types wrote into its model file (``fit.cell``), read as
    :func:`~partcal.data.measurement_rows.read_cell` reads a cell file. Raises :class:`ModelFileError` for a
    model file without it."""
    raw = (doc.get("fit") or {}).get(CELL_FIELD)
    if raw is None:
        raise ModelFileError(f"{model_path}: field 'fit.cell': the model file carries no cell, which rows of "
                             "measurement types are read against (a model of partcal run on measurement types "
                             "writes it): fit it again with partcal run")
    try:
        return cell_from_section(Section(raw, "", {}, f"{model_path}: fit.cell"))
    except ConfigError as exc:
        raise ModelFileError(str(exc)) from None


def stacked_at_model(model, rows: MeasurementRows, cell: dict, model_path, data_path):
    """The stacked problem of ``rows`` at the model's values, every unknown the rows read taken from the model's
    table (refused, naming the first row that reads one the table lacks)."""
    table = model.identification_
    problem = StackedProblem(model.robot_, model.joint_errors_, rows, built_types(rows, cell),
                             np.zeros(len(rows)), model.parametrization_)
    own = problem.own
    values = problem.start.copy()
    values[:own] = table.value[:own]
    fitted = dict(zip(table.names[own:], table.value[own:]))
    for k, (name, _) in enumerate(problem.names):
        if name not in fitted:
            raise DataError(f"{data_path}: {name!r} is not in the model {model_path}, which identified "
                            f"{', '.join(sorted({n.split('.')[0] for n in table.names[own:]})) or 'no cell unknowns'}"
                            ": check reads rows of what the model identified (identify these rows with the "
                            "model's in partcal run)")
        values[own + k] = fitted[name]
    return problem, values


@dataclass(frozen=True)
class RowsUpdated:
    """What :func:`update_type_rows` did."""

    model: object
    n_rows: int
    rms_before: dict
    rms_after: dict
    provenance: dict

    def lines(self) -> list[str]:
        said = ", ".join(f"{k} {self.rms_before[k]:.4f} -> {self.rms_after[k]:.4f}" for k in self.rms_after)
        return [f"updated from {self.n_rows} rows: RMS residual on them with the prior model (its cell's unknowns "
                f"refitted) -> the updated one: {said}",
                "the robot's parameters had the prior model's values and covariance as their prior; the cell's "
                "unknowns (cameras' and boards' poses, intrinsics, planes, points) and the base frame were "
                "identified afresh from the new rows"]


def refit_on_rows(model, rows: MeasurementRows, cell: dict, prior: Prior):
    """A kinematic model like ``model`` fitted on ``rows`` under ``prior``."""
    from ..models.kinematic import KinematicModel
    return KinematicModel(robot=model.robot_, base=bool(model.base), tool=bool(model.tool), rcond=float(model.rcond),
                          parametrization=model.parametrization_, compliance=list(model.joint_errors_.compliance),
                          joint_harmonics=list(model.joint_errors_.harmonics)).fit(rows.q_deg, None, rows=rows,
                                                                                    cell=cell, prior=prior)


def refuse_points_against_camera(model, model_path, data_path, command: str) -> None:
    """Refuse, in one line, tracker points (a point CSV) against a model identified from camera rows without
    them: a camera sees neither the tool offset nor (its rows alone) the base frame, so such a model's tool and base
    are nominal and points cannot be judged by it (``check``), and a fit on points alone would drop its cameras
    and boards, whose poses are in the frame the images defined (``update``)."""
    if "camera" not in getattr(model, "measurement_types_", ()):
        return
    if command == "check" and not getattr(model, "frame_fixed_", True):
        raise DataError(f"{data_path}: tracker points cannot be checked against {model_path}: it was identified from "
                        "camera rows, which see neither the tool offset nor the base frame (both held nominal); "
                        "check new camera rows instead (a measurements file), or identify with tracker points "
                        "beside the images")
    if command == "update":
        raise DataError(f"{data_path}: a point CSV would update {model_path} without its cameras and boards (their "
                        "poses and intrinsics, identified from camera rows): give the new points as rows of a "
                        "measurements file (measurement: point) beside new camera rows, or camera rows alone")


__all__ = ["model_cell", "stacked_at_model", "refuse_points_against_camera", "refit_on_rows", "RowsUpdated"]
