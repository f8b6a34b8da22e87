"""Kinematics of DH chains and the Motoman SK120 (paper, Table 1)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from partcal import ConfigError, UnreachableError, load_robot
from partcal.robot.kinematics import parse_theta, robot_from_dict
from partcal.robot.trajectories import paper_path

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
    if res.success[0]:
        np.testing.assert_allclose(robot.positions(res.q_deg), target, atol=1e-6)
    else:   # only at the limits may a seed fail to converge; it must then say so honestly
        assert res.error_mm[0] > 1e-8


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
    with pytest.raises(ConfigError, match="base: unknown key"):      # not supported: refused, never ignored
        robot_from_dict({**spec, "base": {"xyz": [0, 0, 100]}})
    with pytest.raises(ConfigError, match="not a built-in robot"):
        load_robot("no_such_robot")


FIELDS = ("theta_offset_deg", "d_mm", "a_mm", "alpha_deg")


def test_parameter_jacobian_matches_finite_differences(sk120):
    """Every DH parameter (four per row) and the tool offset, against central differences of FK."""
    q = np.random.default_rng(4).uniform(sk120.limits_deg[:, 0], sk120.limits_deg[:, 1], (7, 6))
    p, jac = sk120.parameter_jacobian(q)
    rows = sk120.alpha_deg.size
    assert jac.shape == (7, 3, 4 * rows + 3)
    np.testing.assert_array_equal(p, sk120.positions(q))
    h = 1e-5

    def moved(k, step):
        if k < 4 * rows:
            row, field = divmod(k, 4)
            values = getattr(sk120, FIELDS[field]).copy()
            values[row] += step
            return sk120.replace(**{FIELDS[field]: values}).positions(q)
        tool = sk120.tool_mm.copy()
        tool[k - 4 * rows] += step
        return sk120.replace(tool_mm=tool).positions(q)

    for k in range(4 * rows + 3):
        numeric = (moved(k, h) - moved(k, -h)) / (2 * h)
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-6, err_msg=f"column {k}")


def test_a_twist_just_off_a_right_angle_is_not_rounded(sk120):
    """alpha = -90 - 5e-4 degrees moves the tool by about 5e-4 degrees times the lever, not by nothing."""
    q = np.array([[10.0, -120.0, -170.0, 20.0, 30.0, 40.0]])
    alpha = sk120.alpha_deg.copy()
    alpha[0] -= 5e-4
    moved = np.linalg.norm(sk120.replace(alpha_deg=alpha).positions(q) - sk120.positions(q))
    slope = np.linalg.norm(sk120.parameter_jacobian(q)[1][0, :, 3])       # mm per degree of the first twist
    assert moved == pytest.approx(5e-4 * slope, rel=1e-3)
