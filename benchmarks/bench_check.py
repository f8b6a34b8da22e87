"""Does a calibration still hold? ``partcal check`` on the IPA UR10 (real data, laser tracker).

B's DH model (identified on series B rows 1-1000, registered as configs/ur10_ipa.yaml registers them, its
spread calibrated as a run calibrates it: forward blocks, depth) checked against 50-pose windows of:

- B 1001-1495 (measured after the identification rows, nothing changed): five windows spread evenly over
  the 495 rows (the done-means), then all nine non-overlapping windows; with the model's calibrated spread
  and, for comparison, with the fit's own spread (no calibration);
- the same windows with joint 2's reading shifted by +0.05 and -0.05 degrees: the verdict, where joint 2's
  offset ranks by evidence (the check's ranking), by the BIC (raw drop of sum z^2 less k ln m) and by the
  raw drop, its fitted change, where it is not first the share of its change the first's parameters do too,
  and the step of forward selection that takes it. Today: moved in 10 of 10; joint 2 first in 3 + 4 of the
  five windows (7 + 8 of the nine), taken first or second by forward selection in 4 + 4 (9 + 9). The two
  it misses (rows 1335-1384 at +0.05, 1446-1495 at -0.05): joint 1 spans 54 and 44 degrees there, 96-98%
  of a joint 2 turn is a frame change, and the window's own misfit cancels or weakens the rest;
- series C (the other shoulder configuration, in B's frame): five windows spread over its 2773 rows: the
  verdict, the likeliest explanation (the base frame in all five) and its fitted values, what forward
  selection takes beyond it, and the check with C's frame registered on the window itself
  (``--frame tracker``: holds in all five).

    .venv/bin/python benchmarks/bench_check.py      (about 5 s)
"""

from __future__ import annotations

import copy
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _table import print_table  # noqa: E402

from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.study.check import check_arrays, registered_on_model  # noqa: E402
from partcal.study.config import SpreadOptions, load_config  # noqa: E402
from partcal.study.prepare import load_datasets  # noqa: E402
from partcal.study.selection import grouped_splits, measured_poses  # noqa: E402
from partcal.study.spread import CalibratedSpread, run_spread  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WINDOW = 50
JOINT2 = "joint 2's offset"


def windows(n: int, count: int | None) -> list[slice]:
    """``count`` windows of :data:`WINDOW` rows spread evenly over ``n`` rows (None: all non-overlapping ones)."""
    starts = (np.arange(n // WINDOW) * WINDOW if count is None else
              np.round(np.linspace(0, n - WINDOW, count)).astype(int))
    return [slice(int(s), int(s) + WINDOW) for s in starts]


def ranks(result) -> tuple[int, int, int]:
    """Joint 2's offset's rank by evidence, by BIC and by the raw drop of sum z^2 (1 = first)."""
    total = result.mean_z2 * result.dof
    drop = {e.name: total - e.mean_z2 * (result.dof - len(e.parameters)) for e in result.explanations}
    bic = {e.name: drop[e.name] - len(e.parameters) * np.log(result.dof) for e in result.explanations}
    order = [e.name for e in result.explanations]
    return (order.index(JOINT2) + 1, sorted(bic, key=lambda k: -bic[k]).index(JOINT2) + 1,
            sorted(drop, key=lambda k: -drop[k]).index(JOINT2) + 1)


def fitted_model(train, robot):
    """B's DH model with its spread calibrated as a run calibrates it (the run's defaults)."""
    model = KinematicModel(robot=robot)
    X, y = train.q_deg, train.errors_mm
    model.fit(X, y)
    spread = run_spread(SpreadOptions(), model, X, y, cv_folds=grouped_splits(measured_poses(train), 5, 0))
    (spread or CalibratedSpread(None)).apply(model)
    own = copy.deepcopy(model)
    CalibratedSpread(None).apply(own)
    return model, own


def b_table(model, own, B, count: int | None) -> None:
    """The unchanged and shifted windows of B 1001-1495."""
    rows, held, first, taken = [], {"calibrated": 0, "own": 0}, {0.05: 0, -0.05: 0}, {0.05: 0, -0.05: 0}
    for sl in windows(len(B.q_deg), count):
        q, errors = B.q_deg[sl], B.errors_mm[sl]
        same, by_own = check_arrays(model, q, errors), check_arrays(own, q, errors)
        held["calibrated"] += same.holds
        held["own"] += by_own.holds
        cells = [f"{1001 + sl.start}-{1000 + sl.stop}", f"{same.mean_z2:.2f}", f"{same.p_value:.2g}",
                 "holds" if same.holds else "moved", "holds" if by_own.holds else "moved"]
        for shift in (0.05, -0.05):
            moved = q.copy()
            moved[:, 1] += shift
            result = check_arrays(model, moved, B.measured_mm[sl] - model.robot_.positions(moved))   # as read
            joint2 = next(e for e in result.explanations if e.name == JOINT2)
            best = result.explanations[0]
            first[shift] += best.name == JOINT2 and not result.holds
            step = next((k for k, (name, _) in enumerate(result.together, 1) if name == JOINT2), None)
            taken[shift] += step is not None and step <= 2 and not result.holds
            cells += ["holds" if result.holds else "moved", "/".join(map(str, ranks(result))),
                      f"{joint2.change[0]:+.4f}", "" if best.name == JOINT2 else f"{best.name} ({best.evidence:.0f} "
                      f"against {joint2.evidence:.0f}; shared {joint2.shared:.2f})",
                      "-" if step is None else f"{step} ({result.together[step - 1][1]:+.1f})"]
        rows.append(cells)
    title = (f"B's DH model against {'five' if count else 'all nine'} 50-pose windows of B 1001-1495 "
             f"(holds: {held['calibrated']} with the calibrated spread, {held['own']} with the fit's own; joint 2 "
             f"moved and first: {first[0.05]} at +0.05, {first[-0.05]} at -0.05; taken first or second: "
             f"{taken[0.05]} and {taken[-0.05]})")
    print_table(title, ["rows", "mean z2", "p", "verdict", "own spread", "+0.05", "rank j2", "fitted deg", "first",
                        "taken", "-0.05", "rank j2", "fitted deg", "first", "taken"], rows)


def c_table(model, C) -> None:
    """Windows of series C in B's frame, and with the frame registered on each window."""
    rows = []
    for sl in windows(len(C.q_deg), 5):
        q, errors = C.q_deg[sl], C.errors_mm[sl]
        result = check_arrays(model, q, errors)
        best = result.explanations[0]
        moved, _ = registered_on_model(model, q, C.measured_mm[sl])
        framed = check_arrays(model, q, moved - model.robot_.positions(q), registered=True)
        rows.append([f"{sl.start + 1}-{sl.stop}", f"{result.mean_z2:.2f}", f"{result.p_value:.2g}",
                     "holds" if result.holds else "moved", best.name, f"{best.evidence:.0f}", f"{best.mean_z2:.2f}",
                     best.values_text().replace(" mm", "").replace(" deg", ""),
                     ", ".join(f"{name} ({gain:+.1f})" for name, gain in result.together[1:]) or "-",
                     f"{framed.mean_z2:.2f}", f"{framed.p_value:.2g}", "holds" if framed.holds else "moved"])
    print_table("B's DH model against 50-pose windows of C (in B's frame; last three: C's frame registered on the "
                "window)", ["rows", "mean z2", "p", "verdict", "likeliest", "evidence", "left",
                            "fitted (mm, deg)", "beyond it", "registered z2", "p", "verdict"], rows)


def main() -> None:
    warnings.simplefilter("ignore")         # the spread calibration's fits on part of the rows warn
    data, robot, _ = load_datasets(load_config(ROOT / "configs" / "ur10_ipa.yaml"))
    train = data["identification"]
    model, own = fitted_model(train, robot)
    print(f"spread scale (x, y, z): {np.round(model.spread_scale_, 3).tolist()}, depth: "
          f"{'none' if model.spread_depth_ is None else model.spread_depth_.beta}")
    B = data["joint_configurations"]
    b_table(model, own, B, 5)
    b_table(model, own, B, None)
    c_table(model, data["random_poses"])
    print("rank j2: joint 2's offset's rank by evidence (the check's) / by BIC / by the raw drop of sum z^2; fitted: "
          "its fitted change (true angle minus the reading); first: the first explanation where it is not joint 2 "
          "(shared: the share of joint 2's change the first's parameters do too); taken: the step of forward "
          "selection that takes joint 2 (its evidence gain), - where it is not taken; beyond it: what forward "
          "selection takes after the likeliest")


if __name__ == "__main__":
    main()
