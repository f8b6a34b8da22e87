"""URDF in: chains from URDF files against yourdfpy's own forward kinematics, mimic joints, refusals."""

from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_jacobian_is_the_central_difference

from partcal import ConfigError, RobotFileError, load_robot
from partcal.robot.description import robot_from_dict, robot_reference, robot_to_dict
from partcal.robot.urdf import robot_from_urdf

yourdfpy = pytest.importorskip("yourdfpy")


def example_urdf(relative: str) -> Path:
    """A URDF shipped by example-robot-data (its files live under the cmeel prefix of site-packages)."""
    try:
        path = Path(distribution("example-robot-data").locate_file(
            f"cmeel.prefix/share/example-robot-data/robots/{relative}"))
    except PackageNotFoundError:
        pytest.skip("example-robot-data is not installed (pip install -e '.[test]')")
    if not path.is_file():
        pytest.skip(f"example-robot-data has no {relative}")
    return path


def yourdfpy_poses(path, base, tip, q_deg, names=None):
    """Tool poses (n, 4, 4) in mm from yourdfpy's scene graph, one configuration at a time."""
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False)
    names = names or urdf.actuated_joint_names[:q_deg.shape[1]]
    out = []
    for q in np.radians(q_deg):
        urdf.update_cfg(dict(zip(names, q)))
        out.append(urdf.get_transform(tip, base))
    out = np.array(out)
    out[:, :3, 3] *= 1000.0
    return out


ARMS = [("ur_description/urdf/ur10_robot.urdf", "base_link", "tool0"),
        ("ur_description/urdf/ur5_robot.urdf", "base_link", "ee_link"),
        ("panda_description/urdf/panda.urdf", "panda_link0", "panda_hand_tcp")]


@pytest.mark.parametrize("relative, base, tip", ARMS)
def test_urdf_chains_equal_yourdfpys_forward_kinematics(relative, base, tip):
    """1,000 random joint sets within the URDF's limits: positions to 1e-9 mm, rotations to 1e-12."""
    path = example_urdf(relative)
    robot = load_robot({"urdf": str(path), "base": base, "tip": tip})
    q = np.random.default_rng(30).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (1000, robot.n_joints))
    expected = yourdfpy_poses(path, base, tip, q)
    poses = robot.forward(q)
    np.testing.assert_allclose(poses[:, :3, 3], expected[:, :3, 3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(poses[:, :3, :3], expected[:, :3, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(robot.positions(q), expected[:, :3, 3], rtol=0, atol=1e-9)


def test_ur10_limits_units_and_what_the_chain_offers():
    """Limits in degrees from the URDF's radians; the robot model file round trip keeps the chain (base pose
    and origins); position IK reaches targets on the URDF chain."""
    path = example_urdf("ur_description/urdf/ur10_robot.urdf")
    robot = load_robot(f"{path}#base=base_link&tip=tool0")
    assert robot.n_joints == 6 and robot.name == "ur10"
    np.testing.assert_allclose(robot.limits_deg[0], [-360.0, 360.0], atol=1e-6)    # +-6.28318530718 rad
    np.testing.assert_allclose(robot.limits_deg[2], [-180.0, 180.0], atol=1e-6)
    q = np.random.default_rng(31).uniform(-170, 170, (30, 6))
    again = robot_from_dict(robot_to_dict(robot))
    np.testing.assert_allclose(again.forward(q), robot.forward(q), rtol=0, atol=1e-9)
    result = robot.inverse(robot.positions(q + 2.0), q)
    assert result.success.all()


MIMIC = """<?xml version="1.0"?>
<robot name="mimic_arm">
  <link name="world"/><link name="a"/><link name="b"/><link name="c"/><link name="d"/><link name="flange"/>
  <joint name="mount" type="fixed"><parent link="world"/><child link="a"/>
    <origin xyz="0.1 -0.2 0.3" rpy="0.1 0.2 0.3"/></joint>
  <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
    <origin xyz="0 0 0.4" rpy="0 0 0"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="continuous"><parent link="b"/><child link="c"/>
    <origin xyz="0.5 0 0" rpy="1.5707963267948966 0 0"/><axis xyz="-1 0 0"/></joint>
  <joint name="j3" type="revolute"><parent link="c"/><child link="d"/>
    <origin xyz="0.3 0.1 0" rpy="0 -0.4 0"/><axis xyz="0 0 -1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/><mimic joint="j1" multiplier="-2" offset="0.1"/></joint>
  <joint name="tool" type="fixed"><parent link="d"/><child link="flange"/>
    <origin xyz="0 0 0.1" rpy="0 0 0.5"/></joint>
</robot>
"""


def test_mimic_joints_tilted_axes_and_fixed_joints_fold_into_coupled_rows(tmp_path):
    """A mimic joint (q3 = -2 q1 + 0.1 rad) is a coupled row; axes off z (also -z, -x) and fixed joints on
    both ends: FK equal to yourdfpy's (which applies the mimic itself) on 200 sets."""
    path = tmp_path / "mimic.urdf"
    path.write_text(MIMIC)
    robot = robot_from_urdf(path, "world", "flange")
    assert robot.n_joints == 2
    np.testing.assert_allclose(robot.coupling[:, 0], [1.0, 0.0, -2.0])
    np.testing.assert_allclose(robot.limits_deg[1], [-360.0, 360.0])            # continuous
    q = np.random.default_rng(32).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (200, 2))
    expected = yourdfpy_poses(path, "world", "flange", q, names=["j1", "j2"])
    np.testing.assert_allclose(robot.forward(q), expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize("edit, message", [
    (('<origin xyz="0.5 0 0"', '<origin xyz="0.5 0"'), r"line 9: <joint name='j2'> <origin xyz=\"0.5 0\">: "
                                                       r"expected 3 finite numbers"),
    (('type="continuous"', 'type="hinge"'), r"line 9: <joint name='j2'>: expected type one of revolute"),
    (('<parent link="b"/>', ''), r"<joint name='j2'>: expected <parent link"),
    (('<axis xyz="-1 0 0"/>', '<axis xyz="0 0 0"/>'), r"expected a non-zero axis"),
    (('type="continuous"', 'type="planar"'), r"<joint name='j2' type='planar'>: expected revolute, "
                                             r"continuous, prismatic or fixed"),
    (('type="continuous"', 'type="prismatic"'), r"<joint name='j2'> <limit>: expected lower < upper \(metres\)"),
    (('lower="-2" upper="2"', 'lower="2" upper="-2"'), r"<joint name='j1'> <limit>: expected lower < upper"),
    (('<robot name="mimic_arm">', '<robt name="mimic_arm">'), r"not well-formed XML"),
])
def test_a_bad_urdf_is_refused_in_one_line_naming_file_element_and_expectation(tmp_path, edit, message):
    path = tmp_path / "bad.urdf"
    path.write_text(MIMIC.replace(*edit))
    with pytest.raises(RobotFileError, match=message) as info:
        robot_from_urdf(path, "world", "flange")
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)


def test_a_chain_that_is_not_there_is_refused(tmp_path):
    path = tmp_path / "arm.urdf"
    path.write_text(MIMIC)
    with pytest.raises(RobotFileError, match="tip link 'b' does not hang below base link 'c'"):
        robot_from_urdf(path, "c", "b")
    with pytest.raises(RobotFileError, match="tip link 'hand': no <link> of that name"):
        robot_from_urdf(path, "world", "hand")
    with pytest.raises(RobotFileError, match="no such URDF file"):
        load_robot({"urdf": str(tmp_path / "missing.urdf")})
    assert robot_reference({"urdf": "arm.urdf", "base": "world", "tip": "flange"}, tmp_path) == \
        f"{tmp_path / 'arm.urdf'}#base=world&tip=flange"
    assert load_robot(robot_reference({"urdf": "arm.urdf"}, tmp_path)).n_joints == 2     # root and only leaf


def six_joint_arm(extra_links: str = "", extra_joints: str = "") -> str:
    """A six-joint serial arm l0 -> l1 -> ... -> l6 (joints j1..j6 on lines 4..15), with more links and joints
    appended."""
    links = "".join(f'<link name="l{k}"/>' for k in range(7))
    joints = "".join(f'  <joint name="j{k}" type="revolute"><parent link="l{k - 1}"/><child link="l{k}"/>\n'
                     f'    <origin xyz="0 0.1 0.2" rpy="0.3 0 0"/><axis xyz="0 0 1"/>'
                     f'<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>\n' for k in range(1, 7))
    return f'<?xml version="1.0"?>\n<robot name="six">\n  {links}{extra_links}\n{joints}{extra_joints}</robot>\n'


TWO_PARENTS = ("", '  <joint name="extra" type="fixed"><parent link="l0"/><child link="l4"/></joint>\n')


@pytest.mark.parametrize("extra, tip, message", [
    (TWO_PARENTS, None, r"line 16: <joint name='extra'> <child link='l4'>: expected one parent joint per link \(a "
                        r"URDF is a tree\); 'l4' is already the child of joint 'j4' at line 10$"),
    (('<link name="l3"/>', ""), None, r"line 3: <link name='l3'>: expected each link name once; already declared "
                                      r"at line 3$"),
    (('<link name="a"/><link name="b"/>',
      '  <joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>\n'
      '  <joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>\n'), None,
     r"line 17: <joint name='ba'>: closes a cycle of links \(a -> b -> a\); expected a tree$"),
    (("", '  <joint name="loop" type="fixed"><parent link="l6"/><child link="l0"/></joint>\n'), "l6",
     r"line 16: <joint name='loop'>: closes a cycle of links \(l0 -> l1 -> l2 -> l3 -> l4 -> l5 -> l6 -> l0\)"),
    (("", '  <joint name="extra" type="fixed"><parent link="l6"/><child link="hand"/></joint>\n'), "l6",
     r"line 16: <joint name='extra'> <child link='hand'>: expected a declared <link>; no link of that name$"),
    (('<link name="t"/>', '  <joint name="j2" type="fixed"><parent link="l6"/><child link="t"/></joint>\n'), "l6",
     r"line 16: <joint name='j2'>: expected each joint name once; already declared at line 6$"),
])
def test_a_urdf_that_is_not_a_tree_is_refused_naming_the_line_and_element(tmp_path, extra, tip, message):
    """Two parents of one link, a link or joint name twice, a cycle (apart from the chain, or through it with
    base and tip named), a joint to an undeclared link: refused in one line before any chain is built."""
    path = tmp_path / "bad.urdf"
    path.write_text(six_joint_arm(*extra))
    with pytest.raises(RobotFileError, match=message) as info:
        robot_from_urdf(path, "l0" if tip else None, tip)
    assert str(info.value).startswith(f"{path}: line ") and "\n" not in str(info.value)


def test_a_link_with_two_parents_is_refused_as_yourdfpy_refuses_it(tmp_path):
    """Without the check the chain kept the second parent (2 joints, extra -> j5 -> j6, instead of 6)."""
    good, bad = tmp_path / "good.urdf", tmp_path / "bad.urdf"
    good.write_text(six_joint_arm())
    bad.write_text(six_joint_arm(*TWO_PARENTS))
    assert robot_from_urdf(good).n_joints == 6
    with pytest.raises(ValueError):
        yourdfpy.URDF.load(str(bad), load_meshes=False)
    with pytest.raises(RobotFileError, match="expected one parent joint per link"):
        robot_from_urdf(bad)


@pytest.mark.parametrize("relative, tip, joints", [
    ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector", [f"j2s6s200_joint_{k}" for k in range(1, 7)]),
    ("so_arm_description/urdf/so101.urdf", "gripper_frame_link",
     ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll"]),
])
def test_fixed_joints_with_a_zero_axis_are_read_as_shipped(relative, tip, joints):
    """example-robot-data's kinova and so101 give their fixed joints ``<axis xyz="0 0 0"/>`` (the URDF spec
    ignores a fixed joint's axis): read, and equal to yourdfpy's forward kinematics on 300 sets."""
    path = example_urdf(relative)
    robot = load_robot({"urdf": str(path), "tip": tip})
    assert robot.n_joints == len(joints)
    q = np.random.default_rng(33).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (300, robot.n_joints))
    root = yourdfpy.URDF.load(str(path), load_meshes=False).base_link
    expected = yourdfpy_poses(path, root, tip, q, names=joints)
    np.testing.assert_allclose(robot.forward(q), expected, rtol=0, atol=1e-9)


IIWA_LIKE = """<?xml version="1.0"?>
<robot name="iiwa_like">
  <link name="world"/><link name="base_link"/><link name="base"/><link name="link_1"/><link name="link_2"/>
  <link name="link_3"/><link name="link_4"/><link name="link_5"/><link name="link_6"/><link name="link_7"/>
  <link name="tool0"/>
  <joint name="world-base_link" type="fixed"><parent link="world"/><child link="base_link"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 0"/></joint>
  <joint name="base_link-base" type="fixed"><parent link="base_link"/><child link="base"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 0"/></joint>
  {joints}
  <joint name="joint_a7-tool0" type="fixed"><parent link="link_7"/><child link="tool0"/>
    <origin xyz="0 0 0.126" rpy="0 0 0"/><axis xyz="0 0 0"/></joint>
</robot>
"""
IIWA_AXES = [("0 0 0.1575", "0 0 1"), ("0 0 0.2025", "0 1 0"), ("0 0.2045 0", "0 0 1"), ("0 0 0.2155", "0 -1 0"),
             ("0 0.1845 0", "0 0 1"), ("0 0 0.2155", "0 1 0"), ("0 0.081 0", "0 0 1")]


def test_an_iiwa_like_chain_with_zero_axis_fixed_joints_on_and_off_the_chain(tmp_path):
    """kuka_experimental's iiwa shape: fixed joints with a zero axis outside the chain (world -> base_link)
    and inside it (base_link -> base, joint_a7 -> tool0); a moving joint's zero axis stays refused."""
    joints = "\n  ".join(
        f'<joint name="joint_a{k}" type="revolute"><parent link="{"base" if k == 1 else f"link_{k - 1}"}"/>'
        f'<child link="link_{k}"/><origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>'
        f'<limit lower="-2.96" upper="2.96" effort="300" velocity="10"/></joint>'
        for k, (xyz, axis) in enumerate(IIWA_AXES, start=1))
    path = tmp_path / "iiwa.urdf"
    path.write_text(IIWA_LIKE.format(joints=joints))
    robot = load_robot(f"{path}#base=base_link&tip=tool0")
    assert robot.n_joints == 7
    q = np.random.default_rng(34).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (300, 7))
    expected = yourdfpy_poses(path, "base_link", "tool0", q, names=[f"joint_a{k}" for k in range(1, 8)])
    np.testing.assert_allclose(robot.forward(q), expected, rtol=0, atol=1e-9)
    # at zero the origins add up: y 204.5 + 184.5 + 81, z 157.5 + 202.5 + 215.5 + 215.5 + 126 (mm)
    np.testing.assert_allclose(robot.positions(np.zeros((1, 7)))[0], [0.0, 470.0, 917.0], rtol=0, atol=1e-9)
    path.write_text(IIWA_LIKE.format(joints=joints.replace('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', 1)))
    with pytest.raises(RobotFileError, match=r"<joint name='joint_a2'> <axis xyz=\"0 0 0\">: expected a non-zero "
                                             r"axis"):
        robot_from_urdf(path, "base_link", "tool0")


def test_runs_and_simulations_take_a_urdf_beside_their_yaml(tmp_path):
    """``robot: {urdf: ur10.urdf, base: base_link, tip: tool0}`` (path relative to the YAML) in a virtual
    robot config and a run config; the complete model identifies the simulated URDF robot to the noise."""
    import shutil

    from partcal import KinematicModel
    from partcal.data.simulate import load_study, simulate
    from partcal.study.config import load_config

    shutil.copy(example_urdf("ur_description/urdf/ur10_robot.urdf"), tmp_path / "ur10.urdf")
    robot_line = "robot: {urdf: ur10.urdf, base: base_link, tip: tool0}"
    virtual = (Path(__file__).resolve().parent.parent / "configs" / "ur10_tilts_virtual.yaml").read_text()
    virtual = virtual.replace("robot: universal_robots_ur10", robot_line).replace("../data/ur10_tilts", "out")
    (tmp_path / "virtual.yaml").write_text(virtual)
    study = load_study(tmp_path / "virtual.yaml")
    assert study.robot.nominal.name == "ur10"
    data = simulate(study)
    ident, test = data["identification"], data["test"]
    model = KinematicModel(robot=study.robot.nominal, parametrization="complete").fit(ident.q_deg, ident.errors_mm)
    left = test.measured_mm - test.nominal_mm - model.predict(test.q_deg)
    assert np.sqrt(np.mean(np.sum(left**2, axis=1))) < 0.06      # the tracker's 0.02 mm per axis at ~2 m
    (tmp_path / "run.yaml").write_text(f"name: urdf_run\n{robot_line}\ndata:\n  identification: "
                                       "out/identification.csv\nmodels:\n  - {name: complete, kind: kinematic, "
                                       "parametrization: complete}\n")
    (tmp_path / "out").mkdir()
    from partcal import write_measurements
    write_measurements(ident, tmp_path / "out" / "identification.csv")
    config = load_config(tmp_path / "run.yaml")
    assert config.robot == f"{tmp_path / 'ur10.urdf'}#base=base_link&tip=tool0"
    assert load_robot(config.robot).n_joints == 6
    (tmp_path / "bad.yaml").write_text("name: bad\nrobot: {urdf: ur10.urdf, tip: hand}\ndata:\n  identification: "
                                       "out/identification.csv\nmodels:\n  - {name: dh, kind: kinematic}\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: robot \(line 2\).*tip link 'hand': no <link>"):
        load_config(tmp_path / "bad.yaml")


def test_the_default_parametrization_is_dh_for_dh_rows_and_complete_for_a_urdf_chain(tmp_path):
    from partcal import KinematicModel

    path = example_urdf("ur_description/urdf/ur10_robot.urdf")
    urdf = load_robot({"urdf": str(path), "base": "base_link", "tip": "tool0"})
    q = np.random.default_rng(33).uniform(-180, 180, (40, 6))
    errors = np.random.default_rng(34).normal(0, 0.1, (40, 3))
    assert KinematicModel(robot=urdf).fit(q, errors).parametrization_ == "complete"
    assert KinematicModel(robot=urdf, compliance=[2]).fit(q, errors).parametrization_ == "complete"
    assert KinematicModel(robot=load_robot("universal_robots_ur10")).fit(q, errors).parametrization_ == "dh"


TRACK = """<?xml version="1.0"?>
<robot name="track_arm">
  <link name="floor"/><link name="carriage"/><link name="lift"/><link name="arm"/><link name="hand"/>
  <link name="finger"/>
  <joint name="track" type="prismatic"><parent link="floor"/><child link="carriage"/>
    <origin xyz="0.2 0.1 0" rpy="0 0 0.3"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-0.5" upper="1.5" effort="1" velocity="1"/></joint>
  <joint name="turn" type="revolute"><parent link="carriage"/><child link="lift"/>
    <origin xyz="0 0 0.3" rpy="0.2 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="reach" type="prismatic"><parent link="lift"/><child link="arm"/>
    <origin xyz="0.4 0 0" rpy="0 0.1 0"/><axis xyz="-1 0 0"/>
    <limit lower="0" upper="0.6" effort="1" velocity="1"/></joint>
  <joint name="wrist" type="continuous"><parent link="arm"/><child link="hand"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="follow" type="prismatic"><parent link="hand"/><child link="finger"/>
    <origin xyz="0 0.05 0.1" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/><mimic joint="track" multiplier="0.5" offset="0.01"/></joint>
</robot>
"""


def test_prismatic_joints_slide_in_mm_and_equal_yourdfpy(tmp_path):
    """Two prismatic joints (one on a tilted axis) and a prismatic mimic between revolute ones: limits in mm,
    FK equal to yourdfpy's (metres there) on 300 sets, the Jacobian's slide columns in mm per mm, IK, the robot
    YAML round trip (d as an expression) and the exported URDF reloaded by yourdfpy."""
    from partcal.robot.export import urdf_from_robot

    path = tmp_path / "track.urdf"
    path.write_text(TRACK)
    robot = robot_from_urdf(path, "floor", "finger")
    assert robot.n_joints == 4 and robot.prismatic.tolist() == [True, False, True, False, True]
    np.testing.assert_allclose(robot.limits_deg[[0, 2]], [[-500.0, 1500.0], [0.0, 600.0]])
    q = np.random.default_rng(35).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (300, 4))
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False)
    expected = []
    for row in q:
        urdf.update_cfg({"track": row[0] / 1000, "turn": np.radians(row[1]), "reach": row[2] / 1000,
                         "wrist": np.radians(row[3])})
        expected.append(urdf.get_transform("finger", "floor"))
    expected = np.array(expected)
    expected[:, :3, 3] *= 1000.0
    np.testing.assert_allclose(robot.forward(q), expected, rtol=0, atol=1e-9)
    assert_jacobian_is_the_central_difference(robot, q[:5], 1e-6)
    start = np.clip(q[:20] + [20.0, 3.0, 10.0, 3.0], robot.limits_deg[:, 0], robot.limits_deg[:, 1])
    result = robot.inverse(robot.positions(q[:20]), start)
    assert result.error_mm.max() < 1e-8
    again = robot_from_dict(robot_to_dict(robot))
    np.testing.assert_allclose(again.forward(q), robot.forward(q), rtol=0, atol=1e-9)
    exported = tmp_path / "out.urdf"
    exported.write_text(urdf_from_robot(robot))
    back = yourdfpy.URDF.load(str(exported), load_meshes=False)
    assert [back.joint_map[n].type for n in back.actuated_joint_names] == ["prismatic", "revolute", "prismatic",
                                                                           "revolute"]
    got = []
    for row in q[:100]:
        back.update_cfg({"joint1": row[0] / 1000, "joint2": np.radians(row[1]), "joint3": row[2] / 1000,
                         "joint4": np.radians(row[3])})
        got.append(back.get_transform("tcp", "base_link")[:3, 3] * 1000.0)
    np.testing.assert_allclose(np.array(got), robot.positions(q[:100]), rtol=0, atol=1e-9)


def test_plan_takes_a_urdf_and_plans_for_the_complete_parametrization(tmp_path):
    """``partcal plan FILE.urdf#base=..&tip=..``: a pose list for the complete model (25 identifiable
    parameters of the UR10, the two tilts between parallel axes beyond DH's 23)."""
    from conftest import partcal_cli

    path = example_urdf("ur_description/urdf/ur10_robot.urdf")
    out = tmp_path / "poses.csv"
    done = partcal_cli("plan", f"{path}#base=base_link&tip=tool0", "-n", "30", "-o", str(out), "-q")
    assert done.returncode == 0, done.stderr
    header = out.read_text().splitlines()[:3]
    assert "(complete with base and tool)" in header[0] and "(25 parameters, 30 poses)" in header[2]


def test_import_computes_nominal_positions_from_a_urdf(tmp_path):
    """``partcal import DATA.csv --robot FILE.urdf#base=..&tip=..``: the nominal columns come from the URDF's
    forward kinematics (mm)."""
    from conftest import partcal_cli

    from partcal import read_measurements

    path = example_urdf("ur_description/urdf/ur10_robot.urdf")
    robot = load_robot(f"{path}#base=base_link&tip=tool0")
    q = np.random.default_rng(36).uniform(-170, 170, (5, 6))
    p = robot.positions(q) + 0.1
    rows = ["q1,q2,q3,q4,q5,q6,x_meas,y_meas,z_meas"] + [",".join(repr(float(v)) for v in (*a, *b))
                                                         for a, b in zip(q, p)]
    (tmp_path / "in.csv").write_text("\n".join(rows) + "\n")
    done = partcal_cli("import", str(tmp_path / "in.csv"), "-o", str(tmp_path / "out.csv"), "--robot",
                       f"{path}#base=base_link&tip=tool0")
    assert done.returncode == 0, done.stderr
    np.testing.assert_allclose(read_measurements(tmp_path / "out.csv").nominal_mm, robot.positions(q), atol=1e-6)


@pytest.mark.parametrize("name", ["ur10.xml", "folder"])
def test_a_urdf_mapping_naming_a_file_without_the_urdf_suffix_says_what_was_expected(tmp_path, name):
    (tmp_path / "folder").mkdir()
    (tmp_path / "ur10.xml").write_text("<robot name='r'/>\n")
    with pytest.raises(ConfigError, match=rf"robot: urdf: expected a file ending in \.urdf, got '\S*/{name}'"):
        load_robot({"urdf": str(tmp_path / name), "base": "base_link", "tip": "tool0"})
