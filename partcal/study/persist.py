"""Model files: versioned plain JSON for global and partitioned models.

No pickle and nothing executable: a model file from elsewhere can only hold
numbers and names. Files keep the training inputs (``train_inputs``, for
``distance_to_data``) and the partition's varying axes (``partition.active``);
files written before either was kept still load: without ``train_inputs``
the distance to the data falls back to the distance outside the data's boxes,
and without ``active`` the varying axes are read off ``region_bounds``. Loading checks the format name, the version and every
field, and refuses a damaged or foreign file with one message naming the
file and the field. Floats are written with ``repr`` precision, so a loaded
model predicts bit for bit what the saved one did.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .._io import atomic_write
from ..errors import ModelFileError
from ..models.bases import Basis, Scaling, varying_inputs
from ..models.partition import Partition
from ..models.partitioned import PartitionedErrorModel
from ..models.series import ErrorModel
from ..robot.kinematics import Robot, robot_from_dict, robot_to_dict

FORMAT = "partcal-model"
VERSION = 1


def model_to_dict(model, *, name: str = "", robot: Robot | None = None, extra: dict | None = None) -> dict:
    """The JSON-ready description of a fitted ``ErrorModel`` or ``PartitionedErrorModel``."""
    out = {"format": FORMAT, "version": VERSION, "partcal_version": __version__, "name": name,
           "robot": robot_to_dict(robot) if robot is not None else None}
    if isinstance(model, PartitionedErrorModel):
        local = model.models_[0]
        out.update(kind="partitioned", inputs=local.inputs, n_inputs=int(model.n_features_in_),
                   n_outputs=int(local.coef_.shape[1]),
                   blend={"method": model.blend, "width": float(model.blend_width)},
                   partition=model.partition_.to_dict(),
                   region_bounds=model.region_bounds_.tolist(), region_counts=model.region_counts_.tolist(),
                   min_samples=int(model.min_samples_),
                   regions=[_global_dict(m) for m in model.models_])
    elif isinstance(model, ErrorModel):
        out.update(kind="global", inputs=model.inputs, n_inputs=int(model.n_features_in_),
                   n_outputs=int(model.coef_.shape[1]), model=_global_dict(model))
    else:
        raise ModelFileError(f"cannot save a {type(model).__name__}: expected an ErrorModel or a "
                             "PartitionedErrorModel")
    if getattr(model, "train_inputs_", None) is not None:
        out["train_inputs"] = model.train_inputs_.tolist()
    out["fit"] = extra or {}
    return out


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
    if version != VERSION:
        r.fail("version", f"this partcal reads version {VERSION}; the file has version {version} "
                          f"(written by partcal {doc.get('partcal_version', '?')})")
    kind = r.get("kind", str)
    n_in, n_out = r.get("n_inputs", int), r.get("n_outputs", int)
    inputs = r.get("inputs", str)
    if inputs not in ("cartesian", "joint"):
        r.fail("inputs", f"expected 'cartesian' or 'joint'; got {inputs!r}")
    if doc.get("robot") is not None:
        try:
            robot_from_dict(r.get("robot", dict), source=f"{source}: robot")
        except Exception as exc:  # noqa: BLE001 - any damage in the robot section is a file error
            raise ModelFileError(str(exc)) from None
    if kind == "global":
        model = _global_from(r.sub("model"), inputs, n_in, n_out)
        model.train_inputs_ = _train_inputs(r, n_in)
        return model
    if kind == "partitioned":
        try:
            partition = Partition.from_dict(r.get("partition", dict))
        except (KeyError, TypeError, ValueError) as exc:
            r.fail("partition", f"damaged ({type(exc).__name__}: {exc})")
        if partition.active.shape != (n_in,):
            r.fail("partition", f"expected {n_in} 'active' flags; got {partition.active.size}")
        regions = r.get("regions", list)
        if len(regions) != partition.n_regions:
            r.fail("regions", f"expected {partition.n_regions} region models; got {len(regions)}")
        blend = r.sub("blend")
        model = PartitionedErrorModel(blend=blend.get("method", str), blend_width=blend.get("width", float))
        model.models_ = [_global_from(r.sub(f"regions[{i}]", item), inputs, n_in, n_out)
                         for i, item in enumerate(regions)]
        model.partition_ = partition
        model.region_bounds_ = r.array("region_bounds", (partition.n_regions, 2, n_in))
        if "active" not in r.get("partition", dict):      # written before constant inputs were left out
            model.partition_ = replace(partition, active=varying_inputs(model.region_bounds_.reshape(-1, n_in)))
        model.train_inputs_ = _train_inputs(r, n_in)
        model.region_counts_ = np.asarray(r.get("region_counts", list), dtype=np.intp)
        model.min_samples_ = r.get("min_samples", int)
        model.n_features_in_ = n_in
        model._y_1d = False
        model.local = ErrorModel(inputs=inputs)
        return model
    r.fail("kind", f"expected 'global' or 'partitioned'; got {kind!r}")


def _train_inputs(r: "_Reader", n_in: int) -> np.ndarray | None:
    """The training inputs (for ``distance_to_data``), or None in files written before they were kept."""
    if "train_inputs" not in r.doc:
        return None
    return r.array("train_inputs", (len(r.get("train_inputs", list)), n_in))


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
