"""The calibrated robot out: URDF (reloaded by yourdfpy), the UR kinematics YAML (rebuilt as ur_description
builds its chain), the DH table, and what geometry cannot carry."""

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
