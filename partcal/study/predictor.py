"""The downstream ``Predictor``: load a model file, predict errors, compensate targets.

Usage, with a model file from ``partcal run``::

    from partcal import load_predictor

    p = load_predictor("reports/paper_sk120/models/sdp-ci.json")
    p.predict(positions=[[1100, 800, 600]])      # predicted error (measured - nominal), mm
    p.compensate([[1100, 800, 600]])             # the position to command instead, mm

A model of pose errors (6 outputs: ``dx, dy, dz`` mm, then the rotation
vector ``rx, ry, rz`` in mrad, base frame, that turns the nominal orientation
into the real one) also compensates orientations::

    from partcal.robot.kinematics import xyz_deg_from_matrices

    r = p.compensate_pose([[1100, 800, 600]], [[180, 0, 90]])   # target orientation: intrinsic XYZ degrees
    r.commanded_mm, xyz_deg_from_matrices(r.commanded_rotation)  # the pose to command
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .._validation import check_array
from ..errors import DataError
from ..metrics import MRAD_PER_RAD, warn_far
from ..models.features import varying_inputs
from ..robot.compensation import (CompensationResult, false_target, false_target_cartesian_poses,
                                  false_target_joints, false_target_poses, merged, reachable, reachable_poses)
from ..robot.description import robot_from_dict
from ..robot.kinematics import Robot, checked_poses, ik_settings
from ..robot.rotations import matrices_from_rotation_vectors, matrices_from_xyz_deg
from .persist import load_model

EXTRAPOLATION_LIMIT = 50.0    # mm (Cartesian models) or degrees (joint models) from the nearest training input
POSE_OUTPUTS = 6              # a pose model: dx, dy, dz (mm), then the rotation vector rx, ry, rz (mrad)
HALF_TURN_MRAD = MRAD_PER_RAD * np.pi    # a predicted turn beyond this is no error, but a model beyond its data


class Predictor:
    """Predict position (or pose) errors and compensate targets with a fitted model.

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

    @property
    def _label(self) -> str:
        """How warnings name the model: ``model 'NAME'`` (nothing for a model without a name)."""
        return f"model {self.name!r}" if self.name else ""

    @property
    def predicts_pose(self) -> bool:
        """True for a model of pose errors (6 outputs: mm, then mrad), False for a position model (3)."""
        return self.model.n_outputs() == POSE_OUTPUTS

    def _errors(self, X: NDArray[np.float64], payload_kg=None) -> NDArray[np.float64]:
        if len(X) == 0:                 # no points, no errors (scikit-learn refuses empty inputs)
            return np.zeros((0, self.model.n_outputs()))
        if payload_kg is None:
            return self.model.predict_validated(X)
        return self.model.predict_validated(X, payload_kg=payload_kg)

    def _check_payload(self, payload_kg) -> None:
        if payload_kg is not None and not self.model.reads_payload:
            raise DataError(f"model {self.name!r} has no joint that yields under gravity, so a payload changes "
                            f"nothing it predicts; got payload_kg={payload_kg!r}")

    def predict(self, positions=None, joints=None, payload_kg=None, return_std: bool = False):
        """Predicted errors (measured - nominal), shape (n, 3) mm, or (n, 6) for a pose model.

        With ``return_std=True`` also the standard deviation of each predicted
        error, same shape and units: ``(mean, std)``. It is the spread of the
        error a measurement at that input would show (the model's uncertainty
        there and the scatter it leaves unexplained; see docs/predictor.md);
        a 95% interval is ``mean +- 1.96 std``. A model file written before
        partcal kept what the spread needs is refused with a message saying so.

        A pose model (:attr:`predicts_pose`) gives the position error in mm,
        then the rotation vector in mrad (axis times angle, base frame) that
        turns the nominal orientation into the real one: ``R_real = exp([r])
        R_nominal``.
        Cartesian models take ``positions`` (n, 3) mm, or ``joints`` when the
        model file carries a robot; joint models take ``joints`` (n, N) degrees.
        ``payload_kg`` (one number, or one per row) is the payload at the tool
        point for a model with compliant joints (default: the payload it was
        given when fitted, see the model's ``payload_kg``).
        """
        self._check_payload(payload_kg)
        X = self._inputs(positions, joints)
        if not return_std:
            return self._errors(X, payload_kg)
        return self._errors_with_std(X, payload_kg)

    def _errors_with_std(self, X: NDArray[np.float64], payload_kg=None
                         ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(mean, std)`` of the predicted errors at validated inputs, each (n, outputs)."""
        if len(X) == 0:
            empty = np.zeros((0, self.model.n_outputs()))
            return empty, empty.copy()
        problem = self.model.spread_problem()
        if problem is not None:
            raise DataError(f"model {self.name or '(unnamed)'!r}: {problem}")
        if payload_kg is None:
            return self.model.std_scaled(X)
        return self.model.std_scaled(X, payload_kg=payload_kg)

    def expected_residual(self, targets_mm, joints=None, *, payload_kg: float | None = None
                          ) -> tuple[CompensationResult, NDArray[np.float64], NDArray[np.float64]]:
        """Compensate ``targets_mm`` (n, 3) mm and say what the robot is expected to miss them by, and how sure.

        Returns ``(result, residual_mm, std_mm)``: the :meth:`compensate_full`
        result; the expected position left (target minus where the model says
        the robot goes at the command), (n, 3) mm, which is the solver's
        remaining miss (near zero where it converged); and its standard
        deviation, (n, 3) mm, the model's spread at the commanded inputs: where
        the robot really lands around the target, as far as the model knows.
        """
        result = self.compensate_full(targets_mm, joints, payload_kg=payload_kg)
        return (result, *self.residual_of(result, check_array(targets_mm, "targets_mm", columns=3), payload_kg))

    def residual_of(self, result: CompensationResult, targets_mm: NDArray[np.float64], payload_kg=None
                    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The expected position left at each compensated target and its standard deviation, both (n, 3) mm
        (see :meth:`expected_residual`); ``payload_kg``: one number or one per target."""
        if len(targets_mm) == 0:
            return np.zeros((0, 3)), np.zeros((0, 3))
        X = result.commanded_mm if self.inputs == "cartesian" else result.joints_deg
        mean, std = self._errors_with_std(X, payload_kg)
        reached = (result.commanded_mm if self.inputs == "cartesian" else self.robot.positions(X)) + mean[:, :3]
        return targets_mm - reached, std[:, :3]

    def predict_point(self, joints, offset_mm, payload_kg=None) -> NDArray[np.float64]:
        """Predicted position error of another point on the tool, shape (n, 3) mm, from a pose model.

        ``offset_mm`` (3,) is the point's offset in the flange frame (a second
        reflector, another tool centre point); ``joints`` (n, N) degrees. The
        tool is taken as rigid: the point moves with the primary target's
        error ``e`` and turns with the orientation error ``r`` about it,
        ``e + (exp([r]) - I) R_flange (offset - tool)`` (``tool`` the model
        file robot's tool offset, ``R_flange`` the nominal flange orientation
        at the joints). Needs a model of pose errors and the robot of its file.
        """
        if not self.predicts_pose:
            raise DataError(f"model {self.name!r} predicts position errors only, so the error of another point on "
                            "the tool is unknown: fit it on pose errors (predict: pose in a run config)")
        if self.robot is None:
            raise DataError(f"model {self.name!r}: its file names no robot, so the flange orientation at the joints "
                            "is unknown")
        self._check_payload(payload_kg)
        q = check_array(joints, "joints", columns=self.robot.n_joints)
        offset = check_array(np.reshape(np.asarray(offset_mm, dtype=float), (1, -1)), "offset_mm", columns=3)[0]
        errors = self._errors(q if self.inputs == "joint" else self.robot.positions(q), payload_kg)
        lever = self.robot.flange(q)[:, :3, :3] @ (offset - self.robot.tool_mm)
        turn = matrices_from_rotation_vectors(errors[:, 3:] / MRAD_PER_RAD) - np.eye(3)
        return errors[:, :3] + np.einsum("nij,nj->ni", turn, lever)

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
        :meth:`compensate_full` returns the details. A pose model compensates
        the position here (:meth:`compensate_pose` does the orientation too).
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
        (:meth:`distance_to_data` of the commanded inputs). A pose model
        compensates the position here, from its position outputs; see
        :meth:`compensate_pose` for the orientation too.
        """
        targets = check_array(targets_mm, "targets_mm", columns=3)
        predicted = self._errors_at(payload_kg)

        def errors(X):
            return predicted(X)[:, :3]

        if len(targets) == 0:
            joints_out = None if self.inputs == "cartesian" else np.zeros((0, self.n_inputs))
            return CompensationResult(np.zeros((0, 3)), joints_out, np.zeros(0, np.int64), np.zeros(0),
                                      np.zeros(0, bool))
        if self.inputs == "cartesian":
            result = false_target(errors, targets, tol_mm=tol_mm, max_iter=max_iter)
            if self.robot is not None:      # a command the arm cannot reach (IK within its limits) is no solution
                seeds = self._given_seeds(joints, len(targets))
                live = np.flatnonzero(result.converged)
                ok = np.zeros(len(targets), dtype=bool)
                ok[live] = reachable(self.robot, result.commanded_mm[live], None if seeds is None else seeds[live])
                result = dataclasses.replace(result, converged=ok)
        else:
            fixed, seeds = self._joint_seeds(joints, len(targets))
            result = false_target_joints(errors, self.robot, targets, seeds, fixed, tol_mm=tol_mm,
                                         max_iter=max_iter)
        result.warn_unconverged(tol_mm, robot=self.robot, targets_mm=targets, source=self._label)
        return result

    def compensate_rows(self, targets_mm, orientations_deg=None, joints=None, *, payload_kg=None,
                        tol_mm: float = 1e-4, tol_deg: float = 1e-5) -> CompensationResult:
        """:meth:`compensate_full` of every target (:meth:`compensate_pose` with ``orientations_deg``), each at
        its own payload.

        ``payload_kg`` is None or one number per row (kg): the rows of one
        payload are compensated together and the results put back in row
        order. ``orientations_deg`` (n, 3) intrinsic XYZ degrees and ``joints``
        (n, N) degrees (seeds) are per row too.
        """
        def solve(rows, kg):
            def some(v):
                return v if rows is None or v is None else v[rows]

            if orientations_deg is None:
                return self.compensate_full(some(targets_mm), some(joints), payload_kg=kg, tol_mm=tol_mm)
            return self.compensate_pose(some(targets_mm), some(orientations_deg), some(joints), payload_kg=kg,
                                        tol_mm=tol_mm, tol_deg=tol_deg)

        if payload_kg is None:
            return solve(None, None)
        groups = [payload_kg == kg for kg in np.unique(payload_kg)]
        return merged([(rows, solve(rows, float(payload_kg[rows][0]))) for rows in groups])

    def compensate_pose(self, positions_mm, orientations_deg, joints=None, *, payload_kg: float | None = None,
                        tol_mm: float = 1e-4, tol_deg: float = 1e-5, max_iter: int = 50) -> CompensationResult:
        """Full-pose false targets: the tool pose to command so that the robot reaches each target pose.

        Needs a pose model (:attr:`predicts_pose`).

        Parameters
        ----------
        positions_mm : array-like, shape (n, 3)
            Target positions of the tool point in the base frame, mm.
        orientations_deg : array-like, shape (n, 3)
            Target orientations of the tool, intrinsic XYZ angles in degrees
            (``R = Rx(rx) Ry(ry) Rz(rz)``, as ``rx_meas..`` of a measurement CSV).
        joints : array-like, shape (n, N), optional
            Degrees: IK seeds, as for :meth:`compensate_full` (joint models:
            the joints the model never saw move are held at the seed's value
            as long as six others are free; a full pose needs six, so a
            six-axis arm's held wrist moves by what the pose asks, usually a
            fraction of a degree; Cartesian models: the seeds of the
            reachability check).
        payload_kg : float, optional
            As for :meth:`compensate`.
        tol_mm, tol_deg : float
            A target is converged when the predicted miss of the commanded pose
            is within ``tol_mm`` (position) and ``tol_deg`` (the angle of the
            orientation miss), and the robot can take the command.
        max_iter : int
            Iterations of each solve: the fixed-damping steps of a joint model,
            then each Levenberg-Marquardt solve that finishes the targets they
            leave near a singularity (``iterations`` counts them all).

        Returns
        -------
        CompensationResult
            ``commanded_mm`` (n, 3) and ``commanded_rotation`` (n, 3, 3): the
            pose to command (:func:`~partcal.robot.kinematics.xyz_deg_from_matrices`
            gives its angles); ``joints_deg`` (n, N) for joint models, else
            None; ``residual_mm``, ``residual_deg`` and ``converged`` per target.

        Joint models solve the whole pose equation for the joints
        (:func:`~partcal.robot.compensation.false_target_poses`). A Cartesian
        model reads the position only, so the commanded position is the fixed
        point of :meth:`compensate_full`, and the commanded orientation is then
        exactly ``exp(-[r(p')]) R_target``; with a robot in the file, a command
        its full-pose IK does not reach within the limits (from ``joints`` or
        the home pose, then from further seeds) is not converged. Unconverged
        targets raise a ``CompensationWarning``.
        """
        if not self.predicts_pose:
            raise DataError(f"model {self.name or '(unnamed)'!r} predicts position errors only "
                            f"({self.model.n_outputs()} outputs), so it cannot compensate an orientation: fit a pose "
                            f"model ({POSE_OUTPUTS} outputs; 'predict: pose' in a run config), or compensate the "
                            "positions alone with compensate()")
        ik_settings(tol_mm, max_iter, 10.0, 0.05, tol_deg=tol_deg)                # checks the tolerances
        positions = check_array(positions_mm, "positions_mm", columns=3)
        angles = check_array(orientations_deg, "orientations_deg", columns=3)
        if len(angles) != len(positions):
            raise DataError(f"orientations_deg has {len(angles)} rows but positions_mm has {len(positions)}")
        poses = pose_matrices(positions, matrices_from_xyz_deg(angles)) if len(positions) else np.zeros((0, 4, 4))
        return self.compensate_poses(poses, joints, payload_kg=payload_kg, tol_mm=tol_mm, tol_deg=tol_deg,
                                     max_iter=max_iter)

    def compensate_poses(self, poses, joints=None, *, payload_kg: float | None = None, tol_mm: float = 1e-4,
                         tol_deg: float = 1e-5, max_iter: int = 50, orientation_kept: bool = False
                         ) -> CompensationResult:
        """:meth:`compensate_pose` of tool poses given as homogeneous transforms (no Euler angles on the way).

        Parameters
        ----------
        poses : array-like, shape (n, 4, 4)
            Target poses of the tool point in the base frame, mm.
        joints, payload_kg, tol_mm, tol_deg, max_iter
            As for :meth:`compensate_pose`.
        orientation_kept : bool
            Do not use the model's orientation outputs (a position model has none): the position is
            compensated and the commanded pose keeps the target's orientation (joint models: the joints at
            which the nominal tool has the target orientation and the predicted position error brings the
            tool point onto the target). Without it a position model is refused.

        Returns
        -------
        CompensationResult
            As for :meth:`compensate_pose`.
        """
        if not self.predicts_pose and not orientation_kept:
            raise DataError(f"model {self.name or '(unnamed)'!r} predicts position errors only "
                            f"({self.model.n_outputs()} outputs), so it cannot compensate an orientation: fit a pose "
                            f"model ({POSE_OUTPUTS} outputs; 'predict: pose' in a run config), or compensate the "
                            "positions alone with compensate() (or orientation_kept=True)")
        ik_settings(tol_mm, max_iter, 10.0, 0.05, tol_deg=tol_deg)                # checks the tolerances
        predicted = self._errors_at(payload_kg)

        def errors(X):          # radians for the solvers
            e = predicted(X)
            if orientation_kept:
                return np.hstack([e[:, :3], np.zeros((len(e), 3))])
            return e * _RADIANS_PER_OUTPUT

        n = len(poses)
        if n == 0:
            return CompensationResult(np.zeros((0, 3)), None if self.inputs == "cartesian" else
                                      np.zeros((0, self.n_inputs)), np.zeros(0, np.int64), np.zeros(0),
                                      np.zeros(0, bool), np.zeros((0, 3, 3)), np.zeros(0))
        poses = checked_poses(poses)
        if self.inputs == "cartesian":
            result = false_target_cartesian_poses(errors, poses, tol_mm=tol_mm, tol_deg=tol_deg, max_iter=max_iter)
            if self.robot is not None:      # a pose the arm cannot take (IK within its limits) is no solution
                seeds = self._given_seeds(joints, n)
                live = np.flatnonzero(result.converged)
                ok = np.zeros(n, dtype=bool)
                ok[live] = reachable_poses(self.robot, pose_matrices(result.commanded_mm[live],
                                                                    result.commanded_rotation[live]),
                                           None if seeds is None else seeds[live])
                result = dataclasses.replace(result, converged=ok)
        else:
            fixed, seeds = self._joint_seeds(joints, n)
            if self.robot.n_joints - len(fixed) < 6:      # a full pose needs six joints: the held ones move too
                fixed = ()
            result = false_target_poses(errors, self.robot, poses, seeds, fixed, tol_mm=tol_mm, tol_deg=tol_deg,
                                        max_iter=max_iter)
        result.warn_unconverged(tol_mm, tol_deg, robot=self.robot, targets_mm=poses[:, :3, 3], source=self._label)
        return result

    def _errors_at(self, payload_kg):
        """The model's errors at one payload (checked here) as a function of its inputs."""
        self._check_payload(payload_kg)
        if payload_kg is not None and np.ndim(payload_kg) != 0:
            raise DataError(f"compensate takes one payload_kg for all targets; got an array of shape "
                            f"{np.shape(payload_kg)}")
        return lambda X: self._errors(X, payload_kg)

    def _given_seeds(self, joints, n: int) -> NDArray[np.float64] | None:
        """The caller's joints (n, N) degrees, checked against the robot and the number of targets, or None."""
        if joints is None:
            return None
        seeds = check_array(joints, "joints", columns=self.robot.n_joints)
        if seeds.shape[0] != n:
            raise DataError(f"joints has {seeds.shape[0]} rows but there are {n} targets")
        return seeds

    def _joint_seeds(self, joints, n: int) -> tuple[tuple[int, ...], NDArray[np.float64]]:
        """A joint model's fixed joints and IK seeds (n, N) degrees: the caller's, or the home pose with the
        fixed joints at their training value."""
        if self.robot is None:
            raise DataError("compensating a joint model needs its robot, and this model file names none")
        fixed, values = self._fixed_joints()
        seeds = self._given_seeds(joints, n)
        if seeds is None:
            seeds = np.tile(self.robot.home_deg, (n, 1))
            seeds[:, [j - 1 for j in fixed]] = values
        return fixed, seeds

    def _fixed_joints(self) -> tuple[tuple[int, ...], NDArray[np.float64]]:
        """Joints constant in the training data (the model cannot know what moving them does)."""
        low, high = self.model.input_bounds()
        active = varying_inputs(np.stack([low, high]))
        fixed = tuple(int(j) + 1 for j in np.flatnonzero(~active))
        return fixed, low[[j - 1 for j in fixed]]

    def refuse_implausible(self, X, errors, source: str = "input", std=None) -> None:
        """Refuse predicted errors ``(n, 3)`` mm (or pose errors ``(n, 6)``) that are not finite, longer than
        the robot's reach, or turn by more than half a turn; with ``std`` (their standard deviations, same
        shape) the same of the spread (an orientation without one, NaN, is not refused: docs/predictor.md).

        Such a number is the model extrapolated beyond meaning (a polynomial
        at 1e200 mm), not an error: a :class:`DataError` names the first such
        data row of ``source``, its input ``X`` and its distance from the data.
        """
        if std is not None:
            std = np.hstack([std[:, :3], np.where(np.isnan(std[:, 3:]), 0.0, std[:, 3:])])
        for values, name in ((errors, "predicted error"), (std, "standard deviation of the predicted error")):
            if values is not None:
                self._refuse(X, values, source, name)

    def _refuse(self, X, values, source: str, name: str) -> None:
        """:meth:`refuse_implausible` of one array (errors or their spread), named ``name`` in the message."""
        size = np.linalg.norm(values[:, :3], axis=1)
        turn = np.linalg.norm(values[:, 3:], axis=1)        # mrad (zeros for a position model)
        limit = self.robot.reach_mm if self.robot is not None else np.inf
        finite = np.isfinite(size) & np.isfinite(turn)
        bad = ~finite | (size > limit) | (turn > HALF_TURN_MRAD)
        if not bad.any():
            return
        k = int(np.flatnonzero(bad)[0])
        what = ("is not finite" if not finite[k] else
                f"is {size[k]:.4g} mm, more than robot {self.robot.name}'s reach ({limit:.0f} mm)" if size[k] > limit
                else f"turns by {turn[k]:.4g} mrad, more than half a turn ({HALF_TURN_MRAD:.0f} mrad)")
        key = "positions" if self.inputs == "cartesian" else "joints"
        far = self.distance_to_data(**{key: X[k:k + 1]})[0]
        raise DataError(f"{source}: data row {k + 1}: the {name} {what} ({int(bad.sum())} of {len(bad)} "
                        f"rows); the input [{', '.join(f'{v:.6g}' for v in X[k])}] lies {far:.4g} "
                        f"{'mm' if self.inputs == 'cartesian' else 'deg'} from the data the model was fitted on: "
                        "nothing written")

    def distance_to_data(self, positions=None, joints=None) -> NDArray[np.float64]:
        """Distance of each input to the nearest training sample, input units (mm or degrees).

        Files written before partcal kept the training inputs give the distance outside the data's boxes.
        """
        X = self._inputs(positions, joints)
        return self.model.distance_to_data(X) if len(X) else np.zeros(0)


_RADIANS_PER_OUTPUT = np.array([1.0, 1.0, 1.0, *[1.0 / MRAD_PER_RAD] * 3])     # a pose model's outputs: mm, mrad


def pose_matrices(positions: NDArray[np.float64], rotations: NDArray[np.float64]) -> NDArray[np.float64]:
    """Poses ``(n, 4, 4)`` from positions ``(n, 3)`` mm and rotations ``(n, 3, 3)``."""
    out = np.zeros((len(positions), 4, 4))
    out[:, :3, :3], out[:, :3, 3], out[:, 3, 3] = rotations, positions, 1.0
    return out


def load_predictor(path: str | Path) -> Predictor:
    """Load a model file written by ``partcal run`` (or :func:`partcal.persist.save_model`)."""
    model, doc = load_model(path)
    robot = robot_from_dict(doc["robot"], source=str(path)) if doc.get("robot") else None
    return Predictor(model, doc, robot)
