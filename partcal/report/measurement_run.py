"""The report of a run on measurement types (:mod:`partcal.study.measurement_run`): what each type measured, what
each model leaves of it in the fit and held out, the test sets, what the data cannot identify, and the
best model's parameters."""

from __future__ import annotations

import base64
import re
from datetime import datetime, timezone
from importlib import resources
from pathlib import Path

import jinja2
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .. import __version__  # noqa: E402
from ..calibration.registry import MEASUREMENT_TYPES
from ..study.measurement_run import MeasurementRunResult  # noqa: E402
from .figures import COLOURS, svg_of  # noqa: E402


def render_measurement_report(result: MeasurementRunResult, folder: Path) -> Path:
    """Write ``index.html`` of a measurement run into ``folder``, in the run report's style (its template's)."""
    env = jinja2.Environment(autoescape=True, undefined=jinja2.StrictUndefined)
    files = resources.files(__package__)
    template = env.from_string(files.joinpath("measurement_template.html").read_text())
    style = re.search(r"<style>.*?</style>", files.joinpath("template.html").read_text(), re.S).group(0)
    path = Path(folder) / "index.html"
    path.write_text(template.render(style=style, **kinds_context(result)), encoding="utf-8")
    return path


def kinds_context(result: MeasurementRunResult) -> dict:
    """Everything the types template shows."""
    data, cfg = result.data, result.config
    measurements = list(data.descriptions)
    best = next(r for r in result.models if r.spec.name == result.best)
    notes = []
    for r in result.models:
        notes += [n for n in r.notes if n not in notes]
    table = best.model.identification_
    return {
        "name": cfg.name, "version": __version__, "seed": cfg.seed, "seconds": result.seconds,
        "date": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "config_path": str(cfg.source),
        "types": [{"name": k, "text": data.descriptions[k], "summary": MEASUREMENT_TYPES[k].summary,
                   "reads": ", ".join(MEASUREMENT_TYPES[k].reads)} for k in measurements],
        "models": [{"name": r.spec.name, "best": r.spec.name == result.best,
                    "fit": [r.fit_rms.get(k) for k in measurements], "cv": [r.cv_rms.get(k) for k in measurements],
                    "weighted": r.cv_pooled, "identified": r.model.identification_.status.count("identified"),
                    "parameters": len(r.model.identification_.names), "seconds": r.fit_seconds,
                    "tests": [_test_text(r.tests[t]) for t in data.tests]} for r in result.models],
        "measurement_names": measurements, "tests": list(data.tests),
        "uncompensated": [_test_text(result.uncompensated[t]) if t in result.uncompensated else "" for t in data.tests],
        "rigid": not data.fixes_frame, "notes": notes, "best": result.best,
        "held": table.unidentifiable(),
        "parameters": [row for row in table.rows()],
        "strengths": [{"model": r.spec.name, "strength": row["prior_strength"], "cv": row["cv_weighted_rms_mm"],
                       "se": row["cv_se"], "chosen": row["chosen"]} for r in result.models
                      for row in (r.prior_strength or [])],
        "hist_svg": _b64(_histograms(best.cv_residuals, best.spec.name)) if best.cv_residuals else None,
    }


def _test_text(figures: dict) -> str:
    if "rms_3d" in figures:
        return f"{figures['rms_3d']:.4f}" + (" (rigid fit)" if figures.get("rigid_fit") else "")
    return ", ".join(f"{k} {v:.4f}" for k, v in figures["rms_by_type"].items())


def _histograms(residuals: dict, name: str) -> str:
    """The held-out residuals of each type, one panel each."""
    fig, axes = plt.subplots(1, len(residuals), figsize=(3.2 * len(residuals) + 1, 2.6), squeeze=False)
    for k, (ax, (measurement, values)) in enumerate(zip(axes[0], residuals.items())):
        ax.hist(values, bins=40, color=COLOURS[k % len(COLOURS)], alpha=0.8)
        ax.set_title(f"{measurement}: RMS {np.sqrt(np.mean(values**2)):.4f} mm")
        ax.set_xlabel("held-out residual (mm)")
    axes[0][0].set_ylabel("rows")
    fig.suptitle(f"{name}: residuals of rows held out by cross-validation")
    return svg_of(fig)


def _b64(text: str) -> str:
    return base64.b64encode(text.encode()).decode("ascii")
