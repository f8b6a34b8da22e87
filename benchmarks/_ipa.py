"""The IPA UR10's files as the benchmarks read them: where ../shared holds them, their format, the split."""

from __future__ import annotations

from pathlib import Path

from partcal.data.formats import MeasurementFormat

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "datasets" / "ipa_ur10"
if not SHARED.is_dir():     # a git worktree one level deeper
    SHARED = ROOT.parents[1] / "shared" / "datasets" / "ipa_ur10"
COLUMNS = {"q1": "shoulder_pan_joint", "q2": "shoulder_lift_joint", "q3": "elbow_joint", "q4": "wrist_1_joint",
           "q5": "wrist_2_joint", "q6": "wrist_3_joint", "x_meas": "measurement_x", "y_meas": "measurement_y",
           "z_meas": "measurement_z"}
FORMAT = MeasurementFormat(delimiter=";", decimal=",", columns=COLUMNS, joint_unit="rad")
SPLIT = {"B 1-1000": ("Series_B/measurements_joint_configurations.csv", "1-1000"),
         "B 1001-1495": ("Series_B/measurements_joint_configurations.csv", "1001-1495"),
         "C": ("Series_C/measurements_random_poses.csv", None),
         "D": ("Series_D/measurements_iso_cubes.csv", None)}
"""The runs' split: identification on B 1-1000; tests on the rest of B, C and D (file, rows)."""
