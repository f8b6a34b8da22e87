"""What a model leaves: the errors left on a data set (position, and orientation for pose errors, in a
shared or a test set's own tracker frame), the part a run ranks on, and the compensation check on a
virtual robot.

A run fits its models on :meth:`Outputs.errors` of the identification set,
scores every data set by :meth:`Outputs.evaluate` (through :func:`errors_left`)
and ranks on :meth:`Outputs.score` of the held-out residuals;
:func:`verify_compensation` commands the compensated test targets on the
simulated true robot.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..data.measurements import Measurements
from ..metrics import MRAD_PER_DEG, MRAD_PER_RAD, ORIENTATION, POSITION, orientation_summary, pooled_rms, summary
from ..models.features import varying_inputs
from ..robot.compensation import CompensationWarning
from ..robot.frames import kabsch
from ..robot.kinematics import Robot
from ..robot.rotations import matrices_from_rotation_vectors, matrices_from_xyz_deg, rotation_vectors_from_matrices
from .config import RunConfig
from .predictor import Predictor, pose_matrices
from .results import ModelResult


@dataclass(frozen=True)
class Outputs:
    """What a run's models predict and the part of it the run ranks by (``predict:``, ``rank_on:``).

    ``predict: position`` fits the primary target's errors, (n, 3) mm; ``pose``
    fits the pose errors (``Measurements.pose_errors``, (n, 6): those, then the
    orientation error as a rotation vector in mrad). The CV score and its
    standard error read the ranked columns alone: the position's, or with
    ``rank_on: orientation`` the orientation's (mrad), never a sum of mm and
    mrad.
    """

    predict: str = "position"
    rank_on: str = "position"

    @classmethod
    def of(cls, config: RunConfig) -> "Outputs":
        return cls(config.predict, config.rank_on)

    @property
    def pose(self) -> bool:
        return self.predict == "pose"

    @property
    def unit(self) -> str:
        """The unit of the ranked score."""
        return "mrad" if self.rank_on == "orientation" else "mm"

    def errors(self, m: Measurements) -> NDArray[np.float64]:
        """What the models fit and predict on a data set."""
        return m.pose_errors if self.pose else m.errors_mm

    def ranked(self, resid: NDArray[np.float64]) -> NDArray[np.float64]:
        """The ranked columns of residuals of :meth:`errors`."""
        return resid[:, ORIENTATION if self.rank_on == "orientation" else POSITION]

    def score(self, resid: NDArray[np.float64]) -> float:
        """The pooled RMS of the ranked columns (mm, or mrad)."""
        return pooled_rms(self.ranked(resid))

    def evaluate(self, m: Measurements, predicted: NDArray[np.float64], own_frame: bool = False) -> dict:
        """The metrics of a prediction on a data set: :func:`summary` of the position errors it leaves (mm) and,
        for pose errors, ``orientation``: :func:`orientation_summary` of the orientation errors left (mrad)."""
        position, orientation = errors_left(m, predicted, own_frame)
        out = summary(position)
        if self.pose:
            out["orientation"] = orientation_summary(orientation)
        return out



TOL_MM, TOL_DEG = 1e-4, 1e-5    # the compensation's tolerances (compensate_full's and compensate_pose's defaults)
Z95 = 1.959963984540054        # a 95% interval is mean +- Z95 std


def spread_summary(m: Measurements, predicted: NDArray[np.float64], std: NDArray[np.float64],
                   own_frame: bool = False) -> dict:
    """How a model's spread fares on a data set: ``std_mean`` (per axis, mm) and ``coverage_95``, the share of
    the position errors left (x, y, z of every pose, as :func:`errors_left` takes them) within ``Z95 std``."""
    position, _ = errors_left(m, predicted, own_frame)
    s = std[:, POSITION]
    return {"std_mean": s.mean(axis=0).tolist(), "coverage_95": float(np.mean(np.abs(position) <= Z95 * s))}


def errors_left(m: Measurements, predicted: NDArray[np.float64], own_frame: bool = False
                ) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """The errors a model leaves on a data set: the position's, (n, 3) mm, measured - nominal - predicted,
    and for a prediction of pose errors (n, 6) the orientation's, (n, 3) mrad (else None): the turn from the
    predicted orientation to the measured one, ``log(exp(e_measured) exp(-e_predicted))``.

    A set registered in its own tracker frame (``registration: own``) is known
    only up to a rigid transform: its registration on the nominal model has
    already absorbed the rigid part of the robot's errors, and a model's
    prediction would count it again. There the errors left are the measured
    positions minus the model's positions (nominal + predicted) moved by their
    best rigid fit to them; with ``predicted = 0`` the same gives the
    uncompensated figure, so both sides are scored alike. The same rotation turns
    the predicted orientation.
    """
    rot = np.eye(3)
    if not own_frame:
        position = m.errors_mm - predicted[:, POSITION]
    else:
        model_mm = m.nominal_mm + predicted[:, POSITION]
        rot, shift = kabsch(model_mm, m.measured_mm)
        position = m.measured_mm - (model_mm @ rot.T + shift)
    if predicted.shape[1] < 6:
        return position, None
    measured = matrices_from_rotation_vectors(np.radians(m.orientation_errors_deg))
    model = rot @ matrices_from_rotation_vectors(predicted[:, ORIENTATION] / MRAD_PER_RAD)
    return position, rotation_vectors_from_matrices(measured @ model.transpose(0, 2, 1)) * MRAD_PER_RAD


def verify_compensation(result: ModelResult, data: dict[str, Measurements], robot: Robot, virtual,
                        seed: int) -> tuple[dict[str, dict], dict[str, tuple]]:
    """Command the compensated test targets on the virtual robot; compare before, predicted and after.

    ``predicted_residual`` is the model's error on the measured test set (what
    compensation should leave); ``after`` is what the true robot, measured by
    the simulated tracker, really misses by when given the false targets whose
    compensation converged (``converged`` of ``n``: the others are no command a
    controller would send). A model of pose errors compensates the full pose
    (the test poses' nominal position and orientation,
    :meth:`Predictor.compensate_pose`), and ``orientation`` holds the same three
    figures of the orientation (mrad). Targets that do not converge raise one
    ``CompensationWarning`` per model and data set, naming both, with each
    listed target's predicted miss and reason (:meth:`CompensationResult.reasons`).

    Returns the figures by test set, and by test set the positions the
    virtual robot's tracker read (n, 3) mm, the mask of the converged targets
    and, for a model of pose errors, the turn from each target orientation to
    the one reached (rotation vectors, degrees; else None): what
    :func:`~partcal.study.iso_figures.run_figures` measures the ISO figures
    after compensation from.
    """
    predictor = Predictor(result.model, {"name": result.spec.name, "inputs": result.spec.inputs,
                                         "n_inputs": result.model.n_features_in_, "kind": "run"}, robot)
    pose = result.model.n_outputs() == 6
    out, attained = {}, {}
    for k, (name, m) in enumerate(data.items()):
        if name == "identification":
            continue
        targets, seeds = m.nominal_mm, m.q_deg if result.spec.inputs == "joint" else None
        with warnings.catch_warnings():        # warned below, naming the data set too
            warnings.simplefilter("ignore", CompensationWarning)
            if pose:
                comp = predictor.compensate_pose(targets, m.nominal_orientation_deg, seeds)
            else:
                comp = predictor.compensate_full(targets, seeds)
        comp.warn_unconverged(TOL_MM, TOL_DEG if pose else None, robot=robot, targets_mm=targets,
                              source=f"verifying compensation: model {result.spec.name!r} on data set {name!r}")
        if result.spec.inputs == "joint":
            q_cmd = comp.joints_deg
        else:     # the controller turns the false target into joints with its nominal model
            fixed = tuple(int(j) + 1 for j in np.flatnonzero(~varying_inputs(m.q_deg)))
            if pose:
                commanded = pose_matrices(comp.commanded_mm, comp.commanded_rotation)
                q_cmd = robot.inverse_pose(commanded, m.q_deg, fixed=fixed).q_deg
            else:
                q_cmd = robot.inverse(comp.commanded_mm, m.q_deg, fixed=fixed).q_deg
        rng = np.random.default_rng([seed, k])
        reached, ok = virtual.measure(q_cmd, rng), comp.converged
        attained[name] = (reached, ok, None)
        out[name] = {"before": summary(m.errors_mm),
                     "predicted_residual": summary(m.errors_mm - result.predictions[name][:, POSITION]),
                     "after": summary((reached - targets)[ok]) if ok.any() else None,
                     "converged": int(ok.sum()), "n": len(targets)}
        if pose:
            turned = _turn_reached(virtual, q_cmd, m, rng)
            attained[name] = (reached, ok, turned / MRAD_PER_DEG)
            out[name]["orientation"] = {"before": orientation_summary(m.orientation_errors_deg * MRAD_PER_DEG),
                                        "predicted_residual": result.metrics[name]["orientation"],
                                        "after": orientation_summary(turned[ok]) if ok.any() else None}
    return out, attained


def _turn_reached(virtual, q_deg: NDArray[np.float64], m: Measurements, rng: np.random.Generator
                  ) -> NDArray[np.float64]:
    """The turn from the test poses' nominal orientation to the one the virtual robot reaches at ``q_deg``, as its
    tracker reads it (noise-free when it reads no orientation), rotation vectors in mrad."""
    seen = virtual.measure_more(q_deg, rng)[1]
    reached = matrices_from_xyz_deg(seen) if seen is not None else virtual.true_flange(q_deg)[1]
    wanted = matrices_from_xyz_deg(m.nominal_orientation_deg)
    return rotation_vectors_from_matrices(reached @ wanted.transpose(0, 2, 1)) * MRAD_PER_RAD
