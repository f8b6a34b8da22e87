"""Tracker registration: exact recovery of a known frame and tool, noise, and refusals."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from partcal import DataError, Measurements, load_robot
from partcal.data.registration import register_tracker, registered
from partcal.robot.frames import kabsch
from partcal.robot.description import robot_from_dict


def synthetic(robot, seed, n=40, angle_deg=None):
    """Poses, a known tracker frame (rotation, translation) and tool, and the points the tracker sees."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(robot.limits_deg[:, 0], robot.limits_deg[:, 1], (n, robot.n_joints))
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = np.radians(angle_deg) if angle_deg is not None else rng.uniform(0, np.pi)
    rot = Rotation.from_rotvec(angle * axis).as_matrix()
    t = rng.uniform(-4000, 4000, 3)
    tool = rng.uniform(-250, 250, 3)
    truth = robot.replace(tool_mm=tool).positions(q)
    return q, rot, t, tool, (truth - t) @ rot            # tracker frame: R^T (p - t)


@pytest.mark.parametrize("seed, angle", [(0, None), (1, None), (2, 179.9), (3, 0.0), (4, 90.0)])
def test_known_frame_and_tool_are_recovered_exactly(sk120, seed, angle):
    q, rot, t, tool, seen = synthetic(sk120, seed, angle_deg=angle)
    reg = register_tracker(sk120, q, seen)
    assert Rotation.from_matrix(reg.rotation @ rot.T).magnitude() < 1e-9
    np.testing.assert_allclose(reg.translation_mm, t, atol=1e-6)
    np.testing.assert_allclose(reg.tool_mm, tool, atol=1e-6)
    assert reg.rms_3d < 1e-6 and reg.max_3d < 1e-6 and reg.n_poses == 40 and reg.fit_tool
    assert 1 <= reg.condition < 100
    np.testing.assert_allclose(Rotation.from_rotvec(reg.rotation_deg, degrees=True).as_matrix(), rot, atol=1e-9)
    d = reg.to_dict()
    assert sorted(d) == ["condition", "fit_tool", "max_3d", "n", "rms_3d", "rotation_deg", "tool_mm", "translation_mm"]
    np.testing.assert_allclose(d["translation_mm"], t, atol=1e-6)


def test_a_fixed_tool_is_kept_and_a_wrong_one_shows_in_the_residual(sk120):
    q, rot, t, tool, seen = synthetic(sk120, 5)
    reg = register_tracker(sk120, q, seen, tool_mm=tool, fit_tool=False)
    assert reg.tool_mm.tolist() == tool.tolist() and not reg.fit_tool and reg.rms_3d < 1e-6
    np.testing.assert_allclose(reg.translation_mm, t, atol=1e-6)
    off = register_tracker(sk120, q, seen, tool_mm=tool + [0, 0, 10], fit_tool=False)
    assert 1.0 < off.rms_3d < 10.0          # a 10 mm tool error cannot hide in a rigid transform


def test_noise_gives_the_expected_residual_and_small_parameter_errors(sk120):
    q, rot, t, tool, seen = synthetic(sk120, 6, n=400)
    sigma = 0.05
    noisy = seen + np.random.default_rng(60).normal(0, sigma, seen.shape)
    reg = register_tracker(sk120, q, noisy)
    expected = sigma * np.sqrt(3 * (1 - 9 / (3 * 400)))     # 9 parameters absorb 9 of the 1200 residuals
    assert reg.rms_3d == pytest.approx(expected, rel=0.1)
    assert np.abs(reg.tool_mm - tool).max() < 0.05 and np.abs(reg.translation_mm - t).max() < 0.1


def test_registered_data_set_is_in_the_base_frame(sk120):
    q, rot, t, tool, seen = synthetic(sk120, 7, n=12)
    reg = register_tracker(sk120, q, seen)
    m = registered(Measurements(q, sk120.positions(q), seen, name="s", labels=("a",) * 12), sk120, reg)
    truth = sk120.replace(tool_mm=tool).positions(q)
    np.testing.assert_allclose(m.measured_mm, truth, atol=1e-6)
    np.testing.assert_allclose(m.nominal_mm, truth, atol=1e-6)
    assert m.name == "s" and m.labels == ("a",) * 12


PLANAR = {"name": "planar", "joints": 2, "limits_deg": [[-170, 170], [-170, 170]],
          "links": [{"theta": "q1", "d": 0, "a": 500, "alpha": 0}, {"theta": "q2", "d": 0, "a": 500, "alpha": 0}]}


def test_refuses_poses_that_do_not_determine_the_registration(sk120):
    planar = robot_from_dict(PLANAR)
    rng = np.random.default_rng(8)
    q = rng.uniform(-150, 150, (30, 2))
    p = planar.replace(tool_mm=np.array([10.0, 0, 50])).positions(q)
    # all poses in one plane, the flange turning only about its normal: tool z and translation z are one
    with pytest.raises(DataError, match=r"flat: the tracker registration is ill-conditioned \(condition number "
                                        r"(inf|[\d.e+]+) > 1000\): the 30 poses do not determine the combination of "
                                        r"(tool z, translation z|translation z, tool z)"):
        register_tracker(planar, q, p, source="flat")
    reg = register_tracker(planar, q, p, tool_mm=[10, 0, 50], fit_tool=False)     # with the tool known: fine
    assert reg.rms_3d < 1e-6 and reg.condition < 10
    # equal links and q2 = 180 - 2 q1 put every point on one line: the turn about it is free
    q1 = np.linspace(10, 80, 6)
    line = np.column_stack([q1, 180 - 2 * q1 - 0.0])
    pts = planar.positions(line)
    assert np.allclose(pts[:, 0], 0.0, atol=1e-9)
    with pytest.raises(DataError, match=r"ill-conditioned .* do not determine (the combination of )?rotation y"):
        register_tracker(planar, line, pts, fit_tool=False, source="line")
    q, *_ , seen = synthetic(sk120, 9, n=3)
    with pytest.raises(DataError, match=r"few: a tracker registration with the tool needs at least 4 poses "
                                        r"\(9 parameters\); got 3"):
        register_tracker(sk120, q, seen, source="few")
    with pytest.raises(DataError, match=r"needs at least 3 poses \(6 parameters\); got 2"):
        register_tracker(sk120, q[:2], seen[:2], fit_tool=False)
    with pytest.raises(DataError, match=r"3 measured points but 2 poses"):
        register_tracker(sk120, q[:2], seen)


def test_kabsch_never_returns_a_reflection():
    rng = np.random.default_rng(10)
    pts = rng.normal(size=(20, 3))
    rot, t = kabsch(pts, pts * [-1, 1, 1])              # a mirror image: the best proper rotation instead
    assert np.linalg.det(rot) == pytest.approx(1.0)
    true = Rotation.from_rotvec([0.3, -1.2, 2.0]).as_matrix()
    rot, t = kabsch(pts, pts @ true.T + [1, 2, 3])
    np.testing.assert_allclose(rot, true, atol=1e-12)
    np.testing.assert_allclose(t, [1, 2, 3], atol=1e-12)


def test_real_robot_tool_default_is_the_robots():
    robot = load_robot("motoman_sk120")
    q, rot, t, _, _ = synthetic(robot, 11)
    seen = (robot.positions(q) - t) @ rot               # the robot's own fixture as the tool
    reg = register_tracker(robot, q, seen, fit_tool=False)
    assert reg.tool_mm.tolist() == robot.tool_mm.tolist() and reg.rms_3d < 1e-6


def _three_targets(seed=7, n=30):
    """A perfect UR10 with three targets and a probe turned on its flange, seen from a known tracker frame."""
    robot = load_robot("universal_robots_ur10")
    q, rot, t, tool, seen = synthetic(robot, seed, n=n)
    rng = np.random.default_rng(seed + 100)
    tools = {"B": tool + rng.uniform(-100, 100, 3), "C": tool + rng.uniform(-100, 100, 3)}
    extra = {k: (robot.replace(tool_mm=v).positions(q) - t) @ rot for k, v in tools.items()}
    probe = Rotation.from_rotvec(rng.normal(size=3)).as_matrix()
    flange = robot.forward(q)[:, :3, :3]
    orientation = Rotation.from_matrix(rot.T @ flange @ probe).as_euler("XYZ", degrees=True)   # in the tracker frame
    return robot, q, rot, t, tool, tools, probe, seen, extra, orientation


def test_one_offset_per_target_and_the_probe_rotation_are_recovered_exactly():
    robot, q, rot, t, tool, tools, probe, seen, extra, orientation = _three_targets()
    reg = register_tracker(robot, q, seen, targets=extra, orientation_deg=orientation)
    assert Rotation.from_matrix(reg.rotation @ rot.T).magnitude() < 1e-9
    np.testing.assert_allclose(reg.translation_mm, t, atol=1e-6)
    np.testing.assert_allclose(reg.tool_mm, tool, atol=1e-6)
    for name in ("B", "C"):
        np.testing.assert_allclose(reg.target_tools_mm[name], tools[name], atol=1e-6)
    assert Rotation.from_matrix(reg.probe_rotation @ probe.T).magnitude() < 1e-9
    assert list(reg.target_rms_3d) == ["A", "B", "C"] and max(reg.target_rms_3d.values()) < 1e-6
    assert reg.orientation_rms_deg < 1e-7
    d = reg.to_dict()
    assert sorted(d["targets"]) == ["A", "B", "C"] and d["orientation_rms_deg"] < 1e-7
    m = Measurements(q, np.zeros_like(seen), seen, extra_measured_mm=extra, extra_nominal_mm={},
                     measured_orientation_deg=orientation, nominal_orientation_deg=orientation)
    base = registered(m, robot, reg)
    for name in ("A", "B", "C"):
        np.testing.assert_allclose(base.measured_of(name) - base.nominal_of(name), 0, atol=1e-6)
    np.testing.assert_allclose(base.orientation_errors_deg, 0, atol=1e-7)


def test_residuals_are_reported_per_target():
    robot, q, rot, t, tool, tools, probe, seen, extra, orientation = _three_targets()
    noisy = {**extra, "C": extra["C"] + np.random.default_rng(0).normal(0, 0.05, extra["C"].shape)}
    reg = register_tracker(robot, q, seen, targets=noisy)
    assert reg.target_rms_3d["C"] > 0.05 and reg.target_rms_3d["A"] < 0.02 and reg.probe_rotation is None
    assert reg.rms_3d == reg.target_rms_3d["A"]
    with pytest.raises(DataError, match=r"with the tool given \(fit_tool: false\) every target's offset must be "
                                        r"given too; target B has none"):
        register_tracker(robot, q, seen, targets=extra, tool_mm=tool, fit_tool=False)
    fixed = register_tracker(robot, q, seen, targets=extra, tool_mm=tool, fit_tool=False, target_tools_mm=tools)
    np.testing.assert_allclose(fixed.translation_mm, t, atol=1e-6)

