"""Identification from one target against three targets and the orientation (issue 20).

The virtual UR10 of configs/ur10_targets_virtual.yaml: three reflectors on a tool plate (A, the
primary, 120 mm out along the flange axis; B and C 100 mm off it), random DH deviations (0.5 mm,
0.03 deg twists, 0.05 deg zero offsets), a tool-plate and a base error, a tracker with 10 ppm noise
per reading (about 0.025 mm per coordinate at 2.5 m) and a T-Mac-like orientation noise of 0.005
degrees; 16 poses for identification, 400 for test, per seed. Each row: one seed of the config
(the true robot, the poses and the noise all change), the DH model (with tool and base) identified
from the primary target alone, from all three targets, and from all three and the orientation.

Columns: parameters identified (of the table's size) and the primary target's test 3-D RMS, mm,
against the measured test set (which carries its own tracker noise, about 0.043 mm 3-D) and
against the true error (what the model misses of the robot). Target: three targets identify more
parameters and reach a lower test RMS than one, on every seed.

Run: .venv/bin/python benchmarks/bench_targets.py   (about 10 s)
"""

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from partcal.data.simulate import load_study, simulate  # noqa: E402
from partcal.calibration.design import target_identifiability
from partcal.models.kinematic import KinematicModel  # noqa: E402

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "ur10_targets_virtual.yaml"
SEEDS = range(20, 30)


def rms(a):
    return float(np.sqrt(np.mean(np.sum(a**2, axis=1))))


def one_seed(seed: int, folder: Path) -> list:
    path = folder / f"seed_{seed}.yaml"
    path.write_text(CONFIG.read_text().replace("seed: 20", f"seed: {seed}"))
    study = load_study(path)
    data = simulate(study)
    ident, test = data["identification"], data["test"]
    targets = {k: (study.robot.targets[k], ident.measured_of(k) - ident.nominal_of(k)) for k in ("B", "C")}
    fits = {"one": {}, "three": {"targets": targets},
            "three + orientation": {"targets": targets, "orientation_deg": ident.orientation_errors_deg}}
    true = study.robot.true_positions(test.q_deg) - test.nominal_mm
    row = [seed]
    for kwargs in fits.values():
        model = KinematicModel(robot=study.robot.nominal).fit(ident.q_deg, ident.errors_mm, **kwargs)
        table = model.identification_
        predicted = model.predict(test.q_deg)
        row += [f"{table.status.count('identified')}/{len(table.names)}", f"{rms(test.errors_mm - predicted):.4f}",
                f"{rms(true - predicted):.4f}"]
    return row


def main() -> None:
    with tempfile.TemporaryDirectory() as folder:
        rows = [one_seed(seed, Path(folder)) for seed in SEEDS]
    numbers = np.array([[float(c) for c in r[1:] if "/" not in str(c)] for r in rows])
    rows.append(["mean", "", *[f"{v:.4f}" for v in numbers.mean(axis=0)[:2]], "",
                 *[f"{v:.4f}" for v in numbers.mean(axis=0)[2:4]], "", *[f"{v:.4f}" for v in numbers.mean(axis=0)[4:]]])
    header = ["seed"] + [f"{label} {c}" for label in ("1 target", "3 targets", "3 + orient.")
                         for c in ("identified", "test RMS", "vs true")]
    print_table("DH identification on the virtual UR10 with three targets (16 poses; 3-D RMS of the primary, mm)",
                header, rows)
    better = sum(float(r[5]) < float(r[2]) for r in rows[:-1])
    print(f"\nthree targets beat one on the measured test set in {better} of {len(rows) - 1} seeds")
    study = load_study(CONFIG)
    q = simulate(study)["identification"].q_deg
    print(f"seed 20, identifiability of the 16 poses: "
          f"{target_identifiability(study.robot.nominal, q, study.robot.targets).text()}")


if __name__ == "__main__":
    main()
