"""Run outputs: metrics.json, model files, per-point predictions, the resolved config, the report.

Everything is written into a temporary folder beside the output folder and
swapped in when complete: a failed or interrupted run leaves the previous
results untouched, and a rerun replaces the folder as a whole.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np
import yaml

from .. import __version__
from ..data.measurements import write_measurements
from ..errors import PartcalError
from ..models.kinds import identification_of, is_physical, run_summary
from ..robot.description import joint_columns, robot_to_dict
from .config import RunConfig
from .persist import save_model
from .results import RunResult

log = logging.getLogger(__name__)


MARKER = ".partcal-output"      # in every folder partcal replaces whole: it may replace it again


def check_writable(output: Path, inputs: Iterable[Path] = (), create: bool = True,
                   option: str = "output: in the config") -> None:
    """Fail early, before any fitting, if the output folder cannot be created or replaced.

    A run replaces its output folder whole, so an existing folder is replaced
    only when it is empty or partcal wrote it (an earlier run or import), and
    never when it holds one of ``inputs`` (the config and data files).
    ``create=False`` (``run --check``) creates no missing parent folder: the
    nearest existing one must be a folder where a folder can be made.
    ``option`` is what names the folder (``output:`` of a run config, ``-o``
    of ``import --config``), for the messages.
    """
    parent = output.parent
    try:
        if create:
            parent.mkdir(parents=True, exist_ok=True)
            os.rmdir(tempfile.mkdtemp(prefix=f".{output.name}.probe-", dir=parent))
        else:
            while not parent.exists() and parent != parent.parent:
                parent = parent.parent
            if not parent.is_dir():
                raise NotADirectoryError(20, "Not a directory")
            os.rmdir(tempfile.mkdtemp(prefix=".partcal.probe-", dir=parent))      # leaves nothing behind
    except OSError as exc:
        raise PartcalError(f"{output}: cannot write the output folder here ({exc.strerror or exc})") from None
    if output.exists() and not output.is_dir():
        raise PartcalError(f"{output}: exists and is not a folder; refusing to replace it")
    if not output.is_dir():
        return
    where = output.resolve()
    for path in inputs:
        if where in Path(path).resolve().parents:
            raise PartcalError(f"{output}: holds {path}, an input of this run; the output folder is replaced whole, "
                               f"so name a folder of its own ({option})")
    entries = sorted(p.name for p in output.iterdir())
    foreign = foreign_entries(output, entries) if entries else []
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        raise PartcalError(f"{output}: exists and holds files partcal did not write ({shown}); the output folder "
                           "is replaced whole, so name a new or empty folder, or an earlier partcal output")


def foreign_entries(folder: Path, entries: list[str]) -> list[str]:
    """The entries of an existing output folder partcal did not write (relative paths, sorted).

    The marker lists every file partcal wrote; anything else (a ``NOTES.txt``,
    a ``raw/`` folder added after the run) is not partcal's to replace. A
    marker of a version before the list, or no marker at all (a version
    before the marker), counts as partcal's when the folder holds only what
    such a run or import writes.
    """
    listed = _listed(folder / MARKER) if MARKER in entries else None
    if listed is not None:
        present = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if not p.is_dir())
        allowed = listed | {MARKER}
        return sorted({_top_foreign(name, allowed) for name in present if name not in allowed})
    if MARKER in entries or {"metrics.json", "config.resolved.yaml"} <= set(entries):
        return [name for name in entries if name not in _RUN_ENTRIES]

    def converted(name: str) -> bool:
        try:
            with open(folder / name, encoding="utf-8") as handle:
                return "(partcal " in handle.readline()
        except (OSError, UnicodeDecodeError):
            return False
    return [name for name in entries if not (name.endswith(".csv") and converted(name))]


# what a run of a version before the marker's file list wrote at the top of its folder
_RUN_ENTRIES = {MARKER, "metrics.json", "config.resolved.yaml", "index.html", "report.png", "models", "predictions",
                "data"}
_MARKER_HEAD = "written by partcal: a later run or import may replace this folder whole; its files:"


def _listed(marker: Path) -> set[str] | None:
    """The files a marker lists, or None for a marker of a version that listed none."""
    try:
        lines = marker.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError):
        return None
    if not lines or lines[0] != _MARKER_HEAD:
        return None
    return {line[2:] for line in lines[1:] if line.startswith("- ")}


def _top_foreign(name: str, allowed: set[str]) -> str:
    """A foreign file's shortest path no listed file lies under (``raw/a.csv`` -> ``raw``)."""
    parts = Path(name).parts
    for k in range(1, len(parts) + 1):
        head = "/".join(parts[:k])
        if not any(a == head or a.startswith(head + "/") for a in allowed):
            return head
    return name


def _spread_calibration(cfg, r, rows: int) -> dict:
    """How the model's spread was calibrated: the config's ``spread`` options and the scale of each output
    (None: the model's own spread; the seconds it took are the entry's ``spread_seconds``) and ``depth_beta``,
    how fast it grows with the inputs' depth (0: not at all; None without a calibration). ``folds`` is the
    number of blocks cut from the ``rows`` identification rows: at most one a row."""
    scale, depth = r.model.spread_scale_, r.model.spread_depth_
    opts = cfg.spread
    return {"method": opts.calibration, "coverage": opts.coverage, "depth": opts.depth,
            **({"folds": min(opts.folds, rows)} if opts.calibration in ("contiguous", "forward") else {}),
            "scale": None if scale is None else [round(float(v), 6) for v in scale],
            "depth_beta": None if scale is None else round(depth.beta if depth is not None else 0.0, 6)}


def metrics_document(result: RunResult) -> dict:
    """The content of ``metrics.json`` (CONTRACTS.md section 4)."""
    cfg = result.config
    models = {}
    for r in result.models:
        entry = {"file": f"models/{r.spec.slug}.json", "fit_seconds": round(r.fit_seconds, 4),
                 "cv_seconds": round(r.cv_seconds, 4), "spread_seconds": round(r.spread_seconds, 4)}
        entry.update(r.metrics)
        plan = result.plan
        folds = len(plan.cv.folds) if plan is not None else cfg.cv_folds
        entry["cv"] = {"folds": folds, "rms_3d": r.cv_rms_3d, "standard_error": _number(r.cv_se),
                       "nested": r.nested}
        if cfg.predict == "pose":            # the score of the ranked part: the position's (mm) or orientation's (mrad)
            entry["cv"] |= {"on": cfg.rank_on, "unit": "mrad" if cfg.rank_on == "orientation" else "mm"}
        entry["effective_parameters"] = _number(r.effective_parameters)
        entry["spread_calibration"] = _spread_calibration(cfg, r, len(result.datasets["identification"]))
        if r.notes:
            entry["notes"] = r.notes
        entry["inputs"], entry["solver"], entry["regions"] = r.spec.inputs, r.model.solver_name, r.n_regions
        entry["kind"] = r.spec.kind if r.spec.residual is None else f"{r.spec.kind} + {r.spec.residual.kind}"
        entry["physical"] = is_physical(r.model)
        entry.update(run_summary(r.model))
        table = identification_of(r.model)
        if table is not None and table.robust is not None:        # the rows a robust loss weighed below 0.5
            entry["robust"] = table.robust
        if r.rms_ratio is not None:
            entry["pso_rms_ratio"] = r.rms_ratio
        if r.granularity is not None:
            entry["granularity"] = r.granularity
        if r.prior_strength is not None:
            entry["prior_strength"] = r.prior_strength
        if r.cv_regions is not None:
            entry["cv"]["regions"] = r.cv_regions
        if r.compensation:
            entry["compensation"] = r.compensation
        models[r.spec.name] = entry
    doc = {
        "partcal_version": __version__, "name": cfg.name, "seed": cfg.seed,
        "datasets": {name: {"n": len(m)} for name, m in result.datasets.items()},
        "uncompensated": result.uncompensated,
        "models": models,
        "rank_by": cfg.rank_by,
        "predict": cfg.predict,
        "rank_on": cfg.rank_on,
        "best": result.best,
        "best_reason": result.best_reason,
    }
    if result.best_caveats:
        doc["best_caveats"] = result.best_caveats
    if result.plan is not None:
        doc["cv"] = {**result.plan.cv.to_dict(), "left_out": list(result.plan.notes),
                     "repeat_scatter_mm": result.plan.repeat_scatter_mm}
    if result.registrations:
        doc["registration"] = registration_document(result.registrations)
    if result.iso9283:
        doc["iso9283"] = result.iso9283
    return doc


def _number(value: float) -> float | None:
    """A float for JSON; None for NaN (JSON has no NaN)."""
    return float(value) if np.isfinite(value) else None


def registration_document(registrations: dict) -> dict:
    """metrics.json ``registration``: the identification set's fit, which data sets share it, and any own ones."""
    shared = registrations["identification"]
    doc = shared.to_dict()
    doc["shared_by"] = [name for name, reg in registrations.items() if reg is shared]
    own = {name: reg.to_dict() for name, reg in registrations.items() if reg is not shared}
    if own:
        doc["own"] = own
    return doc


def write_run(result: RunResult, render: Callable[[RunResult, Path], None] | None = None) -> Path:
    """Write all outputs of a run atomically; return the output folder."""
    def fill(tmp: Path) -> None:
        _write_all(result, tmp)
        if render is not None:
            render(result, tmp)

    replace_folder(result.config.output, fill)
    return result.config.output


def replace_folder(output: Path, fill: Callable[[Path], Any]) -> Any:
    """Build a folder's new content in a temporary sibling (``fill(tmp)``) and swap it in whole.

    A failure while filling leaves the previous folder (or its absence) as it
    was; returns what ``fill`` returned.
    """
    check_writable(output)
    tmp = Path(tempfile.mkdtemp(prefix=f".{output.name}.partial-", dir=output.parent))
    try:
        value = fill(tmp)
        files = sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*") if not p.is_dir())
        (tmp / MARKER).write_text(_MARKER_HEAD + "\n" + "".join(f"- {f}\n" for f in files))
        os.chmod(tmp, 0o755)
        if output.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{output.name}.old-", dir=output.parent))
            os.rmdir(old)
            output.rename(old)
            tmp.rename(output)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(output)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return value


def _write_all(result: RunResult, folder: Path) -> None:
    cfg = result.config
    (folder / "models").mkdir()
    for r in result.models:
        extra = {"cv_rms_3d": r.cv_rms_3d, "fit_seconds": round(r.fit_seconds, 4),
                 "identification": r.metrics["identification"], "seed": cfg.seed, "run": cfg.name}
        save_model(r.model, folder / "models" / f"{r.spec.slug}.json", name=r.spec.name, robot=result.robot,
                   extra=extra)
        pred_dir = folder / "predictions" / r.spec.slug
        pred_dir.mkdir(parents=True)
        for name, m in result.datasets.items():
            _write_predictions(pred_dir / f"{name}.csv", m, r.predictions[name], r.spreads.get(name))
    if cfg.data_options.converted:
        write_datasets(cfg, result.datasets, result.registrations, folder / "data")
    (folder / "metrics.json").write_text(json.dumps(metrics_document(result), indent=1) + "\n")
    resolved = {"partcal_version": __version__, **cfg.resolved()}
    (folder / "config.resolved.yaml").write_text(yaml.safe_dump(resolved, sort_keys=False))


def write_datasets(config: RunConfig, datasets: dict, registrations: dict, folder: Path) -> list[Path]:
    """Data sets as contract CSVs (degrees, mm, base frame): ``folder/<data set>.csv``.

    A run writes them when it converted its data (a format, a row subset or a
    tracker registration), so the converted data can be reused as they are;
    ``partcal import --config`` writes them without fitting anything. Each
    file is written atomically; a header comment says where it came from.
    """
    opts = config.data_options
    folder.mkdir(parents=True, exist_ok=True)
    sources = {"identification": config.identification, "validation": config.validation, **config.tests}
    paths = []
    for name, m in datasets.items():
        source = sources[name]
        lines = [f"{name} of run {config.name!r} (partcal {__version__}), converted to degrees and mm from {source}"]
        if name in opts.rows:
            lines.append(f"data rows {opts.rows[name].text or 'all'}, every {opts.rows[name].every}")
        if name in registrations:
            reg = registrations[name]
            lines.append(registration_comment(reg, shared=reg is registrations["identification"]))
        path = folder / f"{name}.csv"
        write_measurements(m, path, comment="\n".join(lines))
        paths.append(path)
    return paths


def write_robot_yaml(robot, path: Path, comment: str) -> Path:
    """The robot as a robot YAML (docs/robots.md; a URDF's chain too), ``comment`` as its header lines.

    ``partcal import --config`` writes the run's robot, with the registered
    tool offset of a tracker run, beside the converted data sets, so that a
    run of them in the base frame needs no registration and no built-in robot.
    """
    from .._io import atomic_write

    text = "".join(f"# {line}\n" for line in comment.splitlines()) + yaml.safe_dump(robot_to_dict(robot),
                                                                                   sort_keys=False)
    with atomic_write(path) as handle:
        handle.write(text)
    return path


def registration_comment(reg, shared: bool) -> str:
    """One line on a registration for the header of a converted CSV."""
    how = "registered on the identification set" if shared else "registered on this set"
    return (f"base frame: tracker frame {how} ({reg.n_poses} poses, RMS {reg.rms_3d:.4f} mm); rotation vector "
            f"{_triple(reg.rotation_deg)} deg, translation {_triple(reg.translation_mm)} mm, tool "
            f"{_triple(reg.tool_mm)} mm in the flange frame" +
            "".join(f"; tool@{name} {_triple(tool)} mm" for name, tool in reg.target_tools_mm.items()))


def _triple(values) -> str:
    return "[" + ", ".join(f"{v:.6f}" for v in values) + "]"


def _write_predictions(path: Path, m, predicted, std=None) -> None:
    """Per point: joints, nominal position, measured and predicted errors (full precision); for pose errors the
    orientation's too (``drx_meas``.. ``drx_pred``.., rotation vectors in mrad); with the model's spread, the
    standard deviation of each prediction (``dx_sd``..)."""
    pose = predicted.shape[1] == 6
    measured = m.pose_errors if pose else m.errors_mm
    axes = ["dx", "dy", "dz"] + (["drx", "dry", "drz"] if pose else [])
    header = joint_columns(m.n_joints) + ["x_nom", "y_nom", "z_nom"] + [f"{a}_meas" for a in axes] + \
        [f"{a}_pred" for a in axes] + ([f"{a}_sd" for a in axes] if std is not None else [])
    values = np.hstack([m.q_deg, m.nominal_mm, measured, predicted] + ([std] if std is not None else []))
    with path.open("w") as handle:
        handle.write(",".join(header) + "\n")
        for row in values:
            handle.write(",".join(repr(float(v)) for v in row) + "\n")
