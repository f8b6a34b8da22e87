"""The downstream ``Predictor``: load a model file, predict errors, compensate targets.

Usage, with a model file from ``partcal run``::

    from partcal import load_predictor

    p = load_predictor("reports/paper_sk120/models/sdp-ci.json")
    p.predict(positions=[[1100, 800, 600]])      # predicted error (measured - nominal), mm
    p.compensate([[1100, 800, 600]])             # the position to command instead, mm
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import DataError
from ..metrics import warn_far
from ..models.bases import varying_inputs
from ..robot.compensation import CompensationResult, false_target, false_target_joints, reachable
from ..robot.description import robot_from_dict
from ..robot.kinematics import Robot
from .persist import load_model

EXTRAPOLATION_LIMIT = 50.0    # mm (Cartesian models) or degrees (joint models) from the nearest training input


class Predictor:
    """Predict position errors and compensate targets with a fitted model.

    Attributes
    ----------
    name : str
    inputs : "cartesian" or "joint"
    robot : Robot or None
        The robot the model was fitted for (needed for joint models'
        compensation, and to accept joints for Cartesian models).
    document : dict
        The model file's content (fit statistics under ``"fit"``).
    """

    def __init__(self, model, document: dict, robot: Robot | None = None):
        self.model, self.document, self.robot = model, document, robot
        self.name = document.get("name", "")
        self.inputs = document["inputs"]
        self.n_inputs = int(document["n_inputs"])

    def __repr__(self) -> str:
        return f"Predictor({self.name!r}, inputs={self.inputs!r}, kind={self.document['kind']!r})"

    def _errors(self, X: NDArray[np.float64], payload_kg=None) -> NDArray[np.float64]:
        if len(X) == 0:                 # no points, no errors (scikit-learn refuses empty inputs)
            return np.zeros((0, 3))
        if payload_kg is None:
            return self.model.predict_validated(X)
        return self.model.predict_validated(X, payload_kg=payload_kg)

    def _check_payload(self, payload_kg) -> None:
        if payload_kg is not None and not self.model.reads_payload:
            raise DataError(f"model {self.name!r} has no joint that yields under gravity, so a payload changes "
                            f"nothing it predicts; got payload_kg={payload_kg!r}")

    def predict(self, positions=None, joints=None, payload_kg=None) -> NDArray[np.float64]:
        """Predicted errors (measured - nominal), shape (n, 3) mm.

        Cartesian models take ``positions`` (n, 3) mm, or ``joints`` when the
        model file carries a robot; joint models take ``joints`` (n, N) degrees.
        ``payload_kg`` (one number, or one per row) is the payload at the tool
        point for a model with compliant joints (default: the payload it was
        given when fitted, see the model's ``payload_kg``).
        """
        self._check_payload(payload_kg)
        return self._errors(self._inputs(positions, joints), payload_kg)

    def _inputs(self, positions, joints) -> NDArray[np.float64]:
        if (positions is None) == (joints is None):
            raise DataError("give exactly one of positions= (mm) or joints= (degrees)")
        if self.inputs == "joint":
            if joints is None:
                raise DataError("this model takes joint angles: pass joints= (degrees); to reach Cartesian "
                                "targets use compensate(), which solves the inverse kinematics")
            return check_array(joints, "joints", columns=self.n_inputs)
        if positions is not None:
            return check_array(positions, "positions", columns=3)
        if self.robot is None:
            raise DataError("this Cartesian model's file names no robot, so joints cannot be converted: "
                            "pass positions= (mm)")
        return self.robot.positions(check_array(joints, "joints", columns=self.robot.n_joints))

    def compensate(self, targets_mm, joints=None, *, payload_kg: float | None = None, tol_mm: float = 1e-4,
                   max_iter: int = 50) -> NDArray[np.float64]:
        """Commanded ("false target") positions, shape (n, 3) mm, so that the robot reaches the targets.

        ``payload_kg`` (one number) is the payload the robot carries, for a
        model with compliant joints (see :meth:`predict`).

        Targets that do not converge to ``tol_mm`` raise a ``CompensationWarning``
        naming them, and commanded inputs farther than ``EXTRAPOLATION_LIMIT``
        (50 mm or degrees) from the training data an ``ExtrapolationWarning``;
        :meth:`compensate_full` returns the details.
        """
        result = self.compensate_full(targets_mm, joints, payload_kg=payload_kg, tol_mm=tol_mm, max_iter=max_iter)
        evaluated = result.commanded_mm if self.inputs == "cartesian" else result.joints_deg
        if len(evaluated):
            warn_far(self.model.distance_to_data(evaluated), EXTRAPOLATION_LIMIT)     # names the caller's line
        return result.commanded_mm

    def compensate_full(self, targets_mm, joints=None, *, payload_kg: float | None = None, tol_mm: float = 1e-4,
                        max_iter: int = 50) -> CompensationResult:
        """Like :meth:`compensate`, with joints (joint models), iterations and residuals per target.

        ``joints`` (n, N) degrees are IK seeds for joint models (default: the
        robot's home pose, with the joints the model never saw move held at
        their value in the training data), and the seeds of a Cartesian
        model's reachability check: with a robot in the file, a command is
        converged only where the robot's IK reaches it within its joint limits
        and constraints. Unconverged targets warn as in
        :meth:`compensate`; the distance to the data is left to the caller
        (:meth:`distance_to_data` of the commanded inputs).
        """
        targets = check_array(targets_mm, "targets_mm", columns=3)
        self._check_payload(payload_kg)
        if payload_kg is not None and np.ndim(payload_kg) != 0:
            raise DataError(f"compensate takes one payload_kg for all targets; got an array of shape "
                            f"{np.shape(payload_kg)}")

        def errors(X):
            return self._errors(X, payload_kg)

        if len(targets) == 0:
            joints_out = None if self.inputs == "cartesian" else np.zeros((0, self.n_inputs))
            return CompensationResult(np.zeros((0, 3)), joints_out, np.zeros(0, np.int64), np.zeros(0),
                                      np.zeros(0, bool))
        if self.inputs == "cartesian":
            result = false_target(errors, targets, tol_mm=tol_mm, max_iter=max_iter)
            if self.robot is not None:      # a command the arm cannot reach (IK within its limits) is no solution
                seeds = None if joints is None else check_array(joints, "joints", columns=self.robot.n_joints)
                live = np.flatnonzero(result.converged)
                ok = np.zeros(len(targets), dtype=bool)
                ok[live] = reachable(self.robot, result.commanded_mm[live], None if seeds is None else seeds[live])
                result = dataclasses.replace(result, converged=ok)
        else:
            if self.robot is None:
                raise DataError("compensating a joint model needs its robot, and this model file names none")
            fixed, values = self._fixed_joints()
            if joints is None:
                seeds = np.tile(self.robot.home_deg, (len(targets), 1))
                seeds[:, [j - 1 for j in fixed]] = values
            else:
                seeds = check_array(joints, "joints", columns=self.robot.n_joints)
                if seeds.shape[0] != targets.shape[0]:
                    raise DataError(f"joints has {seeds.shape[0]} rows but targets_mm has {targets.shape[0]}")
            result = false_target_joints(errors, self.robot, targets, seeds, fixed, tol_mm=tol_mm,
                                         max_iter=max_iter)
        result.warn_unconverged(tol_mm)
        return result

    def _fixed_joints(self) -> tuple[tuple[int, ...], NDArray[np.float64]]:
        """Joints constant in the training data (the model cannot know what moving them does)."""
        low, high = self.model.input_bounds()
        active = varying_inputs(np.stack([low, high]))
        fixed = tuple(int(j) + 1 for j in np.flatnonzero(~active))
        return fixed, low[[j - 1 for j in fixed]]

    def refuse_implausible(self, X, errors, source: str = "input") -> None:
        """Refuse predicted errors ``(n, 3)`` mm that are not finite or longer than the robot's reach.

        Such a number is the model extrapolated beyond meaning (a polynomial
        at 1e200 mm), not an error: a :class:`DataError` names the first such
        data row of ``source``, its input ``X`` and its distance from the data.
        """
        size = np.linalg.norm(errors, axis=1)
        limit = self.robot.reach_mm if self.robot is not None else np.inf
        bad = ~np.isfinite(size) | (size > limit)
        if not bad.any():
            return
        k = int(np.flatnonzero(bad)[0])
        what = "is not finite" if not np.isfinite(size[k]) else (f"is {size[k]:.4g} mm, more than robot "
                                                                  f"{self.robot.name}'s reach ({limit:.0f} mm)")
        key = "positions" if self.inputs == "cartesian" else "joints"
        far = self.distance_to_data(**{key: X[k:k + 1]})[0]
        raise DataError(f"{source}: data row {k + 1}: the predicted error {what} ({int(bad.sum())} of {len(bad)} "
                        f"rows); the input [{', '.join(f'{v:.6g}' for v in X[k])}] lies {far:.4g} "
                        f"{'mm' if self.inputs == 'cartesian' else 'deg'} from the data the model was fitted on: "
                        "nothing written")

    def distance_to_data(self, positions=None, joints=None) -> NDArray[np.float64]:
        """Distance of each input to the nearest training sample, input units (mm or degrees).

        Files written before partcal kept the training inputs give the distance outside the data's boxes.
        """
        X = self._inputs(positions, joints)
        return self.model.distance_to_data(X) if len(X) else np.zeros(0)


def load_predictor(path: str | Path) -> Predictor:
    """Load a model file written by ``partcal run`` (or :func:`partcal.persist.save_model`)."""
    model, doc = load_model(path)
    robot = robot_from_dict(doc["robot"], source=str(path)) if doc.get("robot") else None
    return Predictor(model, doc, robot)
