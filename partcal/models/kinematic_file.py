"""The model-file section of ``kind: kinematic`` (:class:`~partcal.models.kinematic.KinematicModel`): what it
writes (its robot, settings, identified table, further targets, the measurement types it was fitted on, the box
of its data, its residual model's body) and how it is read back, every field checked against the file's robot."""

from __future__ import annotations

import logging
import math

import numpy as np

from .._validation import FieldReader, boolean
from ..errors import ModelFileError
from ..robot.description import robot_from_dict, robot_to_dict
from ..robot.kinematics import Robot
from ..calibration.joint_errors import JointErrors
from ..calibration.parameters import Identification, nominal_values, parameter_names, PARAMETRIZATIONS, STATUSES
from ..calibration.tracker_points import target_nominal, target_parameters
from .kindtable import body_of, model_from_body
from .pose import PoseErrorModel

log = logging.getLogger(__name__)


def kinematic_section(model) -> dict:
    """The fitted ``model``'s section of a model file."""
    errors = model.joint_errors_
    return {"robot": robot_to_dict(model.robot_), "base": bool(model.base), "tool": bool(model.tool),
            "rcond": float(model.rcond), "payload_kg": float(model.payload_kg),
            **({"parametrization": model.parametrization_} if model.parametrization_ != "dh" else {}),
            **({"orientation_mm_per_rad": float(model.orientation_mm_per_rad)} if model.orientation_ else {}),
            **({"loss": model.loss, "loss_scale": float(model.loss_scale)} if model.loss != "linear" else {}),
            "compliance": list(errors.compliance), "joint_harmonics": list(errors.harmonics),
            "identification": model.identification_.to_dict(),
            **({"targets": {k: [float(v) for v in t] for k, t in model.targets_.items()},
                "orientation": bool(model.orientation_)} if model.targets_ or model.orientation_ else {}),
            **({"measurement_types": list(model.measurement_types_), "frame_fixed": bool(model.frame_fixed_)}
               if getattr(model, "measurement_types_", ()) else {}),
            "data_bounds": model.data_bounds_.tolist(), "active": model.active_.tolist(),
            **({"covariance_scale": model.covariance_scale_} if model.covariance_scale_ != 1.0 else {}),
            **({"fitted_payload_kg": [float(v) for v in model.fitted_payload_kg_]}
               if getattr(model, "fitted_payload_kg_", None) is not None else {}),
            "residual": body_of(model.residual_) if model.residual_ is not None else None}


def kinematic_from_section(cls, r: FieldReader, n_in: int, n_out: int):
    """A kinematic model (of class ``cls``) from its section: the identified table must agree with the file's
    robot (nominal values, unidentified parameters kept nominal, standard errors >= 0). The class builds its
    identified robots from it."""
    try:
        robot = robot_from_dict(r.get("robot", dict), source=f"{r.source}: field {r.path('robot')!r}")
    except Exception as exc:  # noqa: BLE001 - any damage in the robot section is a file error
        raise ModelFileError(str(exc)) from None
    if robot.n_joints != n_in:
        r.fail("robot", f"a robot with the file's {n_in} joints (n_inputs); got {robot.n_joints}")
    if n_out not in (3, 6):
        r.fail("", f"a kinematic model has 3 outputs (n_outputs; position errors) or 6 (pose errors); the file "
                   f"says {n_out}")
    joint = {}
    for name, (default, problem) in cls._joint_rules.items():       # files before the joint errors: none
        joint[name] = r.doc.get(name, default)
        if problem(joint[name], robot.n_joints) is not None:
            r.fail(name, f"expected {problem(joint[name], robot.n_joints)}; got {joint[name]!r}"[:200])
    rules = {key: rule for key, rule in cls._parameter_rules.items()
             if key not in cls._from_fitted and (key in r.doc or key not in cls._OPTIONAL_IN_FILES)}
    tools, orientation = _targets_from(r)
    model = cls(robot=robot, **{key: r.rule(key, rule) for key, rule in rules.items()}, **joint,
                all_targets=bool(tools), use_orientation=orientation)
    errors = JointErrors.for_robot(robot, joint["compliance"], joint["joint_harmonics"])
    if model.parametrization == "auto":     # a file holds what was fitted: written when not dh
        if "parametrization" in r.doc:
            r.fail("parametrization", f"one of {', '.join(PARAMETRIZATIONS)} (what was fitted); got 'auto'")
        model.parametrization = "dh"
    model.parametrization_ = model.parametrization
    key = "measures" if "measures" in r.doc else "measurement_types"      # its name in files of partcal 0.1
    types = r.doc.get(key, [])
    if not (isinstance(types, list) and all(isinstance(k, str) and k for k in types)):
        r.fail(key, f"the names of the measurement types it was fitted on; got {types!r}"[:200])
    model.measurement_types_ = tuple(types)
    model.frame_fixed_ = bool(r.rule("frame_fixed", boolean(True))) if "frame_fixed" in r.doc else True
    if not model.frame_fixed_:
        log.warning("%s: %s", r.source, model.frame_note())
    table = _identification_from(r.sub("identification"), robot, errors, tools, orientation,
                                 model.parametrization_, type_unknowns=bool(types))
    model.robot_, model.identification_, model.joint_errors_ = robot, table, errors
    model.targets_, model.orientation_ = tools, orientation
    model.data_bounds_ = r.array("data_bounds", (2, n_in))
    if np.any(model.data_bounds_[0] > model.data_bounds_[1]):
        r.fail("data_bounds", "a low bound exceeds its high bound")
    model.active_ = r.array("active", (n_in,), bool)
    model.covariance_scale_ = r.number("covariance_scale", 0.0, 1.0) if "covariance_scale" in r.doc else 1.0
    if model.covariance_scale_ != 1.0 and r.doc.get("residual") is None:
        r.fail("covariance_scale", f"a model without a residual model counts all its fit leaves as noise: "
                                   f"expected 1 or no field; got {model.covariance_scale_!r}")
    model.fitted_payload_kg_ = r.array("fitted_payload_kg", (2,)) if "fitted_payload_kg" in r.doc else None
    if model.fitted_payload_kg_ is not None and not 0 <= model.fitted_payload_kg_[0] <= model.fitted_payload_kg_[1]:
        r.fail("fitted_payload_kg", "the smallest and largest payload of the data, 0 <= low <= high kg")
    model.n_features_in_, model.n_outputs_ = n_in, n_out
    model.residual_ = None
    if r.doc.get("residual") is not None:
        model.residual_ = model_from_body(r.sub("residual"))
        if model.residual_.n_outputs() != n_out or isinstance(model.residual_, PoseErrorModel) != (n_out == 6):
            r.sub("residual").fail("kind", f"a residual of {n_out} outputs" + (" of kind 'pose' (one model on the "
                                   "position, one on the orientation)" if n_out == 6 else "") + f"; got kind "
                                   f"{r.sub('residual').doc.get('kind')!r} of {model.residual_.n_outputs()} outputs")
        model.residual = model.residual_ if n_out == 3 else model.residual_.model
    return model


def _targets_from(r: FieldReader) -> tuple[dict, bool]:
    """A model file's extra targets (name -> nominal offset, mm) and whether it read an orientation (files of
    one target have neither)."""
    tools = r.doc.get("targets", {})
    if not isinstance(tools, dict) or not all(
            isinstance(k, str) and isinstance(v, list) and len(v) == 3 and
            all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v)
            for k, v in tools.items()):
        r.fail("targets", "a mapping of target name to its offset [x, y, z] (mm)")
    orientation = r.doc.get("orientation", False)
    if not isinstance(orientation, bool):
        r.fail("orientation", "true or false")
    return {k: np.asarray(v, dtype=float) for k, v in tools.items()}, orientation


def _identification_from(ident: FieldReader, robot: Robot, errors: JointErrors | None = None, tools=None,
                         orientation: bool = False, parametrization: str = "dh",
                         type_unknowns: bool = False) -> Identification:
    """A model file's identified table, which must agree with its robot: the robot's parameter names and
    nominal values, unidentified parameters kept nominal, standard errors finite and >= 0 (or null). Fitted on
    measurement types (``type_unknowns``), the types' unknowns (a plane, a point) follow the robot's, their
    start values as nominal."""
    names = [n for n, _ in parameter_names(robot, errors, parametrization) + target_parameters(tools or {}, orientation)]
    given = ident.get("names", list)
    if type_unknowns and given[:len(names)] == names and all(isinstance(n, str) for n in given):
        names = list(given)
    if given != names:
        ident.fail("names", f"expected the {len(names)} parameters of {robot.name} ({names[0]} ... {names[-1]})")
    status = ident.get("status", list)
    if len(status) != len(names) or any(s not in STATUSES for s in status):
        ident.fail("status", f"expected {len(names)} of {', '.join(STATUSES)}")
    std = ident.get("std_error", list)
    if len(std) != len(names) or not all(v is None or isinstance(v, (int, float)) for v in std):
        ident.fail("std_error", f"expected {len(names)} numbers or nulls")
    nominal, value = ident.array("nominal", (len(names),)), ident.array("value", (len(names),))
    expected = np.concatenate([nominal_values(robot, errors, parametrization), target_nominal(tools or {}, orientation)])
    expected = np.concatenate([expected, nominal[expected.size:]])          # the kinds' unknowns start anywhere
    off = np.flatnonzero(~np.isclose(nominal, expected, rtol=1e-12, atol=1e-9))
    if off.size:
        k = off[0]
        ident.fail("nominal", f"entry {k} ({names[k]}) is {float(nominal[k])!r}, but the file's robot gives "
                              f"{float(expected[k])!r}: "
                              "the nominal values must be those of field 'model.robot'")
    kept = np.flatnonzero((np.array(status) != "identified") & (value != nominal))
    if kept.size:
        k = kept[0]
        ident.fail("value", f"entry {k} ({names[k]}) is {status[k]!r}, so it keeps its nominal value "
                            f"{float(nominal[k])!r}; got {float(value[k])!r}")
    if any(v is not None and not (math.isfinite(v) and v >= 0) for v in std):
        ident.fail("std_error", "standard errors must be finite and >= 0 (or null)")
    if "covariance" in ident.doc:           # files before the spread have none
        k = status.count("identified")
        cov = ident.array("covariance", (k, k))
        if np.any(np.diagonal(cov) < 0) or not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-15):
            ident.fail("covariance", "a symmetric matrix with a diagonal >= 0")
        if ident.number("sigma_mm", 0.0) < 0:
            ident.fail("sigma_mm", "a standard deviation >= 0")
    if "prior_std" in ident.doc:            # files before the unidentified parameters' prior have none
        prior = ident.get("prior_std", list)
        if len(prior) != len(names) or not all(v is None or (isinstance(v, (int, float)) and math.isfinite(v)
                                                             and v > 0) for v in prior):
            ident.fail("prior_std", f"expected {len(names)} standard deviations > 0 or nulls")
        if any(v is not None and s == "identified" for v, s in zip(prior, status)):
            ident.fail("prior_std", "a prior only for parameters that are not identified (null for the others)")
        if status.count("identified"):     # with none identified the matrix has no rows: []
            ident.array("prior_absorbed", (status.count("identified"), sum(v is not None for v in prior)))
    return Identification.from_dict(ident.doc)
