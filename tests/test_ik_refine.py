"""Full-pose IK near singularities: Levenberg-Marquardt with restarts finishes what fixed-damping steps leave."""

import numpy as np

from partcal import load_robot
from partcal.robot import ik, ik_refine
from partcal.robot.kinematics import pose_errors

UR10 = load_robot("universal_robots_ur10").replace(tool_mm=np.array([0.0, 0.0, 120.0]))
FREE = np.arange(6)


def test_conditioning_vanishes_at_the_ur_wrist_singularity_and_grows_with_q5():
    """At q5 = 0 the axes of q2, q3, q4 and q6 are parallel: the pose Jacobian loses a direction (its smallest
    singular value is rounding); away from it the ratio grows as sin(q5)."""
    q = np.tile([20.0, -100.0, 80.0, -60.0, 0.0, 30.0], (4, 1))
    q[:, 4] = [0.0, 0.1, 1.0, 10.0]
    ratio = ik_refine.conditioning(UR10, q, FREE, 1000.0)
    assert ratio[0] < 1e-12 and np.all(np.diff(ratio) > 0)
    np.testing.assert_allclose(ratio[1:] / np.sin(np.radians(q[1:, 4])), ratio[1] / np.sin(np.radians(0.1)),
                               rtol=0.05)


def test_refine_pose_finishes_the_poses_fixed_damping_leaves_near_the_wrist_singularity():
    """40 UR10 poses with |q5| < 1 degree, each solved from a seed up to 3 degrees off its joints: 50 fixed-damping
    steps leave several short of 1e-6 mm and 1e-6 degrees; the finishing solve brings all but a few there, checked
    by forward kinematics of the joints it returns."""
    rng = np.random.default_rng(0)
    q = rng.uniform([-90, -150, 30, -180, -1, -180], [90, -30, 140, 180, 1, 180], (40, 6))
    wanted = UR10.forward(q)
    seeds = q + rng.uniform(-3, 3, q.shape)
    settings = ik.Settings(1e-6, 50)
    solved = ik.solve_pose(UR10, wanted[:, :3, 3], wanted[:, :3, :3], seeds, FREE, settings, 1e-6, 1000.0)[0]
    mm, deg = pose_errors(UR10.forward(solved), wanted)
    left = ~((mm <= 1e-6) & (deg <= 1e-6))
    assert left.sum() >= 5
    refined, iterations = ik_refine.refine_pose(UR10, wanted[left, :3, 3], wanted[left, :3, :3], solved[left], FREE,
                                                settings, 1e-6, 1000.0)
    mm, deg = pose_errors(UR10.forward(refined), wanted[left])
    reached = (mm <= 1e-6) & (deg <= 1e-6)
    assert reached.sum() >= left.sum() - 4 and (iterations > 0).all()
