"""``KinematicModel``: kinematic identification (:mod:`partcal.calibration.identification`) as an error model.

Its predicted error is ``FK(identified, q_actual) - FK(nominal, q)``; fitted
on pose errors, the orientation's too. With ``residual=`` another error model
is fitted to what the identified kinematics leave, and the two predictions add
up (a hybrid model).
"""

from __future__ import annotations

import logging
import warnings
from pathlib import PurePath

import numpy as np
from numpy.typing import NDArray
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted, validate_data

from .._validation import MAX_PAYLOAD_KG, FieldReader, Requirement, boolean, check_array, one_of, param_error, real, seed_from
from ..errors import DataError
from ..metrics import (MRAD_PER_DEG, MRAD_PER_RAD, ORIENTATION, POSITION, ExtrapolationWarning, distance_outside_boxes,
                       pooled_rms, rms_standard_error)
from ..robot.description import load_robot
from ..robot.kinematics import ORIENTATION_MM_PER_RAD, Robot
from ..robot.rotations import matrix_from_rotation_vector, rotation_vectors_from_matrices
from .base import ErrorModelBase, box_points
from .features import varying_inputs
from ..calibration.chain import model_jacobian
from ..calibration.fit import LOSSES, prior_variance
from ..calibration.identification import identify
from ..calibration.parameters import geometric_size, Identification, nominal_values, own_geometry, parameter_names, PARAMETRIZATIONS, PLAUSIBLE_ERROR, PRIMARY_TARGET, resolved_parametrization, robot_with
from ..calibration.joint_errors import compliance_problem, harmonics_problem, JointErrors
from ..calibration.cv import fold_rows, FOLDS, measuring, SCALE_CHOICE, scale_free, strength_table
from ..calibration.measurement import MeasurementRows
from ..calibration.registry import built_types, MEASUREMENT_TYPES
from ..calibration.stacked import identify_measurements
from .kindtable import check_body, may_be_residual, regions_of, residual_kinds
from .kinematic_file import kinematic_from_section, kinematic_section
from .pose import PoseErrorModel
from ..calibration.prior import plausible_prior, Prior, strength_note, strength_problem, strength_rows, strengths_of
from ..calibration.identification import extra_from
from ..calibration.tracker_points import target_parameters

log = logging.getLogger(__name__)


class KinematicModel(ErrorModelBase):
    """Kinematic calibration as an error model, optionally with a model of what it leaves.

    Parameters
    ----------
    robot : Robot or str
        The nominal robot (or a built-in name / robot YAML path).
    base : bool
        Identify the pose of the robot base in the measurement frame.
    tool : bool
        Identify the tool offset.
    rcond : float in (0, 1)
        Relative singular-value threshold below which a parameter direction
        counts as unidentifiable (see :func:`identify`).
    parametrization : {"auto", "dh", "complete"}
        The geometric parameters identified: the four DH parameters of every
        row, or every row's joint offset and the six errors of its fixed
        transform (tilts between parallel axes too), each reduced by the rank
        rule to what the data identify (docs/models.md). ``auto`` (the
        default, chosen by measurement): ``dh`` for a robot of DH rows,
        ``complete`` for a chain with general origins (a URDF's).
    compliance : sequence of int
        1-based joints that yield under gravity (see :mod:`partcal.calibration.joint_errors`).
    joint_harmonics : int or sequence of int
        Harmonics of the cyclic transmission error of every joint (an int),
        or of each joint (one int per joint); 0: none.
    payload_kg : float >= 0
        The payload at the tool point, kg, of data given without one per
        pose (``fit``, ``predict``: ``payload_kg=`` per pose overrides it).
    loss : {"linear", "huber", "soft_l1", "cauchy"}
        The identification's loss (scipy ``least_squares``'): ``linear`` is least squares (the default), the
        others down-weigh rows far off (named in ``identification_.robust``).
    loss_scale : float > 0
        The robust loss's scale in standard deviations of one coordinate: the stated noise
        (``std_mm`` of :meth:`fit`), or without it the robust spread of the least-squares fit's residuals.
    residual : estimator of a kind that may be a residual (the table of kinds), optional
        Fitted to the errors the identified kinematics leave; its prediction
        is added (a hybrid model). A Cartesian residual reads the nominal
        positions ``FK(nominal, q)``.
    random_state : None, int, RandomState or Generator
        Seed of the residual model (a child stream).

    Attributes
    ----------
    robot_, identified_robot_ : Robot
    identification_ : Identification
        The identified table with standard errors and the condition number.
    residual_ : estimator or None
        Fitted on what the kinematics leave of the position errors.
        On pose errors a :class:`~partcal.models.pose.PoseErrorModel`: two residuals of the
        given settings, one on what is left of the position and one of the orientation (a
        Gaussian process then learns its own hyperparameters for each).
    joint_errors_ : JointErrors
        The joint errors identified (their values are the identified table's last entries).
    active_ : ndarray of bool, shape (N,)
        Joints that moved in the training data.

    Examples
    --------
    >>> robot = load_robot("motoman_sk120")
    >>> q = np.random.default_rng(0).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (60, 6))
    >>> longer = robot.replace(a_mm=robot.a_mm + [0, 0, 0.5, 0, 0, 0, 0, 0])
    >>> model = KinematicModel(robot=robot).fit(q, longer.positions(q) - robot.positions(q))
    >>> round(float(model.identification_.correction[10]), 9)        # a[3]: the upper arm, 0.5 mm longer
    0.5
    """

    inputs = "joint"

    def __init__(self, *, robot=None, base=True, tool=True, rcond=1e-6, parametrization="auto", compliance=(),
                 joint_harmonics=0, payload_kg=0.0, all_targets=False, use_orientation=False,
                 orientation_mm_per_rad=ORIENTATION_MM_PER_RAD, loss="linear", loss_scale=3.0, residual=None,
                 prior=None, prior_strength=1.0,
                 random_state=None):
        self.robot = robot
        self.prior = prior
        self.prior_strength = prior_strength
        self.parametrization = parametrization
        self.all_targets = all_targets
        self.use_orientation = use_orientation
        self.orientation_mm_per_rad = orientation_mm_per_rad
        self.base = base
        self.tool = tool
        self.rcond = rcond
        self.compliance = compliance
        self.joint_harmonics = joint_harmonics
        self.payload_kg = payload_kg
        self.loss = loss
        self.loss_scale = loss_scale
        self.residual = residual
        self.random_state = random_state

    kind = "kinematic"
    file_kind = "kinematic"
    _parameter_rules = {"base": boolean(True), "tool": boolean(True),
                        "rcond": real(0.0, 1.0, default=1e-6, low_open=True),
                        "parametrization": one_of("auto", *PARAMETRIZATIONS, default="auto"),
                        "payload_kg": real(0.0, MAX_PAYLOAD_KG, default=0.0),
                        "all_targets": boolean(False), "use_orientation": boolean(False),
                        "orientation_mm_per_rad": real(0.0, 1e6, default=ORIENTATION_MM_PER_RAD, low_open=True),
                        "loss": one_of(*LOSSES, default="linear"),
                        "loss_scale": real(0.0, 1e3, default=3.0, low_open=True)}
    _requirements = (Requirement("orientation_mm_per_rad", f"{ORIENTATION_MM_PER_RAD:g} (its default) unless "
                                 "use_orientation is true: it weighs the orientation in the identification",
                                 lambda p: p["use_orientation"] or p["orientation_mm_per_rad"] == ORIENTATION_MM_PER_RAD),)
    _from_fitted = ("all_targets", "use_orientation")     # a model file keeps what was fitted on instead
    _OPTIONAL_IN_FILES = ("payload_kg", "orientation_mm_per_rad", "parametrization", "loss",
                          "loss_scale")   # older files: the default
    _joint_rules = {"compliance": ((), compliance_problem), "joint_harmonics": (0, harmonics_problem)}

    def _check_params(self) -> Robot:
        own = type(self).__name__
        if not isinstance(self.robot, (Robot, str, PurePath)):
            raise param_error(own, "robot", "a Robot, a built-in robot name or a robot YAML path", self.robot)
        robot = load_robot(self.robot)
        for name, (_, problem) in self._joint_rules.items():
            expected = problem(getattr(self, name), robot.n_joints)
            if expected is not None:
                raise param_error(own, name, expected, getattr(self, name))
        if not (self.prior is None or self.prior == "plausible" or isinstance(self.prior, Prior)):
            raise param_error(own, "prior", "None, 'plausible' or a Prior", self.prior)
        if strength_problem(self.prior_strength) is not None:
            raise param_error(own, "prior_strength", strength_problem(self.prior_strength), self.prior_strength)
        if self.residual is not None and not may_be_residual(self.residual):
            raise param_error(own, "residual", f"None or a model of a kind that may be a residual "
                              f"({', '.join(residual_kinds())})", self.residual)
        return robot

    def joint_settings(self, robot: Robot) -> tuple[JointErrors, str]:
        """The joint errors (compliance, harmonics) and the parametrization (``auto`` resolved) a fit of these
        settings uses for ``robot``: what every identification of this entry is told, fitted or not."""
        return (JointErrors.for_robot(robot, list(self.compliance), self.joint_harmonics),
                self._resolved_parametrization(robot))

    def robot_parameter_names(self) -> list[str]:
        """The names of the robot's parameters a fit of these settings identifies, in the identification table's
        order (rows, joint errors, tool, base; the measurement types' and further targets' unknowns come after them), without
        fitting: what a ``Prior`` must have been made for (:meth:`~partcal.calibration.prior.Prior.check_names`)."""
        robot = self._check_params()
        return [name for name, _ in parameter_names(robot, *self.joint_settings(robot))]

    def _resolved_parametrization(self, robot: Robot) -> str:
        """``parametrization``, ``auto`` resolved: ``complete`` for a chain with general origins, ``dh`` otherwise."""
        return resolved_parametrization(self.parametrization, robot)

    def fit(self, X, y, payload_kg=None, *, targets=None, orientation_deg=None, orientation_mm_per_rad=None,
            rows: MeasurementRows | None = None, cell: dict | None = None, std_mm=None,
            prior: Prior | None = None):
        """Identify the parameters from joint angles ``X`` (n, N) deg and errors ``y`` (n, 3) mm. Returns self.

        ``payload_kg`` (n,) kg per pose, or a number; default the parameter ``payload_kg``.

        ``y`` are the primary target's errors, or the pose errors (n, 6): those, then the
        orientation errors as rotation vectors in mrad (``Measurements.pose_errors``). A model
        fitted on pose errors predicts them: the orientation error of the identified robot (its
        probe's turn too) against the nominal one; with ``use_orientation`` and no
        ``orientation_deg``, the identification reads the orientation from ``y``; without
        ``use_orientation`` it identifies from the positions alone and predicts the orientation
        all the same (a residual model then fits all six). Further targets on the tool and the measured
        orientation, when given, are identified from too (:mod:`partcal.calibration.tracker_points`):
        ``targets`` maps a target's name to ``(offset, errors)``, its nominal offset in the
        flange frame (3,) mm and its errors (n, 3) mm; ``orientation_deg`` (n, 3) are the
        orientation errors, rotation vectors from the nominal flange orientation to the
        measured one in the base frame, degrees, their residuals weighted by
        ``orientation_mm_per_rad`` (one radian counts as that many mm; default the parameter of
        that name, 200: one mrad weighs as 0.2 mm). The prediction stays the
        primary target's (:meth:`predict_target` gives another's).

        ``rows`` (:class:`~partcal.calibration.measurement.MeasurementRows`) and ``cell`` (the cell's description,
        :func:`partcal.data.measurement_rows.read_cell`): rows of any measurement types (plane
        contacts, fixed points, distances, tracker points) and the cell's features, identified from instead
        of ``y`` (which is then ignored; ``X`` are the rows' joints). The model is the same kinematic model;
        what the data cannot identify is in :meth:`fit_notes`.

        ``std_mm`` (n, 3) mm: the standard deviation of each measured coordinate of the primary target, for a
        weighted identification (:func:`~partcal.calibration.identification.identify`); None: every row alike.
        ``prior`` (:class:`~partcal.calibration.prior.Prior`, indices into the identification table's order): a
        Gaussian prior on the parameters, the identification MAP (:func:`~partcal.calibration.identification.identify`);
        default the parameter ``prior``: ``'plausible'`` (:func:`~partcal.calibration.prior.plausible_prior` at
        ``prior_strength``; a list of strengths, or ``'auto'`` for :data:`~partcal.calibration.prior.STRENGTH_GRID`:
        the strongest within one standard error of the lowest RMS on 5 contiguous blocks of the data held out in
        turn, :meth:`_chosen_strength`; a run chooses on its own folds) or a ``Prior`` (another robot's model,
        ``prior: FILE.json`` in a run: its rows times ``prior_strength`` too). With ``rows`` the prior is on
        the robot's parameters alone (never the kinds' unknowns), the fit MAP the same way
        (:func:`~partcal.calibration.stacked.identify_measurements`), and a list of strengths is chosen on 5 random folds of
        the measuring rows instead (they have no order to keep: :meth:`_measurement_strength`).
        """
        robot = self._check_params()
        if rows is not None:
            return self._fit_rows(robot, rows, cell or {}, payload_kg, prior)
        X, y = validate_data(self, X, y, multi_output=True, y_numeric=True, dtype=np.float64)
        if X.shape[1] != robot.n_joints:
            raise DataError(f"{type(self).__name__} for {robot.name} takes {robot.n_joints} joint angles "
                            f"(degrees) per sample; got X with {X.shape[1]} columns")
        if y.ndim != 2 or y.shape[1] not in (3, 6):
            raise DataError(f"Expected y with shape (n, 3) (position errors, mm) or (n, 6) (pose errors: then the "
                            f"orientation's, a rotation vector in mrad), got array with shape {y.shape}.")
        self._y_1d, self.n_outputs_ = False, y.shape[1]
        if self.n_outputs_ == 6 and self.use_orientation and orientation_deg is None:
            orientation_deg = y[:, ORIENTATION] / MRAD_PER_DEG
        nominal = robot.positions(X)
        payload, ident_payload = self._fit_settings(robot, payload_kg, len(X))
        weight = self.orientation_mm_per_rad if orientation_mm_per_rad is None else orientation_mm_per_rad
        extra = extra_from(robot, X, targets, orientation_deg, weight)
        self.prior_strength_table_ = None
        if prior is None and self.prior is not None:
            prior = self._own_prior(robot, X, y, payload_kg)
        if prior is not None:
            prior.check_names([n for n, _ in parameter_names(robot, self.joint_errors_, self.parametrization_)]
                              + ([n for n, _ in target_parameters(extra.tools_mm, extra.rotations is not None)]
                                 if extra is not None else []))
        self.identification_ = identify(robot, X, nominal + y[:, POSITION], base=bool(self.base), tool=bool(self.tool),
                                        rcond=float(self.rcond), errors=self.joint_errors_, payload_kg=ident_payload,
                                        extra=extra, parametrization=self.parametrization_, std_mm=std_mm,
                                        loss=self.loss, loss_scale=float(self.loss_scale), prior=prior)
        self.targets_ = dict(extra.tools_mm) if extra is not None else {}
        self.orientation_ = extra is not None and extra.rotations is not None
        self.measurement_types_, self.measurement_notes_, self.frame_fixed_ = (), [], True
        self.robot_ = robot
        self._build_robots()
        self._fitted_inputs(X)
        self.residual_ = None
        if self.residual is not None:
            seed = self._residual_seed()
            leftover = y - self._kinematic_errors(X, payload)
            residual = clone(self.residual)
            if isinstance(residual, PoseErrorModel):      # frozen on pose errors (nested CV): its parts keep their seed
                self.residual_ = residual
            else:
                residual.set_params(random_state=seed)
                self.residual_ = PoseErrorModel(residual) if self.n_outputs_ == 6 else residual   # one per part
            self.residual_.fit(self._residual_inputs(X, nominal), leftover)
        self.covariance_scale_ = self._hybrid_covariance_scale(X, nominal)
        return self._prepare()

    def _own_prior(self, robot: Robot, X, y, payload_kg) -> Prior | None:
        """The prior of the parameter ``prior`` at ``prior_strength`` (a list: :meth:`_chosen_strength`): the
        plausible one (:func:`~partcal.calibration.prior.plausible_prior` about nominal: the robot's
        ``plausible_error``, else :data:`~partcal.calibration.parameters.PLAUSIBLE_ERROR`) or a given ``Prior``
        (another robot's model, rows of 1 mm noise) with its rows times the strength."""
        strengths = strengths_of(self.prior_strength)
        self.prior_strength_, self.prior_strength_table_ = strengths[0], None
        if len(strengths) > 1:
            best, self.prior_strength_table_ = strength_rows(strengths, *self._chosen_strength(X, y, payload_kg,
                                                                                                strengths))
            self.prior_strength_ = strengths[best]
        return self.prior_at(robot, self.prior_strength_)

    def prior_at(self, robot: Robot, strength: float) -> Prior | None:
        """The prior of the parameter ``prior`` at one ``strength`` for ``robot`` (None without a prior or at
        strength 0): the plausible one (:func:`~partcal.calibration.prior.plausible_prior` about nominal: the
        robot's ``plausible_error``, else :data:`~partcal.calibration.parameters.PLAUSIBLE_ERROR`) or a given
        ``Prior`` with its rows times the strength."""
        if self.prior is None or strength == 0:
            return None
        if isinstance(self.prior, Prior):
            return Prior(self.prior.index, self.prior.mean, self.prior.root * strength, self.prior.names,
                         self.prior.source)
        errors, parametrization = self.joint_settings(robot)
        names = parameter_names(robot, errors, parametrization)
        return plausible_prior([u for _, u in names], geometric_size(robot, parametrization) - 9,
                               nominal_values(robot, errors, parametrization), strength,
                               {**PLAUSIBLE_ERROR, **(robot.plausible_error or {})})

    def _chosen_strength(self, X, y, payload_kg, strengths) -> tuple[list[float], list[float]]:
        """The 3-D RMS of the kinematic part's errors on each of 5 contiguous blocks of the data (measurement
        order: real residuals are correlated, shuffled folds would reward fitting them), held out in turn, for
        each of ``strengths``, and its standard error over the rows (what
        :func:`~partcal.calibration.prior.strongest_within` chooses by); the positions alone (no residual model, no
        further targets). A run chooses on its own folds instead (``partcal.study.selection``)."""
        payload = self._payload(payload_kg, len(X), fitting=True)
        blocks = np.array_split(np.arange(len(X)), min(5, len(X)))
        out, errors = [], []
        for strength in strengths:
            left = []
            for test in blocks:
                train = np.setdiff1d(np.arange(len(X)), test)
                part = clone(self).set_params(prior_strength=float(strength), residual=None)
                part.fit(X[train], y[train, :3], payload[train])
                left.append(y[test, :3] - part.predict_kinematic(X[test], payload[test])[:, :3])
            out.append(pooled_rms(np.vstack(left)))
            errors.append(rms_standard_error(np.vstack(left), np.arange(len(X))))
        return out, errors

    def _fit_settings(self, robot: Robot, payload_kg, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The fitted settings every fit starts with (joint errors, parametrization, the payloads fitted at); the
        payload per row, and the payload per row the identification reads."""
        self.joint_errors_, self.parametrization_ = self.joint_settings(robot)
        payload = self._payload(payload_kg, n, fitting=True)
        self.fitted_payload_kg_ = np.array([payload.min(), payload.max()])
        # at one payload a compliance is a sag at the tool point like the lumped masses' ones: its column
        # (compliance x payload's weight x lever) is held at zero, so it is unidentifiable at any payload
        return payload, (payload if np.ptp(payload) > 0 else np.zeros_like(payload))

    def _fitted_inputs(self, X: NDArray[np.float64]) -> None:
        """What the fit keeps of its joint angles: the joints that moved, and the box of the data."""
        self.active_ = varying_inputs(X)
        self.data_bounds_ = np.stack([X.min(axis=0), X.max(axis=0)])

    def _fit_rows(self, robot: Robot, rows: MeasurementRows, cell: dict, payload_kg, prior: Prior | None = None
                      ) -> "KinematicModel":
        """:meth:`fit` from rows of measurement types (:func:`~partcal.calibration.stacked.identify_measurements`), MAP
        with a prior (``prior``, else the parameter's: a list of strengths chosen by :meth:`_measurement_strength`)."""
        X = validate_data(self, rows.q_deg, dtype=np.float64)
        if X.shape[1] != robot.n_joints:
            raise DataError(f"{type(self).__name__} for {robot.name} takes {robot.n_joints} joint angles "
                            f"(degrees) per row; the rows have {X.shape[1]}")
        self._y_1d, self.n_outputs_ = False, 3
        ident_payload = self._fit_settings(robot, payload_kg if payload_kg is not None else rows.payload_kg,
                                           len(X))[1]
        self.prior_strength_table_ = None
        if prior is None and self.prior is not None:
            strengths = strengths_of(self.prior_strength)
            self.prior_strength_ = strengths[0]
            if len(strengths) > 1:
                best, self.prior_strength_table_ = self._measurement_strength(robot, rows, cell, ident_payload,
                                                                                         strengths)
                self.prior_strength_ = strengths[best]
            prior = self.prior_at(robot, self.prior_strength_)
        self.identification_, self.measurement_notes_ = identify_measurements(
            robot, rows, cell, base=bool(self.base), tool=bool(self.tool),
            rcond=float(self.rcond), errors=self.joint_errors_, payload_kg=ident_payload,
            parametrization=self.parametrization_, prior=prior, loss=self.loss, loss_scale=float(self.loss_scale),
            residual_left=True)
        self.targets_, self.orientation_, self.robot_ = {}, False, robot
        self.measurement_types_ = tuple(dict.fromkeys(k for k in rows.types if k in MEASUREMENT_TYPES))
        self.frame_fixed_ = any(m.fixes_frame for m in built_types(rows, cell))
        self._build_robots()
        self._fitted_inputs(X)
        self.residual_, self.covariance_scale_ = None, 1.0
        if self.residual is not None:
            self._fit_residual_on_points(robot, rows, payload_kg)
        return self._prepare()

    def _fit_residual_on_points(self, robot: Robot, rows: MeasurementRows, payload_kg) -> None:
        """The residual model fitted on what the identified kinematics leave of the tracker points among the rows
        (the primary target's, in the base frame): the only rows that carry a 3-D error field."""
        target = rows.texts.get("target", ("",) * len(rows))
        points = np.array([i for i in rows.of("point") if target[i] in ("", PRIMARY_TARGET)], dtype=np.intp)
        if not self.frame_fixed_ or points.size == 0:
            raise DataError(f"residual: a residual model learns the 3-D error field that tracker points in the base "
                            f"frame show; these rows ({', '.join(self.measurement_types_)}) hold none"
                            + (" (their points are in the tracker's frame)" if points.size else "")
                            + ": fit the kinematic model alone, or add tracker points")
        X = rows.q_deg[points]
        measured = np.column_stack([rows.numbers[c][points] for c in ("x_meas", "y_meas", "z_meas")])
        nominal = robot.positions(X)
        payload = self._payload(None if payload_kg is None and rows.payload_kg is None else
                                (payload_kg if payload_kg is not None else rows.payload_kg[points]), len(X),
                                fitting=True)
        residual = clone(self.residual).set_params(random_state=self._residual_seed())
        self.residual_ = residual
        residual.fit(self._residual_inputs(X, nominal), measured - nominal - self._kinematic_errors(X, payload))
        self.covariance_scale_ = self._hybrid_covariance_scale(X, nominal)

    def _measurement_strength(self, robot: Robot, rows: MeasurementRows, features: dict, payload, strengths
                              ) -> tuple[int, list[dict]]:
        """A list of prior strengths chosen on rows of measurement types: :data:`~partcal.calibration.cv.FOLDS`
        random folds of the measuring rows (drawn from ``random_state``), each strength's held-out residuals
        weighted by their kinds' noise, the strongest within one standard error of the lowest
        (:func:`~partcal.calibration.cv.strength_table`; a measurement run chooses on its own folds the same way)."""
        built_types(rows, features)         # the rows' own faults said as they are, before any fold is cut
        if scale_free(robot, rows, features, base=bool(self.base), tool=bool(self.tool), rcond=float(self.rcond),
                      errors=self.joint_errors_, payload_kg=payload, parametrization=self.parametrization_):
            raise param_error(type(self).__name__, "prior_strength", f"one number here ({SCALE_CHOICE})",
                              self.prior_strength)
        folds = fold_rows(rows, seed_from(self.random_state), min(FOLDS, measuring(rows).size))

        def identified_at(strength: float, train) -> Identification:
            part = clone(self).set_params(prior_strength=float(strength))
            return part.fit(train.q_deg, None, rows=train, cell=features).identification_

        try:
            return strength_table(identified_at, strengths, robot, rows, features, folds, errors=self.joint_errors_,
                                  parametrization=self.parametrization_, payload_kg=payload)
        except DataError as exc:
            raise DataError(f"prior_strength: choosing among {len(strengths)} strengths on {len(folds)} random folds "
                            f"of the rows: {exc}; give prior_strength one number") from None

    def _hybrid_covariance_scale(self, X: NDArray[np.float64], nominal: NDArray[np.float64]) -> float:
        """What the identified parameters' covariance is multiplied by: 1 alone; with a residual model, the
        scatter the whole model leaves (the residual model's own variance at the training inputs, mean over
        rows and axes) over the kinematic fit's residual variance, at most 1. The covariance ``sigma^2
        (J^T J)^-1`` took all the kinematic fit left as noise; what the residual model explains of it is not
        noise (counting it in both parts made a hybrid's interval cover 100% of new poses like the data)."""
        own = self._noise_mm()
        if self.residual_ is None or not own > 0 or self.residual_.spread_problem() is not None:
            return 1.0
        resid = self.residual_.std_validated(self._residual_inputs(X, nominal))[1][:, POSITION]
        return float(min(1.0, np.mean(resid ** 2) / own ** 2))

    def _prepare(self) -> "KinematicModel":
        """Build what a prediction reads (after fitting or loading); returns self.

        A :class:`Robot` compiles its DH rows on its first forward kinematics:
        one pose through both robots does it here, not in ``predict``. The
        residual model prepares its own (see :meth:`ErrorModelBase._prepare`).
        """
        for robot in (self.robot_, self.identified_robot_, self._geometry):
            robot.positions(self.data_bounds_[:1])
        if self.residual_ is not None:
            self.residual_._prepare()
        return super()._prepare()

    def _residual_inputs(self, X: NDArray[np.float64], nominal: NDArray[np.float64]) -> NDArray[np.float64]:
        """What the residual model reads: the nominal positions ``nominal`` (mm) or the joints ``X`` (deg)."""
        return nominal if self.residual_.inputs == "cartesian" else X

    # ------------------------------------------------------------------ prediction
    def _payload(self, payload_kg, n: int, fitting: bool = False) -> NDArray[np.float64]:
        """The payload per pose (n,) kg: ``payload_kg`` (a number or n values in [0, MAX_PAYLOAD_KG]).

        Fitting, the default is the parameter ``payload_kg``. Predicting, it is
        the payload the model was fitted at (:meth:`default_payload_kg`), and a
        payload outside the fitted ones is warned about (an :class:`ExtrapolationWarning`).
        """
        fitted = None if fitting else getattr(self, "fitted_payload_kg_", None)
        value = (self.default_payload_kg() if not fitting else self.payload_kg) if payload_kg is None else payload_kg
        arr = check_array(np.atleast_1d(np.asarray(value, dtype=float)), "payload_kg", ndim=1)
        if arr.size not in (1, n) or np.any(arr < 0) or np.any(arr > MAX_PAYLOAD_KG):
            raise DataError(f"Expected payload_kg as one number in [0, {MAX_PAYLOAD_KG:g}] or {n} of them (kg, one "
                            f"per pose), got {arr.size} values from {arr.min() if arr.size else 'none'} to "
                            f"{arr.max() if arr.size else 'none'}.")
        if fitted is not None and self.reads_payload and np.any((arr < fitted[0] - 1e-9) | (arr > fitted[1] + 1e-9)):
            where = f"{fitted[0]:g} kg" if fitted[0] == fitted[1] else f"{fitted[0]:g} to {fitted[1]:g} kg"
            why = (": from one payload its compliance is not identified, so it predicts as there" if fitted[0] ==
                   fitted[1] else "")
            warnings.warn(f"payload {arr.min():g} to {arr.max():g} kg lies outside the payloads the model was "
                          f"fitted at ({where}){why}", ExtrapolationWarning, stacklevel=4)
        return np.broadcast_to(arr, (n,)).copy()

    def default_payload_kg(self) -> float:
        """The payload a prediction assumes when given none, kg: the parameter ``payload_kg`` when the model was
        fitted at it (or before the payloads were kept in model files), else the smallest fitted payload."""
        fitted = getattr(self, "fitted_payload_kg_", None)
        if fitted is None or fitted[0] - 1e-9 <= self.payload_kg <= fitted[1] + 1e-9:
            return float(self.payload_kg)
        return float(fitted[0])

    def _build_robots(self) -> None:
        """The identified robot, and its geometry in its own base frame (where the joint errors' lever arms
        are taken), from ``robot_`` and the identified table (after fitting or loading)."""
        self.identified_robot_ = robot_with(self.robot_, self.identification_.value, self.parametrization_)
        self._geometry = own_geometry(self.robot_, self.identification_.value, self.parametrization_)

    def _actual(self, X: NDArray[np.float64], payload: NDArray[np.float64]) -> NDArray[np.float64]:
        """The joint angles the identified arm takes (its joint errors), (n, N) deg."""
        errors = self.joint_errors_
        if errors.empty:
            return X
        size = geometric_size(self.robot_, self.parametrization_)
        return errors.design(self._geometry, X, self.identification_.value[size:size + errors.size], payload)[0]

    def _kinematic(self, X: NDArray[np.float64], payload: NDArray[np.float64]) -> NDArray[np.float64]:
        """Tool positions of the identified model (geometry and joint errors), (n, 3) mm."""
        return self.identified_robot_.positions(self._actual(X, payload))

    def _kinematic_errors(self, X: NDArray[np.float64], payload: NDArray[np.float64]) -> NDArray[np.float64]:
        """The identified model's errors against the nominal one, (n, outputs): the tool position's (mm) and, for
        a model of pose errors, the turn ``log(R_identified P R_nominal^T)`` (mrad; ``P`` the identified probe
        turn, identity without one)."""
        actual = self._actual(X, payload)
        if self.n_outputs() == 3:
            return self.identified_robot_.positions(actual) - self.robot_.positions(X)
        model, nominal = self.identified_robot_.forward(actual), self.robot_.forward(X)
        if self.orientation_:
            model[:, :3, :3] = model[:, :3, :3] @ matrix_from_rotation_vector(
                np.radians(self.identification_.value[-3:]))
        turns = rotation_vectors_from_matrices(model[:, :3, :3] @ nominal[:, :3, :3].transpose(0, 2, 1))
        return np.hstack([model[:, :3, 3] - nominal[:, :3, 3], turns * MRAD_PER_RAD])

    def predict_target(self, X, target: str, payload_kg=None) -> NDArray[np.float64]:
        """The kinematic error of a target the model was fitted on, shape (n, 3) mm: ``FK(identified, its
        identified offset) - FK(nominal, its nominal offset)`` (the primary's: :meth:`predict_kinematic`)."""
        check_is_fitted(self, "identification_")
        if target == PRIMARY_TARGET:
            return self.predict_kinematic(X, payload_kg)[:, POSITION]
        if target not in self.targets_:
            raise DataError(f"Expected a target the model was fitted on "
                            f"({', '.join([PRIMARY_TARGET, *self.targets_])}), got {target!r}.")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        names = self.identification_.names
        tool = self.identification_.value[[names.index(f"tool@{target}.{c}") for c in "xyz"]]
        actual = self._actual(X, self._payload(payload_kg, len(X)))
        moved = self.identified_robot_.replace(tool_mm=tool).positions(actual)
        return moved - self.robot_.replace(tool_mm=self.targets_[target]).positions(X)

    def predict(self, X, payload_kg=None) -> NDArray[np.float64]:
        """Predicted errors ``FK(identified) - FK(nominal)`` (+ the residual model), shape (n, 3) mm; for a model
        fitted on pose errors (n, 6), the orientation's in mrad after (see :meth:`fit`).

        ``payload_kg`` (n,) kg per pose, or a number; default the parameter ``payload_kg``.
        """
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._predict_trusted(X, payload_kg)

    def predict_kinematic(self, X, payload_kg=None) -> NDArray[np.float64]:
        """The kinematic part alone, ``FK(identified) - FK(nominal)``, shape (n, 3) mm (a pose model's: (n, 6))."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return self._kinematic_errors(X, self._payload(payload_kg, len(X)))

    def _predict_trusted(self, X: NDArray[np.float64], payload_kg=None) -> NDArray[np.float64]:
        out = self._kinematic_errors(X, self._payload(payload_kg, len(X)))
        if self.residual_ is not None:
            nominal = self.robot_.positions(X) if self.residual_.inputs == "cartesian" else None
            out += self.residual_.predict(self._residual_inputs(X, nominal))
        return out

    def std_validated(self, X: NDArray[np.float64], payload_kg=None
                      ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Prediction and its standard deviation, both (n, outputs): mm (and mrad for a pose model's turn).

        The kinematic part's position variance is ``J(q) C J(q)^T`` per axis
        (``J`` the model's Jacobian at the commanded joints over the identified
        parameters, ``C`` their covariance ``sigma^2 (J^T J)^-1`` from the
        fit, with a residual model scaled by ``covariance_scale_``: what the
        residual model explains is not noise), which grows where the joints
        leave the ranges of the data, plus
        that of the geometric parameters the data did not identify, each with
        the prior standard deviation of its plausible error
        (:func:`~partcal.calibration.fit.prior_variance`: nil where the
        identified ones stand in for it, growing where the data did not go,
        such as a wrist turned that the data held still); to it
        is added the residual model's variance (its own noise included), or,
        without one, the fit's residual variance per coordinate. A pose
        model's turn gets the fit's orientation residual (or its residual
        model's spread); fitted from positions alone without a residual model,
        it has none (NaN).
        """
        problem = self.spread_problem()
        if problem is not None:
            raise DataError(problem)
        payload = self._payload(payload_kg, len(X))
        table = self.identification_
        own = geometric_size(self.robot_, self.parametrization_) + self.joint_errors_.size
        free = np.flatnonzero(np.array(table.status) == "identified")
        keep = free < own
        _, jac = model_jacobian(self.robot_, self.joint_errors_, X, table.value[:own], payload, self.parametrization_)
        var = _quadratic(jac[:, free[keep]], table.covariance[np.ix_(keep, keep)]) * self.covariance_scale_
        prior = table.prior_indices()
        if prior.size:      # tables written before the prior have none: the identified parameters' alone
            on_tool = prior < own           # a further target's offset moves no prediction of the primary target
            jac_prior = np.zeros((len(jac), prior.size))
            jac_prior[:, on_tool] = jac[:, prior[on_tool]]
            var = var + prior_variance(jac[:, free[keep]], jac_prior, table.prior_absorbed[keep],
                                       table.prior_std[prior])
        var = var.reshape(len(X), 3)
        mean = self._predict_trusted(X, payload_kg)
        std = np.full(mean.shape, np.nan)
        if self.residual_ is not None:
            nominal = self.robot_.positions(X) if self.residual_.inputs == "cartesian" else None
            resid = self.residual_.std_validated(self._residual_inputs(X, nominal))[1]
            std[:, POSITION] = np.sqrt(var + resid[:, POSITION] ** 2)
            std[:, 3:] = resid[:, 3:]
            return mean, std
        std[:, POSITION] = np.sqrt(var + self._noise_mm() ** 2)
        if self.n_outputs() == 6 and table.orientation_rms_deg is not None:
            std[:, ORIENTATION] = table.orientation_rms_deg * MRAD_PER_DEG / np.sqrt(3.0)
        return mean, std

    def _noise_mm(self) -> float:
        """The fit's residual standard deviation of one coordinate of the primary target, mm."""
        table = self.identification_
        if PRIMARY_TARGET not in table.target_rms_mm:         # one target, or rows of measurement types
            return float(table.sigma_mm)
        n, k = 3 * table.n_poses, table.status.count("identified")
        return float(table.rms_mm / np.sqrt(3.0) * np.sqrt(n / max(n - k, 1)))

    def spread_problem(self) -> str | None:
        if getattr(self.identification_, "covariance", None) is None:
            return ("this kinematic model's file was written before partcal kept the identification's covariance, "
                    "so its predictions have no standard deviation: fit it again (partcal run)")
        if self.residual_ is not None:
            return self.residual_.spread_problem()
        return None

    def distance_to_data(self, X) -> NDArray[np.float64]:
        """Distance (degrees) of each pose outside the box of the training joint angles, shape (n,)."""
        check_is_fitted(self, "identification_")
        X = validate_data(self, X, reset=False, dtype=np.float64)
        return distance_outside_boxes(X, self.data_bounds_[:1], self.data_bounds_[1:])

    # ------------------------------------------------------------------ the kind: config, files, run, report
    @classmethod
    def params_from_config(cls, sec, context: dict) -> dict:
        """``base``, ``tool``, ``rcond``, ``payload_kg``, ``compliance`` and ``joint_harmonics``; the robot is the
        run's (top-level key ``robot``)."""
        if context.get("robot") is None:
            sec.fail(sec.path("kind"), "kind: kinematic needs the run's robot (top-level key 'robot')")
        n_joints = context["robot"].n_joints
        joint = {name: sec.get(name, "any", default=default, check=lambda v, p=problem: p(v, n_joints))
                 for name, (default, problem) in cls._joint_rules.items()}
        return {"robot": context["robot"], **super().params_from_config(sec, context), **joint,
                **cls._prior_from_config(sec, context)}

    @classmethod
    def _prior_from_config(cls, sec, context: dict) -> dict:
        """``prior``: ``plausible`` or a kinematic model file of another robot of the same type (read by
        ``context["model_prior"]``, the study layer's: ``(section, path text) -> Prior``), with ``prior_strength``
        (a number, or a list or ``auto`` to choose from). No key: no prior."""
        kind = sec.get("prior", "str", default=None, check=lambda v: None if v.strip() else "a non-empty text")
        strength = sec.get("prior_strength", "any", default=1.0, check=strength_problem)
        if kind is None:
            if sec.has("prior_strength"):
                sec.fail(sec.path("prior_strength"), "applies with a prior only (prior: plausible or FILE.json)")
            return {}
        return {"prior": "plausible" if kind == "plausible" else context["model_prior"](sec, kind),
                "prior_strength": (tuple(float(v) for v in strength) if isinstance(strength, list) else
                                   strength if isinstance(strength, str) else float(strength))}

    @classmethod
    def config_keys(cls) -> set[str]:
        return super().config_keys() | set(cls._joint_rules) | {"prior", "prior_strength"}

    @classmethod
    def from_params(cls, params: dict, random_state=None) -> "KinematicModel":
        return cls(**{**params, "robot": load_robot(params["robot"])}, random_state=random_state)

    @classmethod
    def input_space(cls, params: dict) -> str:
        return "joint"

    def file_section(self) -> dict:
        return kinematic_section(self)

    @classmethod
    def from_file_section(cls, r: FieldReader, inputs: str, n_in: int, n_out: int) -> "KinematicModel":
        """A kinematic model from its section (:func:`~partcal.models.kinematic_file.kinematic_from_section`)."""
        model = kinematic_from_section(cls, r, n_in, n_out)
        model._y_1d = False
        model._build_robots()
        return model

    def check_section(self, r: FieldReader, limit_mm: float = 1e6) -> None:
        """The identified robot moves the tool by less than the robot's reach from where the nominal robot
        puts it, at the corners and centre of the joint box of the data; a residual model is checked too."""
        poses = box_points(*self.data_bounds_)
        with np.errstate(all="ignore"):
            moved = self._kinematic(poses, self._payload(None, len(poses)))
            shift = np.linalg.norm(moved - self.robot_.positions(poses), axis=1)
        reach = self.robot_.reach_mm
        if not np.all(np.isfinite(shift)) or shift.max() > reach:
            worst = f"{shift.max():.4g} mm" if np.all(np.isfinite(shift)) else "a non-finite distance"
            r.sub("identification").fail(
                "value", f"the identified robot moves the tool by {worst} within the joint box of its data, more "
                         f"than the robot's reach ({reach:.0f} mm): the identified values are damaged")
        if self.residual_ is not None:
            check_body(self.residual_, r.sub("residual"))

    def n_outputs(self) -> int:
        return int(getattr(self, "n_outputs_", 3))

    def peak_fit_bytes(self, n: int, n_joints: int) -> tuple[float, str]:
        """The residual model's fit (the identification holds arrays of ``n x parameters``)."""
        return self.residual.peak_fit_bytes(n, n_joints) if self.residual is not None else (0.0, "")

    def describe(self) -> str:
        text = f"the kinematic parameters of {self.robot_.name}"
        errors = self.joint_errors_
        if errors.compliance:
            text += f", the gravity compliance of joint{'s' if len(errors.compliance) > 1 else ''} " + \
                ", ".join(str(j) for j in errors.compliance)
        if any(errors.harmonics):
            text += f", transmission errors (up to {max(errors.harmonics)} harmonics per joint)"
        return text + (f", plus a residual {self.residual_.describe()}" if self.residual_ is not None else "")

    @property
    def solver_name(self) -> str:
        return "levenberg-marquardt"

    def family(self) -> str:
        return "Kinematic models" if self.residual is None else "Hybrid models (kinematic + residual)"

    def effective_parameters(self) -> float:
        """The identified parameters, plus the residual model's."""
        own = sum(status == "identified" for status in self.identification_.status)
        return float(own + (self.residual_.effective_parameters() if self.residual_ is not None else 0.0))

    def fit_notes(self) -> list[str]:
        """A compliance the data could not identify (one payload: only its products with the masses, the
        sags, are seen), so that a payload changes nothing the model predicts; then the residual's notes."""
        held = [n for n in self.identification_.unidentifiable() if n.startswith("compliance[")]
        notes = [f"{', '.join(held)} not identifiable (data at one payload show only the sags): the predictions do "
                 "not change with the payload"] if held else []
        ident = self.identification_
        if ident.n_poses and np.isnan(ident.std_error[np.array(ident.status) == "identified"]).any():
            notes.append(f"{sum(s == 'identified' for s in ident.status)} parameters identified from "
                         f"{ident.n_poses} poses leave no residual to estimate their standard errors: the fit "
                         "interpolates the data; measure more poses")
        if self.n_outputs() == 6 and not self.orientation_:
            notes.append("identified from the positions alone, it predicts the orientation its parameters imply, "
                         "which the positions do not determine (use_orientation: true identifies from it)")
        notes += list(getattr(self, "measurement_notes_", []))
        if not getattr(self, "frame_fixed_", True):
            notes.append(self.frame_note())
        if getattr(self, "prior_strength_table_", None):
            table = self.prior_strength_table_
            notes.append(strength_note(table, f"{FOLDS}-fold CV of the rows", "cv_weighted_rms_mm", "CV weighted RMS")
                         if self.measurement_types_ else strength_note(table, "5-block CV"))
        return notes + (self.residual_.fit_notes() if self.residual_ is not None else [])

    def frame_note(self) -> str:
        """What a model identified from measurement types that fix no frame (planes, points, distances) predicts."""
        return (f"identified from {', '.join(self.measurement_types_)} rows, which fix no frame: the base frame is the "
                "nominal one, so absolute positions (and compensated targets) carry the base's error; after a rigid "
                "fit they hold. Tracker points or a fixed point known in the base frame fix it")

    def search_gap(self, other: ErrorModelBase) -> str | None:
        """The residual's (:meth:`ErrorModelBase.search_gap`): the kinematic part searches nothing."""
        if self.residual_ is None or not isinstance(other, KinematicModel) or other.residual_ is None:
            return None
        return self.residual_.search_gap(other.residual_)

    def is_physical(self) -> bool:
        return self.residual is None

    def _residual_seed(self) -> int:
        """The residual model's seed: a child of this model's."""
        return int(np.random.SeedSequence(seed_from(self.random_state)).spawn(1)[0].generate_state(1)[0])

    def frozen(self, X, y, payload_kg=None, **measured) -> "KinematicModel":
        """With a residual model: the residual frozen on what the kinematics identified on ``X, y`` (and the
        further targets and orientation of :meth:`fit`, ``measured``) leave; on pose errors each part of the
        residual frozen on its own columns (a :class:`PoseErrorModel`)."""
        if self.residual is None:
            return self
        fitted = clone(self).set_params(residual=None).fit(X, y, payload_kg=payload_kg, **measured)
        X = np.asarray(X, dtype=float)
        nominal = fitted.robot_.positions(X)
        leftover = np.asarray(y, dtype=float) - fitted.predict(X, payload_kg=payload_kg)
        inputs = nominal if self.residual.inputs == "cartesian" else X
        residual = clone(self.residual).set_params(random_state=self._residual_seed())
        if leftover.shape[1] == 6:
            residual = PoseErrorModel(residual)
        return clone(self).set_params(residual=residual.frozen(inputs, leftover))

    def regions_model(self):
        """The partitioned model of the residual, if it has one (the table's ``holds_regions``)."""
        return regions_of(self.residual_) if self.residual_ is not None else None

    def identification(self) -> Identification:
        """The identified parameter table (the table's ``identified``)."""
        return self.identification_

    def parameter_rows(self) -> tuple[int, tuple[tuple[str, str], ...]]:
        """The chain's rows and each row's parameters with their units (the identified table's first
        ``rows x len(parameters)`` entries, row by row, then tool, base and joint errors)."""
        return int(self.robot_.alpha_deg.size), PARAMETRIZATIONS[self.parametrization_].row_parameters

    def run_summary(self) -> dict:
        table = self.identification_
        return {"kinematic": {"identified": table.status.count("identified"), "parameters": len(table.names),
                              "unidentifiable": table.unidentifiable(), "condition": table.condition,
                              "rms_3d": table.rms_mm, **_targets_summary(table)}}

    def predict_validated(self, X: NDArray[np.float64], payload_kg=None) -> NDArray[np.float64]:
        return self._predict_trusted(X, payload_kg)

    @property
    def reads_payload(self) -> bool:
        """Whether a payload changes the prediction (some joint yields under gravity)."""
        return bool(self.compliance)

    @property
    def reads_targets(self) -> bool:
        """Whether ``fit`` takes every measured target and the orientation (``all_targets``,
        ``use_orientation``): the run then gives them, pose by pose (``targets=``, ``orientation_deg=``)."""
        return bool(self.all_targets or self.use_orientation)


def _quadratic(J: NDArray[np.float64], C: NDArray[np.float64]) -> NDArray[np.float64]:
    """``diag(J C J^T)``, shape (m,), for a covariance ``C`` (k, k), never negative: through ``C``'s eigenvectors
    (eigenvalues clipped at 0), so that nearly dependent parameters (sags of one joint) cancel without
    rounding below zero."""
    if not np.all(np.isfinite(C)):          # a fit with no residual degrees of freedom: no covariance
        return np.full(len(J), np.nan)
    values, vectors = np.linalg.eigh(C)
    return np.sum((J @ vectors) ** 2 * np.maximum(values, 0.0), axis=1)


def _targets_summary(table: Identification) -> dict:
    """metrics.json fields of a fit on several targets or an orientation (none for one target)."""
    if not table.target_rms_mm:
        return {}
    if PRIMARY_TARGET not in table.target_rms_mm:           # rows of measurement types: each type's RMS residual
        return {"rms_by_type": dict(table.target_rms_mm), **(dict(table.misfit) if table.misfit else {})}
    return {"targets_rms_3d": dict(table.target_rms_mm), "orientation_rms_deg": table.orientation_rms_deg,
            "identifiable_from_primary": table.primary_identifiable}
