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
import numpy as np  # noqa: E402


plt.rcParams.update({"svg.fonttype": "none", "font.size": 9, "axes.grid": True, "grid.alpha": 0.3,
                     "axes.spines.top": False, "axes.spines.right": False, "svg.hashsalt": "partcal"})
COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"]
OUTPUT_NAMES = ("x", "y", "z", "rx", "ry", "rz")    # a swarm per output: position, then a pose model's turn


def _svg(fig) -> str:
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None})
    plt.close(fig)
    return buf.getvalue()


def errors_along_path(name: str, measured: np.ndarray, predictions: dict[str, np.ndarray]) -> str:
    """Measured and predicted error per axis against the point index (the paper's Figs. 4, 6, 7, 10, 11)."""
    fig, axes = plt.subplots(3, 1, figsize=(8, 5.4), sharex=True)
    idx = np.arange(len(measured))
    for a, ax in enumerate(axes):
        ax.plot(idx, measured[:, a], color="black", lw=1.4, label="measured")
        for k, (label, pred) in enumerate(predictions.items()):
            ax.plot(idx, pred[:, a], color=COLOURS[k % 4], lw=1.1, ls="--" if k else "-", label=label)
        ax.set_ylabel(f"d{'xyz'[a]} (mm)")
    axes[0].set_title(f"{name}: measured and predicted error")
    axes[0].legend(loc="upper right", ncol=3, fontsize=8, frameon=False)
    axes[-1].set_xlabel("point along the data set")
    return _svg(fig)


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
    return _svg(fig)


def residual_histogram(name: str, measured: np.ndarray, predictions: dict[str, np.ndarray]) -> str:
    """Distribution of the 3-D error left by each model, against the uncompensated one."""
    fig, ax = plt.subplots(figsize=(8, 2.6))
    series = {"uncompensated": np.linalg.norm(measured, axis=1)}
    series.update({label: np.linalg.norm(measured - p, axis=1) for label, p in predictions.items()})
    top = max(v.max() for v in series.values())
    bins = np.linspace(0, top, 40)
    for k, (label, values) in enumerate(series.items()):
        colour = "grey" if k == 0 else COLOURS[(k - 1) % 4]
        ax.hist(values, bins=bins, histtype="stepfilled" if k == 0 else "step", alpha=0.35 if k == 0 else 1,
                color=colour, lw=1.4, label=f"{label} (RMS {np.sqrt(np.mean(values**2)):.2f} mm)")
    ax.set_xlabel("3-D error |e| (mm)")
    ax.set_ylabel("points")
    ax.set_title(f"{name}: residual error")
    ax.legend(fontsize=8, frameon=False)
    return _svg(fig)


def convergence(models: dict[str, object]) -> str | None:
    """Best fitness per iteration over the least-squares optimum (1 = optimal), log scale.

    Global models: one line per axis. Partitioned models: median over regions
    and axes with the 10-90 % band.
    """
    curves = {}
    for label, model in models.items():
        runs = [history / max(lstsq_rms, 1e-12) for history, lstsq_rms in model.swarm_runs()]
        if runs:
            curves[label] = (runs, model.regions_model() is not None)
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
    ax.legend(fontsize=7, frameon=False, ncol=3)
    return _svg(fig)


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
    return _svg(fig)
