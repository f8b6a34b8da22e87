"""The IPA UR10's series C offset (issue 20): a tracker frame of its own, or parameters B leaves open?

In the run of configs/ur10_ipa.yaml every model's predictions on series C (2,773 random poses, the
arm in the other shoulder configuration: joint 1 turned by about 180 degrees) sit a near-constant
~0.7 mm from the measurements in y and z. Either C was measured in another tracker frame than B,
or B's poses leave parameter combinations poorly determined that C's configuration separates.
Both are tested here, with the T-Mac's orientation (read with the format mapping rx_meas:
measurement_rx ..., intrinsic XYZ degrees) and with a frame of C's own:

1. the registrations: B's (as the run does, with the orientation too) and C's own, both with the
   probe's rotation on the flange;
2. DH identified on B alone, predicting C in B's frame (the run's situation);
3. one DH model identified on B and C together, (a) in B's frame, (b) with a frame of C's own (6
   more parameters, fitted jointly), each from positions and from positions and orientation;
4. the same with C's measurements shifted by a known (0, +0.7, -0.7) mm: what a real frame shift
   would look like.

Run: .venv/bin/python benchmarks/bench_ipa_series_c.py   (about 1 minute)
"""

import os
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

sys.path.insert(0, os.path.dirname(__file__))

from _table import print_table  # noqa: E402

from partcal import load_robot  # noqa: E402
from partcal.data.formats import MeasurementFormat, RowSelection  # noqa: E402
from partcal.data.measurements import read_measurements  # noqa: E402
from partcal.data.registration import register_measurements, registered  # noqa: E402
from partcal.models.kinematic import KinematicModel  # noqa: E402
from partcal.calibration.identification import stacked
from partcal.calibration.targets import Extra
from partcal.robot.kinematics import matrices_from_xyz_deg  # noqa: E402

SHARED = Path(__file__).resolve().parent.parent.parent / "shared" / "datasets" / "ipa_ur10"
if not SHARED.is_dir():     # a git worktree one level deeper
    SHARED = Path(__file__).resolve().parents[3] / "shared" / "datasets" / "ipa_ur10"
COLUMNS = {"q1": "shoulder_pan_joint", "q2": "shoulder_lift_joint", "q3": "elbow_joint", "q4": "wrist_1_joint",
           "q5": "wrist_2_joint", "q6": "wrist_3_joint", "x_meas": "measurement_x", "y_meas": "measurement_y",
           "z_meas": "measurement_z", "rx_meas": "measurement_rx", "ry_meas": "measurement_ry",
           "rz_meas": "measurement_rz"}
FORMAT = MeasurementFormat(delimiter=";", decimal=",", columns=COLUMNS, joint_unit="rad")
SHIFT = np.array([0.0, 0.7, -0.7])


def rms(a) -> float:
    return float(np.sqrt(np.mean(np.sum(a**2, axis=1))))


def turn(rotvec_deg):
    return Rotation.from_rotvec(rotvec_deg, degrees=True).as_matrix()


def angle_deg(rotation) -> float:
    return float(np.degrees(Rotation.from_matrix(rotation).magnitude()))


def read(robot, path, rows=None):
    return read_measurements(SHARED / path, robot, fmt=FORMAT, frame="tracker",
                             rows=RowSelection.parse(rows) if rows else None)


def joint_fit(robot, b, c, meas_c, own: bool, orientation: bool) -> list:
    """One DH model on B and C (C's measured positions ``meas_c``): B's and C's RMS, and C's frame when own."""
    kwargs = {"orientation_deg": np.vstack([b.orientation_errors_deg, c.orientation_errors_deg])} if orientation \
        else {}
    q = np.vstack([b.q_deg, c.q_deg])
    shared = KinematicModel(robot=robot).fit(q, np.vstack([b.errors_mm, meas_c - c.nominal_mm]), **kwargs)
    if not own:
        left = meas_c - c.nominal_mm - shared.predict(c.q_deg)
        return [rms(b.errors_mm - shared.predict(b.q_deg)), rms(left), np.round(left.mean(axis=0), 3), "", ""]
    table = shared.identification_
    free = np.flatnonzero(np.array(table.status) == "identified")
    rotations = np.concatenate([matrices_from_xyz_deg(m.measured_orientation_deg) for m in (b, c)])
    centre, n_b = meas_c.mean(axis=0), len(b)

    def residuals(x):       # the model's free parameters, then C's frame: a turn about C's centroid (deg), a shift
        values = table.value.copy()
        values[free] = x[:-6]
        frame = turn(x[-6:-3])
        moved = (meas_c - centre) @ frame.T + centre + x[-3:]
        turned = rotations.copy()
        turned[n_b:] = frame @ turned[n_b:]
        extra = Extra({}, {}, turned if orientation else None)
        return stacked(robot, None, q, values, np.zeros(len(q)), np.vstack([b.measured_mm, moved]), extra,
                       jacobian=False)[0]

    sol = least_squares(residuals, np.concatenate([table.value[free], np.zeros(6)]), method="lm", x_scale="jac")
    left = sol.fun[:3 * len(q)].reshape(-1, 3)
    return [rms(left[:n_b]), rms(left[n_b:]), np.round(left[n_b:].mean(axis=0), 3), np.round(sol.x[-6:-3], 4),
            np.round(sol.x[-3:], 3)]


def main() -> None:
    ur10 = load_robot("universal_robots_ur10")
    b_raw = read(ur10, "Series_B/measurements_joint_configurations.csv", "1-1000")
    c_raw = read(ur10, "Series_C/measurements_random_poses.csv")
    reg_b = register_measurements(ur10, b_raw, source="B")
    reg_c = register_measurements(ur10, c_raw, source="C")
    probe_b, probe_c = (Rotation.from_matrix(r.probe_rotation).as_rotvec(degrees=True) for r in (reg_b, reg_c))
    print_table("1. Registrations with the orientation (nominal UR10; each absorbs its series' rigid robot error)",
                ["series", "RMS mm", "orientation RMS deg", "tool mm", "probe turn deg", "condition"],
                [[name, f"{r.rms_3d:.3f}", f"{r.orientation_rms_deg:.4f}", np.round(r.tool_mm, 3), np.round(p, 3),
                  f"{r.condition:.1f}"] for name, r, p in (("B 1-1000", reg_b, probe_b), ("C own", reg_c, probe_c))])
    print(f"C's own frame against B's: turned by {angle_deg(reg_c.rotation @ reg_b.rotation.T):.4f} deg; the probes "
          f"on the flange differ by {angle_deg(reg_c.probe_rotation @ reg_b.probe_rotation.T):.4f} deg")

    robot = ur10.replace(tool_mm=reg_b.tool_mm)
    b, c = registered(b_raw, robot, reg_b), registered(c_raw, robot, reg_b)
    alone = KinematicModel(robot=robot).fit(b.q_deg, b.errors_mm)
    left = c.errors_mm - alone.predict(c.q_deg)
    print(f"\n2. DH identified on B alone, C in B's frame: C RMS {rms(left):.3f} mm, mean left "
          f"{np.round(left.mean(axis=0), 3)} mm (uncompensated {rms(c.errors_mm):.3f}); B RMS "
          f"{rms(b.errors_mm - alone.predict(b.q_deg)):.3f}")
    rows = []
    for label, meas_c in (("as measured", c.measured_mm), (f"C shifted by {SHIFT.tolist()}", c.measured_mm + SHIFT)):
        for orientation in (False, True):
            for own in (False, True):
                cells = joint_fit(robot, b, c, meas_c, own, orientation)
                rows.append([label, "+ orientation" if orientation else "positions", "own" if own else "B's",
                             f"{cells[0]:.3f}", f"{cells[1]:.3f}", *cells[2:]])
    print_table("3-4. One DH model on B and C: B's frame for both, or a frame of C's own fitted with it",
                ["C data", "fitted on", "C frame", "B RMS", "C RMS", "C mean left mm", "C frame turn deg",
                 "C frame shift mm"], rows)
    joint = KinematicModel(robot=robot).fit(np.vstack([b.q_deg, c.q_deg]), np.vstack([b.errors_mm, c.errors_mm]))
    table = alone.identification_
    moved = (joint.identification_.value - table.value) / table.std_error
    order = np.argsort(-np.nan_to_num(np.abs(moved)))[:6]
    print("\nparameters C moves most (in B's standard errors): " + ", ".join(
        f"{table.names[i]} {joint.identification_.value[i] - table.value[i]:+.3f} {table.units[i]} ({moved[i]:+.1f})"
        for i in order))


if __name__ == "__main__":
    main()
