"""Text tables of a finished run (and of simulated data sets): what the command line prints.

The command line only parses arguments and maps errors to exit codes; the
lines it prints about results are formatted here, beside the run they
describe. Every number keeps its column apart at any magnitude: a cell that
does not fit its width switches to exponent notation.
"""

from __future__ import annotations

from ..metrics import rms_per_axis
from .iso_figures import run_lines

# Table 2 of the paper: uncompensated RMS (mm) per data set, x / y / z.
PAPER_UNCOMPENSATED = {
    "identification": (8.0, 7.5, 17.9),
    "test_rectangle": (16.2, 19.1, 16.6),
    "test_spiral_xy": (54.3, 5.4, 60.9),
    "test_spiral_yz": (11.8, 19.4, 2.0),
}


def cell(value: float, width: int = 8, decimals: int = 2) -> str:
    """``value`` right-aligned in ``width`` characters with at least one leading space.

    >>> cell(2.254), cell(321518.0), cell(float("nan")), cell(0.0412, 7, 3)
    ('    2.25', ' 3.2e+05', '     nan', '  0.041')
    """
    text = f"{value:.{decimals}f}"
    if len(text) > width - 1:
        text = f"{value:.{max(width - 7, 0)}e}"
    return f"{text:>{width}}"


PAPER_ROBOT = "motoman_sk120"
"""The robot of the paper's Table 2: only its virtual twin is compared with it."""


def simulation_table(study, data: dict) -> list[str]:
    """The uncompensated RMS of simulated data sets (``partcal simulate``), beside the paper's Table 2 for the
    paper's robot."""
    paper = study.robot.nominal.name == PAPER_ROBOT
    lines = [f"Virtual {study.robot.nominal.name}, seed {study.seed}: uncompensated RMS error (mm)",
             f"{'data set':<18}{'n':>6}{'x':>8}{'y':>8}{'z':>8}" + ("   paper Table 2 (x / y / z)" if paper else "")]
    for name, m in data.items():
        row = f"{name:<18}{len(m):>6}" + "".join(cell(v) for v in rms_per_axis(m.errors_mm))
        if paper:
            ref = PAPER_UNCOMPENSATED.get(name)
            row += "   " + (" / ".join(f"{v:.1f}" for v in ref) if ref else "-")
        lines.append(row)
    return lines


def results_table(result) -> str:
    """The paper's Table 2 layout: RMS x / y / z (mm) per model and data set, the best model, registrations
    and the compensation check (``partcal run``)."""
    names = list(result.datasets)
    width = max(24, 3 + max((len(r.spec.name) for r in result.models), default=0))    # whole names, and the mark
    score = "CV angle (mrad)" if result.config.rank_on == "orientation" else "CV 3-D (mm)"
    head1 = f"{'RMS error (mm)':<{width}}" + "".join(f"{n[:22]:^24}" for n in names) + f"{score:^18}"
    head2 = f"{'model':<{width}}" + "".join(f"{'x':>8}{'y':>8}{'z':>8}" for _ in names) + f"{'RMS +- SE':>11}{'params':>7}"
    lines = [head1, head2, "-" * len(head2)]

    def row(label, stats):
        return f"{label[:width - 1]:<{width}}" + "".join("".join(cell(v) for v in stats[n]["rms"]) for n in names)

    lines.append(row("uncompensated", result.uncompensated))
    noted = []
    for r in result.models:
        mark = "*" if r.notes else ""
        label = r.spec.name[:width - 1 - len(mark)] + mark
        lines.append(row(label, r.metrics) + cell(r.cv_rms_3d, 7, 3) + " +-" + cell(r.cv_se, 6, 3).lstrip().ljust(5)
                     + cell(r.effective_parameters, 7, 0))
        noted += [f"  * {r.spec.name}: {note}" for note in r.notes]
    if result.config.predict == "pose":
        lines += orientation_table(result, names, width)
    if noted:
        lines += ["", "warnings (also in the report):"] + noted
    best = next(r for r in result.models if r.spec.name == result.best)
    part, unit = ("orientation RMS", "mrad") if result.config.rank_on == "orientation" else ("3-D RMS", "mm")
    rule = f"{'validation' if result.config.rank_by == 'validation' else 'CV'} {part}"
    lines.append(f"best: {best.spec.name} ({rule} {best.score(result.config.rank_by):.3f} {unit}), chosen by the "
                 f"{result.best_reason}")
    if result.iso9283:
        lines += [""] + run_lines(result.iso9283)
    regs = result.registrations
    for reg in {id(r): r for r in regs.values()}.values():
        lines.append(registration_line(reg, [n for n, r in regs.items() if r is reg]))
    comp = [r for r in result.models if r.compensation]
    if comp:
        pose = any("orientation" in c for r in comp for c in r.compensation.values())
        lines.append("")
        lines.append("compensation on the virtual robot, 3-D RMS (mm): before / predicted residual / after"
                     + (" (orientation RMS angle, mrad, likewise)" if pose else ""))
        for r in comp:
            cells = "  ".join(f"{n}: {_before_after(c, 'rms_3d', 2)}" + (f" ({_before_after(c['orientation'], 'rms_angle', 3)})"
                                                                         if "orientation" in c else "")
                              for n, c in r.compensation.items())
            lines.append(f"  {r.spec.name:<{width - 2}}{cells}")
    return "\n".join(lines)


def _before_after(stats: dict, key: str, decimals: int) -> str:
    """``'2.50 / 0.06 / 0.06'``: before, predicted residual and after compensation (nan when none converged)."""
    after = stats["after"][key] if stats["after"] is not None else float("nan")
    return " / ".join(f"{v:.{decimals}f}" for v in (stats["before"][key], stats["predicted_residual"][key], after))


def orientation_table(result, names: list[str], width: int) -> list[str]:
    """The orientation errors a run of pose errors leaves: RMS angle (mrad) per model and data set."""
    lines = ["", f"{'orientation RMS (mrad)':<{width}}" + "".join(f"{n[:15]:>16}" for n in names)]

    def row(label, stats):
        return f"{label[:width - 1]:<{width}}" + "".join(cell(stats[n]["orientation"]["rms_angle"], 16, 3)
                                                       for n in names)

    lines.append(row("uncompensated", result.uncompensated))
    lines += [row(r.spec.name, r.metrics) for r in result.models]
    return lines


def registration_line(reg, sets=None) -> str:
    """One line on a tracker registration: poses, residual, tool offset, condition (and each target's
    residual, the orientation's)."""
    where = f" ({', '.join(sets)})" if sets else ""
    return (f"tracker registration{where}: {reg.n_poses} poses, residual 3-D RMS {reg.rms_3d:.3f} mm, max "
            f"{reg.max_3d:.3f} mm, tool [{', '.join(f'{v:.3f}' for v in reg.tool_mm)}] mm "
            f"({'fitted' if reg.fit_tool else 'given'}), condition {reg.condition:.1f}{_more_registered(reg)}")


def _more_registered(reg) -> str:
    """The per-target residuals and the orientation's, when the registration had them."""
    text = ""
    if reg.target_rms_3d:
        text += "; per target RMS " + ", ".join(f"{k} {v:.3f}" for k, v in reg.target_rms_3d.items()) + " mm"
    if reg.probe_rotation is not None:
        text += f"; orientation RMS {reg.orientation_rms_deg:.4f} deg"
    return text
