"""Model files: versioned plain JSON for every model kind.

No pickle and nothing executable: a model file from elsewhere can only hold
numbers and names. Loading checks the format name, the version and every
field, and refuses a damaged or foreign file with one message naming the
file and the field. Floats are written with ``repr`` precision, so a loaded
model predicts bit for bit what the saved one did.

Kinds: ``global`` (a series ``ErrorModel``), ``partitioned`` (regions of
series models or Gaussian processes), ``gaussian_process`` and
``kinematic`` (identified parameters, with an optional ``residual`` model
stored the same way). Version 2 added the last two kinds, GP regions and the
joint-space ``input_map`` of partitioned models; version 1 files still load.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .._io import atomic_write
from ..errors import ModelFileError
from ..models.angles import InputMap
from ..models.bases import Basis, Scaling
from ..models.gp import KERNELS, NUS, GaussianProcessErrorModel
from ..models.kinematic import STATUSES, Identification, KinematicModel, parameter_names, robot_with
from ..models.partition import Partition
from ..models.partitioned import PartitionedErrorModel
from ..models.series import ErrorModel
from ..robot.kinematics import Robot, robot_from_dict, robot_to_dict

FORMAT = "partcal-model"
VERSION = 2
READABLE = (1, 2)


def model_to_dict(model, *, name: str = "", robot: Robot | None = None, extra: dict | None = None) -> dict:
    """The JSON-ready description of any fitted partcal error model."""
    out = {"format": FORMAT, "version": VERSION, "partcal_version": __version__, "name": name,
           "robot": robot_to_dict(robot) if robot is not None else None}
    out.update(_body(model))
    out["fit"] = extra or {}
    return out


def _body(model) -> dict:
    """Kind, inputs and the fitted numbers of a model (the part a residual model repeats)."""
    if isinstance(model, PartitionedErrorModel):
        local = model.models_[0]
        gp = isinstance(local, GaussianProcessErrorModel)
        imap = getattr(model, "input_map_", None)
        return dict(kind="partitioned", inputs=local.inputs, n_inputs=int(model.n_features_in_),
                    n_outputs=int(model.n_outputs_), local_kind="gaussian_process" if gp else "series",
                    input_map=imap.to_dict() if imap is not None else None,
                    blend={"method": model.blend, "width": float(model.blend_width)},
                    partition=model.partition_.to_dict(),
                    region_bounds=model.region_bounds_.tolist(), region_counts=model.region_counts_.tolist(),
                    min_samples=int(model.min_samples_),
                    regions=[_gp_dict(m) if gp else _global_dict(m) for m in model.models_])
    if isinstance(model, ErrorModel):
        return dict(kind="global", inputs=model.inputs, n_inputs=int(model.n_features_in_),
                    n_outputs=int(model.coef_.shape[1]), model=_global_dict(model))
    if isinstance(model, GaussianProcessErrorModel):
        return dict(kind="gaussian_process", inputs=model.inputs, n_inputs=int(model.n_features_in_),
                    n_outputs=int(model.dual_coef_.shape[1]), model=_gp_dict(model))
    if isinstance(model, KinematicModel):
        residual = _body(model.residual_) if model.residual_ is not None else None
        return dict(kind="kinematic", inputs="joint", n_inputs=int(model.n_features_in_), n_outputs=3,
                    model={"robot": robot_to_dict(model.robot_), "base": bool(model.base),
                           "tool": bool(model.tool), "rcond": float(model.rcond),
                           "identification": model.identification_.to_dict(),
                           "data_bounds": model.data_bounds_.tolist(), "active": model.active_.tolist(),
                           "residual": residual})
    raise ModelFileError(f"cannot save a {type(model).__name__}: expected an ErrorModel, a "
                         "PartitionedErrorModel, a GaussianProcessErrorModel or a KinematicModel")


def _gp_dict(m: GaussianProcessErrorModel) -> dict:
    return {"kernel": m.kernel, "nu": float(m.nu), "restarts": int(m.restarts),
            "input_map": m.input_map_.to_dict(), "x_train": m.X_train_.tolist(),
            "dual_coef": m.dual_coef_.tolist(), "y_mean": m.y_mean_.tolist(), "y_std": m.y_std_.tolist(),
            "amplitude": m.amplitude_, "length_scale": m.length_scale_.tolist(), "noise": m.noise_,
            "log_marginal_likelihood": m.log_marginal_likelihood_, "data_bounds": m.data_bounds_.tolist()}


def _global_dict(m: ErrorModel) -> dict:
    return {"basis": m.basis, "order": m.basis_.order, "cross_terms": bool(m.cross_terms),
            "solver": m.solver, "fitness": m.fitness, "scaling": m.scaling_.to_dict(),
            "terms": [list(t) for t in m.terms_], "coef": m.coef_.tolist(),
            "data_bounds": m.data_bounds_.tolist(), "train_rms": m.train_rms_.tolist(),
            "lstsq_rms": m.lstsq_rms_.tolist(), "rms_ratio": m.rms_ratio_}


def save_model(model, path: str | Path, **kwargs) -> None:
    """Write a model file atomically (see :func:`model_to_dict` for the keywords)."""
    text = json.dumps(model_to_dict(model, **kwargs), indent=1)
    with atomic_write(path) as handle:
        handle.write(text + "\n")


def load_model(path: str | Path) -> tuple[Any, dict]:
    """Read a model file; return ``(model, document)``. Raises :class:`ModelFileError`."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ModelFileError(f"{path}: no such model file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(f"{path}: cannot read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{path}: not a partcal model file (invalid JSON at line {exc.lineno}: {exc.msg})") from None
    return model_from_dict(doc, source=str(path)), doc


def model_from_dict(doc: Any, source: str = "model") -> Any:
    """Rebuild a fitted model from :func:`model_to_dict` output, checking every field."""
    r = _Reader(doc, source, "")
    if r.get("format", str) != FORMAT:
        r.fail("format", f"expected {FORMAT!r}; this is not a partcal model file")
    version = r.get("version", int)
    if version not in READABLE:
        r.fail("version", f"this partcal reads versions {', '.join(map(str, READABLE))}; the file has version "
                          f"{version} (written by partcal {doc.get('partcal_version', '?')})")
    if doc.get("robot") is not None:
        try:
            robot_from_dict(r.get("robot", dict), source=f"{source}: robot")
        except Exception as exc:  # noqa: BLE001 - any damage in the robot section is a file error
            raise ModelFileError(str(exc)) from None
    return _from_body(r)


def _from_body(r: "_Reader") -> Any:
    kind = r.get("kind", str)
    n_in, n_out = r.get("n_inputs", int), r.get("n_outputs", int)
    inputs = r.get("inputs", str)
    if inputs not in ("cartesian", "joint"):
        r.fail("inputs", f"expected 'cartesian' or 'joint'; got {inputs!r}")
    if kind == "global":
        return _global_from(r.sub("model"), inputs, n_in, n_out)
    if kind == "gaussian_process":
        return _gp_from(r.sub("model"), inputs, n_in, n_out)
    if kind == "kinematic":
        return _kinematic_from(r.sub("model"), n_in, n_out)
    if kind == "partitioned":
        return _partitioned_from(r, inputs, n_in, n_out)
    r.fail("kind", f"expected 'global', 'partitioned', 'gaussian_process' or 'kinematic'; got {kind!r}")


def _partitioned_from(r: "_Reader", inputs: str, n_in: int, n_out: int) -> PartitionedErrorModel:
    try:
        partition = Partition.from_dict(r.get("partition", dict))
    except (KeyError, TypeError, ValueError) as exc:
        r.fail("partition", f"damaged ({type(exc).__name__}: {exc})")
    regions = r.get("regions", list)
    if len(regions) != partition.n_regions:
        r.fail("regions", f"expected {partition.n_regions} region models; got {len(regions)}")
    local_kind = r.get("local_kind", str) if "local_kind" in r.doc else "series"      # version 1: series
    if local_kind not in ("series", "gaussian_process"):
        r.fail("local_kind", f"expected 'series' or 'gaussian_process'; got {local_kind!r}")
    read = _gp_from if local_kind == "gaussian_process" else _global_from
    blend = r.sub("blend")
    model = PartitionedErrorModel(blend=blend.get("method", str), blend_width=blend.get("width", float))
    model.models_ = [read(r.sub(f"regions[{i}]", item), inputs, n_in, n_out) for i, item in enumerate(regions)]
    model.input_map_ = _input_map(r, "input_map", n_in) if r.doc.get("input_map") is not None else None
    model.partition_ = partition
    model.region_bounds_ = r.array("region_bounds", (partition.n_regions, 2, n_in))
    model.region_counts_ = np.asarray(r.get("region_counts", list), dtype=np.intp)
    model.min_samples_ = r.get("min_samples", int)
    model.n_features_in_ = n_in
    model.n_outputs_ = n_out
    model._y_1d = False
    first = model.models_[0]
    model.local = GaussianProcessErrorModel(inputs=inputs, kernel=first.kernel, nu=first.nu) \
        if local_kind == "gaussian_process" else ErrorModel(inputs=inputs)
    return model


def _input_map(r: "_Reader", key: str, n_in: int) -> InputMap:
    m = r.sub(key)
    window = m.get("window", list)
    if len(window) != n_in or not all(w is None or (isinstance(w, (int, float)) and not isinstance(w, bool)
                                                    and np.isfinite(w)) for w in window):
        m.fail("window", f"expected {n_in} numbers or nulls")
    active = m.get("active", list)
    if len(active) != n_in or not all(isinstance(a, bool) for a in active):
        m.fail("active", f"expected {n_in} true/false values")
    return InputMap(np.array([np.nan if w is None else w for w in window], dtype=float),
                    m.array("centre", (n_in,)), m.array("scale", (n_in,)), np.array(active, dtype=bool))


def _gp_from(r: "_Reader", inputs: str, n_in: int, n_out: int) -> GaussianProcessErrorModel:
    kernel, nu = r.get("kernel", str), r.get("nu", float)
    if kernel not in KERNELS:
        r.fail("kernel", f"expected one of {', '.join(KERNELS)}; got {kernel!r}")
    if nu not in NUS:
        r.fail("nu", f"expected one of {', '.join(map(str, NUS))}; got {nu!r}")
    imap = _input_map(r, "input_map", n_in)
    d = max(imap.n_active, 1)
    n = len(r.get("x_train", list))
    model = GaussianProcessErrorModel(inputs=inputs, kernel=kernel, nu=nu, restarts=r.get("restarts", int))
    model.input_map_ = imap
    model.X_train_ = r.array("x_train", (n, d))
    model.dual_coef_ = r.array("dual_coef", (n, n_out))
    model.y_mean_, model.y_std_ = r.array("y_mean", (n_out,)), r.array("y_std", (n_out,))
    model.amplitude_, model.noise_ = r.get("amplitude", float), r.get("noise", float)
    model.length_scale_ = r.array("length_scale", (d,))
    if model.amplitude_ <= 0 or np.any(model.length_scale_ <= 0):
        r.fail("length_scale", "expected a positive amplitude and positive length scales")
    model.log_marginal_likelihood_ = r.get("log_marginal_likelihood", float)
    model.data_bounds_ = r.array("data_bounds", (2, n_in))
    model.n_features_in_, model.n_train_, model._y_1d = n_in, n, False
    return model._prepare()


def _kinematic_from(r: "_Reader", n_in: int, n_out: int) -> KinematicModel:
    try:
        robot = robot_from_dict(r.get("robot", dict), source=f"{r.source}: field {r.path('robot')!r}")
    except Exception as exc:  # noqa: BLE001 - any damage in the robot section is a file error
        raise ModelFileError(str(exc)) from None
    if robot.n_joints != n_in or n_out != 3:
        r.fail("robot", f"a robot with {n_in} joints and 3 outputs; got {robot.n_joints} joints, {n_out} outputs")
    ident = r.sub("identification")
    names = [n for n, _ in parameter_names(robot)]
    if ident.get("names", list) != names:
        ident.fail("names", f"expected the {len(names)} parameters of {robot.name} ({names[0]} ... {names[-1]})")
    status = ident.get("status", list)
    if len(status) != len(names) or any(s not in STATUSES for s in status):
        ident.fail("status", f"expected {len(names)} of {', '.join(STATUSES)}")
    std = ident.get("std_error", list)
    if len(std) != len(names) or not all(v is None or isinstance(v, (int, float)) for v in std):
        ident.fail("std_error", f"expected {len(names)} numbers or nulls")
    ident.array("nominal", (len(names),))
    ident.array("value", (len(names),))
    table = Identification.from_dict(ident.doc)
    model = KinematicModel(robot=robot, base=r.get("base", bool), tool=r.get("tool", bool),
                           rcond=r.get("rcond", float))
    model.robot_, model.identification_ = robot, table
    model.identified_robot_ = robot_with(robot, table.value)
    model.data_bounds_ = r.array("data_bounds", (2, n_in))
    model.active_ = r.array("active", (n_in,)).astype(bool)
    model.n_features_in_, model._y_1d = n_in, False
    model.residual_ = None
    if r.doc.get("residual") is not None:
        model.residual_ = _from_body(r.sub("residual"))
        model.residual = model.residual_
    return model


def _global_from(r: "_Reader", inputs: str, n_in: int, n_out: int) -> ErrorModel:
    basis = r.get("basis", str)
    if basis not in ("polynomial", "fourier"):
        r.fail("basis", f"expected 'polynomial' or 'fourier'; got {basis!r}")
    order = r.get("order", int)
    cross = r.get("cross_terms", bool)
    s = r.sub("scaling")
    scaling = Scaling(s.array("centre", (n_in,)), s.array("scale", (n_in,)),
                      s.array("active", (n_in,)).astype(bool))
    raw_terms = r.get("terms", list)
    terms = [tuple(t) if basis == "polynomial" else (t[0], int(t[1]), int(t[2])) for t in raw_terms]
    if basis == "polynomial" and not all(len(t) == n_in and all(isinstance(k, int) for k in t) for t in terms):
        r.fail("terms", f"expected lists of {n_in} integer exponents")
    coef = r.array("coef", (len(terms), n_out))
    model = ErrorModel(inputs=inputs, basis=basis, degree=order if basis == "polynomial" else 1,
                       harmonics=order if basis == "fourier" else 1, cross_terms=cross,
                       solver=r.get("solver", str), fitness=r.get("fitness", str))
    model.coef_, model.scaling_, model.terms_ = coef, scaling, terms
    model.basis_ = Basis(basis, inputs, order, cross)
    model.n_features_in_ = n_in
    model._y_1d = False
    model.data_bounds_ = r.array("data_bounds", (2, n_in))
    model.train_rms_ = r.array("train_rms", (n_out,))
    model.lstsq_rms_ = r.array("lstsq_rms", (n_out,))
    model.rms_ratio_ = r.get("rms_ratio", float)
    model.swarm_results_ = []
    return model


class _Reader:
    """Typed access to one JSON object, failing with the file and the field path."""

    def __init__(self, doc: Any, source: str, where: str):
        self.doc, self.source, self.where = doc, source, where
        if not isinstance(doc, dict):
            self.fail("", f"expected an object; got {type(doc).__name__}")

    def path(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def fail(self, key: str, message: str):
        raise ModelFileError(f"{self.source}: field {self.path(key) or 'top level'!r}: {message}")

    def get(self, key: str, kind):
        if key not in self.doc:
            self.fail(key, "missing")
        value = self.doc[key]
        ok = isinstance(value, kind) and not (kind in (int, float) and isinstance(value, bool))
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            ok, value = True, float(value)
        if not ok:
            self.fail(key, f"expected {kind.__name__}; got {type(value).__name__}")
        return value

    def sub(self, key: str, value: Any = None) -> "_Reader":
        doc = self.get(key, dict) if value is None else value
        return _Reader(doc, self.source, self.path(key) if value is None else key)

    def array(self, key: str, shape: tuple) -> np.ndarray:
        try:
            arr = np.asarray(self.get(key, list), dtype=float)
        except (TypeError, ValueError):
            self.fail(key, "expected an array of numbers")
        if arr.shape != shape:
            self.fail(key, f"expected finite numbers of shape {shape}; got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            self.fail(key, "holds a non-finite value (NaN or infinity)")
        return arr
