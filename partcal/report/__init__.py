"""The HTML report of a batch run: one self-contained page, readable offline.

``render_report(result, folder)`` writes ``folder/index.html``: a summary, the
comparison table in the layout of the paper's Table 2, for a run of pose errors
the orientation left, errors along each data set, 3-D pictures of the
partitions, swarm convergence, the fitted equations (and identified kinematics,
per target) and the compensation check. Figures are embedded (SVG for 2-D, PNG for 3-D);
the page requests nothing from any network. Every user-supplied string is
escaped by the template engine.
"""

from __future__ import annotations

import base64
import datetime as _dt
import logging
import re
import time
from importlib import resources
from pathlib import Path

import jinja2
import numpy as np

from .. import __version__
from ..metrics import MRAD_PER_DEG
from ..calibration.parameters import BASE_PARAMETERS, TOOL_PARAMETERS
from ..models.kinds import equations_of, identification_of, regions_of, run_summary
from ..calibration.tracker_points import target_parameters
from ..study.measurement_run import MeasurementRunResult
from ..study.results import ModelResult, RunResult
from ..study.scoring import Outputs, errors_left
from . import figures
from .measurement_run import render_measurement_report
from .scene import SceneRendering

log = logging.getLogger(__name__)


def render_report(result: RunResult, folder: Path, *, screenshot: bool = False) -> Path:
    """Write ``index.html`` (and ``report.png`` with ``screenshot=True``) into ``folder``. A run on measurement
    types gets its own page (:mod:`partcal.report.measurement_run`)."""
    start = time.perf_counter()
    if isinstance(result, MeasurementRunResult):
        path = render_measurement_report(result, folder)
        if screenshot:
            from .browser import open_report

            open_report(path, Path(folder) / "report.png")
        return path
    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined)
    template = env.from_string(resources.files(__package__).joinpath("template.html").read_text())
    html = template.render(**context(result))
    path = Path(folder) / "index.html"
    path.write_text(html, encoding="utf-8")
    log.info("report: %s (%.0f kB) in %.1f s", path, path.stat().st_size / 1024, time.perf_counter() - start)
    if screenshot:
        from .browser import open_report

        open_report(path, Path(folder) / "report.png")
    return path


def _b64(text: str | bytes) -> str:
    return base64.b64encode(text.encode() if isinstance(text, str) else text).decode("ascii")


def context(result: RunResult) -> dict:
    """Everything the template shows, computed from a finished run."""
    cfg = result.config
    by_name = {r.spec.name: r for r in result.models}
    best = by_name[result.best]
    ranked = sorted(result.models, key=lambda r: r.score(cfg.rank_by))
    global_best = next((r for r in ranked if regions_of(r.model) is None), None)
    part_best = next((r for r in ranked if regions_of(r.model) is not None), None)
    shown = [r for r in (global_best, part_best) if r is not None]
    outputs = Outputs.of(cfg)
    scenes, captions = scene_specs(result)
    rendering = SceneRendering(scenes)            # a child process draws them while the figures are made here
    out = {
        "name": cfg.name, "version": __version__, "seed": cfg.seed, "seconds": result.seconds,
        "date": _dt.datetime.now().strftime("%Y-%m-%d %H:%M"), "config_path": str(cfg.source),
        "folds": cfg.cv_folds, "models": result.models,
        "best": {"name": best.spec.name, "score": best.score(cfg.rank_by)},
        "best_reason": result.best_reason, "best_caveats": result.best_caveats, "rank_by": cfg.rank_by,
        "pose": outputs.pose, "rank_on": cfg.rank_on, "score_unit": outputs.unit,
        "datasets": [{"name": n, "n": len(m), "bounds": [f"{lo:.0f} to {hi:.0f}" for lo, hi in
                                                         zip(m.nominal_mm.min(0), m.nominal_mm.max(0))]}
                     for n, m in result.datasets.items()],
        "families": family_sentences(result),
        "table": comparison_rows(result),
        "descriptions": [{"name": r.spec.name, "text": r.model.describe()} for r in result.models],
        "cv_plan": result.plan.cv.describe() if result.plan else f"{cfg.cv_folds}-fold",
        "fit_warnings": grouped_warnings(result.models),
        "left_out": list(result.plan.notes) if result.plan else [],
        "granularity": granularity_rows(result),
        "strengths": strength_rows(result),
        "coarser_in_cv": coarser_in_cv(result),
        "shown_models": [r.spec.name for r in shown],
        "error_figures": error_figures(result, shown),
        "iso9283": iso_rows(result),
        "spread": spread_rows(result),
        "convergence_svg": _optional_b64(figures.convergence({r.spec.name: r.model for r in result.models})),
        "equations": [{"name": r.spec.name, "lines": lines} for r in result.models
                      if (lines := equations_of(r.model)) is not None],
        "kinematic": kinematic_tables(result),
        **compensation_entries(result),
        "registration": registration_rows(result),
        "registration_targets": registration_target_rows(result),
        "orientation": orientation_section(result, shown) if outputs.pose else None,
        "design": design_summary(result),
    }
    out["scenes"] = scene_entries(rendering, captions)
    return out


def grouped_warnings(models: list[ModelResult]) -> list[dict]:
    """The models' warnings, each text once with the models it concerns, in the order first met.

    Hybrids share their kinematic fit, so a warning of that fit (a parameter kept nominal) comes once per
    model: one bullet naming them all reads better than one per model.
    """
    groups: dict[str, list[str]] = {}
    for r in models:
        for note in r.notes:
            names = groups.setdefault(note, [])
            if r.spec.name not in names:
                names.append(r.spec.name)
    return [{"models": names, "text": text} for text, names in groups.items()]


def error_figures(result: RunResult, shown: list[ModelResult]) -> list[dict]:
    """Per data set: a path's errors along it with each shown model's 95% band, or, for poses scattered over
    the workspace, predicted against measured errors as points; and the residual histogram."""
    out = []
    own = result.config.data_options.own_frame
    for n, m in result.datasets.items():
        predicted = _positions(shown, n)
        spreads = {r.spec.name: r.spreads[n][:, :3] for r in shown if n in r.spreads}
        path = figures.is_path(m.nominal_mm)
        draw = figures.errors_along_path if path else figures.errors_scattered
        left = {"uncompensated": errors_left(m, np.zeros((len(m), 3)), n in own)[0]}
        left.update({label: errors_left(m, p, n in own)[0] for label, p in predicted.items()})
        out.append({"name": n, "path": path, "path_svg": _b64(draw(n, m.errors_mm, predicted, spreads)),
                    "hist_svg": _b64(figures.residual_histogram(n, left, rigid_fit=n in own))})
    return out


def iso_rows(result: RunResult) -> list[dict]:
    """The ISO 9283 section: per test set, AP mean and max (mm) uncompensated and after each model (predicted,
    and measured on the virtual robot where the run has one), and RP."""
    out = []
    for name, entry in result.iso9283.items():
        measured = entry.get("measured", {})
        rows = [{"name": "uncompensated", "uncompensated": True, **entry["uncompensated"], "measured": None}]
        rows += [{"name": model, "uncompensated": False, **stats, "measured": measured.get(model)}
                 for model, stats in entry["models"].items()]
        best = min(rows[1:], key=lambda r: r["AP_mean_mm"], default=None)
        for row in rows:
            row["best"] = row is best
        out.append({"name": name, "poses": entry["poses"], "cycles": entry["cycles_max"],
                    "rp": entry["uncompensated"]["RP_max_mm"], "rows": rows, "measured": bool(measured)})
    return out


def spread_rows(result: RunResult) -> dict | None:
    """The coverage of each model's 95% intervals on each data set and their mean width (None if no model
    has a spread)."""
    names = list(result.datasets)
    rows = []
    for r in result.models:
        if not r.spreads:
            continue
        cells = []
        for n in names:
            s = r.metrics[n].get("spread")
            cells.append("-" if s is None else f"{100 * s['coverage_95']:.1f}% ({np.mean(s['std_mean']):.3f})")
        scale, depth = r.model.spread_scale_, r.model.spread_depth_
        rows.append({"name": r.spec.name, "cells": cells,
                     "scale": "own" if scale is None else " ".join(f"{v:.2f}" for v in scale[:3]),
                     "beta": "-" if scale is None else f"{depth.beta if depth is not None else 0.0:.3g}"})
    spread = result.config.spread
    blocks = min(spread.folds, len(result.datasets["identification"]))      # at most one block a row
    how = {"forward": f"scaled so that {100 * spread.coverage:g}% of the residuals of the identification set's "
                      f"later blocks ({blocks} contiguous blocks in measurement order, each after the first "
                      "predicted by the model fitted on the blocks before it) fall within the interval",
           "contiguous": f"scaled so that {100 * spread.coverage:g}% of the residuals of {blocks} contiguous "
                         "blocks of the identification set (in measurement order), each predicted by the model "
                         "fitted on the others, fall within the interval",
           "folds": f"scaled so that {100 * spread.coverage:g}% of the run's cross-validation residuals fall "
                    "within the interval",
           "none": "not calibrated: each model's own spread"}[spread.calibration]
    if spread.calibration != "none" and spread.depth:
        how += ("; it grows as sqrt(1 + beta d^2) with the depth d of the pose (its distance from the middle of "
                "the identification inputs, in their standard deviations) where the held-out residuals do")
    return {"datasets": names, "rows": rows, "calibration": how} if rows else None


def _positions(models: list[ModelResult], name: str) -> dict:
    """The predicted position errors of each model on a data set, (n, 3) mm (a pose model's first three)."""
    return {r.spec.name: r.predictions[name][:, :3] for r in models}


def design_summary(result: RunResult) -> dict | None:
    """The observability of the identification set (a run with a robot), as ``partcal run`` prints it."""
    ev = result.design
    if ev is None:
        return None
    return {"text": ev.indices.text(), "o1": ev.indices.o1, "condition": ev.indices.condition,
            "poses": ev.indices.n_poses, "parameters": ev.indices.n_parameters, "missing": list(ev.missing),
            "never": list(ev.never), "total": len(ev.names), "noise": ev.noise_mm, "position_rms": ev.position_rms_mm}


def _registrations(result: RunResult) -> list[tuple[object, list[str]]]:
    """Each tracker registration of the run once, with the data sets it carried into the base frame."""
    regs = result.registrations
    return [(reg, [name for name, r in regs.items() if r is reg]) for reg in {id(r): r for r in regs.values()}.values()]


def registration_rows(result: RunResult) -> list[dict]:
    """One row per tracker registration of the run (none when the data were in the base frame)."""
    rows = []
    for reg, sets in _registrations(result):
        rows.append({"sets": ", ".join(sets), "fitted_on": "identification" if "identification" in sets else sets[0],
                     "n": reg.n_poses, "rms": reg.rms_3d, "max": reg.max_3d, "condition": reg.condition,
                     "rotation": " ".join(f"{v:.4f}" for v in reg.rotation_deg),
                     "translation": " ".join(f"{v:.2f}" for v in reg.translation_mm),
                     "tool": " ".join(f"{v:.3f}" for v in reg.tool_mm),
                     "tool_how": "fitted" if reg.fit_tool else "given"})
    return rows


def registration_target_rows(result: RunResult) -> list[dict]:
    """Per registration fitted on several targets or an orientation: each target's residual RMS (mm) and
    offset in the flange frame, and the orientation's residual RMS angle with the probe's turn on the flange."""
    out = []
    for reg, sets in _registrations(result):
        if not reg.target_rms_3d and reg.probe_rotation is None:
            continue
        doc = reg.to_dict()
        out.append({"sets": ", ".join(sets),
                    "targets": [{"name": name, "rms": rms, "primary": k == 0,
                                 "tool": " ".join(f"{v:.3f}" for v in reg.tool_of(name))}
                                for k, (name, rms) in enumerate(reg.target_rms_3d.items())],
                    "orientation": None if reg.probe_rotation is None else {
                        "rms_deg": reg.orientation_rms_deg, "rms_mrad": _mrad(reg.orientation_rms_deg),
                        "probe": " ".join(f"{v:.4f}" for v in doc["probe_rotation_deg"])}})
    return out


def _mrad(deg: float) -> float:
    return float(deg * MRAD_PER_DEG)


def _deg(mrad: float) -> float:
    return float(mrad / MRAD_PER_DEG)


def granularity_rows(result: RunResult) -> list[dict]:
    """CV score of every candidate granularity; the chosen one (first of the lowest) marked."""
    rows = []
    for r in result.models:
        if not r.granularity:
            continue
        chosen = min(range(len(r.granularity)), key=lambda i: r.granularity[i]["cv_rms_3d"])
        rows += [{"model": r.spec.name, "granularity": g["granularity"], "regions": g["regions"],
                  "cv_regions": _span(g["cv_regions"]), "cv": g["cv_rms_3d"], "chosen": i == chosen}
                 for i, g in enumerate(r.granularity)]
    return rows


def strength_rows(result: RunResult) -> list[dict]:
    """CV score (and its standard error) of every candidate prior strength; the chosen one marked (the
    strongest within one standard error of the lowest, :func:`~partcal.study.selection.strength_rule`)."""
    return [{"model": r.spec.name, "strength": row["prior_strength"], "cv": row["cv_rms_3d"], "se": row["cv_se"],
             "chosen": row["chosen"]} for r in result.models for row in (r.prior_strength or [])]


def coarser_in_cv(result: RunResult) -> list[dict]:
    """Partitioned models whose CV fold fits kept fewer regions than the fit on all the data."""
    return [{"model": r.spec.name, "regions": r.n_regions, "cv_regions": _span(r.cv_regions)}
            for r in result.models if r.cv_regions is not None and r.cv_regions[0] < r.n_regions]


def _span(counts: list[int]) -> str:
    return str(counts[0]) if counts[0] == counts[1] else f"{counts[0]}-{counts[1]}"


def _optional_b64(svg: str | None) -> str | None:
    return _b64(svg) if svg else None


def comparison_rows(result: RunResult) -> list[dict]:
    """Table rows: uncompensated, then every model; cells carry their exact value for checks."""
    names = list(result.datasets)
    rows = []

    def cells_for(stats: dict, r: ModelResult | None) -> list[dict]:
        cells = []
        for n in names:
            s = stats[n]
            values = [*s["rms"], s["rms_3d"], s["max_3d"]]
            for key, v in zip(("x", "y", "z", "3d", "max"), values):
                cells.append({"key": f"{n}.{key}", "value": v, "text": f"{v:.2f}"})
        extra = [("cv", r.cv_rms_3d if r else None, "{:.3f}"),
                 ("params", r.effective_parameters if r else None, "{:.0f}"),
                 ("regions", r.n_regions if r else None, "{}"),
                 ("fit_seconds", r.fit_seconds if r else None, "{:.2f}"),
                 ("pso_ratio", r.rms_ratio if r else None, "{:.6f}")]
        for key, v, fmt in extra:
            cells.append({"key": key, "value": v, "text": fmt.format(v) if v is not None else "–"})
        if r is not None:                # the CV score with its standard error
            cells[-5]["text"] += f" ± {r.cv_se:.3f}"
        return cells

    rows.append({"name": "uncompensated", "uncompensated": True, "cells": cells_for(result.uncompensated, None)})
    for r in result.models:
        rows.append({"name": r.spec.name, "uncompensated": False, "cells": cells_for(r.metrics, r)})
    return _mark_best(rows, skip=("params", "regions", "fit_seconds", "pso_ratio"))


def _mark_best(rows: list[dict], skip: tuple[str, ...] = ()) -> list[dict]:
    """Mark the lowest value of each column among the models (``rows[1:]``; row 0 is the uncompensated)."""
    for col in range(len(rows[0]["cells"])):
        if rows[0]["cells"][col]["key"] in skip:
            continue
        values = [row["cells"][col]["value"] for row in rows[1:]]
        low = min(v for v in values if v is not None)
        for row in rows[1:]:
            row["cells"][col]["best"] = row["cells"][col]["value"] == low
    for row in rows:
        for cell in row["cells"]:
            cell.setdefault("best", False)
    return rows


ORIENTATION_COLUMNS = (("rx", "x", "{:.3f}"), ("ry", "y", "{:.3f}"), ("rz", "z", "{:.3f}"),
                       ("angle", "angle", "{:.3f}"), ("angle_deg", "angle (deg)", "{:.4f}"),
                       ("max_angle", "max", "{:.3f}"))


def orientation_rows(result: RunResult) -> list[dict]:
    """The orientation table of a run of pose errors: per data set the RMS of each component of the rotation
    vector left, the RMS angle (mrad and degrees) and the largest angle (mrad); uncompensated, then every model."""
    names = list(result.datasets)

    def cells_for(stats: dict) -> list[dict]:
        cells = []
        for n in names:
            o = stats[n]["orientation"]
            values = [*o["rms"], o["rms_angle"], _deg(o["rms_angle"]), o["max_angle"]]
            cells += [{"key": f"{n}.{key}", "value": float(v), "text": fmt.format(v)}
                      for (key, _, fmt), v in zip(ORIENTATION_COLUMNS, values)]
        return cells

    rows = [{"name": "uncompensated", "uncompensated": True, "cells": cells_for(result.uncompensated)}]
    rows += [{"name": r.spec.name, "uncompensated": False, "cells": cells_for(r.metrics)} for r in result.models]
    return _mark_best(rows)


def orientation_section(result: RunResult, shown: list[ModelResult]) -> dict:
    """The Orientation section of a run of pose errors: its table and, per data set, the angle of the
    orientation error left along the set, uncompensated and after the shown models."""
    own = result.config.data_options.own_frame
    figs = []
    for n, m in result.datasets.items():
        angles = {"uncompensated": _angle_left(m, np.zeros((len(m), 6)), n in own)}
        angles.update({r.spec.name: _angle_left(m, r.predictions[n], n in own) for r in shown})
        figs.append({"name": n, "svg": _b64(figures.orientation_along_path(n, angles))})
    return {"columns": [label for _, label, _ in ORIENTATION_COLUMNS], "rows": orientation_rows(result),
            "figures": figs}


def _angle_left(m, predicted: np.ndarray, own_frame: bool) -> np.ndarray:
    """The angle of the orientation error a prediction (n, 6) leaves at each pose, mrad, as the metrics count it."""
    return np.linalg.norm(errors_left(m, predicted, own_frame)[1], axis=1)


def family_sentences(result: RunResult) -> list[str]:
    """One sentence per model family (kind, global/partitioned, Cartesian/joint inputs) on its gain."""
    tests = [n for n in result.datasets if n != "identification"] or ["identification"]
    families: dict[str, list[ModelResult]] = {}
    for r in result.models:
        families.setdefault(_family(r), []).append(r)
    out = []
    for family, members in families.items():
        best = min(members, key=lambda r: r.score(result.config.rank_by))
        before = np.mean([result.uncompensated[n]["rms_3d"] for n in tests])
        after = np.mean([best.metrics[n]["rms_3d"] for n in tests])
        changes = _change_text([best.metrics[n]["rms_3d"] for n in tests],
                               [result.uncompensated[n]["rms_3d"] for n in tests])
        out.append(f"{family} ({len(members)}): the best by {'validation' if result.config.rank_by == 'validation' else 'CV'}, {best.spec.name}, brings the mean 3-D RMS on "
                   f"{'the test sets' if tests != ['identification'] else 'the identification set'} from "
                   f"{before:.2f} to {after:.2f} mm ({changes})"
                   f"{_orientation_gain(result, best, tests)}.")
    return out


def _orientation_gain(result: RunResult, best: ModelResult, tests: list[str]) -> str:
    """``" and the mean orientation RMS angle from 1.69 to 0.15 mrad (91% less)"`` in a run of pose errors."""
    if result.config.predict != "pose":
        return ""
    before = [result.uncompensated[n]["orientation"]["rms_angle"] for n in tests]
    after = [best.metrics[n]["orientation"]["rms_angle"] for n in tests]
    return (f", and the mean orientation RMS angle from {np.mean(before):.3f} to {np.mean(after):.3f} mrad "
            f"({_change_text(after, before)})")


def _change_text(after: list[float], before: list[float]) -> str:
    """``"12–40% less"``, ``"5% more"`` or ``"from 13% less to 95% more"``: the per-set change from ``before`` to
    ``after`` in percent. A set without error before (data whose errors are all zero) has no change in percent:
    it is said so, and left out of the range.

    >>> _change_text([0.5, 2.0], [1.0, 0.0]), _change_text([0.0], [0.0])
    ('50% less; 1 set without error before', 'no error before to reduce')
    """
    changes = [100 * (a / b - 1) for a, b in zip(after, before) if b > 0]
    if not changes:
        return "no error before to reduce"
    text = _range_text(changes)
    if len(changes) < len(before):
        text += f"; {len(before) - len(changes)} set{'s' if len(before) - len(changes) > 1 else ''} without error before"
    return text


def _range_text(changes: list[float]) -> str:
    """The range of per-set changes in percent, in words."""
    lo, hi = min(changes), max(changes)

    def one(v):
        return f"{_percent(v)}% {'less' if v < 0 else 'more'}"
    if hi < 0:
        return f"{_percent(hi)}–{_percent(lo)}% less" if round(lo) != round(hi) else one(lo)
    if lo >= 0:
        return f"{_percent(lo)}–{_percent(hi)}% more" if round(lo) != round(hi) else one(hi)
    return f"from {one(lo)} to {one(hi)}"


def _percent(v: float) -> str:
    """``|v|`` rounded to whole percent, with the decimals that keep 99.7 from reading as 100.

    >>> _percent(-99.66), _percent(-12.4), _percent(100.0)
    ('99.7', '12', '100')
    """
    digits = 0
    while digits < 3 and abs(v) < 100 and round(abs(v), digits) >= 100:
        digits += 1
    return f"{abs(v):.{digits}f}"


def _family(r: ModelResult) -> str:
    return r.model.family()


def kinematic_tables(result: RunResult) -> list[dict]:
    """The identified parameter table of every kinematic (and hybrid) model, DH rows first.

    A model whose table equals an earlier one's (hybrids share their kinematic part) points to it.
    """
    out, seen = [], []
    for r in result.models:
        table = identification_of(r.model)
        if table is None:
            continue
        same = next((name for name, other in seen if np.array_equal(other.value, table.value)
                     and other.status == table.status), None)
        seen.append((r.spec.name, table))
        if same is not None:
            out.append({"name": r.spec.name, "same_as": same})
            continue
        cells = {row["name"]: _parameter_cell(row) for row in table.rows()}
        n_rows, row_parameters = r.model.parameter_rows()
        targets = identified_targets(run_summary(r.model)["kinematic"])
        added = targets["added"] if targets else []
        own = len(table.names) - len(added)         # a one-target model's parameters, then the added ones
        if targets:
            targets["own_identified"] = table.status[:own].count("identified")
        identified = table.status.count("identified")
        kept = kept_as_implausible(r, table.unidentifiable(), table.rank - identified)
        out.append({"name": r.spec.name, "same_as": None, "condition": table.condition, "n_poses": table.n_poses,
                    "identified": identified, "parameters": len(table.names), "rank": table.rank,
                    "rms": table.rms_mm, "implausible": kept, "implausible_count": table.rank - identified,
                    "unidentifiable": [n for n in table.unidentifiable() if n not in kept],
                    "columns": [f"{'theta offset' if p == 'theta' else p} ({u})" for p, u in row_parameters],
                    "dh": [{"row": k + 1, "cells": [cells[f"{p}[{k + 1}]"] for p, _ in row_parameters]}
                           for k in range(n_rows)],
                    "extra": [cells[n] for n, _ in TOOL_PARAMETERS + BASE_PARAMETERS],
                    "joint_errors": [cells[n] for n in table.names[len(row_parameters) * n_rows + 9:own]],
                    "targets": targets, "added": [cells[n] for n in added], "robust": table.robust})
    return out


IMPLAUSIBLE_NOTE = re.compile(r"(\S+) comes out beyond ")     # the identification's warning (models/identification.py)


def kept_as_implausible(r: ModelResult, unidentifiable: list[str], count: int) -> list[str]:
    """The parameters a kinematic fit kept nominal because it took them beyond a plausible range: identifiable
    from the data (within the Jacobian's rank, ``count`` of them) but not identified. Their names are those
    the fit's warnings give; an empty list when the warnings do not name exactly ``count`` of them (the
    report then gives the count alone)."""
    named = [m.group(1) for note in r.notes if (m := IMPLAUSIBLE_NOTE.match(note))]
    named = [n for n in dict.fromkeys(named) if n in unidentifiable]
    return named if count > 0 and len(named) == count else []


def identified_targets(summary: dict) -> dict | None:
    """A kinematic fit on several targets or an orientation, from its ``run_summary()["kinematic"]``: each
    target's identification RMS (mm, the primary first), the orientation's RMS angle, how many parameters
    the primary target alone would identify against all the data, and the names of the added parameters
    (the further targets' offsets, the probe's turn). None for a fit on one target's positions."""
    if "targets_rms_3d" not in summary:
        return None
    rms = summary["targets_rms_3d"]
    angle = summary["orientation_rms_deg"]
    added = [n for n, _ in target_parameters(dict.fromkeys(list(rms)[1:]), angle is not None)]
    return {"rms": [{"name": name, "rms": v, "primary": k == 0} for k, (name, v) in enumerate(rms.items())],
            "orientation": None if angle is None else {"rms_deg": angle, "rms_mrad": _mrad(angle)},
            "identified": summary["identified"], "parameters": summary["parameters"],
            "from_primary": summary["identifiable_from_primary"],
            "one_target_parameters": summary["parameters"] - len(added), "added": added}


def _parameter_cell(row: dict) -> dict:
    """One parameter as the report shows it: value ± standard error in its unit (deg and mm in fixed
    notation; sags and compliances in 4 significant digits, a compliance with its stiffness)."""
    fixed = row["unit"] in ("deg", "mm")
    digits = 4 if row["unit"] == "deg" else 3

    def show(v, sign=""):
        return f"{v:{sign}.{digits}f}" if fixed else f"{v:{sign}.4g}"

    text = show(row["value"])
    if row["status"] == "identified":
        text += f" ± {show(row['std_error'])}" if row["std_error"] is not None else " ± n/a"   # no residual left
        if row["unit"] == "deg/(N m)" and row["value"] > 0:
            text += f" ({1.0 / row['value']:.4g} N m/deg)"
    return {"name": row["name"], "unit": row["unit"], "status": row["status"], "text": text,
            "nominal": show(row["nominal"]), "correction": show(row["correction"], "+")}


def scene_specs(result: RunResult) -> tuple[dict[str, dict], dict[str, str]]:
    """What the 3-D picture of every partitioned model (also the residual of a hybrid) shows, and its caption."""
    ident = result.datasets["identification"]
    tests = {n: m for n, m in result.datasets.items() if n != "identification"}
    specs, captions = {}, {}
    for r in result.models:
        model = regions_of(r.model)
        if model is None:
            continue
        part = model.partition_
        cartesian = model.inputs == "cartesian"
        X = ident.nominal_mm if cartesian else ident.q_deg
        spec = {"points": ident.nominal_mm, "labels": model.assign(X), "boxes": np.zeros((0, 2, 3)),
                "n_paths": len(tests)}
        residuals = [np.linalg.norm(m.errors_mm - r.predictions[n][:, :3], axis=1) for n, m in tests.items()]
        for k, (m, res) in enumerate(zip(tests.values(), residuals)):
            spec[f"path{k}"], spec[f"residual{k}"] = m.nominal_mm, res
            spec[f"joined{k}"] = np.asarray(figures.is_path(m.nominal_mm))    # scattered poses: points, not a line
        spec["residual_max"] = max([float(x.max()) for x in residuals] + [1e-9])
        boxes = part.region_boxes() if cartesian else None
        if boxes is not None:
            spec["boxes"] = boxes
        specs[r.spec.name] = spec
        space = "the Cartesian workspace" if cartesian else "joint space"
        unit = part.region_noun + ("s" if part.n_regions != 1 else "")
        captions[r.spec.name] = (f"{part.n_regions} {unit} "
                                 f"in {space}; identification points coloured by region"
                                 f"{f', {part.region_noun}s as boxes' if boxes is not None else ''}; test sets (paths as "
                                 "lines, scattered poses as points) coloured by the residual error after the model's "
                                 "prediction.")
    return specs, captions


def scene_entries(rendering: SceneRendering, captions: dict[str, str]) -> list[dict]:
    """The report's 3-D pictures, once their child process has drawn them."""
    pngs, problem = rendering.result()
    if problem:
        log.warning("report: %s", problem)
    return [{"name": name, "caption": captions[name], "png": _b64(pngs[name]) if name in pngs else None,
             "note": f"No picture: {problem or 'rendering unavailable'}. The rest of the report is complete."}
            for name in captions]


def compensation_entries(result: RunResult) -> dict:
    """The compensation check: per model and test set the 3-D RMS before, predicted and after (mm; after: the
    converged targets, NaN when none converged) and, for pose models, the orientation's RMS angles (mrad)."""
    def rms(stats, key):
        return stats[key] if stats is not None else float("nan")

    rows = [(r.spec.name, n, c["before"]["rms_3d"], c["predicted_residual"]["rms_3d"], rms(c["after"], "rms_3d"),
             f"{c['converged']}/{c['n']}") for r in result.models for n, c in r.compensation.items()]
    if not rows:
        return {"compensation": [], "compensation_svg": None, "compensation_pose": False}
    turns = [c.get("orientation") for r in result.models for c in r.compensation.values()]
    entries = [{"model": m, "dataset": d, "before": b, "predicted": p, "after": a, "converged": c,
                "orientation": None if o is None else {"before": o["before"]["rms_angle"],
                                                       "predicted": o["predicted_residual"]["rms_angle"],
                                                       "after": rms(o["after"], "rms_angle")}}
               for (m, d, b, p, a, c), o in zip(rows, turns)]
    return {"compensation": entries, "compensation_pose": any(o is not None for o in turns),
            "compensation_svg": _b64(figures.compensation_bars([row[:5] for row in rows]))}
