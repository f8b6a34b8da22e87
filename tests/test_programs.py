"""Compensated robot programs (URScript, KRL, RAPID, joint trajectories): byte-exact rewriting, the vendors'
conventions, the true robot on the intended poses, and the refusals."""

import json
import re
import warnings

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from partcal import ErrorModel, load_robot
from partcal.data.programs import ProgramSyntaxError, UnknownFrameError, program_kind, read_program
from partcal.errors import PartcalError
from partcal.data.simulate import load_study
from partcal.models.kinematic import KinematicModel
from partcal.robot.rotations import (kuka_abc_from_matrices, matrices_from_kuka_abc, matrices_from_quaternions,
                                     quaternions_from_matrices, rotation_vectors_from_matrices)
from partcal.study.persist import model_to_dict, save_model
from partcal.study.predictor import Predictor
from partcal.study.programs import ProgramFrames, compensate_program

FIXTURES = ROOT / "tests" / "fixtures" / "programs"
UR10, SK120 = load_robot("universal_robots_ur10"), load_robot("motoman_sk120")
PROGRAMS = [("pick_place.script", UR10, 6), ("pallet.dat", SK120, 5), ("pallet.src", SK120, 2),
            ("pallet.mod", SK120, 6), ("trajectory.csv", UR10, 3)]


def constant_model(robot, error, inputs="cartesian", name="const"):
    """A model predicting the same error everywhere (zeros: the zero model), with its robot."""
    rng = np.random.default_rng(0)
    X = rng.uniform(-1000, 1000, (40, 3)) if inputs == "cartesian" else rng.uniform(-90, 90, (40, 6))
    model = ErrorModel(inputs=inputs, degree=1, solver="lstsq").fit(X, np.tile(error, (len(X), 1)))
    return Predictor(model, model_to_dict(model, name=name, robot=robot), robot)


def run(*args):
    """``partcal ARGS`` in this process: its exit code and stderr (as ``partcal_cli`` gives them)."""
    import contextlib
    import io
    import types

    from partcal.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(args))
    return types.SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def compensated(predictor, path, frames=None, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return compensate_program(predictor, read_program(path), frames, **kwargs)


# ---------------------------------------------------------------------- byte for byte
@pytest.mark.parametrize("inputs", ["cartesian", "joint"])
@pytest.mark.parametrize("outputs", [3, 6])
@pytest.mark.parametrize("name, robot, count", PROGRAMS)
def test_a_zero_model_writes_the_program_back_byte_for_byte(name, robot, count, inputs, outputs):
    result = compensated(constant_model(robot, np.zeros(outputs), inputs), FIXTURES / name)
    assert len(result.program.targets) == count and not result.failures
    assert result.output == (FIXTURES / name).read_bytes()


def repository_programs() -> list:
    """Every robot program of the repository (its fixtures and examples, not .venv, .git nor reports), with the
    robot it is written for: the UR10 for URScript and joint trajectories, the SK120 for KRL and RAPID."""
    import os

    from partcal.data.programs import DIALECTS

    suffixes = {e for d in DIALECTS.values() for e in d.extensions}
    found = []
    for folder, subfolders, files in os.walk(ROOT):
        subfolders[:] = sorted(d for d in subfolders if d not in (".venv", ".git", "reports", "__pycache__"))
        for name in sorted(files):
            path = ROOT / folder / name
            kind = program_kind(path) if path.suffix.lower() in suffixes else None
            if kind is not None:
                found.append((path, UR10 if kind in ("urscript", "joints") else SK120))
    return found


@pytest.mark.parametrize("inputs, outputs", [("cartesian", 3), ("joint", 6)])
def test_every_program_of_the_repository_comes_back_byte_for_byte_from_a_model_that_predicts_nothing(inputs, outputs):
    """A cell diffs the compensated program against the one it runs: with no error to correct, every program
    that compensates (exit 0) comes back as it was, whatever its numbers' style (PolyScope's 12 decimals without
    a leading zero, a RobotStudio quaternion of 4 decimals a hair off unit, KSS's $config.dat)."""
    compared = []
    for path, robot in repository_programs():
        try:
            result = compensated(constant_model(robot, np.zeros(outputs), inputs), path)
        except PartcalError:
            continue                                     # exit 2: a frame to give; not an exit-0 program
        if not result.failures:
            assert result.output == path.read_bytes(), path
            compared.append(path.relative_to(FIXTURES).as_posix() if FIXTURES in path.parents else path.name)
    assert {"polyscope_export.script", "robotstudio_taught.mod", "taco_pick.mod", "kuka_home/$config.dat",
            "kuka_home/glue.src", "kuka_home/glue.dat", "kuka_cell/weld.src", "kuka_cell/weld.dat"} <= set(compared)
    assert len(compared) == len(repository_programs())


def test_a_joint_trajectory_with_a_utf8_byte_order_mark_before_its_comment_is_read_and_keeps_it(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbf" + (FIXTURES / "trajectory.csv").read_bytes())
    assert program_kind(path) == "joints"
    result = compensated(constant_model(UR10, np.zeros(3)), path)
    assert len(result.program.targets) == 3 and result.output == path.read_bytes()


def test_a_crlf_urscript_program_keeps_its_line_endings(tmp_path):
    path = tmp_path / "crlf.script"
    path.write_bytes((FIXTURES / "pick_place.script").read_bytes().replace(b"\n", b"\r\n"))
    result = compensated(constant_model(UR10, [0.3, -0.2, 0.1]), path)
    out = result.output
    assert out != path.read_bytes() and out.count(b"\r\n") == out.count(b"\n") == path.read_bytes().count(b"\n")


def test_targets_are_found_where_the_vendors_syntax_puts_them():
    ur = read_program(FIXTURES / "pick_place.script")
    assert [(t.name, t.line, t.kind) for t in ur.targets] == [
        ("home", 6, "joints"), ("approach", 7, "pose"), ("movel", 10, "pose"), ("movep", 11, "pose"),
        ("movej", 14, "joints"), ("movel", 15, "pose")]          # not the comment, the string nor pose_add's offset
    np.testing.assert_allclose(ur.targets[1].position_mm, [-744.6, -297.7, 429.9])
    assert ur.targets[1].tool == "set_tcp at line 4"
    np.testing.assert_allclose(ur.frames["set_tcp at line 4"][:3, 3], [0, 0, 100])
    krl = read_program(FIXTURES / "pallet.dat")
    assert [(t.name, t.configuration) for t in krl.targets] == [
        ("XHOME", None), ("XP1", (2, 6)), ("XP2", (2, 47)), ("XP3", (2, 22)), ("XP4", None)]
    assert (krl.targets[1].frame, krl.targets[1].tool) == ("$NULLFRAME", "$NULLFRAME")     # FDAT FP1: 0 and 0
    rapid = read_program(FIXTURES / "pallet.mod")
    assert [(t.name, t.tool, t.frame) for t in rapid.targets if t.kind == "pose"] == [
        ("p10", "tool0", "wobj0"), ("p20", "tool0", "wobj0"), ("p30", "tGripper", "wTable"),
        ("MoveL", "tool0", "wobj0")]
    np.testing.assert_allclose(rapid.frames["wTable"][:3, 3], [1000, 0, 500])
    np.testing.assert_allclose(rapid.frames["tGripper"][:3, 3], [0, 0, 100])


def test_program_kinds_come_from_the_file_name_and_a_csv_header(tmp_path):
    assert [program_kind(FIXTURES / n) for n, _, _ in PROGRAMS] == ["urscript", "krl", "krl", "rapid", "joints"]
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y,z,q1,q2,q3,q4,q5,q6\n1,2,3,0,0,0,0,0,0\n")
    assert program_kind(targets) is None          # a targets CSV with IK seeds stays a targets CSV


# ---------------------------------------------------------------------- conventions, by hand
def test_kuka_abc_is_z_then_y_then_x():
    # A 90, C 90: x -> y (the turn about z), y -> z (about x, then z), z -> x
    np.testing.assert_allclose(matrices_from_kuka_abc([[90.0, 0.0, 90.0]])[0],
                               [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-15)
    np.testing.assert_allclose(matrices_from_kuka_abc([[0.0, 90.0, 0.0]])[0] @ [1, 0, 0], [0, 0, -1], atol=1e-15)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    np.testing.assert_allclose(matrices_from_kuka_abc([[0.0, 0.0, 30.0]])[0], [[1, 0, 0], [0, c, -s], [0, s, c]],
                               atol=1e-15)
    # A = 180 stays 180 beside an old 180 (not -180); without it, atan2's -180 or 180
    half = matrices_from_kuka_abc([[180.0, 10.0, -20.0]])
    np.testing.assert_allclose(kuka_abc_from_matrices(half, near=[[179.0, 0.0, 0.0]]), [[180.0, 10.0, -20.0]],
                               atol=1e-9)
    np.testing.assert_allclose(kuka_abc_from_matrices(half, near=[[-179.0, 0.0, 0.0]]), [[-180.0, 10.0, -20.0]],
                               atol=1e-9)


@settings(max_examples=50, deadline=None)
@given(st.floats(-180, 180), st.floats(-89.9, 89.9), st.floats(-180, 180), st.floats(-0.01, 0.01))
def test_every_writing_comes_back_near_the_old_one(a, b, c, nudge):
    """A rotation turned by a hundredth of a degree or less reads back within that of its old writing, in all
    three vendors' forms (KUKA angles, quaternions of either sign, rotation vectors of any angle)."""
    old_abc = np.array([[a, b, c]])
    R = matrices_from_kuka_abc(old_abc)
    turned = Rotation.from_rotvec(np.radians([nudge, -nudge, nudge])).as_matrix() @ R
    assert np.abs(kuka_abc_from_matrices(turned, near=old_abc) - old_abc).max() < 0.05 / np.cos(np.radians(b))
    for sign in (1.0, -1.0):
        old_q = sign * quaternions_from_matrices(R)
        assert np.abs(quaternions_from_matrices(turned, near=old_q) - old_q).max() < 1e-3
    old_r = rotation_vectors_from_matrices(R)
    twin = old_r - 2 * np.pi * old_r / max(np.linalg.norm(old_r), 1e-12)
    for old in (old_r, twin) if np.linalg.norm(old_r) > 3.0 else (old_r,):
        assert np.abs(rotation_vectors_from_matrices(turned, near=old) - old).max() < 2e-3


def test_a_krl_target_reads_as_the_hand_computed_rotation(tmp_path):
    path = tmp_path / "one.dat"
    path.write_bytes(b"DEFDAT ONE\r\nDECL E6POS XP1={X 1000,Y 0,Z 1500,A 90,B 0,C 90,S 6,T 0}\r\nENDDAT\r\n")
    t = read_program(path).targets[0]
    np.testing.assert_allclose(t.rotation, [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-15)
    np.testing.assert_allclose(t.position_mm, [1000, 0, 1500])


def test_abb_quaternions_are_scalar_first_and_keep_the_sign_they_were_written_with():
    r = np.sqrt(0.5)
    np.testing.assert_allclose(matrices_from_quaternions([[r, 0, 0, r]])[0], [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
                               atol=1e-15)                          # 90 degrees about z
    turn = matrices_from_quaternions([[r, 0, 0, r]])
    np.testing.assert_allclose(quaternions_from_matrices(turn, near=[[-r, 0, 0, -r]]), [[-r, 0, 0, -r]], atol=1e-15)
    np.testing.assert_allclose(quaternions_from_matrices(turn), [[r, 0, 0, r]], atol=1e-15)


def test_a_compensated_robtarget_keeps_its_quaternion_hemisphere():
    result = compensated(constant_model(SK120, [0.2, 0.1, -0.3, 2.0, -1.0, 0.5]), FIXTURES / "pallet.mod")
    p20 = re.search(rb"p20 := \[ \[[^\]]*\], \[([^\]]*)\]", result.output).group(1)
    q = np.array([float(v) for v in p20.split(b",")])
    assert q[0] < 0 and abs(np.linalg.norm(q) - 1) < 1e-8           # written as -q, as the original
    assert np.dot(q, [-0.388956, -0.519826, -0.170439, -0.741245]) > 0.9999


def test_ur_rotation_vectors_near_half_a_turn_stay_on_the_written_side():
    beyond = Rotation.from_rotvec([0.0, np.pi + 0.001, 0.0]).as_matrix()[None]      # half a turn and a bit about y
    np.testing.assert_allclose(rotation_vectors_from_matrices(beyond, near=[[0.0, 3.1415, 0.0]]),
                               [[0.0, np.pi + 0.001, 0.0]], atol=1e-12)
    np.testing.assert_allclose(rotation_vectors_from_matrices(beyond), [[0.0, -(np.pi - 0.001), 0.0]], atol=1e-12)


def test_a_ur_target_at_half_a_turn_is_written_near_its_old_vector(tmp_path):
    q = np.array([[10.0, -80.0, 90.0, -100.0, -90.0, 20.0]])
    pose = UR10.flange(q)[0]
    r = rotation_vectors_from_matrices(pose[None, :3, :3])[0]
    flipped = r - 2 * np.pi * r / np.linalg.norm(r)            # the same rotation, the other way round
    path = tmp_path / "half.script"
    text = "movel(p[{:.6f}, {:.6f}, {:.6f}, {:.9f}, {:.9f}, {:.9f}])\n".format(*(pose[:3, 3] / 1000), *flipped)
    path.write_text(text)
    result = compensated(constant_model(UR10, [0.0, 0.0, 0.0, 0.0, 0.0, 1.0]), path)       # a 1 mrad turn about z
    new = np.array([float(v) for v in re.search(r"p\[([^\]]*)\]", result.output.decode()).group(1).split(",")])
    assert np.linalg.norm(new[3:] - flipped) < 0.01                  # moved by about a mrad, not by 2 pi
    angle = np.degrees(Rotation.from_matrix(Rotation.from_rotvec(new[3:]).as_matrix() @ pose[:3, :3].T).magnitude())
    assert 0.05 < angle < 0.06                                       # 1 mrad = 0.0573 degrees turned back


# ---------------------------------------------------------------------- the true robot on the intended poses
def pose_errors_of(virtual, q):
    """The virtual robot's true pose errors at commanded joints: position mm, rotation vector mrad."""
    N = virtual.nominal.forward(q)
    turn = Rotation.from_matrix(virtual.true_flange(q)[1] @ N[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
    return np.hstack([virtual.true_positions(q) - N[:, :3, 3], 1000.0 * turn])


def fitted(config, centre, spread, tmp_path, **kwargs):
    """A kinematic pose model fitted by a run (``partcal run``'s stages) on 48 noise-free poses of a virtual
    robot, its model file loaded back. ``kwargs``: the entry's keys."""
    import yaml

    from partcal import load_predictor
    from partcal.data.measurements import Measurements, write_measurements
    from partcal.robot.description import robot_to_dict
    from partcal.robot.kinematics import xyz_deg_from_matrices
    from partcal.study.config import load_config
    from partcal.study.outputs import write_run
    from partcal.study.runner import run as run_study

    virtual = load_study(ROOT / "configs" / config).robot
    rng = np.random.default_rng(1)
    q = np.array(centre) + rng.uniform(-spread, spread, (400, 6))
    q = q[virtual.nominal.within_limits(q)][:48]
    nominal = virtual.nominal.forward(q)
    m = Measurements(q_deg=q, nominal_mm=nominal[:, :3, 3], measured_mm=virtual.true_positions(q),
                     name="identification", nominal_orientation_deg=xyz_deg_from_matrices(nominal[:, :3, :3]),
                     measured_orientation_deg=xyz_deg_from_matrices(virtual.true_flange(q)[1]))
    write_measurements(m, tmp_path / "identification.csv")
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(robot_to_dict(virtual.nominal)))
    entry = {"name": "DH pose", "kind": "kinematic", "use_orientation": True,
             **{k: list(v) for k, v in kwargs.items()}}
    (tmp_path / "run.yaml").write_text(yaml.safe_dump({
        "name": "virtual", "robot": "robot.yaml", "predict": "pose", "cv_folds": 3,
        "data": {"identification": "identification.csv"}, "models": [entry], "output": "out"}))
    write_run(run_study(load_config(tmp_path / "run.yaml")))
    (tmp_path / "model.json").write_bytes((tmp_path / "out" / "models" / "dh-pose.json").read_bytes())
    return virtual, load_predictor(tmp_path / "model.json")


def reached_misses(virtual, predictor, q_cmd, wanted_tool_point):
    """What the true robot misses the intended poses of the model's tool point by, mm and degrees, and the part
    of it that is the model's own prediction error."""
    real = virtual.true_positions(q_cmd), virtual.true_flange(q_cmd)[1]
    miss_mm = np.linalg.norm(real[0] - wanted_tool_point[:, :3, 3], axis=1)
    miss_deg = Rotation.from_matrix(real[1] @ wanted_tool_point[:, :3, :3].transpose(0, 2, 1)).magnitude()
    own = pose_errors_of(virtual, q_cmd) - predictor.predict(joints=q_cmd)
    return miss_mm, np.degrees(miss_deg), np.linalg.norm(own[:, :3], axis=1), np.degrees(
        np.linalg.norm(own[:, 3:], axis=1) / 1000)


def controller_joints(robot, program, frames, tools, seeds):
    """The nominal controller: each rewritten pose target's TCP in its frame, solved on the seeds' branch."""
    from partcal.robot.rotations import inverse_poses, poses_from

    P = poses_from([t.position_mm for t in program.targets], [t.rotation for t in program.targets])
    tool_point = frames @ P @ inverse_poses(tools) @ poses_from(robot.tool_mm, np.eye(3))
    ik = robot.inverse_pose(tool_point, seeds, tol_mm=1e-9, tol_deg=1e-9)
    assert ik.success.all()
    return ik.q_deg


def test_the_virtual_ur10_lands_on_the_intended_poses_of_a_urscript_program(tmp_path):
    virtual, predictor = fitted("ur10_targets_virtual.yaml", [20, -70, 90, -100, -80, 10], 40, tmp_path)
    nominal = virtual.nominal
    q = np.array([20, -70, 90, -100, -80, 10]) + np.random.default_rng(2).uniform(-25, 25, (12, 6))
    feature = np.array([400.0, -100.0, 50.0, 0.1, -0.2, 0.3])                   # mm, then a rotation vector
    from partcal.robot.rotations import inverse_poses, poses_from
    F = poses_from(feature[:3], Rotation.from_rotvec(feature[3:]).as_matrix())[0]
    tcp = poses_from(nominal.tool_mm, np.eye(3))[0]                              # the TCP is the model's tool point
    P = inverse_poses(F) @ nominal.forward(q)                                    # the intended TCP in the feature
    values = np.hstack([P[:, :3, 3] / 1000, Rotation.from_matrix(P[:, :3, :3]).as_rotvec()])     # m, rad
    lines = [f"  movel(pose_trans(table, p[{', '.join(f'{v:.9f}' for v in row)}]), a=1.2, v=0.25)  # {k}"
             for k, row in enumerate(values)]
    path = tmp_path / "virtual.script"
    path.write_text("def run():\n  set_tcp(p[0, 0, 0.12, 0, 0, 0])\n" + "\n".join(lines) + "\nend\n")
    feature_text = f"table=p[{', '.join(f'{v:.12g}' for v in (*feature[:3] / 1000, *feature[3:]))}]"
    out = tmp_path / "out.script"
    done = run("compensate", str(tmp_path / "model.json"), str(path), "-o", str(out), "--frame", feature_text)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "out.script.json").read_text())
    assert summary["compensated"] == 12 and summary["largest_correction"]["mm"] > 0.9
    assert summary["largest_turn"]["deg"] > 0.1 and summary["predicted_residual"]["max_mm"] < 1e-4
    program = read_program(out)
    q_cmd = controller_joints(nominal, program, np.tile(F, (12, 1, 1)), np.tile(tcp, (12, 1, 1)), q)
    wanted = nominal.forward(q)
    miss_mm, miss_deg, own_mm, own_deg = reached_misses(virtual, predictor, q_cmd, wanted)
    assert miss_mm.max() < 1e-3 and miss_deg.max() < 1e-4
    assert np.all(miss_mm <= own_mm + 1e-3) and np.all(miss_deg <= own_deg + 1e-4)
    before_mm = np.linalg.norm(virtual.true_positions(q) - wanted[:, :3, 3], axis=1)
    assert before_mm.min() > 0.9                                                # uncompensated: 0.96 to 1.63 mm


@pytest.mark.parametrize("dialect", ["krl", "rapid"])
def test_the_virtual_sk120_lands_on_the_intended_poses_of_krl_and_rapid_programs(tmp_path, dialect):
    virtual, predictor = fitted("sk120_virtual.yaml", [0, -120, -170, 0, 30, 0], 20, tmp_path,
                                compliance=(2, 3), joint_harmonics=[1, 2, 2, 0, 0, 1])
    nominal = virtual.nominal
    q = np.array([0, -120, -170, 0, 30, 0]) + np.random.default_rng(3).uniform(-12, 12, (10, 6))
    q = q[nominal.within_limits(q)]
    from partcal.robot.rotations import inverse_poses, poses_from
    base = poses_from([800.0, -200.0, 100.0], matrices_from_kuka_abc([[30.0, 0.0, 0.0]]))[0]
    tool = poses_from(nominal.tool_mm, matrices_from_kuka_abc([[0.0, 90.0, 0.0]]))[0]     # the TCP turned 90 degrees
    P = inverse_poses(base) @ nominal.forward(q) @ inverse_poses(poses_from(nominal.tool_mm, np.eye(3))) @ tool
    if dialect == "krl":
        abc = kuka_abc_from_matrices(P[:, :3, :3])
        T = ((q < 0) * (1 << np.arange(6))).sum(axis=1)
        body = "".join(f"DECL E6POS XP{k}={{X {P[k, 0, 3]:.6f},Y {P[k, 1, 3]:.6f},Z {P[k, 2, 3]:.6f},A {abc[k, 0]:.7f},"
                       f"B {abc[k, 1]:.7f},C {abc[k, 2]:.7f},S 2,T {T[k]}}}\r\n"
                       f"DECL FDAT FP{k}={{TOOL_NO 1,BASE_NO 1,IPO_FRAME #BASE}}\r\n" for k in range(len(q)))
        text = "DEFDAT VIRTUAL\r\nBASE_DATA[1]={X 800,Y -200,Z 100,A 30,B 0,C 0}\r\n" + body + "ENDDAT\r\n"
        frames = ProgramFrames(tools={"TOOL_DATA[1]": tool})
        path = tmp_path / "virtual.dat"
    else:
        quat = quaternions_from_matrices(P[:, :3, :3])
        cf = np.floor(q[:, [0, 3, 5]] / 90).astype(int)
        body = "".join(f"  CONST robtarget p{k}:=[[{P[k, 0, 3]:.6f},{P[k, 1, 3]:.6f},{P[k, 2, 3]:.6f}],"
                       f"[{quat[k, 0]:.9f},{quat[k, 1]:.9f},{quat[k, 2]:.9f},{quat[k, 3]:.9f}],"
                       f"[{cf[k, 0]},{cf[k, 1]},{cf[k, 2]},0],[9E9,9E9,9E9,9E9,9E9,9E9]];\r\n" for k in range(len(q)))
        moves = "".join(f"    MoveL p{k}, v100, fine, tProbe\\WObj:=wFixture;\r\n" for k in range(len(q)))
        text = ("MODULE Virtual\r\n  TASK PERS wobjdata wFixture:=[FALSE,TRUE,\"\",[[800,-200,100],"
                f"[{np.cos(np.radians(15)):.12f},0,0,{np.sin(np.radians(15)):.12f}]],[[0,0,0],[1,0,0,0]]];\r\n" + body +
                "  PROC main()\r\n" + moves + "  ENDPROC\r\nENDMODULE\r\n")
        frames = ProgramFrames(tools={"tProbe": tool})
        path = tmp_path / "virtual.mod"
    path.write_bytes(text.encode("latin-1"))
    result = compensated(predictor, path, frames)
    assert not result.failures and result.correction_mm.min() > 1.0
    out = tmp_path / ("out" + path.suffix)
    out.write_bytes(result.output)
    program = read_program(out)
    n = len(q)
    q_cmd = controller_joints(nominal, program, np.tile(base, (n, 1, 1)), np.tile(tool, (n, 1, 1)), q)
    miss_mm, miss_deg, own_mm, own_deg = reached_misses(virtual, predictor, q_cmd, nominal.forward(q))
    assert np.all(miss_mm <= own_mm + 1e-3) and np.all(miss_deg <= own_deg + 1e-4)
    assert miss_mm.max() < 2e-3 and miss_deg.max() < 2e-4          # the model's own error: 2e-4 mm, 2.5e-5 deg
    before_mm = np.linalg.norm(virtual.true_positions(q) - nominal.forward(q)[:, :3, 3], axis=1)
    assert before_mm.min() > 10.0                                   # uncompensated: 13.2 to 16.2 mm


def test_a_joint_trajectory_gets_the_joints_that_reach_its_nominal_poses(tmp_path):
    model = constant_model(UR10, [0.4, -0.3, 0.2, 1.0, 0.5, -0.5], inputs="joint")
    result = compensated(model, FIXTURES / "trajectory.csv")
    out = tmp_path / "out.csv"
    out.write_bytes(result.output)
    rows = [line.split(",") for line in out.read_text().splitlines()[2:]]
    q_new = np.array([[float(c) for c in r[1:7]] for r in rows])
    q_old = np.array([[10.0, -80.0, 90.0, -100.0, -90.0, 20.0], [10.5, -80.2, 90.1, -100.0, -90.0, 20.0],
                      [11.0, -80.4, 90.2, -100.1, -89.9, 20.1]])
    assert [r[0] for r in rows] == ["0.000", "0.008", "0.016"] and [r[7] for r in rows] == ["0.5"] * 3
    reached = UR10.forward(q_new)                # the nominal pose at the new joints, moved by the constant error
    turn = Rotation.from_rotvec([1e-3, 0.5e-3, -0.5e-3]).as_matrix()
    np.testing.assert_allclose(reached[:, :3, 3] + [0.4, -0.3, 0.2], UR10.forward(q_old)[:, :3, 3], atol=2e-4)
    np.testing.assert_allclose(turn @ reached[:, :3, :3], UR10.forward(q_old)[:, :3, :3], atol=1e-7)  # 6 decimals


# ---------------------------------------------------------------------- refusals
@pytest.mark.parametrize("name, old, new, where", [
    ("pick_place.script", b"0.4299, 2.4066", b"0.4299, 2.40.66", "line 7, column 41"),
    ("pallet.dat", b"Y 85.084", b"Y 85,084", "line 10, column"),
    ("pallet.mod", b"[0.212583,-0.556195,0.152896,-0.788719]", b"[0.212583,-0.556195,0.152896]",
     "line 7, column"),
    ("trajectory.csv", b" 10.5 ", b" ten ", "line 4, column 8"),
    ("pick_place.script", b"0.4299, 2.4066", b"0.4299, 2e999", "line 7, column 41"),
    ("pallet.dat", b"Y 85.084", b"Y 85e999", "line 10, column"),
    ("pallet.mod", b"[[5,-120", b"[[5e999,-120", "line 6, column"),
    ("trajectory.csv", b" 10.5 ", b" 1e400 ", "line 4, column 8"),
    ("pick_place.script", b"  set_payload(1.5)\n", b"  spare = p[0.1, 0.2, 0.3, 0, 0\n", "line 5, column 12")])
def test_bad_syntax_in_a_target_exits_2_naming_file_line_and_column(tmp_path, name, old, new, where):
    path = tmp_path / name
    data = (FIXTURES / name).read_bytes()
    assert old in data
    path.write_bytes(data.replace(old, new, 1))
    out = tmp_path / ("out_" + name)
    robot = "universal_robots_ur10" if name.endswith((".script", ".csv")) else "motoman_sk120"
    save_model(constant_model(load_robot(robot), np.zeros(3)).model, tmp_path / "m.json", name="zero",
               robot=load_robot(robot))
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(out))
    assert done.returncode == 2 and f"{path}: {where}" in done.stderr and "nothing written" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not out.exists()


def test_a_target_in_an_unknown_frame_is_refused_not_guessed(tmp_path):
    model = constant_model(SK120, np.zeros(3))
    mod = tmp_path / "wobj.mod"
    mod.write_bytes((FIXTURES / "pallet.mod").read_bytes().replace(b"tGripper\\WObj:=wTable",
                                                                   b"tGripper\\WObj:=wOther"))
    with pytest.raises(UnknownFrameError, match=r"line 9, column 25: target p30: it is given in the frame 'wOther', "
                                                r"which is unknown: give it with --frame 'wOther=VALUE'"):
        compensated(model, mod)
    dat = tmp_path / "base.dat"
    dat.write_bytes((FIXTURES / "pallet.dat").read_bytes().replace(b"BASE_NO 0", b"BASE_NO 3"))
    with pytest.raises(UnknownFrameError, match=r"target XP1: it is given in the frame 'BASE_DATA\[3\]'"):
        compensated(model, dat)
    given = ProgramFrames(frames={"BASE_DATA[3]": np.eye(4)})
    assert compensated(model, dat, given).output == (FIXTURES / "pallet.dat").read_bytes().replace(b"BASE_NO 0",
                                                                                                  b"BASE_NO 3")
    script = tmp_path / "feature.script"
    script.write_text("movel(pose_trans(Plane_1, p[0.1, 0.0, 0.05, 0, 3.1416, 0]), a=1.2, v=0.25)\n")
    with pytest.raises(UnknownFrameError, match=r"line 1, column 29: target movel: it is given in the frame 'Plane_1'"):
        compensated(constant_model(UR10, np.zeros(3)), script)
    script.write_text("set_tcp(gripper_tcp)\nmovel(p[-0.7446, -0.2977, 0.4299, 2.4066, 2.0194, 0.0])\n")
    with pytest.raises(UnknownFrameError, match=r"line 2, column 9: target movel: it is given in the tool "
                                                r"'gripper_tcp', which is unknown: give it with --tool"):
        compensated(constant_model(UR10, np.zeros(3)), script)
    given = ProgramFrames(tools={"gripper_tcp": np.eye(4)})
    assert compensated(constant_model(UR10, np.zeros(3)), script, given).output == script.read_bytes()


def test_a_robtarget_used_with_two_tools_is_refused(tmp_path):
    mod = tmp_path / "two.mod"
    twice = b"MoveJ p10, v1000, z50, tool0; MoveL p10, v10, fine, tGripper;"
    mod.write_bytes((FIXTURES / "pallet.mod").read_bytes().replace(b"MoveJ p10, v1000, z50, tool0;", twice))
    with pytest.raises(UnknownFrameError, match=r"line 7, column 26: target p10: it is used with "
                                                r"tGripper\\WObj:=wobj0 and tool0\\WObj:=wobj0: one robtarget cannot"):
        compensated(constant_model(SK120, np.zeros(3)), mod)


def test_a_target_that_would_leave_its_configuration_is_not_compensated(tmp_path):
    # axis 6 at 89.99 degrees (cf6 = 0); a model that turns the tool by -0.02 degrees about its axis wants axis 6
    # beyond 90 degrees (cf6 = 1): that is another configuration for the controller
    q = np.array([[10.0, -120.0, -170.0, 10.0, 30.0, 89.99]])
    pose = SK120.flange(q)[0]
    quat = quaternions_from_matrices(pose[None, :3, :3])[0]
    path = tmp_path / "edge.mod"
    path.write_text("MODULE Edge\n  CONST robtarget pEdge:=[[{:.6f},{:.6f},{:.6f}],[{:.9f},{:.9f},{:.9f},{:.9f}],"
                    "[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\nENDMODULE\n".format(*pose[:3, 3], *quat))
    z = pose[:3, 2] * np.radians(-0.02) * 1000                  # the turn about the tool's axis, mrad
    model = constant_model(SK120, [0.0, 0.0, 0.0, *z])
    result = compensated(model, path)
    assert result.output is None
    assert [(t.name, why) for t, why in result.failures] == [
        ("pEdge", "leaves its configuration ([0, 0, 0, -1] -> [0, 0, 1, -1] in rapid's terms)")]
    kept = compensated(model, path, keep_unconverged=True)
    assert kept.output == path.read_bytes().replace(b"[9E9,9E9,9E9,9E9,9E9,9E9]];", b"[9E9,9E9,9E9,9E9,9E9,9E9]]; ! "
                                                    b"partcal: not compensated: leaves its configuration ([0, 0, 0, -1]"
                                                    b" -> [0, 0, 1, -1] in rapid's terms)")
    assert compensated(constant_model(SK120, [0.0, 0.0, 0.0, *(-z)]), path).output is not None   # the other way
    path.write_text(path.read_text().replace("[0,0,0,0],", "\n    [0,0,0,0],"))         # a statement on two lines
    kept = compensated(model, path, keep_unconverged=True).output.decode().split("\n")
    assert kept[1].endswith("],") and kept[2].endswith("]]; ! partcal: not compensated: leaves its configuration "
                                                     "([0, 0, 0, -1] -> [0, 0, 1, -1] in rapid's terms)")


def test_unconverged_targets_exit_3_and_write_nothing_unless_kept(tmp_path):
    robot = SK120
    save_model(constant_model(robot, [0.0, 0.0, 2500.0]).model, tmp_path / "far.json", name="far", robot=robot)
    out = tmp_path / "out.src"
    done = run("compensate", str(tmp_path / "far.json"), str(FIXTURES / "pallet.src"), "-o", str(out))
    assert done.returncode == 3 and not out.exists() and not (tmp_path / "out.src.json").exists()
    assert re.fullmatch(r"partcal: \S*pallet.src: line 15, column 11: target PTP is unreachable: the robot cannot "
                        r"take its compensated command within its joint limits \(predicted miss \S+ mm, \S+ deg\) "
                        r"\(and 1 more\); 2 of 2 targets not compensated; nothing written \(--keep-unconverged "
                        r"writes them as they were, with a comment\)\n", done.stderr), done.stderr
    done = run("compensate", str(tmp_path / "far.json"), str(FIXTURES / "pallet.src"), "-o", str(out),
               "--keep-unconverged")
    assert done.returncode == 3
    lines = out.read_bytes().split(b"\r\n")
    original = (FIXTURES / "pallet.src").read_bytes().split(b"\r\n")
    assert lines[14].startswith(original[14] + b" ; partcal: not compensated: is unreachable: the robot cannot take "
                                b"its compensated command within its joint limits (predicted miss ")
    assert lines[15].startswith(original[15] + b" ; partcal: not compensated: ")      # after its own comment
    assert [a for k, a in enumerate(lines) if k not in (14, 15)] == [a for k, a in enumerate(original)
                                                                      if k not in (14, 15)]
    assert json.loads((tmp_path / "out.src.json").read_text())["compensated"] == 0


def test_compensate_refuses_program_options_for_a_targets_csv_and_an_output_that_is_an_input(tmp_path):
    save_model(constant_model(UR10, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=UR10)
    targets = tmp_path / "targets.csv"
    targets.write_text("x,y,z\n-700,-300,430\n")
    done = run("compensate", str(tmp_path / "m.json"), str(targets), "-o", str(tmp_path / "o.csv"),
               "--frame", "p[0,0,0,0,0,0]")
    assert done.returncode == 2 and "--frame is for robot programs" in done.stderr
    copy = tmp_path / "p.script"
    copy.write_bytes((FIXTURES / "pick_place.script").read_bytes())
    done = run("compensate", str(tmp_path / "m.json"), str(copy), "-o", str(copy))
    assert done.returncode == 2 and "is the program" in done.stderr


def test_a_target_whose_compensation_diverges_is_reported_with_its_predicted_miss():
    # an "error" that grows twice as fast as the position: the fixed point p' = p - e(p') runs away
    rng = np.random.default_rng(0)
    X = rng.uniform(-1000, 1000, (40, 3))
    model = ErrorModel(degree=1, solver="lstsq").fit(X, 2.0 * (X - [1000.0, 0.0, 1000.0]))
    predictor = Predictor(model, model_to_dict(model, name="wild", robot=SK120), SK120)
    result = compensated(predictor, FIXTURES / "pallet.src")
    assert result.output is None and len(result.failures) == 2
    assert all(why.startswith("did not converge (predicted miss ") for _, why in result.failures)


def test_a_partial_krl_motion_target_is_refused_and_an_offset_is_kept(tmp_path):
    path = tmp_path / "partial.src"
    path.write_bytes(b"DEF partial( )\r\n  LIN_REL {Z 50}\r\n  PTP {A1 10, A2 -120}\r\nEND\r\n")
    with pytest.raises(ProgramSyntaxError, match=r"partial.src: line 3, column 7: PTP to a partial aggregate: "
                                                 r"expected a whole target"):
        read_program(path)
    path.write_bytes(b"DEF partial( )\r\n  LIN_REL {Z 50}\r\n  XP1 = XP1 : {X 10}\r\n"
                     b"  LIN_REL {X 0,Y 0,Z 50,A 0,B 0,C 0}\r\nEND\r\n")
    assert read_program(path).targets == [] and read_program(path).left == []      # offsets, whole or not


def test_frames_and_tools_are_given_in_the_vendors_own_syntax_on_the_command_line(tmp_path):
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    dat = tmp_path / "base.dat"
    dat.write_bytes((FIXTURES / "pallet.dat").read_bytes().replace(b"TOOL_NO 0,BASE_NO 0", b"TOOL_NO 2,BASE_NO 3"))
    out = tmp_path / "out.dat"
    done = run("compensate", str(tmp_path / "m.json"), str(dat), "-o", str(out), "--frame",
               "BASE_DATA[3]={X 0,Y 0,Z 0,A 0,B 0,C 0}", "--tool", "tool_data[2]={X 0, Y 0, Z 0, A 0, B 0, C 0}")
    assert done.returncode == 0, done.stderr
    assert out.read_bytes() == dat.read_bytes()
    done = run("compensate", str(tmp_path / "m.json"), str(dat), "-o", str(out), "--frame", "BASE_DATA[3]={X 0,Y 0}")
    assert done.returncode == 2 and "lacks Z, A, B, C" in done.stderr
    mod = tmp_path / "w.mod"
    mod.write_bytes((FIXTURES / "pallet.mod").read_bytes().replace(b"tGripper\\WObj:=wTable", b"tGripper\\WObj:=w2"))
    done = run("compensate", str(tmp_path / "m.json"), str(mod), "-o", str(tmp_path / "o.mod"), "--frame",
               "w2=[[1000, 0, 500], [1, 0, 0, 0]]")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "o.mod").read_bytes() == mod.read_bytes()


def test_a_position_model_moves_the_position_and_keeps_the_orientation_as_written():
    # a constant error of (0.5, -0.3, 0.2) mm: every Cartesian target moves by the opposite, A B C stay as written
    result = compensated(constant_model(SK120, [0.5, -0.3, 0.2]), FIXTURES / "pallet.dat")
    assert result.orientation == "kept" and not result.failures
    line = next(x for x in result.output.split(b"\r\n") if x.startswith(b"DECL E6POS XP1="))
    assert line == (b"DECL E6POS XP1={X 1201.145000,Y 85.384000,Z 1049.831000,A -119.9242,B -54.3269,C -54.9937,"
                    b"S 2,T 6,E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}")
    np.testing.assert_allclose(result.correction_mm[1:], np.linalg.norm([0.5, 0.3, 0.2]), rtol=1e-9)
    assert result.correction_deg[1:].max() < 1e-12


def test_a_urscript_pose_variable_is_a_target_only_where_a_move_takes_it(tmp_path):
    script = tmp_path / "vars.script"
    script.write_text("def run():\n"
                      "  lift = p[0, 0, -0.05, 0, 0, 0]          # relative to wp1: a target in the frame wp1\n"
                      "  up = p[0, 0, 0.1, 0, 0, 0]              # an offset no move takes: no target\n"
                      "  global wp1 = p[-0.7446, -0.2977, 0.4299, 2.4066, 2.0194, 0.0]\n"
                      "  movel(pose_add(wp1, up))\n"
                      "  wp2 = p[0.1, 0.0, 0.05, 0, 3.1416, 0]\n"
                      "  movel(wp1, a=1.2, v=0.25)\n"
                      "  movel(pose_trans(wp1, lift), a=1.2, v=0.25)\n"
                      "  movel(pose_trans(Plane_1, wp2), a=1.2, v=0.25)\n"
                      "end\n")
    program = read_program(script)
    assert [(t.name, t.line, t.frame) for t in program.targets] == [("lift", 2, "wp1"), ("wp1", 4, None),
                                                                     ("wp2", 6, "Plane_1")]
    with pytest.raises(UnknownFrameError, match=r"line 2, column 12: target lift: it is given in the frame 'wp1'"):
        compensated(constant_model(UR10, np.zeros(3)), script)       # the frame wp1 is a target: not guessed
    script.write_text(script.read_text().replace("end\n", "  movej(pose_trans(Plane_1, wp1))\nend\n"))
    with pytest.raises(UnknownFrameError, match=r"line 4, column 18: target wp1: it is used in the base and "
                                                r"pose_trans\(Plane_1, ..\): one pose cannot be compensated"):
        read_program(script)


def test_a_joint_trajectory_keeps_an_unconverged_row_with_a_comment_line_before_it():
    far = constant_model(UR10, [0.0, 0.0, 3000.0], inputs="joint")
    result = compensated(far, FIXTURES / "trajectory.csv", keep_unconverged=True)
    assert len(result.failures) == 3
    lines = result.output.decode().split("\n")
    original = (FIXTURES / "trajectory.csv").read_text().split("\n")
    assert lines[2].startswith("# partcal: not compensated: ") and lines[3] == original[2]
    assert [x for x in lines if not x.startswith("# partcal")] == original


def test_rapid_arrays_of_robtargets_are_targets_element_by_element(tmp_path):
    mod = tmp_path / "array.mod"
    p10 = b"[[1201.645,85.084,1050.031],[0.212583,-0.556195,0.152896,-0.788719],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"
    mod.write_bytes(b"MODULE A\r\n  CONST robtarget path{2} := [" + p10 + b",\r\n    " + p10 + b"];\r\n"
                    b"  PROC main()\r\n    MoveL path{1}, v100, fine, tool0;\r\n  ENDPROC\r\nENDMODULE\r\n")
    program = read_program(mod)
    assert [(t.name, t.line, t.tool) for t in program.targets] == [("path{1}", 2, "tool0"), ("path{2}", 3, "tool0")]
    assert compensated(constant_model(SK120, np.zeros(6)), mod).output == mod.read_bytes()
    mod.write_bytes(mod.read_bytes().replace(b"path{2}", b"path{3}"))
    with pytest.raises(ProgramSyntaxError, match=r"line 2, column 30: robtarget array path\{3\}: expected 3 "
                                                 r"bracketed robtargets"):
        read_program(mod)


def test_a_program_without_targets_is_written_as_it_was_with_a_warning(tmp_path):
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    src = tmp_path / "names.src"
    src.write_bytes(b"DEF names( )\r\n  PTP XHOME\r\n  LIN XP1 C_DIS\r\nEND\r\n")
    done = run("compensate", str(tmp_path / "m.json"), str(src), "-o", str(tmp_path / "out.src"))
    assert done.returncode == 0 and "holds no targets partcal reads (krl)" in done.stderr
    assert (tmp_path / "out.src").read_bytes() == src.read_bytes()


def test_numbers_keep_their_text_when_equal_and_get_enough_decimals_when_not():
    from partcal.data.program_text import Field, number_text

    old = Field(0, 6, "+85.08", 85.08)
    assert number_text(85.08 + 1e-12, old, 6) == "+85.08"            # equal at the precision written
    assert number_text(85.0805, old, 6) == "+85.080500"              # at least 6 decimals, the sign kept
    assert number_text(-1e-12, Field(0, 3, "0.5", 0.5), 6) == "0.000000"       # never "-0.000000"
    assert number_text(1.5, Field(0, 10, "0.12345678", 0.12345678), 6) == "1.50000000"   # as many as it had


@pytest.mark.parametrize("name", ["pick_place.script", "pallet.src", "pallet.mod"])
def test_a_utf16_program_is_refused_not_passed_through_uncompensated(tmp_path, name):
    path = tmp_path / name
    path.write_bytes((FIXTURES / name).read_bytes().decode("latin-1").encode("utf-16"))
    robot = "universal_robots_ur10" if name.endswith((".script", ".csv")) else "motoman_sk120"
    save_model(constant_model(load_robot(robot), np.zeros(3)).model, tmp_path / "m.json", name="zero",
               robot=load_robot(robot))
    out = tmp_path / ("out_" + name)
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(out))
    assert done.returncode == 2 and f"{path}: " in done.stderr and "UTF-16" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not out.exists()


def test_a_target_whose_solve_stops_at_a_singularity_says_so(tmp_path):
    """A UR10 joint trajectory with its elbow straight (q3 = 0) under a model whose arm falls 1 mm short in z: the
    command would lie beyond the arm's reach, so the solve stops at the stretched elbow, and the reason says so;
    the same error at a bent elbow is compensated."""
    path = tmp_path / "stretched.csv"
    path.write_text("q1,q2,q3,q4,q5,q6\n0,-90,0,-90,30,0\n0,-90,60,-90,30,0\n")
    result = compensated(constant_model(UR10, [0.0, 0.0, -1.0, 0.0, 0.0, 0.0], "joint"), path)
    assert [t.name for t, _ in result.failures] == [result.program.targets[0].name]
    assert result.failures[0][1].startswith("did not converge: its solve stopped at a singularity, no joints near "
                                            "the target's take its compensated pose (predicted miss ")


def test_a_joint_model_fitted_with_the_wrist_held_compensates_full_poses_where_the_wrist_turns():
    """The paper's data hold q4 = q5 = 0; a KRL/RAPID target keeps its orientation, so its wrist must move a
    little: all six joints are free (four would leave the 6-DOF pose unreachable, 4.9 mm / 0.31 deg)."""
    from partcal import read_measurements

    ident = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    assert np.ptp(ident.q_deg[:, 3:5]) == 0
    model = KinematicModel(robot=SK120).fit(ident.q_deg, ident.errors_mm)
    predictor = Predictor(model, model_to_dict(model, name="DH", robot=SK120), SK120)
    for name in ("pallet.src", "pallet.mod"):
        result = compensated(predictor, FIXTURES / name)
        assert not result.failures, (name, result.failures)
    q = np.array([[0.0, -130.0, -160.0, 5.0, 25.0, 100.0], [10.0, -100.0, -140.0, -20.0, 40.0, 0.0]])
    target = SK120.forward(q)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        comp = predictor.compensate_poses(target, q, orientation_kept=True)
    reached = SK120.forward(comp.joints_deg)         # the nominal pose, moved by the predicted error
    np.testing.assert_allclose(reached[:, :3, 3] + model.predict(comp.joints_deg), target[:, :3, 3], atol=1e-3)
    np.testing.assert_allclose(reached[:, :3, :3], target[:, :3, :3], atol=1e-9)
    assert np.abs(comp.joints_deg[:, 3:5] - q[:, 3:5]).max() > 0.01      # the wrist moved to keep the orientation


# ---------------------------------------------------------------------- line endings, one-line programs
ONE_LINERS = {
    "one.script": (b"movel(p[-0.7446, -0.2977, 0.4299, 2.4066, 2.0194, 0.0], a=1.2, v=0.25)", UR10, 9),
    "one.src": (b"LIN {X 1044.037,Y -8.472,Z 652.644,A -90.8302,B 14.6598,C -84.9212} C_DIS", SK120, 8),
    "one.mod": (b"MODULE One CONST robtarget p10:=[[1201.645,85.084,1050.031],[0.212583,-0.556195,0.152896,"
                b"-0.788719],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]; ENDMODULE", SK120, 35),
    "one.csv": (b"q1,q2,q3,q4,q5,q6\n10.0,-80.0,90.0,-100.0,-90.0,20.0", UR10, 1)}


@pytest.mark.parametrize("name", sorted(ONE_LINERS))
def test_a_program_of_one_line_without_a_final_newline_is_read_and_compensated(tmp_path, name):
    data, robot, column = ONE_LINERS[name]
    path = tmp_path / name
    path.write_bytes(data)
    program = read_program(path)
    assert [(t.line, t.column) for t in program.targets] == [(2 if name.endswith(".csv") else 1, column)]
    assert compensated(constant_model(robot, np.zeros(3)), path).output == data
    out = compensated(constant_model(robot, [0.3, -0.2, 0.1]), path).output
    assert out != data and not out.endswith((b"\n", b"\r")) and out.count(b"\n") == data.count(b"\n")


@pytest.mark.parametrize("name, robot", [("pick_place.script", UR10), ("pallet.dat", SK120), ("pallet.src", SK120),
                                         ("pallet.mod", SK120), ("trajectory.csv", UR10)])
def test_a_program_with_cr_only_line_endings_has_the_targets_and_lines_of_its_lf_twin(tmp_path, name, robot):
    lf = tmp_path / ("lf_" + name)
    lf.write_bytes((FIXTURES / name).read_bytes().replace(b"\r\n", b"\n"))
    cr = tmp_path / name
    cr.write_bytes(lf.read_bytes().replace(b"\n", b"\r"))
    assert b"\n" not in cr.read_bytes()
    twin = [(t.name, t.line, t.column) for t in read_program(lf).targets]
    assert [(t.name, t.line, t.column) for t in read_program(cr).targets] == twin and twin
    assert compensated(constant_model(robot, np.zeros(3)), cr).output == cr.read_bytes()
    moved = compensated(constant_model(robot, [0.3, -0.2, 0.1]), cr).output
    assert b"\n" not in moved and moved.count(b"\r") == cr.read_bytes().count(b"\r")
    assert moved.replace(b"\r", b"\n") == compensated(constant_model(robot, [0.3, -0.2, 0.1]), lf).output


def test_a_note_on_a_cr_only_program_goes_on_the_target_line_with_its_line_ending(tmp_path):
    # an unreachable joint trajectory row gets a comment line before it, ended as the file's lines are
    path = tmp_path / "cr.csv"
    path.write_bytes(b"q1,q2,q3,q4,q5,q6\r10,-80,90,-100,-90,20\r")
    result = compensated(constant_model(UR10, [1e5, 0, 0]), path, keep_unconverged=True)
    assert result.failures
    assert result.output.startswith(b"q1,q2,q3,q4,q5,q6\r# partcal: not compensated: ")
    assert result.output.endswith(b"\r10,-80,90,-100,-90,20\r") and b"\n" not in result.output


def test_a_cp1252_ellipsis_in_a_joint_trajectory_comment_does_not_split_its_line(tmp_path):
    path = tmp_path / "ellipsis.csv"
    path.write_bytes(b"# steps \x85 every 8 ms\nq1,q2,q3,q4,q5,q6\n10,-80,90,-100,-90,20\n")
    assert [(t.line, t.column) for t in read_program(path).targets] == [(3, 1)]


# ---------------------------------------------------------------------- quaternions of tools and work objects
@pytest.mark.parametrize("old, new, field", [
    (b"[[0,0,100],[1,0,0,0]]", b"[[0,0,100],[0,0,0,0]]", "tooldata tGripper tframe: quaternion of norm 0"),
    (b"[[0,0,100],[1,0,0,0]]", b"[[0,0,100],[0.9,0,0,0]]", "tooldata tGripper tframe: quaternion of norm 0.9"),
    (b"[[1000, 0, 500], [1, 0, 0, 0]]", b"[[1000, 0, 500], [0, 0, 0, 0]]", "wobjdata wTable uframe: quaternion of norm 0"),
    (b"[[0,0,0],[1,0,0,0]]];", b"[[0,0,0],[0,0,0,0]]];", "wobjdata wTable oframe: quaternion of norm 0")])
def test_a_zero_or_non_unit_quaternion_of_a_tool_or_work_object_exits_2_naming_it(tmp_path, old, new, field):
    path = tmp_path / "q.mod"
    data = (FIXTURES / "pallet.mod").read_bytes()
    assert data.count(old) == 1
    path.write_bytes(data.replace(old, new))
    at = data.index(old) + new.index(b"],[") + 3 if b"],[" in new else data.index(old) + new.index(b"], [") + 4
    line, column = data.count(b"\n", 0, at) + 1, at - data.rfind(b"\n", 0, at)
    where = f"line {line}, column {column}"
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(tmp_path / "o.mod"))
    assert done.returncode == 2, done.stderr
    assert f"{path}: {where}: {field}: expected a unit quaternion (norm 1 to 0.001)" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "o.mod").exists()


def test_a_zero_quaternion_given_as_a_tool_option_exits_2(tmp_path):
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    done = run("compensate", str(tmp_path / "m.json"), str(FIXTURES / "pallet.mod"), "-o", str(tmp_path / "o.mod"),
               "--tool", "tGripper=[[0, 0, 100], [0, 0, 0, 0]]")
    assert done.returncode == 2 and "quaternion of norm 0: expected a unit quaternion" in done.stderr, done.stderr


# ---------------------------------------------------------------------- URScript: the TCP of the move
def test_a_polyscope_waypoint_has_the_tcp_set_before_the_move_not_before_its_declaration(tmp_path):
    path = FIXTURES / "polyscope_tcp.script"
    program = read_program(path)
    assert [(t.name, t.line, t.tool) for t in program.targets] == [
        ("Waypoint_1_p", 10, "set_tcp at line 19"), ("Waypoint_2_p", 12, "set_tcp at line 19"),
        ("Waypoint_3_p", 14, "set_tcp at line 26")]
    np.testing.assert_allclose(program.frames["set_tcp at line 26"][:3, 3], [0, 50, 200])
    # the same moves with each pose written inline after its set_tcp: the tool there is the one in force
    text = path.read_text()
    for t in program.targets:
        literal = text.splitlines()[t.line - 1].split("=", 1)[1]
        text = text.replace(f"({t.name},", f"({literal},").replace(f"({t.name}, ", f"({literal}, ")
    inline = tmp_path / "inline.script"
    inline.write_text(text)
    assert [t.tool for t in read_program(inline).targets] == [t.tool for t in program.targets]
    model = constant_model(UR10, [0.3, -0.2, 0.1, 0.05, 0.02, -0.03])        # mm and degrees
    mine, theirs = compensated(model, path), compensated(model, inline)
    assert not mine.failures and not theirs.failures
    np.testing.assert_allclose(mine.correction_mm, theirs.correction_mm, rtol=1e-9)
    ours = np.array([t.position_mm for t in read_program_bytes(tmp_path, "a.script", mine.output).targets])
    inl = np.array([t.position_mm for t in read_program_bytes(tmp_path, "b.script", theirs.output).targets])
    np.testing.assert_allclose(ours, inl, atol=1e-5)
    # with the header's zero TCP instead (where the waypoints are declared), Waypoint_3 would land elsewhere
    header = ProgramFrames(tools={"set_tcp at line 26": program.frames["set_tcp at line 7"]})
    other = read_program_bytes(tmp_path, "c.script", compensated(model, path, header).output)
    assert np.linalg.norm(other.targets[2].position_mm - ours[2]) > 0.005      # 0.012 mm: 0.06 deg at 0.2 m
    np.testing.assert_allclose(other.targets[1].position_mm, ours[1], atol=1e-5)


def read_program_bytes(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    return read_program(path)


def test_a_waypoint_moved_to_with_two_tcps_is_refused(tmp_path):
    path = tmp_path / "two.script"
    path.write_bytes((FIXTURES / "polyscope_tcp.script").read_bytes().replace(
        b"movel(Waypoint_3_p, a=1.2, v=0.25)", b"movel(Waypoint_1_p, a=1.2, v=0.25)"))
    with pytest.raises(UnknownFrameError, match=r"line 10, column 25: target Waypoint_1_p: it is moved to with the "
                                                r"tools set_tcp at line 19 and set_tcp at line 26: one pose cannot"):
        read_program(path)


# ---------------------------------------------------------------------- KRL: the base and tool of the motions
CELL = FIXTURES / "kuka_cell"
CONFIG_FRAMES = ProgramFrames(frames={"BASE_DATA[1]": np.array([[1, 0, 0, 1500], [0, 1, 0, 0], [0, 0, 1, 400],
                                                                [0, 0, 0, 1.0]]),
                                      "BASE_DATA[3]": np.array([[0, -1, 0, 1200], [1, 0, 0, -300], [0, 0, 1, 250],
                                                                [0, 0, 0, 1.0]])},   # A 90: x -> y
                              tools={"TOOL_DATA[2]": np.block([[matrices_from_kuka_abc([[0, 30, 0]])[0],
                                                                np.array([[12.5], [-3.0], [240.0]])],
                                                               [np.zeros((1, 3)), np.ones((1, 1))]])})


def krl_fields(data: bytes, name: bytes) -> dict:
    line = next(x for x in data.split(b"\r\n") if x.startswith(name))
    return {k.decode(): float(v) for k, v in re.findall(rb"\b([XYZABC]) ([-\d.]+)", line)}


def test_krl_targets_follow_the_base_and_tool_set_before_their_motions():
    dat = read_program(CELL / "weld.dat")
    assert [(t.name, t.frame, t.tool) for t in dat.targets] == [
        ("XSEAM1", "BASE_DATA[3]", "TOOL_DATA[2]"), ("XSEAM2", "BASE_DATA[3]", "TOOL_DATA[2]"),
        ("XAPPROACH", "BASE_DATA[1]", "TOOL_DATA[2]")]                       # $BASE =, then BAS(#BASE, 1)
    src = read_program(CELL / "weld.src")
    assert [(t.name, t.line, t.frame, t.tool) for t in src.targets] == [("LIN", 17, "BASE_DATA[1]", "TOOL_DATA[2]")]
    # a constant error e in the robot base moves every TCP by -e there: by -R^T e in the base's own axes
    e = np.array([0.5, -0.3, 0.2])
    result = compensated(constant_model(SK120, e), CELL / "weld.dat", CONFIG_FRAMES)
    assert not result.failures
    old = (CELL / "weld.dat").read_bytes()
    for name, shift in ((b"DECL E6POS XSEAM1=", [0.3, 0.5, -0.2]), (b"DECL E6POS XAPPROACH=", [-0.5, 0.3, -0.2])):
        before, after = krl_fields(old, name), krl_fields(result.output, name)
        np.testing.assert_allclose([after[k] - before[k] for k in "XYZ"], shift, atol=1e-6)
        assert [after[k] for k in "ABC"] == [before[k] for k in "ABC"]


def test_a_krl_point_in_a_base_computed_at_run_time_is_left_as_written_and_reported(tmp_path):
    for name, left in (("weld.dat", [("basePos[1]", 11, "no motion of weld.src reaches it"),
                                     ("basePos[2]", 12, "no motion of weld.src reaches it"),
                                     ("XCOMP", 13, "moved to in a base or tool set at run time ($BASE = "
                                                   "BASE_DATA[1] : basePos[2] at line 20)")]),
                       ("weld.src", [("LIN", 22, "moved to in a base or tool set at run time ($BASE = BASE_DATA[1] "
                                                 ": basePos[2] at line 20)")])):
        program = read_program(CELL / name)
        assert [(x.name, x.line) for x in program.left] == [(n, line) for n, line, _ in left]
        assert all(why in x.reason for x, (_, _, why) in zip(program.left, left))
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    out = tmp_path / "weld.src"
    done = run("compensate", str(tmp_path / "m.json"), str(CELL / "weld.src"), "-o", str(out), "--frame",
               "BASE_DATA[1]={X 1500,Y 0,Z 400,A 0,B 0,C 0}", "--tool", "TOOL_DATA[2]={X 12.5,Y -3,Z 240,A 0,B 30,C 0}")
    assert done.returncode == 0, done.stderr
    assert "weld.src: line 22, column 10: LIN: left as written: moved to in a base or tool set at run time" in done.stderr
    summary = json.loads((tmp_path / "weld.src.json").read_text())
    assert [(x["line"], x["target"]) for x in summary["left_as_written"]] == [(22, "LIN")]


def test_a_krl_point_moved_to_in_two_bases_is_refused(tmp_path):
    for name in ("weld.dat", "$config.dat"):
        (tmp_path / name).write_bytes((CELL / name).read_bytes())
    (tmp_path / "weld.src").write_bytes((CELL / "weld.src").read_bytes().replace(b"  PTP XAPPROACH\r\n",
                                                                                 b"  PTP XAPPROACH\r\n  LIN XSEAM1\r\n"))
    with pytest.raises(UnknownFrameError, match=r"weld.dat: line 7, column 22: target XSEAM1: it is moved to with "
                                                r"\$BASE BASE_DATA\[1\], \$TOOL TOOL_DATA\[2\] and \$BASE BASE_DATA\[3\]"):
        read_program(tmp_path / "weld.dat")


def test_krl_data_that_no_motion_reaches_stay_byte_for_byte():
    e = np.array([0.5, -0.3, 0.2])
    result = compensated(constant_model(SK120, e), CELL / "weld.dat", CONFIG_FRAMES)
    old, new = (CELL / "weld.dat").read_bytes().split(b"\r\n"), result.output.split(b"\r\n")
    changed = [a.split(b"=")[0] for a, b in zip(old, new) if a != b]
    assert changed == [b"DECL E6POS XSEAM1", b"DECL E6POS XSEAM2", b"DECL E6POS XAPPROACH"]   # not basePos, XCOMP
    # $config.dat: the home position is a target (every program moves there); the system frames are not
    config = compensated(constant_model(SK120, e), CELL / "$config.dat")
    assert [t.name for t in config.program.targets] == ["XHOME"]
    assert [x.name for x in config.program.left] == ["TOOL_CORR", "BASE_CORR", "REF_TOOL", "REF_PT[1]", "REF_PT[2]"]
    old, new = (CELL / "$config.dat").read_bytes().split(b"\r\n"), config.output.split(b"\r\n")
    assert [a.split(b"=")[0] for a, b in zip(old, new) if a != b] == [b"DECL E6AXIS XHOME"]


# ---------------------------------------------------------------------- RAPID: names, monitoring, run-time data
def test_a_generated_rapid_module_with_configuration_monitoring_off_is_compensated():
    path = FIXTURES / "taco_pick.mod"
    program = read_program(path)
    assert [(t.tool, t.frame, t.configuration) for t in program.targets] == [("custom_tool1", "wobj0", None)] * 6
    model = constant_model(SK120, [0.5, -0.3, 0.2])
    result = compensated(model, path)
    assert not result.failures and result.output != path.read_bytes()
    np.testing.assert_allclose(result.correction_mm, np.linalg.norm([0.5, 0.3, 0.2]), rtol=1e-9)


def test_a_written_configuration_is_checked_where_monitoring_is_on(tmp_path):
    # the generator wrote [0,-1,-1,0] for every target; the joints it came from have axis 4 at 0 (cf4 = 0):
    # with ConfJ and ConfL on (the default) the controller would stop, and partcal says so
    path = tmp_path / "on.mod"
    path.write_bytes((FIXTURES / "taco_pick.mod").read_bytes().replace(b"ConfL \\Off;", b"ConfL \\On;")
                     .replace(b"ConfJ \\Off;", b""))
    program = read_program(path)
    assert [t.configuration for t in program.targets] == [(0, -1, -1, 0)] * 6
    result = compensated(constant_model(SK120, [0.5, -0.3, 0.2]), path)
    assert len(result.failures) == 6 and all("in its configuration (0, -1, -1, 0)" in why for _, why in result.failures)
    # monitoring off for linear moves only: the MoveJ targets keep theirs
    path.write_bytes((FIXTURES / "taco_pick.mod").read_bytes().replace(b"ConfJ \\Off;", b""))
    assert [t.configuration for t in read_program(path).targets] == [(0, -1, -1, 0), None] * 3


def test_rapid_names_are_case_insensitive(tmp_path):
    path = tmp_path / "case.mod"
    path.write_bytes((FIXTURES / "pallet.mod").read_bytes()
                     .replace(b"MoveL p30, v100, fine, tGripper\\WObj:=wTable;", b"MoveL P30, v100, fine, TGRIPPER\\WOBJ:=WTable;")
                     .replace(b"MoveJ p10, v1000, z50, tool0;", b"MoveJ p10, v1000, z50, Tool0\\WObj:=WObj0;"))
    program = read_program(path)
    assert [(t.name, t.tool, t.frame) for t in program.targets if t.kind == "pose"] == [
        ("p10", "tool0", "wobj0"), ("p20", "tool0", "wobj0"), ("p30", "tGripper", "wTable"), ("MoveL", "tool0", "wobj0")]
    model = constant_model(SK120, [0.5, -0.3, 0.2, 0.01, 0.02, -0.01])
    mine, theirs = compensated(model, path), compensated(model, FIXTURES / "pallet.mod")
    assert not mine.failures
    np.testing.assert_allclose(mine.correction_mm, theirs.correction_mm, rtol=1e-12)
    # a tool the module does not declare, spelt two ways, is one tool (named as first written)
    path.write_bytes((FIXTURES / "pallet.mod").read_bytes().replace(b"MoveL p20, v200, z10, tool0 \\WObj:=wobj0;",
                                                                    b"MoveL p20, v200, z10, tWeld;")
                     .replace(b"MoveL Offs(p20, 0, 0, 50), v200, z10, tool0;", b"MoveL Offs(p20, 0, 0, 50), v200, z10, TWELD;"))
    assert [t.tool for t in read_program(path).targets if t.name == "p20"] == ["tWeld"]


@pytest.mark.parametrize("statement, target, reason", [
    (b"wTable.oframe.trans.x := 20;", "p30", "its work object wTable is changed at run time (wTable.oframe.trans.x "
                                             ":= 20 at line 12)"),
    (b"tGripper.tframe.trans.z := tGripper.tframe.trans.z + 5;", "p30", "its tool tGripper is changed at run time"),
    (b"p20 := Offs(p10, 0, 0, 100);", "p20", "assigned at run time (p20 := Offs(p10, 0, 0, 100) at line 12)"),
    (b"PDispOn \\ExeP:=p10, p20, tool0;", "p30", "moved to under a program displacement (PDispOn)")])
def test_rapid_data_changed_at_run_time_are_left_as_written_and_reported(tmp_path, statement, target, reason):
    path = tmp_path / "runtime.mod"
    path.write_bytes((FIXTURES / "pallet.mod").read_bytes().replace(b"  PROC main()\r\n",
                                                                    b"  PROC main()\r\n    " + statement + b"\r\n"))
    program = read_program(path)
    assert target in [x.name for x in program.left] and target not in [t.name for t in program.targets]
    assert reason in next(x.reason for x in program.left if x.name == target)
    result = compensated(constant_model(SK120, [0.5, -0.3, 0.2]), path)
    kept = next(line for line in path.read_bytes().split(b"\r\n") if f" {target}:=".encode() in line
                or f" {target} :=".encode() in line)
    assert not result.failures and kept in result.output.split(b"\r\n")


# ---------------------------------------------------------------------- URScript: poses computed at run time
def test_urscript_poses_computed_at_run_time_are_left_as_written_and_the_rest_compensated(tmp_path):
    path = FIXTURES / "admittance.script"
    program = read_program(path)
    assert [(t.name, t.line, t.kind) for t in program.targets] == [("movel", 7, "pose"), ("movej", 14, "joints")]
    assert [(x.name, x.line, x.column) for x in program.left] == [("movel", 8, 11), ("movel", 11, 25),
                                                                   ("movej", 13, 10)]
    assert program.left[0].reason == ("a pose computed at run time (p[home[0] + r, home[1], home[2], home[3], "
                                      "home[4], home[5]]): kept as written")
    assert program.left[2].reason.startswith("a joint list computed at run time ([q[0] + 0.1, q[1],")
    save_model(constant_model(UR10, [0.3, -0.2, 0.1]).model, tmp_path / "m.json", name="c", robot=UR10)
    out = tmp_path / "out.script"
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("left as written: a ") == 3 and "admittance.script: line 11, column 25: movel" in done.stderr
    old, new = path.read_bytes().split(b"\n"), out.read_bytes().split(b"\n")
    assert [k + 1 for k, (a, b) in enumerate(zip(old, new)) if a != b] == [7, 14]
    summary = json.loads((tmp_path / "out.script.json").read_text())
    assert [(x["line"], x["target"]) for x in summary["left_as_written"]] == [(8, "movel"), (11, "movel"), (13, "movej")]


def test_urscript_a_tcp_computed_at_run_time_leaves_the_poses_moved_to_with_it():
    path = FIXTURES / "admittance.script"
    text = path.read_text().replace("set_tcp(p[0.0, 0.0, 0.12, 0.0, 0.0, 0.0])", "set_tcp(p[0, 0, tool_z, 0, 0, 0])")
    import tempfile
    with tempfile.TemporaryDirectory() as folder:
        other = f"{folder}/tcp.script"
        open(other, "w").write(text)
        program = read_program(other)
    assert [t.name for t in program.targets] == ["movej"]
    assert program.left[0].reason == "moved to with a TCP computed at run time (set_tcp at line 4 (computed at run " \
                                     "time)): kept as written"


# ---------------------------------------------------------------------- file names
@pytest.mark.parametrize("name, fixture, kind", [
    ("ur_driver.urscript", "pick_place.script", "urscript"), ("Pallet.modx", "pallet.mod", "rapid"),
    ("USER.sys", "pallet.mod", "rapid"), ("PALLET_MOD", "pallet.mod", "rapid"), ("pick_place", "pick_place.script",
                                                                                "urscript"),
    ("polyscope", "polyscope_tcp.script", "urscript"), ("weld_src", "kuka_cell/weld.src", "krl"),
    ("config_dat", "kuka_cell/$config.dat", "krl"), ("pallet.txt", "pallet.mod", "rapid")])
def test_programs_with_other_names_or_none_are_read_as_programs_not_as_a_targets_csv(tmp_path, name, fixture, kind):
    path = tmp_path / name
    path.write_bytes((FIXTURES / fixture).read_bytes())
    assert program_kind(path) == kind
    twin = read_program(FIXTURES / fixture) if not fixture.startswith("kuka_cell/weld") else None
    robot = UR10 if kind == "urscript" else SK120
    save_model(constant_model(robot, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=robot)
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(tmp_path / "out"), "--frame",
               "BASE_DATA[1]={X 1500,Y 0,Z 400,A 0,B 0,C 0}", "--tool",
               "TOOL_DATA[2]={X 12.5,Y -3,Z 240,A 0,B 30,C 0}") if kind == "krl" else \
        run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out").read_bytes() == path.read_bytes()
    if twin is not None:
        assert [(t.name, t.line) for t in read_program(path).targets] == [(t.name, t.line) for t in twin.targets]
    targets = tmp_path / "targets"
    targets.write_text("x,y,z\n1000,0,1000\n")
    assert program_kind(targets) is None                # a targets CSV without a name stays one


# ---------------------------------------------------------------------- a Cartesian model: program and CSV agree
def quadratic_model(robot):
    """A second-degree Cartesian model (the paper's SDP(CI) kind) of a smooth error field, with its robot."""
    rng = np.random.default_rng(3)
    X = rng.uniform([600, -900, 0], [1800, 900, 1500], (200, 3))
    y = np.stack([1e-6 * (X[:, 0] - 1000) ** 2 + 2e-3 * X[:, 1], 3e-3 * X[:, 2] - 1e-6 * X[:, 0] * X[:, 1] / 2,
                  -2e-6 * (X[:, 2] - 700) ** 2 + 1e-3 * X[:, 0]], axis=1)
    model = ErrorModel(inputs="cartesian", degree=2, solver="lstsq").fit(X, y)
    return Predictor(model, model_to_dict(model, name="SDP(CI)", robot=robot), robot)


def program_of(dialect, flanges, tool_mm, q):
    """Ten targets as a program of ``dialect`` with the TCP ``tool_mm`` (no turn): the TCP poses."""
    tcp = flanges.copy()
    tcp[:, :3, 3] += np.einsum("nij,j->ni", flanges[:, :3, :3], tool_mm)
    p, R = tcp[:, :3, 3], tcp[:, :3, :3]
    if dialect == "urscript":
        rv = rotation_vectors_from_matrices(R)
        lines = ["def rect():", "  set_tcp(p[%.6f, %.6f, %.6f, 0, 0, 0])" % tuple(np.asarray(tool_mm) / 1000)]
        lines += ["  movel(p[%.8f, %.8f, %.8f, %.9f, %.9f, %.9f], a=1.2, v=0.25)" % (*x / 1000, *r) for x, r in zip(p, rv)]
        return "rect.script", "\n".join(lines + ["end"]) + "\n"
    if dialect == "krl":
        abc = kuka_abc_from_matrices(R)
        lines = ["DEFDAT RECT", "DECL FRAME TOOL_DATA[1]={X %.6f,Y %.6f,Z %.6f,A 0,B 0,C 0}" % tuple(tool_mm)]
        for k, (x, a) in enumerate(zip(p, abc)):
            lines += ["DECL E6POS XP%d={X %.6f,Y %.6f,Z %.6f,A %.6f,B %.6f,C %.6f}" % (k, *x, *a),
                      "DECL FDAT FP%d={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE}" % k]
        return "rect.dat", "\r\n".join(lines + ["ENDDAT"]) + "\r\n"
    quat, cf = quaternions_from_matrices(R), np.floor(q[:, [0, 3, 5]] / 90).astype(int)
    lines = ["MODULE Rect", "  PERS tooldata tTcp:=[TRUE,[[%.6f,%.6f,%.6f],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];"
             % tuple(tool_mm)]
    lines += ["  CONST robtarget p%d:=[[%.6f,%.6f,%.6f],[%.9f,%.9f,%.9f,%.9f],[%d,%d,%d,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
              % (k, *x, *qq, *c) for k, (x, qq, c) in enumerate(zip(p, quat, cf))]
    lines += ["  PROC main()"] + ["    MoveL p%d, v100, fine, tTcp;" % k for k in range(len(p))] + ["  ENDPROC"]
    return "rect.mod", "\r\n".join(lines + ["ENDMODULE"]) + "\r\n"


@pytest.mark.parametrize("dialect", ["urscript", "krl", "rapid"])
def test_a_cartesian_model_compensates_a_program_as_a_csv_of_the_same_tool_points(tmp_path, dialect):
    """A Cartesian model is a function of its tool point's position (the point it was fitted on). A program
    with the model's tool as its TCP names those points: its commands are the CSV's. A program with another
    TCP (here none: the flange) names other points; its TCPs move as the model's tool point does, so the CSV
    of the tool points carried there gives its commands too (1.2 mm from the CSV of the program's own
    numbers on the paper run's SDP(CI): the model read 234 mm away, not a disagreement)."""
    predictor = quadratic_model(SK120)
    save_model(predictor.model, tmp_path / "m.json", name="SDP(CI)", robot=SK120)
    q = np.column_stack([np.linspace(35, 27, 10), np.linspace(-118, -126, 10), np.linspace(-152, -155, 10),
                         np.zeros(10), np.full(10, 30.0), np.linspace(-6, -4.5, 10)])      # axis 4 at 0, tool down
    flanges, tool = SK120.flange(q), SK120.tool_mm
    tool_points = flanges[:, :3, 3] + np.einsum("nij,j->ni", flanges[:, :3, :3], tool)
    (tmp_path / "targets.csv").write_text("x,y,z\n" + "".join("%.6f,%.6f,%.6f\n" % tuple(x) for x in tool_points))
    done = run("compensate", str(tmp_path / "m.json"), str(tmp_path / "targets.csv"), "-o", str(tmp_path / "c.csv"))
    assert done.returncode == 0, done.stderr
    csv = np.loadtxt(tmp_path / "c.csv", delimiter=",", skiprows=1, usecols=(3, 4, 5))
    assert np.linalg.norm(csv - tool_points, axis=1).min() > 0.5                # the model does move them
    for tcp, expected in ((tool, csv), (np.zeros(3), csv - (tool_points - flanges[:, :3, 3]))):
        name, text = program_of(dialect, flanges, tcp, q)
        (tmp_path / name).write_bytes(text.encode())
        out = tmp_path / ("out_" + name)
        done = run("compensate", str(tmp_path / "m.json"), str(tmp_path / name), "-o", str(out))
        assert done.returncode == 0, done.stderr
        got = np.array([t.position_mm for t in read_program(out).targets])
        np.testing.assert_allclose(got, expected, atol=1e-4)


def test_a_krl_point_with_a_fixed_tool_is_left_as_written_and_reported_not_asked_for_as_a_frame(tmp_path):
    path = tmp_path / "fixed.dat"
    path.write_bytes((FIXTURES / "pallet.dat").read_bytes().replace(b"IPO_FRAME #BASE", b"IPO_FRAME #TCP"))
    program = read_program(path)
    assert "XP1" not in [t.name for t in program.targets]
    assert [(x.name, x.line, x.reason) for x in program.left] == [
        ("XP1", 10, "moved to with a fixed tool (IPO_FRAME #TCP: the robot carries the workpiece): not compensated, "
                    "kept as written")]
    result = compensated(constant_model(SK120, [0.5, -0.3, 0.2]), path)
    line = next(x for x in path.read_bytes().split(b"\r\n") if x.startswith(b"DECL E6POS XP1="))
    assert not result.failures and line in result.output.split(b"\r\n")


@pytest.mark.parametrize("name", ["gone.script", "gone.mod", "gone.src"])
def test_a_missing_program_file_exits_2_naming_it(tmp_path, name):
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    done = run("compensate", str(tmp_path / "m.json"), str(tmp_path / name), "-o", str(tmp_path / "out"))
    assert done.returncode == 2 and f"{tmp_path / name}: no such program file" in done.stderr, done.stderr


def test_a_krl_inline_form_sets_the_base_and_tool_of_the_motions_after_it(tmp_path):
    # KSS's inline form: FDAT_ACT = FP1 then BAS(#PTP_PARAMS) set $TOOL and $BASE from FP1; a motion after the
    # fold moves in them too
    (tmp_path / "folded.dat").write_bytes(
        b"DEFDAT  FOLDED\r\nDECL E6POS XP1={X 382.190,Y -377.300,Z 894.064,A 117.9789,B -28.1725,C -31.7403,S 2,"
        b"T 6}\r\nDECL FDAT FP1={TOOL_NO 2,BASE_NO 3,IPO_FRAME #BASE,POINT2[] \" \"}\r\nENDDAT\r\n")
    (tmp_path / "folded.src").write_bytes(
        b"DEF folded( )\r\n;FOLD PTP P1 Vel=100 % PDAT1 Tool[2] Base[3];%{PE}%R 8.3.31,%MKUKATPBASIS,%CMOVE\r\n"
        b"$BWDSTART=FALSE\r\nPDAT_ACT=PPDAT1\r\nFDAT_ACT=FP1\r\nBAS(#PTP_PARAMS,100)\r\nPTP XP1 \r\n;ENDFOLD\r\n"
        b"LIN {X 382.190,Y -377.300,Z 794.064,A 117.9789,B -28.1725,C -31.7403}\r\nEND\r\n")
    assert [(t.name, t.frame, t.tool) for t in read_program(tmp_path / "folded.dat").targets] == [
        ("XP1", "BASE_DATA[3]", "TOOL_DATA[2]")]
    assert [(t.name, t.line, t.frame, t.tool) for t in read_program(tmp_path / "folded.src").targets] == [
        ("LIN", 9, "BASE_DATA[3]", "TOOL_DATA[2]")]


def test_a_joint_target_outside_the_limits_names_each_joint_beyond_its_range(tmp_path):
    """The SK120's joint 3 runs -250 to -110 degrees and joint 6 -360 to 360: a trajectory row asking 100 and 400
    names both, with their ranges; a row inside the limits is compensated."""
    path = tmp_path / "sk120.csv"
    path.write_text("q1,q2,q3,q4,q5,q6\n10,-90,100,0,30,400\n10,-90,-150,0,30,40\n")
    result = compensated(constant_model(SK120, [0.3, -0.2, 0.1]), path, keep_unconverged=True)
    assert [(target.line, why) for target, why in result.failures] == [(2, (
        "is outside the joint limits: joint 3 at 100 deg (range -250 to -110), joint 6 at 400 deg (range -360 to 360)"))]


@pytest.fixture(scope="module")
def paper_sdp():
    """The paper's SDP(CI) kind fitted by least squares on the virtual SK120's identification set, and the first
    ten of every twentieth pose of its test rectangle (the wrist straight: axes 4 and 5 at 0)."""
    from partcal import read_measurements

    ident = read_measurements(ROOT / "data" / "sk120" / "identification.csv")
    model = ErrorModel(inputs="cartesian", degree=2, solver="lstsq").fit(ident.nominal_mm, ident.errors_mm)
    q = read_measurements(ROOT / "data" / "sk120" / "test_rectangle.csv").q_deg[::20][:10]
    assert np.all(q[:, 3:5] == 0) and np.abs(q[:, 5]).max() > 5
    return Predictor(model, model_to_dict(model, name="sdp-ci", robot=SK120), SK120), q


def test_targets_at_a_singular_wrist_are_compensated_as_their_csv_is(tmp_path, paper_sdp):
    """The paper's rectangle holds the SK120's wrist singular (axes 4 and 5 at 0). Ten of its poses as a URScript
    with the model's tool as TCP: every target is compensated (a solve to 1e-6 mm stalled near 4e-5 mm there and
    refused six as unreachable), to the positions the same model gives the tool points as a CSV."""
    predictor, q = paper_sdp
    poses = SK120.forward(q)
    points, turns = poses[:, :3, 3], rotation_vectors_from_matrices(poses[:, :3, :3])
    tool = SK120.tool_mm / 1000
    lines = ["def rectangle():", f"  set_tcp(p[{tool[0]:.6f}, {tool[1]:.6f}, {tool[2]:.6f}, 0, 0, 0])"]
    lines += [f"  movel(p[{', '.join(f'{v:.6f}' for v in [*p / 1000, *r])}])" for p, r in zip(points, turns)]
    path = tmp_path / "rectangle.script"                                   # micrometres, as programs are written
    path.write_text("\n".join(lines + ["end"]) + "\n")
    result = compensated(predictor, path)
    assert result.failures == []
    (tmp_path / "out.script").write_bytes(result.output)
    written = np.array([t.position_mm for t in read_program(path).targets])
    commanded = np.array([t.position_mm for t in read_program(tmp_path / "out.script").targets])
    np.testing.assert_allclose(commanded, predictor.compensate(written), atol=1e-3)      # the file's micrometres


def trimmed(value: float, decimals: int) -> str:
    """A number as RobotStudio and PolyScope write it: fixed decimals, trailing zeros dropped."""
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def rectangle_program(dialect: str, q, tool_mm) -> dict:
    """The rectangle's poses ``q`` (n, 6) as a cell writes them, the TCP ``tool_mm`` on the flange, with the
    configuration of their own joints: RAPID robtargets (RobotStudio's 9 decimals, confdata of axes 1, 4, 6;
    ``rapid-taught``: positions to 0.01 mm and quaternions of 4 decimals, as hand-taught modules write them,
    the wrist then 0.002 to 0.009 degrees off straight), a KRL module of inline forms (the .dat's E6POS in
    KSS's 3 and 4 decimals with S and T; its .src), a PolyScope export (12 decimals, no leading zero). Returns
    file name -> text; the first is compensated."""
    flange = SK120.flange(q)
    tcp = flange[:, :3, 3] + np.einsum("nij,j->ni", flange[:, :3, :3], tool_mm)
    R = flange[:, :3, :3]
    n = len(q)
    if dialect.startswith("rapid"):
        quat, cf = quaternions_from_matrices(R), np.floor(q[:, [0, 3, 5]] / 90).astype(int)
        places = (2, 4) if dialect == "rapid-taught" else (9, 9)
        t = ",".join(trimmed(v, 3) for v in tool_mm)
        lines = ["MODULE Rectangle", f"    PERS tooldata tReflector:=[TRUE,[[{t}],[1,0,0,0]],[5,[0,0,60],[1,0,0,0],0,0,0]];"]
        lines += [f"    CONST robtarget Target_{10 * (k + 1)}:=[[{','.join(trimmed(v, places[0]) for v in tcp[k])}],"
                  f"[{','.join(trimmed(v, places[1]) for v in quat[k])}],[{cf[k, 0]},{cf[k, 1]},{cf[k, 2]},0],"
                  "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];" for k in range(n)]
        lines += ["    PROC Path_10()"] + [f"        MoveL Target_{10 * (k + 1)},v200,fine,tReflector\\WObj:=wobj0;"
                                           for k in range(n)] + ["    ENDPROC", "ENDMODULE"]
        return {"Rectangle.mod": "\r\n".join(lines) + "\r\n"}
    if dialect == "krl":
        abc, turn = kuka_abc_from_matrices(R), ((q < 0) * (1 << np.arange(6))).sum(axis=1)
        dat = ["&ACCESS RVP", "&REL 1", "&PARAM TEMPLATE = C:\\KRC\\Roboter\\Template\\vorgabe", "DEFDAT  RECT",
               ";FOLD EXTERNAL DECLARATIONS;%{PE}%V3.2.0,%MKUKATPBASIS,%CEXT,%VCOMMON,%P",
               ";ENDFOLD (EXTERNAL DECLARATIONS)"]
        src = ["&ACCESS RVP", "&REL 1", "DEF rect( )", ";FOLD INI", "  BAS (#INITMOV,0 )", ";ENDFOLD (INI)"]
        for k in range(n):
            dat += [f"DECL E6POS XP{k + 1}={{X {tcp[k, 0]:.3f},Y {tcp[k, 1]:.3f},Z {tcp[k, 2]:.3f},A {abc[k, 0]:.4f},"
                    f"B {abc[k, 1]:.4f},C {abc[k, 2]:.4f},S 2,T {turn[k]},E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}}",
                    f'DECL FDAT FP{k + 1}={{TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE,POINT2[] " "}}']
            src += [f";FOLD LIN P{k + 1} Vel=0.2 m/s CPDAT1 Tool[1] Base[0];%{{PE}}%R 8.3.31,%MKUKATPBASIS,%CMOVE",
                    "$BWDSTART=FALSE", "LDAT_ACT=LCPDAT1", f"FDAT_ACT=FP{k + 1}", "BAS(#CP_PARAMS,0.2)",
                    f"LIN XP{k + 1}", ";ENDFOLD"]
        return {"rect.dat": "\r\n".join(dat + ["ENDDAT"]) + "\r\n", "rect.src": "\r\n".join(src + ["END"]) + "\r\n"}
    rv = rotation_vectors_from_matrices(R)
    lines = ["def Rectangle():", f"  set_tcp(p[{', '.join(trimmed(v / 1000, 5) for v in tool_mm)}, 0, 0, 0])"]
    for k in range(n):
        pose = ", ".join(trimmed(v, 12).replace("0.", ".", 1) for v in [*tcp[k] / 1000, *rv[k]])
        lines += [f"  global Waypoint_{k + 1}_p=p[{pose}]"]
    lines += ['  $ 1 "Robot Program"', '  $ 2 "MoveL"']
    lines += [f"  movel(Waypoint_{k + 1}_p, a=1.2, v=0.25)" for k in range(n)]
    return {"Rectangle.script": "\n".join(lines + ["end"]) + "\n"}


@pytest.mark.parametrize("dialect", ["rapid", "rapid-taught", "krl", "urscript"])
def test_the_straight_wrist_rectangle_is_compensated_as_its_csv_in_every_dialect(tmp_path, paper_sdp, dialect):
    """The rectangle's poses hold the SK120's wrist straight (axis 5 at 0): axes 4 and 6 share one turn, and the
    configuration written with each target (ABB ``[0, 0, -1, 0]``: axis 6 at -5.8 degrees; KUKA's T) is one split
    of it. Every target is compensated (before: RAPID 0 of 10 in both writings, KRL 4 of 10, the others refused
    as unreachable in their configuration or as leaving it), the written configuration kept on the shared turn,
    and the commands are those that `compensate` gives the same targets as a CSV, to 1e-5 mm."""
    predictor, q = paper_sdp
    save_model(predictor.model, tmp_path / "m.json", name="sdp-ci", robot=SK120)
    files = rectangle_program(dialect, q, SK120.tool_mm)
    for name, text in files.items():
        (tmp_path / name).write_bytes(text.encode("latin-1"))
    path = tmp_path / next(iter(files))
    tool = ("--tool", "TOOL_DATA[1]={X %s,Y %s,Z %s,A 0,B 0,C 0}" % tuple(SK120.tool_mm)) if dialect == "krl" else ()
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(tmp_path / "out" / path.name), *tool)
    assert done.returncode == 0, done.stderr
    summary = json.loads((tmp_path / "out" / (path.name + ".json")).read_text())
    assert (summary["targets"], summary["compensated"]) == (10, 10)
    written = np.array([t.position_mm for t in read_program(path).targets])
    (tmp_path / "targets.csv").write_text("x,y,z\n" + "".join("%.12g,%.12g,%.12g\n" % tuple(x) for x in written))
    done = run("compensate", str(tmp_path / "m.json"), str(tmp_path / "targets.csv"), "-o", str(tmp_path / "c.csv"))
    assert done.returncode == 0, done.stderr
    csv = np.loadtxt(tmp_path / "c.csv", delimiter=",", skiprows=1, usecols=(3, 4, 5))
    got = np.array([t.position_mm for t in read_program(tmp_path / "out" / path.name).targets])
    assert np.linalg.norm(got - written, axis=1).min() > 10.0                  # the model moves them, by 15-17 mm
    np.testing.assert_allclose(got, csv, rtol=0, atol=1e-5)


def test_every_unknown_tool_and_base_of_a_program_is_named_in_one_refusal(tmp_path):
    """Three points of a KRL .dat in tools and bases the cell did not give: one refusal names each, with the
    first target that uses it, so that one rerun with every --tool and --frame suffices."""
    text = (FIXTURES / "pallet.dat").read_bytes().replace(b"TOOL_NO 0,BASE_NO 0", b"TOOL_NO 2,BASE_NO 0")
    text = text.replace(b"DECL POS XP3=", b'DECL FDAT FP2={TOOL_NO 3,BASE_NO 1,IPO_FRAME #BASE,POINT2[] " "}\r\n'
                                          b"DECL POS XP3=")
    dat = tmp_path / "pallet.dat"
    dat.write_bytes(text)
    with pytest.raises(UnknownFrameError) as refused:
        compensated(constant_model(SK120, np.zeros(3)), dat)
    message = str(refused.value)
    assert "it is given in the tool 'TOOL_DATA[2]', which is unknown" in message
    assert "unknown too: " in message and "tool 'TOOL_DATA[3]'" in message and "frame 'BASE_DATA[1]'" in message
    assert message.endswith("; nothing written") and "\n" not in message


@pytest.mark.parametrize("move", [b"TriggJ p10, v1000, trigg1, z50, tGripper;",
                                  b"TriggL p10, v1000, trigg1 \\T2:=trigg2, z50, tGripper;"])
def test_a_trigg_move_takes_the_tool_written_after_its_trigger(tmp_path, move):
    """RAPID's TriggJ/TriggL write the trigger data between speed and zone: the tool comes one argument later
    than in MoveJ. p10 moved to by a Trigg with tGripper is compensated as the same MoveJ with tGripper is."""
    source = (FIXTURES / "pallet.mod").read_bytes()
    assert source.count(b"MoveJ p10, v1000, z50, tool0;") == 1
    model = constant_model(SK120, [0.5, -0.3, 0.2])
    paths = {}
    for name, line in (("trigg", move), ("movej", b"MoveJ p10, v1000, z50, tGripper;")):
        paths[name] = tmp_path / f"{name}.mod"
        paths[name].write_bytes(source.replace(b"MoveJ p10, v1000, z50, tool0;", line))
    trigg, movej = (compensated(model, paths[name]) for name in ("trigg", "movej"))
    assert movej.failures == [] and trigg.failures == []
    (tmp_path / "a.mod").write_bytes(trigg.output)
    (tmp_path / "b.mod").write_bytes(movej.output)
    p10 = [next(t for t in read_program(tmp_path / f).targets if t.name == "p10") for f in ("a.mod", "b.mod")]
    assert p10[0].tool == "tGripper" and np.array_equal(p10[0].position_mm, p10[1].position_mm)


def test_a_move_to_a_pose_a_function_computes_is_reported_not_silently_passed_over(tmp_path):
    """pick_place.script's 'movel(pose_add(get_actual_tcp_pose(), p[0, 0, 0.05, 0, 0, 0]), ..)' at line 13 is
    no target: it is reported with the function, and the file is otherwise compensated as before."""
    program = read_program(FIXTURES / "pick_place.script")
    relative = [(k.line, k.name, k.reason) for k in program.left if "relative motion" in k.reason]
    assert relative == [(13, "movel", "a relative motion computed at run time (pose_add(..)): not compensated, "
                                      "kept as written")]
    path = tmp_path / "approach.script"
    path.write_text("movel(pose_add(approach, p[0, 0, 0.1, 0, 0, 0]), a=1.2, v=0.25)\n"
                    "movel(pose_trans(Plane_1, p[0.1, 0.0, 0.05, 0, 3.1416, 0]), a=1.2, v=0.25)\n")
    assert [(k.line, k.column) for k in read_program(path).left] == [(1, 7)]      # pose_trans: a frame, not this


def test_a_program_named_in_another_language_than_its_own_is_refused_not_copied(tmp_path):
    """--program krl on a RAPID module read no targets and wrote the module back uncompensated, exit 0."""
    from partcal.errors import PartcalError
    from partcal.study.downstream import compensate_program_file

    predictor = constant_model(SK120, [0.1, 0.0, 0.0])
    save_model(predictor.model, tmp_path / "m.json", name="m", robot=SK120)
    out = tmp_path / "out.mod"
    with pytest.raises(PartcalError, match=r"pallet.mod: holds no targets read as krl, and its name or text says "
                                           r"rapid: give --program rapid \(or leave --program out\); nothing written"):
        compensate_program_file(tmp_path / "m.json", FIXTURES / "pallet.mod", out, "krl")
    assert not out.exists()
    done = compensate_program_file(tmp_path / "m.json", FIXTURES / "pallet.mod", out, "rapid")
    assert not done.failure and out.read_bytes() != (FIXTURES / "pallet.mod").read_bytes()


# ---------------------------------------------------------------------- real cells: what they write
def test_a_changed_number_keeps_the_style_it_was_written_in():
    """PolyScope writes .208 (no leading zero), RobotStudio 9E+09 (exponents): a number that changes keeps
    that style and its decimals; one within the precision written keeps its text."""
    from partcal.data.program_text import Field, number_text

    def field(text):
        return Field(0, len(text), text, float(text))

    assert number_text(0.2081234567891, field(".208123456789"), 8) == ".208123456789"      # 1e-13 m: kept
    assert number_text(0.2084, field(".208"), 8) == ".20840000"
    assert number_text(-0.0004, field("-.001221359354"), 8) == "-.000400000000"
    assert number_text(0.15034, field("1.5e-01"), 4) == "1.503e-01"                 # 4 decimals of the value
    assert number_text(1203.5, field("1.2E+03"), 6) == "1.203500000E+03"
    assert number_text(0.0123, field("+1.5E-1"), 6) == "+1.2300E-2"


@pytest.mark.parametrize("value, text, decimals, expected", [
    (0.09999, "1.5e-01", 4, "1.000e-01"),       # 4 decimals of the value round to 0.1000: the mantissa to 1.000
    (-0.09999, "1.5e-01", 4, "-1.000e-01"),
    (0.095, "1.5e-01", 4, "9.50e-02"),          # a mantissa of 9.5 stays below 10
    (1.5, "1.0e+00", 2, "1.50e+00"),            # exponent 0 keeps the "+" it was written with, not "-"
    (1.5, "1.0e00", 2, "1.50e00"),
    (0.0, "1.5e-01", 4, "0.000e-01"),           # zero keeps the written exponent
    (0.0123, "1.5E-001", 6, "1.2300E-002"),     # the exponent's digits kept
    (-0.0123, "1.5E-001", 6, "-1.2300E-002"),   # a negative value's own exponent, not the written one
    (0.1234567, "1.23456e-01", 4, "1.23457e-01"),   # 6 decimals written (5 + 1 of the exponent) outnumber 4
    (0.1234561, "1.23456e-01", 4, "1.23456e-01"),   # equal at those 6: the text kept
    (0.15004, "1.5e-01", 4, "1.5e-01"),         # equal at 4 decimals of the value
    (2.0, "5e+00", 0, "2e+00"),                 # no decimals written, none asked: none
    (0.02, "5e+00", 0, "2e-02"),                # ... never fewer than none in the mantissa
    (0.96, "5e+00", 0, "1e+00"),                # 9.6e-01 rounds up to 10: 1e+00, no decimals
    (0.0096, "5e+00", 0, "1e-02"),
    (-0.2, "+1.5e-01", 4, "-2.000e-01"),        # a "+" written, the value negative: its "-" alone
    (0.2, "+1.5e-01", 4, "+2.000e-01"),
    (0.2, "-1.5e-01", 4, "2.000e-01"),         # a "-" written, the value positive: no sign
    (1.5, "1.0e-01", 2, "1.50e00"),             # an exponent written "-", now 0: no sign, not a "+"
])
def test_a_changed_number_in_exponent_form_keeps_the_style_worked_by_hand(value, text, decimals, expected):
    """Each expected text worked out by hand: the value with max(decimals asked, decimals written) decimals of its
    own (``1.5e-01`` writes 2), in exponent form with the mantissa in [1, 10), the exponent's case, sign and
    digits as written."""
    from partcal.data.program_text import Field, number_text

    assert number_text(value, Field(0, len(text), text, float(text)), decimals) == expected


@pytest.mark.parametrize("value, text, decimals, expected", [
    (-2.25, "+1.5", 3, "-2.250"),               # a "+" written, the value negative
    (2.25, "+1.5", 3, "+2.250"),
    (2.25, "-1.5", 3, "2.250"),
    (1.25, ".5", 2, "1.25"),                    # no leading zero written: none dropped from a whole number
    (0.25, "+.5", 2, "+.25"),
    (-0.25, ".5", 2, "-.25"),
    (1.504, "1.50", 1, "1.50"),                 # equal at the 2 decimals written: the text kept
    (1.506, "1.50", 1, "1.51"),
    (-1e-12, "-0.5", 3, "0.000"),               # never "-0.000"
    (-0.0004, "-0.5", 3, "0.000"),              # nor a value that rounds to zero at the decimals written
    (0.1 + 1e-12, "0.05 * 2", 3, "0.05 * 2"),   # constant arithmetic equal: kept
    (0.125, "0.05 * 2", 3, "0.125"),            # changed: a number, of the decimals asked
    (-0.126, "-0.05*2", 2, "-0.13"),
])
def test_a_changed_plain_number_keeps_the_style_worked_by_hand(value, text, decimals, expected):
    from partcal.data.program_text import Field, constant_value, number_text

    old = Field(0, len(text), text, constant_value(text))
    assert number_text(value, old, decimals) == expected


def test_a_polyscope_placeholder_set_from_pose_trans_is_left_and_the_waypoints_compensated(tmp_path):
    """PolyScope declares a variable waypoint p[0,0,0,0,0,0] at the top and an Assignment node sets it from
    pose_trans(..) before its move: the zeros are no target (they were, unreachable: exit 3), nor the offset
    inside pose_trans (refused as relative to an unknown frame: exit 2); movej(get_inverse_kin(Waypoint_2_p, ..))
    moves to a waypoint, no relative motion computed at run time."""
    program = read_program(FIXTURES / "polyscope_export.script")
    assert [(t.name, t.line) for t in program.targets] == [("Waypoint_1_p", 13), ("Waypoint_2_p", 15),
                                                            ("Waypoint_3_p", 17)]
    assert [(x.name, x.line, x.reason) for x in program.left] == [("Place_p", 12, (
        "Place_p is also assigned pose_trans(Waypoint_3_p, p[0, 0, -0.05, 0, 0, 0]) at line 30: the pose its moves "
        "take is computed at run time, not this one: kept as written"))]
    save_model(constant_model(UR10, [0.3, -0.2, 0.1]).model, tmp_path / "m.json", name="c", robot=UR10)
    out = tmp_path / "out.script"
    done = run("compensate", str(tmp_path / "m.json"), str(FIXTURES / "polyscope_export.script"), "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert json.loads((tmp_path / "out.script.json").read_text())["compensated"] == 3
    line = out.read_text().splitlines()[12]            # the constant error taken off in metres, by hand
    assert line.startswith("  global Waypoint_1_p=p[-.176414488873, -.602542264472, .072670995859, -.001221359354, ")


def test_poses_read_at_run_time_are_left_and_reported_not_asked_for_as_frames(tmp_path):
    """here = get_actual_tcp_pose() is no feature a user can give: a pose relative to it, or a move to it, is
    computed at run time (it asked for --frame 'here=VALUE', exit 2)."""
    path = tmp_path / "probe.script"
    path.write_text("def probe():\n"
                    "  here = get_actual_tcp_pose()\n"
                    "  movel(pose_trans(here, p[0, 0, 0.05, 0, 0, 0]), a=0.3, v=0.1)\n"
                    "  movel(here, a=0.3, v=0.1)\n"
                    "  movel(p[-.7446, -.2977, .4299, 2.4066, 2.0194, 0], a=0.3, v=0.1)\n"
                    "end\n")
    program = read_program(path)
    assert [(t.line, t.name) for t in program.targets] == [(5, "movel")]
    assert [(x.line, x.column, x.reason) for x in program.left] == [
        (3, 28, "relative to here, a pose computed at run time (here = get_actual_tcp_pose() at line 2): kept as "
                "written"),
        (4, 9, "moved to here, a pose computed at run time (here = get_actual_tcp_pose() at line 2): not "
               "compensated, kept as written")]
    result = compensated(constant_model(UR10, [0.3, -0.2, 0.1]), path)
    assert not result.failures and result.summary()["compensated"] == 1


def test_poses_kept_in_a_list_and_moved_to_in_a_loop_are_targets(tmp_path):
    """path = [p[..], p[..]] moved to as path[i] in a loop: each element is a target, with the loop's TCP (the
    file had 'no targets')."""
    path = tmp_path / "loop.script"
    path.write_text("def loop():\n"
                    "  set_tcp(p[0, 0, 0.1, 0, 0, 0])\n"
                    "  path = [p[-.7446, -.2977, .4299, 2.4066, 2.0194, 0], p[-.6872, -.5860, .4023, 1.5708, 2.7207, 0]]\n"
                    "  i = 0\n"
                    "  while i < 2:\n"
                    "    movel(path[i], a=1.2, v=0.25)\n"
                    "    i = i + 1\n"
                    "  end\n"
                    "end\n")
    program = read_program(path)
    assert [(t.name, t.line, t.tool) for t in program.targets] == [("path[0]", 3, "set_tcp at line 2"),
                                                                    ("path[1]", 3, "set_tcp at line 2")]
    np.testing.assert_allclose(program.targets[1].position_mm, [-687.2, -586.0, 402.3])
    result = compensated(constant_model(UR10, [0.3, -0.2, 0.1]), path)
    (tmp_path / "out.script").write_bytes(result.output)
    moved = np.array([t.position_mm for t in read_program(tmp_path / "out.script").targets])
    np.testing.assert_allclose(moved, [[-744.9, -297.5, 429.8], [-687.5, -585.8, 402.2]], atol=1e-6)


def test_constant_arithmetic_in_a_pose_is_read_as_its_value_and_expressions_of_variables_left_alike(tmp_path):
    """0.05 * 2 and -(0.1) are constants (refused as 'expected a number', while z0 - 2*h was left): read, and
    written as a number only when the target moves."""
    path = tmp_path / "arith.script"
    path.write_text("def arith():\n"
                    "  z0 = 0.4\n"
                    "  h = 0.05\n"
                    "  movel(p[-.7446, -.2977, 0.2 * 2 + 0.0299, 2.4066, 2.0194, -(0.1)], a=1.2, v=0.25)\n"
                    "  movel(p[-.7446, -.2977, z0 - 2*h, 2.4066, 2.0194, 0], a=1.2, v=0.25)\n"
                    "  movel(p[-.6872, -.5860, .4023, d2r(90), 2.7207, 0], a=1.2, v=0.25)\n"
                    "end\n")
    program = read_program(path)
    assert [t.line for t in program.targets] == [4, 6] and [x.line for x in program.left] == [5]
    np.testing.assert_allclose([f.value for f in program.targets[0].fields], [-.7446, -.2977, .4299, 2.4066, 2.0194,
                                                                               -0.1])
    assert program.targets[1].fields[3].value == np.pi / 2
    assert compensated(constant_model(UR10, np.zeros(3)), path).output == path.read_bytes()
    out = compensated(constant_model(UR10, [0.0, 0.0, 0.5]), path).output.decode()
    assert "0.2 * 2 + 0.0299" not in out and ", 0.42940000, 2.4066, 2.0194, -(0.1)]" in out   # z moved, turn kept


def cell_copy(tmp_path, config=True, replace=()):
    """kuka_home's module (and its $config.dat, unless ``config`` is False) in ``tmp_path``, with byte
    replacements ``(file, old, new)``."""
    for name in ("glue.src", "glue.dat") + (("$config.dat",) if config else ()):
        data = (FIXTURES / "kuka_home" / name).read_bytes()
        for file, old, new in replace:
            if file == name:
                assert old in data
                data = data.replace(old, new)
        (tmp_path / name).write_bytes(data)
    return tmp_path / "glue.src", tmp_path / "glue.dat"


def test_the_home_fdat_of_kukas_inline_forms_is_read_from_config_dat(tmp_path):
    """FDAT_ACT = FHOME (KUKA's standard home motion) sets the base and tool of FHOME, which $config.dat
    declares: read from the $config.dat beside the module, or in System of a KRC backup above it; without
    one, the motion after it is left, naming $config.dat (it said 'set at run time, not defined')."""
    src = read_program(FIXTURES / "kuka_home" / "glue.src")
    assert [(t.line, t.frame, t.tool) for t in src.targets] == [(27, "$NULLFRAME", "TOOL_DATA[1]")]
    assert [(t.name, t.frame, t.tool) for t in read_program(FIXTURES / "kuka_home" / "glue.dat").targets] == [
        (f"XP{k}", "$NULLFRAME", "TOOL_DATA[1]") for k in range(1, 5)]
    (tmp_path / "alone").mkdir()
    alone, _ = cell_copy(tmp_path / "alone", config=False)
    left = read_program(alone).left
    assert [(x.line, x.reason) for x in left] == [(27, (
        "moved to in the base and tool of FDAT_ACT = FHOME at line 21, which neither the module nor a $config.dat "
        "beside it (or in System/ of a folder above it) defines: put the cell's $config.dat there: not "
        "compensated, kept as written"))]
    backup = tmp_path / "KRC" / "R1"
    (backup / "Program" / "glue").mkdir(parents=True)
    (backup / "System").mkdir()
    (backup / "System" / "$config.dat").write_bytes((FIXTURES / "kuka_home" / "$config.dat").read_bytes())
    in_tree, _ = cell_copy(backup / "Program" / "glue", config=False)
    assert [(t.line, t.tool) for t in read_program(in_tree).targets] == [(27, "TOOL_DATA[1]")]
    shift = np.array([0.5, -0.3, 0.2])
    result = compensated(constant_model(SK120, shift), in_tree)
    (in_tree.parent / "out.src").write_bytes(result.output)
    np.testing.assert_allclose(read_program(in_tree.parent / "out.src").targets[0].position_mm,
                               src.targets[0].position_mm - shift, atol=1e-6)      # TOOL_DATA[1] from System/


def test_config_dats_correction_frames_are_no_targets():
    """KSS's $config.dat types its data without DECL (FRAME TOOL_CORR_W={..}, E6AXIS XHOME={..}): the
    correction frames TOOL_CORR_W and M_BASE_CORR were taken as targets (zeros: exit 3)."""
    program = read_program(FIXTURES / "kuka_home" / "$config.dat")
    assert [(t.name, t.kind) for t in program.targets] == [("XHOME", "joints"), ("XHOME1", "joints")]
    assert {x.name for x in program.left} == {"REF_PT[1]", "REF_PT[2]", "REF_TOOL", "TOOL_CORR", "TOOL_CORR_W",
                                              "BASE_CORR", "M_BASE_CORR"}


@pytest.mark.parametrize("replace, name, line, reason", [
    ((("glue.src", b"LIN XP2 C_DIS", b"XP2={X 1105.878,Y 586.352,A -159.7642,B -70.6469,C 14.0764}\r\nLIN XP2 C_DIS"),),
     "XP2", 40, "a partial aggregate assigned at run time: its Z keep the value XP2 had before"),
    ((("glue.src", b"LIN XP3 C_DIS", b"XP3.Z = XP3.Z + 20\r\nLIN XP3 C_DIS"),),
     "XP3", None, "changed at run time (XP3.Z = XP3.Z + 20 at line 47 of glue.src): its declared value is not"),
    ((("glue.src", b"LIN XP4 C_DIS", b"$IPO_MODE = #TCP\r\nLIN XP4 C_DIS"),),
     "XP4", None, "moved to with a fixed tool ($IPO_MODE = #TCP at line 54: the robot carries the workpiece)"),
    ((("glue.src", b"\r\nEND\r\n", b"\r\nEND\r\nDEF set_table( )\r\n  $BASE = BASE_DATA[1]\r\nEND\r\n"),
      ("glue.src", b"LIN XP4 C_DIS", b"set_table( )\r\nLIN XP4 C_DIS")),
     "XP4", None, "moved to in a base or tool set at run time (set by the subroutine set_table() called at line 54)"),
])
def test_krl_statements_that_change_a_point_or_its_frame_leave_it_and_say_so(tmp_path, replace, name, line, reason):
    """What a .src does to a point before its motion, which was passed over in silence and the point compensated
    as declared (exit 0): a partial aggregate without Z (the .dat's same line is refused), a component
    assignment, $IPO_MODE = #TCP (a fixed tool), a subroutine of the module setting $BASE."""
    src, dat = cell_copy(tmp_path, replace=replace)
    program = read_program(src if line else dat)
    found = [x for x in program.left if x.name == name]
    assert len(found) == 1 and found[0].reason.startswith(reason), program.left
    assert line is None or found[0].line == line
    assert name not in [t.name for t in read_program(dat).targets]
    result = compensated(constant_model(SK120, [0.5, -0.3, 0.2]), dat)
    assert not result.failures and f"DECL E6POS {name}=".encode() in result.output
    kept = next(x for x in dat.read_bytes().split(b"\r\n") if x.startswith(f"DECL E6POS {name}=".encode()))
    assert kept in result.output.split(b"\r\n")                   # byte for byte


@pytest.mark.parametrize("file, old, new, axis", [
    ("glue.dat", b"T 14,E1 0.0", b"T 14,E1 1500.0", "E1 is at 1500"),
    ("robotstudio_taught.mod", b"[0,-1,0,0],[9E+09,", b"[0,-1,0,0],[1500,", "eax_a is at 1500"),
])
def test_a_target_of_a_robot_on_a_track_is_refused_naming_the_axis(tmp_path, file, old, new, axis):
    """A KUKA or ABB on a linear track writes the track's position with each pose (E1, eax_a): the pose is then
    not in the robot's own frame, and was compensated as if it were ('unreachable by the robot's kinematics',
    or a wrong correction). Refused, naming the target, the axis and what is needed; axes at 0 (KSS writes
    E1 0.0 .. E6 0.0 for every E6POS) and ABB's unused 9E9 change nothing."""
    if file == "glue.dat":
        _, path = cell_copy(tmp_path, replace=[(file, old, new)])
    else:
        path = tmp_path / file
        path.write_bytes((FIXTURES / file).read_bytes().replace(old, new))
    save_model(constant_model(SK120, np.zeros(3)).model, tmp_path / "m.json", name="zero", robot=SK120)
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(tmp_path / "out" / path.name))
    assert done.returncode == 2 and f"its external axis {axis} (a linear track carrying the robot" in done.stderr
    assert "give this station's targets relative to the robot's base" in done.stderr and "nothing written" in done.stderr
    assert not (tmp_path / "out").exists()


def test_an_unreachable_target_says_where_the_cause_is(tmp_path):
    """'unreachable by the robot's kinematics' pointed nowhere: a target at the stretched arm says so; one far
    off names the frame and tool it was read in, and that a base or tool set where partcal does not read (a
    subroutine of another module, a track) would move it."""
    poses = UR10.forward(np.array([[0, -90, 0, -90, 90, 0.0], [10, -80, 90, -100, -90, 20.0]]))
    poses[1, :3, 3] += [5000.0, 0.0, 0.0]                                 # far beyond the arm's reach
    rv = rotation_vectors_from_matrices(poses[:, :3, :3])
    path = tmp_path / "cell.script"
    path.write_text("def cell():\n" + "".join(f"  movel(p[{', '.join(f'{v:.9f}' for v in [*p[:3, 3] / 1000, *r])}])\n"
                                              for p, r in zip(poses, rv)) + "end\n")
    result = compensated(constant_model(UR10, [0.3, -0.2, 0.1]), path, keep_unconverged=True)
    why = [w for _, w in result.failures]
    assert why[0].startswith("is unreachable by the robot's kinematics: it lies where the arm is stretched out or "
                             "folded (a singular pose), and the solve stops")
    assert why[1].startswith("is unreachable by the robot's kinematics: the nearest the arm comes is")
    assert "in the frame (the default) with the tool (the default) it was read in; if another base or tool is in " \
           "force at its motion (set by a subroutine partcal does not read, or a track moving the robot)" in why[1]


def test_programs_warn_target_by_target_of_targets_far_from_the_models_data(tmp_path):
    """A joint model fitted within 20 degrees of one posture, a PolyScope program with one target there and one
    with joint 1 turned 183 degrees: only that one is warned of, with its distance (computed here from the
    training joints), as the CSV path warns of its rows (a program said nothing)."""
    rng = np.random.default_rng(4)
    centre = np.array([20.0, -70.0, 90.0, -100.0, -80.0, 10.0])
    X = centre + rng.uniform(-20, 20, (300, 6))
    model = ErrorModel(inputs="joint", degree=1, solver="lstsq").fit(X, np.tile([0.3, -0.2, 0.1], (300, 1)))
    save_model(model, tmp_path / "m.json", name="joint", robot=UR10)
    q = np.array([centre, centre + [183.0, 0, 0, 0, 0, 0]])
    poses = UR10.forward(q)
    rv = rotation_vectors_from_matrices(poses[:, :3, :3])
    joints = ", ".join(f"{v:.6f}" for v in np.radians(q[1]))
    lines = [f"  movej([{', '.join(f'{v:.6f}' for v in np.radians(q[0]))}])",
             f"  movel(p[{', '.join(f'{v:.9f}' for v in [*poses[0, :3, 3] / 1000, *rv[0]])}])",
             f"  movej([{joints}])", f"  movel(p[{', '.join(f'{v:.9f}' for v in [*poses[1, :3, 3] / 1000, *rv[1]])}])"]
    path = tmp_path / "far.script"
    path.write_text("def far():\n" + "\n".join(lines) + "\nend\n")
    done = run("compensate", str(tmp_path / "m.json"), str(path), "-o", str(tmp_path / "out.script"))
    assert done.returncode == 0, done.stderr
    far = [line for line in done.stderr.splitlines() if "from the data the model was fitted on" in line]
    nearest = np.linalg.norm(X[None] - q[:, None], axis=2).min(axis=1)          # brute force, degrees
    assert nearest[0] < 50 < nearest[1]
    assert [re.search(r": line (\d+), column", line).group(1) for line in far] == ["4", "5"]
    for line in far:       # the compensated joints lie within a tenth of a degree of the written ones
        said = float(re.search(r"lies ([\d.]+) deg from the data the model was fitted on \(more than 50 deg\)",
                               line).group(1))
        assert abs(said - nearest[1]) < 0.1
    summary = json.loads((tmp_path / "out.script.json").read_text())
    assert [(x["line"], x["unit"]) for x in summary["far_from_data"]] == [(4, "deg"), (5, "deg")]


@pytest.mark.parametrize("name", ["pallet.mod", "pallet.dat", "pick_place.script"])
@pytest.mark.parametrize("angle_deg, kept", [(0.009, True), (0.011, False)])
def test_a_rotation_within_the_tolerance_keeps_its_numbers_and_one_beyond_is_rewritten(name, angle_deg, kept):
    """Every pose target turned by ``angle_deg`` about its own x axis (the angle between the old and the new rotation
    is that angle, whatever the rotation's form) against a tolerance of 0.01 degrees: 0.009 keeps the rotation's
    numbers as written, 0.011 rewrites them (its quaternion, KUKA angles or rotation vector change by about 1e-4 of
    their unit, beyond the decimals written); the positions, unchanged, keep theirs."""
    program = read_program(FIXTURES / name)
    targets = [t for t in program.targets if t.kind == "pose"]
    turn = Rotation.from_rotvec([np.radians(angle_deg), 0.0, 0.0]).as_matrix()
    texts = program.dialect.texts(targets, np.stack([t.position_mm for t in targets]),
                                  np.stack([t.rotation @ turn for t in targets]), tol_deg=0.01)
    assert len(targets) >= 2
    for t, row in zip(targets, texts):
        assert row[:3] == [f.text for f in t.fields[:3]]
        assert (row[3:] == [f.text for f in t.fields[3:]]) == kept, (t.name, row)


@pytest.mark.parametrize("name, per_degree", [("pick_place.script", np.pi / 180.0), ("trajectory.csv", 1.0)])
def test_joints_one_degree_on_are_written_in_the_files_unit(name, per_degree):
    """Every joint target given back one degree further on every joint: URScript's joints are radians (each number
    grows by pi / 180 = 0.0174533), a joint trajectory's degrees (each grows by 1)."""
    program = read_program(FIXTURES / name)
    targets = [t for t in program.targets if t.kind == "joints"]
    texts = program.dialect.texts(targets, joints_deg=np.stack([t.joints_deg for t in targets]) + 1.0)
    assert len(targets) >= 2
    for t, row in zip(targets, texts):
        np.testing.assert_allclose([float(x) for x in row], [f.value + per_degree for f in t.fields], atol=1e-6)


def test_a_rotation_given_back_unchanged_keeps_its_numbers_with_no_tolerance():
    """RobotStudio's quaternions of 4 decimals a hair off unit: given back exactly the rotations read, with a tolerance
    of 0 degrees, every number keeps its text (normalised, they would print differently)."""
    program = read_program(FIXTURES / "robotstudio_taught.mod")
    targets = [t for t in program.targets if t.kind == "pose"]
    texts = program.dialect.texts(targets, np.stack([t.position_mm for t in targets]),
                                  np.stack([t.rotation for t in targets]), tol_deg=0.0)
    assert len(targets) == 4
    assert texts == [[f.text for f in t.fields] for t in targets]


def test_a_correction_within_the_tolerance_or_a_rotation_kept_leaves_the_numbers_as_written():
    """Below the compensation's tolerance (1e-4 mm, 1e-5 degrees) a target keeps its text though PolyScope's 12
    decimals print 1e-9 mm (a model's 1e-6 mm came back as changed digits); a rotation a position model keeps
    keeps its numbers, a RobotStudio quaternion of 4 decimals a hair off unit included (it was normalised and
    printed to 9 decimals), while the position moves by the constant error taken off."""
    polyscope = FIXTURES / "polyscope_export.script"
    assert compensated(constant_model(UR10, [1e-6, -1e-6, 1e-6]), polyscope).output == polyscope.read_bytes()
    taught = FIXTURES / "robotstudio_taught.mod"
    out = compensated(constant_model(SK120, [0.3, -0.2, 0.1]), taught).output.decode()
    before = re.findall(r"Target_\d+:=\[\[([^\]]*)\],\[([^\]]*)\]", taught.read_text())
    after = re.findall(r"Target_\d+:=\[\[([^\]]*)\],\[([^\]]*)\]", out)
    assert [q for _, q in after] == [q for _, q in before] and len(before) == 4
    for (p0, _), (p1, _) in zip(before, after):
        np.testing.assert_allclose(np.array(p1.split(","), float) - np.array(p0.split(","), float),
                                   [-0.3, 0.2, -0.1], atol=1e-9)
