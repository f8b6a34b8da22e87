"""Kinematics of DH chains and the Motoman SK120 (paper, Table 1)."""

from pathlib import Path

import numpy as np
import pytest
from conftest import assert_jacobian_is_the_central_difference, moved_positions
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import partcal
from partcal import ConfigError, UnreachableError, load_robot
from partcal.robot.description import parse_theta, robot_from_dict
from partcal.robot.rotations import matrix_from_rpy_deg
from partcal.robot.trajectories import paper_path

ROBOTS = Path(partcal.__file__).parent / "robot" / "builtin"

# Hand derivations (written out step by step, not computed by partcal):
# q = (0, -90, -180, 0, 0, 0). Row 1 (a = 215, alpha = -90): shoulder at (215, 0, 0),
# x1 = (1,0,0), y1 = (0,0,-1), z1 = (0,1,0). Parallelogram: the elbow sits at
# shoulder + 1100 (cos q2 x1 + sin q2 y1) = (215, 0, 1100); the three bars turn by
# q3 + 180 = 0 in total, so frame 4 is parallel to frame 1. Row 5 (theta -90,
# a 250, alpha -90): x = -y1 = (0,0,1), origin (215, 0, 1350), z = (1,0,0). Row 6
# (d 1300): wrist at (1515, 0, 1350); rows 6-7 (alpha -90, +90) keep z = (1,0,0),
# x = (0,0,1). Row 8 (d 230): flange at (1745, 0, 1350), x6 = (0,0,1), y6 = (0,-1,0).
# Tool (205.32, 0, 112.65) in frame 6: (1745 + 112.65, 0, 1350 + 205.32).
# q6 = 90 turns x6 into y5 = (0,-1,0): tool = 205.32 (0,-1,0) + 112.65 (1,0,0).
# q1 = 90 rotates the whole arm about z0: (x, y) -> (-y, x).
# q = (0, -90, -90, 0, 0, 0): bars turn by 90, x4 = y1 = (0,0,-1); row 5 moves 250
# along (1,0,0) to (465, 0, 1100) and the forearm axis z points down (0,0,-1):
# wrist (465, 0, -200), flange (465, 0, -430), tool x6 = (1,0,0), z6 = (0,0,-1).
HAND_FK = [
    ((0, -90, -180, 0, 0, 0), (1857.65, 0.0, 1555.32)),
    ((0, -90, -180, 0, 0, 90), (1857.65, -205.32, 1350.0)),
    ((90, -90, -180, 0, 0, 0), (0.0, 1857.65, 1555.32)),
    ((0, -90, -90, 0, 0, 0), (670.32, 0.0, -542.65)),
]


@pytest.mark.parametrize("q, expected", HAND_FK)
def test_fk_matches_hand_derivation(sk120, q, expected):
    np.testing.assert_allclose(sk120.positions([q])[0], expected, atol=1e-9)


# UR10 (standard DH, alpha = 90, 0, 0, 90, -90, 0), by hand. q = 0: row 1 lifts to (0, 0, d1) and
# turns z1 = -y0, y1 = z0; rows 2-3 run a2 + a3 along x0; row 4 runs d4 along z3 = -y0 and turns
# z4 = -z0; row 5 runs d5 down; row 6 runs d6 along z5 = -y0: (a2 + a3, -d4 - d6, d1 - d5).
# q1 = 90 turns all of it about z0: (x, y) -> (-y, x).
D1, A2, A3, D4, D5, D6 = 118.0, -612.7, -571.6, 163.9, 115.7, 92.2
UR10_FK = [
    ((0, 0, 0, 0, 0, 0), (A2 + A3, -D4 - D6, D1 - D5)),
    ((90, 0, 0, 0, 0, 0), (D4 + D6, A2 + A3, D1 - D5)),
]


@pytest.mark.parametrize("q, expected", UR10_FK)
def test_ur10_fk_matches_hand_derivation(q, expected):
    robot = load_robot("universal_robots_ur10")
    assert robot.n_joints == 6 and robot.tool_mm.tolist() == [0.0, 0.0, 0.0]
    np.testing.assert_allclose(robot.positions([q])[0], expected, atol=1e-9)


def test_fk_batch_equals_single_and_forward_pose(sk120):
    rng = np.random.default_rng(1)
    q = rng.uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], size=(5000, 6))
    batch = sk120.positions(q)
    single = np.array([sk120.positions(row)[0] for row in q[:20]])
    np.testing.assert_allclose(batch[:20], single, atol=1e-9)
    poses = sk120.forward(q[:50])
    np.testing.assert_allclose(poses[:, :3, 3], batch[:50], atol=1e-9)
    rot = poses[:, :3, :3]
    np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)


def test_parallelogram_constraint(sk120):
    q = np.array([[10, -120, -170, 5, -7, 30], [-40, -100, -200, 0, 0, 0]], dtype=float)
    theta = sk120.theta_offset_deg + q @ sk120.coupling.T
    np.testing.assert_allclose(theta[:, 1], q[:, 2])                 # theta_bar1 = theta3
    np.testing.assert_allclose(theta[:, 2], q[:, 1] - q[:, 2])       # theta_bar2 = theta2 - theta3
    np.testing.assert_allclose(theta[:, 2] + theta[:, 3], 180.0)     # theta_bar2 + theta_bar3 = pi
    origins, _ = sk120.frames(q)
    shoulder, bar1_end, corner, elbow = (origins[:, k] for k in (1, 2, 3, 4))
    np.testing.assert_allclose(corner - bar1_end, elbow - shoulder, atol=1e-9)   # opposite sides parallel
    np.testing.assert_allclose(corner - elbow, bar1_end - shoulder, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(elbow - shoulder, axis=1), 1100.0)


def test_jacobian_matches_finite_differences(sk120):
    rng = np.random.default_rng(7)
    q = rng.uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], size=(10, 6))
    jac = sk120.jacobian(q)
    h = 1e-5
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        numeric = (sk120.positions(q + dq) - sk120.positions(q - dq)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, j], numeric, atol=1e-5, rtol=1e-7)


@pytest.mark.parametrize("name", ["rectangle", "spiral_xy", "spiral_yz"])
def test_ik_round_trip_along_test_paths(sk120, name):
    targets = paper_path(name)
    q = sk120.inverse_path(targets, fixed=(4, 5))
    assert np.abs(sk120.positions(q) - targets).max() < 1e-6
    assert np.all(q[:, 3] == sk120.home_deg[3]) and np.all(q[:, 4] == sk120.home_deg[4])
    assert np.abs(np.diff(q, axis=0)).max() < 5.0      # warm starts keep one smooth branch
    assert sk120.within_limits(q).all()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0.05, 0.95), min_size=6, max_size=6), st.floats(-3.0, 3.0))
def test_ik_recovers_reachable_positions(fractions, offset):
    robot = load_robot("motoman_sk120")
    lo, hi = robot.limits_deg[:, 0], robot.limits_deg[:, 1]
    q_true = lo + np.array(fractions) * (hi - lo)
    q_true[1] = np.clip(q_true[1], q_true[2] + 20, q_true[2] + 110)     # keep the parallelogram open
    target = robot.positions(q_true)
    seed = q_true + offset
    res = robot.inverse(target, seed)
    assert res.success[0], (q_true, seed, res.error_mm)       # a seed within 3 degrees always converges
    np.testing.assert_allclose(robot.positions(res.q_deg), target, atol=1e-6)
    assert res.error_mm[0] <= 1e-8


def test_unreachable_target_is_reported_by_index_and_distance(sk120):
    targets = np.array([[1100.0, 0.0, 800.0], [9000.0, 0.0, 0.0], [1100.0, 50.0, 800.0]])
    with pytest.raises(UnreachableError, match=r"1 of 3 targets unreachable.*#1 \(") as info:
        sk120.inverse_path(targets, fixed=(4, 5))
    assert info.value.indices == [1]
    assert info.value.distances_mm[0] > 5000   # 9 m away, the arm reaches about 3 m


def test_parse_theta():
    assert parse_theta(" q1 ", 6)[0] == 0.0
    off, c = parse_theta("-90 + 2*q3 - q1", 6)
    assert off == -90.0 and c.tolist() == [-1, 0, 2, 0, 0, 0]
    with pytest.raises(ConfigError, match="names q7"):
        parse_theta("q7", 6)
    with pytest.raises(ConfigError, match="expected '\\+' or '-'"):
        parse_theta("q1 q2", 6)


def test_robot_yaml_errors_name_the_field():
    spec = {"name": "r", "joints": 1, "links": [{"theta": "q1", "d": 0, "a": 1, "alpha": 0}],
            "limits_deg": [[-90, 90]]}
    assert robot_from_dict(spec).n_joints == 1
    with pytest.raises(ConfigError, match=r"limits_deg: expected 1 pairs"):
        robot_from_dict({**spec, "limits_deg": [[90, -90]]})
    with pytest.raises(ConfigError, match=r"links\[0\].theta: .*names q2"):
        robot_from_dict({**spec, "links": [{"theta": "q2", "d": 0, "a": 1, "alpha": 0}]})
    with pytest.raises(ConfigError, match="unknown key"):
        robot_from_dict({**spec, "colour": "red"})
    with pytest.raises(ConfigError, match=r"base: expected \{xyz_mm: \[x, y, z\], rpy_deg"):   # refused, never ignored
        robot_from_dict({**spec, "base": {"xyz": [0, 0, 100]}})
    lifted = robot_from_dict({**spec, "base": {"xyz_mm": [0, 0, 100], "rpy_deg": [0, 0, 90]}})
    np.testing.assert_allclose(lifted.positions([[0.0]]), [[0.0, 1.0, 100.0]], atol=1e-12)  # a = 1 along y
    with pytest.raises(ConfigError, match="not a built-in robot"):
        load_robot("no_such_robot")


def test_robot_yaml_is_read_like_a_run_config(tmp_path):
    """Line numbers, duplicate keys refused, and numbers that must be numbers (today: a bare ValueError)."""
    text = (ROBOTS / "motoman_sk120.yaml").read_text()
    bad = tmp_path / "r.yaml"
    bad.write_text(text.replace("{theta: q1,                d: 0,    a: 215,", "{theta: q1,                d: zero, a: 215,"))
    line = next(i for i, t in enumerate(bad.read_text().splitlines(), 1) if "d: zero" in t)
    with pytest.raises(ConfigError, match=rf"r.yaml: links\[0\]\.d \(line {line}\): must be a finite number; got 'zero'"):
        load_robot(bad)
    bad.write_text(text.replace("joints: 6\n", "joints: 6\njoints: 7\n"))
    with pytest.raises(ConfigError, match=r"r.yaml: joints \(line \d+\): duplicate key \(first at line \d+\)"):
        load_robot(bad)
    bad.write_text(text.replace("tool_mm: [205.32, 0.0, 112.65]", "tool_mm: [205.32, true, 112.65]"))
    with pytest.raises(ConfigError, match=r"r.yaml: tool_mm\[1\] \(line \d+\): must be a finite number; got True"):
        load_robot(bad)


def dh_positions(robot, q_deg):
    """The straightforward forward kinematics: a 4 x 4 matrix product per DH row, one pose at a time."""
    out = []
    for q in np.atleast_2d(q_deg):
        T = np.eye(4)
        theta = robot.theta_offset_deg + robot.coupling @ q
        for th, d, a, al in zip(np.radians(theta), robot.d_mm, robot.a_mm, np.radians(robot.alpha_deg)):
            ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
            T = T @ np.array([[ct, -st * ca, st * sa, a * ct], [st, ct * ca, -ct * sa, a * st],
                              [0.0, sa, ca, d], [0.0, 0.0, 0.0, 1.0]])
        out.append((T @ np.append(robot.tool_mm, 1.0))[:3])
    return np.array(out)


def test_fast_fk_equals_the_dh_matrix_product(sk120):
    q = np.random.default_rng(3).uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], size=(300, 6))
    np.testing.assert_allclose(sk120.positions(q), dh_positions(sk120, q), rtol=0, atol=1e-9)
    np.testing.assert_allclose(sk120.forward(q)[:, :3, 3], dh_positions(sk120, q), rtol=0, atol=1e-9)


def test_ik_of_a_target_does_not_depend_on_the_batch(sk120):
    rng = np.random.default_rng(4)
    q = rng.uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], size=(64, 6))
    q[:, 1] = np.clip(q[:, 1], q[:, 2] + 20, q[:, 2] + 110)
    targets = sk120.positions(q)
    seeds = q + rng.normal(0, 5, q.shape)
    batch = sk120.inverse(targets, seeds, fixed=(4, 5)).q_deg
    for i in (0, 17, 63):
        assert np.array_equal(sk120.inverse(targets[i:i + 1], seeds[i], fixed=(4, 5)).q_deg[0], batch[i])


def sequential_path(robot, targets, fixed=(4, 5)):
    """The straightforward path IK: one target after the other, each from the previous solution."""
    q, seed = np.empty((len(targets), robot.n_joints)), robot.home_deg.copy()
    for i, target in enumerate(targets):
        seed = q[i] = robot.inverse(target[None], seed, fixed=fixed).q_deg[0]
    return q


@pytest.mark.parametrize("name", ["rectangle", "spiral_xy", "spiral_yz"])
def test_batched_path_ik_is_the_sequential_solution(sk120, name):
    targets = paper_path(name)
    q = sk120.inverse_path(targets, fixed=(4, 5))
    reference = sequential_path(sk120, targets)
    np.testing.assert_allclose(q, reference, rtol=0, atol=1e-9)           # degrees: the same branch, point by point
    np.testing.assert_allclose(sk120.positions(q), targets, rtol=0, atol=1e-8)


def test_path_ik_falls_back_to_sequential_steps_where_the_chain_does_not_settle(sk120, monkeypatch):
    from partcal.robot import ik

    targets = paper_path("spiral_xy")[:60]
    reference = sequential_path(sk120, targets)
    monkeypatch.setattr(ik, "_PASSES", 1)            # no time to settle: exact prefixes, then restarts
    monkeypatch.setattr(ik, "_SEGMENT", 25)          # and segments on a short path
    np.testing.assert_allclose(sk120.inverse_path(targets, fixed=(4, 5)), reference, rtol=0, atol=1e-9)


@pytest.mark.parametrize("fixed", [(), (4, 5, 6)])
def test_batched_path_ik_with_more_or_no_redundancy(sk120, fixed):
    # six free joints (a three-dimensional self-motion) or three (none): the general corrections
    targets = paper_path("rectangle")[::3]
    q = sk120.inverse_path(targets, fixed=fixed)
    np.testing.assert_allclose(q, sequential_path(sk120, targets, fixed=fixed), rtol=0, atol=1e-9)


def test_forward_of_a_planar_arm_whose_z_axis_never_turns():
    # every alpha is 0: the walk keeps z as one column; forward() must still give (n, 4, 4) poses
    planar = robot_from_dict({"name": "planar", "joints": 2, "limits_deg": [[-170, 170], [-170, 170]],
                              "links": [{"theta": "q1", "d": 0, "a": 500, "alpha": 0},
                                        {"theta": "q2", "d": 0, "a": 300, "alpha": 0}]})
    q = np.array([[0.0, 90.0], [30.0, -60.0], [90.0, 0.0]])
    poses = planar.forward(q)
    t1, t12 = np.radians(q[:, 0]), np.radians(q.sum(axis=1))
    np.testing.assert_allclose(poses[:, :3, 3], np.column_stack([500 * np.cos(t1) + 300 * np.cos(t12),
                                                                 500 * np.sin(t1) + 300 * np.sin(t12), 0 * t1]),
                               atol=1e-9)
    np.testing.assert_allclose(poses[:, :3, 2], np.tile([0.0, 0.0, 1.0], (3, 1)), atol=1e-12)
    np.testing.assert_allclose(poses[:, :3, 0], np.column_stack([np.cos(t12), np.sin(t12), 0 * t1]), atol=1e-12)

def test_parameter_jacobian_matches_finite_differences(sk120):
    """Every DH parameter (four per row) and the tool offset, against central differences of FK."""
    q = np.random.default_rng(4).uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], (7, 6))
    p, jac = sk120.parameter_jacobian(q)
    rows = sk120.alpha_deg.size
    assert jac.shape == (7, 3, 4 * rows + 3)
    np.testing.assert_allclose(p, sk120.positions(q), rtol=0, atol=1e-9)   # the plain walk and the fast one
    h = 1e-5
    for k in range(4 * rows + 3):
        numeric = (moved_positions(sk120, q, k, h) - moved_positions(sk120, q, k, -h)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-6, err_msg=f"column {k}")


def test_a_twist_just_off_a_right_angle_is_not_rounded(sk120):
    """alpha = -90 - 5e-4 degrees moves the tool by about 5e-4 degrees times the lever, not by nothing."""
    q = np.array([[10.0, -120.0, -170.0, 20.0, 30.0, 40.0]])
    alpha = sk120.alpha_deg.copy()
    alpha[0] -= 5e-4
    moved = np.linalg.norm(sk120.replace(alpha_deg=alpha).positions(q) - sk120.positions(q))
    slope = np.linalg.norm(sk120.parameter_jacobian(q)[1][0, :, 3])       # mm per degree of the first twist
    assert moved == pytest.approx(5e-4 * slope, rel=1e-3)


@pytest.mark.parametrize("angles_deg, x_to", [
    ((90, 0, 0), (1, 0, 0)), ((0, 90, 0), (0, 0, -1)), ((0, 0, 90), (0, 1, 0)),
    ((90, 90, 0), (0, 0, -1)), ((0, 90, 90), (0, 0, -1)), ((90, 0, 90), (0, 1, 0)),
])
def test_matrix_from_rpy_turns_about_x_then_y_then_z(angles_deg, x_to):
    # hand: Ry(90) takes x to -z, Rz(90) takes x to y and leaves z alone, Rx leaves x alone
    np.testing.assert_allclose(matrix_from_rpy_deg(angles_deg) @ [1.0, 0, 0], x_to, atol=1e-15)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-360, 360), min_size=3, max_size=3))
def test_matrix_from_rpy_is_scipys_extrinsic_xyz(angles_deg):
    rot = matrix_from_rpy_deg(angles_deg)
    np.testing.assert_allclose(rot, Rotation.from_euler("xyz", angles_deg, degrees=True).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-14)


@pytest.mark.parametrize("name", ["motoman_sk120", "universal_robots_ur10"])
def test_full_pose_ik_reaches_position_and_orientation(name):
    """Poses of random admissible joints, solved from seeds 8 degrees off: the reached transform (forward
    kinematics) equals the wanted one, and the reported errors are the independent ones (distance, and
    the angle of R_wanted R^T from its trace)."""
    robot = load_robot(name)
    rng = np.random.default_rng(3)
    lo, hi = np.maximum(robot.limits_deg[:, 0], -150), np.minimum(robot.limits_deg[:, 1], 150)
    q = rng.uniform(lo, hi, (400, robot.n_joints))
    q = q[robot.within_limits(q)][:150]
    wanted = robot.forward(q)
    result = robot.inverse_pose(wanted, np.clip(q + rng.normal(0, 8, q.shape), robot.limits_deg[:, 0],
                                                robot.limits_deg[:, 1]))
    assert result.success.mean() > 0.95
    reached = robot.forward(result.q_deg)
    ok = result.success
    np.testing.assert_allclose(reached[ok], wanted[ok], atol=1e-7)
    cos = (np.einsum("nij,nij->n", wanted[:, :3, :3], reached[:, :3, :3]) - 1) / 2
    np.testing.assert_allclose(result.error_deg, np.degrees(np.arccos(np.clip(cos, -1, 1))), atol=1e-5)
    np.testing.assert_allclose(result.error_mm, np.linalg.norm(wanted[:, :3, 3] - reached[:, :3, 3], axis=1))
    alone = robot.inverse_pose(wanted[:3], robot.home_deg)                  # the batch does not matter
    np.testing.assert_allclose(alone.q_deg, robot.inverse_pose(wanted, robot.home_deg).q_deg[:3], atol=1e-9)


def test_full_pose_ik_with_a_joint_held_and_bad_poses(sk120):
    """Five free joints cannot reach an arbitrary orientation: the least-squares compromise is not a
    success; a transform whose rotation block is not a rotation is refused, naming the pose."""
    q = np.array([[10.0, -120, -170, 20, 30, 40]])
    wanted = sk120.forward(q)
    wanted[0, :3, :3] = Rotation.from_rotvec([0.3, 0.2, 0.1]).as_matrix() @ wanted[0, :3, :3]
    held = sk120.inverse_pose(wanted, q, fixed=(6,))
    assert not held.success[0] and held.error_deg[0] > 0.1 and held.q_deg[0, 5] == 40.0
    good = sk120.forward(np.repeat(q, 2, axis=0))
    mirrored = good[1].copy()
    mirrored[:3, 0] *= -1.0
    for where, value, what in [((slice(0, 3), slice(0, 3)), 2.0 * good[1, :3, :3], "has a rotation block that is not "
                                                                                   "orthonormal"),
                               ((0, 3), np.nan, "has a non-finite entry"),
                               ((3,), [1, 2, 3, 5], "has a last row other than"),
                               ((slice(None), slice(None)), mirrored, "has a rotation block that mirrors")]:
        bad = good.copy()
        bad[(1,) + where] = value
        with pytest.raises(partcal.DataError, match=r"poses\[1\] " + what):
            sk120.inverse_pose(bad)
    with pytest.raises(partcal.DataError, match=r"Expected poses with shape \(n, 4, 4\)"):
        sk120.inverse_pose(np.zeros((2, 3, 4)))
    for kwargs, message in [({"length_mm": 0.0}, r"length_mm must be a finite number > 0; got 0.0"),
                            ({"tol_deg": -1.0}, r"tol_deg must be a finite number >= 0"),
                            ({"max_iter": 2.5}, r"max_iter must be an int >= 1; got 2.5"),
                            ({"fixed": (1, 2, 3, 4, 5, 6)}, r"fixed holds every joint of motoman_sk120"),
                            ({"seeds_deg": np.zeros((3, 6))}, r"Expected seeds_deg with shape \(6,\) or \(2, 6\)")]:
        with pytest.raises(partcal.DataError, match=message):
            sk120.inverse_pose(good, **kwargs)
    # a pose written with six decimals (as partcal writes CSVs) is taken, its rotation made orthonormal
    rounded = sk120.inverse_pose(np.round(good, 6), q)
    assert rounded.success.all() and rounded.error_mm.max() < 1e-3


def _generic_chain_of(robot):
    """The DH robot written as a generic chain: every row ``Rz(theta)`` then its fixed transform
    ``Tz(d) Tx(a) Rx(alpha)`` given as an origin (translation ``(a, 0, d)``, roll ``alpha``), no DH part."""
    zeros = np.zeros_like(robot.a_mm)
    origins = np.column_stack([robot.a_mm, zeros, robot.d_mm, robot.alpha_deg, zeros, zeros])
    return robot.replace(a_mm=zeros, d_mm=zeros.copy(), alpha_deg=zeros.copy(), origins=origins)


def _hand_transforms(robot, q):
    """Tool poses (n, 4, 4) from 4 x 4 matrices, row by row: Rz(theta) Tz(d) Tx(a) Rx(alpha) E."""
    theta = np.radians(robot.theta_offset_deg + q @ robot.coupling.T)
    origins = robot.origins if robot.origins is not None else np.zeros((theta.shape[1], 6))
    out = np.tile(np.eye(4), (len(q), 1, 1))
    for r in range(theta.shape[1]):
        ct, st = np.cos(theta[:, r]), np.sin(theta[:, r])
        turn = np.zeros((len(q), 4, 4))
        turn[:, 0, 0], turn[:, 0, 1], turn[:, 1, 0], turn[:, 1, 1] = ct, -st, st, ct
        turn[:, 2, 2] = turn[:, 3, 3] = 1.0
        al = np.radians(robot.alpha_deg[r])
        fixed = np.array([[1, 0, 0, robot.a_mm[r]], [0, np.cos(al), -np.sin(al), 0],
                          [0, np.sin(al), np.cos(al), robot.d_mm[r]], [0, 0, 0, 1.0]])
        extra = np.eye(4)
        extra[:3, :3] = Rotation.from_euler("xyz", origins[r, 3:], degrees=True).as_matrix()   # Rz Ry Rx
        extra[:3, 3] = origins[r, :3]
        out = out @ turn @ fixed @ extra
    tool = np.eye(4)
    tool[:3, 3] = robot.tool_mm
    return out @ tool


@pytest.mark.parametrize("name", partcal.available_robots())
def test_every_builtin_robot_as_a_generic_chain_equals_its_dh_rows(name):
    """1,000 random joint sets: the DH walk, the same robot as rows of pure fixed transforms, and the 4 x 4
    matrix product agree to 1e-9 mm (positions) and 1e-12 (axes)."""
    robot = load_robot(name)
    q = np.random.default_rng(30).uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (1000, robot.n_joints))
    hand = _hand_transforms(robot, q)
    generic = _generic_chain_of(robot)
    for chain in (robot, generic):
        poses = chain.forward(q)
        np.testing.assert_allclose(poses[:, :3, 3], hand[:, :3, 3], rtol=0, atol=1e-9)
        np.testing.assert_allclose(poses[:, :3, :3], hand[:, :3, :3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(chain.positions(q), hand[:, :3, 3], rtol=0, atol=1e-9)
    np.testing.assert_allclose(generic.jacobian(q[:50]), robot.jacobian(q[:50]), rtol=0, atol=1e-9)
    origins, _, zs = robot.frame_axes(q[:50])
    np.testing.assert_allclose(generic.frame_axes(q[:50])[0], origins, rtol=0, atol=1e-9)
    np.testing.assert_allclose(generic.frames(q[:50])[1], zs, rtol=0, atol=1e-12)


def test_a_chain_with_general_origins_matches_matrices_and_inverts():
    """Rows with DH parts and tilted origins together: FK against the matrix product, the position and
    parameter Jacobians against central differences, and IK back to the targets."""
    ur10 = load_robot("universal_robots_ur10")
    origins = np.random.default_rng(31).normal(0.0, [5.0, 5.0, 5.0, 2.0, 2.0, 2.0], (6, 6))
    robot = ur10.replace(origins=origins, tool_mm=np.array([10.0, -20.0, 100.0]))
    q = np.random.default_rng(32).uniform(-180, 180, (200, 6))
    np.testing.assert_allclose(robot.forward(q), _hand_transforms(robot, q), rtol=0, atol=1e-9)
    h = 1e-5
    assert_jacobian_is_the_central_difference(robot, q[:5], h)
    p, jac = robot.parameter_jacobian(q[:5])
    for k in range(4 * 6 + 3):
        numeric = (moved_positions(robot, q[:5], k, h) - moved_positions(robot, q[:5], k, -h)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-6, err_msg=f"column {k}")
    targets = robot.positions(q[:20] + 3.0)
    result = robot.inverse(targets, q[:20])
    assert result.success.all() and result.error_mm.max() < 1e-8


def test_origins_round_trip_through_the_robot_yaml(tmp_path):
    """A row's ``origin: {xyz_mm, rpy_deg}`` is read, written back exactly, and refused when malformed."""
    from partcal.robot.description import robot_to_dict

    ur10 = load_robot("universal_robots_ur10")
    robot = ur10.replace(origins=np.tile([1.0, 2.0, 3.0, 0.1, -0.2, 0.3], (6, 1)))
    again = robot_from_dict(robot_to_dict(robot))
    np.testing.assert_array_equal(again.origins, robot.origins)
    spec = robot_to_dict(robot)
    spec["links"][1]["origin"] = {"xyz_mm": [1, 2]}
    with pytest.raises(ConfigError, match=r"links\[1\]\.origin\.xyz_mm.*three numbers"):
        robot_from_dict(spec)


def test_a_row_slides_when_its_d_names_a_joint():
    """``d: q1 + 100`` makes row 1 a prismatic joint (mm): FK by hand, the Jacobian's column is the axis
    (mm per mm), the YAML round trip keeps it; a row that turns and slides is refused."""
    from partcal.robot.description import robot_to_dict

    spec = {"name": "gantry", "joints": 2, "limits_deg": [[0, 1000], [-180, 180]],
            "links": [{"theta": 0, "d": "q1 + 100", "a": 0, "alpha": 90}, {"theta": "q2", "d": 0, "a": 300, "alpha": 0}]}
    robot = robot_from_dict(spec)
    q = np.array([[250.0, 30.0], [0.0, -90.0]])
    # row 1: up z by q1 + 100, then x stays, z turns to -y; row 2: turn q2 about the new z (-y), 300 along x'
    t = np.radians(q[:, 1])
    expected = np.column_stack([300 * np.cos(t), 0 * t, q[:, 0] + 100 + 300 * np.sin(t)])
    np.testing.assert_allclose(robot.positions(q), expected, atol=1e-9)
    np.testing.assert_allclose(robot.jacobian(q)[:, :, 0], [[0.0, 0.0, 1.0]] * 2, atol=1e-12)
    assert robot_to_dict(robot)["links"][0]["d"] == "100.0 + q1"
    np.testing.assert_allclose(robot_from_dict(robot_to_dict(robot)).positions(q), expected, atol=1e-9)
    spec["links"][0]["theta"] = "q2"
    with pytest.raises(ConfigError, match=r"links\[0\].*turns .* or slides .*not both"):
        robot_from_dict(spec)
