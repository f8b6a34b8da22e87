"""2-D report figures (matplotlib, SVG): errors along paths (position, orientation), residuals, convergence,
compensation.

Every function returns the SVG text of one figure. Fonts stay text (not
paths), which keeps the files small; the report embeds them as data URIs.
"""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402
import numpy as np  # noqa: E402

from ..models.kinds import regions_of, swarm_runs  # noqa: E402


plt.rcParams.update({"svg.fonttype": "none", "font.size": 9, "axes.grid": True, "grid.alpha": 0.3,
                     "axes.spines.top": False, "axes.spines.right": False, "svg.hashsalt": "partcal"})
COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"]
OUTPUT_NAMES = ("x", "y", "z", "rx", "ry", "rz")    # a swarm per output: position, then a pose model's turn


def svg_of(fig) -> str:
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None})
    plt.close(fig)
    return buf.getvalue()


Z95 = 1.959963984540054          # a 95% band is mean +- Z95 std
MAX_SCATTERED = 5_000           # poses drawn in a scatter of predicted against measured errors
PATH_STEP = 0.05                 # a short step: under this share of the diagonal of the data set's box


def is_path(positions_mm: np.ndarray) -> bool:
    """Whether consecutive points of a data set follow a path rather than scatter over the workspace.

    A path goes most of its way in short steps (each under :data:`PATH_STEP`
    of the diagonal of the points' box): its median step is short, and the
    short steps cover at least half of the length travelled. Poses measured in
    small clusters (a few poses millimetres apart, then a jump elsewhere, as
    the IPA UR10's joint configurations) have short median steps but travel in
    the jumps: they are scattered poses, drawn as points.

    >>> line = np.c_[np.arange(100.0), np.zeros(100), np.zeros(100)]
    >>> centres = np.random.default_rng(0).uniform(0, 100, (20, 3))
    >>> clusters = np.repeat(centres, 5, axis=0) + 0.2 * np.tile(np.arange(5.0), 20)[:, None]
    >>> is_path(line), is_path(np.random.default_rng(0).uniform(0, 100, (100, 3))), is_path(clusters)
    (True, False, False)
    """
    p = np.asarray(positions_mm, dtype=float)
    if len(p) < 3:
        return False
    extent = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    if not extent > 0 or float(np.median(steps)) >= PATH_STEP * extent:
        return False
    return float(steps[steps < PATH_STEP * extent].sum()) >= 0.5 * float(steps.sum())


def _legend_below(fig, axes, handles, labels, ncol: int) -> None:
    """A figure legend under the lowest axis decoration (tick labels, axis labels), never over them."""
    renderer = fig.canvas.get_renderer()
    bottom = min(ax.get_tightbbox(renderer).y0 for ax in axes)           # display units
    y = fig.transFigure.inverted().transform((0, bottom))[1]
    fig.legend(handles, labels, loc="upper center", ncol=ncol, fontsize=8, frameon=False, markerscale=2.5,
               bbox_to_anchor=(0.5, y - 0.01), bbox_transform=fig.transFigure)


def errors_along_path(name: str, measured: np.ndarray, predictions: dict[str, np.ndarray],
                      spreads: dict[str, np.ndarray] | None = None) -> str:
    """Measured and predicted error per axis against the point index (the paper's Figs. 4, 6, 7, 10, 11).

    ``spreads`` (per model, (n, 3) mm standard deviations) draws each model's 95% band around its line.
    """
    fig, axes = plt.subplots(3, 1, figsize=(8, 5.4), sharex=True)
    idx = np.arange(len(measured))
    for a, ax in enumerate(axes):
        ax.plot(idx, measured[:, a], color="black", lw=1.4, label="measured")
        for k, (label, pred) in enumerate(predictions.items()):
            colour = COLOURS[k % 4]
            ax.plot(idx, pred[:, a], color=colour, lw=1.1, ls="--" if k else "-", label=label)
            if spreads and label in spreads:
                half = Z95 * spreads[label][:, a]
                ax.fill_between(idx, pred[:, a] - half, pred[:, a] + half, color=colour, alpha=0.15, lw=0,
                                label=f"{label}: 95% band" if a == 0 else None)
        ax.set_ylabel(f"d{'xyz'[a]} (mm)")
    axes[0].set_title(f"{name}: measured and predicted error")
    axes[-1].set_xlabel("point along the data set")
    _legend_below(fig, axes, *axes[0].get_legend_handles_labels(), ncol=3)      # not over the lines
    return svg_of(fig)


def errors_scattered(name: str, measured: np.ndarray, predictions: dict[str, np.ndarray],
                     spreads: dict[str, np.ndarray] | None = None) -> str:
    """Predicted against measured error per axis, one point per pose, for data sets that are no path.

    A perfect model puts every point on the diagonal. With ``spreads``, a
    model's points outside its own 95% interval are drawn hollow, and the
    legend gives the share inside (of every pose). Of more than
    :data:`MAX_SCATTERED` poses, that many evenly spaced ones are drawn (and the
    title says so): 100,000 poses drawn each made a 45 MB report.
    """
    fig, axes = plt.subplots(1, 3, figsize=(8, 3.0))
    size = 4 if len(measured) > 500 else 9
    shown = np.unique(np.linspace(0, len(measured) - 1, min(len(measured), MAX_SCATTERED)).round().astype(int))
    for a, ax in enumerate(axes):
        low, high = float(measured[:, a].min()), float(measured[:, a].max())
        for k, (label, pred) in enumerate(predictions.items()):
            colour = COLOURS[k % 4]
            inside = np.ones(len(pred), dtype=bool)
            if spreads and label in spreads:
                inside = np.abs(measured[:, a] - pred[:, a]) <= Z95 * spreads[label][:, a]
                text = f"{label} ({100 * inside.mean():.0f}% within its 95% interval)"
            else:
                text = label
            m, p, ins = measured[shown, a], pred[shown, a], inside[shown]
            ax.scatter(m[ins], p[ins], s=size, color=colour, alpha=0.5, lw=0, label=text if a == 0 else None)
            ax.scatter(m[~ins], p[~ins], s=size, facecolors="none", edgecolors=colour, alpha=0.6, lw=0.6)
            low, high = min(low, float(pred[:, a].min())), max(high, float(pred[:, a].max()))
        ax.plot([low, high], [low, high], color="black", lw=0.8)
        ax.set_xlabel(f"measured d{'xyz'[a]} (mm)")
        ax.set_aspect("equal", adjustable="datalim")
        for axis in (ax.xaxis, ax.yaxis):          # a narrow panel: few ticks, so that their labels never touch
            axis.set_major_locator(MaxNLocator(nbins=4))
    axes[0].set_ylabel("predicted (mm)")
    some = "" if len(shown) == len(measured) else f" ({len(shown):,} of {len(measured):,} poses drawn, evenly spaced)"
    fig.suptitle(f"{name}: predicted against measured error, one point per pose{some}", fontsize=9)
    fig.tight_layout()
    _legend_below(fig, axes, *axes[0].get_legend_handles_labels(), ncol=2)
    return svg_of(fig)


def orientation_along_path(name: str, angles_mrad: dict[str, np.ndarray]) -> str:
    """The angle of the orientation error at each point of a data set (mrad): uncompensated (the first entry,
    grey, filled) and left by each model, with each series' RMS in the legend."""
    fig, ax = plt.subplots(figsize=(8, 2.6))
    for k, (label, angle) in enumerate(angles_mrad.items()):
        idx = np.arange(len(angle))
        text = f"{label} (RMS {np.sqrt(np.mean(angle**2)):.3f} mrad)"
        if k == 0:
            ax.fill_between(idx, angle, color="grey", alpha=0.3, lw=0)
            ax.plot(idx, angle, color="grey", lw=0.9, label=text)
        else:
            ax.plot(idx, angle, color=COLOURS[(k - 1) % 4], lw=1.1, ls="--" if k > 1 else "-", label=text)
    ax.set_ylim(0, 1.3 * max(max(float(a.max()) for a in angles_mrad.values()), 1e-9))   # room for the legend
    ax.set_xlabel("point along the data set")
    ax.set_ylabel("orientation error (mrad)")
    ax.set_title(f"{name}: angle of the orientation error, uncompensated and left")
    ax.legend(loc="upper right", ncol=2, fontsize=8, frameon=False)
    return svg_of(fig)


def residual_histogram(name: str, left: dict[str, np.ndarray], rigid_fit: bool = False) -> str:
    """Distribution of the 3-D error left (``left``: label -> (n, 3) mm, ``uncompensated`` first) by each model,
    as the run's metrics count it: for a set in its own tracker frame, after the rigid fit (``rigid_fit``)."""
    fig, ax = plt.subplots(figsize=(8, 2.6))
    series = {label: np.linalg.norm(errors, axis=1) for label, errors in left.items()}
    top = max(v.max() for v in series.values())
    bins = np.linspace(0, top, 40)
    for k, (label, values) in enumerate(series.items()):
        colour = "grey" if k == 0 else COLOURS[(k - 1) % 4]
        ax.hist(values, bins=bins, histtype="stepfilled" if k == 0 else "step", alpha=0.35 if k == 0 else 1,
                color=colour, lw=1.4, label=f"{label} (RMS {np.sqrt(np.mean(values**2)):.2f} mm)")
    ax.set_xlabel("3-D error |e| (mm)")
    ax.set_ylabel("points")
    ax.set_title(f"{name}: residual error" + (" after the rigid fit to its own frame, as the table scores it"
                                              if rigid_fit else ""))
    _legend_below(fig, [ax], *ax.get_legend_handles_labels(), ncol=2)          # not over the bars
    return svg_of(fig)


def convergence(models: dict[str, object]) -> str | None:
    """Best fitness per iteration over the least-squares optimum (1 = optimal), log scale.

    Global models: one line per axis. Partitioned models: median over regions
    and axes with the 10-90 % band.
    """
    curves = {}
    for label, model in models.items():
        runs = [history / max(lstsq_rms, 1e-12) for history, lstsq_rms in swarm_runs(model)]
        if runs:
            curves[label] = (runs, regions_of(model) is not None)
    if not curves:
        return None
    fig, ax = plt.subplots(figsize=(8, 3.4))
    for k, (label, (runs, partitioned)) in enumerate(curves.items()):
        colour = COLOURS[k % 4]
        if partitioned:
            length = max(len(r) for r in runs)
            grid = np.array([np.pad(r, (0, length - len(r)), mode="edge") for r in runs])
            ax.plot(np.median(grid, axis=0), color=colour, lw=1.4, label=f"{label} (median of {len(runs)})")
            ax.fill_between(np.arange(length), *np.percentile(grid, [10, 90], axis=0), color=colour, alpha=0.2)
        else:
            for a, r in enumerate(runs):
                ax.plot(r, color=colour, lw=1.1, ls=["-", "--", ":"][a % 3], label=f"{label} {OUTPUT_NAMES[a]}")
    ax.axhline(1.0, color="black", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("iteration")
    ax.set_ylabel("best RMS / least-squares RMS")
    ax.set_title("Particle swarm convergence (1 = the least-squares optimum)")
    _legend_below(fig, [ax], *ax.get_legend_handles_labels(), ncol=4)          # not over the curves
    return svg_of(fig)


def compensation_bars(rows: list[tuple[str, str, float, float, float]]) -> str:
    """Grouped bars: before / predicted residual / after compensation, per model and test set."""
    fig, ax = plt.subplots(figsize=(8, 0.9 + 0.32 * len(rows)))
    y = np.arange(len(rows))
    for k, (label, colour) in enumerate((("before", "grey"), ("predicted residual", COLOURS[0]),
                                         ("after compensation", COLOURS[1]))):
        ax.barh(y + (k - 1) * 0.27, [r[2 + k] for r in rows], height=0.26, color=colour, label=label)
    ax.set_yticks(y, [f"{r[0]} · {r[1]}" for r in rows], fontsize=7)
    ax.invert_yaxis()
    ax.set_xlabel("3-D RMS error (mm)")
    ax.set_title("Compensation on the virtual robot")
    ax.legend(fontsize=8, frameon=False, loc="lower right")
    return svg_of(fig)
