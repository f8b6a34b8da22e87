"""``partcal update``: a kinematic model re-identified from new measurements, with itself as the prior.

The model's identified parameters and their covariance (``Identification.covariance``, inflated by
``inflate``: the robot may have changed since) are a Gaussian prior (:mod:`partcal.calibration.prior`) on
the new identification, which is then MAP. The base frame's six parameters are left out of the prior
and identified afresh: new measurements come with their own setup (a tracker moved, a cell rebuilt).
What the new poses say is judged against the prior (:func:`determined_shares`): per direction of the
prior model's own covariance (uninflated), the share of its variance the new poses would remove; their
sum counts the directions they determine. Below :data:`IDENTIFY_LITTLE`, the new poses identify
little: the update keeps the prior model's values and re-identifies the frame alone (on 20 poses of a compact patch of the IPA UR10's
series D, an update that moved the parameters scored worse than the prior model;
benchmarks/bench_update.py), and says so. The new file records its provenance in ``fit.update``.

    from partcal.study.update import update_file

    done = update_file("b.json", "d20.csv", "b_updated.json", inflate=30)
    print("\\n".join(done.lines()))
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._io import refuse_input_as_output
from ..data.formats import load_format
from ..data.measurements import Measurements, read_measurements
from ..data.measurement_rows import has_measurement_column, read_measurement_rows
from ..errors import ModelFileError, PartcalError
from ..metrics import pooled_rms
from ..calibration.chain import model_jacobian
from ..models.kinematic import KinematicModel
from ..calibration.prior import Prior
from .check_types import CELL_FIELD, RowsUpdated, model_cell, refit_on_rows, refuse_points_against_camera
from .persist import checksum, load_model, save_model

DEFAULT_INFLATE = 30.0
"""The default inflation of the prior model's covariance. The covariance ``sigma^2 (J^T J)^-1`` counts
every residual as independent noise; real residuals are correlated (a model's errors between nearby
poses), so it is far too narrow: on the IPA UR10 (B's DH model updated with 20 random poses of D, scored
on the rest of D, median of 5 draws; benchmarks/bench_update.py) the update left 0.526 / 0.467 / 0.439 /
0.450 / 0.474 mm inflated 1 / 10 / 30 / 100 / 1000 times (B's model alone 0.591, a fresh fit 0.499).
Chosen on those same draws: 10 to 100 are all within 0.03 mm of it."""

FIRM = 1e4
"""Where the new poses identify little, the prior's rows are weighted this many times more: its values hold
to about 1e-4 of their standard deviations while the frame is identified."""

IDENTIFY_LITTLE = 1.5
"""The new poses identify little when they determine fewer than this many directions of the prior model's own
(uninflated) covariance of its identified parameters (:func:`determined_shares`): the judgement does not depend
on the inflation. On the IPA UR10, 20 poses drawn at random from series D determine 2.4 to 3.1 of B's 19
(and the update beats the prior model on the rest of D), D's first 20 rows, a compact patch with joint 6 still,
1.0 (and an update that moves the parameters is worse there): a rule of thumb set between the two on this one
robot, not a test with a known error rate."""


@dataclass(frozen=True)
class Updated:
    """What :func:`update_model` did: the new model, the prior's provenance, how much the poses said."""

    model: KinematicModel
    shares: NDArray[np.float64]                  # share of the prior's variance determined, per direction
    kept_prior: bool                           # the poses identified little: the prior's values kept
    n_poses: int
    rms_before_mm: float                       # the prior model's 3-D RMS on the new poses (frame refitted)
    rms_after_mm: float
    provenance: dict = field(default_factory=dict)

    def lines(self) -> list[str]:
        """What ``partcal update`` prints."""
        out = [f"updated from {self.n_poses} poses: 3-D RMS on them {self.rms_before_mm:.3f} mm with the prior model "
               f"(its frame refitted) -> {self.rms_after_mm:.3f} mm",
               f"the new poses determine {self.shares.sum():.1f} of the {self.shares.size} directions of the prior "
               f"model's covariance"]
        if self.kept_prior:
            out.append("the new poses identify little: the prior model's parameters are kept and only the base "
                       "frame is identified again; measure poses spread over the workspace to update them")
        return out


def model_prior(model: KinematicModel, inflate: float, frame: bool = False, unidentified: bool = True) -> Prior:
    """A kinematic model's parameters as a prior: the identified ones at their values with their covariance
    times ``inflate`` (under the model's own noise, ``sigma_mm``); those its data did not identify at their
    values with their plausible error (``Identification.prior_std``), so that the new poses cannot move them
    further than that (alone they would trade off with the ones the prior holds: on a compact patch of 20
    poses of the IPA UR10 the tool offset went 400 mm). ``frame``: the base frame's parameters too (default:
    left out, identified afresh); ``unidentified``: those the data did not identify too. Raises :class:`ModelFileError` for a model without a covariance."""
    table = model.identification_
    if table.covariance is None or table.sigma_mm is None or not np.isfinite(table.sigma_mm):
        raise ModelFileError("the model has no covariance of its parameters (field 'identification.covariance'; "
                             "written before partcal kept it): fit it again with partcal run")
    identified = np.flatnonzero(np.array(table.status) == "identified")
    own = len(model.robot_parameter_names())        # a model of measurement types lists its cell's unknowns after
    keep = np.array([k < own and (frame or not table.names[k].startswith("base.")) for k in identified], dtype=bool)
    plausible = table.prior_indices()
    plausible = plausible[[k < own and unidentified and (frame or not table.names[k].startswith("base."))
                           for k in plausible]]
    index = np.concatenate([identified[keep], plausible]).astype(np.intp)
    cov = np.zeros((index.size, index.size))
    cov[:keep.sum(), :keep.sum()] = table.covariance[np.ix_(keep, keep)] * inflate
    cov[keep.sum():, keep.sum():] = np.diag(table.prior_std[plausible] ** 2)
    prior = Prior.from_covariance(index, table.value[index], cov, float(table.sigma_mm))
    return Prior(prior.index, prior.mean, prior.root, tuple(table.names[:own]))


def type_prior(model: KinematicModel, plausible: dict[str, float]) -> Prior:
    """Another robot's model as the prior of a robot of the same type (``prior: FILE.json`` in a run): each row
    parameter at that model's value with its plausible error (``plausible``, per unit) as the standard
    deviation, under a noise of 1 mm (the fit scales the rows by its ``prior_strength``). Not the model's own
    covariance: that is how well one robot was measured, not how much two robots of a type differ (on a
    virtual UR10 whose parameters differ from its twin's by 0.1 mm / 0.01 degree, the twin's covariance as the
    prior left twice the error of a fit without one). The tool and the base frame: identified afresh."""
    table = model.identification_
    rows = next((k for k, name in enumerate(table.names) if name.startswith("tool.")), len(table.names))
    index = np.array([k for k in range(rows) if table.units[k] in plausible], dtype=np.intp)
    return dataclasses.replace(Prior.from_std(index, table.value[index], [plausible[table.units[k]] for k in index],
                                              1.0), names=tuple(table.names))


def determined_shares(model: KinematicModel, data: Measurements, prior: Prior) -> NDArray[np.float64]:
    """How much the poses of ``data`` determine of each direction of ``prior``, descending, shape (k,): the share
    ``l / (1 + l)`` of its variance they would remove, ``l`` the eigenvalues of ``C^1/2 J^T J C^1/2 / sigma^2``
    (``C`` the prior's covariance, ``J`` the Jacobian of the new positions over the parameters it holds at the
    model's values with the base frame profiled out, ``sigma`` the model's noise). Their sum is the number of
    the prior's directions the poses determine.

    >>> from partcal.calibration.prior import Prior
    """
    table = model.identification_
    _, jac = model_jacobian(model.robot_, model.joint_errors_, data.q_deg, table.value, np.zeros(len(data.q_deg)),
                            model.parametrization_)
    frame = np.array([k for k, name in enumerate(table.names) if name.startswith("base.")], dtype=np.intp)
    held = jac[:, prior.index]
    if frame.size:
        basis = np.linalg.qr(jac[:, frame])[0]
        held = held - basis @ (basis.T @ held)
    # C = sigma^2 (W^T W)^-1: with W = U S V^T, C^1/2 = sigma V S^-1 V^T
    _, s, vt = np.linalg.svd(prior.root)
    half = (vt.T / s) @ vt
    lam = np.linalg.eigvalsh(half @ (held.T @ held) @ half)
    return np.sort(np.clip(lam, 0.0, None) / (1.0 + np.clip(lam, 0.0, None)))[::-1]


def update_model(model: KinematicModel, data: Measurements, inflate: float = DEFAULT_INFLATE) -> Updated:
    """Re-identify ``model`` from ``data`` (base frame, or any frame near it: the base frame is refitted) with
    itself as the prior (:func:`model_prior`, the covariance inflated by ``inflate``). When the poses determine
    fewer than :data:`IDENTIFY_LITTLE` directions of the model's covariance (:func:`determined_shares`), its values
    are kept and the frame alone is identified."""
    if not (np.isfinite(inflate) and inflate > 0):
        raise PartcalError(f"update: --inflate must be a number > 0; got {inflate!r}")
    prior = model_prior(model, inflate)
    shares = determined_shares(model, data, model_prior(model, 1.0, unidentified=False))
    frame_only = _refit(model, data, Prior(prior.index, prior.mean, prior.root * FIRM, prior.names))
    kept = shares.sum() < IDENTIFY_LITTLE
    updated = frame_only if kept else _refit(model, data, prior)
    if updated.identification_.names != model.identification_.names[:len(model.robot_parameter_names())]:
        raise PartcalError("update: the new fit's parameters differ from the model's (its targets or joint errors)")
    before = pooled_rms(data.errors_mm - frame_only.predict(data.q_deg))
    after = pooled_rms(data.errors_mm - updated.predict(data.q_deg))
    return Updated(updated, shares, kept, len(data.q_deg), before, after)


def _refit(model: KinematicModel, data: Measurements, prior: Prior) -> KinematicModel:
    """A kinematic model like ``model`` (its base frame identified) fitted on ``data`` under ``prior``."""
    return KinematicModel(robot=model.robot_, base=True, tool=bool(model.tool), rcond=float(model.rcond),
                          parametrization=model.parametrization_, compliance=list(model.joint_errors_.compliance),
                          joint_harmonics=list(model.joint_errors_.harmonics),
                          payload_kg=float(model.payload_kg)).fit(data.q_deg, data.errors_mm, prior=prior)


def update_file(model_path: str | Path, data_path: str | Path, output: str | Path, *,
                fmt: str | Path | None = None, inflate: float | None = None) -> Updated:
    """``partcal update``: the model file ``model_path`` updated from the measurement CSV ``data_path`` (base
    frame; ``fmt`` a format file), written to ``output`` with its provenance in ``fit.update``; ``inflate``
    default :data:`DEFAULT_INFLATE`."""
    inflate = DEFAULT_INFLATE if inflate is None else inflate
    refuse_input_as_output(output, "update", [("model file", model_path), ("data file", data_path),
                                              ("format file", fmt)])
    model, doc = load_model(model_path)
    if not isinstance(model, KinematicModel):
        raise ModelFileError(f"{model_path}: field 'kind': update needs a model of kind 'kinematic'; got "
                             f"{doc.get('kind')!r}")
    if model.residual_ is not None:
        raise ModelFileError(f"{model_path}: field 'residual': update re-identifies a kinematic model alone; this "
                             f"one has a residual model of kind {doc.get('residual', {}).get('kind')!r}")
    if model.targets_ or model.orientation_:
        raise ModelFileError(f"{model_path}: field 'targets': update reads positions of one target; this model "
                             "was fitted on further targets or an orientation")
    try:
        model_prior(model, 1.0)
    except ModelFileError as exc:
        raise ModelFileError(f"{model_path}: {exc}") from None
    loaded = load_format(fmt) if fmt else None
    if has_measurement_column(data_path, loaded):                                    # pixels, touches, ...
        return update_type_rows(model, doc, model_path, data_path, output, loaded, inflate)
    refuse_points_against_camera(model, model_path, data_path, "update")
    data = read_measurements(data_path, model.robot_, fmt=loaded)
    done = update_model(model, data, inflate)
    provenance = {"data": str(data_path), "rows": len(data.q_deg), "prior_model": str(model_path),
                  "prior_name": doc.get("name", ""), "prior_checksum": doc.get("checksum") or checksum(doc),
                  "inflate": float(inflate), "kept_prior": bool(done.kept_prior),
                  "determined": float(done.shares.sum()),
                  "rms_3d_before": done.rms_before_mm, "rms_3d_after": done.rms_after_mm}
    name = doc.get("name") or Path(model_path).stem
    save_model(done.model, output, name=f"{name} updated", robot=model.robot_,
               extra={"update": provenance, "n_poses": len(data.q_deg)})
    return Updated(done.model, done.shares, done.kept_prior, done.n_poses, done.rms_before_mm, done.rms_after_mm,
                   provenance)


def update_type_rows(model, doc: dict, model_path, data_path, output, fmt, inflate: float) -> RowsUpdated:
    """``partcal update`` from a measurements file: the model re-identified from the new rows (its cell from the
    model file) with its robot parameters as the prior."""
    cell = model_cell(doc, model_path)
    rows = read_measurement_rows(data_path, model.robot_, fmt, cell or None)
    prior = model_prior(model, inflate)
    updated = refit_on_rows(model, rows, cell, prior)
    held = refit_on_rows(model, rows, cell, Prior(prior.index, prior.mean, prior.root * FIRM, prior.names))
    before = dict(held.identification_.target_rms_mm)
    after = dict(updated.identification_.target_rms_mm)
    provenance = {"data": str(data_path), "rows": len(rows), "prior_model": str(model_path),
                  "prior_name": doc.get("name", ""), "inflate": float(inflate), "rms_by_type_before": before,
                  "rms_by_type_after": after}
    name = doc.get("name") or Path(model_path).stem
    save_model(updated, output, name=f"{name} updated", robot=model.robot_,
               extra={"update": provenance, "n_rows": len(rows), CELL_FIELD: (doc.get("fit") or {})[CELL_FIELD]})
    return RowsUpdated(updated, len(rows), before, after, provenance)
