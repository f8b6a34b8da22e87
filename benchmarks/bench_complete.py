"""The complete parametrization against DH on a virtual UR10 whose parallel axes are tilted (issue 30).

The virtual robot of configs/ur10_tilts_virtual.yaml (DH errors, tilts of 0.03 and -0.02 degrees
about y between joints 2-3 and 3-4, a misaligned base, 0.02 mm tracker noise) is measured on the
IPA UR10's real joint angles: identification on series B 1-1000, tests on B 1001-1495, C and D
(C: the other shoulder configuration). Each kinematic model (positions alone, base and tool
identified) is scored against the truth (the noise-free positions of the true robot) and against
the measurements; "noise" is the measurements' own RMS against the truth, the floor of a perfect
model. Run: .venv/bin/python benchmarks/bench_complete.py   (a few seconds)
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from _ipa import FORMAT, ROOT, SHARED, SPLIT  # noqa: E402

from partcal.data.formats import RowSelection  # noqa: E402
from partcal.data.measurements import read_measurements  # noqa: E402
from partcal.data.simulate import load_study  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402

SETS = {("B 1-1000 (identification)" if name == "B 1-1000" else name): where for name, where in SPLIT.items()}


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.sum(a**2, axis=1))))


def main() -> None:
    study = load_study(ROOT / "configs" / "ur10_tilts_virtual.yaml")
    vr = study.robot
    rng = np.random.default_rng(study.seed)
    data = {}
    for name, (path, rows) in SETS.items():
        q = read_measurements(SHARED / path, vr.nominal, fmt=FORMAT, frame="tracker",
                              rows=RowSelection.parse(rows) if rows else None).q_deg
        data[name] = (q, vr.measure(q, rng), vr.true_positions(q))
    q_id, meas_id, _ = data["B 1-1000 (identification)"]
    nominal = vr.nominal
    models, fits = {}, {}
    for par in ("dh", "complete"):
        start = time.process_time()
        models[par] = KinematicModel(robot=nominal, parametrization=par).fit(q_id, meas_id - nominal.positions(q_id))
        fits[par] = time.process_time() - start
    rows = []
    for name, (q, meas, truth) in data.items():
        predicted = {par: nominal.positions(q) + m.predict(q) for par, m in models.items()}
        rows.append([name, len(q), f"{rms(meas - truth):.4f}", f"{rms(meas - nominal.positions(q)):.3f}",
                     *(f"{rms(predicted[p] - truth):.4f}" for p in models),
                     *(f"{rms(predicted[p] - meas):.4f}" for p in models)])
    print_table("Virtual UR10 with tilts between parallel axes (0.03, -0.02 deg), IPA joint angles: 3-D RMS, mm",
                ["set", "poses", "noise", "uncompensated", "DH vs truth", "complete vs truth", "DH vs measured",
                 "complete vs measured"], rows)
    print_table("The identifications", ["parametrization", "identified", "parameters", "condition", "fit s"],
                [[p, m.identification_.status.count("identified"), len(m.identification_.names),
                  f"{m.identification_.condition:.3g}", f"{fits[p]:.2f}"] for p, m in models.items()])


if __name__ == "__main__":
    main()
