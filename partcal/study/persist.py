"""Model files: the envelope of versioned plain JSON around every model kind's own section.

No pickle and nothing executable: a model file from elsewhere can only hold
numbers and names. This module writes and checks the envelope: the format
name, the version, a ``checksum`` of the content (a number changed after
writing is refused), the robot, the training inputs, and safe JSON reading
(duplicate keys, huge numbers and deep nesting refused). The fitted model
itself is written and read by its kind (``file_section`` /
``from_file_section`` of its estimator, found in ``partcal.models.kinds``),
which checks every field for meaning. Floats are written with ``repr``
precision, so a loaded model predicts bit for bit what the saved one did.

Version 2 added the GP and kinematic kinds, GP regions and the joint-space
``input_map`` of partitioned models; version 1 files (partcal 0.1) still
load. Files keep the training inputs (``train_inputs``, for
``distance_to_data``); without them the distance falls back to the distance
outside the data's boxes.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .._validation import FieldReader
from .._io import atomic_write
from ..errors import ModelFileError, PartcalError
from ..models.depth import BETA_MAX, DepthSpread
from ..models.kinds import body_of, check_body, model_from_body, own_prior
from ..robot.description import robot_from_dict, robot_to_dict
from ..robot.kinematics import Robot

FORMAT = "partcal-model"
VERSION = 2
READABLE = (1, 2)


def model_to_dict(model, *, name: str = "", robot: Robot | None = None, extra: dict | None = None) -> dict:
    """The JSON-ready description of any fitted partcal error model."""
    out = {"format": FORMAT, "version": VERSION, "partcal_version": __version__, "name": name,
           "robot": robot_to_dict(robot) if robot is not None else None}
    out.update(body_of(model))
    if getattr(model, "train_inputs_", None) is not None:
        out["train_inputs"] = model.train_inputs_.tolist()
    if model.spread_scale_ is not None:                        # a calibrated spread (study/spread.py)
        out["spread_scale"] = np.asarray(model.spread_scale_, dtype=float).tolist()
    if model.spread_depth_ is not None:                        # its growth with the depth (models/depth.py)
        out["spread_depth"] = model.spread_depth_.to_dict()
    out["fit"] = extra or {}
    return out


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
    r = FieldReader(doc, source, "")
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
    model = model_from_body(r)
    model.train_inputs_ = r.array("train_inputs", (None, model.n_features_in_)) if "train_inputs" in r.doc else None
    scale = r.array("spread_scale", (model.n_outputs(),)) if "spread_scale" in r.doc else None
    if scale is not None and np.any(scale <= 0):
        r.fail("spread_scale", "the calibrated scales of the spread must be > 0")
    model.set_spread(scale, _spread_depth(r, model.n_features_in_, model.n_outputs(), own_prior(model))
                     if "spread_depth" in r.doc else None)
    check_body(model, r)
    return model.prepared()


def _spread_depth(r: FieldReader, n_inputs: int, n_outputs: int, own_prior: bool) -> DepthSpread:
    """A model file's ``spread_depth`` (the spread's growth with the inputs' depth, models/depth.py)."""
    sec = r.sub("spread_depth")
    held = sec.array("held", (n_inputs,), bool) if sec.doc.get("held") is not None else None
    variance = sec.array("held_variance", (n_outputs,)) if sec.doc.get("held_variance") is not None else None
    if variance is not None:
        if own_prior:
            sec.fail("held_variance", "a kinematic model has its own prior for what its data left unknown: "
                                      "expected null")
        if held is None:
            sec.fail("held", "the held inputs' prior (held_variance) needs the inputs the data held")
        if np.any(variance < 0):
            sec.fail("held_variance", "expected variances >= 0")
    return DepthSpread(sec.array("centre", (n_inputs,)), sec.array("whiten", (n_inputs, n_inputs)),
                       sec.number("beta", 0.0, BETA_MAX), held,
                       sec.number("length", 1e-12) if variance is not None else 1.0, variance)
