"""The calibrated robot out: URDF (reloaded by yourdfpy), the UR kinematics YAML (rebuilt as ur_description
builds its chain), the DH table, and what geometry cannot carry."""

import re

import numpy as np
import pytest
import yaml
from conftest import ROOT, partcal_cli, tilted_dh_chain
from scipy.spatial.transform import Rotation

from partcal import ErrorModel, KinematicModel, PartcalError, load_robot, read_measurements
from partcal.study.export import export_model
from partcal.study.persist import save_model

yourdfpy = pytest.importorskip("yourdfpy")
UR_JOINTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def tilted_ur10_errors(q, seed=0):
    """Errors (n, 3) mm of a UR10 with DH errors, tilts about y after rows 2 and 3, a tool and a turned and
    shifted base, against the nominal UR10 with the nominal tool: written from 4 x 4 DH matrices."""
    rng = np.random.default_rng(seed)
    nominal = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
    d = nominal.d_mm + rng.normal(0, 0.5, 6)
    a = nominal.a_mm + rng.normal(0, 0.5, 6)
    alpha = np.radians(nominal.alpha_deg + rng.normal(0, 0.02, 6))
    offset = rng.normal(0, 0.05, 6)
    start = np.eye(4)
    start[:3, :3] = Rotation.from_euler("xyz", [0.02, -0.03, 0.04], degrees=True).as_matrix()
    start[:3, 3] = [1.0, -0.5, 0.8]
    out = tilted_dh_chain(q, d, a, alpha, offset, {1: 0.03, 2: -0.02}, start)
    return nominal, (out @ [0.3, -0.2, 120.4, 1.0])[:, :3] - nominal.positions(q)


@pytest.fixture(scope="module")
def paper_data():
    return read_measurements(ROOT / "data" / "sk120" / "identification.csv")


@pytest.fixture(scope="module")
def complete_file(tmp_path_factory):
    q = np.random.default_rng(1).uniform(-180, 180, (150, 6))
    nominal, errors = tilted_ur10_errors(q)
    model = KinematicModel(robot=nominal, parametrization="complete").fit(q, errors)
    path = tmp_path_factory.mktemp("export") / "complete.json"
    save_model(model, path, name="complete", robot=nominal)
    return path, model


def ur_description_chain(kinematics, q_deg):
    """tool0 poses (n, 4, 4), metres, in base_link_inertia, as ur_description's ur_macro.xacro builds them:
    per joint <origin xyz rpy> (Tr(x, y, z) Rz(yaw) Ry(pitch) Rx(roll)) then a turn about z; then wrist_3 ->
    flange (rpy 0 -pi/2 -pi/2) -> tool0 (rpy pi/2 0 pi/2)."""
    def origin(xyz, rpy):
        out = np.eye(4)
        out[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()     # extrinsic x, y, z: Rz Ry Rx
        out[:3, 3] = xyz
        return out

    out = np.tile(np.eye(4), (len(q_deg), 1, 1))
    for k, name in enumerate(UR_JOINTS):
        v = kinematics[name]
        turn = np.tile(np.eye(4), (len(q_deg), 1, 1))
        turn[:, :3, :3] = Rotation.from_euler("z", q_deg[:, k, None], degrees=True).as_matrix()
        out = out @ origin([v["x"], v["y"], v["z"]], [v["roll"], v["pitch"], v["yaw"]]) @ turn
    return out @ origin([0, 0, 0], [0, -np.pi / 2, -np.pi / 2]) @ origin([0, 0, 0], [np.pi / 2, 0, np.pi / 2])


def test_exported_urdf_and_ur_kinematics_reproduce_the_complete_models_geometry(complete_file, tmp_path):
    """1,000 joint sets: the URDF reloaded by yourdfpy (world -> tcp) gives the model's positions, and the UR
    file rebuilt as ur_description builds its chain, with the reported TCP, the positions in the robot's own
    base frame, both to 1e-6 mm."""
    path, model = complete_file
    result = export_model(path, tmp_path)
    assert set(result.files) == {"urdf", "ur", "yaml"} and "dh" in result.skipped
    assert "no DH table" in result.skipped["dh"] and result.not_carried == ""
    q = np.random.default_rng(2).uniform(-180, 180, (1000, 6))
    expected = model.robot_.positions(q) + model.predict(q)
    urdf = yourdfpy.URDF.load(str(result.files["urdf"]), load_meshes=False)
    assert urdf.actuated_joint_names == [f"joint{k}" for k in range(1, 7)]
    got = []
    for angles in np.radians(q):
        urdf.update_cfg(angles)
        got.append(urdf.get_transform("tcp", "world")[:3, 3] * 1000.0)
    np.testing.assert_allclose(np.array(got), expected, rtol=0, atol=1e-6)

    kinematics = yaml.safe_load(result.files["ur"].read_text())["kinematics"]
    assert kinematics["hash"].startswith("calib_partcal_")
    tool0 = ur_description_chain(kinematics, q)
    points = tool0[:, :3, :3] @ (result.tcp_mm / 1000.0) + tool0[:, :3, 3]
    size = 7 * 6 + 9
    values = model.identification_.value
    base = Rotation.from_euler("xyz", values[size - 3:size], degrees=True).as_matrix()   # Rz Ry Rx
    own = (expected - values[size - 6:size - 3]) @ base                                  # back to the robot's frame
    np.testing.assert_allclose(points * 1000.0, own, rtol=0, atol=1e-6)


def test_a_dh_model_exports_its_dh_table_and_a_ur_file_of_the_published_form(tmp_path):
    """DH on the UR10: the DH table holds the identified rows; the UR file of the nominal geometry is
    ur_description's layout (shoulder z = d1, upper_arm roll = 90 deg, forearm x = a2, wrist_1 x = a3 and
    z = d4, wrist_2 y = -d5, wrist_3 y = d6: the figures of the built-in YAML)."""
    q = np.random.default_rng(3).uniform(-180, 180, (120, 6))
    nominal, errors = tilted_ur10_errors(q, seed=4)
    model = KinematicModel(robot=nominal).fit(q, errors * 0.0)        # the nominal geometry itself
    path = tmp_path / "dh.json"
    save_model(model, path, name="DH", robot=nominal)
    result = export_model(path, tmp_path / "out")
    assert set(result.files) == {"urdf", "ur", "dh", "yaml"}
    table = result.files["dh"].read_text().splitlines()
    assert table[0] == "row,theta,d_mm,a_mm,alpha_deg" and table[2] == "2,q2,0.0,-612.7,0.0"
    k = yaml.safe_load(result.files["ur"].read_text())["kinematics"]
    np.testing.assert_allclose([k["shoulder"]["z"], k["upper_arm"]["roll"], k["forearm"]["x"], k["wrist_1"]["x"],
                                k["wrist_1"]["z"], k["wrist_2"]["y"], k["wrist_3"]["y"]],
                               [0.118, np.pi / 2, -0.6127, -0.5716, 0.1639, -0.1157, 0.0922], atol=1e-12)
    np.testing.assert_allclose(result.tcp_mm, [0.0, 0.0, 120.0], atol=1e-9)


def test_what_geometry_cannot_carry_is_named_with_both_rms(sk120, tmp_path, paper_data):
    """A hybrid on the SK120: no URDF (a parallelogram row follows two joints) and no UR file; the DH table
    and the robot YAML; the residual named in one line with the RMS of the geometry and of the full model."""
    model = KinematicModel(robot=sk120, residual=ErrorModel(inputs="joint", degree=1, solver="lstsq"))
    model.fit(paper_data.q_deg, paper_data.errors_mm)
    path = tmp_path / "hybrid.json"
    save_model(model, path, name="hybrid", robot=sk120)
    result = export_model(path, tmp_path / "out", q_deg=paper_data.q_deg, errors_mm=paper_data.errors_mm)
    assert set(result.files) == {"dh", "yaml"}
    assert "row 3 turns with 2 joints (q2 q3)" in result.skipped["urdf"]
    assert result.not_carried.startswith("not carried by the geometric files: the residual model")
    assert "by the exported geometry" in result.not_carried and "\n" not in result.not_carried
    series = ErrorModel(inputs="joint", degree=1, solver="lstsq").fit(paper_data.q_deg, paper_data.errors_mm)
    save_model(series, tmp_path / "series.json", name="series", robot=sk120)
    with pytest.raises(PartcalError, match="has no robot geometry to export"):
        export_model(tmp_path / "series.json", tmp_path / "out")


def test_export_on_the_command_line(complete_file, tmp_path):
    path, _ = complete_file
    done = partcal_cli("export", str(path), "-o", str(tmp_path), "--formats", "urdf,dh")
    assert done.returncode == 0, done.stderr
    assert "urdf: " in done.stdout and "dh: not written:" in done.stdout
    bad = partcal_cli("export", str(path), "-o", str(tmp_path), "--formats", "step")
    assert bad.returncode == 2 and "expected one of urdf, ur, dh, yaml" in bad.stderr


def test_export_into_a_file_or_below_one_is_refused_with_exit_2(complete_file, tmp_path):
    path, _ = complete_file
    a_file = tmp_path / "a_file"
    a_file.write_text("keep\n")
    for output in (a_file, a_file / "sub"):
        done = partcal_cli("export", str(path), "-o", str(output))
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1 and str(a_file) in done.stderr and "folder" in done.stderr
    assert a_file.read_text() == "keep\n"


@pytest.fixture(scope="module")
def turned_probe_file(tmp_path_factory):
    """A complete model of a UR10 whose probe sits turned by about 0.05 degrees on the flange, identified from
    noise-free positions and orientations (the orientation a 6-D probe measures)."""
    rng = np.random.default_rng(6)
    q = rng.uniform(-170, 170, (80, 6))
    nominal, errors = tilted_ur10_errors(q, seed=7)
    probe = Rotation.from_rotvec([3e-4, -6e-4, 5e-4])                       # 0.047 deg
    true = true_turned_ur10(nominal, seed=7)
    turns = Rotation.from_matrix(true.forward(q)[:, :3, :3] @ probe.as_matrix()
                                 @ nominal.forward(q)[:, :3, :3].transpose(0, 2, 1)).as_rotvec()
    y = np.hstack([true.positions(q) - nominal.positions(q), turns * 1000.0])      # mm, then mrad
    model = KinematicModel(robot=nominal, parametrization="complete", use_orientation=True).fit(q, y)
    path = tmp_path_factory.mktemp("turned") / "turned.json"
    save_model(model, path, name="turned", robot=nominal)
    return path, model, probe


def true_turned_ur10(nominal, seed):
    """The UR10 of :func:`tilted_ur10_errors`'s kind as a robot: DH errors, a moved tool, a turned base."""
    rng = np.random.default_rng(seed)
    return nominal.replace(d_mm=nominal.d_mm + rng.normal(0, 0.5, 6), a_mm=nominal.a_mm + rng.normal(0, 0.5, 6),
                           alpha_deg=nominal.alpha_deg + rng.normal(0, 0.02, 6),
                           theta_offset_deg=nominal.theta_offset_deg + rng.normal(0, 0.05, 6),
                           tool_mm=nominal.tool_mm + [0.3, -0.2, 0.4],
                           base_rotation=Rotation.from_euler("xyz", [0.02, -0.03, 0.04], degrees=True).as_matrix(),
                           base_mm=np.array([1.0, -0.5, 0.8]))


def model_tool_poses(model, q):
    """The model's full tool poses (n, 4, 4), mm, in the measurement frame: the nominal pose moved by the
    predicted position error and turned by the predicted orientation error (mrad)."""
    nominal = model.robot_.forward(q)
    errors = model.predict(q)
    out = nominal.copy()
    out[:, :3, 3] += errors[:, :3]
    out[:, :3, :3] = Rotation.from_rotvec(errors[:, 3:] / 1000.0).as_matrix() @ nominal[:, :3, :3]
    return out


def turn_deg(a, b):
    """The angle (degrees) between the rotations of poses a and b, (n,)."""
    return np.degrees(np.linalg.norm(Rotation.from_matrix(a[:, :3, :3] @ b[:, :3, :3].transpose(0, 2, 1))
                                     .as_rotvec(), axis=1))


def test_the_identified_probe_turn_is_in_the_exported_urdf_and_the_ur_tcp(turned_probe_file, tmp_path):
    """The tool's identified turn rides on flange -> tcp: the URDF read back by yourdfpy and by partcal gives the
    model's full tool pose (position to 1e-9 mm, orientation to 1e-9 deg) on 300 joint sets; the UR file's
    chain as ur_description builds it, with the reported TCP (position and rotation vector), gives it in the
    robot's own frame. The robot YAML, whose tool is a point, says that it leaves the turn out."""
    path, model, probe = turned_probe_file
    assert model.orientation_
    probe_deg = np.linalg.norm(model.identification_.value[-3:])     # the share the last row's origin leaves
    assert 0.03 < probe_deg < np.degrees(probe.magnitude())
    result = export_model(path, tmp_path)
    q = np.random.default_rng(8).uniform(-180, 180, (300, 6))
    expected = model_tool_poses(model, q)
    assert turn_deg(expected, model.identified_robot_.forward(q)).min() > 0.03    # the turn is there to carry

    urdf = yourdfpy.URDF.load(str(result.files["urdf"]), load_meshes=False)
    got = []
    for angles in np.radians(q):
        urdf.update_cfg(angles)
        got.append(urdf.get_transform("tcp", "world"))
    got = np.array(got)
    got[:, :3, 3] *= 1000.0
    ours = load_robot(f"{result.files['urdf']}#base=world&tip=tcp").forward(q)
    for poses in (got, ours):
        np.testing.assert_allclose(poses[:, :3, 3], expected[:, :3, 3], rtol=0, atol=1e-9)
        assert turn_deg(poses, expected).max() < 1e-9

    kinematics = yaml.safe_load(result.files["ur"].read_text())["kinematics"]
    pose = [float(v) for v in result.tcp_text.split("set_tcp(p[")[1].rstrip("])").split(",")]   # m, rad
    tcp = np.eye(4)
    tcp[:3, :3] = Rotation.from_rotvec(pose[3:]).as_matrix()
    tcp[:3, 3] = pose[:3]
    np.testing.assert_allclose(np.array(pose[:3]) * 1000.0, result.tcp_mm, rtol=0, atol=1e-12)
    tool = ur_description_chain(kinematics, q) @ tcp
    tool[:, :3, 3] *= 1000.0
    size = 7 * 6 + 9
    values = model.identification_.value
    base = np.eye(4)
    base[:3, :3] = Rotation.from_euler("xyz", values[size - 3:size], degrees=True).as_matrix()
    base[:3, 3] = values[size - 6:size - 3]
    own = np.linalg.inv(base) @ expected                                      # in the robot's own base frame
    np.testing.assert_allclose(tool[:, :3, 3], own[:, :3, 3], rtol=0, atol=1e-6)
    assert turn_deg(tool, own).max() < 1e-9
    header = result.files["ur"].read_text().split("kinematics:")[0]
    assert "This file has no tool" in header and "set_tcp(p[" in header
    assert f"the tool's identified turn ({probe_deg:.4f} deg) is not carried by turned_robot.yaml" in \
        result.not_carried


def test_export_prints_the_ur_tcp_with_its_rotation_and_what_the_tool_point_files_leave_out(turned_probe_file,
                                                                                          tmp_path):
    path, _, _ = turned_probe_file
    done = partcal_cli("export", str(path), "-o", str(tmp_path))
    assert done.returncode == 0, done.stderr
    line = next(t for t in done.stdout.splitlines() if t.startswith("ur: the kinematics file has no tool"))
    assert " rad (rotation vector, a turn of " in line and "set_tcp(p[" in line
    assert "the tool's identified turn (" in done.stdout and "is not carried by turned_robot.yaml" in done.stdout


KR16_LIKE = {"name": "kr16_like", "joints": 6, "limits_deg": [[-170, 170]] * 6,
             "links": [{"theta": "q1", "d": 675, "a": 260, "alpha": -90}, {"theta": "q2", "d": 0, "a": 680, "alpha": 0},
                       {"theta": "q3 - 90", "d": 0, "a": -35, "alpha": 90},
                       {"theta": "q4", "d": -670, "a": 0, "alpha": -90}, {"theta": "q5", "d": 0, "a": 0, "alpha": 90},
                       {"theta": "q6", "d": -115, "a": 0, "alpha": 0}]}
SEVEN = {"name": "seven", "joints": 7, "limits_deg": [[-170, 170]] * 7,
         "links": [{"theta": f"q{k}", "d": 300 if k % 2 else 0, "a": 0, "alpha": 90 if k % 2 else -90}
                   for k in range(1, 8)]}


def nominal_model_file(spec, folder, name):
    """A kinematic model of the robot ``spec`` fitted on its own nominal positions (zero errors)."""
    from partcal.robot.description import robot_from_dict

    robot = robot_from_dict(spec)
    q = np.random.default_rng(9).uniform(-150, 150, (60, robot.n_joints))
    model = KinematicModel(robot=robot).fit(q, np.zeros((60, 3)))
    path = folder / f"{name}.json"
    save_model(model, path, name=name, robot=robot)
    return path


def test_the_ur_file_is_written_for_ur_shaped_chains_only(tmp_path):
    """A KUKA-shaped arm (joint 4 along the forearm) gets the URDF, DH table and robot YAML by default, and the
    UR file is skipped saying why; the UR10 (joints 2, 3, 4 parallel) gets it (the test above)."""
    path = nominal_model_file(KR16_LIKE, tmp_path, "kr16")
    result = export_model(path, tmp_path / "out")
    assert set(result.files) == {"urdf", "dh", "yaml"} and result.tcp_text == ""
    assert result.skipped["ur"] == ("kr16_like: the UR kinematics file is for UR-shaped chains (joints 2, 3 and 4 "
                                    "about parallel axes, joint 5 across them, as ur_description builds its arms); "
                                    "here joints 3 and 4 turn about axes 90.0 degrees apart")


@pytest.mark.parametrize("which, formats, message", [
    ("seven", "ur", r"nothing written for .*seven\.json: ur: seven: the UR kinematics file needs six rows turned by "
                    r"q1\.\.q6 in order; the robot has 7 joints in 7 rows"),
    ("complete", "dh", r"nothing written for .*complete\.json: dh: .*no DH table"),
    ("kr16", "ur", r"nothing written for .*kr16\.json: ur: kr16_like: the UR kinematics file is for UR-shaped"),
])
def test_an_export_that_writes_nothing_exits_2_naming_the_format_and_why(complete_file, tmp_path, which, formats,
                                                                         message):
    path = {"seven": lambda: nominal_model_file(SEVEN, tmp_path, "seven"),
            "kr16": lambda: nominal_model_file(KR16_LIKE, tmp_path, "kr16"),
            "complete": lambda: complete_file[0]}[which]()
    out = tmp_path / "out"
    done = partcal_cli("export", str(path), "-o", str(out), "--formats", formats)
    assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
    assert re.search(message, done.stderr) and not out.exists()


def test_a_dh_export_with_data_gives_the_rms_it_leaves_and_warns_when_worse_than_none(sk120, tmp_path, paper_data):
    """A plain DH model carries all its geometry into the files: on data the line gives the 3-D RMS that geometry
    (the identified robot, base correction included) leaves beside the uncompensated one; errors the geometry
    makes worse are said."""
    model = KinematicModel(robot=sk120).fit(paper_data.q_deg, paper_data.errors_mm)
    path = tmp_path / "dh.json"
    save_model(model, path, name="dh", robot=sk120)
    q, errors = paper_data.q_deg, paper_data.errors_mm
    result = export_model(path, tmp_path / "out", q_deg=q, errors_mm=errors)
    moved = model.identified_robot_.positions(q) - sk120.positions(q)
    rms = lambda e: np.sqrt(np.mean(np.sum(e**2, axis=1)))       # noqa: E731
    assert result.not_carried == (f"on the 85 poses given: 3-D RMS left {rms(errors - moved):.3f} mm by the exported "
                                  f"geometry, {rms(errors):.3f} mm uncompensated")
    assert rms(errors - moved) < 0.1 * rms(errors)
    worse = export_model(path, tmp_path / "again", q_deg=q, errors_mm=-moved).not_carried    # turned the wrong way
    assert worse.endswith("the exported geometry alone makes these poses worse than no calibration: use the full "
                          "model (partcal compensate), not the exported files")
