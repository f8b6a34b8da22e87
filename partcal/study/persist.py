"""Model files: versioned plain JSON for every model kind, checked for meaning on loading.

No pickle and nothing executable: a model file from elsewhere can only hold
numbers and names. Loading checks the format name, the version and every
field, and refuses a damaged or foreign file with one message naming the
file and the field. Floats are written with ``repr`` precision, so a loaded
model predicts bit for bit what the saved one did. A file carries a
``checksum`` of its content, so a number changed after writing is refused.

Kinds: ``global`` (a series ``ErrorModel``), ``partitioned`` (regions of
series models or Gaussian processes), ``gaussian_process`` and
``kinematic`` (identified parameters, with an optional ``residual`` model
stored the same way). Version 2 added the last two kinds, GP regions and the
joint-space ``input_map`` of partitioned models; version 1 files (partcal
0.1) still load. Files keep the training inputs (``train_inputs``, for
``distance_to_data``); without them the distance falls back to the distance
outside the data's boxes.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.base import clone

from .. import __version__
from .._io import atomic_write
from ..errors import ModelFileError, PartcalError
from ..models.angles import InputMap
from ..models.bases import Basis, Scaling, varying_inputs
from ..models.gp import HYPERPARAMETERS, KERNELS, NUS, GaussianProcessErrorModel
from ..models.kinematic import (
    STATUSES,
    Identification,
    KinematicModel,
    nominal_values,
    parameter_names,
    robot_with,
)
from ..models.partition import Partition
from ..models.partitioned import PartitionedErrorModel
from ..models.series import FITNESSES, SOLVERS, ErrorModel
from ..robot.description import MAX_JOINTS, robot_from_dict, robot_to_dict
from ..robot.kinematics import Robot

FORMAT = "partcal-model"
VERSION = 2
READABLE = (1, 2)
KINDS = ("global", "partitioned", "gaussian_process", "kinematic")


def model_to_dict(model, *, name: str = "", robot: Robot | None = None, extra: dict | None = None) -> dict:
    """The JSON-ready description of any fitted partcal error model."""
    out = {"format": FORMAT, "version": VERSION, "partcal_version": __version__, "name": name,
           "robot": robot_to_dict(robot) if robot is not None else None}
    out.update(_body(model))
    if getattr(model, "train_inputs_", None) is not None:
        out["train_inputs"] = model.train_inputs_.tolist()
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
            "hyper_samples": None if m.hyper_samples is None else int(m.hyper_samples),
            "hyperparameters": m.hyperparameters, "region_overlap": float(m.region_overlap),
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


def checksum(doc: dict) -> str:
    """SHA-256 of a model document without its ``checksum`` field (canonical JSON: sorted keys)."""
    body = {k: v for k, v in doc.items() if k != "checksum"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def save_model(model, path: str | Path, **kwargs) -> None:
    """Write a model file atomically (see :func:`model_to_dict` for the keywords).

    The file carries a ``checksum`` of its content: a number changed by hand
    (or by a damaged copy) is refused on loading instead of predicting
    silently wrong errors. Delete the field to accept deliberate edits; the
    meaning checks still apply.
    """
    doc = model_to_dict(model, **kwargs)
    doc["checksum"] = checksum(doc)
    text = json.dumps(doc, indent=1)
    with atomic_write(path) as handle:
        handle.write(text + "\n")


def load_model(path: str | Path) -> tuple[Any, dict]:
    """Read a model file; return ``(model, document)``. Raises :class:`ModelFileError`."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"), object_pairs_hook=_no_duplicates)
    except _DuplicateKey as exc:
        raise ModelFileError(f"{path}: field {exc.args[0]!r} appears twice in one object") from None
    except FileNotFoundError:
        raise ModelFileError(f"{path}: no such model file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelFileError(f"{path}: cannot read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise ModelFileError(f"{path}: not a partcal model file (invalid JSON at line {exc.lineno}: {exc.msg})") from None
    except (ValueError, RecursionError) as exc:      # a 5,000-digit number; lists nested 100,000 deep
        raise ModelFileError(f"{path}: not a partcal model file ({str(exc).split(';')[0] or 'nested too deep'})"
                             ) from None
    return model_from_dict(doc, source=str(path)), doc


class _DuplicateKey(Exception):
    pass


def _no_duplicates(pairs: list[tuple[str, Any]]) -> dict:
    """JSON objects with a key twice are refused (the standard reader silently keeps the last)."""
    out = {}
    for key, value in pairs:
        if key in out:
            raise _DuplicateKey(key)
        out[key] = value
    return out


def model_from_dict(doc: Any, source: str = "model") -> Any:
    """Rebuild a fitted model from :func:`model_to_dict` output, checking every field for meaning.

    Beyond types and shapes: scales are positive and agree with the data
    bounds they came from, the terms are exactly those of the basis and
    degree, region and tree indices are in range, kernel widths are positive,
    a series model predicts finite, plausible errors (under 1 km) across the
    box of its data, and a kinematic model agrees with its robot (nominal
    values, unidentified parameters kept nominal, a tool shift under the
    robot's reach). A file that fails any of these is refused naming the
    field, never used to predict ``-inf`` or ``1e300``.
    """
    r = _Reader(doc, source, "")
    if r.get("format", str) != FORMAT:
        r.fail("format", f"expected {FORMAT!r}; this is not a partcal model file")
    if "checksum" in doc and r.get("checksum", str) != checksum(doc):
        r.fail("checksum", "does not match the content: the file was changed after partcal wrote it (delete "
                           "this field to accept a deliberate edit)")
    version = r.get("version", int)
    if version not in READABLE:
        r.fail("version", f"this partcal reads versions {', '.join(map(str, READABLE))}; the file has version "
                          f"{version} (written by partcal {doc.get('partcal_version', '?')})")
    if r.get("robot", (dict, type(None))) is not None:
        try:
            robot = robot_from_dict(doc["robot"], source=f"{source}: robot")
        except PartcalError as exc:
            raise ModelFileError(str(exc)) from None
        if r.doc.get("inputs") == "joint" and robot.n_joints != r.doc.get("n_inputs"):
            r.fail("n_inputs", f"a joint model of robot {robot.name!r} takes {robot.n_joints} joints; "
                               f"got {r.doc.get('n_inputs')!r}")
    model = _from_body(r)
    model.train_inputs_ = _train_inputs(r, model.n_features_in_)
    _check_plausible(r, model)
    return model._prepare()


def _from_body(r: "_Reader") -> Any:
    kind = r.choice("kind", KINDS)
    n_in, n_out = r.integer("n_inputs", 1, MAX_JOINTS), r.integer("n_outputs", 1, 3)
    inputs = r.choice("inputs", ("cartesian", "joint"))
    if kind == "global":
        return _global_from(r.sub("model"), inputs, n_in, n_out)
    if kind == "gaussian_process":
        return _gp_from(r.sub("model"), inputs, n_in, n_out)
    if kind == "kinematic":
        return _kinematic_from(r.sub("model"), n_in, n_out)
    return _partitioned_from(r, inputs, n_in, n_out)


def _partitioned_from(r: "_Reader", inputs: str, n_in: int, n_out: int) -> PartitionedErrorModel:
    blend = r.sub("blend")
    model = PartitionedErrorModel(blend=blend.choice("method", ("gaussian", "hard")),
                                  blend_width=blend.number("width", 0.6, 10.0))
    local_kind = r.choice("local_kind", ("series", "gaussian_process")) if "local_kind" in r.doc else "series"
    model.input_map_ = _input_map(r, "input_map", n_in) if r.doc.get("input_map") is not None else None
    p = r.sub("partition")
    m = p.integer("n_regions", 1)
    model.region_bounds_ = r.array("region_bounds", (m, 2, n_in))
    if np.any(model.region_bounds_[:, 0] > model.region_bounds_[:, 1]):
        r.fail("region_bounds", "a low bound exceeds its high bound")
    # the partition's coordinates: the scaled varying joints under an input map, else the inputs themselves
    d = max(model.input_map_.n_active, 1) if model.input_map_ is not None else n_in
    if "active" in p.doc:
        active = p.array("active", (d,), bool)
    else:        # partcal 0.1 blended along the axes its regions span
        active = varying_inputs(model.region_bounds_.reshape(-1, n_in))
    partition = _partition_from(p, m, d, active)
    regions = r.get("regions", list)
    if len(regions) != m:
        r.fail("regions", f"expected {m} region models (partition.n_regions); got {len(regions)}")
    read = _gp_from if local_kind == "gaussian_process" else _global_from
    model.models_ = [read(r.sub(f"regions[{i}]", item), inputs, n_in, n_out) for i, item in enumerate(regions)]
    model.partition_ = partition
    model.region_counts_ = r.array("region_counts", (m,), int)
    model.min_samples_ = r.integer("min_samples", 1)
    if np.any(model.region_counts_ < 0):
        r.fail("region_counts", "counts must be >= 0")
    model.n_features_in_ = n_in
    model.n_outputs_ = n_out
    model._y_1d = False
    first = model.models_[0]
    model.local = clone(first) if local_kind == "gaussian_process" else ErrorModel(inputs=inputs)
    return model


def _partition_from(p: "_Reader", m: int, n_in: int, active: np.ndarray) -> Partition:
    # n_in: the dimension of the partition's coordinates
    """A partition, with every index in range and every kernel width positive on the varying axes.

    Lists of candidate kernels (``cand``, ``own``) in files of partcal 0.1 are
    ignored: the lookup is rebuilt from the kernels.
    """
    kind = p.choice("kind", ("octree", "kmeans"))
    centres = p.array("centres", (None, n_in))
    k = centres.shape[0]
    sigmas = p.array("sigmas", (k, n_in))
    if not active.any():
        p.fail("active", "no input varies: there is nothing to partition")
    if np.any(sigmas[:, active] <= 0):
        p.fail("sigmas", "kernel widths must be > 0 on the varying axes")
    kernel_region = p.array("kernel_region", (k,), int)
    if np.any((kernel_region < 0) | (kernel_region >= m)) or np.unique(kernel_region).size != m:
        p.fail("kernel_region", f"must map the {k} kernels onto all regions 0..{m - 1}")
    if kind == "kmeans":
        if k != m or np.any(kernel_region != np.arange(m)):
            p.fail("kernel_region", f"a k-means partition has one kernel per region: 0..{m - 1}")
        return Partition("kmeans", m, centres, sigmas, kernel_region, active=active)
    boxes = p.array("boxes", (k, 2, n_in))
    if np.any(boxes[:, 0] > boxes[:, 1]):
        p.fail("boxes", "a low corner exceeds its high corner")
    tree = p.sub("tree")
    node_centre = tree.array("centre", (None, n_in))
    nodes, split = node_centre.shape[0], 2 ** int(active.sum())
    child, leaf = tree.array("child", (nodes,), int), tree.array("leaf", (nodes,), int)
    inner = child >= 0
    if np.any(child[inner] + split > nodes) or np.any(child < -1) or np.any(child[inner] <= np.flatnonzero(inner)):
        tree.fail("child", f"child indices must point forward to {split} nodes within the {nodes} nodes")
    if np.any(inner == (leaf >= 0)) or np.any(leaf >= k) or np.any(leaf < -1):
        tree.fail("leaf", f"every node is either split (child >= 0) or a leaf with an index in 0..{k - 1}")
    return Partition("octree", m, centres, sigmas, kernel_region, active=active, boxes=boxes,
                     tree={"centre": node_centre, "child": child, "leaf": leaf})


def _train_inputs(r: "_Reader", n_in: int) -> np.ndarray | None:
    """The training inputs (for ``distance_to_data``), or None in files written before they were kept."""
    if "train_inputs" not in r.doc:
        return None
    return r.array("train_inputs", (None, n_in))


def _input_map(r: "_Reader", key: str, n_in: int) -> InputMap:
    m = r.sub(key)
    window = m.get("window", list)
    if len(window) != n_in or not all(w is None or (isinstance(w, (int, float)) and not isinstance(w, bool)
                                                    and np.isfinite(w)) for w in window):
        m.fail("window", f"expected {n_in} numbers or nulls")
    active = m.get("active", list)
    if len(active) != n_in or not all(isinstance(a, bool) for a in active):
        m.fail("active", f"expected {n_in} true/false values")
    scale = m.array("scale", (n_in,))
    if np.any(scale[np.array(active, dtype=bool)] <= 0):
        m.fail("scale", "the scales of the varying inputs must be > 0")
    return InputMap(np.array([np.nan if w is None else w for w in window], dtype=float),
                    m.array("centre", (n_in,)), scale, np.array(active, dtype=bool))


def _gp_from(r: "_Reader", inputs: str, n_in: int, n_out: int) -> GaussianProcessErrorModel:
    kernel, nu = r.choice("kernel", KERNELS), r.get("nu", float)
    if nu not in NUS:
        r.fail("nu", f"expected one of {', '.join(map(str, NUS))}; got {nu!r}")
    imap = _input_map(r, "input_map", n_in)
    d = max(imap.n_active, 1)
    n = len(r.get("x_train", list))
    # the search settings (files written before they existed: how such GPs were fitted then)
    hyper_samples = r.integer("hyper_samples", 20) if r.doc.get("hyper_samples") is not None else None
    shared = r.choice("hyperparameters", HYPERPARAMETERS) if "hyperparameters" in r.doc else "per_region"
    overlap = r.number("region_overlap", 1.0, 3.0) if "region_overlap" in r.doc else 1.0
    model = GaussianProcessErrorModel(inputs=inputs, kernel=kernel, nu=nu, restarts=r.integer("restarts", 0, 20),
                                      hyper_samples=hyper_samples, hyperparameters=shared, region_overlap=overlap)
    model.input_map_ = imap
    model.X_train_ = r.array("x_train", (n, d))
    model.dual_coef_ = r.array("dual_coef", (n, n_out))
    model.y_mean_, model.y_std_ = r.array("y_mean", (n_out,)), r.array("y_std", (n_out,))
    if np.any(model.y_std_ <= 0):
        r.fail("y_std", "the output scales must be > 0")
    model.amplitude_, model.noise_ = r.number("amplitude", 0.0), r.number("noise", 0.0)
    model.length_scale_ = r.array("length_scale", (d,))
    if model.amplitude_ <= 0 or np.any(model.length_scale_ <= 0):
        r.fail("length_scale", "expected a positive amplitude and positive length scales")
    model.log_marginal_likelihood_ = r.number("log_marginal_likelihood")
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
    nominal, value = ident.array("nominal", (len(names),)), ident.array("value", (len(names),))
    expected = nominal_values(robot)
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
    table = Identification.from_dict(ident.doc)
    model = KinematicModel(robot=robot, base=r.get("base", bool), tool=r.get("tool", bool),
                           rcond=r.get("rcond", float))
    model.robot_, model.identification_ = robot, table
    model.identified_robot_ = robot_with(robot, table.value)
    model.data_bounds_ = r.array("data_bounds", (2, n_in))
    if np.any(model.data_bounds_[0] > model.data_bounds_[1]):
        r.fail("data_bounds", "a low bound exceeds its high bound")
    model.active_ = r.array("active", (n_in,), bool)
    model.n_features_in_, model._y_1d = n_in, False
    model.residual_ = None
    if r.doc.get("residual") is not None:
        model.residual_ = _from_body(r.sub("residual"))
        model.residual = model.residual_
    return model


def _global_from(r: "_Reader", inputs: str, n_in: int, n_out: int) -> ErrorModel:
    basis = r.choice("basis", ("polynomial", "fourier"))
    order = r.integer("order", 1, 8)
    cross = r.get("cross_terms", bool)
    if cross and basis != "polynomial":
        r.fail("cross_terms", "must be false for the fourier basis")
    bounds = r.array("data_bounds", (2, n_in))
    if np.any(bounds[0] > bounds[1]):
        r.fail("data_bounds", "a low bound exceeds its high bound")
    s = r.sub("scaling")
    scaling = Scaling(s.array("centre", (n_in,)), s.array("scale", (n_in,)), s.array("active", (n_in,), bool))
    expected = Scaling.fit(bounds)          # what the fit derived from the same bounds
    if not np.array_equal(scaling.active, expected.active):
        s.fail("active", f"must mark the inputs that vary within data_bounds: {expected.active.tolist()}")
    for key in ("centre", "scale"):
        if not np.allclose(getattr(scaling, key), getattr(expected, key), rtol=1e-12, atol=0):
            s.fail(key, f"disagrees with data_bounds (expected {getattr(expected, key).tolist()})")
    basis_ = Basis(basis, inputs, order, cross)
    want = basis_.terms(scaling)
    raw_terms = r.get("terms", list)
    terms = _terms(r, raw_terms, basis)
    if terms != want:
        r.fail("terms", f"are not the {len(want)} terms of a {basis} basis of order {order} over the varying "
                        f"inputs (exponents beyond the degree, or a basis that does not match)")
    model = ErrorModel(inputs=inputs, basis=basis, degree=order if basis == "polynomial" else 1,
                       harmonics=order if basis == "fourier" else 1, cross_terms=cross,
                       solver=r.choice("solver", SOLVERS), fitness=r.choice("fitness", FITNESSES))
    model.coef_, model.scaling_, model.terms_, model.basis_ = r.array("coef", (len(terms), n_out)), scaling, terms, basis_
    model.n_features_in_ = n_in
    model._y_1d = False
    model.data_bounds_ = bounds
    model.train_rms_ = r.array("train_rms", (n_out,))
    model.lstsq_rms_ = r.array("lstsq_rms", (n_out,))
    model.rms_ratio_ = r.number("rms_ratio", 0.0)
    if np.any(model.train_rms_ < 0) or np.any(model.lstsq_rms_ < 0):
        r.fail("train_rms", "RMS values must be >= 0")
    model.swarm_results_ = []
    return model


def _terms(r: "_Reader", raw: list, basis: str) -> list[tuple]:
    """Terms as tuples, with the element types checked (no strings for numbers, no booleans)."""
    out = []
    for i, t in enumerate(raw):
        ok = isinstance(t, list) and (
            all(_is_int(k) for k in t) if basis == "polynomial"
            else len(t) == 3 and t[0] in ("1", "cos", "sin") and _is_int(t[1]) and _is_int(t[2]))
        if not ok:
            r.fail(f"terms[{i}]", "expected a list of integer exponents" if basis == "polynomial"
                   else "expected [\"1\"|\"cos\"|\"sin\", input, harmonic]")
        out.append(tuple(t) if basis == "polynomial" else (t[0], int(t[1]), int(t[2])))
    return out


def _is_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _check_plausible(r: "_Reader", model, limit_mm: float = 1e6) -> None:
    """Series models and Gaussian processes (alone, as regions or as a kinematic model's residual) must
    predict finite errors under ``limit_mm`` at the corners and centre of their data box."""
    if isinstance(model, KinematicModel):
        _check_kinematic_plausible(r, model)
        if model.residual_ is not None:
            _check_plausible(r.sub("model").sub("residual"), model.residual_, limit_mm)
        return
    regions = isinstance(model, PartitionedErrorModel)
    field = "coef" if all(isinstance(m, ErrorModel) for m in (model.models_ if regions else [model])) else "dual_coef"
    with np.errstate(all="ignore"):
        for k, local in enumerate(model.models_ if regions else [model]):
            points = _box_points(*local.data_bounds_)
            pred = local._predict_trusted(points) if isinstance(local, ErrorModel) else local.predict(points)
            if not np.all(np.isfinite(pred)) or np.abs(pred).max() > limit_mm:
                worst = f"{np.abs(pred).max():.3g}" if np.all(np.isfinite(pred)) else "a non-finite value"
                r.fail(f"regions[{k}].{field}" if regions else f"model.{field}",
                       f"predicts {worst} mm within the box of its data (limit {limit_mm:g} mm): "
                       "the fitted numbers are damaged")


def _box_points(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The corners of the box ``[lo, hi]`` (of its first 10 inputs, the others at ``lo``) and its centre."""
    n_in = lo.size
    corners = lo + (hi - lo) * ((np.arange(2 ** min(n_in, 10))[:, None] >> np.arange(n_in)) & 1)
    return np.vstack([corners, (lo + hi) / 2])


def _check_kinematic_plausible(r: "_Reader", model: KinematicModel) -> None:
    """The identified robot must move the tool by less than the robot's reach from where the nominal
    robot puts it, at the corners and centre of the joint box of the data (else the values are damaged)."""
    poses = _box_points(*model.data_bounds_)
    with np.errstate(all="ignore"):
        shift = np.linalg.norm(model.identified_robot_.positions(poses) - model.robot_.positions(poses), axis=1)
    reach = model.robot_.reach_mm
    if not np.all(np.isfinite(shift)) or shift.max() > reach:
        worst = f"{shift.max():.4g} mm" if np.all(np.isfinite(shift)) else "a non-finite distance"
        r.sub("model").sub("identification").fail(
            "value", f"the identified robot moves the tool by {worst} within the joint box of its data, more "
                     f"than the robot's reach ({reach:.0f} mm): the identified values are damaged")


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
        kinds = kind if isinstance(kind, tuple) else (kind,)
        ok = isinstance(value, kinds) and not (isinstance(value, bool) and bool not in kinds)
        if float in kinds and _is_int(value):
            ok, value = True, float(value)
        if not ok:
            names = " or ".join("null" if k is type(None) else k.__name__ for k in kinds)
            self.fail(key, f"expected {names}; got {type(value).__name__} {value!r}"[:200])
        return value

    def choice(self, key: str, allowed: tuple[str, ...]) -> str:
        value = self.get(key, str)
        if value not in allowed:
            self.fail(key, f"expected one of {', '.join(map(repr, allowed))}; got {value!r}")
        return value

    def integer(self, key: str, low: int, high: int | None = None) -> int:
        value = self.get(key, int)
        if value < low or (high is not None and value > high):
            self.fail(key, f"expected an integer in [{low}, {high if high is not None else 'inf'}]; got {value}")
        return value

    def number(self, key: str, low: float | None = None, high: float | None = None) -> float:
        value = self.get(key, float)
        if not np.isfinite(value) or (low is not None and value < low) or (high is not None and value > high):
            self.fail(key, f"expected a finite number in [{low}, {high}]; got {value!r}")
        return value

    def sub(self, key: str, value: Any = None) -> "_Reader":
        doc = self.get(key, dict) if value is None else value
        return _Reader(doc, self.source, self.path(key) if value is None else key)

    def array(self, key: str, shape: tuple, kind=float) -> np.ndarray:
        """A nested list of ``kind`` (float: numbers, not strings or booleans; int; bool) of ``shape``.

        ``None`` in ``shape`` accepts any size on that axis.
        """
        value = self.get(key, list)
        check = {float: lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
                 int: _is_int, bool: lambda v: isinstance(v, bool)}[kind]

        def walk(v, depth):
            if depth == len(shape):
                if not check(v):
                    self.fail(key, f"expected {kind.__name__} values; found {type(v).__name__} {v!r}"[:200])
                return
            if not isinstance(v, list):
                self.fail(key, f"expected nested lists of shape {shape}; found {type(v).__name__}")
            for item in v:
                walk(item, depth + 1)

        walk(value, 0)
        try:
            arr = np.array(value, dtype=kind if kind is not int else np.intp)
        except (TypeError, ValueError):
            self.fail(key, f"expected a regular array of shape {shape}")
        if arr.ndim != len(shape) or any(w is not None and w != a for w, a in zip(shape, arr.shape)):
            want = tuple("n" if w is None else w for w in shape)
            self.fail(key, f"expected shape {want}; got shape {arr.shape}")
        if kind is float and not np.all(np.isfinite(arr)):
            self.fail(key, "holds a non-finite value (NaN or infinity)")
        return arr
