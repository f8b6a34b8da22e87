"""Series C of the IPA UR10: another tracker frame, or what series B leaves unidentified? (issue 20)

In the configs/ur10_ipa.yaml run every model's predictions on series C (random poses) sit a
near-constant ~0.7 mm away from the measurements in y and z. Two explanations fit that picture:
the tracker frame of C differs from B's, or B's poses (q1 from -180 to -45 degrees, one arm
configuration) leave combinations of parameters ill-determined that C's poses (q1 from -308 to
-180) separate. They predict different things:

- a frame of its own: a rigid transform fitted to C alone removes the offset whatever its cause,
  so it cannot tell them apart by itself; but if the frame moved, no single frame can hold B and
  C with one set of kinematic parameters;
- one frame for both: DH identified on B and C together, with one base pose (the frame). If the
  frames differ, the fit leaves C's offset (a base translation is shared, and no other parameter
  makes a constant offset over C's joint ranges); if B left parameters ill-determined, it fits
  both as well as each alone.
- the T-Mac's orientation (tracker frame, intrinsic XYZ degrees): the tracker-to-base rotation
  fitted from orientations alone, per series (with the probe's mount on the flange), to compare
  with how far it can be trusted (the orientation residual of the nominal kinematics).

Measured 2026-11-23 (all 1,000 + 495 poses of B, 2,773 of C, 632 of D):
DH on B: C 1.040 mm, mean offset (+0.07, +0.39, -0.74); C in a frame of its own 0.572 mm, the
frame "moved" 0.84 mm and 0.066 deg. DH on B + C in one frame: B 0.449 (0.412 alone), C 0.520
(0.488 alone), mean offsets below 0.03 mm; C's own frame then moves 0.008 mm and 0.005 deg.
Orientation: B and C's tracker rotations differ by 0.08 deg, B's two halves by 0.04 deg, with
0.07-0.10 deg orientation residuals of the nominal model; D (tracker moved) by 133 deg.
Verdict: one tracker frame holds B and C; the offset is B's identification extrapolated: adding
C moves theta[2], a[1], a[2], a[3] and the base tilt by 4-7 of B's standard errors.

    .venv/bin/python benchmarks/bench_ur10_frames.py      (about 10 seconds)
"""

from __future__ import annotations

import csv
import os
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from partcal import KinematicModel, load_robot  # noqa: E402
from partcal.study.config import load_config  # noqa: E402
from partcal.study.registry import load_datasets  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "datasets" / "ipa_ur10"
JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
          "wrist_3_joint"]


def rms(r) -> float:
    return float(np.sqrt(np.mean(np.sum(r ** 2, axis=1))))


def own_frame(predicted, measured):
    """Residual RMS (mm) after the best rigid transform of ``predicted`` onto ``measured``, the shift of C's
    centre (mm) and the rotation (deg) of that transform."""
    mp, mq = predicted.mean(0), measured.mean(0)
    U, _, Vt = np.linalg.svd((predicted - mp).T @ (measured - mq))
    R = Vt.T @ np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))]) @ U.T
    t = mq - R @ mp
    moved = np.linalg.norm(R @ mp + t - mp)
    return rms(measured - (predicted @ R.T + t)), moved, np.degrees(Rotation.from_matrix(R).magnitude())


def orientations(path: Path, rows=None):
    """Joint angles (deg) and the measured T-Mac rotations (tracker frame) of one series file."""
    with open(path) as handle:
        table = list(csv.reader(handle, delimiter=";"))
    header, data = table[0], table[1:][slice(*rows) if rows else slice(None)]

    def column(name):
        return np.array([float(r[header.index(name)].replace(",", ".")) for r in data])

    q = np.degrees(np.column_stack([column(j) for j in JOINTS]))
    angles = np.column_stack([column(f"measurement_r{a}") for a in "xyz"])
    return q, Rotation.from_euler("XYZ", angles, degrees=True).as_matrix()


def tracker_rotation(robot, q, measured):
    """Tracker-to-base and flange-to-probe rotations fitted to the measured orientations: the two
    rotations and the residual RMS (deg)."""
    nominal = robot.forward(q)[:, :3, :3]

    def residual(x):
        frame, mount = Rotation.from_rotvec(x[:3]).as_matrix(), Rotation.from_rotvec(x[3:]).as_matrix()
        return Rotation.from_matrix(frame @ nominal @ mount @ measured.transpose(0, 2, 1)).as_rotvec().ravel()

    start = np.r_[Rotation.from_matrix(measured[0] @ nominal[0].T).as_rotvec(), np.zeros(3)]
    fit = least_squares(residual, start, method="lm")
    r = residual(fit.x).reshape(-1, 3)
    return Rotation.from_rotvec(fit.x[:3]), np.degrees(np.sqrt(np.mean(np.sum(r ** 2, axis=1))))


def main() -> None:
    data, robot, _ = load_datasets(load_config(ROOT / "configs" / "ur10_ipa.yaml"))
    sets = {"B": data["identification"], "rest of B": data["joint_configurations"], "C": data["random_poses"]}

    def fit(names):
        return KinematicModel(robot=robot).fit(np.vstack([sets[n].q_deg for n in names]),
                                               np.vstack([sets[n].errors_mm for n in names]))

    rows, models = [], {}
    for names in (["B"], ["C"], ["B", "C"]):
        model = models[" + ".join(names)] = fit(names)
        resid = {k: m.errors_mm - model.predict(m.q_deg) for k, m in sets.items()}
        own = own_frame(sets["C"].nominal_mm + model.predict(sets["C"].q_deg), sets["C"].measured_mm)
        rows.append([" + ".join(names)] + [f"{rms(r):.3f}" for r in resid.values()]
                    + ["(" + ", ".join(f"{v:+.2f}" for v in resid["C"].mean(0)) + ")",
                       f"{own[0]:.3f}", f"{own[1]:.3f} mm, {own[2]:.4f} deg"])
    print_table("DH identified on each set, in the tracker frame registered on B (mm)",
                ["DH on", "B", "rest of B", "C", "C mean offset", "C in its own frame", "that frame's move"], rows)

    alone, both = models["B"].identification_, models["B + C"].identification_
    moved = sorted(((abs(both.value[i] - alone.value[i]) / alone.std_error[i], name)
                    for i, name in enumerate(alone.names)
                    if alone.status[i] == both.status[i] == "identified"), reverse=True)[:6]
    print_table("Parameters that adding C moves most (in standard errors of the fit on B)",
                ["parameter", "moved (SE)"], [[name, f"{z:.1f}"] for z, name in moved])

    ur10 = load_robot("universal_robots_ur10")
    series = {"B": ("Series_B/measurements_joint_configurations.csv", (0, 1000)),
              "rest of B": ("Series_B/measurements_joint_configurations.csv", (1000, None)),
              "C": ("Series_C/measurements_random_poses.csv", None),
              "D": ("Series_D/measurements_iso_cubes.csv", None)}
    frames, rows = {}, []
    for name, (path, span) in series.items():
        frames[name], residual = tracker_rotation(ur10, *orientations(SHARED / path, span))
        rows.append([name, f"{residual:.3f}", f"{np.degrees((frames[name] * frames['B'].inv()).magnitude()):.3f}"])
    print_table("Tracker-to-base rotation from the measured orientations alone (deg)",
                ["series", "orientation residual", "rotation from B's"], rows)


if __name__ == "__main__":
    main()
