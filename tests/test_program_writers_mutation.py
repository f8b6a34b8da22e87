"""The per-dialect program writers (RAPID, KRL, URScript) against numbers worked by hand: their units, rotations,
configurations, IK seeds and joint ranges, and what their parsers read from a target's text. Written for the
survivors of a mutation run (issue 49, CONTRIBUTING.md "Mutation testing"): each test compares with values
computed here independently of the module, never with the module's own output."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from partcal.data.program_krl import DIALECT as KRL
from partcal.data.program_rapid import DIALECT as RAPID
from partcal.data.program_urscript import DIALECT as UR
from partcal.data.programs import ProgramSyntaxError, read_program

R = np.sqrt(0.5)
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])      # 90 degrees about z
INF = np.inf


def program(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text.encode("latin-1"))
    return read_program(path)


# ---------------------------------------------------------------------- RAPID
def test_rapid_confdata_is_the_quarter_revolution_of_axes_1_4_and_6_rounded_down():
    q = [[-10.0, 20.0, 30.0, 95.0, 0.0, -180.0],       # floor(-10/90) = -1, floor(95/90) = 1, floor(-180/90) = -2
         [0.0, -50.0, 80.0, -0.5, 10.0, 269.9],        # 0, floor(-0.5/90) = -1, floor(269.9/90) = 2
         [89.9, 0.0, 0.0, 90.0, 0.0, 360.0]]           # 0, 1, 4
    assert RAPID.configuration(q).tolist() == [[-1, 1, -2, -1], [0, -1, 2, -1], [0, 1, 4, -1]]
    assert RAPID.compare == (0, 1, 2)                  # cfx is not computed, never compared


def test_rapid_seeds_put_axes_1_4_and_6_mid_quarter_and_keep_the_other_reference_joints():
    reference = np.array([[1.0, 2.0, 3.0, 4.0, 5.0, 6.0], [-7.0, 8.0, -9.0, 10.0, -11.0, 12.0]])
    seeds = RAPID.seeds([[-1, 1, -2, 0], [0, 2, 3, 1]], reference)
    np.testing.assert_array_equal(seeds, [[-45.0, 2.0, 3.0, 135.0, 5.0, -135.0],      # -90 + 45, 90 + 45, -180 + 45
                                          [45.0, 8.0, -9.0, 225.0, -11.0, 315.0]])
    np.testing.assert_array_equal(reference[0], [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])       # the reference is not changed


def test_rapid_ranges_are_the_written_quarter_revolutions_of_axes_1_4_and_6_and_free_elsewhere():
    low, high = RAPID.ranges([[-1, 1, -2, 0], [0, 0, 3, -1]])
    np.testing.assert_array_equal(low, [[-90.0, -INF, -INF, 90.0, -INF, -180.0], [0.0, -INF, -INF, 0.0, -INF, 270.0]])
    np.testing.assert_array_equal(high, [[0.0, INF, INF, 180.0, INF, -90.0], [90.0, INF, INF, 90.0, INF, 360.0]])


def test_rapid_pose_fields_are_millimetres_and_a_scalar_first_quaternion_on_the_written_side():
    positions, rotations = RAPID.poses(np.array([[100.0, -200.0, 300.5, R, 0.0, 0.0, R]]))
    np.testing.assert_array_equal(positions, [[100.0, -200.0, 300.5]])
    np.testing.assert_allclose(rotations[0], RZ90, atol=1e-15)
    for sign in (1.0, -1.0):
        old = np.array([[0.0, 0.0, 0.0, sign * 0.70, 0.0, 0.0, sign * 0.71]])
        np.testing.assert_allclose(RAPID.pose_values([[1.0, 2.0, 3.0]], RZ90[None], old),
                                   [[1.0, 2.0, 3.0, sign * R, 0.0, 0.0, sign * R]], atol=1e-15)


def test_rapid_frame_option_is_a_pose_of_millimetres_and_a_quaternion():
    np.testing.assert_allclose(RAPID.frame(" [[1, 2, 3], [0.7071068, 0, 0, 0.7071068]] ", "--tool"),
                               [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], atol=1e-7)
    with pytest.raises(ProgramSyntaxError, match="expected a RAPID pose"):
        RAPID.frame("tool1", "--tool")


ROBTARGET = """MODULE M
  CONST robtarget p1:=[[1,-2,3.5],[{q}],[-1,0,2,1],[1500,9E9,9E9,9E9,8.8E9,-20]];
  CONST jointtarget j1:=[[10,-20,30.5,0,45,-90],[9E9,9E9,9E9,9E9,9E9,9E9]];
ENDMODULE
"""


def test_a_robtarget_reads_its_position_rotation_confdata_and_used_external_axes(tmp_path):
    p1, j1 = program(tmp_path, "m.mod", ROBTARGET.format(q=f"0,{R},0,{R}")).targets
    assert (p1.name, p1.kind, p1.line, p1.column) == ("p1", "pose", 2, 25)
    np.testing.assert_array_equal(p1.position_mm, [1.0, -2.0, 3.5])
    np.testing.assert_allclose(p1.rotation, [[0, 0, 1], [0, -1, 0], [1, 0, 0]], atol=1e-12)  # half a turn about x+z
    assert p1.configuration == (-1, 0, 2, 1)
    assert p1.external == (("eax_a", 1500.0), ("eax_e", 8.8e9), ("eax_f", -20.0))   # 9E9: not used
    assert [f.text for f in p1.fields] == ["1", "-2", "3.5", "0", str(R), "0", str(R)]
    assert (j1.name, j1.kind) == ("j1", "joints")
    np.testing.assert_array_equal(j1.joints_deg, [10.0, -20.0, 30.5, 0.0, 45.0, -90.0])
    assert [f.text for f in j1.fields] == ["10", "-20", "30.5", "0", "45", "-90"]


@pytest.mark.parametrize("q, kept", [("1.0009,0,0,0", True), ("0.9991,0,0,0", True), ("1.0011,0,0,0", False),
                                     ("0.9989,0,0,0", False), ("0,0,0,0", False)])
def test_a_robtarget_quaternion_is_taken_within_a_thousandth_of_unit_norm_and_refused_beyond(tmp_path, q, kept):
    text = ROBTARGET.format(q=q)
    if kept:
        assert program(tmp_path, "m.mod", text).targets[0].configuration == (-1, 0, 2, 1)
    else:
        with pytest.raises(ProgramSyntaxError, match=r"m.mod: line 2, column 36: p1: quaternion of norm"):
            program(tmp_path, "m.mod", text)


@pytest.mark.parametrize("old, new, expected", [
    ("[-1,0,2,1]", "[-1,0,2]", r"line 2, column 46: p1: confdata \[cf1, cf4, cf6, cfx\]: expected 4 numbers \(got 3\)"),
    ("[[10,-20,30.5,0,45,-90],[9E9", "[[10,-20,30.5,0,45],[9E9",
     r"line 3, column 27: j1: robax \[j1, .., j6\] \(degrees\): expected 6 numbers \(got 5\)"),
    ("],[-1,0,2,1],[1500", "],[-1,0,2,1],[1500],[1500", r"line 2, column 23: robtarget p1 .*four bracketed lists"),
    ("[[10,-20,30.5,0,45,-90],[9E9,9E9,9E9,9E9,9E9,9E9]]", "[[10,-20,30.5,0,45,-90]]",
     r"line 3, column 25: jointtarget j1 .*two bracketed lists"),
    ("[9E9,9E9,9E9,9E9,9E9,9E9]]", "[9E9,9E9,9E9,9E9,9E9,9E9],[0]]", r"line 3, column 25: jointtarget j1 .*two bracketed lists"),
    ("[9E9,9E9,9E9,9E9,9E9,9E9]]", "9E9]", r"line 3, column 25: jointtarget j1 .*two bracketed lists"),
])
def test_a_robtarget_or_jointtarget_of_the_wrong_shape_is_refused_where_it_is(tmp_path, old, new, expected):
    with pytest.raises(ProgramSyntaxError, match=expected):
        program(tmp_path, "m.mod", ROBTARGET.format(q="1,0,0,0").replace(old, new, 1))


# ---------------------------------------------------------------------- KRL
def test_krl_turn_sets_bit_k_for_each_negative_axis_k_plus_1_and_status_is_not_computed():
    q = [[-1.0, 2.0, -3.0, 0.0, -0.1, 5.0],            # axes 1, 3, 5 negative: 1 + 4 + 16
         [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],               # 0 is not negative
         [-1.0, -1.0, -1.0, -1.0, -1.0, -1.0]]         # 63
    assert KRL.configuration(q).tolist() == [[-1, 21], [-1, 0], [-1, 63]]
    assert KRL.configuration([[10.0, -20.0, 30.0, 40.0, 50.0, -60.0, -99.0]]).tolist() == [[-1, 34]]  # E1 not counted
    assert KRL.compare == (1,)                          # S is not computed, never compared


def test_krl_seeds_have_the_signs_the_turn_names_and_keep_rows_without_one():
    reference = np.array([[10.0, -20.0, 0.5, -30.0, 0.0, -1.0, -300.0],
                          [-10.0, 20.0, -0.5, 0.0, 5.0, -6.0, 7.0],
                          [-5.0, 6.0, -7.0, 8.0, 0.2, -9.0, 10.0]])
    seeds = KRL.seeds([[2, 5], [6, 0], [2, -1]], reference)       # T 5: axes 1 and 3 negative; T 0: none; -1: unwritten
    np.testing.assert_array_equal(seeds, [[-10.0, 20.0, -45.0, 30.0, 45.0, 1.0, -300.0],   # |q| < 1 becomes 45
                                          [10.0, 20.0, 45.0, 45.0, 5.0, 6.0, 7.0],
                                          [-5.0, 6.0, -7.0, 8.0, 0.2, -9.0, 10.0]])
    assert reference[0, 0] == 10.0                                   # the reference is not changed


def test_krl_ranges_put_each_axis_on_the_side_of_0_its_turn_bit_names_and_free_an_unwritten_turn():
    low, high = KRL.ranges([[2, 5], [2, 0], [2, -1], [2, 63]])
    np.testing.assert_array_equal(low, [[-INF, 0, -INF, 0, 0, 0], [0, 0, 0, 0, 0, 0], [-INF] * 6, [-INF] * 6])
    np.testing.assert_array_equal(high, [[0, INF, 0, INF, INF, INF], [INF] * 6, [INF] * 6, [0] * 6])


def test_krl_pose_fields_are_millimetres_and_a_b_c_degrees_kept_near_the_written_angles():
    positions, rotations = KRL.poses(np.array([[1000.0, -5.0, 1500.0, 90.0, 0.0, 90.0]]))
    np.testing.assert_array_equal(positions, [[1000.0, -5.0, 1500.0]])
    np.testing.assert_allclose(rotations[0], [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-15)    # Rz(90) Rx(90)
    half = Rotation.from_euler("ZYX", [180.0, 10.0, -20.0], degrees=True).as_matrix()[None]  # Rz(A) Ry(B) Rx(C)
    for a in (180.0, -180.0):
        np.testing.assert_allclose(KRL.pose_values([[1.0, 2.0, 3.0]], half, np.array([[0, 0, 0, a - np.sign(a), 0, 0]])),
                                   [[1.0, 2.0, 3.0, a, 10.0, -20.0]], atol=1e-9)


def test_krl_frame_option_is_a_frame_aggregate_of_millimetres_and_degrees():
    np.testing.assert_allclose(KRL.frame(" {X 1, Y 2, Z 3, A 90, B 0, C 0} ", "--frame"),
                               [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]], atol=1e-15)
    with pytest.raises(ProgramSyntaxError, match=r"--frame: the frame .* lacks B, C"):
        KRL.frame("{X 1, Y 2, Z 3, A 90}", "--frame")
    with pytest.raises(ProgramSyntaxError, match="expected a KRL frame"):
        KRL.frame("X 1, Y 2, Z 3, A 90, B 0, C 0", "--frame")


KRL_DAT = """DEFDAT ONE
DECL E6POS XP1={{X 1,Y -2,Z 3.5,A 90,B 0,C 90,S {s},T {t},E1 1500}}
DECL E6AXIS XJ1={{A1 10,A2 -20,A3 30.5,A4 0,A5 45,A6 -90,E1 0}}
ENDDAT
"""


@pytest.mark.parametrize("s, t, configuration", [("'B110'", "'H1F'", (6, 31)), ("6", "+5", (6, 5)),
                                                  ("'b010'", "'B101011'", (2, 43)), ("'H0A'", "0", (10, 0))])
def test_krl_status_and_turn_are_read_as_integers_in_decimal_binary_or_hex(tmp_path, s, t, configuration):
    xp1, xj1 = program(tmp_path, "one.dat", KRL_DAT.format(s=s, t=t)).targets
    assert (xp1.name, xp1.kind, xp1.line, xp1.column, xp1.configuration) == ("XP1", "pose", 2, 19, configuration)
    np.testing.assert_array_equal(xp1.position_mm, [1.0, -2.0, 3.5])
    np.testing.assert_allclose(xp1.rotation, [[0, 0, 1], [1, 0, 0], [0, 1, 0]], atol=1e-15)
    assert xp1.external == (("E1", 1500.0),)
    assert (xj1.name, xj1.kind) == ("XJ1", "joints")
    np.testing.assert_array_equal(xj1.joints_deg, [10.0, -20.0, 30.5, 0.0, 45.0, -90.0])


@pytest.mark.parametrize("s, t, expected", [("1.5", "0", r"line 2, column 48: XP1, S: expected an integer"),
                                            ("6", "'B012'", r"line 2, column 52: XP1, T: expected an integer"),
                                            ("6", "'H1G'", r"line 2, column 52: XP1, T: expected an integer")])
def test_krl_a_status_or_turn_that_is_no_integer_is_refused_where_it_is(tmp_path, s, t, expected):
    with pytest.raises(ProgramSyntaxError, match=expected):
        program(tmp_path, "one.dat", KRL_DAT.format(s=s, t=t))


# ---------------------------------------------------------------------- URScript
def test_urscript_pose_fields_are_metres_and_a_rotation_vector_kept_near_the_written_one():
    positions, rotations = UR.poses(np.array([[0.1, -0.2, 0.3, 0.0, 0.0, np.pi / 2]]))
    np.testing.assert_allclose(positions, [[100.0, -200.0, 300.0]], atol=1e-12)
    np.testing.assert_allclose(rotations[0], RZ90, atol=1e-15)
    for old_rz in (np.pi / 2 - 0.1, -1.5 * np.pi + 0.1):           # 90 degrees about z, or its twin -270 degrees
        near = np.array([[0.0, 0.0, 0.0, 0.0, 0.0, old_rz]])
        expected = np.pi / 2 if old_rz > 0 else -1.5 * np.pi
        np.testing.assert_allclose(UR.pose_values([[100.0, -200.0, 300.0]], RZ90[None], near),
                                   [[0.1, -0.2, 0.3, 0.0, 0.0, expected]], atol=1e-12)


def test_urscript_frame_option_is_a_pose_of_metres_and_a_rotation_vector_in_millimetres():
    np.testing.assert_allclose(UR.frame(" p[0.1, 0.2, 0.3, 0, 0, 1.5707963267948966] ", "--frame"),
                               [[0, -1, 0, 100], [1, 0, 0, 200], [0, 0, 1, 300], [0, 0, 0, 1]], atol=1e-12)
    with pytest.raises(ProgramSyntaxError, match="expected a URScript pose"):
        UR.frame("[0.1, 0.2, 0.3, 0, 0, 0]", "--frame")


UR_SCRIPT = """def prog():
  set_tcp(p[0, 0.01, 0.1, 0, 0, 1.5707963267948966])
  movej([0, -1.5707963267948966, 1.5707963267948966, 0, 0.5, -3.141592653589793], a=1.2, v=0.25)
  movel(p[0.5, -0.25, 0.125, 0, 0, 1.5707963267948966], a=1.2, v=0.25)
end
"""


def test_urscript_joints_are_radians_and_a_set_tcp_pose_is_a_tool_in_millimetres(tmp_path):
    p = program(tmp_path, "one.script", UR_SCRIPT)
    joints, pose = p.targets
    assert (joints.name, joints.kind, joints.line, joints.column) == ("movej", "joints", 3, 10)
    np.testing.assert_allclose(joints.joints_deg, [0.0, -90.0, 90.0, 0.0, np.degrees(0.5), -180.0], atol=1e-12)
    assert (pose.name, pose.kind, pose.line, pose.column, pose.tool) == ("movel", "pose", 4, 11, "set_tcp at line 2")
    np.testing.assert_allclose(pose.position_mm, [500.0, -250.0, 125.0], atol=1e-12)
    np.testing.assert_allclose(pose.rotation, RZ90, atol=1e-15)
    np.testing.assert_allclose(p.frames["set_tcp at line 2"],
                               [[0, -1, 0, 0], [1, 0, 0, 10], [0, 0, 1, 100], [0, 0, 0, 1]], atol=1e-12)


def test_urscript_a_joint_list_of_constant_arithmetic_is_read_as_its_value(tmp_path):
    p = program(tmp_path, "one.script", "def prog():\n  movej([d2r(10), -pi/2, 0.5 * pi, 0, -d2r(45), pi], a=1.2)\nend\n")
    np.testing.assert_allclose(p.targets[0].joints_deg, [10.0, -90.0, 90.0, 0.0, -45.0, 180.0], atol=1e-12)


def test_urscript_a_program_cut_off_inside_a_joint_list_is_refused_where_the_list_opens(tmp_path):
    with pytest.raises(ProgramSyntaxError, match=r"one.script: line 2, column 9: joint list: expected a closing '\]'"):
        program(tmp_path, "one.script", "def prog():\n  movej([0, -1.57, 1.57, 0, 0, 0")
