"""The floor a planned pose keeps above (partcal.robot.floor), checked with forward kinematics written out here."""

import contextlib
import io
import re

from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import SHARED

import partcal

from partcal.errors import PartcalError
from partcal.robot import load_robot
from partcal.robot.floor import Floor, above_floor, moving_points, robot_floor
from partcal.robot.iso_cube import cube_corners
from partcal.study import plan

# The UR10's standard DH rows (d, a, alpha) from the CB3 manual, written out independently of the YAML reader.
UR10_D = [118.0, 0.0, 0.0, 163.9, 115.7, 92.2]
UR10_A = [0.0, -612.7, -571.6, 0.0, 0.0, 0.0]
UR10_ALPHA = [90.0, 0.0, 0.0, 90.0, -90.0, 0.0]


def ur10_frame_origins(q_deg):
    """Origins of the UR10's frames 1..6 (the last the flange), shape (n, 6, 3) mm: T = Rz Tz Tx Rx per row."""
    out = np.zeros((len(q_deg), 6, 3))
    for i, q in enumerate(np.radians(q_deg)):
        T = np.eye(4)
        for k in range(6):
            ct, st = np.cos(q[k]), np.sin(q[k])
            ca, sa = np.cos(np.radians(UR10_ALPHA[k])), np.sin(np.radians(UR10_ALPHA[k]))
            T = T @ np.array([[ct, -st * ca, st * sa, UR10_A[k] * ct],
                              [st, ct * ca, -ct * sa, UR10_A[k] * st],
                              [0, sa, ca, UR10_D[k]],
                              [0, 0, 0, 1]])
            out[i, k] = T[:3, 3]
    return out


def cli(*args):
    from partcal.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def read_poses(path):
    rows = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    return np.array([[float(v) for v in row.split(",")[:6]] for row in rows[1:]])


def test_the_hand_written_fk_is_the_robots():
    robot = load_robot("universal_robots_ur10")
    q = np.random.default_rng(0).uniform(-180, 180, (20, 6))
    np.testing.assert_allclose(ur10_frame_origins(q), robot.frames(q)[0][:, 1:], atol=1e-9)


def test_the_ur10_stands_on_its_base_plane_and_the_sk120_has_no_floor():
    ur10, sk120 = load_robot("universal_robots_ur10"), load_robot("motoman_sk120")
    assert ur10.floor_mm == 0.0 and sk120.floor_mm is None
    assert robot_floor(ur10) == Floor(0.0, 100.0) and robot_floor(sk120) is None
    assert robot_floor(sk120, -650.0, 50.0) == Floor(-650.0, 50.0) and robot_floor(ur10, off=True) is None
    # the shoulder (frame 1, 118 mm up whatever q1 is) is the base's own: not checked
    assert moving_points(ur10).tolist() == [False, True, True, True, True, True, True]


@pytest.mark.parametrize("height, clearance", [(np.nan, 0.0), (0.0, -1.0), (0.0, np.inf)])
def test_a_bad_floor_is_refused_naming_the_value(height, clearance):
    with pytest.raises(PartcalError, match=r"floor.*got"):
        Floor(height, clearance)


def test_above_floor_agrees_with_the_hand_written_fk():
    robot = load_robot("universal_robots_ur10")
    q = np.random.default_rng(1).uniform(-360, 360, (500, 6))
    floor = Floor(0.0, 100.0)
    frames = ur10_frame_origins(q)[:, 1:]           # frames 2..6: frame 1 never moves
    expected = frames[:, :, 2].min(axis=1) >= 100.0   # the bare flange is the tool
    np.testing.assert_array_equal(above_floor(robot, q, floor), expected)
    assert 0.2 < expected.mean() < 0.8                # both kinds are present
    assert above_floor(robot, q, None).all()


def test_planned_ur10_poses_keep_every_link_above_the_floor(tmp_path):
    out = tmp_path / "plan.csv"
    code, _, err = cli("plan", "universal_robots_ur10", "-n", 30, "-o", out, "--pool", 400)
    assert code == 0 and "every link above the floor (z >= 100 mm: floor 0 mm + clearance 100 mm)" in err
    q = read_poses(out)
    assert q.shape == (30, 6)                         # resampled, not dropped: all 30 delivered
    assert ur10_frame_origins(q)[:, 1:, 2].min() >= 100.0
    code, _, _ = cli("plan", "universal_robots_ur10", "-n", 30, "-o", out, "--pool", 400, "--floor-mm", -500,
                     "--clearance-mm", 0, "-q")
    low = ur10_frame_origins(read_poses(out))[:, 1:, 2].min()
    assert code == 0 and -500.0 <= low < 100.0
    code, _, err = cli("plan", "universal_robots_ur10", "-n", 30, "-o", out, "--pool", 400, "--no-floor")
    assert code == 0 and ", no floor" in err
    assert ur10_frame_origins(read_poses(out))[:, 1:, 2].min() < 0     # without the floor, poses go below


def test_a_floor_that_leaves_no_room_gets_one_line():
    robot = load_robot("universal_robots_ur10")
    with pytest.raises(PartcalError, match=r"^only 0 of \d+ random joint-limit poses of universal_robots_ur10 are "
                                           r"admissible with every link above the floor \(z >= 2000 mm"):
        plan.candidates_within_limits(robot, 10, np.random.default_rng(0), floor=Floor(1900.0, 100.0))


def test_candidates_below_a_floor_the_command_states_are_refused_naming_the_row_and_the_point(tmp_path):
    """The cell's own candidates are checked against --floor-mm (or --clearance-mm), not the description's."""
    cand = tmp_path / "cand.csv"
    cand.write_text("q1,q2,q3,q4,q5,q6\n0,-90,0,-90,0,0\n0,0,0,0,0,0\n")
    code, _, err = cli("plan", "universal_robots_ur10", "-n", 2, "-o", tmp_path / "p.csv", "--candidates", cand)
    assert code == 0, err                                     # the built-in's floor_mm: 0 is for drawn poses
    code, _, err = cli("plan", "universal_robots_ur10", "-n", 1, "-o", tmp_path / "p.csv", "--candidates", cand,
                       "--floor-mm", 0)
    assert code == 2
    assert err.startswith("partcal: error: ") and err.count("\n") == 1
    assert ("cand.csv: data row 2 ([0.0, 0.0, 0.0, 0.0, 0.0, 0.0] deg) puts frame 5 at z = 2.3 mm, below the "
            "floor") in err


@pytest.mark.parametrize("args, message", [
    (["--floor-mm", "nan"], r"--floor-mm must be a finite number of mm .*got nan"),
    (["--clearance-mm", "-5"], r"--clearance-mm must be a number of mm >= 0; got -5.0"),
    (["--clearance-mm", "-1e1"], r"--clearance-mm must be a number of mm >= 0; got -10.0"),   # an exponent: a value
    (["--no-floor", "--floor-mm", "0"], r"--no-floor goes without --floor-mm"),
])
def test_bad_floor_options_get_one_line_and_exit_2(tmp_path, args, message):
    code, _, err = cli("plan", "universal_robots_ur10", "-n", 10, "-o", tmp_path / "p.csv", *args)
    assert code == 2 and err.count("\n") == 1
    assert re.search(message, err)


def test_a_clearance_without_any_floor_is_refused():
    code, _, err = cli("plan", "motoman_sk120", "-n", 10, "-o", "p.csv", "--clearance-mm", "50")
    assert code == 2 and "motoman_sk120 is described without one (floor_mm: null): give --floor-mm too" in err


def test_an_iso_cube_below_the_floor_is_refused_naming_its_corner(tmp_path):
    code, _, err = cli("plan", "universal_robots_ur10", "--iso9283", "-o", tmp_path / "p.csv",
                       "--cube", 600, 0, 100, 400)
    assert code == 2
    assert ("reaches below the floor of universal_robots_ur10 (z >= 100 mm: floor 0 mm + clearance 100 mm) at "
            "corner C1 [400.0, -200.0, -100.0] mm (4 of 8 corners below)") in err


def test_the_largest_iso_cube_and_its_poses_stay_above_the_floor(tmp_path):
    out = tmp_path / "p.csv"
    code, stdout, _ = cli("plan", "universal_robots_ur10", "--iso9283", "-o", out, "--cycles", 1)
    assert code == 0
    centre = np.array([float(v) for v in stdout.split("cube centre [")[1].split("]")[0].split(",")])
    edge = float(stdout.split("edge ")[1].split(" mm")[0])
    assert cube_corners(centre, edge)[:, 2].min() >= 100.0
    assert ur10_frame_origins(read_poses(out))[:, 1:, 2].min() >= 100.0


def test_a_floor_takes_numpy_numbers_and_refuses_a_bool():
    floor = Floor(np.int64(-650), np.float32(150.0))
    assert (floor.height_mm, floor.clearance_mm, floor.lowest_mm) == (-650.0, 150.0, -500.0)
    assert type(floor.height_mm) is float and floor == Floor(-650.0, 150.0)
    with pytest.raises(PartcalError, match=r"the floor's height must be a finite number of mm; got True"):
        Floor(True)


def test_a_negative_number_with_an_exponent_is_a_value_not_an_option():
    from partcal.cli import build_parser

    for text in ("-5e2", "-500", "-500.0", "-.5e3", "-5E+2"):
        args = build_parser().parse_args(["plan", "universal_robots_ur10", "-o", "p.csv", "--floor-mm", text])
        assert args.floor_mm == -500.0, text


IPA_SERIES_B = SHARED / "datasets" / "ipa_ur10" / "Series_B" / "measurements_joint_configurations.csv"
IPA_JOINTS = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint",
              "wrist_3_joint"]


def test_a_robot_described_without_floor_mm_has_no_floor(tmp_path):
    """No floor_mm (and a URDF's chain): no floor, and none written back; a stated one, 0 too, round-trips."""
    from partcal.robot.description import robot_from_dict, robot_to_dict
    from partcal.robot.urdf import robot_from_urdf

    spec = robot_to_dict(load_robot("universal_robots_ur10"))
    assert spec["floor_mm"] == 0.0
    del spec["floor_mm"]
    bare = robot_from_dict(spec)
    assert bare.floor_mm is None and robot_floor(bare) is None and "floor_mm" not in robot_to_dict(bare)
    assert robot_from_dict({**spec, "floor_mm": -650}).floor_mm == -650.0
    urdf = tmp_path / "one.urdf"
    urdf.write_text('<robot name="one"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
                    '<parent link="a"/><child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>'
                    '</robot>')
    assert robot_from_urdf(urdf).floor_mm is None
    path = tmp_path / "ur10.yaml"
    path.write_text(yaml.safe_dump(spec))
    code, _, err = cli("plan", path, "-n", 30, "-o", tmp_path / "p.csv", "--pool", 400)
    assert code == 0 and ", no floor" in err


def ipa_series_b_joints():
    """The 1495 joint sets (deg) of the IPA UR10's series B, read here from the tracker export (semicolons,
    decimal commas, radians)."""
    if not IPA_SERIES_B.is_file():
        pytest.skip(f"the IPA UR10 data set is not at {IPA_SERIES_B}")
    lines = IPA_SERIES_B.read_text().splitlines()
    header = lines[0].split(";")
    columns = [header.index(name) for name in IPA_JOINTS]
    rows = [line.split(";") for line in lines[1:] if line.strip()]
    return np.degrees(np.array([[float(row[c].replace(",", ".")) for c in columns] for row in rows]))


def test_a_cells_own_measured_poses_are_taken_as_candidates(tmp_path):
    """The IPA UR10's 1495 measured poses of series B as --candidates: taken with the built-in UR10 (floor_mm:
    0) and with a robot file without floor_mm; --floor-mm 0 refuses them naming as many poses below the floor
    (z < 100 mm) as the hand-written FK finds (34: the elbow's frame 2 near the base plane)."""
    q = ipa_series_b_joints()
    below = int((ur10_frame_origins(q)[:, 1:, 2].min(axis=1) < 100.0).sum())     # frames 2..6: the moving ones
    assert len(q) == 1495 and below == 34
    fmt = tmp_path / "fmt.yaml"
    fmt.write_text(yaml.safe_dump({"delimiter": ";", "decimal": ",", "joint_unit": "rad",
                                   "columns": {f"q{k + 1}": name for k, name in enumerate(IPA_JOINTS)}}))
    spec = yaml.safe_load((Path(partcal.__file__).parent / "robot" / "builtin" / "universal_robots_ur10.yaml")
                          .read_text())
    del spec["floor_mm"]
    bare = tmp_path / "ur10_pedestal.yaml"
    bare.write_text(yaml.safe_dump(spec))
    args = ["--candidates", IPA_SERIES_B, "--format", fmt, "-n", 30, "-o", tmp_path / "p.csv"]
    for robot in ("universal_robots_ur10", bare):
        code, _, err = cli("plan", robot, *args)
        assert code == 0, err
        assert "over the 1495 poses of" in err
    code, _, err = cli("plan", "universal_robots_ur10", *args, "--floor-mm", 0)
    assert code == 2 and f"; {below} of 1495 poses are below)" in err


def test_a_robot_built_in_python_without_a_floor_has_none():
    """A floor not stated is not assumed, in Python as in a description: a Robot given no floor_mm keeps every
    pose a plan may take, below its base plane too; given one, poses below it are not above the floor."""
    from dataclasses import replace

    ur10 = load_robot("universal_robots_ur10")
    fields = {f: getattr(ur10, f) for f in ur10.__dataclass_fields__ if f != "floor_mm"}
    bare = type(ur10)(**fields)
    assert bare.floor_mm is None and robot_floor(bare) is None
    low = np.array([[0.0, 30.0, 0.0, 0.0, 90.0, 0.0]])              # the arm reaching down: the tool at z = -620 mm
    assert bare.positions(low)[0, 2] < -600 and above_floor(bare, low, robot_floor(bare)).all()
    floored = replace(bare, floor_mm=0.0)
    assert not above_floor(floored, low, robot_floor(floored)).any()
